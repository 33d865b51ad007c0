// rostest node: the replay bag played (rosbag play --clock, started here once every connection is up) through the
// running hpds node must give, message for message and byte for byte, what `hpds replay` wrote for the same bag;
// the truncated cloud in the bag is dropped and counted by both.
//
// Parameters: ~bag (input bag), ~expected_bag (`hpds replay` output), ~target (node name), ~frames (good clouds in
// the bag), ~rate (playback rate).
#include <gtest/gtest.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>

#include <cstdlib>

#include "RosTestUtil.hpp"

namespace {

using hpds_test::Collector;
using sensor_msgs::PointCloud2;

std::vector<PointCloud2::ConstPtr> readTopic(const std::string &path, const std::string &topic) {
  rosbag::Bag bag(path, rosbag::bagmode::Read);
  std::vector<PointCloud2::ConstPtr> out;
  for (const rosbag::MessageInstance &m : rosbag::View(bag, rosbag::TopicQuery(topic)))
    if (auto msg = m.instantiate<PointCloud2>()) out.push_back(msg);
  return out;
}

void expectSameClouds(const std::vector<PointCloud2::ConstPtr> &node, const std::vector<PointCloud2::ConstPtr> &cli,
                      const std::string &what) {
  ASSERT_EQ(node.size(), cli.size()) << what << ": message counts differ";
  for (std::size_t i = 0; i < node.size(); ++i) {
    SCOPED_TRACE(what + " message " + std::to_string(i));
    EXPECT_EQ(node[i]->header.stamp, cli[i]->header.stamp);
    EXPECT_EQ(node[i]->header.frame_id, cli[i]->header.frame_id);
    EXPECT_EQ(node[i]->fields, cli[i]->fields);
    EXPECT_EQ(node[i]->width, cli[i]->width);
    EXPECT_EQ(node[i]->height, cli[i]->height);
    EXPECT_EQ(node[i]->point_step, cli[i]->point_step);
    EXPECT_TRUE(node[i]->data == cli[i]->data) << "sample bytes differ";
  }
}

TEST(HpdsReplay, NodeAndCliGiveTheSameSamples) {
  ros::NodeHandle nh, pnh("~");
  const std::string bag = pnh.param<std::string>("bag", "");
  const std::string expected = pnh.param<std::string>("expected_bag", "");
  const std::string target = pnh.param<std::string>("target", "/hpds");
  const int frames = pnh.param("frames", 6);
  const double rate = pnh.param("rate", 0.5);
  ASSERT_FALSE(bag.empty());
  ASSERT_FALSE(expected.empty());

  Collector<PointCloud2> output(nh, target + "/output"), fresh(nh, target + "/new_samples"),
      local(nh, target + "/local_map");
  hpds_test::DiagnosticsReader diag(nh, target.substr(1));
  ASSERT_TRUE(hpds_test::waitFor([&] { return output.connected() && fresh.connected() && local.connected(); }, 30.0));
  // hpds must also be listening to the input and to tf before the first message goes out.
  ros::master::V_TopicInfo topics;
  ASSERT_TRUE(hpds_test::waitFor(
      [&] {
        XmlRpc::XmlRpcValue req, res, payload;
        req[0] = ros::this_node::getName();
        if (!ros::master::execute("getSystemState", req, res, payload, false)) return false;
        int wanted = 0;
        for (int i = 0; i < payload[1].size(); ++i) {
          const std::string topic = payload[1][i][0];
          for (int j = 0; j < payload[1][i][1].size(); ++j)
            if (std::string(payload[1][i][1][j]) == target &&
                (topic == "/velodyne_points" || topic == "/tf" || topic == "/tf_static"))
              ++wanted;
        }
        return wanted == 3;
      },
      30.0))
      << target << " does not subscribe to /velodyne_points, /tf and /tf_static";

  // hpds subscribing (above) is the master's view; its connection to the player is made only after the player
  // advertises. rosbag play waits for a connected subscriber on each of the bag's topics (all of them hpds's), so
  // the first frame cannot go out before hpds can receive it (with the default 0.2 s delay a slow, sanitized node
  // missed it).
  const std::string play =
      "rosbag play --clock -q --wait-for-subscribers -r " + std::to_string(rate) + " '" + bag + "'";
  ASSERT_EQ(std::system(play.c_str()), 0) << play;
  ASSERT_TRUE(hpds_test::waitFor([&] { return fresh.size() >= std::size_t(frames); }, 120.0))
      << "got " << fresh.size() << " of " << frames << " frames";
  ros::WallDuration(1.0).sleep();  // anything extra (a duplicate, a late local map) would show up now

  expectSameClouds(fresh.messages(), readTopic(expected, target + "/new_samples"), "new_samples");
  expectSameClouds(output.messages(), readTopic(expected, target + "/output"), "output");
  expectSameClouds(local.messages(), readTopic(expected, target + "/local_map"), "local_map");
  EXPECT_TRUE(hpds_test::waitFor([&] { return diag.value("dropped malformed") == 1.0; }, 10.0))
      << "the truncated cloud must be dropped once";
  EXPECT_EQ(diag.value("frames processed"), double(frames));
}

}  // namespace

int main(int argc, char **argv) { return hpds_test::runRosTests(argc, argv, "test_node_replay"); }
