#include <iostream>

#include "controllers/session_controller.h"
#include "exe/args.h"
#include "exe/cli_progress.h"
#include "exe/commands.h"
#include "store/sqlite_database.h"
#include "store/store_path.h"

namespace arpos {

int RunSessionCommand(const std::vector<std::string>& argv) {
  const char* usage =
      "usage: arpos session CASE_DIR [--store DB] [--plan ID] [--initial-alignment FILE]\n"
      "                      [--out DIR] [--threads N]\n"
      "The session stage: from the case's body_scan/, the body marker map (sticker poses),\n"
      "the body reconstruction and its mesh, and the alignment of the plan's reference\n"
      "model to it (automatic, or from --initial-alignment), all stored in a new session\n"
      "of the plan. Needs a plan with a room map (arpos plan CASE).\n"
      "  --store DB                session store (default: $ARPOS_STORE, else ./arpos_store.db)\n"
      "  --plan ID                 plan to use (default: the newest plan of the case's patient)\n"
      "  --initial-alignment FILE  4x4 row-major reference-model -> room pose to start from\n"
      "  --out DIR                 also write model_pose.txt (model -> room for every body_scan\n"
      "                            frame, TUM), camera_pose.txt and reconstruction_mesh.ply\n";
  const Args args(argv, {"store", "plan", "initial-alignment", "out", "threads"}, {"help"});
  if (const auto exit_status = UsageExit(args, usage, 1)) return *exit_status;
  SessionStageOptions options;
  options.case_dir = args.positional()[0];
  if (args.Has("plan")) options.plan_id = PlanId(args.GetInt("plan", 0));
  if (args.Has("initial-alignment")) options.initial_alignment = args.Require("initial-alignment");
  if (args.Has("out")) options.out_dir = args.Require("out");
  options.threads = static_cast<int>(args.GetInt("threads", 2));
  auto database = SqliteDatabase::Open(args.GetOr("store", DefaultStorePath()));
  SessionController controller(options, database.get(),
                               CliProgress());
  controller.Run();
  std::cout << controller.result().Summary();
  return 0;
}

}  // namespace arpos
