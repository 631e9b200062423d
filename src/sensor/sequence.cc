#include "sensor/sequence.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "util/check.h"
#include "util/string_util.h"

namespace arpos {

Sequence Sequence::Open(const std::filesystem::path& folder) { return OpenImpl(folder, false); }

Sequence Sequence::OpenEveryColourFrame(const std::filesystem::path& folder) { return OpenImpl(folder, true); }

Sequence Sequence::OpenImpl(const std::filesystem::path& folder, bool every_colour_frame) {
  if (!std::filesystem::is_directory(folder)) {
    ARPOS_INPUT_ERROR(folder.string() << ": sequence folder does not exist");
  }
  Sequence seq;
  seq.folder_ = folder;
  for (const char* list : {"rgb.txt", "depth.txt"}) {
    if (!std::filesystem::exists(folder / list)) {
      ARPOS_INPUT_ERROR((folder / list).string() << ": missing (every sequence needs rgb.txt and depth.txt)");
    }
  }
  const auto rgb = ReadImageList(folder / "rgb.txt");
  const auto depth = ReadImageList(folder / "depth.txt");
  // Frames are used in list order as time order (tracking, association).
  for (const auto* list : {&rgb, &depth}) {
    const std::string problem = ImageListTimestampProblem(*list);
    if (!problem.empty()) {
      ARPOS_INPUT_ERROR((folder / (list == &rgb ? "rgb.txt" : "depth.txt")).string()
                        << ": " << problem);
    }
  }
  std::vector<double> rgb_t, depth_t;
  for (const auto& e : rgb) rgb_t.push_back(e.timestamp_s);
  for (const auto& e : depth) depth_t.push_back(e.timestamp_s);
  const auto pairs = AssociateTimestamps(rgb_t, depth_t, kFrameAssociationS);
  if (pairs.empty()) {
    ARPOS_INPUT_ERROR(folder.string() << ": no colour image has a depth image within "
                                      << kFrameAssociationS << " s (" << rgb.size()
                                      << " colour, " << depth.size() << " depth entries)");
  }
  if (every_colour_frame) {
    std::vector<std::string> partner(rgb.size());
    std::vector<double> delay(rgb.size(), 0.0);
    for (const auto& [i, j] : pairs) {
      partner[i] = depth[j].relative_path;
      delay[i] = depth[j].timestamp_s - rgb[i].timestamp_s;
    }
    for (size_t i = 0; i < rgb.size(); ++i) {
      seq.frames_.push_back({rgb[i].timestamp_s, rgb[i].relative_path, partner[i], delay[i]});
    }
  } else {
    for (const auto& [i, j] : pairs) {
      seq.frames_.push_back({rgb[i].timestamp_s, rgb[i].relative_path, depth[j].relative_path,
                             depth[j].timestamp_s - rgb[i].timestamp_s});
    }
  }
  seq.unmatched_color_ = rgb.size() - pairs.size();
  return seq;
}

namespace {
// A colour image depth.txt pairs with no depth image.
std::string NoDepthListed() {
  return "no depth image within " + StringPrintf("%.3f", kFrameAssociationS) + " s in depth.txt";
}

// The depth image of a frame, or empty with the reason.
cv::Mat ReadDepth(const std::filesystem::path& depth_file, const CameraIntrinsics& intrinsics, std::string* problem) {
  if (!std::filesystem::exists(depth_file)) {
    *problem = depth_file.string() + ": missing depth image";
    return cv::Mat();
  }
  cv::Mat depth = cv::imread(depth_file.string(), cv::IMREAD_UNCHANGED);
  if (depth.empty()) {
    *problem = depth_file.string() + ": unreadable or corrupt image";
    return cv::Mat();
  }
  if (depth.type() != CV_16UC1) {
    *problem = depth_file.string() + ": depth must be 16-bit single-channel, got " +
               std::to_string(depth.channels()) + " channel(s) of " + (depth.depth() == CV_8U ? "8" : "non-16") +
               "-bit";
    return cv::Mat();
  }
  if (depth.cols != intrinsics.width || depth.rows != intrinsics.height) {
    *problem = depth_file.string() + ": image is " + std::to_string(depth.cols) + "x" + std::to_string(depth.rows) +
               " but case.yaml camera is " + std::to_string(intrinsics.width) + "x" +
               std::to_string(intrinsics.height);
    return cv::Mat();
  }
  return depth;
}
}  // namespace

cv::Mat Sequence::LoadColour(size_t i, const CameraIntrinsics& intrinsics) const {
  ARPOS_CHECK(i < frames_.size(), "frame " << i << " out of range (" << frames_.size() << ")");
  const auto color_file = color_path(i);
  if (!std::filesystem::exists(color_file)) ARPOS_INPUT_ERROR(color_file.string() << ": missing colour image");
  cv::Mat color = cv::imread(color_file.string(), cv::IMREAD_UNCHANGED);
  if (color.empty()) ARPOS_INPUT_ERROR(color_file.string() << ": unreadable or corrupt image");
  if (color.depth() != CV_8U) {
    ARPOS_INPUT_ERROR(color_file.string() << ": colour must be 8-bit per channel");
  }
  if (color.channels() == 1) {
    cv::Mat bgr;
    cv::cvtColor(color, bgr, cv::COLOR_GRAY2BGR);
    color = bgr;
  } else if (color.channels() == 4) {
    cv::Mat bgr;
    cv::cvtColor(color, bgr, cv::COLOR_BGRA2BGR);
    color = bgr;
  }
  if (color.cols != intrinsics.width || color.rows != intrinsics.height) {
    ARPOS_INPUT_ERROR(color_file.string() << ": image is " << color.cols << "x" << color.rows
                                          << " but case.yaml camera is " << intrinsics.width << "x"
                                          << intrinsics.height);
  }
  return color;
}

RgbdFrame Sequence::LoadFrameColourFirst(size_t i, const CameraIntrinsics& intrinsics,
                                         std::string* depth_problem) const {
  ARPOS_CHECK(i < frames_.size(), "frame " << i << " out of range (" << frames_.size() << ")");
  ARPOS_CHECK(depth_problem != nullptr, "depth_problem must not be null");
  depth_problem->clear();
  RgbdFrame frame;
  frame.index = static_cast<int>(i);
  frame.timestamp_s = frames_[i].timestamp_s;
  frame.depth_scale = intrinsics.depth_scale;
  frame.color = LoadColour(i, intrinsics);
  if (frames_[i].depth.empty()) {
    *depth_problem = NoDepthListed();
  } else {
    frame.depth = ReadDepth(depth_path(i), intrinsics, depth_problem);
    if (!frame.depth.empty()) frame.depth_delay_s = frames_[i].depth_delay_s;
  }
  return frame;
}

cv::Mat Sequence::LoadDepth(size_t i, const CameraIntrinsics& intrinsics) const {
  ARPOS_CHECK(i < frames_.size(), "frame " << i << " out of range (" << frames_.size() << ")");
  if (frames_[i].depth.empty()) {
    ARPOS_INPUT_ERROR(color_path(i).string() << ": " << NoDepthListed());
  }
  std::string problem;
  cv::Mat depth = ReadDepth(depth_path(i), intrinsics, &problem);
  if (!problem.empty()) ARPOS_INPUT_ERROR(problem);
  return depth;
}

RgbdFrame Sequence::LoadFrame(size_t i, const CameraIntrinsics& intrinsics) const {
  ARPOS_CHECK(i < frames_.size(), "frame " << i << " out of range (" << frames_.size() << ")");
  std::string depth_problem;
  RgbdFrame frame = LoadFrameColourFirst(i, intrinsics, &depth_problem);
  if (!depth_problem.empty()) ARPOS_INPUT_ERROR(depth_problem);
  return frame;
}

std::optional<std::vector<StampedPose>> Sequence::CameraGroundTruth() const {
  const auto path = folder_ / "groundtruth.txt";
  if (!std::filesystem::exists(path)) return std::nullopt;
  return ReadTrajectory(path);
}

std::optional<std::vector<StampedPose>> Sequence::BodyGroundTruth() const {
  const auto path = folder_ / "body_groundtruth.txt";
  if (!std::filesystem::exists(path)) return std::nullopt;
  return ReadTrajectory(path);
}

}  // namespace arpos
