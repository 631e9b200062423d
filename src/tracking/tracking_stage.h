#pragma once
/// The tracking stage with the session store: what a tracking run needs (the
/// plan's room map, reference model and planned pose; the session's stickers
/// on the model), one recorded sequence tracked frame by frame, the files of
/// DATASET.md "Outputs of tracking", and the run with every frame in the
/// store. Used by `arpos track`, `arpos run-case` and the GUI.
///
/// A run writes its files first and then stores the run and its frames in
/// one transaction: a run whose files cannot be written stores nothing.
/// Frames that cannot be used (no or corrupt colour, missing depth, a gap in
/// the timestamps, no body in view) each get a stated state and the run goes
/// on.

#include <array>
#include <chrono>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "feedback/couch_correction.h"
#include "geometry/rigid3.h"
#include "geometry/triangle_mesh.h"
#include "room_map/room_map.h"
#include "sensor/camera_source.h"
#include "sensor/case_config.h"
#include "sensor/tum_io.h"
#include "store/records.h"
#include "store/roles.h"
#include "tracking/tracker.h"

namespace arpos {

class Database;

/// Everything a tracking run reads from the store.
struct TrackingInputs {
  SessionId session_id;
  PlanId plan_id;
  RoomMapId room_map_id;
  BodyMarkerMapId body_marker_map_id;
  AlignmentId alignment_id;
  /// The session stage's verdict on that alignment ("ok", or what to check,
  /// e.g. "check: 3 sticker(s) off the aligned model"; empty: not stored).
  std::string alignment_status;
  /// The plan's room map with, first among its landmarks, those the
  /// session's body scan placed around the couch (scan_landmarks.h).
  RoomMap room_map;
  int scan_landmarks = 0;
  double scan_landmark_sigma_mm = 0;  ///< their placement in the room (1 sigma)
  TriangleMesh model;
  Rigid3d room_from_model_target;
  /// The session's stickers in the model frame:
  /// reconstruction_from_model^-1 * body_from_marker.
  std::map<int, Rigid3d> model_from_marker;
  double sticker_size_m = 0;
  /// Breathing as the session measured it: per moving sticker how far it
  /// moved along its normal (1 sigma, m), and the moving surface patches
  /// (model frame, cubes of `surface_patch_m`). Empty when nothing moved.
  std::map<int, double> sticker_motion_m;
  /// ... and which way, where the session measured it (unit, sticker frame).
  std::map<int, Eigen::Vector3d> sticker_motion_direction;
  std::vector<Eigen::Vector3d> moving_surface_patches;
  double surface_patch_m = 0;
  /// The patient's pose at the session's body scan (the alignment): where
  /// tracking looks first.
  Rigid3d room_from_model_at_scan;
  /// The plan's room frame uncertainty at the planned isocentre (1 sigma;
  /// rotation: tilt and yaw together); absent for a map stored before the
  /// plan measured it.
  std::optional<double> room_frame_position_sigma_mm;
  std::optional<double> room_frame_rotation_sigma_deg;
  /// Which session and why, for the user.
  std::string session_choice;
};

/// The inputs of `session` if given (it must be open), else of the one open
/// session (with a body marker map and an alignment) of the patient
/// `patient_external_id`, or of the store if it does not know the patient;
/// several open sessions are refused ("choose one with --session ID").
/// Throws InputError saying what is missing and which command makes it.
/// `newest_if_several`: a research run takes the newest of several open
/// sessions and says so; clinical roles choose.
TrackingInputs LoadTrackingInputs(Database* database, std::optional<SessionId> session,
                                  const std::string& patient_external_id, bool newest_if_several = false);

/// What the plan's room frame uncertainty does to the corrections' bounds
/// (`uncertainty_sigmas` of it, TrackerOptions): a line for the user, and
/// whether it alone keeps every frame from reading `in` at `tolerances`.
struct RoomFrameNote {
  std::string text;
  bool blocks_in = false;
  /// When it blocks `in`: the same for whoever plans or approves, as one
  /// sentence (what no frame can read, why, what to record); else empty.
  std::string plan_advice;
};
RoomFrameNote DescribeRoomFrame(const TrackingInputs& inputs, const CouchTolerances& tolerances,
                                double uncertainty_sigmas = TrackerOptions().uncertainty_sigmas);
/// The same from a room map as stored (its room frame's sigmas: position at
/// the couch, tilt and yaw together), for those who approve or show a plan.
RoomFrameNote DescribeRoomFrame(const RoomMapRecord& map, const CouchTolerances& tolerances = {},
                                double uncertainty_sigmas = TrackerOptions().uncertainty_sigmas);

/// Where the overlay draws the model for a tracked frame: the current pose
/// (camera_from_model, from the room poses when the camera is localised, else
/// the body tracker's own) and the planned one (only with a camera pose).
struct OverlayPoses {
  std::optional<Rigid3d> camera_from_model_current;
  std::optional<Rigid3d> camera_from_model_planned;
};
OverlayPoses OverlayPosesOf(const TrackedFrame& tracked, const Rigid3d& room_from_model_target);

/// One frame as TrackSequence finished it, for a live display.
struct TrackedFrameEvent {
  size_t index = 0;  ///< frame index in the sequence
  size_t count = 0;  ///< frames in the sequence
  const TrackedFrame* tracked = nullptr;
  /// The colour image (BGR); empty when the frame could not be read.
  cv::Mat colour;
  bool has_depth = false;  ///< the frame had a usable depth image
  OverlayPoses poses;
  std::string note;  ///< the frame's note as stored (gap, depth problem, why lost)
};

struct TrackSequenceOptions {
  /// A recorded sequence, played by the replay plugin (with the camera of
  /// `config`), unless `source` is given.
  std::filesystem::path sequence_dir;
  /// The case whose case.yaml describes sequence_dir's camera (empty: the
  /// nearest above sequence_dir).
  std::filesystem::path case_dir;
  /// A camera source to track instead (`arpos track --source`; not owned,
  /// opened and closed here). A live source runs on a capture thread of its
  /// own; frames more than live_queue_frames behind are dropped and counted
  /// (sensor/frame_feed.h). Its intrinsics are used for tracking.
  CameraSource* source = nullptr;
  /// A live source: frames that may wait while one is tracked (a spike of a
  /// slow frame is caught up; more behind than this, the oldest is dropped).
  int live_queue_frames = 2;
  /// Stop after this many frames (0: the whole stream).
  int max_frames = 0;
  /// Every frame the source delivers, tracked or dropped, on the capture
  /// thread (the recorder). Must be quick.
  std::function<void(const RgbdFrame&)> on_capture;
  /// The recording the frames are written to (`--record`), stored as the
  /// run's recording path for a source that is not a recording itself.
  std::filesystem::path record_dir;
  /// The run's name (the tracking/<name> folder name); empty: the folder's name.
  std::string name;
  /// Output folder: poses.txt, camera_poses.txt, corrections.csv, timing.csv
  /// and, with `overlay`, overlay/<timestamp>.png. Created if missing. Empty:
  /// no files (the run is stored all the same).
  std::filesystem::path out_dir;
  bool overlay = false;
  CouchTolerances tolerances;
  /// Who tracks (a therapist, or a research run; store/roles.h).
  Operator op;
  /// The tracking recording already stored for this sequence (run-case
  /// registers them); otherwise one is added with the run.
  std::optional<RecordingId> recording_id;
  /// Frames further apart than this are a gap: said in the frame's note.
  double max_frame_gap_s = 0.25;
  /// Tracking on two threads (scene and body); false for one.
  bool parallel = true;
  /// The patient's room pose through the constant-velocity filter (tracker.h).
  bool temporal_filter = true;
  /// Progress: frame index and count, after each frame.
  std::function<void(size_t, size_t)> progress;
  /// Live use (the GUI). Called before frame `index` of `count` is read; may
  /// block (pause) and returns false to stop: the frames so far are written
  /// and stored as the run (result.stopped). Empty: every frame.
  std::function<bool(size_t index, size_t count)> before_frame;
  /// Called on the tracking thread after each frame, before the next is read.
  std::function<void(const TrackedFrameEvent&)> on_frame;
  /// Called as soon as a frame's correction is known, before its overlay and
  /// files (streaming): the frame as tracked and when it arrived.
  std::function<void(const TrackedFrame&, std::chrono::steady_clock::time_point arrival)> on_result;
};

struct TrackSequenceResult {
  TrackingRunId run_id;
  RecordingId recording_id;
  std::string name;
  /// Stopped by options.before_frame after `frames` of `sequence_frames`.
  bool stopped = false;
  int sequence_frames = 0;  ///< frames in the stream (a live source: captured)
  int dropped = 0;          ///< live source: frames that arrived while one was tracked
  int frames = 0, tracked = 0, carried = 0, lost = 0;
  int in_tolerance = 0, out_of_tolerance = 0;
  /// Frames lost while at least one mapped sticker was detected.
  int lost_with_stickers = 0;
  /// Lost frames by why (index: TrackingLoss).
  std::array<int, kTrackingLossCount> lost_by_cause{};
  double mean_total_ms = 0, p95_total_ms = 0, max_total_ms = 0;
  std::string response_message;  ///< the recording's camera response
  /// How well the plan's room frame is known and what that does to the
  /// corrections' bounds (in Summary() when it keeps every frame from `in`).
  RoomFrameNote room_frame;
  /// The session stage's verdict on the alignment tracked against, when it
  /// is not "ok" (in Summary(), with what to do).
  std::string alignment_check;
  /// The last frame's correction (what the therapist last saw).
  CouchCorrection last_correction;
  /// room_from_model of every frame with a pose (poses.txt).
  std::vector<StampedPose> poses;
  std::string Summary() const;
};

/// "session's alignment: <status> (the session stage's verdict): look at
/// ..." for a session stage's verdict on its alignment that is not "ok";
/// empty for "ok" or none. Under a run's summary and before the first frame
/// on the positioning screen.
std::string DescribeAlignmentCheck(const std::string& alignment_status);

/// Tracks `options.source`, else `options.sequence_dir` (a TUM-layout
/// sequence with the case's camera `config`), against `inputs`, writes the
/// files, stores the run.
/// Throws InputError for an unreadable sequence or an unwritable out_dir
/// (before any work), StoreError when the store fails (files written).
TrackSequenceResult TrackSequence(Database* database, const TrackingInputs& inputs, const CaseConfig& config,
                                  const TrackSequenceOptions& options);

/// The tracker options for a case (dictionaries and id ranges from case.yaml).
TrackerOptions MakeTrackerOptions(const CaseConfig& config, const TrackingInputs& inputs);

}  // namespace arpos
