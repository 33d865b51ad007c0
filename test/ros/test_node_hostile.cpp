// rostest node: malformed and hostile PointCloud2 messages keep hpds alive, each counted where it belongs; gaps in
// header.seq are counted as lost upstream; every kind of drop is also logged (seen on /rosout). Runs without the
// shared data (clouds are generated here).
//
// Parameters: ~target (hpds with a deep queue), ~overload_target (hpds with queue_size 1), ~seq_target (hpds for the
// numbering gaps), ~log_target (hpds without a transform to its output frame, queue_size 1).
#include <gtest/gtest.h>
#include <geometry_msgs/TransformStamped.h>
#include <rosgraph_msgs/Log.h>
#include <tf2_msgs/TFMessage.h>
#include <topic_tools/shape_shifter.h>

#include <algorithm>
#include <cstring>
#include <limits>
#include <random>

#include "RosTestUtil.hpp"

namespace {

using hpds_test::Collector;
using hpds_test::LogCollector;
using sensor_msgs::PointCloud2;
using sensor_msgs::PointCloud2Ptr;
using sensor_msgs::PointField;

PointField field(const std::string &name, std::uint32_t offset, std::uint8_t type, std::uint32_t count = 1) {
  PointField f;
  f.name = name;
  f.offset = offset;
  f.datatype = type;
  f.count = count;
  return f;
}

// n points on a wavy 20 m x 20 m patch: x y z float32, intensity float32, ring uint16 (point_step 16 with padding).
PointCloud2Ptr validCloud(std::size_t n, std::uint32_t seed, const ros::Time &stamp) {
  auto msg = boost::make_shared<PointCloud2>();
  msg->header.frame_id = "lidar";
  msg->header.stamp = stamp;
  msg->fields = {field("x", 0, PointField::FLOAT32), field("y", 4, PointField::FLOAT32),
                 field("z", 8, PointField::FLOAT32), field("intensity", 12, PointField::FLOAT32),
                 field("ring", 16, PointField::UINT16)};
  msg->point_step = 20;
  msg->width = static_cast<std::uint32_t>(n);
  msg->height = 1;
  msg->row_step = msg->width * msg->point_step;
  msg->is_dense = true;
  msg->data.resize(std::size_t(msg->row_step));
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-10.f, 10.f);
  for (std::size_t i = 0; i < n; ++i) {
    const float x = u(rng), y = u(rng), z = 0.3f * std::sin(x) + 0.01f * u(rng), in = 100.f;
    const std::uint16_t ring = std::uint16_t(i % 32);
    std::uint8_t *r = msg->data.data() + i * msg->point_step;
    std::memcpy(r, &x, 4);
    std::memcpy(r + 4, &y, 4);
    std::memcpy(r + 8, &z, 4);
    std::memcpy(r + 12, &in, 4);
    std::memcpy(r + 16, &ring, 2);
  }
  return msg;
}

/// A node's log, diagnostics, input and output, connected: what a test that feeds it frames and reads its counters
/// and log lines needs.
struct NodeProbe {
  NodeProbe(ros::NodeHandle &nh, const std::string &target)
      : logs(nh, target), diag(nh, target.substr(1)), pub(nh.advertise<PointCloud2>(target + "/input", 10)),
        output(nh, target + "/output") {}
  [[nodiscard]] bool connected() {
    return hpds_test::waitFor(
        [&] { return pub.getNumSubscribers() > 0 && output.connected() && logs.connected() && diag.updates() > 0; },
        30.0);
  }
  LogCollector logs;
  hpds_test::DiagnosticsReader diag;
  ros::Publisher pub;
  Collector<PointCloud2> output;
};

class HostileTest : public testing::Test {
 protected:
  void SetUp() override {
    ros::NodeHandle pnh("~");
    target_ = pnh.param<std::string>("target", "/hpds_hostile");
    overload_target_ = pnh.param<std::string>("overload_target", "/hpds_overload");
  }
  std::string target_, overload_target_;
  ros::NodeHandle nh_;
};

