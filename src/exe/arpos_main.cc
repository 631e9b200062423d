// The one ARPos executable: dispatches subcommands from a table.
#include <cstring>
#include <functional>
#include <iostream>
#include <string>
#include <vector>

#include "exe/args.h"
#include "exe/commands.h"
#include "util/check.h"
#include "util/logging.h"

#ifdef ARPOS_HAVE_STORE
#include "exe/cmd_store.h"
#include "store/database.h"
#endif
#ifdef ARPOS_HAVE_SIMULATE
#include "exe/cmd_simulate.h"
#endif
#ifdef ARPOS_HAVE_GUI
#include "exe/cmd_gui.h"
#endif
#ifdef ARPOS_HAVE_IMPORT_MODEL
#include "exe/cmd_import_model.h"
#endif
#ifdef ARPOS_HAVE_PLANNING
#include "exe/cmd_localize.h"
#include "exe/cmd_plan.h"
#endif
#ifdef ARPOS_HAVE_TRACKING
#include "exe/cmd_track.h"
#endif
#ifdef ARPOS_HAVE_REPORT
#include "exe/cmd_report.h"
#endif

namespace {

struct Command {
  const char* name;
  const char* summary;
  std::function<int(const std::vector<std::string>&)> run;
};

const std::vector<Command>& Commands() {
  static const std::vector<Command> commands = {
#ifdef ARPOS_HAVE_GUI
      {"gui", "open the wizard (planning, session, tracking, audit)", arpos::RunGuiCommand},
#endif
      {"run-case", "run every stage on a case folder and store the results", arpos::RunRunCaseCommand},
      {"session", "session stage: body marker map, reconstruction, model alignment",
       arpos::RunSessionCommand},
      {"check", "validate a case folder and report every problem", arpos::RunCheckCommand},
#ifdef ARPOS_HAVE_IMPORT_MODEL
      {"import-model", "import the reference body surface (mesh, CT series, RTSTRUCT)",
       arpos::RunImportModelCommand},
#endif
#ifdef ARPOS_HAVE_PLANNING
      {"plan", "build the room map from a case's room/ sequence and store it", arpos::RunPlanCommand},
      {"localize", "camera pose of every frame of a sequence against the stored room map",
       arpos::RunLocalizeCommand},
#endif
#ifdef ARPOS_HAVE_TRACKING
      {"track", "tracking mode: camera, patient and couch correction every frame", arpos::RunTrackCommand},
#endif
#ifdef ARPOS_HAVE_SIMULATE
      {"simulate", "write a synthetic case folder with exact ground truth", arpos::RunSimulateCommand},
#endif
      {"sources", "list the camera sources (plugins) and the devices attached", arpos::RunSourcesCommand},
      {"record", "write a camera source as a sequence folder (DATASET.md)", arpos::RunRecordCommand},
      {"evaluate", "trajectory or couch-correction error against ground truth (MTE/MRE, lost, in while out)",
       arpos::RunEvaluateCommand},
#ifdef ARPOS_HAVE_STORE
      {"store", "inspect the session store (store info)", arpos::RunStoreCommand},
      {"audit", "check the audit log's hash chain and coverage (audit verify)", arpos::RunAuditCommand},
#endif
#ifdef ARPOS_HAVE_REPORT
      {"report", "the signed session report (HTML or PDF): figures, plots, audit trail", arpos::RunReportCommand},
#endif
  };
  return commands;
}

void PrintHelp(std::ostream& out) {
  out << "ARPos: AR-guided patient positioning with a hand-held RGB-D camera.\n\n"
      << "usage: arpos COMMAND [ARGS...]    (arpos COMMAND --help for details)\n\n"
      << "commands:\n";
  for (const auto& c : Commands()) {
    out << "  " << c.name << std::string(14 - std::min<size_t>(13, std::strlen(c.name)), ' ')
        << c.summary << "\n";
  }
  out << "\nglobal options (before the command): --verbose, --quiet\n"
      << "who: --user NAME --role technician|therapist|physicist|research (anywhere; else\n"
      << "     $ARPOS_USER / $ARPOS_ROLE; no role: a research run, which may not approve plans)\n"
      << "The session store defaults to $ARPOS_STORE, else ./arpos_store.db; --store overrides it.\n";
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> args(argv + 1, argv + argc);
  arpos::LogLevel level = arpos::LogLevel::kInfo;
  while (!args.empty() && (args.front() == "--verbose" || args.front() == "--quiet")) {
    level = args.front() == "--verbose" ? arpos::LogLevel::kDebug : arpos::LogLevel::kWarning;
    args.erase(args.begin());
  }
  arpos::SetLogLevel(level);
  arpos::SetLogSink([](arpos::LogLevel lvl, const std::string& message) {
    if (lvl >= arpos::LogLevel::kWarning) {
      std::cerr << arpos::LogLevelName(lvl) << ": " << message << std::endl;
    } else {
      std::cerr << message << std::endl;
    }
  });
  if (args.empty() || args.front() == "--help" || args.front() == "-h" || args.front() == "help") {
    PrintHelp(std::cout);
    return args.empty() ? 2 : 0;
  }
  if (args.front() == "--version") {
    std::cout << "arpos " << ARPOS_VERSION << "\n";
    return 0;
  }
  const std::string name = args.front();
  args.erase(args.begin());
  try {
    arpos::TakeOperatorFlags(&args);
  } catch (const arpos::InputError& e) {
    std::cerr << "arpos " << name << ": error: " << e.what() << std::endl;
    return 2;
  }
  for (const auto& command : Commands()) {
    if (name != command.name) continue;
    try {
      return command.run(args);
    } catch (const arpos::InputError& e) {
      std::cerr << "arpos " << name << ": error: " << e.what() << std::endl;
      return 2;
#ifdef ARPOS_HAVE_STORE
    } catch (const arpos::StoreAccessError& e) {
      // The store file or its folder, not the program: the message says which
      // and what to do.
      std::cerr << "arpos " << name << ": store error: " << e.what() << std::endl;
      return 2;
#endif
    } catch (const std::exception& e) {
      std::cerr << "arpos " << name << ": internal error: " << e.what() << std::endl;
      return 3;
    }
  }
  std::cerr << "arpos: unknown command '" << name << "'\n\n";
  PrintHelp(std::cerr);
  return 2;
}
