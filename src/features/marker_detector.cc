#include "features/marker_detector.h"

#include <algorithm>
#include <cmath>

#include <omp.h>

#include <opencv2/aruco.hpp>
#include <opencv2/imgproc.hpp>

#include "sensor/case_config.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos {

const char* CornerRefinementMethodName(CornerRefinementMethod method) {
  switch (method) {
    case CornerRefinementMethod::kEdgeLines:
      return "edge_lines";
    case CornerRefinementMethod::kOpenCvNone:
      return "opencv_none";
    case CornerRefinementMethod::kOpenCvSubpix:
      return "opencv_subpix";
    case CornerRefinementMethod::kOpenCvContour:
      return "opencv_contour";
    case CornerRefinementMethod::kOpenCvAprilTag:
      return "opencv_apriltag";
  }
  return "unknown";
}

std::string MarkerDetectorOptions::Validate() const {
  if (ArucoDictionaryId(dictionary) < 0) return "unknown ArUco dictionary '" + dictionary + "'";
  for (const IdRange& r : id_ranges) {
    if (r.min_id < 0 || r.max_id < r.min_id) {
      return StringPrintf("id range [%d, %d] is empty or negative", r.min_id, r.max_id);
    }
  }
  if (!(min_marker_perimeter_px >= 12)) {
    return StringPrintf("min_marker_perimeter_px must be at least 12, got %g",
                        min_marker_perimeter_px);
  }
  if (adaptive_thresh_win_size_min < 3 ||
      adaptive_thresh_win_size_max < adaptive_thresh_win_size_min ||
      adaptive_thresh_win_size_step < 1) {
    return "adaptive threshold window sizes must satisfy 3 <= min <= max and step >= 1";
  }
  if (second_pass_window_px != 0 && second_pass_window_px < 3) {
    return StringPrintf("second_pass_window_px must be 0 (none) or at least 3, got %d",
                        second_pass_window_px);
  }
  if (opencv_subpix_window_px < 1) return "opencv_subpix_window_px must be positive";
  if (perspective_remove_pixel_per_cell < 2)
    return "perspective_remove_pixel_per_cell must be >= 2";
  if (num_threads < 0) return "num_threads must be non-negative";
  return edge.Validate();
}

bool MarkerDetectorOptions::Check(std::string* reason) const {
  const std::string r = Validate();
  if (reason != nullptr) *reason = r;
  return r.empty();
}

struct MarkerDetector::Impl {
  cv::Ptr<cv::aruco::Dictionary> dictionary;
  cv::Ptr<cv::aruco::DetectorParameters> params;
  cv::Ptr<cv::aruco::DetectorParameters> second_pass;  // null: none
  EdgeRefinementOptions edge;
  PixelUndistorter undistorter;
  std::vector<std::unique_ptr<EdgeRefinementWorkspace>> workspaces;  // one per thread
  cv::Mat gray;
  std::vector<std::vector<cv::Point2f>> corners;
  std::vector<int> ids;
  std::vector<std::vector<cv::Point2f>> second_corners;
  std::vector<int> second_ids;
};

MarkerDetector::MarkerDetector(const MarkerDetectorOptions& options)
    : options_(options), impl_(std::make_unique<Impl>()) {
  const int dict_id = ArucoDictionaryId(options.dictionary);
  if (dict_id < 0) ARPOS_INPUT_ERROR("unknown ArUco dictionary '" << options.dictionary << "'");
  std::string reason;
  ARPOS_CHECK(options.Check(&reason), "invalid MarkerDetectorOptions: " << reason);

  Impl& m = *impl_;
  m.dictionary = cv::aruco::getPredefinedDictionary(dict_id);
  m.edge = options.edge;
  m.edge.marker_bits = m.dictionary->markerSize;
  if (options.intrinsics.has_value()) m.undistorter = PixelUndistorter(*options.intrinsics);
  const int threads = options.num_threads > 0 ? options.num_threads : omp_get_max_threads();
  for (int i = 0; i < std::max(1, threads); ++i) {
    m.workspaces.push_back(std::make_unique<EdgeRefinementWorkspace>());
  }

  cv::aruco::DetectorParameters& p = *(m.params = cv::aruco::DetectorParameters::create());
  p.adaptiveThreshWinSizeMin = options.adaptive_thresh_win_size_min;
  p.adaptiveThreshWinSizeMax = options.adaptive_thresh_win_size_max;
  p.adaptiveThreshWinSizeStep = options.adaptive_thresh_win_size_step;
  p.adaptiveThreshConstant = options.adaptive_thresh_constant;
  p.maxMarkerPerimeterRate = options.max_marker_perimeter_rate;
  p.polygonalApproxAccuracyRate = options.polygonal_approx_accuracy_rate;
  p.minCornerDistanceRate = options.min_corner_distance_rate;
  p.minDistanceToBorder = options.min_distance_to_border_px;
  p.minMarkerDistanceRate = options.min_marker_distance_rate;
  p.markerBorderBits = options.edge.border_bits;
  p.perspectiveRemovePixelPerCell = options.perspective_remove_pixel_per_cell;
  p.perspectiveRemoveIgnoredMarginPerCell = options.perspective_remove_ignored_margin_per_cell;
  p.maxErroneousBitsInBorderRate = options.max_erroneous_bits_in_border_rate;
  p.errorCorrectionRate = options.error_correction_rate;
  p.cornerRefinementWinSize = options.opencv_subpix_window_px;
  switch (options.refinement) {
    case CornerRefinementMethod::kEdgeLines:
    case CornerRefinementMethod::kOpenCvNone:
      p.cornerRefinementMethod = cv::aruco::CORNER_REFINE_NONE;
      break;
    case CornerRefinementMethod::kOpenCvSubpix:
      p.cornerRefinementMethod = cv::aruco::CORNER_REFINE_SUBPIX;
      break;
    case CornerRefinementMethod::kOpenCvContour:
      p.cornerRefinementMethod = cv::aruco::CORNER_REFINE_CONTOUR;
      break;
    case CornerRefinementMethod::kOpenCvAprilTag:
      p.cornerRefinementMethod = cv::aruco::CORNER_REFINE_APRILTAG;
      break;
  }
  if (options.second_pass_window_px > 0) {
    m.second_pass = cv::makePtr<cv::aruco::DetectorParameters>(p);
    m.second_pass->adaptiveThreshWinSizeMin = options.second_pass_window_px;
    m.second_pass->adaptiveThreshWinSizeMax = options.second_pass_window_px;
    m.second_pass->adaptiveThreshWinSizeStep = 1;
  }
}

