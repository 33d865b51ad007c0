// Map persistence: save/load round trips bit for bit, a loaded map continues exactly like an uninterrupted run,
// and every damaged, forged or mismatched file is refused with a message naming it, never half-loaded.
#include <gtest/gtest.h>

#include <sys/stat.h>

#include <cstring>
#include <fstream>
#include <functional>
#include <map>
#include <set>
#include <tuple>

#include "TestData.hpp"
#include "hpds/io/HierarchyFile.hpp"
#include "hpds/pipeline/Pipeline.hpp"
#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds/pcl/PointCloudFile.hpp"
#include "hpds/io/PoseFile.hpp"
#include "hpds/util/Crc32.hpp"

namespace hpds {
namespace {

namespace fs = std::filesystem;

std::vector<std::uint8_t> readBytes(const fs::path &p) {
  std::ifstream f(p, std::ios::binary);
  return std::vector<std::uint8_t>(std::istreambuf_iterator<char>(f), {});
}

void writeBytes(const fs::path &p, const std::vector<std::uint8_t> &b) {
  std::ofstream f(p, std::ios::binary | std::ios::trunc);
  f.write(reinterpret_cast<const char *>(b.data()), static_cast<std::streamsize>(b.size()));
}

// Bytes of the kept normals' settings in a version-3 header (HierarchyFile.cpp's layout).
constexpr std::size_t kNormalSettingsBytes = 4 + 8 + 4 + 4 + 4 + 8 + 8 + 8 + 3 * 8;
// Bytes of a version-3 header's free-slot count, its last field.
constexpr std::size_t kFreeCountBytes = 8;

std::uint32_t u32At(const std::vector<std::uint8_t> &b, std::size_t at) {
  std::uint32_t v;
  std::memcpy(&v, b.data() + at, 4);
  return v;
}

// Recomputes both checksums so that a deliberately forged file passes the integrity check and reaches the
// semantic checks behind it.
void refreshCrcs(std::vector<std::uint8_t> &b) {
  const std::uint32_t header_size = u32At(b, 12);
  const std::uint32_t h = crc32(b.data(), header_size - 4);
  std::memcpy(b.data() + header_size - 4, &h, 4);
  const std::uint32_t body = crc32(b.data() + header_size, b.size() - header_size - 4);
  std::memcpy(b.data() + b.size() - 4, &body, 4);
}

SyntheticLidarConfig drive(int frames) {
  SyntheticLidarConfig c;
  c.beams = 16;
  c.azimuth_steps = 600;
  c.frames = frames;
  c.speed = 3.0;
  return c;
}

HpdsConfig mapConfig() {
  HpdsConfig c;
  c.mode = Mode::Map;
  c.hierarchy.max_depth = 6;
  c.map.evict_distance = 25.0;  // leaves free slots behind, which the file must compact
  c.order.seed = 7;
  return c;
}

using SampleKey = std::tuple<double, double, double, int, std::uint32_t>;

std::set<SampleKey> sampleSet(const Hierarchy &h) {
  std::set<SampleKey> s;
  for (SampleId id = 0; id < h.idBound(); ++id)
    if (h.isLive(id)) s.emplace(h.position(id)[0], h.position(id)[1], h.position(id)[2], h.level(id), h.frameIndex(id));
  return s;
}

// The same live samples in the same (increasing id) order, ids aside: what a version-2 file, which compacted its
// ids, gives back.
void expectSameSamplesInOrder(const Hierarchy &a, const Hierarchy &b) {
  ASSERT_EQ(a.sampleCount(), b.sampleCount());
  ASSERT_EQ(a.recordLayout(), b.recordLayout());
  ASSERT_EQ(a.cellSize(), b.cellSize());
  ASSERT_EQ(a.maxDepth(), b.maxDepth());
  const std::size_t step = a.recordLayout().point_step;
  SampleId j = 0;
  for (SampleId i = 0; i < a.idBound(); ++i) {
    if (!a.isLive(i)) continue;
    while (j < b.idBound() && !b.isLive(j)) ++j;
    ASSERT_TRUE(b.isLive(j));
    ASSERT_EQ(std::memcmp(a.position(i), b.position(j), 24), 0) << i;
    ASSERT_EQ(a.level(i), b.level(j));
    ASSERT_EQ(a.frameIndex(i), b.frameIndex(j));
    ASSERT_EQ(a.toViewpoint(i), b.toViewpoint(j));
    if (step) {
      ASSERT_EQ(std::memcmp(a.record(i), b.record(j), step), 0);
    }
    ASSERT_EQ(b.sampleInCell(b.level(j), b.position(j)), j);  // the grids know it
    ++j;
  }
  for (int l = 0; l <= a.maxDepth(); ++l) EXPECT_EQ(a.countAtLevel(l), b.countAtLevel(l));
}

// Identical, ids included: every sample at its own id, the same free slots in the same reuse order.
void expectIdentical(const Hierarchy &a, const Hierarchy &b) {
  expectSameSamplesInOrder(a, b);
  ASSERT_EQ(a.idBound(), b.idBound());
  for (SampleId i = 0; i < a.idBound(); ++i) ASSERT_EQ(a.isLive(i), b.isLive(i)) << i;
  EXPECT_EQ(a.freeSlots(), b.freeSlots());
}

/// A hierarchy (4 m cells, depth 3) whose records carry `count` elements of `type` after x y z, holding `n` level-0
/// samples of frame 1 in a row along x, 4 m apart: the maps whose free slots cost far more memory than their file.
Hierarchy rowWithLargeRecords(FieldType type, std::uint32_t count, int n) {
  Hierarchy h(4.0, 3);
  PointLayout layout;
  for (const char *name : {"x", "y", "z"}) layout.append(name, FieldType::Float32);
  layout.append("blob", type, count);
  h.setRecordLayout(layout);
  const float view[3] = {0, 0, 1};
  for (int i = 0; i < n; ++i) {
    const double p[3] = {0.5 + 4.0 * i, 0.5, 0.5};
    h.restoreSample(p, 0, 1, view, nullptr);
  }
  return h;
}

class MapFile : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    lidar_ = new SyntheticLidar(drive(12));
    pipeline_ = new Pipeline(mapConfig());
    for (int i = 0; i < 8; ++i) pipeline_->addFrame(lidar_->frame(i).frame);
    // An empty frame 15 m further on evicts without inserting, so free slots remain that the file must compact.
    Frame ahead = lidar_->frame(7).frame;
    ahead.points = PointBuffer(ahead.points.layout(), 0);
    ahead.sensor_to_fixed.translation().x() += 15.0;
    pipeline_->addFrame(ahead);
  }
  static void TearDownTestSuite() {
    delete pipeline_;
    delete lidar_;
  }
  fs::path savedMap(const fs::path &dir) {
    const fs::path p = dir / "map.hpdsmap";
    saveMap(p.string(), *pipeline_);
    return p;
  }
  static SyntheticLidar *lidar_;
  static Pipeline *pipeline_;
};
SyntheticLidar *MapFile::lidar_ = nullptr;
Pipeline *MapFile::pipeline_ = nullptr;

