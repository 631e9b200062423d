#pragma once
/// The couch correction shown to the therapist: the couch motion that brings
/// the patient from the current pose to the planned one (DATASET.md,
/// "Corrections").
///
/// - The isocentre (the reference model's origin) moves by t_target - t_current;
///   the patient turns about the isocentre by R_target * R_current^T.
/// - Couch axes (IEC 61217, head first supine) are the planned model's axes for
///   a model in DICOM patient coordinates (x to the patient's left, y
///   posterior, z superior): lateral = +x, longitudinal = +z (towards the
///   gantry), vertical = -y (up). Translations are the isocentre shift in these
///   axes; pitch, roll and yaw are the components of the correction's rotation
///   vector about lateral, longitudinal and vertical.
/// - State: `in` only when the correction *plus its own uncertainty* is within
///   both tolerances, so a frame truly out of tolerance does not read `in` as
///   long as the uncertainty bound holds; `out` otherwise; `lost` without a pose.
///
/// No Qt, no I/O beyond formatting: the GUI, the CLI and the store use it alike.

#include <string>

#include "geometry/rigid3.h"

namespace arpos {

enum class CorrectionState { kIn, kOut, kLost };
/// "in", "out", "lost" (the corrections.csv spelling).
const char* CorrectionStateName(CorrectionState state);

struct CouchTolerances {
  double translation_mm = 2.0;  ///< > 0
  double rotation_deg = 1.0;    ///< > 0
  /// Empty if valid, else what is wrong.
  std::string Validate() const;
};

/// What the correction itself may be wrong by (a bound, e.g. 3 sigma, of the
/// pose error at the isocentre and of its angle), added to the correction's
/// magnitude before the tolerance test.
struct CorrectionUncertainty {
  double translation_mm = 0;
  double rotation_deg = 0;
};

struct CouchCorrection {
  double lateral_mm = 0, longitudinal_mm = 0, vertical_mm = 0;
  double pitch_deg = 0, roll_deg = 0, yaw_deg = 0;
  double translation_mm = 0;  ///< length of the shift
  double rotation_deg = 0;    ///< angle of the turn
  CorrectionUncertainty uncertainty;  ///< the bound the state was decided with
  CorrectionState state = CorrectionState::kLost;
};

/// The correction's size with the bound its state was decided with, and the
/// state: "1.0 +-4.5 mm  0.33 +-0.30 deg  OUT OF TOLERANCE" (the bound left
/// out when there is none), so that a shift within the tolerance that reads
/// `out` shows why. Not for a lost correction.
std::string SizeAndState(const CouchCorrection& c);

/// How many sigmas of a pose's uncertainty a correction's bound spans by
/// default (TrackerOptions::uncertainty_sigmas).
constexpr double kDefaultUncertaintySigmas = 3.0;

/// What a room frame known to `position_sigma_mm` at the isocentre and
/// `rotation_sigma_deg` (1 sigma, from the plan) alone adds to every
/// correction's bound, `sigmas` of each: whether that alone keeps every frame
/// from reading `in` at `tolerances` (the bound reaches either tolerance),
/// and then one sentence for whoever plans, approves or audits the plan
/// (what cannot read `in`, why, what to record); empty otherwise.
struct RoomFrameBound {
  double translation_mm = 0, rotation_deg = 0;  ///< the bound it adds
  bool blocks_in = false;
  std::string advice;
};
RoomFrameBound BoundOfRoomFrame(double position_sigma_mm, double rotation_sigma_deg,
                                const CouchTolerances& tolerances,
                                double sigmas = kDefaultUncertaintySigmas);

/// The correction from `room_from_model_current` to `room_from_model_target`.
CouchCorrection ComputeCouchCorrection(const Rigid3d& room_from_model_current,
                                       const Rigid3d& room_from_model_target,
                                       const CorrectionUncertainty& uncertainty,
                                       const CouchTolerances& tolerances);

/// A frame with no pose: every number zero, state lost.
CouchCorrection LostCorrection();

/// The pose the patient is at after the couch applies `correction` to
/// `room_from_model_current` (the inverse of ComputeCouchCorrection, for tests
/// and for the display of what the couch will do).
Rigid3d ApplyCouchCorrection(const Rigid3d& room_from_model_current, const CouchCorrection& correction,
                             const Rigid3d& room_from_model_target);

/// corrections.csv (DATASET.md): the header line (with '\n') and one row.
std::string CorrectionsCsvHeader();
std::string CorrectionsCsvRow(double timestamp_s, const CouchCorrection& correction);

/// One line for a person: "move lateral +1.2 mm, ... (out of tolerance)".
std::string DescribeCorrection(const CouchCorrection& correction);

}  // namespace arpos
