// 2DGS surfel compositing on the CPU: forward and backward, OpenMP over tiles. The fused
// projection + SH op and the tile lists (surfels_proj_core.h) are bound here too.
//
// Per surfel row m (camera-major, C*N rows) the caller gives the adjugate H of its homography T
// (row-major 3x3), det(T), the projected centre, the centre depth, the opacity and F features
// (colours then camera-frame normals). For a pixel centre (a, b): q = H (a, b, 1),
// (u, v) = (q_x, q_y) / q_z, depth = det / q_z, rho = min(u^2 + v^2, 2 |c - (a, b)|^2) (the
// low-pass of 2DGS; its depth is the centre depth), alpha = min(0.99, o exp(-rho / 2)), skipped
// under 1/255 or at depth <= near, and a pixel stops before transmittance falls under 1e-4.
// The pure-torch reference (surfels_torch.py) computes the same thing; tests compare them.
//
// Output channels per pixel: F features, accumulated depth, alpha, distortion, median depth.
// Distortion = sum_i w_i sum_{j<i} w_j (z_i - z_j)^2 (the 2DGS code's L2 form on camera z).
#include <torch/extension.h>
#include <ATen/Parallel.h>
#include <omp.h>

#include <cmath>
#include <vector>

#include "surfels_proj_core.h"

