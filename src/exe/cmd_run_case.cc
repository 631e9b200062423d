#include <iostream>

#include "exe/args.h"
#include "exe/commands.h"
#include "sensor/case_check.h"

namespace arpos {

int RunRunCaseCommand(const std::vector<std::string>& argv) {
  const Args args(argv, {"store"}, {"help"});
  if (args.Has("help") || args.positional().size() != 1) {
    std::cout << "usage: arpos run-case CASE_DIR [--store DB]\n";
    return args.Has("help") ? 0 : 2;
  }
  const CaseCheckReport report = CheckCase(args.positional()[0]);
  for (const auto& p : report.problems) std::cout << p.ToString() << "\n";
  return report.ok() ? 0 : 1;
}

}  // namespace arpos
