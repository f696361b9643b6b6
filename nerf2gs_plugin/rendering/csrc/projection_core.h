// Projection + SH colours of 3D Gaussians, forward and backward: the same formulas as
// projection.py / sh.py, fused per (camera, Gaussian) pair so that a frame does not pay for ~100
// small torch ops (and their autograd graph). The backward is in projection_bwd.h.
#pragma once
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>

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

struct ProjectArgs {
  int64_t n_cams, n, width, height, K;  // K: SH coefficients per Gaussian (0 = no SH evaluation)
  int sh_degree;
  double near_plane, far_plane, eps2d;
};

// means [N,3], quats [N,4] wxyz, scales [N,3], opac [N], sh [N,K,3], viewmats [C,4,4], Ks [C,3,3]
// -> means2d [C,N,2], conics [C,N,3], depths [C,N], radii [C,N], comp_out [C,N] (the antialiasing
// compensation), cov2d [C,N,4], colors [C,N,3] (when K > 0).
template <typename T>
void project_forward(const T* means, const T* quats, const T* scales, const T* sh, const T* viewmats,
                     const T* Ks, const ProjectArgs a, int n_threads, T* means2d, T* conics, T* depths, int32_t* radii,
                     T* comp_out, T* cov2d, T* colors) {
  const int64_t total = a.n_cams * a.n;
#pragma omp parallel for num_threads(n_threads) schedule(static)
  for (int64_t i = 0; i < total; ++i) {
    const int64_t c = i / a.n, g = i % a.n;
    const T* V = viewmats + 16 * c;
    const T* Kc = Ks + 9 * c;
    const T* m = means + 3 * g;
    const T px = V[0] * m[0] + V[1] * m[1] + V[2] * m[2] + V[3];
    const T py = V[4] * m[0] + V[5] * m[1] + V[6] * m[2] + V[7];
    const T pz = V[8] * m[0] + V[9] * m[1] + V[10] * m[2] + V[11];
    const bool in_depth = pz > T(a.near_plane) && pz < T(a.far_plane);
    const T zs = in_depth ? pz : T(1);
    // M = R_v R_q S
    const T* q = quats + 4 * g;
    const T w = q[0], x = q[1], y = q[2], z = q[3];
    const T R[9] = {T(1) - T(2) * (y * y + z * z), T(2) * (x * y - w * z), T(2) * (x * z + w * y),
                    T(2) * (x * y + w * z), T(1) - T(2) * (x * x + z * z), T(2) * (y * z - w * x),
                    T(2) * (x * z - w * y), T(2) * (y * z + w * x), T(1) - T(2) * (x * x + y * y)};
    const T* s = scales + 3 * g;
    T M[9];
    for (int r = 0; r < 3; ++r)
      for (int k = 0; k < 3; ++k) M[3 * r + k] = (V[4 * r] * R[k] + V[4 * r + 1] * R[3 + k] + V[4 * r + 2] * R[6 + k]) * s[k];
    const T fx = Kc[0], fy = Kc[4], cx = Kc[2], cy = Kc[5];
    const T W = T(a.width), H = T(a.height);
    const T tan_fx = T(0.5) * W / fx, tan_fy = T(0.5) * H / fy;
    const T lxp = (W - cx) / fx + T(0.3) * tan_fx, lxn = cx / fx + T(0.3) * tan_fx;
    const T lyp = (H - cy) / fy + T(0.3) * tan_fy, lyn = cy / fy + T(0.3) * tan_fy;
    const T tx = zs * std::min(lxp, std::max(-lxn, px / zs));
    const T ty = zs * std::min(lyp, std::max(-lyn, py / zs));
    const T iz = T(1) / zs;
    const T ja = fx * iz, jb = fx * tx * iz * iz, jc = fy * iz, jd = fy * ty * iz * iz;
    T cxx = 0, cxy = 0, cyy = 0;
    for (int k = 0; k < 3; ++k) {
      const T u = ja * M[k] - jb * M[6 + k];
      const T v = jc * M[3 + k] - jd * M[6 + k];
      cxx += u * u;
      cxy += u * v;
      cyy += v * v;
    }
    const T det_orig = cxx * cyy - cxy * cxy;
    const T A = cxx + T(a.eps2d), C = cyy + T(a.eps2d);
    const T det = A * C - cxy * cxy;
    const bool valid = in_depth && det > 0;
    const T det_s = valid ? det : T(1);
    const T comp = std::sqrt(std::max(det_orig / det_s, T(0)));
    conics[3 * i] = C / det_s;
    conics[3 * i + 1] = -cxy / det_s;
    conics[3 * i + 2] = A / det_s;
    const T mx = fx * px / zs + cx, my = fy * py / zs + cy;
    means2d[2 * i] = mx;
    means2d[2 * i + 1] = my;
    depths[i] = pz;
    cov2d[4 * i] = A;
    cov2d[4 * i + 1] = cxy;
    cov2d[4 * i + 2] = cxy;
    cov2d[4 * i + 3] = C;
    comp_out[i] = comp;
    const T mid = T(0.5) * (A + C);
    const T lam = mid + std::sqrt(std::max(mid * mid - det, T(0.01)));
    const T radius = std::ceil(T(3) * std::sqrt(lam));
    const bool on = mx + radius > 0 && mx - radius < W && my + radius > 0 && my - radius < H;
    radii[i] = (valid && on && std::isfinite(radius)) ? static_cast<int32_t>(radius) : 0;
    if (a.K > 0) {
      // view direction: mean - camera centre, centre = -R_v^T t
      const T ccx = -(V[0] * V[3] + V[4] * V[7] + V[8] * V[11]);
      const T ccy = -(V[1] * V[3] + V[5] * V[7] + V[9] * V[11]);
      const T ccz = -(V[2] * V[3] + V[6] * V[7] + V[10] * V[11]);
      T dx = m[0] - ccx, dy = m[1] - ccy, dz = m[2] - ccz;
      const T nrm = std::max(std::sqrt(dx * dx + dy * dy + dz * dz), T(1e-12));
      dx /= nrm;
      dy /= nrm;
      dz /= nrm;
      T b[16];
      sh_basis<T>(a.sh_degree, dx, dy, dz, b);
      const int nb = (a.sh_degree + 1) * (a.sh_degree + 1);
      const T* coef = sh + g * a.K * 3;
      for (int ch = 0; ch < 3; ++ch) {
        T acc = 0;
        for (int k = 0; k < nb; ++k) acc += b[k] * coef[3 * k + ch];
        colors[3 * i + ch] = std::max(acc + T(0.5), T(0));
      }
    }
  }
}

}  // namespace gs3d
