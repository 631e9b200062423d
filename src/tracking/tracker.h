#pragma once
/// Tracking mode, one frame at a time: where the camera is in the room, where
/// the patient is, and the couch correction to the planned pose.
///
/// Per frame, on two threads at once:
///  - scene: the camera pose in the room (CameraLocalizer: room markers and
///    keypoints against the plan's room map);
///  - body: the reference model's pose in the camera (BodyTracker: stickers
///    of the session's body marker map refined with depth on the model's
///    visible surface).
/// Then room_from_model = room_from_camera * camera_from_model, its
/// uncertainty at the isocentre (the camera's position and rotation errors,
/// the latter acting over the camera-to-isocentre distance, and the body's),
/// and the correction (feedback/couch_correction.h) with that uncertainty
/// and the plan's room frame's (`uncertainty_sigmas` of them together)
/// added before the tolerance test. With the
/// temporal filter (pose_filter.h) the reported pose and correction are the
/// filtered ones, and a frame reads `in` only when both the filtered and the
/// frame's own estimate, each with its bound, are within tolerance.
/// A frame is lost when either half is lost, except that a patient seen in a
/// frame whose camera is not placed is carried by the filter's motion model
/// for a moment (max_camera_carry_s; the frame says so and is never `in`).
///
/// Thread-safety: one Tracker per stream; Process() is called from one thread.

#include <cstddef>
#include <map>
#include <memory>
#include <optional>
#include <string>

#include "feedback/couch_correction.h"
#include "geometry/rigid3.h"
#include "geometry/triangle_mesh.h"
#include "room_map/camera_localizer.h"
#include "room_map/room_map.h"
#include "sensor/intrinsics.h"
#include "sensor/rgbd_frame.h"
#include "tracking/body_tracker.h"
#include "tracking/pose_filter.h"

namespace arpos {

struct TrackerOptions {
  CameraLocalizerOptions camera;
  BodyTrackerOptions body;
  CouchTolerances tolerances;
  /// The correction's uncertainty bound is this many sigmas of the pose's
  /// own uncertainty, at least the floors below.
  double uncertainty_sigmas = kDefaultUncertaintySigmas;
  double uncertainty_floor_mm = 0.3;
  double uncertainty_floor_deg = 0.05;
  /// A frame whose own pose is less certain than this at the isocentre (1
  /// sigma, mostly the camera's rotation acting over its distance) is lost:
  /// a correction known only to centimetres helps no one, and its overlay
  /// would mislead.
  double max_position_sigma_mm = 10.0;
  /// Scene and body on two threads (false: one after the other, e.g. to
  /// measure each alone).
  bool parallel = true;
  /// The patient's room pose through a constant-velocity filter weighted by
  /// each frame's uncertainty (pose_filter.h); false: each frame alone.
  bool temporal_filter = true;
  PoseFilterOptions filter;
  /// A frame whose camera is not placed in the room, or too uncertainly
  /// (max_position_sigma_mm), while the patient is seen in it (motion blur,
  /// no room marker, keypoints that do not agree):
  /// the patient's room pose carried by the filter's motion model for at
  /// most this long after the last placed frame (s), while the predicted
  /// pose is within max_position_sigma_mm; the frame is `carried` and never
  /// `in`, and the camera's pose implied by the patient seen in it is where
  /// the localiser searches next. 0: such frames are lost.
  double max_camera_carry_s = 0.35;
  /// A camera placed without a room marker (keypoints, followed, held by
  /// depth) is refused when, with the patient seen in this frame, it puts
  /// the patient farther from where the last frame with both put it than
  /// the patient moves in between: max_patient_speed_m_s * dt +
  /// patient_jump_margin_m, compared for at most patient_jump_window_s
  /// after that frame. The stickers place the patient in the camera to a
  /// millimetre; a patient on a couch does not move centimetres in a frame,
  /// while keypoints can agree on a wrong place (measured on random-
  /// conditions d435 cases: a relocalisation on 23 landmarks 99 mm off,
  /// sigma 6 mm, 76 mm from the last frame's camera 0.067 s before; a
  /// tracked frame moved 60 mm on 31 keypoints). The localiser then searches
  /// again where the patient puts the camera. 0 speed: no check.
  double max_patient_speed_m_s = 0.15;
  double patient_jump_margin_m = 0.02;
  double patient_jump_window_s = 0.2;
  /// The room frame's own uncertainty at the planned isocentre (1 sigma,
  /// from the plan: RoomMapRecord): the origin marker's pose is shared by
  /// every frame, so a weak room frame moves every reported pose alike.
  /// Added in quadrature to each frame's own uncertainty in the correction's
  /// bound (not in the per-frame test of max_position_sigma_mm). Measured on
  /// cases with random conditions without it: tracked poses 22-39 mm off,
  /// beyond their bounds, where the plan had reported its room frame 24 mm
  /// (1 sigma) at the couch; a patient truly out by that much in the wrong
  /// direction would have read `in`.
  double room_frame_position_sigma_mm = 0;
  double room_frame_rotation_sigma_deg = 0;
  /// How well the session placed its body scan in the room (1 sigma at the
  /// stickers): the room landmarks the scan placed (RoomMap::scan_landmarks)
  /// carry it. A frame whose camera keypoints are partly on them gets it in
  /// its own uncertainty, in proportion to their share of the keypoint
  /// inliers (in quadrature).
  double scan_landmark_sigma_mm = 0;