TEST_F(MapFile, RoundTripKeepsEverySampleBitForBit) {
  const auto dir = test::scratchDir("map_roundtrip");
  ASSERT_GT(pipeline_->totals().evicted, 0u);
  ASSERT_LT(pipeline_->hierarchy().sampleCount(), pipeline_->hierarchy().idBound());  // there are holes
  const fs::path p = savedMap(dir);
  const LoadedHierarchy loaded = loadHierarchy(p.string());
  EXPECT_EQ(loaded.next_frame, 9u);
  expectIdentical(pipeline_->hierarchy(), loaded.hierarchy);
  // Exact size: nothing but the header, the entries (with the normals the map keeps) and the checksum.
  const auto &l = pipeline_->hierarchy().recordLayout();
  const std::vector<std::uint8_t> bytes = readBytes(p);
  // The normals' size, then the settings they were estimated with, close the header.
  const std::uint32_t normal_bytes = u32At(bytes, u32At(bytes, 12) - 4 - kFreeCountBytes - kNormalSettingsBytes - 4);
  EXPECT_EQ(normal_bytes, 33u) << "a map-mode pipeline with normals keeps them";
  const std::size_t free_slots = pipeline_->hierarchy().freeSlots().size();
  EXPECT_GT(free_slots, 0u);
  EXPECT_EQ(fs::file_size(p), u32At(bytes, 12) + 4 * free_slots +
                                  pipeline_->hierarchy().sampleCount() * (41 + l.point_step + normal_bytes) + 4);
  // Loading into a pipeline and saving again reproduces the file byte for byte, and the same output cloud, normals
  // included: the loaded samples keep the normals of the frames that saw them.
  Pipeline again(mapConfig());
  loadMap(p.string(), again);
  saveMap((dir / "again.hpdsmap").string(), again);
  EXPECT_EQ(bytes, readBytes(dir / "again.hpdsmap"));
  EXPECT_EQ(pipeline_->makeCloud(pipeline_->outputSamples(), true).bytes(),
            again.makeCloud(again.outputSamples(), true).bytes());
  // The hierarchy alone round-trips without them.
  saveHierarchy((dir / "plain.hpdsmap").string(), loaded.hierarchy, loaded.next_frame);
  const std::vector<std::uint8_t> plain = readBytes(dir / "plain.hpdsmap");
  EXPECT_EQ(u32At(plain, u32At(plain, 12) - 8 - kFreeCountBytes), 0u);
  expectIdentical(pipeline_->hierarchy(), loadHierarchy((dir / "plain.hpdsmap").string()).hierarchy);
  // No temporaries are left beside the file.
  std::size_t entries = 0;
  for (const auto &e : fs::directory_iterator(dir)) entries += e.path().string().find("tmp.") == std::string::npos;
  EXPECT_EQ(entries, std::size_t(std::distance(fs::directory_iterator(dir), fs::directory_iterator())));
}

TEST_F(MapFile, EmptyAndRecordlessHierarchiesRoundTrip) {
  const auto dir = test::scratchDir("map_empty");
  Hierarchy empty(2.0, 3);
  saveHierarchy((dir / "e.hpdsmap").string(), empty, 5);
  const LoadedHierarchy a = loadHierarchy((dir / "e.hpdsmap").string());
  EXPECT_EQ(a.hierarchy.sampleCount(), 0u);
  EXPECT_EQ(a.next_frame, 5u);
  EXPECT_EQ(a.hierarchy.cellSize(), 2.0);
  Hierarchy bare(1.0, 4);  // no record layout: samples without records
  const double p[3] = {0.5, 0.25, -3.0};
  const float v[3] = {1, 2, 3};
  bare.restoreSample(p, 2, 9, v, nullptr);
  saveHierarchy((dir / "b.hpdsmap").string(), bare);
  expectIdentical(bare, loadHierarchy((dir / "b.hpdsmap").string()).hierarchy);
}

TEST_F(MapFile, LoadedMapContinuesExactlyLikeAnUninterruptedRun) {
  const auto dir = test::scratchDir("map_continue");
  Pipeline whole(mapConfig());
  for (int i = 0; i < 12; ++i) whole.addFrame(lidar_->frame(i).frame);

  Pipeline first(mapConfig());
  for (int i = 0; i < 5; ++i) first.addFrame(lidar_->frame(i).frame);
  saveMap((dir / "m.hpdsmap").string(), first);
  Pipeline second(mapConfig());
  loadMap((dir / "m.hpdsmap").string(), second);
  EXPECT_EQ(second.framesProcessed(), 5u);
  for (int i = 5; i < 12; ++i) second.addFrame(lidar_->frame(i).frame);
  EXPECT_EQ(sampleSet(whole.hierarchy()), sampleSet(second.hierarchy()));
  EXPECT_GT(whole.hierarchy().sampleCount(), 1000u);
}

// Output normals of every output sample, as bytes (NaN for invalid ones compares equal this way).
std::vector<std::uint8_t> outputNormalBytes(const Pipeline &p) {
  const std::vector<SampleNormal> n = p.normals(p.outputSamples());
  std::vector<std::uint8_t> b(n.size() * 16);
  for (std::size_t i = 0; i < n.size(); ++i) {
    std::memcpy(b.data() + 16 * i, n[i].normal, 12);
    const float valid = n[i].valid ? 1.0f : 0.0f;
    std::memcpy(b.data() + 16 * i + 12, &valid, 4);
  }
  return b;
}

