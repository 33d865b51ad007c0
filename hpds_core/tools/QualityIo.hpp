// Shared by `hpds analyze` and `hpds render`: a sampling file as plain vectors, input clouds in the fixed frame, and the
// small CSV/JSON writing both commands need.
//
// Contract
// - loadSampling reads any cloud readPointCloud understands. x/y/z are required; `level`, normal_x/y/z, `curvature`
//   and `frame` are picked up when present (vectors left empty otherwise). A `level` value that is not an integer
//   in 0..21 throws std::invalid_argument naming the file.
// - keepFrame keeps the samples of one frame (scan-mode files of several inputs hold one sampling per frame).
// - loadInputs reads each input, applies pose i (KITTI file, one pose per input) when given, and drops the points a
//   sampler skips: non-finite and exact (0,0,0) no-returns.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

namespace hpds::cli {

struct SamplingCloud {
  std::vector<Eigen::Vector3d> xyz;
  std::vector<int> level;               ///< empty when the file has no `level`
  std::vector<Eigen::Vector3d> normal;  ///< empty without normal_x/y/z
  std::vector<float> curvature;         ///< empty without `curvature`
  std::vector<std::uint32_t> frame;     ///< empty without `frame`
  bool has_level = false, has_frame = false;  ///< the file has the field (a sampling of 0 points has it too)

  [[nodiscard]] int maxLevel() const;
};

[[nodiscard]] SamplingCloud loadSampling(const std::string &path);

/// The samples with frame == `frame` (no-op without a frame field).
[[nodiscard]] SamplingCloud keepFrame(const SamplingCloud &cloud, std::uint32_t frame);

[[nodiscard]] std::vector<Eigen::Vector3d> loadInputs(const std::vector<std::string> &inputs,
                                                      const std::string &poses_file);

/// A text file written atomically (AtomicFile): the text is kept in memory and put in place by close(); a TextFile
/// destroyed without close() (an exception on the way) writes nothing. Errors name the path.
class TextFile {
 public:
  explicit TextFile(std::string path) : path_(std::move(path)) {}
  TextFile(const TextFile &) = delete;
  TextFile &operator=(const TextFile &) = delete;
  /// Writes the file (throws std::runtime_error naming the path on failure); no << after it.
  void close();
  template <typename T>
  TextFile &operator<<(const T &v) {
    out_ << v;
    return *this;
  }

 private:
  std::string path_;
  std::ostringstream out_;
};

/// `text` as a JSON string literal: quoted, with quotes, backslashes and control characters escaped.
[[nodiscard]] std::string jsonQuoted(const std::string &text);

/// Shortest round-trip decimal text of a double; "null" for NaN/Inf (valid JSON, empty-safe in CSV readers).
[[nodiscard]] std::string num(double v);

}  // namespace hpds::cli