TEST_F(HostileTest, MalformedAndFuzzedMessagesAreCountedAndTheNodeSurvives) {
  ros::Publisher pub = nh_.advertise<PointCloud2>(target_ + "/input", 2000);
  Collector<PointCloud2> output(nh_, target_ + "/output");
  hpds_test::DiagnosticsReader diag(nh_, target_.substr(1));
  ASSERT_TRUE(hpds_test::waitFor([&] { return pub.getNumSubscribers() > 0 && output.connected(); }, 30.0));
  ASSERT_TRUE(hpds_test::waitFor([&] { return diag.updates() > 0; }, 30.0)) << "no diagnostics from " << target_;

  std::uint64_t sent = 0;
  auto send = [&](const PointCloud2Ptr &m) {
    pub.publish(m);
    ++sent;
    ros::WallDuration(0.002).sleep();  // keeps the transport's queues from dropping: every message must be counted
  };
  ros::Time stamp(50, 0);
  auto next = [&] { return stamp += ros::Duration(0.1); };

  // 1. One message per malformed case, each counted under its own reason.
  const std::vector<std::pair<std::string, std::function<void(PointCloud2 &)>>> malformed = {
      {"big_endian", [](PointCloud2 &m) { m.is_bigendian = true; }},
      {"bad_datatype", [](PointCloud2 &m) { m.fields[3].datatype = 13; }},
      {"bad_count", [](PointCloud2 &m) { m.fields[4].count = 0; }},
      {"field_outside_point", [](PointCloud2 &m) { m.fields[4].offset = 19; }},
      {"duplicate_field", [](PointCloud2 &m) { m.fields[3].name = "y"; }},
      {"missing_xyz", [](PointCloud2 &m) { m.fields.erase(m.fields.begin() + 2); }},
      {"bad_xyz", [](PointCloud2 &m) { m.fields[0].count = 3; }},
      {"bad_row_step", [](PointCloud2 &m) { m.row_step = 7; }},
      {"data_size", [](PointCloud2 &m) { m.data.resize(m.data.size() - 3); }},
      {"overlapping_xyz", [](PointCloud2 &m) { m.fields[1].offset = 0; }},
  };
  for (const auto &[reason, mutate] : malformed) {
    auto m = validCloud(500, 1, next());
    mutate(*m);
    send(m);
  }
  // 2. Valid but hostile: NaN-only (unorganised and organised), zero-size, float64 xyz with Inf, integer extras.
  auto nan_cloud = validCloud(1000, 2, next());
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (std::size_t i = 0; i < 1000; ++i)
    for (int a = 0; a < 3; ++a) std::memcpy(nan_cloud->data.data() + i * 20 + 4 * a, &nan, 4);
  nan_cloud->is_dense = false;
  send(nan_cloud);
  auto nan_organized = boost::make_shared<PointCloud2>(*nan_cloud);
  nan_organized->header.stamp = next();
  nan_organized->width = 50;
  nan_organized->height = 20;
  nan_organized->row_step = 50 * 20;
  send(nan_organized);
  auto empty = validCloud(0, 3, next());
  send(empty);
  auto empty_organized = validCloud(0, 3, next());
  empty_organized->width = 16;
  empty_organized->height = 0;
  empty_organized->row_step = 16 * 20;
  send(empty_organized);
  auto wide = boost::make_shared<PointCloud2>();
  wide->header.stamp = next();
  wide->header.frame_id = "lidar";
  wide->fields = {field("x", 0, PointField::FLOAT64), field("y", 8, PointField::FLOAT64),
                  field("z", 16, PointField::FLOAT64), field("t", 24, PointField::INT8, 3)};
  wide->point_step = 27;
  wide->width = 300;
  wide->height = 1;
  wide->row_step = 300 * 27;
  wide->data.resize(300 * 27);
  for (int i = 0; i < 300; ++i) {
    const double p[3] = {i % 2 ? std::numeric_limits<double>::infinity() : 0.01 * i, 1e300 * (i % 3 == 0), 0.5};
    std::memcpy(wide->data.data() + i * 27, p, 24);
  }
  send(wide);
  const std::uint64_t hostile_valid = 5;

  // 3. Fuzzed layouts and bytes: any outcome but a crash; each message processed or dropped as malformed.
  std::mt19937 rng(7);
  for (int i = 0; i < 300; ++i) {
    auto m = validCloud(64, 100 + i, next());
    const int edits = 1 + int(rng() % 4);
    for (int e = 0; e < edits; ++e) {
      PointField &f = m->fields[rng() % m->fields.size()];
      switch (rng() % 8) {
        case 0: f.datatype = std::uint8_t(rng() % 10); break;
        case 1: f.offset = rng() % 2 ? rng() : rng() % 24; break;
        case 2: f.count = rng() % 3; break;
        case 3: m->point_step = rng() % 32; m->row_step = m->width * m->point_step; break;
        case 4: m->height = rng() % 3; break;
        case 5: m->data.resize(rng() % (m->data.size() + 40)); break;
        case 6: for (auto &b : m->data) b = std::uint8_t(rng()); break;  // NaN, Inf, huge values, garbage
        case 7: f.name = std::string(1 + rng() % 3, char('a' + rng() % 26)); break;
      }
    }
    send(m);
  }

  // 4. A frame whose every point is NaN is processed, and counted as empty like a zero-size one.
  ASSERT_TRUE(hpds_test::waitFor(
      [&] { return diag.value("frames processed") + diag.value("dropped malformed") == double(sent); }, 30.0));
  const double empty_before = diag.value("frames empty");
  auto all_nan = validCloud(500, 3, next());
  std::fill(all_nan->data.begin(), all_nan->data.end(), std::uint8_t(0xFF));  // x, y, z all NaN
  send(all_nan);
  EXPECT_TRUE(hpds_test::waitFor([&] { return diag.value("frames empty") == empty_before + 1.0; }, 30.0))
      << "frames empty " << diag.value("frames empty") << " after " << empty_before;

  // 5. Still alive: a valid frame gives output.
  output.clear();
  const ros::Time last = next();
  send(validCloud(5000, 9, last));
  ASSERT_TRUE(hpds_test::waitFor(
      [&] {
        for (const auto &m : output.messages())
          if (m->header.stamp == last) return true;
        return false;
      },
      60.0))
      << "no output after the hostile messages";
  ASSERT_TRUE(hpds_test::waitFor([&] { return diag.value("frames received") == double(sent); }, 30.0))
      << "received " << diag.value("frames received") << " of " << sent;
  ASSERT_TRUE(hpds_test::waitFor(
      [&] { return diag.value("frames processed") + diag.value("dropped malformed") == double(sent); }, 30.0))
      << "processed " << diag.value("frames processed") << " + malformed " << diag.value("dropped malformed")
      << " != " << sent;
  for (const auto &[reason, mutate] : malformed)
    EXPECT_GE(diag.value("dropped malformed " + reason), 1.0) << reason;
  EXPECT_GE(diag.value("frames processed"), double(hostile_valid + 1));
  EXPECT_GE(diag.value("frames empty"), 2.0);
  EXPECT_GE(diag.value("points skipped invalid"), 2000.0 + 150.0);
  EXPECT_EQ(diag.value("dropped overload"), 0.0);
}

