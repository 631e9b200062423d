#pragma once
/// Which parts of the patient's surface moved during the body scan, measured
/// from the scan itself: breathing lifts the anterior chest and abdomen while
/// the head, the back and the limbs stay still.
///
/// Why: the reconstruction fuses frames taken at every phase of breathing, so
/// a breathing surface shows at its mean, outside the end-exhale surface the
/// reference model is (breathing dwells at end-exhale and rises briefly). The
/// model aligned to all of it is lifted by a share of that mean; aligned to
/// the still parts it is not.
///
/// How: every fused frame's depth points, placed in the model frame at the
/// aligned pose, are compared with the reference surface: per patch of the
/// surface (cubes of `patch_m` in the model frame, keyed by the nearest
/// surface point) and per frame, the mean signed distance along the
/// surface's outward normal. A frame's own registration error moves all its
/// patches alike: the median over the frame's still patches is taken off.
/// Breathing then moves every moving patch with one time course b(t), each
/// by its own share w (rank one; a patch missing from a frame is simply
/// missing): b and w are fitted alternately, b started from the patches that
/// vary most. A patch moved when its w b is both large (`min_motion_m`,
/// 1 sigma over the frames) and well determined (`min_motion_sigmas` times
/// its standard error): noise and registration errors do not follow b, so a
/// still patch's w is near zero however noisy its depth. Two rounds: the
/// second takes each frame's offset from the patches the first found still,
/// so that a frame filled by the chest does not make the head look as if it
/// moved. Measured on simulated scans (xtion, 23 frames, 4 mm breathing):
/// 69 of 84 patches of the front of the torso found, 8 of 373 elsewhere,
/// where the plain spread over the frames separated them barely (the still
/// patches' 90th percentile 0.70 mm, the torso's median 0.85 mm).
///
/// Units: metres; frames as named (model, room, camera).

#include <cstdint>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include "geometry/rigid3.h"
#include "registration/kdtree.h"
#include "registration/point_cloud.h"

namespace arpos {

struct SurfaceMotionOptions {
  double patch_m = 0.04;           ///< side of a surface patch (model frame cube)
  double max_distance_m = 0.015;   ///< farther from the reference surface: not its skin
  int stride = 2;                  ///< every stride-th point of a frame's cloud
  int min_points_per_patch = 12;   ///< per frame, for the patch's mean in that frame
  int min_frames_per_patch = 4;    ///< frames that measure a patch for its spread
  double min_motion_m = 0.0004;    ///< moved: its breathing share above this (1 sigma over the frames) ...
  double min_motion_sigmas = 4;    ///< ... and this many times its standard error
  std::string Validate() const;
};

/// One frame: its depth points in the camera frame and where the camera was.
struct SurfaceMotionFrame {
  const PointCloud* cloud_in_camera = nullptr;
  Rigid3d room_from_camera;
};

struct SurfaceMotion {
  bool measured = false;  ///< enough frames and patches to tell (else nothing is marked)
  int frames = 0;         ///< frames that measured at least one patch
  int patches = 0;        ///< patches measured in min_frames_per_patch frames or more
  int moving_patches = 0;
  double median_spread_m = 0;  ///< the median patch's spread over the frames (1 sigma)
  double moving_mean_spread_m = 0;  ///< mean spread of the moving patches
  double moving_peak_to_peak_m = 0; ///< largest range over the frames of a moving patch
  double patch_m = 0.04;
  /// Per patch key: spread over the frames (m) and whether it moved.
  struct Patch {
    double spread_m = 0;       ///< of its distance over the frames (1 sigma)
    double range_m = 0;        ///< largest minus smallest distance over the frames
    int frames = 0;
    double motion_m = 0;       ///< the share that follows the common time course (1 sigma)
    double motion_sigmas = 0;  ///< motion_m over its standard error
    bool moving = false;
  };
  std::unordered_map<uint64_t, Patch> patch_by_key;

  /// Whether the surface near `point_in_model` (a reference-surface point,
  /// model frame) moved; false where nothing was measured.
  bool IsMoving(const Eigen::Vector3d& point_in_model) const;
  /// How far the surface near `point_in_model` moved with the common time
  /// course (1 sigma, m): its patch's motion_m where that patch moved, else 0.
  double MotionAt(const Eigen::Vector3d& point_in_model) const;
  /// The centres of the patches that moved (model frame), in key order.
  std::vector<Eigen::Vector3d> MovingPatchCentres() const;
  /// For people: "N of M surface patches moved (by up to X mm) ..." or why
  /// nothing could be told.
  std::string Describe() const;
};

/// The patch key of a model-frame point (cubes of `patch_m`: CubeKey).
uint64_t SurfacePatchKey(const Eigen::Vector3d& point_in_model, double patch_m);

/// Measures as in the file comment. `model_surface` (model frame) needs
/// outward normals (SampleMeshSurface gives them) and `model_tree` is its
/// tree; `model_from_room` the aligned pose. Throws arpos::Error for invalid
/// options or a surface without normals (a caller's mistake).
SurfaceMotion MeasureSurfaceMotion(const std::vector<SurfaceMotionFrame>& frames, const PointCloud& model_surface,
                                   const KdTree& model_tree, const Rigid3d& model_from_room,
                                   const SurfaceMotionOptions& options = {});

}  // namespace arpos
