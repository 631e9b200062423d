#include "controllers/run_case_controller.h"

#include <sstream>

#include "geometry/mesh_io.h"
#include "sensor/case_check.h"
#include "sensor/case_folder.h"
#include "sensor/sequence.h"
#include "store/database.h"
#include "util/logging.h"
#include "util/string_util.h"

namespace arpos {
namespace {

RecordingIntrinsics ToRecordingIntrinsics(const CameraIntrinsics& c) {
  RecordingIntrinsics r;
  r.width = c.width;
  r.height = c.height;
  r.fx = c.fx;
  r.fy = c.fy;
  r.cx = c.cx;
  r.cy = c.cy;
  r.distortion = c.distortion;
  r.depth_scale = c.depth_scale;
  return r;
}

StoredTriangleMesh ToStoredMesh(const TriangleMesh& mesh) {
  StoredTriangleMesh stored;
  stored.vertices = mesh.vertices;
  stored.faces.reserve(mesh.faces.size());
  for (const auto& f : mesh.faces) {
    stored.faces.push_back({static_cast<std::uint32_t>(f[0]), static_cast<std::uint32_t>(f[1]),
                            static_cast<std::uint32_t>(f[2])});
  }
  return stored;
}

}  // namespace

std::string RunCaseOptions::Check() const {
  if (case_dir.empty()) return "no case folder given";
  if (actor.empty()) return "actor must not be empty";
  return "";
}

std::string RunCaseResult::Summary() const {
  std::ostringstream out;
  out << "stored: patient " << patient_id.value() << ", plan " << plan_id.value() << ", session "
      << session_id.value() << ", " << recordings.size() << " recordings (" << frames
      << " frames), reference model " << reference_model_vertices << " vertices\n";
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
  ARPOS_CHECK(database_ != nullptr, "run-case needs a session store");
  result_ = RunCaseResult();

  Step("checking the case folder", 0.0);
  CaseCheckOptions check_options;
  check_options.read_all_images = options_.read_all_images;
  const CaseCheckReport report = CheckCase(options_.case_dir, check_options);
  std::ostringstream errors;
  for (const auto& p : report.problems) {
    if (p.severity == CaseProblem::Severity::kError) {
      errors << "\n  " << p.ToString();
    } else {
      result_.warnings.push_back(p.ToString());
    }
  }
  if (!report.ok()) {
    ARPOS_INPUT_ERROR(options_.case_dir.string() << ": the case has problems (arpos check lists them):"
                                                 << errors.str());
  }
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

  Step("storing the plan", 0.2);
  const CameraIntrinsics& camera = folder.config.camera;
  // Plan, recordings and session commit together: a failure stores nothing.
  database_->WithTransaction([&] {
    std::optional<PatientRecord> patient = database_->FindPatient(case_name);
    if (patient) {
      result_.patient_id = patient->id;
    } else {
      PatientRecord record;
      record.external_id = case_name;
      record.display_name = case_name;
      result_.patient_id = database_->AddPatient(record);
      database_->AppendAudit({AuditId(), 0, options_.actor, "add_patient",
                              "patient:" + std::to_string(result_.patient_id.value()),
                              "from case " + folder.root.string()});
    }
    PlanRecord plan;
    plan.patient_id = result_.patient_id;
    plan.name = case_name + " plan";
    plan.reference_model_name = folder.reference_model.filename().string();
    plan.reference_model = ToStoredMesh(model);
    plan.room_from_model_target = folder.room_from_model_target;
    result_.plan_id = database_->AddPlan(plan);
    database_->AppendAudit({AuditId(), 0, options_.actor, "add_plan",
                            "plan:" + std::to_string(result_.plan_id.value()),
                            "reference model " + plan.reference_model_name + ", target pose " +
                                plan.room_from_model_target.ToString()});

    auto add_recording = [&](RecordingKind kind, const std::string& name,
                             const std::filesystem::path& dir) {
      RecordingRecord rec;
      rec.kind = kind;
      if (kind == RecordingKind::kRoom) {
        rec.plan_id = result_.plan_id;
      } else {
        rec.session_id = result_.session_id;
      }
      rec.name = name;
      rec.path = std::filesystem::absolute(dir).lexically_normal().string();
      rec.frame_count = static_cast<std::int64_t>(Sequence::Open(dir).size());
      rec.intrinsics = ToRecordingIntrinsics(camera);
      result_.frames += static_cast<int>(rec.frame_count);
      result_.recordings.push_back(database_->AddRecording(rec));
    };
    add_recording(RecordingKind::kRoom, "room", folder.room_dir);

    SessionRecord session;
    session.plan_id = result_.plan_id;
    session.operator_name = options_.actor;
    session.notes = "run-case " + folder.root.string();
    result_.session_id = database_->AddSession(session);
    database_->AppendAudit({AuditId(), 0, options_.actor, "open_session",
                            "session:" + std::to_string(result_.session_id.value()), ""});
    add_recording(RecordingKind::kBodyScan, "body_scan", folder.body_scan_dir);
    for (const auto& [name, dir] : folder.tracking) add_recording(RecordingKind::kTracking, name, dir);
  });
  result_.stages_done.push_back("plan stored");
  result_.stages_done.push_back("recordings registered");
  Step("done", 1.0);
  ARPOS_INFO("run-case: " << result_.Summary());
}

}  // namespace arpos
