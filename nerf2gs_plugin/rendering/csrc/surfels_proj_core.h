// 2DGS surfel projection + SH colours on the CPU, forward and backward, and the per-tile lists:
// what surfels_torch.project_surfels / build_tile_lists and sh.eval_sh compute, fused per
// (camera, surfel) pair instead of ~150 small autograd ops. The forward emits what the
// compositor (surfels.cpp) reads: adj(T) and det(T) of the homography T = K [t_u | t_v | p], the
// projected centre, the centre depth, the camera-facing normal, the footprint box and radius.
// The backward loops over cameras inside one surfel, so per-surfel sums need no atomics.
#pragma once
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "binning_core.h"    // radix_sort_by_depth
#include "projection_bwd.h"  // quat_rotmat(+_vjp), view_dir, sh_color(+_vjp)

namespace surf2d {

struct SurfArgs {
  int64_t n_cams, n, width, height, K;  // K: SH coefficients per surfel (0 = no colours)
  int sh_degree;
  double near_plane, far_plane;
};

template <typename T>
inline void cross3(const T* a, const T* b, T* c) {
  c[0] = a[1] * b[2] - a[2] * b[1];
  c[1] = a[2] * b[0] - a[0] * b[2];
  c[2] = a[0] * b[1] - a[1] * b[0];
}

// Per pair geometry shared by forward and backward.
template <typename T>
struct PairGeo {
  T qn[4], R[9];          // normalised quaternion and its rotation
  T p[3], tu[3], tv[3], nrm[3], facing;
  T Tm[9];                // homography, row-major
  bool in_range;
  T ws;                   // T[2][2] or 1 when culled by depth
};

template <typename T>
inline void normalize_quat(const T* q, T* qn, T& len) {
  len = std::max(std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]), T(1e-12));
  for (int k = 0; k < 4; ++k) qn[k] = q[k] / len;
}

template <typename T>
inline void pair_geo(const T* m, const T* s, const T* qn, const T* R, const T* V, const T* Kc, const SurfArgs& a,
                     PairGeo<T>& G) {
  for (int r = 0; r < 3; ++r) {
    G.p[r] = V[4 * r] * m[0] + V[4 * r + 1] * m[1] + V[4 * r + 2] * m[2] + V[4 * r + 3];
    G.tu[r] = V[4 * r] * (R[0] * s[0]) + V[4 * r + 1] * (R[3] * s[0]) + V[4 * r + 2] * (R[6] * s[0]);
    G.tv[r] = V[4 * r] * (R[1] * s[1]) + V[4 * r + 1] * (R[4] * s[1]) + V[4 * r + 2] * (R[7] * s[1]);
    G.nrm[r] = V[4 * r] * R[2] + V[4 * r + 1] * R[5] + V[4 * r + 2] * R[8];
  }
  G.facing = (G.nrm[0] * G.p[0] + G.nrm[1] * G.p[1] + G.nrm[2] * G.p[2]) > T(0) ? T(-1) : T(1);
  const T* cols[3] = {G.tu, G.tv, G.p};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) G.Tm[3 * i + j] = Kc[3 * i] * cols[j][0] + Kc[3 * i + 1] * cols[j][1] + Kc[3 * i + 2] * cols[j][2];
  const T z = G.p[2];
  G.in_range = z > T(a.near_plane) && z < T(a.far_plane);
  G.ws = G.in_range ? G.Tm[8] : T(1);
}

