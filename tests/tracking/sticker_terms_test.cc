// A sticker that breathes: its corners' terms in the body fit give up what
// moving along the sticker's normal would explain and keep the rest
// (tracking/sticker_terms.h).
#include <gtest/gtest.h>

#include <array>
#include <vector>

#include <Eigen/Geometry>

#include "tracking/sticker_terms.h"

namespace arpos {
namespace {

using Matrix6d = Eigen::Matrix<double, 6, 6>;
using Vector6d = Eigen::Matrix<double, 6, 1>;

Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d s;
  s << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return s;
}

// A 3 cm sticker 0.8 m in front of a 525 px camera, tilted 30 degrees, its
// corners whitened at 0.2 px: residuals (zero), the Jacobian for a left
// perturbation of the pose (rotation, translation) and b, the corners'
// motion per metre along the sticker's normal.
struct Sticker {
  StickerResiduals r = StickerResiduals::Zero(), b = StickerResiduals::Zero();
  StickerJacobian J = StickerJacobian::Zero();
  Eigen::Vector3d normal;
  StickerResiduals along =
      StickerResiduals::Zero();  ///< the corners' motion per metre along `MakeSticker`'s axis
};

Sticker MakeSticker(const Eigen::Vector3d& centre = Eigen::Vector3d(0.05, -0.02, 0.8),
                    const Eigen::Matrix3d& R =
                        Eigen::AngleAxisd(0.5236, Eigen::Vector3d::UnitX()).toRotationMatrix(),
                    const Eigen::Vector3d& axis = Eigen::Vector3d(0, 0, -1)) {
  Sticker s;
  const double f = 525, sigma = 0.2, half = 0.015;
  s.normal = R * Eigen::Vector3d(0, 0, -1);
  const std::array<Eigen::Vector2d, 4> corners = {Eigen::Vector2d(-half, half), Eigen::Vector2d(half, half),
                                                  Eigen::Vector2d(half, -half), Eigen::Vector2d(-half, -half)};
  for (int c = 0; c < 4; ++c) {
    const Eigen::Vector3d p = centre + R * Eigen::Vector3d(corners[c].x(), corners[c].y(), 0);
    const double iz = 1 / p.z();
    Eigen::Matrix<double, 2, 3> dproj;
    dproj << f * iz / sigma, 0, -f * p.x() * iz * iz / sigma, 0, f * iz / sigma, -f * p.y() * iz * iz / sigma;
    Eigen::Matrix<double, 3, 6> dp;
    dp << -Skew(p), Eigen::Matrix3d::Identity();
    s.J.middleRows<2>(2 * c) = dproj * dp;
    s.b.segment<2>(2 * c) = dproj * s.normal;
    s.along.segment<2>(2 * c) = dproj * axis;
  }
  return s;
}

TEST(StickerTerms, AStillStickerIsThePlainSum) {
  const Sticker s = MakeSticker();
  StickerResiduals r;
  r << 0.3, -0.2, 0.1, 0.4, -0.5, 0.2, 0.0, -0.1;
  Matrix6d H = Matrix6d::Zero();
  Vector6d g = Vector6d::Zero();
  double chi2 = 0;
  AddStickerTerms(r, s.J, s.b, 0.0, &H, &g, &chi2);
  EXPECT_TRUE(H.isApprox(s.J.transpose() * s.J));
  EXPECT_TRUE(g.isApprox(s.J.transpose() * r));
  EXPECT_DOUBLE_EQ(chi2, r.squaredNorm());
}

TEST(StickerTerms, ABreathingStickerGivesUpItsNormalAndKeepsTheRest) {
  const Sticker s = MakeSticker();
  // The pose moved along the sticker's normal moves its corners by b.
  Vector6d along_normal, across;
  along_normal << 0, 0, 0, s.normal;
  // Sideways (camera x, across the normal): what the corners show of it is
  // nothing like what breathing does to them.
  across << 0, 0, 0, 1, 0, 0;
  ASSERT_NEAR(s.normal.x(), 0, 1e-12);
  ASSERT_TRUE((s.J * along_normal).isApprox(s.b));
  const auto information = [&](double motion_m, const Vector6d& v) {
    Matrix6d H = Matrix6d::Zero();
    Vector6d g = Vector6d::Zero();
    double chi2 = 0;
    AddStickerTerms(s.r, s.J, s.b, motion_m, &H, &g, &chi2);
    return v.dot(H * v);
  };
  const double still_along = information(0, along_normal), still_across = information(0, across);
  // 1.5 mm of breathing: along the normal the sticker is worth what 1.5 mm
  // allows (1 / 1.5 mm^2 at most), sideways almost all it was.
  const double breathing_along = information(0.0015, along_normal);
  EXPECT_LT(breathing_along, 1.0 / (0.0015 * 0.0015));
  EXPECT_LT(breathing_along, 0.05 * still_along);
  EXPECT_GT(information(0.0015, across), 0.9 * still_across);
  // More motion, less information along the normal; none without bound.
  EXPECT_LT(information(0.01, along_normal), breathing_along);
  EXPECT_LT(information(1.0, along_normal), 1e-3 * still_along);
}

TEST(StickerTerms, ResidualsBreathingCanExplainCostLittle) {
  const Sticker s = MakeSticker();
  // Corners 1 mm along the normal from where the pose puts them.
  const StickerResiduals r = 0.001 * s.b;
  Matrix6d H = Matrix6d::Zero();
  Vector6d g = Vector6d::Zero();
  double still = 0, breathing = 0;
  AddStickerTerms(r, s.J, s.b, 0, &H, &g, &still);
  AddStickerTerms(r, s.J, s.b, 0.0015, &H, &g, &breathing);
  EXPECT_GT(still, 1);
  // What is left is the prior's cost of 1 mm at 1.5 mm: (1/1.5)^2, a little less.
  EXPECT_LT(breathing, 0.45);
  EXPECT_GT(breathing, 0.3);
}

// Six stickers on a chest that rises 2 mm, each along its own normal (a
// curved surface: the normals fan out by up to 40 degrees), and two still
// stickers on the head: one Gauss-Newton step from the true pose. Each
// moving sticker on its own (0.6 mm of breathing, 1 sigma) pulls the pose
// towards the chest; the rise they share is taken out, and the step is the
// pose part of the explicit seven-unknown solve.
TEST(StickerTerms, TheRiseTheMovingStickersShareDoesNotMoveThePose) {
  struct Placed {
    Sticker s;
    double motion_m;
  };
  std::vector<Placed> stickers;
  for (int i = 0; i < 6; ++i) {
    const double tilt = -0.7 + 0.28 * i;  // about the camera's y axis
    const Eigen::Matrix3d R = (Eigen::AngleAxisd(tilt, Eigen::Vector3d::UnitY()) *
                               Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitX()))
                                  .toRotationMatrix();
    stickers.push_back({MakeSticker(Eigen::Vector3d(-0.15 + 0.06 * i, 0.05 * (i % 2), 0.8 + 0.02 * (i % 3)), R),
                        0.0006});
  }
  stickers.push_back({MakeSticker(Eigen::Vector3d(0.0, -0.25, 0.9), Eigen::Matrix3d::Identity()), 0.0});
  stickers.push_back({MakeSticker(Eigen::Vector3d(0.08, -0.28, 0.9), Eigen::Matrix3d::Identity()), 0.0});
  // Residuals of the moving stickers: 2 mm along their normals.
  for (Placed& p : stickers) p.s.r = p.motion_m > 0 ? StickerResiduals(-0.002 * p.s.b) : StickerResiduals::Zero();
  const double beta_sigma = 3;
  const auto step = [&](bool shared) {
    Matrix6d H = Matrix6d::Zero();
    Vector6d g = Vector6d::Zero();
    double chi2 = 0;
    SharedBreathing breathing;
    for (const Placed& p : stickers) {
      AddStickerTerms(p.s.r, p.s.J, p.s.b, p.motion_m, &H, &g, &chi2, shared ? &breathing : nullptr);
    }
    if (shared) {
      EXPECT_EQ(breathing.stickers, 6);
      breathing.Eliminate(beta_sigma, &H, &g, &chi2);
    }
    return Vector6d(-H.ldlt().solve(g));
  };
  const Vector6d alone = step(false), together = step(true);
  EXPECT_GT(alone.tail<3>().norm(), 0.0005) << alone.transpose();
  EXPECT_LT(together.tail<3>().norm(), 0.1 * alone.tail<3>().norm()) << together.transpose();
  // The same step from the seven unknowns (pose, rise) solved at once.
  Eigen::Matrix<double, 7, 7> H7 = Eigen::Matrix<double, 7, 7>::Zero();
  Eigen::Matrix<double, 7, 1> g7 = Eigen::Matrix<double, 7, 1>::Zero();
  for (const Placed& p : stickers) {
    Eigen::Matrix<double, 8, 7> J7;
    J7 << p.s.J, p.motion_m * p.s.b;
    Eigen::Matrix<double, 8, 8> W = Eigen::Matrix<double, 8, 8>::Identity();
    if (p.motion_m > 0) {
      const double k = 1.0 / (1.0 / (p.motion_m * p.motion_m) + p.s.b.squaredNorm());
      W -= k * p.s.b * p.s.b.transpose();
    }
    H7 += J7.transpose() * W * J7;
    g7 += J7.transpose() * W * p.s.r;
  }
  H7(6, 6) += 1 / (beta_sigma * beta_sigma);
  const Eigen::Matrix<double, 7, 1> full = -H7.ldlt().solve(g7);
  EXPECT_LT((full.head<6>() - together).norm(), 1e-9 * (1 + full.head<6>().norm())) << full.transpose();
}

