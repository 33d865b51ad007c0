// rostest node: real scans in, scan-mode output checked (frame, stamp, fields byte for byte, Poisson property),
// against every hpds instance listed in ~targets (node, nodelet in a manager, standalone nodelet).
//
// Parameters: ~data_dir (shared lidar folder; the test skips when absent), ~targets (list of node names), ~input
// (the topic the targets read, remapped by the launch file), ~frames (file names in data_dir).
#include <gtest/gtest.h>

#include <map>
#include <tuple>

#include "RosTestUtil.hpp"
#include "hpds/pipeline/Pipeline.hpp"
#include "hpds_node/HpdsServer.hpp"

namespace {

using hpds_test::Collector;
using sensor_msgs::PointCloud2;

std::vector<std::string> stringList(const std::string &param, std::vector<std::string> fallback) {
  std::vector<std::string> v;
  return ros::NodeHandle("~").getParam(param, v) ? v : fallback;
}

// Checks one output cloud against the input it came from.
void checkScanOutput(const PointCloud2 &out, const PointCloud2 &in, const hpds_node::NodeConfig &config) {
  EXPECT_EQ(out.header.frame_id, in.header.frame_id);
  EXPECT_EQ(out.header.stamp, in.header.stamp);
  hpds_test::expectOutputLayout(out, in, config.hpds.normals.enabled);
  const hpds::PointBuffer cloud = hpds_test::toBuffer(out);
  ASSERT_GT(cloud.size(), 100u);

  // Poisson property of levels 0..L (all of ~output) at r_L, up to float32 rounding of the coordinates.
  const int L = hpds::resolveOutputLevel(config.hpds);
  const double r = hpds::resolveOutput(config.hpds).radius;
  const auto xyz = hpds_test::positions(cloud);
  double extent = 0.0;
  for (const auto &p : xyz) extent = std::max(extent, p.cwiseAbs().maxCoeff());
  const double tol = 4.0 * std::ldexp(1.0, -24) * extent;
  EXPECT_GE(hpds_test::minDistanceBelow(xyz, r), r - tol) << "levels 0.." << L << " violate the Poisson radius";

  const hpds::PointField *level = cloud.layout().find("level");
  ASSERT_NE(level, nullptr);
  for (std::size_t i = 0; i < cloud.size(); ++i) ASSERT_LE(hpds::readAsDouble(cloud.record(i), *level), L);

  // Every input field of every sample equals, byte for byte, the input point at the same (float32) position.
  hpds::PointBuffer input = hpds_test::toBuffer(in);
  const hpds::PointField *ix = input.layout().find("x"), *iy = input.layout().find("y"),
                         *iz = input.layout().find("z");
  // Dual-return sensors give several records at one position: the sample must equal one of them.
  std::multimap<std::tuple<float, float, float>, std::size_t> by_position;
  for (std::size_t i = 0; i < input.size(); ++i) {
    const std::uint8_t *rec = input.record(i);
    by_position.emplace(std::make_tuple(float(hpds::readAsDouble(rec, *ix)), float(hpds::readAsDouble(rec, *iy)),
                                        float(hpds::readAsDouble(rec, *iz))),
                        i);
  }
  auto sameInputFields = [&](std::size_t sample, std::size_t point) {
    for (const hpds::PointField &f : input.layout().fields) {
      if (f.name == "x" || f.name == "y" || f.name == "z") continue;
      const hpds::PointField *g = cloud.layout().find(f.name);
      if (!g || std::memcmp(cloud.record(sample) + g->offset, input.record(point) + f.offset, f.byteSize()) != 0)
        return false;
    }
    return true;
  };
  std::size_t compared = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const auto range = by_position.equal_range(std::make_tuple(float(xyz[i].x()), float(xyz[i].y()), float(xyz[i].z())));
    ASSERT_NE(range.first, range.second) << "output sample " << i << " is not an input point";
    bool match = false;
    for (auto it = range.first; it != range.second && !match; ++it) match = sameInputFields(i, it->second);
    ASSERT_TRUE(match) << "the input fields of sample " << i << " differ from every input point at its position";
    ++compared;
  }
  if (input.layout().fields.size() > 3) {
    EXPECT_GT(compared, 0u);
  }
}

TEST(HpdsNodeScan, RealFramesGiveValidOutput) {
  const std::string data = hpds_test::sharedDataDir();
  if (data.empty()) GTEST_SKIP() << "../shared/data/lidar is absent: real-frame ROS test skipped";
  ros::NodeHandle nh;
  const std::string input_topic = ros::NodeHandle("~").param<std::string>("input", "/velodyne_points");
  const auto targets = stringList("targets", {"/hpds"});
  const auto files = stringList("frames", {"hdl32_a.pcd", "velodyne_vlp16.pcd"});

  ros::Publisher pub = nh.advertise<PointCloud2>(input_topic, 4);
  for (const std::string &target : targets) {
    SCOPED_TRACE("target " + target);
    const hpds_node::NodeConfig config = hpds_node::loadNodeConfigFromParams(ros::NodeHandle(target));
    Collector<PointCloud2> output(nh, target + "/output");
    std::vector<std::unique_ptr<Collector<PointCloud2>>> levels;
    for (int d : config.ros.publish_levels)
      levels.push_back(std::make_unique<Collector<PointCloud2>>(nh, target + "/level_" + std::to_string(d)));
    // Outputs are built only for connected subscribers: every collector must be connected before publishing.
    ASSERT_TRUE(hpds_test::waitFor(
        [&] {
          bool all = output.connected() && pub.getNumSubscribers() >= targets.size();
          for (const auto &l : levels) all = all && l->connected();
          return all;
        },
        30.0))
        << "no connection to " << target;

    for (std::size_t i = 0; i < files.size(); ++i) {
      SCOPED_TRACE(files[i]);
      const ros::Time stamp(1000 + i, 250000000);
      const auto frame = hpds_test::loadFrame(data + "/" + files[i], "velodyne", stamp);
      output.clear();
      for (auto &l : levels) l->clear();
      pub.publish(frame);
      // Every target reads the same input, but only this one has a subscriber on its output, so the others skip.
      ASSERT_TRUE(hpds_test::waitFor([&] { return output.size() >= 1; }, 60.0)) << "no output";
      checkScanOutput(*output.messages().front(), *frame, config);
      for (std::size_t k = 0; k < levels.size(); ++k) {
        ASSERT_TRUE(hpds_test::waitFor([&] { return levels[k]->size() >= 1; }, 10.0));
        const auto cloud = hpds_test::toBuffer(*levels[k]->messages().front());
        const hpds::PointField *lf = cloud.layout().find("level");
        ASSERT_NE(lf, nullptr);
        ASSERT_GT(cloud.size(), 0u);
        for (std::size_t p = 0; p < cloud.size(); ++p)
          ASSERT_EQ(hpds::readAsDouble(cloud.record(p), *lf), config.ros.publish_levels[k]);
      }
    }
  }
}

}  // namespace

int main(int argc, char **argv) { return hpds_test::runRosTests(argc, argv, "test_node_scan"); }
