#include "sampling/BallGrid.hpp"

#include "sampling/AxisMedian.hpp"
#include "sampling/KeyRadixSort.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

namespace hpds {

namespace {
constexpr std::int64_t kAxisCells = std::int64_t(1) << 21;

inline void prefetch(const void *p) {
#if defined(__GNUC__)
  __builtin_prefetch(p);
#else
  (void)p;
#endif
}

/// Calls emit(keyOf(r), indexOf(r)) for the sorted records r of `v`. The caller reads each element's position in this
/// (spatial) order, scattered in memory: fetch a few ahead.
template <typename Rec, typename KeyOf, typename IndexOf, typename Emit>
void emitInOrder(const PointSet &set, const std::vector<Rec> &v, KeyOf keyOf, IndexOf indexOf, Emit &emit) {
  constexpr std::size_t kAhead = 8;
  for (std::size_t t = 0; t < v.size(); ++t) {
    if (t + kAhead < v.size()) prefetch(set.at(indexOf(v[t + kAhead])));
    emit(keyOf(v[t]), indexOf(v[t]));
  }
}

/// Calls emit(key, i) for the elements of `set` with a cell (keyOf true), by ascending (key, i): stable LSD radix
/// passes of at most 11 bits over the key, the index ascending to begin with. Keys below 2^32 (up to 2^32 cells in
/// the bounding box) travel packed with the index in one word; wider ones (fine radii over a whole frame: a
/// 3.4 cm radius over a 200 m VLS-128 frame needs 39 bits) as (key, index) records (sortByKeyStable), where a
/// comparison sort took 18% of that frame's default normals.
template <typename KeyOf, typename Emit>
void forEachSorted(const PointSet &set, const KeyOf &keyOf, int key_bits, Emit &&emit) {
  if (key_bits <= 32) {
    std::vector<std::uint64_t> v(set.size);
    std::size_t kept = 0;
    for (std::size_t i = 0; i < set.size; ++i) {
      std::uint64_t key;
      if (keyOf(set.at(i), key)) v[kept++] = key << 32 | i;
    }
    v.resize(kept);
    // The index, in the low word, is already ascending.
    const auto packedKey = [](std::uint64_t x) { return x >> 32; };
    sortByKeyStable(v, key_bits, packedKey);
    emitInOrder(set, v, packedKey, [](std::uint64_t x) { return static_cast<std::uint32_t>(x); }, emit);
  } else {
    std::vector<KeyedIndex> v;
    v.reserve(set.size);
    for (std::size_t i = 0; i < set.size; ++i) {
      std::uint64_t key;
      if (keyOf(set.at(i), key)) v.push_back(KeyedIndex{key, static_cast<std::uint32_t>(i)});
    }
    sortByKeyStable(v, key_bits);
    emitInOrder(set, v, [](const KeyedIndex &x) { return x.key; }, [](const KeyedIndex &x) { return x.index; }, emit);
  }
}

/// The elements of `set` that have a cell, sorted by cell: positions and element index by slot, the distinct cell
/// keys and the slot each starts at (one more entry than keys, closing the last cell).
template <typename KeyOf>
void sortIntoCells(const PointSet &set, const KeyOf &keyOf, int key_bits, std::vector<double> &pos,
                   std::vector<std::uint32_t> &index, std::vector<std::uint64_t> &keys,
                   std::vector<std::uint32_t> &starts) {
  pos.resize(3 * set.size);
  index.resize(set.size);
  std::size_t slot = 0;
  forEachSorted(set, keyOf, key_bits, [&](std::uint64_t key, std::uint32_t i) {
    if (keys.empty() || key != keys.back()) {
      keys.push_back(key);
      starts.push_back(static_cast<std::uint32_t>(slot));
    }
    const double *p = set.at(i);
    double *o = &pos[3 * slot];
    o[0] = p[0], o[1] = p[1], o[2] = p[2];
    index[slot++] = i;
  });
  pos.resize(3 * slot);
  index.resize(slot);
  starts.push_back(static_cast<std::uint32_t>(slot));
}

}  // namespace

void BallGridPoints::frame(double radius, const double lo[3], const double hi[3], const PointSet &points) {
  radius_ = radius;
  r2_ = radius * radius;
  // Cells a hair wider than the radius, so that round-off in the cell computation cannot put a point within the
  // radius two cells away from the query's.
  const double edge = radius * (1.0 + 1e-8);
  edge_ = edge;
  inv_ = 1.0 / edge;
  // Two cells of margin below and one above: every cell c of a point has c - 1 >= 0 and c + 1 < dims, so the 27
  // neighbours of a cell are plain key offsets. Keys are linear, x-major and z fastest.
  std::uint64_t dims[3];
  for (int a = 0; a < 3; ++a) {
    // At most 2^21 cells per axis (63-bit keys). Data wider than that (a far cluster, a georeferenced cloud tens of
    // km wide at a fine radius, a glitched return 2 000 km out) is squeezed along that axis: in blocks of 2^10 (or
    // 2^5) cells, only the blocks that hold points count, each run of empty blocks shortened to one. Every cell
    // keeps its neighbours and its order, so the grid visits exactly what an unbounded one would. Only where even
    // the occupied blocks are too many is the axis a window of 2^21 cells centred on the points' median, and what
    // lies beyond it has no cell.
    origin_[a] = lo[a] - 2.0 * edge;
    if ((hi[a] - lo[a]) * inv_ + 4.0 >= static_cast<double>(kAxisCells)) {
      windowed_ = true;
      if (squeeze(a, points)) {
        const SqueezedAxis &sq = squeeze_[a];
        dims[a] = ((std::uint64_t(sq.squeezed.back()) + 2) << sq.shift) + 1;
        limit_[a] = static_cast<double>(dims[a] - 1);
        continue;
      }
      origin_[a] = medianCoordinate(points.base, points.index, points.size, a, lo[a]) -
                   0.5 * static_cast<double>(kAxisCells) * edge - 2.0 * edge;
    }
    const double top = std::floor((hi[a] - origin_[a]) * inv_) + 2.0;  // largest cell + 2
    if (top > static_cast<double>(kAxisCells)) windowed_ = true;
    dims[a] = static_cast<std::uint64_t>(std::min(top, static_cast<double>(kAxisCells)));
    limit_[a] = static_cast<double>(dims[a] - 1);
  }
  stride_y_ = dims[2];
  stride_x_ = dims[1] * dims[2];
  key_bits_ = bitWidth(dims[0] * stride_x_ - 1);
  int col = 0;
  for (std::int64_t dx = -1; dx <= 1; ++dx)
    for (std::int64_t dy = -1; dy <= 1; ++dy)
      column_offset_[col++] =
          static_cast<std::uint64_t>(dx * std::int64_t(stride_x_) + dy * std::int64_t(stride_y_) - 1);
  framed_ = true;
}

bool BallGridPoints::wideCell(double v, int axis, std::int64_t &cell) const {
  // In long double (64-bit mantissa): cell numbers beyond 2^30 would carry more rounding in double than the 1e-8 of
  // a cell that the edge has to spare. Points and queries are numbered by this same expression.
  const long double f = (static_cast<long double>(v) - static_cast<long double>(origin_[axis])) *
                        static_cast<long double>(inv_);
  if (!(std::fabs(f) < 0x1p62L)) return false;  // not finite, or beyond any coordinate a double resolves per cell
  cell = static_cast<std::int64_t>(std::floor(f));
  return true;
}

std::size_t BallGridPoints::SqueezedAxis::slotOf(std::int64_t block) const {
  const std::uint64_t h = static_cast<std::uint64_t>(block) * 0x9E3779B97F4A7C15ull;
  std::size_t slot = static_cast<std::size_t>(h ^ (h >> 29)) & mask;
  while (slot_index[slot] != 0 && slot_block[slot] != block) slot = (slot + 1) & mask;
  return slot;
}

namespace {
/// floor(cell / 2^shift) for negative cells too (an arithmetic shift is implementation-defined before C++20).
std::int64_t blockOf(std::int64_t cell, int shift) {
  return cell >= 0 ? cell >> shift : -(((-cell) - 1) >> shift) - 1;
}
}  // namespace

bool BallGridPoints::squeeze(int axis, const PointSet &points) {
  // Blocks of 1 024 cells first: a frame's bulk is a few of them. Many scattered clusters take blocks of 32.
  for (const int shift : {10, 5})
    if (squeezeBlocks(axis, points, shift)) {
      squeezed_ = true;
      return true;
    }
  return false;
}

bool BallGridPoints::squeezeBlocks(int axis, const PointSet &points, int shift) {
  SqueezedAxis &sq = squeeze_[axis];
  sq = SqueezedAxis{};
  sq.shift = shift;
  // The key has room for this many blocks of 2^shift cells, with one below and one above all of them and the
  // margins: stop collecting beyond it, so that the table stays small (and in the cache) whatever the data.
  const std::size_t max_blocks = (std::size_t(kAxisCells) >> shift) / 2 - 2;
  std::size_t cap = 64;
  sq.slot_block.assign(cap, 0);
  sq.slot_index.assign(cap, 0);
  sq.mask = cap - 1;
  for (std::size_t i = 0; i < points.size; ++i) {
    const double *p = points.at(i);
    std::int64_t cell;
    if (!(std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]) && wideCell(p[axis], axis, cell)))
      continue;
    const std::int64_t block = blockOf(cell, shift);
    const std::size_t slot = sq.slotOf(block);
    if (sq.slot_index[slot] != 0) continue;
    if (sq.blocks.size() >= max_blocks) {
      sq = SqueezedAxis{};
      return false;
    }
    sq.blocks.push_back(block);
    sq.slot_block[slot] = block;
    sq.slot_index[slot] = static_cast<std::uint32_t>(sq.blocks.size());
    if (2 * sq.blocks.size() > cap) {  // at most half full: rebuild twice as large
      cap *= 2;
      sq.mask = cap - 1;
      sq.slot_block.assign(cap, 0);
      sq.slot_index.assign(cap, 0);
      for (std::size_t b = 0; b < sq.blocks.size(); ++b) {
        const std::size_t s2 = sq.slotOf(sq.blocks[b]);
        sq.slot_block[s2] = sq.blocks[b];
        sq.slot_index[s2] = static_cast<std::uint32_t>(b + 1);
      }
    }
  }
  if (sq.blocks.empty()) sq.blocks.push_back(0);  // no finite point: one block, so that the frame is well formed
  // Ascending blocks, the table pointing at their new places.
  std::vector<std::int64_t> sorted = sq.blocks;
  std::sort(sorted.begin(), sorted.end());
  sq.squeezed.assign(sorted.size(), 0);
  // Squeezed blocks from 2 (block 1 stands for every cell below the points', block 0 holds the margin cell):
  // consecutive blocks stay adjacent, a gap of empty blocks becomes one empty block.
  std::uint32_t next = 2;
  for (std::size_t b = 0; b < sorted.size(); ++b) {
    if (b > 0) next += sorted[b] - sorted[b - 1] == 1 ? 1 : 2;
    sq.squeezed[b] = next;
  }
  for (std::size_t slot = 0; slot < sq.slot_index.size(); ++slot)
    if (sq.slot_index[slot] != 0)
      sq.slot_index[slot] = static_cast<std::uint32_t>(
          std::lower_bound(sorted.begin(), sorted.end(), sq.slot_block[slot]) - sorted.begin() + 1);
  sq.blocks = std::move(sorted);
  return true;
}

