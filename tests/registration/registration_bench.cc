// Google Benchmark for the registration layer, and (with --report) the
// accuracy figures of benchmark/registration.md. Not part of the default
// ctest set. Run by hand (see benchmark/registration.md):
//   registration_bench [--case=DIR] [benchmark flags]   timing
//   registration_bench [--case=DIR] --report[=gicp,local,global,recon]
//                                                        accuracy tables, then timing
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

#include "geometry/mesh_io.h"
#include "geometry/so3.h"
#include "util/file.h"
#include "registration/global_registration.h"
#include "registration/kdtree.h"
#include "registration/mesh_cloud.h"
#include "registration/pcl_gicp.h"
#include "registration/poisson.h"
#include "registration/preprocess.h"
#include "registration/reconstruction.h"
#include "registration/registration.h"
#include "registration/scenario.h"
#include "registration/synthetic.h"
#include "sensor/case_folder.h"
#include "sensor/sequence.h"

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

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}
double Max(const std::vector<double>& v) {
  return v.empty() ? 0 : *std::max_element(v.begin(), v.end());
}

// Point-to-plane and GICP, frame body points vs the reference model, over
// several frames of the scan and perturbed starts.
void ReportLocalAccuracy() {
  std::vector<int> frames = {20, 60, 100, 140, 180, 220, 260};
  CaseScenario s = g_case_dir.empty() ? SyntheticScenario(7, 0.0015, 9)
                                      : LoadCaseScenario(g_case_dir, frames);
  std::printf("\n### Point-to-plane vs GICP accuracy, %zu frames x 5 starts (%s)\n\n",
              s.frames.size(), s.description.c_str());
  std::printf("Source: the frame's body points (7 mm voxels, camera frame); target: the reference "
              "model sampled at 2 mm, 7 mm voxels, with normals and covariances. Starts: truth "
              "perturbed by up to 2 cm / 2 deg. Error at the isocentre.\n\n");
  std::printf("| method | runs | converged | t err median mm | t err p95 mm | t err max mm | "
              "R err median deg | R err max deg | time median ms (1 thread) |\n"
              "|---|---|---|---|---|---|---|---|---|\n");
  PointCloud target = VoxelDownsample(SampleMeshSurface(s.reference_model, 0.002, 3), 0.007);
  const KdTree tree(target);
  NormalOptions no;
  EstimateNormalsAndCovariances(&target, tree, no);
  for (int method = 0; method < 2; ++method) {
    std::vector<double> t_mm, r_deg, ms;
    int converged = 0;
    std::mt19937_64 rng(5);
    for (const FrameScenario& f : s.frames) {
      PointCloud source = VoxelDownsample(f.body_in_camera, 0.007);
      if (method == 1) {
        const KdTree st(source);
        EstimateCovariances(&source, st, no);
      }
      for (int k = 0; k < 5; ++k) {
        const Rigid3d start = RandomPose(rng, 0.02, RadFromDeg(2.0)) * f.model_from_camera;
        RegistrationOptions o = OwnOptions(1);
        const double t0 = NowS();
        const RegistrationResult r = method == 0 ? AlignPointToPlane(source, target, tree, start, o)
                                                 : AlignGicp(source, target, tree, start, o);
        ms.push_back(1e3 * (NowS() - t0));
        converged += r.converged;
        t_mm.push_back(1e3 * ModelTranslationError(f.model_from_camera, r.target_from_source));
        r_deg.push_back(DegFromRad(ModelRotationErrorRad(f.model_from_camera, r.target_from_source)));
      }
    }
    std::vector<double> sorted = t_mm;
    std::sort(sorted.begin(), sorted.end());
    std::printf("| %s | %zu | %d | %.3f | %.3f | %.3f | %.4f | %.4f | %.1f |\n",
                method == 0 ? "point-to-plane" : "GICP (prepared target)", t_mm.size(), converged,
                Median(t_mm), sorted[static_cast<size_t>(0.95 * (sorted.size() - 1))], Max(t_mm),
                Median(r_deg), Max(r_deg), Median(ms));
  }
}

