#include "feedback/couch_correction.h"

#include <cmath>
#include <sstream>

#include "util/string_util.h"

namespace arpos {

const char* CorrectionStateName(CorrectionState state) {
  switch (state) {
    case CorrectionState::kIn: return "in";
    case CorrectionState::kOut: return "out";
    case CorrectionState::kLost: return "lost";
  }
  return "lost";
}

std::string CouchTolerances::Validate() const {
  if (!(translation_mm > 0) || !std::isfinite(translation_mm)) return "translation tolerance must be a positive number of mm";
  if (!(rotation_deg > 0) || !std::isfinite(rotation_deg)) return "rotation tolerance must be a positive number of degrees";
  return "";
}

namespace {
constexpr double kPi = 3.14159265358979323846;
// Couch axes (lateral, longitudinal, vertical) from the planned model's axes.
Eigen::Vector3d ToCouch(const Eigen::Vector3d& in_model) {
  return Eigen::Vector3d(in_model.x(), in_model.z(), -in_model.y());
}
Eigen::Vector3d FromCouch(const Eigen::Vector3d& couch) {
  return Eigen::Vector3d(couch.x(), -couch.z(), couch.y());
}
}  // namespace

CouchCorrection ComputeCouchCorrection(const Rigid3d& room_from_model_current,
                                       const Rigid3d& room_from_model_target,
                                       const CorrectionUncertainty& uncertainty,
                                       const CouchTolerances& tolerances) {
  const Eigen::Matrix3d R_target = room_from_model_target.RotationMatrix();
  const Eigen::Vector3d shift_room = room_from_model_target.translation - room_from_model_current.translation;
  const Eigen::Quaterniond turn = room_from_model_target.rotation * room_from_model_current.rotation.conjugate();
  const Eigen::AngleAxisd aa(turn.normalized());
  Eigen::Vector3d rotvec_room = aa.axis() * aa.angle();
  if (aa.angle() > kPi) rotvec_room = aa.axis() * (aa.angle() - 2 * kPi);
  const Eigen::Vector3d shift = 1000.0 * ToCouch(R_target.transpose() * shift_room);
  const Eigen::Vector3d turn_deg = (180.0 / kPi) * ToCouch(R_target.transpose() * rotvec_room);
  CouchCorrection c;
  c.lateral_mm = shift.x();
  c.longitudinal_mm = shift.y();
  c.vertical_mm = shift.z();
  c.pitch_deg = turn_deg.x();
  c.roll_deg = turn_deg.y();
  c.yaw_deg = turn_deg.z();
  c.translation_mm = shift.norm();
  c.rotation_deg = turn_deg.norm();
  c.uncertainty = uncertainty;
  const bool within = c.translation_mm + std::max(0.0, uncertainty.translation_mm) <= tolerances.translation_mm &&
                      c.rotation_deg + std::max(0.0, uncertainty.rotation_deg) <= tolerances.rotation_deg;
  c.state = within ? CorrectionState::kIn : CorrectionState::kOut;
  return c;
}

CouchCorrection LostCorrection() { return CouchCorrection(); }

Rigid3d ApplyCouchCorrection(const Rigid3d& room_from_model_current, const CouchCorrection& correction,
                             const Rigid3d& room_from_model_target) {
  const Eigen::Matrix3d R_target = room_from_model_target.RotationMatrix();
  const Eigen::Vector3d shift_room =
      R_target * FromCouch(Eigen::Vector3d(correction.lateral_mm, correction.longitudinal_mm, correction.vertical_mm)) /
      1000.0;
  const Eigen::Vector3d rotvec_room =
      R_target * FromCouch(Eigen::Vector3d(correction.pitch_deg, correction.roll_deg, correction.yaw_deg)) * kPi /
      180.0;
  const Rigid3d turn = Rigid3d::FromRotationVector(rotvec_room, Eigen::Vector3d::Zero());
  return Rigid3d(turn.rotation * room_from_model_current.rotation, room_from_model_current.translation + shift_room);
}

std::string CorrectionsCsvHeader() {
  return "timestamp,lateral_mm,longitudinal_mm,vertical_mm,pitch_deg,roll_deg,yaw_deg,translation_mm,rotation_deg,"
         "state\n";
}

namespace {
// A value as printed with `decimals`, without "-0.000" for what rounds to zero.
double Printable(double value, int decimals) {
  return std::abs(value) < 0.5 * std::pow(10.0, -decimals) ? 0.0 : value;
}
}  // namespace

std::string CorrectionsCsvRow(double timestamp_s, const CouchCorrection& c) {
  if (c.state == CorrectionState::kLost) return StringPrintf("%.6f,,,,,,,,,lost\n", timestamp_s);
  return StringPrintf("%.6f,%.3f,%.3f,%.3f,%.4f,%.4f,%.4f,%.3f,%.4f,%s\n", timestamp_s, Printable(c.lateral_mm, 3),
                      Printable(c.longitudinal_mm, 3), Printable(c.vertical_mm, 3), Printable(c.pitch_deg, 4),
                      Printable(c.roll_deg, 4), Printable(c.yaw_deg, 4), Printable(c.translation_mm, 3),
                      Printable(c.rotation_deg, 4), CorrectionStateName(c.state));
}

std::string SizeAndState(const CouchCorrection& c) {
  const bool bound = c.uncertainty.translation_mm > 0 || c.uncertainty.rotation_deg > 0;
  const std::string shift = bound ? StringPrintf("%.1f +-%.1f mm", Printable(c.translation_mm, 1),
                                                 c.uncertainty.translation_mm)
                                  : StringPrintf("%.1f mm", Printable(c.translation_mm, 1));
  const std::string turn = bound ? StringPrintf("%.2f +-%.2f deg", Printable(c.rotation_deg, 2),
                                                c.uncertainty.rotation_deg)
                                 : StringPrintf("%.2f deg", Printable(c.rotation_deg, 2));
  return shift + "  " + turn + "  " +
         (c.state == CorrectionState::kIn ? "IN TOLERANCE" : "OUT OF TOLERANCE");
}

std::string DescribeCorrection(const CouchCorrection& c) {
  if (c.state == CorrectionState::kLost) return "patient lost: no correction";
  return StringPrintf(
             "lat %+.1f  lng %+.1f  vrt %+.1f mm | pitch %+.2f  roll %+.2f  yaw %+.2f deg | ",
             Printable(c.lateral_mm, 1), Printable(c.longitudinal_mm, 1),
             Printable(c.vertical_mm, 1), Printable(c.pitch_deg, 2), Printable(c.roll_deg, 2),
             Printable(c.yaw_deg, 2)) +
         SizeAndState(c);
}

RoomFrameBound BoundOfRoomFrame(double position_sigma_mm, double rotation_sigma_deg,
                                const CouchTolerances& tolerances, double sigmas) {
  RoomFrameBound bound;
  bound.translation_mm = sigmas * position_sigma_mm;
  bound.rotation_deg = sigmas * rotation_sigma_deg;
  bound.blocks_in = !(bound.translation_mm < tolerances.translation_mm &&
                      bound.rotation_deg < tolerances.rotation_deg);
  if (bound.blocks_in) {
    bound.advice = StringPrintf(
        "with this room map no tracked frame can read `in` at a tolerance of %.1f mm / %.1f deg: "
        "the room frame alone bounds every correction by %.1f mm / %.2f deg (%g sigma); record "
        "the room again with close, sharp views of the origin marker, or more room markers "
        "between it and the couch",
        tolerances.translation_mm, tolerances.rotation_deg, bound.translation_mm,
        bound.rotation_deg, sigmas);
  }
  return bound;
}

}  // namespace arpos
