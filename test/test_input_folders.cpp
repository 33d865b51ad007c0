// Input lists: natural name order (a strict weak order that sorts digit runs as numbers), the warning for files
// given out of it, and which PLY files a folder leaves out (a sampling's outputs, not frames hpds wrote).
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "TestData.hpp"
#include "hpds/io/InputFolders.hpp"
#include "hpds/io/PlyWriter.hpp"

namespace hpds {
namespace {

std::string randomName(std::mt19937 &rng) {
  static const std::string alphabet = "ab_.0123456789";
  std::uniform_int_distribution<int> length(0, 7), pick(0, int(alphabet.size()) - 1);
  std::string s;
  for (int i = length(rng); i > 0; --i) s += alphabet[std::size_t(pick(rng))];
  return s;
}

// Brute force over random names: irreflexive, asymmetric, transitive, and incomparability transitive (what
// std::sort needs); equal names only are equivalent, so the order of a folder's files is the same on every run.
TEST(InputFolders, NaturalOrderIsAStrictTotalOrderOnRandomNames) {
  std::mt19937 rng(7);
  std::vector<std::string> names(120);
  for (std::string &n : names) n = randomName(rng);
  for (const std::string &a : names) {
    EXPECT_FALSE(naturalLess(a, a)) << a;
    for (const std::string &b : names) {
      if (a != b) {
        EXPECT_NE(naturalLess(a, b), naturalLess(b, a)) << "'" << a << "' '" << b << "'";
      }
      for (const std::string &c : names) {
        if (naturalLess(a, b) && naturalLess(b, c)) {
          EXPECT_TRUE(naturalLess(a, c)) << a << " " << b << " " << c;
        }
      }
    }
  }
}

TEST(InputFolders, DigitRunsCompareAsNumbers) {
  std::vector<std::string> names;
  for (int i : {10, 2, 0, 100, 1, 11, 9}) names.push_back("f_" + std::to_string(i) + ".pcd");
  std::sort(names.begin(), names.end(), naturalLess);
  EXPECT_EQ(names, (std::vector<std::string>{"f_0.pcd", "f_1.pcd", "f_2.pcd", "f_9.pcd", "f_10.pcd", "f_11.pcd",
                                             "f_100.pcd"}));
  EXPECT_TRUE(naturalLess("frame_000002.pcd", "frame_000010.pcd"));  // padded: the same as text order
  EXPECT_TRUE(naturalLess("f_2.pcd", "f_02.pcd")) << "equal values: fewer leading zeros first, never equivalent";
  EXPECT_TRUE(naturalLess("a_9.pcd", "b_1.pcd"));
}

TEST(InputFolders, FilesGivenOutOfNameOrderAreWarnedPerFolder) {
  EXPECT_EQ(inputOrderWarning({"d/f_1.pcd", "d/f_2.pcd", "d/f_10.pcd"}), "");
  EXPECT_EQ(inputOrderWarning({"a/f_9.pcd", "b/f_1.pcd", "a/f_10.pcd"}), "") << "each folder on its own";
  EXPECT_EQ(inputOrderWarning({"one.pcd"}), "");
  const std::string w = inputOrderWarning({"d/f_1.pcd", "d/f_10.pcd", "d/f_2.pcd"});
  EXPECT_NE(w.find("'d/f_10.pcd' is given before 'd/f_2.pcd'"), std::string::npos) << w;
  EXPECT_NE(w.find("give the folder 'd' itself"), std::string::npos) << w;
  const std::string here = inputOrderWarning({"f_3.bin", "f_20.bin", "f_100.bin", "f_4.bin"});
  EXPECT_NE(here.find("'f_100.bin' is given before 'f_4.bin'"), std::string::npos) << here;
  EXPECT_NE(here.find("give the folder '.' itself"), std::string::npos) << here;
}

// Found in a trial: a folder of frames from `hpds synth --format ply` was refused ("holds no frame"), as every PLY
// hpds wrote carried the mark of a sampling's output. Only outputs carry it now.
TEST(InputFolders, OnlyASamplingsOutputIsLeftOut) {
  const auto dir = test::scratchDir("input_folders_marks");
  PointLayout l;
  for (const char *axis : {"x", "y", "z"}) l.append(axis, FieldType::Float32);
  PointBuffer cloud(l, 4);
  writePly((dir / "frame_1.ply").string(), cloud);
  writePly((dir / "frame_2.ply").string(), cloud, PlyContent::kPoints);
  writePly((dir / "samples.ply").string(), cloud, PlyContent::kSamples);
  std::ostringstream notes;
  const std::vector<std::string> inputs = expandInputFolders({dir.string()}, notes);
  ASSERT_EQ(inputs.size(), 2u) << notes.str();
  EXPECT_EQ(std::filesystem::path(inputs[0]).filename(), "frame_1.ply");
  EXPECT_EQ(std::filesystem::path(inputs[1]).filename(), "frame_2.ply");
  EXPECT_NE(notes.str().find("samples.ply' left out of folder"), std::string::npos) << notes.str();
  // Named one by one, an output is taken as given.
  std::ostringstream none;
  EXPECT_EQ(expandInputFolders({(dir / "samples.ply").string()}, none).size(), 1u);
  EXPECT_EQ(none.str(), "");
}

}  // namespace
}  // namespace hpds
