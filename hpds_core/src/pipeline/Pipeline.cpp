#include "hpds/pipeline/Pipeline.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <exception>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include "hpds/io/PoseFile.hpp"
#include "hpds/pipeline/FramePoints.hpp"
#include "hpds/pipeline/OutputCloud.hpp"
#include "hpds/sampling/FrameGridIndex.hpp"
#include "hpds/sampling/InsertionOrderer.hpp"
#include "hpds/util/ParallelFor.hpp"
#include "normals/CellCentroids.hpp"
#include "normals/MapNormals.hpp"
#include "normals/RefinedNormals.hpp"

namespace hpds {

namespace {

/// Search radii of the scan-mode normals sorted ahead on the second thread (see addFrame).
constexpr std::size_t kAheadRadii = 4;
/// Samples whose neighbourhoods the second thread estimates at once while a frame is inserted: at least a few
/// hundred (each call sorts its queries into every round's grid), at most a few thousand, so that the insertion
/// rarely waits for a call to finish when it ends.
constexpr std::size_t kEarlyMinChunk = 256, kEarlyMaxChunk = 2048;
constexpr std::chrono::microseconds kEarlyPoll{50};
double secondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}
}  // namespace

FrameCounters &FrameCounters::operator+=(const FrameCounters &o) {
  input += o.input;
  skipped_invalid += o.skipped_invalid;
  skipped_zero += o.skipped_zero;
  skipped_range += o.skipped_range;
  out_of_range += o.out_of_range;
  dropped_depth += o.dropped_depth;
  accepted += o.accepted;
  evicted += o.evicted;
  for (std::size_t i = 0; i < accepted_per_level.size(); ++i) accepted_per_level[i] += o.accepted_per_level[i];
  return *this;
}

namespace {
/// True when `a` and `b` hold the same fields (name, type, count), whatever their order, offsets and padding.
bool sameFields(const PointLayout &a, const PointLayout &b) {
  if (a.fields.size() != b.fields.size()) return false;
  for (const PointField &f : a.fields) {
    const PointField *g = b.find(f.name);
    if (!g || g->type != f.type || g->count != f.count) return false;
  }
  return true;
}

/// The deepest level read: the output levels and the levels a map keeps. No level is built for the normals: they
/// average the frame's own points per cell of a finer level instead (fineLevelFor).
int buildDepthFor(const HpdsConfig &config, int output_level) {
  const int kept = config.mode == Mode::Map ? config.map.keep_depth : -1;
  return std::min(config.hierarchy.max_depth, std::max(output_level, kept));
}

/// Normals that average finer detail: the level whose cells they average the frame's points in
/// (normalsAveragingLevel), or -1. A map that keeps that level anyway (map.keep_depth) is read instead: its finer
/// levels hold every frame's points, not one frame's.
int fineLevelFor(const HpdsConfig &config, int output_level) {
  const int fine = normalsAveragingLevel(config, output_level);
  return config.mode == Mode::Map && config.map.keep_depth >= fine ? -1 : fine;
}
}  // namespace

Pipeline::Pipeline(const HpdsConfig &config)
    : resolution_((validateConfig(config), resolveOutput(config))),
      config_(resolvedConfig(config)),
      output_level_(resolution_.level),
      build_depth_(buildDepthFor(config_, output_level_)),
      fine_level_(fineLevelFor(config_, output_level_)),
      hierarchy_(config_.hierarchy.cell_size, config_.hierarchy.max_depth) {
  if (config_.mode == Mode::Map && fine_level_ >= 0) map_normals_ = std::make_shared<MapNormals>();
}

void Pipeline::requireLevel(int level) {
  if (level < 0 || level > config_.hierarchy.max_depth)
    throw std::invalid_argument("required level " + std::to_string(level) + " is outside 0..hierarchy.max_depth (" +
                                std::to_string(config_.hierarchy.max_depth) + ")");
  build_depth_ = std::max(build_depth_, level);
}

