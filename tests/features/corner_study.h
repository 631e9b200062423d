#pragma once
/// Corner accuracy study shared by features_test and features_bench: run one
/// detector configuration over rendered images and compare with the truth.

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "features/marker_detector.h"
#include "features/marker_render.h"
#include "sensor/intrinsics.h"

namespace arpos::testing {

struct StudyImage {
  cv::Mat image;
  std::vector<MarkerTruth> truth;
};

/// `num_images` renders of `markers_per_image` random markers (3 cm, sides in
/// [min_side_px, max_side_px], tilt up to max_tilt_deg).
std::vector<StudyImage> MakeStudyImages(const CameraIntrinsics& camera, int num_images,
                                        int markers_per_image, double min_side_px,
                                        double max_side_px, double max_tilt_deg,
                                        const RenderOptions& render, unsigned seed);

struct MarkerErrors {
  double side_px = 0;
  std::array<double, 4> corner_error_px{};
  Eigen::Vector2d mean_offset_px = Eigen::Vector2d::Zero();  ///< mean of (est - true) over corners
  double scale_bias = 0;            ///< mean (|c_est - centre| / |c_true - centre|) - 1
  double translation_error_mm = 0;  ///< IPPE (best reprojection) pose vs truth
  double rotation_error_deg = 0;
  MarkerStatus status = MarkerStatus::kNotRefined;
};

struct StudyResult {
  std::vector<MarkerErrors> markers;  ///< detected and matched
  int num_truth = 0;
  int num_wrong_ids = 0;
  double total_time_ms = 0;
  int num_images = 0;
};

/// Detects with `options` in every image and matches by id.
StudyResult RunStudy(const std::vector<StudyImage>& images, const CameraIntrinsics& camera,
                     const MarkerDetectorOptions& options);

struct Summary {
  int count = 0;
  double median_px = 0, p95_px = 0, max_px = 0;
  double scale_bias_percent = 0;  ///< mean over markers
  Eigen::Vector2d mean_offset_px = Eigen::Vector2d::Zero();
  double translation_median_mm = 0, translation_p95_mm = 0;
  double rotation_median_deg = 0;
};

/// Statistics over markers with side in [min_side_px, max_side_px) and, if
/// `precise_only`, status kRefined/kNotRefined.
Summary Summarise(const StudyResult& result, double min_side_px, double max_side_px,
                  bool precise_only = false);

double Percentile(std::vector<double> values, double q);

}  // namespace arpos::testing
