#include "eval/trajectory_eval.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "util/string_util.h"

namespace arpos {

ErrorStats ComputeErrorStats(std::vector<double> values) {
  ErrorStats stats;
  if (values.empty()) return stats;
  std::sort(values.begin(), values.end());
  const size_t n = values.size();
  double sum = 0, sum_sq = 0;
  for (double v : values) {
    sum += v;
    sum_sq += v * v;
  }
  stats.mean = sum / n;
  stats.rmse = std::sqrt(sum_sq / n);
  stats.median = n % 2 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
  const double rank = 0.95 * (n - 1);
  const size_t lo = static_cast<size_t>(std::floor(rank));
  const size_t hi = std::min(n - 1, lo + 1);
  stats.p95 = values[lo] + (rank - lo) * (values[hi] - values[lo]);
  stats.max = values.back();
  return stats;
}

TrajectoryEvaluation EvaluateTrajectory(const std::vector<StampedPose>& ground_truth,
                                        const std::vector<StampedPose>& estimate,
                                        double max_difference_s) {
  std::vector<double> gt_t, est_t;
  for (const auto& p : ground_truth) gt_t.push_back(p.timestamp_s);
  for (const auto& p : estimate) est_t.push_back(p.timestamp_s);
  const auto pairs = AssociateTimestamps(gt_t, est_t, max_difference_s);

  TrajectoryEvaluation eval;
  eval.ground_truth_frames = static_cast<int>(ground_truth.size());
  eval.estimated_frames = static_cast<int>(pairs.size());
  eval.lost_frames = eval.ground_truth_frames - eval.estimated_frames;
  eval.unmatched_estimates = static_cast<int>(estimate.size() - pairs.size());
  eval.lost_percent =
      ground_truth.empty() ? 0.0 : 100.0 * eval.lost_frames / eval.ground_truth_frames;
  std::vector<double> t_mm, r_deg;
  for (const auto& [i, j] : pairs) {
    FrameError fe;
    fe.timestamp_s = ground_truth[i].timestamp_s;
    fe.error = ComputePoseError(ground_truth[i].room_from_x, estimate[j].room_from_x);
    t_mm.push_back(fe.error.translation_mm);
    r_deg.push_back(fe.error.rotation_deg);
    eval.frames.push_back(fe);
  }
  eval.translation_mm = ComputeErrorStats(t_mm);
  eval.rotation_deg = ComputeErrorStats(r_deg);
  return eval;
}

std::string TrajectoryEvaluation::ToText() const {
  std::ostringstream out;
  out << StringPrintf("frames with ground truth: %d, estimated: %d, lost: %d (%.1f %%)\n",
                      ground_truth_frames, estimated_frames, lost_frames, lost_percent);
  if (unmatched_estimates > 0) {
    out << StringPrintf("estimates without ground truth (ignored): %d\n", unmatched_estimates);
  }
  if (!has_errors()) {
    out << "translation [mm]: mean (MTE) n/a (no estimate matched a ground-truth frame)\n"
        << "rotation [deg]:   mean (MRE) n/a\n";
    return out.str();
  }
  out << StringPrintf("translation [mm]: mean (MTE) %.3f  median %.3f  p95 %.3f  max %.3f  rmse %.3f\n",
                      translation_mm.mean, translation_mm.median, translation_mm.p95,
                      translation_mm.max, translation_mm.rmse);
  out << StringPrintf("rotation [deg]:   mean (MRE) %.4f  median %.4f  p95 %.4f  max %.4f  rmse %.4f\n",
                      rotation_deg.mean, rotation_deg.median, rotation_deg.p95, rotation_deg.max,
                      rotation_deg.rmse);
  return out.str();
}

std::string TrajectoryEvaluation::ToJson(bool include_frames) const {
  auto stats = [this](const ErrorStats& s) {
    if (!has_errors()) return std::string("null");
    return StringPrintf("{\"mean\": %.6f, \"median\": %.6f, \"p95\": %.6f, \"max\": %.6f, \"rmse\": %.6f}",
                        s.mean, s.median, s.p95, s.max, s.rmse);
  };
  std::ostringstream out;
  out << "{\n"
      << "  \"ground_truth_frames\": " << ground_truth_frames << ",\n"
      << "  \"estimated_frames\": " << estimated_frames << ",\n"
      << "  \"lost_frames\": " << lost_frames << ",\n"
      << "  \"unmatched_estimates\": " << unmatched_estimates << ",\n"
      << StringPrintf("  \"lost_percent\": %.4f,\n", lost_percent)
      << "  \"translation_mm\": " << stats(translation_mm) << ",\n"
      << "  \"rotation_deg\": " << stats(rotation_deg);
  if (include_frames) {
    out << ",\n  \"frames\": [";
    for (size_t i = 0; i < frames.size(); ++i) {
      out << (i ? ",\n    " : "\n    ")
          << StringPrintf("{\"timestamp\": %.6f, \"translation_mm\": %.6f, \"rotation_deg\": %.6f}",
                          frames[i].timestamp_s, frames[i].error.translation_mm,
                          frames[i].error.rotation_deg);
    }
    out << "\n  ]";
  }
  out << "\n}\n";
  return out.str();
}

}  // namespace arpos
