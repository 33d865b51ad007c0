#include "hpds/eval/GridSubsampling.hpp"
#include "hpds/util/SplitMix64.hpp"

#include <algorithm>
#include <array>
#include <stdexcept>
#include <unordered_map>

namespace hpds {

namespace {

using Key = std::array<std::int64_t, 3>;

struct KeyHash {
  std::size_t operator()(const Key &k) const {
    std::uint64_t h = 0x9E3779B97F4A7C15ull;
    for (std::int64_t v : k) h = (h ^ static_cast<std::uint64_t>(v)) * 0xBF58476D1CE4E5B9ull + (h >> 29);
    return static_cast<std::size_t>(h);
  }
};

void checkCell(double cell) {
  if (!(cell > 0.0) || !std::isfinite(cell)) throw std::invalid_argument("grid subsampling: cell must be finite and > 0");
}

bool keyOf(const Eigen::Vector3d &p, const Eigen::Vector3d &origin, double inv, Key &k) {
  if (!p.allFinite()) return false;
  for (int a = 0; a < 3; ++a)
    k[static_cast<std::size_t>(a)] = static_cast<std::int64_t>(std::floor((p[a] - origin[a]) * inv));
  return true;
}


// Per cell, the index minimising score(i) (ties: lower index): the one selection rule behind both index baselines.
template <typename Score>
std::vector<std::uint32_t> pickPerCell(const std::vector<Eigen::Vector3d> &points, double cell,
                                       const Eigen::Vector3d &origin, Score &&score) {
  checkCell(cell);
  const double inv = 1.0 / cell;
  std::unordered_map<Key, std::pair<double, std::uint32_t>, KeyHash> best;
  best.reserve(points.size() / 4 + 16);
  Key k;
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!keyOf(points[i], origin, inv, k)) continue;
    const double s = score(static_cast<std::uint32_t>(i), k);
    auto it = best.find(k);
    if (it == best.end())
      best.emplace(k, std::make_pair(s, static_cast<std::uint32_t>(i)));
    else if (s < it->second.first)
      it->second = {s, static_cast<std::uint32_t>(i)};
  }
  std::vector<std::uint32_t> out;
  out.reserve(best.size());
  for (const auto &kv : best) out.push_back(kv.second.second);
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace

std::vector<std::uint32_t> gridRandom(const std::vector<Eigen::Vector3d> &points, double cell, std::uint64_t seed,
                                      const Eigen::Vector3d &origin) {
  // The minimum of i.i.d. hashes is a uniform pick among the cell's points.
  return pickPerCell(points, cell, origin, [&](std::uint32_t i, const Key &) {
    return static_cast<double>(splitMix64Mix(seed * kSplitMix64Increment + i + 1) >> 11);
  });
}

std::vector<std::uint32_t> gridClosestToCenter(const std::vector<Eigen::Vector3d> &points, double cell,
                                               const Eigen::Vector3d &origin) {
  return pickPerCell(points, cell, origin, [&](std::uint32_t i, const Key &k) {
    double d2 = 0.0;
    for (int a = 0; a < 3; ++a) {
      const double c = origin[a] + (static_cast<double>(k[static_cast<std::size_t>(a)]) + 0.5) * cell;
      d2 += (points[i][a] - c) * (points[i][a] - c);
    }
    return d2;
  });
}

std::vector<Eigen::Vector3d> voxelCentroids(const std::vector<Eigen::Vector3d> &points, double cell,
                                            const Eigen::Vector3d &origin) {
  checkCell(cell);
  const double inv = 1.0 / cell;
  std::unordered_map<Key, std::pair<Eigen::Vector3d, std::size_t>, KeyHash> acc;
  Key k;
  for (const auto &p : points) {
    if (!keyOf(p, origin, inv, k)) continue;
    auto &slot = acc[k];
    if (slot.second == 0) slot.first.setZero();
    slot.first += p;
    ++slot.second;
  }
  std::vector<std::pair<Key, Eigen::Vector3d>> cells;
  cells.reserve(acc.size());
  for (const auto &kv : acc) cells.emplace_back(kv.first, kv.second.first / static_cast<double>(kv.second.second));
  std::sort(cells.begin(), cells.end(), [](const auto &a, const auto &b) { return a.first < b.first; });
  std::vector<Eigen::Vector3d> out;
  out.reserve(cells.size());
  for (const auto &c : cells) out.push_back(c.second);
  return out;
}

}  // namespace hpds
