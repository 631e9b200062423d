#pragma once
/// Sub-pixel marker corners from straight-line fits to the four outer edges.
///
/// Why: OpenCV 4.6's own refinements are biased on small markers (PITFALLS.md:
/// NONE/CONTOUR ~0.7 px inward, SUBPIX's window too large, APRILTAG shifted by
/// half a pixel), and a 1 % scale error in a 30 px marker is centimetres of
/// depth. The outer edge of the black square against the white quiet zone is a
/// long straight step; its position can be measured far more precisely than any
/// corner.
///
/// Method (all in the undistorted pixel coordinates of `undistorter`):
///  1. From the current quadrilateral, a homography marker-square -> image gives
///     each edge's band: pixels within `band_half_width_px` of the edge line,
///     at least `inner_guard_px` outside the inner side of the black border
///     cell (so no code bit is sampled), at least as far inside the outer limit
///     of the quiet zone, and at least `corner_guard_px` inside both adjacent
///     edges (so no corner is sampled).
///  2. The grey values of all four bands are fitted together, by robust
///     (Huber) Levenberg-Marquardt, with a blurred step evaluated at the pixel
///     centres:
///        I(p) = black(p) + (white(p) - black(p)) * S(d_k(p); sigma_k)
///     where d_k is the signed distance to edge k's line (theta_k, rho_k;
///     positive towards the white quiet zone), black/white are planar
///     illumination fields shared by the whole marker (so a thin band on a
///     tiny marker still knows its levels), and S is the unit step convolved
///     with a Gaussian (sigma_k, per edge: motion blur is directional) and
///     with the pixel's square footprint seen along the edge normal. S is
///     symmetric about the line, as is any lens blur and the pixels' area
///     integration, so the 50 % point is the edge itself: no half-pixel
///     convention offset and no inward bias. Pixel values are used at their
///     true centres, without interpolation. 18 parameters; weak priors keep
///     ill-determined ones near marker-wide values.
///  3. Each edge is cut into segments of ~`segment_length_px`; each segment's
///     own offset from its line (and contrast) is estimated. Segments off the
///     line (occlusion, glare, the image border) are excluded and the model
///     refitted; their RMS offset is the quality figure edge_fit_rms_px.
/// Adjacent lines are intersected into corners; the whole is repeated (at most
/// `outer_iterations` times) with bands re-centred on the refined lines.
///
/// Lens distortion: straight marker edges are straight only in undistorted
/// coordinates. With a distorting camera every band pixel is mapped to ideal
/// (undistorted) pixel coordinates before fitting, and the intersected corners
/// are distorted back, so inputs and outputs stay in the given image's pixels.
/// (Our cases have zero distortion; the mapping then is the identity and free.)
///
/// Camera response: the model is linear in scene radiance. A tone-curved
/// image (sRGB-like, as most colour cameras deliver) moves the apparent 50 %
/// point of a blurred edge towards one side, i.e. scales the marker by a
/// fraction of the blur: ~0.6-0.8 px at 1 px blur for a 2.2 gamma, a 2-3 %
/// scale error (features_bench --report). `response` linearises the codes
/// first; it is estimated per recording from the markers' cell widths
/// (camera_response.h). Fitting it from the edges' asymmetry was tried, per
/// marker and pooled over a recording: the profile's shape leaves it too
/// poorly determined.
///
/// Not modelled: printer ink spread (prints the black square slightly large or
/// small: calibrate the printed size instead) and non-planar (curved) markers.

#include <Eigen/Core>
#include <array>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "features/camera_response.h"
#include "features/marker_observation.h"
#include "sensor/intrinsics.h"

namespace arpos {

struct EdgeRefinementOptions {
  /// Marker layout: data bits per side (4 for DICT_4X4_*) and black border bits.
  int marker_bits = 4;
  int border_bits = 1;
  /// Width of white quiet zone around the black square, in cells, that is
  /// guaranteed on the print. The band never samples beyond it.
  double quiet_zone_cells = 1.0;