TEST_F(HostileTest, OverloadDropsTheOldestAndCountsIt) {
  ros::Publisher pub = nh_.advertise<PointCloud2>(overload_target_ + "/input", 100);
  Collector<PointCloud2> output(nh_, overload_target_ + "/output");
  hpds_test::DiagnosticsReader diag(nh_, overload_target_.substr(1));
  ASSERT_TRUE(hpds_test::waitFor([&] { return pub.getNumSubscribers() > 0 && output.connected(); }, 30.0));
  const int n = 30;
  ros::Time last;
  for (int i = 0; i < n; ++i) {
    last = ros::Time(80 + i, 0);
    pub.publish(validCloud(60000, 200 + i, last));
    ros::WallDuration(0.005).sleep();
  }
  // The newest frame wins: the last one published is always processed.
  ASSERT_TRUE(hpds_test::waitFor(
      [&] {
        for (const auto &m : output.messages())
          if (m->header.stamp == last) return true;
        return false;
      },
      120.0));
  // Every frame is processed or counted: dropped from the node's queue (overload) or, when the subscriber's thread
  // did not run for several frames (a loaded machine, a sanitizer build), by roscpp's queue before the callback saw
  // it, which the header.seq gap counts as lost upstream.
  ASSERT_TRUE(hpds_test::waitFor(
      [&] {
        return diag.value("frames processed") + diag.value("dropped overload") + diag.value("frames lost upstream") ==
               double(n);
      },
      30.0))
      << "processed " << diag.value("frames processed") << " overload " << diag.value("dropped overload")
      << " lost upstream " << diag.value("frames lost upstream");
  EXPECT_GT(diag.value("dropped overload"), 0.0);
  EXPECT_LT(diag.value("frames processed"), double(n));
}

