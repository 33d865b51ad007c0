// Pipeline: the per-frame flow shared by the CLI and the ROS node.
//
// Contract
// - The config is resolved first (resolvedConfig: the level-0 cell derived from output.spacing when
//   hierarchy.cell_size is 0); config() and the hierarchy use the resolved values, outputResolution() says why.
// - Only levels 0..buildDepth() are built, in both modes: the output level, a level asked for by requireLevel and,
//   in map mode, map.keep_depth; never past max_depth. Points
//   rejected down to buildDepth() count as dropped_depth. In scan mode those levels are exactly what building to
//   max_depth gives; in map mode finer samples of earlier frames also keep later candidates away, so a map built
//   deeper (map.keep_depth) differs at its coarse levels too, equally valid.
// - The normals' finer detail (normals.neighborhood_level_offset) comes from the frames themselves: the centroids
//   of a frame's points per cell of level output + offset (clamped to max_depth) stand in for the samples of those
//   levels, which are not built for it (with threads > 1, beside the insertion, and with them the normals' first
//   search grids and, in scan mode, the neighbourhoods of the samples accepted so far, which the frame's first
//   normals() then takes).
// - Scan mode: every frame is sampled on its own (the hierarchy is cleared first); normals() estimates from the last
//   frame's centroids. Map mode: one persistent hierarchy in the fixed frame; earlier samples never move or change
//   level; samples farther than map.evict_distance from the latest sensor position are evicted before the frame is
//   inserted, and the store is cut back to map.max_samples (farthest first) before and after it: between frames the
//   map holds at most the cap (FrameResult::new_samples lists only the frame's samples still in it), and memory is
//   bounded by the cap plus one frame. With normals that average finer detail, each frame estimates the normals of
//   the output samples it hits (within 2 r_L of its points) from its centroids, and every sample keeps the one of
//   the frame that saw it from closest (FrameResult::seconds_normals); normals() returns the kept ones, and for
//   samples with none (a loaded map not hit since, levels below the output) estimates from the map's own levels. A
//   map that keeps the finer levels anyway (map.keep_depth >= L + offset) keeps no normals: normals() reads those
//   levels, which hold every frame's points (more accurate than one frame's, at the cost of building them).
// - Points are transformed by frame.sensor_to_fixed (identity = sensor frame). NaN/Inf coordinates, exact (0,0,0)
//   no-returns (input.skip_zero_points) and points outside input.min_range/max_range (measured from
//   frame.viewpoint) are skipped and counted. Normals face, and eviction measures from, sensor_to_fixed * viewpoint.
// - A frame without x/y/z fields, with a pose that is not rigid (rigidPoseProblem, io/PoseFile.hpp), or a viewpoint
//   that is not finite throws std::invalid_argument before anything changes.
// - Map mode keeps every sample's record in one layout: the first frame's with points, or the loaded map's. A frame
//   of the same fields (name, type, count) in another order or at other offsets is copied into it; a frame without
//   points neither sets it nor has to match it; a frame of other fields throws std::invalid_argument before anything
//   changes, unless the map has never held a sample (then its fields become the map's).
// - Same config (seed) and same frames give identical samples, whatever `threads` is.
// - normals() and makeCloud() take ids of live samples (outputSamples(), FrameResult::new_samples of the last frame, ...)
//   and throw std::invalid_argument for an id that is no live sample. Ids are valid until the next addFrame or
//   loadMap: the hierarchy reuses the slots of evicted samples and scan mode starts each frame afresh, so an id kept
//   across frames may name another sample by then, which cannot be told from a stale id. Keep positions or the
//   output cloud across frames, not ids.
// - Not thread-safe: one thread drives a Pipeline, const member functions included (normals() and makeCloud() fill
//   caches). A moved-from Pipeline may only be assigned to or destroyed.
//   Another thread may stop a long addFrame or normals() through setInterrupt (util/Interrupt.hpp).
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "hpds/config/Config.hpp"
#include "hpds/points/Frame.hpp"
#include "hpds/sampling/Hierarchy.hpp"
#include "hpds/normals/NormalEstimator.hpp"
#include "hpds/points/PointBuffer.hpp"
#include "hpds/util/Interrupt.hpp"