// The same chest rising 2 mm, but as a chest does: all along one axis
// (towards the camera), not along each sticker's normal. Taken along their
// normals (as before the session measured the directions) the shared rise
// cannot explain the motion across them and the step turns and shifts the
// pose; taken along the direction each moves (what the session now stores)
// it moves the pose a tenth as much or less.
TEST(StickerTerms, StickersTakenAlongTheWayTheyMoveLeaveThePose) {
  // The camera looks at the chest from 45 degrees: the rise is half
  // towards it, half across the image.
  const Eigen::Vector3d axis = Eigen::Vector3d(0, -1, -1).normalized();
  std::vector<Sticker> moving, still;
  for (int i = 0; i < 6; ++i) {
    const double tilt = -0.7 + 0.28 * i;  // the normals fan out about the axis
    const Eigen::Matrix3d R = (Eigen::AngleAxisd(tilt, Eigen::Vector3d(0, 1, -1).normalized()) *
                               Eigen::AngleAxisd(-0.785, Eigen::Vector3d::UnitX()))
                                  .toRotationMatrix();
    moving.push_back(MakeSticker(
        Eigen::Vector3d(-0.15 + 0.06 * i, 0.05 * (i % 2), 0.8 + 0.02 * (i % 3)), R, axis));
    moving.back().r = -0.0012 * moving.back().along;
  }
  still.push_back(MakeSticker(Eigen::Vector3d(0.0, -0.25, 0.9), Eigen::Matrix3d::Identity(), axis));
  still.push_back(
      MakeSticker(Eigen::Vector3d(0.08, -0.28, 0.9), Eigen::Matrix3d::Identity(), axis));
  const auto step = [&](bool along_the_axis) {
    Matrix6d H = Matrix6d::Zero();
    Vector6d g = Vector6d::Zero();
    double chi2 = 0;
    SharedBreathing breathing;
    for (const Sticker& s : moving) {
      AddStickerTerms(s.r, s.J, along_the_axis ? s.along : s.b, 0.0008, &H, &g, &chi2, &breathing);
    }
    for (const Sticker& s : still) AddStickerTerms(s.r, s.J, s.b, 0.0, &H, &g, &chi2, &breathing);
    breathing.Eliminate(3, &H, &g, &chi2);
    return Vector6d(-H.ldlt().solve(g));
  };
  const Vector6d normals = step(false), measured = step(true);
  EXPECT_GT(normals.head<3>().norm(), 0.05 * 3.14159 / 180)
      << normals.transpose();  // 0.05 deg or more
  EXPECT_LT(measured.head<3>().norm(), 0.1 * normals.head<3>().norm()) << measured.transpose();
  EXPECT_LT(measured.tail<3>().norm(), 0.1 * normals.tail<3>().norm()) << measured.transpose();
}

}  // namespace
}  // namespace arpos
