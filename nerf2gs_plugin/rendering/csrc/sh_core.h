// SH colours (degree <= 3, 3DGS convention) with their backward, for the cpu backend's training
// renders: colour = max(sum_k Y_k(d) c_k + 0.5, 0) with d = normalise(mean - camera centre).
// Replaces ~100 small autograd ops; sh.py's eval_sh stays the reference it is tested against.
#pragma once
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "projection_core.h"  // sh_basis

namespace gs3d {

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

// dirs [C,N,3] (unnormalised), coeffs [N,K,3] -> colors [C,N,3]
template <typename T>
void sh_forward(int degree, const T* dirs, const T* coeffs, int64_t C, int64_t N, int64_t K, int n_threads, T* colors) {
  const int nb = (degree + 1) * (degree + 1);
#pragma omp parallel for num_threads(n_threads) schedule(static)
  for (int64_t i = 0; i < C * N; ++i) {
    const int64_t g = i % N;
    const T* d = dirs + 3 * i;
    const T nrm = std::max(std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]), T(1e-12));
    T b[16];
    sh_basis<T>(degree, d[0] / nrm, d[1] / nrm, d[2] / nrm, b);
    const T* cf = coeffs + g * K * 3;
    for (int ch = 0; ch < 3; ++ch) {
      T acc = 0;
      for (int k = 0; k < nb; ++k) acc += b[k] * cf[3 * k + ch];
      colors[3 * i + ch] = std::max(acc + T(0.5), T(0));
    }
  }
}

// v_colors [C,N,3] -> v_coeffs [N,K,3] (zero-initialised), v_dirs [C,N,3]
template <typename T>
void sh_backward(int degree, const T* dirs, const T* coeffs, const T* v_colors, int64_t C, int64_t N, int64_t K,
                 int n_threads, T* v_coeffs, T* v_dirs) {
  const int nb = (degree + 1) * (degree + 1);
#pragma omp parallel for num_threads(n_threads) schedule(static)
  for (int64_t g = 0; g < N; ++g) {  // per Gaussian, so the coefficient sums over cameras need no atomics
    const T* cf = coeffs + g * K * 3;
    T* vc = v_coeffs + g * K * 3;
    for (int64_t c = 0; c < C; ++c) {
      const int64_t i = c * N + g;
      const T* d = dirs + 3 * i;
      const T nrm = std::max(std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]), T(1e-12));
      const T x = d[0] / nrm, y = d[1] / nrm, z = d[2] / nrm;
      T b[16];
      sh_basis<T>(degree, x, y, z, b);
      T gcol[3];
      for (int ch = 0; ch < 3; ++ch) {
        T acc = 0;
        for (int k = 0; k < nb; ++k) acc += b[k] * cf[3 * k + ch];
        gcol[ch] = acc + T(0.5) >= T(0) ? v_colors[3 * i + ch] : T(0);  // clamp_min(0) passes at >= 0
      }
      T G[16];
      for (int k = 0; k < nb; ++k) {
        G[k] = 0;
        for (int ch = 0; ch < 3; ++ch) {
          vc[3 * k + ch] += b[k] * gcol[ch];
          G[k] += cf[3 * k + ch] * gcol[ch];
        }
      }
      T gx, gy, gz;
      sh_basis_vjp<T>(degree, x, y, z, G, gx, gy, gz);
      // through the normalisation: (v - n (n . v)) / |d|  (zero below the 1e-12 clamp, as torch)
      const T dot = gx * x + gy * y + gz * z;
      const T inv = nrm > T(1e-12) ? T(1) / nrm : T(0);
      v_dirs[3 * i] = (gx - x * dot) * inv;
      v_dirs[3 * i + 1] = (gy - y * dot) * inv;
      v_dirs[3 * i + 2] = (gz - z * dot) * inv;
    }
  }
}

}  // namespace gs3d
