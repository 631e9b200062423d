#include "tracking/tracker.h"

#include <chrono>
#include <cmath>
#include <future>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "util/check.h"
#include "util/logging.h"
#include "util/string_util.h"

namespace arpos {

namespace {
using Clock = std::chrono::steady_clock;
double MsSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}
constexpr double kDegPerRad = 180.0 / 3.14159265358979323846;
}  // namespace

std::string TrackerOptions::Validate() const {
  std::string problem = camera.Validate();
  if (!problem.empty()) return "camera: " + problem;
  problem = body.Validate();
  if (!problem.empty()) return "body: " + problem;
  problem = tolerances.Validate();
  if (!problem.empty()) return problem;
  if (!(uncertainty_sigmas >= 0)) return "uncertainty_sigmas must not be negative";
  if (!(uncertainty_floor_mm >= 0) || !(uncertainty_floor_deg >= 0)) return "uncertainty floors must not be negative";
  if (!(max_position_sigma_mm > 0)) return "max_position_sigma_mm must be positive";
  if (!(max_camera_carry_s >= 0)) return "max_camera_carry_s must not be negative";
  if (!(max_patient_speed_m_s >= 0) || !(patient_jump_margin_m >= 0) ||
      !(patient_jump_window_s >= 0) ||
      !std::isfinite(max_patient_speed_m_s + patient_jump_margin_m + patient_jump_window_s)) {
    return "max_patient_speed_m_s, patient_jump_margin_m and patient_jump_window_s must be finite "
           "and not negative";
  }
  if (!(room_frame_position_sigma_mm >= 0 && std::isfinite(room_frame_position_sigma_mm)) ||
      !(room_frame_rotation_sigma_deg >= 0 && std::isfinite(room_frame_rotation_sigma_deg))) {
    return "the room frame's sigmas must be finite and not negative";
  }
  if (!(scan_landmark_sigma_mm >= 0 && std::isfinite(scan_landmark_sigma_mm))) {
    return "scan_landmark_sigma_mm must be finite and not negative";
  }
  problem = filter.Validate();
  if (!problem.empty()) return "filter: " + problem;
  return "";
}

const char* TrackingStateName(TrackingState state) {
  switch (state) {
    case TrackingState::kTracked: return "tracked";
    case TrackingState::kCarried: return "carried";
    case TrackingState::kLost: return "lost";
  }
  return "lost";
}

const char* TrackingLossHeadline(TrackingLoss loss) {
  switch (loss) {
    case TrackingLoss::kNone: return "";
    case TrackingLoss::kFrame: return "FRAME UNUSABLE";
    case TrackingLoss::kCamera: return "CAMERA NOT PLACED IN ROOM";
    case TrackingLoss::kPatient: return "PATIENT NOT FOUND";
    case TrackingLoss::kCameraAndPatient: return "CAMERA AND PATIENT NOT FOUND";
    case TrackingLoss::kUncertain: return "POSE TOO UNCERTAIN";
  }
  return "";
}

const char* TrackingLossAdvice(TrackingLoss loss) {
  switch (loss) {
    case TrackingLoss::kNone: return "";
    case TrackingLoss::kFrame: return "The camera's image could not be used: check the camera and its cable.";
    case TrackingLoss::kCamera:
      return "Bring a room marker into view, or a part of the room the room recording covered.";
    case TrackingLoss::kPatient: return "Bring the patient's stickers into view, nearer or less obliquely.";
    case TrackingLoss::kCameraAndPatient:
      return "Point the camera at the patient's stickers with a room marker in view.";
    case TrackingLoss::kUncertain:
      return "Hold the camera steady, nearer the patient, with a room marker in view.";
  }
  return "";
}

