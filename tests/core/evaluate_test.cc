#include <gtest/gtest.h>

#include "eval/trajectory_eval.h"
#include "geometry/so3.h"

namespace arpos {
namespace {

std::vector<StampedPose> Trajectory(int n) {
  std::vector<StampedPose> poses;
  for (int i = 0; i < n; ++i) {
    const double t = i / 30.0;
    poses.push_back({t, Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.1 * i, Eigen::Vector3d(1, 2, 3).normalized())),
                                Eigen::Vector3d(0.1 * i, -0.05 * i, 1.0))});
  }
  return poses;
}

TEST(Evaluate, IdenticalTrajectoriesGiveZero) {
  const auto gt = Trajectory(50);
  const auto eval = EvaluateTrajectory(gt, gt);
  EXPECT_EQ(eval.estimated_frames, 50);
  EXPECT_EQ(eval.lost_frames, 0);
  EXPECT_NEAR(eval.translation_mm.max, 0.0, 1e-9);
  EXPECT_NEAR(eval.rotation_deg.max, 0.0, 1e-6);
}

TEST(Evaluate, PerturbedTrajectoryGivesKnownFigures) {
  const auto gt = Trajectory(10);
  auto est = gt;
  // Frame i gets a translational error of i mm along the moving frame's x and
  // a rotational error of 0.1*i degrees: MTE 4.5 mm, median 4.5, MRE 0.45 deg.
  for (int i = 0; i < 10; ++i) {
    const Rigid3d delta(QuaternionFromRotationVector(Eigen::Vector3d(0, 0, RadFromDeg(0.1 * i))),
                        Eigen::Vector3d(0.001 * i, 0, 0));
    est[i].room_from_x = gt[i].room_from_x * delta;
    est[i].timestamp_s += 0.005;  // within the 0.02 s association window
  }
  const auto eval = EvaluateTrajectory(gt, est);
  EXPECT_EQ(eval.estimated_frames, 10);
  EXPECT_NEAR(eval.translation_mm.mean, 4.5, 1e-6);
  EXPECT_NEAR(eval.translation_mm.median, 4.5, 1e-6);
  EXPECT_NEAR(eval.translation_mm.max, 9.0, 1e-6);
  EXPECT_NEAR(eval.translation_mm.p95, 8.55, 1e-6);  // 0.95 * 9 = rank 8.55
  EXPECT_NEAR(eval.rotation_deg.mean, 0.45, 1e-6);
}

TEST(Evaluate, MissingEstimatesCountAsLost) {
  const auto gt = Trajectory(20);
  std::vector<StampedPose> est(gt.begin(), gt.begin() + 15);
  est.push_back({100.0, gt[0].room_from_x});  // no ground truth near it
  const auto eval = EvaluateTrajectory(gt, est);
  EXPECT_EQ(eval.lost_frames, 5);
  EXPECT_NEAR(eval.lost_percent, 25.0, 1e-9);
  EXPECT_EQ(eval.unmatched_estimates, 1);
  // Timestamps beyond the 0.02 s window do not associate.
  std::vector<StampedPose> sparse;  // 0.1 s apart
  for (size_t i = 0; i < gt.size(); i += 3) sparse.push_back(gt[i]);
  auto late = sparse;
  for (auto& p : late) p.timestamp_s += 0.025;
  EXPECT_EQ(EvaluateTrajectory(sparse, late).estimated_frames, 0);
  for (auto& p : late) p.timestamp_s -= 0.01;  // 0.015 s: inside the window
  EXPECT_EQ(EvaluateTrajectory(sparse, late).estimated_frames, static_cast<int>(sparse.size()));
}

// Nothing matched is no result, not a perfect one: no figures, n/a.
TEST(Evaluate, NothingMatchedHasNoErrorFigures) {
  const auto gt = Trajectory(10);
  for (const auto& est : {std::vector<StampedPose>{}, std::vector<StampedPose>{{1000.0, gt[0].room_from_x}}}) {
    const auto eval = EvaluateTrajectory(gt, est);
    EXPECT_FALSE(eval.has_errors());
    EXPECT_EQ(eval.lost_frames, 10);
    const std::string text = eval.ToText();
    EXPECT_NE(text.find("mean (MTE) n/a"), std::string::npos) << text;
    EXPECT_EQ(text.find("0.000"), std::string::npos) << text;
    const std::string json = eval.ToJson();
    EXPECT_NE(json.find("\"translation_mm\": null"), std::string::npos) << json;
    EXPECT_NE(json.find("\"rotation_deg\": null"), std::string::npos) << json;
  }
  EXPECT_TRUE(EvaluateTrajectory(gt, gt).has_errors());
}

TEST(Evaluate, StatsOfKnownValues) {
  const ErrorStats s = ComputeErrorStats({4, 1, 3, 2});
  EXPECT_DOUBLE_EQ(s.mean, 2.5);
  EXPECT_DOUBLE_EQ(s.median, 2.5);
  EXPECT_DOUBLE_EQ(s.max, 4);
  EXPECT_NEAR(s.p95, 3.85, 1e-12);
  EXPECT_NEAR(s.rmse, std::sqrt(7.5), 1e-12);
}

}  // namespace
}  // namespace arpos
