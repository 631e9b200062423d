#include <iostream>

#include "eval/correction_eval.h"
#include "eval/trajectory_eval.h"
#include "exe/args.h"
#include "exe/commands.h"
#include "sensor/case_check.h"
#include "sensor/tum_io.h"
#include "util/check.h"

namespace arpos {

namespace {

// target_pose.txt: the case's planned pose, checked as a case check does.
Rigid3d ReadTargetPose(const std::string& path) {
  const Eigen::Matrix4d m = ReadMatrix4(path);
  const std::string problem = TargetPoseProblem(m);
  if (!problem.empty()) ARPOS_INPUT_ERROR(path << ": " << problem);
  return Rigid3d::FromMatrix(m, 1e-4);
}

int EvaluateCorrectionsMode(const Args& args, double max_dt) {
  if (args.Has("est")) ARPOS_INPUT_ERROR("--est and --corrections exclude each other");
  const std::string csv_path = args.Require("corrections");
  const std::string gt_path = args.Require("gt");
  const std::string target_path = args.Require("target");
  CorrectionEvaluationOptions options;
  options.max_difference_s = max_dt;
  options.tolerances.translation_mm = args.GetDouble("tolerance-mm", options.tolerances.translation_mm);
  options.tolerances.rotation_deg = args.GetDouble("tolerance-deg", options.tolerances.rotation_deg);
  const std::string tol_problem = options.tolerances.Validate();
  if (!tol_problem.empty()) ARPOS_INPUT_ERROR("--tolerance-mm/--tolerance-deg: " << tol_problem);
  const auto rows = ReadCorrectionsCsv(csv_path);
  const auto gt = ReadTrajectory(gt_path);
  if (gt.empty()) ARPOS_INPUT_ERROR(gt_path << ": holds no poses");
  const Rigid3d room_from_model_target = ReadTargetPose(target_path);
  const CorrectionEvaluation eval = EvaluateCorrections(rows, gt, room_from_model_target, options);
  std::cout << (args.Has("json") ? eval.ToJson(args.Has("frames")) : eval.ToText());
  if (!eval.has_errors()) {
    std::cerr << "arpos evaluate: no row of " << csv_path << " with a correction (" << rows.size()
              << " rows, " << eval.reported_lost << " matched rows lost) lies within " << max_dt
              << " s of a ground-truth frame of " << gt_path << " (" << gt.size()
              << " poses): correction errors n/a\n";
    return 1;
  }
  return 0;
}

}  // namespace

int RunEvaluateCommand(const std::vector<std::string>& argv) {
  const char* usage =
      "usage: arpos evaluate --gt GT.txt --est EST.txt [--json] [--frames] [--max-dt S]\n"
      "       arpos evaluate --corrections corrections.csv --gt GT.txt --target target_pose.txt\n"
      "                      [--tolerance-mm 2] [--tolerance-deg 1] [--json] [--frames] [--max-dt S]\n"
      "Error of an estimated trajectory against ground truth (TUM files, DATASET.md):\n"
      "per frame E = T_gt^-1 T_est, translational error |t(E)| in mm and rotational\n"
      "error angle(R(E)) in degrees; mean (MTE/MRE), median, 95th percentile, max;\n"
      "ground-truth frames with no estimate within --max-dt (default 0.02 s) count as\n"
      "lost. No trajectory alignment is applied. Exit status 1 when no estimate\n"
      "matches a ground-truth frame (the figures are then n/a).\n"
      "With --corrections: the couch corrections of `arpos track` (corrections.csv)\n"
      "against the true correction from GT (body_groundtruth.txt, model -> room) to\n"
      "the planned pose (target_pose.txt, 4x4 row-major model -> room), rows matched\n"
      "within --max-dt: error per couch axis (|lateral|, |longitudinal|, |vertical| mm,\n"
      "|pitch|, |roll|, |yaw| deg), of the shift vector (mm) and the turn (deg); frames\n"
      "reported in / out / lost, truly in / out (true correction within both\n"
      "tolerances), and the safety figure: frames reported in while truly out (each\n"
      "listed; must be 0) and reported out while truly in. Exit status 1 when no row\n"
      "with a correction matches a ground-truth frame.\n"
      "  --json     machine-readable output\n"
      "  --frames   include per-frame errors (JSON) \n";
  const Args args(argv, {"gt", "est", "max-dt", "corrections", "target", "tolerance-mm", "tolerance-deg"},
                  {"json", "frames", "help"});
  if (args.Has("help")) {
    std::cout << usage;
    return 0;
  }
  if (!args.positional().empty()) ARPOS_INPUT_ERROR("unexpected argument '" << args.positional()[0] << "'");
  const double max_dt = args.GetDouble("max-dt", kEvaluationAssociationS);
  if (!(max_dt > 0 && max_dt < 10)) ARPOS_INPUT_ERROR("--max-dt must be in (0, 10) seconds");
  if (args.Has("corrections")) return EvaluateCorrectionsMode(args, max_dt);
  for (const char* option : {"target", "tolerance-mm", "tolerance-deg"}) {
    if (args.Has(option)) ARPOS_INPUT_ERROR("--" << option << " belongs to --corrections");
  }
  const auto gt = ReadTrajectory(args.Require("gt"));
  const auto est = ReadTrajectory(args.Require("est"));
  if (gt.empty()) ARPOS_INPUT_ERROR(args.Require("gt") << ": holds no poses");
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
