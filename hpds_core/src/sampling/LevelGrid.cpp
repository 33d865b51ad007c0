#include "hpds/sampling/LevelGrid.hpp"

#include <algorithm>
#include <cstring>
#include <stdexcept>

namespace hpds {

namespace {
constexpr std::size_t kInitialCapacity = 16;
constexpr LevelGrid::Block kFreeSlot{0, 0, 0, 0, 0};
}  // namespace

int LevelGrid::sizeClass(unsigned count) {
  int c = 0;
  while ((2u << c) < count) ++c;
  return c;
}

std::uint32_t LevelGrid::allocChunk(int cls) {
  auto &free = free_chunks_[static_cast<std::size_t>(cls)];
  if (!free.empty()) {
    const std::uint32_t base = free.back();
    free.pop_back();
    free_ids_ -= 2u << cls;
    return base;
  }
  const std::size_t base = ids_.size(), need = base + (2u << cls);
  if (need > 0xFFFFFFFFull) throw std::length_error("LevelGrid: id pool exceeds 2^32 entries");
  // Grow by a quarter, not the vector's doubling: the pool is most of a long-running map's grid memory.
  if (need > ids_.capacity()) ids_.reserve(std::max(need, ids_.size() + ids_.size() / 4 + 256));
  ids_.resize(need, kNoSample);
  return static_cast<std::uint32_t>(base);
}

void LevelGrid::freeChunk(std::uint32_t base, int cls) {
  free_chunks_[static_cast<std::size_t>(cls)].push_back(base);
  free_ids_ += 2u << cls;
}

void LevelGrid::compactPool() {
  // Chunks freed by erasures only get reused by their own size class; once they are most of the pool, rebuild it
  // in slot order (each block in the chunk its count calls for).
  std::vector<SampleId> fresh;
  fresh.reserve(ids_.size() - free_ids_ + ids_.size() / 8);
  for (Block &b : slots_) {
    const unsigned count = bitCount(b.mask);
    if (count < 2) continue;  // empty slot or an inline id
    const std::size_t base = fresh.size();
    fresh.insert(fresh.end(), ids_.begin() + b.base, ids_.begin() + b.base + count);
    fresh.resize(base + (2u << sizeClass(count)), kNoSample);
    b.base = static_cast<std::uint32_t>(base);
  }
  ids_.swap(fresh);
  for (auto &f : free_chunks_) f.clear();
  free_ids_ = 0;
}

bool LevelGrid::insert(const CellKey &key, SampleId id) {
  if (free_ids_ > 1024 && free_ids_ * 2 > ids_.size()) compactPool();
  // Blocks at half load: probe runs stay short; a block slot is small next to the ids it stands for.
  if ((blocks_ + 1) * 2 > slots_.size()) rehash(slots_.empty() ? kInitialCapacity : slots_.size() * 2);
  const std::int32_t bx = key.x >> kBlockShift, by = key.y >> kBlockShift, bz = key.z >> kBlockShift;
  const unsigned bit = localBit(key.x, key.y, key.z);
  const std::uint64_t m = std::uint64_t(1) << bit;
  std::size_t i = hash(bx, by, bz) & mask_;
  for (;; i = (i + 1) & mask_) {
    Block &b = slots_[i];
    if (b.mask == 0) {
      b = Block{bx, by, bz, id, m};
      ++blocks_;
      ++size_;
      return true;
    }
    if (b.x == bx && b.y == by && b.z == bz) break;
  }
  Block &b = slots_[i];
  if (b.mask & m) return false;
  const unsigned count = bitCount(b.mask);
  const unsigned rank = bitCount(b.mask & (m - 1));
  if (count == 1) {
    // Out of line: the inline id and the new one, in bit order.
    const std::uint32_t base = allocChunk(0);
    ids_[base + rank] = id;
    ids_[base + 1 - rank] = b.base;
    b.base = base;
  } else {
    const int cls = sizeClass(count);
    if (count + 1 > (2u << cls)) {
      // Move to a chunk twice the size; the old one goes on its class's free list.
      const std::uint32_t base = allocChunk(cls + 1);
      std::memcpy(&ids_[base], &ids_[b.base], count * sizeof(SampleId));
      freeChunk(b.base, cls);
      b.base = base;
    }
    SampleId *p = &ids_[b.base];
    std::memmove(p + rank + 1, p + rank, (count - rank) * sizeof(SampleId));
    p[rank] = id;
  }
  b.mask |= m;
  ++size_;
  return true;
}

bool LevelGrid::erase(const CellKey &key) {
  if (size_ == 0) return false;
  const std::int32_t bx = key.x >> kBlockShift, by = key.y >> kBlockShift, bz = key.z >> kBlockShift;
  std::size_t i = hash(bx, by, bz) & mask_;
  for (;; i = (i + 1) & mask_) {
    const Block &b = slots_[i];
    if (b.mask == 0) return false;
    if (b.x == bx && b.y == by && b.z == bz) break;
  }
  Block &b = slots_[i];
  const std::uint64_t m = std::uint64_t(1) << localBit(key.x, key.y, key.z);
  if (!(b.mask & m)) return false;
  const unsigned count = bitCount(b.mask);
  const unsigned rank = bitCount(b.mask & (m - 1));
  --size_;
  if (count == 1) {
    eraseSlot(i);
    return true;
  }
  const int cls = sizeClass(count);
  b.mask &= ~m;
  if (count == 2) {
    // Back inline: the other id.
    const SampleId other = ids_[b.base + 1 - rank];
    freeChunk(b.base, cls);
    b.base = other;
    return true;
  }
  SampleId *p = &ids_[b.base];
  std::memmove(p + rank, p + rank + 1, (count - rank - 1) * sizeof(SampleId));
  const int new_cls = sizeClass(count - 1);
  if (new_cls < cls) {
    // A block's chunk class is a function of its count (the pool compaction relies on it).
    const std::uint32_t base = allocChunk(new_cls);
    std::memcpy(&ids_[base], &ids_[b.base], (count - 1) * sizeof(SampleId));
    freeChunk(b.base, cls);
    b.base = base;
  }
  return true;
}

void LevelGrid::eraseSlot(std::size_t i) {
  // Backward-shift: pull later members of the probe run into the hole when their home slot allows it.
  for (std::size_t j = i;;) {
    j = (j + 1) & mask_;
    if (slots_[j].mask == 0) break;
    const std::size_t home = hash(slots_[j].x, slots_[j].y, slots_[j].z) & mask_;
    const bool home_between = (i <= j) ? (i < home && home <= j) : (i < home || home <= j);
    if (!home_between) {
      slots_[i] = slots_[j];
      i = j;
    }
  }
  slots_[i] = kFreeSlot;
  --blocks_;
}

void LevelGrid::clear() {
  slots_.clear();
  slots_.shrink_to_fit();
  ids_.clear();
  ids_.shrink_to_fit();
  for (auto &f : free_chunks_) {
    f.clear();
    f.shrink_to_fit();
  }
  size_ = blocks_ = mask_ = free_ids_ = 0;
}

void LevelGrid::reset() {
  if (size_ != 0)
    for (Block &b : slots_) b = kFreeSlot;
  ids_.clear();
  for (auto &f : free_chunks_) f.clear();
  size_ = blocks_ = free_ids_ = 0;
}

void LevelGrid::rehash(std::size_t new_capacity) {
  std::vector<Block> old(new_capacity, kFreeSlot);
  old.swap(slots_);
  mask_ = new_capacity - 1;
  for (const Block &b : old)
    if (b.mask != 0)
      for (std::size_t i = hash(b.x, b.y, b.z) & mask_;; i = (i + 1) & mask_)
        if (slots_[i].mask == 0) {
          slots_[i] = b;
          break;
        }
}

std::size_t LevelGrid::memUsage() const {
  std::size_t bytes = slots_.capacity() * sizeof(Block) + ids_.capacity() * sizeof(SampleId);
  for (const auto &f : free_chunks_) bytes += f.capacity() * sizeof(std::uint32_t);
  return bytes;
}

}  // namespace hpds
