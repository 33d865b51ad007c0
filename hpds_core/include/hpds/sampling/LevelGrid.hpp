// LevelGrid: the sparse grid of one hierarchy level, cell key -> sample id, at most one sample per cell.
//
// Contract
// - Cells are grouped in blocks of 4x4x4. A flat open-addressing hash (linear probing, backward-shift deletion)
//   maps a block key to a 64-bit occupancy mask and an offset into one shared id pool, where the block's ids are
//   stored compactly in mask-bit order. A neighbourhood query therefore hashes once per block (one to eight per
//   3x3x3 neighbourhood) and answers "empty" from the mask alone; no per-insert allocation beyond pool growth.
// - Iteration order depends on the insertion history only (no pointers, no randomisation): deterministic.
// - Move-only; not thread-safe for concurrent mutation; concurrent const lookups are safe.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "hpds/sampling/CellKey.hpp"

namespace hpds {

using SampleId = std::uint32_t;
inline constexpr SampleId kNoSample = 0xFFFFFFFFu;

namespace detail {
// Per axis and [lo, hi] (index lo * 4 + hi): the cells of a 4x4x4 block whose local coordinate on that axis lies in
// [lo, hi]; a cell's bit is x | y << 2 | z << 4.
struct BlockAxisMasks {
  std::uint64_t m[3][16];
};
constexpr BlockAxisMasks makeBlockAxisMasks() {
  BlockAxisMasks t{};
  for (int lo = 0; lo < 4; ++lo)
    for (int hi = lo; hi < 4; ++hi)
      for (unsigned bit = 0; bit < 64; ++bit) {
        const int c[3] = {static_cast<int>(bit & 3), static_cast<int>((bit >> 2) & 3), static_cast<int>(bit >> 4)};
        for (int a = 0; a < 3; ++a)
          if (c[a] >= lo && c[a] <= hi) t.m[a][lo * 4 + hi] |= std::uint64_t(1) << bit;
      }
  return t;
}
inline constexpr BlockAxisMasks kBlockAxisMasks = makeBlockAxisMasks();
}  // namespace detail

class LevelGrid {
 public:
  /// Cells per block along each axis is 1 << kBlockShift.
  static constexpr int kBlockShift = 2;

  /// One block: which of its 64 cells hold a sample, and where their ids start in the pool. Blocks with an empty
  /// mask do not exist (a zero mask marks a free hash slot).
  struct Block {
    std::int32_t x, y, z;  ///< block coordinates (cell coordinates >> kBlockShift)
    std::uint32_t base;    ///< the id itself when one cell is occupied, else the first id of this block in the pool
    std::uint64_t mask;    ///< bit (cx | cy << 2 | cz << 4) set when that local cell is occupied
  };

  LevelGrid() = default;
  LevelGrid(const LevelGrid &) = delete;
  LevelGrid &operator=(const LevelGrid &) = delete;
  LevelGrid(LevelGrid &&) noexcept = default;
  LevelGrid &operator=(LevelGrid &&) noexcept = default;

  /// The block with block coordinates (bx, by, bz), or nullptr when none of its cells is occupied. The pointer is
  /// valid until the next mutation.
  [[nodiscard]] const Block *findBlock(std::int32_t bx, std::int32_t by, std::int32_t bz) const {
    if (size_ == 0) return nullptr;
    for (std::size_t i = hash(bx, by, bz) & mask_;; i = (i + 1) & mask_) {
      const Block &b = slots_[i];
      if (b.mask == 0) return nullptr;
      if (b.x == bx && b.y == by && b.z == bz) return &b;
    }
  }
  /// Set bits of m. Baseline x86-64 has no popcnt instruction and __builtin_popcountll becomes a libgcc call, which
  /// showed up at 3% of an insertion profile; this is a handful of inline integer operations.
  [[nodiscard]] static unsigned bitCount(std::uint64_t m) {
    m = m - ((m >> 1) & 0x5555555555555555ull);
    m = (m & 0x3333333333333333ull) + ((m >> 2) & 0x3333333333333333ull);
    m = (m + (m >> 4)) & 0x0F0F0F0F0F0F0F0Full;
    return static_cast<unsigned>((m * 0x0101010101010101ull) >> 56);
  }
  /// Cells of a block whose local coordinate along `axis` (0 = x, 1 = y, 2 = z) lies in [lo, hi], 0 <= lo <= hi <= 3.
  /// AND-ing the three axes gives the cells of a block inside a box of cells, so a box query reads only occupied
  /// cells of the blocks it overlaps.
  [[nodiscard]] static std::uint64_t axisMask(int axis, int lo, int hi) { return detail::kBlockAxisMasks.m[axis][lo * 4 + hi]; }
  /// Index of a cell inside its block.
  [[nodiscard]] static unsigned localBit(std::int32_t x, std::int32_t y, std::int32_t z) {
    return static_cast<unsigned>((x & 3) | ((y & 3) << 2) | ((z & 3) << 4));
  }
  /// Sample in local cell `bit` of block `b`, or kNoSample.
  [[nodiscard]] SampleId idAt(const Block &b, unsigned bit) const {
    const std::uint64_t m = std::uint64_t(1) << bit;
    if (!(b.mask & m)) return kNoSample;
    if ((b.mask & (b.mask - 1)) == 0) return b.base;
    return ids_[b.base + bitCount(b.mask & (m - 1))];
  }

  /// Key of local cell `bit` of block `b`.
  [[nodiscard]] static CellKey cellAt(const Block &b, unsigned bit) {
    constexpr std::int32_t n = 1 << kBlockShift;
    return CellKey{b.x * n + static_cast<std::int32_t>(bit & 3), b.y * n + static_cast<std::int32_t>((bit >> 2) & 3),
                   b.z * n + static_cast<std::int32_t>(bit >> 4)};
  }

