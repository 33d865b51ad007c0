// Helpers shared by the libFuzzer targets.
//
// Contract
// - writeTemp puts the input into a file of a private directory (on tmpfs when /dev/shm exists) so that the
//   file-based readers see exactly the fuzzer's bytes; the directory is removed at exit.
// - exercise runs a cloud that a reader accepted through the pipeline (map mode, normals, output cloud) and the PLY
//   writer/reader: a reader's promise (x/y/z present, valid layout) that does not hold there is a finding.
// - violated reports a broken invariant and aborts, which libFuzzer records as a crash with the input saved.
// - fuzzPointFile is the whole body of the file-reader targets: the input becomes a file "input<extension>", is read
//   with readPointCloud (only std::runtime_error may come out) and an accepted cloud goes through exercise.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "hpds/points/PointBuffer.hpp"

namespace hpds::fuzz {

[[nodiscard]] std::string writeTemp(const std::string &name, const std::uint8_t *data, std::size_t size);

void exercise(const PointBuffer &cloud);

[[noreturn]] void violated(const std::string &what);

int fuzzPointFile(const std::uint8_t *data, std::size_t size, const char *extension);

}  // namespace hpds::fuzz
