#pragma once
/// Builds the room map (room_map.h) from the planning sequence `room/`.
///
/// Steps:
///  1. per frame (in parallel): room-marker detection with edge-fit corners
///     (features/marker_detector.h), single-marker poses (IPPE, both solutions,
///     error-ratio test and depth: features/marker_pose.h), depth samples
///     inside each marker, grid-spread ORB keypoints with depth (keypoints.h);
///  2. marker poses initialised by a MarkerMapper-style pose graph
///     (marker_graph.h), camera poses from all their markers;
///  3. bundle adjustment over markers and cameras (corners + marker-plane depth);
///  4. keypoint landmarks: back-projected with depth, associated across frames
///     by projection and descriptor, frames without markers posed by PnP on
///     the landmarks; landmarks seen often enough, outside the exclusion
///     boxes (things that move during treatment: the couch top), thinned to a
///     few thousand spread over the room;
///  5. joint bundle adjustment (markers, cameras, landmarks; reprojection +
///     depth), outlier observations dropped, adjusted again; then the
///     candidates the thinning left out are triangulated against the
///     adjusted cameras and kept for localisation only (many more landmarks
///     for keypoint-only tracking frames, at no cost to the adjustment);
///  6. residuals per marker and overall, and the depth scale check (measured
///     depth in markers / depth the map predicts: 1.000 if consistent).
///
/// Frames: the result is in the room frame, the origin marker's. Units SI.

#include <filesystem>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "controllers/controller.h"
#include "features/marker_detector.h"
#include "features/marker_pose.h"
#include "features/response_from_recording.h"
#include "room_map/bundle_adjustment.h"
#include "room_map/keypoints.h"
#include "room_map/room_map.h"
#include "room_map/room_planes.h"
#include "sensor/case_config.h"
#include "sensor/sequence.h"

namespace arpos {

/// Of a marker's two IPPE solutions (camera_from_marker), the one whose plane
/// the depth around the marker (the floor or wall it lies on) agrees with:
/// Cauchy-weighted depth residuals over the sensor's noise; nullopt unless
/// one explains the depth clearly better (cost ratio >= 2) and at least 50
/// samples lie on its plane. One small, oblique view cannot tell its two
/// solutions apart by reprojection, and the few depth pixels inside a 20 px
/// marker cannot either; the plane around it can. Each solution's plane is
/// taken with its orientation and the offset the depth gives it (the
/// median along its normal): such a view's distance is the weakest part of
/// its pose (random seed 402, a 31 px origin at 59 deg: with the pose's own
/// offset 44 and 62 of 2335 samples lay within 3 sigma of either plane).
std::optional<int> SolutionBySupportDepth(const MarkerPose& pose,
                                          const std::vector<DepthSample>& samples,
                                          const CameraIntrinsics& K, const BaOptions& ba_options);

struct RoomMapBuildOptions {
  /// Depth of another instant than its colour (sensor/depth_timing.h): once
  /// every frame is placed (markers, then keypoints), each such frame's
  /// depth is read again as of its colour instant (DepthAtColourInstant) by
  /// the camera's motion between the frames placed around it
  /// (ColourFromDepthCamera), before depth enters the adjustment; the room
  /// surface likewise. Off: used as read.
  bool move_delayed_depth = true;
  /// The poses that motion is taken from: the markers and keypoints alone
  /// adjusted, at most this many iterations.
  int delayed_depth_pose_iterations = 10;

  /// Room-marker detection; dictionary and id range are taken from the case
  /// by MakeRoomMapBuildOptions.
  MarkerDetectorOptions detector;
  MarkerPoseOptions marker_pose;
  KeypointOptions keypoints;
  BaOptions bundle_adjustment;

