// The sampling record in a samples PLY's header: written by writePly, read back bit for bit, absent from other
// files, and refused with the path when malformed; the file stays readable as a cloud by PCL's and hpds's readers.

#include <gtest/gtest.h>

#include <clocale>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <string>

#include "IoTestSupport.hpp"
#include "hpds/io/PlyWriter.hpp"
#include "hpds/io/SamplingRecord.hpp"
#include "hpds/pcl/PointCloudFile.hpp"

namespace fs = std::filesystem;
using namespace hpds;
using hpds::test::expectError;
using hpds::test::readBytes;
using hpds::test::ScratchDir;
using hpds::test::writeBytes;
using hpds::test::xyzLayout;

namespace {

PointBuffer twoPoints() {
  PointLayout l = xyzLayout(FieldType::Float32);
  l.append("level", FieldType::UInt8);
  PointBuffer b(l, 2);
  for (std::size_t i = 0; i < 2; ++i)
    for (std::size_t k = 0; k < 4; ++k) writeFromDouble(b.record(i), l.fields[k], static_cast<double>(i + k));
  return b;
}

// A PLY header with `line` where writePly puts the record, and one vertex.
std::string plyWith(const std::string &line) {
  std::string s = "ply\nformat ascii 1.0\ncomment written by hpds\n" + line +
                  "\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n";
  return s;
}

}  // namespace

TEST(SamplingRecord, ReadsBackBitForBitAndTheCloudStaysReadable) {
  const ScratchDir scratch("sampling_record");
  const std::string path = (scratch.path / "s.ply").string();
  // A derived cell (spacing 0.1 at level 5) is not a short decimal: it must come back with every bit.
  const SamplingRecord written{0.1 * 32.0 / (std::sqrt(3.0) / 2.0), 8, 5};
  writePly(path, twoPoints(), written);
  const std::optional<SamplingRecord> back = readSamplingRecord(path);
  ASSERT_TRUE(back.has_value());
  EXPECT_EQ(std::memcmp(&back->cell_size, &written.cell_size, sizeof(double)), 0) << back->cell_size;
  EXPECT_EQ(back->max_depth, 8);
  EXPECT_EQ(back->output_level, 5);
  // Still a samples file (an input folder leaves it out) and still the same cloud.
  const std::string text = readBytes(path);
  EXPECT_EQ(text.rfind("ply\nformat binary_little_endian 1.0\ncomment written by hpds\ncomment hpds sampling ", 0), 0u)
      << text.substr(0, 200);
  const PointBuffer cloud = readPointCloud(path);
  ASSERT_EQ(cloud.size(), 2u);
  EXPECT_EQ(readAsDouble(cloud.record(1), *cloud.layout().find("level")), 4.0);
}

TEST(SamplingRecord, IsWrittenTheSameUnderADecimalCommaLocale) {
  // A program embedding the library may set LC_NUMERIC; the header must still say 0.5, not 0,5.
  const ScratchDir scratch("sampling_record_locale");
  const std::string path = (scratch.path / "s.ply").string();
  const char *previous = std::setlocale(LC_NUMERIC, nullptr);
  const std::string saved = previous ? previous : "C";
  const bool comma = std::setlocale(LC_NUMERIC, "de_DE.UTF-8") != nullptr;
  writePly(path, twoPoints(), SamplingRecord{0.5, 3, 2});
  const std::optional<SamplingRecord> back = readSamplingRecord(path);
  std::setlocale(LC_NUMERIC, saved.c_str());
  ASSERT_TRUE(back.has_value());
  EXPECT_EQ(back->cell_size, 0.5);
  EXPECT_NE(readBytes(path).find("cell_size 0.5 max_depth 3 output_level 2\n"), std::string::npos);
  if (!comma) GTEST_LOG_(INFO) << "no de_DE.UTF-8 locale here: checked under the C locale only";
}

