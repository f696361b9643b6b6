// SH colours (degree <= 3, 3DGS convention) with their backward, for the cpu backend's training
// renders: colour = max(sum_k Y_k(d) c_k + 0.5, 0) with d = normalise(mean - camera centre).
// Replaces ~100 small autograd ops; sh.py's eval_sh stays the reference it is tested against.
// The per-direction colour and its VJP (sh_color, sh_color_vjp) are also what the fused 3DGS and
// 2DGS projections (projection_core.h, projection_bwd.h, surfels_proj_core.h) call per pair.
#pragma once
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>

// For the per-pair helpers called in the projections' hot loops: GCC's heuristics would leave
// sh_color_vjp out of line, which costs ~15% of the projection backward.
#if defined(__GNUC__)
#define GS3D_FORCE_INLINE inline __attribute__((always_inline))
#else
#define GS3D_FORCE_INLINE inline
#endif

namespace gs3d {

template <typename T>
inline void sh_basis(int degree, T x, T y, T z, T* b) {
  b[0] = T(0.28209479177387814);
  if (degree < 1) return;
  b[1] = T(-0.48860251190291987) * y;
  b[2] = T(0.48860251190291987) * z;
  b[3] = T(-0.48860251190291987) * x;
  if (degree < 2) return;
  const T xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
  b[4] = T(1.0925484305920792) * xy;
  b[5] = T(-1.0925484305920792) * yz;
  b[6] = T(0.94617469575755997) * zz - T(0.31539156525251999);
  b[7] = T(-1.0925484305920792) * xz;
  b[8] = T(0.54627421529603959) * (xx - yy);
  if (degree < 3) return;
  b[9] = T(0.59004358992664352) * y * (T(-3) * xx + yy);
  b[10] = T(2.8906114426405538) * xy * z;
  b[11] = T(0.45704579946446572) * y * (T(1) - T(5) * zz);
  b[12] = T(0.3731763325901154) * z * (T(5) * zz - T(3));
  b[13] = T(0.45704579946446572) * x * (T(1) - T(5) * zz);
  b[14] = T(1.4453057213202769) * z * (xx - yy);
  b[15] = T(0.59004358992664352) * x * (-xx + T(3) * yy);
}

// d(basis)/d(x, y, z) contracted with G_k = dL/dY_k (unit direction x, y, z).
template <typename T>
inline void sh_basis_vjp(int degree, T x, T y, T z, const T* G, T& gx, T& gy, T& gz) {
  gx = gy = gz = 0;
  if (degree < 1) return;
  const T C1 = T(0.48860251190291987);
  gx += -C1 * G[3];
  gy += -C1 * G[1];
  gz += C1 * G[2];
  if (degree < 2) return;
  const T a4 = T(1.0925484305920792), a5 = T(-1.0925484305920792), a6 = T(0.94617469575755997);
  const T a7 = T(-1.0925484305920792), a8 = T(0.54627421529603959);
  gx += a4 * y * G[4] + a7 * z * G[7] + T(2) * a8 * x * G[8];
  gy += a4 * x * G[4] + a5 * z * G[5] - T(2) * a8 * y * G[8];
  gz += a5 * y * G[5] + T(2) * a6 * z * G[6] + a7 * x * G[7];
  if (degree < 3) return;
  const T a9 = T(0.59004358992664352), a10 = T(2.8906114426405538), a11 = T(0.45704579946446572);
  const T a12 = T(0.3731763325901154), a13 = T(0.45704579946446572), a14 = T(1.4453057213202769);
  const T a15 = T(0.59004358992664352);
  const T xx = x * x, yy = y * y, zz = z * z;
  gx += a9 * y * (T(-6) * x) * G[9] + a10 * y * z * G[10] + a13 * (T(1) - T(5) * zz) * G[13] +
        a14 * z * T(2) * x * G[14] + a15 * (T(-3) * xx + T(3) * yy) * G[15];
  gy += a9 * (T(-3) * xx + T(3) * yy) * G[9] + a10 * x * z * G[10] + a11 * (T(1) - T(5) * zz) * G[11] -
        T(2) * a14 * z * y * G[14] + a15 * x * T(6) * y * G[15];
  gz += a10 * x * y * G[10] + a11 * y * (T(-10) * z) * G[11] + a12 * (T(15) * zz - T(3)) * G[12] +
        a13 * x * (T(-10) * z) * G[13] + a14 * (xx - yy) * G[14];
}

// SH view direction of a mean m for the world-to-camera matrix V [4,4]: m - camera centre, with
// the centre -R^T t (unnormalised).
template <typename T>
inline void view_dir(const T* V, const T* m, T* d) {
  d[0] = m[0] + (V[0] * V[3] + V[4] * V[7] + V[8] * V[11]);
  d[1] = m[1] + (V[1] * V[3] + V[5] * V[7] + V[9] * V[11]);
  d[2] = m[2] + (V[2] * V[3] + V[6] * V[7] + V[10] * V[11]);
}

// Colour of coefficients cf [K,3] along the unnormalised direction d:
// max(sum_k Y_k(d / max(|d|, 1e-12)) cf_k + 0.5, 0).
template <typename T>
GS3D_FORCE_INLINE void sh_color(int degree, const T* d, const T* cf, T* color) {
  const int nb = (degree + 1) * (degree + 1);
  const T nrm = std::max(std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]), T(1e-12));
  T b[16];
  sh_basis<T>(degree, d[0] / nrm, d[1] / nrm, d[2] / nrm, b);
  for (int ch = 0; ch < 3; ++ch) {
    T acc = 0;
    for (int k = 0; k < nb; ++k) acc += b[k] * cf[3 * k + ch];
    color[ch] = std::max(acc + T(0.5), T(0));
  }
}

