#include "exe/cmd_plan.h"

#include <iostream>

#include "exe/args.h"
#include "room_map/plan_stage.h"
#include "sensor/sequence.h"
#include "sensor/tum_io.h"
#include "store/lifecycle.h"
#include "store/sqlite_database.h"
#include "store/store_path.h"
#include "tracking/tracking_stage.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos {

namespace {

// What the room frame does to tracking at the default tolerances, said when
// the room is mapped and when the plan is approved, not first when a
// therapist tracks.
void PrintRoomFrameAdvice(Database* database, RoomMapId map_id) {
  const auto map = database->GetRoomMap(map_id);
  if (!map) return;
  const RoomFrameNote note = DescribeRoomFrame(*map);
  if (note.blocks_in) std::cout << "warning: " << note.plan_advice << "\n";
}

int RunPlanApprove(const std::vector<std::string>& argv) {
  const char* usage =
      "usage: arpos plan approve PLAN_ID [--note TEXT] [--store DB] --role physicist --user NAME\n"
      "A physicist approves a plan: its reference model, target pose and room map. From then\n"
      "on the plan cannot be changed, and therapists run sessions on it.\n";
  const Args args(argv, {"store", "note"}, {"help"});
  if (const auto exit_status = UsageExit(args, usage, 1)) return *exit_status;
  const Operator op = ResolveOperator(GivenOperatorFlags().user, GivenOperatorFlags().role);
  long long id = 0;
  if (!ParseInt(args.positional()[0], &id) || id <= 0) {
    ARPOS_INPUT_ERROR("plan approve: '" << args.positional()[0] << "' is not a plan id");
  }
  const std::string store_path = args.GetOr("store", DefaultStorePath());
  auto database = SqliteDatabase::Open(store_path);
  RecoverInterruptedSessions(database.get());
  const PlanRecord plan = ApprovePlan(database.get(), op, PlanId(id), args.GetOr("note", ""));
  std::cout << "plan " << plan.id.value() << " \"" << plan.name << "\" " << DescribeApproval(plan) << "\n";
  if (const auto map_id = database->LatestRoomMap(plan.id))
    PrintRoomFrameAdvice(database.get(), *map_id);
  return 0;
}

int RunPlanList(const std::vector<std::string>& argv) {
  const char* usage =
      "usage: arpos plan list [--patient ID] [--store DB]\n"
      "Lists the plans (newest first) with their room maps, sessions and approval.\n";
  const Args args(argv, {"store", "patient"}, {"help"});
  if (const auto exit_status = UsageExit(args, usage, 0)) return *exit_status;
  auto database = SqliteDatabase::Open(args.GetOr("store", DefaultStorePath()));
  std::optional<PatientId> patient;
  if (args.Has("patient")) {
    const auto p = database->FindPatient(args.Require("patient"));
    if (!p) ARPOS_INPUT_ERROR("--patient " << args.Require("patient") << ": no such patient in the store");
    patient = p->id;
  }
  for (const PlanSummary& p : database->ListPlans(patient)) {
    std::cout << StringPrintf("plan %lld  patient %s  \"%s\"  %lld room map(s), %lld session(s), %s\n",
                              static_cast<long long>(p.id.value()), p.patient_external_id.c_str(), p.name.c_str(),
                              static_cast<long long>(p.num_room_maps), static_cast<long long>(p.num_sessions),
                              DescribeApproval(p).c_str());
  }
  return 0;
}

}  // namespace

