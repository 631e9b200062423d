#pragma once
/// Local rigid registration of point clouds: Generalized ICP (Segal et al.
/// 2009, in the small_gicp formulation) and point-to-plane ICP, both
/// minimised by Gauss-Newton (or Levenberg-Marquardt) on SE(3).
///
/// Contract
/// - Functions take (source, target) in that order and return
///   `target_from_source`, the rigid transform mapping source points into the
///   target frame: point_in_target = target_from_source * point_in_source.
/// - Units: metres and radians.
/// - Correspondences: for every source point, its nearest target point (kd-tree)
///   within `max_correspondence_distance_m` of the transformed source point;
///   the others do not take part (not inliers).
/// - The parameter vector of `information` is (omega, v): a perturbation applied
///   on the right, target_from_source * Exp(omega, v), i.e. in the source frame
///   (omega rotation vector in rad, v translation in m).
/// - Determinism: OpenMP sums are formed over fixed blocks of points and then
///   added in a fixed order, so the result is bit-identical for any number of
///   threads.
/// - Expected failures (too few correspondences, divergence) come back as data
///   (`converged = false`, `message`); invalid options or clouds missing a
///   required attribute throw arpos::Error. Nothing is printed.
/// - Thread-safety: re-entrant; the inputs are only read.

#include <Eigen/Core>
#include <string>

#include "geometry/rigid3.h"
#include "registration/kdtree.h"
#include "registration/point_cloud.h"

namespace arpos {

enum class RobustKernel {
  kNone,    ///< plain least squares
  kHuber,   ///< w = min(1, c / |r|)
  kCauchy,  ///< w = 1 / (1 + (|r| / c)^2)
  kTukey,   ///< w = (1 - (|r| / c)^2)^2 for |r| < c, else 0
};

struct RegistrationOptions {
  /// Source points farther than this from their nearest target point (after
  /// transformation) are not used.
  double max_correspondence_distance_m = 0.02;
  int max_iterations = 50;
  /// Converged when one update moves by less than both tolerances. They are
  /// deliberately tight: an update of 10 um / 0.0006 deg costs one more
  /// iteration, not a false "converged" at millimetres (PITFALLS.md). Also
  /// converged: the pose comes back within the tolerances of a pose 2-4
  /// updates earlier with updates below 10x the tolerances (sparse clouds make
  /// correspondences flip back and forth; `message` says so).
  double translation_tolerance_m = 1e-5;
  double rotation_tolerance_rad = 1e-5;
  /// Levenberg-Marquardt with step acceptance instead of plain Gauss-Newton.
  bool levenberg_marquardt = false;
  double lm_initial_lambda = 1e-4;  ///< Marquardt damping: H + lambda diag(H)
  int lm_max_inner_iterations = 10;
  /// Robust weighting of correspondences by their residual length |r| in
  /// metres (GICP: Euclidean distance; point-to-plane: distance to the plane).
  RobustKernel robust_kernel = RobustKernel::kNone;
  double robust_scale_m = 0.01;  ///< the kernel's c
  /// Fewer inliers than this ends the run unconverged.
  int min_correspondences = 12;
  /// OpenMP threads; 0 = OpenMP's default. Does not change the result.
  int num_threads = 0;
  /// Neighbourhood used when a cloud lacks covariances (GICP) or the target
  /// lacks normals (point-to-plane) and they are computed on a copy.
  int neighbors = 20;
  double covariance_epsilon = 1e-3;

