#include "exe/cmd_plan.h"

#include <iostream>

#include "exe/args.h"
#include "room_map/plan_stage.h"
#include "sensor/sequence.h"
#include "sensor/tum_io.h"
#include "store/sqlite_database.h"
#include "store/store_path.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos {

int RunPlanCommand(const std::vector<std::string>& argv) {
  const char* usage =
      "usage: arpos plan CASE_DIR [--store DB] [--plan ID] [options]\n"
      "Builds the room map from CASE_DIR/room/ (DATASET.md): room markers (edge-fit\n"
      "corners, IPPE + depth, pose graph, bundle adjustment with the origin marker\n"
      "fixing the room frame) and keypoint landmarks with depth, adjusted jointly;\n"
      "stores it as the room map of a plan. Without --plan, the newest plan of the\n"
      "case's patient (the case folder name) is used, and a patient and plan are\n"
      "created from the case if the store has none.\n"
      "  --store DB          session store (default: $ARPOS_STORE, else ./arpos_store.db)\n"
      "  --plan ID           store the map under this plan\n"
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
                  {"no-keypoints", "keep-couch", "help"});
  if (const auto exit_status = UsageExit(args, usage, 1)) return *exit_status;
  PlanRoomMapOptions options;
  options.case_dir = args.positional()[0];
  if (args.Has("plan")) {
    const long long id = args.GetInt("plan", 0);
    if (id <= 0) ARPOS_INPUT_ERROR("--plan must be a positive id");
    options.plan_id = PlanId(id);
  }
  options.patient_external_id = args.GetOr("patient", "");
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
  return 0;
}

}  // namespace arpos
