#include "room_map/landmark_triangulation.h"

#include <Eigen/Cholesky>
#include <climits>
#include <cmath>
#include <opencv2/calib3d.hpp>

#include "room_map/keypoints.h"

namespace arpos {

const std::uint8_t* MedoidDescriptor(const std::vector<const std::uint8_t*>& descriptors) {
  const std::uint8_t* best = nullptr;
  int best_sum = INT32_MAX;
  for (const std::uint8_t* a : descriptors) {
    int sum = 0;
    for (const std::uint8_t* b : descriptors) sum += HammingDistance32(a, b);
    if (sum < best_sum) {
      best_sum = sum;
      best = a;
    }
  }
  return best;
}

std::vector<Eigen::Vector2d> IdealPixels(const std::vector<Eigen::Vector2d>& px,
                                         const CameraIntrinsics& K) {
  if (!K.HasDistortion() || px.empty()) return px;
  std::vector<cv::Point2d> in, out;
  for (const auto& p : px) in.emplace_back(p.x(), p.y());
  cv::undistortPoints(in, out, K.CvK(), K.CvDistortion(), cv::noArray(), K.CvK());
  std::vector<Eigen::Vector2d> result;
  for (const auto& p : out) result.emplace_back(p.x, p.y);
  return result;
}

std::optional<TriangulatedLandmark> TriangulateLandmark(
    const std::vector<LandmarkObservation>& obs, const std::vector<Rigid3d>& camera_from_room,
    const CameraIntrinsics& K, const LandmarkTriangulationOptions& options) {
  if (static_cast<int>(obs.size()) < options.min_observations) return std::nullopt;
  // Start: the nearest observation with depth (its depth is the most precise).
  int start = -1;
  for (size_t k = 0; k < obs.size(); ++k) {
    if (obs[k].depth_m > 0 && (start < 0 || obs[k].depth_m < obs[start].depth_m))
      start = static_cast<int>(k);
  }
  if (start < 0) return std::nullopt;
  TriangulatedLandmark out;
  Eigen::Vector3d& X = out.point_in_room;
  X = camera_from_room[obs[start].camera].Inverse() *
      K.Unproject(obs[start].px.x(), obs[start].px.y(), obs[start].depth_m);
  out.inlier.assign(obs.size(), true);
  const double w = 1.0 / (options.keypoint_sigma_px * options.keypoint_sigma_px);
  for (int pass = 0; pass < 2; ++pass) {
    for (int it = 0; it < 5; ++it) {
      Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
      Eigen::Vector3d g = Eigen::Vector3d::Zero();
      for (size_t k = 0; k < obs.size(); ++k) {
        if (!out.inlier[k]) continue;
        const Rigid3d& T = camera_from_room[obs[k].camera];
        const Eigen::Matrix3d R = T.RotationMatrix();
        const Eigen::Vector3d p = T * X;
        if (p.z() < 0.05) continue;
        const double iz = 1.0 / p.z();
        Eigen::Matrix<double, 2, 3> J;
        J << K.fx * iz, 0, -K.fx * p.x() * iz * iz, 0, K.fy * iz, -K.fy * p.y() * iz * iz;
        J = J * R;
        const Eigen::Vector2d r(K.fx * p.x() * iz + K.cx - obs[k].px.x(),
                                K.fy * p.y() * iz + K.cy - obs[k].px.y());
        H += w * J.transpose() * J;
        g += w * J.transpose() * r;
        if (obs[k].depth_m > 0) {
          const double sz = options.DepthSigmaM(obs[k].depth_m);
          const Eigen::RowVector3d Jz = R.row(2);
          H += Jz.transpose() * Jz / (sz * sz);
          g += Jz.transpose() * (p.z() - obs[k].depth_m) / (sz * sz);
        }
      }
      const Eigen::Vector3d step = H.ldlt().solve(-g);
      if (!step.allFinite()) return std::nullopt;
      X += step;
      if (step.norm() < 1e-6) break;
    }
    // Outliers as the adjustment drops them, then solve once more.
    out.inliers = 0;
    for (size_t k = 0; k < obs.size(); ++k) {
      const Eigen::Vector3d p = camera_from_room[obs[k].camera] * X;
      if (p.z() < 0.05) return std::nullopt;
      const double e = (K.Project(p) - obs[k].px).norm();
      const bool z_ok =
          !(obs[k].depth_m > 0) || std::abs(p.z() - obs[k].depth_m) <
                                       options.outlier_sigmas * options.DepthSigmaM(obs[k].depth_m);
      out.inlier[k] = e < options.outlier_sigmas * options.keypoint_sigma_px && z_ok;
      out.inliers += out.inlier[k];
    }
    if (out.inliers < options.min_observations) return std::nullopt;
  }
  if (!X.allFinite()) return std::nullopt;
  return out;
}

}  // namespace arpos