FrameResult Pipeline::addFrame(const Frame &frame) {
  throwIfInterrupted(interrupt_, "before the frame");
  FrameResult result;
  FrameCounters &c = result.counters;
  const PointBuffer &pts = frame.points;
  const PointLayout &layout = pts.layout();
  const PointField *fx = layout.find("x"), *fy = layout.find("y"), *fz = layout.find("z");
  if (!fx || !fy || !fz) throw std::invalid_argument("frame has no x/y/z fields");
  if (fx->count != 1 || fy->count != 1 || fz->count != 1) throw std::invalid_argument("x/y/z fields must have count 1");
  layout.validate();
  if (const std::string why = rigidPoseProblem(frame.sensor_to_fixed); !why.empty())
    throw std::invalid_argument("frame.sensor_to_fixed: " + why);
  if (!frame.viewpoint.allFinite()) throw std::invalid_argument("frame.viewpoint is not finite");
  const bool map_mode = config_.mode == Mode::Map;
  // Map mode: the samples' records keep the fields of the first frame that had points, or the loaded map's.
  // - A frame without points has no record to keep: it neither fixes the fields nor has to match them (drivers and
  //   filters publish empty clouds of other fields, e.g. before the first scan).
  // - The same fields in another order, at other offsets or with other padding are copied into the map's layout.
  // - Other fields are refused while the map holds samples (or free slots); a map without any takes the frame's.
  const PointBuffer *records = &pts;
  PointBuffer records_in_map_layout;
  bool keep_layout = !map_mode || !pts.empty();
  if (map_mode && map_layout_fixed_ && keep_layout && layout != hierarchy_.recordLayout()) {
    if (sameFields(layout, hierarchy_.recordLayout())) {
      records_in_map_layout = withLayout(pts, hierarchy_.recordLayout());
      records = &records_in_map_layout;
      keep_layout = false;
    } else if (hierarchy_.idBound() > 0) {
      throw std::invalid_argument("frame's point fields (" + describeFields(layout) + ") differ from the map's (" +
                                  describeFields(hierarchy_.recordLayout()) +
                                  "; those of the first frame with points or of the loaded map)");
    }
  }

  hit_cache_valid_ = false;
  hit_cache_.clear();

  // 1. Scan mode starts every frame on an empty hierarchy.
  if (!map_mode) hierarchy_.clear();
  if (keep_layout) {
    hierarchy_.setRecordLayout(layout);
    if (map_mode) map_layout_fixed_ = true;
  }
  // Capacity kept from a frame far larger than any recent one (the peak decays by 10% per frame) is released
  // instead of being held for the life of the pipeline.
  recent_points_ = std::max(static_cast<double>(pts.size()), 0.9 * recent_points_);
  if (static_cast<double>(candidates_.capacity()) > 4.0 * recent_points_ + 65536.0) {
    std::vector<double>().swap(xyz_);  // `= {}` would keep the capacity
    std::vector<std::uint32_t>().swap(candidates_);
    std::vector<std::uint32_t>().swap(early_points_);
    std::vector<LocalPca>().swap(early_chosen_);
    std::vector<std::uint8_t>().swap(early_have_);
    hierarchy_.shrink();
#if defined(__GLIBC__)
    // glibc keeps freed blocks below its (self-raising, up to 32 MB) mmap threshold in its heaps: without this the
    // process, unlike the pipeline, keeps the huge frame's memory (the node's resident set stayed 100 MB above its
    // level before one 1.5 M point frame, the frame's message and outputs included). Rare: once per such decay.
    malloc_trim(0);
#endif
  }

  // 2. Sensor-frame filtering, then into the fixed frame.
  const auto t_order = std::chrono::steady_clock::now();
  c.input = pts.size();
  SkippedPoints skipped;
  poseFramePoints(frame, config_.input, xyz_, candidates_, skipped);
  // Out-of-key-range points (a glitched return at -1e30) are counted here and go no further: every later step takes
  // candidates_ as the frame's extent, and one such point as the corner of the normals' centroid grids put every
  // real point beyond their reach (no sample of the frame got a normal).
  std::uint64_t out_of_key_range = 0;
  {
    std::size_t kept = 0;
    for (const std::uint32_t i : candidates_)
      if (hierarchy_.inKeyRange(&xyz_[3 * std::size_t(i)]))
        candidates_[kept++] = i;
      else
        ++out_of_key_range;
    candidates_.resize(kept);
  }
  c.skipped_invalid = skipped.invalid;
  c.skipped_zero = skipped.zero;
  c.skipped_range = skipped.range;
  const std::size_t n = pts.size();
  const Eigen::Vector3d t = frame.sensor_to_fixed * frame.viewpoint;

  // 3. Map mode: keep memory bounded around the sensor before adding more.
  const double viewpoint[3] = {t.x(), t.y(), t.z()};
  if (map_mode) {
    if (config_.map.evict_distance > 0.0) c.evicted += hierarchy_.evictOutside(viewpoint, config_.map.evict_distance);
    if (config_.map.max_samples > 0)
      c.evicted += hierarchy_.evictToCap(viewpoint, static_cast<std::size_t>(config_.map.max_samples));
  }

  const double seconds_posing = secondsSince(t_order);
  throwIfInterrupted(interrupt_, "after posing");

  // 4. Scan-mode normals average the frame's points per cell of the fine level instead of that many more levels of
  //    the hierarchy: those centroids only need the points, so with a second thread they are made during steps 5 and 6,
  //    and so are the search grids of the first radii. Then that thread estimates the neighbourhoods of the
  //    samples the insertion has accepted so far (a sample's neighbourhood depends on its position only; see
  //    refinedNeighbourhoodsOverCentroids), sorting another grid ahead when none are waiting, until the insertion is
  //    done: the normals then only estimate the rest, with the same result as estimating all.
  std::thread fine_worker;
  std::exception_ptr fine_error;
  std::atomic<bool> inserted_all{false};
  std::atomic<std::size_t> published{0};
  fine_points_.clear();
  fine_grids_.reset();
  early_done_ = 0;
  early_slot_.clear();
  const NormalParams normal_params = normalParamsFor(config_, output_level_);
  const bool ahead = fine_level_ >= 0 && resolveThreads(config_.threads) > 1;
  // Map mode estimates the normals of every output sample the frame hits, old ones too: none to take early.
  const bool early = ahead && !map_mode && normal_params.k == 0 && normal_params.radius > 0.0;
  if (early) early_points_.resize(candidates_.size());
  if (fine_level_ >= 0) {
    std::vector<double> radii = refinedSearchRadii(hierarchy_, normal_params);
    // The grids only serve queries inside their box. Scan mode queries the frame's own points; map mode also the
    // earlier samples the frame hits, up to 2 r_L beyond its points (step 7): the box is that much wider there.
    const double box_margin = map_mode ? 2.0 * hierarchy_.radius(output_level_) : 0.0;
    auto centroids = [this, &fine_error, &inserted_all, &published, ahead, early, &normal_params, box_margin,
                      radii = std::move(radii)]() mutable {
      try {
        double box[6];
        fine_points_ = cellCentroids(xyz_.data(), candidates_.data(), candidates_.size(),
                                     cellEdge(config_.hierarchy.cell_size, fine_level_), box, interrupt_);
        if (!std::isfinite(box[0])) return;
        throwIfInterrupted(interrupt_, "after the centroids");
        auto grids = std::make_shared<AveragingGrids>();
        grids->radii = std::move(radii);
        for (int a = 0; a < 3; ++a) {
          grids->lo[a] = box[a] - box_margin;
          grids->hi[a] = box[3 + a] + box_margin;
        }
        grids->by_radius.resize(grids->radii.size());
        fine_grids_ = grids;
        if (!ahead) return;
        const PointSet points{fine_points_.data(), nullptr, fine_points_.size() / 3};
        // The first rounds hold most queries; a later round is a few queries over as many points, where sorting ahead
        // saves as much but is less likely to finish in time: at most kAheadRadii of them (every radius ahead, six on
        // HDL-32, took its 2-thread frame path from 10.0-10.4 to 10.6-11.2 ms in alternating runs).
        std::size_t next_grid = 0;
        auto sortAhead = [&] {
          while (next_grid < std::min(grids->radii.size(), kAheadRadii) && grids->by_radius[next_grid]) ++next_grid;
          if (next_grid >= std::min(grids->radii.size(), kAheadRadii)) return false;
          grids->by_radius[next_grid] = grids->make(next_grid, points);
          return true;
        };
        if (!early) {
          while (!inserted_all.load(std::memory_order_relaxed) && sortAhead()) {
          }
          return;
        }
        for (;;) {
          if (inserted_all.load(std::memory_order_acquire)) break;  // the rest is left to the normals' threads
          const std::size_t ready = published.load(std::memory_order_acquire);
          if (ready - early_done_ >= kEarlyMinChunk) {
            const std::size_t count = std::min(ready - early_done_, kEarlyMaxChunk);
            early_chosen_.resize(early_done_ + count);
            early_have_.resize(early_done_ + count);
            refinedNeighbourhoodsOverCentroids(xyz_.data(), early_points_.data() + early_done_, count, normal_params,
                                               config_.hierarchy.cell_size, fine_points_, *grids,
                                               early_chosen_.data() + early_done_, early_have_.data() + early_done_);
            early_done_ += count;
          } else if (!sortAhead()) {
            // Nothing to do until more samples are accepted: sleep rather than spin, so that on a busy machine the
            // insertion keeps its core (a chunk's worth is ~0.2 ms of insertion on the HDL-32 frame).
            std::this_thread::sleep_for(kEarlyPoll);
          }
        }
      } catch (...) {
        fine_error = std::current_exception();
      }
    };
    if (ahead)
      fine_worker = std::thread(centroids);
    else
      centroids();
  }

  // 5. Insertion order (random, input or feature-sensitive).
  const auto t_shuffle = std::chrono::steady_clock::now();
  const double feature_radius = config_.order.feature_radius > 0.0
                                    ? config_.order.feature_radius
                                    : 2.0 * poissonRadius(config_.hierarchy.cell_size, output_level_);
  std::vector<std::uint32_t> order;
  try {
    throwIfInterrupted(interrupt_, "before the insertion order");
    order = insertionOrder(xyz_.data(), candidates_, config_.order.type, config_.order.seed + frames_,
                           feature_radius, config_.threads);
  } catch (...) {
    inserted_all = true;
    if (fine_worker.joinable()) fine_worker.join();
    early_done_ = 0;
    throw;
  }
  result.seconds_order = seconds_posing + secondsSince(t_shuffle);

  // 6. Breadth-first insertion into the hierarchy.
  const auto t_insert = std::chrono::steady_clock::now();
  InsertBatch batch;
  batch.xyz = xyz_.data();
  batch.size = n;
  batch.order = order.data();
  batch.order_size = order.size();
  // A frame without points kept no layout (above): it has no record either.
  batch.records = records->empty() ? nullptr : records->bytes().data();
  batch.record_step = records->layout().point_step;
  for (int a = 0; a < 3; ++a) batch.viewpoint[a] = viewpoint[a];
  batch.frame_index = frames_;
  batch.max_level = buildDepth();
  batch.interrupt = interrupt_;
  if (early) {
    batch.published = early_points_.data();
    batch.published_count = &published;
    batch.publish_level = output_level_;
  }
  InsertResult inserted;
  try {
    inserted = hierarchy_.insert(batch);
  } catch (...) {
    inserted_all = true;
    if (fine_worker.joinable()) fine_worker.join();
    early_done_ = 0;
    throw;
  }
  inserted_all.store(true, std::memory_order_release);
  result.seconds_insert = secondsSince(t_insert);
  if (fine_worker.joinable()) fine_worker.join();
  if (fine_error) {
    early_done_ = 0;
    std::rethrow_exception(fine_error);
  }
  result.normals_ahead = early_done_;
  if (early_done_ > 0) {  // which samples the early neighbourhoods belong to: the first ones published
    early_slot_.assign(hierarchy_.idBound(), kNoSample);
    std::size_t k = 0;
    for (SampleId id : inserted.accepted)
      if (hierarchy_.level(id) <= output_level_ && k < early_done_) early_slot_[id] = static_cast<std::uint32_t>(k++);
  }

  c.out_of_range = out_of_key_range + inserted.out_of_range;
  c.dropped_depth = inserted.dropped_depth;
  c.accepted = inserted.accepted.size();
  c.accepted_per_level = inserted.accepted_per_level;

  // 7. Map mode: back to map.max_samples, farthest from the sensor first, the frame's own samples too, so that the cap
  //    holds between frames, not only before each (it was exceeded by up to a frame's samples); then the normals the
  //    map keeps, for the output samples this frame hit, none of them evicted.
  if (map_mode && config_.map.max_samples > 0 && hierarchy_.sampleCount() > config_.map.max_samples) {
    c.evicted += hierarchy_.evictToCap(viewpoint, static_cast<std::size_t>(config_.map.max_samples));
    std::vector<SampleId> &fresh = inserted.accepted;
    fresh.erase(std::remove_if(fresh.begin(), fresh.end(), [&](SampleId id) { return !hierarchy_.isLive(id); }),
                fresh.end());
  }
  if (map_normals_) {
    const auto t_normals = std::chrono::steady_clock::now();
    updateMapNormals(inserted.accepted, viewpoint, normal_params);
    result.seconds_normals = secondsSince(t_normals);
  }

  result.new_samples = std::move(inserted.accepted);
  totals_ += c;
  ++frames_;
  return result;
}

