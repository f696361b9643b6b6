// Tile compositing of projected 3D Gaussians, forward and backward, on raw pointers (no torch
// types here, so the kernel can be compiled and inspected on its own). See rasterize_gaussians.cpp.
//
// Semantics (as gsplat / 3DGS): alpha = min(0.99, o * exp(-sigma)); pairs with alpha < 1/255 or
// sigma < 0 are skipped; compositing stops before the Gaussian that would bring the transmittance
// to <= 1e-4. The backward walks each tile back to front and rebuilds the transmittance by
// division (alpha <= 0.99 keeps that stable).
//
// Pixels of a tile are the innermost loop so that it vectorises (AVX-512 with -march=native); a
// Gaussian only visits the tile rows its alpha >= 1/255 ellipse can reach. OpenMP parallelises over
// tiles; gradients go to per-thread buffers (no atomics). Rows whose pixels are all terminated
// (forward) or past their last composited Gaussian (backward) are skipped.
#pragma once
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

namespace gs3d {

constexpr float kAlphaMin = 1.0f / 255.0f;
constexpr float kAlphaMax = 0.99f;
constexpr float kTMin = 1e-4f;
constexpr int kMaxTile = 64;  // largest tile edge the kernels accept

// exp(x) for x <= 0: 2^n * 2^f with |f| <= 0.5 and a degree-6 Taylor polynomial (relative error
// ~1e-7), branch-free so that GCC vectorises it (libm's expf would not be, without -ffast-math).
template <typename T>
inline T exp_neg(T x) { return std::exp(x); }

template <>
inline float exp_neg<float>(float x) {
  x = x < -87.0f ? -87.0f : x;
  const float t = x * 1.4426950408889634f;
  const float n = std::nearbyint(t);
  const float f = (t - n) * 0.6931471805599453f;
  const float p = 1.0f + f * (1.0f + f * (0.5f + f * (0.16666667f + f * (0.041666668f + f * (0.008333334f + f * 0.0013888889f)))));
  const int32_t bits = (static_cast<int32_t>(n) + 127) << 23;
  float s;
  std::memcpy(&s, &bits, sizeof(float));
  return p * s;
}

struct Dims {
  int64_t n_cams, height, width, D;
  int ts;
  int tiles_x() const { return static_cast<int>((width + ts - 1) / ts); }
  int tiles_y() const { return static_cast<int>((height + ts - 1) / ts); }
  int64_t n_tiles() const { return n_cams * tiles_x() * tiles_y(); }
};

struct Tile {
  int cam, x0, y0;
};

inline Tile tile_of(int64_t t, const Dims& d) {
  const int per_cam = d.tiles_x() * d.tiles_y();
  const int local = static_cast<int>(t % per_cam);
  return {static_cast<int>(t / per_cam), (local % d.tiles_x()) * d.ts, (local / d.tiles_x()) * d.ts};
}

// Vertical half-extent (1 px margin) of a Gaussian's alpha >= 1/255 ellipse: once per pair, not per tile.
template <typename T>
inline T row_reach(T ca, T cb, T cc, T op) {
  const T det = ca * cc - cb * cb;
  const T s = std::log(std::max(op * T(255), T(1)));
  const T cov_yy = det > 0 ? ca / det : T(0);
  return std::sqrt(std::max(T(2) * s * cov_yy, T(0))) + T(1);
}

// row_reach of every pair, filled by the threads of the enclosing parallel region (ends on a barrier).
template <typename T>
inline void row_reaches(const T* cn, const T* opa, int64_t CN, T* ey) {
#pragma omp for schedule(static)
  for (int64_t i = 0; i < CN; ++i) ey[i] = row_reach<T>(cn[3 * i], cn[3 * i + 1], cn[3 * i + 2], opa[i]);
}

// Rows [r0, r1) of the tile that a Gaussian's alpha >= 1/255 ellipse can reach (ey: its row_reach).
template <typename T>
inline void row_range(T my, T ey, int y0, int ts, int& r0, int& r1) {
  r0 = static_cast<int>(std::max(T(0), std::floor(my - ey - T(0.5) - y0)));
  r1 = static_cast<int>(std::min(T(ts), std::floor(my + ey - T(0.5) - y0) + T(1)));
}

// out [C,H,W,D], out_a [C,H,W], out_last / out_med [C,H,W] (list index of the last composited
// pair / pair id of the median Gaussian, -1 for none).
// TS: the tile edge at compile time (one SIMD row of 16 floats), or 0 for d.ts at run time.
// LAST / MED: whether the last-composited index (backward) and median ids are wanted.
// DC: the channel count at compile time (3 or 4: the channels composited in the pass that makes the weights),
// or 0 for d.D at run time (a second pass per channel).
template <typename T, int TS, bool LAST, bool MED, int DC>
void forward_tiles_impl(const T* m2, const T* cn, const T* col, const T* opa, const int64_t* off, const int64_t* ids,
                        const Dims d, int64_t CN, int n_threads, T* out, T* out_a, int64_t* out_last, int64_t* out_med) {
  const int ts = TS > 0 ? TS : d.ts, P = ts * ts;
  constexpr int L = TS > 0 ? TS : kMaxTile;
  const int64_t D = DC > 0 ? DC : d.D;
  std::vector<T> reach(CN);
#pragma omp parallel num_threads(n_threads)
  {
    row_reaches<T>(cn, opa, CN, reach.data());
    std::vector<T> px(P), py(P), Tr(P), act(P), acc(P * D), w(P);
    T* const accp = acc.data();
    std::vector<int32_t> lst(P), med(P), rowlive(ts);
#pragma omp for schedule(dynamic, 1)
    for (int64_t t = 0; t < d.n_tiles(); ++t) {
      const Tile g = tile_of(t, d);
      for (int p = 0; p < P; ++p) {
        const int x = g.x0 + p % ts, y = g.y0 + p / ts;
        px[p] = T(x) + T(0.5);
        py[p] = T(y) + T(0.5);
        Tr[p] = T(1);
        act[p] = (x < d.width && y < d.height) ? T(1) : T(0);
        lst[p] = -1;
        med[p] = -1;
      }
      std::fill(acc.begin(), acc.end(), T(0));
      int32_t tile_live = 0;
      for (int r = 0; r < ts; ++r) {
        int32_t c = 0;
        for (int q = 0; q < ts; ++q) c += act[r * ts + q] > 0 ? 1 : 0;
        rowlive[r] = c;
        tile_live += c;
      }
      const int64_t k0 = off[t];
      const int32_t n_list = static_cast<int32_t>(off[t + 1] - k0);
      for (int32_t kk = 0; kk < n_list && tile_live > 0; ++kk) {
        if ((kk & 7) == 7) {  // refresh which rows still have live pixels
          tile_live = 0;
          for (int r = 0; r < ts; ++r) {
            if (rowlive[r] == 0) continue;
            T m = 0;
#pragma omp simd reduction(max : m)
            for (int q = 0; q < ts; ++q) m = std::max(m, act[r * ts + q]);
            rowlive[r] = m > 0 ? 1 : 0;
            tile_live += rowlive[r];
          }
          if (tile_live == 0) break;
        }
        const int64_t id = ids[k0 + kk];
        const T mx = m2[2 * id], my = m2[2 * id + 1];
        const T ca = cn[3 * id], cb = cn[3 * id + 1], cc = cn[3 * id + 2];
        const T op = opa[id];
        int r0, r1;
        row_range<T>(my, reach[id], g.y0, ts, r0, r1);
        if (r0 >= r1) continue;
        const int p0 = r0 * ts, p1 = r1 * ts;
        const int32_t id32 = static_cast<int32_t>(id);
        int32_t lane_any[L] = {};
        T cl[DC > 0 ? DC : 1];
        if constexpr (DC > 0)
          for (int ch = 0; ch < DC; ++ch) cl[ch] = col[id * DC + ch];
        for (int row = p0; row < p1; row += ts) {
        if (rowlive[row / ts] == 0) {
          if constexpr (DC == 0)
            for (int p = row; p < row + ts; ++p) w[p] = T(0);
          continue;
        }
#pragma omp simd
        for (int q = 0; q < ts; ++q) {
          const int p = row + q;
          const T dx = mx - px[p], dy = my - py[p];
          const T sigma = T(0.5) * (ca * dx * dx + cc * dy * dy) + cb * dx * dy;
          T a = op * exp_neg<T>(-sigma);
          a = a > T(kAlphaMax) ? T(kAlphaMax) : a;
          const T tr = Tr[p];
          const bool valid = act[p] > 0 && sigma >= 0 && a >= T(kAlphaMin);
          const T nt = tr * (T(1) - a);
          const bool term = valid && nt <= T(kTMin);
          const bool contrib = valid && !term;
          const T wp = contrib ? a * tr : T(0);
          if constexpr (DC > 0) {
            for (int ch = 0; ch < DC; ++ch) accp[ch * P + p] += wp * cl[ch];
          } else {
            w[p] = wp;
          }
          lane_any[q] |= contrib ? 1 : 0;
          if constexpr (MED) med[p] = (contrib && tr > T(0.5)) ? id32 : med[p];
          Tr[p] = contrib ? nt : tr;
          act[p] = term ? T(0) : act[p];
          if constexpr (LAST) lst[p] = contrib ? kk : lst[p];
        }
        }
        if constexpr (DC > 0) continue;
        int32_t any_w = 0;
        for (int q = 0; q < ts; ++q) any_w |= lane_any[q];
        if (!any_w) continue;
        for (int64_t ch = 0; ch < D; ++ch) {
          const T c = col[id * D + ch];
          T* ac = acc.data() + ch * P;
          for (int row = p0; row < p1; row += ts) {
#pragma omp simd
            for (int p = row; p < row + ts; ++p) ac[p] += w[p] * c;
          }
        }
      }
      for (int p = 0; p < P; ++p) {
        const int x = g.x0 + p % ts, y = g.y0 + p / ts;
        if (x >= d.width || y >= d.height) continue;
        const int64_t pix = (static_cast<int64_t>(g.cam) * d.height + y) * d.width + x;
        for (int64_t ch = 0; ch < D; ++ch) out[pix * D + ch] = acc[ch * P + p];
        out_a[pix] = T(1) - Tr[p];
        out_last[pix] = lst[p] >= 0 ? k0 + lst[p] : -1;
        out_med[pix] = med[p];
      }
    }
  }
}

template <typename T, int TS, int DC>
void forward_tiles_ts(const T* m2, const T* cn, const T* col, const T* opa, const int64_t* off, const int64_t* ids,
                      const Dims d, int64_t CN, int n_threads, T* out, T* out_a, int64_t* out_last, int64_t* out_med, bool last,
                      bool med) {
  if (last && med)
    forward_tiles_impl<T, TS, true, true, DC>(m2, cn, col, opa, off, ids, d, CN, n_threads, out, out_a, out_last, out_med);
  else if (last)
    forward_tiles_impl<T, TS, true, false, DC>(m2, cn, col, opa, off, ids, d, CN, n_threads, out, out_a, out_last, out_med);
  else if (med)
    forward_tiles_impl<T, TS, false, true, DC>(m2, cn, col, opa, off, ids, d, CN, n_threads, out, out_a, out_last, out_med);
  else
    forward_tiles_impl<T, TS, false, false, DC>(m2, cn, col, opa, off, ids, d, CN, n_threads, out, out_a, out_last, out_med);
}

// out_last / out_med stay -1 where not asked for (need_last is only required for backward).
template <typename T>
void forward_tiles(const T* m2, const T* cn, const T* col, const T* opa, const int64_t* off, const int64_t* ids,
                   const Dims d, int64_t CN, int n_threads, T* out, T* out_a, int64_t* out_last, int64_t* out_med,
                   bool need_last = true, bool need_med = true) {
  if (d.ts == 16 && d.D == 3)
    forward_tiles_ts<T, 16, 3>(m2, cn, col, opa, off, ids, d, CN, n_threads, out, out_a, out_last, out_med, need_last, need_med);
  else if (d.ts == 16 && d.D == 4)
    forward_tiles_ts<T, 16, 4>(m2, cn, col, opa, off, ids, d, CN, n_threads, out, out_a, out_last, out_med, need_last, need_med);
  else if (d.ts == 16)
    forward_tiles_ts<T, 16, 0>(m2, cn, col, opa, off, ids, d, CN, n_threads, out, out_a, out_last, out_med, need_last, need_med);
  else
    forward_tiles_ts<T, 0, 0>(m2, cn, col, opa, off, ids, d, CN, n_threads, out, out_a, out_last, out_med, need_last, need_med);
}

// a pair's six 2D gradients (mean x, y; conic a, b, c; opacity), per lane of a tile row: each pixel adds its
// share in its lane, and the lanes are summed once per pair (not once per row)
template <typename T, int L>
struct PairLanes {
  T mx[L] = {}, my[L] = {}, a[L] = {}, b[L] = {}, c[L] = {}, o[L] = {};