namespace {

constexpr double kAlphaMin = 1.0 / 255.0;
constexpr double kAlphaMax = 0.99;
constexpr double kTMin = 1e-4;
constexpr double kLowpass = 2.0;

template <typename T>
struct Surfel {
  T h[9];
  T det, mx, my, zc, o;
  T thr;  // rho beyond which o exp(-rho/2) < 1/255, plus a margin (a pre-test only)
  T by0, by1;  // rows of the footprint box, 1 px margin
  int64_t row;
};

template <typename T>
struct Hit {
  bool ok;
  bool use3;
  T u, v, inv, dx, dy, G, alpha, z;
};

template <typename T>
inline Hit<T> intersect(const Surfel<T>& s, T a, T b, T near) {
  Hit<T> r;
  r.ok = false;
  const T qx = s.h[0] * a + s.h[1] * b + s.h[2];
  const T qy = s.h[3] * a + s.h[4] * b + s.h[5];
  const T qz = s.h[6] * a + s.h[7] * b + s.h[8];
  r.dx = s.mx - a;
  r.dy = s.my - b;
  const T rho2 = T(kLowpass) * (r.dx * r.dx + r.dy * r.dy);
  // cheap rejection before the division and the exp: both distances beyond the cut-off
  if (rho2 > s.thr && qx * qx + qy * qy > s.thr * qz * qz) return r;
  if (!(qz != T(0) && std::abs(qz) * T(1e6) > std::abs(qx) + std::abs(qy))) return r;
  r.inv = T(1) / qz;
  r.u = qx * r.inv;
  r.v = qy * r.inv;
  const T rho3 = r.u * r.u + r.v * r.v;
  r.use3 = rho3 <= rho2;
  const T rho = r.use3 ? rho3 : rho2;
  r.z = r.use3 ? s.det * r.inv : s.zc;
  r.G = std::exp(T(-0.5) * rho);
  r.alpha = std::min(T(kAlphaMax), s.o * r.G);
  if (r.alpha < T(kAlphaMin) || !(r.z > near) || !std::isfinite(r.z)) return r;
  r.ok = true;
  return r;
}

template <typename T>
void load_tile(std::vector<Surfel<T>>& buf, const int64_t* ids, int64_t start, int64_t count, const T* adj,
               const T* det, const T* m2, const T* zc, const T* op, const T* box) {
  buf.resize(count);
  for (int64_t k = 0; k < count; ++k) {
    const int64_t g = ids[start + k];
    Surfel<T>& s = buf[k];
    for (int i = 0; i < 9; ++i) s.h[i] = adj[g * 9 + i];
    s.det = det[g];
    s.mx = m2[g * 2];
    s.my = m2[g * 2 + 1];
    s.zc = zc[g];
    s.o = op[g];
    s.thr = s.o > T(0) ? T(2) * std::log(s.o * T(255)) * T(1.001) + T(1e-3) : T(-1);
    s.by0 = box[g * 4 + 1] - T(1);
    s.by1 = box[g * 4 + 3] + T(1);
    s.row = g;
  }
}

// Per tile row, the list positions of the surfels whose footprint box reaches that row (in list
// order, i.e. front to back): a pixel only visits those.
template <typename T>
void row_lists(const std::vector<Surfel<T>>& buf, int64_t y0, int64_t ts, std::vector<std::vector<int32_t>>& rows) {
  rows.resize(ts);
  for (auto& r : rows) r.clear();
  for (int32_t k = 0; k < (int32_t)buf.size(); ++k) {
    const T lo = std::ceil(buf[k].by0 - T(0.5) - T(y0)), hi = std::floor(buf[k].by1 - T(0.5) - T(y0));
    const int64_t r0 = (int64_t)std::max(lo, T(0)), r1 = (int64_t)std::min(hi, T(ts - 1));
    for (int64_t r = r0; r <= r1; ++r) rows[r].push_back(k);
  }
}

template <typename T>
void forward_impl(const T* adj, const T* det, const T* m2, const T* zc, const T* op, const T* box, const T* feats, int64_t F,
                  const int64_t* ids, const int64_t* starts, const int64_t* counts, const std::vector<int64_t>& tiles,
                  int64_t H, int64_t W, int64_t ts, int64_t tw, int64_t th, T near, T* out, T* auxf, int32_t* auxi) {
  const int64_t nc = F + 4;
#pragma omp parallel
  {
    std::vector<Surfel<T>> buf;
    std::vector<std::vector<int32_t>> rows;
    std::vector<T> acc(F);
#pragma omp for schedule(dynamic, 1)
    for (int64_t ti = 0; ti < (int64_t)tiles.size(); ++ti) {
      const int64_t tile = tiles[ti];
      const int64_t cam = tile / (tw * th), t_in = tile % (tw * th);
      const int64_t x0 = (t_in % tw) * ts, y0 = (t_in / tw) * ts;
      const int64_t cnt = counts[tile];
      load_tile(buf, ids, starts[tile], cnt, adj, det, m2, zc, op, box);
      row_lists(buf, y0, ts, rows);
      for (int64_t py = y0; py < std::min(y0 + ts, H); ++py) {
        const std::vector<int32_t>& rl = rows[py - y0];
        for (int64_t px = x0; px < std::min(x0 + ts, W); ++px) {
          const T a = T(px) + T(0.5), b = T(py) + T(0.5);
          T Tr = 1, dsum = 0, A = 0, M1 = 0, M2 = 0, dist = 0, median = 0;
          int32_t med_pos = -1, last = 0;
          std::fill(acc.begin(), acc.end(), T(0));
          for (const int32_t k : rl) {
            const Surfel<T>& s = buf[k];
            const Hit<T> hit = intersect(s, a, b, near);
            if (!hit.ok) continue;
            const T Tn = Tr * (T(1) - hit.alpha);
            if (Tn < T(kTMin)) break;
            const T w = hit.alpha * Tr;
            const T* f = feats + s.row * F;
            for (int64_t c = 0; c < F; ++c) acc[c] += w * f[c];
            const T z = hit.z;
            dsum += w * z;
            dist += w * (z * z * A + M2 - T(2) * z * M1);
            A += w;
            M1 += w * z;
            M2 += w * z * z;
            if (Tr > T(0.5)) {
              median = z;
              med_pos = (int32_t)k;
            }
            Tr = Tn;
            last = (int32_t)(k + 1);
          }
          const int64_t pix = (cam * H + py) * W + px;
          T* o = out + pix * nc;
          for (int64_t c = 0; c < F; ++c) o[c] = acc[c];
          o[F] = dsum;
          o[F + 1] = T(1) - Tr;
          o[F + 2] = dist;
          o[F + 3] = median;
          auxf[pix * 2] = Tr;
          auxf[pix * 2 + 1] = M2;
          auxi[pix * 2] = last;
          auxi[pix * 2 + 1] = med_pos;
        }
      }
    }
  }
}

// gradient row layout (per surfel row): adj 9 | det | m2 2 | zc | o | densify 2 | feats F
template <typename T>
void backward_impl(const T* adj, const T* det, const T* m2, const T* zc, const T* op, const T* box, const T* feats, int64_t F,
                   const int64_t* ids, const int64_t* starts, const int64_t* counts, const std::vector<int64_t>& tiles,
                   int64_t H, int64_t W, int64_t ts, int64_t tw, int64_t th, T near, const T* out, const T* auxf,
                   const int32_t* auxi, const T* gout, T* grads, int64_t M, bool screen_signal) {
  const int64_t nc = F + 4, G = 16 + F;
  const int nthreads = omp_get_max_threads();
  std::vector<std::vector<T>> local(nthreads);
#pragma omp parallel
  {
    const int tid = omp_get_thread_num();
    std::vector<T>& gl = local[tid];
    gl.assign(M * G, T(0));
    std::vector<Surfel<T>> buf;
    std::vector<std::vector<int32_t>> rows;
#pragma omp for schedule(dynamic, 1)
    for (int64_t ti = 0; ti < (int64_t)tiles.size(); ++ti) {
      const int64_t tile = tiles[ti];
      const int64_t cam = tile / (tw * th), t_in = tile % (tw * th);
      const int64_t x0 = (t_in % tw) * ts, y0 = (t_in / tw) * ts;
      load_tile(buf, ids, starts[tile], counts[tile], adj, det, m2, zc, op, box);
      row_lists(buf, y0, ts, rows);
      for (int64_t py = y0; py < std::min(y0 + ts, H); ++py) {
        const std::vector<int32_t>& rl = rows[py - y0];
        for (int64_t px = x0; px < std::min(x0 + ts, W); ++px) {
          const int64_t pix = (cam * H + py) * W + px;
          const int32_t last = auxi[pix * 2], med_pos = auxi[pix * 2 + 1];
          if (last == 0) continue;
          const T a = T(px) + T(0.5), b = T(py) + T(0.5);
          const T* o = out + pix * nc;
          const T* go = gout + pix * nc;
          const T Atot = o[F + 1], M1tot = o[F], M2tot = auxf[pix * 2 + 1];
          const T gD = go[F], gA = go[F + 1], gDist = go[F + 2], gMed = go[F + 3];
          T Tr = auxf[pix * 2];
          T S = 0;
          for (int64_t j = (int64_t)rl.size() - 1; j >= 0; --j) {
            const int32_t k = rl[j];
            if (k >= last) continue;
            const Surfel<T>& s = buf[k];
            const Hit<T> hit = intersect(s, a, b, near);
            if (!hit.ok) continue;
            const T alpha = hit.alpha, z = hit.z;
            const T Tk = Tr / (T(1) - alpha);
            const T w = alpha * Tk;
            const T* f = feats + s.row * F;
            T* g = gl.data() + s.row * G;
            T gw = gA + gD * z + gDist * (z * z * Atot - T(2) * z * M1tot + M2tot);
            for (int64_t c = 0; c < F; ++c) {
              gw += go[c] * f[c];
              g[16 + c] += w * go[c];
            }
            T gz = gD * w + gDist * T(2) * w * (z * Atot - M1tot);
            if (k == med_pos) gz += gMed;
            const T galpha = gw * Tk - S / (T(1) - alpha);
            S += gw * w;
            Tr = Tk;
            T gG = 0;
            if (s.o * hit.G <= T(kAlphaMax)) {
              g[13] += galpha * hit.G;
              gG = galpha * s.o;
            }
            if (screen_signal && hit.use3) {
              // densification signal: the surfel moved rigidly on screen, dG/dc = -grad_x G = G (u grad u + v grad v)
              const T dua = (s.h[0] - hit.u * s.h[6]) * hit.inv, dva = (s.h[3] - hit.v * s.h[6]) * hit.inv;
              const T dub = (s.h[1] - hit.u * s.h[7]) * hit.inv, dvb = (s.h[4] - hit.v * s.h[7]) * hit.inv;
              g[14] += gG * hit.G * (hit.u * dua + hit.v * dva);
              g[15] += gG * hit.G * (hit.u * dub + hit.v * dvb);
            } else {  // the low-pass Gaussian about the centre (where it wins, both signals agree)
              g[14] += gG * (-T(kLowpass) * hit.G) * hit.dx;
              g[15] += gG * (-T(kLowpass) * hit.G) * hit.dy;
            }
            const T grho = gG * T(-0.5) * hit.G;
            if (hit.use3) {
              const T gu = grho * T(2) * hit.u, gv = grho * T(2) * hit.v;
              const T gqx = gu * hit.inv, gqy = gv * hit.inv;
              const T gqz = -(gu * hit.u + gv * hit.v) * hit.inv - gz * z * hit.inv;
              g[0] += gqx * a; g[1] += gqx * b; g[2] += gqx;
              g[3] += gqy * a; g[4] += gqy * b; g[5] += gqy;
              g[6] += gqz * a; g[7] += gqz * b; g[8] += gqz;
              g[9] += gz * hit.inv;
            } else {
              g[10] += grho * T(2 * kLowpass) * hit.dx;
              g[11] += grho * T(2 * kLowpass) * hit.dy;
              g[12] += gz;
            }
          }
        }
      }
    }
  }
  // reduce the per-thread buffers
  const int64_t total = M * G;
#pragma omp parallel for schedule(static)
  for (int64_t i = 0; i < total; ++i) {
    T v = 0;
    for (int t = 0; t < nthreads; ++t)
      if (!local[t].empty()) v += local[t][i];
    grads[i] = v;
  }
}

std::vector<int64_t> nonempty_tiles(const torch::Tensor& counts) {
  std::vector<int64_t> tiles;
  const int64_t* c = counts.data_ptr<int64_t>();
  for (int64_t i = 0; i < counts.numel(); ++i)
    if (c[i] > 0) tiles.push_back(i);
  return tiles;
}

}  // namespace

