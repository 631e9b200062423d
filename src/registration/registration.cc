#include "registration/registration.h"

#include <omp.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <cmath>
#include <vector>

#include "geometry/so3.h"
#include "registration/preprocess.h"
#include "util/check.h"

namespace arpos {
namespace {

using Matrix6d = Eigen::Matrix<double, 6, 6>;
using Vector6d = Eigen::Matrix<double, 6, 1>;

// Points per reduction block. Fixed (not derived from the thread count), so the
// order of floating-point additions, hence the result, never depends on it.
constexpr size_t kBlock = 256;

struct Accumulator {
  Matrix6d h = Matrix6d::Zero();
  Vector6d b = Vector6d::Zero();
  double cost = 0;
  double sq_residual_sum = 0;
  int inliers = 0;

  void Add(const Accumulator& o) {
    h += o.h;
    b += o.b;
    cost += o.cost;
    sq_residual_sum += o.sq_residual_sum;
    inliers += o.inliers;
  }
};

double RobustWeight(RobustKernel kernel, double c, double r) {
  switch (kernel) {
    case RobustKernel::kNone:
      return 1.0;
    case RobustKernel::kHuber:
      return r <= c ? 1.0 : c / r;
    case RobustKernel::kCauchy: {
      const double q = r / c;
      return 1.0 / (1.0 + q * q);
    }
    case RobustKernel::kTukey: {
      if (r >= c) return 0.0;
      const double q = r / c;
      const double s = 1.0 - q * q;
      return s * s;
    }
  }
  return 1.0;
}

// GICP residual r = q - T s whitened by (C_q + R C_s R^T)^-1 (small_gicp).
struct GicpFactor {
  const PointCloud& source;
  const PointCloud& target;
  bool target_normals;

  // Adds point i matched to target j at pose (R, t); `p` = R s + t.
  void Linearize(size_t i, size_t j, const Eigen::Matrix3d& r_mat, const Eigen::Vector3d& p,
                 RobustKernel kernel, double scale, Accumulator* acc) const {
    const Eigen::Vector3d s = traits::point(source, i).head<3>();
    const Eigen::Vector3d q = traits::point(target, j).head<3>();
    const Eigen::Matrix3d rcr = traits::cov(target, j).topLeftCorner<3, 3>() +
                                r_mat * traits::cov(source, i).topLeftCorner<3, 3>() *
                                    r_mat.transpose();
    const Eigen::Matrix3d m = rcr.inverse();
    const Eigen::Vector3d r = q - p;
    const double w = RobustWeight(kernel, scale, r.norm());
    Eigen::Matrix<double, 3, 6> jac;
    jac.leftCols<3>() = r_mat * Skew(s);
    jac.rightCols<3>() = -r_mat;
    const Eigen::Matrix<double, 6, 3> jtm = jac.transpose() * m;
    acc->h.noalias() += w * (jtm * jac);
    acc->b.noalias() += w * (jtm * r);
    acc->cost += 0.5 * w * r.dot(m * r);
    const double plane = target_normals ? traits::normal(target, j).head<3>().dot(r) : r.norm();
    acc->sq_residual_sum += plane * plane;
    ++acc->inliers;
  }
  double Cost(size_t i, size_t j, const Eigen::Matrix3d& r_mat, const Eigen::Vector3d& p,
              RobustKernel kernel, double scale) const {
    const Eigen::Vector3d q = traits::point(target, j).head<3>();
    const Eigen::Matrix3d rcr = traits::cov(target, j).topLeftCorner<3, 3>() +
                                r_mat * traits::cov(source, i).topLeftCorner<3, 3>() *
                                    r_mat.transpose();
    const Eigen::Vector3d r = q - p;
    const double w = RobustWeight(kernel, scale, r.norm());
    return 0.5 * w * r.dot(rcr.inverse() * r);
  }
};

// Point-to-plane residual n_q . (q - T s).
struct PointToPlaneFactor {
  const PointCloud& source;
  const PointCloud& target;

