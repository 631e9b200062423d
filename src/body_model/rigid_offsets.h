#pragma once
// Small rigid offsets measured frame by frame (the room map's pose of a scan
// camera against its pose on the reconstruction, a GICP correction against
// none), their robust mean and how well that mean is known.

#include <limits>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "geometry/rigid3.h"

namespace arpos {

/// A small rigid offset as (rotation vector, shift it gives a centre).
using Offset = Eigen::Matrix<double, 6, 1>;

/// `offset` as (rotation vector, offset * centre - centre).
Offset OffsetAt(const Rigid3d& offset, const Eigen::Vector3d& centre);

/// The mean of `offsets`, leaving out those whose shift exceeds 3 x the
/// median shift + `margin_m` (an offset pulled wrongly); small angles,
/// weighted means (`weights`: one positive weight per offset, or empty for
/// equal weights). The mean as a rotation about `centre` followed by the
/// shift; nullopt with fewer than `min_count` offsets kept. (Weighing each
/// run of consecutive frames the same placed 8 of 10 near-couch simulated
/// scans worse than equal frames: benchmark/accuracy.md.)
std::optional<Rigid3d> RobustMeanOffset(const std::vector<Offset>& offsets, const Eigen::Vector3d& centre,
                                        double margin_m, size_t min_count,
                                        const std::vector<double>& weights = {});

/// How well the robust mean of offsets taken at `times_s` (one per offset,
/// the frame's timestamp) places the centre.
struct OffsetMeanSigma {
  int frames = 0;  ///< offsets the mean keeps (the RobustMeanOffset rule)
  int runs = 0;    ///< runs of consecutive frames among them
  /// The runs as independent samples of the mean: (sum W_r)^2 / sum W_r^2
  /// over the runs' summed weights W_r (= runs when they weigh the same).
  double effective_runs = 0;
  /// mm, 1 sigma, largest axis: the (weighted) spread of the kept shifts
  /// over the square root of the effective runs. Consecutive frames see the
  /// room from nearly the same place and share their error, so each run
  /// counts once (over the square root of the frames the figure read
  /// 1.1-1.7x low). Infinity with fewer than 3 frames kept (two cannot show
  /// their spread).
  double sigma_mm = std::numeric_limits<double>::infinity();
};
/// A run breaks where the time to the next kept frame exceeds 1.5 x the
/// shortest such step. `times_s` must have one entry per offset; `weights`
/// as for RobustMeanOffset (the same ones: this is that mean's sigma).
OffsetMeanSigma MeanOffsetSigma(const std::vector<Offset>& offsets, const std::vector<double>& times_s,
                                double margin_m, const std::vector<double>& weights = {});

}  // namespace arpos