int RunPlanCommand(const std::vector<std::string>& argv) {
  if (!argv.empty() && argv.front() == "approve") return RunPlanApprove({argv.begin() + 1, argv.end()});
  if (!argv.empty() && argv.front() == "list") return RunPlanList({argv.begin() + 1, argv.end()});
  const char* usage =
      "usage: arpos plan CASE_DIR [--store DB] [--plan ID | --new-plan] [options]\n"
      "       arpos plan approve PLAN_ID [--note TEXT]    (a physicist)\n"
      "       arpos plan list [--patient ID]\n"
      "Builds the room map from CASE_DIR/room/ (DATASET.md): room markers (edge-fit\n"
      "corners, IPPE + depth, pose graph, bundle adjustment with the origin marker\n"
      "fixing the room frame) and keypoint landmarks with depth, adjusted jointly;\n"
      "stores it as the room map of a plan. Without --plan, the case's patient's (the\n"
      "case folder name) one plan that is not yet approved is used; a patient and plan\n"
      "are created from the case if it has none; several are refused (choose one).\n"
      "An approved plan is never changed. Planning is for a technician (--role technician)\n"
      "or a research run (no role).\n"
      "  --store DB          session store (default: $ARPOS_STORE, else ./arpos_store.db)\n"
      "  --plan ID           store the map under this plan (not approved)\n"
      "  --new-plan          a new plan for the patient, from the case's model and target pose\n"
      "  --patient ID        patient external id (default: the case folder name)\n"
      "  --frame-step N      use every N-th room frame (default 1)\n"
      "  --max-frames N      use at most N frames (default all)\n"
      "  --threads N         worker threads (default 2)\n"
      "  --max-landmarks N   keypoint landmarks kept (default 4000)\n"
      "  --no-keypoints      markers only\n"
      "  --keep-couch        keep landmarks on the couch top (by default they are left\n"
      "                      out: the couch moves during positioning)\n"
      "  --poses FILE        also write the room frames' camera poses (TUM)\n";
  const Args args(argv, {"store", "plan", "patient", "frame-step", "max-frames", "threads", "max-landmarks", "poses"},
                  {"no-keypoints", "keep-couch", "new-plan", "help"});
  if (const auto exit_status = UsageExit(args, usage, 1)) return *exit_status;
  PlanRoomMapOptions options;
  options.case_dir = args.positional()[0];
  if (args.Has("plan")) {
    const long long id = args.GetInt("plan", 0);
    if (id <= 0) ARPOS_INPUT_ERROR("--plan must be a positive id");
    options.plan_id = PlanId(id);
  }
  options.patient_external_id = args.GetOr("patient", "");
  options.new_plan = args.Has("new-plan");
  options.op = ResolveOperator(GivenOperatorFlags().user, GivenOperatorFlags().role);
  options.stage.frame_step = static_cast<int>(args.GetInt("frame-step", 1));
  options.stage.max_frames = static_cast<int>(args.GetInt("max-frames", 0));
  options.stage.threads = static_cast<int>(args.GetInt("threads", 2));
  options.stage.max_landmarks = static_cast<int>(args.GetInt("max-landmarks", 4000));
  options.stage.use_keypoints = !args.Has("no-keypoints");
  options.stage.exclude_couch = !args.Has("keep-couch");
  const std::string problem = options.Check();
  if (!problem.empty()) ARPOS_INPUT_ERROR(problem);

  if (args.Has("poses")) RequireWritableFileLocation(args.Require("poses"), "--poses");

  const std::string store_path = args.GetOr("store", DefaultStorePath());
  auto database = SqliteDatabase::Open(store_path);
  RecoverInterruptedSessions(database.get());
  int last_percent = -1;
  const PlanRoomMapResult result = RunPlanRoomMap(
      options, database.get(),
      {[&](const std::string& step, double fraction) {
         const int percent = static_cast<int>(100 * fraction);
         if (percent / 10 != last_percent / 10) {
           std::cerr << StringPrintf("[%3d%%] ", percent) << step << std::endl;
           last_percent = percent;
         }
       },
       nullptr});
  if (args.Has("poses")) {
    std::vector<StampedPose> poses;
    const Sequence room = Sequence::Open(LoadCaseFolder(options.case_dir).room_dir);
    for (const auto& [index, pose] : result.build.report.room_from_camera) {
      poses.push_back({room.timestamp_s(index), pose});
    }
    WriteTrajectory(args.Require("poses"), poses, "arpos plan: room frames, room_from_camera");
  }
  std::cout << "store: " << store_path << "\n" << result.Summary();
  PrintRoomFrameAdvice(database.get(), result.room_map_id);
  return 0;
}

}  // namespace arpos