namespace hpds {

struct AveragingGrids;  // internal: the normals' search grids over a frame's cell centroids
class MapNormals;       // internal: the normals a map keeps per sample
class AtomicFile;

struct FrameCounters {
  std::uint64_t input = 0;            ///< points in the frame
  std::uint64_t skipped_invalid = 0;  ///< NaN/Inf coordinates
  std::uint64_t skipped_zero = 0;     ///< exact (0,0,0) no-return points
  std::uint64_t skipped_range = 0;    ///< outside input.min_range / input.max_range
  std::uint64_t out_of_range = 0;     ///< coordinates beyond the hierarchy's exact key range
  std::uint64_t dropped_depth = 0;    ///< rejected at every level down to buildDepth()
  std::uint64_t accepted = 0;
  std::uint64_t evicted = 0;  ///< samples removed from the map with this frame (before and after its insertion)
  std::array<std::uint64_t, kMaxDepthLimit + 1> accepted_per_level{};

  FrameCounters &operator+=(const FrameCounters &o);
};

struct FrameResult {
  FrameCounters counters;
  std::vector<SampleId> new_samples;  ///< accepted from this frame, all levels, acceptance order
  double seconds_order = 0.0;         ///< insertion order (features included)
  double seconds_insert = 0.0;
  /// Map mode with normals: estimating the normals the map keeps for the output samples the frame hit.
  double seconds_normals = 0.0;
  /// Scan mode with 2+ threads: output samples whose normal neighbourhood the second thread estimated while the frame
  /// was inserted (the next normals() only estimates the others; the result is the same either way).
  std::size_t normals_ahead = 0;
};

class Pipeline {
 public:
  /// Validates the config (std::invalid_argument naming the key) and runs with resolvedConfig(config).
  explicit Pipeline(const HpdsConfig &config);

  /// Inserts one frame (see contract).
  FrameResult addFrame(const Frame &frame);

  /// Samples of levels 0..outputLevel(), increasing id order.
  [[nodiscard]] std::vector<SampleId> outputSamples() const;
  /// Of `ids`, those at levels <= outputLevel().
  [[nodiscard]] std::vector<SampleId> atOutputLevels(const std::vector<SampleId> &ids) const;
  /// Output-level samples strictly within `radius` of `center` (fixed frame).
  [[nodiscard]] std::vector<SampleId> outputSamplesNear(const double center[3], double radius) const;
  /// Samples of levels min_level..max_level that the last frame "hit": at least one of its inserted candidates
  /// (the points that passed the skip rules, in the fixed frame) lies strictly within `radius`. With radius 2 r_L
  /// every candidate has a hit sample (coverage), so this is the map as that sweep saw it. Increasing id order.
  [[nodiscard]] std::vector<SampleId> samplesHitByLastFrame(int min_level, int max_level, double radius) const;
  /// Normals of `ids` (samples of the hierarchy) with the config's normal settings, as makeCloud estimates them: in
  /// scan mode from the last frame's cell centroids, in map mode those the map keeps (see contract), so a caller
  /// must not estimate them from hierarchy() alone, which holds no level below buildDepth(). `neighbourhoods`: when
  /// given, resized to ids.size() and set to the PCA each normal came from (for covariances).
  [[nodiscard]] std::vector<SampleNormal> normals(const std::vector<SampleId> &ids,
                                                  std::vector<LocalPca> *neighbourhoods = nullptr) const;
  /// Output cloud of `ids` (normals estimated when normals.enabled, with covariances when normals.covariances),
  /// layout of OutputCloud.hpp. `seconds_normals` gets the time of both. x y z are float32 unless the input's are
  /// float64 or an output key says otherwise: in map mode with poses far from the origin (UTM), float32 rounds the
  /// fixed-frame positions (positionRounding; widenXyzForPoses sets output.float64_xyz where that matters).
  [[nodiscard]] PointBuffer makeCloud(const std::vector<SampleId> &ids, bool with_frame_field,
                                      double *seconds_normals = nullptr) const;

  /// The resolved config: hierarchy.cell_size and output.level as the pipeline runs them (see resolvedConfig).
  [[nodiscard]] const HpdsConfig &config() const { return config_; }
  /// How the output level and the level-0 cell were chosen from the config given (for logs and reports).
  [[nodiscard]] const OutputResolution &outputResolution() const { return resolution_; }
  [[nodiscard]] const Hierarchy &hierarchy() const { return hierarchy_; }
  [[nodiscard]] int outputLevel() const { return output_level_; }
  /// Deepest level a frame is inserted down to (see contract).
  [[nodiscard]] int buildDepth() const { return build_depth_; }
  /// Build levels 0..level too (e.g. levels a node publishes besides the output). std::invalid_argument outside
  /// 0..max_depth.
  void requireLevel(int level);
  [[nodiscard]] const FrameCounters &totals() const { return totals_; }
  [[nodiscard]] std::uint32_t framesProcessed() const { return frames_; }
  /// Bytes held: the hierarchy (samples, grids, insertion scratch) and the per-frame scratch. Scratch grown for a
  /// rare huge frame is given back once recent frames are far smaller (bounded memory in long runs).
  [[nodiscard]] std::size_t memUsage() const;
  /// Index the next frame gets (its `frame` tag and its random-order seed offset). Scan-mode workers that share a
  /// stream set it to the input index, so the output does not depend on which worker took the frame.
  void setNextFrameIndex(std::uint32_t index) { frames_ = index; }
  /// While `flag` is set (by any thread; it must outlive its use here), addFrame and normals() throw Interrupted
  /// (util/Interrupt.hpp) at their next stage boundary: before they start, before each level's insertion pass, before
  /// the normals. An interrupted frame leaves the map unfinished: discard the pipeline. nullptr: never (the default).
  void setInterrupt(const std::atomic<bool> *flag) { interrupt_ = flag; }

