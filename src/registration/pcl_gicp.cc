// PCL translation unit #1 (GICP): keep PCL headers out of everything else.
#include "registration/pcl_gicp.h"

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/registration/gicp.h>

#include "registration/pcl_convert.h"
#include "util/check.h"

namespace arpos {
namespace {

class Gicp : public pcl::GeneralizedIterativeClosestPoint<pcl::PointXYZ, pcl::PointXYZ> {
 public:
  int iterations() const { return nr_iterations_; }
};

}  // namespace

std::string PclGicpOptions::Validate() const {
  if (!(max_correspondence_distance_m > 0)) {
    return "max_correspondence_distance_m: must be positive";
  }
  if (max_iterations < 1) return "max_iterations: must be >= 1";
  if (!(transformation_epsilon > 0)) return "transformation_epsilon: must be positive";
  if (!(rotation_epsilon > 0)) return "rotation_epsilon: must be positive";
  if (!(gradient_tolerance > 0)) return "gradient_tolerance: must be positive";
  if (max_optimizer_iterations < 1) return "max_optimizer_iterations: must be >= 1";
  if (covariance_neighbors < 3) return "covariance_neighbors: must be >= 3";
  return "";
}

RegistrationResult AlignGicpPcl(const PointCloud& source, const PointCloud& target,
                                const Rigid3d& initial_target_from_source,
                                const PclGicpOptions& options) {
  const std::string problem = options.Validate();
  ARPOS_CHECK(problem.empty(), "PclGicpOptions: " << problem);
  RegistrationResult result;
  result.target_from_source = initial_target_from_source;
  if (source.size() < 3 || target.size() < 3) {
    result.message = "too few points";
    return result;
  }
  Gicp gicp;
  gicp.setInputSource(ToPclPoints(source));
  gicp.setInputTarget(ToPclPoints(target));
  gicp.setMaxCorrespondenceDistance(options.max_correspondence_distance_m);
  gicp.setMaximumIterations(options.max_iterations);
  gicp.setTransformationEpsilon(options.transformation_epsilon);
  gicp.setCorrespondenceRandomness(options.covariance_neighbors);
  if (options.tuned) {
    gicp.setRotationEpsilon(options.rotation_epsilon);
    gicp.setTranslationGradientTolerance(options.gradient_tolerance);
    gicp.setRotationGradientTolerance(options.gradient_tolerance);
    gicp.setMaximumOptimizerIterations(options.max_optimizer_iterations);
  }
  pcl::PointCloud<pcl::PointXYZ> aligned;
  gicp.align(aligned, initial_target_from_source.ToMatrix().cast<float>());
  const Eigen::Matrix4d m = gicp.getFinalTransformation().cast<double>();
  // PCL composes in float: re-project the rotation before building a Rigid3d.
  Eigen::Quaterniond q(Eigen::Matrix3d(m.topLeftCorner<3, 3>()));
  result.target_from_source = Rigid3d(q.normalized(), m.topRightCorner<3, 1>());
  result.iterations = gicp.iterations();
  result.converged = gicp.hasConverged() && gicp.iterations() < options.max_iterations;
  result.message = result.converged ? "converged" : "reached max_iterations";
  return result;
}

}  // namespace arpos