void Pipeline::updateMapNormals(const std::vector<SampleId> &fresh, const double viewpoint[3],
                                const NormalParams &params) {
  map_normals_->resetSlots(fresh, hierarchy_.idBound());
  hit_cache_ = samplesHitByLastFrame(0, output_level_, 2.0 * hierarchy_.radius(output_level_));
  hit_cache_valid_ = true;
  const std::vector<SampleId> &hit = hit_cache_;
  std::vector<float> ranges;
  const std::vector<SampleId> ids = map_normals_->improvable(hierarchy_, hit, viewpoint, params.line_ratio, ranges);
  if (!ids.empty()) {
    std::vector<LocalPca> neighbourhoods(ids.size());
    const std::vector<SampleNormal> normals =
        estimateNormalsRefined(hierarchy_, ids, params, &fine_points_, &neighbourhoods, fine_grids_.get(), nullptr);
    for (std::size_t i = 0; i < ids.size(); ++i)
      map_normals_->offer(ids[i], normals[i], neighbourhoods[i], ranges[i], params.line_ratio);
  }
  // The frame's grids serve this estimate only.
  if (fine_grids_)
    for (auto &g : fine_grids_->by_radius) g.reset();
}

std::size_t Pipeline::memUsage() const {
  return hierarchy_.memUsage() + hierarchy_.scratchBytes() + xyz_.capacity() * sizeof(double) +
         candidates_.capacity() * sizeof(std::uint32_t) + fine_points_.capacity() * sizeof(double) +
         (fine_grids_ ? fine_grids_->memUsage() : 0) + early_points_.capacity() * sizeof(std::uint32_t) +
         early_chosen_.capacity() * sizeof(LocalPca) + early_have_.capacity() +
         early_slot_.capacity() * sizeof(SampleId) + (map_normals_ ? map_normals_->memUsage() : 0) +
         hit_cache_.capacity() * sizeof(SampleId);
}

