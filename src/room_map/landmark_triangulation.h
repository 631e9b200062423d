#pragma once
/// One keypoint landmark placed from its observations in cameras whose poses
/// are held fixed: reprojection and depth residuals, Gauss-Newton, outliers
/// dropped and the point solved again. Used for the room map's landmarks
/// placed after its adjustment (room_map_builder.cc) and for the landmarks a
/// body scan adds around the couch (scan_landmarks.h).
///
/// Frames: cameras as camera_from_room (OpenCV camera), the point in the room
/// frame. Metres; pixels of an undistorted (ideal) image.

#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <vector>

#include "geometry/rigid3.h"
#include "sensor/intrinsics.h"

namespace arpos {

/// The medoid of a landmark's ORB descriptors (least summed Hamming distance
/// to the others); null for none.
const std::uint8_t* MedoidDescriptor(const std::vector<const std::uint8_t*>& descriptors);

/// Pixels of the recorded (distorted) image as the ideal pinhole camera sees
/// them; unchanged without distortion.
std::vector<Eigen::Vector2d> IdealPixels(const std::vector<Eigen::Vector2d>& px,
                                         const CameraIntrinsics& K);

struct LandmarkObservation {
  int camera = -1;     ///< index into the camera poses
  Eigen::Vector2d px;  ///< ideal pixel
  double depth_m = 0;  ///< the depth reading at it (0: none)
};

struct LandmarkTriangulationOptions {
  double keypoint_sigma_px = 0.7;
  /// sigma(z) = depth_sigma_const_m + depth_sigma_quad_per_m * z^2
  double depth_sigma_const_m = 0.002;
  double depth_sigma_quad_per_m = 0.003;
  /// An observation whose reprojection (or depth) residual exceeds this many
  /// sigmas is dropped after a solve.
  double outlier_sigmas = 4.0;
  int min_observations = 3;
  double DepthSigmaM(double z_m) const {
    return depth_sigma_const_m + depth_sigma_quad_per_m * z_m * z_m;
  }
};

struct TriangulatedLandmark {
  Eigen::Vector3d point_in_room = Eigen::Vector3d::Zero();
  std::vector<bool> inlier;  ///< per observation
  int inliers = 0;
};

/// The point from its nearest observation with depth, refined (two passes of
/// at most five Gauss-Newton steps, outliers dropped between them). nullopt
/// when no observation has depth, the solve fails, the point falls behind a
/// camera that saw it, or fewer than min_observations remain inliers.
std::optional<TriangulatedLandmark> TriangulateLandmark(
    const std::vector<LandmarkObservation>& observations,
    const std::vector<Rigid3d>& camera_from_room, const CameraIntrinsics& K,
    const LandmarkTriangulationOptions& options);

}  // namespace arpos
