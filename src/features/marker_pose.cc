#include "features/marker_pose.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <vector>

#include <opencv2/calib3d.hpp>

#include "features/edge_refinement.h"
#include "geometry/so3.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

double Cross2(const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return a.x() * b.y() - a.y() * b.x();
}

/// Projective centre of a quadrilateral: intersection of its diagonals.
Eigen::Vector2d DiagonalIntersection(const std::array<Eigen::Vector2d, 4>& q) {
  const Eigen::Vector2d d1 = q[2] - q[0], d2 = q[3] - q[1];
  const double den = Cross2(d1, d2);
  if (std::abs(den) < 1e-12) return 0.25 * (q[0] + q[1] + q[2] + q[3]);
  const double s = Cross2(q[1] - q[0], d2) / den;
  return q[0] + s * d1;
}

bool InsideConvexQuad(const std::array<Eigen::Vector2d, 4>& q, const Eigen::Vector2d& p) {
  int sign = 0;
  for (int k = 0; k < 4; ++k) {
    const double c = Cross2(q[(k + 1) % 4] - q[k], p - q[k]);
    const int s = c > 0 ? 1 : (c < 0 ? -1 : 0);
    if (s == 0) continue;
    if (sign == 0) sign = s;
    if (s != sign) return false;
  }
  return true;
}

double DepthMetres(const cv::Mat& depth, int u, int v, double depth_scale) {
  if (depth.type() == CV_16UC1) {
    const uint16_t d = depth.ptr<uint16_t>(v)[u];
    return d == 0 ? 0.0 : d / depth_scale;
  }
  const float d = depth.ptr<float>(v)[u];
  return std::isfinite(d) && d > 0 ? static_cast<double>(d) : 0.0;
}

/// Points behind the plane fit, kept for the joint refinement.
struct DepthPoints {
  std::vector<Eigen::Vector3d> points;
  std::vector<double> residual;
  std::vector<double> weight;
  std::vector<char> inlier;
};

DepthPlane FitPlaneToPoints(DepthPoints* dp, const MarkerPoseOptions& options) {
  DepthPlane plane;
  const int n = static_cast<int>(dp->points.size());
  plane.num_points = n;
  if (n < std::max(3, options.min_depth_points)) return plane;
  dp->weight.assign(n, 1.0);
  dp->residual.assign(n, 0.0);
  dp->inlier.assign(n, 1);
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ(), centroid = Eigen::Vector3d::Zero();
  double scale = 0;
  std::vector<double> abs_res(n);
  for (int iter = 0; iter < 8; ++iter) {
    double wsum = 0;
    centroid.setZero();
    for (int i = 0; i < n; ++i) {
      centroid += dp->weight[i] * dp->points[i];
      wsum += dp->weight[i];
    }
    if (wsum <= 0) return plane;
    centroid /= wsum;
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector3d d = dp->points[i] - centroid;
      cov += dp->weight[i] * d * d.transpose();
    }
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
    normal = eig.eigenvectors().col(0);
    for (int i = 0; i < n; ++i) {
      dp->residual[i] = normal.dot(dp->points[i] - centroid);
      abs_res[i] = std::abs(dp->residual[i]);
    }
    std::nth_element(abs_res.begin(), abs_res.begin() + n / 2, abs_res.end());
    scale = std::max(1.4826 * abs_res[n / 2], 2e-4);
    const double c = 4.685 * scale;  // Tukey biweight
    for (int i = 0; i < n; ++i) {
      const double u = dp->residual[i] / c;
      dp->weight[i] = std::abs(u) < 1 ? (1 - u * u) * (1 - u * u) : 0.0;
    }
  }
  double sum_sq = 0;
  int inliers = 0;
  for (int i = 0; i < n; ++i) {
    dp->inlier[i] = std::abs(dp->residual[i]) <= 3.0 * scale;
    if (!dp->inlier[i]) continue;
    sum_sq += dp->residual[i] * dp->residual[i];
    ++inliers;
  }
  if (normal.dot(centroid) > 0) normal = -normal;  // towards the camera at the origin
  plane.normal_in_camera = normal;
  plane.point_in_camera = centroid;
  plane.num_inliers = inliers;
  plane.rms_m = inliers > 0 ? std::sqrt(sum_sq / inliers) : 0;
  plane.valid = inliers >= options.min_depth_points && plane.rms_m <= options.max_depth_plane_rms_m;
  return plane;
}

