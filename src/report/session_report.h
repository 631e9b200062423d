#pragma once
/// The session report a medical physicist signs: everything the store knows
/// about one session, gathered into plain values (no Qt, no rendering).
///
/// GatherSessionReport reads the session, its plan and patient, body marker
/// maps, reconstructions, alignments, tracking runs with their frames, the
/// audit entries that belong to them, and the audit log's verification.
/// Renderers (report_html.h, report_writer.h) turn it into HTML or PDF.
///
/// Tracking figures, per run:
/// - tracked / carried / lost count the frames by their `source`; in / out /
///   lost by their status (the in/out verdict includes the uncertainty bound).
/// - Time in tolerance (s) is the sum, over the frames in tolerance, of the
///   time to the next frame; the last frame adds nothing. The duration is
///   last minus first timestamp.
/// - Correction magnitudes are |translation| (mm) and the rotation vector's
///   length (deg); per-axis values are in the couch axes of DATASET.md
///   (lateral, longitudinal, vertical; pitch, roll, yaw).
/// - Latency is the frames' total_ms (frames with total_ms 0, from stores
///   before schema version 5, are left out).

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "store/audit_chain.h"
#include "store/database.h"
#include "store/records.h"

namespace arpos {

/// The plan's approval (store/lifecycle.h: only a physicist approves).
struct PlanApprovalInfo {
  bool approved = false;
  std::string approved_by;            ///< "name (role)"; empty while not approved
  std::int64_t approved_unix_ms = 0;  ///< 0 while not approved
  std::string note;                   ///< the approver's note
};

struct ReportAlignment {
  AlignmentRecord record;
  bool used_by_tracking = false;  ///< some tracking run of the session started from it
};

struct ReportReconstruction {
  ReconstructionId id;
  std::int64_t num_points = 0;
  std::optional<std::int64_t> num_mesh_faces;
  std::int64_t num_frames_used = 0;
  double voxel_size_m = 0;
  std::int64_t created_unix_ms = 0;
  std::vector<ReportAlignment> alignments;  ///< oldest first
};

/// One frame's numbers as the plots and tables use them.
struct ReportFrame {
  std::int64_t frame_index = 0;
  double time_s = 0;  ///< since the run's first frame
  TrackingFrameStatus status = TrackingFrameStatus::kLost;
  std::string source;
  std::optional<Correction6Dof> correction;  ///< empty when lost
  double total_ms = 0;
};

struct ReportRun {
  TrackingRunRecord run;
  std::string name;  ///< sequence name, or "run N" when not recorded
  std::vector<ReportFrame> frames;
  int num_frames = 0;
  int num_tracked = 0, num_carried = 0, num_lost_source = 0;  ///< by source
  int num_in = 0, num_out = 0, num_lost = 0;                  ///< by status
  double duration_s = 0;
  double time_in_tolerance_s = 0;
  /// First and last frame with a correction, and the largest magnitudes.
  std::optional<ReportFrame> first_correction, last_correction;
  double max_translation_mm = 0, max_rotation_deg = 0;
  std::optional<double> latency_mean_ms, latency_p95_ms;
  int latency_frames = 0;

  static double Percent(int part, int whole) { return whole > 0 ? 100.0 * part / whole : 0.0; }
};

/// The plan's newest room map, as much as the report says of it (no blobs).
struct ReportRoomMap {
  RoomMapId id;
  int origin_marker_id = 0;
  int num_markers = 0;
  std::int64_t num_landmarks = 0;
  double mean_residual_px = 0, max_residual_px = 0;
  std::int64_t created_unix_ms = 0;
  /// How well the room frame is known at the couch (1 sigma); nullopt: a
  /// map from before it was measured.
  std::optional<RoomFrameSigmas> room_frame;
};

struct SessionReport {
  std::string title = "ARPos patient positioning session report";
  std::int64_t generated_unix_ms = 0;
  std::string program_version;
  std::string store_path;

  PatientRecord patient;  ///< no blobs
  PlanRecord plan;        ///< reference_model left empty (only its size below)
  std::int64_t reference_model_vertices = 0, reference_model_faces = 0;
  std::optional<PlanApprovalInfo> approval;  ///< set whenever the plan was read
  std::optional<ReportRoomMap> room_map;     ///< the plan's newest room map, if any
  SessionRecord session;

  std::vector<BodyMarkerMapRecord> body_marker_maps;
  std::vector<ReportReconstruction> reconstructions;
  std::vector<ReportRun> runs;

  /// Audit entries of the session, its records, the plan (and its room maps)
  /// and the patient, oldest first.
  std::vector<AuditEntry> audit;
  AuditVerification verification;
  /// One line: "Audit log verifies: ..." or "Audit log does not verify: ...".
  std::string verification_line;
};

/// Gathers the report of `session`. Throws InputError("session N is not in
/// the store FILE") when there is no such session; `store_path` names the
/// store in that message and in the report. Reads only.
SessionReport GatherSessionReport(Database* database, SessionId session,
                                  const std::string& store_path = std::string());

/// The verification as one line for people (see SessionReport).
std::string VerificationLine(const AuditVerification& verification);

/// The program version (the project's version, e.g. "0.1.0").
const char* ReportProgramVersion();

/// "x, y, z" with `decimals` decimals.
std::string FormatVector3(const Eigen::Vector3d& v, int decimals);

/// What the body scan measured of the breathing, for people: "stickers 107,
/// 125 moved with the breathing (1.1-1.3 mm, 1 sigma each along the direction the
/// scan measured);
/// 84 surface patches of 4 cm moved", or "no sticker or surface patch moved
/// with the breathing (or the scan could not tell)".
std::string DescribeBreathing(const BodyMarkerMapRecord& map);

/// The room landmarks the body scan placed for tracking (room_map/scan_landmarks.h),
/// for people: "323 keypoints around the couch, for frames the room map does not
/// place; in the room as the scan was placed (2.1 mm at the stickers, 1 sigma),
/// each to 4.6 mm", or why there are none.
std::string DescribeScanLandmarks(const BodyMarkerMapRecord& map);

}  // namespace arpos
