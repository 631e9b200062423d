#include <gtest/gtest.h>

#include <random>

#include "sensor/sequence.h"
#include "sensor/test_case_builder.h"
#include "sensor/tum_io.h"
#include "util/check.h"
#include "util/file.h"

namespace arpos {
namespace {

TEST(TumIo, TrajectoryRoundTripKeepsPrecision) {
  TempDir dir;
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<StampedPose> poses;
  for (int i = 0; i < 20; ++i) {
    poses.push_back({1e9 + i * 0.033333,
                     Rigid3d(Eigen::Quaterniond(u(rng), u(rng), u(rng), u(rng)).normalized(),
                             Eigen::Vector3d(u(rng), u(rng), u(rng)))});
  }
  WriteTrajectory(dir.path() / "t.txt", poses, "test");
  const auto back = ReadTrajectory(dir.path() / "t.txt");
  ASSERT_EQ(back.size(), poses.size());
  for (size_t i = 0; i < poses.size(); ++i) {
    EXPECT_NEAR(back[i].timestamp_s, poses[i].timestamp_s, 1e-6);
    EXPECT_TRUE(back[i].room_from_x.IsApprox(poses[i].room_from_x, 1e-8, 1e-8));
  }
}

TEST(TumIo, MalformedLinesNameFileAndLine) {
  TempDir dir;
  WriteFileAtomic(dir.path() / "t.txt", "# header\n1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 1\n");
  try {
    ReadTrajectory(dir.path() / "t.txt");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("t.txt:3: expected 8 numbers"), std::string::npos) << e.what();
  }
  WriteFileAtomic(dir.path() / "q.txt", "1.0 0 0 0 0 0 0 2\n");
  EXPECT_THROW(ReadTrajectory(dir.path() / "q.txt"), InputError);
  WriteFileAtomic(dir.path() / "rgb.txt", "1.0 rgb/a.png extra\n");
  EXPECT_THROW(ReadImageList(dir.path() / "rgb.txt"), InputError);
  WriteFileAtomic(dir.path() / "m.txt", "1 0 0 0\n0 1 0 0\n0 0 1 0\n");
  EXPECT_THROW(ReadMatrix4(dir.path() / "m.txt"), InputError);
}

// Files written on Windows: a UTF-8 byte-order mark first (Notepad, .NET
// writers) and CRLF line ends. The mark used to be read into the first
// token ("'\xEF\xBB\xBF#' is not a number", the mark invisible in the message).
TEST(TumIo, FilesWithAByteOrderMarkAndCrlfLineEndsReadAsWithout) {
  TempDir dir;
  const std::string bom = "\xEF\xBB\xBF";
  WriteFileAtomic(dir.path() / "m.txt",
                  bom + "# target\r\n1 0 0 0.5\r\n0 1 0 0\r\n0 0 1 0\r\n0 0 0 1\r\n");
  EXPECT_DOUBLE_EQ(ReadMatrix4(dir.path() / "m.txt")(0, 3), 0.5);
  WriteFileAtomic(dir.path() / "rgb.txt", bom + "1.0 rgb/a.png\r\n2.0 rgb/b.png\r\n");
  const std::vector<ImageListEntry> list = ReadImageList(dir.path() / "rgb.txt");
  ASSERT_EQ(list.size(), 2u);
  EXPECT_DOUBLE_EQ(list[0].timestamp_s, 1.0);
  EXPECT_EQ(list[1].relative_path, "rgb/b.png");
  WriteFileAtomic(dir.path() / "t.txt", bom + "1.0 0 0 0 0 0 0 1\r\n");
  ASSERT_EQ(ReadTrajectory(dir.path() / "t.txt").size(), 1u);
  // Only a leading mark is dropped.
  WriteFileAtomic(dir.path() / "late.txt", "1.0 rgb/a.png\n" + bom + "2.0 rgb/b.png\n");
  EXPECT_THROW(ReadImageList(dir.path() / "late.txt"), InputError);
}

// A NaN in a pose line used to be reported as "expected 8 numbers", as if
// the line were short.
TEST(TumIo, ANonFiniteValueIsNamedWithFileLineAndField) {
  TempDir dir;
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"1.0 0 0 nan 0 0 0 1", "tz is 'nan', not a finite number"},
      {"1.0 0 0 0 0 0 0 -inf", "qw is '-inf', not a finite number"},
      {"1e999 0 0 0 0 0 0 1", "timestamp is '1e999', not a finite number"},
      {"1.0 NaN 0 0 0 0 0 1", "tx is 'NaN', not a finite number"}};
  for (const auto& [line, message] : cases) {
    WriteFileAtomic(dir.path() / "gt.txt", "# timestamp tx ty tz qx qy qz qw\n0.5 0 0 0 0 0 0 1\n" + line + "\n");
    try {
      ReadTrajectory(dir.path() / "gt.txt");
      ADD_FAILURE() << "no throw for " << line;
    } catch (const InputError& e) {
      const std::string expected = (dir.path() / "gt.txt").string() + ":3: " + message;
      EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
    }
  }
  // A word is still a malformed line, not a non-finite number.
  WriteFileAtomic(dir.path() / "w.txt", "1.0 0 0 zero 0 0 0 1\n");
  try {
    ReadTrajectory(dir.path() / "w.txt");
    ADD_FAILURE() << "no throw";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("w.txt:1: expected 8 numbers"), std::string::npos) << e.what();
  }
}

TEST(TumIo, AssociationIsGreedyAndWindowed) {
  const std::vector<double> a = {1.0, 1.033, 1.066, 2.0};
  const std::vector<double> b = {1.001, 1.035, 1.5, 1.067};
  const auto pairs = AssociateTimestamps(a, b, 0.02);
  ASSERT_EQ(pairs.size(), 3u);
  EXPECT_EQ(pairs[0], std::make_pair(size_t{0}, size_t{0}));
  EXPECT_EQ(pairs[1], std::make_pair(size_t{1}, size_t{1}));
  EXPECT_EQ(pairs[2], std::make_pair(size_t{2}, size_t{3}));
  // One b may serve only one a: the closer wins.
  const auto single = AssociateTimestamps({1.0, 1.01}, {1.009}, 0.02);
  ASSERT_EQ(single.size(), 1u);
  EXPECT_EQ(single[0].first, 1u);
}

TEST(Sequence, LoadsFrames) {
  TempDir dir;
  testing::WriteTinyCase(dir.path());
  const auto config = testing::TinyCaseConfig();
  const Sequence seq = Sequence::Open(dir.path() / "room");
  ASSERT_EQ(seq.size(), 3u);
  const RgbdFrame f = seq.LoadFrame(1, config.camera);
  EXPECT_EQ(f.color.type(), CV_8UC3);
  EXPECT_EQ(f.depth.type(), CV_16UC1);
  EXPECT_NEAR(f.DepthM(5, 5), 5100 / 5000.0, 1e-12);
  ASSERT_TRUE(seq.CameraGroundTruth());
  EXPECT_EQ(seq.CameraGroundTruth()->size(), 3u);

}

}  // namespace
}  // namespace arpos
