#pragma once
/// Initial marker poses from single-view marker poses (after MarkerMapper,
/// Muñoz-Salinas et al. 2018): every frame that sees markers a and b gives a
/// relative pose a_from_b = (camera_from_a)^-1 camera_from_b; each pair keeps
/// the candidate that best explains all frames seeing both (median corner
/// reprojection error); a minimum spanning tree over those errors, rooted at
/// the origin marker, chains the relative poses into `room_from_marker`.
/// Bundle adjustment (bundle_adjustment.h) then refines everything jointly.
///
/// Frames: room = origin marker frame; marker frames OpenCV ArUco; camera
/// frames OpenCV. Pixels are undistorted (ideal) pixels.

#include <Eigen/Core>
#include <array>
#include <map>
#include <optional>
#include <vector>

#include "geometry/rigid3.h"
#include "sensor/intrinsics.h"

namespace arpos {

/// One marker seen in one frame, with its single-view pose (already
/// disambiguated, e.g. by EstimateMarkerPose with depth).
struct MarkerView {
  int frame = -1;
  int marker_id = -1;
  Rigid3d camera_from_marker;
  std::array<Eigen::Vector2d, 4> corners_px{};  ///< undistorted pixels, ArUco order
  double reprojection_rms_px = 0;
};

struct MarkerGraphEdge {
  int marker_a = -1, marker_b = -1;
  Rigid3d a_from_b;
  double median_error_px = 0;  ///< of the chosen candidate over all co-visible frames
  int num_frames = 0;          ///< frames seeing both
};

struct MarkerGraphResult {
  std::map<int, Rigid3d> room_from_marker;  ///< markers connected to the origin
  std::vector<int> unconnected_markers;     ///< seen, but never together with the tree
  std::vector<MarkerGraphEdge> tree_edges;  ///< the spanning tree, parent -> child
};

/// Builds the spanning tree from `views`. Returns an empty room_from_marker
/// map if the origin marker is not among the views.
MarkerGraphResult InitializeMarkerPoses(const std::vector<MarkerView>& views, int origin_id,
                                        double marker_size_m, const CameraIntrinsics& intrinsics);

/// Camera pose of one frame from all its markers with known room poses:
/// every single-marker pose is tried as a start, each refined over all
/// corners (Levenberg-Marquardt), the lowest RMS kept. nullopt if no marker of
/// the frame is in `room_from_marker`. `rms_px` receives the final corner RMS.
std::optional<Rigid3d> CameraFromRoomFromMarkers(const std::vector<MarkerView>& frame_views,
                                                 const std::map<int, Rigid3d>& room_from_marker,
                                                 double marker_size_m,
                                                 const CameraIntrinsics& intrinsics,
                                                 double* rms_px = nullptr);

}  // namespace arpos
