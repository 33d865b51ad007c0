// Writes the replay test's input bag: a synthetic lidar drive (hpds/eval/SyntheticLidar.hpp) as PointCloud2 on
// /velodyne_points in frame "velodyne", its poses on /tf (odom -> base_link, at each cloud's stamp) and a static
// base_link -> velodyne mount on /tf_static, plus one truncated cloud that both the node and `hpds replay` must
// drop and count. With JUMP_AT, the odom poses of frames JUMP_AT on are shifted 40 m (a relocalisation), which
// the node and `hpds replay` must report as a pose jump.
//
// Usage: make_replay_bag OUT.bag [frames [JUMP_AT]]
#include <rosbag/bag.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_msgs/TFMessage.h>

#include <iostream>
#include <string>

#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds_node/CloudConversion.hpp"

namespace {

geometry_msgs::TransformStamped transform(const Eigen::Isometry3d &pose, const std::string &parent,
                                          const std::string &child, const ros::Time &stamp) {
  geometry_msgs::TransformStamped t = tf2::eigenToTransform(pose);
  t.header.frame_id = parent;
  t.child_frame_id = child;
  t.header.stamp = stamp;
  return t;
}

}  // namespace

int main(int argc, char **argv) {
  if (argc < 2) {
    std::cerr << "usage: make_replay_bag OUT.bag [frames [JUMP_AT]]\n";
    return 2;
  }
  hpds::SyntheticLidarConfig lidar;
  lidar.beams = 16;
  lidar.azimuth_steps = 900;
  lidar.frames = argc > 2 ? std::stoi(argv[2]) : 6;
  lidar.speed = 1.5;
  const int jump_at = argc > 3 ? std::stoi(argv[3]) : -1;
  const hpds::SyntheticLidar sensor(lidar);

  Eigen::Isometry3d mount = Eigen::Isometry3d::Identity();
  mount.translation() = Eigen::Vector3d(0.3, 0.0, -0.2);
  const ros::Time t0(1000, 0);

  rosbag::Bag bag(argv[1], rosbag::bagmode::Write);
  tf2_msgs::TFMessage statics;
  statics.transforms.push_back(transform(mount, "base_link", "velodyne", t0));
  // A custom connection header replaces rosbag's, so it must carry the type fields too; "latching" makes
  // `rosbag play` latch /tf_static as tf2_ros' static broadcaster does.
  auto latched = boost::make_shared<ros::M_string>();
  (*latched)["type"] = ros::message_traits::datatype<tf2_msgs::TFMessage>();
  (*latched)["md5sum"] = ros::message_traits::md5sum<tf2_msgs::TFMessage>();
  (*latched)["message_definition"] = ros::message_traits::definition<tf2_msgs::TFMessage>();
  (*latched)["callerid"] = "/make_replay_bag";
  (*latched)["latching"] = "1";
  bag.write("/tf_static", t0, statics, latched);

  for (int i = 0; i < lidar.frames; ++i) {
    const hpds::SyntheticFrame f = sensor.frame(i);
    const ros::Time stamp = t0 + ros::Duration(0.05 + f.frame.stamp);
    // odom -> base_link such that odom -> velodyne is the synthetic sensor pose.
    tf2_msgs::TFMessage tf;
    Eigen::Isometry3d jump = Eigen::Isometry3d::Identity();
    if (jump_at >= 0 && i >= jump_at) jump.translation() = Eigen::Vector3d(40.0, 0.0, 0.0);
    tf.transforms.push_back(transform(jump * f.frame.sensor_to_fixed * mount.inverse(), "odom", "base_link", stamp));
    bag.write("/tf", stamp, tf);

    std_msgs::Header header;
    header.frame_id = "velodyne";
    header.stamp = stamp;
    sensor_msgs::PointCloud2 cloud;
    hpds_node::toRosCloud(f.frame.points, header, cloud);
    bag.write("/velodyne_points", stamp + ros::Duration(0.001), cloud);

    if (i == 2) {
      sensor_msgs::PointCloud2 broken = cloud;
      broken.data.resize(broken.data.size() / 2);  // truncated: must be dropped as malformed, never processed
      bag.write("/velodyne_points", stamp + ros::Duration(0.002), broken);
    }
  }
  bag.close();
  std::cout << "wrote " << argv[1] << ": " << lidar.frames << " frames + 1 truncated cloud\n";
  return 0;
}
