// MapNormals: the normal a map keeps for each of its samples, estimated from the frames that hit the sample.
//
// Why map mode keeps normals instead of estimating them from the map when asked: that estimate averaged the map's
// levels L+1..L+neighborhood_level_offset, and building those levels was most of a map-mode frame's cost (a
// 64-beam synthetic drive at the defaults: 270 ms of insertion per frame with them, 45 ms without, and five times
// the samples held). Each frame instead averages its own points per cell of the fine level, as scan mode does,
// for the output samples it hits; a sample keeps the estimate from the frame that saw it from closest, where the
// scan lines around it lie densest, unless that frame left it on one scan line and another did not: a line-like
// neighbourhood pins no plane (a wall grazed by a closer frame's one ring; planar_urban's wall p90 44 degrees with
// closeness alone, 12 with this rule).
//
// Contract
// - Indexed by sample id. Ids of evicted samples are reused, so a new sample's slot is emptied (resetSlots) before
//   anything is offered for it.
// - An entry is empty, invalid (no frame so far gave a normal: too few neighbours) or valid; a valid one is
//   line-like (its neighbourhood's l1 < line_ratio * l2, NormalParams::line_ratio) or planar. offer() replaces an
//   empty entry; a valid estimate replaces an invalid one, a line-like one by a planar one from any distance, and
//   one of its own kind from farther away; on a tie the first stays, so the result depends only on the frames and
//   their order.
// - Not thread-safe; const members may run concurrently.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "hpds/normals/LocalPca.hpp"
#include "hpds/normals/NormalEstimator.hpp"
#include "hpds/sampling/Hierarchy.hpp"

namespace hpds {

class MapNormals {
 public:
  /// Forgets every entry (a replaced map).
  void clear() { std::vector<Entry>().swap(entries_); }
  /// Grows to `id_bound` slots and empties those of `fresh` (samples new since the last call).
  void resetSlots(const std::vector<SampleId> &fresh, std::size_t id_bound);
  /// Of `hit`, the samples a frame seen from `viewpoint` (fixed frame) could give a better entry: empty, invalid,
  /// line-like, or valid from farther away. `ranges` gets their distances to the viewpoint, same order.
  /// `line_ratio`: NormalParams::line_ratio of the normals kept and offered.
  [[nodiscard]] std::vector<SampleId> improvable(const Hierarchy &hierarchy, const std::vector<SampleId> &hit,
                                                 const double viewpoint[3], double line_ratio,
                                                 std::vector<float> &ranges) const;
  /// Offers an estimate for `id` from a frame `range` metres away (see contract), judged with `line_ratio` as above.
  void offer(SampleId id, const SampleNormal &normal, const LocalPca &neighbourhood, float range, double line_ratio);
  /// The valid normal kept for `id` and the neighbourhood it came from (its normal and eigenvalues; float
  /// precision); false when there is none.
  bool lookup(SampleId id, SampleNormal &normal, LocalPca *neighbourhood) const;
  [[nodiscard]] std::size_t memUsage() const { return entries_.capacity() * sizeof(Entry); }

  /// Bytes of one entry in a map file (HierarchyFile.cpp): f32 normal[3], curvature, l0 l1 l2, range, u8 state.
  static constexpr std::size_t kFileBytes = 8 * 4 + 1;
  /// Writes `id`'s entry (an empty one when there is none) as kFileBytes bytes.
  void save(SampleId id, std::uint8_t *out) const;
  /// Sets `id`'s entry from kFileBytes bytes; false (nothing set) when they hold no entry this build writes.
  bool restore(SampleId id, const std::uint8_t *in);

 private:
  enum : std::uint8_t { kEmpty = 0, kInvalid = 1, kValid = 2 };
  struct Entry {
    float normal[3] = {0.f, 0.f, 0.f};
    float curvature = 0.f;
    float eigen[3] = {0.f, 0.f, 0.f};  ///< l0 l1 l2 of the neighbourhood (covariances tell line-like ones apart)
    float range = 0.f;                 ///< [m] sensor distance of the frame that gave it
    std::uint8_t state = kEmpty;
  };
  /// In float, as kept: an entry and the estimate it is compared with are judged alike.
  [[nodiscard]] static bool lineLike(float l1, float l2, double line_ratio) {
    return l1 < static_cast<float>(line_ratio) * l2;
  }
  /// `id`'s entry, growing the table (empty entries) to hold it.
  Entry &slot(SampleId id) {
    if (id >= entries_.size()) entries_.resize(std::size_t(id) + 1);
    return entries_[id];
  }
  std::vector<Entry> entries_;
};

}  // namespace hpds