// means [N,3], quats [N,4], scales [N,3], opac [N], sh [N,K,3], viewmats [C,4,4], Ks [C,3,3] ->
// adj [C*N,9], det [C*N], means2d [C*N,2], depths [C*N], normals [C*N,3], radii [C*N] int32,
// bbox [C*N,4], colors [C*N,3] (K > 0).
template <typename T>
void project_forward(const T* means, const T* quats, const T* scales, const T* opac, const T* sh, const T* viewmats,
                     const T* Ks, const SurfArgs a, int n_threads, T* adj, T* det, T* means2d, T* depths, T* normals,
                     int32_t* radii, T* bbox, T* colors) {
  const T Wd = T(a.width), Hd = T(a.height), big = T(std::max(a.width, a.height)) * T(4);
#pragma omp parallel for num_threads(n_threads) schedule(static)
  for (int64_t g = 0; g < a.n; ++g) {
    T qn[4], len, R[9];
    normalize_quat(quats + 4 * g, qn, len);
    gs3d::quat_rotmat<T>(qn, R);
    const T* m = means + 3 * g;
    const T o = opac[g];
    const T r2 = T(2) * std::log(std::max(o * T(255), T(1)));
    const T qz = T(-1) / std::max(r2, T(1e-12));
    const T lp = std::sqrt(r2 / T(2));
    for (int64_t c = 0; c < a.n_cams; ++c) {
      const int64_t i = c * a.n + g;
      PairGeo<T> G;
      pair_geo<T>(m, scales + 3 * g, qn, R, viewmats + 16 * c, Ks + 9 * c, a, G);
      const T* r0 = G.Tm;
      const T *r1 = G.Tm + 3, *r2r = G.Tm + 6;
      T a0[3], a1[3], a2[3];
      cross3(r1, r2r, a0);
      cross3(r2r, r0, a1);
      cross3(r0, r1, a2);
      for (int k = 0; k < 3; ++k) {
        adj[9 * i + 3 * k] = a0[k];
        adj[9 * i + 3 * k + 1] = a1[k];
        adj[9 * i + 3 * k + 2] = a2[k];
      }
      det[i] = r0[0] * a0[0] + r0[1] * a0[1] + r0[2] * a0[2];
      const T mx = G.Tm[2] / G.ws, my = G.Tm[5] / G.ws;
      means2d[2 * i] = mx;
      means2d[2 * i + 1] = my;
      depths[i] = G.p[2];
      for (int k = 0; k < 3; ++k) normals[3 * i + k] = G.nrm[k] * G.facing;
      // footprint box: the dual conic D = T diag(1, 1, qz) T^T of the disc's image
      T D[9];
      for (int u = 0; u < 3; ++u)
        for (int v = 0; v < 3; ++v)
          D[3 * u + v] = G.Tm[3 * u] * G.Tm[3 * v] + G.Tm[3 * u + 1] * G.Tm[3 * v + 1] + G.Tm[3 * u + 2] * qz * G.Tm[3 * v + 2];
      const bool ellipse = D[8] < T(0);
      const T d22s = ellipse ? D[8] : T(-1);
      const T cx = D[2] / d22s, cy = D[5] / d22s;
      const T hx = std::sqrt(std::max(cx * cx - D[0] / d22s, T(0)));
      const T hy = std::sqrt(std::max(cy * cy - D[4] / d22s, T(0)));
      T x0 = std::min(cx - hx, mx - lp), x1 = std::max(cx + hx, mx + lp);
      T y0 = std::min(cy - hy, my - lp), y1 = std::max(cy + hy, my + lp);
      if (!ellipse) x0 = y0 = -big, x1 = y1 = big;
      bool finite = std::isfinite(x0) && std::isfinite(x1) && std::isfinite(y0) && std::isfinite(y1);
      for (int k = 0; k < 9; ++k) finite = finite && std::isfinite(G.Tm[k]);
      const bool on = x1 > T(0) && x0 < Wd && y1 > T(0) && y0 < Hd;
      const bool vis = G.in_range && finite && on && o >= T(1.0 / 255.0);
      const T rad = std::max(x1 - x0, y1 - y0) * T(0.5);
      radii[i] = vis ? static_cast<int32_t>(std::ceil(std::min(rad, T(std::max(a.width, a.height))))) : 0;
      bbox[4 * i] = vis ? x0 : T(0);
      bbox[4 * i + 1] = vis ? y0 : T(0);
      bbox[4 * i + 2] = vis ? x1 : T(0);
      bbox[4 * i + 3] = vis ? y1 : T(0);
      if (a.K > 0) {
        T d[3];
        gs3d::view_dir<T>(viewmats + 16 * c, m, d);
        gs3d::sh_color<T>(a.sh_degree, d, sh + g * a.K * 3, colors + 3 * i);
      }
    }
  }
}

