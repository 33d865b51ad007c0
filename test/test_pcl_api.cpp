// The PCL one-call API (hpds/pcl.hpp) and the promise behind both one-call APIs: the samples are those that
// `hpds sample` writes for the same points and config.
#include <gtest/gtest.h>

#include <pcl/point_types.h>

#include <cmath>
#include <fstream>
#include <limits>

#include "TestData.hpp"
#include "hpds/config/ConfigYaml.hpp"
#include "hpds/eval/SyntheticLidar.hpp"
#include "hpds/pcl.hpp"
#include "hpds/pcl/PointCloudFile.hpp"

namespace hpds {
namespace {

pcl::PointCloud<pcl::PointXYZI> syntheticCloud() {
  SyntheticLidarConfig c;
  c.beams = 16;
  c.azimuth_steps = 720;
  c.frames = 1;
  const PointBuffer points = SyntheticLidar(c).frame(0).frame.points;
  const PointLayout &l = points.layout();
  pcl::PointCloud<pcl::PointXYZI> cloud;
  cloud.resize(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    cloud[i].x = static_cast<float>(readAsDouble(points.record(i), *l.find("x")));
    cloud[i].y = static_cast<float>(readAsDouble(points.record(i), *l.find("y")));
    cloud[i].z = static_cast<float>(readAsDouble(points.record(i), *l.find("z")));
    cloud[i].intensity = static_cast<float>(i % 1000);  // tells every point apart
  }
  cloud[3].x = std::numeric_limits<float>::quiet_NaN();
  cloud.header.frame_id = "lidar";
  cloud.header.stamp = 123456;
  return cloud;
}

std::vector<Eigen::Vector3f> xyzOf(const pcl::PointCloud<pcl::PointXYZI> &cloud) {
  std::vector<Eigen::Vector3f> out;
  for (const auto &p : cloud.points) out.emplace_back(p.x, p.y, p.z);
  return out;
}

HpdsConfig config() {
  HpdsConfig c;
  c.output.level = -1;
  c.output.spacing = 0.15;
  c.normals.enabled = true;
  return c;
}

TEST(PclDownsample, RealInputPointsWithEveryFieldInSampleOrder) {
  const pcl::PointCloud<pcl::PointXYZI> cloud = syntheticCloud();
  pcl::PointCloud<pcl::Normal> normals;
  const auto out = downsample(cloud, config(), &normals);
  const Samples s = downsample(xyzOf(cloud), config());
  ASSERT_EQ(out->size(), s.size());
  ASSERT_EQ(normals.size(), s.size());
  ASSERT_GT(s.size(), 100u);
  EXPECT_EQ(out->header.frame_id, "lidar");
  EXPECT_EQ(out->header.stamp, 123456u);
  EXPECT_EQ(out->height, 1u);
  EXPECT_EQ(out->width, s.size());
  EXPECT_TRUE(out->is_dense);
  for (std::size_t i = 0; i < s.size(); ++i) {
    const pcl::PointXYZI &in = cloud[s.index[i]];
    ASSERT_EQ((*out)[i].x, in.x);
    ASSERT_EQ((*out)[i].y, in.y);
    ASSERT_EQ((*out)[i].z, in.z);
    ASSERT_EQ((*out)[i].intensity, in.intensity);
    ASSERT_TRUE(std::isfinite((*out)[i].x));
    const bool nan = std::isnan(s.normal[i].x());
    EXPECT_EQ(std::isnan(normals[i].normal_x), nan);
    if (!nan) {
      EXPECT_EQ(normals[i].normal_x, s.normal[i].x());
      EXPECT_EQ(normals[i].normal_z, s.normal[i].z());
      EXPECT_EQ(normals[i].curvature, s.curvature[i]);
    }
  }
}

TEST(PclDownsample, NormalsOnlyWhenAskedForAndTheSamplesDoNotDependOnIt) {
  const pcl::PointCloud<pcl::PointXYZI> cloud = syntheticCloud();
  HpdsConfig off = config();
  off.normals.enabled = false;
  pcl::PointCloud<pcl::Normal> normals;
  const auto with = downsample(cloud, off, &normals);
  const auto without = downsample(cloud, config());
  ASSERT_EQ(with->size(), without->size());
  ASSERT_EQ(normals.size(), with->size());
  std::size_t valid = 0;
  for (std::size_t i = 0; i < with->size(); ++i) {
    ASSERT_EQ((*with)[i].intensity, (*without)[i].intensity);
    valid += std::isfinite(normals[i].normal_x) ? 1 : 0;
  }
  EXPECT_GT(valid, with->size() / 2);
}

// As PCL's NormalEstimation, the normals face the cloud's sensor_origin_: a frame saved in a map frame keeps its
// sensor position there.
TEST(PclDownsample, NormalsFaceTheCloudsSensorOrigin) {
  pcl::PointCloud<pcl::PointXYZ> cloud;
  for (int i = 0; i < 60; ++i)
    for (int j = 0; j < 60; ++j) cloud.push_back(pcl::PointXYZ(10.0f, -1.5f + 0.05f * float(i), -1.5f + 0.05f * float(j)));
  pcl::PointCloud<pcl::Normal> toward_origin, toward_sensor;
  (void)downsample(cloud, config(), &toward_origin);
  cloud.sensor_origin_ = Eigen::Vector4f(20.0f, 0.0f, 0.0f, 0.0f);
  const auto out = downsample(cloud, config(), &toward_sensor);
  EXPECT_EQ(out->sensor_origin_, cloud.sensor_origin_);
  ASSERT_EQ(toward_sensor.size(), toward_origin.size());
  std::size_t valid = 0;
  for (std::size_t i = 0; i < toward_sensor.size(); ++i) {
    if (std::isnan(toward_sensor[i].normal_x)) continue;
    ++valid;
    EXPECT_LT(toward_origin[i].normal_x, -0.99f) << i;
    EXPECT_GT(toward_sensor[i].normal_x, 0.99f) << i;
  }
  EXPECT_GT(valid, toward_sensor.size() / 2);
}

TEST(PclDownsample, CovariancesOnlyWhenAskedForInGicpsType) {
  pcl::PointCloud<pcl::PointXYZI> cloud = syntheticCloud();
  // Lone returns far from everything get no normal. Their covariance was NaN, and PCL's GICP given one returned a
  // NaN transform that said it had converged (found in a user trial): it is the identity, as on a scan line.
  for (int k = 0; k < 5; ++k) {
    pcl::PointXYZI lone;
    lone.x = 60.f + 7.f * float(k), lone.y = -40.f, lone.z = 9.f, lone.intensity = 1.f;
    cloud.push_back(lone);
  }
  HpdsConfig asked = config();
  asked.normals.covariances = true;
  const Samples s = downsample(xyzOf(cloud), asked);
  // Asked for by the pointer alone: neither normals nor covariances need to be on in the config.
  HpdsConfig off = config();
  off.normals.enabled = false;
  SampleCovariances covariances;
  const auto out = downsample(cloud, off, nullptr, &covariances);
  ASSERT_EQ(out->size(), s.size());
  ASSERT_EQ(covariances.size(), s.size());
  std::size_t without_normal = 0;
  for (std::size_t i = 0; i < s.size(); ++i) {
    ASSERT_TRUE(covariances[i].allFinite()) << i;
    EXPECT_TRUE(covariances[i] == s.covariance[i].cast<double>()) << i;
    if (!s.normal[i].allFinite()) {
      ++without_normal;
      EXPECT_TRUE(covariances[i] == Eigen::Matrix3d::Identity()) << i;
    }
  }
  EXPECT_GE(without_normal, 5u);
  // A config asking for covariances is fine without the pointer (nothing is computed for them).
  EXPECT_EQ(downsample(cloud, asked)->size(), s.size());
  // A config every other reader refuses (covariances without normals) is refused here too, named, whatever the
  // pointers ask for: the switches set from them hid it.
  HpdsConfig contradictory = config();
  contradictory.normals.enabled = false;
  contradictory.normals.covariances = true;
  EXPECT_THROW((void)downsample(xyzOf(cloud), contradictory), std::invalid_argument);
  for (SampleCovariances *asked_for : {static_cast<SampleCovariances *>(nullptr), &covariances}) {
    try {
      (void)downsample(cloud, contradictory, nullptr, asked_for);
      ADD_FAILURE() << "covariances on with normals off was taken";
    } catch (const std::invalid_argument &e) {
      EXPECT_NE(std::string(e.what()).find("normals.covariances"), std::string::npos) << e.what();
    }
  }
}

// Both one-call APIs promise the samples `hpds sample` writes: run the tool on the same points and config.
TEST(PclDownsample, TheSamplesAreThoseHpdsSampleWrites) {
  const pcl::PointCloud<pcl::PointXYZI> cloud = syntheticCloud();
  const auto dir = test::scratchDir("pcl_api_cli");
  PointLayout layout;
  layout.append("x", FieldType::Float32);
  layout.append("y", FieldType::Float32);
  layout.append("z", FieldType::Float32);
  layout.append("intensity", FieldType::Float32);
  PointBuffer buffer(layout, cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i)
    std::memcpy(buffer.record(i), &cloud[i].x, 3 * sizeof(float)),
        std::memcpy(buffer.record(i) + 12, &cloud[i].intensity, sizeof(float));
  writePcd((dir / "in.pcd").string(), buffer);
  std::ofstream((dir / "config.yaml").string()) << dumpConfigYaml(config());

  std::string log;
  ASSERT_EQ(test::runHpds("sample " + test::shellQuote(dir / "in.pcd") + " --config " +
                              test::shellQuote(dir / "config.yaml") + " -o " + test::shellQuote(dir / "out.ply"),
                          &log),
            0)
      << log;
  const PointBuffer written = readPointCloud((dir / "out.ply").string());
  pcl::PointCloud<pcl::Normal> normals;
  const auto out = downsample(cloud, config(), &normals);
  ASSERT_EQ(written.size(), out->size());
  const PointLayout &w = written.layout();
  for (std::size_t i = 0; i < written.size(); ++i) {
    ASSERT_EQ(readAsDouble(written.record(i), *w.find("x")), static_cast<double>((*out)[i].x)) << i;
    ASSERT_EQ(readAsDouble(written.record(i), *w.find("y")), static_cast<double>((*out)[i].y)) << i;
    ASSERT_EQ(readAsDouble(written.record(i), *w.find("intensity")), static_cast<double>((*out)[i].intensity)) << i;
    const double nx = readAsDouble(written.record(i), *w.find("normal_x"));
    if (std::isnan(nx)) {
      EXPECT_TRUE(std::isnan(normals[i].normal_x));
    } else {
      EXPECT_EQ(nx, static_cast<double>(normals[i].normal_x));
    }
  }
}

}  // namespace
}  // namespace hpds
