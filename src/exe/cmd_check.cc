#include <iostream>

#include "exe/args.h"
#include "exe/commands.h"
#include "sensor/case_check.h"

namespace arpos {

int RunCheckCommand(const std::vector<std::string>& argv) {
  const char* usage =
      "usage: arpos check CASE_DIR [--quick]\n"
      "Validates a case folder (DATASET.md) and reports every problem found:\n"
      "case.yaml keys and ranges, reference model, target pose, every sequence's\n"
      "lists, images and ground truth. Exit status 1 if anything is wrong.\n"
      "  --quick   read a sample of the images instead of all of them\n";
  const Args args(argv, {}, {"quick", "help"});
  if (const auto exit_status = UsageExit(args, usage, 1)) return *exit_status;
  CaseCheckOptions options;
  options.read_all_images = !args.Has("quick");
  const CaseCheckReport report = CheckCase(args.positional()[0], options);
  for (const auto& problem : report.problems) std::cout << problem.ToString() << "\n";
  int errors = 0, warnings = 0;
  for (const auto& p : report.problems) {
    (p.severity == CaseProblem::Severity::kError ? errors : warnings)++;
  }
  std::cout << args.positional()[0] << ": " << report.sequences << " sequences, " << report.frames
            << " frames, " << report.images_read << " images read; " << errors << " errors, "
            << warnings << " warnings: " << (report.ok() ? "OK" : "FAILED") << "\n";
  return report.ok() ? 0 : 1;
}

}  // namespace arpos