// The message as a ShapeShifter, whose header.seq roscpp passes on as it is (rosbag play works the same way): the
// only way to publish a numbering with gaps.
boost::shared_ptr<topic_tools::ShapeShifter> asShapeShifter(const PointCloud2 &msg) {
  const std::uint32_t size = ros::serialization::serializationLength(msg);
  std::vector<std::uint8_t> bytes(size);
  ros::serialization::OStream out(bytes.data(), size);
  ros::serialization::serialize(out, msg);
  auto shifter = boost::make_shared<topic_tools::ShapeShifter>();
  shifter->morph(ros::message_traits::md5sum<PointCloud2>(), ros::message_traits::datatype<PointCloud2>(),
                 ros::message_traits::definition<PointCloud2>(), "");
  ros::serialization::IStream in(bytes.data(), size);
  shifter->read(in);
  return shifter;
}

TEST_F(HostileTest, GapsInHeaderSeqAreCountedAsLostUpstreamAndLogged) {
  const std::string target = ros::NodeHandle("~").param<std::string>("seq_target", "/hpds_seq");
  LogCollector logs(nh_, target);
  hpds_test::DiagnosticsReader diag(nh_, target.substr(1));
  Collector<PointCloud2> output(nh_, target + "/output");
  const std::vector<std::uint32_t> seqs = {0, 1, 2, 5, 6, 10, 11};  // 2 + 3 missing
  ros::Publisher pub = asShapeShifter(*validCloud(10, 1, ros::Time(1, 0)))->advertise(nh_, target + "/input", 100);
  ASSERT_TRUE(hpds_test::waitFor(
      [&] { return pub.getNumSubscribers() > 0 && output.connected() && logs.connected() && diag.updates() > 0; },
      30.0));
  for (std::size_t i = 0; i < seqs.size(); ++i) {
    auto m = validCloud(500, 300 + std::uint32_t(i), ros::Time(120 + i, 0));
    m->header.seq = seqs[i];
    pub.publish(*asShapeShifter(*m));
    ros::WallDuration(0.01).sleep();
  }
  ASSERT_TRUE(hpds_test::waitFor([&] { return diag.value("frames processed") == double(seqs.size()); }, 30.0))
      << "processed " << diag.value("frames processed");
  EXPECT_EQ(diag.value("frames received"), double(seqs.size()));
  // Counted and logged, but not as drops of the node's (they never reached it; a throttle upstream skips numbers
  // on purpose), so the node does not WARN for them.
  EXPECT_EQ(diag.value("frames lost upstream"), 5.0);
  EXPECT_EQ(diag.value("dropped total"), 0.0);
  ros::WallDuration(0.5).sleep();  // more diagnostics periods (0.2 s), covering the last frames
  EXPECT_LT(diag.highestLevel(), int(diagnostic_msgs::DiagnosticStatus::WARN));
  EXPECT_TRUE(hpds_test::waitFor(
      [&] { return logs.has(rosgraph_msgs::Log::WARN, {"never arrived", "counted in /diagnostics as 'frames lost upstream'"}); }, 10.0))
      << logs.dump();
}

