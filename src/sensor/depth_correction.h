#pragma once
/// Systematic depth error of an RGB-D camera, estimated against what the
/// markers of a recording measure, and its removal from depth images.
///
/// Model (structured-light and time-of-flight sensors alike: a scale error of
/// the baseline or clock, and a smooth error field that grows with the
/// square of the distance, as disparity errors do):
///   z_measured = z_true * (1 + scale) + z_true^2 * field(x, y)
/// with (x, y) = ((u - cx) / fx, (v - cy) / fy) the ideal normalised image
/// coordinates and field (1/m) bilinear on a coarse grid over the image
/// (9 x 7 nodes: smooth errors of a few cycles across the image, as
/// structured-light sensors show; a quadratic polynomial was tried and left
/// such fields in place). Fitted (robust linear least squares) to depth samples inside
/// markers whose depth the colour image fixes through the markers' printed
/// size (room map adjustment without depth terms), and on the planes such
/// markers span near them (each view's offset over the plane estimated with
/// the correction: DepthComparison::view_offset). Kept only when it
/// explains the data clearly better than no correction, or predicts
/// readings it was not fitted to (cross-validation over two halves of the
/// views: FitDepthCorrection). The readings' noise is taken from the
/// recording when it is clearly below the sensor model's, and readings far
/// outside it (what stands on a floor seen far away) are left out.

#include <array>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "sensor/intrinsics.h"

namespace arpos {

struct DepthCorrection {
  double scale = 0;
  /// The field's grid: nx * ny values, row-major, nodes spaced evenly over
  /// [x0, x1] x [y0, y1]; empty = no field.
  int nx = 0, ny = 0;
  double x0 = 0, x1 = 0, y0 = 0, y1 = 0;
  std::vector<double> grid;

  double Field(double x, double y) const;

  bool IsIdentity() const;
  /// The true depth for a measured one at normalised coordinates (x, y).
  double TrueDepth(double z_measured_m, double x, double y) const;
  /// The same, with the field at that pixel already evaluated (Field(x, y)).
  double TrueDepthWithField(double z_measured_m, double field) const;
  /// Measured depth error at z_true = 1 m in the image centre and its
  /// largest magnitude over the image corners (mm), for people.
  double ErrorAt1mCentreMm() const;
  std::string Describe() const;
  /// "depth correction: scale nx ny x0 x1 y0 y1 g..."; Parse reads it back (InputError
  /// naming `what` on malformed text).
  std::string Serialize() const;
  static DepthCorrection Parse(const std::string& text, const std::string& what);
};

/// A depth reading and the depth the markers say it should have.
struct DepthComparison {
  double x = 0, y = 0;         ///< normalised image coordinates
  double measured_m = 0;       ///< the sensor's reading
  double expected_m = 0;       ///< from the colour geometry
  double sigma_m = 0.001;      ///< the reading's noise (1 sigma)
  /// Readings of one group (one marker view) share the view's pose error:
  /// a group counts as at most a few independent readings when the data's
  /// support for a correction is weighed; -1 = a group of its own.
  int group = -1;
  /// Which half of the data (0 or 1) the reading falls in when the
  /// correction is cross-validated: whole views, in blocks of frames.
  int split = 0;
  /// The group's readings share an unknown offset and tilt over the image
  /// (a + b x + c y, metres: the pose error of a view over a wide surface),
  /// estimated with the correction under a zero-mean prior and not counted
  /// as the camera's error.
  bool view_offset = false;
};

struct DepthCorrectionFit {
  bool applied = false;  ///< false: no correction is better supported than none
  DepthCorrection correction;
  int samples = 0;
  /// RMS of (measured - expected) / sigma before and after the correction,
  /// over the readings without a view offset (those inside the markers)
  /// when there are any, else over all.
  double normalised_rms_before = 0, normalised_rms_after = 0;
  /// The model fitted to one half of the views, tried on the other (both
  /// ways): the drop in squared normalised residual per effective sample
  /// against no correction (a view's readings counting as a few). Positive:
  /// the correction predicts readings it was not fitted to.
  bool cross_validated = false;
  double cross_validated_gain = 0;
  /// The same gain of the full model against the scale alone; at most
  /// the gain a correction needs (0.025), the field is left out and the
  /// scale alone fitted (field_left_out), cross_validated_gain then being
  /// the scale's.
  double field_gain = 0;
  bool field_left_out = false;
  /// The readings' noise relative to their sigma_m, as the readings inside
  /// the markers spread around a first fit (robust; clamped to 0.2-3). The
  /// fit is made at that noise when it is below 1/1.5 (a sensor clearly
  /// quieter than the model), else at sigma_m; readings beyond 4 sigma (at
  /// the noise the fit is made at) are left out after its first two rounds.
  double noise_factor = 1;
  std::string message;
};

/// Fits the model to `samples`; `applied` only when there are enough samples
/// spread over depth and either the normalised RMS drops by at least 15 %
/// or the model fitted to each half of the groups (by `split`) lowers the
/// other half's squared normalised residual by more than 0.025 per
/// effective reading (a group counting as at most 4). The field is kept
/// only when it predicts the other half so much better than the scale
/// alone (DepthCorrectionFit::field_gain).
DepthCorrectionFit FitDepthCorrection(const std::vector<DepthComparison>& samples,
                                      const CameraIntrinsics& intrinsics);

/// Corrects a CV_16UC1 depth image (intrinsics.depth_scale units per metre,
/// registered to colour) in place; zeros stay zeros. One image: for a
/// stream of them, DepthCorrector.
void CorrectDepthImage(const CameraIntrinsics& intrinsics, const DepthCorrection& correction,
                       cv::Mat* depth);

/// CorrectDepthImage for every frame of one camera, to the same values: the
/// field at each pixel is computed once (a frame then costs a square root a
/// reading, on OpenCV's threads). Measured with tracking_bench on a random-
/// conditions case (848x480, a 9 x 7 field): 7.2-8.3 ms a frame with the
/// field evaluated at every reading.
class DepthCorrector {
 public:
  /// Throws arpos::Error for intrinsics without a positive size.
  DepthCorrector(const CameraIntrinsics& intrinsics, const DepthCorrection& correction);
  /// As CorrectDepthImage (throws arpos::Error for an image that is not
  /// CV_16UC1; one of another size is corrected as CorrectDepthImage does).
  void Apply(cv::Mat* depth) const;
  bool IsIdentity() const { return identity_; }

 private:
  CameraIntrinsics intrinsics_;
  DepthCorrection correction_;
  int width_ = 0, height_ = 0;
  double to_m_ = 0, depth_scale_ = 0;
  bool identity_ = true;
  std::vector<double> field_;  ///< DepthCorrection::Field at each pixel, row-major
};

}  // namespace arpos
