#pragma once
/// Rigid transforms named by what they map.
///
/// A Rigid3d called `b_from_a` maps points expressed in frame a into frame b:
///   point_in_b = b_from_a * point_in_a
/// and composes right to left: c_from_a = c_from_b * b_from_a. Translation in
/// metres; rotation as a unit Hamilton quaternion (Eigen's convention, the same
/// as the TUM files' qx qy qz qw).

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>

namespace arpos {

struct Rigid3d {
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  Rigid3d() = default;
  Rigid3d(const Eigen::Quaterniond& q, const Eigen::Vector3d& t)
      : rotation(q.normalized()), translation(t) {}
  Rigid3d(const Eigen::Matrix3d& r, const Eigen::Vector3d& t);

  static Rigid3d Identity() { return Rigid3d(); }

  /// From a 4x4 homogeneous matrix. Throws arpos::Error if the matrix is not a
  /// rigid transform within `tolerance` (see IsRigidTransform).
  static Rigid3d FromMatrix(const Eigen::Matrix4d& matrix, double tolerance = 1e-6);
  /// From a 3x4 [R|t]; same check.
  static Rigid3d FromMatrix3x4(const Eigen::Matrix<double, 3, 4>& matrix,
                               double tolerance = 1e-6);
  /// From axis-angle (rotation vector, radians) and translation.
  static Rigid3d FromRotationVector(const Eigen::Vector3d& rotation_vector,
                                    const Eigen::Vector3d& translation);

  Eigen::Matrix3d RotationMatrix() const { return rotation.toRotationMatrix(); }
  Eigen::Matrix4d ToMatrix() const;
  Eigen::Matrix<double, 3, 4> ToMatrix3x4() const;
  Eigen::Vector3d RotationVector() const;

  /// a_from_b for this b_from_a.
  Rigid3d Inverse() const;

  Eigen::Vector3d operator*(const Eigen::Vector3d& point) const {
    return rotation * point + translation;
  }
  Rigid3d operator*(const Rigid3d& a) const {
    return Rigid3d(rotation * a.rotation, rotation * a.translation + translation);
  }
  /// Exact equality of components (tests use IsApprox).
  bool IsApprox(const Rigid3d& other, double translation_tol_m = 1e-9,
                double rotation_tol_rad = 1e-9) const;

  /// "t=[x y z] m, r=[rx ry rz] deg" for logs and messages.
  std::string ToString() const;
};

/// Is `matrix` a rigid transform? Checks last row (0 0 0 1), R^T R = I and
/// det R = +1 within `tolerance`, and finiteness. On failure `reason` says why.
bool IsRigidTransform(const Eigen::Matrix4d& matrix, double tolerance, std::string* reason);

/// Linear interpolation of translation, slerp of rotation; alpha in [0, 1].
Rigid3d Interpolate(const Rigid3d& a, const Rigid3d& b, double alpha);

}  // namespace arpos
