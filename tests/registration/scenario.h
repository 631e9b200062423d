#pragma once
// Registration scenarios with exact ground truth for the benchmark and the
// report: a depth frame of the patient (camera frame) against the reference
// model (model frame), from a simulated case folder (`arpos simulate`) or,
// without one, from the test renderer on the MakeHuman body.

#include <filesystem>
#include <string>
#include <vector>

#include "geometry/rigid3.h"
#include "geometry/triangle_mesh.h"
#include "registration/point_cloud.h"
#include "sensor/intrinsics.h"

namespace arpos::testing {

struct FrameScenario {
  std::string description;
  PointCloud body_in_camera;  ///< full-resolution depth points on the body
  Rigid3d model_from_camera;  ///< exact
  Rigid3d room_from_camera;   ///< exact (identity room for synthetic scenarios)
};

struct CaseScenario {
  std::string description;
  TriangleMesh reference_model;  ///< model frame (with the case's noise)
  TriangleMesh true_surface;     ///< model frame; the reference model itself in a case
  Rigid3d room_from_model;       ///< exact, constant during the body scan
  CameraIntrinsics intrinsics;
  std::vector<FrameScenario> frames;
};

/// Frames `frame_indices` of `case_dir`/body_scan, body points selected with
/// the ground truth (depth points within `body_margin_m` of the posed
/// reference model; the couch and room are dropped).
CaseScenario LoadCaseScenario(const std::filesystem::path& case_dir,
                              const std::vector<int>& frame_indices, double body_margin_m = 0.02);

/// Synthetic: views of the MakeHuman body lying on its back (model frame =
/// the mesh's), camera 0.9-1.2 m above, exact depth plus Gaussian noise of
/// `depth_noise_m` quantised to 0.2 mm, `num_frames` views around the body.
CaseScenario SyntheticScenario(int num_frames, double depth_noise_m, uint64_t seed);

/// Error of an estimated model_from_camera against the truth, measured at the
/// model origin (the isocentre): translation in m and rotation in rad of
/// camera_from_model_truth^-1 * camera_from_model_estimate.
double ModelTranslationError(const Rigid3d& model_from_camera_truth,
                             const Rigid3d& model_from_camera_estimate);
double ModelRotationErrorRad(const Rigid3d& model_from_camera_truth,
                             const Rigid3d& model_from_camera_estimate);

}  // namespace arpos::testing
