#pragma once
/// Smooth, deterministic motions: a hand-held camera and a patient moved by
/// the couch. Both are continuous functions of time, so they can be sampled
/// at frame times and inside the exposure (motion blur).

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "geometry/rigid3.h"

namespace arpos::sim {

/// A key of a hand-held path: where the camera is and what it looks at
/// (room frame, metres), at a fraction of the sequence's duration.
struct CameraKey {
  Eigen::Vector3d position_m;
  Eigen::Vector3d look_at_m;
};

/// Hand-held camera: keys spaced evenly in time, Catmull-Rom interpolation
/// of position and look-at point, camera up along room +z with a slowly
/// varying roll, plus hand tremor (band-limited sinusoids, 0.8-6 Hz).
class HandheldTrajectory {
 public:
  HandheldTrajectory() = default;
  HandheldTrajectory(std::vector<CameraKey> keys, double duration_s, uint64_t seed,
                     double tremor_m = 0.0015, double tremor_deg = 0.25, double roll_deg = 4.0);
  /// room_from_camera at time t (s from the start; clamped to [0, duration]).
  Rigid3d RoomFromCamera(double t_s) const;
  double duration_s() const { return duration_s_; }

  /// Paces the keys like a person walking with the camera instead of evenly:
  /// each key is reached after a time in proportion to the way there (the
  /// distance at `walk_m_per_s` plus the turn of the view at
  /// `turn_deg_per_s`), the whole still lasting duration_s; and the view
  /// turns by heading and elevation, as a person turns, instead of swinging
  /// its look-at point through the camera when two keys look opposite ways.
  void PaceLikeAWalk(double walk_m_per_s = 0.8, double turn_deg_per_s = 60.0);

 private:
  struct Wave {
    double frequency_hz, phase, amplitude;
  };
  std::vector<CameraKey> keys_;
  double duration_s_ = 1;
  std::vector<double> key_times_s_;  ///< empty: keys evenly spaced
  /// Per key when paced: heading (unwrapped), elevation (rad), look distance (m).
  std::vector<Eigen::Vector3d> key_views_;
  std::vector<Wave> waves_[7];  // tx ty tz rx ry rz roll
};

/// Camera pose looking from `position` at `look_at` with room +z as up
/// (image y points down), rolled by `roll_rad` about the optical axis.
Rigid3d LookAt(const Eigen::Vector3d& position, const Eigen::Vector3d& look_at, double roll_rad = 0);

/// Patient motion about the isocentre: room_from_model(t) =
/// [R(delta(t)) R_target, t_target + delta_t(t)], i.e. a rotation about the
/// isocentre in room axes and a shift of it. The delta passes smoothly
/// (cosine easing) through waypoints; |each translation component| <=
/// max_shift_m, |rotation| <= max_rotation_deg.
class BodyMotion {
 public:
  BodyMotion() = default;
  /// Still at `room_from_model`.
  explicit BodyMotion(const Rigid3d& room_from_model);
  /// Waypoints (translation m, rotation vector rad) evenly spaced over the
  /// duration, relative to `room_from_model_target`.
  BodyMotion(const Rigid3d& room_from_model_target,
             std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> waypoints, double duration_s);
  Rigid3d RoomFromModel(double t_s) const;

 private:
  Rigid3d target_;
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> waypoints_;
  double duration_s_ = 1;
};

/// Random delta (translation, rotation vector) with each translation
/// component within +-max_shift_m and rotation angle <= max_rotation_deg.
std::pair<Eigen::Vector3d, Eigen::Vector3d> RandomPoseDelta(uint64_t seed, double max_shift_m,
                                                             double max_rotation_deg);

}  // namespace arpos::sim
