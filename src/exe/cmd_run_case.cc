#include <iostream>

#include "controllers/run_case_controller.h"
#include "exe/args.h"
#include "exe/cli_progress.h"
#include "exe/commands.h"
#include "store/sqlite_database.h"
#include "store/store_path.h"

namespace arpos {

int RunRunCaseCommand(const std::vector<std::string>& argv) {
  const char* usage =
      "usage: arpos run-case CASE_DIR [--store DB] [--patient ID] [--quick]\n"
      "Runs every stage that exists on a case folder (DATASET.md) and stores the\n"
      "results in the session store: validates the case, imports the reference\n"
      "model and target pose into a plan, registers the recordings and opens a\n"
      "session (room map, body marker map, reconstruction, alignment). A stage that\n"
      "cannot be done is reported (exit status 1); what earlier stages stored stays.\n"
      "  --store DB     session store (default: $ARPOS_STORE, else ./arpos_store.db)\n"
      "  --patient ID   patient id to file the plan under (default: the case folder name)\n"
      "  --quick        check a sample of the images instead of all\n";
  const Args args(argv, {"store", "patient"}, {"quick", "help"});
  if (const auto exit_status = UsageExit(args, usage, 1)) return *exit_status;
  RunCaseOptions options;
  options.case_dir = args.positional()[0];
  options.patient_external_id = args.GetOr("patient", "");
  options.read_all_images = !args.Has("quick");
  const std::string store_path = args.GetOr("store", DefaultStorePath());
  auto database = SqliteDatabase::Open(store_path);
  RunCaseController controller(options, database.get(),
                               CliProgress());
  controller.Run();
  for (const auto& w : controller.result().warnings) std::cout << w << "\n";
  std::cout << "store: " << store_path << "\n" << controller.result().Summary();
  return controller.result().ok() ? 0 : 1;
}

}  // namespace arpos
