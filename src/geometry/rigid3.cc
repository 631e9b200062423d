#include "geometry/rigid3.h"

#include <cmath>

#include "geometry/so3.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos {

Rigid3d::Rigid3d(const Eigen::Matrix3d& r, const Eigen::Vector3d& t)
    : rotation(Eigen::Quaterniond(r).normalized()), translation(t) {}

Rigid3d Rigid3d::FromMatrix(const Eigen::Matrix4d& matrix, double tolerance) {
  std::string reason;
  ARPOS_CHECK(IsRigidTransform(matrix, tolerance, &reason), "not a rigid transform: " << reason);
  return Rigid3d(ProjectToSO3(matrix.topLeftCorner<3, 3>()), matrix.topRightCorner<3, 1>());
}

Rigid3d Rigid3d::FromMatrix3x4(const Eigen::Matrix<double, 3, 4>& matrix, double tolerance) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topRows<3>() = matrix;
  return FromMatrix(m, tolerance);
}

Rigid3d Rigid3d::FromRotationVector(const Eigen::Vector3d& rotation_vector,
                                    const Eigen::Vector3d& translation) {
  return Rigid3d(QuaternionFromRotationVector(rotation_vector), translation);
}

Eigen::Matrix4d Rigid3d::ToMatrix() const {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = RotationMatrix();
  m.topRightCorner<3, 1>() = translation;
  return m;
}

Eigen::Matrix<double, 3, 4> Rigid3d::ToMatrix3x4() const { return ToMatrix().topRows<3>(); }

Eigen::Vector3d Rigid3d::RotationVector() const { return RotationVectorFromQuaternion(rotation); }

Rigid3d Rigid3d::Inverse() const {
  const Eigen::Quaterniond inv = rotation.conjugate();
  return Rigid3d(inv, -(inv * translation));
}

bool Rigid3d::IsApprox(const Rigid3d& other, double translation_tol_m,
                       double rotation_tol_rad) const {
  return (translation - other.translation).norm() <= translation_tol_m &&
         rotation.angularDistance(other.rotation) <= rotation_tol_rad;
}

std::string Rigid3d::ToString() const {
  const Eigen::Vector3d r = RotationVector() * (180.0 / M_PI);
  return StringPrintf("t=[%.6f %.6f %.6f] m, r=[%.4f %.4f %.4f] deg", translation.x(),
                      translation.y(), translation.z(), r.x(), r.y(), r.z());
}

bool IsRigidTransform(const Eigen::Matrix4d& matrix, double tolerance, std::string* reason) {
  auto fail = [&](const std::string& why) {
    if (reason) *reason = why;
    return false;
  };
  if (!matrix.allFinite()) return fail("it contains a non-finite value");
  if (std::abs(matrix(3, 0)) > tolerance || std::abs(matrix(3, 1)) > tolerance ||
      std::abs(matrix(3, 2)) > tolerance || std::abs(matrix(3, 3) - 1.0) > tolerance) {
    return fail("its last row is not [0 0 0 1]");
  }
  const Eigen::Matrix3d r = matrix.topLeftCorner<3, 3>();
  const double orthogonality = (r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (orthogonality > tolerance) {
    return fail(StringPrintf("its rotation is not orthonormal (|R^T R - I| = %.3g, tolerance %.3g)",
                             orthogonality, tolerance));
  }
  const double det = r.determinant();
  if (det < 0) return fail("its rotation is a reflection (det R < 0)");
  if (std::abs(det - 1.0) > tolerance) {
    return fail(StringPrintf("its rotation has determinant %.6f, not 1", det));
  }
  return true;
}

Rigid3d Interpolate(const Rigid3d& a, const Rigid3d& b, double alpha) {
  return Rigid3d(a.rotation.slerp(alpha, b.rotation),
                 (1.0 - alpha) * a.translation + alpha * b.translation);
}

}  // namespace arpos