TEST_F(MapFile, KeptNormalsOfOtherSettingsAreDroppedWithAWarning) {
  const auto dir = test::scratchDir("map_normal_settings");
  const fs::path p = savedMap(dir);
  // The map's own settings: its kept normals come back, and with them the normals it output.
  Pipeline same(mapConfig());
  EXPECT_EQ(loadMap(p.string(), same), "");
  EXPECT_EQ(outputNormalBytes(same), outputNormalBytes(*pipeline_));

  // Other settings each: the kept normals are dropped and the warning names both settings. The oracle is the same map
  // loaded without any kept normals (saveHierarchy leaves them out), where every normal is this run's own estimate.
  const fs::path bare = dir / "bare.hpdsmap";
  saveHierarchy(bare.string(), pipeline_->hierarchy(), pipeline_->framesProcessed());
  for (const auto &[edit, key] : std::vector<std::pair<std::function<void(HpdsConfig &)>, std::string>>{
           {[](HpdsConfig &c) { c.normals.max_growth = 4.0; }, "max_growth 4"},
           {[](HpdsConfig &c) { c.normals.radius = 0.6; }, "radius 0.6 m"},
           {[](HpdsConfig &c) { c.normals.neighborhood_level_offset = 1; }, "neighborhood_level_offset 1"},
           // At the map's own cell (derived from the spacing before), the coarsest level with r_D <= 0.25 m.
           {[&](HpdsConfig &c) {
              c.hierarchy.cell_size = pipeline_->config().hierarchy.cell_size;
              c.output.spacing = 0.25;
            },
            "output level 4"}}) {
    HpdsConfig other = mapConfig();
    edit(other);
    Pipeline loaded(other);
    const std::string w = loadMap(p.string(), loaded);
    EXPECT_NE(w.find("other settings"), std::string::npos) << key << ": " << w;
    EXPECT_NE(w.find(key), std::string::npos) << key << ": " << w;
    EXPECT_NE(w.find("dropped"), std::string::npos) << key << ": " << w;
    Pipeline oracle(other);
    EXPECT_EQ(loadMap(bare.string(), oracle), "") << key;
    EXPECT_EQ(outputNormalBytes(loaded), outputNormalBytes(oracle)) << key;
    // Both then continue alike: the next frame's normals are this run's in both.
    loaded.addFrame(lidar_->frame(8).frame);
    oracle.addFrame(lidar_->frame(8).frame);
    EXPECT_EQ(outputNormalBytes(loaded), outputNormalBytes(oracle)) << key;
  }
  // The test could fail: with its kept normals, the map's output differs from its own fresh estimate.
  Pipeline fresh(mapConfig());
  (void)loadMap(bare.string(), fresh);
  EXPECT_NE(outputNormalBytes(fresh), outputNormalBytes(same));
  // threads changes no result, so it is not a setting that drops them.
  HpdsConfig two = mapConfig();
  two.threads = 2;
  Pipeline threaded(two);
  EXPECT_EQ(loadMap(p.string(), threaded), "");
  EXPECT_EQ(outputNormalBytes(threaded), outputNormalBytes(*pipeline_));
}

TEST_F(MapFile, VersionTwoFilesKeepTheirNormalsWhateverTheSettings) {
  // A version-2 file is this build's file without the settings block: its kept normals load as before (it cannot
  // say what made them).
  const auto dir = test::scratchDir("map_version2");
  std::vector<std::uint8_t> b = readBytes(savedMap(dir));
  const std::uint32_t header_size = u32At(b, 12);
  std::uint64_t free_count = 0;
  std::memcpy(&free_count, b.data() + header_size - 4 - kFreeCountBytes, 8);
  ASSERT_GT(free_count, 0u);
  // Version 2 had no free slots (its ids were compacted): the free ids go, and the settings and count from the header.
  b.erase(b.begin() + header_size, b.begin() + header_size + 4 * free_count);
  b.erase(b.begin() + (header_size - 4 - kFreeCountBytes - kNormalSettingsBytes), b.begin() + (header_size - 4));
  b[8] = 2;
  const std::uint32_t v2_size = header_size - static_cast<std::uint32_t>(kNormalSettingsBytes + kFreeCountBytes);
  std::memcpy(b.data() + 12, &v2_size, 4);
  refreshCrcs(b);
  const fs::path p = dir / "v2.hpdsmap";
  writeBytes(p, b);
  HpdsConfig other = mapConfig();
  other.normals.max_growth = 4.0;
  Pipeline loaded(other);
  EXPECT_EQ(loadMap(p.string(), loaded), "");
  Pipeline same(mapConfig());
  EXPECT_EQ(loadMap(p.string(), same), "");
  EXPECT_EQ(outputNormalBytes(same), outputNormalBytes(*pipeline_));
  const Hierarchy v2 = loadHierarchy(p.string()).hierarchy;
  expectSameSamplesInOrder(pipeline_->hierarchy(), v2);
  EXPECT_EQ(v2.idBound(), v2.sampleCount()) << "a version-2 file's samples take ids 0..n-1";
}

// The fixture's map has free slots (an empty frame evicted samples and inserted none): an uninterrupted run reuses
// them in its own order, so a loaded map must keep ids, holes and that order to continue with the same output
// cloud, order included (a compacted map gave the same samples in another order).
TEST_F(MapFile, LoadedMapWithFreeSlotsContinuesInTheSameOrder) {
  const auto dir = test::scratchDir("map_free_slots");
  ASSERT_LT(pipeline_->hierarchy().sampleCount(), pipeline_->hierarchy().idBound());
  auto run = [&](Pipeline &p) {
    for (int i = 0; i < 8; ++i) p.addFrame(lidar_->frame(i).frame);
    Frame ahead = lidar_->frame(7).frame;
    ahead.points = PointBuffer(ahead.points.layout(), 0);
    ahead.sensor_to_fixed.translation().x() += 15.0;
    p.addFrame(ahead);
  };
  Pipeline whole(mapConfig());
  run(whole);
  Pipeline first(mapConfig());
  run(first);
  saveMap((dir / "m.hpdsmap").string(), first);
  Pipeline second(mapConfig());
  EXPECT_EQ(loadMap((dir / "m.hpdsmap").string(), second), "");
  EXPECT_EQ(second.hierarchy().idBound(), whole.hierarchy().idBound());
  EXPECT_EQ(second.makeCloud(second.outputSamples(), true).bytes(), whole.makeCloud(whole.outputSamples(), true).bytes());
  for (int i = 8; i < 12; ++i) {
    whole.addFrame(lidar_->frame(i).frame);
    second.addFrame(lidar_->frame(i).frame);
    ASSERT_EQ(second.makeCloud(second.outputSamples(), true).bytes(), whole.makeCloud(whole.outputSamples(), true).bytes())
        << "frame " << i;
  }
  EXPECT_EQ(second.hierarchy().idBound(), whole.hierarchy().idBound());
}

