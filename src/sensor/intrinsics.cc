#include "sensor/intrinsics.h"

#include <cmath>

#include "util/string_util.h"

namespace arpos {

std::string CameraIntrinsics::Validate() const {
  if (width <= 0 || width > 16384) return StringPrintf("width must be in 1..16384, got %d", width);
  if (height <= 0 || height > 16384) {
    return StringPrintf("height must be in 1..16384, got %d", height);
  }
  if (!(fx > 0) || !std::isfinite(fx)) return StringPrintf("fx must be positive, got %g", fx);
  if (!(fy > 0) || !std::isfinite(fy)) return StringPrintf("fy must be positive, got %g", fy);
  // A principal point outside the image is always a unit or convention mistake.
  if (!(cx >= 0 && cx <= width)) {
    return StringPrintf("cx must lie inside the image (0..%d), got %g", width, cx);
  }
  if (!(cy >= 0 && cy <= height)) {
    return StringPrintf("cy must lie inside the image (0..%d), got %g", height, cy);
  }
  // Field of view between ~10 and ~170 degrees: fx in [0.05, 6] * width.
  if (fx < 0.05 * width || fx > 6.0 * width) {
    return StringPrintf("fx = %g is implausible for an image %d px wide", fx, width);
  }
  if (fy < 0.05 * height || fy > 8.0 * height) {
    return StringPrintf("fy = %g is implausible for an image %d px high", fy, height);
  }
  if (std::abs(fx / fy - 1.0) > 0.2) {
    return StringPrintf("fx/fy = %g: pixels this far from square are implausible", fx / fy);
  }
  for (double d : distortion) {
    if (!std::isfinite(d) || std::abs(d) > 10) {
      return StringPrintf("distortion coefficient %g is out of range", d);
    }
  }
  if (!(depth_scale > 0) || depth_scale > 1e6) {
    return StringPrintf("depth_scale must be positive (units per metre), got %g", depth_scale);
  }
  return "";
}

bool CameraIntrinsics::HasDistortion() const {
  for (double d : distortion) {
    if (d != 0) return true;
  }
  return false;
}

Eigen::Matrix3d CameraIntrinsics::K() const {
  Eigen::Matrix3d k;
  k << fx, 0, cx, 0, fy, cy, 0, 0, 1;
  return k;
}

cv::Matx33d CameraIntrinsics::CvK() const { return cv::Matx33d(fx, 0, cx, 0, fy, cy, 0, 0, 1); }

cv::Mat CameraIntrinsics::CvDistortion() const {
  cv::Mat d(1, 5, CV_64F);
  for (int i = 0; i < 5; ++i) d.at<double>(0, i) = distortion[i];
  return d;
}

}  // namespace arpos
