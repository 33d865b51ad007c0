// rostest node: a scan-mode node with threads: 2 takes two frames at a time. Synthetic frames are sent in one burst
// (the node's queue holds them all); every ~output must arrive in sending order and equal, byte for byte, what one
// FrameProcessor on one thread makes of the same messages in the same order.
//
// A drop logged by one worker counts the drops of both: a burst of malformed messages, one of each kind (each kind
// has its own log throttle), split between the workers, ends in a line that counts (nearly) all of them.
//
// Parameters: ~target (the node), ~input (its input topic), ~frames (how many to send).
#include <gtest/gtest.h>
#include <rosgraph_msgs/Log.h>

#include <regex>

#include "RosTestUtil.hpp"
#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds_node/FrameProcessor.hpp"
#include "hpds_node/HpdsServer.hpp"

namespace {

using hpds_test::Collector;
using sensor_msgs::PointCloud2;

TEST(HpdsNodeWorkers, FramesInParallelGiveTheSingleWorkerOutputInOrder) {
  ros::NodeHandle nh, pnh("~");
  const std::string target = pnh.param<std::string>("target", "/hpds_workers");
  const std::string input = pnh.param<std::string>("input", "/workers_points");
  const int frames = pnh.param("frames", 12);
  hpds_node::NodeConfig config = hpds_node::loadNodeConfigFromParams(ros::NodeHandle(target));
  ASSERT_EQ(config.hpds.mode, hpds::Mode::Scan);
  ASSERT_EQ(config.hpds.threads, 2) << "the launch file must give the node two threads";
  ASSERT_GE(config.ros.queue_size, frames) << "a burst must fit the node's queue";

  Collector<PointCloud2> output(nh, target + "/output");
  hpds_test::DiagnosticsReader diag(nh, target.substr(1));
  ros::Publisher pub = nh.advertise<PointCloud2>(input, static_cast<std::uint32_t>(frames));
  ASSERT_TRUE(hpds_test::waitFor([&] { return output.connected() && pub.getNumSubscribers() > 0; }, 30.0));

  hpds::SyntheticLidarConfig lc;
  lc.beams = 32;
  lc.azimuth_steps = 1200;
  lc.frames = frames;
  lc.speed = 2.0;
  const hpds::SyntheticLidar lidar(lc);
  std::vector<PointCloud2> sent;
  for (int i = 0; i < frames; ++i) {
    // Odd frames keep a tenth of their points: they finish before the even frame sent just ahead of them, so
    // publishing them when they are done would put them out of order.
    hpds::PointBuffer points = lidar.frame(i).frame.points;
    if (i % 2) points.resize(points.size() / 10);
    sent.push_back(hpds_test::toMsg(points, "lidar", ros::Time(50 + i, 0)));
    pub.publish(sent.back());
  }
  ASSERT_TRUE(hpds_test::waitFor([&] { return output.size() >= static_cast<std::size_t>(frames); }, 120.0))
      << output.size() << " of " << frames << " outputs arrived";
  EXPECT_TRUE(hpds_test::waitFor([&] { return diag.value("frames processed") == double(frames); }, 30.0))
      << "frames processed: " << diag.value("frames processed");

  // The reference: one processor, one thread, the frames in sending order.
  config.hpds.threads = 1;
  hpds_node::FrameProcessor ref(config);
  const auto got = output.messages();
  ASSERT_EQ(got.size(), static_cast<std::size_t>(frames));
  for (int i = 0; i < frames; ++i) {
    SCOPED_TRACE("frame " + std::to_string(i));
    EXPECT_EQ(got[i]->header.stamp, sent[i].header.stamp) << "published out of order";
    ASSERT_EQ(ref.check(sent[i]), hpds_node::CloudError::None);
    hpds_node::OutputRequest wants;
    wants.output = true;
    const hpds_node::ProcessedFrame r = ref.process(sent[i], Eigen::Isometry3d::Identity(), wants);
    ASSERT_TRUE(r.processed) << r.why;
    EXPECT_GT(r.output.width, i % 2 ? 20u : 200u);
    EXPECT_EQ(got[i]->width, r.output.width);
    EXPECT_TRUE(got[i]->data == r.output.data) << "~output differs from the single-worker reference";
  }
}

TEST(HpdsNodeWorkers, DropLogsCountTheDropsOfEveryWorker) {
  ros::NodeHandle nh, pnh("~");
  const std::string target = pnh.param<std::string>("target", "/hpds_workers");
  const std::string input = pnh.param<std::string>("input", "/workers_points");
  Collector<rosgraph_msgs::Log> rosout(nh, "/rosout");
  hpds_test::DiagnosticsReader diag(nh, target.substr(1));
  ros::Publisher pub = nh.advertise<PointCloud2>(input, 16);
  ASSERT_TRUE(hpds_test::waitFor(
      [&] { return rosout.connected() && pub.getNumSubscribers() > 0 && diag.updates() > 0; }, 30.0));
  const double malformed_before = diag.value("dropped malformed");

  hpds::SyntheticLidarConfig lc;
  lc.beams = 8;
  lc.azimuth_steps = 200;
  const PointCloud2 good = hpds_test::toMsg(hpds::SyntheticLidar(lc).frame(0).frame.points, "lidar", ros::Time(900, 0));
  std::vector<PointCloud2> bad(6, good);
  bad[0].is_bigendian = true;
  bad[1].fields[0].datatype = 0;
  bad[2].fields[1].count = 0;
  bad[3].fields[2].offset = bad[3].point_step;
  bad[4].row_step = 7;
  bad[5].data.resize(bad[5].data.size() - 1);
  for (const PointCloud2 &m : bad) pub.publish(m);
  ASSERT_TRUE(hpds_test::waitFor([&] { return diag.value("dropped malformed") == malformed_before + 6.0; }, 30.0))
      << "dropped malformed: " << diag.value("dropped malformed");

  // "(<reason>, N malformed so far)": with two workers at most one other drop is in flight when a line is written,
  // so the last line counts at least all but one. A worker counting only its own would stop near half.
  const std::regex so_far(R"(, ([0-9]+) malformed so far\))");
  std::size_t lines = 0, most = 0;
  EXPECT_TRUE(hpds_test::waitFor(
      [&] {
        lines = most = 0;
        for (const auto &m : rosout.messages()) {
          std::smatch match;
          if (m->name != target || !std::regex_search(m->msg, match, so_far)) continue;
          ++lines;
          most = std::max<std::size_t>(most, std::stoul(match[1]));
        }
        return lines >= 6;
      },
      10.0))
      << lines << " malformed-drop lines logged";
  EXPECT_GE(most + 1, std::size_t(malformed_before) + 6) << "largest count logged: " << most;
}

}  // namespace

int main(int argc, char **argv) { return hpds_test::runRosTests(argc, argv, "test_node_workers"); }
