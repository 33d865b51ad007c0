// rostest node: hpds.launch started with nothing but `input:=` (the shipped config/hpds.yaml) gets a frame stream at
// 10 Hz: each output well under half its input, samples at least the default spacing apart, finite normals on nearly
// every sample, aligned fields, and every frame processed. A frame may be dropped only if the node said, once, that
// it cannot keep up (item 1 of the shipped defaults' contract: keep up at 10 Hz on one thread, or say so); whether
// the defaults keep up is a matter of the machine's speed, measured by `make bench`, not asserted here.
//
// Parameters: ~data_dir (shared lidar folder; the real-frame stream is skipped when absent), ~input, ~target.
#include <gtest/gtest.h>
#include <rosgraph_msgs/Log.h>

#include <cmath>
#include <iostream>

#include "RosTestUtil.hpp"
#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds_node/HpdsServer.hpp"

namespace {

using hpds_test::Collector;
using sensor_msgs::PointCloud2;
using sensor_msgs::PointCloud2Ptr;

constexpr double kPeriod = 0.1;  // 10 Hz, the rate of the spinning lidars in ../shared/data/lidar
constexpr double kMaxOutputShare = 0.4;
constexpr double kMinFiniteNormalShare = 0.95;

// The node's log, from before the first frame of any stream to the end (the keep-up warning comes at most once).
Collector<rosgraph_msgs::Log> &rosout() {
  static ros::NodeHandle nh;
  static Collector<rosgraph_msgs::Log> log(nh, "/rosout");
  return log;
}

std::vector<std::string> keepUpWarnings(const std::string &node) {
  std::vector<std::string> found;
  for (const auto &m : rosout().messages())
    if (m->name == node && (hpds_test::contains(m->msg, "cannot keep up") ||
                            hpds_test::contains(m->msg, "fell behind the input for a moment")))
      found.push_back(m->msg);
  return found;
}

// The node's lines for drops behind its first frame (which pays for the node's allocations), said at INFO.
std::size_t startUpDropLines(const std::string &node) {
  std::size_t n = 0;
  for (const auto &m : rosout().messages())
    if (m->name == node && hpds_test::contains(m->msg, "while the first frame was processed")) ++n;
  return n;
}

// Publishes `frames` (in turn) `count` times at 10 Hz of wall time, each with a fresh stamp, and checks every output.
void playAndCheck(const std::vector<PointCloud2Ptr> &frames, int count) {
  ros::NodeHandle nh, pnh("~");
  const std::string input = pnh.param<std::string>("input", "/velodyne_points");
  const std::string target = pnh.param<std::string>("target", "/hpds");
  const hpds_node::NodeConfig config = hpds_node::loadNodeConfigFromParams(ros::NodeHandle(target));
  ASSERT_EQ(config.hpds.mode, hpds::Mode::Scan) << "the shipped config runs in scan mode";
  ASSERT_TRUE(config.hpds.normals.enabled) << "the shipped config estimates normals";
  const double spacing = config.hpds.output.spacing;
  ASSERT_GT(spacing, 0.0) << "the shipped config sets an output spacing";

  ros::Publisher pub = nh.advertise<PointCloud2>(input, 4);
  Collector<PointCloud2> output(nh, target + "/output");
  hpds_test::DiagnosticsReader diagnostics(nh, target.substr(1));
  ASSERT_TRUE(hpds_test::waitFor([&] { return output.connected() && pub.getNumSubscribers() > 0; }, 30.0))
      << "no connection to " << target;
  ASSERT_TRUE(hpds_test::waitFor([&] { return rosout().connected(); }, 30.0)) << "no /rosout";
  ASSERT_TRUE(hpds_test::waitFor([&] { return diagnostics.value("frames processed") >= 0; }, 30.0)) << "no diagnostics";
  const double received_before = diagnostics.value("frames received");
  const double processed_before = diagnostics.value("frames processed");
  const double dropped_before = diagnostics.value("dropped total");
  const double overload_before = diagnostics.value("dropped overload");

  // 10 Hz by the wall clock, stamps 0.1 s apart, like a driver.
  ros::WallTime next = ros::WallTime::now();
  std::vector<PointCloud2Ptr> sent;
  for (int i = 0; i < count; ++i) {
    PointCloud2Ptr msg = boost::make_shared<PointCloud2>(*frames[i % frames.size()]);
    msg->header.stamp = ros::Time(2000.0 + kPeriod * i);
    ros::WallTime::sleepUntil(next);
    pub.publish(msg);
    sent.push_back(msg);
    next += ros::WallDuration(kPeriod);
  }

  // Every frame is accounted for: received, then processed or dropped (the counters as of after the last frame;
  // the diagnostics come every diagnostic_period).
  const double n = double(sent.size());
  ASSERT_TRUE(hpds_test::waitFor(
      [&] {
        return diagnostics.value("frames received") >= received_before + n &&
               diagnostics.value("frames processed") + diagnostics.value("dropped total") >=
                   processed_before + dropped_before + n;
      },
      60.0))
      << "received " << diagnostics.value("frames received") - received_before << ", processed "
      << diagnostics.value("frames processed") - processed_before << ", dropped "
      << diagnostics.value("dropped total") - dropped_before << " of " << n << " frames";
  const double processed = diagnostics.value("frames processed") - processed_before;
  const double dropped = diagnostics.value("dropped total") - dropped_before;
  EXPECT_EQ(diagnostics.value("frames received") - received_before, n);
  EXPECT_EQ(processed + dropped, n);
  EXPECT_EQ(dropped, diagnostics.value("dropped overload") - overload_before) << "drops other than overload";
  ASSERT_TRUE(hpds_test::waitFor([&] { return double(output.size()) >= processed; }, 30.0));
  std::cout << "[ node_defaults ] " << processed << " of " << n << " frames processed, " << dropped
            << " dropped; processing time mean / max over all frames: "
            << diagnostics.value("processing time mean, all frames [ms]") << " / "
            << diagnostics.value("processing time max, all frames [ms]") << " ms\n";

  // Drops only after the node said, once, that it cannot keep up, or behind its first frame, said as the start-up's
  // (at most the queue's worth of frames that arrive while the first frame runs: a few at 10 Hz).
  ASSERT_TRUE(hpds_test::waitFor(
      [&] { return dropped == 0.0 || !keepUpWarnings(target).empty() || startUpDropLines(target) > 0; }, 10.0))
      << dropped << " frames dropped at 10 Hz without the node saying that it cannot keep up";
  const auto warnings = keepUpWarnings(target);
  EXPECT_LE(warnings.size(), 1u) << "the keep-up warning must come at most once";
  if (!warnings.empty()) std::cout << "[ node_defaults ] the node said: " << warnings.front() << "\n";
  if (warnings.empty() && dropped > 0.0) {
    EXPECT_LE(dropped, 5.0) << "more than a start-up's drops, and no keep-up warning";
    std::cout << "[ node_defaults ] " << dropped << " frame(s) dropped behind the first frame only\n";
  }
  if (dropped > 0.0 && !warnings.empty()) {
    EXPECT_TRUE(hpds_test::contains(warnings.front(), "output.spacing (now 0.1 m)")) << warnings.front();
  }

  // Outputs come in arrival order, one per processed frame: match them to the frames sent by stamp.
  const auto outputs = output.messages();
  ASSERT_EQ(double(outputs.size()), processed);
  std::size_t next_sent = 0;
  for (std::size_t i = 0; i < outputs.size(); ++i) {
    SCOPED_TRACE("output " + std::to_string(i));
    while (next_sent < sent.size() && sent[next_sent]->header.stamp != outputs[i]->header.stamp) ++next_sent;
    ASSERT_LT(next_sent, sent.size()) << "an output whose stamp is no frame's (or out of order)";
    const PointCloud2 &in = *sent[next_sent++];
    const PointCloud2 &out = *outputs[i];
    hpds_test::expectOutputLayout(out, in, true);
    const hpds::PointBuffer cloud = hpds_test::toBuffer(out);
    const std::size_t n_in = std::size_t(in.width) * in.height;
    ASSERT_GT(cloud.size(), 100u);
    EXPECT_LT(double(cloud.size()), kMaxOutputShare * double(n_in)) << cloud.size() << " of " << n_in << " points";

    std::size_t finite = 0;
    const hpds::PointField *nx = cloud.layout().find("normal_x"), *ny = cloud.layout().find("normal_y"),
                           *nz = cloud.layout().find("normal_z");
    for (std::size_t k = 0; k < cloud.size(); ++k) {
      const double x = hpds::readAsDouble(cloud.record(k), *nx), y = hpds::readAsDouble(cloud.record(k), *ny),
                   z = hpds::readAsDouble(cloud.record(k), *nz);
      if (std::isfinite(x) && std::isfinite(y) && std::isfinite(z)) {
        ++finite;
        EXPECT_NEAR(x * x + y * y + z * z, 1.0, 1e-5) << "sample " << k;
      }
    }
    EXPECT_GE(double(finite), kMinFiniteNormalShare * double(cloud.size())) << finite << " finite normals of " << cloud.size();

    // The spacing asked is the spacing got: every two samples at least `spacing` apart (float32 rounding aside).
    if (i < 2) {
      const auto xyz = hpds_test::positions(cloud);
      double extent = 0.0;
      for (const auto &p : xyz) extent = std::max(extent, p.cwiseAbs().maxCoeff());
      EXPECT_GE(hpds_test::minDistanceBelow(xyz, spacing), spacing - 4.0 * std::ldexp(1.0, -24) * extent);
    }
  }
}

TEST(HpdsNodeDefaults, RealStreamAt10HzIsDownsampledWithNormalsAndDropsOnlyWhenSaid) {
  const std::string data = hpds_test::sharedDataDir();
  if (data.empty()) GTEST_SKIP() << "../shared/data/lidar is absent: the real-frame stream is skipped (the synthetic one runs)";
  // Two consecutive HDL-32E scans of one scene, in turn: 3 s of a 10 Hz sensor.
  const std::vector<PointCloud2Ptr> frames = {hpds_test::loadFrame(data + "/hdl32_a.pcd", "velodyne", ros::Time(1)),
                                              hpds_test::loadFrame(data + "/hdl32_b.pcd", "velodyne", ros::Time(1))};
  playAndCheck(frames, 30);
}

TEST(HpdsNodeDefaults, SyntheticStreamAt10HzIsDownsampledWithNormalsAndDropsOnlyWhenSaid) {
  hpds::SyntheticLidarConfig c;  // 32 beams x 1800 columns (57 600 points), an urban street driven at 1 m a frame
  c.frames = 10;
  const hpds::SyntheticLidar lidar(c);
  std::vector<PointCloud2Ptr> frames;
  for (int i = 0; i < c.frames; ++i)
    frames.push_back(boost::make_shared<PointCloud2>(hpds_test::toMsg(lidar.frame(i).frame.points, "velodyne", ros::Time(1))));
  playAndCheck(frames, 30);
}

}  // namespace

int main(int argc, char **argv) { return hpds_test::runRosTests(argc, argv, "test_node_defaults"); }
