#include "registration/scenario.h"

#include <random>

#include "geometry/mesh_io.h"
#include "geometry/so3.h"
#include "registration/mesh_cloud.h"
#include "registration/preprocess.h"
#include "registration/synthetic.h"
#include "sensor/case_folder.h"
#include "sensor/sequence.h"
#include "util/check.h"

namespace arpos::testing {

CaseScenario LoadCaseScenario(const std::filesystem::path& case_dir,
                              const std::vector<int>& frame_indices, double body_margin_m) {
  const CaseFolder folder = LoadCaseFolder(case_dir);
  const Sequence sequence = Sequence::Open(folder.body_scan_dir);
  const auto cameras = sequence.CameraGroundTruth();
  const auto bodies = sequence.BodyGroundTruth();
  ARPOS_CHECK(cameras && bodies, "case " << case_dir << " has no body_scan ground truth");
  CaseScenario scenario;
  scenario.description = "simulated case " + case_dir.string();
  scenario.reference_model = LoadTriangleMesh(folder.reference_model);
  scenario.true_surface = scenario.reference_model;
  scenario.intrinsics = folder.config.camera;
  scenario.room_from_model = bodies->front().room_from_x;
  const MeshDistance distance(scenario.reference_model);
  for (int index : frame_indices) {
    ARPOS_CHECK(index >= 0 && static_cast<size_t>(index) < sequence.size(),
                "frame " << index << " out of range");
    const RgbdFrame frame = sequence.LoadFrame(index, folder.config.camera);
    FrameScenario f;
    f.room_from_camera = (*cameras)[index].room_from_x;
    const Rigid3d room_from_model = (*bodies)[index].room_from_x;
    f.model_from_camera = room_from_model.Inverse() * f.room_from_camera;
    f.description = "body_scan frame " + std::to_string(index);
    const PointCloud all = DepthToCloud(frame, folder.config.camera);
    const PointCloud in_model = all.Transformed(f.model_from_camera);
    const std::vector<double> d = distance.Distances(in_model);
    std::vector<size_t> keep;
    for (size_t i = 0; i < d.size(); ++i) {
      if (d[i] < body_margin_m) keep.push_back(i);
    }
    f.body_in_camera = all.Select(keep);
    scenario.frames.push_back(std::move(f));
  }
  return scenario;
}

CaseScenario SyntheticScenario(int num_frames, double depth_noise_m, uint64_t seed) {
  CaseScenario scenario;
  scenario.description = "synthetic MakeHuman body, test renderer";
  scenario.true_surface = BodyMesh();
  scenario.reference_model = BodyMesh();
  scenario.intrinsics = TestIntrinsics();
  scenario.room_from_model = Rigid3d::Identity();
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::normal_distribution<double> noise(0.0, depth_noise_m);
  for (int i = 0; i < num_frames; ++i) {
    // Sweep from the legs to the head, 0.9-1.2 m above the front (+z).
    const double s = num_frames > 1 ? static_cast<double>(i) / (num_frames - 1) : 0.5;
    const Eigen::Vector3d eye(0.25 * u(rng), -0.55 + 1.1 * s, 1.05 + 0.15 * u(rng));
    const Eigen::Vector3d look(0.05 * u(rng), -0.45 + 0.9 * s, 0.1);
    const Rigid3d model_from_camera = LookAt(eye, look, Eigen::Vector3d(0, 1, 0));
    cv::Mat depth = RenderDepth(BodyMesh(), scenario.intrinsics, model_from_camera.Inverse());
    if (depth_noise_m > 0) {
      for (int v = 0; v < depth.rows; ++v) {
        for (int c = 0; c < depth.cols; ++c) {
          float& z = depth.at<float>(v, c);
          if (z > 0) z = static_cast<float>(std::round((z + noise(rng)) * 5000.0) / 5000.0);
        }
      }
    }
    FrameScenario f;
    f.description = "synthetic view " + std::to_string(i);
    f.model_from_camera = model_from_camera;
    f.room_from_camera = model_from_camera;
    f.body_in_camera = DepthToCloud(depth, 1.0, scenario.intrinsics);
    scenario.frames.push_back(std::move(f));
  }
  return scenario;
}

double ModelTranslationError(const Rigid3d& truth, const Rigid3d& estimate) {
  return (truth * estimate.Inverse()).translation.norm();
}

double ModelRotationErrorRad(const Rigid3d& truth, const Rigid3d& estimate) {
  return RotationAngleRad((truth * estimate.Inverse()).rotation);
}

}  // namespace arpos::testing