DepthPlane FitDepthPlaneImpl(const cv::Mat& depth, const std::array<Eigen::Vector2d, 4>& corners_px,
                             const CameraIntrinsics& intrinsics, const MarkerPoseOptions& options,
                             DepthPoints* dp) {
  ARPOS_CHECK(depth.type() == CV_16UC1 || depth.type() == CV_32FC1,
              "depth must be CV_16UC1 or CV_32FC1, got type " << depth.type());
  ARPOS_CHECK(depth.cols == intrinsics.width && depth.rows == intrinsics.height,
              "depth is " << depth.cols << "x" << depth.rows << " but the camera is "
                          << intrinsics.width << "x" << intrinsics.height);
  const Eigen::Vector2d centre = DiagonalIntersection(corners_px);
  std::array<Eigen::Vector2d, 4> region;
  double x_min = 1e300, x_max = -1e300, y_min = 1e300, y_max = -1e300;
  for (int k = 0; k < 4; ++k) {
    region[k] = centre + options.depth_region_scale * (corners_px[k] - centre);
    x_min = std::min(x_min, region[k].x());
    x_max = std::max(x_max, region[k].x());
    y_min = std::min(y_min, region[k].y());
    y_max = std::max(y_max, region[k].y());
  }
  const PixelUndistorter undistorter(intrinsics);
  dp->points.clear();
  const int u0 = std::max(0, static_cast<int>(std::ceil(x_min)));
  const int u1 = std::min(depth.cols - 1, static_cast<int>(std::floor(x_max)));
  const int v0 = std::max(0, static_cast<int>(std::ceil(y_min)));
  const int v1 = std::min(depth.rows - 1, static_cast<int>(std::floor(y_max)));
  for (int v = v0; v <= v1; ++v) {
    for (int u = u0; u <= u1; ++u) {
      if (!InsideConvexQuad(region, Eigen::Vector2d(u, v))) continue;
      const double z = DepthMetres(depth, u, v, intrinsics.depth_scale);
      if (!(z > 0)) continue;
      const Eigen::Vector2d ideal = undistorter.Undistort(Eigen::Vector2d(u, v));
      dp->points.push_back(intrinsics.Unproject(ideal.x(), ideal.y(), z));
    }
  }
  return FitPlaneToPoints(dp, options);
}

double ReprojectionRms(const Rigid3d& camera_from_marker, const std::array<Eigen::Vector3d, 4>& obj,
                       const std::array<Eigen::Vector2d, 4>& ideal_px,
                       const CameraIntrinsics& intrinsics) {
  double sum_sq = 0;
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector3d p = camera_from_marker * obj[k];
    if (!(p.z() > 0)) return std::numeric_limits<double>::infinity();
    sum_sq += (intrinsics.Project(p) - ideal_px[k]).squaredNorm();
  }
  return std::sqrt(sum_sq / 4);
}

void DepthAgreement(const Rigid3d& camera_from_marker, const DepthPlane& plane, double* normal_deg,
                    double* distance_mm) {
  if (!plane.valid) {
    *normal_deg = *distance_mm = kNaN;
    return;
  }
  const Eigen::Vector3d z_axis = camera_from_marker.rotation * Eigen::Vector3d::UnitZ();
  *normal_deg = DegFromRad(std::acos(std::clamp(z_axis.dot(plane.normal_in_camera), -1.0, 1.0)));
  *distance_mm = 1000.0 * plane.SignedDistanceM(camera_from_marker.translation);
}

/// Gauss-Newton on (rotation, translation) with corner reprojection residuals
/// and depth point-to-marker-plane residuals.
Rigid3d RefineWithDepth(const Rigid3d& start, const std::array<Eigen::Vector3d, 4>& obj,
                        const std::array<Eigen::Vector2d, 4>& ideal_px,
                        const std::array<double, 4>& corner_sigma_px, const DepthPoints& dp,
                        const CameraIntrinsics& intrinsics, const MarkerPoseOptions& options) {
  Eigen::Matrix3d rot = start.RotationMatrix();
  Eigen::Vector3d t = start.translation;
  int num_inliers = 0;
  for (char in : dp.inlier) num_inliers += in ? 1 : 0;
  const double depth_weight =
      num_inliers > 0
          ? std::sqrt(std::min(
                1.0, static_cast<double>(options.depth_max_effective_points) / num_inliers)) /
                options.depth_sigma_m
          : 0.0;
  for (int iter = 0; iter < options.max_refine_iterations; ++iter) {
    Eigen::Matrix<double, 6, 6> jtj = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> jtr = Eigen::Matrix<double, 6, 1>::Zero();
    for (int k = 0; k < 4; ++k) {
      const Eigen::Vector3d rp = rot * obj[k];
      const Eigen::Vector3d p = rp + t;
      const double iz = 1.0 / p.z();
      const double w = 1.0 / std::max(options.corner_sigma_px, corner_sigma_px[k]);
      Eigen::Matrix<double, 2, 3> dproj;
      dproj << intrinsics.fx * iz, 0, -intrinsics.fx * p.x() * iz * iz, 0, intrinsics.fy * iz,
          -intrinsics.fy * p.y() * iz * iz;
      Eigen::Matrix<double, 3, 6> dp_dx;
      dp_dx.leftCols<3>() = -Skew(rp);
      dp_dx.rightCols<3>().setIdentity();
      const Eigen::Matrix<double, 2, 6> j = w * dproj * dp_dx;
      const Eigen::Vector2d r = w * (intrinsics.Project(p) - ideal_px[k]);
      jtj += j.transpose() * j;
      jtr += j.transpose() * r;
    }
    const Eigen::Vector3d n = rot.col(2);
    for (size_t i = 0; i < dp.points.size(); ++i) {
      if (!dp.inlier[i]) continue;
      const Eigen::Vector3d v = dp.points[i] - t;
      const double r = depth_weight * n.dot(v);
      Eigen::Matrix<double, 1, 6> j;
      j.leftCols<3>() = depth_weight * n.cross(v).transpose();
      j.rightCols<3>() = -depth_weight * n.transpose();
      jtj += j.transpose() * j;
      jtr += j.transpose() * r;
    }
    const Eigen::Matrix<double, 6, 1> step = -jtj.ldlt().solve(jtr);
    if (!step.allFinite()) break;
    rot = QuaternionFromRotationVector(step.head<3>()).toRotationMatrix() * rot;
    t += step.tail<3>();
    if (step.head<3>().norm() < 1e-9 && step.tail<3>().norm() < 1e-9) break;
  }
  return Rigid3d(ProjectToSO3(rot), t);
}

}  // namespace

