#include "RosTestUtil.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <unordered_map>

#include "hpds/pcl/PointCloudFile.hpp"
#include "hpds_node/CloudConversion.hpp"

namespace hpds_test {

int runRosTests(int argc, char **argv, const std::string &node_name) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, node_name);
  ros::AsyncSpinner spinner(2);
  spinner.start();
  return RUN_ALL_TESTS();
}

std::string sharedDataDir() {
  std::string dir;
  ros::NodeHandle("~").param<std::string>("data_dir", dir, "");
  std::error_code ec;
  if (dir.empty() || !std::filesystem::exists(std::filesystem::path(dir) / "hdl32_a.pcd", ec)) return "";
  return dir;
}

sensor_msgs::PointCloud2 toMsg(const hpds::PointBuffer &points, const std::string &frame_id, const ros::Time &stamp) {
  std_msgs::Header header;
  header.frame_id = frame_id;
  header.stamp = stamp;
  sensor_msgs::PointCloud2 msg;
  hpds_node::toRosCloud(points, header, msg);
  return msg;
}

sensor_msgs::PointCloud2Ptr loadFrame(const std::string &path, const std::string &frame_id, const ros::Time &stamp) {
  return boost::make_shared<sensor_msgs::PointCloud2>(toMsg(hpds::readPointCloud(path), frame_id, stamp));
}

sensor_msgs::PointCloud2Ptr fixedFrameMsg(const hpds::SyntheticLidar &lidar, int i, const std::string &frame_id,
                                          const ros::Time &stamp) {
  hpds::SyntheticFrame f = lidar.frame(i);
  hpds::PointBuffer &points = f.frame.points;
  const hpds::PointLayout &l = points.layout();
  const hpds::PointField *fx = l.find("x"), *fy = l.find("y"), *fz = l.find("z");
  for (std::size_t k = 0; k < points.size(); ++k) {
    std::uint8_t *r = points.record(k);
    const Eigen::Vector3d p =
        f.frame.sensor_to_fixed *
        Eigen::Vector3d(hpds::readAsDouble(r, *fx), hpds::readAsDouble(r, *fy), hpds::readAsDouble(r, *fz));
    hpds::writeFromDouble(r, *fx, p.x());
    hpds::writeFromDouble(r, *fy, p.y());
    hpds::writeFromDouble(r, *fz, p.z());
  }
  return boost::make_shared<sensor_msgs::PointCloud2>(toMsg(points, frame_id, stamp));
}

bool waitFor(const std::function<bool()> &pred, double timeout_s) {
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(timeout_s);
  while (!pred()) {
    if (ros::WallTime::now() > deadline || !ros::ok()) return pred();
    ros::WallDuration(0.01).sleep();
  }
  return true;
}

hpds::PointBuffer toBuffer(const sensor_msgs::PointCloud2 &msg) {
  hpds::PointBuffer buf;
  std::string why;
  const hpds_node::CloudError e = hpds_node::fromRosCloud(msg, buf, &why);
  if (e != hpds_node::CloudError::None) ADD_FAILURE() << "output cloud does not convert: " << why;
  return buf;
}

std::vector<Eigen::Vector3d> positions(const hpds::PointBuffer &cloud) {
  std::vector<Eigen::Vector3d> out;
  const hpds::PointField *fx = cloud.layout().find("x"), *fy = cloud.layout().find("y"),
                         *fz = cloud.layout().find("z");
  if (!fx || !fy || !fz) return out;
  out.reserve(cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const std::uint8_t *r = cloud.record(i);
    out.emplace_back(hpds::readAsDouble(r, *fx), hpds::readAsDouble(r, *fy), hpds::readAsDouble(r, *fz));
  }
  return out;
}

double minDistanceBelow(const std::vector<Eigen::Vector3d> &points, double limit) {
  struct Key {
    std::int64_t x, y, z;
    bool operator==(const Key &o) const { return x == o.x && y == o.y && z == o.z; }
  };
  struct Hash {
    std::size_t operator()(const Key &k) const {
      return std::size_t(k.x * 73856093) ^ std::size_t(k.y * 19349663) ^ std::size_t(k.z * 83492791);
    }
  };
  std::unordered_map<Key, std::vector<std::size_t>, Hash> grid;
  auto keyOf = [&](const Eigen::Vector3d &p) {
    return Key{std::int64_t(std::floor(p.x() / limit)), std::int64_t(std::floor(p.y() / limit)),
               std::int64_t(std::floor(p.z() / limit))};
  };
  for (std::size_t i = 0; i < points.size(); ++i) grid[keyOf(points[i])].push_back(i);
  double best = limit;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const Key k = keyOf(points[i]);
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const auto it = grid.find(Key{k.x + dx, k.y + dy, k.z + dz});
          if (it == grid.end()) continue;
          for (std::size_t j : it->second)
            if (j > i) best = std::min(best, (points[i] - points[j]).norm());
        }
  }
  return best;
}

