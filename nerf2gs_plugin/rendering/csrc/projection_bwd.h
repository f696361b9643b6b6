// Backward of the fused projection + SH colours (projection_core.h): it recomputes the forward
// quantities of each (camera, Gaussian) pair and loops over cameras inside one Gaussian, so the
// per-Gaussian sums need no atomics. Mirrors torch autograd through projection.py and sh.py.
#pragma once
#include "projection_core.h"
#include "sh_core.h"

namespace gs3d {

// VJP of quat_rotmat (quaternion used as given, not normalised): G = dL/dR (row-major) -> dL/dq.
template <typename T>
inline void quat_rotmat_vjp(const T* q, const T* G, T* gq) {
  const T w = q[0], x = q[1], y = q[2], z = q[3];
  gq[0] = T(2) * (-z * G[1] + y * G[2] + z * G[3] - x * G[5] - y * G[6] + x * G[7]);
  gq[1] = T(2) * (y * G[1] + z * G[2] + y * G[3] - T(2) * x * G[4] - w * G[5] + z * G[6] + w * G[7] - T(2) * x * G[8]);
  gq[2] = T(2) * (-T(2) * y * G[0] + x * G[1] + w * G[2] + x * G[3] + z * G[5] - w * G[6] + z * G[7] - T(2) * y * G[8]);
  gq[3] = T(2) * (-T(2) * z * G[0] - w * G[1] + x * G[2] + w * G[3] - T(2) * z * G[4] + y * G[5] + x * G[6] + y * G[7]);
}

// Backward of project_forward. Gradients in: v_means2d [C,N,2], v_conics [C,N,3], v_depths [C,N],
// v_comp [C,N], v_colors [C,N,3] (or null). Out (overwritten): v_means [N,3], v_quats [N,4],
// v_scales [N,3], v_sh [N,K,3] (when K > 0; only the first (degree+1)^2 rows written, the rest zeroed).
// Follows torch's autograd of projection.py: culled pairs (zs = 1, ds = 1) still pass the
// gradients of their outputs; clamped x/z, y/z pass none; compensation at det_orig <= 0 passes none.
template <typename T>
void project_backward(const T* means, const T* quats, const T* scales, const T* sh, const T* viewmats, const T* Ks,
                      const ProjectArgs a, int n_threads, const T* v_means2d, const T* v_conics, const T* v_depths,
                      const T* v_comp, const T* v_colors, T* v_means, T* v_quats, T* v_scales, T* v_sh) {
#pragma omp parallel for num_threads(n_threads) schedule(static)
  for (int64_t g = 0; g < a.n; ++g) {
    const T* m = means + 3 * g;
    const T* q = quats + 4 * g;
    const T* s = scales + 3 * g;
    T R[9];
    quat_rotmat<T>(q, R);
    T gm[3] = {0, 0, 0}, gN[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
    T* vsh = sh_grad_rows<T>(v_sh, g, a.K);
    for (int64_t c = 0; c < a.n_cams; ++c) {
      const int64_t i = c * a.n + g;
      const T* V = viewmats + 16 * c;
      PairProj<T> P;  // the forward's quantities, recomputed
      pair_proj<T>(m, R, s, V, Ks + 9 * c, a, P);
      const T A = P.A, C = P.C, cxy = P.cxy, ds = P.ds, zs = P.zs, iz = P.iz;
      // ---- conics (C, -cxy, A) / ds and compensation sqrt(det_orig / ds)
      const T* vc = v_conics + 3 * i;
      T gA = vc[2] / ds, gC = vc[0] / ds, gxy = -vc[1] / ds;
      T g_ds = -(vc[0] * C - vc[1] * cxy + vc[2] * A) / (ds * ds);
      T g_do = 0;
      const T ratio = P.det_orig / ds;
      if (v_comp != nullptr && ratio > T(0)) {
        const T v_r = v_comp[i] / (T(2) * std::sqrt(ratio));
        g_do = v_r / ds;
        g_ds -= v_r * P.det_orig / (ds * ds);
      }
      if (P.valid) {
        gA += g_ds * C;
        gC += g_ds * A;
        gxy -= T(2) * cxy * g_ds;
      }
      const T gxx = gA + g_do * P.cyy, gyy = gC + g_do * P.cxx;
      gxy -= T(2) * cxy * g_do;
      // ---- u, v -> M and the Jacobian entries
      T gja = 0, gjb = 0, gjc = 0, gjd = 0;
      T gM[9];
      for (int k = 0; k < 3; ++k) {
        const T gu = T(2) * gxx * P.u[k] + gxy * P.v[k];
        const T gv = T(2) * gyy * P.v[k] + gxy * P.u[k];
        gM[k] = P.ja * gu;
        gM[3 + k] = P.jc * gv;
        gM[6 + k] = -P.jb * gu - P.jd * gv;
        gja += gu * P.M[k];
        gjb -= gu * P.M[6 + k];
        gjc += gv * P.M[3 + k];
        gjd -= gv * P.M[6 + k];
      }
      const T fx = P.fx, fy = P.fy, px = P.px, py = P.py;
      T g_iz = fx * gja + T(2) * fx * P.tx * iz * gjb + fy * gjc + T(2) * fy * P.ty * iz * gjd;
      const T g_tx = fx * iz * iz * gjb, g_ty = fy * iz * iz * gjd;
      // ---- means2d = (fx x / zs + cx, fy y / zs + cy), depth = z
      const T vmx = v_means2d[2 * i], vmy = v_means2d[2 * i + 1];
      T g_px = fx * vmx / zs, g_py = fy * vmy / zs;
      T g_zs = -(fx * px * vmx + fy * py * vmy) / (zs * zs) - g_iz / (zs * zs);
      g_zs += P.clx * g_tx + P.cly * g_ty;
      if (P.rx > -P.lxn && P.rx < P.lxp) {
        const T g_rx = zs * g_tx;
        g_px += g_rx / zs;
        g_zs -= g_rx * px / (zs * zs);
      }
      if (P.ry > -P.lyn && P.ry < P.lyp) {
        const T g_ry = zs * g_ty;
        g_py += g_ry / zs;
        g_zs -= g_ry * py / (zs * zs);
      }
      T g_pz = v_depths[i] + (P.in_depth ? g_zs : T(0));
      // p = Rv m + t
      for (int j = 0; j < 3; ++j) gm[j] += V[j] * g_px + V[4 + j] * g_py + V[8 + j] * g_pz;
      // M = Rv (Rq S): gN = Rv^T gM
      for (int j = 0; j < 3; ++j)
        for (int k = 0; k < 3; ++k) gN[3 * j + k] += V[j] * gM[k] + V[4 + j] * gM[3 + k] + V[8 + j] * gM[6 + k];
      // ---- SH colours along normalise(mean - camera centre)
      if (vsh != nullptr && v_colors != nullptr) {
        T d[3];
        view_dir<T>(V, m, d);
        sh_color_vjp<T>(a.sh_degree, d, sh + g * a.K * 3, v_colors + 3 * i, vsh, gm);
      }
    }
    for (int j = 0; j < 3; ++j) v_means[3 * g + j] = gm[j];
    T gR[9];
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) gR[3 * j + k] = gN[3 * j + k] * s[k];
    for (int k = 0; k < 3; ++k) v_scales[3 * g + k] = gN[k] * R[k] + gN[3 + k] * R[3 + k] + gN[6 + k] * R[6 + k];
    quat_rotmat_vjp<T>(q, gR, v_quats + 4 * g);
  }
}

}  // namespace gs3d