std::vector<torch::Tensor> surfels_forward(torch::Tensor adj, torch::Tensor det, torch::Tensor m2, torch::Tensor zc,
                                           torch::Tensor op, torch::Tensor box, torch::Tensor feats, torch::Tensor ids,
                                           torch::Tensor starts, torch::Tensor counts, int64_t C, int64_t H, int64_t W,
                                           int64_t ts, int64_t tw, int64_t th, double near) {
  const int64_t F = feats.size(1);
  auto out = torch::zeros({C, H, W, F + 4}, feats.options());
  auto auxf = torch::zeros({C, H, W, 2}, feats.options());
  auto auxi = torch::zeros({C, H, W, 2}, feats.options().dtype(torch::kInt32));
  auxf.select(3, 0).fill_(1.0);
  auxi.select(3, 1).fill_(-1);
  const auto tiles = nonempty_tiles(counts);
  AT_DISPATCH_FLOATING_TYPES(feats.scalar_type(), "surfels_forward", [&] {
    forward_impl<scalar_t>(adj.data_ptr<scalar_t>(), det.data_ptr<scalar_t>(), m2.data_ptr<scalar_t>(),
                           zc.data_ptr<scalar_t>(), op.data_ptr<scalar_t>(), box.data_ptr<scalar_t>(), feats.data_ptr<scalar_t>(), F,
                           ids.data_ptr<int64_t>(), starts.data_ptr<int64_t>(), counts.data_ptr<int64_t>(), tiles, H,
                           W, ts, tw, th, (scalar_t)near, out.data_ptr<scalar_t>(), auxf.data_ptr<scalar_t>(),
                           auxi.data_ptr<int32_t>());
  });
  return {out, auxf, auxi};
}

