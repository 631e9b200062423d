#pragma once
/// The cells of a dictionary's markers as printed: one pixel per cell, the
/// black border included (0 black, 255 white), as cv::aruco::drawMarker
/// draws them; each marker drawn once and kept. The pattern fit
/// (marker_template.h) and the response estimate (response_from_recording.h)
/// read them.
/// Thread-safety: one MarkerCells per thread.

#include <map>
#include <string>

#include <opencv2/core.hpp>

namespace cv {
namespace aruco {
class Dictionary;
}  // namespace aruco
}  // namespace cv

namespace arpos {

class MarkerCells {
 public:
  /// `dictionary`: an ArUco dictionary name (case_config.h,
  /// ArucoDictionaryId); throws arpos::Error for one it does not know, or a
  /// negative border.
  MarkerCells(const std::string& dictionary, int border_bits);
  /// Cells across a marker, border included.
  int cells_per_side() const { return cells_per_side_; }
  /// Marker `id`'s cells (CV_8UC1, cells_per_side() square); empty for an
  /// id the dictionary does not hold.
  const cv::Mat& Of(int id);

 private:
  cv::Ptr<cv::aruco::Dictionary> dictionary_;
  int border_bits_ = 1;
  int cells_per_side_ = 0;
  std::map<int, cv::Mat> drawn_;
  cv::Mat none_;
};

}  // namespace arpos