// A free slot is 4 bytes in the file but a record in memory: a file whose free slots would take more than 16 times its
// body plus 64 MiB (here 1 100 free slots of 64 KiB records beside 2 samples) loads compacted instead.
TEST(MapFileFreeSlots, FreeSlotsThatWouldTakeFarMoreMemoryThanTheFileLoadCompacted) {
  const auto dir = test::scratchDir("map_compacted");
  Hierarchy h = rowWithLargeRecords(FieldType::UInt8, 65536, 1102);
  const double origin[3] = {0.0, 0.0, 0.0};
  EXPECT_EQ(h.evictOutside(origin, 6.0), 1100u);
  saveHierarchy((dir / "holes.hpdsmap").string(), h, 3);
  EXPECT_LT(fs::file_size(dir / "holes.hpdsmap"), 200000u);
  const LoadedHierarchy loaded = loadHierarchy((dir / "holes.hpdsmap").string());
  EXPECT_TRUE(loaded.ids_compacted);
  expectSameSamplesInOrder(h, loaded.hierarchy);
  EXPECT_EQ(loaded.hierarchy.idBound(), 2u);
  EXPECT_TRUE(loaded.hierarchy.freeSlots().empty());
  // Most of them reused: the ids are kept.
  const float v[3] = {0, 0, 1};
  for (int i = 0; i < 1000; ++i) {
    const double p[3] = {0.5, 4.5 + 4.0 * i, 0.5};
    h.restoreSample(p, 0, 2, v, nullptr);
  }
  ASSERT_EQ(h.freeSlots().size(), 100u);
  saveHierarchy((dir / "few.hpdsmap").string(), h, 3);
  const LoadedHierarchy kept = loadHierarchy((dir / "few.hpdsmap").string());
  EXPECT_FALSE(kept.ids_compacted);
  expectIdentical(h, kept.hierarchy);
}

// A map of 4 MiB records whose samples were all evicted is a few dozen bytes of file; loading its free slots
// reserved 1024 records of headroom (4 GiB; a forged file with 16 MiB records asked for 16 GiB). The headroom is
// capped at 64 MiB of records.
TEST(MapFileFreeSlots, FreeSlotsOfHugeRecordsReserveBoundedMemory) {
  const auto dir = test::scratchDir("map_huge_free");
  Hierarchy h = rowWithLargeRecords(FieldType::UInt32, 1u << 20, 3);  // 4 MiB records
  EXPECT_LE(h.memUsage(), std::size_t(256) << 20);
  const double far_away[3] = {1000.0, 0.0, 0.0};
  ASSERT_EQ(h.evictOutside(far_away, 1.0), 3u);
  saveHierarchy((dir / "empty.hpdsmap").string(), h, 1);
  EXPECT_LT(fs::file_size(dir / "empty.hpdsmap"), 1000u);
  const LoadedHierarchy loaded = loadHierarchy((dir / "empty.hpdsmap").string());
  EXPECT_FALSE(loaded.ids_compacted);
  EXPECT_EQ(loaded.hierarchy.idBound(), 3u);
  EXPECT_EQ(loaded.hierarchy.freeSlots(), h.freeSlots());
  EXPECT_LE(loaded.hierarchy.memUsage(), std::size_t(256) << 20);
}

// Free slots of small records keep their ids even when they outnumber the samples many times (a map that an empty
// frame far ahead has nearly emptied), and the map continues like the run that saved it.
TEST_F(MapFile, AMapOfMostlyFreeSlotsKeepsItsIds) {
  const auto dir = test::scratchDir("map_mostly_free");
  Pipeline emptied(mapConfig());
  for (int i = 0; i < 3; ++i) emptied.addFrame(lidar_->frame(i).frame);
  Frame far = lidar_->frame(2).frame;  // an empty frame 40 m on: nearly every sample is evicted
  far.points = PointBuffer(far.points.layout(), 0);
  far.sensor_to_fixed.translation().x() += 40.0;
  emptied.addFrame(far);
  ASSERT_GT(emptied.hierarchy().freeSlots().size(), 4 * emptied.hierarchy().sampleCount());
  saveMap((dir / "m.hpdsmap").string(), emptied);
  Pipeline loaded(mapConfig());
  EXPECT_EQ(loadMap((dir / "m.hpdsmap").string(), loaded), "");
  expectIdentical(emptied.hierarchy(), loaded.hierarchy());
  emptied.addFrame(lidar_->frame(3).frame);
  loaded.addFrame(lidar_->frame(3).frame);
  EXPECT_EQ(loaded.makeCloud(loaded.outputSamples(), true).bytes(),
            emptied.makeCloud(emptied.outputSamples(), true).bytes());
}

