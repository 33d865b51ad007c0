// The sampling a samples file was made with, kept in its PLY header so that checks of the file (`hpds verify`,
// `hpds analyze`) need not be told the cell and depth again, and cannot be told wrong ones unnoticed.
//
// Contract
// - The header line is `comment hpds sampling cell_size C max_depth M output_level L`, C printed with 17 significant
//   digits (read back bit for bit), M the hierarchy.max_depth the keys were made for, L the output level (the file
//   holds levels 0..L). writePly puts it right after kPlySamplesComment.
// - readSamplingRecord: std::nullopt when the file is not a PLY file or its header has no such line (written by
//   another tool or an older hpds). std::runtime_error, starting with the path, when the file cannot be opened, when
//   its header does not end within 1 MiB, or when the line is there but malformed or out of range (C not in
//   (0, 1e6], M not in 0..21, L not in 0..M).
// - Thread-safety: free functions, reentrant.
#pragma once

#include <optional>
#include <string>

namespace hpds {

struct SamplingRecord {
  double cell_size = 0.0;  ///< [m] edge of a level-0 cell
  int max_depth = 0;       ///< hierarchy.max_depth: the finest level whose exact keys bounded the inserted points
  int output_level = 0;    ///< the file holds samples of levels 0..output_level
};

/// The PLY header line for `record`, without its newline; std::invalid_argument when `record` is out of the range
/// readSamplingRecord takes.
[[nodiscard]] std::string samplingRecordLine(const SamplingRecord &record);

/// The record in the PLY header of `path`, if it has one (see the contract above).
[[nodiscard]] std::optional<SamplingRecord> readSamplingRecord(const std::string &path);

}  // namespace hpds
