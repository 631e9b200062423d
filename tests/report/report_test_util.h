#pragma once
// A session store for the report tests, written through the Database API as
// the program writes it (every clinical row with its audit entry, so the
// audit log verifies): a patient, a plan, a session with a body marker map, a
// reconstruction, two alignments and tracking runs with known figures.

#include <filesystem>
#include <string>

#include "store/database.h"

namespace arpos::test {

struct ReportStoreOptions {
  std::string patient_external_id = "P-REPORT-7";
  std::string patient_name = "Test Patient";
  std::string plan_name = "Pelvis plan A";
  int num_runs = 2;  ///< 0: a session without tracking
  /// >= 0: the plan gets a room map (id 7 origin, two markers) whose room
  /// frame is known to this at the couch, tilt 0.03 and yaw 0.04 deg (so
  /// 0.05 deg together); < 0: no room map.
  double room_frame_couch_sigma_mm = -1;
};

struct ReportStoreIds {
  PatientId patient;
  PlanId plan;
  SessionId session;
  SessionId other_session;  ///< a second session of the same plan, with its own run
  std::vector<TrackingRunId> runs;
  std::vector<AlignmentId> alignments;
};

/// Run 1 ("seq_00"): 20 frames 0.1 s apart, tolerance 3 mm / 2 deg:
///   frames 0-4   out of tolerance, tracked, correction (10 - 2i, 1, -1) mm, (1, 0, 0) deg
///   frames 5-7   lost
///   frames 8-19  in tolerance (8-9 carried, the rest tracked), correction
///                (0.5, 0.2, -0.1) mm, (0.1, 0.2, 0.3) deg; the last (19)
///                (0.4, -0.3, 0.2) mm, (0.1, -0.2, 0.3) deg
///   total_ms = 10 + frame index
/// Run 2 ("seq_01"): 5 frames, all in tolerance.
ReportStoreIds WriteReportStore(Database& database, const ReportStoreOptions& options = {});

}  // namespace arpos::test
