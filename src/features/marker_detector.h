#pragma once
/// ArUco marker detection with sub-pixel edge-line corner refinement.
///
/// Detection is cv::aruco::detectMarkers (OpenCV 4.6) with parameters tuned
/// for small markers (3 cm at 0.6-1.5 m, i.e. ~15-60 px per side) and its own
/// corner refinement off; the corners are then refined by RefineMarkerCorners
/// (features/edge_refinement.h): straight lines fitted to the four outer edges
/// at sub-pixel precision, intersected. On synthetic renders of 30-60 px
/// markers this reaches a few hundredths of a pixel without scale bias, where
/// OpenCV's refinements are biased by 0.3-0.7 px (see tests/features and
/// PITFALLS.md). The OpenCV refinements stay selectable for comparison.

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "features/edge_refinement.h"
#include "features/marker_observation.h"
#include "sensor/intrinsics.h"

namespace arpos {

enum class CornerRefinementMethod {
  kEdgeLines = 0,   ///< ours: edge-line fits (default)
  kOpenCvNone,      ///< OpenCV CORNER_REFINE_NONE (contour polygon corners)
  kOpenCvSubpix,    ///< OpenCV CORNER_REFINE_SUBPIX, window opencv_subpix_window_px
  kOpenCvContour,   ///< OpenCV CORNER_REFINE_CONTOUR
  kOpenCvAprilTag,  ///< OpenCV CORNER_REFINE_APRILTAG (also its own detector; slow)
};

const char* CornerRefinementMethodName(CornerRefinementMethod method);

struct MarkerDetectorOptions {
  /// OpenCV predefined dictionary name (case.yaml `markers.dictionary`).
  std::string dictionary = "DICT_4X4_250";
  /// Ids to report; empty = every id of the dictionary. Others are dropped
  /// before refinement.
  std::vector<IdRange> id_ranges;
  CornerRefinementMethod refinement = CornerRefinementMethod::kEdgeLines;
  /// Camera model; only its distortion is used (edge fits in undistorted
  /// coordinates). Unset or zero distortion: plain image pixels.
  std::optional<CameraIntrinsics> intrinsics;
  /// Keep observations whose refinement failed or found occlusion (their
  /// status says so); false drops everything but MarkerStatus::kRefined
  /// (or kNotRefined for the OpenCV methods).
  bool keep_unreliable = true;
  /// Threads refining the markers of a frame in parallel (OpenMP); 0 =
  /// OpenMP's default. 1 by default: on our 2-core target the other
  /// pipeline stages want the second core, and detection itself already runs
  /// on OpenCV's thread pool.
  int num_threads = 1;

  // cv::aruco::DetectorParameters (names follow OpenCV's).
  /// Smallest marker perimeter to detect, px (OpenCV takes a rate of the
  /// image's larger side; converted per image). 30 px = 7.5 px sides: a
  /// 13 px marker seen at 40 deg is ~9 px across one way.
  double min_marker_perimeter_px = 30;
  double max_marker_perimeter_rate = 4.0;
  int adaptive_thresh_win_size_min = 3;
  int adaptive_thresh_win_size_max = 23;
  int adaptive_thresh_win_size_step = 10;
  double adaptive_thresh_constant = 7;
  /// A second detection pass thresholded with this one window (px; 0: none),
  /// for markers the windows above miss: cells of about 3 px (a 22 px
  /// ARUCO_ORIGINAL marker far on the floor) fall between the 3 px and
  /// 13 px windows. Markers it finds whose id the first pass did not are
  /// added. Measured over 14 simulated cases (xtion, l515, d435; room, body
  /// scan and tracking recordings, every third frame): +246 marker views on
  /// 5147 (4.8 %), 1 -> 52 views of a d435 tracking sequence whose camera
  /// saw the room only through its 22 px origin marker, at +45 % of the
  /// detection time; windows of 7 or 9 px found fewer (219, 196).
  int second_pass_window_px = 5;
  double polygonal_approx_accuracy_rate = 0.05;  ///< OpenCV 0.03; small quads need slack
  double min_corner_distance_rate = 0.05;
  int min_distance_to_border_px = 3;
  double min_marker_distance_rate = 0.05;
  int perspective_remove_pixel_per_cell = 8;  ///< OpenCV 4; more samples per bit
  /// OpenCV 0.13. Reading only the middle 40 % of each (blurred) bit cell
  /// found 67 of 80 markers of 11-16 px where OpenCV's defaults found 55.
  double perspective_remove_ignored_margin_per_cell = 0.3;
  double max_erroneous_bits_in_border_rate = 0.35;
  double error_correction_rate = 0.6;
  /// cornerRefinementWinSize for kOpenCvSubpix (OpenCV default 5).
  int opencv_subpix_window_px = 5;

  /// Our refinement. marker_bits is overwritten from the dictionary.
  EdgeRefinementOptions edge;

  std::string Validate() const;
  bool Check(std::string* reason = nullptr) const;
};

/// Detects and refines markers frame after frame, reusing its buffers.
/// Not thread-safe (one instance per calling thread); internally refines the
/// markers of a frame in parallel.
class MarkerDetector {
 public:
  /// Throws arpos::InputError for an unknown dictionary, arpos::Error for
  /// invalid options.
  explicit MarkerDetector(const MarkerDetectorOptions& options);
  ~MarkerDetector();
  MarkerDetector(const MarkerDetector&) = delete;
  MarkerDetector& operator=(const MarkerDetector&) = delete;

  /// Markers in `gray_or_bgr` (CV_8UC1, CV_8UC3 BGR or CV_8UC4 BGRA), sorted by
  /// id. Throws arpos::Error for other image types.
  std::vector<MarkerObservation> Detect(const cv::Mat& gray_or_bgr);
  /// Same, into `observations` (cleared first) to reuse its capacity.
  void Detect(const cv::Mat& gray_or_bgr, std::vector<MarkerObservation>* observations);
  /// Markers found inside `window` of the whole image `gray_or_bgr` (a
  /// search near a predicted place); their corners are refined and reported
  /// in the whole image's pixels, so a camera's distortion applies as it
  /// does to Detect. An empty window searches the whole image.
  void Detect(const cv::Mat& gray_or_bgr, std::vector<MarkerObservation>* observations, const cv::Rect& window);

  const MarkerDetectorOptions& options() const { return options_; }
  /// Data bits per marker side of the dictionary (4 for DICT_4X4_*).
  int marker_bits() const;

 private:
  struct Impl;
  MarkerDetectorOptions options_;
  std::unique_ptr<Impl> impl_;
};

/// The side (px) below which ArUco cannot read a marker of `marker_bits`
/// data bits a side: about 2 px a cell, the black border included (12 px for
/// 4x4 markers). Measured: 2 cm stickers 9-10 px across (4x4, 640x480 camera
/// at 1.1-1.3 m) were read in 16-24 % of the frames.
inline double ReadableMarkerSidePx(int marker_bits) { return 2.0 * (marker_bits + 2); }

/// One-shot convenience: MarkerDetector(options).Detect(gray_or_bgr).
std::vector<MarkerObservation> DetectMarkers(const cv::Mat& gray_or_bgr,
                                             const MarkerDetectorOptions& options = {});

}  // namespace arpos