bool BallGridPoints::squeezedKeyOf(const double *p, std::uint64_t &key) const {
  std::uint64_t c[3];
  for (int a = 0; a < 3; ++a) {
    const SqueezedAxis &sq = squeeze_[a];
    if (!sq.active()) {
      const double f = (p[a] - origin_[a]) * inv_;
      if (!(f >= 1.0 && f < limit_[a])) return false;
      c[a] = static_cast<std::uint64_t>(f);
      continue;
    }
    std::int64_t cell;
    if (!wideCell(p[a], a, cell)) return false;
    const std::int64_t block = blockOf(cell, sq.shift);
    const std::uint64_t offset = static_cast<std::uint64_t>(cell - block * (std::int64_t(1) << sq.shift));
    // A block with points has its own place; an empty one lies between two occupied ones (one empty block there),
    // or below or above all of them, with its cells in their order. A cell of it is then next to cells it is not
    // next to in space: that only costs distance tests, never a neighbour.
    const std::size_t slot = sq.slotOf(block);
    std::uint64_t squeezed;
    if (sq.slot_index[slot] != 0) {
      squeezed = sq.squeezed[sq.slot_index[slot] - 1];
    } else {
      const std::size_t above =
          static_cast<std::size_t>(std::upper_bound(sq.blocks.begin(), sq.blocks.end(), block) - sq.blocks.begin());
      squeezed = above == 0 ? sq.squeezed[0] - 1 : sq.squeezed[above - 1] + 1;
    }
    c[a] = (squeezed << sq.shift) + offset;
  }
  key = c[0] * stride_x_ + c[1] * stride_y_ + c[2];
  return true;
}

