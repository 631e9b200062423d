#pragma once
/// Plain records the session store reads and writes (src/store/database.h).
///
/// One struct per table of schema/NNNN_*.sql. Records are values: no
/// behaviour, no database handles. Units are in the names (SI inside; mm and
/// degrees only for the corrections a person reads); every pose is a Rigid3d
/// named by what it maps (see geometry/rigid3.h):
///   room frame    frame of the room origin marker (DATASET.md)
///   model frame   coordinates of the reference model file
///   body frame    frame of a session's body scan: the body marker map and the
///                 reconstruction built from the same scan share it
/// Times are UTC milliseconds since 1970-01-01 (`*_unix_ms`). On Add*, a
/// created/started time of 0 means "now".

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "geometry/rigid3.h"

namespace arpos {

/// A row id typed by the table it belongs to, so a SessionId cannot be passed
/// where a PlanId is expected. 0 is "no id" (SQLite row ids start at 1).
template <typename Tag>
class RowId {
 public:
  constexpr RowId() = default;
  constexpr explicit RowId(std::int64_t value) : value_(value) {}
  constexpr std::int64_t value() const { return value_; }
  constexpr bool valid() const { return value_ > 0; }
  friend constexpr bool operator==(RowId a, RowId b) { return a.value_ == b.value_; }
  friend constexpr bool operator!=(RowId a, RowId b) { return a.value_ != b.value_; }
  friend constexpr bool operator<(RowId a, RowId b) { return a.value_ < b.value_; }

