#include "room_map/pose_refiner.h"

#include <cmath>
#include <sstream>

#include <Eigen/Cholesky>

#include "geometry/so3.h"
#include "sensor/depth_timing.h"

namespace arpos {

void PoseCorrespondences::clear() {
  depth_motion_covariance.setZero();
  plane_point_in_room.clear();
  plane_normal_in_room.clear();
  plane_ray.clear();
  plane_depth_m.clear();
  plane_inv_sigma.clear();
  points_in_room.clear();
  pixels.clear();
  inv_sigma_px.clear();
  depth_m.clear();
  inv_sigma_depth.clear();
  group.clear();
  tag.clear();
}

void PoseCorrespondences::reserve(size_t n) {
  points_in_room.reserve(n);
  pixels.reserve(n);
  inv_sigma_px.reserve(n);
  depth_m.reserve(n);
  inv_sigma_depth.reserve(n);
  group.reserve(n);
  tag.reserve(n);
}

void PoseCorrespondences::Add(const Eigen::Vector3d& point_in_room, const Eigen::Vector2d& pixel,
                              double sigma_px, CorrespondenceGroup g, int t, double depth,
                              double sigma_depth_m) {
  points_in_room.push_back(point_in_room);
  pixels.push_back(pixel);
  inv_sigma_px.push_back(static_cast<float>(1.0 / sigma_px));
  const bool has_depth = depth > 0 && sigma_depth_m > 0;
  depth_m.push_back(has_depth ? static_cast<float>(depth) : 0.f);
  inv_sigma_depth.push_back(has_depth ? static_cast<float>(1.0 / sigma_depth_m) : 0.f);
  group.push_back(g);
  tag.push_back(t);
}

void PoseCorrespondences::AddPlaneDepth(const Eigen::Vector3d& point_in_room, const Eigen::Vector3d& normal_in_room,
                                        const Eigen::Vector2d& ray_xy, double depth_m, double sigma_m) {
  plane_point_in_room.push_back(point_in_room);
  plane_normal_in_room.push_back(normal_in_room);
  plane_ray.push_back(ray_xy);
  plane_depth_m.push_back(static_cast<float>(depth_m));
  plane_inv_sigma.push_back(static_cast<float>(1.0 / sigma_m));
}

std::string PoseRefinerOptions::Validate() const {
  std::ostringstream out;
  if (max_iterations < 1) out << "max_iterations must be at least 1";
  else if (huber_iterations < 0) out << "huber_iterations must not be negative";
  else if (!(marker_huber > 0) || !(keypoint_tukey > 0) || !(inlier_threshold > 0))
    out << "robust thresholds must be positive";
  return out.str();
}

bool PoseRefinerOptions::Check(std::string* reason) const {
  const std::string r = Validate();
  if (reason) *reason = r;
  return r.empty();
}

namespace {

inline double HuberWeight(double r, double k) { return r <= k ? 1.0 : k / r; }
inline double TukeyWeight(double r, double c) {
  if (r >= c) return 0.0;
  const double x = r / c;
  const double w = 1 - x * x;
  return w * w;
}

using Mat6 = Eigen::Matrix<double, 6, 6>;
using Vec6 = Eigen::Matrix<double, 6, 1>;

// One point correspondence's weighted normal-equation terms at its
// camera-frame point p: reprojection (H_pixel, shared into the markers'
// information) and depth; used = false when it carries no weight.
struct PointTerms {
  Mat6 H_pixel, H_depth;
  Vec6 g, g_depth;
  bool used = false;
};

inline PointTerms PointTermsAt(const Eigen::Vector3d& p, const PoseCorrespondences& corr, size_t i,
                               const CameraIntrinsics& K, bool tukey,
                               const PoseRefinerOptions& options) {
  PointTerms out;
  if (p.z() <= 1e-6) return out;
  const double iz = 1.0 / p.z();
  const double u = K.fx * p.x() * iz + K.cx, v = K.fy * p.y() * iz + K.cy;
  const double s = corr.inv_sigma_px[i];
  const double ru = (u - corr.pixels[i].x()) * s, rv = (v - corr.pixels[i].y()) * s;
  const double r = std::sqrt(ru * ru + rv * rv);
  const double w = corr.group[i] == CorrespondenceGroup::kMarker
                       ? HuberWeight(r, options.marker_huber)
                   : tukey ? TukeyWeight(r, options.keypoint_tukey)
                           : HuberWeight(r, options.marker_huber);
  if (w <= 0) return out;
  out.used = true;
  // d(u,v)/dp and dp/d(omega, t) = [-[p]x, I].
  Eigen::Matrix<double, 2, 3> Jp;
  Jp << K.fx * iz, 0, -K.fx * p.x() * iz * iz, 0, K.fy * iz, -K.fy * p.y() * iz * iz;
  Eigen::Matrix<double, 2, 6> J;
  J.leftCols<3>() = -Jp * Skew(p);
  J.rightCols<3>() = Jp;
  J *= s;
  out.H_pixel.noalias() = w * J.transpose() * J;
  out.g.noalias() = w * J.transpose() * Eigen::Vector2d(ru, rv);
  out.H_depth.setZero();
  out.g_depth.setZero();
  if (corr.inv_sigma_depth[i] > 0) {
    const double sd = corr.inv_sigma_depth[i];
    const double rd = (p.z() - corr.depth_m[i]) * sd;
    const double wd = tukey ? TukeyWeight(std::abs(rd), options.keypoint_tukey)
                            : HuberWeight(std::abs(rd), options.marker_huber);
    if (wd > 0) {
      Vec6 Jd;
      Jd << p.y(), -p.x(), 0, 0, 0, 1;
      Jd *= sd;
      out.H_depth.noalias() = wd * Jd * Jd.transpose();
      out.g_depth.noalias() = wd * Jd * rd;
    }
  }
  return out;
}

}  // namespace

Eigen::Matrix<double, 6, 6> PointInformation(const PoseCorrespondences& corr, size_t i,
                                             const CameraIntrinsics& intrinsics,
                                             const Rigid3d& camera_from_room,
                                             const PoseRefinerOptions& options) {
  const bool tukey = options.max_iterations > options.huber_iterations;
  const PointTerms terms =
      PointTermsAt(camera_from_room * corr.points_in_room[i], corr, i, intrinsics, tukey, options);
  // Each point's own share: depth of another instant is not marginalised here.
  return terms.used ? Mat6(terms.H_pixel + terms.H_depth) : Mat6::Zero();
}

PoseRefinementResult RefineCameraPose(const PoseCorrespondences& corr,
                                      const CameraIntrinsics& intrinsics,
                                      const Rigid3d& camera_from_room_initial,
                                      const PoseRefinerOptions& options,
                                      const std::optional<PosePrior>& prior) {
  PoseRefinementResult result;
  result.camera_from_room = camera_from_room_initial;
  const size_t n = corr.size();
  result.inlier.assign(n, 0);
  if (n < 3 && !prior) return result;

  const double fx = intrinsics.fx, fy = intrinsics.fy, cx = intrinsics.cx, cy = intrinsics.cy;
  Eigen::Matrix3d R = camera_from_room_initial.RotationMatrix();
  Eigen::Vector3d t = camera_from_room_initial.translation;
  Eigen::Matrix3d prior_R_inv = Eigen::Matrix3d::Identity();
  if (prior) prior_R_inv = prior->camera_from_room.RotationMatrix().transpose();

  Mat6 H, H_prior = Mat6::Zero(), H_marker = Mat6::Zero(), H_depth;
  Vec6 g, g_depth;
  const bool delayed_depth = !corr.depth_motion_covariance.isZero(0);
  Mat6 H_depth_read = Mat6::Zero();  // the depth's own, before the motion is taken out
  Vec6 g_depth_read = Vec6::Zero(), last_step = Vec6::Zero();
  for (int it = 0; it < options.max_iterations; ++it) {
    H.setZero();
    H_prior.setZero();
    H_marker.setZero();
    H_depth.setZero();
    g.setZero();
    g_depth.setZero();
    const bool tukey = it >= options.huber_iterations;
    int used = 0;
    for (size_t i = 0; i < n; ++i) {
      const PointTerms terms =
          PointTermsAt(R * corr.points_in_room[i] + t, corr, i, intrinsics, tukey, options);
      if (!terms.used) continue;
      ++used;
      H.noalias() += terms.H_pixel;
      H_depth.noalias() += terms.H_depth;
      if (corr.group[i] == CorrespondenceGroup::kMarker) H_marker.noalias() += terms.H_pixel;
      g.noalias() += terms.g;
      g_depth.noalias() += terms.g_depth;
    }
    // Plane depths: z = (n.q) / (n.r) with n = R n_room, q = R p_room + t;
    // dz/domega = -(n.q) / (n.r)^2 (n x r), dz/dt = n / (n.r).
    for (size_t i = 0; i < corr.plane_ray.size(); ++i) {
      const Eigen::Vector3d nc = R * corr.plane_normal_in_room[i];
      const Eigen::Vector3d q = R * corr.plane_point_in_room[i] + t;
      const Eigen::Vector3d ray(corr.plane_ray[i].x(), corr.plane_ray[i].y(), 1.0);
      const double nr = nc.dot(ray);
      if (std::abs(nr) < 1e-3) continue;
      const double nq = nc.dot(q);
      const double z = nq / nr;
      if (z <= 0) continue;
      const double s = corr.plane_inv_sigma[i];
      const double r = (z - corr.plane_depth_m[i]) * s;
      const double w = HuberWeight(std::abs(r), options.marker_huber);
      Vec6 J;
      J.head<3>() = -(nq / (nr * nr)) * nc.cross(ray);
      J.tail<3>() = nc / nr;
      J *= s;
      H_depth.noalias() += w * J * J.transpose();
      g_depth.noalias() += w * J * r;
    }
    if (delayed_depth) {
      H_depth_read = H_depth;
      g_depth_read = g_depth;
      MarginaliseSharedMotion(corr.depth_motion_covariance, &H_depth, &g_depth);
    }
    H += H_depth;
    g += g_depth;
    if (prior) {
      const Eigen::Matrix3d dR = R * prior_R_inv;
      const Eigen::Vector3d e_rot = RotationVectorFromQuaternion(Eigen::Quaterniond(dR));
      const Eigen::Vector3d e_t = t - dR * prior->camera_from_room.translation;
      if (prior->information) {
        Vec6 e;
        e << e_rot, e_t;
        H_prior = *prior->information;
        H += H_prior;
        g += *prior->information * e;
      } else {
        const double wr = 1.0 / (prior->sigma_rad * prior->sigma_rad);
        const double wt = 1.0 / (prior->sigma_m * prior->sigma_m);
        H_prior.topLeftCorner<3, 3>().diagonal().array() += wr;
        H_prior.bottomRightCorner<3, 3>().diagonal().array() += wt;
        H += H_prior;
        g.head<3>() += wr * e_rot;
        g.tail<3>() += wt * e_t;
      }
    } else if (used < 3) {
      return result;
    }
    const Eigen::LDLT<Mat6> ldlt(H);
    if (ldlt.info() != Eigen::Success) break;
    const Vec6 delta = -ldlt.solve(g);
    if (!delta.allFinite()) break;
    last_step = delta;
    const Eigen::Matrix3d dR = QuaternionFromRotationVector(delta.head<3>()).toRotationMatrix();
    R = dR * R;
    t = dR * t + delta.tail<3>();
    result.iterations = it + 1;
    if (delta.head<3>().norm() < options.min_step_rad && delta.tail<3>().norm() < options.min_step_m &&
        it + 1 >= options.huber_iterations) {
      result.converged = true;
      break;
    }
  }
  if (result.iterations == options.max_iterations) result.converged = true;  // ran its course
  result.camera_from_room = Rigid3d(ProjectToSO3(R), t);
  result.information = H;
  result.data_information = H - H_prior;
  result.marker_information = H_marker;
  if (delayed_depth && result.iterations > 0) {
    // Measured at the pose before the last step: relative to the pose after it.
    DepthCameraMotion depth_motion = MeasuredSharedMotion(corr.depth_motion_covariance,
                                                          H_depth_read, g_depth_read, Vec6::Zero());
    depth_motion.mean -= last_step;
    result.depth_camera_motion = depth_motion;
  }

  // Inliers and residual statistics at the solution.
  double sum_m = 0, sum_k = 0;
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d p = R * corr.points_in_room[i] + t;
    if (p.z() <= 1e-6) continue;
    const double u = fx * p.x() / p.z() + cx, v = fy * p.y() / p.z() + cy;
    const double du = u - corr.pixels[i].x(), dv = v - corr.pixels[i].y();
    const double e2 = du * du + dv * dv;
    const double r = std::sqrt(e2) * corr.inv_sigma_px[i];
    bool ok = r < options.inlier_threshold;
    if (ok && corr.inv_sigma_depth[i] > 0) {
      ok = std::abs(p.z() - corr.depth_m[i]) * corr.inv_sigma_depth[i] < options.inlier_threshold;
    }
    if (!ok) continue;
    result.inlier[i] = 1;
    ++result.num_inliers;
    if (corr.group[i] == CorrespondenceGroup::kMarker) {
      ++result.marker_inliers;
      sum_m += e2;
    } else {
      ++result.keypoint_inliers;
      sum_k += e2;
    }
  }
  if (result.marker_inliers) result.marker_rms_px = std::sqrt(sum_m / result.marker_inliers);
  if (result.keypoint_inliers) result.keypoint_rms_px = std::sqrt(sum_k / result.keypoint_inliers);
  if (result.num_inliers) result.rms_px = std::sqrt((sum_m + sum_k) / result.num_inliers);
  return result;
}

}  // namespace arpos