DiagnosticsReader::DiagnosticsReader(ros::NodeHandle &nh, const std::string &node_name) : node_name_(node_name) {
  sub_ = nh.subscribe<diagnostic_msgs::DiagnosticArray>(
      "/diagnostics", 100, [this](const diagnostic_msgs::DiagnosticArray::ConstPtr &m) {
        for (const auto &status : m->status) {
          if (status.name.find(node_name_) == std::string::npos) continue;
          std::lock_guard<std::mutex> lock(mutex_);
          for (const auto &kv : status.values) values_[kv.key] = kv.value;
          hardware_id_ = status.hardware_id;
          highest_level_ = std::max(highest_level_, int(status.level));
          ++updates_;
        }
      });
}

double DiagnosticsReader::value(const std::string &key) const {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto it = values_.find(key);
  return it == values_.end() ? -1.0 : std::stod(it->second);
}

int DiagnosticsReader::highestLevel() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return highest_level_;
}

std::string DiagnosticsReader::hardwareId() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return hardware_id_;
}

std::size_t DiagnosticsReader::updates() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return updates_;
}

void expectAlignedFields(const sensor_msgs::PointCloud2 &cloud, std::uint8_t xyz_datatype) {
  ASSERT_GE(cloud.fields.size(), 3u);
  const char *axes[] = {"x", "y", "z"};
  const std::uint32_t xyz_size = xyz_datatype == sensor_msgs::PointField::FLOAT64 ? 8 : 4;
  for (std::size_t a = 0; a < 3; ++a) {
    EXPECT_EQ(cloud.fields[a].name, axes[a]);
    EXPECT_EQ(cloud.fields[a].offset, xyz_size * a) << cloud.fields[a].name;
    EXPECT_EQ(int(cloud.fields[a].datatype), int(xyz_datatype)) << cloud.fields[a].name;
  }
  EXPECT_EQ(cloud.point_step % 4, 0u) << "point_step " << cloud.point_step;
  std::vector<bool> used(cloud.point_step, false);
  for (const auto &f : cloud.fields) {
    ASSERT_TRUE(hpds::isValidFieldType(f.datatype)) << f.name;
    const std::size_t size = hpds::fieldTypeSize(static_cast<hpds::FieldType>(f.datatype));
    EXPECT_EQ(f.offset % size, 0u) << "field " << f.name << " at offset " << f.offset << ", element size " << size;
    EXPECT_EQ(cloud.point_step % size, 0u) << "point_step " << cloud.point_step << ", field " << f.name;
    ASSERT_LE(f.offset + f.count * size, cloud.point_step) << f.name;
    for (std::size_t b = f.offset; b < f.offset + f.count * size; ++b) {
      EXPECT_FALSE(used[b]) << "field " << f.name << " overlaps another at byte " << b;
      used[b] = true;
    }
  }
}

void expectOutputLayout(const sensor_msgs::PointCloud2 &out, const sensor_msgs::PointCloud2 &input, bool normals) {
  // Fields are found by name: their order after x y z follows the element sizes (OutputCloud.hpp).
  std::map<std::string, std::pair<int, std::uint32_t>> expected = {{"x", {7, 1}}, {"y", {7, 1}}, {"z", {7, 1}},
                                                                    {"level", {2, 1}}};
  if (normals)
    for (const char *n : {"normal_x", "normal_y", "normal_z", "curvature"}) expected.emplace(n, std::make_pair(7, 1u));
  for (const auto &f : input.fields)
    if (f.name != "x" && f.name != "y" && f.name != "z" && f.name != "_")
      expected.emplace(f.name, std::make_pair(int(f.datatype), f.count));
  std::map<std::string, std::pair<int, std::uint32_t>> got;
  for (const auto &f : out.fields)
    EXPECT_TRUE(got.emplace(f.name, std::make_pair(int(f.datatype), f.count)).second) << "field " << f.name << " twice";
  EXPECT_EQ(got, expected);
  expectAlignedFields(out);
  EXPECT_FALSE(out.is_bigendian);
}

std::vector<std::uint8_t> readBytes(const std::filesystem::path &p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void writeBytes(const std::filesystem::path &p, const std::vector<std::uint8_t> &bytes) {
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char *>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}

}  // namespace hpds_test
