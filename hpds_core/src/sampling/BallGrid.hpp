// BallGrid: the fixed-radius neighbourhoods of many query positions at once (normal estimation).
//
// Contract
// - Built from a point set, a query set (each: 3 doubles per element, read during construction only) and a radius
//   R. A query's neighbours are the points at squared distance ax*ax + ay*ay + az*az < R*R, the axis differences
//   taken in double as point - query: the same test, bit for bit, as FrameGridIndex.
// - Neighbours are visited in a fixed order (the 27 cells of edge ~R around the query's cell by x, then y, then z;
//   a cell's points by increasing index, or, in a grid grouped from a finer one, in that grid's order), so anything
//   computed from them is independent of how the queries are split among threads.
// - Keys address at most 2^21 cells per axis, counted from the data's bounding-box corner. Where the data is wider
//   (far clusters, a far outlier), that axis is squeezed: runs of empty cells between the points' cells shrink to
//   one, which keeps every neighbour and the visiting order. Only with more than ~2^20 distinct occupied cells along
//   such an axis is it a window of 2^21 cells centred on the points' median instead; points or queries outside it
//   are left out (no neighbours / never visited). Const; visit() may run concurrently on disjoint ranges.
// - The point side can be sorted ahead, over a box given instead of the data's bounding box (BallGridPoints), and
//   then serve query sets that lie in that box.
//
// Why it is fast: points and queries are both sorted by a linear cell key (x-major, z fastest; LSD radix sort, no
// hashing). Queries of one cell share the search for the 27 cells around it, which are 9 contiguous runs of the
// sorted points (the 3 cells along z of an (x, y) column are adjacent keys) found by 9 cursors that only move
// forward as the query cells ascend. A query is then one pass over those runs, sequential in memory, with a
// branch-free distance test; its position is read from a sorted copy, never from scattered memory.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace hpds {

/// Positions of a point set: element i is at base + 3 * index[i] (index null: base + 3 * i).
struct PointSet {
  const double *base = nullptr;
  const std::uint32_t *index = nullptr;
  std::size_t size = 0;
  [[nodiscard]] const double *at(std::size_t i) const { return base + 3 * std::size_t(index ? index[i] : i); }
  [[nodiscard]] bool operator==(const PointSet &o) const {
    return base == o.base && index == o.index && size == o.size;
  }
};

/// One query's neighbourhood, valid only during the callback. Points are addressed by their slot in the grid's
/// cell-sorted arrays.
struct BallView {
  const double *q;              ///< the query position (3 doubles)
  const double *xyz;            ///< positions of all grid points by slot (3 doubles each, absolute)
  const std::uint32_t *point;   ///< point index (element of the point set) by slot
  const std::uint32_t *inside;  ///< slots of the points strictly within the radius, in visiting order
  const double *d2;             ///< d2[t]: squared distance of neighbour inside[t] to the query
  std::size_t count;            ///< number of neighbours
};

/// The point side of a BallGrid: the points sorted into cells of edge ~R laid over a box given up front, so that it
/// can be built before the queries are known (the pipeline builds it while a frame is inserted) and serve several
/// query sets of that radius. A BallGrid over it only visits queries inside the box. Two of these over the same
/// points, radius and box visit every query's neighbours in the same order. Const after construction.
class BallGridPoints {
 public:
  /// lo/hi: the box (both corners finite, lo <= hi on every axis); points outside it are left out, as far outliers.
  BallGridPoints(const PointSet &points, double radius, const double lo[3], const double hi[3]);
  /// The same points and box at radius finer.radius() * 2^doublings (doublings >= 1): the cells nest (each is a block
  /// of finer's cells, the frame aligned to finer's), so the points are grouped from finer's cells, not sorted again,
  /// and a cell's points come in finer's cell order (then finer's order inside each) instead of by index. Where
  /// finer's or this frame is a window over wide data, sorted from `points` as the other constructor does.
  BallGridPoints(const BallGridPoints &finer, int doublings, const PointSet &points, const double lo[3],
                 const double hi[3]);
  [[nodiscard]] double radius() const { return radius_; }
  /// Bytes held.
  [[nodiscard]] std::size_t memUsage() const;