MarkerDetector::~MarkerDetector() = default;

std::vector<MarkerObservation> MarkerDetector::Detect(const cv::Mat& gray_or_bgr) {
  std::vector<MarkerObservation> observations;
  Detect(gray_or_bgr, &observations);
  return observations;
}

void MarkerDetector::Detect(const cv::Mat& image, std::vector<MarkerObservation>* observations) {
  Detect(image, observations, cv::Rect());
}

void MarkerDetector::Detect(const cv::Mat& image, std::vector<MarkerObservation>* observations,
                            const cv::Rect& window) {
  ARPOS_CHECK(observations != nullptr, "Detect needs an output vector");
  observations->clear();
  Impl& m = *impl_;
  const cv::Mat* gray = &image;
  switch (image.type()) {
    case CV_8UC1:
      break;
    case CV_8UC3:
      cv::cvtColor(image, m.gray, cv::COLOR_BGR2GRAY);
      gray = &m.gray;
      break;
    case CV_8UC4:
      cv::cvtColor(image, m.gray, cv::COLOR_BGRA2GRAY);
      gray = &m.gray;
      break;
    default:
      ARPOS_CHECK(
          false, "DetectMarkers needs an 8-bit grey, BGR or BGRA image, got type " << image.type());
  }
  if (gray->empty()) return;
  const cv::Rect search = window.area() > 0 ? window & cv::Rect(0, 0, gray->cols, gray->rows)
                                            : cv::Rect(0, 0, gray->cols, gray->rows);
  if (search.area() <= 0) return;
  const cv::Mat searched = (*gray)(search);

  m.params->minMarkerPerimeterRate =
      options_.min_marker_perimeter_px / std::max(searched.cols, searched.rows);
  m.corners.clear();
  m.ids.clear();
  cv::aruco::detectMarkers(searched, m.dictionary, m.corners, m.ids, m.params);
  if (m.second_pass) {
    m.second_pass->minMarkerPerimeterRate = m.params->minMarkerPerimeterRate;
    m.second_corners.clear();
    m.second_ids.clear();
    cv::aruco::detectMarkers(searched, m.dictionary, m.second_corners, m.second_ids, m.second_pass);
    for (size_t i = 0; i < m.second_ids.size(); ++i) {
      if (std::find(m.ids.begin(), m.ids.end(), m.second_ids[i]) != m.ids.end()) continue;
      m.ids.push_back(m.second_ids[i]);
      m.corners.push_back(m.second_corners[i]);
    }
  }

  for (size_t i = 0; i < m.ids.size(); ++i) {
    const int id = m.ids[i];
    if (!options_.id_ranges.empty() &&
        std::none_of(options_.id_ranges.begin(), options_.id_ranges.end(),
                     [id](const IdRange& r) { return r.Contains(id); })) {
      continue;
    }
    MarkerObservation obs;
    obs.id = id;
    for (int k = 0; k < 4; ++k) {
      obs.detected_corners_px[k] = Eigen::Vector2d(m.corners[i][k].x + search.x, m.corners[i][k].y + search.y);
    }
    obs.corners_px = obs.detected_corners_px;
    obs.status = MarkerStatus::kNotRefined;
    observations->push_back(obs);
  }

  if (options_.refinement == CornerRefinementMethod::kEdgeLines) {
    // Markers are independent: refine them in parallel, one workspace per thread.
    const int n = static_cast<int>(observations->size());
    const int threads = std::min(static_cast<int>(m.workspaces.size()), std::max(1, n));
#pragma omp parallel for schedule(dynamic) num_threads(threads)
    for (int i = 0; i < n; ++i) {
      MarkerObservation& obs = (*observations)[i];
      EdgeRefinementWorkspace& ws = *m.workspaces[omp_get_thread_num()];
      ApplyRefinement(RefineMarkerCorners(*gray, obs.detected_corners_px, m.edge, m.undistorter, &ws), &obs);
    }
    if (!options_.keep_unreliable) {
      observations->erase(std::remove_if(observations->begin(), observations->end(),
                                         [](const MarkerObservation& o) { return !o.IsPrecise(); }),
                          observations->end());
    }
  }
  for (MarkerObservation& obs : *observations) {
    double perimeter = 0;
    for (int k = 0; k < 4; ++k)
      perimeter += (obs.corners_px[(k + 1) % 4] - obs.corners_px[k]).norm();
    obs.perimeter_px = static_cast<int>(std::lround(perimeter));
  }
  std::sort(observations->begin(), observations->end(),
            [](const MarkerObservation& a, const MarkerObservation& b) { return a.id < b.id; });
}

int MarkerDetector::marker_bits() const { return impl_->dictionary->markerSize; }

std::vector<MarkerObservation> DetectMarkers(const cv::Mat& gray_or_bgr,
                                             const MarkerDetectorOptions& options) {
  MarkerDetector detector(options);
  return detector.Detect(gray_or_bgr);
}

}  // namespace arpos