torch::Tensor surfels_backward(torch::Tensor adj, torch::Tensor det, torch::Tensor m2, torch::Tensor zc,
                               torch::Tensor op, torch::Tensor box, torch::Tensor feats, torch::Tensor ids, torch::Tensor starts,
                               torch::Tensor counts, int64_t C, int64_t H, int64_t W, int64_t ts, int64_t tw,
                               int64_t th, double near, torch::Tensor out, torch::Tensor auxf, torch::Tensor auxi,
                               torch::Tensor gout, bool screen_signal) {
  const int64_t F = feats.size(1), M = feats.size(0);
  auto grads = torch::zeros({M, 16 + F}, feats.options());
  const auto tiles = nonempty_tiles(counts);
  AT_DISPATCH_FLOATING_TYPES(feats.scalar_type(), "surfels_backward", [&] {
    backward_impl<scalar_t>(adj.data_ptr<scalar_t>(), det.data_ptr<scalar_t>(), m2.data_ptr<scalar_t>(),
                            zc.data_ptr<scalar_t>(), op.data_ptr<scalar_t>(), box.data_ptr<scalar_t>(), feats.data_ptr<scalar_t>(), F,
                            ids.data_ptr<int64_t>(), starts.data_ptr<int64_t>(), counts.data_ptr<int64_t>(), tiles,
                            H, W, ts, tw, th, (scalar_t)near, out.data_ptr<scalar_t>(), auxf.data_ptr<scalar_t>(),
                            auxi.data_ptr<int32_t>(), gout.data_ptr<scalar_t>(), grads.data_ptr<scalar_t>(), M,
                            screen_signal);
  });
  return grads;
}

