// The couch correction's axes, signs and verdict against known offsets
// (DATASET.md "Corrections").
#include "feedback/couch_correction.h"

#include <cmath>

#include <gtest/gtest.h>

namespace arpos {
namespace {

constexpr double kPi = 3.14159265358979323846;
Rigid3d Turn(const Eigen::Vector3d& axis, double deg) {
  return Rigid3d::FromRotationVector(axis.normalized() * deg * kPi / 180, Eigen::Vector3d::Zero());
}
// A planned pose whose model axes are not the room's (supine patient: the
// model's y axis, posterior, points down in the room).
Rigid3d Target() {
  return Rigid3d(Turn(Eigen::Vector3d::UnitX(), -90).rotation * Turn(Eigen::Vector3d(0.1, 0.2, 1), 7).rotation,
                 Eigen::Vector3d(0.8, 1.3, 0.95));
}
// The patient displaced from the target by `shift` (model axes of the
// target, metres) and turned by `turn` about the isocentre (model axes).
Rigid3d Displaced(const Eigen::Vector3d& shift_model, const Rigid3d& turn_model = Rigid3d()) {
  const Rigid3d target = Target();
  return Rigid3d(target.rotation * turn_model.rotation, target.translation + target.rotation * shift_model);
}

TEST(CouchCorrection, TranslationsAlongEachCouchAxis) {
  const CouchTolerances tol;
  // Patient 10 mm to their left (+x model): the couch moves them 10 mm to the right.
  CouchCorrection c = ComputeCouchCorrection(Displaced({0.010, 0, 0}), Target(), {}, tol);
  EXPECT_NEAR(c.lateral_mm, -10, 1e-9);
  EXPECT_NEAR(c.longitudinal_mm, 0, 1e-9);
  EXPECT_NEAR(c.vertical_mm, 0, 1e-9);
  // 5 mm too far superior (+z model, towards the gantry): longitudinal -5.
  c = ComputeCouchCorrection(Displaced({0, 0, 0.005}), Target(), {}, tol);
  EXPECT_NEAR(c.longitudinal_mm, -5, 1e-9);
  EXPECT_NEAR(c.lateral_mm, 0, 1e-9);
  // 3 mm too posterior (+y model = down): the couch moves up 3 mm (vertical +3).
  c = ComputeCouchCorrection(Displaced({0, 0.003, 0}), Target(), {}, tol);
  EXPECT_NEAR(c.vertical_mm, 3, 1e-9);
  EXPECT_NEAR(c.translation_mm, 3, 1e-9);
  EXPECT_NEAR(c.rotation_deg, 0, 1e-9);
}

TEST(CouchCorrection, RotationsAboutEachCouchAxis) {
  const CouchTolerances tol;
  // Turned +0.5 deg about the lateral axis: pitch -0.5 undoes it.
  CouchCorrection c = ComputeCouchCorrection(Displaced({0, 0, 0}, Turn(Eigen::Vector3d::UnitX(), 0.5)), Target(), {}, tol);
  EXPECT_NEAR(c.pitch_deg, -0.5, 1e-9);
  EXPECT_NEAR(c.roll_deg, 0, 1e-9);
  EXPECT_NEAR(c.yaw_deg, 0, 1e-9);
  EXPECT_NEAR(c.translation_mm, 0, 1e-9);  // about the isocentre: no shift
  // +0.7 deg about the longitudinal axis (+z): roll -0.7.
  c = ComputeCouchCorrection(Displaced({0, 0, 0}, Turn(Eigen::Vector3d::UnitZ(), 0.7)), Target(), {}, tol);
  EXPECT_NEAR(c.roll_deg, -0.7, 1e-9);
  // +0.3 deg about the vertical axis (up = -y): yaw -0.3.
  c = ComputeCouchCorrection(Displaced({0, 0, 0}, Turn(-Eigen::Vector3d::UnitY(), 0.3)), Target(), {}, tol);
  EXPECT_NEAR(c.yaw_deg, -0.3, 1e-9);
  EXPECT_NEAR(c.rotation_deg, 0.3, 1e-9);
}

TEST(CouchCorrection, ApplyingTheCorrectionReachesThePlannedPose) {
  const Rigid3d current =
      Displaced({0.004, -0.012, 0.021}, Turn(Eigen::Vector3d(0.3, -1, 0.4), 1.7));
  const CouchCorrection c = ComputeCouchCorrection(current, Target(), {}, {});
  const Rigid3d after = ApplyCouchCorrection(current, c, Target());
  EXPECT_TRUE(after.IsApprox(Target(), 1e-9, 1e-9)) << after.ToString() << " vs " << Target().ToString();
  EXPECT_NEAR(c.translation_mm, std::sqrt(4.0 * 4 + 12 * 12 + 21 * 21), 1e-9);
  EXPECT_NEAR(c.rotation_deg, 1.7, 1e-9);
}

// What the README tells the therapist: positive pitch raises the head end,
// positive roll lowers the patient's left side, positive yaw turns the head
// towards the patient's right; positive lateral/longitudinal/vertical move the
// patient to their left, towards the gantry, up.
TEST(CouchCorrection, SignsAsTheReadmeStatesThem) {
  const Rigid3d target = Target();
  const Rigid3d model_from_room = target.Inverse();
  // Where a model point ends up after the couch applies `c` to a patient at the
  // planned pose, in the planned model's axes (x left, y down, z head).
  auto moved = [&](CouchCorrection c, const Eigen::Vector3d& point) {
    const Rigid3d after = ApplyCouchCorrection(target, c, target);
    return Eigen::Vector3d(model_from_room * (after * point));
  };
  CouchCorrection c;
  c.pitch_deg = 1;
  EXPECT_LT(moved(c, {0, 0, 0.8}).y(), -0.01);  // head end up (y is down)
  c = CouchCorrection();
  c.roll_deg = 1;
  EXPECT_GT(moved(c, {0.2, 0, 0}).y(), 0.003);  // left side down
  c = CouchCorrection();
  c.yaw_deg = 1;
  EXPECT_LT(moved(c, {0, 0, 0.8}).x(), -0.01);  // head towards the patient's right
  c = CouchCorrection();
  c.lateral_mm = 5;
  EXPECT_NEAR(moved(c, {0, 0, 0}).x(), 0.005, 1e-12);
  c = CouchCorrection();
  c.longitudinal_mm = 5;
  EXPECT_NEAR(moved(c, {0, 0, 0}).z(), 0.005, 1e-12);
  c = CouchCorrection();
  c.vertical_mm = 5;
  EXPECT_NEAR(moved(c, {0, 0, 0}).y(), -0.005, 1e-12);
}

TEST(CouchCorrection, InOnlyWhenTheCorrectionPlusItsUncertaintyIsWithinTolerance) {
  CouchTolerances tol;
  tol.translation_mm = 2;
  tol.rotation_deg = 1;
  const Rigid3d current = Displaced({0.0015, 0, 0}, Turn(Eigen::Vector3d::UnitZ(), 0.5));
  EXPECT_EQ(ComputeCouchCorrection(current, Target(), {0.4, 0.4}, tol).state, CorrectionState::kIn);
  // 1.5 mm + 0.6 mm > 2 mm: out, though the correction alone is within.
  EXPECT_EQ(ComputeCouchCorrection(current, Target(), {0.6, 0.1}, tol).state, CorrectionState::kOut);
  // 0.5 deg + 0.6 deg > 1 deg: out.
  EXPECT_EQ(ComputeCouchCorrection(current, Target(), {0.1, 0.6}, tol).state, CorrectionState::kOut);
  // Truly out never reads in, whatever the uncertainty.
  EXPECT_EQ(ComputeCouchCorrection(Displaced({0.0025, 0, 0}), Target(), {0, 0}, tol).state, CorrectionState::kOut);
  EXPECT_EQ(LostCorrection().state, CorrectionState::kLost);
}

// What rounds to zero reads +0.0, never -0.0 (the panel, the report, the
// OpenIGTLink status string).
TEST(CouchCorrection, DescriptionHasNoNegativeZero) {
  CouchCorrection c;
  c.state = CorrectionState::kOut;
  c.lateral_mm = -0.04;
  c.longitudinal_mm = -3.26;
  c.pitch_deg = -0.004;
  c.translation_mm = 3.3;
  const std::string text = DescribeCorrection(c);
  EXPECT_EQ(text.find("-0.0"), std::string::npos) << text;
  EXPECT_NE(text.find("lat +0.0"), std::string::npos) << text;
  EXPECT_NE(text.find("lng -3.3"), std::string::npos) << text;
  EXPECT_NE(text.find("pitch +0.00"), std::string::npos) << text;
}

// A shift within the tolerance that reads `out` shows why: the bound its
// state was decided with, beside the size (panel, `arpos track`, OpenIGTLink).
TEST(CouchCorrection, TheSizeIsShownWithTheBoundItsStateWasDecidedWith) {
  const Rigid3d target = Target();
  Rigid3d current = target;
  current.translation.x() += 0.001;  // 1 mm off: within a 2 mm tolerance on its own
  const CouchTolerances tol;
  const CouchCorrection unsure = ComputeCouchCorrection(current, target, {4.5, 0.3}, tol);
  EXPECT_EQ(unsure.state, CorrectionState::kOut);
  EXPECT_EQ(SizeAndState(unsure), "1.0 +-4.5 mm  0.00 +-0.30 deg  OUT OF TOLERANCE");
  const CouchCorrection sure = ComputeCouchCorrection(current, target, {0.5, 0.1}, tol);
  EXPECT_EQ(sure.state, CorrectionState::kIn);
  EXPECT_EQ(SizeAndState(sure), "1.0 +-0.5 mm  0.00 +-0.10 deg  IN TOLERANCE");
  EXPECT_NE(DescribeCorrection(unsure).find("| 1.0 +-4.5 mm  0.00 +-0.30 deg  OUT OF TOLERANCE"),
            std::string::npos)
      << DescribeCorrection(unsure);
  CouchCorrection bare = sure;
  bare.uncertainty = {};
  EXPECT_EQ(SizeAndState(bare), "1.0 mm  0.00 deg  IN TOLERANCE") << "no bound, none shown";
}

TEST(CouchCorrection, CsvRowsFollowTheHeader) {
  EXPECT_EQ(CorrectionsCsvHeader(),
            "timestamp,lateral_mm,longitudinal_mm,vertical_mm,pitch_deg,roll_deg,yaw_deg,translation_mm,rotation_deg,"
            "state\n");
  const CouchCorrection c = ComputeCouchCorrection(Displaced({0.010, 0, 0}), Target(), {}, {});
  EXPECT_EQ(CorrectionsCsvRow(12.5, c), "12.500000,-10.000,0.000,0.000,0.0000,0.0000,0.0000,10.000,0.0000,out\n");
  EXPECT_EQ(CorrectionsCsvRow(13, LostCorrection()), "13.000000,,,,,,,,,lost\n");
  CouchTolerances bad;
  bad.translation_mm = 0;
  EXPECT_FALSE(bad.Validate().empty());
  bad.translation_mm = 2;
  bad.rotation_deg = std::nan("");
  EXPECT_FALSE(bad.Validate().empty());
}

}  // namespace
}  // namespace arpos
