// Tile binning on the CPU (what tiles.py does in torch, for the cpu backend): each visible
// (camera, Gaussian) pair is listed in every tile its alpha >= 1/255 ellipse (capped at 3 sigma)
// can reach, front to back. Pairs are visited in depth order (a stable sort) and appended to
// their tiles' buckets, so each tile's list comes out sorted without a per-tile sort.
#pragma once
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <vector>

namespace gs3d {

struct Rect {
  int32_t x0, x1, y0, y1;  // tile ranges [x0, x1) x [y0, y1)
};

template <typename T>
inline Rect tile_rect(T mx, T my, T cxx, T cyy, T op, int32_t radius, int ts, int tx_n, int ty_n) {
  T s = std::log(std::max(op * T(255), T(1)));
  s = std::min(s, T(4.5));
  if (radius <= 0 || !(s > 0)) return {0, 0, 0, 0};
  const T ex = std::sqrt(std::max(T(2) * s * cxx, T(0)));
  const T ey = std::sqrt(std::max(T(2) * s * cyy, T(0)));
  auto clampi = [](T v, int hi) { return static_cast<int32_t>(std::min(std::max(v, T(0)), T(hi))); };
  return {clampi(std::floor((mx - ex) / ts), tx_n), clampi(std::floor((mx + ex) / ts) + T(1), tx_n),
          clampi(std::floor((my - ey) / ts), ty_n), clampi(std::floor((my + ey) / ts) + T(1), ty_n)};
}

// means2d [C*N, 2], cov2d [C*N, 4] (xx, xy, yx, yy), opacities, depths [C*N], radii [C*N];
// offsets_out gets C*TY*TX + 1 entries; returns the flat ids.
template <typename T>
std::vector<int64_t> bin_pairs(const T* m2, const T* cov, const T* opa, const T* depth, const int32_t* radii, int64_t n_cams,
                               int64_t n, int64_t width, int64_t height, int ts, int n_threads,
                               std::vector<int64_t>& offsets_out) {
  const int tx_n = static_cast<int>((width + ts - 1) / ts), ty_n = static_cast<int>((height + ts - 1) / ts);
  const int64_t CN = n_cams * n, n_tiles = n_cams * tx_n * ty_n;
  std::vector<Rect> rects(CN);
#pragma omp parallel for num_threads(n_threads) schedule(static)
  for (int64_t i = 0; i < CN; ++i)
    rects[i] = tile_rect<T>(m2[2 * i], m2[2 * i + 1], cov[4 * i], cov[4 * i + 3], opa[i], radii[i], ts, tx_n, ty_n);
  std::vector<int64_t> counts(n_tiles + 1, 0);
  std::vector<int64_t> order;
  order.reserve(CN);
  for (int64_t i = 0; i < CN; ++i) {
    const Rect& r = rects[i];
    if (r.x1 <= r.x0 || r.y1 <= r.y0) continue;
    order.push_back(i);
    const int64_t base = (i / n) * tx_n * ty_n;
    for (int y = r.y0; y < r.y1; ++y)
      for (int x = r.x0; x < r.x1; ++x) ++counts[base + static_cast<int64_t>(y) * tx_n + x + 1];
  }
  std::stable_sort(order.begin(), order.end(), [depth](int64_t a, int64_t b) { return depth[a] < depth[b]; });
  for (int64_t t = 0; t < n_tiles; ++t) counts[t + 1] += counts[t];
  offsets_out.assign(counts.begin(), counts.end());
  std::vector<int64_t> ids(counts[n_tiles]);
  std::vector<int64_t> cursor(counts.begin(), counts.end() - 1);
  for (int64_t i : order) {
    const Rect& r = rects[i];
    const int64_t base = (i / n) * tx_n * ty_n;
    for (int y = r.y0; y < r.y1; ++y)
      for (int x = r.x0; x < r.x1; ++x) ids[cursor[base + static_cast<int64_t>(y) * tx_n + x]++] = i;
  }
  return ids;
}

}  // namespace gs3d
