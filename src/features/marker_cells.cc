#include "features/marker_cells.h"

#include <opencv2/aruco.hpp>

#include "sensor/case_config.h"
#include "util/check.h"

namespace arpos {

MarkerCells::MarkerCells(const std::string& dictionary, int border_bits)
    : border_bits_(border_bits) {
  const int id = ArucoDictionaryId(dictionary);
  ARPOS_CHECK(id >= 0, "unknown dictionary " << dictionary);
  ARPOS_CHECK(border_bits >= 0, "negative marker border " << border_bits);
  dictionary_ = cv::aruco::getPredefinedDictionary(id);
  cells_per_side_ = dictionary_->markerSize + 2 * border_bits;
}

const cv::Mat& MarkerCells::Of(int id) {
  if (id < 0 || id >= dictionary_->bytesList.rows) return none_;
  auto it = drawn_.find(id);
  if (it == drawn_.end()) {
    cv::Mat m;
    cv::aruco::drawMarker(dictionary_, id, cells_per_side_, m, border_bits_);
    it = drawn_.emplace(id, m).first;
  }
  return it->second;
}

}  // namespace arpos