  /// Estimate the camera's response from the room sequence's markers
  /// (features/response_from_recording.h) and refine corners under it; when
  /// the data cannot tell, or when off, `detector.edge.response` is used.
  bool estimate_response = true;
  /// Check the depth against the markers (after a markers-only adjustment
  /// without depth terms) and remove a systematic error the data show
  /// (sensor/depth_correction.h) before depth enters the map.
  bool estimate_depth_correction = true;
  /// The depth check reads the depth on the planes the markers span too
  /// (floor, walls: at least room_plane_min_markers markers), within this
  /// distance of one of the plane's markers; 0: inside the markers only.
  /// (Depth error left at 1 m over 17 random xtion rooms with an error:
  /// 0.79 mm RMS mean inside the markers only; 0.51, 0.52, 0.54, 0.62 and
  /// 0.67 mm within 0.3, 0.4, 0.5, 0.75 and 1 m: the planes' own tilt tells
  /// farther out.)
  double depth_check_plane_support_m = 0.5;
  /// Depth readings that spread around the colour geometry by more than
  /// this many times the sensor model's noise are weighted as that spread.
  double depth_inflation_threshold = 1.5;
  /// With the standard curves tried when the response cannot be estimated
  /// (RecordingResponseOptions::standard_curves).
  RecordingResponseOptions response = [] {
    RecordingResponseOptions o;
    o.standard_curves = {"linear", "gamma1.6", "srgb", "gamma2.6"};
    return o;
  }();
  int frame_step = 1;   ///< use every n-th frame
  int max_frames = 0;   ///< 0 = all
  int threads = 2;      ///< frame processing
  /// Threads of the bundle adjustments (Ceres). One: Ceres's Schur
  /// elimination sums in thread order, so with two the same recording gave
  /// different plans from run to run (a random d435 room: 3146 and 3131
  /// landmarks, the couch position 2.77 and 2.95 mm, and its tracking 84 or
  /// 100 % lost); with one, identical plans, the 240-frame room sweep's
  /// adjustment 7.5 -> 7.9 s.
  int adjustment_threads = 1;

  /// Corner noise floor (px): the edge fits' own sigma is used when larger.
  double marker_corner_sigma_px = 0.1;
  /// Corners of markers with small projected cells are down-weighted (see
  /// MarkerCornerSigmaPx); 0 disables.
  double marker_reference_cell_px = 4.0;
  /// Only markers whose corners refined fully (MarkerStatus::kRefined) are
  /// used; single-view poses must also pass this reprojection RMS (px).
  double max_marker_view_rms_px = 2.0;
  /// Markers seen in fewer views are left out of the map (a marker seen once
  /// fits its one view exactly but its pose is poorly determined: ~1 cm).
  int min_marker_observations = 3;
  /// Depth samples kept per marker view for the plane term and scale check.
  int marker_depth_samples = 16;

  bool use_keypoints = true;
  double keypoint_sigma_px = 0.7;
  /// Association: a keypoint joins a landmark projected within this radius,
  /// with a descriptor within this Hamming distance, and a back-projected
  /// point within max(3 sigma(z), association_min_distance_m).
  double association_radius_px = 4.0;
  int max_hamming = 50;
  double association_min_distance_m = 0.01;
  int min_landmark_observations = 3;
  /// A frame without known markers is placed by PnP on the keypoints of the
  /// placed frames around it, matched by descriptor with a ratio test; 20
  /// inliers place it. With fewer (6-19: a wide step between frames, a
  /// repeating tiled floor), the pose they give is used to search those
  /// frames' keypoints again by projection (within 8 then 4 px, at a depth
  /// the frame's own reading agrees with, a ratio test among the candidates
  /// there), and 15 inliers of that search place it. Seed 13 of the random
  /// conditions with an sRGB camera: the walk's last eight frames (the
  /// origin alone on a bare floor) are placed only this way.
  bool keypoint_search_by_projection = true;
  int max_landmarks = 4000;
  /// Landmarks are thinned over a voxel grid of this size for spread.
  double landmark_voxel_m = 0.1;
  /// Candidates the thinning left out (seen often enough, outside the
  /// exclusion boxes) are triangulated afterwards against the adjusted,
  /// fixed cameras and kept for localisation only (they do not shape the
  /// map), at most this many, most-seen first. Keypoint-only tracking
  /// frames need them: on a 300-frame xtion room the camera at the
  /// isocentre was 2.22 mm off with the adjusted 4000, 1.29 mm with 8000
  /// and 1.04 mm with 12000 in the adjustment (47 -> 65 s to build).
  int max_localization_landmarks = 12000;
  std::vector<ExclusionBox> exclude_landmarks;

