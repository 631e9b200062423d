#pragma once

// A marker too small for its edge lines, located by its whole known pattern.
//
// The edge-line refinement (edge_refinement.h) needs a few pixels of black
// border and of white quiet zone across each edge; below ~2.5 px a cell
// (a 6x6 sticker under 20 px) it cannot fit them. Where the caller knows
// which marker it is and roughly where (a sticker of a tracked patient),
// every cell of the marker still carries its boundaries: the pattern as
// drawn (cv::aruco::drawMarker), blurred, is fitted to the image through a
// homography of its four corners, with the black, white and surrounding
// levels free, coarse (much blur) to fine (the image's own blur).

#include <Eigen/Core>
#include <array>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "features/camera_response.h"

namespace arpos {

struct MarkerTemplateOptions {
  /// Width of the white quiet zone around the black square, in cells (the
  /// print's guaranteed margin); beyond it the surroundings' own level.
  double quiet_zone_cells = 1.0;
  /// The camera's response: codes are read through it as linear values
  /// (a camera's own sharpening is not undone: on the exact renders of
  /// marker_template_test, unsharp masking of 0.5 and 1.0 gave 0.15 and
  /// 0.14 px RMS against 0.16 without).
  CameraResponse response;
  /// How far beyond the quiet zone the fit reads the surroundings (cells):
  /// none (their level still enters through the blur). Measured on exact
  /// renders over a textured background (marker_template_test): 0.14 px
  /// RMS with none, 0.19 with 0.3 cells, 0.26 with 0.75 (the surroundings'
  /// texture, which one level cannot follow, pulls the outer edge).
  double surround_cells = 0;
  /// Blur schedule (px, 1 sigma beyond the pixel's footprint): the first
  /// fit at `coarse_blur_px` (a wide basin), then the image's blur, found
  /// among `blur_candidates_px` at the converged corners.
  double coarse_blur_px = 1.6;
  std::vector<double> blur_candidates_px{0.35, 0.5, 0.7, 0.9, 1.2, 1.6};
  /// Before the fits, the pattern is correlated with the image over shifts
  /// of up to this (px; 0: none), blurred this much (px), and the fits start
  /// from the best.
  double search_radius_px = 0;
  double search_blur_px = 0.8;
  int max_iterations = 12;
  /// Residuals beyond this many robust sigmas weigh less (Huber).
  double huber_sigmas = 2.0;
  /// A fit whose corners moved further than this fraction of the side
  /// (beyond the search radius) from the start has found something else.
  double max_shift_fraction = 0.5;
  /// The corners' stated sigma at least this (px): the template's own
  /// approximations (a Gaussian for the pixel's square, one blur in the
  /// marker's cells across a tilted marker).
  double min_corner_sigma_px = 0.08;
  /// Converged when no corner moved further in an iteration (px).
  double convergence_px = 0.005;
  /// Markers whose mean side is outside [min, max] px are not fitted.
  double min_side_px = 6;
  double max_side_px = 60;
  /// Acceptance: white minus black (linear grey levels) at least this, and
  /// this many times the residual noise; the pattern must explain the
  /// pixels this many times better (sum of squares) than the same marker
  /// turned by a quarter, a half or three quarters in the same place (a
  /// blob, a dark square or another marker does not).
  double min_contrast_grey = 6.0;
  double min_contrast_to_noise = 5.0;
  double min_pattern_gain = 1.5;
};

struct MarkerTemplateResult {
  bool ok = false;
  std::array<Eigen::Vector2d, 4> corners_px{};  ///< ArUco order, image px (pixel centres integer)
  std::array<double, 4> corner_sigma_px{{0, 0, 0, 0}};
  double contrast_grey = 0;     ///< white minus black, linear grey levels
  double noise_sigma_grey = 0;  ///< residual RMS
  double blur_sigma_px = 0;
  double pattern_gain = 0;  ///< the best turned pattern's sum of squares / the pattern's
  int pixels = 0;
  int iterations = 0;
  std::string failure;  ///< why, when not ok
};

/// Blurred patterns kept between fits (the same sticker at many starts, the
/// same blur frame after frame). Not thread-safe: one per thread.
class MarkerTemplateCache {
 public:
  MarkerTemplateCache();
  ~MarkerTemplateCache();
  MarkerTemplateCache(const MarkerTemplateCache&) = delete;
  MarkerTemplateCache& operator=(const MarkerTemplateCache&) = delete;
  struct Impl;
  Impl& impl() { return *impl_; }

 private:
  std::unique_ptr<Impl> impl_;
};

/// Fits the marker whose cells `cells` holds (CV_8UC1, one pixel per cell,
/// black border included, 0 black, as cv::aruco::drawMarker draws it) to
/// `gray` (CV_8UC1) from `initial_px` (ArUco order). Never throws on data:
/// a marker that does not fit comes back with ok false and the reason.
MarkerTemplateResult FitMarkerTemplate(const cv::Mat& gray, const cv::Mat& cells,
                                       const std::array<Eigen::Vector2d, 4>& initial_px,
                                       const MarkerTemplateOptions& options = {},
                                       MarkerTemplateCache* cache = nullptr);

}  // namespace arpos
