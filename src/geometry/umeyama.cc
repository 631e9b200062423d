#include "geometry/umeyama.h"

#include <Eigen/SVD>
#include <cmath>

#include "util/check.h"

namespace arpos {

std::optional<Sim3Result> EstimateRigidTransform(const std::vector<Eigen::Vector3d>& source,
                                                 const std::vector<Eigen::Vector3d>& target,
                                                 bool estimate_scale,
                                                 const std::vector<double>* weights) {
  ARPOS_CHECK(source.size() == target.size(),
              "source and target sizes differ: " << source.size() << " vs " << target.size());
  if (weights) ARPOS_CHECK(weights->size() == source.size(), "one weight per pair is needed");
  const size_t n = source.size();
  if (n < 3) return std::nullopt;

  double total_weight = 0;
  Eigen::Vector3d mean_s = Eigen::Vector3d::Zero(), mean_t = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < n; ++i) {
    const double w = weights ? (*weights)[i] : 1.0;
    ARPOS_CHECK(w >= 0 && std::isfinite(w), "weights must be finite and non-negative");
    total_weight += w;
    mean_s += w * source[i];
    mean_t += w * target[i];
  }
  if (total_weight <= 0) return std::nullopt;
  mean_s /= total_weight;
  mean_t /= total_weight;

  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  double var_s = 0;
  for (size_t i = 0; i < n; ++i) {
    const double w = weights ? (*weights)[i] : 1.0;
    const Eigen::Vector3d ds = source[i] - mean_s, dt = target[i] - mean_t;
    cov += w * dt * ds.transpose();
    var_s += w * ds.squaredNorm();
  }
  cov /= total_weight;
  var_s /= total_weight;
  if (var_s < 1e-20) return std::nullopt;

  Eigen::JacobiSVD<Eigen::Matrix3d> svd(cov, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Vector3d sv = svd.singularValues();
  // Collinear points leave rotation about their line undetermined.
  if (sv(1) < 1e-12 * std::max(1.0, sv(0))) return std::nullopt;
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  if ((svd.matrixU() * svd.matrixV().transpose()).determinant() < 0) d(2, 2) = -1;
  const Eigen::Matrix3d r = svd.matrixU() * d * svd.matrixV().transpose();
  double scale = 1.0;
  if (estimate_scale) scale = (sv.asDiagonal() * d).trace() / var_s;

  Sim3Result result;
  result.scale = scale;
  result.target_from_source = Rigid3d(r, mean_t - scale * r * mean_s);
  double sq = 0;
  for (size_t i = 0; i < n; ++i) {
    const double w = weights ? (*weights)[i] : 1.0;
    const Eigen::Vector3d p = scale * (r * source[i]) + result.target_from_source.translation;
    sq += w * (p - target[i]).squaredNorm();
  }
  result.rmse_m = std::sqrt(sq / total_weight);
  return result;
}

}  // namespace arpos
