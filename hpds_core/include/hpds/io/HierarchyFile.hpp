// HierarchyFile: saving a map-mode hierarchy to disk and loading it back (persistence across runs).
//
// Contract
// - Format (version 3, all numbers little-endian; version 2 files, whose kept normals do not say what settings
//   made them, and version 1 files, without kept normals, load too), see HierarchyFile.cpp for the byte layout:
//   header  = magic "HPDSMAP\0", version, cell_size, max_depth, next frame index, sample count, record layout
//             (point_step and every field: name, offset, datatype, count), CRC-32 of the header;
//   body    = one fixed-size entry per live sample: x y z (float64), level (uint8), frame index (uint32),
//             to_viewpoint (3 x float32), the record (point_step bytes) and, from saveMap of a map-mode pipeline with
//             kept normals (Pipeline.hpp), that normal (the header then also records the normal settings they were
//             estimated with); then CRC-32 of the body.
//   The file size is fully determined by the header, so truncation and trailing bytes are detected before any
//   sample is read, and nothing is allocated beyond a small multiple of what the file holds.
// - saveHierarchy writes atomically (AtomicFile.hpp): a temporary file in the same directory, fsync'ed, then renamed
//   over `path`. A failure, an exception or a killed process leaves any previous file at `path` untouched; the
//   temporary is removed (a killed process's by the next write into that folder).
// - Everything is kept: samples at their ids (positions bit for bit, levels, frame indices, viewpoint directions,
//   record bytes), and the free slots evicted samples left with the order they are reused in, so that a loaded map
//   continues exactly like an uninterrupted run, its output's order included. Version 2 and 1 files hold no free
//   slots: their samples get ids 0..n-1 in file order. So do the samples of a file whose free slots would take more
//   than 16 times its body plus 64 MiB of memory (LoadedHierarchy::ids_compacted, and loadMap warns): a free slot is
//   4 bytes in the file but a record in memory.
// - loadHierarchy never half-loads: the samples go into a fresh Hierarchy that is returned only when the whole file
//   checked out. Errors are std::runtime_error "<path>: <problem>": missing/unreadable file, not a map file (magic),
//   unsupported version, corrupt header or body (checksum), truncated or oversized file, invalid layout or
//   parameters, a sample the hierarchy refuses (level out of range, non-finite or out-of-range position, two samples
//   in one cell), and, when `expected` is given, a cell_size or max_depth that differs from it.
// - Pipeline integration: saveMap / loadMap below carry the frame counter and the kept normals as well, so that a
//   loaded map continues with the same frame indices, random-order seeds and normals as an uninterrupted run.
//   saveHierarchy / loadHierarchy leave the normals out.
// - Thread-safety: reentrant; concurrent saves to the same path leave one complete file.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "hpds/config/Config.hpp"
#include "hpds/io/AtomicFile.hpp"
#include "hpds/sampling/Hierarchy.hpp"

namespace hpds {

class Pipeline;

inline constexpr std::uint32_t kHierarchyFileVersion = 3;

/// A hierarchy read from a file, with the frame index the next inserted frame should get.
struct LoadedHierarchy {
  Hierarchy hierarchy;
  std::uint32_t next_frame = 0;
  /// True when the file's free slots were dropped and its samples took ids 0..n-1 (see contract).
  bool ids_compacted = false;
};

/// Writes `hierarchy` to `path` atomically (see contract); `next_frame` is stored for the loader.
void saveHierarchy(const std::string &path, const Hierarchy &hierarchy, std::uint32_t next_frame = 0);
/// The same bytes into `file` (its target names the file in messages), without committing it (see writePly).
void saveHierarchy(AtomicFile &file, const Hierarchy &hierarchy, std::uint32_t next_frame = 0);

/// Reads a file written by saveHierarchy. With `expected`, a file whose cell_size or max_depth differ is refused.
[[nodiscard]] LoadedHierarchy loadHierarchy(const std::string &path, const HierarchyConfig *expected = nullptr);

/// Same as loadHierarchy from bytes held in memory (`name` stands for the path in messages).
[[nodiscard]] LoadedHierarchy loadHierarchyBytes(const std::uint8_t *data, std::size_t size,
                                                 const std::string &name, const HierarchyConfig *expected = nullptr);

/// True when `path` ends (case-insensitively) in the extension of another format hpds reads or writes (.pcd, .ply,
/// .bin, .bag, .json, .yaml, .yml, .png, .csv, .txt): a map file named like that is refused, so that saving a map
/// can never replace a point cloud, a bag or a config.
[[nodiscard]] bool isOtherFormatName(const std::string &path);

/// Map mode only: saves the pipeline's map and its frame counter (framesProcessed()); std::invalid_argument for a
/// scan-mode pipeline (nothing written), as loadMap refuses one.
void saveMap(const std::string &path, const Pipeline &pipeline);
/// The same into `file`, without committing it.
void saveMap(AtomicFile &file, const Pipeline &pipeline);

/// After loadMap: a warning (empty when there is nothing to say) when the map holds no sample below a level that
/// `pipeline` builds (a map made at a coarser spacing continued at a finer one): the finer levels then hold only the
/// new frames' samples, so their coverage does not reach the earlier frames' points (map.keep_depth keeps them).
[[nodiscard]] std::string shallowMapWarning(const Pipeline &pipeline);

/// The deepest level that holds a sample, or -1 when the hierarchy is empty.
[[nodiscard]] int deepestPopulatedLevel(const Hierarchy &hierarchy);

/// Before saving a map that was loaded when it held samples down to `loaded_deepest` (deepestPopulatedLevel then)
/// and whose frame counter was `loaded_frames` (framesProcessed then): a warning (empty when there is nothing to
/// say) when `pipeline` has taken frames since and built fewer levels than that. The saved map's
/// deeper levels then cover the earlier runs' frames only, and the load-time check of a later run that reads them
/// (shallowMapWarning) finds them populated and cannot tell.
[[nodiscard]] std::string shallowSaveWarning(const Pipeline &pipeline, int loaded_deepest,
                                             std::uint32_t loaded_frames);

/// Map mode only: loads `path`, checked against the pipeline's hierarchy config, and replaces the pipeline's map with
/// it (strong guarantee: on any error the pipeline is unchanged). Throws std::runtime_error for file problems and
/// std::invalid_argument when the pipeline is not in map mode. Returns a warning (empty when there is nothing to
/// say) when the file's kept normals were estimated with other normal settings than the pipeline's (output level,
/// normals.*): those are dropped, and the samples get normals with the pipeline's settings instead; and when the
/// file's ids were compacted (LoadedHierarchy::ids_compacted).
std::string loadMap(const std::string &path, Pipeline &pipeline);

}  // namespace hpds
