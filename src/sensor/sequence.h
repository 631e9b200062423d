#pragma once
/// A TUM-layout RGB-D sequence folder (DATASET.md): rgb.txt, depth.txt, images,
/// optional groundtruth.txt and body_groundtruth.txt.

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "sensor/intrinsics.h"
#include "sensor/rgbd_frame.h"
#include "sensor/tum_io.h"

namespace arpos {

/// Colour and depth images associated within this many seconds form a frame.
constexpr double kFrameAssociationS = 0.02;

class Sequence {
 public:
  /// Reads the lists and associates colour with depth. Throws InputError
  /// naming the file when a list is missing or malformed, its timestamps do
  /// not increase (naming the line), or no frame pairs up.
  /// Images are not read here.
  static Sequence Open(const std::filesystem::path& folder);
  /// Same, but every colour entry is a frame; those without a depth partner
  /// have none (has_depth(i) is false). For tracking, where a frame without
  /// depth is still a frame to report.
  static Sequence OpenEveryColourFrame(const std::filesystem::path& folder);

  const std::filesystem::path& folder() const { return folder_; }
  size_t size() const { return frames_.size(); }
  double timestamp_s(size_t i) const { return frames_[i].timestamp_s; }
  std::filesystem::path color_path(size_t i) const { return folder_ / frames_[i].color; }
  std::filesystem::path depth_path(size_t i) const { return folder_ / frames_[i].depth; }
  bool has_depth(size_t i) const { return !frames_[i].depth.empty(); }
  /// Frame i's depth timestamp minus its colour timestamp (0 without depth).
  double depth_delay_s(size_t i) const { return frames_[i].depth_delay_s; }
  /// Colour entries that found no depth partner within kFrameAssociationS.
  size_t unmatched_color() const { return unmatched_color_; }

  /// Loads frame i. Throws InputError naming the image file if it is missing,
  /// unreadable, of the wrong type (colour must be 8-bit, depth 16-bit single
  /// channel) or of a size other than `intrinsics`' width x height.
  RgbdFrame LoadFrame(size_t i, const CameraIntrinsics& intrinsics) const;
  /// Loads frame i keeping going without depth: colour problems throw as in
  /// LoadFrame; a missing, unreadable or ill-shaped depth image (or none in
  /// the list) leaves `depth` empty and says why in `*depth_problem`.
  RgbdFrame LoadFrameColourFirst(size_t i, const CameraIntrinsics& intrinsics, std::string* depth_problem) const;
  /// Frame i's colour image alone (BGR, CV_8UC3), checked as LoadFrame checks
  /// it (InputError naming the file); the depth image is not read.
  cv::Mat LoadColour(size_t i, const CameraIntrinsics& intrinsics) const;
  /// Frame i's depth image alone (CV_16UC1), checked as LoadFrame checks it
  /// (InputError naming the file, or the frame when depth.txt lists none).
  cv::Mat LoadDepth(size_t i, const CameraIntrinsics& intrinsics) const;

  /// groundtruth.txt / body_groundtruth.txt if present.
  std::optional<std::vector<StampedPose>> CameraGroundTruth() const;
  std::optional<std::vector<StampedPose>> BodyGroundTruth() const;

 private:
  static Sequence OpenImpl(const std::filesystem::path& folder, bool every_colour_frame);
  struct FramePaths {
    double timestamp_s;
    std::string color, depth;
    double depth_delay_s = 0;
  };
  std::filesystem::path folder_;
  std::vector<FramePaths> frames_;
  size_t unmatched_color_ = 0;
};

}  // namespace arpos
