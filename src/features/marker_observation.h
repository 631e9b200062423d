#pragma once
/// One ArUco marker seen in one image: id and sub-pixel corners.
///
/// Pixel convention (OpenCV, the same as sensor/intrinsics.h): the centre of the
/// top-left pixel is (0, 0), so pixel (i, j) covers [i-0.5, i+0.5] x [j-0.5, j+0.5].
/// Corners are in OpenCV ArUco order: top-left, top-right, bottom-right,
/// bottom-left of the black square as seen printed (clockwise in the image).
/// In the marker frame (origin at the centre, x right, y up, z out of the
/// printed face) corner k of a marker of side s is
///   0: (-s/2, +s/2, 0)  1: (+s/2, +s/2, 0)  2: (+s/2, -s/2, 0)  3: (-s/2, -s/2, 0).
/// Corners are in the coordinates of the image that was given (distorted pixels
/// if the camera has lens distortion), so they feed cv::solvePnP with the
/// camera's distortion coefficients unchanged.

#include <Eigen/Core>
#include <array>

namespace arpos {

/// How far the corners of an observation can be trusted.
enum class MarkerStatus {
  /// All four edges fit straight lines over their whole length: the corners are
  /// the intersections of those lines (sub-pixel, unbiased). Use for mapping.
  kRefined = 0,
  /// Some segments of some edge did not fit the edge's line (occlusion, a
  /// shadow, a glare spot, the image border): the corners come from the
  /// consistent segments only. Good enough to track, not to build maps from.
  kPartiallyOccluded = 1,
  /// An edge could not be fitted at all (too little contrast or pixels, no
  /// convergence, a corner moved implausibly far): the corners are OpenCV's
  /// unrefined ones, biased by ~0.5-0.7 px inward. Do not use for poses.
  kRefinementFailed = 2,
  /// Refinement was not asked for (an OpenCV refinement method was selected).
  kNotRefined = 3,
};

const char* MarkerStatusName(MarkerStatus status);

/// Inclusive id range, e.g. the room markers [0, 49] of case.yaml.
struct IdRange {
  int min_id = 0;
  int max_id = 0;
  bool Contains(int id) const { return id >= min_id && id <= max_id; }
};

struct MarkerObservation {
  int id = -1;
  /// Refined corners (see the file comment for order and pixel convention).
  std::array<Eigen::Vector2d, 4> corners_px{};
  /// The corners as cv::aruco::detectMarkers returned them, before our refinement.
  std::array<Eigen::Vector2d, 4> detected_corners_px{};
  MarkerStatus status = MarkerStatus::kNotRefined;

  /// RMS, over the consistent segments of all four edges, of each segment's
  /// offset from its edge's fitted line (px). Noise-dominated: ~0.01-0.05 px
  /// for a clean marker; a bent or occluded edge shows as > 0.2 px.
  double edge_fit_rms_px = 0;
  /// Largest |offset| of any segment from its line, inliers and outliers (px).
  double max_segment_offset_px = 0;
  /// Fraction of edge segments (over the four edges) consistent with the lines.
  double edge_inlier_fraction = 0;
  /// 1-sigma uncertainty of each corner per image axis (px), propagated from
  /// the line fits' covariance with the measured image noise. For weighting in
  /// bundle adjustment; it does not include model errors (gamma, defocus shape).
  std::array<double, 4> corner_sigma_px{{0, 0, 0, 0}};
  double contrast_grey = 0;  ///< white border minus black square, grey levels
  double blur_sigma_px =
      0;  ///< fitted optical blur (Gaussian sigma, px, beyond the pixel footprint)
  double noise_sigma_grey = 0;  ///< robust image noise estimate along the edges
  int perimeter_px = 0;         ///< perimeter of the corner quadrilateral, rounded

  /// Corners good enough for sub-pixel work (maps, calibration, precise poses).
  bool IsPrecise() const { return status == MarkerStatus::kRefined; }
  /// Side length in pixels, averaged over the four sides.
  double MeanSidePx() const;
};

}  // namespace arpos