void Pipeline::replaceMap(Hierarchy &&map, std::uint32_t next_frame) {
  if (config_.mode != Mode::Map) throw std::invalid_argument("mode: replacing the map needs map mode");
  if (map.cellSize() != config_.hierarchy.cell_size || map.maxDepth() != config_.hierarchy.max_depth)
    throw std::invalid_argument("hierarchy: the map's cell_size/max_depth differ from the configuration's");
  // Frames already taken fixed the fields: a map of other fields would have every later frame refused.
  if (map_layout_fixed_ && map.idBound() > 0 && !sameFields(map.recordLayout(), hierarchy_.recordLayout())) {
    throw std::invalid_argument("the map's point fields (" + describeFields(map.recordLayout()) +
                                ") differ from those of the frames so far (" + describeFields(hierarchy_.recordLayout()) +
                                "): later frames would all be refused");
  }
  hierarchy_ = std::move(map);
  frames_ = next_frame;
  hit_cache_valid_ = false;
  hit_cache_.clear();
  // Kept normals belong to the old map (loadMap restores a file's own after this); until a frame hits them, samples
  // without one get theirs from the map (keptNormals).
  if (map_normals_) map_normals_->clear();
  // A map that has a layout (a saved one always does, even without samples) fixes it; a bare Hierarchy (the tiled
  // build's empty band) leaves it to the first frame.
  map_layout_fixed_ = !hierarchy_.recordLayout().fields.empty();
}

