#include "hpds/LevelGrid.hpp"

namespace hpds {

namespace {
constexpr std::size_t kInitialCapacity = 64;
}

bool LevelGrid::insert(const CellKey &key, SampleId id) {
  // Grow at half load: linear probing stays short, which matters more here than the slots' memory.
  if ((size_ + 1) * 2 > slots_.size()) rehash(slots_.empty() ? kInitialCapacity : slots_.size() * 2);
  for (std::size_t i = hash(key) & mask_;; i = (i + 1) & mask_) {
    Slot &s = slots_[i];
    if (s.id == kNoSample) {
      s = Slot{key.x, key.y, key.z, id};
      ++size_;
      return true;
    }
    if (s.x == key.x && s.y == key.y && s.z == key.z) return false;
  }
}

bool LevelGrid::erase(const CellKey &key) {
  if (slots_.empty()) return false;
  std::size_t i = hash(key) & mask_;
  for (;; i = (i + 1) & mask_) {
    const Slot &s = slots_[i];
    if (s.id == kNoSample) return false;
    if (s.x == key.x && s.y == key.y && s.z == key.z) break;
  }
  // Backward-shift: pull later members of the probe run into the hole when their home slot allows it.
  for (std::size_t j = i;;) {
    j = (j + 1) & mask_;
    if (slots_[j].id == kNoSample) break;
    const std::size_t home = hash(CellKey{slots_[j].x, slots_[j].y, slots_[j].z}) & mask_;
    const bool home_between = (i <= j) ? (i < home && home <= j) : (i < home || home <= j);
    if (!home_between) {
      slots_[i] = slots_[j];
      i = j;
    }
  }
  slots_[i].id = kNoSample;
  --size_;
  return true;
}

void LevelGrid::clear() {
  slots_.clear();
  slots_.shrink_to_fit();
  size_ = 0;
  mask_ = 0;
}

void LevelGrid::reset() {
  for (Slot &s : slots_) s.id = kNoSample;
  size_ = 0;
}

void LevelGrid::rehash(std::size_t new_capacity) {
  std::vector<Slot> old;
  old.swap(slots_);
  slots_.assign(new_capacity, Slot{0, 0, 0, kNoSample});
  mask_ = new_capacity - 1;
  size_ = 0;
  for (const Slot &s : old)
    if (s.id != kNoSample) {
      for (std::size_t i = hash(CellKey{s.x, s.y, s.z}) & mask_;; i = (i + 1) & mask_) {
        if (slots_[i].id == kNoSample) {
          slots_[i] = s;
          break;
        }
      }
      ++size_;
    }
}

}  // namespace hpds