Tracker::Tracker(RoomMap map, const TriangleMesh& model, std::map<int, Rigid3d> model_from_marker,
                 const Rigid3d& room_from_model_target, const CameraIntrinsics& intrinsics,
                 const TrackerOptions& options, const std::optional<Rigid3d>& room_from_model_expected)
    : options_(options), target_(room_from_model_target), intrinsics_(intrinsics), filter_([&] {
        const std::string problem = options.Validate();
        ARPOS_CHECK(problem.empty(), "tracker options: " << problem);
        return options.filter;
      }()) {
  expected_room_from_model_ = room_from_model_expected;
  camera_ = std::make_unique<CameraLocalizer>(std::move(map), intrinsics, options_.camera);
  // The couch top and the patient move: the room is not followed by
  // keypoints there (CameraLocalizerOptions::follow_room_keypoints).
  camera_->SetMovingRegions({CouchExclusionBox(target_)});
  body_ = std::make_unique<BodyTracker>(model, std::move(model_from_marker), intrinsics, options_.body);
}

Tracker::~Tracker() = default;

void Tracker::WarmUp() {
  // Blocks of random grey at two scales (corners for the keypoint detector,
  // contours for the marker search), a plane 1.5 m away.
  const int w = intrinsics_.width, h = intrinsics_.height;
  cv::RNG rng(0x5eed);
  cv::Mat coarse(std::max(1, h / 24), std::max(1, w / 24), CV_8UC1), fine(std::max(1, h / 6), std::max(1, w / 6), CV_8UC1);
  rng.fill(coarse, cv::RNG::UNIFORM, 0, 256);
  rng.fill(fine, cv::RNG::UNIFORM, 0, 256);
  cv::Mat a, b, gray;
  cv::resize(coarse, a, cv::Size(w, h), 0, 0, cv::INTER_NEAREST);
  cv::resize(fine, b, cv::Size(w, h), 0, 0, cv::INTER_NEAREST);
  cv::addWeighted(a, 0.7, b, 0.3, 0, gray);
  RgbdFrame frame;
  frame.index = 0;
  frame.timestamp_s = 0;
  frame.depth_scale = intrinsics_.depth_scale;
  cv::cvtColor(gray, frame.color, cv::COLOR_GRAY2BGR);
  frame.depth = cv::Mat(h, w, CV_16UC1, cv::Scalar(static_cast<int>(std::lround(1.5 * frame.depth_scale))));
  Process(frame);
  // Forget it.
  camera_->Reset();
  camera_->SetMovingRegions({CouchExclusionBox(target_)});
  body_->Reset();
  filter_.Reset();
  last_room_from_camera_.reset();
  last_room_from_model_.reset();
  last_camera_t_ = last_model_t_ = -1;
  camera_placed_last_frame_ = false;
  last_seen_room_from_model_.reset();
  last_seen_t_ = -1;
}

CorrectionUncertainty Tracker::BoundOf(double position_sigma_mm, double rotation_sigma_deg) const {
  CorrectionUncertainty bound;
  bound.translation_mm =
      std::max(options_.uncertainty_floor_mm,
               options_.uncertainty_sigmas * std::hypot(position_sigma_mm, options_.room_frame_position_sigma_mm));
  bound.rotation_deg =
      std::max(options_.uncertainty_floor_deg,
               options_.uncertainty_sigmas * std::hypot(rotation_sigma_deg, options_.room_frame_rotation_sigma_deg));
  return bound;
}

std::optional<Rigid3d> Tracker::KnownRoomFromModel(double t) const {
  if (last_room_from_model_ && t - last_model_t_ < 5.0) return last_room_from_model_;
  return expected_room_from_model_;
}

bool Tracker::CarryByMotion(double t, const std::string& why, TrackedFrame* out) {
  if (!options_.temporal_filter || !(options_.max_camera_carry_s > 0) || last_model_t_ < 0 ||
      !(t - last_model_t_ <= options_.max_camera_carry_s)) {
    return false;
  }
  const std::optional<FilteredPose> predicted = filter_.Predict(t);
  if (!predicted || !(1000 * predicted->position_sigma_m <= options_.max_position_sigma_mm)) return false;
  out->state = TrackingState::kCarried;
  out->room_from_model = predicted->room_from_model;
  out->position_sigma_mm = 1000 * predicted->position_sigma_m;
  out->rotation_sigma_deg = kDegPerRad * predicted->rotation_sigma_rad;
  // The camera where the patient seen in it puts it: the pose the overlay
  // draws with (the red model on the patient), and where the localiser
  // searches next if it lost this frame.
  const Rigid3d room_from_camera = predicted->room_from_model * out->body.camera_from_model.Inverse();
  out->room_from_camera = room_from_camera;
  camera_->SuggestSearchStart(room_from_camera);
  out->correction = ComputeCouchCorrection(*out->room_from_model, target_,
                                          BoundOf(out->position_sigma_mm, out->rotation_sigma_deg), options_.tolerances);
  // No measurement of the patient in the room this frame: never `in`.
  if (out->correction.state == CorrectionState::kIn) out->correction.state = CorrectionState::kOut;
  out->message = StringPrintf("pose predicted %.2f s ahead by its motion; ", t - last_model_t_) + why;
  return true;
}

