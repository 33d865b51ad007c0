#include "hpds/sampling/Hierarchy.hpp"

#include <algorithm>
#include <cstring>
#include <numeric>
#include <stdexcept>
#include <string>

#include "hpds/util/Interrupt.hpp"

namespace hpds {

Hierarchy::Hierarchy(double cell_size, int max_depth) : cell_size_(cell_size), max_depth_(max_depth) {
  if (!(cell_size > 0.0) || !std::isfinite(cell_size))
    throw std::invalid_argument("hierarchy.cell_size: must be a finite number > 0");
  if (max_depth < 0 || max_depth > kMaxDepthLimit)
    throw std::invalid_argument("hierarchy.max_depth: must be in 0..21, got " + std::to_string(max_depth));
  for (int d = 0; d <= max_depth; ++d) {
    edge_[d] = std::ldexp(cell_size, -d);  // exact: a power-of-two scaling
    inv_edge_[d] = 1.0 / edge_[d];
    radius_[d] = 0.5 * std::sqrt(3.0) * edge_[d];
    radius2_[d] = radius_[d] * radius_[d];
  }
  grids_.resize(static_cast<std::size_t>(max_depth) + 1);
  pending_.resize(static_cast<std::size_t>(max_depth) + 2);  // [max_depth + 1]: dropped, so rejection never branches
}

void Hierarchy::setRecordLayout(const PointLayout &layout) {
  if (layout == record_layout_) return;
  if (live_ > 0 || !level_.empty())
    throw std::invalid_argument("point layout differs from the layout of the samples already in the map");
  layout.validate();
  record_layout_ = layout;
}

bool Hierarchy::keyAt(int level, const double q[3], CellKey &key) const {
  const double e = edge_[level], ie = inv_edge_[level];
  if (!inCellRange(q[0], ie) || !inCellRange(q[1], ie) || !inCellRange(q[2], ie)) return false;
  key = CellKey{exactCellCoord(q[0], e, ie), exactCellCoord(q[1], e, ie), exactCellCoord(q[2], e, ie)};
  return true;
}

SampleId Hierarchy::sampleInCell(int level, const double xyz[3]) const {
  CellKey k;
  if (level < 0 || level > max_depth_ || !keyAt(level, xyz, k)) return kNoSample;
  return grids_[level].find(k);
}

template <typename Test>
double Hierarchy::walkConflicts(const LevelGrid &grid, double e, const double q[3], const CellKey &k, double radius,
                                const LevelGrid::KnownBlock *known, Test &&test) const {
  // radius <= sqrt(3)/2 * e, so the ball never reaches past the 26 neighbours.
  // A neighbour side is taken only when even the rounding-widened ball reaches it.
  const double reach = radius + pruneSlack(q, e);
  const double prune = reach * reach;
  const std::int32_t kc[3] = {k.x, k.y, k.z};
  std::int32_t c0[3], c1[3];
  for (int a = 0; a < 3; ++a) {
    const double below = offsetInCell(q[a], kc[a], e), above = e - below;
    c0[a] = kc[a] - (below * below <= prune ? 1 : 0);
    c1[a] = kc[a] + (above * above <= prune ? 1 : 0);
  }
  // The window covers one or two blocks per axis; corner cells the ball misses cost a distance test only when
  // occupied.
  double found = -1.0;
  grid.anyInBox(
      CellKey{c0[0], c0[1], c0[2]}, CellKey{c1[0], c1[1], c1[2]},
      [&](SampleId s, const LevelGrid::Block &b, unsigned bit) {
        found = test(s, b, bit);
        return found >= 0.0;
      },
      known);
  return found;
}

double Hierarchy::conflictWith(SampleId s, const double q[3], double r2, SampleId &witness) const {
  const double d2 = distance2(position(s), q);
  if (!(d2 < r2)) return -1.0;
  witness = s;
  return d2;
}

double Hierarchy::conflictIn(const LevelGrid &grid, double e, const double q[3], const CellKey &k, double radius,
                             SampleId &witness, const LevelGrid::KnownBlock *known) const {
  const double r2 = radius * radius;
  return walkConflicts(grid, e, q, k, radius, known,
                       [&](SampleId s, const LevelGrid::Block &, unsigned) { return conflictWith(s, q, r2, witness); });
}

double Hierarchy::passConflict(int level, const double q[3], const CellKey &k, SampleId &witness,
                               const LevelGrid::KnownBlock &own) const {
  const double r2 = radius2_[level];
  return walkConflicts(pass_grid_, edge_[level], q, k, radius_[level], &own,
                       [&](SampleId s, const LevelGrid::Block &b, unsigned bit) {
                         if (!(s & kSharedCell)) return conflictWith(s, q, r2, witness);
                         const double d2 = conflictWith(s & ~kSharedCell, q, r2, witness);
                         if (d2 >= 0.0) return d2;
                         return conflictWith(shared_.find(LevelGrid::cellAt(b, bit)), q, r2, witness);
                       });
}

SampleId Hierarchy::allocate() {
  if (!free_ids_.empty()) {
    const SampleId id = free_ids_.back();
    free_ids_.pop_back();
    return id;
  }
  return appendSlot();
}

SampleId Hierarchy::appendSlot() {
  if (level_.size() >= kNoSample) throw std::length_error("hierarchy: more than 2^32-1 sample slots");
  const SampleId id = static_cast<SampleId>(level_.size());
  if (level_.size() == level_.capacity()) {
    // Grow by an eighth instead of doubling: per-sample arrays are most of a long-running map's memory, and a map
    // with eviction reaches its size once (the copies stay amortised O(1) per sample). The fixed headroom is 1024
    // slots, but at most 64 MiB of records: with 16 MiB records 1024 slots were 16 GiB for a map file's first
    // sample or free slot (a forged 415-byte file asked for that).
    const std::size_t step = std::max<std::size_t>(1, record_layout_.point_step);
    const std::size_t headroom = std::max<std::size_t>(1, std::min<std::size_t>(1024, (std::size_t(64) << 20) / step));
    const std::size_t cap = level_.size() + level_.size() / 8 + headroom;
    level_.reserve(cap);
    frame_.reserve(cap);
    view_.reserve(cap);
    xyz_.reserve(3 * cap);
    records_.reserve(cap * record_layout_.point_step);
  }
  level_.push_back(kFreeSlotLevel);
  frame_.push_back(0);
  view_.push_back(0);
  xyz_.resize(xyz_.size() + 3);
  records_.resize(records_.size() + record_layout_.point_step);
  return id;
}

void Hierarchy::release(SampleId id) {
  CellKey k;
  const int l = level_[id];
  if (keyAt(l, position(id), k)) grids_[l].erase(k);
  level_[id] = kFreeSlotLevel;
  free_ids_.push_back(id);
  --live_;
}

// Forced inline, like the pass loop's other helpers: it runs once per witness-cache miss.
__attribute__((always_inline)) inline int Hierarchy::checkTry(int d, const double *q, const CellKey &finest,
                                                              bool pass_valid, int finest_populated, int last,
                                                              SampleId &witness) const {
  const double rd2 = radius2_[d];
  const CellKey key = coarsen(finest, d);
  if (pass_valid) {
    // The cell is taken when its occupant is of level d, or is a coarser sample that shares it with one.
    const LevelGrid::KnownBlock own = ownBlock(pass_grid_, key);
    const SampleId occupant = ownOccupant(pass_grid_, own);
    if (occupant != kNoSample) {
      const SampleId c = occupant & ~kSharedCell;
      const double d2 = distance2(position(c), q);
      if ((occupant & kSharedCell) || level_[c] == d || d2 < rd2) {
        witness = c;
        return nextLevelAfterConflict(d, d2, last);
      }
    }
    const double d2 = passConflict(d, q, key, witness, own);
    if (d2 >= 0.0) return nextLevelAfterConflict(d, d2, last);
  } else {
    const LevelGrid::KnownBlock own = ownBlock(grids_[d], key);
    const SampleId occupant = ownOccupant(grids_[d], own);
    if (occupant != kNoSample) {
      witness = occupant;
      return nextLevelAfterConflict(d, distance2(position(occupant), q), last);
    }
    double d2 = conflictIn(grids_[d], edge_[d], q, key, radius_[d], witness, &own);
    for (int l = d - 1; d2 < 0.0 && l >= 0; --l) d2 = conflictAt(l, q, coarsen(finest, l), radius_[d], witness);
    if (d2 >= 0.0) return nextLevelAfterConflict(d, d2, last);
  }
  // Samples of finer levels (earlier batches) keep their own, smaller radius. A conflict at level l rules out every
  // level <= l, so the point continues at l + 1 (or later, as above). Such a sample is no witness for level d, so it
  // is not reported (the caller would cache it).
  SampleId finer = kNoSample;
  for (int l = finest_populated; l > d; --l) {
    const double d2 = conflictAt(l, q, coarsen(finest, l), radius_[l], finer);
    if (d2 >= 0.0) return std::max(l + 1, nextLevelAfterConflict(d, d2, last));
  }
  return d;
}

__attribute__((always_inline)) inline void Hierarchy::store(int d, const InsertBatch &batch, std::uint32_t pi,
                                                            const double *q, const CellKey &finest, bool pass_valid,
                                                            InsertResult &result) {
  const CellKey key = coarsen(finest, d);
  const SampleId id = allocate();
  std::memcpy(&xyz_[3 * std::size_t(id)], q, 3 * sizeof(double));
  level_[id] = static_cast<std::uint8_t>(d);
  frame_[id] = batch.frame_index;
  view_[id] = encodeViewDirection(batch.viewpoint[0] - q[0], batch.viewpoint[1] - q[1], batch.viewpoint[2] - q[2]);
  if (batch.records && record_layout_.point_step)
    std::memcpy(&records_[std::size_t(id) * record_layout_.point_step], batch.records + pi * batch.record_step,
                record_layout_.point_step);
  grids_[d].insert(key, id);
  if (pass_valid && !pass_grid_.insert(key, id)) {
    // A coarser sample holds the cell (a level-d one would have taken it): both stay findable.
    const SampleId c = pass_grid_.find(key);
    pass_grid_.erase(key);
    pass_grid_.insert(key, c | kSharedCell);
    shared_.insert(key, id);
  }
  ++live_;
  ++result.accepted_per_level[d];
  result.accepted.push_back(id);
  accepted_keys_.push_back(finest);
  if (batch.published && d <= batch.publish_level) {
    batch.published[result.published++] = pi;
    if ((result.published & 63) == 0) batch.published_count->store(result.published, std::memory_order_release);
  }
}

InsertResult Hierarchy::insert(const InsertBatch &batch) {
  InsertResult result;
  if (batch.records && batch.record_step != record_layout_.point_step)
    throw std::invalid_argument("insert: record_step does not match the record layout");
  if (batch.published && !batch.published_count) throw std::invalid_argument("insert: published without a count");

  // Highest level holding samples from earlier batches: only those need the finer-level check.
  int finest_populated = -1;
  for (int l = max_depth_; l >= 0; --l)
    if (grids_[l].size() > 0) {
      finest_populated = l;
      break;
    }

  // The finest-level cell of every point, computed exactly once; coarser cells are shifts of it. One range check
  // at the finest level covers every coarser level.
  const std::size_t n = batch.order_size;
  const std::size_t words = (n + 63) / 64;
  for (auto &p : pending_) p.assign(words, 0);
  ranked_.resize(n);
  accepted_keys_.clear();
  const double ef = edge_[max_depth_], ief = inv_edge_[max_depth_];
  for (std::uint32_t rank = 0; rank < n; ++rank) {
    // Ranks visit the points at random places: fetch a few ahead so the loads overlap.
    if (rank + kPrefetchDistance < n) __builtin_prefetch(batch.xyz + 3 * std::size_t(batch.order[rank + kPrefetchDistance]));
    const double *q = batch.xyz + 3 * std::size_t(batch.order[rank]);
    if (inCellRange(q[0], ief) && inCellRange(q[1], ief) && inCellRange(q[2], ief)) {
      RankedPoint &rp = ranked_[rank];
      std::memcpy(rp.xyz, q, 3 * sizeof(double));
      rp.finest = CellKey{exactCellCoord(q[0], ef, ief), exactCellCoord(q[1], ef, ief), exactCellCoord(q[2], ef, ief)};
      schedule(0, rank);
    } else {
      ++result.out_of_range;
    }
  }

  // Witness cache: points that are close to each other are mostly rejected by the same nearby sample, so the
  // sample that last decided a point is tried first for the points near it (one distance test instead of a grid
  // walk). A hit is a genuine conflict whatever the slot held, so a stale or colliding slot costs only a miss.
  // At most 2^15 slots (1 MB): a larger table no longer fits the cache beside the grids, and on frames where most
  // tries miss anyway (a third of the points accepted) its loads cost more than the hits save (VLS-128, 209 k
  // points: 4 MB -> 1 MB took insertion from 121 to 112 ms; the denser frames are unchanged).
  std::size_t slots = 1024;
  while (slots < n / 2 && slots < (std::size_t(1) << 15)) slots <<= 1;
  witness_.assign(slots, WitnessSlot{});
  const int slot_shift = 64 - __builtin_ctzll(slots);

  const int last_level = batch.max_level < 0 ? max_depth_ : std::min(batch.max_level, max_depth_);
  for (int d = 0; d <= last_level; ++d) {
    throwIfInterrupted(batch.interrupt, "inserting");
    const double rd2 = radius2_[d];
    // When the batch started on an empty hierarchy (scan mode), the samples of levels < d are exactly those accepted
    // so far: one grid of level d's cells holding them, and the level-d samples as they come, replaces the d + 1
    // per-level grid walks of a check. No two samples of levels < d share a level-d cell (they are at least
    // r_(d-1) apart, the cell's diagonal); a level-d sample in a cell that a coarser one holds is kept in shared_
    // and the cell's id carries kSharedCell. Should rounding ever put two coarser samples in one cell, or ids reach
    // the flag bit, the pass uses the per-level walks, as map mode does.
    bool pass_valid = finest_populated < 0 && level_.size() + n < kSharedCell;
    if (pass_valid) {
      pass_grid_.reset();
      shared_.reset();
      for (std::size_t i = 0; i < result.accepted.size(); ++i)
        pass_valid &= pass_grid_.insert(coarsen(accepted_keys_[i], d), result.accepted[i]);
    }
    const int group_level = std::min(d + kWitnessGroupOffset, max_depth_);
    const std::vector<std::uint64_t> &todo = pending_[d];
    // A pass visits its points in rank order: their positions and cells are in address order (ranked_), but their
    // witness slots are at random places, so a cursor running a few points ahead prefetches each one's slot and
    // hands its hash on.
    struct Ahead {
      std::uint32_t rank;
      std::uint64_t hash;
    };
    Ahead ring[kPrefetchDistance + 1];
    std::size_t head = 0, tail = 0, ahead_w = 0;
    std::uint64_t ahead_bits = words ? todo[0] : 0;
    // Forced inline: GCC kept it as a call (10% of an HDL-32 insertion profile).
    auto pushAhead = [&]() __attribute__((always_inline)) {
      while (ahead_bits == 0) {
        if (++ahead_w >= words) return;
        // Every 2^18 ranks: a pass over millions of points took 1.4 s, too long for Ctrl-C to wait on.
        if ((ahead_w & 4095) == 0) throwIfInterrupted(batch.interrupt, "inserting");
        ahead_bits = todo[ahead_w];
      }
      const std::uint32_t r = static_cast<std::uint32_t>(ahead_w * 64 + static_cast<std::size_t>(__builtin_ctzll(ahead_bits)));
      ahead_bits &= ahead_bits - 1;
      const std::uint64_t hr = witnessHash(coarsen(ranked_[r].finest, group_level), d);
      __builtin_prefetch(&witness_[hr >> slot_shift]);
      ring[head] = Ahead{r, hr};
      head = head == kPrefetchDistance ? 0 : head + 1;
    };
    for (int i = 0; i < kPrefetchDistance; ++i) pushAhead();
    while (tail != head) {
      const Ahead cur = ring[tail];
      tail = tail == kPrefetchDistance ? 0 : tail + 1;
      pushAhead();
      const std::uint32_t rank = cur.rank;
      const double *q = ranked_[rank].xyz;
      const CellKey &finest = ranked_[rank].finest;
      const std::uint64_t h = cur.hash;
      WitnessSlot &slot = witness_[h >> slot_shift];
      {
        // An empty slot holds (0,0,0) with tag 0: the distance is computed anyway and ignored, one branch less.
        const double d2 = distance2(slot.xyz, q);
        if ((slot.tag == h) & (d2 < rd2)) {
          schedule(nextLevelAfterConflict(d, d2, last_level), rank);
          continue;
        }
      }
      // From here on the point may be accepted: start fetching its record while the neighbourhood is checked.
      const std::uint32_t pi = batch.order[rank];
      if (batch.records) __builtin_prefetch(batch.records + std::size_t(pi) * batch.record_step);
      SampleId witness = kNoSample;
      const int next = checkTry(d, q, finest, pass_valid, finest_populated, last_level, witness);
      if (next == d) {
        store(d, batch, pi, q, finest, pass_valid, result);
        slot.remember(h, q);
      } else {
        if (witness != kNoSample) slot.remember(h, position(witness));
        schedule(next, rank);
      }
    }
    if (batch.published_count) batch.published_count->store(result.published, std::memory_order_release);
  }
  // Points still scheduled past the last level tried (at most max_depth + 1) are dropped.
  for (int l = last_level + 1; l <= max_depth_ + 1; ++l)
    for (const std::uint64_t word : pending_[l]) result.dropped_depth += LevelGrid::bitCount(word);
  return result;
}

SampleId Hierarchy::restoreSample(const double xyz[3], int level, std::uint32_t frame_index, const float to_viewpoint[3],
                                  const std::uint8_t *record) {
  if (level < 0 || level > max_depth_) throw std::invalid_argument("restored sample has level " + std::to_string(level));
  const double lim = inv_edge_[max_depth_];
  if (!inCellRange(xyz[0], lim) || !inCellRange(xyz[1], lim) || !inCellRange(xyz[2], lim))
    throw std::invalid_argument("restored sample lies beyond the exact key range");
  CellKey key;
  keyAt(level, xyz, key);
  if (grids_[level].find(key) != kNoSample)
    throw std::invalid_argument("restored sample's level-" + std::to_string(level) + " cell is already occupied");
  const SampleId id = allocate();
  std::memcpy(&xyz_[3 * std::size_t(id)], xyz, 3 * sizeof(double));
  level_[id] = static_cast<std::uint8_t>(level);
  frame_[id] = frame_index;
  view_[id] = encodeViewDirection(to_viewpoint[0], to_viewpoint[1], to_viewpoint[2]);
  if (record_layout_.point_step) {
    std::uint8_t *dst = &records_[std::size_t(id) * record_layout_.point_step];
    if (record)
      std::memcpy(dst, record, record_layout_.point_step);
    else
      std::memset(dst, 0, record_layout_.point_step);
  }
  grids_[level].insert(key, id);
  ++live_;
  return id;
}

void Hierarchy::restoreFreeSlot() { (void)appendSlot(); }

void Hierarchy::restoreFreeOrder(const std::vector<SampleId> &order) {
  const std::size_t free_slots = level_.size() - live_;
  if (order.size() != free_slots)
    throw std::invalid_argument("the free slots' order lists " + std::to_string(order.size()) + " ids for " +
                                std::to_string(free_slots) + " free slots");
  std::vector<std::uint8_t> seen(level_.size(), 0);
  for (const SampleId id : order) {
    if (id >= level_.size() || level_[id] != kFreeSlotLevel || seen[id])
      throw std::invalid_argument("the free slots' order names id " + std::to_string(id) +
                                  (id >= level_.size()     ? ", beyond every slot"
                                   : seen[id]              ? " twice"
                                                           : ", which holds a sample"));
    seen[id] = 1;
  }
  free_ids_ = order;
}

std::size_t Hierarchy::evictOutside(const double center[3], double distance) {
  const double r2 = distance * distance;
  std::size_t n = 0;
  for (SampleId id = 0; id < level_.size(); ++id) {
    if (level_[id] == kFreeSlotLevel) continue;
    if (distance2(position(id), center) > r2) {
      release(id);
      ++n;
    }
  }
  return n;
}

std::size_t Hierarchy::evictToCap(const double center[3], std::size_t max_samples) {
  if (live_ <= max_samples) return 0;
  const std::size_t excess = live_ - max_samples;
  // Farthest first, ties broken by id (deterministic). A list of every sample's distance would cost 16 B per sample
  // at the cap (160 MB at map.max_samples' default, every frame once it is reached); a histogram over the top 16 bits
  // of the squared distance (non-negative doubles order as their bit patterns) finds the boundary bin instead, and
  // only that bin's samples are ranked.
  auto binOf = [](double d2) {
    std::uint64_t bits;
    std::memcpy(&bits, &d2, sizeof bits);
    return static_cast<std::uint32_t>(bits >> 48);
  };
  std::vector<std::uint32_t> count(std::size_t{1} << 16, 0);
  for (SampleId id = 0; id < level_.size(); ++id)
    if (level_[id] != kFreeSlotLevel) ++count[binOf(distance2(position(id), center))];
  std::uint32_t edge = static_cast<std::uint32_t>(count.size() - 1);
  std::size_t beyond = 0;  // samples in bins above `edge`: all evicted
  while (beyond + count[edge] < excess) beyond += count[edge--];
  std::vector<std::pair<double, SampleId>> at_edge;
  at_edge.reserve(count[edge]);
  for (SampleId id = 0; id < level_.size(); ++id) {
    if (level_[id] == kFreeSlotLevel) continue;
    const double d2 = distance2(position(id), center);
    const std::uint32_t bin = binOf(d2);
    if (bin > edge)
      release(id);
    else if (bin == edge)
      at_edge.emplace_back(d2, id);
  }
  const std::size_t rest = excess - beyond;
  std::nth_element(at_edge.begin(), at_edge.begin() + static_cast<std::ptrdiff_t>(rest), at_edge.end(),
                   [](const auto &a, const auto &b) {
                     return a.first != b.first ? a.first > b.first : a.second < b.second;
                   });
  for (std::size_t i = 0; i < rest; ++i) release(at_edge[i].second);
  return excess;
}

void Hierarchy::shrink() {
  for (auto &g : grids_)
    if (g.size() == 0) g.clear();
  xyz_.shrink_to_fit();
  level_.shrink_to_fit();
  frame_.shrink_to_fit();
  view_.shrink_to_fit();
  records_.shrink_to_fit();
  free_ids_.shrink_to_fit();
  std::vector<RankedPoint>().swap(ranked_);  // `= {}` would keep the capacity
  std::vector<CellKey>().swap(accepted_keys_);
  pass_grid_.clear();
  shared_.clear();
  std::vector<WitnessSlot>().swap(witness_);
  for (auto &p : pending_) std::vector<std::uint64_t>().swap(p);
}

void Hierarchy::clear() {
  for (auto &g : grids_) g.reset();
  xyz_.clear();
  level_.clear();
  frame_.clear();
  view_.clear();
  records_.clear();
  free_ids_.clear();
  live_ = 0;
}

std::vector<SampleId> Hierarchy::samplesUpTo(int max_level) const {
  std::vector<SampleId> ids;
  std::size_t n = 0;
  for (int l = 0; l <= std::min(max_level, max_depth_); ++l) n += grids_[l].size();
  ids.reserve(n);
  for (SampleId id = 0; id < level_.size(); ++id)
    if (level_[id] != kFreeSlotLevel && level_[id] <= max_level) ids.push_back(id);
  return ids;
}

std::size_t Hierarchy::memUsage() const {
  std::size_t bytes = 0;
  for (const auto &g : grids_) bytes += g.memUsage();
  bytes += xyz_.capacity() * sizeof(double) + level_.capacity() + frame_.capacity() * sizeof(std::uint32_t) +
           view_.capacity() * sizeof(std::uint32_t) + records_.capacity() + free_ids_.capacity() * sizeof(SampleId);
  return bytes;
}

std::size_t Hierarchy::scratchBytes() const {
  std::size_t bytes = ranked_.capacity() * sizeof(RankedPoint) + accepted_keys_.capacity() * sizeof(CellKey) +
                      witness_.capacity() * sizeof(WitnessSlot) + pass_grid_.memUsage() + shared_.memUsage();
  for (const auto &p : pending_) bytes += p.capacity() * sizeof(std::uint64_t);
  return bytes;
}

}  // namespace hpds
