#include "normals/CellCentroids.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "hpds/util/Interrupt.hpp"
#include "sampling/KeyRadixSort.hpp"

namespace hpds {

namespace {

/// Centroids of runs of equal cells: `count` points in cell order, sameCell(a, b) comparing two of them, pointAt(t)
/// giving the t-th point's coordinates.
template <typename SameCell, typename PointAt>
std::vector<double> runCentroids(std::size_t count, SameCell &&sameCell, PointAt &&pointAt) {
  // Cell order visits the points at scattered places: fetching a few ahead took this loop from 60% of the function's
  // time (a cache miss per point) to a fifth of it.
  constexpr std::size_t kAhead = 8;
  std::vector<double> out;
  out.reserve(3 * count);
  for (std::size_t b = 0; b < count;) {
    std::size_t e = b;
    double s[3] = {0.0, 0.0, 0.0};
    for (; e < count && sameCell(b, e); ++e) {
      if (e + kAhead < count) __builtin_prefetch(pointAt(e + kAhead));
      const double *p = pointAt(e);
      s[0] += p[0], s[1] += p[1], s[2] += p[2];
    }
    const double inv = 1.0 / static_cast<double>(e - b);
    out.push_back(s[0] * inv);
    out.push_back(s[1] * inv);
    out.push_back(s[2] * inv);
    b = e;
  }
  return out;
}

/// Far outliers: cells as (x, y, z) doubles, compared exactly (a rare path, so a comparison sort).
std::vector<double> wideCentroids(const double *xyz, const std::uint32_t *indices, std::size_t count, double inv) {
  struct Cell {
    double c[3];
    std::uint32_t index;
  };
  std::vector<Cell> cells;
  cells.reserve(count);
  for (std::size_t i = 0; i < count; ++i) {
    const double *p = xyz + 3 * std::size_t(indices[i]);
    const Cell c{{std::floor(p[0] * inv), std::floor(p[1] * inv), std::floor(p[2] * inv)}, indices[i]};
    if (std::isfinite(c.c[0]) && std::isfinite(c.c[1]) && std::isfinite(c.c[2])) cells.push_back(c);
  }
  std::stable_sort(cells.begin(), cells.end(), [](const Cell &a, const Cell &b) {
    return a.c[0] != b.c[0] ? a.c[0] < b.c[0] : a.c[1] != b.c[1] ? a.c[1] < b.c[1] : a.c[2] < b.c[2];
  });
  return runCentroids(
      cells.size(),
      [&](std::size_t a, std::size_t b) {
        return cells[a].c[0] == cells[b].c[0] && cells[a].c[1] == cells[b].c[1] && cells[a].c[2] == cells[b].c[2];
      },
      [&](std::size_t t) { return xyz + 3 * std::size_t(cells[t].index); });
}

}  // namespace

std::vector<double> cellCentroids(const double *xyz, const std::uint32_t *indices, std::size_t count, double edge,
                                  double *box, const std::atomic<bool> *interrupt) {
  if (box) std::fill(box, box + 6, std::numeric_limits<double>::quiet_NaN());
  if (count == 0 || !(edge > 0.0) || !std::isfinite(edge)) return {};
  const double inv = 1.0 / edge;
  // Cell coordinates of every point, floor(p / edge) by truncation and a correction below zero (baseline x86-64 has
  // no rounding instruction: std::floor is a libm call there, a third of this function's time). Within +-2^30 cells
  // they fit int32 with room for the offsets below; anything else takes the wide path.
  constexpr double kLimit = 1073741824.0;  // 2^30
  std::vector<std::int32_t> cell(3 * count);
  // The running bounds in scalars: as arrays indexed by axis, GCC kept them in memory, a store-to-load chain per
  // coordinate that cost more than the rest of this loop.
  std::int32_t lo0 = INT32_MAX, lo1 = INT32_MAX, lo2 = INT32_MAX, hi0 = INT32_MIN, hi1 = INT32_MIN, hi2 = INT32_MIN;
  std::size_t kept = 0;
  std::vector<std::uint32_t> pos(count);  // input position of the kept points
  const auto floorOf = [](double v) {
    const std::int32_t t = static_cast<std::int32_t>(v);
    return t - (v < static_cast<double>(t) ? 1 : 0);
  };
  for (std::size_t i = 0; i < count; ++i) {
    const double *p = xyz + 3 * std::size_t(indices[i]);
    const double q0 = p[0] * inv, q1 = p[1] * inv, q2 = p[2] * inv;
    if (!(std::fabs(q0) < kLimit && std::fabs(q1) < kLimit && std::fabs(q2) < kLimit)) {
      if (std::isfinite(q0) && std::isfinite(q1) && std::isfinite(q2)) return wideCentroids(xyz, indices, count, inv);
      continue;  // a non-finite coordinate
    }
    const std::int32_t c0 = floorOf(q0), c1 = floorOf(q1), c2 = floorOf(q2);
    std::int32_t *c = &cell[3 * kept];
    c[0] = c0, c[1] = c1, c[2] = c2;
    lo0 = std::min(lo0, c0), lo1 = std::min(lo1, c1), lo2 = std::min(lo2, c2);
    hi0 = std::max(hi0, c0), hi1 = std::max(hi1, c1), hi2 = std::max(hi2, c2);
    pos[kept++] = static_cast<std::uint32_t>(i);
  }
  if (kept == 0) return {};
  throwIfInterrupted(interrupt, "averaging the points per cell");
  const std::int32_t lo[3] = {lo0, lo1, lo2}, hi[3] = {hi0, hi1, hi2};
  if (box)  // a cell of margin on each side absorbs the round-off of p * inv
    for (int a = 0; a < 3; ++a) {
      box[a] = (static_cast<double>(lo[a]) - 1.0) * edge;
      box[3 + a] = (static_cast<double>(hi[a]) + 2.0) * edge;
    }
  int bits[3];
  for (int a = 0; a < 3; ++a) bits[a] = bitWidth(static_cast<std::uint64_t>(std::int64_t(hi[a]) - lo[a]));
  const int key_bits = bits[0] + bits[1] + bits[2];  // <= 3 * 31
  const int pos_bits = bitWidth(kept - 1);
  auto keyOf = [&](std::size_t t) {
    const std::int32_t *c = &cell[3 * t];
    return static_cast<std::uint64_t>(std::int64_t(c[0]) - lo[0]) << (bits[1] + bits[2]) |
           static_cast<std::uint64_t>(std::int64_t(c[1]) - lo[1]) << bits[2] |
           static_cast<std::uint64_t>(std::int64_t(c[2]) - lo[2]);
  };
  auto pointAt = [&](std::uint32_t t) { return xyz + 3 * std::size_t(indices[pos[t]]); };
  if (key_bits + pos_bits <= 64) {
    // The usual case: key and position packed in one word (the position, in the low bits, keeps equal keys stable).
    std::vector<std::uint64_t> v(kept);
    for (std::size_t t = 0; t < kept; ++t) v[t] = keyOf(t) << pos_bits | t;
    sortByKeyStable(v, key_bits, [&](std::uint64_t x) { return x >> pos_bits; });
    throwIfInterrupted(interrupt, "averaging the points per cell");
    return runCentroids(
        kept, [&](std::size_t a, std::size_t b) { return (v[a] >> pos_bits) == (v[b] >> pos_bits); },
        [&](std::size_t t) { return pointAt(static_cast<std::uint32_t>(v[t] & ((std::uint64_t(1) << pos_bits) - 1))); });
  }
  if (key_bits <= 64) {
    std::vector<KeyedIndex> v(kept);
    for (std::size_t t = 0; t < kept; ++t) v[t] = KeyedIndex{keyOf(t), static_cast<std::uint32_t>(t)};
    sortByKeyStable(v, key_bits);
    throwIfInterrupted(interrupt, "averaging the points per cell");
    return runCentroids(
        kept, [&](std::size_t a, std::size_t b) { return v[a].key == v[b].key; },
        [&](std::size_t t) { return pointAt(v[t].index); });
  }
  return wideCentroids(xyz, indices, count, inv);
}

}  // namespace hpds
