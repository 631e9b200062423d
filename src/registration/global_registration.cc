#include "registration/global_registration.h"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>

#include "geometry/so3.h"
#include "geometry/umeyama.h"
#include "registration/features.h"
#include "registration/kdtree.h"
#include "registration/preprocess.h"
#include "util/check.h"

namespace arpos {
namespace {

double NowS() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

int ThreadCount(int requested) { return requested > 0 ? requested : omp_get_max_threads(); }

uint64_t Mix64(uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

struct Candidate {
  Rigid3d scene_from_model;
  int support = 0;        // inlier correspondences
  int64_t iteration = 0;  // tie-breaker: makes the order unique
  double fitness = 0;     // on all scene points, after scoring
};

bool Better(const Candidate& a, const Candidate& b) {
  if (a.support != b.support) return a.support > b.support;
  return a.iteration < b.iteration;
}

// Downsampled copy with normals (kept and averaged if present, else k-NN).
PointCloud Prepare(const PointCloud& cloud, double voxel_m, int neighbors, int threads) {
  PointCloud out = VoxelDownsample(cloud, voxel_m);
  out.covs.clear();
  if (!out.has_normals() && out.size() >= 3) {
    const KdTree tree(out);
    NormalOptions options;
    options.k = std::min<int>(neighbors, static_cast<int>(out.size()));
    options.k = std::max(options.k, 3);
    options.num_threads = threads;
    EstimateNormals(&out, tree, options);
  }
  return out;
}

bool WithinPrior(const Rigid3d& scene_from_model, const GlobalRegistrationOptions& o) {
  if (!o.prior_target_from_source) return true;
  const Rigid3d& prior = *o.prior_target_from_source;
  if (o.max_prior_translation_m > 0 &&
      (scene_from_model.translation - prior.translation).norm() > o.max_prior_translation_m) {
    return false;
  }
  if (o.max_prior_rotation_rad > 0 &&
      RotationAngleRad(prior.rotation.conjugate() * scene_from_model.rotation) >
          o.max_prior_rotation_rad) {
    return false;
  }
  return true;
}

// RMS distance between where two scene_from_model poses put the model, seen
// from the scene points (both mapped into the model frame).
double RmsDifference(const Rigid3d& a, const Rigid3d& b, const std::vector<Eigen::Vector3d>& probe) {
  const Rigid3d a_inv = a.Inverse(), b_inv = b.Inverse();
  double sum = 0;
  for (const auto& p : probe) sum += ((a_inv * p) - (b_inv * p)).squaredNorm();
  return probe.empty() ? 0.0 : std::sqrt(sum / probe.size());
}

double SceneFitness(const Rigid3d& scene_from_model, const PointCloud& scene, const KdTree& model_tree,
                    double distance_m) {
  const Rigid3d model_from_scene = scene_from_model.Inverse();
  const Eigen::Matrix3d r = model_from_scene.RotationMatrix();
  const double max_sq = distance_m * distance_m;
  int inliers = 0;
  for (size_t i = 0; i < scene.size(); ++i) {
    const Eigen::Vector3d p = r * scene.point3(i) + model_from_scene.translation;
    size_t j;
    double sq;
    if (model_tree.Nearest(Eigen::Vector4d(p.x(), p.y(), p.z(), 1.0), &j, &sq, max_sq)) ++inliers;
  }
  return scene.empty() ? 0.0 : static_cast<double>(inliers) / scene.size();
}

}  // namespace

const char* GlobalRegistrationStatusName(GlobalRegistrationStatus status) {
  switch (status) {
    case GlobalRegistrationStatus::kOk:
      return "ok";
    case GlobalRegistrationStatus::kAmbiguous:
      return "ambiguous";
    case GlobalRegistrationStatus::kFailed:
      return "failed";
  }
  return "?";
}

std::string GlobalRegistrationOptions::Validate() const {
  if (!(voxel_m > 0)) return "voxel_m: must be positive";
  if (normal_neighbors < 3) return "normal_neighbors: must be >= 3";
  if (!(feature_radius_m > voxel_m)) return "feature_radius_m: must exceed voxel_m";
  if (ransac_iterations < 1) return "ransac_iterations: must be >= 1";
  if (!(edge_length_similarity > 0 && edge_length_similarity < 1)) {
    return "edge_length_similarity: must be in (0, 1)";
  }
  if (!(ransac_inlier_distance_m > 0)) return "ransac_inlier_distance_m: must be positive";
  if (hypotheses_scored < 1) return "hypotheses_scored: must be >= 1";
  if (!(refine_voxel_m > 0)) return "refine_voxel_m: must be positive";
  if (hypotheses_refined < 1) return "hypotheses_refined: must be >= 1";
  if (!(refine_coarse_distance_m > 0)) return "refine_coarse_distance_m: must be positive";
  if (refine_max_iterations < 1) return "refine_max_iterations: must be >= 1";
  if (!(inlier_distance_m > 0)) return "inlier_distance_m: must be positive";
  if (!(distinct_rms_m > 0)) return "distinct_rms_m: must be positive";
  if (!(min_fitness >= 0 && min_fitness <= 1)) return "min_fitness: must be in [0, 1]";
  if (!(ambiguity_fitness_ratio > 0 && ambiguity_fitness_ratio <= 1)) {
    return "ambiguity_fitness_ratio: must be in (0, 1]";
  }
  if (!(ambiguity_rmse_ratio >= 1)) return "ambiguity_rmse_ratio: must be >= 1";
  if (!(min_conditioning >= 0)) return "min_conditioning: must be >= 0";
  if (!(min_match_diversity >= 0 && min_match_diversity <= 1)) {
    return "min_match_diversity: must be in [0, 1]";
  }
  if (num_threads < 0) return "num_threads: must be >= 0";
  return "";
}

GlobalRegistrationModel::GlobalRegistrationModel(const PointCloud& model_cloud,
                                                 const GlobalRegistrationOptions& options) {
  const std::string problem = options.Validate();
  ARPOS_CHECK(problem.empty(), "GlobalRegistrationOptions: " << problem);
  const double start_s = NowS();
  const int threads = ThreadCount(options.num_threads);
  voxel_m_ = options.voxel_m;
  refine_voxel_m_ = options.refine_voxel_m;
  feature_radius_m_ = options.feature_radius_m;
  normal_neighbors_ = options.normal_neighbors;
  coarse_ = Prepare(model_cloud, voxel_m_, normal_neighbors_, threads);
  fine_ = Prepare(model_cloud, refine_voxel_m_, normal_neighbors_, threads);
  coarse_tree_ = KdTree(coarse_);
  fine_tree_ = KdTree(fine_);
  FpfhOptions fpfh;
  fpfh.radius_m = feature_radius_m_;
  fpfh.num_threads = threads;
  features_ = ComputeFpfh(coarse_, fpfh, &valid_);
  features_s_ = NowS() - start_s;
}

bool GlobalRegistrationModel::Matches(const GlobalRegistrationOptions& options) const {
  return options.voxel_m == voxel_m_ && options.refine_voxel_m == refine_voxel_m_ &&
         options.feature_radius_m == feature_radius_m_ &&
         options.normal_neighbors == normal_neighbors_;
}

GlobalRegistrationResult AlignGlobal(const PointCloud& model_cloud, const PointCloud& scene_cloud,
                                     const GlobalRegistrationOptions& options) {
  const double start_s = NowS();
  if (model_cloud.size() < 10) {
    GlobalRegistrationResult result;
    result.reason = "too few points in the model";
    return result;
  }
  const GlobalRegistrationModel model(model_cloud, options);
  GlobalRegistrationResult result = AlignGlobal(model, scene_cloud, options);
  result.features_s += model.features_s();
  result.total_s = NowS() - start_s;
  return result;
}

GlobalRegistrationResult AlignGlobal(const GlobalRegistrationModel& prepared,
                                     const PointCloud& scene_cloud,
                                     const GlobalRegistrationOptions& options) {
  const std::string problem = options.Validate();
  ARPOS_CHECK(problem.empty(), "GlobalRegistrationOptions: " << problem);
  ARPOS_CHECK(prepared.Matches(options),
              "AlignGlobal: the prepared model was built with other voxel/feature options");
  const double start_s = NowS();
  const int threads = ThreadCount(options.num_threads);
  GlobalRegistrationResult result;
  auto finish = [&](GlobalRegistrationStatus status, const std::string& reason) {
    result.status = status;
    result.reason = reason;
    result.total_s = NowS() - start_s;
    return result;
  };
  if (prepared.size() < 10 || scene_cloud.size() < 10) {
    return finish(GlobalRegistrationStatus::kFailed, "too few points in the model or the scene");
  }

  // 1. Scene features; matches scene -> model.
  const PointCloud& model = prepared.coarse_;
  const PointCloud scene = Prepare(scene_cloud, options.voxel_m, options.normal_neighbors, threads);
  FpfhOptions fpfh;
  fpfh.radius_m = options.feature_radius_m;
  fpfh.num_threads = threads;
  std::vector<bool> scene_valid;
  const auto scene_features = ComputeFpfh(scene, fpfh, &scene_valid);
  FeatureMatchOptions match_options;
  match_options.mutual = options.mutual_matches;
  const auto matches = MatchFeatures(scene_features, scene_valid, prepared.features_,
                                     prepared.valid_, match_options);
  result.num_correspondences = static_cast<int>(matches.size());
  {
    std::vector<int> targets;
    for (const auto& m : matches) targets.push_back(m.second);
    std::sort(targets.begin(), targets.end());
    const size_t unique = std::unique(targets.begin(), targets.end()) - targets.begin();
    result.match_diversity = matches.empty() ? 0.0 : static_cast<double>(unique) / matches.size();
  }
  result.features_s = NowS() - start_s;
  const KdTree& model_tree = prepared.coarse_tree_;

  // 2. RANSAC over 3-point samples: scene_from_model from model -> scene pairs.
  const double ransac_start_s = NowS();
  std::vector<Candidate> pool;
  if (matches.size() >= 3) {
    const double sim = options.edge_length_similarity;
    const double min_edge = 2.0 * options.voxel_m;
    const double inlier_sq = options.ransac_inlier_distance_m * options.ransac_inlier_distance_m;
    const size_t pool_size = static_cast<size_t>(options.hypotheses_scored);
    std::vector<std::vector<Candidate>> pools(threads);
#pragma omp parallel num_threads(threads)
    {
      std::vector<Candidate>& local = pools[omp_get_thread_num()];
      std::vector<Eigen::Vector3d> src(3), dst(3);
#pragma omp for schedule(static)
      for (int64_t it = 0; it < options.ransac_iterations; ++it) {
        uint64_t state = Mix64(options.seed * 0x100000001b3ULL + static_cast<uint64_t>(it));
        int pick[3];
        for (int k = 0; k < 3; ++k) {
          state = Mix64(state);
          pick[k] = static_cast<int>(state % matches.size());
        }
        if (pick[0] == pick[1] || pick[0] == pick[2] || pick[1] == pick[2]) continue;
        bool ok = true;
        for (int k = 0; k < 3; ++k) {
          dst[k] = scene.point3(matches[pick[k]].first);
          src[k] = model.point3(matches[pick[k]].second);
        }
        for (int a = 0; a < 3 && ok; ++a) {
          const int b = (a + 1) % 3;
          const double ls = (src[a] - src[b]).norm(), ld = (dst[a] - dst[b]).norm();
          if (ls < min_edge || ld < min_edge) ok = false;
          if (ls < sim * ld || ld < sim * ls) ok = false;
        }
        if (!ok) continue;
        const auto fit = EstimateRigidTransform(src, dst);
        if (!fit) continue;
        const Rigid3d& pose = fit->target_from_source;
        if (!WithinPrior(pose, options)) continue;
        const Eigen::Matrix3d r = pose.RotationMatrix();
        int support = 0;
        for (const auto& m : matches) {
          const Eigen::Vector3d p = r * model.point3(m.second) + pose.translation;
          if ((p - scene.point3(m.first)).squaredNorm() < inlier_sq) ++support;
        }
        if (support < 3) continue;
        Candidate c{pose, support, it, 0.0};
        if (local.size() < pool_size) {
          local.push_back(c);
          std::push_heap(local.begin(), local.end(), Better);  // worst on top
        } else if (Better(c, local.front())) {
          std::pop_heap(local.begin(), local.end(), Better);
          local.back() = c;
          std::push_heap(local.begin(), local.end(), Better);
        }
      }
    }
    for (const auto& local : pools) pool.insert(pool.end(), local.begin(), local.end());
    std::sort(pool.begin(), pool.end(), Better);
    if (pool.size() > pool_size) pool.resize(pool_size);
  }
  // Score every pooled hypothesis on all scene points.
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
  for (int64_t i = 0; i < static_cast<int64_t>(pool.size()); ++i) {
    pool[i].fitness = SceneFitness(pool[i].scene_from_model, scene, model_tree,
                                   options.ransac_inlier_distance_m);
  }
  std::stable_sort(pool.begin(), pool.end(), [](const Candidate& a, const Candidate& b) {
    return a.fitness > b.fitness;
  });
  result.ransac_s = NowS() - ransac_start_s;

  // 3. Distinct hypotheses (plus the prior), refined by point-to-plane ICP of
  //    the scene onto the model.
  const double refine_start_s = NowS();
  std::vector<Eigen::Vector3d> probe;
  const size_t probe_step = std::max<size_t>(1, scene.size() / 256);
  for (size_t i = 0; i < scene.size(); i += probe_step) probe.push_back(scene.point3(i));
  std::vector<Candidate> distinct;
  if (options.prior_target_from_source) {
    distinct.push_back(Candidate{*options.prior_target_from_source, 0, -1, 0.0});
  }
  for (const Candidate& c : pool) {
    if (static_cast<int>(distinct.size()) >=
        options.hypotheses_refined + (options.prior_target_from_source ? 1 : 0)) {
      break;
    }
    bool is_new = true;
    for (const Candidate& d : distinct) {
      if (RmsDifference(c.scene_from_model, d.scene_from_model, probe) < options.distinct_rms_m) {
        is_new = false;
        break;
      }
    }
    if (is_new) distinct.push_back(c);
  }
  if (distinct.empty()) {
    result.refine_s = NowS() - refine_start_s;
    if (!matches.empty() && result.match_diversity < options.min_match_diversity) {
      // Every scene point looks like the same few model points: the surface
      // has no distinctive shape (sphere, plane, cylinder), so any pose we
      // picked would be a guess.
      char text[200];
      std::snprintf(text, sizeof(text),
                    "featureless surface: %zu scene descriptors match only %.0f%% distinct "
                    "model points; give a prior",
                    matches.size(), 100.0 * result.match_diversity);
      return finish(GlobalRegistrationStatus::kAmbiguous, text);
    }
    return finish(GlobalRegistrationStatus::kFailed,
                  "no pose hypothesis (" + std::to_string(matches.size()) +
                      " feature matches; the scene may not show the model)");
  }
  const PointCloud& fine_model = prepared.fine_;
  const PointCloud fine_scene = VoxelDownsample(scene_cloud, options.refine_voxel_m);
  const KdTree& fine_model_tree = prepared.fine_tree_;
  struct Refined {
    PoseHypothesis hypothesis;
    RegistrationResult registration;
  };
  std::vector<Refined> refined;
  for (const Candidate& c : distinct) {
    RegistrationOptions icp;
    icp.num_threads = threads;
    icp.max_correspondence_distance_m = options.refine_coarse_distance_m;
    icp.max_iterations = options.refine_max_iterations;
    const RegistrationResult coarse = AlignPointToPlane(
        fine_scene, fine_model, fine_model_tree, c.scene_from_model.Inverse(), icp);
    icp.max_correspondence_distance_m = options.inlier_distance_m;
    const RegistrationResult fine = AlignPointToPlane(
        fine_scene, fine_model, fine_model_tree, coarse.target_from_source, icp);
    Refined r;
    r.registration = fine;
    r.hypothesis.target_from_source = fine.target_from_source.Inverse();
    r.hypothesis.fitness = fine.fitness;
    r.hypothesis.rmse_m = fine.rmse_m;
    r.hypothesis.ransac_support = c.support;
    if (!WithinPrior(r.hypothesis.target_from_source, options)) continue;
    refined.push_back(r);
  }
  std::stable_sort(refined.begin(), refined.end(), [](const Refined& a, const Refined& b) {
    if (a.hypothesis.fitness != b.hypothesis.fitness) {
      return a.hypothesis.fitness > b.hypothesis.fitness;
    }
    return a.hypothesis.rmse_m < b.hypothesis.rmse_m;
  });
  // Refinement may have merged hypotheses: keep the distinct ones.
  std::vector<Refined> unique;
  for (const Refined& r : refined) {
    bool is_new = true;
    for (const Refined& u : unique) {
      if (RmsDifference(r.hypothesis.target_from_source, u.hypothesis.target_from_source, probe) <
          options.distinct_rms_m) {
        is_new = false;
        break;
      }
    }
    if (is_new) unique.push_back(r);
  }
  result.refine_s = NowS() - refine_start_s;
  for (const Refined& u : unique) result.hypotheses.push_back(u.hypothesis);
  if (unique.empty()) {
    return finish(GlobalRegistrationStatus::kFailed, "no hypothesis within the prior's limits");
  }

  // 4. Verdict.
  const Refined& best = unique.front();
  result.target_from_source = best.hypothesis.target_from_source;
  result.fitness = best.hypothesis.fitness;
  result.rmse_m = best.hypothesis.rmse_m;
  result.refinement = best.registration;
  result.conditioning = AnalyseConditioning(best.registration, fine_scene);
  char text[256];
  if (best.hypothesis.fitness < options.min_fitness) {
    std::snprintf(text, sizeof(text), "best fitness %.2f below %.2f (rmse %.1f mm)",
                  best.hypothesis.fitness, options.min_fitness, 1e3 * best.hypothesis.rmse_m);
    return finish(GlobalRegistrationStatus::kFailed, text);
  }
  if (unique.size() > 1) {
    const PoseHypothesis& second = unique[1].hypothesis;
    if (second.fitness >= options.ambiguity_fitness_ratio * best.hypothesis.fitness &&
        second.rmse_m <= options.ambiguity_rmse_ratio * best.hypothesis.rmse_m) {
      std::snprintf(text, sizeof(text),
                    "a distinct pose fits nearly as well: fitness %.3f vs %.3f, rmse %.2f vs "
                    "%.2f mm, %.0f mm apart",
                    second.fitness, best.hypothesis.fitness, 1e3 * second.rmse_m,
                    1e3 * best.hypothesis.rmse_m,
                    1e3 * RmsDifference(second.target_from_source,
                                        best.hypothesis.target_from_source, probe));
      return finish(GlobalRegistrationStatus::kAmbiguous, text);
    }
  }
  if (result.conditioning.min_max_ratio < options.min_conditioning) {
    const Conditioning& c = result.conditioning;
    std::snprintf(text, sizeof(text),
                  "degenerate direction (eigenvalue ratio %.1e): %s along [%.2f %.2f %.2f]",
                  c.min_max_ratio, c.weakest_rotation_share > 0.5 ? "rotation" : "translation",
                  c.weakest_rotation_share > 0.5 ? c.weakest_rotation_axis.x()
                                                 : c.weakest_translation.normalized().x(),
                  c.weakest_rotation_share > 0.5 ? c.weakest_rotation_axis.y()
                                                 : c.weakest_translation.normalized().y(),
                  c.weakest_rotation_share > 0.5 ? c.weakest_rotation_axis.z()
                                                 : c.weakest_translation.normalized().z());
    return finish(GlobalRegistrationStatus::kAmbiguous, text);
  }
  std::snprintf(text, sizeof(text), "fitness %.3f, rmse %.2f mm, next best fitness %.3f",
                best.hypothesis.fitness, 1e3 * best.hypothesis.rmse_m,
                unique.size() > 1 ? unique[1].hypothesis.fitness : 0.0);
  return finish(GlobalRegistrationStatus::kOk, text);
}

}  // namespace arpos
