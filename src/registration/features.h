#pragma once
/// Local shape descriptors for global registration: FPFH (Rusu et al. 2009,
/// PCL's FPFHEstimationOMP) and nearest-neighbour matching in descriptor
/// space (FLANN kd-tree). PCL stays inside features.cc.
///
/// Units: metres for radii. Thread-safety: re-entrant.

#include <array>
#include <string>
#include <utility>
#include <vector>

#include "registration/point_cloud.h"

namespace arpos {

/// 33-bin Fast Point Feature Histogram.
using FpfhDescriptor = std::array<float, 33>;

struct FpfhOptions {
  double radius_m = 0.05;  ///< neighbourhood for the histograms (~5 voxels)
  int num_threads = 0;     ///< 0 = OpenMP's default
  std::string Validate() const;
};

/// One descriptor per point of `cloud`, which needs normals (throws
/// arpos::Error otherwise). `valid[i]` is false where PCL could not form a
/// histogram (too few neighbours); those descriptors are zero.
std::vector<FpfhDescriptor> ComputeFpfh(const PointCloud& cloud, const FpfhOptions& options,
                                        std::vector<bool>* valid = nullptr);

struct FeatureMatchOptions {
  /// Keep a pair only if each descriptor is the other's nearest neighbour.
  bool mutual = true;
  /// Lowe's ratio test (nearest / second nearest distance) when < 1.
  double max_ratio = 1.0;
  std::string Validate() const;
};

/// Pairs (i, j): source descriptor i and its nearest target descriptor j
/// (L2), sorted by i. Invalid descriptors (see ComputeFpfh) take no part.
std::vector<std::pair<int, int>> MatchFeatures(const std::vector<FpfhDescriptor>& source,
                                               const std::vector<bool>& source_valid,
                                               const std::vector<FpfhDescriptor>& target,
                                               const std::vector<bool>& target_valid,
                                               const FeatureMatchOptions& options = {});

}  // namespace arpos
