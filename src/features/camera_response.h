#pragma once
/// Camera response: how a camera turned scene radiance into 8-bit codes, and
/// its estimation from the marker edges of a recording.
///
/// Why it matters: a marker edge blurred by the optics is a symmetric step in
/// linear radiance, so its 50 % point is the edge. Encoded by a non-linear
/// tone curve the step becomes asymmetric and the 50 % point of the codes
/// moves towards one side by a fraction of the blur. Measured with the
/// project's edge-line corners: 0.26-0.39 px outward per edge when a linear
/// image is read as if it were sRGB, which tilts the pose of a small oblique
/// marker by tenths of a degree. Cameras differ (sRGB-like, pure gammas,
/// S-shaped consumer curves, raw/linear modes), so the response is estimated
/// from the recording rather than assumed.
///
/// Representation: `linear_from_code[v]` for each 8-bit code v, scaled so that
/// code 0 -> 0 and code 255 -> 255. Only the shape matters to the corners
/// (edge fits have free black and white levels), so exposure and an affine
/// change of the table are irrelevant.
///
/// Estimation, from the markers themselves: their black and white cells have
/// equal printed widths. Every cell boundary of a marker (and its outer
/// edge against the quiet zone) is fitted, in linear values read through a
/// candidate response, with a blurred step (edge_profile.h) at a free offset
/// from where the marker's corners put it. Under the right response the
/// offsets are those of a rigid grid (a common shift, scale and turn of the
/// grid absorbs the corners' own errors); under a wrong one every boundary
/// also moves towards the white (or the black) side by the same amount: the
/// marker's black "widening". EstimateCameraResponse finds the response that
/// makes the widening vanish over all markers: a smooth deformation of a
/// prior curve (a few sine terms that keep the ends), Gauss-Newton, ridge
/// towards the prior where the markers say nothing (levels they do not
/// cover). Markers at different exposures and lighting cover different
/// parts of the curve.
///
/// Tried and not kept: the edges' profile asymmetry alone (per marker, or
/// pooled with a free curve): the profile shape leaves the response too
/// poorly determined; thresholding each marker at the code that equalises
/// cell widths: interpolating sharp edges between pixels biases that code by
/// 1-3 codes, and a free table chased those biases.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace arpos {

class CameraResponse {
 public:
  /// Linear (raw) response: the identity.
  CameraResponse();
  static CameraResponse Linear();
  /// The sRGB transfer curve (IEC 61966-2-1).
  static CameraResponse Srgb();
  /// A pure power law: code = 255 * (linear / 255)^(1 / gamma).
  static CameraResponse Gamma(double gamma);
  /// A table of 256 linear values for codes 0..255 (rescaled so that 0 -> 0
  /// and 255 -> 255). Throws InputError unless finite and non-decreasing with
  /// 255 above 0.
  static CameraResponse FromTable(const std::array<double, 256>& linear_from_code,
                                  std::string name = "estimated");
  /// By name: "linear", "srgb", "gamma<G>" (e.g. gamma2.2). Throws InputError
  /// naming the text otherwise.
  static CameraResponse FromName(const std::string& name);

  /// Short name: linear, srgb, gamma2.60, or "estimated".
  const std::string& name() const { return name_; }

  /// The camera's own sharpening after its tone curve (sharpening.h): codes
  /// were delivered as code + amount * (code - Gaussian(code, sigma_px)).
  /// 0 = none. Readers of sub-pixel intensities undo it first
  /// (UndoSharpening). Throws InputError unless amount is in [0, 5]
  /// and sigma in [0.3, 5] px.
  CameraResponse WithSharpening(double amount, double sigma_px) const;
  double sharpen_amount() const { return sharpen_amount_; }
  double sharpen_sigma_px() const { return sharpen_sigma_px_; }
  bool sharpened() const { return sharpen_amount_ > 0; }
  const std::array<double, 256>& linear_from_code() const { return table_; }
  double Linearize(int code) const { return table_[code & 255]; }

  /// The linear value as a fraction of full scale for a code (0..1).
  double LinearFraction(int code) const { return table_[code & 255] / 255.0; }

  /// Text for the store and reports: "name: v0 v1 ... v255" (the table,
  /// rounded to 1e-4), followed by " sharpen AMOUNT SIGMA" for a sharpening
  /// camera. Parse reads it back (InputError on malformed text, naming
  /// `what`).
  std::string Serialize() const;
  static CameraResponse Parse(const std::string& text, const std::string& what);