// ROS 1 drivers and old bags write frame ids with a leading slash ("/odom"), which tf2 refuses (it warned on every
// lookup, ~50 lines per frame, and every frame was dropped as no_transform); the node looks them up without it.
TEST_F(HostileTest, FrameIdsWithALeadingSlashAreLookedUpWithoutIt) {
  const std::string target = ros::NodeHandle("~").param<std::string>("slash_target", "/hpds_slash");
  hpds_test::DiagnosticsReader diag(nh_, target.substr(1));
  Collector<PointCloud2> output(nh_, target + "/output");
  ros::Publisher pub = nh_.advertise<PointCloud2>(target + "/input", 10);
  ASSERT_TRUE(hpds_test::waitFor(
      [&] { return pub.getNumSubscribers() > 0 && output.connected() && diag.updates() > 0; }, 30.0));
  for (int i = 0; i < 3; ++i) {
    auto m = validCloud(500, 900 + std::uint32_t(i), ros::Time(300 + i, 0));
    m->header.frame_id = i == 2 ? "//odom" : "/odom";
    pub.publish(m);
    ros::WallDuration(0.05).sleep();
  }
  ASSERT_TRUE(hpds_test::waitFor([&] { return diag.value("frames processed") == 3.0; }, 30.0))
      << "processed " << diag.value("frames processed") << ", no_transform " << diag.value("dropped no_transform");
  EXPECT_EQ(diag.value("dropped no_transform"), 0.0);
  EXPECT_TRUE(hpds_test::waitFor([&] { return output.size() >= 3; }, 10.0));
}

// Each reason a frame is dropped for is logged (throttled), not only counted. A node that has no transform to its
// output frame and a queue of one: a malformed message, then a burst of valid ones, each of which waits for tf.
TEST_F(HostileTest, DropsAreLoggedNotOnlyCounted) {
  const std::string target = ros::NodeHandle("~").param<std::string>("log_target", "/hpds_logs");
  LogCollector logs(nh_, target);
  hpds_test::DiagnosticsReader diag(nh_, target.substr(1));
  Collector<PointCloud2> output(nh_, target + "/output");
  ros::Publisher pub = nh_.advertise<PointCloud2>(target + "/input", 100);
  ASSERT_TRUE(hpds_test::waitFor(
      [&] { return pub.getNumSubscribers() > 0 && output.connected() && logs.connected() && diag.updates() > 0; },
      30.0));
  // Two malformed frames of different reasons within the 5 s throttle (0.1 s apart, so that queue_size 1 keeps
  // both): each reason has its own throttle, so both are logged.
  auto bad = validCloud(100, 1, ros::Time(200, 0));
  bad->row_step = 7;
  pub.publish(bad);
  ros::WallDuration(0.1).sleep();
  auto bad2 = validCloud(100, 2, ros::Time(200, 50000000));
  bad2->is_bigendian = true;
  pub.publish(bad2);
  ros::WallDuration(0.1).sleep();
  const int burst = 10;
  for (int i = 0; i < burst; ++i) pub.publish(validCloud(100, 400 + i, ros::Time(201 + i, 0)));
  ASSERT_TRUE(hpds_test::waitFor(
      [&] {
        return diag.value("dropped malformed") + diag.value("dropped no_transform") + diag.value("dropped overload") +
                   diag.value("frames lost upstream") ==
               double(burst + 2);
      },
      60.0))
      << "malformed " << diag.value("dropped malformed") << ", no_transform " << diag.value("dropped no_transform")
      << ", overload " << diag.value("dropped overload");
  EXPECT_GT(diag.value("dropped overload"), 0.0);
  EXPECT_TRUE(hpds_test::waitFor(
      [&] {
        return logs.has(rosgraph_msgs::Log::ERROR, {"dropped malformed PointCloud2", "bad_row_step"}) &&
               logs.has(rosgraph_msgs::Log::ERROR, {"dropped malformed PointCloud2", "big_endian"}) &&
               logs.has(rosgraph_msgs::Log::WARN, {"no transform", "counted as no_transform"}) &&
               logs.has(rosgraph_msgs::Log::WARN, {"counted as overload", "ros.queue_size 1"});
      },
      10.0))
      << logs.dump();
}

