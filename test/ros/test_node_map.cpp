// rostest node: map mode with tf. Two consecutive real HDL-32 scans with their true relative pose go in; checked:
// outputs in the fixed frame with the input stamps, new samples are input points moved by the tf pose, the map
// (union of ~new_samples) is Poisson at r_L, ~output covers the frame within 2 r_L, ~local_map arrives; frames
// without a transform or with other fields are dropped and counted in the diagnostics.
//
// Parameters: ~data_dir, ~target (node name), ~input (its input topic), ~fixed_frame.
#include <gtest/gtest.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_msgs/TFMessage.h>

#include <fstream>

#include "RosTestUtil.hpp"
#include "hpds/pipeline/Pipeline.hpp"
#include "hpds_node/HpdsServer.hpp"

namespace {

using hpds_test::Collector;
using sensor_msgs::PointCloud2;

Eigen::Isometry3d readRelativePose(const std::string &path) {
  std::ifstream in(path);
  Eigen::Matrix4d m;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) in >> m(r, c);
  Eigen::Isometry3d pose;
  pose.matrix() = m;
  // The file's rotation is rounded to 6 digits; re-orthonormalise so tf2 gets a proper rotation.
  const Eigen::Quaterniond q(m.block<3, 3>(0, 0));
  pose.linear() = q.normalized().toRotationMatrix();
  return pose;
}

// The accepted points of a frame (pipeline skip rules with default input config) moved into the fixed frame.
std::vector<Eigen::Vector3d> acceptedPoints(const PointCloud2 &msg, const Eigen::Isometry3d &pose) {
  std::vector<Eigen::Vector3d> out;
  for (const Eigen::Vector3d &p : hpds_test::positions(hpds_test::toBuffer(msg)))
    if (p.allFinite() && !(p.x() == 0.0 && p.y() == 0.0 && p.z() == 0.0)) out.push_back(pose * p);
  return out;
}

// Fraction of `queries` that have a point of `points` within `radius`.
double fractionWithin(const std::vector<Eigen::Vector3d> &queries, const std::vector<Eigen::Vector3d> &points,
                      double radius, std::size_t stride = 1) {
  // Grid over `points` with edge `radius`, then a 27-cell lookup per query.
  std::size_t hit = 0, n = 0;
  struct Key {
    std::int64_t x, y, z;
    bool operator<(const Key &o) const { return std::tie(x, y, z) < std::tie(o.x, o.y, o.z); }
  };
  std::map<Key, std::vector<std::size_t>> grid;
  auto keyOf = [&](const Eigen::Vector3d &p) {
    return Key{std::int64_t(std::floor(p.x() / radius)), std::int64_t(std::floor(p.y() / radius)),
               std::int64_t(std::floor(p.z() / radius))};
  };
  for (std::size_t i = 0; i < points.size(); ++i) grid[keyOf(points[i])].push_back(i);
  for (std::size_t i = 0; i < queries.size(); i += stride) {
    ++n;
    const Key k = keyOf(queries[i]);
    bool found = false;
    for (int dx = -1; dx <= 1 && !found; ++dx)
      for (int dy = -1; dy <= 1 && !found; ++dy)
        for (int dz = -1; dz <= 1 && !found; ++dz) {
          const auto it = grid.find(Key{k.x + dx, k.y + dy, k.z + dz});
          if (it == grid.end()) continue;
          for (std::size_t j : it->second)
            if ((points[j] - queries[i]).norm() < radius) {
              found = true;
              break;
            }
        }
    hit += found ? 1 : 0;
  }
  return n ? double(hit) / double(n) : 1.0;
}

class MapTest : public testing::Test {
 protected:
  void SetUp() override {
    data_ = hpds_test::sharedDataDir();
    if (data_.empty()) GTEST_SKIP() << "../shared/data/lidar is absent: real-frame ROS test skipped";
    ros::NodeHandle pnh("~");
    target_ = pnh.param<std::string>("target", "/hpds_map");
    input_ = pnh.param<std::string>("input", "/velodyne_points");
    fixed_ = pnh.param<std::string>("fixed_frame", "odom");
    config_ = hpds_node::loadNodeConfigFromParams(ros::NodeHandle(target_));
  }

  void publishPose(const Eigen::Isometry3d &pose, const ros::Time &stamp) {
    geometry_msgs::TransformStamped t = tf2::eigenToTransform(pose);
    t.header.stamp = stamp;
    t.header.frame_id = fixed_;
    t.child_frame_id = "velodyne";
    tf2_msgs::TFMessage m;
    m.transforms.push_back(t);
    tf_pub_.publish(m);
  }

  std::string data_, target_, input_, fixed_;
  hpds_node::NodeConfig config_;
  ros::NodeHandle nh_;
  ros::Publisher tf_pub_;
};

