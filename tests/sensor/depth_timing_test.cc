#include <gtest/gtest.h>

#include <cmath>

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

}  // namespace
}  // namespace arpos