 private:
  friend class BallGrid;
  BallGridPoints() = default;
  /// The cell frame over lo..hi; `points` only matter when that is wider than 2^21 cells on some axis (see .cpp).
  void frame(double radius, const double lo[3], const double hi[3], const PointSet &points);
  /// The cell key of p, false when p has no cell (outside the frame or not finite).
  bool keyOf(const double *p, std::uint64_t &key) const {
    if (squeezed_) return squeezedKeyOf(p, key);
    const double fx = (p[0] - origin_[0]) * inv_, fy = (p[1] - origin_[1]) * inv_, fz = (p[2] - origin_[2]) * inv_;
    if (!(fx >= 1.0 && fx < limit_[0] && fy >= 1.0 && fy < limit_[1] && fz >= 1.0 && fz < limit_[2])) return false;
    key = static_cast<std::uint64_t>(fx) * stride_x_ + static_cast<std::uint64_t>(fy) * stride_y_ +
          static_cast<std::uint64_t>(fz);
    return true;
  }
  /// keyOf where some axis is squeezed (see frame()).
  bool squeezedKeyOf(const double *p, std::uint64_t &key) const;
  /// Squeezes `axis` over the points' cells when that fits 2^21 cells; false (nothing changed) otherwise.
  bool squeeze(int axis, const PointSet &points);
  /// Squeezes `axis` in blocks of 2^shift cells when the points occupy few enough of them.
  bool squeezeBlocks(int axis, const PointSet &points, int shift);
  /// The unbounded cell number of coordinate v on a squeezed axis (origin_ and inv_ in extended precision), false
  /// when v is not finite or too far out to number.
  bool wideCell(double v, int axis, std::int64_t &cell) const;
  void sortPoints(const PointSet &points);

  /// The cells of this frame from finer's (see the nesting constructor); false when the frames do not nest.
  bool groupFrom(const BallGridPoints &finer, int doublings);

  double radius_ = 0.0, r2_ = 0.0;
  bool framed_ = false;  ///< false: no finite box, no cells
  bool windowed_ = false;  ///< some axis is a window over wider data (or capped at 2^21 cells): no nesting
  double origin_[3] = {}, limit_[3] = {}, inv_ = 0.0, edge_ = 0.0;
  std::uint64_t stride_x_ = 0, stride_y_ = 0;
  int key_bits_ = 0;
  std::uint64_t column_offset_[9] = {};  // key offset of the (dx, dy) columns' dz = -1 cell
  // A squeezed axis (wide data): blocks of 2^shift cells; the blocks that hold points, ascending, the block each is
  // in the key, and an open-addressing table of them (slot -> index + 1, 0 = free) for the points' own lookups.
  struct SqueezedAxis {
    int shift = 0;
    std::vector<std::int64_t> blocks;
    std::vector<std::uint32_t> squeezed;
    std::vector<std::int64_t> slot_block;
    std::vector<std::uint32_t> slot_index;
    std::size_t mask = 0;
    [[nodiscard]] bool active() const { return !blocks.empty(); }
    /// The table slot holding `block`, or the free slot where it would go.
    [[nodiscard]] std::size_t slotOf(std::int64_t block) const;
  };
  bool squeezed_ = false;
  SqueezedAxis squeeze_[3];
  // Points sorted by cell: positions and point index by slot; distinct cells (keys, then 3 sentinels) with
  // the slot of their first point (cells_ + 1 entries).
  std::vector<double> pos_;  // 3 per slot: a candidate's coordinates share a cache line
  std::vector<std::uint32_t> pidx_;
  std::vector<std::uint64_t> ckey_;
  std::vector<std::uint32_t> cstart_;
  std::size_t cells_ = 0;
};

class BallGrid {
 public:
  /// `queries` may be the very same set as `points` (same base, index and size): then one sort serves both.
  BallGrid(const PointSet &points, const PointSet &queries, double radius);
  /// Over points sorted ahead; `points` must outlive the grid. Queries outside its box are never visited.
  BallGrid(const BallGridPoints &points, const PointSet &queries);
  // Holds a pointer to its own point side.
  BallGrid(const BallGrid &) = delete;
  BallGrid &operator=(const BallGrid &) = delete;

  /// Number of distinct query cells; visit() takes ranges of them (parallelFor over [0, cellCount())).
  [[nodiscard]] std::size_t cellCount() const { return qcell_start_ ? qcells_ : 0; }

  /// Calls fn(query_index, const BallView &) for every query of cells [begin, end), sequentially, with scratch
  /// local to the call. Queries of a cell whose 27 cells hold fewer than `min_count` points are skipped (they
  /// cannot have that many neighbours).
  template <typename Fn>
  void visit(std::size_t begin, std::size_t end, Fn &&fn, std::size_t min_count = 0) const;

