#include <iostream>

#include "controllers/run_case_controller.h"
#include "exe/args.h"
#include "exe/cli_progress.h"
#include "exe/commands.h"
#include "store/lifecycle.h"
#include "store/sqlite_database.h"
#include "store/store_path.h"

namespace arpos {

int RunRunCaseCommand(const std::vector<std::string>& argv) {
  const char* usage =
      "usage: arpos run-case CASE_DIR [--store DB] [--out DIR] [options]\n"
      "Runs every stage on a case folder (DATASET.md) and stores the results in the\n"
      "session store: validates the case, imports the reference model and target pose\n"
      "into a plan with the room map (planning), opens a session (body marker map,\n"
      "reconstruction, alignment), then tracks every tracking/<name> sequence (camera,\n"
      "patient and couch correction per frame). A stage that cannot be done is\n"
      "reported (exit status 1); what earlier stages stored stays. A research run (no\n"
      "--role, or --role research): the plan it makes is not approved and its session\n"
      "is recorded so; the session is completed at the end (aborted if tracking failed).\n"
      "  --store DB          session store (default: $ARPOS_STORE, else ./arpos_store.db)\n"
      "  --out DIR           write the session outputs (model_pose.txt, camera_pose.txt,\n"
      "                      reconstruction_mesh.ply) and, per tracking sequence,\n"
      "                      DIR/<name>/poses.txt, camera_poses.txt, corrections.csv,\n"
      "                      timing.csv and overlay/<timestamp>.png\n"
      "  --no-overlay        with --out: no overlay images\n"
      "  --tolerance-mm MM   tracking: translation tolerance (default 2)\n"
      "  --tolerance-deg DEG tracking: rotation tolerance (default 1)\n"
      "  --patient ID        patient id to file the plan under (default: the case folder name)\n"
      "  --quick             check a sample of the images instead of all\n"
      "  --keep-open         leave the session open (to track more, e.g. in arpos gui)\n";
  const Args args(argv, {"store", "patient", "out", "tolerance-mm", "tolerance-deg"},
                  {"quick", "no-overlay", "keep-open", "help"});
  if (const auto exit_status = UsageExit(args, usage, 1)) return *exit_status;
  RunCaseOptions options;
  options.case_dir = args.positional()[0];
  options.patient_external_id = args.GetOr("patient", "");
  options.read_all_images = !args.Has("quick");
  if (args.Has("out")) options.out_dir = std::filesystem::path(args.Require("out"));
  options.overlay = !args.Has("no-overlay");
  options.tolerances.translation_mm = args.GetDouble("tolerance-mm", 2.0);
  options.tolerances.rotation_deg = args.GetDouble("tolerance-deg", 1.0);
  options.keep_session_open = args.Has("keep-open");
  options.op = ResolveOperator(GivenOperatorFlags().user, GivenOperatorFlags().role);
  RequirePermission(options.op, Action::kRunCase);
  const std::string store_path = args.GetOr("store", DefaultStorePath());
  auto database = SqliteDatabase::Open(store_path);
  RecoverInterruptedSessions(database.get());
  RunCaseController controller(options, database.get(),
                               CliProgress());
  controller.Run();
  for (const auto& w : controller.result().warnings) std::cout << w << "\n";
  std::cout << "store: " << store_path << "\n" << controller.result().Summary();
  return controller.result().ok() ? 0 : 1;
}

}  // namespace arpos
