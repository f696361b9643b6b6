// Tile binning on the CPU (what tiles.py does in torch, for the cpu backend): each visible
// (camera, Gaussian) pair is listed in every tile its alpha >= 1/255 ellipse (capped at 3 sigma)
// can reach, front to back. Pairs are visited in depth order and appended to their tiles'
// buckets, so each tile's list comes out sorted without a per-tile sort. The depth order is an LSD
// radix sort on the depths' bits (stable, like tiles.py's torch.argsort(stable=True); digits that
// all keys share are skipped), a few linear passes instead of a comparison sort.
#pragma once
#include <omp.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <numeric>
#include <type_traits>
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

// Order-preserving unsigned key of a float/double (negative values flipped entirely, positive
// ones get the sign bit set), so unsigned comparison of keys is numeric comparison of values.
template <typename T>
inline auto sort_key(T v) {
  using U = std::conditional_t<sizeof(T) == 8, uint64_t, uint32_t>;
  U u;
  std::memcpy(&u, &v, sizeof(T));
  constexpr U sign = U(1) << (8 * sizeof(T) - 1);
  return (u & sign) ? U(~u) : U(u | sign);
}

// Stable LSD radix sort (8-bit digits) of `idx` by `depth[idx]`.
template <typename T>
void radix_sort_by_depth(std::vector<int64_t>& idx, const T* depth) {
  using U = decltype(sort_key(T(0)));
  const size_t n = idx.size();
  if (n < 2) return;
  std::vector<U> key(n), key2(n);
  std::vector<int64_t> idx2(n);
  for (size_t i = 0; i < n; ++i) key[i] = sort_key(depth[idx[i]]);
  for (unsigned shift = 0; shift < 8 * sizeof(U); shift += 8) {
    std::array<size_t, 257> cnt{};
    for (size_t i = 0; i < n; ++i) ++cnt[((key[i] >> shift) & 0xFF) + 1];
    if (*std::max_element(cnt.begin() + 1, cnt.end()) == n) continue;  // every key has this digit
    for (int b = 0; b < 256; ++b) cnt[b + 1] += cnt[b];
    for (size_t i = 0; i < n; ++i) {
      const size_t dst = cnt[(key[i] >> shift) & 0xFF]++;
      key2[dst] = key[i];
      idx2[dst] = idx[i];
    }
    key.swap(key2);
    idx.swap(idx2);
  }
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
  radix_sort_by_depth<T>(order, depth);
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