  /// The camera's response (camera_response.h): codes are read through it
  /// as linear values before fitting. Default: linear (codes unchanged).
  CameraResponse response;

  /// Half-width of the band fitted across each edge (px).
  double band_half_width_px = 3.0;
  /// Long edges are subsampled to about this many band pixels (0 = all):
  /// beyond it precision is far below other errors and time grows linearly.
  int max_pixels_per_edge = 200;
  /// Distance kept from the inner side of the border cell and from the outer
  /// limit of the quiet zone (px): about 2 blur sigmas.
  double inner_guard_px = 1.25;
  /// On markers whose cells are narrower than 2 * inner_guard_px the guard
  /// shrinks to half a cell, but not below this (px).
  double min_inner_guard_px = 0.6;
  /// Distance kept from the adjacent edges, i.e. from the corners (px).
  double corner_guard_px = 1.5;
  /// OpenCV's contour corners lie on boundary pixel centres, ~0.5 px inside the
  /// square; the first band is centred this far outward of them (px).
  double initial_outward_shift_px = 0.5;

  int outer_iterations = 3;      ///< band re-centring passes (at most)
  double convergence_px = 0.01;  ///< stop when no corner moved further in a pass
  int max_fit_iterations = 10;   ///< Levenberg-Marquardt iterations per fit
  /// A fit has converged when no line moved further than this in a step (px).
  double fit_step_tolerance_px = 1e-3;
  /// Model the pixel's square footprint in the edge profile (exact for
  /// area-integrating pixels). Off: a plain blurred step (erf), which is
  /// biased by up to ~0.2 px on sharp, nearly axis-aligned edges.
  bool model_pixel_footprint = true;
  double segment_length_px = 4.0;  ///< length of the quality segments along an edge
  /// A segment is inconsistent if its offset from the line exceeds
  /// max(max_segment_offset_px, 5 sigma of that offset)...
  double max_segment_offset_px = 0.3;
  /// ...or its contrast differs from the edge's by more than this fraction.
  double max_segment_contrast_change = 0.35;
  /// Weaker edges fail: the contrast (white minus black, in the response's
  /// linear grey levels) must reach min_contrast_to_noise times the image
  /// noise the fit measured along the edges, and at least min_contrast_grey.
  /// What an edge's contrast is worth beyond that is in its corners' sigmas.
  /// (A fixed 15 grey levels refused every room marker of a dark, linearly
  /// encoded recording read as sRGB: 7-9 levels at a noise of 0.5, while
  /// OpenCV read them and their edges fitted.)
  double min_contrast_grey = 4.0;
  double min_contrast_to_noise = 10.0;
  /// Priors that keep ill-determined parameters of thin bands (tiny markers)
  /// near marker-wide values: black/white levels and their gradients around
  /// the bands' percentiles (grey levels, 1 sigma) and, after the first pass,
  /// each edge's blur around the marker's median (px, 1 sigma). Negligible on
  /// larger markers.
  double level_prior_sigma_grey = 15.0;
  double blur_prior_sigma_px = 0.3;
  int min_pixels_per_edge = 12;
  /// Plausibility: each fitted line must pass within this distance (px) of
  /// the detected edge at 1/4 and 3/4 of its length; a corner may move at most
  /// max(max_corner_shift_px, max_corner_shift_fraction * mean side) from its
  /// detection (acute corners of oblique markers legitimately move several px:
  /// OpenCV's polygon vertices are cut off there).
  double max_edge_shift_px = 2.0;
  double max_corner_shift_px = 3.0;
  double max_corner_shift_fraction = 0.25;

