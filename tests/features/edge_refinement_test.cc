// Sub-pixel corner refinement on synthetic renders with exactly known corners
// (tests/features/marker_render.h: exact area coverage, blur, noise).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include <opencv2/imgproc.hpp>

#include "features/corner_study.h"
#include "features/edge_refinement.h"
#include "features/marker_detector.h"
#include "features/marker_render.h"
#include "util/check.h"

namespace arpos::testing {
namespace {

/// One marker at the image centre of a VGA camera.
struct SingleMarker {
  cv::Mat image;
  MarkerTruth truth;
};

SingleMarker RenderOne(double side_px, double tilt_deg, unsigned seed,
                       const RenderOptions& render = RenderOptions(),
                       const Eigen::Vector2d& centre = Eigen::Vector2d(330.3, 228.7),
                       double black_grey = 30, double white_grey = 215) {
  std::mt19937 rng(seed);
  const CameraIntrinsics cam = VgaCamera();
  MarkerPlacement m;
  m.id = 7;
  m.black_grey = black_grey;
  m.white_grey = white_grey;
  m.camera_from_marker = MarkerPoseForView(cam, centre, side_px, 0.03, tilt_deg, &rng);
  std::vector<MarkerTruth> truth;
  SingleMarker out;
  out.image = RenderMarkers(cam, {m}, render, &rng, &truth);
  out.truth = truth[0];
  return out;
}

std::array<Eigen::Vector2d, 4> Perturbed(const std::array<Eigen::Vector2d, 4>& corners,
                                         double sigma_px, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0, sigma_px);
  std::array<Eigen::Vector2d, 4> out = corners;
  for (auto& c : out) c += Eigen::Vector2d(n(rng), n(rng));
  return out;
}

double MaxCornerError(const std::array<Eigen::Vector2d, 4>& a,
                      const std::array<Eigen::Vector2d, 4>& b) {
  double e = 0;
  for (int k = 0; k < 4; ++k) e = std::max(e, (a[k] - b[k]).norm());
  return e;
}

TEST(EdgeRefinement, RecoversCornersFromPerturbedStart) {
  for (unsigned seed = 1; seed <= 12; ++seed) {
    const double side = 20 + 5 * seed;
    const SingleMarker m = RenderOne(side, 5.0 * seed, seed);
    const auto start = Perturbed(m.truth.corners_px, 0.7, seed);
    const CornerRefinementResult r = RefineMarkerCorners(m.image, start);
    ASSERT_EQ(r.status, MarkerStatus::kRefined) << "side " << side << ": " << r.failure;
    EXPECT_LT(MaxCornerError(r.corners_px, m.truth.corners_px), 0.1) << "side " << side;
    EXPECT_GT(r.edge_inlier_fraction, 0.999);
    EXPECT_LT(r.edge_fit_rms_px, 0.1);
    EXPECT_NEAR(r.contrast_grey, 185, 40);  // white 215 - black 30, shading aside
    EXPECT_NEAR(r.noise_sigma_grey, 2.0, 1.2) << "side " << side;
  }
}

TEST(EdgeRefinement, FootprintModelMattersOnSharpAxisAlignedEdges) {
  // A sharp (unblurred), face-on, axis-aligned marker: each column crosses the
  // edge in one pixel at the same sub-pixel phase. The exact pixel-footprint
  // model gets it right; a plain erf is biased.
  RenderOptions render;
  render.blur_sigma_px = 0;
  render.noise_sigma_grey = 0.5;
  std::mt19937 rng(3);
  const CameraIntrinsics cam = VgaCamera();
  MarkerPlacement m;
  m.id = 3;
  Eigen::Matrix3d facing;
  facing << 1, 0, 0, 0, -1, 0, 0, 0, -1;
  m.camera_from_marker = Rigid3d(facing, cam.Unproject(320.3, 240.25, 0.4));
  std::vector<MarkerTruth> truth;
  const cv::Mat image = RenderMarkers(cam, {m}, render, &rng, &truth);
  const auto start = Perturbed(truth[0].corners_px, 0.5, 1);
  EdgeRefinementOptions options;
  const CornerRefinementResult exact = RefineMarkerCorners(image, start, options);
  options.model_pixel_footprint = false;
  const CornerRefinementResult erf = RefineMarkerCorners(image, start, options);
  ASSERT_EQ(exact.status, MarkerStatus::kRefined);
  const double exact_err = MaxCornerError(exact.corners_px, truth[0].corners_px);
  const double erf_err = MaxCornerError(erf.corners_px, truth[0].corners_px);
  std::printf(
      "sharp axis-aligned marker: max corner error %.4f px (footprint model), "
      "%.4f px (plain erf)\n",
      exact_err, erf_err);
  EXPECT_LT(exact_err, 0.02);
  EXPECT_GT(erf_err, 2 * exact_err);
}

TEST(EdgeRefinement, FlagsPartiallyOccludedEdge) {
  const SingleMarker m = RenderOne(48, 20, 5);
  // A grey occluder (a finger, a cable) across the middle third of edge 0,
  // reaching into the quiet zone and the border cell.
  cv::Mat image = m.image.clone();
  const Eigen::Vector2d a = m.truth.corners_px[0], b = m.truth.corners_px[1];
  const Eigen::Vector2d mid = 0.5 * (a + b), along = (b - a).normalized();
  const Eigen::Vector2d out = (mid - m.truth.centre_px).normalized();
  std::vector<cv::Point> poly;
  for (const Eigen::Vector2d& p :
       {Eigen::Vector2d(mid - 8 * along - 3 * out), Eigen::Vector2d(mid + 8 * along - 3 * out),
        Eigen::Vector2d(mid + 8 * along + 10 * out), Eigen::Vector2d(mid - 8 * along + 10 * out)}) {
    poly.emplace_back(static_cast<int>(std::lround(p.x())), static_cast<int>(std::lround(p.y())));
  }
  cv::fillConvexPoly(image, poly, cv::Scalar(110));
  const auto start = Perturbed(m.truth.corners_px, 0.5, 2);

  const CornerRefinementResult clean = RefineMarkerCorners(m.image, start);
  const CornerRefinementResult occluded = RefineMarkerCorners(image, start);
  ASSERT_EQ(clean.status, MarkerStatus::kRefined);
  EXPECT_EQ(occluded.status, MarkerStatus::kPartiallyOccluded) << occluded.failure;
  EXPECT_LT(occluded.edges[0].num_inlier_segments, occluded.edges[0].num_segments);
  EXPECT_EQ(occluded.edges[2].num_inlier_segments, occluded.edges[2].num_segments);
  EXPECT_GT(occluded.max_segment_offset_px, 0.3);
  // The consistent segments still give good corners.
  EXPECT_LT(MaxCornerError(occluded.corners_px, m.truth.corners_px), 0.15);

  // Most of an edge covered: no line to trust, corners are not refined.
  cv::Mat covered = m.image.clone();
  std::vector<cv::Point> big;
  for (const Eigen::Vector2d& p :
       {Eigen::Vector2d(a + 4 * along - 3 * out), Eigen::Vector2d(b - 4 * along - 3 * out),
        Eigen::Vector2d(b - 4 * along + 10 * out), Eigen::Vector2d(a + 4 * along + 10 * out)}) {
    big.emplace_back(static_cast<int>(std::lround(p.x())), static_cast<int>(std::lround(p.y())));
  }
  cv::fillConvexPoly(covered, big, cv::Scalar(110));
  const CornerRefinementResult failed = RefineMarkerCorners(covered, start);
  EXPECT_EQ(failed.status, MarkerStatus::kRefinementFailed);
  EXPECT_FALSE(failed.failure.empty());
  EXPECT_EQ(failed.corners_px[0], start[0]);  // the detection, not a guess
}

TEST(EdgeRefinement, HandlesLensDistortion) {
  CameraIntrinsics cam = VgaCamera();
  cam.distortion = {-0.25, 0.08, 0.0005, -0.0004, 0.0};
  const PixelUndistorter undistorter(cam);
  // Round trip of the distortion model, and agreement with the renderer's.
  for (const Eigen::Vector2d& p : {Eigen::Vector2d(10, 12), Eigen::Vector2d(600, 30),
                                   Eigen::Vector2d(320, 240), Eigen::Vector2d(630, 470)}) {
    EXPECT_LT((undistorter.Distort(undistorter.Undistort(p)) - p).norm(), 1e-6);
    const Eigen::Vector3d ray = cam.Unproject(p.x(), p.y(), 1.0);
    EXPECT_LT((undistorter.Distort(p) - ProjectWithDistortion(cam, ray)).norm(), 1e-9);
  }
  // A 70 px marker near the image corner, where the lines bend most.
  std::mt19937 rng(4);
  MarkerPlacement m;
  m.id = 11;
  m.camera_from_marker = MarkerPoseForView(cam, {120, 110}, 70, 0.03, 25, &rng);
  RenderOptions render;
  render.distorted_supersampling = 6;
  std::vector<MarkerTruth> truth;
  const cv::Mat image = RenderMarkers(cam, {m}, render, &rng, &truth);
  const auto start = Perturbed(truth[0].corners_px, 0.5, 3);
  EdgeRefinementWorkspace ws;
  const CornerRefinementResult with =
      RefineMarkerCorners(image, start, EdgeRefinementOptions(), undistorter, &ws);
  const CornerRefinementResult without =
      RefineMarkerCorners(image, start, EdgeRefinementOptions(), PixelUndistorter(), &ws);
  ASSERT_EQ(with.status, MarkerStatus::kRefined) << with.failure;
  const double err_with = MaxCornerError(with.corners_px, truth[0].corners_px);
  const double err_without = MaxCornerError(without.corners_px, truth[0].corners_px);
  std::printf(
      "distorted 70 px marker: max corner error %.3f px undistorting, %.3f px not "
      "(status %s, edge rms %.3f px)\n",
      err_with, err_without, MarkerStatusName(without.status), without.edge_fit_rms_px);
  EXPECT_LT(err_with, 0.06);
  EXPECT_GT(err_without, 2 * err_with);
}

TEST(EdgeRefinement, CornerSigmaMatchesActualScatter) {
  // The propagated 1-sigma must describe the real error (for BA weights).
  double sum_sq_err = 0, sum_sq_sigma = 0;
  int n = 0;
  for (unsigned seed = 1; seed <= 16; ++seed) {
    RenderOptions render;
    render.noise_sigma_grey = 6;
    const SingleMarker m = RenderOne(30, 30, 100 + seed, render);
    const CornerRefinementResult r =
        RefineMarkerCorners(m.image, Perturbed(m.truth.corners_px, 0.5, seed));
    ASSERT_EQ(r.status, MarkerStatus::kRefined);
    for (int k = 0; k < 4; ++k) {
      sum_sq_err += 0.5 * (r.corners_px[k] - m.truth.corners_px[k]).squaredNorm();
      sum_sq_sigma += r.corner_sigma_px[k] * r.corner_sigma_px[k];
      ++n;
    }
  }
  const double ratio = std::sqrt(sum_sq_err / sum_sq_sigma);
  std::printf(
      "noise 6 grey, 30 px: rms corner error / rms predicted sigma = %.2f (sigma %.3f px)\n", ratio,
      std::sqrt(sum_sq_sigma / n));
  EXPECT_GT(ratio, 0.5);
  EXPECT_LT(ratio, 2.0);
}

TEST(EdgeRefinement, GammaEncodedImagesNeedLinearising) {
  // A camera that gamma-encodes (sRGB-like) moves a blurred edge's 50 % point
  // towards the dark side: the marker shrinks unless values are linearised.
  RenderOptions render;
  render.gamma = 2.2;
  render.blur_sigma_px = 1.0;
  double bias_raw = 0, bias_linearised = 0;
  int n = 0;
  for (unsigned seed = 1; seed <= 6; ++seed) {
    const SingleMarker m = RenderOne(40, 30, 200 + seed, render);
    const auto start = Perturbed(m.truth.corners_px, 0.5, seed);
    EdgeRefinementOptions options;
    const CornerRefinementResult raw = RefineMarkerCorners(m.image, start, options);
    options.response = CameraResponse::Gamma(2.2);
    const CornerRefinementResult lin = RefineMarkerCorners(m.image, start, options);
    ASSERT_EQ(lin.status, MarkerStatus::kRefined);
    for (int k = 0; k < 4; ++k) {
      const double truth_r = (m.truth.corners_px[k] - m.truth.centre_px).norm();
      bias_raw += (raw.corners_px[k] - m.truth.centre_px).norm() / truth_r - 1;
      bias_linearised += (lin.corners_px[k] - m.truth.centre_px).norm() / truth_r - 1;
      ++n;
    }
  }
  bias_raw *= 100.0 / n;
  bias_linearised *= 100.0 / n;
  std::printf("gamma 2.2, blur 1 px, 40 px: scale bias %+.2f %% raw, %+.3f %% linearised\n",
              bias_raw, bias_linearised);
  EXPECT_LT(bias_raw, -1.0);
  EXPECT_LT(std::abs(bias_linearised), 0.15);
}

TEST(EdgeRefinement, ADimMarkerIsRefinedWhenItsEdgesStandAboveTheNoise) {
  // A dark scene (white 14, black 3 grey levels, noise 0.4): the edges stand
  // 25 times above the noise and are refined, their sigmas saying what
  // they are worth; a fixed 15-level floor refused such markers outright.
  RenderOptions dark;
  dark.textured_background = false;
  dark.background_grey = 9;
  dark.noise_sigma_grey = 0.4;
  RenderOptions bright;
  bright.noise_sigma_grey = 0.4;
  for (unsigned seed = 1; seed <= 4; ++seed) {
    const Eigen::Vector2d centre(330.3, 228.7);
    const SingleMarker m = RenderOne(32, 20, 300 + seed, dark, centre, 3, 14);
    const auto start = Perturbed(m.truth.corners_px, 0.5, seed);
    const CornerRefinementResult r = RefineMarkerCorners(m.image, start);
    ASSERT_EQ(r.status, MarkerStatus::kRefined) << r.failure;
    EXPECT_LT(r.contrast_grey, 15);
    EXPECT_LT(MaxCornerError(r.corners_px, m.truth.corners_px), 0.3);
    const CornerRefinementResult b =
        RefineMarkerCorners(RenderOne(32, 20, 300 + seed, bright).image, start);
    ASSERT_EQ(b.status, MarkerStatus::kRefined) << b.failure;
    EXPECT_GT(r.corner_sigma_px[0], 3 * b.corner_sigma_px[0]);
  }
  // Edges that do not stand ten times above the noise still fail.
  RenderOptions noisy = dark;
  noisy.noise_sigma_grey = 1.5;
  const SingleMarker m = RenderOne(32, 20, 310, noisy, Eigen::Vector2d(330.3, 228.7), 8, 14);
  const CornerRefinementResult r =
      RefineMarkerCorners(m.image, Perturbed(m.truth.corners_px, 0.5, 1));
  EXPECT_EQ(r.status, MarkerStatus::kRefinementFailed);
  EXPECT_NE(r.failure.find("too low"), std::string::npos) << r.failure;
}

TEST(EdgeRefinement, RejectsBadInput) {
  EdgeRefinementOptions options;
  EXPECT_TRUE(options.Check());
  options.band_half_width_px = 0.2;
  std::string reason;
  EXPECT_FALSE(options.Check(&reason));
  EXPECT_NE(reason.find("band_half_width_px"), std::string::npos);
  const cv::Mat color(100, 100, CV_8UC3, cv::Scalar(0, 0, 0));
  std::array<Eigen::Vector2d, 4> quad = {Eigen::Vector2d(30, 30), Eigen::Vector2d(70, 30),
                                         Eigen::Vector2d(70, 70), Eigen::Vector2d(30, 70)};
  EXPECT_THROW(RefineMarkerCorners(color, quad), Error);
  // A flat image: nothing to fit, the detection is returned with a reason.
  const cv::Mat flat(100, 100, CV_8UC1, cv::Scalar(128));
  const CornerRefinementResult r = RefineMarkerCorners(flat, quad);
  EXPECT_EQ(r.status, MarkerStatus::kRefinementFailed);
  EXPECT_EQ(r.corners_px[2], quad[2]);
}

}  // namespace
}  // namespace arpos::testing