  /// Where the patient will be (room frame; the plan's isocentre), and how
  /// weak a room frame may be there before the build warns (1 sigma).
  Eigen::Vector3d couch_point_in_room = Eigen::Vector3d::Zero();
  double max_room_frame_tilt_sigma_deg = 0.05;
  double max_room_frame_couch_sigma_mm = 0.5;
  /// When the origin's own tilt is weaker than the tolerance, fuse the plane
  /// of the markers coplanar with it (within 5 deg and 3 cm), allowing this
  /// much unflatness of the floor or wall (m, 1 sigma).
  bool use_coplanar_markers = true;
  double coplanar_flatness_m = 0.002;
  /// Fuse also when the tilt is within its tolerance but the room frame is
  /// weaker than max_room_frame_couch_sigma_mm at the couch (the tilt acts
  /// over the origin's distance to the couch). Measured on 56 simulated
  /// cases: the couch sigma of 5 of them 0.6-0.7 times what it was, their
  /// markers near the couch as close or closer, none worse.
  bool fuse_tilt_when_weak_at_couch = true;
  /// And the plane the origin lies on as depth sees it around it (the floor
  /// or the wall): depth on a grid of at most `support_plane_samples` over
  /// +-`support_plane_half_width_m` about the origin in each view of it,
  /// placed by the adjusted cameras, fitted robustly; its tilt uncertainty
  /// is the larger of the fit's and the spread between views. Off: on 20
  /// random xtion scenes it did not help on balance, because an
  /// undetected depth error field (1.9 mm at 1 m on one seed) tilts the
  /// plane by 0.2 deg, more than the origin's own corners do
  /// (benchmark/accuracy.md, "What limits a far origin, and what was tried").
  /// (The samples are taken whatever this says: they also settle which of
  /// its two single-view poses a lone, ambiguous view of the origin has.)
  bool use_support_plane = false;
  double support_plane_half_width_m = 0.5;
  int support_plane_samples = 2500;
  /// Depth bias left after the correction tilts the support plane in a way
  /// no fit shows: its tilt is taken as known to no better than this over
  /// the square root of the views (deg, 1 sigma).
  double support_plane_min_sigma_deg = 0.02;

  /// The room's planes in the joint adjustment: markers lying in one plane
  /// (at least room_plane_min_markers, spread room_plane_min_spread_m RMS
  /// across; room_planes.h) make a plane, adjusted with the map; each
  /// frame's depth pixels on it (a grid of about 80 across the image, within
  /// room_plane_gate_m or 3 sigma of it at the frame's pose, within
  /// room_plane_support_m of one of its markers, fitted again as the frame
  /// sees the plane and its outliers left out) tie the frame's tilt and
  /// distance to it, at most room_plane_max_samples a view counting as
  /// room_plane_max_effective independent ones.
  bool use_room_planes = true;
  /// The origin's own plane (the floor or wall around it) is one even
  /// without other markers in it; and the markers of a plane lie on it
  /// (centres within room_plane_flatness_m, normals along the plane's within
  /// room_plane_marker_tilt_deg, 1 sigma; 0: not tied): the depth of every
  /// view of that floor or wall then holds the origin's tilt, not its few
  /// pixels alone.
  bool room_plane_for_origin = true;
  bool room_plane_ties_markers = true;
  double room_plane_flatness_m = 0.002;
  double room_plane_marker_tilt_deg = 0.03;
  int room_plane_min_markers = 2;
  double room_plane_min_spread_m = 0.2;
  double room_plane_support_m = 2.0;
  double room_plane_gate_m = 0.03;
  int room_plane_min_samples = 40;
  int room_plane_max_samples = 200;
  double room_plane_max_effective = 25;
  /// Planes found in the depth itself join them after the first adjustment
  /// (room_planes.h, AddDepthPlanes; depth read up to
  /// room_plane_depth_max_m): walls without markers, the floor beyond its
  /// markers' reach. A frame that sees the floor and a wall has its whole
  /// turn tied to the room, not only its tilt, so the chain of frames from a
  /// far origin to the couch cannot turn about the vertical. The origin's
  /// own plane is not extended (AddDepthPlanes says why).
  bool room_planes_from_depth = true;
  double room_plane_depth_max_m = 3.5;
  DepthPlaneOptions depth_planes;