  /// Empty if valid, else a sentence naming the first bad field.
  std::string Validate() const;
  bool Check(std::string* reason = nullptr) const;
};

/// Maps image pixels to the undistorted ("ideal") pixel coordinates in which
/// marker edges are straight, and back. Identity for a camera without
/// distortion. Coordinates follow the OpenCV pixel convention. Thread-safe.
class PixelUndistorter {
 public:
  PixelUndistorter() = default;  ///< identity
  explicit PixelUndistorter(const CameraIntrinsics& intrinsics);
  bool IsIdentity() const { return identity_; }
  /// Distorted image pixel -> ideal pixel (iterative inversion, ~1e-6 px).
  Eigen::Vector2d Undistort(const Eigen::Vector2d& distorted_px) const;
  /// Ideal pixel -> distorted image pixel (the OpenCV model, closed form).
  Eigen::Vector2d Distort(const Eigen::Vector2d& ideal_px) const;

 private:
  bool identity_ = true;
  double fx_ = 1, fy_ = 1, cx_ = 0, cy_ = 0;
  double k1_ = 0, k2_ = 0, p1_ = 0, p2_ = 0, k3_ = 0;
};

/// Per-edge details of a refinement (edge k runs from corner k to corner k+1).
struct EdgeFit {
  bool ok = false;
  Eigen::Vector2d point_px = Eigen::Vector2d::Zero();  ///< a point on the line (ideal px)
  Eigen::Vector2d normal = Eigen::Vector2d::Zero();    ///< unit, towards the white side
  double contrast_grey = 0;
  double blur_sigma_px = 0;
  double noise_sigma_grey = 0;
  int num_pixels = 0;
  int num_segments = 0;
  int num_inlier_segments = 0;
  double segment_offset_rms_px = 0;  ///< over inlier segments
  double max_segment_offset_px = 0;  ///< over all segments
};

struct CornerRefinementResult {
  MarkerStatus status = MarkerStatus::kRefinementFailed;
  std::array<Eigen::Vector2d, 4> corners_px{};  ///< image pixels (distorted if the camera is)
  std::array<double, 4> corner_sigma_px{{0, 0, 0, 0}};
  std::array<EdgeFit, 4> edges{};
  double edge_fit_rms_px = 0;
  double max_segment_offset_px = 0;
  double edge_inlier_fraction = 0;
  double contrast_grey = 0;
  double blur_sigma_px = 0;
  double noise_sigma_grey = 0;
  std::string failure;  ///< why, when status is kRefinementFailed
};

/// Scratch memory reused between calls so that refinement does not allocate
/// once warmed up. Not thread-safe: one per thread.
class EdgeRefinementWorkspace {
 public:
  EdgeRefinementWorkspace();
  ~EdgeRefinementWorkspace();
  EdgeRefinementWorkspace(const EdgeRefinementWorkspace&) = delete;
  EdgeRefinementWorkspace& operator=(const EdgeRefinementWorkspace&) = delete;
  struct Impl;
  Impl& impl() { return *impl_; }

 private:
  Impl* impl_;
};

/// Refines the four corners of one marker in `gray` (CV_8UC1). `initial_px`
/// are corners in image pixels and marker order, e.g. from
/// cv::aruco::detectMarkers with CORNER_REFINE_NONE (within ~1.5 px). On
/// failure the result carries `initial_px` and status kRefinementFailed.
/// Throws arpos::Error for a wrong image type or invalid options.
CornerRefinementResult RefineMarkerCorners(const cv::Mat& gray,
                                           const std::array<Eigen::Vector2d, 4>& initial_px,
                                           const EdgeRefinementOptions& options,
                                           const PixelUndistorter& undistorter,
                                           EdgeRefinementWorkspace* workspace);

/// Copies a refinement's outcome into an observation: status, corners, their
/// sigmas and the fit's quality figures (id and detected corners untouched).
void ApplyRefinement(const CornerRefinementResult& refinement, MarkerObservation* observation);

/// Convenience overload: identity undistorter, temporary workspace.
CornerRefinementResult RefineMarkerCorners(const cv::Mat& gray,
                                           const std::array<Eigen::Vector2d, 4>& initial_px,
                                           const EdgeRefinementOptions& options = {});

}  // namespace arpos
