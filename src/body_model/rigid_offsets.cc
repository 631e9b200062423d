#include "body_model/rigid_offsets.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Eigenvalues>

#include "util/check.h"

namespace arpos {
namespace {

// Which offsets the mean keeps: shift <= 3 x the median shift + margin_m.
std::vector<bool> KeptOffsets(const std::vector<Offset>& offsets, double margin_m) {
  std::vector<bool> kept(offsets.size(), false);
  if (offsets.empty()) return kept;
  std::vector<double> sizes;
  for (const auto& v : offsets) sizes.push_back(v.tail<3>().norm());
  std::vector<double> sorted = sizes;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  const double limit = 3 * sorted[sorted.size() / 2] + margin_m;
  for (size_t k = 0; k < offsets.size(); ++k) kept[k] = sizes[k] <= limit;
  return kept;
}

// Runs of consecutive frames among the kept offsets: a run breaks where the
// time to the next kept frame exceeds 1.5 x the shortest such step. The run
// of each offset (-1 where not kept), runs numbered in time order.
std::vector<int> RunLabels(const std::vector<bool>& kept, const std::vector<double>& times_s) {
  std::vector<size_t> order;
  for (size_t k = 0; k < kept.size(); ++k) {
    if (kept[k]) order.push_back(k);
  }
  std::vector<int> label(kept.size(), -1);
  if (order.empty()) return label;
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return times_s[a] < times_s[b]; });
  double shortest = std::numeric_limits<double>::infinity();
  for (size_t i = 1; i < order.size(); ++i) shortest = std::min(shortest, times_s[order[i]] - times_s[order[i - 1]]);
  int run = 0;
  label[order[0]] = 0;
  for (size_t i = 1; i < order.size(); ++i) {
    if (times_s[order[i]] - times_s[order[i - 1]] > 1.5 * shortest) ++run;
    label[order[i]] = run;
  }
  return label;
}

// The weight of offset k: `weights[k]`, or 1 when no weights are given.
double WeightOf(const std::vector<double>& weights, size_t k) { return weights.empty() ? 1.0 : weights[k]; }

void CheckWeights(const std::vector<double>& weights, size_t n) {
  ARPOS_CHECK(weights.empty() || weights.size() == n, "one weight per offset");
  for (double w : weights) ARPOS_CHECK(std::isfinite(w) && w > 0, "offset weights must be positive");
}

}  // namespace

Offset OffsetAt(const Rigid3d& offset, const Eigen::Vector3d& centre) {
  Offset v;
  v << offset.RotationVector(), offset * centre - centre;
  return v;
}

std::optional<Rigid3d> RobustMeanOffset(const std::vector<Offset>& offsets, const Eigen::Vector3d& centre,
                                        double margin_m, size_t min_count, const std::vector<double>& weights) {
  CheckWeights(weights, offsets.size());
  if (offsets.size() < std::max<size_t>(min_count, 1)) return std::nullopt;
  const std::vector<bool> kept = KeptOffsets(offsets, margin_m);
  Offset mean = Offset::Zero();
  size_t used = 0;
  double weight_sum = 0;
  for (size_t k = 0; k < offsets.size(); ++k) {
    if (!kept[k]) continue;
    mean += WeightOf(weights, k) * offsets[k];
    weight_sum += WeightOf(weights, k);
    ++used;
  }
  if (used == 0 || used < min_count) return std::nullopt;
  mean /= weight_sum;
  const Rigid3d turn = Rigid3d::FromRotationVector(mean.head<3>(), Eigen::Vector3d::Zero());
  return Rigid3d(turn.rotation, centre + mean.tail<3>() - turn * centre);
}

OffsetMeanSigma MeanOffsetSigma(const std::vector<Offset>& offsets, const std::vector<double>& times_s,
                                double margin_m, const std::vector<double>& weights) {
  ARPOS_CHECK(times_s.size() == offsets.size(), "one time per offset");
  CheckWeights(weights, offsets.size());
  OffsetMeanSigma result;
  const std::vector<bool> kept = KeptOffsets(offsets, margin_m);
  const std::vector<int> run = RunLabels(kept, times_s);
  for (int r : run) result.runs = std::max(result.runs, r + 1);  // 0 when none is kept
  std::vector<size_t> order;
  for (size_t k = 0; k < offsets.size(); ++k) {
    if (kept[k]) order.push_back(k);
  }
  result.frames = static_cast<int>(order.size());
  if (order.size() < 3) return result;
  // The weighted mean's own spread: the frames' weighted covariance about it
  // (n / (n - 1) for the mean taken from them), largest axis.
  double weight_sum = 0;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (size_t k : order) {
    mean += WeightOf(weights, k) * offsets[k].tail<3>();
    weight_sum += WeightOf(weights, k);
  }
  mean /= weight_sum;
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (size_t k : order) {
    const Eigen::Vector3d d = offsets[k].tail<3>() - mean;
    cov += WeightOf(weights, k) * d * d.transpose();
  }
  const double n = static_cast<double>(order.size());
  cov *= n / ((n - 1) * weight_sum);
  const double spread = std::sqrt(std::max(0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(cov).eigenvalues().maxCoeff()));
  // Each run's frames share one error, so the mean averages runs, each
  // weighing what its frames weigh together: (sum W_r)^2 / sum W_r^2 of
  // them count (the runs themselves when they weigh the same).
  std::vector<double> run_weight(static_cast<size_t>(result.runs), 0.0);
  for (size_t k : order) run_weight[static_cast<size_t>(run[k])] += WeightOf(weights, k);
  double sum_sq = 0;
  for (double w : run_weight) sum_sq += w * w;
  result.effective_runs = weight_sum * weight_sum / sum_sq;
  result.sigma_mm = 1000 * spread / std::sqrt(result.effective_runs);
  return result;
}

}  // namespace arpos
