#include "room_map/plan_stage.h"

#include <cmath>
#include <sstream>

#include "geometry/mesh_io.h"
#include "sensor/case_check.h"
#include "sensor/sequence.h"
#include "store/lifecycle.h"
#include "store/record_conversions.h"
#include "util/check.h"
#include "util/logging.h"
#include "util/string_util.h"

namespace arpos {

std::string RoomMapStageOptions::Check() const {
  if (frame_step < 1) return "frame step must be at least 1";
  if (max_frames < 0) return "max frames must not be negative";
  if (threads < 1) return "threads must be at least 1";
  if (max_landmarks < 0) return "max landmarks must not be negative";
  return "";
}

std::string PlanRoomMapOptions::Check() const {
  if (case_dir.empty()) return "no case folder given";
  if (plan_id && !plan_id->valid()) return "plan id must be positive";
  if (plan_id && new_plan) return "give either a plan or a new plan, not both";
  return stage.Check();
}

std::string CasePatientId(const std::filesystem::path& case_root) {
  return std::filesystem::absolute(case_root).lexically_normal().filename().string();
}

std::optional<std::filesystem::path> FindCaseRoot(const std::filesystem::path& sequence_dir) {
  std::filesystem::path p = std::filesystem::absolute(sequence_dir).lexically_normal();
  if (p.has_filename() == false) p = p.parent_path();
  while (!p.empty()) {
    if (std::filesystem::exists(p / "case.yaml")) return p;
    if (p == p.root_path() || p.parent_path() == p) break;
    p = p.parent_path();
  }
  return std::nullopt;
}

RoomMapBuildOptions MakeRoomMapBuildOptions(const CaseFolder& folder, const RoomMapStageOptions& options) {
  RoomMapBuildOptions build = MakeRoomMapBuildOptions(folder.config);
  build.frame_step = options.frame_step;
  build.max_frames = options.max_frames;
  build.threads = options.threads;
  build.use_keypoints = options.use_keypoints;
  build.max_landmarks = options.max_landmarks;
  if (options.exclude_couch) build.exclude_landmarks.push_back(CouchExclusionBox(folder.room_from_model_target));
  build.couch_point_in_room = folder.room_from_model_target.translation;
  return build;
}

RoomMapBuildResult BuildCaseRoomMap(const CaseFolder& folder, const RoomMapStageOptions& options,
                                    const ControllerCallbacks& callbacks) {
  const std::string problem = options.Check();
  if (!problem.empty()) ARPOS_INPUT_ERROR("room map: " << problem);
  if (!std::filesystem::is_directory(folder.room_dir)) {
    ARPOS_INPUT_ERROR(folder.room_dir.string() << ": no room sequence (the room map is built from room/)");
  }
  const Sequence room = Sequence::Open(folder.room_dir);
  return BuildRoomMap(room, folder.config, MakeRoomMapBuildOptions(folder, options), callbacks);
}

namespace {

// The builder leaves a sigma infinite when it could not measure it; the
// store keeps that as "not measured".
std::optional<double> Measured(double value) {
  return std::isfinite(value) ? std::optional<double>(value) : std::nullopt;
}

// Report lines go into one line of audit details.
std::string OneLine(std::string text) {
  for (char& c : text) {
    if (c == '\n') c = ' ';
  }
  return text;
}

}  // namespace

RoomMapId StoreRoomMap(Database* database, PlanId plan, std::optional<RecordingId> room_recording,
                       const CaseFolder& folder, const RoomMapBuildResult& build, const std::string& actor) {
  ARPOS_CHECK(database != nullptr, "the room map stage needs a session store");
  const RoomMap& map = build.map;
  const RoomMapBuildReport& r = build.report;
  RoomMapRecord record = ToRecord(map, plan, room_recording);
  record.room_frame_tilt_sigma_deg = Measured(r.CouchTiltSigmaDeg());
  record.room_frame_yaw_sigma_deg = Measured(r.CouchYawSigmaDeg());
  record.room_frame_couch_sigma_mm = Measured(r.CouchSigmaMm());
  std::string details = StringPrintf(
      "plan %lld, %zu markers (origin %d), %d landmarks, marker residual mean %.3f px max %.3f px, "
      "%d/%d frames, depth scale %.4f, from %s",
      static_cast<long long>(plan.value()), map.markers.size(), map.origin_marker_id, map.num_landmarks(),
      map.mean_residual_px, map.max_residual_px, r.frames_used, r.frames_total, r.depth_scale_ratio,
      folder.room_dir.string().c_str());
  details += StringPrintf("; room frame (origin marker, %d views): tilt %.4f deg, yaw %.4f deg, position at the "
                          "couch %.3f mm (1 sigma)",
                          r.origin_observations, r.room_frame_tilt_sigma_deg, r.room_frame_yaw_sigma_deg,
                          r.room_frame_couch_sigma_mm);
  if (r.map_couch_markers > 0) {
    details += StringPrintf("; the map near the couch relative to it %.3f mm, tilt %.4f deg, yaw %.4f deg (1 sigma)",
                            r.map_couch_sigma_mm, r.map_couch_tilt_sigma_deg, r.map_couch_yaw_sigma_deg);
  }
  if (!r.camera_response.empty()) details += "; " + OneLine(r.camera_response);
  if (!r.depth_correction.empty()) details += "; " + OneLine(r.depth_correction);
  if (!map.surface.empty()) {
    details += StringPrintf("; room surface %zu points (%.0f mm voxels)", map.surface.size(), 1000 * map.surface.voxel_m);
  }
  RoomMapId id;
  database->WithTransaction([&] {
    id = database->AddRoomMap(record);
    database->AppendAudit(
        {AuditId(), 0, actor, "build_room_map", "room_map:" + std::to_string(id.value()), details});
  });
  return id;
}

PatientId AddCasePatient(Database* database, const CaseFolder& folder, const std::string& external_id,
                         const std::string& actor) {
  PatientRecord record;
  record.external_id = external_id;
  record.display_name = external_id;
  const PatientId id = database->AddPatient(record);
  database->AppendAudit({AuditId(), 0, actor, "add_patient", "patient:" + std::to_string(id.value()),
                         "from case " + folder.root.string()});
  return id;
}

PlanId AddCasePlan(Database* database, PatientId patient, const CaseFolder& folder, const TriangleMesh& model,
                   const std::string& case_name, const std::string& actor) {
  PlanRecord plan;
  plan.patient_id = patient;
  plan.name = case_name + " plan";
  plan.reference_model_name = folder.reference_model.filename().string();
  plan.reference_model = ToStoredMesh(model);
  plan.room_from_model_target = folder.room_from_model_target;
  const PlanId id = database->AddPlan(plan);
  database->AppendAudit({AuditId(), 0, actor, "add_plan", "plan:" + std::to_string(id.value()),
                         "reference model " + plan.reference_model_name + ", target pose " +
                             plan.room_from_model_target.ToString()});
  return id;
}

RecordingId AddRoomRecording(Database* database, PlanId plan, const CaseFolder& folder) {
  RecordingRecord rec;
  rec.kind = RecordingKind::kRoom;
  rec.plan_id = plan;
  rec.name = "room";
  rec.path = std::filesystem::absolute(folder.room_dir).lexically_normal().string();
  rec.frame_count = std::filesystem::is_directory(folder.room_dir)
                        ? static_cast<std::int64_t>(Sequence::Open(folder.room_dir).size())
                        : 0;
  rec.intrinsics = ToRecordingIntrinsics(folder.config.camera);
  return database->AddRecording(rec);
}

std::string PlanRoomMapResult::Summary() const {
  std::ostringstream out;
  out << "room map " << room_map_id.value() << " stored for plan " << plan_id.value()
      << (created_plan ? " (created)" : "") << ", patient " << patient_id.value() << ", recording "
      << recording_id.value() << "\n";
  if (!plan_choice.empty()) out << "plan: " << plan_choice << "; not approved until a physicist approves it\n";
  out << "markers: " << build.map.markers.size() << " (origin " << build.map.origin_marker_id
      << "), residual mean " << StringPrintf("%.3f", build.map.mean_residual_px) << " px, max "
      << StringPrintf("%.3f", build.map.max_residual_px) << " px\n";
  for (const auto& m : build.map.markers) {
    const Eigen::Vector3d& t = m.room_from_marker.translation;
    out << StringPrintf("  marker %3d  at [%8.4f %8.4f %8.4f] m  residual %.3f px  %d views\n", m.id, t.x(), t.y(),
                        t.z(), m.residual_px, m.num_observations);
  }
  out << build.report.ToText();
  return out.str();
}

PlanRoomMapResult RunPlanRoomMap(const PlanRoomMapOptions& options, Database* database,
                                 const ControllerCallbacks& callbacks) {
  ARPOS_CHECK(database != nullptr, "plan needs a session store");
  const std::string problem = options.Check();
  if (!problem.empty()) ARPOS_INPUT_ERROR("plan: " << problem);
  if (callbacks.progress) callbacks.progress("reading the case", 0.0);
  // What planning reads, checked as `arpos check` does (quick: a sample of the
  // images), before anything is stored.
  CaseCheckOptions check;
  check.read_all_images = false;
  check.sequences = std::vector<std::filesystem::path>{"room"};
  RequireValidCase(options.case_dir, check);
  const CaseFolder folder = LoadCaseFolder(options.case_dir);
  const std::string patient_name =
      options.patient_external_id.empty() ? CasePatientId(folder.root) : options.patient_external_id;
  RequirePermission(options.op, Action::kPlan);
  const std::string actor = options.op.Actor("arpos plan");
  // Which plan the map goes to; asked again inside the transaction below.
  // An approved plan is never changed; without --plan the patient's one
  // unapproved plan is used, a new plan made if it has none, and a choice
  // between several refused.
  auto choose_plan = [&](PlanRoomMapResult* result) {
    if (options.plan_id) {
      const std::optional<PlanRecord> plan = database->GetPlan(*options.plan_id);
      if (!plan) ARPOS_INPUT_ERROR("the store has no plan " << options.plan_id->value());
      if (plan->approved()) {
        ARPOS_INPUT_ERROR("plan " << plan->id.value() << " is " << DescribeApproval(*plan)
                                  << ": an approved plan cannot be changed; make a new plan with --new-plan");
      }
      result->plan_id = plan->id;
      result->patient_id = plan->patient_id;
      result->plan_choice = "plan " + std::to_string(plan->id.value()) + " (given)";
      return;
    }
    const std::optional<PatientRecord> patient = database->FindPatient(patient_name);
    if (!patient) return;
    result->patient_id = patient->id;
    if (options.new_plan) return;
    std::vector<PlanSummary> open_plans;
    int approved = 0;
    for (const PlanSummary& p : database->ListPlans(patient->id)) {
      if (p.approved()) {
        ++approved;
      } else {
        open_plans.push_back(p);
      }
    }
    if (open_plans.size() > 1 && options.op.role == Role::kResearch) {
      // A research run takes the newest (ListPlans is newest first) and says so.
      result->plan_id = open_plans.front().id;
      result->plan_choice = "plan " + std::to_string(result->plan_id.value()) + ", the newest of the patient's " +
                            std::to_string(open_plans.size()) + " plans not yet approved (research run; --plan ID " +
                            "chooses)";
      return;
    }
    if (open_plans.size() > 1) {
      std::string ids;
      for (const PlanSummary& p : open_plans) ids += (ids.empty() ? "" : ", ") + std::to_string(p.id.value());
      ARPOS_INPUT_ERROR("patient " << patient_name << " has " << open_plans.size()
                                   << " plans that are not approved (" << ids
                                   << "): choose one with --plan ID, or make a new one with --new-plan");
    }
    if (open_plans.size() == 1) {
      result->plan_id = open_plans.front().id;
      result->plan_choice = "plan " + std::to_string(result->plan_id.value()) + " (the patient's plan not yet approved)";
    } else if (approved > 0) {
      result->plan_choice = "a new plan (the patient's " + std::to_string(approved) +
                            " approved plan(s) cannot be changed)";
    }
  };
  {
    PlanRoomMapResult probe;  // fail before the long build on what the store can already tell
    choose_plan(&probe);
  }

  PlanRoomMapResult result;
  result.build = BuildCaseRoomMap(folder, options.stage, callbacks);

  // Everything planning stores commits together, after the map exists: a
  // room that cannot be mapped leaves no patient, plan or recording behind.
  // The lookups run inside the transaction (which holds the write lock), so
  // another program planning the same case meanwhile is seen.
  database->WithTransaction([&] {
    choose_plan(&result);
    if (!result.patient_id.valid()) result.patient_id = AddCasePatient(database, folder, patient_name, actor);
    if (!result.plan_id.valid()) {
      result.plan_id = AddCasePlan(database, result.patient_id, folder, LoadTriangleMesh(folder.reference_model),
                                   patient_name, actor);
      result.created_plan = true;
      if (result.plan_choice.empty()) result.plan_choice = "a new plan";
      result.plan_choice += ": plan " + std::to_string(result.plan_id.value()) + " created";
    }
    result.recording_id = AddRoomRecording(database, result.plan_id, folder);
    result.room_map_id = StoreRoomMap(database, result.plan_id, result.recording_id, folder, result.build, actor);
  });
  return result;
}

PlanId ChoosePlanForSession(Database* database, std::optional<PlanId> given, const std::string& patient_external_id,
                            bool need_approved, bool newest_if_several, std::string* said) {
  auto describe = [&](PlanId id, const std::string& name, const std::string& approval) {
    return "plan " + std::to_string(id.value()) + " \"" + name + "\" (" + approval + ")";
  };
  const std::string approve_hint = " (a physicist approves a plan: arpos plan approve ID --role physicist; "
                                   "a session on a plan not approved needs --unapproved, and is recorded so)";
  if (given) {
    const std::optional<PlanRecord> plan = database->GetPlan(*given);
    if (!plan) ARPOS_INPUT_ERROR("the store has no plan " << given->value());
    if (!database->LatestRoomMap(*given)) {
      ARPOS_INPUT_ERROR("plan " << given->value() << " has no room map: run `arpos plan CASE --plan "
                                << given->value() << "` first");
    }
    if (need_approved && !plan->approved()) {
      ARPOS_INPUT_ERROR("plan " << given->value() << " is not approved" << approve_hint);
    }
    if (said) *said = "using " + describe(plan->id, plan->name, DescribeApproval(*plan)) + ", as given";
    return plan->id;
  }
  const std::optional<PatientRecord> patient = database->FindPatient(patient_external_id);
  if (!patient) {
    ARPOS_INPUT_ERROR("the store has no patient '" << patient_external_id
                                                   << "' (the case folder's name): plan the case first (arpos plan "
                                                      "CASE), or give --plan ID");
  }
  std::vector<PlanSummary> with_map, approved;
  std::vector<PlanSummary> all = database->ListPlans(patient->id);
  for (const PlanSummary& p : all) {
    if (p.num_room_maps == 0) continue;
    with_map.push_back(p);
    if (p.approved()) approved.push_back(p);
  }
  const std::vector<PlanSummary>& candidates = (need_approved || !approved.empty()) ? approved : with_map;
  if (candidates.size() == 1) {
    const PlanSummary& p = candidates.front();
    if (said) {
      *said = "using " + describe(p.id, p.name, DescribeApproval(p)) + ", the patient's only " +
              (p.approved() ? "approved plan" : "plan with a room map");
    }
    return p.id;
  }
  if (candidates.size() > 1) {
    std::string list;
    for (const PlanSummary& p : candidates) {
      list += (list.empty() ? "" : "; ") + describe(p.id, p.name, DescribeApproval(p));
    }
    if (newest_if_several) {  // ListPlans is newest first
      const PlanSummary& p = candidates.front();
      ARPOS_WARN("patient " << patient_external_id << " has " << candidates.size()
                            << " plans with a room map (" << list << "): this research run takes the newest");
      if (said) *said = "using " + describe(p.id, p.name, DescribeApproval(p)) + ", the newest of " +
                        std::to_string(candidates.size()) + " (research run; give --plan ID to choose)";
      return p.id;
    }
    ARPOS_INPUT_ERROR("patient " << patient_external_id << " has " << candidates.size() << " "
                                 << (candidates.front().approved() ? "approved plans" : "plans with a room map")
                                 << ": " << list << "; choose one with --plan ID");
  }
  if (all.empty()) ARPOS_INPUT_ERROR("patient " << patient_external_id << " has no plan: run `arpos plan CASE` first");
  if (with_map.empty()) {
    ARPOS_INPUT_ERROR("no plan of patient " << patient_external_id << " has a room map: run `arpos plan CASE` first");
  }
  std::string list;
  for (const PlanSummary& p : with_map) list += (list.empty() ? "" : ", ") + std::to_string(p.id.value());
  ARPOS_INPUT_ERROR("no plan of patient " << patient_external_id << " is approved (plans with a room map: " << list
                                          << ")" << approve_hint);
}

RoomMap LoadRoomMapForLocalization(Database* database, std::optional<PlanId> plan,
                                   const std::string& patient_external_id, PlanId* plan_out,
                                   RoomMapId* map_id_out) {
  ARPOS_CHECK(database != nullptr, "localisation needs a session store");
  std::optional<RoomMapId> map_id;
  PlanId chosen;
  if (plan) {
    if (!database->GetPlan(*plan)) ARPOS_INPUT_ERROR("the store has no plan " << plan->value());
    map_id = database->LatestRoomMap(*plan);
    if (!map_id) {
      ARPOS_INPUT_ERROR("plan " << plan->value() << " has no room map: run `arpos plan CASE --plan "
                                << plan->value() << "` first");
    }
    chosen = *plan;
  } else {
    std::vector<PlanSummary> plans;
    if (!patient_external_id.empty()) {
      if (const auto patient = database->FindPatient(patient_external_id)) plans = database->ListPlans(patient->id);
    }
    if (plans.empty()) plans = database->ListPlans();
    for (const auto& p : plans) {
      map_id = database->LatestRoomMap(p.id);
      if (map_id) {
        chosen = p.id;
        break;
      }
    }
    if (!map_id) {
      ARPOS_INPUT_ERROR("the store has no room map" << (plans.empty() ? " (and no plan)" : "")
                                                    << ": run `arpos plan CASE` first");
    }
  }
  const std::optional<RoomMapRecord> record = database->GetRoomMap(*map_id);
  if (!record) ARPOS_INPUT_ERROR("room map " << map_id->value() << " could not be read");
  if (plan_out) *plan_out = chosen;
  if (map_id_out) *map_id_out = *map_id;
  return FromRecord(*record);
}

}  // namespace arpos