// Gradients in: v_adj [C*N,9], v_det, v_means2d [C*N,2], v_depths, v_normals [C*N,3], v_colors
// [C*N,3] (null: none). Out (overwritten): v_means [N,3], v_quats [N,4], v_scales [N,3] (the
// normal axis gets 0), v_sh [N,K,3] (K > 0).
template <typename T>
void project_backward(const T* means, const T* quats, const T* scales, const T* sh, const T* viewmats, const T* Ks,
                      const SurfArgs a, int n_threads, const T* v_adj, const T* v_det, const T* v_means2d,
                      const T* v_depths, const T* v_normals, const T* v_colors, T* v_means, T* v_quats, T* v_scales,
                      T* v_sh) {
#pragma omp parallel for num_threads(n_threads) schedule(static)
  for (int64_t g = 0; g < a.n; ++g) {
    const T* m = means + 3 * g;
    const T* s = scales + 3 * g;
    T qn[4], len, R[9];
    normalize_quat(quats + 4 * g, qn, len);
    gs3d::quat_rotmat<T>(qn, R);
    T gm[3] = {0, 0, 0}, gR[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0}, gs0 = 0, gs1 = 0;
    T* vsh = gs3d::sh_grad_rows<T>(v_sh, g, a.K);
    for (int64_t c = 0; c < a.n_cams; ++c) {
      const int64_t i = c * a.n + g;
      const T* V = viewmats + 16 * c;
      const T* Kc = Ks + 9 * c;
      PairGeo<T> G;
      pair_geo<T>(m, s, qn, R, V, Kc, a, G);
      const T* r[3] = {G.Tm, G.Tm + 3, G.Tm + 6};
      T gr[3][3] = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}};
      // adj columns a0 = r1 x r2, a1 = r2 x r0, a2 = r0 x r1; det = r0 . a0
      T ga[3][3];
      for (int k = 0; k < 3; ++k)
        for (int j = 0; j < 3; ++j) ga[j][k] = v_adj[9 * i + 3 * k + j];
      T a0[3];
      cross3(r[1], r[2], a0);
      const T vd = v_det[i];
      for (int k = 0; k < 3; ++k) {
        gr[0][k] += vd * a0[k];
        ga[0][k] += vd * r[0][k];
      }
      T tmp[3];
      // c = x cross y: g_x = y cross g_c, g_y = g_c cross x
      cross3(r[2], ga[0], tmp); for (int k = 0; k < 3; ++k) gr[1][k] += tmp[k];
      cross3(ga[0], r[1], tmp); for (int k = 0; k < 3; ++k) gr[2][k] += tmp[k];
      cross3(r[0], ga[1], tmp); for (int k = 0; k < 3; ++k) gr[2][k] += tmp[k];
      cross3(ga[1], r[2], tmp); for (int k = 0; k < 3; ++k) gr[0][k] += tmp[k];
      cross3(r[1], ga[2], tmp); for (int k = 0; k < 3; ++k) gr[0][k] += tmp[k];
      cross3(ga[2], r[0], tmp); for (int k = 0; k < 3; ++k) gr[1][k] += tmp[k];
      // means2d = T[0:2, 2] / ws
      const T vmx = v_means2d[2 * i], vmy = v_means2d[2 * i + 1];
      gr[0][2] += vmx / G.ws;
      gr[1][2] += vmy / G.ws;
      if (G.in_range) gr[2][2] -= (G.Tm[2] * vmx + G.Tm[5] * vmy) / (G.ws * G.ws);
      // T = K M, M columns (tu, tv, p): gM = K^T gT
      T gcol[3][3];  // gcol[j] = gradient of column j of M
      for (int j = 0; j < 3; ++j)
        for (int k = 0; k < 3; ++k) gcol[j][k] = Kc[k] * gr[0][j] + Kc[3 + k] * gr[1][j] + Kc[6 + k] * gr[2][j];
      gcol[2][2] += v_depths[i];
      T gn[3];
      for (int k = 0; k < 3; ++k) gn[k] = v_normals[3 * i + k] * G.facing;
      // back through the view rotation: x_cam = Rv x  =>  g_x = Rv^T g
      for (int k = 0; k < 3; ++k) {
        const T wu = V[k] * gcol[0][0] + V[4 + k] * gcol[0][1] + V[8 + k] * gcol[0][2];
        const T wv = V[k] * gcol[1][0] + V[4 + k] * gcol[1][1] + V[8 + k] * gcol[1][2];
        const T wp = V[k] * gcol[2][0] + V[4 + k] * gcol[2][1] + V[8 + k] * gcol[2][2];
        const T wn = V[k] * gn[0] + V[4 + k] * gn[1] + V[8 + k] * gn[2];
        gm[k] += wp;
        gR[3 * k] += wu * s[0];
        gR[3 * k + 1] += wv * s[1];
        gR[3 * k + 2] += wn;
        gs0 += wu * R[3 * k];
        gs1 += wv * R[3 * k + 1];
      }
      if (vsh != nullptr && v_colors != nullptr) {
        T d[3];
        gs3d::view_dir<T>(V, m, d);
        gs3d::sh_color_vjp<T>(a.sh_degree, d, sh + g * a.K * 3, v_colors + 3 * i, vsh, gm);
      }
    }
    for (int k = 0; k < 3; ++k) v_means[3 * g + k] = gm[k];
    v_scales[3 * g] = gs0;
    v_scales[3 * g + 1] = gs1;
    v_scales[3 * g + 2] = 0;
    T gqn[4];
    gs3d::quat_rotmat_vjp<T>(qn, gR, gqn);
    // qn = q / max(|q|, 1e-12)
    const T dot = gqn[0] * qn[0] + gqn[1] * qn[1] + gqn[2] * qn[2] + gqn[3] * qn[3];
    const T* q = quats + 4 * g;
    const T qlen = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    for (int k = 0; k < 4; ++k) v_quats[4 * g + k] = qlen > T(1e-12) ? (gqn[k] - qn[k] * dot) / len : gqn[k] / len;
  }
}