  // pixel in lane q at (dx, dy) from the mean, its transmittance vis, v_al the loss gradient of its alpha
  inline void add(int q, T vis, T v_al, T op, T dx, T dy, T ca, T cb, T cc) {
    const T v_sig = -op * vis * v_al;
    o[q] += vis * v_al;
    a[q] += T(0.5) * v_sig * dx * dx;
    b[q] += v_sig * dx * dy;
    c[q] += T(0.5) * v_sig * dy * dy;
    mx[q] += v_sig * (ca * dx + cb * dy);
    my[q] += v_sig * (cb * dx + cc * dy);
  }

  // the lanes' sums added to out[0..5]
  inline void sum_into(T* out, int ts) const {
    T g_mx = 0, g_my = 0, g_a = 0, g_b = 0, g_c = 0, g_o = 0;
    for (int q = 0; q < ts; ++q) {
      g_mx += mx[q];
      g_my += my[q];
      g_a += a[q];
      g_b += b[q];
      g_c += c[q];
      g_o += o[q];
    }
    out[0] += g_mx;
    out[1] += g_my;
    out[2] += g_a;
    out[3] += g_b;
    out[4] += g_c;
    out[5] += g_o;
  }
};

// One Gaussian of a tile's backward in one pass over its rows (see backward_tiles_impl): the same arithmetic,
// per pixel and per lane in the same order as the three-pass form. Adds its gradients to o; false when no pixel
// composited it.
template <typename T, int L, int DC>
inline bool fused_pair(T mx, T my, T ca, T cb, T cc, T op, const T* c, int32_t kk, int p0, int p1, int ts, int P,
                       const int32_t* rowmax, const int32_t* lst, const T* px, const T* py, T* Tr, const T* Tfin,
                       const T* vap, const T* vout, T* buf, T* o) {
  T cl[DC];
  for (int ch = 0; ch < DC; ++ch) cl[ch] = c[ch];
  T lane_c[DC][L] = {};
  PairLanes<T, L> lanes;
  int32_t any = 0;
  for (int row = p0; row < p1; row += ts) {
    if (kk > rowmax[row / ts]) continue;
#pragma omp simd reduction(| : any)
    for (int q = 0; q < ts; ++q) {
      const int p = row + q;
      const T dx = mx - px[p], dy = my - py[p];
      const T sigma = T(0.5) * (ca * dx * dx + cc * dy * dy) + cb * dx * dy;
      const T vis = exp_neg<T>(-sigma);
      T a = op * vis;
      a = a > T(kAlphaMax) ? T(kAlphaMax) : a;
      const bool valid = kk <= lst[p] && sigma >= 0 && a >= T(kAlphaMin);
      const T ra = T(1) / (T(1) - a);
      const T tb = Tr[p] * ra;
      const T rap = valid ? ra : T(0);
      const T Tb = valid ? tb : T(0);
      const T fac = valid ? a * tb : T(0);
      T vacc = valid ? Tfin[p] * ra * vap[p] : T(0);
      Tr[p] = valid ? tb : Tr[p];
      any |= valid ? 1 : 0;
      for (int ch = 0; ch < DC; ++ch) {
        const T vo = vout[ch * P + p], bf = buf[ch * P + p];
        lane_c[ch][q] += fac * vo;
        vacc += (cl[ch] * Tb - bf * rap) * vo;
        buf[ch * P + p] = bf + cl[ch] * fac;
      }
      const T v_al = op * vis < T(kAlphaMax) ? vacc : T(0);  // 0 where not composited
      lanes.add(q, vis, v_al, op, dx, dy, ca, cb, cc);
    }
  }
  if (!any) return false;
  lanes.sum_into(o, ts);
  for (int ch = 0; ch < DC; ++ch) {
    T vc = 0;
    for (int q = 0; q < ts; ++q) vc += lane_c[ch][q];
    o[6 + ch] += vc;
  }
  return true;
}

// grads: [n_threads][CN][6 + D] zero-initialised; per pair (means2d x, y, conic a, b, c, opacity,
// features...). The caller sums over threads.
// DC: the channel count at compile time (3 or 4: one pass over a Gaussian's rows, its per-pixel values kept in
// registers across the channels), or 0 for d.D at run time (three passes: alpha, channels, geometry).
template <typename T, int TS, int DC>
void backward_tiles_impl(const T* m2, const T* cn, const T* col, const T* opa, const int64_t* off, const int64_t* ids,
                         const T* al, const int64_t* lastp, const T* vr, const T* va, const Dims d, int64_t CN,
                         int n_threads, T* grads) {
  const int ts = TS > 0 ? TS : d.ts, P = ts * ts;
  constexpr int L = TS > 0 ? TS : kMaxTile;
  const int64_t D = DC > 0 ? DC : d.D, G = 6 + D;
  std::vector<T> reach(CN);
#pragma omp parallel num_threads(n_threads)
  {
    row_reaches<T>(cn, opa, CN, reach.data());
    T* my_gr = grads + static_cast<int64_t>(omp_get_thread_num()) * CN * G;
    std::vector<T> px(P), py(P), Tr(P), Tfin(P), vout(P * D), buf(P * D), vap(P), fac(P), rap(P), Tb(P), vacc(P), visp(P);
    std::vector<int32_t> lst(P), rowmax(ts);
    std::vector<T> vcol(D);
// static round-robin: tile -> thread is fixed, so the per-thread sums (and the gradients) are
    // bit-for-bit reproducible
#pragma omp for schedule(static, 1)
    for (int64_t t = 0; t < d.n_tiles(); ++t) {
      const Tile g = tile_of(t, d);
      const int64_t k0 = off[t];
      int32_t kmax = -1;
      for (int p = 0; p < P; ++p) {
        const int x = g.x0 + p % ts, y = g.y0 + p / ts;
        px[p] = T(x) + T(0.5);
        py[p] = T(y) + T(0.5);
        const bool in = x < d.width && y < d.height;
        const int64_t pix = in ? (static_cast<int64_t>(g.cam) * d.height + y) * d.width + x : 0;
        lst[p] = (in && lastp[pix] >= 0) ? static_cast<int32_t>(lastp[pix] - k0) : -1;
        Tfin[p] = in ? T(1) - al[pix] : T(0);
        Tr[p] = Tfin[p];
        vap[p] = in ? va[pix] : T(0);
        for (int64_t ch = 0; ch < D; ++ch) {
          vout[ch * P + p] = in ? vr[pix * D + ch] : T(0);
          buf[ch * P + p] = 0;
        }
        kmax = std::max(kmax, lst[p]);
      }
      for (int r = 0; r < ts; ++r) {  // last composited list index per row: rows past it are skipped
        int32_t m = -1;
        for (int q = 0; q < ts; ++q) m = std::max(m, lst[r * ts + q]);
        rowmax[r] = m;
      }
      for (int32_t kk = kmax; kk >= 0; --kk) {
        const int64_t id = ids[k0 + kk];
        const T mx = m2[2 * id], my = m2[2 * id + 1];
        const T ca = cn[3 * id], cb = cn[3 * id + 1], cc = cn[3 * id + 2];
        const T op = opa[id];
        int r0, r1;
        row_range<T>(my, reach[id], g.y0, ts, r0, r1);
        if (r0 >= r1) continue;
        const int p0 = r0 * ts, p1 = r1 * ts;
        if constexpr (DC > 0) {
          fused_pair<T, L, DC>(mx, my, ca, cb, cc, op, col + id * DC, kk, p0, p1, ts, P, rowmax.data(), lst.data(), px.data(),
                               py.data(), Tr.data(), Tfin.data(), vap.data(), vout.data(), buf.data(), my_gr + id * G);
          continue;
        }
        int32_t any = 0;
        for (int row = p0; row < p1; row += ts) {
        if (kk > rowmax[row / ts]) {
          continue;
        }
#pragma omp simd reduction(| : any)
        for (int p = row; p < row + ts; ++p) {
          const T dx = mx - px[p], dy = my - py[p];
          const T sigma = T(0.5) * (ca * dx * dx + cc * dy * dy) + cb * dx * dy;
          const T vis = exp_neg<T>(-sigma);
          T a = op * vis;
          a = a > T(kAlphaMax) ? T(kAlphaMax) : a;
          const bool valid = kk <= lst[p] && sigma >= 0 && a >= T(kAlphaMin);
          visp[p] = vis;
          const T ra = T(1) / (T(1) - a);
          const T tb = Tr[p] * ra;
          rap[p] = valid ? ra : T(0);
          Tb[p] = valid ? tb : T(0);
          fac[p] = valid ? a * tb : T(0);
          vacc[p] = valid ? Tfin[p] * ra * vap[p] : T(0);
          Tr[p] = valid ? tb : Tr[p];
          any |= valid ? 1 : 0;
        }
        }
        if (!any) continue;
        for (int64_t ch = 0; ch < D; ++ch) {
          const T c = col[id * D + ch];
          T* vo = vout.data() + ch * P;
          T* bf = buf.data() + ch * P;
          T lane_c[L] = {};
          for (int row = p0; row < p1; row += ts) {
            if (kk > rowmax[row / ts]) continue;
#pragma omp simd
            for (int q = 0; q < ts; ++q) {
              const int p = row + q;
              lane_c[q] += fac[p] * vo[p];
              vacc[p] += (c * Tb[p] - bf[p] * rap[p]) * vo[p];
              bf[p] += c * fac[p];
            }
          }
          T vc = 0;
          for (int q = 0; q < ts; ++q) vc += lane_c[q];
          vcol[ch] = vc;
        }
        // per-lane partial sums, reduced once per Gaussian (not once per row)
        PairLanes<T, L> lanes;
        for (int row = p0; row < p1; row += ts) {
          if (kk > rowmax[row / ts]) continue;
#pragma omp simd
          for (int q = 0; q < ts; ++q) {
            const int p = row + q;
            const T dx = mx - px[p], dy = my - py[p];
            const T vis = visp[p];
            const T v_al = op * vis < T(kAlphaMax) ? vacc[p] : T(0);  // 0 where not composited
            lanes.add(q, vis, v_al, op, dx, dy, ca, cb, cc);
          }
        }
        T* o = my_gr + id * G;
        lanes.sum_into(o, ts);
        for (int64_t ch = 0; ch < D; ++ch) o[6 + ch] += vcol[ch];
      }
    }
  }
}

template <typename T>
void backward_tiles(const T* m2, const T* cn, const T* col, const T* opa, const int64_t* off, const int64_t* ids,
                    const T* al, const int64_t* lastp, const T* vr, const T* va, const Dims d, int64_t CN,
                    int n_threads, T* grads) {
  if (d.ts == 16 && d.D == 3)
    backward_tiles_impl<T, 16, 3>(m2, cn, col, opa, off, ids, al, lastp, vr, va, d, CN, n_threads, grads);
  else if (d.ts == 16 && d.D == 4)
    backward_tiles_impl<T, 16, 4>(m2, cn, col, opa, off, ids, al, lastp, vr, va, d, CN, n_threads, grads);
  else if (d.ts == 16)
    backward_tiles_impl<T, 16, 0>(m2, cn, col, opa, off, ids, al, lastp, vr, va, d, CN, n_threads, grads);
  else
    backward_tiles_impl<T, 0, 0>(m2, cn, col, opa, off, ids, al, lastp, vr, va, d, CN, n_threads, grads);
}

}  // namespace gs3d