  void Linearize(size_t i, size_t j, const Eigen::Matrix3d& r_mat, const Eigen::Vector3d& p,
                 RobustKernel kernel, double scale, Accumulator* acc) const {
    const Eigen::Vector3d s = traits::point(source, i).head<3>();
    const Eigen::Vector3d q = traits::point(target, j).head<3>();
    const Eigen::Vector3d n = traits::normal(target, j).head<3>();
    const double r = n.dot(q - p);
    const double w = RobustWeight(kernel, scale, std::abs(r));
    const Eigen::Vector3d n_src = r_mat.transpose() * n;  // normal in the source frame
    Vector6d jac;
    jac.head<3>() = n_src.cross(s);
    jac.tail<3>() = -n_src;
    acc->h.noalias() += w * (jac * jac.transpose());
    acc->b.noalias() += w * r * jac;
    acc->cost += 0.5 * w * r * r;
    acc->sq_residual_sum += r * r;
    ++acc->inliers;
  }
  double Cost(size_t i, size_t j, const Eigen::Matrix3d& r_mat, const Eigen::Vector3d& p,
              RobustKernel kernel, double scale) const {
    const Eigen::Vector3d q = traits::point(target, j).head<3>();
    const double r = traits::normal(target, j).head<3>().dot(q - p);
    return 0.5 * RobustWeight(kernel, scale, std::abs(r)) * r * r;
  }
};

int ThreadCount(int requested) { return requested > 0 ? requested : omp_get_max_threads(); }

// One correspondence search + linearisation over all source points.
template <class Factor>
Accumulator Linearize(const Factor& factor, const PointCloud& source, const KdTree& tree,
                      const Rigid3d& target_from_source, const RegistrationOptions& options,
                      std::vector<int64_t>* correspondences) {
  const size_t n = traits::size(source);
  const size_t blocks = (n + kBlock - 1) / kBlock;
  std::vector<Accumulator> partial(blocks);
  const Eigen::Matrix3d r_mat = target_from_source.RotationMatrix();
  const Eigen::Vector3d t = target_from_source.translation;
  const double max_sq = options.max_correspondence_distance_m *
                        options.max_correspondence_distance_m;
  correspondences->assign(n, -1);
#pragma omp parallel for schedule(dynamic, 1) num_threads(ThreadCount(options.num_threads))
  for (int64_t block = 0; block < static_cast<int64_t>(blocks); ++block) {
    Accumulator acc;
    const size_t end = std::min(n, (block + 1) * kBlock);
    for (size_t i = block * kBlock; i < end; ++i) {
      const Eigen::Vector3d p = r_mat * traits::point(source, i).head<3>() + t;
      size_t j;
      double sq;
      if (!tree.Nearest(Eigen::Vector4d(p.x(), p.y(), p.z(), 1.0), &j, &sq, max_sq)) continue;
      (*correspondences)[i] = static_cast<int64_t>(j);
      factor.Linearize(i, j, r_mat, p, options.robust_kernel, options.robust_scale_m, &acc);
    }
    partial[block] = acc;
  }
  Accumulator total;
  for (const auto& a : partial) total.Add(a);
  return total;
}

// Cost at a trial pose with fixed correspondences (Levenberg-Marquardt).
template <class Factor>
double EvaluateCost(const Factor& factor, const PointCloud& source,
                    const Rigid3d& target_from_source, const RegistrationOptions& options,
                    const std::vector<int64_t>& correspondences) {
  const size_t n = traits::size(source);
  const size_t blocks = (n + kBlock - 1) / kBlock;
  std::vector<double> partial(blocks, 0.0);
  const Eigen::Matrix3d r_mat = target_from_source.RotationMatrix();
  const Eigen::Vector3d t = target_from_source.translation;
#pragma omp parallel for schedule(dynamic, 1) num_threads(ThreadCount(options.num_threads))
  for (int64_t block = 0; block < static_cast<int64_t>(blocks); ++block) {
    double sum = 0;
    const size_t end = std::min(n, (block + 1) * kBlock);
    for (size_t i = block * kBlock; i < end; ++i) {
      if (correspondences[i] < 0) continue;
      const Eigen::Vector3d p = r_mat * traits::point(source, i).head<3>() + t;
      sum += factor.Cost(i, static_cast<size_t>(correspondences[i]), r_mat, p,
                         options.robust_kernel, options.robust_scale_m);
    }
    partial[block] = sum;
  }
  double total = 0;
  for (double c : partial) total += c;
  return total;
}

// Right-multiplied update: R' = R Exp(omega), t' = t + R v.
Rigid3d Retract(const Rigid3d& target_from_source, const Vector6d& delta) {
  const Eigen::Quaterniond dq = QuaternionFromRotationVector(delta.head<3>());
  return Rigid3d(target_from_source.rotation * dq,
                 target_from_source.translation + target_from_source.rotation * delta.tail<3>());
}

Vector6d SolveDamped(const Matrix6d& h, const Vector6d& b, double lambda) {
  Matrix6d damped = h;
  if (lambda > 0) {
    damped.diagonal() += lambda * h.diagonal();
  }
  // A whisper of absolute damping keeps a degenerate system (a plane, a
  // sphere) from taking an unbounded step along its null directions.
  const double floor = 1e-9 * std::max(1e-30, h.diagonal().cwiseAbs().maxCoeff());
  damped.diagonal().array() += floor;
  return -damped.ldlt().solve(b);
}

template <class Factor>
RegistrationResult Optimize(const Factor& factor, const PointCloud& source, const KdTree& tree,
                            const Rigid3d& initial, const RegistrationOptions& options) {
  RegistrationResult result;
  result.target_from_source = initial;
  if (traits::size(source) == 0 || tree.empty()) {
    result.message = "empty source or target cloud";
    return result;
  }
  std::vector<int64_t> correspondences;
  Rigid3d pose = initial;
  std::vector<Rigid3d> recent;  // poses before the last (up to) four updates
  double lambda = options.lm_initial_lambda;
  for (int iteration = 1; iteration <= options.max_iterations; ++iteration) {
    const Accumulator lin = Linearize(factor, source, tree, pose, options, &correspondences);
    result.iterations = iteration;
    result.num_inliers = lin.inliers;
    result.fitness = static_cast<double>(lin.inliers) / static_cast<double>(traits::size(source));
    result.rmse_m = lin.inliers > 0 ? std::sqrt(lin.sq_residual_sum / lin.inliers) : 0.0;
    result.cost = lin.cost;
    result.information = lin.h;
    result.target_from_source = pose;
    if (lin.inliers < options.min_correspondences) {
      result.message = "too few correspondences (" + std::to_string(lin.inliers) + ")";
      return result;
    }
    recent.push_back(pose);
    if (recent.size() > 4) recent.erase(recent.begin());
    Vector6d delta;
    if (!options.levenberg_marquardt) {
      delta = SolveDamped(lin.h, lin.b, 0.0);
      if (!delta.allFinite()) {
        result.message = "numerical failure in the Gauss-Newton step";
        return result;
      }
      pose = Retract(pose, delta);
    } else {
      bool accepted = false;
      for (int inner = 0; inner < options.lm_max_inner_iterations; ++inner) {
        delta = SolveDamped(lin.h, lin.b, lambda);
        if (!delta.allFinite()) break;
        const Rigid3d trial = Retract(pose, delta);
        const double cost = EvaluateCost(factor, source, trial, options, correspondences);
        if (cost <= lin.cost) {
          pose = trial;
          lambda = std::max(lambda / 10.0, 1e-12);
          accepted = true;
          break;
        }
        lambda *= 10.0;
      }
      if (!accepted) {
        // No damped step lowers the cost: this is the minimum for these
        // correspondences, which are the current pose's own.
        result.target_from_source = pose;
        result.converged = true;
        result.message = "converged (no descent step)";
        return result;
      }
    }
    if (delta.head<3>().norm() < options.rotation_tolerance_rad &&
        delta.tail<3>().norm() < options.translation_tolerance_m) {
      result.target_from_source = pose;
      result.converged = true;
      result.message = "converged after " + std::to_string(iteration) + " iterations";
      return result;
    }
    // On sparse clouds correspondences can flip back and forth, so the pose
    // cycles through a few states a few tolerances apart and the step test
    // never passes. Back within tolerance of a pose 2-4 steps ago, with small
    // steps: the optimum lies within the cycle; call it converged.
    if (delta.head<3>().norm() < 10 * options.rotation_tolerance_rad &&
        delta.tail<3>().norm() < 10 * options.translation_tolerance_m) {
      for (size_t k = 0; k + 1 < recent.size(); ++k) {  // recent.back() is pose_before
        const Rigid3d back = recent[k].Inverse() * pose;
        if (RotationAngleRad(back.rotation) < options.rotation_tolerance_rad &&
            back.translation.norm() < options.translation_tolerance_m) {
          result.target_from_source = pose;
          result.converged = true;
          result.message = "converged after " + std::to_string(iteration) +
                           " iterations (cycling between correspondence sets)";
          return result;
        }
      }
    }
  }
  result.target_from_source = pose;
  result.message = "reached max_iterations";
  return result;
}

void CheckOptions(const RegistrationOptions& options) {
  const std::string problem = options.Validate();
  ARPOS_CHECK(problem.empty(), "RegistrationOptions: " << problem);
}

NormalOptions LocalGeometryOptions(const RegistrationOptions& options) {
  NormalOptions n;
  n.k = options.neighbors;
  n.covariance_epsilon = options.covariance_epsilon;
  n.num_threads = options.num_threads;
  return n;
}

}  // namespace

std::string RegistrationOptions::Validate() const {
  if (!(max_correspondence_distance_m > 0)) {
    return "max_correspondence_distance_m: must be positive";
  }
  if (max_iterations < 1) return "max_iterations: must be >= 1";
  if (!(translation_tolerance_m > 0)) return "translation_tolerance_m: must be positive";
  if (!(rotation_tolerance_rad > 0)) return "rotation_tolerance_rad: must be positive";
  if (!(lm_initial_lambda > 0)) return "lm_initial_lambda: must be positive";
  if (lm_max_inner_iterations < 1) return "lm_max_inner_iterations: must be >= 1";
  if (!(robust_scale_m > 0)) return "robust_scale_m: must be positive";
  if (min_correspondences < 6) return "min_correspondences: must be >= 6";
  if (num_threads < 0) return "num_threads: must be >= 0";
  if (neighbors < 3) return "neighbors: must be >= 3";
  if (!(covariance_epsilon > 0 && covariance_epsilon <= 1)) {
    return "covariance_epsilon: must be in (0, 1]";
  }
  return "";
}

RegistrationResult AlignGicp(const PointCloud& source, const PointCloud& target,
                             const KdTree& target_tree,
                             const Rigid3d& initial_target_from_source,
                             const RegistrationOptions& options) {
  CheckOptions(options);
  ARPOS_CHECK(source.empty() || source.has_covs(), "AlignGicp: the source needs covariances");
  ARPOS_CHECK(target.empty() || target.has_covs(), "AlignGicp: the target needs covariances");
  ARPOS_CHECK(target_tree.size() == target.size(),
              "AlignGicp: the kd-tree must be built over the target");
  const GicpFactor factor{source, target, target.has_normals()};
  return Optimize(factor, source, target_tree, initial_target_from_source, options);
}

RegistrationResult AlignGicp(const PointCloud& source, const PointCloud& target,
                             const Rigid3d& initial_target_from_source,
                             const RegistrationOptions& options) {
  CheckOptions(options);
  const NormalOptions local = LocalGeometryOptions(options);
  PointCloud source_copy, target_copy;
  const PointCloud* src = &source;
  const PointCloud* tgt = &target;
  if (!source.has_covs() && !source.empty()) {
    source_copy = source;
    const KdTree source_tree(source_copy);
    EstimateCovariances(&source_copy, source_tree, local);
    src = &source_copy;
  }
  const KdTree tree(target);
  if (!target.has_covs() && !target.empty()) {
    target_copy = target;
    EstimateCovariances(&target_copy, tree, local);
    tgt = &target_copy;
  }
  return AlignGicp(*src, *tgt, tree, initial_target_from_source, options);
}

RegistrationResult AlignPointToPlane(const PointCloud& source, const PointCloud& target,
                                     const KdTree& target_tree,
                                     const Rigid3d& initial_target_from_source,
                                     const RegistrationOptions& options) {
  CheckOptions(options);
  ARPOS_CHECK(target.empty() || target.has_normals(),
              "AlignPointToPlane: the target needs normals");
  ARPOS_CHECK(target_tree.size() == target.size(),
              "AlignPointToPlane: the kd-tree must be built over the target");
  const PointToPlaneFactor factor{source, target};
  return Optimize(factor, source, target_tree, initial_target_from_source, options);
}

RegistrationResult AlignPointToPlane(const PointCloud& source, const PointCloud& target,
                                     const Rigid3d& initial_target_from_source,
                                     const RegistrationOptions& options) {
  CheckOptions(options);
  const KdTree tree(target);
  if (target.has_normals() || target.empty()) {
    return AlignPointToPlane(source, target, tree, initial_target_from_source, options);
  }
  PointCloud target_copy = target;
  EstimateNormals(&target_copy, tree, LocalGeometryOptions(options));
  return AlignPointToPlane(source, target_copy, tree, initial_target_from_source, options);
}

Conditioning AnalyseConditioning(const Eigen::Matrix<double, 6, 6>& information, int num_inliers,
                                 const Eigen::Vector3d& centre_in_source,
                                 double length_scale_m) {
  ARPOS_CHECK(length_scale_m > 0, "AnalyseConditioning: length scale must be positive");
  // delta = A delta' with delta' = (omega, v') rotating about the centre.
  Matrix6d a = Matrix6d::Identity();
  a.block<3, 3>(3, 0) = Skew(centre_in_source);
  Matrix6d s = Matrix6d::Identity();
  s.topLeftCorner<3, 3>() *= 1.0 / length_scale_m;
  Matrix6d h = s * a.transpose() * information * a * s / std::max(1, num_inliers);
  h = 0.5 * (h + h.transpose());
  Eigen::SelfAdjointEigenSolver<Matrix6d> eig(h);
  Conditioning c;
  c.eigenvalues = eig.eigenvalues();
  c.eigenvectors = eig.eigenvectors();
  const double largest = c.eigenvalues(5);
  c.min_max_ratio = largest > 0 ? std::max(0.0, c.eigenvalues(0)) / largest : 0.0;
  const Vector6d weakest = c.eigenvectors.col(0);
  c.weakest_rotation_share = weakest.head<3>().squaredNorm();
  if (weakest.head<3>().norm() > 1e-12) c.weakest_rotation_axis = weakest.head<3>().normalized();
  c.weakest_translation = weakest.tail<3>();
  return c;
}

Conditioning AnalyseConditioning(const RegistrationResult& result, const PointCloud& source) {
  const double radius = RmsRadius(source);
  return AnalyseConditioning(result.information, result.num_inliers, source.Centroid(),
                             radius > 0 ? radius : 1.0);
}

double RmsRadius(const PointCloud& cloud) {
  if (cloud.size() < 2) return 0.0;
  const Eigen::Vector3d c = cloud.Centroid();
  double sum = 0;
  for (size_t i = 0; i < cloud.size(); ++i) sum += (cloud.point3(i) - c).squaredNorm();
  return std::sqrt(sum / static_cast<double>(cloud.size()));
}

}  // namespace arpos
