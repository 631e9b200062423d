// Own kd-tree vs PCL's KdTreeFLANN on the same cloud (the choice behind
// registration/kdtree.h). Separate TU: PCL headers compile slowly.
#include <benchmark/benchmark.h>
#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include "registration/kdtree.h"
#include "registration/mesh_cloud.h"
#include "registration/preprocess.h"
#include "registration/synthetic.h"

namespace arpos::testing {
namespace {

// The MakeHuman body sampled at 2 mm, 7 mm voxels (~40k points), as the
// GICP target of the benchmark.
const PointCloud& Cloud() {
  static const PointCloud* cloud =
      new PointCloud(VoxelDownsample(SampleMeshSurface(BodyMesh(), 0.002, 3), 0.007));
  return *cloud;
}

pcl::PointCloud<pcl::PointXYZ>::Ptr PclCloud() {
  static pcl::PointCloud<pcl::PointXYZ>::Ptr cloud = [] {
    pcl::PointCloud<pcl::PointXYZ>::Ptr c(new pcl::PointCloud<pcl::PointXYZ>);
    for (const auto& p : Cloud().points) {
      c->push_back(pcl::PointXYZ(static_cast<float>(p.x()), static_cast<float>(p.y()),
                                 static_cast<float>(p.z())));
    }
    return c;
  }();
  return cloud;
}

void BM_KnnOwn(benchmark::State& state) {
  const int k = static_cast<int>(state.range(0));
  const KdTree tree(Cloud());
  std::vector<size_t> idx(k);
  std::vector<double> d(k);
  for (auto _ : state) {
    for (const auto& q : Cloud().points) benchmark::DoNotOptimize(tree.Knn(q, k, idx.data(), d.data()));
  }
  state.counters["queries_per_s"] = benchmark::Counter(
      static_cast<double>(Cloud().size()), benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_KnnOwn)->Arg(1)->Arg(20)->ArgNames({"k"})->Unit(benchmark::kMillisecond);

void BM_KnnPclFlann(benchmark::State& state) {
  const int k = static_cast<int>(state.range(0));
  pcl::KdTreeFLANN<pcl::PointXYZ> tree;
  tree.setInputCloud(PclCloud());
  pcl::Indices idx(k);
  std::vector<float> d(k);
  for (auto _ : state) {
    for (const auto& q : PclCloud()->points) benchmark::DoNotOptimize(tree.nearestKSearch(q, k, idx, d));
  }
  state.counters["queries_per_s"] = benchmark::Counter(
      static_cast<double>(Cloud().size()), benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_KnnPclFlann)->Arg(1)->Arg(20)->ArgNames({"k"})->Unit(benchmark::kMillisecond);

void BM_BuildOwn(benchmark::State& state) {
  for (auto _ : state) benchmark::DoNotOptimize(KdTree(Cloud()));
}
BENCHMARK(BM_BuildOwn)->Unit(benchmark::kMillisecond);

void BM_BuildPclFlann(benchmark::State& state) {
  for (auto _ : state) {
    pcl::KdTreeFLANN<pcl::PointXYZ> tree;
    tree.setInputCloud(PclCloud());
    benchmark::DoNotOptimize(tree);
  }
}
BENCHMARK(BM_BuildPclFlann)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace arpos::testing
