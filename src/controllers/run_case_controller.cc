#include "controllers/run_case_controller.h"

#include <sstream>

#include "controllers/session_controller.h"
#include "eval/trajectory_eval.h"
#include "geometry/mesh_io.h"
#include "room_map/plan_stage.h"
#include "sensor/case_check.h"
#include "sensor/case_folder.h"
#include "sensor/sequence.h"
#include "store/database.h"
#include "store/lifecycle.h"
#include "store/record_conversions.h"
#include "tracking/tracking_stage.h"
#include "util/logging.h"
#include "util/string_util.h"

namespace arpos {

std::string RunCaseOptions::Check() const {
  if (case_dir.empty()) return "no case folder given";
  if (const std::string t = tolerances.Validate(); !t.empty()) return "--tolerance-mm/--tolerance-deg: " + t;
  return "";
}

std::string RunCaseResult::Summary() const {
  std::ostringstream out;
  out << "stored: patient " << patient_id.value() << ", plan " << plan_id.value() << ", session "
      << session_id.value() << ", " << recordings.size() << " recordings (" << frames
      << " frames), reference model " << reference_model_vertices << " vertices\n";
  if (!plan_summary.empty()) out << plan_summary << "\n";
  if (!session_summary.empty()) out << session_summary;
  if (!tracking_summary.empty()) out << tracking_summary;
  if (!evaluation.empty()) out << evaluation;
  for (const auto& f : failures) out << "FAILED: " << f << "\n";
  out << "stages done: ";
  for (size_t i = 0; i < stages_done.size(); ++i) out << (i ? ", " : "") << stages_done[i];
  out << "\n";
  return out.str();
}

RunCaseController::RunCaseController(RunCaseOptions options, Database* database,
                                     ControllerCallbacks callbacks)
    : Controller(std::move(callbacks)), options_(std::move(options)), database_(database) {}

void RunCaseController::Run() {
  const std::string problem = options_.Check();
  if (!problem.empty()) ARPOS_INPUT_ERROR("run-case: " << problem);
  RequirePermission(options_.op, Action::kRunCase);
  const std::string actor = options_.op.Actor("arpos run-case");
  ARPOS_CHECK(database_ != nullptr, "run-case needs a session store");
  result_ = RunCaseResult();

  Step("checking the case folder", 0.0);
  CaseCheckOptions check_options;
  check_options.read_all_images = options_.read_all_images;
  const CaseCheckReport report = RequireValidCase(options_.case_dir, check_options);
  for (const auto& p : report.problems) result_.warnings.push_back(p.ToString());
  if (options_.out_dir) RequireWritableFolder(*options_.out_dir, "--out");
  result_.stages_done.push_back("check");

  Step("importing the reference model", 0.1);
  const CaseFolder folder = LoadCaseFolder(options_.case_dir);
  TriangleMesh model = LoadTriangleMesh(folder.reference_model);
  result_.reference_model_vertices = static_cast<int>(model.vertices.size());

  const std::string patient_external =
      options_.patient_external_id.empty()
          ? std::filesystem::absolute(folder.root).lexically_normal().filename().string()
          : options_.patient_external_id;
  const std::string case_name = patient_external.empty() ? "case" : patient_external;

  // The room map is built before anything is stored, then the patient,
  // plan, room recording and map commit together: a room that cannot be
  // mapped leaves the store as it was.
  Step("building the room map", 0.15);
  RoomMapStageOptions map_options;
  map_options.threads = options_.threads;
  const RoomMapBuildResult room_map = BuildCaseRoomMap(folder, map_options);

  Step("storing the plan", 0.4);
  RecordingId room_recording;
  database_->WithTransaction([&] {
    if (const std::optional<PatientRecord> patient = database_->FindPatient(case_name)) {
      result_.patient_id = patient->id;
    } else {
      result_.patient_id = AddCasePatient(database_, folder, case_name, actor);
    }
    result_.plan_id = AddCasePlan(database_, result_.patient_id, folder, model, case_name, actor);
    room_recording = AddRoomRecording(database_, result_.plan_id, folder);
    result_.room_map_id = StoreRoomMap(database_, result_.plan_id, room_recording, folder, room_map, actor);
  });
  result_.recordings.push_back(room_recording);
  result_.frames += static_cast<int>(Sequence::Open(folder.room_dir).size());
  result_.stages_done.push_back("plan stored");
  result_.plan_summary = StringPrintf("room map %lld: ", static_cast<long long>(result_.room_map_id.value())) +
                         room_map.report.ToText();
  result_.stages_done.push_back("room map");

  Step("session stage", 0.45);
  SessionStageOptions session_options;
  session_options.case_dir = folder.root;
  session_options.plan_id = result_.plan_id;
  session_options.out_dir = options_.out_dir;
  session_options.threads = options_.threads;
  session_options.op = options_.op;
  session_options.unapproved = true;
  SessionController session(session_options, database_);
  try {
    session.Run();
  } catch (const InputError& e) {
    // The plan and room map stay stored; report what stopped the session.
    result_.failures.push_back(std::string("session stage: ") + e.what());
    Step("done (session stage failed)", 1.0);
    return;
  }
  const SessionStageResult& s = session.result();
  result_.session_id = s.session_id;
  // Registered as at work on the session until the end: a run-case that dies
  // leaves the session to be marked aborted by the next command.
  const SessionActivityGuard activity(database_, s.session_id, "arpos run-case " + folder.root.string());
  result_.recordings.push_back(s.recording_id);
  result_.frames += s.frames;
  result_.session_summary = s.Summary();
  result_.stages_done.push_back("body marker map");
  result_.stages_done.push_back("reconstruction");
  result_.stages_done.push_back("alignment");

  Step("registering the tracking recordings", 0.85);
  const CameraIntrinsics& camera = folder.config.camera;
  std::vector<std::pair<std::string, RecordingId>> tracking_recordings;
  database_->WithTransaction([&] {
    for (const auto& [name, dir] : folder.tracking) {
      RecordingRecord rec;
      rec.kind = RecordingKind::kTracking;
      rec.session_id = result_.session_id;
      rec.name = name;
      rec.path = std::filesystem::absolute(dir).lexically_normal().string();
      rec.frame_count = static_cast<std::int64_t>(Sequence::Open(dir).size());
      rec.intrinsics = ToRecordingIntrinsics(camera);
      result_.frames += static_cast<int>(rec.frame_count);
      result_.recordings.push_back(database_->AddRecording(rec));
      tracking_recordings.emplace_back(name, result_.recordings.back());
    }
  });
  result_.stages_done.push_back("tracking recordings registered");

  // Tracking mode on every tracking/<name>, into <out>/<name>/.
  std::vector<std::pair<std::string, TrackSequenceResult>> tracked;
  if (!folder.tracking.empty()) {
    const TrackingInputs inputs = LoadTrackingInputs(database_, result_.session_id, "");
    size_t k = 0;
    for (const auto& [name, dir] : folder.tracking) {
      Step("tracking " + name, 0.87 + 0.12 * k / folder.tracking.size());
      TrackSequenceOptions track;
      track.sequence_dir = dir;
      track.name = name;
      if (options_.out_dir) track.out_dir = *options_.out_dir / name;
      track.overlay = options_.out_dir.has_value() && options_.overlay;
      track.tolerances = options_.tolerances;
      track.op = options_.op;
      track.recording_id = tracking_recordings[k].second;
      try {
        TrackSequenceResult r = TrackSequence(database_, inputs, folder.config, track);
        result_.tracking_summary += r.Summary() + "\n";
        tracked.emplace_back(name, std::move(r));
      } catch (const InputError& e) {
        result_.failures.push_back("tracking " + name + ": " + e.what());
      }
      ++k;
    }
    if (!tracked.empty()) result_.stages_done.push_back("tracking");
  }

  // Ground truth, where the case has it.
  const Sequence scan = Sequence::Open(folder.body_scan_dir);
  std::ostringstream evaluation;
  if (const auto body_gt = scan.BodyGroundTruth(); body_gt && !body_gt->empty()) {
    std::vector<StampedPose> estimate;
    for (const auto& p : *body_gt) estimate.push_back({p.timestamp_s, s.room_from_model});
    const TrajectoryEvaluation e = EvaluateTrajectory(*body_gt, estimate);
    evaluation << StringPrintf("model pose at scan time vs body_groundtruth.txt: %.3f mm, %.4f deg\n",
                               e.translation_mm.mean, e.rotation_deg.mean);
  }
  for (const auto& [name, r] : tracked) {
    std::filesystem::path dir;
    for (const auto& [n, d] : folder.tracking) {
      if (n == name) dir = d;
    }
    const Sequence seq = Sequence::Open(dir);
    const auto body_gt = seq.BodyGroundTruth();
    if (!body_gt || body_gt->empty()) continue;
    const TrajectoryEvaluation e = EvaluateTrajectory(*body_gt, r.poses);
    if (e.has_errors()) {
      evaluation << StringPrintf("tracking %s vs body_groundtruth.txt: MTE %.2f mm, MRE %.3f deg (median %.2f mm, "
                                 "p95 %.2f mm), %.1f %% lost\n",
                                 name.c_str(), e.translation_mm.mean, e.rotation_deg.mean, e.translation_mm.median,
                                 e.translation_mm.p95, e.lost_percent);
    } else {
      evaluation << "tracking " << name << " vs body_groundtruth.txt: n/a (every frame lost)\n";
    }
  }
  result_.evaluation = evaluation.str();
  if (!options_.keep_session_open) {
    std::string reason;
    for (const std::string& f : result_.failures) reason += (reason.empty() ? "" : "; ") + f;
    EndSession(database_, options_.op, result_.session_id,
               reason.empty() ? SessionStatus::kCompleted : SessionStatus::kAborted,
               reason.empty() ? "run-case: every stage done" : "run-case: " + reason);
    result_.stages_done.push_back(reason.empty() ? "session completed" : "session aborted");
  }
  Step("done", 1.0);
}

}  // namespace arpos