// VJP of sh_color for v_color = dL/dcolor: adds dL/dcf to v_cf [K,3] and dL/dd to v_d [3] (both
// accumulate: the projections sum over cameras, and dL/dd adds to the mean's gradient).
template <typename T>
GS3D_FORCE_INLINE void sh_color_vjp(int degree, const T* d, const T* cf, const T* v_color, T* v_cf, T* v_d) {
  const int nb = (degree + 1) * (degree + 1);
  const T nrm = std::max(std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]), T(1e-12));
  const T x = d[0] / nrm, y = d[1] / nrm, z = d[2] / nrm;
  T b[16];
  sh_basis<T>(degree, x, y, z, b);
  T gcol[3];
  for (int ch = 0; ch < 3; ++ch) {
    T acc = 0;
    for (int k = 0; k < nb; ++k) acc += b[k] * cf[3 * k + ch];
    gcol[ch] = acc + T(0.5) >= T(0) ? v_color[ch] : T(0);  // clamp_min(0) passes at >= 0
  }
  T G[16];
  for (int k = 0; k < nb; ++k) {
    G[k] = 0;
    for (int ch = 0; ch < 3; ++ch) {
      v_cf[3 * k + ch] += b[k] * gcol[ch];
      G[k] += cf[3 * k + ch] * gcol[ch];
    }
  }
  T gx, gy, gz;
  sh_basis_vjp<T>(degree, x, y, z, G, gx, gy, gz);
  // through the normalisation: (v - n (n . v)) / |d|  (zero below the 1e-12 clamp, as torch)
  const T dot = gx * x + gy * y + gz * z;
  const T inv = nrm > T(1e-12) ? T(1) / nrm : T(0);
  v_d[0] += (gx - x * dot) * inv;
  v_d[1] += (gy - y * dot) * inv;
  v_d[2] += (gz - z * dot) * inv;
}

// Gaussian g's rows of v_sh [N,K,3], zeroed for the projections' backwards to accumulate into over
// cameras; null without SH (K = 0).
template <typename T>
inline T* sh_grad_rows(T* v_sh, int64_t g, int64_t K) {
  if (K <= 0) return nullptr;
  T* rows = v_sh + g * K * 3;
  std::fill(rows, rows + K * 3, T(0));
  return rows;
}

// dirs [C,N,3] (unnormalised), coeffs [N,K,3] -> colors [C,N,3]
template <typename T>
void sh_forward(int degree, const T* dirs, const T* coeffs, int64_t C, int64_t N, int64_t K, int n_threads, T* colors) {
#pragma omp parallel for num_threads(n_threads) schedule(static)
  for (int64_t i = 0; i < C * N; ++i) sh_color<T>(degree, dirs + 3 * i, coeffs + (i % N) * K * 3, colors + 3 * i);
}

// v_colors [C,N,3] -> v_coeffs [N,K,3] (zero-initialised), v_dirs [C,N,3]
template <typename T>
void sh_backward(int degree, const T* dirs, const T* coeffs, const T* v_colors, int64_t C, int64_t N, int64_t K,
                 int n_threads, T* v_coeffs, T* v_dirs) {
#pragma omp parallel for num_threads(n_threads) schedule(static)
  for (int64_t g = 0; g < N; ++g)  // per Gaussian, so the coefficient sums over cameras need no atomics
    for (int64_t c = 0; c < C; ++c) {
      const int64_t i = c * N + g;
      v_dirs[3 * i] = v_dirs[3 * i + 1] = v_dirs[3 * i + 2] = 0;
      sh_color_vjp<T>(degree, dirs + 3 * i, coeffs + g * K * 3, v_colors + 3 * i, v_coeffs + g * K * 3, v_dirs + 3 * i);
    }
}

}  // namespace gs3d
