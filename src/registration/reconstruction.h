#pragma once
/// Incremental surface reconstruction from depth clouds with known camera
/// poses, each refined by GICP against what has been built so far.
///
/// Frames: every cloud is given in its camera frame with `world_from_camera`
/// (the world is the caller's: the room for a session); the reconstruction
/// is in the world frame. Units: metres.
///
/// Per offered frame (only every `frame_stride`-th is used):
///  1. optional crops in the world frame (oriented box; keep above a plane,
///     e.g. the couch top): the caller knows where the patient is;
///  2. d_i = max(cbrt(V_i / N), d_0), V_i the volume of the reconstruction's
///     axis-aligned bounding box, N = target_points, d_0 = min_voxel_m: the
///     registration resolution grows with the reconstruction so GICP keeps
///     about N target points;
///  3. GICP of the frame (downsampled to d_i) against the reconstruction
///     (downsampled to d_i) from the given pose; the corrected pose is kept
///     only if GICP converged, fits well enough and the correction is within
///     the limits, else the given pose is used and the report says why;
///  4. fusion: every point is added to a voxel grid of output_voxel_m
///     (running centroid per voxel, so the result equals voxel-downsampling
///     the union of all placed points).
///
/// Thread-safety: one builder per thread (AddFrame mutates); Cloud() is
/// const. Nothing is printed.

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "geometry/rigid3.h"
#include "registration/point_cloud.h"
#include "registration/preprocess.h"
#include "registration/registration.h"

namespace arpos {

struct ReconstructionOptions {
  int frame_stride = 10;          ///< l: use frames 0, l, 2l, ... of those offered
  double min_voxel_m = 0.01;      ///< d_0
  double target_points = 5e4;     ///< N
  double output_voxel_m = 0.01;   ///< fused result resolution
  bool refine_poses = true;       ///< GICP against the reconstruction
  /// GICP settings for the refinement (max_correspondence_distance_m is the
  /// largest pose error it can pull in).
  RegistrationOptions registration = [] {
    RegistrationOptions r;
    r.max_correspondence_distance_m = 0.03;
    return r;
  }();
  double max_correction_m = 0.05;      ///< larger GICP corrections are refused
  double max_correction_rad = 0.0873;  ///< 5 degrees
  double min_fitness = 0.5;            ///< share of frame points matched
  /// A frame whose GICP correction was refused disagrees with the
  /// reconstruction (a wrong pose, something in front of the body): it is
  /// not fused unless this is set. The first frame is always fused.
  bool fuse_refused_frames = false;
  /// Optional crops, world frame (applied before anything else).
  std::optional<OrientedBox> crop_box;
  std::optional<Plane> keep_above_plane;
  double min_height_above_plane_m = 0.01;
  int num_threads = 0;  ///< 0 = OpenMP's default
  std::string Validate() const;
};

struct ReconstructionFrameReport {
  int offered_index = -1;     ///< 0-based count of AddFrame calls
  bool used = false;          ///< false: skipped by frame_stride (nothing else filled)
  bool refined = false;       ///< the GICP correction was applied
  bool fused = false;         ///< its points went into the reconstruction
  Rigid3d world_from_camera;  ///< the pose the frame was fused with
  Rigid3d correction;         ///< world_from_camera * given^-1 (identity if not refined)
  RegistrationResult registration;  ///< empty for the first frame or refine_poses off
  double voxel_m = 0;         ///< d_i
  int points_in = 0;          ///< after the crops
  int reconstruction_points = 0;  ///< voxels after fusion
  double seconds = 0;         ///< wall time of AddFrame
  std::string message;        ///< why a correction was refused, etc.
};

class ReconstructionBuilder {
 public:
  /// Throws arpos::Error for invalid options.
  explicit ReconstructionBuilder(const ReconstructionOptions& options = {});

  /// Offers one depth cloud (camera frame) taken at `world_from_camera`.
  ReconstructionFrameReport AddFrame(const PointCloud& cloud_in_camera,
                                     const Rigid3d& world_from_camera);

  /// Registers a frame to the reconstruction as it is now (the same crop,
  /// GICP and acceptance checks as AddFrame, at the output voxel size: the
  /// last frames' d_i is too coarse to pose a frame to a millimetre; measured
  /// in the tests: one of six frames did not converge at ~2.2 cm) without fusing
  /// it or counting it as offered: `refined` says whether
  /// `world_from_camera` is the GICP-corrected pose (else the given one and
  /// `message` says why). For posing frames after the fact, e.g. the
  /// body-scan frames that see stickers. The prepared target is cached until
  /// a frame is fused.
  ReconstructionFrameReport RegisterFrame(const PointCloud& cloud_in_camera, const Rigid3d& world_from_camera);

  /// The fused cloud (world frame): one centroid per occupied output voxel
  /// seen by at least `min_points_per_voxel` points, with k-NN normals
  /// oriented towards the cameras that saw it. Deterministic order.
  PointCloud Cloud(int min_points_per_voxel = 1) const;
  size_t size() const { return voxels_.size(); }
  int frames_offered() const { return frames_offered_; }
  int frames_used() const { return frames_used_; }
  /// Frames whose points went into the reconstruction.
  int frames_fused() const { return frames_fused_; }
  /// d_i the next used frame would get.
  double CurrentVoxel() const;

 private:
  struct Voxel {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    Eigen::Vector3d view_sum = Eigen::Vector3d::Zero();  ///< unit vectors to the cameras
    int count = 0;
  };
  PointCloud Crop(const PointCloud& cloud_in_camera, const Rigid3d& world_from_camera) const;
  PointCloud Centroids() const;
  // GICP of the cropped `cloud` (world_from_camera given) against the
  // reconstruction at voxel `voxel_m`; fills the report's registration,
  // refined, world_from_camera and message.
  void Refine(const PointCloud& cloud, const Rigid3d& world_from_camera, double voxel_m,
              ReconstructionFrameReport* report);
  struct Target;
  std::shared_ptr<Target> target_;  ///< prepared target at target_->voxel_m, reset when a frame is fused

  ReconstructionOptions options_;
  std::unordered_map<uint64_t, Voxel> voxels_;
  Eigen::AlignedBox3d bounds_;
  int frames_offered_ = 0;
  int frames_used_ = 0;
  int frames_fused_ = 0;
};

/// One frame offered to BuildAnchoredReconstruction.
struct ReconstructionInput {
  const PointCloud* cloud = nullptr;  ///< camera frame
  Rigid3d world_from_camera;
};

struct AnchoredReconstruction {
  std::unique_ptr<ReconstructionBuilder> builder;
  std::vector<ReconstructionFrameReport> reports;  ///< build order: the anchor first
  std::vector<size_t> order;                       ///< the input of each report
  size_t anchor = 0;                               ///< the input it was built from
  bool rebuilt = false;  ///< the first build left too many frames out; others were tried
};

/// A reconstruction follows its first frame (GICP registers the others to
/// what is built), so one badly posed first frame makes the well posed ones
/// "disagree" and be left out. Built from inputs[0] first, the others in
/// their order; when fewer than `min_joined_share` of them join (and there
/// are at least three), built again from each of `alternatives` (indices
/// into `inputs`, tried in order: the frames posed most surely), and the
/// build most frames join is kept (ties: the earlier). Every frame is
/// offered, so use frame_stride 1. An empty `inputs` gives an empty builder.
AnchoredReconstruction BuildAnchoredReconstruction(const std::vector<ReconstructionInput>& inputs,
                                                   const std::vector<size_t>& alternatives,
                                                   const ReconstructionOptions& options,
                                                   double min_joined_share = 2.0 / 3.0);

}  // namespace arpos
