#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <opencv2/core.hpp>

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

// A frame's depth readings share one unknown motion of the camera: however
// many they are, they place the colour camera no better than that motion is
// known (their information tends to the motion's inverse covariance), where
// few readings say little the motion changes nothing, and with the motion
// marginalised the readings' own estimate keeps its place (shifted by the
// motion's mean). The motion itself is measured as far as the readings see
// it: where they see nothing, as it was assumed.
TEST(DelayedDepth, OneMotionSharedByEveryReadingIsMarginalisedOut) {
  using Mat6 = Eigen::Matrix<double, 6, 6>;
  using Vec6 = Eigen::Matrix<double, 6, 1>;
  DelayedDepthSigma motion;
  motion.const_m = 0.0015;  // 0.15 m/s over 10 ms
  motion.per_m = 0.002;     // 0.11 deg
  const Mat6 C = motion.Covariance();
  EXPECT_NEAR(C(0, 0), 0.002 * 0.002, 1e-15);
  EXPECT_NEAR(C(5, 5), 0.0015 * 0.0015, 1e-15);
  EXPECT_NEAR(C(0, 5), 0.0, 1e-15);
  // A well-conditioned block (a depth of many readings), its estimate z_hat.
  Eigen::Matrix<double, 6, 6> A;
  A << 4, 1, 0, 0, 1, 0,  //
      1, 5, 1, 0, 0, 1,   //
      0, 1, 6, 1, 0, 0,   //
      0, 0, 1, 3, 1, 0,   //
      1, 0, 0, 1, 4, 1,   //
      0, 1, 0, 0, 1, 5;
  const Vec6 z_hat = (Vec6() << 0.001, -0.002, 0.0005, 0.003, -0.001, 0.002).finished();
  for (double readings : {1.0, 1e4, 1e9}) {
    const Mat6 H0 = readings * 1e3 * A;
    const Vec6 g0 = -H0 * z_hat;  // the gradient at 0 of a quadratic whose minimum is z_hat
    Mat6 H = H0;
    Vec6 g = g0;
    MarginaliseSharedMotion(C, &H, &g);
    // (H0^-1 + C)^-1: the sum of the two covariances.
    const Mat6 expected = (H0.inverse() + C).inverse();
    EXPECT_LT((H - expected).norm(), 1e-6 * expected.norm()) << readings;
    EXPECT_LT((H - H.transpose()).norm(), 1e-9 * H.norm());
    // The minimum stays where the readings put it.
    const Vec6 y = -H.ldlt().solve(g);
    EXPECT_LT((y - z_hat).norm(), 1e-9) << readings;
    // With a known mean motion m, the colour camera is at z_hat - m.
    const Vec6 m = (Vec6() << 0.0002, 0, 0, 0.001, 0, 0).finished();
    Mat6 Hm = H0;
    Vec6 gm = g0;
    MarginaliseSharedMotion(C, &Hm, &gm, m);
    EXPECT_LT((-Hm.ldlt().solve(gm) - (z_hat - m)).norm(), 1e-9) << readings;
  }
  // Many readings: the information is at most the motion's.
  {
    Mat6 H = 1e12 * A;
    Vec6 g = Vec6::Zero();
    MarginaliseSharedMotion(C, &H, &g);
    const Mat6 cov = H.inverse();
    EXPECT_NEAR(cov(5, 5), C(5, 5), 0.01 * C(5, 5));
    EXPECT_NEAR(cov(0, 0), C(0, 0), 0.01 * C(0, 0));
  }
  // No delay: nothing changes.
  {
    Mat6 H = A;
    Vec6 g = Vec6::Ones();
    MarginaliseSharedMotion(Mat6::Zero(), &H, &g);
    EXPECT_EQ(H, A);
    EXPECT_EQ(g, Vec6::Ones());
  }
  // The motion measured: precise readings find it (the depth camera at
  // exp(z_hat) * colour camera); none leave it as assumed.
  {
    const Mat6 H0 = 1e12 * A;
    const DepthCameraMotion measured = MeasuredSharedMotion(C, H0, -H0 * z_hat, Vec6::Zero());
    EXPECT_LT((measured.mean - z_hat).norm(), 1e-6);
    EXPECT_LT(measured.covariance.norm(), 1e-3 * C.norm());
    const DepthCameraMotion blind = MeasuredSharedMotion(C, Mat6::Zero(), Vec6::Zero(), z_hat);
    EXPECT_LT((blind.mean - z_hat).norm(), 1e-15);
    EXPECT_LT((blind.covariance - C).norm(), 1e-15);
  }
}