std::vector<torch::Tensor> surfels_project(torch::Tensor means, torch::Tensor quats, torch::Tensor scales,
                                           torch::Tensor opac, torch::Tensor sh, torch::Tensor viewmats, torch::Tensor Ks,
                                           int64_t width, int64_t height, double near_plane, double far_plane,
                                           int64_t sh_degree) {
  // sh [N,K,3] or empty -> adj [C*N,9], det [C*N], means2d [C,N,2], depths [C,N], normals [C,N,3],
  // radii [C,N] int32, bbox [C,N,4], colors [C,N,3] (empty without SH)
  for (auto* x : {&means, &quats, &scales, &opac, &sh, &viewmats, &Ks})
    TORCH_CHECK(x->device().is_cpu() && x->is_contiguous(), "surfel projection inputs must be contiguous CPU tensors");
  const int64_t C = viewmats.size(0), N = means.size(0), K = sh.numel() > 0 ? sh.size(1) : 0;
  TORCH_CHECK(sh_degree >= 0 && sh_degree <= 3 && (K == 0 || K >= (sh_degree + 1) * (sh_degree + 1)), "bad SH degree");
  auto o = means.options();
  auto adj = torch::empty({C * N, 9}, o), det = torch::empty({C * N}, o), m2 = torch::empty({C, N, 2}, o);
  auto depths = torch::empty({C, N}, o), normals = torch::empty({C, N, 3}, o);
  auto radii = torch::empty({C, N}, o.dtype(torch::kInt32)), bbox = torch::empty({C, N, 4}, o);
  auto colors = torch::empty({C, N, K > 0 ? 3 : 0}, o);
  const surf2d::SurfArgs a{C, N, width, height, K, static_cast<int>(sh_degree), near_plane, far_plane};
  const int nt = std::max(1, at::get_num_threads());
  AT_DISPATCH_FLOATING_TYPES(means.scalar_type(), "surfels_project", [&] {
    surf2d::project_forward<scalar_t>(means.data_ptr<scalar_t>(), quats.data_ptr<scalar_t>(), scales.data_ptr<scalar_t>(),
                                      opac.data_ptr<scalar_t>(), K > 0 ? sh.data_ptr<scalar_t>() : nullptr,
                                      viewmats.data_ptr<scalar_t>(), Ks.data_ptr<scalar_t>(), a, nt, adj.data_ptr<scalar_t>(),
                                      det.data_ptr<scalar_t>(), m2.data_ptr<scalar_t>(), depths.data_ptr<scalar_t>(),
                                      normals.data_ptr<scalar_t>(), radii.data_ptr<int32_t>(), bbox.data_ptr<scalar_t>(),
                                      K > 0 ? colors.data_ptr<scalar_t>() : nullptr);
  });
  return {adj, det, m2, depths, normals, radii, bbox, colors};
}

