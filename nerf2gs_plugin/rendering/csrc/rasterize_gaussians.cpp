// Tile-based alpha compositing of projected 3D Gaussians on the CPU: forward and backward.
//
// Inputs come from the torch side (projection, SH, tile binning): per camera-Gaussian pair
// (flattened as c * N + n) the pixel-space mean, the conic (inverse 2D covariance a, b, c),
// the features to composite and the (possibly antialiasing-compensated) opacity; per tile the
// front-to-back depth-sorted list of pairs (`tile_offsets`, `flat_ids`). The semantics match
// gsplat / 3DGS: alpha = min(0.99, o * exp(-sigma)); skip alpha < 1/255 or sigma < 0; stop
// before the Gaussian that would bring the transmittance to <= 1e-4. The backward walks each
// tile back to front and rebuilds the transmittance by division (alpha <= 0.99 keeps it stable).
//
// Loops run over a tile's pixels in the innermost position so that they vectorise (AVX-512
// with -march=native); each Gaussian only visits the tile rows its alpha >= 1/255 ellipse can
// reach. OpenMP parallelises over tiles; gradients go to per-thread buffers (no atomics).
#include <torch/extension.h>
#include <ATen/Parallel.h>
#include <omp.h>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

namespace {

constexpr float kAlphaMin = 1.0f / 255.0f;
constexpr float kAlphaMax = 0.99f;
constexpr float kTMin = 1e-4f;

// exp(x) for x <= 0: range reduction to 2^n * 2^f with |f| <= 0.5 and a degree-6 Taylor
// polynomial (relative error ~1e-7); written so that GCC vectorises it (libm's expf would not be).
template <typename T>
inline T exp_neg(T x) { return std::exp(x); }

template <>
inline float exp_neg<float>(float x) {
  x = x < -87.0f ? -87.0f : x;
  const float t = x * 1.4426950408889634f;
  const float n = std::nearbyint(t);
  const float f = (t - n) * 0.6931471805599453f;
  float p = 1.0f + f * (1.0f + f * (0.5f + f * (0.16666667f + f * (0.041666668f + f * (0.008333334f + f * 0.0013888889f)))));
  const int e = static_cast<int>(n) + 127;
  const int bits = e << 23;
  float s;
  std::memcpy(&s, &bits, sizeof(float));
  return p * s;
}

struct TileGeom {
  int cam, x0, y0;  // camera index and pixel origin of the tile
};

inline TileGeom tile_geom(int64_t t, int tiles_x, int tiles_y, int ts) {
  const int per_cam = tiles_x * tiles_y;
  const int cam = static_cast<int>(t / per_cam);
  const int local = static_cast<int>(t % per_cam);
  return {cam, (local % tiles_x) * ts, (local / tiles_x) * ts};
}

// Rows [r0, r1) of the tile that a Gaussian's alpha >= 1/255 ellipse can reach (conservative).
template <typename T>
inline void row_range(T my, T ca, T cb, T cc, T op, int y0, int ts, int& r0, int& r1) {
  const T det = ca * cc - cb * cb;
  const T s = std::log(std::max(op * T(255), T(1)));
  const T cov_yy = det > 0 ? ca / det : T(0);
  const T ey = std::sqrt(std::max(T(2) * s * cov_yy, T(0))) + T(1);
  const T lo = my - ey - T(0.5) - y0, hi = my + ey - T(0.5) - y0;
  r0 = static_cast<int>(std::max(T(0), std::floor(lo)));
  r1 = static_cast<int>(std::min(T(ts), std::floor(hi) + T(1)));
}

template <typename T>
std::vector<torch::Tensor> forward_impl(const torch::Tensor& means2d, const torch::Tensor& conics,
                                        const torch::Tensor& colors, const torch::Tensor& opacities,
                                        const torch::Tensor& tile_offsets, const torch::Tensor& flat_ids,
                                        int64_t n_cams, int64_t height, int64_t width, int64_t ts) {
  const int64_t D = colors.size(1);
  const int tiles_x = static_cast<int>((width + ts - 1) / ts), tiles_y = static_cast<int>((height + ts - 1) / ts);
  const int64_t n_tiles = n_cams * tiles_x * tiles_y;
  auto opts = means2d.options();
  auto render = torch::zeros({n_cams, height, width, D}, opts);
  auto alpha = torch::zeros({n_cams, height, width}, opts);
  auto last = torch::full({n_cams, height, width}, -1, opts.dtype(torch::kInt64));
  auto median = torch::full({n_cams, height, width}, -1, opts.dtype(torch::kInt64));
  const T* m2 = means2d.data_ptr<T>();
  const T* cn = conics.data_ptr<T>();
  const T* col = colors.data_ptr<T>();
  const T* opa = opacities.data_ptr<T>();
  const int64_t* off = tile_offsets.data_ptr<int64_t>();
  const int64_t* ids = flat_ids.data_ptr<int64_t>();
  T* out = render.data_ptr<T>();
  T* out_a = alpha.data_ptr<T>();
  int64_t* out_last = last.data_ptr<int64_t>();
  int64_t* out_med = median.data_ptr<int64_t>();
  const int P = static_cast<int>(ts * ts);

#pragma omp parallel num_threads(at::get_num_threads())
  {
    std::vector<T> px(P), py(P), Tr(P), act(P), acc(P * D), w(P);
    std::vector<int64_t> lst(P), med(P);
#pragma omp for schedule(dynamic, 1)
    for (int64_t t = 0; t < n_tiles; ++t) {
      const TileGeom g = tile_geom(t, tiles_x, tiles_y, static_cast<int>(ts));
      for (int p = 0; p < P; ++p) {
        const int x = g.x0 + p % ts, y = g.y0 + p / ts;
        px[p] = T(x) + T(0.5);
        py[p] = T(y) + T(0.5);
        Tr[p] = T(1);
        act[p] = (x < width && y < height) ? T(1) : T(0);
        lst[p] = -1;
        med[p] = -1;
      }
      std::fill(acc.begin(), acc.end(), T(0));
      int64_t k = off[t];
      const int64_t k_end = off[t + 1];
      for (; k < k_end; ++k) {
        if (((k - off[t]) & 15) == 15) {
          T any = 0;
#pragma omp simd reduction(+ : any)
          for (int p = 0; p < P; ++p) any += act[p];
          if (any == 0) break;
        }
        const int64_t id = ids[k];
        const T mx = m2[2 * id], my = m2[2 * id + 1];
        const T ca = cn[3 * id], cb = cn[3 * id + 1], cc = cn[3 * id + 2];
        const T op = opa[id];
        int r0, r1;
        row_range<T>(my, ca, cb, cc, op, g.y0, static_cast<int>(ts), r0, r1);
        if (r0 >= r1) continue;
        const int p0 = r0 * static_cast<int>(ts), p1 = r1 * static_cast<int>(ts);
        bool any_w = false;
#pragma omp simd reduction(| : any_w)
        for (int p = p0; p < p1; ++p) {
          const T dx = mx - px[p], dy = my - py[p];
          const T sigma = T(0.5) * (ca * dx * dx + cc * dy * dy) + cb * dx * dy;
          T a = op * exp_neg<T>(-sigma);
          a = a > T(kAlphaMax) ? T(kAlphaMax) : a;
          const bool valid = act[p] > 0 && sigma >= 0 && a >= T(kAlphaMin);
          const T nt = Tr[p] * (T(1) - a);
          const bool term = valid && nt <= T(kTMin);
          const bool contrib = valid && !term;
          const T wp = contrib ? a * Tr[p] : T(0);
          w[p] = wp;
          any_w |= contrib;
          med[p] = (contrib && Tr[p] > T(0.5)) ? id : med[p];
          Tr[p] = contrib ? nt : Tr[p];
          act[p] = term ? T(0) : act[p];
          lst[p] = contrib ? k : lst[p];
        }
        if (!any_w) continue;
        for (int64_t ch = 0; ch < D; ++ch) {
          const T c = col[id * D + ch];
          T* ac = acc.data() + ch * P;
#pragma omp simd
          for (int p = p0; p < p1; ++p) ac[p] += w[p] * c;
        }
      }
      for (int p = 0; p < P; ++p) {
        const int x = g.x0 + p % ts, y = g.y0 + p / ts;
        if (x >= width || y >= height) continue;
        const int64_t pix = (static_cast<int64_t>(g.cam) * height + y) * width + x;
        for (int64_t ch = 0; ch < D; ++ch) out[pix * D + ch] = acc[ch * P + p];
        out_a[pix] = T(1) - Tr[p];
        out_last[pix] = lst[p];
        out_med[pix] = med[p];
      }
    }
  }
  return {render, alpha, last, median};
}

template <typename T>
std::vector<torch::Tensor> backward_impl(const torch::Tensor& means2d, const torch::Tensor& conics,
                                         const torch::Tensor& colors, const torch::Tensor& opacities,
                                         const torch::Tensor& tile_offsets, const torch::Tensor& flat_ids,
                                         const torch::Tensor& alpha, const torch::Tensor& last,
                                         const torch::Tensor& v_render, const torch::Tensor& v_alpha,
                                         int64_t n_cams, int64_t height, int64_t width, int64_t ts) {
  const int64_t D = colors.size(1);
  const int64_t CN = means2d.size(0);
  const int tiles_x = static_cast<int>((width + ts - 1) / ts), tiles_y = static_cast<int>((height + ts - 1) / ts);
  const int64_t n_tiles = n_cams * tiles_x * tiles_y;
  const int nt = std::max(1, at::get_num_threads());
  auto opts = means2d.options();
  // per-thread accumulators, laid out [thread][pair][means2d(2) conic(3) opacity(1) colours(D)]
  const int64_t G = 6 + D;
  auto grads = torch::zeros({nt, CN, G}, opts);
  const T* m2 = means2d.data_ptr<T>();
  const T* cn = conics.data_ptr<T>();
  const T* col = colors.data_ptr<T>();
  const T* opa = opacities.data_ptr<T>();
  const int64_t* off = tile_offsets.data_ptr<int64_t>();
  const int64_t* ids = flat_ids.data_ptr<int64_t>();
  const T* al = alpha.data_ptr<T>();
  const int64_t* lastp = last.data_ptr<int64_t>();
  const T* vr = v_render.data_ptr<T>();
  const T* va = v_alpha.data_ptr<T>();
  T* gr = grads.data_ptr<T>();
  const int P = static_cast<int>(ts * ts);

#pragma omp parallel num_threads(nt)
  {
    T* my_gr = gr + static_cast<int64_t>(omp_get_thread_num()) * CN * G;
    std::vector<T> px(P), py(P), Tr(P), Tfin(P), vout(P * D), buf(P * D), vap(P), fac(P), rap(P), Tb(P), vacc(P);
    std::vector<int64_t> lst(P);
    std::vector<T> vcol(D);
#pragma omp for schedule(dynamic, 1)
    for (int64_t t = 0; t < n_tiles; ++t) {
      const TileGeom g = tile_geom(t, tiles_x, tiles_y, static_cast<int>(ts));
      int64_t kmax = -1;
      for (int p = 0; p < P; ++p) {
        const int x = g.x0 + p % ts, y = g.y0 + p / ts;
        px[p] = T(x) + T(0.5);
        py[p] = T(y) + T(0.5);
        const bool in = x < width && y < height;
        const int64_t pix = in ? (static_cast<int64_t>(g.cam) * height + y) * width + x : 0;
        lst[p] = in ? lastp[pix] : -1;
        Tfin[p] = in ? T(1) - al[pix] : T(0);
        Tr[p] = Tfin[p];
        vap[p] = in ? va[pix] : T(0);
        for (int64_t ch = 0; ch < D; ++ch) {
          vout[ch * P + p] = in ? vr[pix * D + ch] : T(0);
          buf[ch * P + p] = 0;
        }
        kmax = std::max(kmax, lst[p]);
      }
      for (int64_t k = kmax; k >= off[t]; --k) {
        const int64_t id = ids[k];
        const T mx = m2[2 * id], my = m2[2 * id + 1];
        const T ca = cn[3 * id], cb = cn[3 * id + 1], cc = cn[3 * id + 2];
        const T op = opa[id];
        int r0, r1;
        row_range<T>(my, ca, cb, cc, op, g.y0, static_cast<int>(ts), r0, r1);
        if (r0 >= r1) continue;
        const int p0 = r0 * static_cast<int>(ts), p1 = r1 * static_cast<int>(ts);
        bool any = false;
#pragma omp simd reduction(| : any)
        for (int p = p0; p < p1; ++p) {
          const T dx = mx - px[p], dy = my - py[p];
          const T sigma = T(0.5) * (ca * dx * dx + cc * dy * dy) + cb * dx * dy;
          T a = op * exp_neg<T>(-sigma);
          a = a > T(kAlphaMax) ? T(kAlphaMax) : a;
          const bool valid = k <= lst[p] && sigma >= 0 && a >= T(kAlphaMin);
          const T ra = T(1) / (T(1) - a);
          const T tb = Tr[p] * ra;
          rap[p] = valid ? ra : T(0);
          Tb[p] = valid ? tb : T(0);
          fac[p] = valid ? a * tb : T(0);
          vacc[p] = valid ? Tfin[p] * ra * vap[p] : T(0);
          Tr[p] = valid ? tb : Tr[p];
          any |= valid;
        }
        if (!any) continue;
        for (int64_t ch = 0; ch < D; ++ch) {
          const T c = col[id * D + ch];
          T* vo = vout.data() + ch * P;
          T* bf = buf.data() + ch * P;
          T vc = 0;
#pragma omp simd reduction(+ : vc)
          for (int p = p0; p < p1; ++p) {
            vc += fac[p] * vo[p];
            vacc[p] += (c * Tb[p] - bf[p] * rap[p]) * vo[p];
            bf[p] += c * fac[p];
          }
          vcol[ch] = vc;
        }
        T g_mx = 0, g_my = 0, g_a = 0, g_b = 0, g_c = 0, g_o = 0;
#pragma omp simd reduction(+ : g_mx, g_my, g_a, g_b, g_c, g_o)
        for (int p = p0; p < p1; ++p) {
          const T dx = mx - px[p], dy = my - py[p];
          const T sigma = T(0.5) * (ca * dx * dx + cc * dy * dy) + cb * dx * dy;
          const T vis = exp_neg<T>(-sigma);
          const T v_al = op * vis < T(kAlphaMax) ? vacc[p] : T(0);  // 0 where not composited
          const T v_sig = -op * vis * v_al;
          g_o += vis * v_al;
          g_a += T(0.5) * v_sig * dx * dx;
          g_b += v_sig * dx * dy;
          g_c += T(0.5) * v_sig * dy * dy;
          g_mx += v_sig * (ca * dx + cb * dy);
          g_my += v_sig * (cb * dx + cc * dy);
        }
        T* o = my_gr + id * G;
        o[0] += g_mx; o[1] += g_my; o[2] += g_a; o[3] += g_b; o[4] += g_c; o[5] += g_o;
        for (int64_t ch = 0; ch < D; ++ch) o[6 + ch] += vcol[ch];
      }
    }
  }
  auto total = grads.sum(0);  // [CN, G]
  return {total.slice(1, 0, 2).contiguous(), total.slice(1, 2, 5).contiguous(),
          total.slice(1, 6, 6 + D).contiguous(), total.select(1, 5).contiguous()};
}

void check(const torch::Tensor& x, const char* name) {
  TORCH_CHECK(x.device().is_cpu(), name, " must be a CPU tensor");
  TORCH_CHECK(x.is_contiguous(), name, " must be contiguous");
}

}  // namespace