// A zero header.stamp makes tf hand out its latest transform instead of the one of the capture: the frame is
// processed, and said once to have a stamp the driver must fix.
TEST_F(HostileTest, ZeroStampsAreProcessedAndWarnedAboutOnce) {
  const std::string target = ros::NodeHandle("~").param<std::string>("slash_target", "/hpds_slash");
  LogCollector logs(nh_, target);
  hpds_test::DiagnosticsReader diag(nh_, target.substr(1));
  ros::Publisher pub = nh_.advertise<PointCloud2>(target + "/input", 10);
  ASSERT_TRUE(
      hpds_test::waitFor([&] { return pub.getNumSubscribers() > 0 && logs.connected() && diag.updates() > 0; }, 30.0));
  const double before = diag.value("frames processed");
  const double zero_before = diag.value("frames with zero stamp");
  for (int i = 0; i < 2; ++i) {
    auto m = validCloud(500, 950 + std::uint32_t(i), ros::Time(0, 0));
    m->header.frame_id = "odom";
    pub.publish(m);
    ros::WallDuration(0.05).sleep();
  }
  ASSERT_TRUE(hpds_test::waitFor([&] { return diag.value("frames processed") == before + 2; }, 30.0))
      << "processed " << diag.value("frames processed") << " after " << before;
  EXPECT_TRUE(hpds_test::waitFor(
      [&] { return logs.has(rosgraph_msgs::Log::WARN, {"zero header.stamp", "latest transform", "driver's stamps"}); },
      10.0))
      << logs.dump();
  ros::WallDuration(0.5).sleep();
  EXPECT_EQ(logs.count(rosgraph_msgs::Log::WARN, {"zero header.stamp"}), 1u) << logs.dump();
  EXPECT_TRUE(hpds_test::waitFor([&] { return diag.value("frames with zero stamp") == zero_before + 2; }, 10.0))
      << "frames with zero stamp " << diag.value("frames with zero stamp") << " after " << zero_before;
}

// Map mode forgets samples by design (map/evict_distance, 100 m by default): counted in /diagnostics and said once at
// INFO, so that a map saved or shown later is not taken for the whole drive. Frames in the fixed frame have their
// sensor at its origin: a frame 150 m out is evicted before the next one.
TEST_F(HostileTest, EvictionsAreCountedAndSaidOnce) {
  NodeProbe node(nh_, ros::NodeHandle("~").param<std::string>("slash_target", "/hpds_slash"));
  ASSERT_TRUE(node.connected());
  const double processed = node.diag.value("frames processed"), evicted = node.diag.value("samples evicted");
  for (int i = 0; i < 3; ++i) {
    auto m = validCloud(500, 990 + std::uint32_t(i), ros::Time(2000 + i, 0));
    m->header.frame_id = "odom";
    for (std::size_t k = 0; k < 500; ++k) {  // x += 150 m
      float x;
      std::memcpy(&x, m->data.data() + k * m->point_step, 4);
      x += 150.0f;
      std::memcpy(m->data.data() + k * m->point_step, &x, 4);
    }
    node.pub.publish(m);
    ros::WallDuration(0.1).sleep();
  }
  ASSERT_TRUE(hpds_test::waitFor([&] { return node.diag.value("frames processed") == processed + 3; }, 30.0))
      << "processed " << node.diag.value("frames processed") << " after " << processed;
  EXPECT_TRUE(hpds_test::waitFor([&] { return node.diag.value("samples evicted") > evicted + 100; }, 10.0))
      << "samples evicted " << node.diag.value("samples evicted") << " after " << evicted;
  EXPECT_TRUE(hpds_test::waitFor(
      [&] { return node.logs.has(rosgraph_msgs::Log::INFO, {"the map evicts samples from now on", "samples evicted"}); },
      10.0))
      << node.logs.dump();
  ros::WallDuration(0.5).sleep();
  EXPECT_EQ(node.logs.count(rosgraph_msgs::Log::INFO, {"the map evicts samples from now on"}), 1u) << node.logs.dump();
}