// Global registration of the reference model to single frames' body points,
// no prior: 20 frames, 20 seeds.
void ReportGlobal() {
  std::vector<int> frames;
  for (int k = 0; k < 20; ++k) frames.push_back(5 + 14 * k);
  CaseScenario s = g_case_dir.empty() ? SyntheticScenario(20, 0.0015, 10)
                                      : LoadCaseScenario(g_case_dir, frames);
  std::printf("\n### Global registration, reference model -> frame body points, no prior (%s)\n\n",
              s.description.c_str());
  GlobalRegistrationOptions options;
  const PointCloud model_cloud = SampleMeshSurface(s.reference_model, 0.004, 1);
  const double t0 = NowS();
  const GlobalRegistrationModel model(model_cloud, options);
  const double prepare_s = NowS() - t0;
  int ok = 0, ok_right = 0, ambiguous = 0, failed = 0, confident_wrong = 0;
  std::vector<double> t_mm, r_deg, total_s, ransac_s, features_s, refine_s;
  std::string notes;
  for (size_t i = 0; i < s.frames.size(); ++i) {
    const FrameScenario& f = s.frames[i];
    options.seed = 100 + i;
    const GlobalRegistrationResult r = AlignGlobal(model, f.body_in_camera, options);
    const Rigid3d camera_from_model = f.model_from_camera.Inverse();
    const double te = 1e3 * TranslationError(camera_from_model, r.target_from_source);
    const double re = DegFromRad(RotationErrorRad(camera_from_model, r.target_from_source));
    total_s.push_back(r.total_s);
    features_s.push_back(r.features_s);
    ransac_s.push_back(r.ransac_s);
    refine_s.push_back(r.refine_s);
    const bool right = te < 5.0 && re < 1.0;
    switch (r.status) {
      case GlobalRegistrationStatus::kOk:
        ++ok;
        if (right) {
          ++ok_right;
          t_mm.push_back(te);
          r_deg.push_back(re);
        } else {
          ++confident_wrong;
        }
        break;
      case GlobalRegistrationStatus::kAmbiguous:
        ++ambiguous;
        notes += "- " + f.description + " (" + std::to_string(f.body_in_camera.size()) +
                 " body points): ambiguous, " + r.reason + (right ? " (best pose right)" : " (best pose wrong)") + "\n";
        break;
      case GlobalRegistrationStatus::kFailed:
        ++failed;
        notes += "- " + f.description + ": failed, " + r.reason + "\n";
        break;
    }
  }
  std::printf("Model prepared once (%zu coarse points, FPFH): %.2f s. Per frame: FPFH of the "
              "scene, RANSAC 50k samples, 4 hypotheses refined.\n\n",
              model.size(), prepare_s);
  std::printf("| frames | ok & right (<5 mm, <1 deg) | ok but wrong | ambiguous | failed | "
              "t err median mm (ok) | R err median deg (ok) | time median s | features | RANSAC | refine |\n"
              "|---|---|---|---|---|---|---|---|---|---|---|\n");
  std::printf("| %zu | %d | %d | %d | %d | %.3f | %.4f | %.2f | %.2f | %.2f | %.2f |\n", s.frames.size(),
              ok_right, confident_wrong, ambiguous, failed, Median(t_mm), Median(r_deg),
              Median(total_s), Median(features_s), Median(ransac_s), Median(refine_s));
  if (!notes.empty()) std::printf("\n%s", notes.c_str());
  (void)ok;
}