TEST_F(MapFile, MismatchedConfigAndScanModeAreRefusedAndLeaveThePipelineUnchanged) {
  const auto dir = test::scratchDir("map_mismatch");
  const fs::path p = savedMap(dir);
  HpdsConfig other = mapConfig();
  other.hierarchy.cell_size = 2.0;
  Pipeline q(other);
  q.addFrame(lidar_->frame(0).frame);
  const std::size_t before = q.hierarchy().sampleCount();
  try {
    loadMap(p.string(), q);
    FAIL() << "loaded a map with another cell size";
  } catch (const std::runtime_error &e) {
    EXPECT_NE(std::string(e.what()).find(p.string()), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("cell_size"), std::string::npos) << e.what();
  }
  EXPECT_EQ(q.hierarchy().sampleCount(), before);
  EXPECT_EQ(q.framesProcessed(), 1u);
  HpdsConfig deeper = mapConfig();
  deeper.hierarchy.max_depth = 7;
  Pipeline d(deeper);
  EXPECT_THROW(loadMap(p.string(), d), std::runtime_error);
  HpdsConfig scan = mapConfig();
  scan.mode = Mode::Scan;
  Pipeline s(scan);
  EXPECT_THROW(loadMap(p.string(), s), std::invalid_argument);
  EXPECT_THROW(s.replaceMap(Hierarchy(4.0, 6), 0), std::invalid_argument);
  // Saving is refused as loading is (found by a library user: a scan-mode save wrote a file its load refused), and
  // writes nothing.
  const auto scan_path = p.parent_path() / "scan.hpdsmap";
  try {
    saveMap(scan_path.string(), s);
    ADD_FAILURE() << "a scan-mode pipeline's map was saved";
  } catch (const std::invalid_argument &e) {
    EXPECT_NE(std::string(e.what()).find("saving a map needs mode: map"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(scan_path));
  // A frame whose fields differ from the loaded map's is refused by the pipeline, as for a live map.
  Pipeline m(mapConfig());
  loadMap(p.string(), m);
  Frame other_fields;
  PointLayout xyz;
  for (const char *n : {"x", "y", "z"}) xyz.append(n, FieldType::Float64);
  other_fields.points = PointBuffer(xyz, 4);
  try {
    (void)m.addFrame(other_fields);
    ADD_FAILURE() << "a frame of other fields was taken";
  } catch (const std::invalid_argument &e) {
    // Both sets of fields are named, so a user sees what differs.
    const std::string what = e.what();
    EXPECT_NE(what.find("(x y z as float64 float64 float64, 24 bytes)"), std::string::npos) << what;
    EXPECT_NE(what.find("loaded map"), std::string::npos) << what;
  }
  // The other way round: a pipeline that took frames of other fields refuses the map (the node's load_map service
  // answered success, then dropped every later frame).
  Pipeline running(mapConfig());
  Frame xyz_frame;
  xyz_frame.points = PointBuffer(xyz, 1);
  for (const char *n : {"x", "y", "z"}) writeFromDouble(xyz_frame.points.record(0), *xyz.find(n), 1.0);
  (void)running.addFrame(xyz_frame);
  const std::size_t kept = running.hierarchy().sampleCount();
  try {
    loadMap(p.string(), running);
    ADD_FAILURE() << "a map of other fields was loaded";
  } catch (const std::invalid_argument &e) {
    EXPECT_NE(std::string(e.what()).find("differ from those of the frames so far"), std::string::npos) << e.what();
  }
  EXPECT_EQ(running.hierarchy().sampleCount(), kept);
  EXPECT_EQ(running.framesProcessed(), 1u);
}

void expectRefused(const fs::path &p, const std::string &what, const std::string &why) {
  try {
    (void)loadHierarchy(p.string());
    ADD_FAILURE() << why << ": loaded";
  } catch (const std::runtime_error &e) {
    const std::string msg = e.what();
    EXPECT_EQ(msg.rfind(p.string() + ": ", 0), 0u) << why << ": " << msg;
    EXPECT_NE(msg.find(what), std::string::npos) << why << ": " << msg;
  }
}

TEST_F(MapFile, EveryTruncationIsRefused) {
  const auto dir = test::scratchDir("map_trunc");
  const std::vector<std::uint8_t> good = readBytes(savedMap(dir));
  const fs::path p = dir / "cut.hpdsmap";
  const std::uint32_t header_size = u32At(good, 12);
  std::vector<std::size_t> cuts;
  for (std::size_t n = 0; n <= header_size + 8; ++n) cuts.push_back(n);
  for (std::size_t n = header_size + 8; n < good.size(); n += good.size() / 50 + 1) cuts.push_back(n);
  for (std::size_t n = good.size() - 8; n < good.size(); ++n) cuts.push_back(n);
  for (std::size_t n : cuts) {
    writeBytes(p, std::vector<std::uint8_t>(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(n)));
    const std::string what = n == 0 ? "empty" : n < 8 ? "truncated" : "";
    expectRefused(p, what, "cut at " + std::to_string(n));
  }
  std::vector<std::uint8_t> longer = good;
  longer.push_back(0);
  writeBytes(p, longer);
  expectRefused(p, "trailing", "one byte appended");
}

TEST_F(MapFile, EveryHeaderBitFlipAndBodyFlipsAreRefused) {
  const auto dir = test::scratchDir("map_flip");
  const std::vector<std::uint8_t> good = readBytes(savedMap(dir));
  const fs::path p = dir / "flip.hpdsmap";
  const std::uint32_t header_size = u32At(good, 12);
  for (std::size_t byte = 0; byte < header_size; ++byte) {
    std::vector<std::uint8_t> bad = good;
    bad[byte] ^= static_cast<std::uint8_t>(1u << (byte % 8));
    writeBytes(p, bad);
    expectRefused(p, "", "header byte " + std::to_string(byte));
  }
  for (std::size_t byte = header_size; byte < good.size(); byte += good.size() / 40 + 1) {
    std::vector<std::uint8_t> bad = good;
    bad[byte] ^= 0x10;
    writeBytes(p, bad);
    expectRefused(p, "checksum", "body byte " + std::to_string(byte));
  }
}

TEST_F(MapFile, ForgedFilesWithValidChecksumsAreRefusedByMeaning) {
  const auto dir = test::scratchDir("map_forged");
  const std::vector<std::uint8_t> good = readBytes(savedMap(dir));
  const fs::path p = dir / "forged.hpdsmap";
  const std::uint32_t header_size = u32At(good, 12);
  const std::uint32_t step = u32At(good, 40);
  // The saved map keeps normals: their size, then their settings, close the header.
  const std::size_t free_at = header_size - 4 - kFreeCountBytes;
  const std::size_t normal_at = free_at - kNormalSettingsBytes - 4;
  const std::uint32_t normal_bytes = u32At(good, normal_at);
  ASSERT_EQ(normal_bytes, 33u);
  const std::size_t entry = 41 + step + normal_bytes;
  const std::uint32_t free_count = u32At(good, free_at);
  ASSERT_GT(free_count, 1u);
  const std::size_t body = header_size + 4 * std::size_t(free_count);  // the first sample's entry
  auto forged = [&](auto &&edit, const std::string &what, const std::string &why) {
    std::vector<std::uint8_t> b = good;
    edit(b);
    refreshCrcs(b);
    writeBytes(p, b);
    expectRefused(p, what, why);
  };
  forged([](auto &b) { b[8] = 4; }, "unsupported hpds map version 4", "version 4");
  forged([](auto &b) { b[8] = 0; }, "unsupported hpds map version 0", "version 0");
  forged([](auto &b) { b[0] = 'X'; }, "bad magic", "magic");
  forged([](auto &b) { b[24] = 22; }, "invalid hierarchy parameters", "max_depth 22");
  forged([](auto &b) { std::memset(b.data() + 16, 0xFF, 8); }, "invalid hierarchy parameters", "NaN cell size");
  forged([&](auto &b) { b[body + 24] = 7; }, "level 7", "level beyond max_depth");
  forged([&](auto &b) { std::memset(b.data() + body, 0xFF, 8); }, "not finite", "NaN position");
  forged([&](auto &b) { std::memcpy(b.data() + body + entry, b.data() + body, 25); }, "occupied",
         "two samples in one cell");
  forged([](auto &b) { b[40] += 1; }, "", "point_step changed without the body");
  forged([](auto &b) { std::uint64_t n; std::memcpy(&n, b.data() + 32, 8); n += 1; std::memcpy(b.data() + 32, &n, 8); },
         "truncated", "one sample more declared");
  // The first field's datatype byte: after magic..field_count (48), name_len (4), name, offset (4).
  forged([&](auto &b) { b[48 + 4 + u32At(good, 48) + 4] = 9; }, "datatype 9", "bad field datatype");
  forged([&](auto &b) { std::memset(b.data() + 48 + 4 + u32At(good, 48), 0xFF, 4); }, "invalid record layout",
         "field offset beyond the record");
  forged([&](auto &b) { b[normal_at] = 7; }, "kept normals of 7 bytes", "a normal size this build never writes");
  // Free slots: an id beyond every slot, one listed twice, a count that does not match the body.
  forged([&](auto &b) { std::memset(b.data() + header_size, 0xFF, 4); }, "beyond the", "free slot beyond the ids");
  forged([&](auto &b) { std::memcpy(b.data() + header_size + 4, b.data() + header_size, 4); }, "listed twice",
         "free slot twice");
  forged([&](auto &b) { b[free_at] += 1; }, "free slots but", "one free slot more declared");
  // The settings' level (the first i32 after the normals' size), and their radius as NaN.
  forged([&](auto &b) { b[normal_at + 4] = 200; }, "impossible kept normals' settings", "settings level 200");
  forged([&](auto &b) { std::memset(b.data() + normal_at + 8, 0xFF, 8); }, "impossible kept normals' settings",
         "settings radius NaN");
  // Kept normals a map file cannot hold: refused by loadMap, naming the sample, with the pipeline unchanged.
  for (const auto &[edit, why] : std::vector<std::pair<std::function<void(std::vector<std::uint8_t> &)>, std::string>>{
           {[&](auto &b) { b[body + entry - 1] = 9; }, "state 9"},
           {[&](auto &b) {
              b[body + entry - 1] = 2;
              std::memset(b.data() + body + entry - normal_bytes, 0, 12);
            },
            "a valid normal of length 0"}}) {
    std::vector<std::uint8_t> b = good;
    edit(b);
    refreshCrcs(b);
    writeBytes(p, b);
    Pipeline q(mapConfig());
    try {
      loadMap(p.string(), q);
      ADD_FAILURE() << why << ": loaded";
    } catch (const std::runtime_error &e) {
      EXPECT_NE(std::string(e.what()).find("sample 0 has an impossible kept normal"), std::string::npos) << e.what();
    }
    EXPECT_EQ(q.framesProcessed(), 0u) << why;
  }
  const std::string foreign = "ply\nformat binary_little_endian 1.0\nend_header\n";
  writeBytes(p, std::vector<std::uint8_t>(foreign.begin(), foreign.end()));
  expectRefused(p, "bad magic", "a PLY file");
  expectRefused(dir / "missing.hpdsmap", "file not found", "missing");
  expectRefused(dir, "not a regular file", "directory");
}

TEST_F(MapFile, FailedSaveLeavesThePreviousFileAndNoTemporary) {
  const auto dir = test::scratchDir("map_atomic");
  const fs::path p = savedMap(dir);
  const std::vector<std::uint8_t> before = readBytes(p);
  // The target is a directory: the temporary is written, the rename fails, the temporary is removed.
  fs::create_directory(dir / "occupied");
  fs::create_directory(dir / "occupied" / "x");
  EXPECT_THROW(saveMap((dir / "occupied").string(), *pipeline_), std::runtime_error);
  EXPECT_THROW(saveMap((dir / "no_such_dir" / "m.hpdsmap").string(), *pipeline_), std::runtime_error);
  std::size_t files = 0;
  for (const auto &e : fs::directory_iterator(dir)) files += fs::is_regular_file(e.path()) ? 1 : 0;
  EXPECT_EQ(files, 1u);
  EXPECT_EQ(readBytes(p), before);
  // A read-only directory cannot take the temporary; the old file stays (root ignores permissions, skip then).
  fs::permissions(dir, fs::perms::owner_read | fs::perms::owner_exec);
  if (::access(dir.c_str(), W_OK) != 0) {
    EXPECT_THROW(saveMap(p.string(), *pipeline_), std::runtime_error);
    EXPECT_EQ(readBytes(p), before);
  }
  fs::permissions(dir, fs::perms::owner_all);
}

TEST(MapFileBytes, InMemoryLoaderMatchesTheFileLoader) {
  Hierarchy h(4.0, 3);
  const double p[3] = {1, 2, 3};
  const float v[3] = {0, 0, 1};
  h.restoreSample(p, 1, 0, v, nullptr);
  const auto dir = test::scratchDir("map_bytes");
  saveHierarchy((dir / "m").string(), h);
  const auto bytes = readBytes(dir / "m");
  const LoadedHierarchy l = loadHierarchyBytes(bytes.data(), bytes.size(), "mem");
  EXPECT_EQ(l.hierarchy.sampleCount(), 1u);
  EXPECT_THROW((void)loadHierarchyBytes(bytes.data(), bytes.size() - 1, "mem"), std::runtime_error);
  EXPECT_THROW((void)loadHierarchyBytes(nullptr, 0, "mem"), std::runtime_error);
}

TEST(MapFileBytes, HugeRecordsAreSavedInBoundedChunks) {
  // Found by fuzz_map: saving reserved 4096 entries whatever the record size (2.7 GB for 655 kB records).
  Hierarchy h(4.0, 2);
  PointLayout l;
  l.append("x", FieldType::Float32);
  // The largest record the format allows, 16 MiB, in fields of at most kMaxFieldCount elements.
  for (int i = 0; i < 16; ++i)
    l.append("blob" + std::to_string(i), FieldType::UInt8, i < 15 ? (1u << 20) : (1u << 20) - 4);
  ASSERT_EQ(l.point_step, 1u << 24);
  h.setRecordLayout(l);
  std::vector<std::uint8_t> record(l.point_step, 0x5A);
  const float v[3] = {0, 0, 0};
  for (int i = 0; i < 3; ++i) {
    const double p[3] = {10.0 * i, 0, 0};
    h.restoreSample(p, 0, 0, v, record.data());
  }
  const auto dir = test::scratchDir("map_huge");
  saveHierarchy((dir / "m").string(), h);
  const LoadedHierarchy back = loadHierarchy((dir / "m").string());
  expectIdentical(h, back.hierarchy);
}

TEST(MapFileBytes, AMapIsNeverSavedUnderAnotherFormatsName) {
  // The library's saveMap/saveHierarchy refuse it themselves (the CLI and the node checked; a program did not).
  const auto dir = test::scratchDir("map_names");
  Hierarchy h(4.0, 2);
  for (const char *name : {"scan.pcd", "cloud.PLY", "drive.bag", "config.yaml"}) {
    EXPECT_THROW(saveHierarchy((dir / name).string(), h), std::runtime_error) << name;
    EXPECT_FALSE(std::filesystem::exists(dir / name)) << name;
  }
  EXPECT_NO_THROW(saveHierarchy((dir / "map.hpdsmap").string(), h));
}

TEST(MapFileBytes, Crc32MatchesTheStandardCheckValue) {
  const char *s = "123456789";
  EXPECT_EQ(crc32(s, 9), 0xCBF43926u);
  EXPECT_EQ(crc32(s + 4, 5, crc32(s, 4)), 0xCBF43926u);
}

// ---------------------------------------------------------------- CLI

using test::runHpds;
using test::shellQuote;


TEST(MapFileCli, SaveThenLoadContinuesTheMap) {
  const auto tmp = test::scratchDir("map_cli");
  std::string log;
  ASSERT_EQ(runHpds("synth -o " + shellQuote(tmp / "s") + " --frames 4 --beams 8 --azimuth-steps 600", &log), 0) << log;
  auto frame = [&](int i) { return shellQuote(tmp / "s" / ("frame_00000" + std::to_string(i) + ".pcd")); };
  const auto poses = readKittiPoses((tmp / "s" / "poses.txt").string());
  auto posesFile = [&](const fs::path &p, int from, int to) {
    writeKittiPoses(p.string(), std::vector<Eigen::Isometry3d>(poses.begin() + from, poses.begin() + to));
    return shellQuote(p);
  };
  const std::string common = " --mode map --max-depth 6 --seed 3";
  ASSERT_EQ(runHpds("sample " + frame(0) + " " + frame(1) + " " + frame(2) + " " + frame(3) + " --poses " +
                     posesFile(tmp / "p03.txt", 0, 4) + common + " -o " + shellQuote(tmp / "whole.ply"),
                 &log),
            0)
      << log;
  ASSERT_EQ(runHpds("sample " + frame(0) + " " + frame(1) + " --poses " + posesFile(tmp / "p01.txt", 0, 2) + common +
                     " -o " + shellQuote(tmp / "half.ply") + " --save-map " + shellQuote(tmp / "m.hpdsmap"),
                 &log),
            0)
      << log;
  ASSERT_EQ(runHpds("sample " + frame(2) + " " + frame(3) + " --poses " + posesFile(tmp / "p23.txt", 2, 4) + common +
                     " -o " + shellQuote(tmp / "cont.ply") + " --load-map " + shellQuote(tmp / "m.hpdsmap") + " --save-map " +
                     shellQuote(tmp / "m2.hpdsmap"),
                 &log),
            0)
      << log;
  EXPECT_EQ(log.find("the loaded map holds levels"), std::string::npos) << "continued at its own spacing\n" << log;
  EXPECT_EQ(log.find("kept normals"), std::string::npos) << "continued with its own normal settings\n" << log;
  // Continued with other normal settings (a config file): the map loads, its kept normals do not, and it is said.
  {
    std::ofstream(tmp / "growth.yaml") << "normals:\n  max_growth: 4\n";
    ASSERT_EQ(runHpds("sample " + frame(2) + " --poses " + posesFile(tmp / "p2g.txt", 2, 3) + common + " --config " +
                          shellQuote(tmp / "growth.yaml") + " -o " + shellQuote(tmp / "growth.ply") + " --load-map " +
                          shellQuote(tmp / "m.hpdsmap"),
                      &log),
              0)
        << log;
    EXPECT_NE(log.find("hpds: warning: the map's kept normals were estimated with other settings than this run's "
                       "(max_growth 8 in the map, max_growth 4 here): they are dropped"),
              std::string::npos)
        << log;
  }
  // Continued at a finer spacing than the map was built to (levels 0..5 without normals; 0.05 m derives the same
  // cell at level 6): said, with what to set.
  ASSERT_EQ(runHpds("sample " + frame(0) + " --poses " + posesFile(tmp / "p0.txt", 0, 1) + common +
                        " --no-normals -o " + shellQuote(tmp / "coarse.ply") + " --save-map " +
                        shellQuote(tmp / "coarse.hpdsmap"),
                    &log),
            0)
      << log;
  ASSERT_EQ(runHpds("sample " + frame(2) + " --poses " + posesFile(tmp / "p2.txt", 2, 3) + common +
                        " --no-normals --spacing 0.05 -o " + shellQuote(tmp / "finer.ply") + " --load-map " +
                        shellQuote(tmp / "coarse.hpdsmap"),
                    &log),
            0)
      << log;
  EXPECT_NE(log.find("hpds: warning: the loaded map holds levels 0..5 only, and this run builds down to level 6"),
            std::string::npos)
      << log;
  EXPECT_NE(log.find("map.keep_depth 6"), std::string::npos) << log;
  // Same samples with the same normals (the map file keeps them), compared as whole records.
  const PointBuffer whole = readPointCloud((tmp / "whole.ply").string());
  const PointBuffer cont = readPointCloud((tmp / "cont.ply").string());
  ASSERT_GT(whole.size(), 100u);
  ASSERT_NE(whole.layout().find("normal_x"), nullptr);
  ASSERT_EQ(whole.layout(), cont.layout());
  const std::size_t step = whole.layout().point_step;
  std::multiset<std::vector<std::uint8_t>> a, b;
  for (std::size_t i = 0; i < whole.size(); ++i) a.emplace(whole.record(i), whole.record(i) + step);
  for (std::size_t i = 0; i < cont.size(); ++i) b.emplace(cont.record(i), cont.record(i) + step);
  EXPECT_EQ(a, b);

  struct Case {
    std::string args;
    std::string message;
  };
  writeBytes(tmp / "junk.hpdsmap", {1, 2, 3});
  const std::vector<Case> cases = {
      {frame(0) + " --mode scan --save-map " + shellQuote(tmp / "x.hpdsmap"), "--mode map"},
      {frame(0) + " --mode scan --load-map " + shellQuote(tmp / "m.hpdsmap"), "--mode map"},
      {frame(0) + common + " --load-map " + shellQuote(tmp / "nope.hpdsmap"), "nope.hpdsmap: file not found"},
      {frame(0) + common + " --load-map " + shellQuote(tmp / "junk.hpdsmap"), "junk.hpdsmap: not an hpds map file"},
      {frame(0) + " --mode map --max-depth 5 --load-map " + shellQuote(tmp / "m.hpdsmap"), "max_depth"},
      // Another spacing derives another cell: the message said the cells differ, not how to read the map anyway.
      {frame(0) + common + " --spacing 0.15 --load-map " + shellQuote(tmp / "m.hpdsmap"),
       "to read it at another spacing, set hierarchy.cell_size: 3.6950417228136052 and hierarchy.max_depth: 6 "
       "(--cell-size 3.6950417228136052 --max-depth 6)"},
      {frame(0) + common + " --save-map " + shellQuote(tmp / "nodir" / "m.hpdsmap"), "m.hpdsmap"},
  };
  for (const Case &c : cases) {
    EXPECT_EQ(runHpds("sample " + c.args + " -o " + shellQuote(tmp / "o.ply"), &log), 1) << c.args << "\n" << log;
    EXPECT_NE(log.find("hpds: error: "), std::string::npos) << log;
    EXPECT_NE(log.find(c.message), std::string::npos) << c.args << "\n" << log;
  }
}

// A map built down to level 6 (normals on), continued without normals (levels 0..5) and saved: level 6 of the saved
// map then covers the first run's frames only. The load-time check of a later run sees level 6 populated and says
// nothing, so a finer spacing read from that map had holes wherever the shallow run drove (on a synthetic drive,
// half the level-6 samples of one uninterrupted run). The run that saves such a map is the one that can tell.
TEST(MapFileCli, SavingAMapContinuedShallowerThanItWasBuiltSaysSo) {
  const auto tmp = test::scratchDir("map_cli_shallow");
  std::string log;
  ASSERT_EQ(runHpds("synth -o " + shellQuote(tmp / "s") + " --frames 2 --beams 8 --azimuth-steps 600", &log), 0) << log;
  auto frame = [&](int i) { return shellQuote(tmp / "s" / ("frame_00000" + std::to_string(i) + ".pcd")); };
  const auto poses = readKittiPoses((tmp / "s" / "poses.txt").string());
  writeKittiPoses((tmp / "p0.txt").string(), {poses[0]});
  writeKittiPoses((tmp / "p1.txt").string(), {poses[1]});
  const std::string common = " --mode map --max-depth 6";
  { std::ofstream(tmp / "keep.yaml") << "map:\n  keep_depth: 6\n"; }  // levels 6 kept for later reads: a deeper map
  ASSERT_EQ(runHpds("sample " + frame(0) + " --poses " + shellQuote(tmp / "p0.txt") + common + " --config " +
                        shellQuote(tmp / "keep.yaml") + " -o " + shellQuote(tmp / "deep.ply") + " --save-map " +
                        shellQuote(tmp / "deep.hpdsmap"),
                    &log),
            0)
      << log;
  const std::string shallow = "sample " + frame(1) + " --poses " + shellQuote(tmp / "p1.txt") + common +
                              " -o " + shellQuote(tmp / "shallow.ply") + " --load-map " +
                              shellQuote(tmp / "deep.hpdsmap");
  // Nothing saved: nothing to say.
  ASSERT_EQ(runHpds(shallow, &log), 0) << log;
  EXPECT_EQ(log.find("warning"), std::string::npos) << log;
  ASSERT_EQ(runHpds(shallow + " --save-map " + shellQuote(tmp / "shallow.hpdsmap"), &log), 0) << log;
  EXPECT_NE(log.find("hpds: warning: the loaded map holds levels down to 6, but this run built levels 0..5 only"),
            std::string::npos)
      << log;
  EXPECT_NE(log.find("map.keep_depth 6"), std::string::npos) << log;
  // Saved at its own depth: nothing to say.
  ASSERT_EQ(runHpds("sample " + frame(1) + " --poses " + shellQuote(tmp / "p1.txt") + common + " --config " +
                        shellQuote(tmp / "keep.yaml") + " -o " + shellQuote(tmp / "same.ply") + " --load-map " +
                        shellQuote(tmp / "deep.hpdsmap") +
                        " --save-map " + shellQuote(tmp / "same.hpdsmap"),
                    &log),
            0)
      << log;
  EXPECT_EQ(log.find("warning"), std::string::npos) << log;
}

}  // namespace
}  // namespace hpds