const char* MarkerPoseStatusName(MarkerPoseStatus status) {
  switch (status) {
    case MarkerPoseStatus::kOk:
      return "ok";
    case MarkerPoseStatus::kAmbiguous:
      return "ambiguous";
    case MarkerPoseStatus::kDepthMismatch:
      return "depth_mismatch";
    case MarkerPoseStatus::kFailed:
      return "failed";
  }
  return "unknown";
}

std::string MarkerPoseOptions::Validate() const {
  if (!(depth_region_scale > 0.1 && depth_region_scale <= 1.0)) {
    return StringPrintf("depth_region_scale must be in (0.1, 1], got %g", depth_region_scale);
  }
  if (min_depth_points < 3) return "min_depth_points must be at least 3";
  if (!(max_depth_plane_rms_m > 0)) return "max_depth_plane_rms_m must be positive";
  if (!(max_depth_normal_error_deg > 0)) return "max_depth_normal_error_deg must be positive";
  if (!(max_depth_distance_error_m > 0)) return "max_depth_distance_error_m must be positive";
  if (!(min_unambiguous_ratio >= 1)) return "min_unambiguous_ratio must be at least 1";
  if (!(corner_sigma_px > 0)) return "corner_sigma_px must be positive";
  if (!(depth_sigma_m > 0)) return "depth_sigma_m must be positive";
  if (depth_max_effective_points < 1) return "depth_max_effective_points must be positive";
  if (max_refine_iterations < 0) return "max_refine_iterations must be non-negative";
  return "";
}

bool MarkerPoseOptions::Check(std::string* reason) const {
  const std::string r = Validate();
  if (reason != nullptr) *reason = r;
  return r.empty();
}

std::array<Eigen::Vector3d, 4> MarkerCornersInMarker(double marker_size_m) {
  const double h = 0.5 * marker_size_m;
  return {Eigen::Vector3d(-h, h, 0), Eigen::Vector3d(h, h, 0), Eigen::Vector3d(h, -h, 0),
          Eigen::Vector3d(-h, -h, 0)};
}

DepthPlane FitDepthPlaneInQuad(const cv::Mat& depth,
                               const std::array<Eigen::Vector2d, 4>& corners_px,
                               const CameraIntrinsics& intrinsics,
                               const MarkerPoseOptions& options) {
  DepthPoints dp;
  return FitDepthPlaneImpl(depth, corners_px, intrinsics, options, &dp);
}