  std::string Validate() const;
};

/// Why a camera placed with `room_markers_used` room markers is refused
/// (TrackerOptions::max_patient_speed_m_s): it puts the patient at
/// `room_from_model`, `dt_s` after a frame that put it at
/// `last_room_from_model`, farther than the patient moves in between; ""
/// when it is not (a room marker used, no check, out of the window, within
/// reach).
std::string PatientJumpRefusal(const TrackerOptions& options, double dt_s,
                               const Rigid3d& last_room_from_model, const Rigid3d& room_from_model,
                               int room_markers_used);

/// Milliseconds per step of one frame (wall clock of the thread that did it).
struct TrackingTimings {
  LocalizationTimings camera;  ///< CPU ms of the scene thread, by step
  BodyTrackingTimings body;
  double camera_ms = 0;   ///< wall ms of the scene half
  double body_ms = 0;     ///< wall ms of the body half
  double combine_ms = 0;  ///< pose, uncertainty, correction
  double total_ms = 0;    ///< frame handed over to correction ready
};

enum class TrackingState {
  kTracked = 0,   ///< camera and patient from this frame's data
  kCarried = 1,   ///< patient carried: on the surface without stickers, or by
                  ///< its motion while the camera is not placed
  kLost = 2,      ///< no pose (camera or patient)
};
const char* TrackingStateName(TrackingState state);

/// Why a frame has no pose, in terms of what the person holding the camera
/// can do about it.
enum class TrackingLoss {
  kNone = 0,          ///< a pose (tracked or carried)
  kFrame,             ///< the frame could not be read or processed
  kCamera,            ///< the patient seen, the camera not placed in the room
  kPatient,           ///< the camera placed, the patient not found
  kCameraAndPatient,  ///< neither
  kUncertain,         ///< both found, the pose too uncertain to report
};
constexpr std::size_t kTrackingLossCount = static_cast<std::size_t>(TrackingLoss::kUncertain) + 1;
/// A display's headline, upper case ("CAMERA NOT PLACED IN ROOM"); "" for kNone.
const char* TrackingLossHeadline(TrackingLoss loss);
/// What to do, one sentence; "" for kNone.
const char* TrackingLossAdvice(TrackingLoss loss);

struct TrackedFrame {
  int index = -1;
  double timestamp_s = 0;
  TrackingState state = TrackingState::kLost;
  std::optional<Rigid3d> room_from_camera;
  std::optional<Rigid3d> camera_from_model;
  std::optional<Rigid3d> room_from_model;
  /// This frame's own estimate before the temporal filter, and its 1-sigma
  /// uncertainty.
  std::optional<Rigid3d> measured_room_from_model;
  double measured_position_sigma_mm = 0;
  double measured_rotation_sigma_deg = 0;
  /// 1-sigma uncertainty of room_from_model (after the filter): position at
  /// the isocentre (largest axis) and rotation.
  double position_sigma_mm = 0;
  double rotation_sigma_deg = 0;
  CouchCorrection correction;
  /// Why there is no pose: kNone exactly when state is not kLost (a frame
  /// never processed: kFrame).
  TrackingLoss loss = TrackingLoss::kFrame;
  LocalizationResult camera;
  BodyPoseResult body;
  std::string message;  ///< why lost or carried
  TrackingTimings timings;
};

class Tracker {
 public:
  /// `map`: the plan's room map; `model`: the reference model; `model_from_marker`:
  /// the session's stickers in the model frame; `room_from_model_target`: the
  /// planned pose. Throws arpos::Error for invalid options, InputError for
  /// unusable inputs.
  /// `room_from_model_expected`: where the patient is expected before it is
  /// first found (e.g. its pose at the session's body scan); the body
  /// tracker looks there first when its stickers are too small to read in
  /// the whole image.
  Tracker(RoomMap map, const TriangleMesh& model, std::map<int, Rigid3d> model_from_marker,
          const Rigid3d& room_from_model_target, const CameraIntrinsics& intrinsics,
          const TrackerOptions& options, const std::optional<Rigid3d>& room_from_model_expected = std::nullopt);
  ~Tracker();
  Tracker(const Tracker&) = delete;
  Tracker& operator=(const Tracker&) = delete;