void Pipeline::clearMap() {
  if (config_.mode != Mode::Map) throw std::invalid_argument("mode: clearing the map needs map mode");
  // A bare hierarchy has no fields, so replaceMap lets the next frame set them.
  replaceMap(Hierarchy(config_.hierarchy.cell_size, config_.hierarchy.max_depth), frames_);
}

std::vector<SampleId> Pipeline::outputSamples() const { return hierarchy_.samplesUpTo(output_level_); }

std::vector<SampleId> Pipeline::atOutputLevels(const std::vector<SampleId> &ids) const {
  std::vector<SampleId> out;
  out.reserve(ids.size());
  for (SampleId id : ids)
    if (hierarchy_.isLive(id) && hierarchy_.level(id) <= output_level_) out.push_back(id);
  return out;
}

std::vector<SampleId> Pipeline::outputSamplesNear(const double center[3], double radius) const {
  std::vector<SampleId> out;
  hierarchy_.forEachInBall(center, radius, output_level_, [&](SampleId id, double) { out.push_back(id); });
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<SampleId> Pipeline::samplesHitByLastFrame(int min_level, int max_level, double radius) const {
  // The map's normals asked for this set already (the node's ~output asks for it again).
  if (hit_cache_valid_ && min_level == 0 && max_level == output_level_ &&
      radius == 2.0 * hierarchy_.radius(output_level_))
    return hit_cache_;
  std::vector<SampleId> hit;
  if (candidates_.empty() || !(radius > 0.0)) return hit;
  const auto inLevels = [&](SampleId id) {
    return hierarchy_.isLive(id) && hierarchy_.level(id) >= min_level && hierarchy_.level(id) <= max_level;
  };
  if (std::isinf(radius)) {  // every candidate is within an infinite radius of every sample
    for (SampleId id = 0; id < hierarchy_.idBound(); ++id)
      if (inLevels(id)) hit.push_back(id);
    return hit;
  }
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (std::uint32_t i : candidates_)
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], xyz_[3 * std::size_t(i) + a] - radius);
      hi[a] = std::max(hi[a], xyz_[3 * std::size_t(i) + a] + radius);
    }
  // FrameGridIndex keys 2^21 cells of edge `radius` per axis: a frame wider than that (a radius far below the
  // spacing) is searched from each candidate through the hierarchy's own grids instead, which cost a few cells per
  // level at such a radius.
  constexpr double kGridCells = 1048576.0;  // 2^20: half FrameGridIndex's window, a margin for rounding
  if (hi[0] - lo[0] >= kGridCells * radius || hi[1] - lo[1] >= kGridCells * radius ||
      hi[2] - lo[2] >= kGridCells * radius) {
    std::vector<std::uint8_t> marked(hierarchy_.idBound(), 0);
    for (std::uint32_t i : candidates_)
      hierarchy_.forEachInBall(&xyz_[3 * std::size_t(i)], radius, std::min(max_level, hierarchy_.maxDepth()),
                               [&](SampleId id, double) { marked[id] = 1; });
    for (SampleId id = 0; id < hierarchy_.idBound(); ++id)
      if (marked[id] && inLevels(id)) hit.push_back(id);
    return hit;
  }
  // The last frame's candidates are still in xyz_ (fixed frame): bucket them once, then test each sample near
  // them against its 27 buckets.
  const FrameGridIndex index(xyz_.data(), candidates_, radius);
  for (SampleId id = 0; id < hierarchy_.idBound(); ++id) {
    if (!inLevels(id)) continue;
    const double *p = hierarchy_.position(id);
    if (p[0] < lo[0] || p[0] > hi[0] || p[1] < lo[1] || p[1] > hi[1] || p[2] < lo[2] || p[2] > hi[2]) continue;
    if (index.anyWithin(p)) hit.push_back(id);
  }
  return hit;
}