TEST_F(MapTest, TwoScansBuildAPoissonMapInTheFixedFrame) {
  Collector<PointCloud2> output(nh_, target_ + "/output"), fresh(nh_, target_ + "/new_samples"),
      local(nh_, target_ + "/local_map");
  hpds_test::DiagnosticsReader diag(nh_, target_.substr(1));
  ros::Publisher pub = nh_.advertise<PointCloud2>(input_, 4);
  // A plain /tf publisher (not a TransformBroadcaster) so the test can wait until hpds' listener is connected.
  tf_pub_ = nh_.advertise<tf2_msgs::TFMessage>("/tf", 100);
  ASSERT_TRUE(hpds_test::waitFor(
      [&] {
        return output.connected() && fresh.connected() && local.connected() && pub.getNumSubscribers() > 0 &&
               tf_pub_.getNumSubscribers() > 0;
      },
      30.0));

  const double rL = hpds::resolveOutput(config_.hpds).radius;
  const Eigen::Isometry3d poses[2] = {Eigen::Isometry3d::Identity(),
                                      readRelativePose(data_ + "/hdl32_relative.txt")};
  const char *files[2] = {"hdl32_a.pcd", "hdl32_b.pcd"};
  std::vector<Eigen::Vector3d> map_points;
  for (int i = 0; i < 2; ++i) {
    SCOPED_TRACE(files[i]);
    const ros::Time stamp(200 + i, 5000);
    const auto frame = hpds_test::loadFrame(data_ + "/" + files[i], "velodyne", stamp);
    publishPose(poses[i], stamp);
    ros::WallDuration(0.2).sleep();
    pub.publish(frame);
    ASSERT_TRUE(hpds_test::waitFor(
        [&] { return output.size() > std::size_t(i) && fresh.size() > std::size_t(i) && local.size() > std::size_t(i); },
        60.0))
        << "outputs of frame " << i << " did not arrive";
    const auto out = output.messages()[i], news = fresh.messages()[i], loc = local.messages()[i];
    for (const auto &m : {out, news, loc}) {
      EXPECT_EQ(m->header.frame_id, fixed_);
      EXPECT_EQ(m->header.stamp, stamp);
      hpds_test::expectOutputLayout(*m, *frame, config_.hpds.normals.enabled);
    }

    // New samples are input points moved by the tf pose (float32 output: within a micrometre-ish).
    const auto accepted = acceptedPoints(*frame, poses[i]);
    const auto new_xyz = hpds_test::positions(hpds_test::toBuffer(*news));
    ASSERT_GT(new_xyz.size(), 100u);
    EXPECT_EQ(fractionWithin(new_xyz, accepted, 1e-3), 1.0) << "new samples are not the frame's points in " << fixed_;
    map_points.insert(map_points.end(), new_xyz.begin(), new_xyz.end());

    // ~output: every sample is hit by the frame (a point within 2 r_L) and covers it: every accepted point has a
    // sample within 2 r_L (float32 slack).
    const auto out_xyz = hpds_test::positions(hpds_test::toBuffer(*out));
    ASSERT_GT(out_xyz.size(), 100u);
    EXPECT_EQ(fractionWithin(out_xyz, accepted, 2.0 * rL + 1e-4), 1.0);
    EXPECT_EQ(fractionWithin(accepted, out_xyz, 2.0 * rL + 1e-4, 7), 1.0);
    EXPECT_GT(hpds_test::positions(hpds_test::toBuffer(*loc)).size(), 100u);
  }
  // The map (levels 0..L of both frames) keeps the Poisson radius r_L across frames.
  double extent = 0.0;
  for (const auto &p : map_points) extent = std::max(extent, p.cwiseAbs().maxCoeff());
  EXPECT_GE(hpds_test::minDistanceBelow(map_points, rL), rL - 4.0 * std::ldexp(1.0, -24) * extent);

  // A frame whose sensor frame has no transform is dropped and counted, the node keeps running.
  auto lost = hpds_test::loadFrame(data_ + "/hdl32_a.pcd", "nowhere", ros::Time(202, 0));
  pub.publish(lost);
  EXPECT_TRUE(hpds_test::waitFor([&] { return diag.value("dropped no_transform") >= 1.0; }, 30.0));
  // A frame with other fields than the map's is dropped and counted.
  const ros::Time t3(203, 0);
  publishPose(poses[1], t3);
  ros::WallDuration(0.2).sleep();
  pub.publish(hpds_test::loadFrame(data_ + "/velodyne_vlp16.pcd", "velodyne", t3));
  EXPECT_TRUE(hpds_test::waitFor([&] { return diag.value("dropped layout_changed") >= 1.0; }, 30.0));
  EXPECT_EQ(diag.value("frames processed"), 2.0);
  EXPECT_GT(diag.value("memory in use [bytes]"), 0.0);
  double per_level = 0.0;
  // Levels below the deepest built have no key (value() would say -1 for them).
  const int deepest = static_cast<int>(diag.value("deepest level built"));
  ASSERT_GE(deepest, 0);
  for (int d = 0; d <= deepest; ++d) per_level += diag.value("samples level " + std::to_string(d));
  EXPECT_EQ(diag.value("samples stored"), per_level);
  EXPECT_EQ(output.size(), 2u);
}

}  // namespace

int main(int argc, char **argv) { return hpds_test::runRosTests(argc, argv, "test_node_map"); }
