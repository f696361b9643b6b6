// Backward of the fused projection + SH colours (projection_core.h): it recomputes the forward
// quantities of each (camera, Gaussian) pair and loops over cameras inside one Gaussian, so the
// per-Gaussian sums need no atomics. Mirrors torch autograd through projection.py and sh.py.
#pragma once
#include "projection_core.h"
#include "sh_core.h"

namespace gs3d {

template <typename T>
inline void quat_rotmat(const T* q, T* R) {
  const T w = q[0], x = q[1], y = q[2], z = q[3];
  R[0] = T(1) - T(2) * (y * y + z * z); R[1] = T(2) * (x * y - w * z); R[2] = T(2) * (x * z + w * y);
  R[3] = T(2) * (x * y + w * z); R[4] = T(1) - T(2) * (x * x + z * z); R[5] = T(2) * (y * z - w * x);
  R[6] = T(2) * (x * z - w * y); R[7] = T(2) * (y * z + w * x); R[8] = T(1) - T(2) * (x * x + y * y);
}

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
// Follows torch's autograd of projection.py: culled pairs (zs = 1, det_s = 1) still pass the
// gradients of their outputs; clamped x/z, y/z pass none; compensation at det_orig <= 0 passes none.
template <typename T>
void project_backward(const T* means, const T* quats, const T* scales, const T* sh, const T* viewmats, const T* Ks,
                      const ProjectArgs a, int n_threads, const T* v_means2d, const T* v_conics, const T* v_depths,
                      const T* v_comp, const T* v_colors, T* v_means, T* v_quats, T* v_scales, T* v_sh) {
  const int nb = (a.sh_degree + 1) * (a.sh_degree + 1);
#pragma omp parallel for num_threads(n_threads) schedule(static)
  for (int64_t g = 0; g < a.n; ++g) {
    const T* m = means + 3 * g;
    const T* q = quats + 4 * g;
    const T* s = scales + 3 * g;
    T R[9];
    quat_rotmat<T>(q, R);
    T gm[3] = {0, 0, 0}, gN[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
    T* vsh = a.K > 0 ? v_sh + g * a.K * 3 : nullptr;
    if (vsh)
      for (int64_t k = 0; k < a.K * 3; ++k) vsh[k] = 0;
    for (int64_t c = 0; c < a.n_cams; ++c) {
      const int64_t i = c * a.n + g;
      const T* V = viewmats + 16 * c;
      const T* Kc = Ks + 9 * c;
      // ---- forward recomputation
      const T px = V[0] * m[0] + V[1] * m[1] + V[2] * m[2] + V[3];
      const T py = V[4] * m[0] + V[5] * m[1] + V[6] * m[2] + V[7];
      const T pz = V[8] * m[0] + V[9] * m[1] + V[10] * m[2] + V[11];
      const bool in_depth = pz > T(a.near_plane) && pz < T(a.far_plane);
      const T zs = in_depth ? pz : T(1);
      T M[9];
      for (int r = 0; r < 3; ++r)
        for (int k = 0; k < 3; ++k) M[3 * r + k] = (V[4 * r] * R[k] + V[4 * r + 1] * R[3 + k] + V[4 * r + 2] * R[6 + k]) * s[k];
      const T fx = Kc[0], fy = Kc[4], cx = Kc[2], cy = Kc[5];
      const T W = T(a.width), H = T(a.height);
      const T tan_fx = T(0.5) * W / fx, tan_fy = T(0.5) * H / fy;
      const T lxp = (W - cx) / fx + T(0.3) * tan_fx, lxn = cx / fx + T(0.3) * tan_fx;
      const T lyp = (H - cy) / fy + T(0.3) * tan_fy, lyn = cy / fy + T(0.3) * tan_fy;
      const T rx = px / zs, ry = py / zs;
      const T clx = std::min(lxp, std::max(-lxn, rx)), cly = std::min(lyp, std::max(-lyn, ry));
      const T tx = zs * clx, ty = zs * cly;
      const T iz = T(1) / zs;
      const T ja = fx * iz, jb = fx * tx * iz * iz, jc = fy * iz, jd = fy * ty * iz * iz;
      T u[3], v[3];
      T cxx = 0, cxy = 0, cyy = 0;
      for (int k = 0; k < 3; ++k) {
        u[k] = ja * M[k] - jb * M[6 + k];
        v[k] = jc * M[3 + k] - jd * M[6 + k];
        cxx += u[k] * u[k];
        cxy += u[k] * v[k];
        cyy += v[k] * v[k];
      }
      const T det_orig = cxx * cyy - cxy * cxy;
      const T A = cxx + T(a.eps2d), C = cyy + T(a.eps2d);
      const T det = A * C - cxy * cxy;
      const bool valid = in_depth && det > 0;
      const T ds = valid ? det : T(1);
      // ---- conics (C, -cxy, A) / ds and compensation sqrt(det_orig / ds)
      const T* vc = v_conics + 3 * i;
      T gA = vc[2] / ds, gC = vc[0] / ds, gxy = -vc[1] / ds;
      T g_ds = -(vc[0] * C - vc[1] * cxy + vc[2] * A) / (ds * ds);
      T g_do = 0;
      const T ratio = det_orig / ds;
      if (v_comp != nullptr && ratio > T(0)) {
        const T v_r = v_comp[i] / (T(2) * std::sqrt(ratio));
        g_do = v_r / ds;
        g_ds -= v_r * det_orig / (ds * ds);
      }
      if (valid) {
        gA += g_ds * C;
        gC += g_ds * A;
        gxy -= T(2) * cxy * g_ds;
      }
      const T gxx = gA + g_do * cyy, gyy = gC + g_do * cxx;
      gxy -= T(2) * cxy * g_do;
      // ---- u, v -> M and the Jacobian entries
      T gja = 0, gjb = 0, gjc = 0, gjd = 0;
      T gM[9];
      for (int k = 0; k < 3; ++k) {
        const T gu = T(2) * gxx * u[k] + gxy * v[k];
        const T gv = T(2) * gyy * v[k] + gxy * u[k];
        gM[k] = ja * gu;
        gM[3 + k] = jc * gv;
        gM[6 + k] = -jb * gu - jd * gv;
        gja += gu * M[k];
        gjb -= gu * M[6 + k];
        gjc += gv * M[3 + k];
        gjd -= gv * M[6 + k];
      }
      T g_iz = fx * gja + T(2) * fx * tx * iz * gjb + fy * gjc + T(2) * fy * ty * iz * gjd;
      const T g_tx = fx * iz * iz * gjb, g_ty = fy * iz * iz * gjd;
      // ---- means2d = (fx x / zs + cx, fy y / zs + cy), depth = z
      const T vmx = v_means2d[2 * i], vmy = v_means2d[2 * i + 1];
      T g_px = fx * vmx / zs, g_py = fy * vmy / zs;
      T g_zs = -(fx * px * vmx + fy * py * vmy) / (zs * zs) - g_iz / (zs * zs);
      g_zs += clx * g_tx + cly * g_ty;
      if (rx > -lxn && rx < lxp) {
        const T g_rx = zs * g_tx;
        g_px += g_rx / zs;
        g_zs -= g_rx * px / (zs * zs);
      }
      if (ry > -lyn && ry < lyp) {
        const T g_ry = zs * g_ty;
        g_py += g_ry / zs;
        g_zs -= g_ry * py / (zs * zs);
      }
      T g_pz = v_depths[i] + (in_depth ? g_zs : T(0));
      // p = Rv m + t
      for (int j = 0; j < 3; ++j) gm[j] += V[j] * g_px + V[4 + j] * g_py + V[8 + j] * g_pz;
      // M = Rv (Rq S): gN = Rv^T gM
      for (int j = 0; j < 3; ++j)
        for (int k = 0; k < 3; ++k) gN[3 * j + k] += V[j] * gM[k] + V[4 + j] * gM[3 + k] + V[8 + j] * gM[6 + k];
      // ---- SH colours along normalise(mean - camera centre)
      if (vsh != nullptr && v_colors != nullptr) {
        const T ccx = -(V[0] * V[3] + V[4] * V[7] + V[8] * V[11]);
        const T ccy = -(V[1] * V[3] + V[5] * V[7] + V[9] * V[11]);
        const T ccz = -(V[2] * V[3] + V[6] * V[7] + V[10] * V[11]);
        const T dx0 = m[0] - ccx, dy0 = m[1] - ccy, dz0 = m[2] - ccz;
        const T nrm = std::max(std::sqrt(dx0 * dx0 + dy0 * dy0 + dz0 * dz0), T(1e-12));
        const T x = dx0 / nrm, y = dy0 / nrm, z = dz0 / nrm;
        T b[16];
        sh_basis<T>(a.sh_degree, x, y, z, b);
        const T* cf = sh + g * a.K * 3;
        T gcol[3];
        for (int ch = 0; ch < 3; ++ch) {
          T acc = 0;
          for (int k = 0; k < nb; ++k) acc += b[k] * cf[3 * k + ch];
          gcol[ch] = acc + T(0.5) >= T(0) ? v_colors[3 * i + ch] : T(0);
        }
        T G[16];
        for (int k = 0; k < nb; ++k) {
          G[k] = 0;
          for (int ch = 0; ch < 3; ++ch) {
            vsh[3 * k + ch] += b[k] * gcol[ch];
            G[k] += cf[3 * k + ch] * gcol[ch];
          }
        }
        T gx, gy, gz;
        sh_basis_vjp<T>(a.sh_degree, x, y, z, G, gx, gy, gz);
        const T dot = gx * x + gy * y + gz * z;
        const T inv = nrm > T(1e-12) ? T(1) / nrm : T(0);
        gm[0] += (gx - x * dot) * inv;
        gm[1] += (gy - y * dot) * inv;
        gm[2] += (gz - z * dot) * inv;
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
