// PCL translation unit #2 (FPFH, FLANN): keep PCL headers out of everything else.
#include "registration/features.h"

#include <omp.h>
#include <pcl/features/fpfh_omp.h>
#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>

#include <cmath>

#include "registration/pcl_convert.h"
#include "util/check.h"

namespace arpos {
namespace {

// FLANN needs a point representation for the 33-D descriptors.
class FpfhRepresentation : public pcl::PointRepresentation<pcl::FPFHSignature33> {
 public:
  FpfhRepresentation() { nr_dimensions_ = 33; }
  void copyToFloatArray(const pcl::FPFHSignature33& p, float* out) const override {
    for (int i = 0; i < 33; ++i) out[i] = p.histogram[i];
  }
};

pcl::PointCloud<pcl::FPFHSignature33>::Ptr ToPclFeatures(
    const std::vector<FpfhDescriptor>& features, const std::vector<bool>& valid,
    std::vector<int>* original_index) {
  pcl::PointCloud<pcl::FPFHSignature33>::Ptr out(new pcl::PointCloud<pcl::FPFHSignature33>);
  original_index->clear();
  for (size_t i = 0; i < features.size(); ++i) {
    if (!valid.empty() && !valid[i]) continue;
    pcl::FPFHSignature33 f;
    for (int k = 0; k < 33; ++k) f.histogram[k] = features[i][k];
    out->push_back(f);
    original_index->push_back(static_cast<int>(i));
  }
  return out;
}

}  // namespace

std::string FpfhOptions::Validate() const {
  if (!(radius_m > 0)) return "radius_m: must be positive";
  if (num_threads < 0) return "num_threads: must be >= 0";
  return "";
}

std::string FeatureMatchOptions::Validate() const {
  if (!(max_ratio > 0)) return "max_ratio: must be positive";
  return "";
}

std::vector<FpfhDescriptor> ComputeFpfh(const PointCloud& cloud, const FpfhOptions& options,
                                        std::vector<bool>* valid) {
  const std::string problem = options.Validate();
  ARPOS_CHECK(problem.empty(), "FpfhOptions: " << problem);
  ARPOS_CHECK(cloud.empty() || cloud.has_normals(), "ComputeFpfh: the cloud needs normals");
  std::vector<FpfhDescriptor> out(cloud.size());
  if (valid) valid->assign(cloud.size(), false);
  if (cloud.empty()) return out;
  const pcl::PointCloud<pcl::PointNormal>::Ptr input = ToPclPointNormals(cloud);
  pcl::FPFHEstimationOMP<pcl::PointNormal, pcl::PointNormal, pcl::FPFHSignature33> fpfh;
  fpfh.setNumberOfThreads(options.num_threads > 0 ? options.num_threads
                                                  : omp_get_max_threads());
  fpfh.setInputCloud(input);
  fpfh.setInputNormals(input);
  pcl::search::KdTree<pcl::PointNormal>::Ptr tree(new pcl::search::KdTree<pcl::PointNormal>);
  fpfh.setSearchMethod(tree);
  fpfh.setRadiusSearch(options.radius_m);
  pcl::PointCloud<pcl::FPFHSignature33> features;
  fpfh.compute(features);
  ARPOS_CHECK(features.size() == cloud.size(), "FPFH returned " << features.size()
                                                   << " descriptors for " << cloud.size()
                                                   << " points");
  for (size_t i = 0; i < cloud.size(); ++i) {
    bool ok = true;
    float sum = 0;
    for (int k = 0; k < 33; ++k) {
      const float v = features[i].histogram[k];
      if (!std::isfinite(v)) ok = false;
      out[i][k] = std::isfinite(v) ? v : 0.f;
      sum += out[i][k];
    }
    if (valid) (*valid)[i] = ok && sum > 0;
  }
  return out;
}

std::vector<std::pair<int, int>> MatchFeatures(const std::vector<FpfhDescriptor>& source,
                                               const std::vector<bool>& source_valid,
                                               const std::vector<FpfhDescriptor>& target,
                                               const std::vector<bool>& target_valid,
                                               const FeatureMatchOptions& options) {
  const std::string problem = options.Validate();
  ARPOS_CHECK(problem.empty(), "FeatureMatchOptions: " << problem);
  std::vector<int> source_index, target_index;
  const auto source_pcl = ToPclFeatures(source, source_valid, &source_index);
  const auto target_pcl = ToPclFeatures(target, target_valid, &target_index);
  std::vector<std::pair<int, int>> pairs;
  if (source_pcl->empty() || target_pcl->empty()) return pairs;
  const auto representation = std::make_shared<FpfhRepresentation>();
  pcl::KdTreeFLANN<pcl::FPFHSignature33> target_tree, source_tree;
  target_tree.setPointRepresentation(representation);
  target_tree.setInputCloud(target_pcl);
  if (options.mutual) {
    source_tree.setPointRepresentation(representation);
    source_tree.setInputCloud(source_pcl);
  }
  const int k = options.max_ratio < 1.0 ? 2 : 1;
  const int n = static_cast<int>(source_pcl->size());
  std::vector<int> match(n, -1);
#pragma omp parallel for schedule(dynamic, 64)
  for (int i = 0; i < n; ++i) {
    pcl::Indices idx(k);
    std::vector<float> d(k);
    if (target_tree.nearestKSearch((*source_pcl)[i], k, idx, d) < 1) continue;
    if (k == 2 && idx.size() == 2 && d[1] > 0 &&
        std::sqrt(d[0] / d[1]) > options.max_ratio) {
      continue;
    }
    if (options.mutual) {
      pcl::Indices back(1);
      std::vector<float> back_d(1);
      if (source_tree.nearestKSearch((*target_pcl)[idx[0]], 1, back, back_d) < 1) continue;
      if (back[0] != i) continue;
    }
    match[i] = idx[0];
  }
  for (int i = 0; i < n; ++i) {
    if (match[i] >= 0) pairs.emplace_back(source_index[i], target_index[match[i]]);
  }
  return pairs;
}

}  // namespace arpos
