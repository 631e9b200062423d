#pragma once
/// A constant-velocity filter on the patient's pose in the room.
///
/// Why: the patient (on the couch) moves smoothly while the hand-held camera
/// does not, and the camera's pose in the room is what varies most from frame
/// to frame (one frame may see a marker, the next only far keypoints). Each
/// frame's pose comes with its own uncertainty; a Kalman filter with a
/// constant-velocity motion model weighs every frame by it, so a poorly
/// localised frame is pulled to the motion of its neighbours while a well
/// localised one is taken almost as it is. A constant-velocity model follows
/// steady motion without lag; what it cannot follow (a jerk of the couch, a
/// patient who moves) shows as an innovation beyond `reset_sigmas` and the
/// filter restarts from that frame.
///
/// State per axis: position and velocity of the isocentre (room frame, m) and
/// of the rotation (a rotation vector about the current estimate, rad); the
/// axes are filtered independently with the measurement's isotropic sigma.

#include <optional>
#include <string>

#include <Eigen/Core>

#include "geometry/rigid3.h"

namespace arpos {

struct PoseFilterOptions {
  /// Unmodelled acceleration (1 sigma, white noise) of the isocentre and of
  /// the rotation.
  double acceleration_m_s2 = 0.3;
  double angular_acceleration_rad_s2 = 0.2;
  /// An innovation beyond this many sigmas on any axis restarts the filter.
  double reset_sigmas = 4.0;
  /// Frames further apart than this restart the filter (s).
  double max_gap_s = 0.5;
  std::string Validate() const;
};

struct FilteredPose {
  Rigid3d room_from_model;
  double position_sigma_m = 0;   ///< largest axis, 1 sigma
  double rotation_sigma_rad = 0;  ///< largest axis, 1 sigma
  bool restarted = false;        ///< this frame started the filter afresh
};

class PoseFilter {
 public:
  explicit PoseFilter(const PoseFilterOptions& options = {});
  /// Adds a measured pose at time `t` (s, increasing) with its 1-sigma
  /// position (m, at the model origin) and rotation (rad) uncertainty.
  FilteredPose Update(double t, const Rigid3d& measured, double position_sigma_m, double rotation_sigma_rad);
  /// Where the motion model puts the pose at time `t` (s), without a
  /// measurement and without changing the filter; sigmas grow with the time
  /// since the last update. nullopt when the filter has not started, `t` is
  /// not after the last update, or further from it than `max_gap_s`.
  std::optional<FilteredPose> Predict(double t) const;
  /// Forgets everything (the next Update starts afresh).
  void Reset() { started_ = false; }

 private:
  struct Axis {
    double x = 0, v = 0;
    double pxx = 0, pxv = 0, pvv = 0;
  };
  void Predict(Axis* a, double dt, double q) const;
  PoseFilterOptions options_;
  bool started_ = false;
  double t_ = 0;
  Axis pos_[3], rot_[3];
  Eigen::Quaterniond rotation_ = Eigen::Quaterniond::Identity();  // reference of rot_
};

}  // namespace arpos
