#pragma once
/// SO(3) helpers: projection, exponential/log maps, angles.

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace arpos {

/// Nearest rotation to `m` in the Frobenius norm (SVD, reflection-corrected).
Eigen::Matrix3d ProjectToSO3(const Eigen::Matrix3d& m);

/// Exponential map: rotation vector (axis * angle, radians) -> unit quaternion.
Eigen::Quaterniond QuaternionFromRotationVector(const Eigen::Vector3d& rotation_vector);
/// Log map: unit quaternion -> rotation vector with angle in [0, pi].
Eigen::Vector3d RotationVectorFromQuaternion(const Eigen::Quaterniond& q);

/// Rotation angle of q in radians, in [0, pi]; robust near 0 and pi.
double RotationAngleRad(const Eigen::Quaterniond& q);

/// Skew-symmetric matrix [v]x with [v]x w = v x w.
Eigen::Matrix3d Skew(const Eigen::Vector3d& v);

inline double DegFromRad(double rad) { return rad * 57.29577951308232; }
inline double RadFromDeg(double deg) { return deg * 0.017453292519943295; }

}  // namespace arpos
