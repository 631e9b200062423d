#pragma once
/// Global (initial-guess-free) registration of a model to a scene, e.g. the
/// reference body model to the session's reconstruction or a depth view:
/// FPFH correspondences, RANSAC over 3-point samples with edge-length
/// pre-rejection, distinct pose hypotheses, point-to-plane ICP refinement of
/// the best few, and a verdict that says AMBIGUOUS rather than returning a
/// confident wrong answer.
///
/// Contract
/// - AlignGlobal(source = model, target = scene) returns
///   target_from_source = scene_from_model.
/// - The scene should be roughly cropped to the patient by the caller (couch
///   and room removal are the caller's business; see preprocess.h helpers).
/// - Fitness is measured on the scene: the share of scene points within
///   `inlier_distance_m` of the posed model. A partial view of the body can
///   thus reach ~1 while the model's back stays unseen.
/// - Verdict:
///   kFailed     no hypothesis, or the best fits less than min_fitness;
///   kAmbiguous  the descriptors cannot tell surface points apart
///               (featureless surface, no hypothesis), or
///               a distinct second hypothesis fits nearly as well
///               (fitness >= ambiguity_fitness_ratio x best and rmse not much
///               worse), or the refined pose has a degenerate direction
///               (Conditioning::min_max_ratio < min_conditioning: a flat,
///               spherical or cylindrical surface);
///   kOk         otherwise.
///   `reason` says which, in words. The best pose is filled in for every
///   status except kFailed with no hypothesis, but only kOk may be used
///   without a person's confirmation.
/// - Deterministic for a given seed, for any number of threads.
/// - Units: metres, radians. Thread-safety: re-entrant. Nothing is printed.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "geometry/rigid3.h"
#include "registration/features.h"
#include "registration/kdtree.h"
#include "registration/point_cloud.h"
#include "registration/registration.h"

namespace arpos {

enum class GlobalRegistrationStatus { kOk, kAmbiguous, kFailed };
const char* GlobalRegistrationStatusName(GlobalRegistrationStatus status);

struct GlobalRegistrationOptions {
  // Features and RANSAC, on clouds downsampled to voxel_m.
  double voxel_m = 0.01;
  int normal_neighbors = 20;        ///< for clouds without normals
  double feature_radius_m = 0.05;   ///< FPFH radius
  bool mutual_matches = false;      ///< keep only mutual descriptor matches
  int ransac_iterations = 50000;
  double edge_length_similarity = 0.9;  ///< pre-rejection of 3-point samples
  double ransac_inlier_distance_m = 0.015;
  int hypotheses_scored = 64;       ///< best RANSAC samples scored on all points
  // Refinement: point-to-plane ICP of the scene onto the model.
  double refine_voxel_m = 0.005;
  int hypotheses_refined = 4;       ///< distinct hypotheses refined
  double refine_coarse_distance_m = 0.025;  ///< first ICP stage correspondence gate
  int refine_max_iterations = 15;           ///< per ICP stage
  double inlier_distance_m = 0.006;         ///< final ICP gate = fitness threshold
  /// Two poses are distinct when the scene points they map differ by more
  /// than this RMS distance.
  double distinct_rms_m = 0.03;
  // Verdict.
  double min_fitness = 0.5;
  double ambiguity_fitness_ratio = 0.9;
  double ambiguity_rmse_ratio = 1.5;  ///< second's rmse must be within this x best's
  double min_conditioning = 0.01;
  /// Without any hypothesis, a match diversity below this (see the result)
  /// means a featureless surface: kAmbiguous rather than kFailed.
  double min_match_diversity = 0.1;
  /// Optional prior scene_from_model and search restriction around it:
  /// hypotheses farther than these (model origin displacement, rotation
  /// angle) are discarded; the prior itself is always refined as a
  /// hypothesis. Non-positive limits mean unrestricted.
  std::optional<Rigid3d> prior_target_from_source;
  double max_prior_translation_m = 0;
  double max_prior_rotation_rad = 0;
  uint64_t seed = 1;
  int num_threads = 0;  ///< 0 = OpenMP's default; does not change the result
  std::string Validate() const;
};

/// One refined pose hypothesis.
struct PoseHypothesis {
  Rigid3d target_from_source;
  double fitness = 0;      ///< after refinement, see the contract
  double rmse_m = 0;       ///< point-to-plane RMS of the inliers
  int ransac_support = 0;  ///< inlier correspondences of its RANSAC sample
};

struct GlobalRegistrationResult {
  GlobalRegistrationStatus status = GlobalRegistrationStatus::kFailed;
  std::string reason;
  Rigid3d target_from_source;  ///< best hypothesis (scene_from_model)
  double fitness = 0;
  double rmse_m = 0;
  /// Distinct refined hypotheses, best first (the first is the result).
  std::vector<PoseHypothesis> hypotheses;
  /// Of the best hypothesis' refinement (scene onto model, scene frame
  /// parameters).
  RegistrationResult refinement;
  Conditioning conditioning;
  int num_correspondences = 0;   ///< descriptor matches fed to RANSAC
  /// Distinct model points among the matches / matches: near 0 when every
  /// descriptor looks alike (a featureless surface).
  double match_diversity = 0;
  /// Wall times: scene (and model, when not prepared) descriptors and
  /// matching; RANSAC and scoring; ICP refinement; the whole call.
  double features_s = 0, ransac_s = 0, refine_s = 0, total_s = 0;
};

/// The model side of AlignGlobal prepared once (downsampled clouds, normals,
/// descriptors, kd-trees): describing a whole-body model takes most of a
/// second, so a controller that aligns several scenes to one model keeps
/// this. Immutable after construction; may be shared between threads.
class GlobalRegistrationModel {
 public:
  /// Uses options.voxel_m, normal_neighbors, feature_radius_m,
  /// refine_voxel_m and num_threads. Throws arpos::Error for invalid options.
  GlobalRegistrationModel(const PointCloud& model_cloud, const GlobalRegistrationOptions& options);

  size_t size() const { return coarse_.size(); }
  /// True if `options` describe the model as this was built (same voxel
  /// sizes, normal neighbours and feature radius).
  bool Matches(const GlobalRegistrationOptions& options) const;
  /// Wall time the preparation took.
  double features_s() const { return features_s_; }

 private:
  friend GlobalRegistrationResult AlignGlobal(const GlobalRegistrationModel&, const PointCloud&,
                                              const GlobalRegistrationOptions&);
  double voxel_m_, refine_voxel_m_, feature_radius_m_;
  int normal_neighbors_;
  PointCloud coarse_, fine_;
  KdTree coarse_tree_, fine_tree_;
  std::vector<FpfhDescriptor> features_;
  std::vector<bool> valid_;
  double features_s_ = 0;
};

/// See the file comment. Clouds without normals get k-NN normals oriented
/// towards their frame's origin (right for a camera-frame scene; give a model
/// its outward normals, e.g. from SampleMeshSurface). Throws arpos::Error for
/// invalid options.
GlobalRegistrationResult AlignGlobal(const PointCloud& model_cloud, const PointCloud& scene_cloud,
                                     const GlobalRegistrationOptions& options = {});
/// Same with a prepared model; throws arpos::Error if !model.Matches(options).
GlobalRegistrationResult AlignGlobal(const GlobalRegistrationModel& model,
                                     const PointCloud& scene_cloud,
                                     const GlobalRegistrationOptions& options = {});

}  // namespace arpos