  /// A block the caller has already looked up (`block`, nullptr when it does not exist), so that a box walk does not
  /// hash it again, and the cells of it (`skip`, a mask of local bits) the walk must leave out.
  struct KnownBlock {
    std::int32_t x, y, z;  ///< block coordinates
    const Block *block;
    std::uint64_t skip;
  };

  /// Calls fn(id, block, bit) for the occupied cells with lo <= key <= hi on each axis; each block the box overlaps
  /// is hashed once (`known` instead, when it is that block) and only its occupied cells inside the box are read.
  /// Stops, and returns true, as soon as fn returns true.
  template <typename Fn>
  bool anyInBox(const CellKey &lo, const CellKey &hi, Fn &&fn, const KnownBlock *known = nullptr) const {
    if (size_ == 0) return false;
    constexpr int sh = kBlockShift, n = 1 << kBlockShift;  // block coordinates are scaled by n, not shifted:
    // a left shift of a negative value is undefined in C++17
    for (std::int32_t bz = lo.z >> sh; bz <= (hi.z >> sh); ++bz) {
      const std::uint64_t zm = axisMask(2, std::max(lo.z - bz * n, 0), std::min(hi.z - bz * n, 3));
      for (std::int32_t by = lo.y >> sh; by <= (hi.y >> sh); ++by) {
        const std::uint64_t yzm = zm & axisMask(1, std::max(lo.y - by * n, 0), std::min(hi.y - by * n, 3));
        for (std::int32_t bx = lo.x >> sh; bx <= (hi.x >> sh); ++bx) {
          const bool is_known = known && bx == known->x && by == known->y && bz == known->z;
          const Block *b = is_known ? known->block : findBlock(bx, by, bz);
          if (!b) continue;
          std::uint64_t bits = b->mask & yzm & axisMask(0, std::max(lo.x - bx * n, 0), std::min(hi.x - bx * n, 3));
          if (is_known) bits &= ~known->skip;
          for (; bits != 0; bits &= bits - 1) {
            const unsigned bit = static_cast<unsigned>(__builtin_ctzll(bits));
            if (fn(idAt(*b, bit), *b, bit)) return true;
          }
        }
      }
    }
    return false;
  }

  /// Calls fn(SampleId) for every occupied cell with lo <= key <= hi on each axis (anyInBox without stopping).
  template <typename Fn>
  void forEachInBox(const CellKey &lo, const CellKey &hi, Fn &&fn) const {
    anyInBox(lo, hi, [&](SampleId id, const Block &, unsigned) {
      fn(id);
      return false;
    });
  }

  /// Sample in `key`'s cell, or kNoSample.
  [[nodiscard]] SampleId find(const CellKey &key) const {
    const Block *b = findBlock(key.x >> kBlockShift, key.y >> kBlockShift, key.z >> kBlockShift);
    return b ? idAt(*b, localBit(key.x, key.y, key.z)) : kNoSample;
  }
  /// Stores `id` in a free cell; returns false (and stores nothing) when the cell is occupied.
  bool insert(const CellKey &key, SampleId id);
  /// Frees `key`'s cell; returns false when it was free.
  bool erase(const CellKey &key);
  /// Frees memory too.
  void clear();
  /// Empties the grid but keeps its capacity (scan mode refills a similar amount every frame).
  void reset();

  /// Occupied cells.
  [[nodiscard]] std::size_t size() const { return size_; }
  /// Hash slots for blocks (a full scan visits every slot).
  [[nodiscard]] std::size_t capacity() const { return slots_.size(); }
  [[nodiscard]] std::size_t memUsage() const;

  /// Calls fn(const CellKey&, SampleId) for every occupied cell.
  template <typename Fn>
  void forEach(Fn &&fn) const {
    for (const Block &b : slots_)
      for (std::uint64_t m = b.mask; m != 0; m &= m - 1) {
        const unsigned bit = static_cast<unsigned>(__builtin_ctzll(m));
        fn(cellAt(b, bit), idAt(b, bit));
      }
  }

 private:
  static std::size_t hash(std::int32_t x, std::int32_t y, std::int32_t z) {
    std::uint64_t h = static_cast<std::uint64_t>(static_cast<std::uint32_t>(x)) * 0x9E3779B97F4A7C15ull;
    h ^= static_cast<std::uint64_t>(static_cast<std::uint32_t>(y)) * 0xC2B2AE3D27D4EB4Full;
    h ^= static_cast<std::uint64_t>(static_cast<std::uint32_t>(z)) * 0x165667B19E3779F9ull;
    h ^= h >> 31;
    h *= 0xBF58476D1CE4E5B9ull;
    h ^= h >> 29;
    return static_cast<std::size_t>(h);
  }
  /// Pool chunk sizes are powers of two from 2 to 64 ids; class c holds 2 << c (for counts >= 2).
  static int sizeClass(unsigned count);
  std::uint32_t allocChunk(int cls);
  void freeChunk(std::uint32_t base, int cls);
  void compactPool();
  void rehash(std::size_t new_capacity);
  void eraseSlot(std::size_t i);

  std::vector<Block> slots_;
  std::vector<SampleId> ids_;
  std::array<std::vector<std::uint32_t>, 6> free_chunks_;
  std::size_t size_ = 0;
  std::size_t blocks_ = 0;
  std::size_t free_ids_ = 0;  ///< ids held by chunks on the free lists
  std::size_t mask_ = 0;
};

}  // namespace hpds
