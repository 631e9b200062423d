#include <gtest/gtest.h>

#include <random>

#include "geometry/pose_error.h"
#include "geometry/rigid3.h"
#include "geometry/so3.h"
#include "geometry/triangle_mesh.h"
#include "geometry/umeyama.h"
#include "util/check.h"

namespace arpos {
namespace {

Rigid3d RandomPose(std::mt19937& rng, double max_t = 2.0) {
  std::uniform_real_distribution<double> u(-1, 1);
  Eigen::Quaterniond q(u(rng), u(rng), u(rng), u(rng));
  return Rigid3d(q.normalized(), Eigen::Vector3d(u(rng), u(rng), u(rng)) * max_t);
}

TEST(Rigid3, ComposeAndInverse) {
  std::mt19937 rng(1);
  for (int i = 0; i < 100; ++i) {
    const Rigid3d b_from_a = RandomPose(rng), c_from_b = RandomPose(rng);
    const Eigen::Vector3d p_a(0.3, -0.2, 1.5);
    const Rigid3d c_from_a = c_from_b * b_from_a;
    EXPECT_LT((c_from_a * p_a - c_from_b * (b_from_a * p_a)).norm(), 1e-12);
    EXPECT_TRUE((b_from_a * b_from_a.Inverse()).IsApprox(Rigid3d::Identity(), 1e-12, 1e-12));
    // Matrix form agrees with the quaternion form.
    const Eigen::Vector4d h = c_from_a.ToMatrix() * p_a.homogeneous();
    EXPECT_LT((h.head<3>() - c_from_a * p_a).norm(), 1e-12);
    EXPECT_TRUE(Rigid3d::FromMatrix(c_from_a.ToMatrix()).IsApprox(c_from_a, 1e-12, 1e-9));
  }
}

TEST(Rigid3, KnownAnswer) {
  // 90 degrees about z then +1 m in x: (1,0,0) -> (0,1,0) -> (1,1,0).
  const Rigid3d b_from_a(Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ())),
                         Eigen::Vector3d(1, 0, 0));
  EXPECT_LT((b_from_a * Eigen::Vector3d(1, 0, 0) - Eigen::Vector3d(1, 1, 0)).norm(), 1e-12);
  EXPECT_LT((b_from_a.Inverse() * Eigen::Vector3d(1, 1, 0) - Eigen::Vector3d(1, 0, 0)).norm(), 1e-12);
}

TEST(Rigid3, RejectsNonRigidMatrices) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  std::string reason;
  EXPECT_TRUE(IsRigidTransform(m, 1e-9, &reason));
  m(0, 0) = 2;  // scale
  EXPECT_FALSE(IsRigidTransform(m, 1e-6, &reason));
  EXPECT_NE(reason.find("orthonormal"), std::string::npos);
  m = Eigen::Matrix4d::Identity();
  m(2, 2) = -1;  // reflection
  EXPECT_FALSE(IsRigidTransform(m, 1e-6, &reason));
  EXPECT_NE(reason.find("reflection"), std::string::npos);
  m = Eigen::Matrix4d::Identity();
  m(3, 0) = 0.5;
  EXPECT_FALSE(IsRigidTransform(m, 1e-6, &reason));
  EXPECT_NE(reason.find("last row"), std::string::npos);
  m = Eigen::Matrix4d::Identity();
  m(1, 3) = std::nan("");
  EXPECT_FALSE(IsRigidTransform(m, 1e-6, &reason));
  EXPECT_THROW(Rigid3d::FromMatrix(m), Error);
}

TEST(SO3, ProjectionFindsNearestRotation) {
  std::mt19937 rng(2);
  std::normal_distribution<double> n(0, 1e-3);
  for (int i = 0; i < 50; ++i) {
    const Eigen::Matrix3d r = RandomPose(rng).RotationMatrix();
    Eigen::Matrix3d noisy = r;
    for (int k = 0; k < 9; ++k) noisy(k / 3, k % 3) += n(rng);
    const Eigen::Matrix3d p = ProjectToSO3(noisy);
    EXPECT_LT((p.transpose() * p - Eigen::Matrix3d::Identity()).norm(), 1e-12);
    EXPECT_NEAR(p.determinant(), 1.0, 1e-12);
    EXPECT_LT((p - r).norm(), 1e-2);
  }
  // A reflection projects to a proper rotation.
  EXPECT_NEAR(ProjectToSO3(Eigen::Vector3d(1, 1, -1).asDiagonal().toDenseMatrix()).determinant(),
              1.0, 1e-12);
}