void Pipeline::requireLiveIds(const std::vector<SampleId> &ids, const char *what) const {
  for (SampleId id : ids)
    if (!hierarchy_.isLive(id))
      throw std::invalid_argument(std::string(what) + ": id " + std::to_string(id) +
                                  " is no sample of the hierarchy (evicted, or from a frame before the last in scan "
                                  "mode: ids do not outlive the next addFrame there)");
}

std::vector<SampleNormal> Pipeline::normals(const std::vector<SampleId> &ids,
                                             std::vector<LocalPca> *neighbourhoods) const {
  requireLiveIds(ids, "normals");
  throwIfInterrupted(interrupt_, "before the normals");
  return normalsOfLive(ids, neighbourhoods);
}

std::vector<SampleNormal> Pipeline::normalsOfLive(const std::vector<SampleId> &ids,
                                                  std::vector<LocalPca> *neighbourhoods) const {
  const NormalParams params = normalParamsFor(config_, output_level_);
  if (fine_level_ < 0) return estimateNormals(hierarchy_, ids, params, neighbourhoods);
  if (map_normals_) return keptNormals(ids, params, neighbourhoods);
  if (neighbourhoods) neighbourhoods->assign(ids.size(), LocalPca{});
  // Neighbourhoods estimated beside the insertion (addFrame) for the samples among ids.
  std::vector<std::uint8_t> state;
  std::vector<LocalPca> chosen;
  KnownNeighbourhoods known;
  if (early_done_ > 0) {
    state.assign(ids.size(), KnownNeighbourhoods::kUnknown);
    chosen.resize(ids.size());
    for (std::size_t i = 0; i < ids.size(); ++i) {
      const SampleId id = ids[i];
      const std::uint32_t k = id < early_slot_.size() ? early_slot_[id] : kNoSample;
      if (k == kNoSample) continue;
      state[i] = early_have_[k] ? KnownNeighbourhoods::kChosen : KnownNeighbourhoods::kNone;
      chosen[i] = early_chosen_[k];
    }
    known = KnownNeighbourhoods{state.data(), chosen.data()};
  }
  std::vector<SampleNormal> normals = estimateNormalsRefined(hierarchy_, ids, params, &fine_points_, neighbourhoods,
                                                             fine_grids_.get(), early_done_ > 0 ? &known : nullptr);
  // The grids sorted ahead and the early neighbourhoods serve the frame's first estimate only (VLS-128: 26 MB of
  // grids held to the next frame otherwise); a second one estimates everything, with the same result.
  if (fine_grids_)
    for (auto &g : fine_grids_->by_radius) g.reset();
  early_done_ = 0;
  std::vector<std::uint32_t>().swap(early_slot_);
  return normals;
}