// The body scan: every frame offered, every 10th used, poses as given (exact
// or perturbed), then Poisson.
void ReportReconstruction() {
  if (g_case_dir.empty()) {
    std::printf("\n(reconstruction report needs --case=DIR)\n");
    return;
  }
  const CaseFolder folder = LoadCaseFolder(g_case_dir);
  const Sequence sequence = Sequence::Open(folder.body_scan_dir);
  const auto cameras = sequence.CameraGroundTruth();
  const auto bodies = sequence.BodyGroundTruth();
  const TriangleMesh reference = LoadTriangleMesh(folder.reference_model);
  const Rigid3d room_from_model = bodies->front().room_from_x;
  TriangleMesh true_surface = reference;
  true_surface.Transform(room_from_model);
  const MeshDistance distance(true_surface);
  // Crops the caller would set: a box around the model at its pose, and
  // above the couch top (simulation.yaml couch_top_height_m).
  Eigen::Vector3f lo, hi;
  reference.Bounds(&lo, &hi);
  const Eigen::Vector3d centre = 0.5 * (lo + hi).cast<double>();
  OrientedBox box;
  box.frame_from_box = room_from_model * Rigid3d(Eigen::Quaterniond::Identity(), centre);
  box.half_extents_m = 0.5 * (hi - lo).cast<double>() + Eigen::Vector3d::Constant(0.03);
  double couch_top_m = 0.8;
  {
    const std::string yaml = ReadTextFile(std::filesystem::path(g_case_dir) / "simulation.yaml");
    const size_t at = yaml.find("couch_top_height_m:");
    if (at != std::string::npos) couch_top_m = std::atof(yaml.c_str() + at + 19);
  }
  std::printf("\n### Reconstruction of body_scan (%zu frames, 640x480), every 10th frame used\n\n",
              sequence.size());
  std::printf("Crops: box around the model at its pose (+3 cm), above the couch top (z > %.3f m "
              "+ 1 cm). Depth back-projected at stride 1. Error: distance of the fused 1 cm "
              "points to the true surface (reference model at its true pose; it carries 0.3 mm "
              "noise of its own). Given poses: ground truth, or ground truth times a random error "
              "of up to 5 mm / 0.5 deg per frame (the first exact).\n\n",
              couch_top_m);
  std::printf("| given poses | refine | N | used frames | refined | points | mean mm | p95 mm | "
              "max mm | AddFrame median ms (used) | max ms | load+back-project ms/frame | "
              "model->reconstruction (global + point-to-plane): status, t err mm, R err deg |\n"
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  GlobalRegistrationOptions global_options;
  const GlobalRegistrationModel global_model(SampleMeshSurface(reference, 0.004, 1),
                                             global_options);
  PointCloud last_cloud;
  struct Config {
    bool perturb;
    bool refine;
    double n;
  };
  for (const Config& c : {Config{false, false, 5e4}, Config{false, true, 5e4}, Config{true, false, 5e4},
                          Config{true, true, 5e4}, Config{false, true, 1e9},
                          Config{true, true, 1e9}}) {
    ReconstructionOptions options;
    options.refine_poses = c.refine;
    options.target_points = c.n;
    options.crop_box = box;
    options.keep_above_plane = Plane{Eigen::Vector3d::UnitZ(), -couch_top_m};
    options.min_height_above_plane_m = 0.01;
    ReconstructionBuilder builder(options);
    std::mt19937_64 rng(77);
    std::vector<double> add_ms, load_ms;
    int refined = 0;
    for (size_t i = 0; i < sequence.size(); ++i) {
      const Rigid3d noise = RandomPose(rng, 0.005, RadFromDeg(0.5));
      if (i % options.frame_stride != 0) {
        builder.AddFrame(PointCloud(), Rigid3d());  // offered, skipped
        continue;
      }
      const double t0 = NowS();
      const RgbdFrame frame = sequence.LoadFrame(i, folder.config.camera);
      const PointCloud cloud = DepthToCloud(frame, folder.config.camera);
      load_ms.push_back(1e3 * (NowS() - t0));
      const Rigid3d given = (c.perturb && i > 0) ? (*cameras)[i].room_from_x * noise
                                                 : (*cameras)[i].room_from_x;
      const ReconstructionFrameReport r = builder.AddFrame(cloud, given);
      add_ms.push_back(1e3 * r.seconds);
      refined += r.refined;
    }
    const PointCloud cloud = LargestCluster(builder.Cloud(), 0.03);
    const DistanceStats st = SummariseDistances(distance.Distances(cloud));
    // The session's next step: the reference model onto the reconstruction.
    const GlobalRegistrationResult g = AlignGlobal(global_model, cloud, global_options);
    std::printf("| %s | %s | %.0e | %d | %d | %zu | %.3f | %.3f | %.2f | %.1f | %.1f | %.1f | "
                "%s, %.3f, %.4f |\n",
                c.perturb ? "perturbed" : "exact", c.refine ? "GICP" : "off", c.n,
                builder.frames_used(), refined, cloud.size(), 1e3 * st.mean_m, 1e3 * st.p95_m,
                1e3 * st.max_m, Median(add_ms), Max(add_ms), Median(load_ms),
                GlobalRegistrationStatusName(g.status),
                1e3 * ModelTranslationError(room_from_model.Inverse(), g.target_from_source.Inverse()),
                DegFromRad(ModelRotationErrorRad(room_from_model.Inverse(),
                                                 g.target_from_source.Inverse())));
    if (c.perturb && c.refine && c.n == 5e4) last_cloud = cloud;
  }
  std::printf("\nPoisson on the default reconstruction (perturbed poses, GICP, N = 5e4), prune "
              "1 cm, 1 thread:\n\n| depth | points | faces before/after pruning | Poisson s | "
              "prune s | vertex error mean mm | p95 mm |\n|---|---|---|---|---|---|---|\n");
  for (int depth : {6, 7, 8}) {
    PoissonOptions po;
    po.depth = depth;
    const PoissonResult pr = PoissonMesh(last_cloud, po);
    std::vector<double> d;
    for (const auto& v : pr.mesh.vertices) d.push_back(distance.Distance(v.cast<double>()));
    const DistanceStats st = SummariseDistances(d);
    std::printf("| %d | %zu | %d / %zu | %.2f | %.3f | %.3f | %.3f |\n", depth, last_cloud.size(),
                pr.faces_before_pruning, pr.mesh.faces.size(), pr.poisson_s, pr.prune_s,
                1e3 * st.mean_m, 1e3 * st.p95_m);
  }
}

void RunReport(const std::string& sections) {
  auto want = [&](const char* name) {
    return sections.empty() || sections.find(name) != std::string::npos;
  };
  if (want("gicp")) ReportGicp();
  if (want("local")) ReportLocalAccuracy();
  if (want("global")) ReportGlobal();
  if (want("recon")) ReportReconstruction();
}

}  // namespace
}  // namespace arpos::testing

int main(int argc, char** argv) {
  bool report = false;
  std::string sections;
  std::vector<char*> rest;
  for (int i = 0; i < argc; ++i) {
    if (std::strcmp(argv[i], "--report") == 0) {
      report = true;
    } else if (std::strncmp(argv[i], "--report=", 9) == 0) {
      report = true;
      sections = argv[i] + 9;
    } else if (std::strncmp(argv[i], "--case=", 7) == 0) {
      arpos::testing::g_case_dir = argv[i] + 7;
    } else {
      rest.push_back(argv[i]);
    }
  }
  int rest_argc = static_cast<int>(rest.size());
  if (report) arpos::testing::RunReport(sections);
  benchmark::Initialize(&rest_argc, rest.data());
  if (benchmark::ReportUnrecognizedArguments(rest_argc, rest.data())) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