std::vector<torch::Tensor> rasterize_forward(torch::Tensor means2d, torch::Tensor conics, torch::Tensor colors,
                                             torch::Tensor opacities, torch::Tensor tile_offsets, torch::Tensor flat_ids,
                                             int64_t n_cams, int64_t height, int64_t width, int64_t tile_size) {
  for (auto* x : {&means2d, &conics, &colors, &opacities, &tile_offsets, &flat_ids}) check(*x, "input");
  TORCH_CHECK(tile_offsets.scalar_type() == torch::kInt64 && flat_ids.scalar_type() == torch::kInt64, "tile lists must be int64");
  if (means2d.scalar_type() == torch::kDouble)
    return forward_impl<double>(means2d, conics, colors, opacities, tile_offsets, flat_ids, n_cams, height, width, tile_size);
  TORCH_CHECK(means2d.scalar_type() == torch::kFloat, "rasterizer inputs must be float32 or float64");
  return forward_impl<float>(means2d, conics, colors, opacities, tile_offsets, flat_ids, n_cams, height, width, tile_size);
}

std::vector<torch::Tensor> rasterize_backward(torch::Tensor means2d, torch::Tensor conics, torch::Tensor colors,
                                              torch::Tensor opacities, torch::Tensor tile_offsets, torch::Tensor flat_ids,
                                              torch::Tensor alpha, torch::Tensor last, torch::Tensor v_render,
                                              torch::Tensor v_alpha, int64_t n_cams, int64_t height, int64_t width,
                                              int64_t tile_size) {
  for (auto* x : {&means2d, &conics, &colors, &opacities, &tile_offsets, &flat_ids, &alpha, &last, &v_render, &v_alpha})
    check(*x, "input");
  if (means2d.scalar_type() == torch::kDouble)
    return backward_impl<double>(means2d, conics, colors, opacities, tile_offsets, flat_ids, alpha, last, v_render,
                                 v_alpha, n_cams, height, width, tile_size);
  return backward_impl<float>(means2d, conics, colors, opacities, tile_offsets, flat_ids, alpha, last, v_render, v_alpha,
                              n_cams, height, width, tile_size);
}

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
  m.def("forward", &rasterize_forward, "3DGS tile compositing forward (CPU)");
  m.def("backward", &rasterize_backward, "3DGS tile compositing backward (CPU)");
}