TEST(SamplingRecord, IsAbsentFromOtherFiles) {
  const ScratchDir scratch("sampling_record_absent");
  const fs::path &dir = scratch.path;
  writePly((dir / "points.ply").string(), twoPoints());
  writePly((dir / "samples.ply").string(), twoPoints(), PlyContent::kSamples);
  writePcd((dir / "points.pcd").string(), twoPoints());
  writeBytes(dir / "frame.bin", std::string(4096, '\x01'));  // a KITTI scan: no newline for a long way
  writeBytes(dir / "crlf.ply", "ply\r\nformat ascii 1.0\r\nelement vertex 0\r\nproperty float x\r\nend_header\r\n");
  for (const char *name : {"points.ply", "samples.ply", "points.pcd", "frame.bin", "crlf.ply"})
    EXPECT_FALSE(readSamplingRecord((dir / name).string()).has_value()) << name;
  // A record written with CRLF line ends is still found.
  writeBytes(dir / "crlf_record.ply",
             "ply\r\nformat ascii 1.0\r\ncomment hpds sampling cell_size 2 max_depth 4 output_level 1\r\n"
             "element vertex 0\r\nproperty float x\r\nend_header\r\n");
  const auto crlf = readSamplingRecord((dir / "crlf_record.ply").string());
  ASSERT_TRUE(crlf.has_value());
  EXPECT_EQ(crlf->cell_size, 2.0);
  EXPECT_EQ(crlf->output_level, 1);
  expectError([&] { (void)readSamplingRecord((dir / "missing.ply").string()); }, (dir / "missing.ply").string(),
              {"file not found"});
}

TEST(SamplingRecord, AMalformedOrOutOfRangeRecordIsRefusedWithThePath) {
  const ScratchDir scratch("sampling_record_bad");
  const struct {
    const char *line;
    const char *says;
  } cases[] = {
      {"comment hpds sampling", "malformed header line"},
      {"comment hpds sampling cell_size 4 max_depth 8", "malformed header line"},
      {"comment hpds sampling cell_size 4x max_depth 8 output_level 5", "malformed header line"},
      {"comment hpds sampling cell_size 4 max_depth 8 output_level 5 extra", "malformed header line"},
      {"comment hpds sampling max_depth 8 cell_size 4 output_level 5", "malformed header line"},
      {"comment hpds sampling cell_size nan max_depth 8 output_level 5", "out of range"},
      {"comment hpds sampling cell_size 0 max_depth 8 output_level 5", "out of range"},
      {"comment hpds sampling cell_size 1e7 max_depth 8 output_level 5", "out of range"},
      {"comment hpds sampling cell_size 4 max_depth 22 output_level 5", "out of range"},
      {"comment hpds sampling cell_size 4 max_depth 4 output_level 5", "out of range"},
      {"comment hpds sampling cell_size 4 max_depth 8 output_level -1", "out of range"},
      {"comment hpds sampling cell_size 4 max_depth 8 output_level 5\ncomment hpds sampling cell_size 4 max_depth 8 "
       "output_level 5",
       "two 'comment hpds sampling' lines"},
  };
  int i = 0;
  for (const auto &c : cases) {
    const fs::path path = scratch.path / ("bad_" + std::to_string(i++) + ".ply");
    writeBytes(path, plyWith(c.line));
    expectError([&] { (void)readSamplingRecord(path.string()); }, path.string(), {c.says});
  }
  // Another comment that merely starts alike is not a record.
  const fs::path other = scratch.path / "other.ply";
  writeBytes(other, plyWith("comment hpds samplingx 1"));
  EXPECT_FALSE(readSamplingRecord(other.string()).has_value());
  // A header that never ends within 1 MiB.
  const fs::path endless = scratch.path / "endless.ply";
  writeBytes(endless, "ply\n" + std::string(1 << 20, 'c') + "\n");
  expectError([&] { (void)readSamplingRecord(endless.string()); }, endless.string(), {"1 MiB"});
}

TEST(SamplingRecord, ARecordNoReaderTakesIsNotWritten) {
  const ScratchDir scratch("sampling_record_write");
  const fs::path path = scratch.path / "s.ply";
  for (const SamplingRecord &r : {SamplingRecord{0.0, 8, 5}, SamplingRecord{std::nan(""), 8, 5},
                                  SamplingRecord{4.0, 22, 5}, SamplingRecord{4.0, 4, 5}, SamplingRecord{4.0, 8, -1}}) {
    expectError([&] { writePly(path.string(), twoPoints(), r); }, path.string(), {"cannot write PLY", "out of range"});
    EXPECT_FALSE(fs::exists(path));
  }
}