 private:
  std::int64_t value_ = 0;
};

using PatientId = RowId<struct PatientIdTag>;
using PlanId = RowId<struct PlanIdTag>;
using SessionId = RowId<struct SessionIdTag>;
using RecordingId = RowId<struct RecordingIdTag>;
using RoomMapId = RowId<struct RoomMapIdTag>;
using BodyMarkerMapId = RowId<struct BodyMarkerMapIdTag>;
using ReconstructionId = RowId<struct ReconstructionIdTag>;
using AlignmentId = RowId<struct AlignmentIdTag>;
using TrackingRunId = RowId<struct TrackingRunIdTag>;
using AuditId = RowId<struct AuditIdTag>;

// ---------------------------------------------------------------- geometry data

/// A point cloud as stored (blob_codec.h): positions in metres in the frame the
/// owning record names; `normals` (unit vectors) and `colors` (RGB) are either
/// empty or exactly one per point.
struct StoredPointCloud {
  std::vector<Eigen::Vector3f> points;
  std::vector<Eigen::Vector3f> normals;
  std::vector<std::array<std::uint8_t, 3>> colors;  ///< R, G, B
};

/// A triangle mesh as stored: vertex positions in metres; each face holds
/// three vertex indices, counter-clockwise seen from outside.
struct StoredTriangleMesh {
  std::vector<Eigen::Vector3f> vertices;
  std::vector<std::array<std::uint32_t, 3>> faces;
};

/// Row-major bytes, e.g. one binary feature descriptor (ORB: 32 bytes) per row.
using ByteMatrix = Eigen::Matrix<std::uint8_t, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// ---------------------------------------------------------------- planning

struct PatientRecord {
  PatientId id;             ///< set by the store
  std::string external_id;  ///< hospital patient id; unique, non-empty
  std::string display_name;
  std::int64_t created_unix_ms = 0;
};

/// A treatment plan: the reference body surface and where it must be in the room.
struct PlanRecord {
  PlanId id;  ///< set by the store
  PatientId patient_id;
  std::string name;                    ///< non-empty
  std::string reference_model_name;    ///< source file name, for people
  StoredTriangleMesh reference_model;  ///< model frame, metres
  Rigid3d room_from_model_target;      ///< desired pose of the model in the room
  std::int64_t created_unix_ms = 0;
  /// Approval (Database::ApprovePlan; only a physicist approves, store/roles.h).
  /// Empty / nullopt while the plan is not approved; AddPlan ignores them.
  /// An approved plan cannot be changed, deleted, or given another room map.
  std::string approved_by;  ///< "name (role)"
  std::optional<std::int64_t> approved_unix_ms;
  std::string approval_note;
  bool approved() const { return approved_unix_ms.has_value(); }
};

/// One line of a plan listing (no blobs).
struct PlanSummary {
  PlanId id;
  PatientId patient_id;
  std::string patient_external_id;
  std::string name;
  std::int64_t created_unix_ms = 0;
  std::int64_t num_sessions = 0;
  std::int64_t num_room_maps = 0;
  std::string approved_by;                       ///< empty while not approved
  std::optional<std::int64_t> approved_unix_ms;  ///< nullopt while not approved
  bool approved() const { return approved_unix_ms.has_value(); }
};

/// A room marker in the map: its 4 corners in the room frame (metres, OpenCV
/// ArUco corner order: top-left, top-right, bottom-right, bottom-left of the
/// printed face) and its mean reprojection residual over the room sequence.
struct RoomMapMarker {
  int marker_id = 0;
  std::array<Eigen::Vector3d, 4> corners_in_room;
  double residual_px = 0;
  int num_observations = 0;
};

/// The planning-stage map of the treatment room, expressed in the room frame.
struct RoomMapRecord {
  RoomMapId id;  ///< set by the store
  PlanId plan_id;
  std::optional<RecordingId> recording_id;  ///< the room sequence it was built from
  int origin_marker_id = 0;                 ///< defines the room frame
  double marker_size_m = 0;                 ///< > 0
  std::vector<RoomMapMarker> markers;       ///< marker ids unique
  double mean_residual_px = 0;              ///< over all markers and views
  double max_residual_px = 0;               ///< >= mean_residual_px
  /// Keypoint landmarks: positions in the room frame and, row for row, their
  /// descriptors. Both empty if the map has no keypoint layer.
  StoredPointCloud landmarks_in_room;
  ByteMatrix landmark_descriptors;
  /// The colour camera's response as CameraResponse::Serialize writes it
  /// (features/camera_response.h); empty: not recorded (read as sRGB).
  /// Stored as text so the store does not depend on the features layer.
  std::string camera_response;
  /// The depth camera's systematic error as DepthCorrection::Serialize
  /// writes it (sensor/depth_correction.h); empty: not recorded (no correction).
  std::string depth_correction;
  /// The room frame's own uncertainty (1 sigma; room_map_builder.h
  /// RoomMapBuildReport): tilt of the origin marker about its in-plane axes,
  /// yaw about its normal, and the position error at the plan's isocentre:
  /// the larger of the origin's own and the map's near the couch relative
  /// to the origin (RoomMapBuildReport::CouchSigmaMm; maps planned before
  /// 2026-12-04 hold the origin's own alone); tilt and yaw likewise
  /// (CouchTiltSigmaDeg, CouchYawSigmaDeg; before 2026-12-05 the origin's
  /// own alone).
  /// Empty: not measured (maps from before schema version 4, or too few views).
  std::optional<double> room_frame_tilt_sigma_deg;
  std::optional<double> room_frame_yaw_sigma_deg;
  std::optional<double> room_frame_couch_sigma_mm;
  /// The room's still surface near the couch (room_map/room_surface.h):
  /// points with unit normals in the room frame, gathered on voxels of
  /// surface_voxel_m. Empty: none kept (maps from before schema version 10).
  StoredPointCloud surface;
  double surface_voxel_m = 0;
  std::int64_t created_unix_ms = 0;
};

/// The room frame's uncertainty at the planned isocentre as tracking takes
/// it (1 sigma): the position, and one angle for tilt and yaw together
/// (their root sum of squares); nullopt when the map does not hold all three
/// or any is not a finite non-negative number.
struct RoomFrameSigmas {
  double position_mm = 0;
  double rotation_deg = 0;
};
std::optional<RoomFrameSigmas> RoomFrameSigmasOf(const RoomMapRecord& map);

// ---------------------------------------------------------------- session

enum class SessionStatus { kOpen, kCompleted, kAborted };

/// One treatment session (fraction) of a plan.
struct SessionRecord {
  SessionId id;  ///< set by the store
  PlanId plan_id;
  int fraction = 1;  ///< >= 1
  std::string operator_name;
  std::int64_t started_unix_ms = 0;
  SessionStatus status = SessionStatus::kOpen;
  std::optional<std::int64_t> ended_unix_ms;  ///< set when no longer open
  std::string notes;
  /// The session ran on a plan that was not approved (the --unapproved
  /// escape, or a research run); recorded when it is opened.
  bool on_unapproved_plan = false;
  std::string ended_by;    ///< who completed or aborted it ("name (role)")
  std::string end_reason;  ///< why, in words (aborted runs; may be empty)
};

/// A command at work on a session (a tracking run, the positioning screen):
/// one row while it runs. A row left behind by a process that no longer
/// exists is a run that died (controllers/session_lifecycle.h).
struct SessionActivity {
  std::int64_t id = 0;  ///< set by the store
  SessionId session_id;
  std::int64_t pid = 0;
  std::string host;
  std::string command;  ///< e.g. "arpos track seq_00"
  std::int64_t started_unix_ms = 0;
};

enum class RecordingKind { kRoom, kBodyScan, kTracking };

/// Pinhole model of a recording; the same fields as sensor/intrinsics.h
/// CameraIntrinsics (the store does not depend on the sensor layer).
struct RecordingIntrinsics {
  int width = 0;
  int height = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;
  std::array<double, 5> distortion{{0, 0, 0, 0, 0}};  ///< OpenCV k1 k2 p1 p2 k3
  double depth_scale = 1000.0;                        ///< depth units per metre
};

/// An RGB-D sequence on disk (DATASET.md layout). A kRoom recording belongs to
/// a plan; kBodyScan and kTracking recordings belong to a session: exactly one
/// of plan_id and session_id is set, matching the kind.
struct RecordingRecord {
  RecordingId id;  ///< set by the store
  std::optional<PlanId> plan_id;
  std::optional<SessionId> session_id;
  RecordingKind kind = RecordingKind::kRoom;
  std::string name;  ///< e.g. the tracking/<name> folder name
  std::string path;  ///< sequence folder, non-empty
  std::int64_t frame_count = 0;
  RecordingIntrinsics intrinsics;
  std::int64_t created_unix_ms = 0;
};

/// A body marker in the body frame, with its residual over the body scan.
struct BodyMarker {
  int marker_id = 0;
  Rigid3d body_from_marker;
  double residual_px = 0;
  int num_observations = 0;
  /// How far the sticker moved with the breathing during the scan, along
  /// `motion_direction` (1 sigma, m; 0: it did not, or nothing could be told).
  double motion_m = 0;
  /// Which way it moved, a unit vector in the sticker's own frame
  /// (body_model/sticker_motion.h); (0, 0, 1), its normal, where the scan
  /// could not tell (and for maps stored before schema version 12).
  Eigen::Vector3d motion_direction = Eigen::Vector3d::UnitZ();
  /// Whether the scan measured which way it moved (else: along its normal).
  bool HasMotionDirection() const {
    return !motion_direction.isApprox(Eigen::Vector3d::UnitZ(), 1e-12);
  }
};

struct BodyMarkerMapRecord {
  BodyMarkerMapId id;  ///< set by the store
  SessionId session_id;
  std::optional<RecordingId> recording_id;  ///< the body scan
  double marker_size_m = 0;                 ///< > 0
  std::vector<BodyMarker> markers;          ///< marker ids unique
  double mean_residual_px = 0;
  double max_residual_px = 0;  ///< >= mean_residual_px
  /// The reference model's surface patches that moved during the scan
  /// (breathing): centres of cubes of `surface_patch_m`, model frame. Empty:
  /// nothing moved, or nothing could be told.
  double surface_patch_m = 0;
  std::vector<Eigen::Vector3d> moving_surface_patches;
  /// The room around the couch as the scan saw it (room_map/scan_landmarks.h):
  /// keypoint landmarks in the room frame and, row for row, their ORB
  /// descriptors (N x 32), for tracking. Empty: none (maps stored before
  /// schema version 11, or a scan that placed none).
  StoredPointCloud room_landmarks;
  ByteMatrix room_landmark_descriptors;
  /// How well they sit in the room (1 sigma, m): all together, as the
  /// session placed its scan (at the stickers), and each on its own (how
  /// far its views disagree: ScanLandmarks::spread_m).
  double room_landmarks_placement_sigma_m = 0;
  double room_landmarks_position_sigma_m = 0;
  std::int64_t created_unix_ms = 0;
};

/// The body surface reconstructed from a scan, in the body frame.
struct ReconstructionRecord {
  ReconstructionId id;  ///< set by the store
  SessionId session_id;
  std::optional<RecordingId> recording_id;
  StoredPointCloud cloud;
  std::optional<StoredTriangleMesh> mesh;
  std::int64_t num_frames_used = 0;
  double voxel_size_m = 0;  ///< 0: not voxelised
  std::int64_t created_unix_ms = 0;
};

enum class AlignmentMethod { kManual, kIcp, kAutomatic };

/// The reference model registered to a reconstruction. A refinement names the
/// alignment it started from in `parent_alignment_id`.
struct AlignmentRecord {
  AlignmentId id;  ///< set by the store
  ReconstructionId reconstruction_id;
  std::optional<AlignmentId> parent_alignment_id;
  AlignmentMethod method = AlignmentMethod::kManual;
  Rigid3d reconstruction_from_model;
  double fitness = 0;  ///< inlier fraction in [0, 1]
  double rmse_m = 0;   ///< inlier RMSE, >= 0
  std::int64_t num_inliers = 0;
  std::string options;  ///< stage options as YAML, for the record
  std::int64_t created_unix_ms = 0;

