// Found by a library user: a program built with -march=native laid hpds::Frame out otherwise than the library
// (Eigen aligns Eigen::Isometry3d to its vector width), so Pipeline::addFrame read the pose from the wrong bytes and
// refused a rigid pose as "not 0 0 0 1". A translation unit built with -mavx (AvxFrameConsumer.cpp) stands for that
// program: Frame has one layout on both sides, a posed frame gives the library's samples, and readKittiPoses, whose
// vector cannot be aligned for that side, refuses with the fix instead of returning it.
#include <gtest/gtest.h>

#include <random>

#include "AvxFrameConsumer.hpp"
#include "TestData.hpp"
#include "hpds/io/PoseFile.hpp"
#include "hpds/pipeline/Pipeline.hpp"

namespace {

bool cpuHasAvx() {
#if defined(__x86_64__) || defined(__i386__)
  return __builtin_cpu_supports("avx");
#else
  return false;
#endif
}

std::vector<Eigen::Vector3f> patch() {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-10.f, 10.f);
  std::vector<Eigen::Vector3f> points(20000);
  for (auto &p : points) p = Eigen::Vector3f(u(rng), u(rng), 0.1f * std::sin(u(rng)));
  return points;
}

TEST(EigenAlignment, AFrameHasOneLayoutWhateverTheCallersVectorFlags) {
  if (!cpuHasAvx()) GTEST_SKIP() << "this CPU has no AVX: the -mavx translation unit cannot run here";
  const avx_consumer::FrameLayout avx = avx_consumer::frameLayout();
  ASSERT_GT(avx.isometry_alignment, alignof(Eigen::Isometry3d)) << "the -mavx translation unit did not get AVX";
  hpds::Frame f;
  const auto *base = reinterpret_cast<const char *>(&f);
  EXPECT_EQ(avx.size, sizeof(hpds::Frame));
  EXPECT_EQ(avx.pose_offset, static_cast<std::size_t>(reinterpret_cast<const char *>(&f.sensor_to_fixed) - base));
  EXPECT_EQ(avx.viewpoint_offset, static_cast<std::size_t>(reinterpret_cast<const char *>(&f.viewpoint) - base));
}

TEST(EigenAlignment, APosedFrameFromAnAvxProgramGivesTheLibrarysSamples) {
  if (!cpuHasAvx()) GTEST_SKIP() << "this CPU has no AVX: the -mavx translation unit cannot run here";
  const std::vector<Eigen::Vector3f> points = patch();
  const Eigen::Vector3d t(100.0, -20.0, 3.0);
  hpds::HpdsConfig config;
  config.mode = hpds::Mode::Map;
  config.normals.enabled = false;
  hpds::Pipeline pipeline(config);
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translation() = t;
  pipeline.addFrame(hpds::frameFromPoints(points, pose, 1.0));
  ASSERT_GT(pipeline.hierarchy().sampleCount(), 100u);
  EXPECT_EQ(avx_consumer::mapSamples(points, t), pipeline.hierarchy().sampleCount());
}

TEST(EigenAlignment, ReadKittiPosesRefusesAMoreAlignedCallerWithTheFix) {
  if (!cpuHasAvx()) GTEST_SKIP() << "this CPU has no AVX: the -mavx translation unit cannot run here";
  const auto dir = hpds::test::scratchDir("eigen_alignment");
  const std::string path = (dir / "poses.txt").string();
  hpds::writeKittiPoses(path, {Eigen::Isometry3d::Identity(), Eigen::Isometry3d::Identity()});
  EXPECT_EQ(hpds::readKittiPoses(path).size(), 2u);  // the library's own alignment
  const std::string error = avx_consumer::readPosesError(path);
  EXPECT_NE(error.find("-DEIGEN_MAX_STATIC_ALIGN_BYTES=" + std::to_string(alignof(Eigen::Isometry3d))),
            std::string::npos)
      << error;
  EXPECT_NE(error.find("32-byte Eigen alignment"), std::string::npos) << error;
}

}  // namespace
