#pragma once
/// PCL's GeneralizedIterativeClosestPoint behind a plain interface: the
/// reference our own AlignGicp is measured against (benchmark/registration.md).
///
/// PITFALLS.md: with PCL 1.13's default inner tolerances GICP stops after a few
/// iterations at millimetres of error; `tuned` applies the settings that make
/// it converge (rotation epsilon, translation/rotation gradient tolerances
/// 1e-6, 50 optimizer iterations). PCL computes its own covariances (k
/// neighbours) and kd-trees inside every call; any normals or covariances of
/// the inputs are ignored. Points are converted to float (PCL's PointXYZ).
/// Single-threaded. Re-entrant (each call owns its PCL objects).

#include <string>

#include "geometry/rigid3.h"
#include "registration/point_cloud.h"
#include "registration/registration.h"

namespace arpos {

struct PclGicpOptions {
  double max_correspondence_distance_m = 0.02;
  int max_iterations = 50;              ///< outer (correspondence) iterations
  double transformation_epsilon = 5e-4; ///< PCL's default: translation change, m
  bool tuned = true;                    ///< apply the PITFALLS.md settings below
  double rotation_epsilon = 1e-6;       ///< used when tuned (PCL default 2e-3)
  double gradient_tolerance = 1e-6;     ///< translation and rotation, when tuned
  int max_optimizer_iterations = 50;    ///< BFGS iterations, when tuned (default 20)
  int covariance_neighbors = 20;
  std::string Validate() const;
};

/// Runs PCL GICP from `initial_target_from_source`. Fills target_from_source,
/// iterations (PCL's outer iterations) and converged (stopped before
/// max_iterations); fitness, rmse_m, num_inliers, cost and information are
/// left at zero (PCL does not report them; compute them separately if needed).
RegistrationResult AlignGicpPcl(const PointCloud& source, const PointCloud& target,
                                const Rigid3d& initial_target_from_source,
                                const PclGicpOptions& options = {});

}  // namespace arpos