// Found in a ROS map-mode trial: a relocalisation (odom -> sensor stepping 60 m in one frame) put the next frame's
// points elsewhere in the map, without a word. Counted as a pose jump and warned about; the frame is processed.
TEST_F(HostileTest, APoseJumpIsCountedAndWarnedAbout) {
  NodeProbe node(nh_, ros::NodeHandle("~").param<std::string>("slash_target", "/hpds_slash"));
  ASSERT_TRUE(node.connected());
  // A plain /tf publisher, not tf2_ros's broadcaster: the test waits for the node's listener to connect, or the
  // first transform is lost.
  ros::Publisher tf = nh_.advertise<tf2_msgs::TFMessage>("/tf", 10);
  ASSERT_TRUE(hpds_test::waitFor([&] { return tf.getNumSubscribers() > 0; }, 30.0)) << "no tf listener";
  const double processed = node.diag.value("frames processed"), jumps = node.diag.value("pose jumps");
  // 1 s apart: 0.5 m is a walk, 59.5 m is no vehicle's speed. Stamps after the other tests' (no step back). The
  // three transforms go out well before the clouds: on a loaded machine one sent just before its cloud could arrive
  // after the node's ros/tf_timeout (0.2 s) and drop the frame as no_transform.
  const double x[3] = {0.0, 0.5, 60.0};
  tf2_msgs::TFMessage transforms;
  for (int i = 0; i < 3; ++i) {
    geometry_msgs::TransformStamped t;
    t.header.stamp = ros::Time(5000 + i, 0);
    t.header.frame_id = "odom";
    t.child_frame_id = "jumpy";
    t.transform.translation.x = x[i];
    t.transform.rotation.w = 1.0;
    transforms.transforms.push_back(t);
  }
  tf.publish(transforms);
  ros::WallDuration(1.0).sleep();
  for (int i = 0; i < 3; ++i) {
    auto m = validCloud(500, 1990 + std::uint32_t(i), ros::Time(5000 + i, 0));
    m->header.frame_id = "jumpy";
    node.pub.publish(m);
    ros::WallDuration(0.3).sleep();
  }
  ASSERT_TRUE(hpds_test::waitFor([&] { return node.diag.value("frames processed") == processed + 3; }, 30.0))
      << "processed " << node.diag.value("frames processed") << " after " << processed << "\n" << node.logs.dump();
  EXPECT_TRUE(hpds_test::waitFor([&] { return node.diag.value("pose jumps") == jumps + 1; }, 10.0))
      << "pose jumps " << node.diag.value("pose jumps") << " after " << jumps;
  EXPECT_TRUE(hpds_test::waitFor(
      [&] {
        return node.logs.has(rosgraph_msgs::Log::WARN,
                             {"the sensor moved 59.5 m in 1 s", "~clear_map", "counted in /diagnostics as 'pose jumps'"});
      },
      10.0))
      << node.logs.dump();
}

// Scan mode: a cloud without header.frame_id is processed (its outputs keep the empty frame), warned about once
// and counted, so that a driver that never sets it shows in /diagnostics as well as in the log.
TEST_F(HostileTest, EmptyFrameIdsAreProcessedCountedAndWarnedAboutOnce) {
  // A node no other test sends an empty frame_id, so that its one warning is this test's.
  NodeProbe node(nh_, ros::NodeHandle("~").param<std::string>("seq_target", "/hpds_seq"));
  ASSERT_TRUE(node.connected());
  const double before = node.diag.value("frames processed");
  const double counted_before = node.diag.value("frames without frame_id");
  for (int i = 0; i < 3; ++i) {
    auto m = validCloud(500, 970 + std::uint32_t(i), ros::Time(100 + i, 0));
    m->header.frame_id.clear();
    node.pub.publish(m);
    ros::WallDuration(0.05).sleep();
  }
  ASSERT_TRUE(hpds_test::waitFor([&] { return node.diag.value("frames processed") == before + 3; }, 30.0))
      << "processed " << node.diag.value("frames processed") << " after " << before;
  EXPECT_TRUE(hpds_test::waitFor([&] { return node.diag.value("frames without frame_id") == counted_before + 3; }, 10.0))
      << "frames without frame_id " << node.diag.value("frames without frame_id") << " after " << counted_before;
  EXPECT_TRUE(hpds_test::waitFor(
      [&] { return node.logs.has(rosgraph_msgs::Log::WARN, {"empty header.frame_id", "frames without frame_id"}); }, 10.0))
      << node.logs.dump();
  ros::WallDuration(0.5).sleep();
  EXPECT_EQ(node.logs.count(rosgraph_msgs::Log::WARN, {"empty header.frame_id"}), 1u) << node.logs.dump();
}

}  // namespace

int main(int argc, char **argv) { return hpds_test::runRosTests(argc, argv, "test_node_hostile"); }
