#pragma once
/// One RGB-D frame as a camera source delivers it.

#include <chrono>
#include <opencv2/core.hpp>
#include <optional>
#include <string>

#include "geometry/rigid3.h"

namespace arpos {

struct RgbdFrame {
  int index = -1;            ///< 0-based index in its sequence
  double timestamp_s = 0;    ///< colour timestamp
  cv::Mat color;             ///< CV_8UC3, BGR
  cv::Mat depth;             ///< CV_16UC1, registered to colour, 0 = no reading
  /// When the depth was captured after the colour (its depth.txt timestamp
  /// minus timestamp_s; a camera without colour-depth sync): 0 when the same
  /// instant or not known.
  double depth_delay_s = 0;
  double depth_scale = 1000; ///< depth units per metre
  /// What is wrong with this frame, empty when it is whole: colour that
  /// could not be read (then `color` is empty), depth missing or unreadable
  /// (then `depth` is empty). A source reports such frames as data.
  std::string problem;
  /// When the frame reached the program (the source's capture thread, or
  /// when a recording's file was read): where latency is counted from.
  std::chrono::steady_clock::time_point arrival{};
  /// Ground truth, when the source knows it (the simulator): the camera ->
  /// room and reference model -> room poses of this frame. The recorder
  /// writes them as groundtruth.txt and body_groundtruth.txt.
  std::optional<Rigid3d> true_room_from_camera;
  std::optional<Rigid3d> true_room_from_model;

  /// Depth in metres at pixel (u, v); 0 if there is no reading.
  double DepthM(int u, int v) const {
    return depth.at<uint16_t>(v, u) / depth_scale;
  }
};

}  // namespace arpos
