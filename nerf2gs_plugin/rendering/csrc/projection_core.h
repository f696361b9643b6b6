// Projection + SH colours of 3D Gaussians, forward and backward: the same formulas as
// projection.py / sh.py, fused per (camera, Gaussian) pair so that a frame does not pay for ~100
// small torch ops (and their autograd graph). The backward is in projection_bwd.h.
#pragma once
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "sh_core.h"  // view_dir, sh_color

namespace gs3d {

struct ProjectArgs {
  int64_t n_cams, n, width, height, K;  // K: SH coefficients per Gaussian (0 = no SH evaluation)
  int sh_degree;
  double near_plane, far_plane, eps2d;
};

template <typename T>
inline void quat_rotmat(const T* q, T* R) {
  const T w = q[0], x = q[1], y = q[2], z = q[3];
  R[0] = T(1) - T(2) * (y * y + z * z); R[1] = T(2) * (x * y - w * z); R[2] = T(2) * (x * z + w * y);
  R[3] = T(2) * (x * y + w * z); R[4] = T(1) - T(2) * (x * x + z * z); R[5] = T(2) * (y * z - w * x);
  R[6] = T(2) * (x * z - w * y); R[7] = T(2) * (y * z + w * x); R[8] = T(1) - T(2) * (x * x + y * y);
}

// What the forward computes for one (camera, Gaussian) pair before its outputs, and what the
// backward recomputes: one definition so the two cannot drift apart.
template <typename T>
struct PairProj {
  T px, py, pz;                // camera-space mean
  bool in_depth, valid;        // inside (near, far); and with a positive 2D determinant
  T zs, iz;                    // pz, or 1 when culled by depth; 1 / zs
  T M[9];                      // R_v R_q S, row-major
  T fx, fy, cx, cy;
  T lxp, lxn, lyp, lyn;        // x/z and y/z limits of the Jacobian (1.3 x the half field of view)
  T rx, ry, clx, cly, tx, ty;  // x/z, y/z, the clamped ratios, and zs times them
  T ja, jb, jc, jd;            // Jacobian entries
  T u[3], v[3];                // rows of J M
  T cxx, cxy, cyy, det_orig;   // 2D covariance before the eps2d blur, and its determinant
  T A, C, det, ds;             // blurred diagonal, its determinant; ds = det, or 1 when not valid
};

template <typename T>
GS3D_FORCE_INLINE void pair_proj(const T* m, const T* R, const T* s, const T* V, const T* Kc, const ProjectArgs& a, PairProj<T>& P) {
  P.px = V[0] * m[0] + V[1] * m[1] + V[2] * m[2] + V[3];
  P.py = V[4] * m[0] + V[5] * m[1] + V[6] * m[2] + V[7];
  P.pz = V[8] * m[0] + V[9] * m[1] + V[10] * m[2] + V[11];
  P.in_depth = P.pz > T(a.near_plane) && P.pz < T(a.far_plane);
  P.zs = P.in_depth ? P.pz : T(1);
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 3; ++k) P.M[3 * r + k] = (V[4 * r] * R[k] + V[4 * r + 1] * R[3 + k] + V[4 * r + 2] * R[6 + k]) * s[k];
  P.fx = Kc[0], P.fy = Kc[4], P.cx = Kc[2], P.cy = Kc[5];
  const T W = T(a.width), H = T(a.height);
  const T tan_fx = T(0.5) * W / P.fx, tan_fy = T(0.5) * H / P.fy;
  P.lxp = (W - P.cx) / P.fx + T(0.3) * tan_fx, P.lxn = P.cx / P.fx + T(0.3) * tan_fx;
  P.lyp = (H - P.cy) / P.fy + T(0.3) * tan_fy, P.lyn = P.cy / P.fy + T(0.3) * tan_fy;
  P.rx = P.px / P.zs, P.ry = P.py / P.zs;
  P.clx = std::min(P.lxp, std::max(-P.lxn, P.rx)), P.cly = std::min(P.lyp, std::max(-P.lyn, P.ry));
  P.tx = P.zs * P.clx, P.ty = P.zs * P.cly;
  P.iz = T(1) / P.zs;
  P.ja = P.fx * P.iz, P.jb = P.fx * P.tx * P.iz * P.iz, P.jc = P.fy * P.iz, P.jd = P.fy * P.ty * P.iz * P.iz;
  P.cxx = 0, P.cxy = 0, P.cyy = 0;
  for (int k = 0; k < 3; ++k) {
    P.u[k] = P.ja * P.M[k] - P.jb * P.M[6 + k];
    P.v[k] = P.jc * P.M[3 + k] - P.jd * P.M[6 + k];
    P.cxx += P.u[k] * P.u[k];
    P.cxy += P.u[k] * P.v[k];
    P.cyy += P.v[k] * P.v[k];
  }
  P.det_orig = P.cxx * P.cyy - P.cxy * P.cxy;
  P.A = P.cxx + T(a.eps2d), P.C = P.cyy + T(a.eps2d);
  P.det = P.A * P.C - P.cxy * P.cxy;
  P.valid = P.in_depth && P.det > 0;
  P.ds = P.valid ? P.det : T(1);
}

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
    const T* m = means + 3 * g;
    T R[9];
    quat_rotmat<T>(quats + 4 * g, R);
    PairProj<T> P;
    pair_proj<T>(m, R, scales + 3 * g, V, Ks + 9 * c, a, P);
    const T comp = std::sqrt(std::max(P.det_orig / P.ds, T(0)));
    conics[3 * i] = P.C / P.ds;
    conics[3 * i + 1] = -P.cxy / P.ds;
    conics[3 * i + 2] = P.A / P.ds;
    const T mx = P.fx * P.px / P.zs + P.cx, my = P.fy * P.py / P.zs + P.cy;
    means2d[2 * i] = mx;
    means2d[2 * i + 1] = my;
    depths[i] = P.pz;
    cov2d[4 * i] = P.A;
    cov2d[4 * i + 1] = P.cxy;
    cov2d[4 * i + 2] = P.cxy;
    cov2d[4 * i + 3] = P.C;
    comp_out[i] = comp;
    const T mid = T(0.5) * (P.A + P.C);
    const T lam = mid + std::sqrt(std::max(mid * mid - P.det, T(0.01)));
    const T radius = std::ceil(T(3) * std::sqrt(lam));
    const bool on = mx + radius > 0 && mx - radius < T(a.width) && my + radius > 0 && my - radius < T(a.height);
    radii[i] = (P.valid && on && std::isfinite(radius)) ? static_cast<int32_t>(radius) : 0;
    if (a.K > 0) {
      T d[3];
      view_dir<T>(V, m, d);
      sh_color<T>(a.sh_degree, d, sh + g * a.K * 3, colors + 3 * i);
    }
  }
}

}  // namespace gs3d
