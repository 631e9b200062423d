#include "plugins/openni2/openni2_frame.h"

#include <cmath>
#include <cstring>
#include <sstream>

#include <opencv2/imgproc.hpp>

#include "sensor/sequence.h"
#include "util/check.h"

namespace arpos {
namespace {

/// Copies `image` (bytes_per_pixel per pixel) into a Mat of `type`, or
/// returns an empty Mat and says why in `problem`. Row by row, because
/// OpenNI2's stride need not be a multiple of the pixel size.
cv::Mat CopyRows(const OpenNi2Image& image, const char* what, int bytes_per_pixel, int type,
                 std::string* problem) {
  std::ostringstream why;
  const long long row_bytes = static_cast<long long>(image.width) * bytes_per_pixel;
  if (image.data == nullptr) {
    why << what << ": no image";
  } else if (image.width <= 0 || image.height <= 0) {
    why << what << ": size " << image.width << "x" << image.height;
  } else if (image.stride_bytes < row_bytes) {
    why << what << ": rows " << image.stride_bytes << " bytes apart, shorter than a " << image.width
        << "-pixel row (" << row_bytes << " bytes)";
  } else if (const long long needed = static_cast<long long>(image.stride_bytes) * (image.height - 1) + row_bytes;
             image.data_size < needed) {
    why << what << ": " << image.data_size << " bytes for " << image.width << "x" << image.height << " pixels"
        << " (needs " << needed << ")";
  }
  if (!why.str().empty()) {
    *problem = why.str();
    return {};
  }
  cv::Mat copy(image.height, image.width, type);
  const auto* bytes = static_cast<const unsigned char*>(image.data);
  for (int y = 0; y < image.height; ++y) {
    std::memcpy(copy.ptr(y), bytes + static_cast<size_t>(y) * image.stride_bytes, static_cast<size_t>(row_bytes));
  }
  return copy;
}

void AddProblem(RgbdFrame* frame, const std::string& problem) {
  if (problem.empty()) return;
  frame->problem += (frame->problem.empty() ? "" : "; ") + problem;
}

}  // namespace

std::string OpenNi2PixelFormatName(openni::PixelFormat format) {
  switch (format) {
    case openni::PIXEL_FORMAT_DEPTH_1_MM: return "DEPTH_1_MM";
    case openni::PIXEL_FORMAT_DEPTH_100_UM: return "DEPTH_100_UM";
    case openni::PIXEL_FORMAT_SHIFT_9_2: return "SHIFT_9_2";
    case openni::PIXEL_FORMAT_SHIFT_9_3: return "SHIFT_9_3";
    case openni::PIXEL_FORMAT_RGB888: return "RGB888";
    case openni::PIXEL_FORMAT_YUV422: return "YUV422";
    case openni::PIXEL_FORMAT_GRAY8: return "GRAY8";
    case openni::PIXEL_FORMAT_GRAY16: return "GRAY16";
    case openni::PIXEL_FORMAT_JPEG: return "JPEG";
    case openni::PIXEL_FORMAT_YUYV: return "YUYV";
  }
  return "pixel format " + std::to_string(static_cast<int>(format));
}

double OpenNi2DepthScale(openni::PixelFormat format) {
  switch (format) {
    case openni::PIXEL_FORMAT_DEPTH_1_MM: return 1000.0;
    case openni::PIXEL_FORMAT_DEPTH_100_UM: return 10000.0;
    default: return 0.0;
  }
}

RgbdFrame RgbdFrameFromOpenNi2(const OpenNi2Image& color, const OpenNi2Image& depth) {
  RgbdFrame frame;
  frame.timestamp_s = static_cast<double>(color.timestamp_us) * 1e-6;
  std::string problem;
  if (color.format != openni::PIXEL_FORMAT_RGB888) {
    problem = "colour arrives as " + OpenNi2PixelFormatName(color.format) + ", not RGB888";
  } else if (cv::Mat rgb = CopyRows(color, "colour", 3, CV_8UC3, &problem); !rgb.empty()) {
    cv::cvtColor(rgb, frame.color, cv::COLOR_RGB2BGR);
  }
  AddProblem(&frame, problem);

  problem.clear();
  const double scale = OpenNi2DepthScale(depth.format);
  if (scale == 0) {
    problem = "depth arrives as " + OpenNi2PixelFormatName(depth.format) + ", not DEPTH_1_MM or DEPTH_100_UM";
  } else if (depth.width != color.width || depth.height != color.height) {
    std::ostringstream why;
    why << "depth is " << depth.width << "x" << depth.height << ", the colour " << color.width << "x" << color.height
        << ": not registered to the colour image";
    problem = why.str();
  } else {
    frame.depth = CopyRows(depth, "depth", 2, CV_16UC1, &problem);
    frame.depth_scale = scale;
    // Both on the device's clock: the depth's own instant, when it is one a
    // frame can pair (sensor/sequence.h); a farther one is not this colour
    // image's depth instant but a stream the source paired late, left at 0.
    const double delay_s =
        (static_cast<double>(depth.timestamp_us) - static_cast<double>(color.timestamp_us)) * 1e-6;
    if (!frame.depth.empty() && std::abs(delay_s) < kFrameAssociationS)
      frame.depth_delay_s = delay_s;
  }
  AddProblem(&frame, problem);
  return frame;
}

CameraIntrinsics IntrinsicsFromOpenNi2FieldOfView(int width, int height, double horizontal_fov_rad,
                                                  double vertical_fov_rad, double depth_scale) {
  for (const auto& [name, fov] : {std::pair<const char*, double>{"horizontal", horizontal_fov_rad},
                                  std::pair<const char*, double>{"vertical", vertical_fov_rad}}) {
    if (!(fov > 0 && fov < M_PI)) {
      ARPOS_INPUT_ERROR("the camera reports no usable " << name << " field of view (" << fov
                        << " rad), so its intrinsics are unknown");
    }
  }
  CameraIntrinsics k;
  k.width = width;
  k.height = height;
  k.fx = width / (2.0 * std::tan(horizontal_fov_rad / 2));
  k.fy = height / (2.0 * std::tan(vertical_fov_rad / 2));
  k.cx = width / 2.0;
  k.cy = height / 2.0;
  k.depth_scale = depth_scale;
  if (const std::string bad = k.Validate(); !bad.empty()) {
    ARPOS_INPUT_ERROR("the camera's fields of view (" << horizontal_fov_rad << " x " << vertical_fov_rad
                      << " rad at " << width << "x" << height << ") give implausible intrinsics: " << bad);
  }
  return k;
}

}  // namespace arpos