void BallGridPoints::sortPoints(const PointSet &points) {
  // Far outliers (outside the 2^21-cell window) and non-finite coordinates have no cell. Positive, so truncation is
  // floor.
  sortIntoCells(points, [this](const double *p, std::uint64_t &key) { return keyOf(p, key); }, key_bits_, pos_, pidx_,
                ckey_, cstart_);
  cells_ = ckey_.size();
  ckey_.insert(ckey_.end(), 3, ~std::uint64_t(0));  // sentinels: above any key (keys stay below 2^63)
}

BallGridPoints::BallGridPoints(const PointSet &points, double radius, const double lo[3], const double hi[3]) {
  if (!(radius > 0.0) || !std::isfinite(radius)) return;
  for (int a = 0; a < 3; ++a)
    if (!(std::isfinite(lo[a]) && std::isfinite(hi[a]) && lo[a] <= hi[a])) return;
  frame(radius, lo, hi, points);
  sortPoints(points);
}

BallGridPoints::BallGridPoints(const BallGridPoints &finer, int doublings, const PointSet &points, const double lo[3],
                               const double hi[3]) {
  const double radius = std::ldexp(finer.radius_, doublings);
  if (!(radius > 0.0) || !std::isfinite(radius)) return;
  for (int a = 0; a < 3; ++a)
    if (!(std::isfinite(lo[a]) && std::isfinite(hi[a]) && lo[a] <= hi[a])) return;
  frame(radius, lo, hi, points);
  if (!groupFrom(finer, doublings)) sortPoints(points);
}

