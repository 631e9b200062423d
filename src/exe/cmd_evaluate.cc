#include <iostream>

#include "eval/trajectory_eval.h"
#include "exe/args.h"
#include "exe/commands.h"
#include "sensor/tum_io.h"
#include "util/check.h"

namespace arpos {

int RunEvaluateCommand(const std::vector<std::string>& argv) {
  const char* usage =
      "usage: arpos evaluate --gt GT.txt --est EST.txt [--json] [--frames] [--max-dt S]\n"
      "Error of an estimated trajectory against ground truth (TUM files, DATASET.md):\n"
      "per frame E = T_gt^-1 T_est, translational error |t(E)| in mm and rotational\n"
      "error angle(R(E)) in degrees; mean (MTE/MRE), median, 95th percentile, max;\n"
      "ground-truth frames with no estimate within --max-dt (default 0.02 s) count as\n"
      "lost. No trajectory alignment is applied. Exit status 1 when no estimate\n"
      "matches a ground-truth frame (the figures are then n/a).\n"
      "  --json     machine-readable output\n"
      "  --frames   include per-frame errors (JSON) \n";
  const Args args(argv, {"gt", "est", "max-dt"}, {"json", "frames", "help"});
  if (args.Has("help")) {
    std::cout << usage;
    return 0;
  }
  if (!args.positional().empty()) ARPOS_INPUT_ERROR("unexpected argument '" << args.positional()[0] << "'");
  const auto gt = ReadTrajectory(args.Require("gt"));
  const auto est = ReadTrajectory(args.Require("est"));
  if (gt.empty()) ARPOS_INPUT_ERROR(args.Require("gt") << ": holds no poses");
  const double max_dt = args.GetDouble("max-dt", kEvaluationAssociationS);
  if (!(max_dt > 0 && max_dt < 10)) ARPOS_INPUT_ERROR("--max-dt must be in (0, 10) seconds");
  const TrajectoryEvaluation eval = EvaluateTrajectory(gt, est, max_dt);
  std::cout << (args.Has("json") ? eval.ToJson(args.Has("frames")) : eval.ToText());
  if (!eval.has_errors()) {
    // 100 % lost is not a perfect result: no figures, and a failure status.
    std::cerr << "arpos evaluate: no estimate in " << args.Require("est") << " ("
              << est.size() << " poses) lies within " << max_dt << " s of a ground-truth frame of "
              << args.Require("gt") << " (" << gt.size()
              << " poses): every frame is lost, MTE/MRE n/a\n";
    return 1;
  }
  return 0;
}

}  // namespace arpos
