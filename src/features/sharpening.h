#pragma once
/// A colour camera's own sharpening, estimated from a recording and undone
/// where sub-pixel intensities are read.
///
/// Why: consumer cameras (and RealSense's default "sharpness") apply an
/// unsharp mask to the encoded image, after the tone curve:
///     delivered = code + amount * (code - Gaussian(code, sigma)).
/// The halo it leaves beside every edge is not a blurred step in any tone
/// curve, so the edge fits (edge_refinement.h) and the response estimate
/// (camera_response.h) read it as a steeper curve and a larger marker:
/// features_bench, sRGB, amount 1, sigma 1 px: corners 0.066 px median off
/// (0.020 without), marker scale +0.21 %; end to end (random xtion scenes,
/// sRGB) the model pose at scan time went from 1.39 to 1.95 mm mean over
/// eight seeds, and to 25 mm on a ninth.
///
/// Undoing: the mask is linear in the codes, so for known (amount, sigma)
/// the codes before it are the fixed point of
///     E <- (delivered + amount * Gaussian(E, sigma)) / (1 + amount),
/// a contraction (factor amount / (1 + amount)); a few iterations around
/// each marker, rounded back to 8 bits. Saturated halos (clipped at 0 or
/// 255) cannot be restored; markers are mid-grey enough that this is rare.
///
/// Estimating: the profile across a marker's outer edge is monotone for any
/// tone curve and any symmetric blur (and so is any average of such
/// profiles), while a sharpening halo makes it overshoot on both sides.
/// Each candidate amount is undone around the markers and the edges'
/// profiles (+-5.5 px across the middle of each outer edge), normalised to
/// their own black and white levels, are pooled; the least amount whose
/// pooled profile is monotone within its noise is taken: undoing more than
/// the camera did only blurs. Nothing is undone unless the delivered
/// profile overshoots by more than twice what its noise explains (JPEG at
/// quality 75-90 does not: features_bench).

#include <array>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "features/marker_observation.h"

namespace arpos {

/// Rounds `delivered` (CV_8UC1) back through the inverse of the unsharp mask
/// inside each of `regions` (clipped to the image) into `out`, which gets a
/// copy of `delivered` elsewhere. `out` may not alias `delivered`.
void UndoSharpening(const cv::Mat& delivered, const std::vector<cv::Rect>& regions, double amount,
                    double sigma_px, cv::Mat* out);

/// The region a marker's edge fits read: its corners' bounding box grown by
/// one and a half cells (the quiet zone and the bands) and 4 px.
cv::Rect MarkerReadRegion(const std::array<Eigen::Vector2d, 4>& corners_px, int cells_per_side,
                          const cv::Size& image_size);

struct SharpeningEstimationOptions {
  /// Candidates: amounts step, 2 step, ... max_amount, of a mask of radius
  /// sigma_px. The radius is poorly told by the profile (a wider mask undone
  /// by a smaller amount leaves it as monotone, and sharper: a search over
  /// radii picked the widest), so one is assumed: features_bench, a camera's
  /// 0.7 px mask undone as a 1 px one, corners 0.047 -> 0.026 px median
  /// (0.020 unsharpened).
  double amount_step = 0.1;
  double max_amount = 2.5;
  double sigma_px = 1.0;
  /// Profiles reach +-profile_half_width_px across each edge, where the halo
  /// has faded (about 2.5 times the blur and the mask's radius together),
  /// or 0.6 of a cell when too few markers have cells that wide, but not
  /// less than min_profile_half_width_px (else not estimated: shorter
  /// profiles hold part of the halo as the edge's own levels, and the amount
  /// found scattered from 0.4 to 2.5 for a true 1.0 over 60-frame xtion
  /// walks whose fourth largest marker had cells of 5-7 px).
  double profile_half_width_px = 5.5;
  double min_profile_half_width_px = 4.5;
  double bin_px = 0.25;
  /// Edges with less contrast (codes) are not used.
  double min_contrast_codes = 20;
  /// Edges with more than max_clipped_fraction of their profile's pixels
  /// within clip_codes of 0 or 255 are not used, nor any marker view with
  /// such an edge (before the reach is chosen): a clipped halo cannot be
  /// undone, and what is left of it is not the mask's shape (a simulated
  /// linear, auto-exposed camera whose black reads 0 over whole cells:
  /// amount 2.3 found for a true 0.8, the room map's couch-side markers 2
  /// mm off instead of 0.3-0.8).
  int clip_codes = 1;
  double max_clipped_fraction = 0.1;
  /// Fewer edges (min_edges / 4 marker views set the reach): not
  /// estimated, and the caller keeps what it had (the fallback response's).
  int min_edges = 32;
  int max_markers = 60;
  /// The pooled profile must overshoot by more than this share of the
  /// edges' contrast (besides twice what its noise allows) to be taken for
  /// sharpening. Profiles of cameras that do not sharpen overshoot by
  /// 0.4-3.8 % in the simulated sweeps (the marker's inner cells within the
  /// profile's reach, the blur); with 84 edges pooled the noise allowance
  /// fell to a fraction of that, and a gamma-2.6 camera that does not
  /// sharpen was given an amount of 1.3 from 1.8 %: its room map 4 mm off
  /// at the couch. Sharpening cameras (amounts 0.8-1.5): 6-17 %.
  double min_overshoot = 0.04;
  std::string Validate() const;
};

struct SharpeningEstimate {
  bool ok = false;       ///< false: too few usable edges; amount 0 assumed
  double amount = 0;
  double sigma_px = 1.0;
  int edges_used = 0;
  double profile_half_width_px = 0;  ///< the reach the profiles had
  /// Overshoot of the pooled profile (sum of its decreases, fraction of
  /// contrast) as delivered and after undoing the estimate.
  double overshoot_delivered = 0;
  double overshoot_after = 0;
  std::string message;  ///< one line for people
};

/// A marker view's cell width as the estimate measures it (px): its shortest
/// side over the cells across it.
double MarkerCellWidthPx(const MarkerObservation& marker, int cells_per_side);

/// What the estimate needs: this many marker views (min_edges / 4) with
/// cells at least `min_profile_half_width_px / 0.6` wide.
int SharpeningViewsNeeded(const SharpeningEstimationOptions& options);
double SharpeningCellNeededPx(const SharpeningEstimationOptions& options);

/// `frames`: grey images (CV_8UC1, the camera's codes) with their markers,
/// whose `corners_px` are refined (any response). `cells_per_side`: marker
/// bits + 2 border bits of the dictionary.
SharpeningEstimate EstimateSharpening(const std::vector<const cv::Mat*>& grays,
                                      const std::vector<const std::vector<MarkerObservation>*>& markers,
                                      int cells_per_side, const SharpeningEstimationOptions& options = {});

}  // namespace arpos