  /// Map mode: replaces the map with `map` (e.g. read by loadMap in HierarchyFile.hpp) and numbers the next frame
  /// `next_frame`, as if the frames that built `map` had gone through this pipeline. Throws std::invalid_argument,
  /// leaving the pipeline unchanged, outside map mode, when the map's cell_size/max_depth differ from the config, or
  /// when frames already taken have other point fields than the map's (every later frame would be refused).
  void replaceMap(Hierarchy &&map, std::uint32_t next_frame);
  /// Map mode: forgets every sample and the map's point fields (the next frame with points sets them again); frames
  /// keep their numbering. The way out for a stream whose fields changed for good (a driver restarted with other
  /// fields), whose frames the map refuses. std::invalid_argument in scan mode.
  void clearMap();

 private:
  // Map files carry the kept normals (io/HierarchyFile.hpp).
  friend void saveMap(const std::string &path, const Pipeline &pipeline);
  friend void saveMap(AtomicFile &file, const Pipeline &pipeline);
  friend std::string loadMap(const std::string &path, Pipeline &pipeline);

  void requireLiveIds(const std::vector<SampleId> &ids, const char *what) const;
  /// Map mode: offers the map's normals estimates for the output samples the last frame hit (`fresh`: its new ids).
  void updateMapNormals(const std::vector<SampleId> &fresh, const double viewpoint[3], const NormalParams &params);
  /// Map mode: the kept normals of ids, estimated from the map where none is kept.
  [[nodiscard]] std::vector<SampleNormal> keptNormals(const std::vector<SampleId> &ids, const NormalParams &params,
                                                      std::vector<LocalPca> *neighbourhoods) const;
  /// normals() for ids already checked by requireLiveIds.
  [[nodiscard]] std::vector<SampleNormal> normalsOfLive(const std::vector<SampleId> &ids,
                                                        std::vector<LocalPca> *neighbourhoods) const;

  OutputResolution resolution_;
  const std::atomic<bool> *interrupt_ = nullptr;
  HpdsConfig config_;
  int output_level_;
  int build_depth_;
  // Normals with normals.neighborhood_level_offset: the level whose cells the normals average the last frame's
  // points in (-1: the normals read the hierarchy's own levels), and those cell centroids (3 doubles each).
  int fine_level_;
  std::vector<double> fine_points_;
  // Their search grids, the first radii sorted while the frame is inserted when a second thread is allowed.
  std::shared_ptr<AveragingGrids> fine_grids_;
  // Map mode with those normals: what each sample keeps (normalsOfLive reads it; null otherwise).
  std::shared_ptr<MapNormals> map_normals_;
  // samplesHitByLastFrame(0, output level, 2 r_L) of the last frame, as the map's normals took it.
  std::vector<SampleId> hit_cache_;
  bool hit_cache_valid_ = false;
  // With a second thread: the neighbourhoods it estimated while the frame was inserted, for the first early_done_
  // samples the insertion published (point indices in early_points_), and each sample's entry (early_slot_, by id;
  // kNoSample: none). The frame's first normals() takes them and lets them go.
  std::vector<std::uint32_t> early_points_;
  std::vector<LocalPca> early_chosen_;
  std::vector<std::uint8_t> early_have_;
  mutable std::vector<std::uint32_t> early_slot_;
  mutable std::size_t early_done_ = 0;
  Hierarchy hierarchy_;
  FrameCounters totals_;
  std::uint32_t frames_ = 0;
  bool map_layout_fixed_ = false;  ///< map mode: a frame (or a loaded map) has set the map's point layout
  // Per-frame scratch, and a slowly decaying peak of recent frame sizes that decides when to give it back.
  std::vector<double> xyz_;
  std::vector<std::uint32_t> candidates_;
  double recent_points_ = 0.0;
};

}  // namespace hpds