// A sloped floor and a box on it, read by a depth camera turned 0.5 deg and
// moved 3 mm from the colour camera (a room walk's turn over 10 ms): read
// as of the colour camera, each pixel's depth is the colour camera's own to
// within what a pixel's step on the slope makes it; taken as read, the
// turn alone puts the floor's depth off by centimetres.
TEST(DelayedDepth, ADepthImageIsReadAsOfItsColourInstant) {
  const int w = 640, h = 480;
  const double f = 540, cx = 319.5, cy = 239.5, scale = 1000;
  const Rigid3d colour_from_depth = Rigid3d::FromRotationVector(
      Eigen::Vector3d(0.0087, 0.002, -0.001), Eigen::Vector3d(0.003, -0.001, 0.002));
  // The scene in the colour camera: a floor plane n.x = d seen obliquely,
  // and a box face nearer in the middle.
  const Eigen::Vector3d n = Eigen::Vector3d(0, -0.8, -0.6).normalized();
  const double d = -1.6;
  auto depth_of = [&](const Rigid3d& camera_from_colour, int u, int v) {
    // Along the ray of (u, v) of a camera at camera_from_colour: the nearer
    // of the box face (z = 1.2 in the colour camera, |x| < 0.2, |y| < 0.15)
    // and the floor.
    const Rigid3d colour_from_camera = camera_from_colour.Inverse();
    const Eigen::Vector3d o = colour_from_camera.translation;
    const Eigen::Vector3d r =
        colour_from_camera.rotation * Eigen::Vector3d((u - cx) / f, (v - cy) / f, 1);
    double best = 1e9;
    const double t_box = (1.2 - o.z()) / r.z();
    const Eigen::Vector3d at_box = o + t_box * r;
    if (t_box > 0 && std::abs(at_box.x()) < 0.2 && std::abs(at_box.y()) < 0.15) best = t_box;
    const double t_floor = (d - n.dot(o)) / n.dot(r);
    if (t_floor > 0) best = std::min(best, t_floor);
    return best < 1e8 ? best : 0.0;  // z along a ray whose z component is 1 (in that camera)
  };
  cv::Mat colour_truth(h, w, CV_16UC1), read(h, w, CV_16UC1);
  const Rigid3d depth_from_colour = colour_from_depth.Inverse();
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      colour_truth.at<uint16_t>(v, u) =
          static_cast<uint16_t>(std::lround(scale * depth_of(Rigid3d::Identity(), u, v)));
      // The depth camera's ray has z 1 in its own axes: its depth is t.
      read.at<uint16_t>(v, u) =
          static_cast<uint16_t>(std::lround(scale * depth_of(depth_from_colour, u, v)));
    }
  }
  const cv::Mat moved = DepthAtColourInstant(read, scale, f, f, cx, cy, colour_from_depth);
  int valid = 0, close = 0, compared = 0;
  double error_moved = 0, error_as_read = 0;
  for (int v = 2; v < h - 2; ++v) {
    for (int u = 2; u < w - 2; ++u) {
      const double truth = colour_truth.at<uint16_t>(v, u) / scale;
      if (!(truth > 0) || read.at<uint16_t>(v, u) == 0) continue;
      ++compared;
      error_as_read += std::abs(read.at<uint16_t>(v, u) / scale - truth);
      if (moved.at<uint16_t>(v, u) == 0) continue;
      ++valid;
      const double e = std::abs(moved.at<uint16_t>(v, u) / scale - truth);
      error_moved += e;
      close += e < 3 * truth / f;  // about two pixels' step on the slope
    }
  }
  ASSERT_GT(compared, 200000);
  error_as_read /= compared;
  error_moved /= valid;
  EXPECT_GT(valid, 0.97 * compared);
  EXPECT_GT(close, 0.97 * valid) << close << " of " << valid;
  EXPECT_GT(error_as_read, 0.01) << "the turn should move the floor's depth by centimetres";
  EXPECT_LT(error_moved, 0.1 * error_as_read)
      << 1000 * error_moved << " mm against " << 1000 * error_as_read;
  // No motion: the image as it was.
  const cv::Mat same = DepthAtColourInstant(read, scale, f, f, cx, cy, Rigid3d::Identity());
  EXPECT_EQ(cv::countNonZero(same != read), 0);
}

}  // namespace
}  // namespace arpos