  /// The session stage ends an ICP alignment's options with its verdict,
  /// "status: ok" or what to check; kStatusKey marks it.
  static constexpr const char* kStatusKey = "status: ";
  /// That verdict ("ok", "check: 3 sticker(s) off the aligned model", ...),
  /// empty when the options hold none.
  std::string StageVerdict() const {
    const std::string key = kStatusKey;
    const size_t at = options.rfind(key);
    return at == std::string::npos ? std::string() : options.substr(at + key.size());
  }
  /// Whether a verdict asks for the alignment to be looked at (not "ok", not none).
  static bool AsksForCheck(const std::string& verdict) {
    return !verdict.empty() && verdict != "ok";
  }
};

// ---------------------------------------------------------------- tracking

struct TrackingRunRecord {
  TrackingRunId id;  ///< set by the store
  SessionId session_id;
  std::optional<AlignmentId> alignment_id;  ///< the alignment tracking started from
  std::optional<RecordingId> recording_id;  ///< the sequence, if replayed or recorded
  std::string options;                      ///< stage options as YAML
  double tolerance_translation_mm = 3.0;    ///< > 0
  double tolerance_rotation_deg = 2.0;      ///< > 0
  std::int64_t started_unix_ms = 0;
  /// The tracking/<name> folder name of the sequence; empty: not recorded
  /// (runs from before schema version 5).
  std::string sequence_name;
  /// Person-readable summary written when the run is stored (frames,
  /// tracked/carried/lost, in/out, timing); empty: not recorded.
  std::string summary;
};

enum class TrackingFrameStatus { kInTolerance, kOutOfTolerance, kLost };

/// The 6-DoF couch correction shown to the operator, in the couch axes of
/// DATASET.md "Corrections" (IEC 61217, the planned model's axes):
/// translation_mm = (lateral, longitudinal, vertical) isocentre shift in mm,
/// rotation_deg = (pitch, roll, yaw), the rotation vector's components about
/// those axes in degrees.
struct Correction6Dof {
  Eigen::Vector3d translation_mm = Eigen::Vector3d::Zero();
  Eigen::Vector3d rotation_deg = Eigen::Vector3d::Zero();
};

/// One processed frame. kLost <=> no estimate: room_from_model, correction
/// and the uncertainty are empty exactly when status is kLost, and source is
/// "lost" exactly then (Database::AppendTrackingFrames refuses anything else).
/// Frames stored before schema version 5 read back with source "lost" or
/// "tracked" by their status, no room_from_camera, no uncertainty (even when
/// not lost), total_ms 0 and an empty note.
struct TrackingFrameRecord {
  std::int64_t frame_index = 0;  ///< >= 0, unique within a run
  double timestamp_s = 0;        ///< sequence timestamp
  TrackingFrameStatus status = TrackingFrameStatus::kLost;
  std::optional<Rigid3d> room_from_model;  ///< estimated model pose in the room
  std::optional<Correction6Dof> correction;
  /// Camera -> room, the camera's localisation in the room map. May be set on
  /// a lost frame (camera localised, patient not found); empty when the
  /// camera was not localised.
  std::optional<Rigid3d> room_from_camera;
  /// How the patient pose was obtained: "tracked" (measured in this frame),
  /// "carried" (carried over from earlier frames) or "lost" (none).
  std::string source = "lost";
  /// The bound on the pose error the in/out verdict was made with; both set,
  /// >= 0, exactly when not lost.
  std::optional<double> uncertainty_translation_mm;
  std::optional<double> uncertainty_rotation_deg;
  double total_ms = 0;  ///< processing time of the frame, >= 0
  std::string note;     ///< why lost or carried, free text; may be empty
};

// ---------------------------------------------------------------- audit

/// One line of the append-only audit log.
struct AuditEntry {
  AuditId id;  ///< set by the store
  std::int64_t time_unix_ms = 0;
  std::string actor;    ///< who (user or program), non-empty
  std::string action;   ///< what, e.g. "approve_alignment", non-empty
  std::string entity;   ///< on what, e.g. "alignment:7"
  std::string details;  ///< free text
};

const char* ToString(SessionStatus status);
const char* ToString(RecordingKind kind);
const char* ToString(AlignmentMethod method);
const char* ToString(TrackingFrameStatus status);
/// Inverses of ToString; throw arpos::Error naming the unknown text.
SessionStatus ParseSessionStatus(const std::string& text);
RecordingKind ParseRecordingKind(const std::string& text);
AlignmentMethod ParseAlignmentMethod(const std::string& text);
TrackingFrameStatus ParseTrackingFrameStatus(const std::string& text);

}  // namespace arpos

template <typename Tag>
struct std::hash<arpos::RowId<Tag>> {
  std::size_t operator()(arpos::RowId<Tag> id) const noexcept {
    return std::hash<std::int64_t>()(id.value());
  }
};
