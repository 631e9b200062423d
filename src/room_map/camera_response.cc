#include "room_map/camera_response.h"

#include <cmath>

#include <opencv2/core.hpp>

#include "util/check.h"

namespace arpos {

const cv::Mat& SrgbToLinearLut() {
  static const cv::Mat lut = [] {
    cv::Mat t(1, 256, CV_8UC1);
    for (int v = 0; v < 256; ++v) {
      const double c = v / 255.0;
      const double linear = c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
      t.at<uchar>(0, v) = cv::saturate_cast<uchar>(linear * 255.0);
    }
    return t;
  }();
  return lut;
}

void LinearizeSrgb(const cv::Mat& gray, cv::Mat* linear) {
  ARPOS_CHECK(linear != nullptr, "no output image");
  ARPOS_CHECK(gray.type() == CV_8UC1, "LinearizeSrgb needs an 8-bit grey image, got type " << gray.type());
  cv::LUT(gray, SrgbToLinearLut(), *linear);
}

}  // namespace arpos
