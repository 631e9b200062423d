#pragma once
// The room's static surface near the couch, as the planning recording's
// depth shows it: a dense model the camera localiser registers each
// tracking frame's depth to (camera_localizer.h, use_room_surface).
//
// Markers and keypoints fix the camera by what is textured and seen; during
// treatment the camera often sees one room marker or none, and keypoints on
// a far floor or wall leave it a few millimetres off. The couch base, the
// floor around it, the gantry and any other still surface near the patient
// are seen in depth in nearly every frame: each face pins the camera along
// its normal. So the planning stage keeps the surface it saw, placed by the
// adjusted room cameras, and tracking matches depth to it point to plane.
//
// The surface is a voxel grid (voxel_m) of the depth the room frames saw
// within radius_m of the couch point, outside the couch's exclusion box
// (the couch top moves with the patient), each voxel seen in at least
// min_frames frames. A voxel keeps a point and a normal only where its
// neighbourhood (the voxels within +-1) is flat: edges, corners and clutter
// give no reliable normal and are left out.

#include <functional>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "geometry/rigid3.h"
#include "sensor/depth_correction.h"
#include "sensor/intrinsics.h"

namespace arpos {

class Sequence;

struct RoomSurface {
  double voxel_m = 0;                    ///< grid the points were gathered on (0: no surface)
  std::vector<Eigen::Vector3f> points;   ///< room frame, m: on the local plane
  std::vector<Eigen::Vector3f> normals;  ///< unit, row for row (the sign carries no meaning)

  bool empty() const { return points.empty(); }
  size_t size() const { return points.size(); }
  /// Empty if consistent, else what is wrong (sizes match, finite, unit
  /// normals, a positive voxel size when there are points, within 100 m of
  /// the origin and 20 m across).
  std::string Validate() const;
};

struct RoomSurfaceOptions {
  double voxel_m = 0.03;
  /// Around the couch point: what the tracking camera sees near the patient
  /// (the couch base, the floor about it, the gantry's face), where the
  /// map's cameras are best placed. Measured on simulated cases: a wall
  /// 2.2-2.5 m from the couch point that the map had placed about 2 cm off
  /// pulled keypoint-only frames 13-37 mm off with 2.5 m; 1.0, 1.5 and
  /// 2.0 m gave the same poses there.
  double radius_m = 1.5;
  /// Depth samples across the image per frame (a grid; more rows follow
  /// the aspect ratio).
  int samples_across = 160;
  double min_depth_m = 0.3;
  double max_depth_m = 4.0;
  int min_frames = 3;
  /// Depth noise, sigma(z) = const + quad * z^2: samples are weighted by it.
  double depth_sigma_const_m = 0.001;
  double depth_sigma_quad_per_m = 0.0015;
  /// A voxel's neighbourhood (+-1 voxel) must be flat: the weighted
  /// variance of its samples across their plane at most 4 times what the
  /// depth noise gives, plus this squared (m).
  double max_unflatness_m = 0.003;
  /// And span a patch in both directions (RMS along its narrower extent, m).
  double min_extent_m = 0.015;
  int max_points = 120000;

  std::string Validate() const;
};

struct RoomSurfaceReport {
  int frames = 0;          ///< frames whose depth was read
  int samples = 0;         ///< depth samples gathered (inside the radius, outside exclusions)
  int voxels = 0;          ///< voxels seen in at least min_frames frames
  int flat_voxels = 0;     ///< of them, flat: the surface's points
  double seconds = 0;
  std::string note;  ///< appended to the line (e.g. how localisation uses it)
  std::string ToText() const;
};

/// Pixels on a grid every `step` px (the first at step / 2) and their ideal
/// rays, (x, y) of (x, y, 1), through the lens when the intrinsics have one:
/// where the surface is gathered and where the localiser reads the room's
/// depth.
struct DepthSampleGrid {
  std::vector<cv::Point> px;
  std::vector<Eigen::Vector2d> ray;
};
DepthSampleGrid MakeDepthSampleGrid(const CameraIntrinsics& intrinsics, int step);

/// Gathers the surface from the depth of `sequence`'s frames at the given
/// camera poses (sequence index, room_from_camera), with `correction`
/// removed from the depth first. `keep` says whether a room point may enter
/// (false inside exclusion boxes); `centre` is the couch point. Frames whose
/// depth cannot be read are skipped (the map builder reported them).
RoomSurface BuildRoomSurface(const Sequence& sequence, const CameraIntrinsics& intrinsics,
                             const DepthCorrection& correction,
                             const std::vector<std::pair<int, Rigid3d>>& room_from_camera,
                             const std::function<bool(const Eigen::Vector3d&)>& keep,
                             const Eigen::Vector3d& centre, const RoomSurfaceOptions& options,
                             RoomSurfaceReport* report = nullptr);

/// Constant-time lookup of a surface point near a room point: a dense grid
/// of the surface's voxels over its bounding box, each cell holding the
/// surface point nearest to its centre among those in the 27 cells about
/// it. For a point-to-plane match any point of the same face serves: the
/// residual does not change along the face.
class RoomSurfaceIndex {
 public:
  RoomSurfaceIndex() = default;
  explicit RoomSurfaceIndex(const RoomSurface& surface);
  bool empty() const { return points_.empty(); }
  /// A surface point within about 1.5 voxels of `x`, or -1 when there is none.
  int Near(const Eigen::Vector3d& x) const;
  const Eigen::Vector3d& point(int i) const { return points_[i]; }
  const Eigen::Vector3d& normal(int i) const { return normals_[i]; }

 private:
  double inv_voxel_ = 0;
  Eigen::Vector3d origin_ = Eigen::Vector3d::Zero();  ///< corner of cell (0, 0, 0)
  Eigen::Vector3i size_ = Eigen::Vector3i::Zero();
  std::vector<Eigen::Vector3d> points_, normals_;
  std::vector<int> cell_point_;  ///< per cell, -1: none
};

}  // namespace arpos
