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
// time to the next kept frame exceeds 1.5 x the shortest such step.
int RunsOf(const std::vector<bool>& kept, const std::vector<double>& times_s) {
  std::vector<double> t;
  for (size_t k = 0; k < kept.size(); ++k) {
    if (kept[k]) t.push_back(times_s[k]);
  }
  if (t.empty()) return 0;
  std::sort(t.begin(), t.end());
  double shortest = std::numeric_limits<double>::infinity();
  for (size_t i = 1; i < t.size(); ++i) shortest = std::min(shortest, t[i] - t[i - 1]);
  int runs = 1;
  for (size_t i = 1; i < t.size(); ++i) runs += t[i] - t[i - 1] > 1.5 * shortest ? 1 : 0;
  return runs;
}

}  // namespace

Offset OffsetAt(const Rigid3d& offset, const Eigen::Vector3d& centre) {
  Offset v;
  v << offset.RotationVector(), offset * centre - centre;
  return v;
}

std::optional<Rigid3d> RobustMeanOffset(const std::vector<Offset>& offsets, const Eigen::Vector3d& centre,
                                        double margin_m, size_t min_count) {
  if (offsets.size() < std::max<size_t>(min_count, 1)) return std::nullopt;
  const std::vector<bool> kept = KeptOffsets(offsets, margin_m);
  Offset mean = Offset::Zero();
  size_t used = 0;
  for (size_t k = 0; k < offsets.size(); ++k) {
    if (!kept[k]) continue;
    mean += offsets[k];
    ++used;
  }
  if (used == 0 || used < min_count) return std::nullopt;
  mean /= static_cast<double>(used);
  const Rigid3d turn = Rigid3d::FromRotationVector(mean.head<3>(), Eigen::Vector3d::Zero());
  return Rigid3d(turn.rotation, centre + mean.tail<3>() - turn * centre);
}

OffsetMeanSigma MeanOffsetSigma(const std::vector<Offset>& offsets, const std::vector<double>& times_s,
                                double margin_m) {
  ARPOS_CHECK(times_s.size() == offsets.size(), "one time per offset");
  OffsetMeanSigma result;
  const std::vector<bool> kept = KeptOffsets(offsets, margin_m);
  result.runs = RunsOf(kept, times_s);
  std::vector<size_t> order;
  for (size_t k = 0; k < offsets.size(); ++k) {
    if (kept[k]) order.push_back(k);
  }
  result.frames = static_cast<int>(order.size());
  if (order.size() < 3) return result;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (size_t k : order) mean += offsets[k].tail<3>();
  mean /= static_cast<double>(order.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (size_t k : order) {
    const Eigen::Vector3d d = offsets[k].tail<3>() - mean;
    cov += d * d.transpose();
  }
  cov /= static_cast<double>(order.size() - 1);
  const double spread = std::sqrt(std::max(0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(cov).eigenvalues().maxCoeff()));
  result.sigma_mm = 1000 * spread / std::sqrt(static_cast<double>(result.runs));
  return result;
}

}  // namespace arpos
