#pragma once
/// Depth taken at another instant than its colour image: a camera without
/// colour-depth sync (RgbdFrame::depth_delay_s, from depth.txt's own
/// timestamps). Between the two instants a hand-held camera moves, so the
/// depth image is of a camera a little elsewhere than the colour image's:
/// its translation over the delay, and its turn over the delay (moving a
/// point at depth z by |omega| |delay| z). That motion is one unknown shared
/// by every reading of the frame: the localiser and the body tracker solve
/// for the colour camera with the frame's depth taken at a camera moved by
/// an unknown motion of that size, marginalised out
/// (MarginaliseSharedMotion), so the frame's depth places the colour camera
/// no better than the motion is known; each reading's gates and robust
/// weights allow for the motion too (its sigma plus DelayedDepthSigma::At).
/// Added to each reading's sigma alone (independent per reading), the
/// frame's depth stayed as sure as hundreds of readings make it: 1.53 mm
/// MTE on simulated xtion tracking (seed 41, depth 10 ms late) against 0.57
/// mm with depth of the colour's instant. Not moved back by a known amount:
/// the camera's motion over 10 ms is not known well enough from the frames
/// before it (the depth image warped to the colour instant at the velocity
/// of the last two placed frames tracked at 2.27-2.37 mm against 1.69 mm as
/// it was; the velocity from two poses 67 ms apart was off by as much as
/// the motion).

#include <Eigen/Core>
#include <cstddef>
#include <opencv2/core.hpp>
#include <optional>
#include <vector>

#include "geometry/rigid3.h"

namespace arpos {

/// A hand-held camera's motion when nothing says more (no earlier poses):
/// 0.2 m/s and 0.35 rad/s (20 deg/s), at the faster end of a positioning
/// walk (the simulated tracking walks: median 0.15 m/s, 12 deg/s).
constexpr double kAssumedHandheldSpeedMS = 0.2;
constexpr double kAssumedHandheldTurnRadS = 0.35;

/// The camera's motion over a delay, as 1-sigma sizes: its translation and
/// its turn (which moves a point at depth z by per_m * z).
struct DelayedDepthSigma {
  double const_m = 0;  ///< |delay| * speed (m)
  double per_m = 0;    ///< |delay| * turn rate (rad)
  double At(double z_m) const { return const_m + per_m * z_m; }
  bool any() const { return const_m > 0 || per_m > 0; }
  /// The motion's covariance on a left perturbation [rotation (rad);
  /// translation (m)] of a camera_from_X pose, isotropic (the direction of
  /// the motion is not known).
  Eigen::Matrix<double, 6, 6> Covariance() const;
};

/// The normal equations of a frame's depth readings (`H`, `g` on the left
/// perturbation [rotation; translation] of camera_from_X, at the camera of
/// the colour image), their depth camera moved from the colour camera by a
/// zero-mean unknown motion of `covariance`, that motion marginalised out:
/// H <- (I + H C)^-1 H, g <- (I + H C)^-1 g. H keeps at most C^-1: however
/// many readings, the frame's depth places the colour camera no better than
/// the motion is known. C = 0 leaves both as they are.
void MarginaliseSharedMotion(
    const Eigen::Matrix<double, 6, 6>& covariance, Eigen::Matrix<double, 6, 6>* H,
    Eigen::Matrix<double, 6, 1>* g,
    const Eigen::Matrix<double, 6, 1>& mean = Eigen::Matrix<double, 6, 1>::Zero());

/// The camera's motion from a colour image's instant to its depth image's,
/// as a frame's depth measured it against what else places the camera:
/// camera_at_depth_from_X = exp(mean) * camera_at_colour_from_X (the left
/// perturbation [rotation (rad); translation (m)]), with its covariance.
struct DepthCameraMotion {
  Eigen::Matrix<double, 6, 1> mean = Eigen::Matrix<double, 6, 1>::Zero();
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();
};

/// That motion measured: the depth readings' normal equations `H`, `g` (at
/// the colour camera, as for MarginaliseSharedMotion) against the motion's
/// prior N(`mean`, `covariance`): (I + C H)^-1 (mean - C g), covariance
/// (I + C H)^-1 C (no inverse of C, which may be singular).
DepthCameraMotion MeasuredSharedMotion(const Eigen::Matrix<double, 6, 6>& covariance,
                                       const Eigen::Matrix<double, 6, 6>& H,
                                       const Eigen::Matrix<double, 6, 1>& g,
                                       const Eigen::Matrix<double, 6, 1>& mean);

/// For a depth delay of `delay_s`, the camera (relative to what it looks at)
/// having moved by `step` (b_from_a, either direction) over `step_s` seconds;
/// without a step (nullptr, or step_s <= 0) the assumed hand-held motion.
/// Zero for no delay.
DelayedDepthSigma DelayedDepthSigmaOf(double delay_s, const Rigid3d* step, double step_s);

/// Where a recording is processed as a whole (the body scan), the camera's
/// motion over the delay is known from both sides: frame k's
/// colour_from_depth_camera (points of the camera at its depth instant into
/// the camera at its colour instant), the camera at the depth instant
/// interpolated at constant velocity between the two posed frames around it
/// (`room_from_camera` at `times_s`, in time order; beyond the last or before
/// the first, from the nearest two). nullopt when those two are more than
/// `max_gap_s` apart, or with no delay.
constexpr double kMaxInterpolationGapS = 0.5;
std::optional<Rigid3d> ColourFromDepthCamera(const std::vector<double>& times_s,
                                             const std::vector<Rigid3d>& room_from_camera, size_t k,
                                             double delay_s,
                                             double max_gap_s = kMaxInterpolationGapS);

/// A recording whose frames are placed before its depth is used (the plan:
/// from its markers and keypoints): a depth image (CV_16UC1, `depth_scale`
/// units per metre) of a camera at `colour_from_depth` from its colour
/// camera, as the colour camera
/// would have read it. Each pixel's reading is taken where the depth camera
/// saw that pixel's point (two fixed-point steps from the pixel's own
/// reading, nearest pixel) and given as its z in the colour camera; 0 where
/// the depth camera read nothing there. Pinhole rays: the shift is a few
/// pixels, which the lens changes by a fraction of one.
cv::Mat DepthAtColourInstant(const cv::Mat& depth, double depth_scale, double fx, double fy,
                             double cx, double cy, const Rigid3d& colour_from_depth);

}  // namespace arpos
