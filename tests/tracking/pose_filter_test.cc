// The patient's pose filter: follows steady motion without lag, weighs
// frames by their uncertainty, restarts on a jump or a gap.
#include "tracking/pose_filter.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

namespace arpos {
namespace {

Rigid3d At(double t) {
  // 20 mm/s along x, 1 deg/s about z: a couch moving the patient.
  return Rigid3d::FromRotationVector(Eigen::Vector3d(0, 0, t * 3.14159265358979 / 180), Eigen::Vector3d(0.02 * t, 1.2, 0.9));
}

TEST(PoseFilter, FollowsSteadyMotionWithoutLagAndAveragesNoise) {
  PoseFilter filter;
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0, 0.002);  // 2 mm per axis
  double raw_sq = 0, filtered_sq = 0;
  int n = 0;
  for (int i = 0; i < 300; ++i) {
    const double t = i / 30.0;
    Rigid3d measured = At(t);
    measured.translation += Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
    const FilteredPose f = filter.Update(t, measured, 0.002, 0.001);
    if (i >= 60) {  // after settling
      raw_sq += (measured.translation - At(t).translation).squaredNorm();
      filtered_sq += (f.room_from_model.translation - At(t).translation).squaredNorm();
      ++n;
    }
  }
  const double raw = std::sqrt(raw_sq / n), filtered = std::sqrt(filtered_sq / n);
  EXPECT_LT(filtered, 0.6 * raw) << "raw " << raw * 1000 << " mm, filtered " << filtered * 1000 << " mm";
  // No lag: without noise the filter sits on the motion.
  PoseFilter exact;
  FilteredPose last;
  for (int i = 0; i < 90; ++i) last = exact.Update(i / 30.0, At(i / 30.0), 0.002, 0.001);
  EXPECT_LT((last.room_from_model.translation - At(89 / 30.0).translation).norm(), 1e-4);
  EXPECT_LT(last.room_from_model.rotation.angularDistance(At(89 / 30.0).rotation), 1e-4);
}

TEST(PoseFilter, AnUncertainFrameBarelyMovesTheEstimate) {
  PoseFilter filter;
  for (int i = 0; i < 60; ++i) filter.Update(i / 30.0, At(i / 30.0), 0.001, 0.0005);
  Rigid3d off = At(2.0);
  off.translation.x() += 0.03;  // 30 mm off, but said to be known to 20 mm
  const FilteredPose f = filter.Update(2.0, off, 0.02, 0.0005);
  EXPECT_FALSE(f.restarted);
  EXPECT_LT((f.room_from_model.translation - At(2.0).translation).norm(), 0.002);
}

// A prediction without a measurement: along the motion, less certain the
// further ahead, none beyond the gap limit or before the start, and the
// filter itself unchanged by it.
TEST(PoseFilter, PredictsAlongTheMotionWithGrowingUncertaintyAndChangesNothing) {
  PoseFilter filter, twin;
  EXPECT_FALSE(filter.Predict(0.0).has_value());
  for (int i = 0; i < 60; ++i) {
    filter.Update(i / 30.0, At(i / 30.0), 0.001, 0.0005);
    twin.Update(i / 30.0, At(i / 30.0), 0.001, 0.0005);
  }
  const double last = 59 / 30.0;
  double previous_sigma = 0;
  for (int k = 1; k <= 6; ++k) {
    const double t = last + k / 30.0;
    const std::optional<FilteredPose> p = filter.Predict(t);
    ASSERT_TRUE(p.has_value()) << k;
    EXPECT_LT((p->room_from_model.translation - At(t).translation).norm(), 1e-4) << k;
    EXPECT_LT(p->room_from_model.rotation.angularDistance(At(t).rotation), 1e-4) << k;
    EXPECT_GT(p->position_sigma_m, previous_sigma) << k;
    previous_sigma = p->position_sigma_m;
  }
  EXPECT_FALSE(filter.Predict(last).has_value());
  EXPECT_FALSE(filter.Predict(last + 0.6).has_value());  // beyond max_gap_s
  const FilteredPose a = filter.Update(2.0, At(2.0), 0.001, 0.0005);
  const FilteredPose b = twin.Update(2.0, At(2.0), 0.001, 0.0005);
  EXPECT_EQ(a.room_from_model.translation, b.room_from_model.translation);
  EXPECT_EQ(a.position_sigma_m, b.position_sigma_m);
}

TEST(PoseFilter, RestartsOnAJumpOrAGap) {
  PoseFilter filter;
  for (int i = 0; i < 60; ++i) filter.Update(i / 30.0, At(i / 30.0), 0.001, 0.0005);
  Rigid3d jumped = At(2.0);
  jumped.translation.y() += 0.05;  // 50 mm, known to 1 mm: the patient moved
  FilteredPose f = filter.Update(2.0, jumped, 0.001, 0.0005);
  EXPECT_TRUE(f.restarted);
  EXPECT_LT((f.room_from_model.translation - jumped.translation).norm(), 1e-9);
  f = filter.Update(3.0, At(3.0), 0.001, 0.0005);  // 1 s later
  EXPECT_TRUE(f.restarted);
  PoseFilterOptions bad;
  bad.acceleration_m_s2 = 0;
  EXPECT_FALSE(bad.Validate().empty());
}

}  // namespace
}  // namespace arpos