std::string PatientJumpRefusal(const TrackerOptions& options, double dt_s,
                               const Rigid3d& last_room_from_model, const Rigid3d& room_from_model,
                               int room_markers_used) {
  if (!(options.max_patient_speed_m_s > 0) || room_markers_used > 0) return "";
  if (!(dt_s > 0 && dt_s <= options.patient_jump_window_s)) return "";
  const double moved_m = (room_from_model.translation - last_room_from_model.translation).norm();
  const double reach_m = options.max_patient_speed_m_s * dt_s + options.patient_jump_margin_m;
  if (!(moved_m > reach_m)) return "";
  return StringPrintf(
      "placed without a room marker where the patient would have moved %.0f mm in %.2f s (at most "
      "%.0f mm); refused",
      1000 * moved_m, dt_s, 1000 * reach_m);
}

std::string Tracker::PatientJump(double t, const LocalizationResult& camera,
                                 const BodyPoseResult& body) const {
  if (!camera.ok || !body.ok || !last_seen_room_from_model_) return "";
  return PatientJumpRefusal(options_, t - last_seen_t_, *last_seen_room_from_model_,
                            camera.room_from_camera * body.camera_from_model, camera.markers_used);
}

TrackedFrame Tracker::Process(const RgbdFrame& input) {
  const auto start = Clock::now();
  TrackedFrame out;
  out.index = input.index;
  out.timestamp_s = input.timestamp_s;
  out.correction = LostCorrection();
  // Frames that cannot be read as the camera's are lost, with the reason;
  // unusable depth is dropped and the frame goes on without it.
  RgbdFrame frame = input;
  if (frame.color.empty() || frame.color.type() != CV_8UC3 || frame.color.cols != intrinsics_.width ||
      frame.color.rows != intrinsics_.height) {
    out.message = frame.color.empty() ? "no colour image (missing or unreadable)"
                                      : StringPrintf("colour image %dx%d (type %d), the camera is %dx%d BGR",
                                                     frame.color.cols, frame.color.rows, frame.color.type(),
                                                     intrinsics_.width, intrinsics_.height);
    out.timings.total_ms = MsSince(start);
    return out;
  }
  std::string depth_note;
  if (!frame.depth.empty() && (frame.depth.type() != CV_16UC1 || frame.depth.size() != frame.color.size())) {
    frame.depth = cv::Mat();
    depth_note = "depth unusable (type or size): ignored";
  } else if (frame.depth.empty()) {
    depth_note = "no depth";
  }

  if (last_room_from_model_) {
    camera_->SetMovingRegions({CouchExclusionBox(target_), CouchExclusionBox(*last_room_from_model_)});
  }
  auto run_camera = [&] {
    const auto t0 = Clock::now();
    LocalizationResult r;
    try {
      r = camera_->Localize(frame);
    } catch (const std::exception& e) {
      r = LocalizationResult();
      r.message = e.what();
    }
    out.timings.camera_ms = MsSince(t0);
    return r;
  };
  // The patient is where it was last seen in the room, seen from where the
  // camera last was (both recent): a start for the body tracker after a loss.
  // Before the patient is first found (or long after it was last seen),
  // where it is expected.
  auto hint_from = [&](const Rigid3d& room_from_camera) -> std::optional<Rigid3d> {
    const std::optional<Rigid3d> room_from_model = KnownRoomFromModel(frame.timestamp_s);
    if (!room_from_model) return std::nullopt;
    return room_from_camera.Inverse() * *room_from_model;
  };
  std::optional<Rigid3d> hint;
  if (last_room_from_camera_ && frame.timestamp_s - last_camera_t_ < 0.5) hint = hint_from(*last_room_from_camera_);
  // `depth_motion`: this frame's camera motion between its colour and depth
  // instants as the localiser measured it (depth of another instant), read
  // only once the camera is done.
  auto run_body = [&](const DepthCameraMotion* depth_motion) {
    const auto t0 = Clock::now();
    BodyPoseResult r = body_->Track(frame, hint, depth_motion);
    out.timings.body_ms = MsSince(t0);
    return r;
  };
  auto measured_motion = [&]() -> const DepthCameraMotion* {
    return out.camera.ok && out.camera.depth_camera_motion ? &*out.camera.depth_camera_motion
                                                           : nullptr;
  };
  try {
    if (!hint && !body_->HasRecentPose(frame.timestamp_s)) {
      // Nothing tells the body tracker where to look (first frame, or after
      // the camera and the patient were both lost): the camera first, then
      // the body from this frame's camera pose.
      out.camera = run_camera();
      if (out.camera.ok) hint = hint_from(out.camera.room_from_camera);
      out.body = run_body(measured_motion());
      const std::optional<Rigid3d> room_from_model = KnownRoomFromModel(frame.timestamp_s);
      if (!out.camera.ok && out.body.ok && room_from_model) {
        // The room not recognised from scratch, the patient found: the
        // camera again, searched first where the patient's last (or
        // expected) room pose puts it (measured on cases with random
        // conditions: the first frame of 4 of 10 sequences lost).
        const double first_ms = out.timings.camera_ms;
        const LocalizationTimings first_steps = out.camera.timings;
        camera_->SuggestSearchStart(*room_from_model * out.body.camera_from_model.Inverse());
        out.camera = run_camera();
        out.timings.camera_ms += first_ms;
        out.camera.timings += first_steps;
      }
    } else if (frame.depth_delay_s != 0 && !frame.depth.empty() &&
               (camera_placed_last_frame_ || !options_.parallel)) {
      // Depth of another instant: the body takes the frame's depth at the
      // camera's motion as the room's depth measured it, so after the camera.
      // Not after a frame whose camera was not placed: this one's is then
      // searched for in the whole image and map, mostly in vain, and gives
      // no motion; the body runs beside it with the motion's assumed size
      // (measured on random-conditions cases with lost frames, tracking_bench
      // p95 75.6-95.5 -> 65.2-70.3 ms on l515 seed 406, 58.3-67.8 ->
      // 52.9-62.3 ms on d435 seed 413; over 14 random sequences 455 -> 443
      // frames lost, MTE within 0.1 mm but on one that tracked 6-7 frames).
      out.camera = run_camera();
      out.body = run_body(measured_motion());
    } else if (options_.parallel) {
      std::future<BodyPoseResult> body = std::async(std::launch::async, run_body, nullptr);
      out.camera = run_camera();
      out.body = body.get();
    } else {
      out.camera = run_camera();
      out.body = run_body(measured_motion());
    }
  } catch (const std::exception& e) {
    out.message = std::string("frame could not be processed: ") + e.what();
    out.timings.total_ms = MsSince(start);
    return out;
  }
  out.timings.camera = out.camera.timings;
  if (const std::string jump = PatientJump(frame.timestamp_s, out.camera, out.body);
      !jump.empty()) {
    // The patient seen in this frame is where it was: the camera is searched
    // for again where the patient puts it.
    out.camera.ok = false;
    out.camera.status = LocalizationStatus::kLost;
    out.camera.message = jump;
    camera_->Reset();
    camera_->SuggestSearchStart(*last_seen_room_from_model_ * out.body.camera_from_model.Inverse());
  }
  if (out.camera.ok && out.body.ok) {
    last_seen_room_from_model_ = out.camera.room_from_camera * out.body.camera_from_model;
    last_seen_t_ = frame.timestamp_s;
  }
  ARPOS_DEBUG(
      "camera frame " << frame.index << ": "
                      << (out.camera.ok ? LocalizationStatusName(out.camera.status) : "lost")
                      << ", " << out.camera.markers_used << " markers, "
                      << out.camera.keypoints_used << " keypoints ("
                      << out.camera.scan_keypoints_used << " on the scan's landmarks), rms "
                      << out.camera.rms_px << " px, sigma " << out.camera.position_sigma_mm
                      << " mm " << out.camera.rotation_sigma_deg << " deg"
                      << (out.camera.followed ? ", followed" : "")
                      << (out.camera.unconfirmed ? ", unconfirmed" : "")
                      << (out.camera.held_by_depth ? ", held by depth" : "")
                      << (out.camera.message.empty() ? "" : " (" + out.camera.message + ")"));
  if (out.camera.ok) {
    last_room_from_camera_ = out.camera.room_from_camera;
    last_camera_t_ = frame.timestamp_s;
  }
  camera_placed_last_frame_ = out.camera.ok;
  out.timings.body = out.body.timings;

  const auto t_combine = Clock::now();
  if (out.camera.ok) out.room_from_camera = out.camera.room_from_camera;
  if (out.body.ok) out.camera_from_model = out.body.camera_from_model;
  // The frame's own uncertainty at the isocentre: the camera's error there
  // and the body's.
  auto camera_failure = [&] {
    return "camera not localised in the room" + (out.camera.message.empty() ? "" : " (" + out.camera.message + ")");
  };
  double own_sigma_mm = 0;
  if (out.camera.ok && out.body.ok) {
    // The camera's error at the model's origin (where corrections are
    // measured, DATASET.md: the isocentre). Where room markers placed the
    // camera, through the pose's full covariance: its position and rotation
    // errors largely cancel at the points it sees (the bound 15-20 % lower
    // on the default cases). Where keypoints alone did, the two added as if
    // independent (about twice that): the covariance does not see the map's
    // errors at far landmarks, and on 36 random cases it left 116 of 3082
    // such frames beyond their bound against 65 (with markers: 7 of 1889,
    // from room frames stated too tightly, against 1).
    const Eigen::Vector3d patient = out.body.camera_from_model.translation;
    const double camera_mm = out.camera.markers_used > 0 ? out.camera.PointSigmaMm(patient)
                                                         : out.camera.SeparateSigmasMm(patient);
    const double scan_share =
        out.camera.keypoints_used > 0
            ? static_cast<double>(out.camera.scan_keypoints_used) / out.camera.keypoints_used
            : 0.0;
    own_sigma_mm = std::sqrt(std::pow(camera_mm, 2) + std::pow(out.body.position_sigma_mm, 2) +
                             std::pow(scan_share * options_.scan_landmark_sigma_mm, 2));
    ARPOS_DEBUG("frame " << frame.index << ": 1 sigma at the isocentre " << own_sigma_mm
                         << " mm (camera " << camera_mm << ", patient "
                         << out.body.position_sigma_mm << ", scan's landmarks "
                         << scan_share * options_.scan_landmark_sigma_mm << ")");
  }
  if (out.camera.ok && out.body.ok && own_sigma_mm > options_.max_position_sigma_mm) {
    const std::string why =
        StringPrintf("pose too uncertain: %.1f mm at the isocentre (1 sigma; camera %.1f mm, %.2f deg; "
                     "patient %.1f mm)",
                     own_sigma_mm, out.camera.position_sigma_mm, out.camera.rotation_sigma_deg,
                     out.body.position_sigma_mm);
    if (!CarryByMotion(frame.timestamp_s, why, &out)) {
      out.message = why;
      out.loss = TrackingLoss::kUncertain;
    }
  } else if (!out.camera.ok && out.body.ok && CarryByMotion(frame.timestamp_s, camera_failure(), &out)) {
    // Done: the patient's pose predicted, the camera implied by it.
  } else if (!out.camera.ok || !out.body.ok) {
    std::string why;
    if (!out.camera.ok) why = camera_failure();
    if (!out.body.ok) {
      why += (why.empty() ? "" : "; ") + std::string("patient not found") +
             (out.body.message.empty() ? "" : " (" + out.body.message + ")");
    }
    if (!depth_note.empty()) why += "; " + depth_note;
    out.message = why;
    out.loss = !out.camera.ok && !out.body.ok ? TrackingLoss::kCameraAndPatient
               : !out.camera.ok              ? TrackingLoss::kCamera
                                             : TrackingLoss::kPatient;
    if (!out.camera.ok && out.body.ok) {
      // The patient seen, the camera not placed: the next relocalisation
      // searches first where the patient's last (or expected) room pose
      // puts the camera (measured on a case with random conditions: the
      // first 18 frames lost to the whole-map search).
      const std::optional<Rigid3d> room_from_model = KnownRoomFromModel(frame.timestamp_s);
      if (room_from_model) camera_->SuggestSearchStart(*room_from_model * out.body.camera_from_model.Inverse());
    }
  } else {
    out.room_from_model = out.camera.room_from_camera * out.body.camera_from_model;
    last_room_from_model_ = out.room_from_model;
    last_model_t_ = frame.timestamp_s;
    out.state = out.body.source == BodyPoseSource::kCarried ? TrackingState::kCarried : TrackingState::kTracked;
    out.position_sigma_mm = own_sigma_mm;
    out.rotation_sigma_deg = std::hypot(out.camera.rotation_sigma_deg, out.body.rotation_sigma_deg);
    out.measured_room_from_model = out.room_from_model;
    out.measured_position_sigma_mm = out.position_sigma_mm;
    out.measured_rotation_sigma_deg = out.rotation_sigma_deg;
    if (options_.temporal_filter) {
      const FilteredPose f = filter_.Update(frame.timestamp_s, *out.room_from_model, out.position_sigma_mm / 1000,
                                            out.rotation_sigma_deg / kDegPerRad);
      out.room_from_model = f.room_from_model;
      out.position_sigma_mm = 1000 * f.position_sigma_m;
      out.rotation_sigma_deg = kDegPerRad * f.rotation_sigma_rad;
    }
    out.correction = ComputeCouchCorrection(*out.room_from_model, target_,
                                            BoundOf(out.position_sigma_mm, out.rotation_sigma_deg), options_.tolerances);
    // `in` only when this frame's own estimate agrees: the filter's bound
    // holds only as long as its motion model does.
    if (options_.temporal_filter && out.correction.state == CorrectionState::kIn) {
      const CorrectionUncertainty own = BoundOf(out.measured_position_sigma_mm, out.measured_rotation_sigma_deg);
      if (ComputeCouchCorrection(*out.measured_room_from_model, target_, own, options_.tolerances).state != CorrectionState::kIn) {
        out.correction.state = CorrectionState::kOut;
      }
    }
    out.message = out.body.source == BodyPoseSource::kCarried ? out.body.message : depth_note;
    if (out.camera.unconfirmed) {
      // Keypoints alone placed the camera after a loss: never `in` until a
      // room marker confirms where it is.
      if (out.correction.state == CorrectionState::kIn) out.correction.state = CorrectionState::kOut;
      out.message += std::string(out.message.empty() ? "" : "; ") +
                     "camera placed by keypoints alone (at the start or after a loss), not yet confirmed by a room marker";
    }
    if (out.camera.followed) {
      // Followed by the room's keypoints from the last frame the map placed:
      // its bound includes that frame's uncertainty, but what the map does
      // not see is not checked against it; never `in` until the map places
      // the camera again.
      if (out.correction.state == CorrectionState::kIn) out.correction.state = CorrectionState::kOut;
      out.message += std::string(out.message.empty() ? "" : "; ") +
                     StringPrintf("camera followed by the room's keypoints for %.1f s since the room map last placed "
                                  "it (no room marker or mapped landmark in view); not `in` until the map places it",
                                  out.camera.followed_s);
    }
    if (out.camera.held_by_depth) {
      out.message += std::string(out.message.empty() ? "" : "; ") +
                     "camera held by the room's depth and its motion (no room marker, few keypoints)";
    }
  }
  if (out.state != TrackingState::kLost) out.loss = TrackingLoss::kNone;
  out.timings.combine_ms = MsSince(t_combine);
  out.timings.total_ms = MsSince(start);
  return out;
}

}  // namespace arpos
