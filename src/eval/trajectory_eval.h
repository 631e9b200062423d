#pragma once
/// Trajectory error figures exactly as DATASET.md defines them.
///
/// Each estimated pose is associated with a ground-truth pose within
/// `max_difference_s` (TUM association), with no trajectory alignment: both
/// are already in the room frame. Per frame E = T_gt^-1 * T_est; translational
/// error |t(E)| in mm, rotational error angle(R(E)) in degrees. Ground-truth
/// frames with no associated estimate count as lost.

#include <string>
#include <vector>

#include "geometry/pose_error.h"
#include "sensor/tum_io.h"

namespace arpos {

struct ErrorStats {
  double mean = 0, median = 0, p95 = 0, max = 0, rmse = 0;
};

struct FrameError {
  double timestamp_s = 0;
  PoseError error;
};

struct TrajectoryEvaluation {
  int ground_truth_frames = 0;
  int estimated_frames = 0;   ///< estimates associated with a ground-truth frame
  int lost_frames = 0;        ///< ground-truth frames with no estimate
  int unmatched_estimates = 0;  ///< estimates with no ground truth near them
  double lost_percent = 0;
  ErrorStats translation_mm;  ///< MTE = translation_mm.mean
  ErrorStats rotation_deg;    ///< MRE = rotation_deg.mean
  std::vector<FrameError> frames;

  /// False when no estimate matched a ground-truth frame: then there are no
  /// error figures (the stats are not zero errors), ToText says "n/a" and
  /// ToJson gives null, and `arpos evaluate` exits non-zero.
  bool has_errors() const { return estimated_frames > 0; }
  std::string ToText() const;
  std::string ToJson(bool include_frames = false) const;
};

constexpr double kEvaluationAssociationS = 0.02;

TrajectoryEvaluation EvaluateTrajectory(const std::vector<StampedPose>& ground_truth,
                                        const std::vector<StampedPose>& estimate,
                                        double max_difference_s = kEvaluationAssociationS);

/// Mean, median (average of the two middle values for even counts), 95th
/// percentile (linear interpolation between order statistics), max, RMSE.
ErrorStats ComputeErrorStats(std::vector<double> values);

}  // namespace arpos