std::vector<SampleNormal> Pipeline::keptNormals(const std::vector<SampleId> &ids, const NormalParams &params,
                                                std::vector<LocalPca> *neighbourhoods) const {
  std::vector<SampleNormal> normals(ids.size(), invalidNormal());
  if (neighbourhoods) neighbourhoods->assign(ids.size(), LocalPca{});
  // Samples no frame gave a valid normal since the map was made or loaded (or of levels below the output's) get one
  // from the map's own levels: fewer points than a frame's cells hold, but every frame's.
  std::vector<SampleId> rest;
  std::vector<std::size_t> rest_at;
  for (std::size_t i = 0; i < ids.size(); ++i) {
    const bool kept = hierarchy_.level(ids[i]) <= output_level_ &&
                      map_normals_->lookup(ids[i], normals[i], neighbourhoods ? &(*neighbourhoods)[i] : nullptr);
    if (!kept) {
      rest.push_back(ids[i]);
      rest_at.push_back(i);
    }
  }
  if (rest.empty()) return normals;
  std::vector<LocalPca> rest_neighbourhoods;
  const std::vector<SampleNormal> estimated =
      estimateNormals(hierarchy_, rest, params, neighbourhoods ? &rest_neighbourhoods : nullptr);
  for (std::size_t j = 0; j < rest.size(); ++j) {
    normals[rest_at[j]] = estimated[j];
    if (neighbourhoods) (*neighbourhoods)[rest_at[j]] = rest_neighbourhoods[j];
  }
  return normals;
}

PointBuffer Pipeline::makeCloud(const std::vector<SampleId> &ids, bool with_frame_field, double *seconds_normals) const {
  requireLiveIds(ids, "makeCloud");
  const XyzType xyz = outputXyzType(config_.output);
  if (!config_.normals.enabled)
    return buildOutputCloud(hierarchy_, ids, nullptr, with_frame_field, nullptr, xyz);
  const auto t0 = std::chrono::steady_clock::now();
  const bool with_covariances = config_.normals.covariances;
  std::vector<LocalPca> neighbourhoods;
  const std::vector<SampleNormal> normals = normalsOfLive(ids, with_covariances ? &neighbourhoods : nullptr);
  std::vector<SampleCovariance> covariances;
  if (with_covariances)
    covariances = estimateCovariances(hierarchy_, ids, output_level_, normals, neighbourhoods, config_);
  if (seconds_normals) *seconds_normals = secondsSince(t0);
  return buildOutputCloud(hierarchy_, ids, &normals, with_frame_field, with_covariances ? &covariances : nullptr, xyz);
}

}  // namespace hpds