// Tiles (tw x th per camera, inclusive ranges from the pixel box; pixel i's centre is i + 0.5)
// listed front to back by centre depth (ties in pair order), as build_tile_lists.
// -> flat_ids, starts, counts.
template <typename T>
void tile_lists(const T* bbox, const T* depths, const int32_t* radii, int64_t n_cams, int64_t n, int ts, int tw,
                int th, std::vector<int64_t>& ids, std::vector<int64_t>& starts, std::vector<int64_t>& counts) {
  const int64_t CN = n_cams * n, n_tiles = n_cams * tw * th;
  std::vector<int32_t> rect(4 * CN);
  std::vector<int64_t> order;
  order.reserve(CN);
  counts.assign(n_tiles, 0);
  auto tile_of = [ts](T v, int hi) {
    return static_cast<int32_t>(std::min(std::max(std::floor((v - T(0.5)) / T(ts)), T(0)), T(hi - 1)));
  };
  for (int64_t c = 0, i = 0; c < n_cams; ++c) {
    for (int64_t g = 0; g < n; ++g, ++i) {
      if (radii[i] <= 0) continue;
      const T* b = bbox + 4 * i;
      int32_t* r = rect.data() + 4 * i;
      r[0] = tile_of(b[0], tw);
      r[1] = tile_of(b[2], tw);
      r[2] = tile_of(b[1], th);
      r[3] = tile_of(b[3], th);
      order.push_back(i);
      for (int y = r[2]; y <= r[3]; ++y)
        for (int x = r[0]; x <= r[1]; ++x) ++counts[c * tw * th + y * tw + x];
    }
  }
  gs3d::radix_sort_by_depth<T>(order, depths);
  starts.assign(n_tiles, 0);
  for (int64_t t = 1; t < n_tiles; ++t) starts[t] = starts[t - 1] + counts[t - 1];
  ids.assign(n_tiles > 0 ? starts[n_tiles - 1] + counts[n_tiles - 1] : 0, 0);
  std::vector<int64_t> cursor(starts);
  for (int64_t i : order) {
    const int32_t* r = rect.data() + 4 * i;
    const int64_t base = (i / n) * tw * th;
    for (int y = r[2]; y <= r[3]; ++y)
      for (int x = r[0]; x <= r[1]; ++x) ids[cursor[base + y * tw + x]++] = i;
  }
}

}  // namespace surf2d