  /// Largest difference from another response over codes from..to, as a
  /// fraction of full scale.
  double MaxDifference(const CameraResponse& other, int from_code = 0, int to_code = 255) const;

  /// `gray` (CV_8UC1) mapped through the table, rounded to 8 bits, into
  /// `linear` (may alias). For detectors that want a linear-looking image;
  /// the edge fits read the table at full precision instead.
  void LinearizeImage(const cv::Mat& gray, cv::Mat* linear) const;

 private:
  std::array<double, 256> table_{};
  std::string name_;
  double sharpen_amount_ = 0;
  double sharpen_sigma_px_ = 1.0;
};

class PixelUndistorter;

/// The pixels around one marker's cell boundaries, prepared once; the
/// response is applied when the widening is measured.
struct MarkerCellEdges {
  struct Boundary {
    std::vector<std::uint8_t> code;
    std::vector<float> distance_px;  ///< signed, positive towards the white side
    double normal_x = 0, normal_y = 0;  ///< unit, towards white (ideal px)
    double centre_x = 0, centre_y = 0;  ///< relative to the marker centre (ideal px)
  };
  std::vector<Boundary> boundaries;
  double blur_sigma_px = 0.5;
  double cell_px = 0;
};

struct CellEdgeOptions {
  int marker_bits = 4;  ///< data bits per side (DICT_4X4_*)
  int border_bits = 1;
  double quiet_zone_cells = 1.0;
  /// Cells must span at least this many pixels (shortest side / cells).
  double min_cell_px = 4.0;
  std::string Validate() const;
};

/// Prepares one marker whose corners (image px, ArUco order) are refined;
/// `bits` is its (marker_bits + 2 border_bits)^2 cell matrix (CV_8UC1, 0 =
/// black) as cv::aruco::drawMarker draws it at one pixel per cell, and
/// `blur_sigma_px` its edges' blur from the refinement. Nothing when the
/// marker is too small or too close to the image border.
std::optional<MarkerCellEdges> PrepareMarkerCellEdges(const cv::Mat& gray,
                                                      const std::array<Eigen::Vector2d, 4>& corners_px,
                                                      const cv::Mat& bits, double blur_sigma_px,
                                                      const PixelUndistorter& undistorter,
                                                      const CellEdgeOptions& options = {});

/// The marker's black widening under `response`: how far (px) every
/// boundary sits towards the white side beyond a rigid grid; 0 under the
/// right response. NaN when too few boundaries could be fitted. `sigma_px`
/// gets its 1-sigma uncertainty.
double MarkerWidening(const MarkerCellEdges& marker, const CameraResponse& response,
                      double* sigma_px = nullptr);

struct ResponseEstimationOptions {
  /// g = prior + 255 sum_{k=1..basis} a_k sin(k pi code / 255).
  int basis = 4;
  /// The data cannot tell with fewer markers: the prior curve is kept.
  int min_markers = 6;
  /// Ridge prior on each a_k (1 sigma): linear vs sRGB is a_1 ~ 0.3.
  double deformation_sigma = 0.3;
  /// Floor of a marker's widening uncertainty (px): what the model leaves.
  double widening_floor_px = 0.01;
  int iterations = 8;
  /// Markers used at most (the largest cells first).
  int max_markers = 80;
  std::string Validate() const;
};

struct ResponseEstimate {
  bool ok = false;  ///< false: too few markers
  CameraResponse response;
  int markers_used = 0;
  /// RMS widening over the markers (px) under the prior and under the estimate.
  double widening_prior_px = 0, widening_px = 0;
  /// The closest of sRGB / gamma 1.0..3.0 (for people), and its largest
  /// difference from the estimate over codes 16..240 (fraction of full scale).
  std::string closest_standard;
  double closest_difference = 0;
  std::string message;  ///< why not ok, or a one-line summary
};

/// Solves for the response that makes the markers' widening vanish; `prior`
/// is kept where the markers do not constrain it (and returned when they are
/// too few).
ResponseEstimate EstimateCameraResponse(const std::vector<MarkerCellEdges>& markers,
                                        const CameraResponse& prior,
                                        const ResponseEstimationOptions& options = {});

}  // namespace arpos
