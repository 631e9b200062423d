// Runs the real `arpos` executable as a user would.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>

#include "cli/cli_util.h"
#include "sensor/test_case_builder.h"
#include "sensor/tum_io.h"
#include "util/file.h"

namespace arpos {
namespace {

using Result = testing::CliResult;
using testing::RunArpos;

TEST(Cli, HelpListsSubcommands) {
  const Result r = RunArpos("--help");
  EXPECT_EQ(r.status, 0);
  for (const char* command : {"check", "evaluate", "run-case"}) {
    EXPECT_NE(r.output.find(std::string("  ") + command), std::string::npos) << r.output;
  }
  EXPECT_EQ(RunArpos("no-such-command").status, 2);
  EXPECT_EQ(RunArpos("check --no-such-option x").status, 2);
}

// The README's main command on the committed sample session: every stage
// runs, the store is written, and the model pose at scan time lands near the
// simulator's truth (the sample is small: a few body-scan frames).
TEST(Cli, RunCaseOnTheSampleSessionDoesEveryStage) {
  TempDir dir;
  const std::string store = (dir.path() / "store.db").string();
  const Result r =
      RunArpos("run-case " + std::string(ARPOS_SAMPLE_SESSIONS_DIR) + "/demo_xtion --store " + store);
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("body marker map"), std::string::npos) << r.output;
  const size_t at = r.output.find("model pose at scan time vs body_groundtruth.txt: ");
  ASSERT_NE(at, std::string::npos) << r.output;
  double mm = -1, deg = -1;
  ASSERT_EQ(std::sscanf(r.output.c_str() + at, "model pose at scan time vs body_groundtruth.txt: %lf mm, %lf deg",
                        &mm, &deg),
            2);
  EXPECT_LT(mm, 5.0) << r.output;
  EXPECT_LT(deg, 0.5) << r.output;
  // Tracking ran on tracking/seq_00 and was evaluated (no files without --out).
  const size_t tracked = r.output.find("tracking seq_00 vs body_groundtruth.txt: MTE ");
  ASSERT_NE(tracked, std::string::npos) << r.output;
  double mte = -1;
  ASSERT_EQ(std::sscanf(r.output.c_str() + tracked, "tracking seq_00 vs body_groundtruth.txt: MTE %lf", &mte), 1);
  EXPECT_LT(mte, 5.0) << r.output;
  // Running it again, with --out, adds a second session to the same store and
  // writes the tracking files and the overlay.
  const Result again = RunArpos("run-case " + std::string(ARPOS_SAMPLE_SESSIONS_DIR) + "/demo_xtion --store " +
                                store + " --out " + (dir.path() / "out").string());
  EXPECT_EQ(again.status, 0) << again.output;
  for (const char* file : {"seq_00/poses.txt", "seq_00/camera_poses.txt", "seq_00/corrections.csv",
                           "seq_00/timing.csv", "seq_00/overlay/2000.000000.png", "model_pose.txt"}) {
    EXPECT_TRUE(std::filesystem::exists(dir.path() / "out" / file)) << file;
  }
  const Result info = RunArpos("store info --store " + store);
  EXPECT_EQ(info.status, 0) << info.output;
}

TEST(Cli, CheckPassesAndFails) {
  TempDir dir;
  testing::WriteTinyCase(dir.path() / "case");
  Result r = RunArpos("check " + (dir.path() / "case").string());
  EXPECT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("OK"), std::string::npos);
  std::filesystem::remove(dir.path() / "case" / "room" / "depth" / "2.png");
  WriteFileAtomic(dir.path() / "case" / "target_pose.txt", "1 2 3\n");
  r = RunArpos("check " + (dir.path() / "case").string());
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_NE(r.output.find("room/depth/2.png: missing"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("target_pose.txt: expected a 4x4 matrix"), std::string::npos) << r.output;
}

TEST(Cli, EvaluateIdenticalAndPerturbed) {
  TempDir dir;
  std::vector<StampedPose> gt, est;
  for (int i = 0; i < 10; ++i) {
    const Rigid3d pose(Eigen::Quaterniond(Eigen::AngleAxisd(0.1 * i, Eigen::Vector3d::UnitY())),
                       Eigen::Vector3d(i * 0.01, 0.5, 1.0));
    gt.push_back({i * 0.1, pose});
    // 2 mm along the moving frame's z; frame 9 missing (lost).
    if (i < 9) est.push_back({i * 0.1 + 0.001, pose * Rigid3d(Eigen::Quaterniond::Identity(), {0, 0, 0.002})});
  }
  WriteTrajectory(dir.path() / "gt.txt", gt);
  WriteTrajectory(dir.path() / "est.txt", est);
  Result r = RunArpos("evaluate --gt " + (dir.path() / "gt.txt").string() + " --est " +
                 (dir.path() / "gt.txt").string() + " --json");
  EXPECT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("\"translation_mm\": {\"mean\": 0.000000"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("\"lost_percent\": 0.0000"), std::string::npos) << r.output;
  r = RunArpos("evaluate --gt " + (dir.path() / "gt.txt").string() + " --est " +
          (dir.path() / "est.txt").string() + " --json");
  EXPECT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("\"translation_mm\": {\"mean\": 2.000000"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("\"lost_percent\": 10.0000"), std::string::npos) << r.output;
  r = RunArpos("evaluate --gt " + (dir.path() / "missing.txt").string() + " --est x");
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.output.find("missing.txt: cannot open"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace arpos
