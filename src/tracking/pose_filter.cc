#include "tracking/pose_filter.h"

#include <algorithm>
#include <cmath>

#include "geometry/so3.h"
#include "util/check.h"

namespace arpos {

std::string PoseFilterOptions::Validate() const {
  if (!(acceleration_m_s2 > 0) || !(angular_acceleration_rad_s2 > 0)) return "accelerations must be positive";
  if (!(reset_sigmas > 0)) return "reset_sigmas must be positive";
  if (!(max_gap_s > 0)) return "max_gap_s must be positive";
  return "";
}

PoseFilter::PoseFilter(const PoseFilterOptions& options) : options_(options) {
  const std::string problem = options_.Validate();
  ARPOS_CHECK(problem.empty(), "pose filter options: " << problem);
}

void PoseFilter::Predict(Axis* a, double dt, double q) const {
  // x += v dt; P = F P F^T + Q (white-noise acceleration of variance q^2).
  a->x += a->v * dt;
  const double pxx = a->pxx + 2 * dt * a->pxv + dt * dt * a->pvv;
  const double pxv = a->pxv + dt * a->pvv;
  const double q2 = q * q;
  a->pxx = pxx + q2 * dt * dt * dt * dt / 4;
  a->pxv = pxv + q2 * dt * dt * dt / 2;
  a->pvv = a->pvv + q2 * dt * dt;
}

std::optional<FilteredPose> PoseFilter::Predict(double t) const {
  const double dt = t - t_;
  if (!started_ || !(dt > 0) || dt > options_.max_gap_s) return std::nullopt;
  FilteredPose out;
  double max_p = 0, max_r = 0;
  Eigen::Vector3d position, rv;
  for (int k = 0; k < 3; ++k) {
    Axis p = pos_[k], r = rot_[k];
    Predict(&p, dt, options_.acceleration_m_s2);
    Predict(&r, dt, options_.angular_acceleration_rad_s2);
    position[k] = p.x;
    rv[k] = r.x;
    max_p = std::max(max_p, p.pxx);
    max_r = std::max(max_r, r.pxx);
  }
  out.room_from_model = Rigid3d((QuaternionFromRotationVector(rv) * rotation_).normalized(), position);
  out.position_sigma_m = std::sqrt(max_p);
  out.rotation_sigma_rad = std::sqrt(max_r);
  return out;
}

FilteredPose PoseFilter::Update(double t, const Rigid3d& measured, double position_sigma_m,
                                double rotation_sigma_rad) {
  const double rp = std::max(1e-6, position_sigma_m), rr = std::max(1e-7, rotation_sigma_rad);
  FilteredPose out;
  const double dt = t - t_;
  bool restart = !started_ || !(dt > 0) || dt > options_.max_gap_s;
  Axis pos[3], rot[3];
  Eigen::Vector3d innovation_rot = Eigen::Vector3d::Zero();
  if (!restart) {
    for (int k = 0; k < 3; ++k) {
      pos[k] = pos_[k];
      rot[k] = rot_[k];
      Predict(&pos[k], dt, options_.acceleration_m_s2);
      Predict(&rot[k], dt, options_.angular_acceleration_rad_s2);
    }
    // The measured rotation about the reference, as a rotation vector.
    const Eigen::AngleAxisd aa((measured.rotation * rotation_.conjugate()).normalized());
    innovation_rot = aa.axis() * aa.angle();
    for (int k = 0; k < 3 && !restart; ++k) {
      const double sp = std::sqrt(pos[k].pxx + rp * rp), sr = std::sqrt(rot[k].pxx + rr * rr);
      restart |= std::abs(measured.translation[k] - pos[k].x) > options_.reset_sigmas * sp;
      restart |= std::abs(innovation_rot[k] - rot[k].x) > options_.reset_sigmas * sr;
    }
  }
  if (restart) {
    started_ = true;
    rotation_ = measured.rotation.normalized();
    for (int k = 0; k < 3; ++k) {
      pos_[k] = Axis{measured.translation[k], 0, rp * rp, 0, 1.0};  // velocity unknown: 1 m/s
      rot_[k] = Axis{0, 0, rr * rr, 0, 1.0};
    }
    t_ = t;
    out.room_from_model = Rigid3d(rotation_, measured.translation);
    out.position_sigma_m = rp;
    out.rotation_sigma_rad = rr;
    out.restarted = true;
    return out;
  }
  auto correct = [](Axis* a, double z, double r2) {
    const double s = a->pxx + r2;
    const double kx = a->pxx / s, kv = a->pxv / s;
    const double y = z - a->x;
    a->x += kx * y;
    a->v += kv * y;
    const double pxx = (1 - kx) * a->pxx, pxv = (1 - kx) * a->pxv, pvv = a->pvv - kv * a->pxv;
    a->pxx = pxx, a->pxv = pxv, a->pvv = pvv;
  };
  double max_p = 0, max_r = 0;
  for (int k = 0; k < 3; ++k) {
    correct(&pos[k], measured.translation[k], rp * rp);
    correct(&rot[k], innovation_rot[k], rr * rr);
    pos_[k] = pos[k];
    rot_[k] = rot[k];
    max_p = std::max(max_p, pos[k].pxx);
    max_r = std::max(max_r, rot[k].pxx);
  }
  // Move the rotation reference onto the estimate (the rotation states
  // become zero; velocities stay).
  const Eigen::Vector3d rv(rot_[0].x, rot_[1].x, rot_[2].x);
  const double angle = rv.norm();
  const Eigen::Quaterniond delta =
      angle > 0 ? Eigen::Quaterniond(Eigen::AngleAxisd(angle, rv / angle)) : Eigen::Quaterniond::Identity();
  rotation_ = (delta * rotation_).normalized();
  for (int k = 0; k < 3; ++k) rot_[k].x = 0;
  t_ = t;
  out.room_from_model = Rigid3d(rotation_, Eigen::Vector3d(pos_[0].x, pos_[1].x, pos_[2].x));
  out.position_sigma_m = std::sqrt(max_p);
  out.rotation_sigma_rad = std::sqrt(max_r);
  return out;
}

}  // namespace arpos
