#include "registration/reconstruction.h"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>

#include "geometry/so3.h"
#include "registration/kdtree.h"
#include "util/check.h"

namespace arpos {
namespace {

double NowS() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

constexpr int64_t kKeyOffset = int64_t{1} << 20;

bool VoxelKey(const Eigen::Vector3d& p, double inv_voxel, uint64_t* key) {
  const int64_t x = static_cast<int64_t>(std::floor(p.x() * inv_voxel)) + kKeyOffset;
  const int64_t y = static_cast<int64_t>(std::floor(p.y() * inv_voxel)) + kKeyOffset;
  const int64_t z = static_cast<int64_t>(std::floor(p.z() * inv_voxel)) + kKeyOffset;
  if (x < 0 || y < 0 || z < 0 || x >= 2 * kKeyOffset || y >= 2 * kKeyOffset ||
      z >= 2 * kKeyOffset) {
    return false;
  }
  *key = (static_cast<uint64_t>(x) << 42) | (static_cast<uint64_t>(y) << 21) |
         static_cast<uint64_t>(z);
  return true;
}

}  // namespace

std::string ReconstructionOptions::Validate() const {
  if (frame_stride < 1) return "frame_stride: must be >= 1";
  if (!(min_voxel_m > 0)) return "min_voxel_m: must be positive";
  if (!(target_points >= 1)) return "target_points: must be >= 1";
  if (!(output_voxel_m > 0)) return "output_voxel_m: must be positive";
  const std::string r = registration.Validate();
  if (!r.empty()) return "registration." + r;
  if (!(max_correction_m > 0)) return "max_correction_m: must be positive";
  if (!(max_correction_rad > 0)) return "max_correction_rad: must be positive";
  if (!(min_fitness >= 0 && min_fitness <= 1)) return "min_fitness: must be in [0, 1]";
  if (crop_box && !(crop_box->half_extents_m.array() > 0).all()) {
    return "crop_box: half extents must be positive";
  }
  if (keep_above_plane && std::abs(keep_above_plane->normal.norm() - 1.0) > 1e-6) {
    return "keep_above_plane: normal must be unit";
  }
  if (num_threads < 0) return "num_threads: must be >= 0";
  return "";
}

ReconstructionBuilder::ReconstructionBuilder(const ReconstructionOptions& options)
    : options_(options) {
  const std::string problem = options.Validate();
  ARPOS_CHECK(problem.empty(), "ReconstructionOptions: " << problem);
  options_.registration.num_threads = options.num_threads;
}

double ReconstructionBuilder::CurrentVoxel() const {
  if (voxels_.empty() || bounds_.isEmpty()) return options_.min_voxel_m;
  const double volume = bounds_.volume();
  return std::max(std::cbrt(volume / options_.target_points), options_.min_voxel_m);
}

PointCloud ReconstructionBuilder::Crop(const PointCloud& cloud_in_camera,
                                       const Rigid3d& world_from_camera) const {
  if (!options_.crop_box && !options_.keep_above_plane) return cloud_in_camera;
  const Eigen::Matrix3d r = world_from_camera.RotationMatrix();
  const Rigid3d box_from_world =
      options_.crop_box ? options_.crop_box->frame_from_box.Inverse() : Rigid3d();
  std::vector<size_t> keep;
  keep.reserve(cloud_in_camera.size());
  for (size_t i = 0; i < cloud_in_camera.size(); ++i) {
    const Eigen::Vector3d w = r * cloud_in_camera.point3(i) + world_from_camera.translation;
    if (options_.keep_above_plane &&
        options_.keep_above_plane->SignedDistance(w) <= options_.min_height_above_plane_m) {
      continue;
    }
    if (options_.crop_box &&
        !((box_from_world * w).array().abs() <= options_.crop_box->half_extents_m.array()).all()) {
      continue;
    }
    keep.push_back(i);
  }
  return cloud_in_camera.Select(keep);
}

PointCloud ReconstructionBuilder::Centroids() const {
  std::vector<std::pair<uint64_t, const Voxel*>> sorted;
  sorted.reserve(voxels_.size());
  for (const auto& [key, voxel] : voxels_) sorted.emplace_back(key, &voxel);
  std::sort(sorted.begin(), sorted.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  PointCloud cloud;
  cloud.points.reserve(sorted.size());
  for (const auto& [key, voxel] : sorted) {
    const Eigen::Vector3d c = voxel->sum / voxel->count;
    cloud.points.emplace_back(c.x(), c.y(), c.z(), 1.0);
  }
  return cloud;
}

struct ReconstructionBuilder::Target {
  double voxel_m = 0;
  PointCloud cloud;
  std::unique_ptr<KdTree> tree;
};

void ReconstructionBuilder::Refine(const PointCloud& cloud, const Rigid3d& world_from_camera, double voxel_m,
                                   ReconstructionFrameReport* report) {
  NormalOptions local;
  local.k = options_.registration.neighbors;
  local.covariance_epsilon = options_.registration.covariance_epsilon;
  local.num_threads = options_.num_threads;
  PointCloud source = VoxelDownsample(cloud, voxel_m);
  if (!target_ || target_->voxel_m != voxel_m) {
    auto t = std::make_shared<Target>();
    t->voxel_m = voxel_m;
    t->cloud = Centroids();
    if (voxel_m > options_.output_voxel_m) t->cloud = VoxelDownsample(t->cloud, voxel_m);
    if (t->cloud.size() >= 10) {
      t->tree = std::make_unique<KdTree>(t->cloud);
      EstimateCovariances(&t->cloud, *t->tree, local);
    }
    target_ = t;
  }
  const PointCloud& target = target_->cloud;
  if (source.size() < 10 || target.size() < 10) {
    report->message = "too few points to refine";
    return;
  }
  const KdTree source_tree(source);
  EstimateCovariances(&source, source_tree, local);
  report->registration = AlignGicp(source, target, *target_->tree, world_from_camera, options_.registration);
  const Rigid3d& refined = report->registration.target_from_source;
  // Size of the correction where the frame's points are, not at the
  // world origin.
  const Eigen::Vector3d centre = source.Centroid();
  const double moved_m = (refined * centre - world_from_camera * centre).norm();
  const double turned_rad = RotationAngleRad(refined.rotation * world_from_camera.rotation.conjugate());
  if (!report->registration.converged) {
    report->message = "GICP did not converge (" + report->registration.message + ")";
  } else if (report->registration.fitness < options_.min_fitness) {
    report->message = "GICP fitness " + std::to_string(report->registration.fitness) + " below " +
                      std::to_string(options_.min_fitness);
  } else if (moved_m > options_.max_correction_m || turned_rad > options_.max_correction_rad) {
    report->message = "GICP correction too large (" + std::to_string(1e3 * moved_m) + " mm, " +
                      std::to_string(DegFromRad(turned_rad)) + " deg)";
  } else {
    report->refined = true;
    report->world_from_camera = refined;
  }
}

ReconstructionFrameReport ReconstructionBuilder::RegisterFrame(const PointCloud& cloud_in_camera,
                                                               const Rigid3d& world_from_camera) {
  ReconstructionFrameReport report;
  const double start_s = NowS();
  report.world_from_camera = world_from_camera;
  const PointCloud cloud = Crop(cloud_in_camera, world_from_camera);
  report.points_in = static_cast<int>(cloud.size());
  report.voxel_m = options_.output_voxel_m;
  if (voxels_.empty() || cloud.size() < 10) {
    report.message = voxels_.empty() ? "the reconstruction is empty" : "too few points to refine";
  } else {
    Refine(cloud, world_from_camera, report.voxel_m, &report);
  }
  report.correction = report.world_from_camera * world_from_camera.Inverse();
  report.reconstruction_points = static_cast<int>(voxels_.size());
  report.seconds = NowS() - start_s;
  return report;
}

ReconstructionFrameReport ReconstructionBuilder::AddFrame(const PointCloud& cloud_in_camera,
                                                          const Rigid3d& world_from_camera) {
  ReconstructionFrameReport report;
  report.offered_index = frames_offered_++;
  if (report.offered_index % options_.frame_stride != 0) return report;
  const double start_s = NowS();
  report.used = true;
  ++frames_used_;
  const PointCloud cloud = Crop(cloud_in_camera, world_from_camera);
  report.points_in = static_cast<int>(cloud.size());
  report.voxel_m = CurrentVoxel();
  report.world_from_camera = world_from_camera;

  if (options_.refine_poses && !voxels_.empty() && cloud.size() >= 10) {
    Refine(cloud, world_from_camera, report.voxel_m, &report);
  }
  report.correction = report.world_from_camera * world_from_camera.Inverse();
  const bool refinement_refused = options_.refine_poses && !voxels_.empty() && !report.refined;
  if (refinement_refused && !options_.fuse_refused_frames) {
    report.reconstruction_points = static_cast<int>(voxels_.size());
    report.seconds = NowS() - start_s;
    return report;
  }
  report.fused = true;
  ++frames_fused_;
  target_.reset();  // the voxels change below: a prepared target is stale

  // Fusion: running centroids in output voxels.
  const Eigen::Matrix3d r = report.world_from_camera.RotationMatrix();
  const Eigen::Vector3d t = report.world_from_camera.translation;
  const double inv = 1.0 / options_.output_voxel_m;
  for (size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3d w = r * cloud.point3(i) + t;
    uint64_t key;
    if (!VoxelKey(w, inv, &key)) continue;
    Voxel& voxel = voxels_[key];
    voxel.sum += w;
    const Eigen::Vector3d view = t - w;
    const double norm = view.norm();
    if (norm > 0) voxel.view_sum += view / norm;
    ++voxel.count;
    bounds_.extend(w);
  }
  report.reconstruction_points = static_cast<int>(voxels_.size());
  report.seconds = NowS() - start_s;
  return report;
}

PointCloud ReconstructionBuilder::Cloud(int min_points_per_voxel) const {
  std::vector<std::pair<uint64_t, const Voxel*>> sorted;
  sorted.reserve(voxels_.size());
  for (const auto& [key, voxel] : voxels_) {
    if (voxel.count >= min_points_per_voxel) sorted.emplace_back(key, &voxel);
  }
  std::sort(sorted.begin(), sorted.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  PointCloud cloud;
  cloud.points.reserve(sorted.size());
  cloud.normals.reserve(sorted.size());
  for (const auto& [key, voxel] : sorted) {
    const Eigen::Vector3d c = voxel->sum / voxel->count;
    cloud.points.emplace_back(c.x(), c.y(), c.z(), 1.0);
    Eigen::Vector3d view = voxel->view_sum;
    if (view.norm() > 0) view.normalize();
    cloud.normals.emplace_back(view.x(), view.y(), view.z(), 0.0);
  }
  if (cloud.size() >= 3) {
    // PCA normals, each flipped to face the cameras that saw its voxel.
    const KdTree tree(cloud);
    NormalOptions options;
    options.k = std::min<int>(20, static_cast<int>(cloud.size()));
    options.orient_like_existing = true;
    options.num_threads = options_.num_threads;
    EstimateNormals(&cloud, tree, options);
  }
  return cloud;
}

AnchoredReconstruction BuildAnchoredReconstruction(const std::vector<ReconstructionInput>& inputs,
                                                   const std::vector<size_t>& alternatives,
                                                   const ReconstructionOptions& options,
                                                   double min_joined_share) {
  ARPOS_CHECK(min_joined_share >= 0 && min_joined_share <= 1, "min_joined_share must be in [0, 1]");
  AnchoredReconstruction best;
  auto build_from = [&](size_t first) {
    ARPOS_CHECK(first < inputs.size(), "reconstruction anchor out of range");
    AnchoredReconstruction b;
    b.builder = std::make_unique<ReconstructionBuilder>(options);
    b.anchor = first;
    b.order.push_back(first);
    for (size_t i = 0; i < inputs.size(); ++i) {
      if (i != first) b.order.push_back(i);
    }
    for (size_t i : b.order) {
      ARPOS_CHECK(inputs[i].cloud != nullptr, "reconstruction input without a cloud");
      b.reports.push_back(b.builder->AddFrame(*inputs[i].cloud, inputs[i].world_from_camera));
    }
    if (!best.builder || b.builder->frames_fused() > best.builder->frames_fused())
      best = std::move(b);
  };
  if (inputs.empty()) {
    best.builder = std::make_unique<ReconstructionBuilder>(options);
    return best;
  }
  build_from(0);
  const double joined = best.builder->frames_fused();
  if (inputs.size() >= 3 && joined < min_joined_share * static_cast<double>(inputs.size())) {
    for (size_t i : alternatives) {
      if (i != 0) build_from(i);
    }
    best.rebuilt = true;
  }
  return best;
}

}  // namespace arpos
