#pragma once
/// Closed-form point-set alignment (Kabsch / Umeyama).

#include <Eigen/Core>
#include <optional>
#include <vector>

#include "geometry/rigid3.h"

namespace arpos {

struct Sim3Result {
  Rigid3d target_from_source;
  double scale = 1.0;
  double rmse_m = 0.0;  ///< after applying the estimate
};

/// Least-squares rigid transform (Kabsch; with `estimate_scale`, Umeyama's
/// similarity) mapping `source[i]` onto `target[i]`. Needs at least 3
/// non-collinear pairs; returns nullopt for fewer or a degenerate set.
/// Optional `weights` (non-negative, one per pair).
std::optional<Sim3Result> EstimateRigidTransform(const std::vector<Eigen::Vector3d>& source,
                                                 const std::vector<Eigen::Vector3d>& target,
                                                 bool estimate_scale = false,
                                                 const std::vector<double>* weights = nullptr);

}  // namespace arpos
