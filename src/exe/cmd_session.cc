#include <iostream>

#include "controllers/session_controller.h"
#include "exe/args.h"
#include "exe/cli_progress.h"
#include "exe/commands.h"
#include "store/lifecycle.h"
#include "store/sqlite_database.h"
#include "util/string_util.h"
#include "store/store_path.h"

namespace arpos {

namespace {

/// arpos session complete|abort ID [--reason TEXT]
int RunSessionEnd(const std::string& verb, const std::vector<std::string>& argv) {
  const char* usage =
      "usage: arpos session complete SESSION_ID [--reason TEXT] [--store DB]\n"
      "       arpos session abort SESSION_ID --reason TEXT [--store DB]\n"
      "Ends an open session (a therapist, or a research run): completed when the patient\n"
      "was positioned, aborted otherwise (say why). An ended session takes no more\n"
      "tracking runs.\n";
  const Args args(argv, {"store", "reason"}, {"help"});
  if (const auto exit_status = UsageExit(args, usage, 1)) return *exit_status;
  long long id = 0;
  if (!ParseInt(args.positional()[0], &id) || id <= 0) {
    ARPOS_INPUT_ERROR("session " << verb << ": '" << args.positional()[0] << "' is not a session id");
  }
  const bool abort = verb == "abort";
  if (abort && args.GetOr("reason", "").empty()) ARPOS_INPUT_ERROR("session abort needs --reason TEXT");
  const Operator op = ResolveOperator(GivenOperatorFlags().user, GivenOperatorFlags().role);
  auto database = SqliteDatabase::Open(args.GetOr("store", DefaultStorePath()));
  RecoverInterruptedSessions(database.get());
  const SessionRecord s = EndSession(database.get(), op, SessionId(id),
                                     abort ? SessionStatus::kAborted : SessionStatus::kCompleted,
                                     args.GetOr("reason", ""));
  std::cout << "session " << s.id.value() << " " << ToString(s.status) << " by " << s.ended_by << "\n";
  return 0;
}

}  // namespace

int RunSessionCommand(const std::vector<std::string>& argv) {
  if (!argv.empty() && (argv.front() == "complete" || argv.front() == "abort")) {
    return RunSessionEnd(argv.front(), {argv.begin() + 1, argv.end()});
  }
  const char* usage =
      "usage: arpos session CASE_DIR [--store DB] [--plan ID] [--unapproved] [--initial-alignment FILE]\n"
      "                      [--out DIR] [--threads N]\n"
      "       arpos session complete|abort SESSION_ID [--reason TEXT]\n"
      "The session stage: from the case's body_scan/, the body marker map (sticker poses),\n"
      "the body reconstruction and its mesh, and the alignment of the plan's reference\n"
      "model to it (automatic, or from --initial-alignment), all stored in a new session\n"
      "of the plan. Needs a plan with a room map (arpos plan CASE), approved by a\n"
      "physicist (arpos plan approve ID). Sessions are for a therapist (--role therapist)\n"
      "or a research run (no role: any plan, recorded as not approved).\n"
      "  --store DB                session store (default: $ARPOS_STORE, else ./arpos_store.db)\n"
      "  --plan ID                 plan to use (default: the case's patient's one approved plan\n"
      "                            with a room map; several are refused, a research run takes the newest)\n"
      "  --unapproved              run on a plan that is not approved (tests, research;\n"
      "                            recorded in the session and the audit log)\n"
      "  --initial-alignment FILE  4x4 row-major reference-model -> room pose to start from\n"
      "  --out DIR                 also write model_pose.txt (model -> room for every body_scan\n"
      "                            frame, TUM), camera_pose.txt and reconstruction_mesh.ply\n";
  const Args args(argv, {"store", "plan", "initial-alignment", "out", "threads"}, {"unapproved", "help"});
  if (const auto exit_status = UsageExit(args, usage, 1)) return *exit_status;
  SessionStageOptions options;
  options.case_dir = args.positional()[0];
  if (args.Has("plan")) options.plan_id = PlanId(args.GetInt("plan", 0));
  if (args.Has("initial-alignment")) options.initial_alignment = args.Require("initial-alignment");
  if (args.Has("out")) options.out_dir = args.Require("out");
  options.threads = static_cast<int>(args.GetInt("threads", 2));
  options.unapproved = args.Has("unapproved");
  options.op = ResolveOperator(GivenOperatorFlags().user, GivenOperatorFlags().role);
  RequirePermission(options.op, Action::kRunSession);
  auto database = SqliteDatabase::Open(args.GetOr("store", DefaultStorePath()));
  RecoverInterruptedSessions(database.get());
  SessionController controller(options, database.get(),
                               CliProgress());
  controller.Run();
  std::cout << controller.result().Summary();
  return 0;
}

}  // namespace arpos