bool BallGridPoints::groupFrom(const BallGridPoints &finer, int doublings) {
  if (doublings < 1 || doublings > 20 || !finer.framed_ || finer.windowed_ || windowed_) return false;
  // Edges: radius * (1 + 1e-8) at both, so this one is exactly 2^doublings of finer's; origins: box corner minus two
  // edges at both, so in exact arithmetic finer's lies 2^(doublings + 1) - 2 finer cells above this one. A finer cell
  // i is then inside cell (i + 2^(doublings + 1) - 2) >> doublings. Each origin is rounded on its own, which moves
  // the grouped cells' faces against the ones queries are keyed by: a point within the radius of a query is still
  // in one of the 27 cells around the query's while that shift stays below the 1e-8 of the radius that cells have
  // to spare. Far from the origin with small radii (coordinates beyond ~3e7 radii: a 5 cm footprint at a UTM
  // northing) one ulp of the corner exceeds half of that: then this grid is sorted afresh.
  if (std::ldexp(inv_, doublings) != finer.inv_) return false;
  const std::uint64_t add = (std::uint64_t(2) << doublings) - 2;
  for (int a = 0; a < 3; ++a) {
    const double shift = (finer.origin_[a] - origin_[a]) - static_cast<double>(add) * finer.edge_;
    // Half the spare width: the other half covers the rounding of the keys themselves (below ~1e-9 of a cell
    // at 2^21 cells per axis).
    if (!(std::fabs(shift) <= 0.5e-8 * edge_)) return false;
  }
  const std::size_t cells = finer.cells_;
  // The finer cells' coordinates, tracked as their keys ascend (x-major): a new x is a division, a new y within it
  // one by reciprocal (exact after one correction: the remainder is below 2^42).
  const double inv_stride_y = 1.0 / static_cast<double>(finer.stride_y_);
  std::uint64_t ix = 0, iy = 0, x_base = 0, y_base = 0;
  auto coarseKey = [&](std::uint64_t key, std::uint64_t &out) {
    if (key >= x_base + finer.stride_x_) {
      ix = key / finer.stride_x_;
      x_base = ix * finer.stride_x_;
      iy = 0, y_base = x_base;
    }
    if (key >= y_base + finer.stride_y_) {
      const std::uint64_t rem = key - x_base;
      iy = static_cast<std::uint64_t>(static_cast<double>(rem) * inv_stride_y);
      while (iy * finer.stride_y_ > rem) --iy;
      while ((iy + 1) * finer.stride_y_ <= rem) ++iy;
      y_base = x_base + iy * finer.stride_y_;
    }
    const std::uint64_t iz = key - y_base;
    const std::uint64_t cx = (ix + add) >> doublings, cy = (iy + add) >> doublings, cz = (iz + add) >> doublings;
    // Inside this frame's cells with a neighbour on each side, as keyOf guarantees (the frames' rounding could put
    // the last cell one further): else sorted afresh.
    if (!(static_cast<double>(cx) < limit_[0] && static_cast<double>(cy) < limit_[1] &&
          static_cast<double>(cz) < limit_[2]))
      return false;
    out = cx * stride_x_ + cy * stride_y_ + cz;
    return true;
  };
  // Coarse key and finer cell: packed in one word when the key fits 32 bits (as forEachSorted), else as records;
  // finer cells come in ascending key order, which the stable sort keeps within a coarse cell.
  std::vector<std::uint64_t> packed;
  std::vector<KeyedIndex> v;
  if (key_bits_ <= 32) {
    packed.resize(cells);
    for (std::size_t c = 0; c < cells; ++c) {
      std::uint64_t k;
      if (!coarseKey(finer.ckey_[c], k)) return false;
      packed[c] = k << 32 | c;
    }
    sortByKeyStable(packed, key_bits_, [](std::uint64_t x) { return x >> 32; });
  } else {
    v.resize(cells);
    for (std::size_t c = 0; c < cells; ++c) {
      std::uint64_t k;
      if (!coarseKey(finer.ckey_[c], k)) return false;
      v[c] = KeyedIndex{k, static_cast<std::uint32_t>(c)};
    }
    sortByKeyStable(v, key_bits_);
  }
  pos_.resize(finer.pos_.size());
  pidx_.resize(finer.pidx_.size());
  ckey_.clear();
  cstart_.clear();
  std::size_t slot = 0;
  auto emit = [&](std::uint64_t key, std::size_t c) {
    if (ckey_.empty() || key != ckey_.back()) {
      ckey_.push_back(key);
      cstart_.push_back(static_cast<std::uint32_t>(slot));
    }
    const std::size_t b = finer.cstart_[c], e = finer.cstart_[c + 1];
    std::copy(finer.pos_.begin() + 3 * b, finer.pos_.begin() + 3 * e, pos_.begin() + 3 * slot);
    std::copy(finer.pidx_.begin() + b, finer.pidx_.begin() + e, pidx_.begin() + slot);
    slot += e - b;
  };
  for (const std::uint64_t x : packed) emit(x >> 32, static_cast<std::uint32_t>(x));
  for (const KeyedIndex &r : v) emit(r.key, r.index);
  cstart_.push_back(static_cast<std::uint32_t>(slot));
  cells_ = ckey_.size();
  ckey_.insert(ckey_.end(), 3, ~std::uint64_t(0));  // sentinels, as sortPoints
  return true;
}

