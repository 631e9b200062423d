#include "tracking/tracking_stage.h"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <sstream>

#include <opencv2/imgcodecs.hpp>

#include "features/response_from_recording.h"
#include "room_map/scan_landmarks.h"
#include "sensor/frame_feed.h"
#include "sensor/sequence.h"
#include "sensor/source_plugin.h"
#include "sensor/tum_io.h"
#include "store/database.h"
#include "store/lifecycle.h"
#include "store/record_conversions.h"
#include "tracking/overlay.h"
#include "util/check.h"
#include "util/file.h"
#include "util/logging.h"
#include "util/string_util.h"

namespace arpos {

namespace {
using Clock = std::chrono::steady_clock;
double MsSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

// The newest alignment of the newest reconstruction of a session, and its
// newest body marker map; nullopt when the session lacks either.
struct SessionPieces {
  BodyMarkerMapId marker_map;
  AlignmentRecord alignment;
};
std::optional<SessionPieces> PiecesOf(Database* database, SessionId session) {
  const std::vector<BodyMarkerMapId> maps = database->ListBodyMarkerMapIds(session);
  const std::vector<ReconstructionId> reconstructions = database->ListReconstructionIds(session);
  if (maps.empty() || reconstructions.empty()) return std::nullopt;
  for (auto r = reconstructions.rbegin(); r != reconstructions.rend(); ++r) {
    const std::vector<AlignmentRecord> alignments = database->ListAlignments(*r);
    if (!alignments.empty()) return SessionPieces{maps.back(), alignments.back()};
  }
  return std::nullopt;
}

// The room frame's sigmas of a stored map (none when it predates them).
void SetRoomFrameSigmas(const RoomMapRecord& map, TrackingInputs* in) {
  if (const auto sigmas = RoomFrameSigmasOf(map)) {
    in->room_frame_position_sigma_mm = sigmas->position_mm;
    in->room_frame_rotation_sigma_deg = sigmas->rotation_deg;
  }
}
}  // namespace

TrackingInputs LoadTrackingInputs(Database* database, std::optional<SessionId> session,
                                  const std::string& patient_external_id, bool newest_if_several) {
  ARPOS_CHECK(database != nullptr, "tracking needs a session store");
  std::optional<SessionPieces> pieces;
  SessionId chosen;
  std::string said;
  if (session) {
    RequireOpenSession(database, *session, "tracking");
    pieces = PiecesOf(database, *session);
    if (!pieces) {
      ARPOS_INPUT_ERROR("session " << session->value()
                                   << " has no body marker map and aligned reconstruction: run `arpos session CASE` first");
    }
    chosen = *session;
    said = "session " + std::to_string(chosen.value()) + ", as given";
  } else {
    // The open sessions (with what tracking needs) of the case's patient, or
    // of the whole store when the store does not know the patient. Never a
    // guess: several are refused.
    std::vector<SessionRecord> sessions;
    std::string whose = "the store";
    if (!patient_external_id.empty()) {
      if (const auto patient = database->FindPatient(patient_external_id)) {
        whose = "patient " + patient_external_id;
        for (const auto& plan : database->ListPlans(patient->id)) {
          for (const auto& s : database->ListSessions(plan.id)) sessions.push_back(s);
        }
      }
    }
    if (whose == "the store") sessions = database->ListSessions();
    std::vector<SessionRecord> usable;
    std::map<std::int64_t, SessionPieces> usable_pieces;
    int closed = 0;
    for (const auto& s : sessions) {
      if (s.status != SessionStatus::kOpen) {
        ++closed;
      } else if (const std::optional<SessionPieces> p = PiecesOf(database, s.id)) {
        usable.push_back(s);
        usable_pieces.emplace(s.id.value(), *p);
      }
    }
    std::sort(usable.begin(), usable.end(), [](const SessionRecord& a, const SessionRecord& b) {
      return a.started_unix_ms != b.started_unix_ms ? a.started_unix_ms > b.started_unix_ms
                                                    : a.id.value() > b.id.value();
    });
    std::string others;
    if (usable.size() > 1) {
      std::string ids;
      for (const auto& s : usable) ids += (ids.empty() ? "" : ", ") + std::to_string(s.id.value());
      others = ids;
      if (!newest_if_several) {
        ARPOS_INPUT_ERROR(whose << " has " << usable.size() << " open sessions (" << ids
                                << "): choose one with --session ID (and complete or abort the others: "
                                   "arpos session complete|abort ID)");
      }
    }
    if (usable.empty()) {
      ARPOS_INPUT_ERROR(whose << " has no open session with a body marker map and an alignment"
                              << (closed > 0 ? " (" + std::to_string(closed) +
                                                   " completed or aborted; run-case completes its session at the "
                                                   "end unless --keep-open)"
                                             : "")
                              << ": run `arpos session CASE` first");
    }
    chosen = usable.front().id;
    pieces = usable_pieces.at(chosen.value());
    said = "session " + std::to_string(chosen.value()) +
           (others.empty() ? ", the only open session of " + whose
                           : ", the newest of the open sessions of " + whose + " (" + others +
                                 "; research run: give --session ID to choose)");
  }
  TrackingInputs in;
  in.session_id = chosen;
  in.session_choice = said;
  const std::optional<SessionRecord> s = database->GetSession(chosen);
  ARPOS_CHECK(s.has_value(), "session " << chosen.value() << " vanished");
  in.plan_id = s->plan_id;
  const std::optional<PlanRecord> plan = database->GetPlan(s->plan_id);
  if (!plan) ARPOS_INPUT_ERROR("session " << chosen.value() << ": its plan " << s->plan_id.value() << " is missing");
  const std::optional<RoomMapId> map_id = database->LatestRoomMap(s->plan_id);
  if (!map_id) {
    ARPOS_INPUT_ERROR("plan " << s->plan_id.value() << " has no room map: run `arpos plan CASE --plan "
                              << s->plan_id.value() << "` first");
  }
  const std::optional<RoomMapRecord> map = database->GetRoomMap(*map_id);
  if (!map) ARPOS_INPUT_ERROR("room map " << map_id->value() << " could not be read");
  in.room_map_id = *map_id;
  in.room_map = FromRecord(*map);
  SetRoomFrameSigmas(*map, &in);
  in.model = FromStoredMesh(plan->reference_model);
  if (in.model.empty()) ARPOS_INPUT_ERROR("plan " << plan->id.value() << ": the reference model has no faces");
  in.room_from_model_target = plan->room_from_model_target;
  in.body_marker_map_id = pieces->marker_map;
  in.alignment_id = pieces->alignment.id;
  in.alignment_status = pieces->alignment.StageVerdict();
  const std::optional<BodyMarkerMapRecord> markers = database->GetBodyMarkerMap(pieces->marker_map);
  if (!markers) ARPOS_INPUT_ERROR("body marker map " << pieces->marker_map.value() << " could not be read");
  in.sticker_size_m = markers->marker_size_m;
  in.room_from_model_at_scan = pieces->alignment.reconstruction_from_model;
  const Rigid3d model_from_body = pieces->alignment.reconstruction_from_model.Inverse();
  for (const auto& m : markers->markers) {
    in.model_from_marker[m.marker_id] = model_from_body * m.body_from_marker;
    if (m.motion_m > 0) in.sticker_motion_m[m.marker_id] = m.motion_m;
    if (m.motion_m > 0 && m.HasMotionDirection()) {
      in.sticker_motion_direction[m.marker_id] = m.motion_direction;
    }
  }
  in.moving_surface_patches = markers->moving_surface_patches;
  in.surface_patch_m = markers->surface_patch_m;
  in.scan_landmarks = AddScanLandmarks(*markers, &in.room_map);
  in.scan_landmark_sigma_mm = 1000 * markers->room_landmarks_placement_sigma_m;
  if (in.model_from_marker.empty()) {
    ARPOS_INPUT_ERROR("session " << chosen.value() << ": its body marker map holds no sticker");
  }
  return in;
}

TrackerOptions MakeTrackerOptions(const CaseConfig& config, const TrackingInputs& inputs) {
  TrackerOptions options;
  options.camera = MakeCameraLocalizerOptions(config);
  options.body.detector.dictionary = config.dictionary;
  options.body.detector.id_ranges = {{config.body_markers.id_min, config.body_markers.id_max}};
  options.body.detector.intrinsics = config.camera;
  options.body.detector.edge.response = CameraResponse::Srgb();
  options.body.marker_size_m = inputs.sticker_size_m;
  options.room_frame_position_sigma_mm = inputs.room_frame_position_sigma_mm.value_or(0.0);
  options.scan_landmark_sigma_mm = inputs.scan_landmark_sigma_mm;
  options.room_frame_rotation_sigma_deg = inputs.room_frame_rotation_sigma_deg.value_or(0.0);
  return options;
}

std::string TrackSequenceResult::Summary() const {
  std::ostringstream out;
  if (stopped) out << StringPrintf("stopped after %d of %d frames; ", frames, sequence_frames);
  // Why frames were lost, as the display says it: "22 camera not placed in room, ...".
  std::string causes;
  for (size_t k = 0; k < lost_by_cause.size(); ++k) {
    if (lost_by_cause[k] == 0) continue;
    std::string what = TrackingLossHeadline(static_cast<TrackingLoss>(k));
    std::transform(what.begin(), what.end(), what.begin(), [](unsigned char c) { return std::tolower(c); });
    causes += "; " + std::to_string(lost_by_cause[k]) + " " + what;
  }
  out << StringPrintf("tracking %s: %d frames, %d tracked, %d carried, %d lost (%.1f %%%s); %d in tolerance, %d out",
                      name.c_str(), frames, tracked, carried, lost, frames ? 100.0 * lost / frames : 0.0,
                      causes.c_str(), in_tolerance, out_of_tolerance);
  if (lost_with_stickers) out << StringPrintf("; %d lost with stickers in view", lost_with_stickers);
  if (dropped) out << StringPrintf("; %d of %d camera frames dropped (the tracker too far behind)", dropped, sequence_frames);
  out << StringPrintf("; %.1f ms per frame (p95 %.1f, max %.1f)", mean_total_ms, p95_total_ms, max_total_ms);
  if (frames) out << "\n  last correction: " << DescribeCorrection(last_correction);
  // The commonest reason, when it cost a tenth of the frames or more, with
  // what to do about it.
  size_t worst = 0;
  for (size_t k = 1; k < lost_by_cause.size(); ++k) {
    if (lost_by_cause[k] > lost_by_cause[worst]) worst = k;
  }
  if (worst != 0 && frames > 0 && 10 * lost_by_cause[worst] >= frames) {
    std::string what = TrackingLossHeadline(static_cast<TrackingLoss>(worst));
    std::transform(what.begin(), what.end(), what.begin(),
                   [](unsigned char c) { return std::tolower(c); });
    out << StringPrintf("\n  %d of %d frames lost as \"%s\": %s", lost_by_cause[worst], frames,
                        what.c_str(), TrackingLossAdvice(static_cast<TrackingLoss>(worst)));
  }
  if (room_frame.blocks_in) out << "\n  " << room_frame.text;
  if (!alignment_check.empty()) out << "\n  " << DescribeAlignmentCheck(alignment_check);
  return out.str();
}

std::string DescribeAlignmentCheck(const std::string& alignment_status) {
  if (!AlignmentRecord::AsksForCheck(alignment_status)) return "";
  return "session's alignment: " + alignment_status +
         " (the session stage's verdict): look at the alignment before relying on the corrections "
         "(arpos gui, audit: the session's surface against the model)";
}

RoomFrameNote DescribeRoomFrame(const TrackingInputs& inputs, const CouchTolerances& tolerances,
                                double uncertainty_sigmas) {
  RoomFrameNote note;
  if (!inputs.room_frame_position_sigma_mm || !inputs.room_frame_rotation_sigma_deg) {
    note.text =
        "room frame: the room map does not say how well its origin marker places it (stored before the plan "
        "measured this); each correction is bounded by its frame's own uncertainty alone: plan again to include it";
    return note;
  }
  const double k = uncertainty_sigmas;
  const double sigma_mm = *inputs.room_frame_position_sigma_mm, sigma_deg = *inputs.room_frame_rotation_sigma_deg;
  note.text = StringPrintf(
      "room frame: known to %.2f mm at the planned isocentre and %.3f deg (1 sigma, from the plan); part of "
      "every correction's bound",
      sigma_mm, sigma_deg);
  const RoomFrameBound bound = BoundOfRoomFrame(sigma_mm, sigma_deg, tolerances, k);
  note.blocks_in = bound.blocks_in;
  note.plan_advice = bound.advice;
  if (note.blocks_in) {
    note.text += StringPrintf(
        ": alone it bounds every correction by %.1f mm / %.2f deg (%g sigma), not within the "
        "%.1f mm / %.1f deg tolerance, so no frame can read `in`; record the room again as the "
        "plan's warning says (close, sharp views of the origin marker, or more room markers "
        "between it and the couch)",
        bound.translation_mm, bound.rotation_deg, k, tolerances.translation_mm,
        tolerances.rotation_deg);
  }
  return note;
}

RoomFrameNote DescribeRoomFrame(const RoomMapRecord& map, const CouchTolerances& tolerances,
                                double uncertainty_sigmas) {
  TrackingInputs inputs;
  SetRoomFrameSigmas(map, &inputs);
  return DescribeRoomFrame(inputs, tolerances, uncertainty_sigmas);
}

OverlayPoses OverlayPosesOf(const TrackedFrame& tracked, const Rigid3d& room_from_model_target) {
  OverlayPoses poses;
  if (tracked.room_from_camera) {
    const Rigid3d camera_from_room = tracked.room_from_camera->Inverse();
    poses.camera_from_model_planned = camera_from_room * room_from_model_target;
    if (tracked.room_from_model) poses.camera_from_model_current = camera_from_room * *tracked.room_from_model;
  } else if (tracked.camera_from_model) {
    poses.camera_from_model_current = tracked.camera_from_model;
  }
  return poses;
}

TrackSequenceResult TrackSequence(Database* database, const TrackingInputs& inputs, const CaseConfig& config,
                                  const TrackSequenceOptions& options) {
  RequirePermission(options.op, Action::kTrack);
  const std::string actor = options.op.Actor("arpos track");
  ARPOS_CHECK(database != nullptr, "tracking needs a session store");
  const std::string tol_problem = options.tolerances.Validate();
  if (!tol_problem.empty()) ARPOS_INPUT_ERROR("tolerances: " << tol_problem);
  if (std::abs(inputs.room_map.marker_size_m - config.room_markers.size_m) > 1e-6) {
    ARPOS_INPUT_ERROR("room map " << inputs.room_map_id.value() << " was built with " << inputs.room_map.marker_size_m
                                  << " m markers but case.yaml says " << config.room_markers.size_m << " m");
  }
  RequireOpenSession(database, inputs.session_id, "tracking");
  std::unique_ptr<CameraSource> owned_source;
  CameraSource* source = options.source;
  if (!source) {
    if (options.sequence_dir.empty()) ARPOS_INPUT_ERROR("tracking needs a sequence folder or a camera source");
    std::string uri = "replay:" + std::filesystem::absolute(options.sequence_dir).string();
    if (!options.case_dir.empty()) uri += "?case=" + std::filesystem::absolute(options.case_dir).string();
    owned_source = SourceRegistry().Create(uri);
    source = owned_source.get();
  }
  const std::string recording_path = source->recording_path();
  TrackSequenceResult result;
  if (!options.name.empty()) {
    result.name = options.name;
  } else if (!options.sequence_dir.empty()) {
    result.name = std::filesystem::absolute(options.sequence_dir).lexically_normal().filename().string();
  } else {
    ARPOS_INPUT_ERROR("a tracking run of a live source needs a name");
  }
  const CameraIntrinsics camera = source->intrinsics();
  if (camera.width != config.camera.width || camera.height != config.camera.height) {
    Log(LogLevel::kWarning, StringPrintf("the source's images are %dx%d, case.yaml says %dx%d: tracking uses the "
                                         "source's camera",
                                         camera.width, camera.height, config.camera.width, config.camera.height));
  }
  const bool write_files = !options.out_dir.empty();
  if (options.overlay && !write_files) ARPOS_INPUT_ERROR("the overlay needs an output folder (--out)");
  if (write_files) {
    std::error_code ec;
    std::filesystem::create_directories(options.out_dir / (options.overlay ? "overlay" : ""), ec);
    if (ec) ARPOS_INPUT_ERROR(options.out_dir.string() << ": cannot create the output folder (" << ec.message() << ")");
  }

  // At work on the session until the run is stored: a run that dies leaves
  // the session to be marked aborted by the next command (store/lifecycle.h).
  const SessionActivityGuard activity(database, inputs.session_id, "arpos track " + result.name);
  TrackerOptions tracker_options = MakeTrackerOptions(config, inputs);
  tracker_options.camera.detector.intrinsics = camera;
  tracker_options.body.detector.intrinsics = camera;
  tracker_options.tolerances = options.tolerances;
  tracker_options.parallel = options.parallel;
  tracker_options.temporal_filter = options.temporal_filter;
  RecordingResponse response;
  if (!recording_path.empty()) {
    response = EstimateRecordingResponse(Sequence::OpenEveryColourFrame(recording_path), config,
                                         inputs.room_map.camera_response);
  } else {
    // A live stream cannot be sampled ahead: the planning recording's
    // response, measured by the same camera (store it with the room map).
    response.response = inputs.room_map.camera_response;
    response.message = "camera response: the room map's (" + inputs.room_map.camera_response.name() +
                       "); a live stream is not sampled ahead";
  }
  result.response_message = response.message;
  result.room_frame = DescribeRoomFrame(inputs, options.tolerances, tracker_options.uncertainty_sigmas);
  if (AlignmentRecord::AsksForCheck(inputs.alignment_status))
    result.alignment_check = inputs.alignment_status;

  tracker_options.camera.detector.edge.response = response.response;
  tracker_options.body.detector.edge.response = response.response;
  // Breathing, as the session measured it.
  tracker_options.body.sticker_motion_m = inputs.sticker_motion_m;
  tracker_options.body.sticker_motion_direction = inputs.sticker_motion_direction;
  tracker_options.body.moving_surface_patches = inputs.moving_surface_patches;
  if (inputs.surface_patch_m > 0) tracker_options.body.moving_surface_patch_m = inputs.surface_patch_m;
  const DepthCorrector depth_corrector(config.camera, inputs.room_map.depth_correction);
  Tracker tracker(inputs.room_map, inputs.model, inputs.model_from_marker, inputs.room_from_model_target, camera,
                  tracker_options, inputs.room_from_model_at_scan);
  // Before the first frame arrives (a live source starts in FrameFeed): the
  // first frame's latency without the process's one-off costs.
  tracker.WarmUp();
  std::optional<OverlayRenderer> overlay;
  if (options.overlay) overlay.emplace(inputs.model, camera);

  std::vector<StampedPose> poses, camera_poses;
  std::ostringstream corrections, timing;
  corrections << CorrectionsCsvHeader();
  timing << "timestamp,load_ms,depth_correction_ms,camera_detection_ms,camera_keypoints_ms,camera_matching_ms,"
            "camera_pnp_ms,camera_refinement_ms,camera_ms,body_detection_ms,body_pose_ms,body_ms,combine_ms,"
            "total_ms\n";
  std::vector<TrackingFrameRecord> records;
  std::vector<double> totals;
  double last_t = -1;
  const int stream_frames = source->frame_count();
  const size_t count = stream_frames > 0 ? static_cast<size_t>(stream_frames) : 0;
  FrameFeed feed(source, options.on_capture, options.live_queue_frames);
  for (size_t i = 0;; ++i) {
    if (options.max_frames > 0 && static_cast<int>(i) >= options.max_frames) break;
    if (options.before_frame && !options.before_frame(i, count)) {
      result.stopped = true;
      break;
    }
    const auto t_load = Clock::now();
    RgbdFrame frame;
    if (!feed.Take(&frame)) break;
    const double t = frame.timestamp_s;
    std::string note;
    if (last_t >= 0 && t - last_t > options.max_frame_gap_s) {
      note = StringPrintf("%.3f s since the previous frame", t - last_t);
    }
    last_t = t;
    const bool readable = !frame.color.empty();
    const std::string depth_problem = readable ? frame.problem : "";
    if (!readable) note += (note.empty() ? "" : "; ") + frame.problem;
    const double load_ms = MsSince(t_load);
    TrackedFrame tracked;
    double depth_ms = 0;
    // Frame arrival (the source's capture, or the file read): from here to
    // the correction is the latency.
    const Clock::time_point arrival = frame.arrival == Clock::time_point{} ? Clock::now() : frame.arrival;
    if (readable) {
      // Depth of another type or size is the tracker's to refuse, with the reason.
      if (!frame.depth.empty() && frame.depth.type() == CV_16UC1 &&
          frame.depth.cols == camera.width && frame.depth.rows == camera.height) {
        depth_corrector.Apply(&frame.depth);
      }
      depth_ms = MsSince(arrival);
      tracked = tracker.Process(frame);
      tracked.timings.total_ms = MsSince(arrival);
      if (options.on_result) options.on_result(tracked, arrival);
      if (!depth_problem.empty()) note += (note.empty() ? "" : "; ") + depth_problem;
    } else {
      tracked.index = static_cast<int>(i);
      tracked.timestamp_s = t;
      tracked.correction = LostCorrection();
      if (options.on_result) options.on_result(tracked, arrival);
    }
    if (!tracked.message.empty()) note += (note.empty() ? "" : "; ") + tracked.message;

    ++result.frames;
    switch (tracked.state) {
      case TrackingState::kTracked: ++result.tracked; break;
      case TrackingState::kCarried: ++result.carried; break;
      case TrackingState::kLost:
        ++result.lost;
        ++result.lost_by_cause.at(static_cast<size_t>(tracked.loss));
        if (!tracked.body.sticker_ids.empty() || !tracked.body.stickers_dropped.empty()) ++result.lost_with_stickers;
        break;
    }
    if (tracked.correction.state == CorrectionState::kIn) ++result.in_tolerance;
    if (tracked.correction.state == CorrectionState::kOut) ++result.out_of_tolerance;
    if (tracked.room_from_model) poses.push_back({t, *tracked.room_from_model});
    if (tracked.room_from_camera) camera_poses.push_back({t, *tracked.room_from_camera});
    corrections << CorrectionsCsvRow(t, tracked.correction);
    const TrackingTimings& tm = tracked.timings;
    // DATASET.md: every column after the timestamp is milliseconds.
    timing << StringPrintf("%.6f,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f\n", t, load_ms,
                           depth_ms, tm.camera.detection_ms, tm.camera.keypoints_ms, tm.camera.matching_ms,
                           tm.camera.pnp_ms, tm.camera.refinement_ms, tm.camera_ms, tm.body.detection_ms,
                           tm.body.pose_ms, tm.body_ms, tm.combine_ms, tm.total_ms);
    if (readable) totals.push_back(tm.total_ms);

    TrackingFrameRecord record;
    // The camera's frame number: a live run's dropped frames show as gaps.
    record.frame_index = static_cast<std::int64_t>(frame.index >= 0 ? static_cast<size_t>(frame.index) : i);
    record.timestamp_s = t;
    record.status = tracked.correction.state == CorrectionState::kIn    ? TrackingFrameStatus::kInTolerance
                    : tracked.correction.state == CorrectionState::kOut ? TrackingFrameStatus::kOutOfTolerance
                                                                        : TrackingFrameStatus::kLost;
    if (record.status != TrackingFrameStatus::kLost) {
      record.room_from_model = tracked.room_from_model;
      Correction6Dof c;
      c.translation_mm = Eigen::Vector3d(tracked.correction.lateral_mm, tracked.correction.longitudinal_mm,
                                         tracked.correction.vertical_mm);
      c.rotation_deg = Eigen::Vector3d(tracked.correction.pitch_deg, tracked.correction.roll_deg,
                                       tracked.correction.yaw_deg);
      record.correction = c;
      record.uncertainty_translation_mm = tracked.correction.uncertainty.translation_mm;
      record.uncertainty_rotation_deg = tracked.correction.uncertainty.rotation_deg;
    }
    record.room_from_camera = tracked.room_from_camera;
    record.source = TrackingStateName(tracked.state);
    record.total_ms = std::max(0.0, tm.total_ms);
    record.note = note;
    records.push_back(std::move(record));
    result.last_correction = tracked.correction;

    const OverlayPoses overlay_poses = OverlayPosesOf(tracked, inputs.room_from_model_target);
    if (overlay && readable) {
      const std::optional<Rigid3d>& current = overlay_poses.camera_from_model_current;
      const std::optional<Rigid3d>& planned = overlay_poses.camera_from_model_planned;
      // What to do first when lost, then why (wrapped to the image's width).
      const std::string advice = TrackingLossAdvice(tracked.loss);
      const std::string why = advice.empty() ? tracked.message
                              : tracked.message.empty() ? advice
                                                        : advice + " (" + tracked.message + ")";
      const std::string caption = StringPrintf("t %.3f s  frame %zu  %s%s%s", t, i, TrackingStateName(tracked.state),
                                               why.empty() ? "" : ": ", why.c_str());
      const cv::Mat image = overlay->Render(frame.color, current, planned, tracked.correction, caption,
                                            TrackingLossHeadline(tracked.loss));
      const std::filesystem::path file = options.out_dir / "overlay" / StringPrintf("%.6f.png", t);
      if (!cv::imwrite(file.string(), image)) ARPOS_INPUT_ERROR(file.string() << ": could not be written");
    }
    if (options.on_frame) {
      TrackedFrameEvent event;
      event.index = i;
      event.count = count;
      event.tracked = &tracked;
      if (readable) event.colour = frame.color;
      event.has_depth = readable && !frame.depth.empty();
      event.poses = overlay_poses;
      event.note = note;
      options.on_frame(event);
    }
    if (options.progress) options.progress(i + 1, count);
  }
  feed.Stop();
  result.dropped = feed.dropped();
  result.sequence_frames = stream_frames > 0 ? stream_frames : feed.captured();
  if (!totals.empty()) {
    double sum = 0;
    for (double v : totals) sum += v;
    result.mean_total_ms = sum / totals.size();
    std::vector<double> sorted = totals;
    std::sort(sorted.begin(), sorted.end());
    result.p95_total_ms = sorted[std::min(sorted.size() - 1, static_cast<size_t>(0.95 * sorted.size()))];
    result.max_total_ms = sorted.back();
  }

  // Files first: a run whose files cannot be written stores nothing.
  const std::string header = StringPrintf("arpos track %s: session %lld, plan %lld, room map %lld",
                                          result.name.c_str(), static_cast<long long>(inputs.session_id.value()),
                                          static_cast<long long>(inputs.plan_id.value()),
                                          static_cast<long long>(inputs.room_map_id.value()));
  if (write_files) {
    WriteTrajectory(options.out_dir / "poses.txt", poses, header + ": room_from_model (reference model -> room)");
    WriteTrajectory(options.out_dir / "camera_poses.txt", camera_poses,
                    header + ": room_from_camera (camera -> room)");
    WriteFileAtomic(options.out_dir / "corrections.csv", corrections.str());
    WriteFileAtomic(options.out_dir / "timing.csv", timing.str());
  }
  result.poses = poses;

  // What the run tracked: the recording, else the live source (and where it
  // was recorded, if it was).
  const std::string run_recording =
      !recording_path.empty()        ? std::filesystem::absolute(recording_path).lexically_normal().string()
      : !options.record_dir.empty() ? std::filesystem::absolute(options.record_dir).lexically_normal().string()
                                     : "live: " + source->description();
  const std::string run_source = recording_path.empty() ? source->description() + (options.record_dir.empty() ? "" : ", recorded to " + run_recording) : run_recording;
  TrackingRunRecord run;
  run.session_id = inputs.session_id;
  run.alignment_id = inputs.alignment_id;
  run.tolerance_translation_mm = options.tolerances.translation_mm;
  run.tolerance_rotation_deg = options.tolerances.rotation_deg;
  run.sequence_name = result.name;
  run.options = StringPrintf(
      "sequence: %s\nout: %s\noverlay: %s\nparallel: %s\ntemporal_filter: %s\nuncertainty_sigmas: %g\n"
      "body_marker_map: %lld\n"
      "room_map: %lld\nresponse: %s\nroom_frame_sigma: %s\n",
      run_source.c_str(),
      write_files ? std::filesystem::absolute(options.out_dir).lexically_normal().string().c_str() : "(none)",
      options.overlay ? "true" : "false",
      options.parallel ? "true" : "false", options.temporal_filter ? "true" : "false",
      tracker_options.uncertainty_sigmas,
      static_cast<long long>(inputs.body_marker_map_id.value()), static_cast<long long>(inputs.room_map_id.value()),
      response.message.c_str(),
      inputs.room_frame_position_sigma_mm
          ? StringPrintf("%.3f mm, %.4f deg", tracker_options.room_frame_position_sigma_mm,
                         tracker_options.room_frame_rotation_sigma_deg).c_str()
          : "unknown");
  run.options += StringPrintf(
      "scan_landmarks: %d (placed to %.2f mm, for frames the room map does not place)\n",
      inputs.scan_landmarks, inputs.scan_landmark_sigma_mm);
  run.options += StringPrintf(
      "breathing_stickers: %zu (%zu with the direction the scan measured, the others along "
      "their normals)\n",
      inputs.sticker_motion_m.size(), inputs.sticker_motion_direction.size());
  run.summary = result.Summary();
  database->WithTransaction([&] {
    if (options.recording_id) {
      result.recording_id = *options.recording_id;
    } else {
      RecordingRecord rec;
      rec.kind = RecordingKind::kTracking;
      rec.session_id = inputs.session_id;
      rec.name = result.name;
      rec.path = run_recording;
      rec.frame_count = static_cast<std::int64_t>(result.sequence_frames);
      rec.intrinsics = ToRecordingIntrinsics(camera);
      result.recording_id = database->AddRecording(rec);
    }
    run.recording_id = result.recording_id;
    result.run_id = database->AddTrackingRun(run);
    database->AppendTrackingFrames(result.run_id, records);
    database->AppendAudit({AuditId(), 0, actor, "track",
                           "tracking_run:" + std::to_string(result.run_id.value()), result.Summary()});
  });
  return result;
}

}  // namespace arpos