 private:
  /// Slot ranges [b[col], e[col]) of the 9 (x, y) columns of 3 cells around query cell c, and their total size;
  /// the cursors only move forward over ascending query cells.
  std::size_t columns(std::size_t c, std::size_t cursor[9], std::uint32_t b[9], std::uint32_t e[9]) const;
  void initCursors(std::size_t c, std::size_t cursor[9]) const;
  void sortQueries(const PointSet &queries);

  BallGridPoints own_;                   ///< the point side when built here
  const BallGridPoints *pts_ = &own_;  ///< the point side in use
  // Queries sorted by cell (the point arrays themselves when the sets are the same): query index and position
  // by sorted position, distinct query cells with their first sorted position.
  bool same_ = false;
  std::vector<std::uint32_t> qorder_own_;
  std::vector<double> qpos_;
  std::vector<std::uint64_t> qkey_own_;
  std::vector<std::uint32_t> qstart_own_;
  const std::uint32_t *qorder_ = nullptr;
  const std::uint64_t *qcell_key_ = nullptr;
  const std::uint32_t *qcell_start_ = nullptr;
  std::size_t qcells_ = 0;
};

template <typename Fn>
void BallGrid::visit(std::size_t begin, std::size_t end, Fn &&fn, std::size_t min_count) const {
  if (begin >= end) return;
  std::vector<std::uint32_t> inside;
  std::vector<double> d2;
  std::size_t cursor[9];
  initCursors(begin, cursor);
  const double r2 = pts_->r2_;
  const double *pos = pts_->pos_.data();
  for (std::size_t c = begin; c < end; ++c) {
    std::uint32_t rb[9], re[9];
    const std::size_t total = columns(c, cursor, rb, re);
    if (total < min_count) continue;
    if (inside.size() < total) inside.resize(2 * total), d2.resize(2 * total);
    std::uint32_t *in = inside.data();
    double *dd = d2.data();
    for (std::uint32_t k = qcell_start_[c]; k < qcell_start_[c + 1]; ++k) {
      const double *q = same_ ? &pos[3 * std::size_t(k)] : &qpos_[3 * std::size_t(k)];
      const double qx = q[0], qy = q[1], qz = q[2];
      std::size_t m = 0;
      for (int col = 0; col < 9; ++col) {
        std::uint32_t j = rb[col];
#if defined(__SSE2__)
        // Two slots at a time: their six coordinates are three 16-byte loads, and every sum below is the scalar
        // loop's, in its order ((x^2 + y^2) + z^2), so the distances are the same bits.
        const __m128d qxy = _mm_set_pd(qy, qx), qzx = _mm_set_pd(qx, qz), qyz = _mm_set_pd(qz, qy);
        const __m128d lim = _mm_set1_pd(r2);
        for (; j + 1 < re[col]; j += 2) {
          const double *p = pos + 3 * std::size_t(j);
          const __m128d u = _mm_sub_pd(_mm_loadu_pd(p), qxy);      // x0 y0
          const __m128d v = _mm_sub_pd(_mm_loadu_pd(p + 2), qzx);  // z0 x1
          const __m128d w = _mm_sub_pd(_mm_loadu_pd(p + 4), qyz);  // y1 z1
          const __m128d sa = _mm_mul_pd(u, u), sb = _mm_mul_pd(v, v), sc = _mm_mul_pd(w, w);
          const __m128d xx = _mm_shuffle_pd(sa, sb, 2), yy = _mm_shuffle_pd(sa, sc, 1), zz = _mm_shuffle_pd(sb, sc, 2);
          const __m128d d = _mm_add_pd(_mm_add_pd(xx, yy), zz);
          const int kept = _mm_movemask_pd(_mm_cmplt_pd(d, lim));
          in[m] = j;  // branch-free compaction: the slot is kept only if the test passes
          _mm_store_sd(&dd[m], d);
          m += kept & 1;
          in[m] = j + 1;
          _mm_storeh_pd(&dd[m], d);
          m += kept >> 1;
        }
#endif
        for (; j < re[col]; ++j) {
          const double *p = pos + 3 * std::size_t(j);
          const double ax = p[0] - qx, ay = p[1] - qy, az = p[2] - qz;
          const double d = ax * ax + ay * ay + az * az;
          in[m] = j;
          dd[m] = d;
          m += d < r2 ? 1 : 0;
        }
      }
      fn(std::size_t(qorder_[k]), BallView{q, pos, pts_->pidx_.data(), in, dd, m});
    }
  }
}

}  // namespace hpds