std::size_t BallGridPoints::memUsage() const {
  std::size_t squeeze = 0;
  for (const SqueezedAxis &sq : squeeze_)
    squeeze += (sq.blocks.capacity() + sq.slot_block.capacity()) * sizeof(std::int64_t) +
               (sq.squeezed.capacity() + sq.slot_index.capacity()) * sizeof(std::uint32_t);
  return pos_.capacity() * sizeof(double) + pidx_.capacity() * sizeof(std::uint32_t) +
         ckey_.capacity() * sizeof(std::uint64_t) + cstart_.capacity() * sizeof(std::uint32_t) + squeeze;
}

BallGrid::BallGrid(const PointSet &points, const PointSet &queries, double radius) {
  if (!(radius > 0.0) || !std::isfinite(radius) || queries.size == 0) return;
  same_ = points == queries;
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  auto extend = [&](const PointSet &set) {
    for (std::size_t i = 0; i < set.size; ++i) {
      const double *p = set.at(i);
      if (!(std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]))) continue;
      for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], p[a]), hi[a] = std::max(hi[a], p[a]);
    }
  };
  extend(points);
  if (!same_) extend(queries);
  if (!(lo[0] <= hi[0])) return;  // nothing finite
  own_ = BallGridPoints(points, radius, lo, hi);
  if (same_) {
    qorder_ = own_.pidx_.data();
    qcell_key_ = own_.ckey_.data();
    qcell_start_ = own_.cstart_.data();
    qcells_ = own_.cells_;
    return;
  }
  sortQueries(queries);
}