  std::string Validate() const;  ///< empty if valid, else "field: problem"
};

/// Outcome of a local registration, as data.
struct RegistrationResult {
  Rigid3d target_from_source;
  bool converged = false;   ///< see RegistrationOptions' tolerances
  int iterations = 0;       ///< linearisations (correspondence searches) done
  /// Statistics at the last linearisation (the final pose differs from it by
  /// the last update, below the tolerances when converged):
  double fitness = 0;       ///< num_inliers / source size
  double rmse_m = 0;        ///< RMS residual of inliers: distance along the
                            ///< target normal when the target has normals,
                            ///< else Euclidean
  int num_inliers = 0;
  double cost = 0;          ///< 0.5 * sum of weighted squared (Mahalanobis) residuals
  /// Gauss-Newton Hessian J^T W J of the cost in the (omega, v) parameters
  /// above. Point-to-plane: residuals in metres, so sigma^2 * H^-1 (sigma the
  /// plane noise, ~rmse_m) approximates the pose covariance. GICP: residuals
  /// are whitened by normalised covariances (eigenvalues 1, 1, eps), so only
  /// the shape of H is meaningful (see AnalyseConditioning).
  Eigen::Matrix<double, 6, 6> information = Eigen::Matrix<double, 6, 6>::Zero();
  std::string message;      ///< why it stopped, for logs
};

/// Generalized ICP. Source and target need covariances (EstimateCovariances);
/// when either lacks them they are computed on a copy from `neighbors`
/// neighbours, with a kd-tree built for the purpose; the target tree is built
/// here too. Use the overload with a tree to reuse a prepared target.
RegistrationResult AlignGicp(const PointCloud& source, const PointCloud& target,
                             const Rigid3d& initial_target_from_source,
                             const RegistrationOptions& options = {});
/// Same with a prepared target: `target_tree` built over `target`, and both
/// clouds must have covariances (throws arpos::Error otherwise).
RegistrationResult AlignGicp(const PointCloud& source, const PointCloud& target,
                             const KdTree& target_tree,
                             const Rigid3d& initial_target_from_source,
                             const RegistrationOptions& options = {});

/// Point-to-plane ICP: minimises the squared distances of source points to
/// the tangent planes of their target correspondences. The target needs
/// normals (computed on a copy, oriented towards the target origin, when
/// missing); the source needs none.
RegistrationResult AlignPointToPlane(const PointCloud& source, const PointCloud& target,
                                     const Rigid3d& initial_target_from_source,
                                     const RegistrationOptions& options = {});
/// Same with a prepared target (`target_tree` over `target`, target normals
/// required).
RegistrationResult AlignPointToPlane(const PointCloud& source, const PointCloud& target,
                                     const KdTree& target_tree,
                                     const Rigid3d& initial_target_from_source,
                                     const RegistrationOptions& options = {});

/// How well a registration pins down each degree of freedom.
struct Conditioning {
  /// Eigenvalues (ascending) of S H S / num_inliers with
  /// S = diag(1/L, 1/L, 1/L, 1, 1, 1): rotations expressed as the arc they
  /// sweep at the length scale L, so rotation and translation compare.
  Eigen::Matrix<double, 6, 1> eigenvalues = Eigen::Matrix<double, 6, 1>::Zero();
  /// Unit eigenvectors (columns, same order) in the scaled parameters
  /// (L * omega, v).
  Eigen::Matrix<double, 6, 6> eigenvectors = Eigen::Matrix<double, 6, 6>::Identity();
  /// smallest / largest eigenvalue: ~0 for a surface that can slide or spin on
  /// itself (plane, sphere, cylinder), O(0.01..1) for a well-shaped surface.
  double min_max_ratio = 0;
  /// The weakest direction split for reading: rotation part (unit axis, the
  /// share of the eigenvector's squared length on rotation) and translation.
  Eigen::Vector3d weakest_rotation_axis = Eigen::Vector3d::Zero();
  Eigen::Vector3d weakest_translation = Eigen::Vector3d::Zero();
  double weakest_rotation_share = 0;
};

/// Conditioning of `information` (as RegistrationResult defines it). The
/// rotations are first re-centred on `centre_in_source` (where the cloud is;
/// rotating about a far-away origin would mix in translation), then scaled by
/// `length_scale_m`, the cloud's characteristic size (e.g. RmsRadius).
/// num_inliers <= 0 is treated as 1.
Conditioning AnalyseConditioning(const Eigen::Matrix<double, 6, 6>& information,
                                 int num_inliers, const Eigen::Vector3d& centre_in_source,
                                 double length_scale_m);
/// Same with the centroid and RmsRadius of `source` (the cloud that was aligned).
Conditioning AnalyseConditioning(const RegistrationResult& result, const PointCloud& source);

/// RMS distance of the points from their centroid; 0 for fewer than 2 points.
double RmsRadius(const PointCloud& cloud);

}  // namespace arpos
