// Google Benchmark for the registration layer, and (with --report) the
// accuracy figures of benchmark/registration.md. Not part of the default
// ctest set. Run by hand (see benchmark/registration.md):
//   registration_bench [--case=DIR] [benchmark flags]   timing
//   registration_bench [--case=DIR] --report             accuracy tables, then timing
// Without --case the scenes come from the test renderer on the MakeHuman body.
#include <benchmark/benchmark.h>
#include <omp.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <map>
#include <algorithm>
#include <random>
#include <string>
#include <vector>

#include "geometry/so3.h"
#include "registration/kdtree.h"
#include "registration/mesh_cloud.h"
#include "registration/pcl_gicp.h"
#include "registration/preprocess.h"
#include "registration/registration.h"
#include "registration/scenario.h"
#include "registration/synthetic.h"

namespace arpos::testing {
namespace {

std::string g_case_dir;  // --case=DIR

double NowS() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

const CaseScenario& Scenario() {
  static const CaseScenario* scenario = [] {
    if (!g_case_dir.empty()) return new CaseScenario(LoadCaseScenario(g_case_dir, {40, 150}));
    return new CaseScenario(SyntheticScenario(2, 0.0015, 7));
  }();
  return *scenario;
}

// One GICP problem: a frame's body points (camera frame) against the
// reference model sampled (model frame), both voxel-downsampled alike.
struct GicpProblem {
  double voxel_m = 0;
  PointCloud source;  // camera frame
  PointCloud target;  // model frame
  Rigid3d truth;      // model_from_camera
  std::vector<Rigid3d> starts;
};

const GicpProblem& Problem(double voxel_m) {
  static std::map<double, GicpProblem>* cache = new std::map<double, GicpProblem>;
  auto it = cache->find(voxel_m);
  if (it != cache->end()) return it->second;
  const CaseScenario& s = Scenario();
  GicpProblem p;
  p.voxel_m = voxel_m;
  p.source = VoxelDownsample(s.frames.front().body_in_camera, voxel_m);
  p.target = VoxelDownsample(SampleMeshSurface(s.reference_model, 0.002, 3), voxel_m);
  p.truth = s.frames.front().model_from_camera;
  std::mt19937_64 rng(11);
  for (int i = 0; i < 10; ++i) {
    // Perturbation about the body (model frame): up to 2 cm and 2 degrees.
    p.starts.push_back(RandomPose(rng, 0.02, RadFromDeg(2.0)) * p.truth);
  }
  return cache->emplace(voxel_m, std::move(p)).first->second;
}

RegistrationOptions OwnOptions(int threads) {
  RegistrationOptions o;
  o.max_correspondence_distance_m = 0.03;
  o.num_threads = threads;
  return o;
}

PclGicpOptions PclOptions(bool tuned) {
  PclGicpOptions o;
  o.max_correspondence_distance_m = 0.03;
  o.tuned = tuned;
  return o;
}

// Full job, as PCL does it: kd-trees and covariances of both clouds, then
// the alignment.
void BM_GicpOwn(benchmark::State& state) {
  const GicpProblem& p = Problem(state.range(0) * 1e-3);
  const int threads = static_cast<int>(state.range(1));
  size_t k = 0;
  double err_sum = 0;
  int runs = 0;
  for (auto _ : state) {
    const RegistrationResult r =
        AlignGicp(p.source, p.target, p.starts[k++ % p.starts.size()], OwnOptions(threads));
    err_sum += ModelTranslationError(p.truth, r.target_from_source);
    ++runs;
  }
  state.counters["src_pts"] = p.source.size();
  state.counters["tgt_pts"] = p.target.size();
  state.counters["err_mm"] = 1e3 * err_sum / runs;
}
BENCHMARK(BM_GicpOwn)
    ->ArgsProduct({{10, 7}, {1, 2}})
    ->ArgNames({"voxel_mm", "threads"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_GicpPclTuned(benchmark::State& state) {
  const GicpProblem& p = Problem(state.range(0) * 1e-3);
  size_t k = 0;
  double err_sum = 0;
  int runs = 0;
  for (auto _ : state) {
    const RegistrationResult r =
        AlignGicpPcl(p.source, p.target, p.starts[k++ % p.starts.size()], PclOptions(true));
    err_sum += ModelTranslationError(p.truth, r.target_from_source);
    ++runs;
  }
  state.counters["src_pts"] = p.source.size();
  state.counters["err_mm"] = 1e3 * err_sum / runs;
}
BENCHMARK(BM_GicpPclTuned)
    ->Arg(10)
    ->Arg(7)
    ->ArgNames({"voxel_mm"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// Alignment only, target prepared once (kd-tree + covariances), as a session
// controller aligning many frames against one model would run it.
void BM_GicpOwnPreparedTarget(benchmark::State& state) {
  const GicpProblem& p = Problem(state.range(0) * 1e-3);
  const int threads = static_cast<int>(state.range(1));
  PointCloud target = p.target;
  const KdTree tree(target);
  NormalOptions no;
  no.num_threads = threads;
  EstimateNormalsAndCovariances(&target, tree, no);
  size_t k = 0;
  for (auto _ : state) {
    PointCloud source = p.source;
    const KdTree source_tree(source);
    EstimateCovariances(&source, source_tree, no);
    benchmark::DoNotOptimize(AlignGicp(source, target, tree, p.starts[k++ % p.starts.size()],
                                       OwnOptions(threads)));
  }
}
BENCHMARK(BM_GicpOwnPreparedTarget)
    ->ArgsProduct({{10, 7}, {1, 2}})
    ->ArgNames({"voxel_mm", "threads"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_KdTreeBuild(benchmark::State& state) {
  const PointCloud& cloud = Scenario().frames.front().body_in_camera;
  for (auto _ : state) benchmark::DoNotOptimize(KdTree(cloud));
  state.counters["points"] = cloud.size();
}
BENCHMARK(BM_KdTreeBuild)->Unit(benchmark::kMillisecond);

void BM_KdTreeKnn20(benchmark::State& state) {
  const GicpProblem& p = Problem(0.007);
  KdTreeOptions options;
  options.max_leaf_size = static_cast<int>(state.range(0));
  const KdTree tree(p.target, options);
  size_t idx[20];
  double d[20];
  for (auto _ : state) {
    for (const auto& q : p.target.points) benchmark::DoNotOptimize(tree.Knn(q, 20, idx, d));
  }
  state.counters["queries_per_s"] =
      benchmark::Counter(static_cast<double>(p.target.size()), benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_KdTreeKnn20)->Arg(6)->Arg(12)->Arg(20)->Arg(32)->ArgNames({"leaf"})->Unit(benchmark::kMillisecond);

void BM_VoxelDownsample(benchmark::State& state) {
  const PointCloud& cloud = Scenario().frames.front().body_in_camera;
  for (auto _ : state) benchmark::DoNotOptimize(VoxelDownsample(cloud, state.range(0) * 1e-3));
  state.counters["points"] = cloud.size();
}
BENCHMARK(BM_VoxelDownsample)->Arg(5)->Arg(10)->ArgNames({"voxel_mm"})->Unit(benchmark::kMillisecond);

void BM_NormalsAndCovariances(benchmark::State& state) {
  const GicpProblem& p = Problem(0.007);
  NormalOptions no;
  no.num_threads = static_cast<int>(state.range(0));
  for (auto _ : state) {
    PointCloud c = p.target;
    const KdTree tree(c);
    EstimateNormalsAndCovariances(&c, tree, no);
    benchmark::DoNotOptimize(c);
  }
  state.counters["points"] = p.target.size();
}
BENCHMARK(BM_NormalsAndCovariances)->Arg(1)->Arg(2)->ArgNames({"threads"})->Unit(benchmark::kMillisecond);

// --report ------------------------------------------------------------------

struct Stats {
  std::vector<double> t_mm, r_deg, ms;
  std::vector<int> iters;
  int converged = 0;
  void Print(const char* name, size_t points) const {
    auto med = [](std::vector<double> v) {
      std::sort(v.begin(), v.end());
      return v.empty() ? 0.0 : v[v.size() / 2];
    };
    auto mx = [](const std::vector<double>& v) {
      return v.empty() ? 0.0 : *std::max_element(v.begin(), v.end());
    };
    double it = 0;
    for (int i : iters) it += i;
    std::printf("| %s | %zu | %.3f | %.3f | %.4f | %.4f | %.1f | %d/%zu | %.1f |\n", name, points,
                med(t_mm), mx(t_mm), med(r_deg), mx(r_deg), it / std::max<size_t>(1, iters.size()),
                converged, iters.size(), med(ms));
  }
};

void ReportGicp() {
  std::printf("\n### GICP: frame body points (camera) vs reference model (model), %s\n\n",
              Scenario().description.c_str());
  std::printf("Starts: truth perturbed by up to 2 cm / 2 deg (10 draws). Error at the model "
              "origin (isocentre) against the exact pose. Times are wall clock, median.\n\n");
  std::printf("| method | source pts | t err median mm | t err max mm | R err median deg | "
              "R err max deg | iterations | converged | time ms |\n|---|---|---|---|---|---|---|---|---|\n");
  for (double voxel : {0.010, 0.007}) {
    const GicpProblem& p = Problem(voxel);
    struct Method {
      std::string name;
      std::function<RegistrationResult(const Rigid3d&)> run;
    };
    std::vector<Method> methods = {
        {"own GICP, 1 thread", [&](const Rigid3d& s) { return AlignGicp(p.source, p.target, s, OwnOptions(1)); }},
        {"own GICP, 2 threads", [&](const Rigid3d& s) { return AlignGicp(p.source, p.target, s, OwnOptions(2)); }},
        {"PCL GICP tuned", [&](const Rigid3d& s) { return AlignGicpPcl(p.source, p.target, s, PclOptions(true)); }},
        {"PCL GICP defaults", [&](const Rigid3d& s) { return AlignGicpPcl(p.source, p.target, s, PclOptions(false)); }},
    };
    for (const Method& m : methods) {
      Stats st;
      for (const Rigid3d& start : p.starts) {
        const double t0 = NowS();
        const RegistrationResult r = m.run(start);
        st.ms.push_back(1e3 * (NowS() - t0));
        st.t_mm.push_back(1e3 * ModelTranslationError(p.truth, r.target_from_source));
        st.r_deg.push_back(DegFromRad(ModelRotationErrorRad(p.truth, r.target_from_source)));
        st.iters.push_back(r.iterations);
        st.converged += r.converged;
      }
      const std::string name = m.name + ", voxel " + std::to_string(int(voxel * 1e3 + 0.5)) + " mm";
      st.Print(name.c_str(), p.source.size());
    }
  }
}

void RunReport() { ReportGicp(); }

}  // namespace
}  // namespace arpos::testing

int main(int argc, char** argv) {
  bool report = false;
  std::vector<char*> rest;
  for (int i = 0; i < argc; ++i) {
    if (std::strcmp(argv[i], "--report") == 0) {
      report = true;
    } else if (std::strncmp(argv[i], "--case=", 7) == 0) {
      arpos::testing::g_case_dir = argv[i] + 7;
    } else {
      rest.push_back(argv[i]);
    }
  }
  int rest_argc = static_cast<int>(rest.size());
  if (report) arpos::testing::RunReport();
  benchmark::Initialize(&rest_argc, rest.data());
  if (benchmark::ReportUnrecognizedArguments(rest_argc, rest.data())) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