BallGrid::BallGrid(const BallGridPoints &points, const PointSet &queries) : pts_(&points) {
  if (!points.framed_ || queries.size == 0) return;
  sortQueries(queries);
}

void BallGrid::sortQueries(const PointSet &queries) {
  const BallGridPoints &pts = *pts_;
  sortIntoCells(queries, [&pts](const double *p, std::uint64_t &key) { return pts.keyOf(p, key); }, pts.key_bits_,
                qpos_, qorder_own_, qkey_own_, qstart_own_);
  qorder_ = qorder_own_.data();
  qcell_key_ = qkey_own_.data();
  qcell_start_ = qstart_own_.data();
  qcells_ = qkey_own_.size();
}

void BallGrid::initCursors(std::size_t c, std::size_t cursor[9]) const {
  const std::uint64_t *ckey = pts_->ckey_.data();
  const std::size_t cells = pts_->cells_;
  for (int col = 0; col < 9; ++col)
    cursor[col] =
        static_cast<std::size_t>(std::lower_bound(ckey, ckey + cells, qcell_key_[c] + pts_->column_offset_[col]) - ckey);
}

std::size_t BallGrid::columns(std::size_t c, std::size_t cursor[9], std::uint32_t b[9], std::uint32_t e[9]) const {
  const std::uint64_t key = qcell_key_[c];
  const BallGridPoints &pts = *pts_;
  const std::uint64_t *ckey = pts.ckey_.data();  // followed by 3 sentinels, so ckey[cur + 2] is readable
  const std::size_t cells = pts.cells_;
  const std::uint32_t *cstart = pts.cstart_.data();
  std::size_t total = 0;
  for (int col = 0; col < 9; ++col) {
    const std::uint64_t lo = key + pts.column_offset_[col], hi = lo + 2;
    std::size_t cur = cursor[col];
    // Forward: usually 0..2 cells (branch-free), else a few more steps or a binary search over a long gap.
    cur += ckey[cur] < lo ? 1 : 0;
    cur += ckey[cur] < lo ? 1 : 0;
    if (ckey[cur] < lo) {
      if (ckey[cur + 2] < lo) cur = static_cast<std::size_t>(std::lower_bound(ckey + cur + 2, ckey + cells, lo) - ckey);
      while (ckey[cur] < lo) ++cur;
    }
    cursor[col] = cur;
    // The column's cells lo..hi are among the next 3 keys (sorted, distinct).
    const std::size_t end = cur + (ckey[cur] <= hi ? 1 : 0) + (ckey[cur + 1] <= hi ? 1 : 0) + (ckey[cur + 2] <= hi ? 1 : 0);
    b[col] = cstart[cur];
    e[col] = cstart[end];
    total += e[col] - b[col];
  }
  return total;
}

}  // namespace hpds