  /// One frame. Never throws for bad data (a frame without depth or with a
  /// broken image is processed as far as it goes, or lost with a message).
  TrackedFrame Process(const RgbdFrame& frame);

  /// Runs the per-frame steps once on a synthetic frame of the camera's size
  /// (textured grey, a flat depth) and forgets it: the tracker's state
  /// afterwards is as constructed. The first real frame then does not pay
  /// the one-off costs of a process's first frame (threads started, buffers
  /// first allocated and touched). Call before frames arrive.
  void WarmUp();

  const Rigid3d& room_from_model_target() const { return target_; }
  const TrackerOptions& options() const { return options_; }

 private:
  // The correction's bound: `uncertainty_sigmas` of the pose's 1-sigma
  // uncertainty, at least the floors.
  CorrectionUncertainty BoundOf(double position_sigma_mm, double rotation_sigma_deg) const;
  // Where the patient is in the room as far as this tracker knows at time
  // `t`: its last measured pose if recent (5 s), else where it is expected.
  std::optional<Rigid3d> KnownRoomFromModel(double t) const;
  // The camera not placed (or too uncertain: `why`), the patient seen: its
  // room pose from the filter's motion model, if recent and certain enough
  // (fills `out`; false: lost).
  bool CarryByMotion(double t, const std::string& why, TrackedFrame* out);
  // The camera placed without a room marker where the patient seen in this
  // frame would have jumped since the last frame with both
  // (max_patient_speed_m_s): why it is refused, or "".
  std::string PatientJump(double t, const LocalizationResult& camera,
                          const BodyPoseResult& body) const;
  TrackerOptions options_;
  Rigid3d target_;
  CameraIntrinsics intrinsics_;
  std::unique_ptr<CameraLocalizer> camera_;
  std::unique_ptr<BodyTracker> body_;
  // The last room poses of camera and patient: where to look for the
  // patient when the body tracker has lost it.
  std::optional<Rigid3d> last_room_from_camera_, last_room_from_model_, expected_room_from_model_;
  PoseFilter filter_;
  double last_camera_t_ = -1, last_model_t_ = -1;
  // Whether the last frame processed placed its camera in the room.
  bool camera_placed_last_frame_ = false;
  // The patient's room pose in the last frame whose camera and patient were
  // both found (whether or not the frame was reported), and when.
  std::optional<Rigid3d> last_seen_room_from_model_;
  double last_seen_t_ = -1;
};

}  // namespace arpos
