#include "simulation/trajectory.h"

#include <algorithm>
#include <cmath>

#include "geometry/so3.h"
#include "simulation/random.h"
#include "util/check.h"

namespace arpos::sim {
namespace {

Eigen::Vector3d CatmullRom(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1,
                           const Eigen::Vector3d& p2, const Eigen::Vector3d& p3, double t) {
  const double t2 = t * t, t3 = t2 * t;
  return 0.5 * ((2 * p1) + (-p0 + p2) * t + (2 * p0 - 5 * p1 + 4 * p2 - p3) * t2 +
                (-p0 + 3 * p1 - 3 * p2 + p3) * t3);
}

}  // namespace

Rigid3d LookAt(const Eigen::Vector3d& position, const Eigen::Vector3d& look_at, double roll_rad) {
  const Eigen::Vector3d z = (look_at - position).normalized();
  Eigen::Vector3d up(0, 0, 1);
  if (std::abs(z.dot(up)) > 0.999) up = Eigen::Vector3d(0, 1, 0);
  const Eigen::Vector3d y = -(up - up.dot(z) * z).normalized();  // image down
  const Eigen::Vector3d x = y.cross(z);
  Eigen::Matrix3d r;
  r.col(0) = x;
  r.col(1) = y;
  r.col(2) = z;
  const Eigen::Matrix3d roll = Eigen::AngleAxisd(roll_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return Rigid3d(r * roll, position);
}

HandheldTrajectory::HandheldTrajectory(std::vector<CameraKey> keys, double duration_s,
                                       uint64_t seed, double tremor_m, double tremor_deg,
                                       double roll_deg)
    : keys_(std::move(keys)), duration_s_(duration_s) {
  ARPOS_CHECK(keys_.size() >= 2, "a trajectory needs at least two keys");
  ARPOS_CHECK(duration_s > 0, "trajectory duration must be positive");
  Rng rng(seed);
  for (int axis = 0; axis < 7; ++axis) {
    const double amplitude = axis < 3 ? tremor_m : axis < 6 ? RadFromDeg(tremor_deg)
                                                            : RadFromDeg(roll_deg);
    const int count = axis < 6 ? 4 : 2;
    for (int k = 0; k < count; ++k) {
      Wave w;
      w.frequency_hz = axis < 6 ? rng.Uniform(0.8, 6.0) : rng.Uniform(0.05, 0.2);
      w.phase = rng.Uniform(0, 2 * M_PI);
      // Sum of `count` unit sinusoids has RMS sqrt(count / 2).
      w.amplitude = amplitude * rng.Uniform(0.5, 1.5) / std::sqrt(count / 2.0);
      waves_[axis].push_back(w);
    }
  }
}

void HandheldTrajectory::PaceLikeAWalk(double walk_m_per_s, double turn_deg_per_s) {
  ARPOS_CHECK(walk_m_per_s > 0 && turn_deg_per_s > 0, "walking pace must be positive");
  key_views_.clear();
  for (size_t k = 0; k < keys_.size(); ++k) {
    const Eigen::Vector3d d = keys_[k].look_at_m - keys_[k].position_m;
    double heading = std::atan2(d.y(), d.x());
    if (k > 0) {  // unwrapped: the shorter way round from the previous key
      const double previous = key_views_.back().x();
      heading = previous + std::remainder(heading - previous, 2 * M_PI);
    }
    key_views_.emplace_back(heading, std::atan2(d.z(), d.head<2>().norm()), d.norm());
  }
  std::vector<double> effort = {0.0};
  for (size_t k = 1; k < keys_.size(); ++k) {
    const double distance = (keys_[k].position_m - keys_[k - 1].position_m).norm();
    const Eigen::Vector3d turn = key_views_[k] - key_views_[k - 1];
    const double turn_deg = DegFromRad(std::hypot(turn.x(), turn.y()));
    effort.push_back(effort.back() + distance / walk_m_per_s + turn_deg / turn_deg_per_s + 1e-3);
  }
  key_times_s_.clear();
  for (double e : effort) key_times_s_.push_back(e / effort.back() * duration_s_);
}

Rigid3d HandheldTrajectory::RoomFromCamera(double t_s) const {
  const double t = std::clamp(t_s, 0.0, duration_s_);
  int i = 0;
  double f = 0;
  if (key_times_s_.empty()) {
    const double s = t / duration_s_ * (keys_.size() - 1);
    i = std::min(static_cast<int>(s), static_cast<int>(keys_.size()) - 2);
    f = s - i;
  } else {
    while (i + 2 < static_cast<int>(keys_.size()) && t >= key_times_s_[i + 1]) ++i;
    f = std::clamp((t - key_times_s_[i]) / (key_times_s_[i + 1] - key_times_s_[i]), 0.0, 1.0);
  }
  auto key = [&](int k) { return keys_[std::clamp(k, 0, static_cast<int>(keys_.size()) - 1)]; };
  const Eigen::Vector3d position = CatmullRom(key(i - 1).position_m, key(i).position_m,
                                              key(i + 1).position_m, key(i + 2).position_m, f);
  Eigen::Vector3d look;
  if (key_views_.empty()) {
    look = CatmullRom(key(i - 1).look_at_m, key(i).look_at_m, key(i + 1).look_at_m, key(i + 2).look_at_m, f);
  } else {
    auto view = [&](int k) { return key_views_[std::clamp(k, 0, static_cast<int>(key_views_.size()) - 1)]; };
    const Eigen::Vector3d v = CatmullRom(view(i - 1), view(i), view(i + 1), view(i + 2), f);
    look = position + v.z() * Eigen::Vector3d(std::cos(v.y()) * std::cos(v.x()),
                                              std::cos(v.y()) * std::sin(v.x()), std::sin(v.y()));
  }
  double v[7];
  for (int axis = 0; axis < 7; ++axis) {
    v[axis] = 0;
    for (const Wave& w : waves_[axis]) {
      v[axis] += w.amplitude * std::sin(2 * M_PI * w.frequency_hz * t + w.phase);
    }
  }
  const Rigid3d smooth = LookAt(position, look, v[6]);
  const Rigid3d tremor = Rigid3d::FromRotationVector(Eigen::Vector3d(v[3], v[4], v[5]),
                                                     Eigen::Vector3d(v[0], v[1], v[2]));
  // Tremor in the camera frame (the hand shakes the camera).
  return smooth * tremor;
}

BodyMotion::BodyMotion(const Rigid3d& room_from_model) : target_(room_from_model) {
  waypoints_.push_back({Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()});
}

BodyMotion::BodyMotion(const Rigid3d& room_from_model_target,
                       std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> waypoints,
                       double duration_s)
    : target_(room_from_model_target), waypoints_(std::move(waypoints)), duration_s_(duration_s) {
  ARPOS_CHECK(!waypoints_.empty(), "body motion needs a waypoint");
  ARPOS_CHECK(duration_s > 0, "body motion duration must be positive");
}

Rigid3d BodyMotion::RoomFromModel(double t_s) const {
  std::pair<Eigen::Vector3d, Eigen::Vector3d> delta = waypoints_.front();
  if (waypoints_.size() > 1) {
    const double s = std::clamp(t_s / duration_s_, 0.0, 1.0) * (waypoints_.size() - 1);
    const int i = std::min(static_cast<int>(s), static_cast<int>(waypoints_.size()) - 2);
    const double f = s - i;
    const double e = 0.5 - 0.5 * std::cos(M_PI * f);  // ease in and out: smooth, no overshoot
    delta.first = (1 - e) * waypoints_[i].first + e * waypoints_[i + 1].first;
    delta.second = (1 - e) * waypoints_[i].second + e * waypoints_[i + 1].second;
  }
  const Eigen::Quaterniond q = QuaternionFromRotationVector(delta.second);
  return Rigid3d(q * target_.rotation, target_.translation + delta.first);
}

std::pair<Eigen::Vector3d, Eigen::Vector3d> RandomPoseDelta(uint64_t seed, double max_shift_m,
                                                            double max_rotation_deg) {
  Rng rng(seed);
  Eigen::Vector3d t(rng.Uniform(-max_shift_m, max_shift_m), rng.Uniform(-max_shift_m, max_shift_m),
                    rng.Uniform(-max_shift_m, max_shift_m));
  Eigen::Vector3d axis(rng.Normal(), rng.Normal(), rng.Normal());
  axis.normalize();
  const double angle = RadFromDeg(rng.Uniform(0.3, 1.0) * max_rotation_deg);
  return {t, axis * angle};
}

}  // namespace arpos::sim
