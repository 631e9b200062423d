#include <gtest/gtest.h>

#include <cmath>
#include <optional>
#include <vector>

#include "geometry/so3.h"
#include "sensor/depth_timing.h"

namespace arpos {
namespace {

// Depth 10 ms late from a camera moving 0.15 m/s and turning 12 deg/s: the
// reading is worth 1.5 mm less plus 2.1 mm per metre of depth; from no
// earlier poses, the assumed hand-held motion; no delay, nothing.
TEST(DelayedDepth, SigmaFollowsTheCamerasSpeedAndTurnOverTheDelay) {
  const double step_s = 1.0 / 15;
  const double turn = 12.0 * M_PI / 180;
  const Rigid3d step(QuaternionFromRotationVector(Eigen::Vector3d(0, turn * step_s, 0)),
                     Eigen::Vector3d(0.15 * step_s, 0, 0));
  const DelayedDepthSigma s = DelayedDepthSigmaOf(0.010, &step, step_s);
  EXPECT_NEAR(s.const_m, 0.0015, 1e-9);
  EXPECT_NEAR(s.per_m, 0.010 * turn, 1e-9);
  EXPECT_NEAR(s.At(2.0), 0.0015 + 2 * 0.010 * turn, 1e-9);
  // Depth before its colour is as far from it.
  EXPECT_NEAR(DelayedDepthSigmaOf(-0.010, &step, step_s).At(2.0), s.At(2.0), 1e-12);
  const DelayedDepthSigma assumed = DelayedDepthSigmaOf(0.010, nullptr, 0);
  EXPECT_NEAR(assumed.const_m, 0.010 * kAssumedHandheldSpeedMS, 1e-12);
  EXPECT_NEAR(assumed.per_m, 0.010 * kAssumedHandheldTurnRadS, 1e-12);
  EXPECT_FALSE(DelayedDepthSigmaOf(0.0, &step, step_s).any());
  EXPECT_TRUE(s.any());
}

// A camera moving at 0.5 m/s along x and turning 50 deg/s about y, posed
// every 0.1 s: the camera at a depth instant 10 ms after (or before) its
// colour instant is where that motion puts it, from the frames around it,
// at the ends from the nearest two.
TEST(DelayedDepth, TheDepthCameraIsInterpolatedBetweenTheFramesAroundIt) {
  const double turn = 50.0 * M_PI / 180;
  auto room_from_camera = [&](double t) {
    return Rigid3d(QuaternionFromRotationVector(Eigen::Vector3d(0, turn * t, 0)),
                   Eigen::Vector3d(0.5 * t, 0, 1));
  };
  const std::vector<double> times = {0.0, 0.1, 0.2};
  std::vector<Rigid3d> poses;
  for (double t : times) poses.push_back(room_from_camera(t));
  for (size_t k = 0; k < times.size(); ++k) {
    for (double delay : {0.010, -0.010}) {
      const std::optional<Rigid3d> m = ColourFromDepthCamera(times, poses, k, delay);
      ASSERT_TRUE(m.has_value()) << k << " " << delay;
      const Rigid3d expected = poses[k].Inverse() * room_from_camera(times[k] + delay);
      EXPECT_TRUE(m->IsApprox(expected, 1e-4, 1e-6)) << k << " " << delay;
      EXPECT_GT(m->translation.norm(), 0.004);  // it moved
    }
  }
  EXPECT_FALSE(ColourFromDepthCamera(times, poses, 1, 0.0).has_value());
  EXPECT_FALSE(ColourFromDepthCamera({0.0, 1.0}, {poses[0], poses[1]}, 0, 0.01)
                   .has_value());  // too far apart
  EXPECT_FALSE(ColourFromDepthCamera({0.0}, {poses[0]}, 0, 0.01).has_value());
}

}  // namespace
}  // namespace arpos