MarkerPose EstimateMarkerPose(const MarkerObservation& observation, double marker_size_m,
                              const CameraIntrinsics& intrinsics, const cv::Mat& depth,
                              const MarkerPoseOptions& options) {
  ARPOS_CHECK(marker_size_m > 0, "marker size must be positive, got " << marker_size_m);
  const std::string bad = intrinsics.Validate();
  ARPOS_CHECK(bad.empty(), "invalid intrinsics: " << bad);
  std::string reason;
  ARPOS_CHECK(options.Check(&reason), "invalid MarkerPoseOptions: " << reason);

  MarkerPose pose;
  const PixelUndistorter undistorter(intrinsics);
  const std::array<Eigen::Vector3d, 4> obj = MarkerCornersInMarker(marker_size_m);
  std::array<Eigen::Vector2d, 4> ideal;
  std::vector<cv::Point3d> cv_obj;
  std::vector<cv::Point2d> cv_img;
  for (int k = 0; k < 4; ++k) {
    ideal[k] = undistorter.Undistort(observation.corners_px[k]);
    if (!ideal[k].allFinite()) {
      pose.message = "non-finite corner";
      return pose;
    }
    cv_obj.emplace_back(obj[k].x(), obj[k].y(), obj[k].z());
    cv_img.emplace_back(ideal[k].x(), ideal[k].y());
  }

  std::vector<cv::Mat> rvecs, tvecs;
  try {
    cv::solvePnPGeneric(cv_obj, cv_img, cv::Mat(intrinsics.CvK()), cv::noArray(), rvecs, tvecs,
                        false, cv::SOLVEPNP_IPPE_SQUARE);
  } catch (const cv::Exception& e) {
    pose.message = std::string("solvePnPGeneric failed: ") + e.what();
    return pose;
  }
  for (size_t i = 0; i < rvecs.size() && pose.num_solutions < 2; ++i) {
    cv::Mat r, t;
    rvecs[i].convertTo(r, CV_64F);
    tvecs[i].convertTo(t, CV_64F);
    const Rigid3d s = Rigid3d::FromRotationVector(
        Eigen::Vector3d(r.at<double>(0), r.at<double>(1), r.at<double>(2)),
        Eigen::Vector3d(t.at<double>(0), t.at<double>(1), t.at<double>(2)));
    if (!s.translation.allFinite() || !(s.translation.z() > 0)) continue;
    IppeSolution& sol = pose.solutions[pose.num_solutions++];
    sol.camera_from_marker = s;
    sol.reprojection_rms_px = ReprojectionRms(s, obj, ideal, intrinsics);
  }
  if (pose.num_solutions == 0) {
    pose.message = "IPPE returned no solution in front of the camera";
    return pose;
  }
  if (pose.num_solutions == 2 &&
      pose.solutions[1].reprojection_rms_px < pose.solutions[0].reprojection_rms_px) {
    std::swap(pose.solutions[0], pose.solutions[1]);
  }
  pose.ambiguity_ratio = pose.num_solutions < 2
                             ? std::numeric_limits<double>::infinity()
                             : pose.solutions[1].reprojection_rms_px /
                                   std::max(pose.solutions[0].reprojection_rms_px, 1e-300);

  DepthPoints dp;
  if (!depth.empty()) {
    pose.depth_plane = FitDepthPlaneImpl(depth, observation.corners_px, intrinsics, options, &dp);
  }
  for (int i = 0; i < pose.num_solutions; ++i) {
    DepthAgreement(pose.solutions[i].camera_from_marker, pose.depth_plane,
                   &pose.solutions[i].depth_normal_error_deg,
                   &pose.solutions[i].depth_distance_error_mm);
  }

  pose.chosen = 0;
  if (pose.depth_plane.valid) {
    if (pose.num_solutions == 2 &&
        pose.solutions[1].depth_normal_error_deg < pose.solutions[0].depth_normal_error_deg) {
      pose.chosen = 1;
    }
    const IppeSolution& c = pose.solutions[pose.chosen];
    const bool agrees =
        c.depth_normal_error_deg <= options.max_depth_normal_error_deg &&
        std::abs(c.depth_distance_error_mm) <= 1000.0 * options.max_depth_distance_error_m;
    if (agrees) {
      pose.status = MarkerPoseStatus::kOk;
      pose.chosen_by_depth = true;
    } else {
      pose.status = MarkerPoseStatus::kDepthMismatch;
      pose.message =
          StringPrintf("depth plane disagrees with both IPPE solutions (best: %.1f deg, %.1f mm)",
                       c.depth_normal_error_deg, c.depth_distance_error_mm);
      pose.chosen = 0;
    }
  } else {
    pose.status = pose.ambiguity_ratio >= options.min_unambiguous_ratio
                      ? MarkerPoseStatus::kOk
                      : MarkerPoseStatus::kAmbiguous;
  }

  pose.camera_from_marker = pose.solutions[pose.chosen].camera_from_marker;
  if (pose.chosen_by_depth && options.refine_with_depth) {
    pose.camera_from_marker = RefineWithDepth(pose.camera_from_marker, obj, ideal,
                                              observation.corner_sigma_px, dp, intrinsics, options);
    pose.refined_with_depth = true;
  }
  pose.reprojection_rms_px = ReprojectionRms(pose.camera_from_marker, obj, ideal, intrinsics);
  DepthAgreement(pose.camera_from_marker, pose.depth_plane, &pose.depth_normal_error_deg,
                 &pose.depth_distance_error_mm);
  return pose;
}

}  // namespace arpos
