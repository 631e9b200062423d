#pragma once
/// Synthetic marker images with exactly known corners, for the features tests
/// and benchmark (independent of src/simulation on purpose).
///
/// Rendering is exact area coverage: every cell of the marker (drawn by
/// cv::aruco::drawMarker) and its white quiet zone is projected through the
/// camera as a quadrilateral and clipped against each pixel's square
/// [i-0.5, i+0.5] x [j-0.5, j+0.5] (OpenCV pixel convention), so a pixel's
/// value is the true area-weighted mean of the scene over that pixel. With
/// lens distortion the edges are curved, and pixels are instead supersampled
/// (`distorted_supersampling`^2 samples, undistorted by cv::undistortPoints).
/// Then Gaussian blur (in linear radiance), the camera's gamma, Gaussian noise
/// and rounding to 8 bits.

#include <Eigen/Core>
#include <array>
#include <functional>
#include <random>
#include <vector>

#include <opencv2/core.hpp>

#include "features/camera_response.h"
#include "geometry/rigid3.h"
#include "sensor/intrinsics.h"

namespace arpos::testing {

struct MarkerPlacement {
  int id = 0;
  double size_m = 0.03;  ///< black square side
  Rigid3d camera_from_marker;
  double black_grey = 30;
  double white_grey = 215;
};

struct MarkerTruth {
  int id = 0;
  std::array<Eigen::Vector2d, 4> corners_px{};          ///< exact projections (with distortion)
  Eigen::Vector2d centre_px = Eigen::Vector2d::Zero();  ///< projection of the marker origin
  Rigid3d camera_from_marker;
  double size_m = 0;
  double side_px = 0;  ///< mean projected side
};

struct RenderOptions {
  std::string dictionary = "DICT_4X4_250";
  double quiet_zone_cells = 1.0;  ///< white margin around the black square
  double noise_sigma_grey = 2.0;
  double blur_sigma_px = 0.7;  ///< applied after pixel integration
  bool textured_background = true;
  double background_grey = 120;  ///< when not textured
  int distorted_supersampling = 8;
  /// Camera response: the scene (grey levels above, as they appear in the
  /// image) is composed and blurred in linear radiance, then encoded with
  /// this gamma (1 = linear camera; ~2.2 for sRGB-like colour cameras).
  double gamma = 1.0;
  /// Any other tone curve: linear fraction (0..1) -> encoded fraction (0..1),
  /// monotone increasing; overrides `gamma` when set.
  std::function<double(double)> encode;
  /// A camera's own processing after encoding, as consumer cameras do it:
  /// unsharp masking of the encoded codes (code + amount * (code - blurred
  /// code), Gaussian of `sharpen_sigma_px`; 0 = none), then JPEG at
  /// `jpeg_quality` (0 = none).
  double sharpen_amount = 0;
  double sharpen_sigma_px = 1.0;
  int jpeg_quality = 0;
};

/// The camera response (code -> linear table) of a monotone encoding
/// (linear fraction -> encoded fraction), by inverting it.
CameraResponse ResponseOfEncoding(const std::function<double(double)>& encode);

/// Renders `markers` into a CV_8UC1 image of the camera's size. `truth` gets
/// one entry per marker. Markers must not overlap (not checked).
cv::Mat RenderMarkers(const CameraIntrinsics& camera, const std::vector<MarkerPlacement>& markers,
                      const RenderOptions& options, std::mt19937* rng,
                      std::vector<MarkerTruth>* truth);

/// A marker whose normal makes `tilt_deg` with the line of sight (tilted about
/// a random axis in its plane, then rotated by a random in-plane angle), with
/// its centre projecting to `centre_px` at the distance where its side spans
/// `side_px` pixels when seen face-on.
Rigid3d MarkerPoseForView(const CameraIntrinsics& camera, const Eigen::Vector2d& centre_px,
                          double side_px, double size_m, double tilt_deg, std::mt19937* rng);

/// `count` non-overlapping markers (ids first_id, first_id+1, ...), sides
/// uniform in [min_side_px, max_side_px], tilts uniform in [0, max_tilt_deg].
/// May return fewer if the image is too crowded.
std::vector<MarkerPlacement> RandomPlacements(const CameraIntrinsics& camera, int count,
                                              double min_side_px, double max_side_px,
                                              double max_tilt_deg, double size_m, int first_id,
                                              std::mt19937* rng);

/// Depth image (CV_16UC1, camera.depth_scale units per metre) of the plane of
/// `camera_from_plane` (its z = 0 plane) filling the view, with Gaussian noise.
cv::Mat RenderPlaneDepth(const CameraIntrinsics& camera, const Rigid3d& camera_from_plane,
                         double noise_sigma_m, std::mt19937* rng);

/// Exact projection (with the camera's distortion) of a camera-frame point.
Eigen::Vector2d ProjectWithDistortion(const CameraIntrinsics& camera, const Eigen::Vector3d& p);

/// A 640x480 or 1280x720 camera with f = 525 (resp. 910) px and no distortion.
CameraIntrinsics VgaCamera();
CameraIntrinsics HdCamera();

}  // namespace arpos::testing