  /// Observations with a reprojection error above this many sigmas after the
  /// first joint adjustment are dropped before the second.
  double outlier_sigmas = 4.0;
  /// Keep the room's still surface near couch_point_in_room (outside the
  /// exclusion boxes) from the room frames' depth, placed by the adjusted
  /// cameras, for the localiser to register depth to (room_surface.h).
  bool build_surface = true;
  RoomSurfaceOptions surface;

  std::string Validate() const;
  bool Check(std::string* reason = nullptr) const;
};

/// Options for a case: dictionary, room id range and intrinsics from `config`.
RoomMapBuildOptions MakeRoomMapBuildOptions(const CaseConfig& config);

struct RoomMapBuildReport {
  int frames_total = 0;
  int frames_used = 0;          ///< frames with a camera pose in the final adjustment
  int frames_with_markers = 0;  ///< frames seeing at least one usable room marker
  int frames_posed_by_keypoints = 0;
  int marker_views = 0;
  int ambiguous_marker_views = 0;  ///< single-view poses rejected (ambiguous / depth mismatch)
  /// Views read whose edge lines could not be fitted (motion blur, defocus,
  /// cells of a pixel or two): not used, counted apart from marker_views.
  int unrefined_marker_views = 0;
  std::vector<int> unconnected_markers;  ///< seen but not linked to the origin: not in the map
  std::vector<int> sparse_markers;       ///< seen in too few views: not in the map
  int landmark_candidates = 0;
  int landmarks_excluded = 0;   ///< inside an exclusion box
  int landmarks = 0;
  int localization_landmarks = 0;  ///< of `landmarks`, placed after the adjustment (localisation only)
  int keypoint_observations = 0;
  double marker_rms_px = 0;     ///< over all marker corner observations
  double keypoint_rms_px = 0;   ///< over kept keypoint observations
  double keypoint_depth_rms_m = 0;
  /// Median over marker views of measured depth / map-predicted depth
  /// inside the marker (1.000 = consistent scale), and its robust spread.
  double depth_scale_ratio = 0;
  double depth_scale_ratio_mad = 0;
  BaSummary marker_adjustment;
  BaSummary joint_adjustment;
  double frames_s = 0, initialisation_s = 0, landmarks_s = 0, adjustment_s = 0, total_s = 0;
  std::vector<std::string> warnings;
  /// How the camera response was found (estimated, or assumed and why).
  std::string camera_response;
  /// The depth check against the markers, and the correction if one was made.
  std::string depth_correction;
  /// The room's planes in the joint adjustment (empty: not used).
  std::string room_planes;
  /// Views whose depth of the origin's plane (tied to it in the
  /// adjustment) went into the room frame's tilt uncertainty; 0: none.
  int origin_plane_views = 0;
  /// The room frame's own uncertainty (1 sigma): the origin marker's pose
  /// from its views given the adjusted cameras; tilt about the marker's
  /// in-plane axes, yaw about its normal, and the position error this
  /// gives at options.couch_point_in_room.
  int origin_observations = 0;
  double room_frame_tilt_sigma_deg = std::numeric_limits<double>::infinity();
  double room_frame_yaw_sigma_deg = std::numeric_limits<double>::infinity();
  double room_frame_couch_sigma_mm = std::numeric_limits<double>::infinity();
  /// The origin marker pose's covariance (rotation vector rad, translation
  /// m; room frame); infinite when it has no observation.
  Eigen::Matrix<double, 6, 6> room_frame_covariance =
      Eigen::Matrix<double, 6, 6>::Constant(std::numeric_limits<double>::infinity());
  /// Markers coplanar with the origin whose plane was fused into the room
  /// frame's tilt (0: not used).
  int coplanar_markers = 0;
  /// The origin's support plane in depth (0 views: not used): views and
  /// depth points fitted, its own tilt uncertainty (1 sigma) and its tilt
  /// from the origin marker's as first adjusted.
  int support_plane_views = 0;
  int support_plane_points = 0;
  double support_plane_tilt_sigma_deg = std::numeric_limits<double>::infinity();
  double support_plane_offset_deg = 0;
  /// How far the fused planes turned the room frame (deg; 0: not turned).
  double room_frame_turn_deg = 0;
  /// The map near the couch relative to the origin marker (1 sigma, mm):
  /// the median, over the markers within 1.5 m of the couch point (or the
  /// nearest marker), of the uncertainty of the marker's centre in the
  /// origin's frame, marginal over everything the last joint adjustment
  /// estimates (cameras, landmarks, planes, other markers): the chain of
  /// frames between a far origin and the couch, which the room frame's own
  /// figure above leaves out. Infinite when not computed.
  double map_couch_sigma_mm = std::numeric_limits<double>::infinity();
  /// And their orientation relative to the origin marker's (1 sigma, deg,
  /// medians over the same markers): about the origin's in-plane axes (the
  /// larger of the two) and about its normal. Where the markers near the
  /// couch are linked to the origin through frames and other markers, the
  /// chain adds its own turn to the origin's: on 28 random plans the
  /// tilt near the couch was 1.4-3.6 times (median 1.95) the origin's own,
  /// and the map's turn against the truth beyond 3 of the origin's own
  /// sigmas on 3 of them, on none against the larger of the two
  /// (benchmark/accuracy.md, session 33).
  double map_couch_tilt_sigma_deg = std::numeric_limits<double>::infinity();
  double map_couch_yaw_sigma_deg = std::numeric_limits<double>::infinity();
  int map_couch_markers = 0;
  /// Landmarks seen in two frames only, kept because they tie groups of
  /// frames that nothing else in the adjustment ties (0: none needed).
  int landmarks_joining_groups = 0;
  double map_couch_covariance_s = 0;
  /// The larger of the two: how well the couch's position in the room
  /// frame is known (what the plan stores and tracking adds to its bounds).
  double CouchSigmaMm() const { return LargerWhereComputed(room_frame_couch_sigma_mm, map_couch_sigma_mm); }
  /// The same for the orientation: the larger of the origin's own tilt
  /// (yaw) and the map's near the couch relative to it (what the plan
  /// stores and tracking adds to its rotation bounds).
  double CouchTiltSigmaDeg() const { return LargerWhereComputed(room_frame_tilt_sigma_deg, map_couch_tilt_sigma_deg); }
  double CouchYawSigmaDeg() const { return LargerWhereComputed(room_frame_yaw_sigma_deg, map_couch_yaw_sigma_deg); }
  /// `own` (the origin's), or `near_couch` (the map's) when it was computed
  /// (finite) and larger.
  static double LargerWhereComputed(double own, double near_couch) {
    return std::isfinite(near_couch) ? std::max(own, near_couch) : own;
  }
  /// 1-sigma position error (mm) the room frame's uncertainty gives at a point.
  double RoomFramePositionSigmaMm(const Eigen::Vector3d& point_in_room) const;
  RoomSurfaceReport surface;
  /// Camera poses of the used frames (sequence index, room_from_camera).
  std::vector<std::pair<int, Rigid3d>> room_from_camera;
  /// Depth of another instant than its colour: the median delay (s) and the
  /// frames whose depth was read as of its colour instant
  /// (RoomMapBuildOptions::move_delayed_depth), of those with delayed depth.
  double depth_delay_s = 0;
  int frames_depth_moved_to_colour = 0, frames_depth_delayed = 0;
  double depth_move_s = 0;  ///< reading that depth again, included in adjustment_s and total_s

  std::string ToText() const;
};

struct RoomMapBuildResult {
  RoomMap map;
  RoomMapBuildReport report;
};

/// Builds the map of `sequence` (the room/ folder of a case with `config`).
/// Depth of another instant than its colour: read as of its colour instant
/// (RoomMapBuildOptions::move_delayed_depth).
/// Throws InputError naming the file for unreadable frames, and when the
/// origin marker is never seen (the room frame would be undefined) or no
/// usable marker is found; Cancelled if `callbacks.cancel_requested` says so.
RoomMapBuildResult BuildRoomMap(const Sequence& sequence, const CaseConfig& config,
                                const RoomMapBuildOptions& options,
                                const ControllerCallbacks& callbacks = {});

}  // namespace arpos
