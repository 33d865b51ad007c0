// LevelGrid: the sparse grid of one hierarchy level, cell key -> sample id, at most one sample per cell.
//
// Contract
// - Open addressing with linear probing over 16-byte slots (three int32 coordinates + the id), no per-insert
//   allocation; erase uses backward-shift deletion so lookups never scan tombstones.
// - Iteration order depends on the insertion history only (no pointers, no randomisation): deterministic.
// - Move-only; not thread-safe for concurrent mutation; concurrent const lookups are safe.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "hpds/CellKey.hpp"

namespace hpds {

using SampleId = std::uint32_t;
inline constexpr SampleId kNoSample = 0xFFFFFFFFu;

class LevelGrid {
 public:
  LevelGrid() = default;
  LevelGrid(const LevelGrid &) = delete;
  LevelGrid &operator=(const LevelGrid &) = delete;
  LevelGrid(LevelGrid &&) noexcept = default;
  LevelGrid &operator=(LevelGrid &&) noexcept = default;

  /// Sample in `key`'s cell, or kNoSample.
  [[nodiscard]] SampleId find(const CellKey &key) const {
    if (slots_.empty()) return kNoSample;
    for (std::size_t i = hash(key) & mask_;; i = (i + 1) & mask_) {
      const Slot &s = slots_[i];
      if (s.id == kNoSample) return kNoSample;
      if (s.x == key.x && s.y == key.y && s.z == key.z) return s.id;
    }
  }
  /// Stores `id` in a free cell; returns false (and stores nothing) when the cell is occupied.
  bool insert(const CellKey &key, SampleId id);
  /// Frees `key`'s cell; returns false when it was free.
  bool erase(const CellKey &key);
  /// Frees memory too.
  void clear();
  /// Empties the grid but keeps its capacity (scan mode refills a similar amount every frame).
  void reset();

  [[nodiscard]] std::size_t size() const { return size_; }
  [[nodiscard]] std::size_t capacity() const { return slots_.size(); }
  [[nodiscard]] std::size_t memUsage() const { return slots_.capacity() * sizeof(Slot); }

  /// Calls fn(const CellKey&, SampleId) for every occupied cell.
  template <typename Fn>
  void forEach(Fn &&fn) const {
    for (const Slot &s : slots_)
      if (s.id != kNoSample) fn(CellKey{s.x, s.y, s.z}, s.id);
  }

 private:
  struct Slot {
    std::int32_t x, y, z;
    SampleId id;
  };
  static std::size_t hash(const CellKey &k) {
    std::uint64_t h = static_cast<std::uint64_t>(static_cast<std::uint32_t>(k.x)) * 0x9E3779B97F4A7C15ull;
    h ^= static_cast<std::uint64_t>(static_cast<std::uint32_t>(k.y)) * 0xC2B2AE3D27D4EB4Full;
    h ^= static_cast<std::uint64_t>(static_cast<std::uint32_t>(k.z)) * 0x165667B19E3779F9ull;
    h ^= h >> 31;
    h *= 0xBF58476D1CE4E5B9ull;
    h ^= h >> 29;
    return static_cast<std::size_t>(h);
  }
  void rehash(std::size_t new_capacity);

  std::vector<Slot> slots_;
  std::size_t size_ = 0;
  std::size_t mask_ = 0;
};

}  // namespace hpds
