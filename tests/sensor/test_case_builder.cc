#include "sensor/test_case_builder.h"

#include <opencv2/imgcodecs.hpp>

#include "sensor/tum_io.h"
#include "util/file.h"

namespace arpos::testing {

CaseConfig TinyCaseConfig(const TinyCaseOptions& options) {
  CaseConfig config;
  config.camera.width = options.width;
  config.camera.height = options.height;
  config.camera.fx = config.camera.fy = 0.8 * options.width;
  config.camera.cx = (options.width - 1) / 2.0;
  config.camera.cy = (options.height - 1) / 2.0;
  config.camera.depth_scale = 5000;
  config.dictionary = "DICT_4X4_250";
  config.room_markers = {0.15, 0, 49};
  config.room_origin_id = 0;
  config.body_markers = {0.03, 100, 199};
  return config;
}

namespace {

void WriteSequence(const std::filesystem::path& dir, const TinyCaseOptions& options, bool body) {
  CreateDirectories(dir / "rgb");
  CreateDirectories(dir / "depth");
  std::vector<ImageListEntry> rgb, depth;
  std::vector<StampedPose> gt;
  for (int i = 0; i < options.frames; ++i) {
    const double t = 1.0 + i / 30.0;
    const std::string name = std::to_string(i) + ".png";
    cv::Mat color(options.height, options.width, CV_8UC3, cv::Scalar(40 * i, 100, 200));
    cv::Mat d(options.height, options.width, CV_16UC1, cv::Scalar(5000 + 100 * i));
    cv::imwrite((dir / "rgb" / name).string(), color);
    cv::imwrite((dir / "depth" / name).string(), d);
    rgb.push_back({t, "rgb/" + name, 0});
    depth.push_back({t, "depth/" + name, 0});
    gt.push_back({t, Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.01 * i, 0, 1))});
  }
  WriteImageList(dir / "rgb.txt", rgb, "colour images");
  WriteImageList(dir / "depth.txt", depth, "depth images");
  if (options.with_ground_truth) {
    WriteTrajectory(dir / "groundtruth.txt", gt, "camera -> room");
    if (body) WriteTrajectory(dir / "body_groundtruth.txt", gt, "model -> room");
  }
}

}  // namespace

void WriteTinyCase(const std::filesystem::path& root, const TinyCaseOptions& options) {
  CreateDirectories(root);
  SaveCaseConfig(TinyCaseConfig(options), root / "case.yaml");
  WriteFileAtomic(root / "reference_model.ply",
                  "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                  "property float z\nelement face 4\nproperty list uchar int vertex_indices\n"
                  "end_header\n0 0 0\n0.1 0 0\n0 0.1 0\n0 0 0.1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n"
                  "3 1 2 3\n");
  WriteMatrix4(root / "target_pose.txt", Eigen::Matrix4d::Identity(), "model -> room");
  WriteSequence(root / "room", options, false);
  WriteSequence(root / "body_scan", options, true);
  WriteSequence(root / "tracking" / "a", options, true);
}

}  // namespace arpos::testing
