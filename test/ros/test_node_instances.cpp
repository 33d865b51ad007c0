// rostest node: two hpds nodelets in one manager (a front and a rear lidar) are two instances in every respect their
// users see: each says its own once-only warnings (ROS_*_ONCE's flag is one per process, so the second instance
// stayed silent), every line names the instance it comes from (both log through the manager's node name), and
// each one's diagnostics name its sensor (hardware_id: the input topic; it was "none").
#include <gtest/gtest.h>

#include <cstring>

#include "RosTestUtil.hpp"
#include "hpds/eval/SyntheticLidar.hpp"

namespace {

using hpds_test::Collector;
using hpds_test::LogCollector;
using sensor_msgs::PointCloud2;
using sensor_msgs::PointCloud2Ptr;

// A synthetic frame 1e7 m out along x: its float32 x y z are rounded by about 0.5 m, which the node warns about once.
PointCloud2Ptr farFrame(int i) {
  hpds::SyntheticLidarConfig c;
  c.beams = 16;
  c.azimuth_steps = 600;
  c.emit_no_returns = false;
  const hpds::SyntheticLidar lidar(c);
  PointCloud2Ptr msg = hpds_test::fixedFrameMsg(lidar, i, "lidar", ros::Time(100 + i, 0));
  std::uint32_t x_offset = 0;
  for (const auto &f : msg->fields)
    if (f.name == "x") x_offset = f.offset;
  for (std::size_t p = 0; p + msg->point_step <= msg->data.size(); p += msg->point_step) {
    float x;
    std::memcpy(&x, &msg->data[p + x_offset], sizeof x);
    x = static_cast<float>(double(x) + 1e7);
    std::memcpy(&msg->data[p + x_offset], &x, sizeof x);
  }
  return msg;
}

TEST(NodeInstances, EachNodeletWarnsForItselfAndEveryLineNamesIt) {
  ros::NodeHandle nh;
  LogCollector logs(nh, "/lidar_manager");
  const std::vector<std::string> names = {"hpds_front", "hpds_rear"};
  std::vector<ros::Publisher> pubs;
  std::vector<std::unique_ptr<Collector<PointCloud2>>> outputs;
  for (const std::string &name : names) {
    pubs.push_back(nh.advertise<PointCloud2>("/" + name + "_points", 4));
    outputs.push_back(std::make_unique<Collector<PointCloud2>>(nh, "/" + name + "/output"));
  }
  ASSERT_TRUE(hpds_test::waitFor(
      [&] {
        bool up = logs.connected();
        for (std::size_t i = 0; i < names.size(); ++i)
          up = up && pubs[i].getNumSubscribers() > 0 && outputs[i]->connected();
        return up;
      },
      60.0))
      << "the two nodelets did not come up";
  for (std::size_t i = 0; i < names.size(); ++i) {
    pubs[i].publish(farFrame(int(i)));
    ASSERT_TRUE(hpds_test::waitFor([&] { return outputs[i]->size() >= 1; }, 60.0)) << names[i] << " gave no output";
  }
  PointCloud2Ptr bad = farFrame(2);
  bad->is_bigendian = true;
  pubs[1].publish(bad);
  for (const std::string &name : names)
    EXPECT_TRUE(hpds_test::waitFor(
        [&] { return logs.has(rosgraph_msgs::Log::WARN, {"hpds /" + name + ": ", "round positions"}); }, 30.0))
        << name << " did not warn about the rounding of its own input:\n"
        << logs.dump();
  EXPECT_TRUE(hpds_test::waitFor(
      [&] {
        return logs.has(rosgraph_msgs::Log::ERROR, {"hpds /hpds_rear: dropped malformed PointCloud2", "big_endian"});
      },
      30.0))
      << logs.dump();
  EXPECT_FALSE(logs.has(rosgraph_msgs::Log::ERROR, {"hpds /hpds_front: dropped malformed"})) << logs.dump();
  // Their diagnostics name the sensor each serves: the input topic is the hardware id.
  for (const std::string &name : names) {
    hpds_test::DiagnosticsReader diagnostics(nh, name);
    ASSERT_TRUE(hpds_test::waitFor([&] { return diagnostics.updates() > 0; }, 30.0)) << name << ": no diagnostics";
    EXPECT_EQ(diagnostics.hardwareId(), "/" + name + "_points");
  }
}

}  // namespace

int main(int argc, char **argv) { return hpds_test::runRosTests(argc, argv, "test_node_instances"); }