TEST(SO3, RotationVectorRoundTrip) {
  for (double angle : {0.0, 1e-10, 1e-5, 0.3, 1.0, 3.0, M_PI - 1e-6}) {
    const Eigen::Vector3d axis = Eigen::Vector3d(0.2, -0.5, 0.8).normalized();
    const Eigen::Vector3d v = axis * angle;
    const Eigen::Quaterniond q = QuaternionFromRotationVector(v);
    EXPECT_LT((RotationVectorFromQuaternion(q) - v).norm(), 1e-9) << angle;
    EXPECT_NEAR(RotationAngleRad(q), angle, 1e-9) << angle;
    // -q is the same rotation.
    Eigen::Quaterniond neg(-q.w(), -q.x(), -q.y(), -q.z());
    EXPECT_NEAR(RotationAngleRad(neg), angle, 1e-9);
  }
  EXPECT_LT((Skew(Eigen::Vector3d(1, 2, 3)) * Eigen::Vector3d(4, 5, 6) -
             Eigen::Vector3d(1, 2, 3).cross(Eigen::Vector3d(4, 5, 6))).norm(), 1e-12);
}

TEST(Umeyama, RecoversKnownRigidAndSimilarity) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int trial = 0; trial < 20; ++trial) {
    const Rigid3d target_from_source = RandomPose(rng);
    std::vector<Eigen::Vector3d> src, dst, dst_scaled;
    for (int i = 0; i < 10; ++i) {
      src.emplace_back(u(rng), u(rng), u(rng));
      dst.push_back(target_from_source * src.back());
      dst_scaled.push_back(target_from_source.rotation * (1.7 * src.back()) +
                           target_from_source.translation);
    }
    const auto rigid = EstimateRigidTransform(src, dst);
    ASSERT_TRUE(rigid);
    EXPECT_TRUE(rigid->target_from_source.IsApprox(target_from_source, 1e-10, 1e-10));
    EXPECT_LT(rigid->rmse_m, 1e-10);
    const auto sim = EstimateRigidTransform(src, dst_scaled, true);
    ASSERT_TRUE(sim);
    EXPECT_NEAR(sim->scale, 1.7, 1e-10);
    EXPECT_TRUE(sim->target_from_source.IsApprox(target_from_source, 1e-9, 1e-10));
    // The inverse direction gives the inverse transform.
    const auto back = EstimateRigidTransform(dst, src);
    ASSERT_TRUE(back);
    EXPECT_TRUE(back->target_from_source.IsApprox(target_from_source.Inverse(), 1e-10, 1e-10));
  }
}

TEST(Umeyama, RejectsDegenerateSets) {
  std::vector<Eigen::Vector3d> two = {{0, 0, 0}, {1, 0, 0}};
  EXPECT_FALSE(EstimateRigidTransform(two, two));
  std::vector<Eigen::Vector3d> line = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {3, 0, 0}};
  EXPECT_FALSE(EstimateRigidTransform(line, line));
  std::vector<Eigen::Vector3d> same(5, Eigen::Vector3d(1, 2, 3));
  EXPECT_FALSE(EstimateRigidTransform(same, same));
  EXPECT_THROW(EstimateRigidTransform(two, line), Error);
}

TEST(PoseError, KnownAnswers) {
  const Rigid3d gt(Eigen::Quaterniond(Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitX())),
                   Eigen::Vector3d(1, 2, 3));
  EXPECT_DOUBLE_EQ(ComputePoseError(gt, gt).translation_mm, 0.0);
  EXPECT_NEAR(ComputePoseError(gt, gt).rotation_deg, 0.0, 1e-9);
  // est = gt * delta: error is exactly delta, measured in the moving frame.
  const Rigid3d delta(Eigen::Quaterniond(Eigen::AngleAxisd(RadFromDeg(10), Eigen::Vector3d::UnitZ())),
                      Eigen::Vector3d(0.003, 0.004, 0));
  const PoseError e = ComputePoseError(gt, gt * delta);
  EXPECT_NEAR(e.translation_mm, 5.0, 1e-9);
  EXPECT_NEAR(e.rotation_deg, 10.0, 1e-9);
  // Pure rotation about the moving frame's origin gives no translation error.
  const Rigid3d spin(Eigen::Quaterniond(Eigen::AngleAxisd(RadFromDeg(2), Eigen::Vector3d::UnitY())),
                     Eigen::Vector3d::Zero());
  EXPECT_NEAR(ComputePoseError(gt, gt * spin).translation_mm, 0.0, 1e-9);
  EXPECT_NEAR(ComputePoseError(gt, gt * spin).rotation_deg, 2.0, 1e-9);
}

TEST(TriangleMesh, ClosedAreaNormals) {
  // Unit tetrahedron, outward-facing.
  TriangleMesh m;
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  m.faces = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  EXPECT_TRUE(m.IsClosed());
  EXPECT_NEAR(m.SurfaceArea(), 1.5 + std::sqrt(3.0) / 2, 1e-6);
  m.ComputeVertexNormals();
  EXPECT_GT(m.vertex_normals[3].z(), 0.5);  // apex normal points up/out
  m.faces.pop_back();
  EXPECT_FALSE(m.IsClosed());
}

}  // namespace
}  // namespace arpos