std::vector<torch::Tensor> surfels_project_backward(torch::Tensor means, torch::Tensor quats, torch::Tensor scales,
                                                    torch::Tensor sh, torch::Tensor viewmats, torch::Tensor Ks,
                                                    int64_t width, int64_t height, double near_plane, double far_plane,
                                                    int64_t sh_degree, torch::Tensor v_adj, torch::Tensor v_det,
                                                    torch::Tensor v_m2, torch::Tensor v_depths, torch::Tensor v_normals,
                                                    torch::Tensor v_colors) {
  // v_colors may be empty; returns v_means, v_quats, v_scales, v_sh
  for (auto* x : {&means, &quats, &scales, &sh, &viewmats, &Ks, &v_adj, &v_det, &v_m2, &v_depths, &v_normals, &v_colors})
    TORCH_CHECK(x->device().is_cpu() && x->is_contiguous(), "surfel projection gradients must be contiguous CPU tensors");
  const int64_t C = viewmats.size(0), N = means.size(0), K = sh.numel() > 0 ? sh.size(1) : 0;
  TORCH_CHECK(v_adj.numel() == C * N * 9 && v_det.numel() == C * N && v_m2.numel() == C * N * 2 &&
                  v_depths.numel() == C * N && v_normals.numel() == C * N * 3,
              "surfel projection gradients have the wrong size");
  auto v_means = torch::empty_like(means), v_quats = torch::empty_like(quats), v_scales = torch::empty_like(scales);
  auto v_sh = torch::empty_like(sh);
  const surf2d::SurfArgs a{C, N, width, height, K, static_cast<int>(sh_degree), near_plane, far_plane};
  const int nt = std::max(1, at::get_num_threads());
  AT_DISPATCH_FLOATING_TYPES(means.scalar_type(), "surfels_project_backward", [&] {
    surf2d::project_backward<scalar_t>(
        means.data_ptr<scalar_t>(), quats.data_ptr<scalar_t>(), scales.data_ptr<scalar_t>(),
        K > 0 ? sh.data_ptr<scalar_t>() : nullptr, viewmats.data_ptr<scalar_t>(), Ks.data_ptr<scalar_t>(), a, nt,
        v_adj.data_ptr<scalar_t>(), v_det.data_ptr<scalar_t>(), v_m2.data_ptr<scalar_t>(), v_depths.data_ptr<scalar_t>(),
        v_normals.data_ptr<scalar_t>(), (K > 0 && v_colors.numel() > 0) ? v_colors.data_ptr<scalar_t>() : nullptr,
        v_means.data_ptr<scalar_t>(), v_quats.data_ptr<scalar_t>(), v_scales.data_ptr<scalar_t>(),
        K > 0 ? v_sh.data_ptr<scalar_t>() : nullptr);
  });
  return {v_means, v_quats, v_scales, v_sh};
}

std::vector<torch::Tensor> surfels_tile_lists(torch::Tensor bbox, torch::Tensor depths, torch::Tensor radii, int64_t width,
                                              int64_t height, int64_t ts) {
  // bbox [C,N,4], depths [C,N], radii [C,N] int32 -> flat_ids, starts, counts (int64), as build_tile_lists
  for (auto* x : {&bbox, &depths, &radii})
    TORCH_CHECK(x->device().is_cpu() && x->is_contiguous(), "tile list inputs must be contiguous CPU tensors");
  TORCH_CHECK(radii.scalar_type() == torch::kInt32, "radii must be int32");
  const int64_t C = depths.size(0), N = depths.size(1);
  const int tw = static_cast<int>((width + ts - 1) / ts), th = static_cast<int>((height + ts - 1) / ts);
  std::vector<int64_t> ids, starts, counts;
  AT_DISPATCH_FLOATING_TYPES(depths.scalar_type(), "surfels_tile_lists", [&] {
    surf2d::tile_lists<scalar_t>(bbox.data_ptr<scalar_t>(), depths.data_ptr<scalar_t>(), radii.data_ptr<int32_t>(), C, N,
                                 static_cast<int>(ts), tw, th, ids, starts, counts);
  });
  auto to_t = [](const std::vector<int64_t>& v) {
    auto t = torch::empty({static_cast<int64_t>(v.size())}, torch::kInt64);
    std::copy(v.begin(), v.end(), t.data_ptr<int64_t>());
    return t;
  };
  return {to_t(ids), to_t(starts), to_t(counts)};
}

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
  m.def("project", &surfels_project, "2DGS surfel projection + SH colours (CPU)");
  m.def("project_backward", &surfels_project_backward, "backward of project (CPU)");
  m.def("tile_lists", &surfels_tile_lists, "per-tile depth-sorted surfel lists (CPU)");
  m.def("forward", &surfels_forward, "2DGS surfel compositing forward (CPU)");
  m.def("backward", &surfels_backward, "2DGS surfel compositing backward (CPU)");
}
