#pragma once
/// Per-frame camera localisation against a room map (the scene-tracking half
/// of tracking mode): room_from_camera for every RGB-D frame.
///
/// Per frame:
///  1. prediction: constant-velocity motion model from the last two poses;
///  2. markers: in tracking, each map marker the predicted pose puts in view is
///     searched only in a window around its predicted corners (detection +
///     edge-fit corners, features/marker_detector.h); when lost, the whole
///     image is searched. Detections may also be passed in by a caller that
///     has them already (the tracking stage detects body markers anyway);
///  3. keypoints: grid-spread ORB with depth (keypoints.h); in tracking each
///     map landmark the prediction puts in view is matched to keypoints within
///     a search radius of its predicted pixel (descriptor distance, depth
///     agreement, ratio test); when lost, all keypoints are matched against the
///     map's adjusted landmarks (brute force, ratio test);
///  4. relocalisation (no usable prediction): best single-marker pose
///     (IPPE + depth) or PnP + RANSAC on keypoint matches;
///  5. refinement: marker corners and keypoints jointly (and keypoint depth),
///     Gauss-Newton with Huber/Tukey losses and a weak motion prior
///     (pose_refiner.h); a second matching pass at the refined pose;
///  6. acceptance: enough inliers (a fully seen marker whose corners alone
///     hold the pose within max_position_sigma_m, or min_keypoints), RMS
///     within bounds (markers_alone_must_hold);
///  7. while tracking, a frame the map does not place is followed from the
///     last frame it did (that frame's keypoints with depth, outside the
///     regions that move), its uncertainty carried on; or held by the
///     room's depth. Otherwise the frame is lost: no pose is reported and
///     nothing is guessed.
///
/// Frames: room = origin marker frame (DATASET.md); camera = OpenCV. Metres,
/// pixels of the frame's image. Thread-safety: one CameraLocalizer per thread.

#include <array>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "features/marker_detector.h"
#include "features/marker_pose.h"
#include "geometry/rigid3.h"
#include "room_map/keypoints.h"
#include "room_map/pose_refiner.h"
#include "room_map/room_map.h"
#include "sensor/case_config.h"
#include "sensor/intrinsics.h"
#include "sensor/rgbd_frame.h"

namespace arpos {

struct CameraLocalizerOptions {
  /// Room-marker detection (dictionary, room id range; see MakeCameraLocalizerOptions).
  MarkerDetectorOptions detector;
  MarkerPoseOptions marker_pose;
  KeypointOptions keypoints;
  PoseRefinerOptions refiner;

  bool use_markers = true;
  bool use_keypoints = true;
  /// Landmarks a session's body scan placed (RoomMap::scan_landmarks), for
  /// frames the room map alone does not place.
  bool use_scan_landmarks = true;
  /// Search markers only around their predicted corners while tracking
  /// (where the lens puts them; refined in the whole image).
  bool marker_windows = true;
  /// Window margin around the predicted marker: max(px, fraction * side).
  double window_margin_px = 16;
  double window_margin_fraction = 0.5;
  /// Markers predicted smaller than this (mean side, px) are not searched.
  double min_marker_side_px = 12;

  /// Pixel noise (1 sigma) of marker corners (floor; the edge fit's own sigma
  /// is used when larger) and of keypoints.
  double marker_corner_sigma_px = 0.15;
  /// Small projected marker cells are down-weighted (MarkerCornerSigmaPx).
  double marker_reference_cell_px = 4.0;
  double keypoint_sigma_px = 1.0;
  /// Keypoint landmarks carry correlated map errors (~1 px at the true pose
  /// on simulated cases) that fully refined markers do not: with markers in
  /// view keypoints are down-weighted, sigma * sqrt(1 + S) with
  /// S = sum over markers of (mean side / marker_support_side_px)^2.
  double marker_support_side_px = 15;
  /// Use measured depth at keypoints in the refinement, with
  /// sigma(z) = depth_sigma_const_m + depth_sigma_quad_per_m * z^2.
  bool use_keypoint_depth = true;
  double depth_sigma_const_m = 0.002;
  double depth_sigma_quad_per_m = 0.003;

  /// Depth pixels inside each refined marker against the mapped marker's
  /// plane: the depth sensor measures the marker's distance without the
  /// corner fit's scale bias. sigma(z) per pixel as below; the samples of one
  /// marker count as at most marker_depth_max_effective independent ones.
  bool use_marker_depth = true;
  int marker_depth_samples = 16;
  int marker_depth_max_effective = 8;
  double marker_depth_sigma_const_m = 0.001;
  double marker_depth_sigma_quad_per_m = 0.0015;
  /// The room's planes in depth: markers lying in one plane (the floor, a
  /// wall; at least room_plane_min_markers of them) make a plane of the map,
  /// and depth pixels that the first refinement puts on it (within
  /// max(room_plane_gate_m, 3 sigma(z)), within room_plane_support_m of one
  /// of its markers) constrain the camera's height and tilt against it.
  /// Sampled every room_plane_step_px pixels (at least width / 80); one plane's samples count as
  /// at most room_plane_max_effective independent ones (depth noise is
  /// partly smooth over the image).
  bool use_room_planes = true;
  int room_plane_min_markers = 2;
  /// ... spread over the plane in both directions: RMS of their corners
  /// along the plane's narrower extent at least this (a row of markers is
  /// left out).
  double room_plane_min_spread_m = 0.2;
  double room_plane_support_m = 2.0;
  double room_plane_gate_m = 0.03;
  int room_plane_step_px = 8;
  int room_plane_min_samples = 40;
  double room_plane_max_effective = 25;
  /// The room's still surface in depth (the map's RoomSurface, kept by the
  /// planning stage): the same grid's pixels that no plane took, put in the
  /// room by the first refinement, matched to a surface point near it
  /// (RoomSurfaceIndex) within room_surface_gate_m (or 3 sigma(z)) along
  /// its normal, seen at
  /// least room_surface_min_incidence (cosine) face-on. The samples are
  /// grouped by their normal's main room axis; a group counts as at most
  /// room_surface_max_effective independent samples.
  bool use_room_surface = true;
  double room_surface_gate_m = 0.03;
  /// A sample is used only when its distance from the surface agrees with
  /// the first refinement's pose within 3 sigma: its depth noise, the pose's
  /// own uncertainty there, and this much error of the surface's placement.
  /// (This keeps out what disagrees with a well-held pose; where the pose is
  /// itself weak, a surface the map placed centimetres off passes, which is
  /// why the plan keeps the surface near the couch only: RoomSurfaceOptions.)
  double room_surface_sigma_m = 0.002;
  /// Also when the plan found the depth biased and removed a correction
  /// (RoomMap::depth_correction). What a correction leaves is not known to
  /// the millimetre, and on the earliest random seeds with a depth scale
  /// error of 0.5-0.6 % the surface moved the camera by about 1 mm (camera
  /// at the isocentre over 6 sequences 1.27 mm without, 1.55 mm with); but
  /// where the camera has only far keypoints the surface is worth more than
  /// that: on 14 random seeds whose plans corrected the depth (444-463),
  /// tracking MTE 3.73 -> 3.46 mm mean, 11 better, frames lost 9.3 ->
  /// 8.3 %, frames above their stated bound 19 -> 12 (benchmark/accuracy.md,
  /// "The room's surface after a depth correction").
  bool room_surface_with_corrected_depth = true;
  double room_surface_min_incidence = 0.25;
  int room_surface_min_samples = 20;
  double room_surface_max_effective = 25;
  /// Tracking search: radius around the predicted pixel, descriptor distance,
  /// and the best/second-best ratio for a match.
  double search_radius_px = 15;
  double refined_search_radius_px = 4;
  int max_hamming = 64;
  double match_ratio = 0.9;
  /// Relocalisation, first from the last pose if it is at most this many
  /// frames old, searching landmarks within the wide radius...
  int recent_pose_max_frames = 30;
  /// A relocalised pose without a fully seen map marker is refused when it
  /// lies farther from the last localised pose (at most
  /// recent_pose_max_frames old) than a hand-held camera moves in the time
  /// between: speed * dt + margin, in position and in rotation. Keypoints
  /// alone can agree on a wrong place (repeated floor tiles: measured
  /// 0.4 m off with 38 inliers at 1 px, 1/6 s after a correct pose).
  double max_camera_speed_m_s = 1.0;
  double max_camera_jump_margin_m = 0.05;
  double max_camera_turn_deg_s = 60;
  double max_camera_turn_margin_deg = 5;
  double wide_search_radius_px = 50;
  /// A tracked keypoint-only pose on fewer inliers than this fraction of the
  /// last frame's is checked by the wide search from the last pose; the
  /// pose more keypoints agree on is kept (0: never; 1: whenever the
  /// support drops, about every other keypoint-only frame, +0.5-1 ms).
  double weak_tracking_fraction = 1.0;
  /// ... then by brute-force matching against the map's first landmarks
  /// (the adjusted ones, spread over the room: RoomMap), at most this many:
  /// matching every keypoint against all of a map's 12000+ landmarks took
  /// 60-70 ms a frame, a latency spike while the patient is shown.
  int relocalisation_max_landmarks = 4000;
  int relocalisation_max_hamming = 50;
  double relocalisation_ratio = 0.8;
  int ransac_iterations = 200;
  double ransac_threshold_px = 4.0;
  /// A relocalisation hypothesis from those matches needs this many PnP
  /// inliers; it is then refined by matching by projection over the whole
  /// map and accepted only as any pose is (min_keypoints, sigma, reach).
  int relocalisation_min_inliers = 10;

  /// Prior on the pose from the constant-velocity motion model (only while
  /// tracking): sigmas for frames 1/30 s apart, growing in proportion to the
  /// time since the last localised frame (the prediction gets worse).
  bool use_motion_prior = true;
  double motion_prior_sigma_m = 0.01;
  double motion_prior_sigma_deg = 0.5;
  /// Constant-velocity filter: once a pose has a covariance, the prior is
  /// the prediction with the covariance propagated from the last poses plus
  /// the motion a hand-held camera can add in the frame interval
  /// (acceleration * dt^2 / 2). The result is checked against what the frame
  /// alone says; if they disagree (chi-square, 6 dof, above
  /// filter_reset_chi2) the frame's own pose is used and the filter restarts.
  bool motion_filter = true;
  double motion_accel_m_s2 = 3.0;
  double motion_angular_accel_rad_s2 = 10.0;
  double filter_reset_chi2 = 22.5;
  /// Tracking continues from the last pose for this many lost frames, then
  /// the next frame is relocalised from scratch.
  int max_frames_lost_before_relocalising = 3;

  /// Acceptance: a frame is localised with at least this many inlier marker
  /// corners, or at least min_keypoints keypoint inliers ...
  int min_marker_corners = 4;
  int min_keypoints = 20;
  /// While tracking (matches found around a motion-predicted pose). Not
  /// fewer than when relocalising: measured with 12, tracking on l515 cases
  /// accepted poses 60-153 mm off on 12-15 keypoints.
  int min_keypoints_tracking = 25;
  /// ... and inlier RMS reprojection errors within these.
  double max_marker_rms_px = 1.5;
  double max_keypoint_rms_px = 2.5;
  /// ... and the pose's own 1-sigma position uncertainty (from the
  /// refinement's information matrix, camera axes, largest) below this (m).
  double max_position_sigma_m = 0.02;
  /// Room markers place a frame by themselves only when their corners alone
  /// hold the pose within max_position_sigma_m; otherwise the keypoints must
  /// (min_keypoints). Measured on a d435 case: a 22 px origin marker at 3 m
  /// (its corners alone 50-110 mm) with 5-19 keypoints gave poses 30-160 mm
  /// off at a stated 7-17 mm. The session's body scan turns it off: it
  /// places the scan by a robust mean over many frames, and there such
  /// frames (2-32 mm off on an xtion case) helped: the scan known to 2.09 mm
  /// at the stickers from 16 frames with them, 4.54 mm from 3 without.
  bool markers_alone_must_hold = true;
  /// ... and, for a pose found without a motion prior from keypoints alone
  /// (no fully seen marker), below this: keypoints on a far wall alone
  /// leave the classic sideways-shift / turn ambiguity (measured: 36 cm and
  /// 5.4 deg off at 3.5 m with 29 inliers at 1.2 px, reported sigma 13.6 mm).
  double max_relocalisation_position_sigma_m = 0.006;
  /// ... and within max_position_sigma_m still once this many keypoints,
  /// those that hold the pose most (greedily, each the one whose leaving out
  /// widens it most), are left out: one wrong match near the camera among
  /// keypoints on a far wall picks one pose of their shift/turn ambiguity
  /// and makes it look well conditioned (measured on a random d435 case: 1
  /// such match among 56, sigma 4.9 mm with it, 36.9 mm without it and the
  /// next, the pose 188 mm / 2.7 deg off). Right poses on 24-30 keypoints
  /// of a small case: 6.4-10.1 mm without their two. 0: off.
  int relocalisation_leave_out = 2;
  /// ... and, for such a pose, the frame's depth must not see through the
  /// room's still surface (RoomMap::surface, whatever the depth correction):
  /// of the surface points in view with a reading at their pixel (every
  /// k-th, at most relocalisation_surface_points), those whose reading lies
  /// beyond them by more than max(gate, 4 sigma(z)) must be fewer than
  /// relocalisation_surface_min_beyond or at most this fraction of those
  /// the reading agrees with or lies beyond (nearer readings are things in
  /// front: people, the patient). Measured on a d435 case: 31 keypoints in a
  /// strip along a far wall, 1-7 px from the truth, agreed on a pose turned
  /// 11.8 deg about that strip and 0.79 m off (reported sigma 2.9 mm),
  /// which tracking then followed for 55 frames.
  bool verify_relocalisation_with_surface = true;
  int relocalisation_surface_points = 4000;
  double relocalisation_surface_min_depth_m = 0.3;
  double relocalisation_surface_gate_m = 0.05;
  int relocalisation_surface_min_beyond = 30;
  double relocalisation_surface_max_beyond_fraction = 0.25;
  /// While tracking, a frame without a marker and with too few keypoints
  /// (a plain wall, the patient filling the view), which relocalisation does
  /// not place either, is still localised when the room's planes and surface
  /// in depth, with the motion filter's prediction, hold the pose: at least `min_depth_held_samples` depth
  /// samples matched and a 1-sigma position (filter and depth together)
  /// within `max_depth_held_position_sigma_m`. What depth does not fix (a
  /// direction along every face in view) keeps the prediction's growing
  /// uncertainty, so such a run ends by itself; at most
  /// `max_depth_held_frames` in a row.
  bool depth_held_tracking = true;
  int min_depth_held_samples = 150;
  double max_depth_held_position_sigma_m = 0.005;
  int max_depth_held_frames = 30;
  /// While tracking, a frame the map does not place (no room marker, the
  /// map's landmarks not in view: a part of the room the room recording
  /// did not cover) is followed from the last frame the map did place (the
  /// anchor): that frame's keypoints with depth, put in the room by its
  /// pose, outside the moving regions (SetMovingRegions: the couch and the
  /// patient), are matched by projection and the pose refined on them and
  /// the room's depth. Its uncertainty is the anchor's carried to this
  /// camera plus the frame's own against the anchor; at most
  /// `max_followed_s` after the map last placed a frame, at least
  /// min_keypoints_tracking inliers, and within max_position_sigma_m; such
  /// a frame is `followed` (LocalizationResult). When the inliers fall below
  /// twice that, the followed frame becomes the next anchor (its
  /// uncertainty, which grows, carried on).
  bool follow_room_keypoints = true;
  double max_followed_s = 4.0;
  double follow_min_depth_m = 0.3;
  double follow_max_depth_m = 4.0;
  /// A frame the map places stays out of the anchor's place while the
  /// anchor is at most `anchor_keep_s` old and the frame's position sigma is
  /// above `anchor_keep_ratio` times the anchor's.
  double anchor_keep_s = 1.0;
  double anchor_keep_ratio = 1.5;

  std::string Validate() const;
  bool Check(std::string* reason = nullptr) const;
};

/// Options for a case: dictionary and room id range from case.yaml.
CameraLocalizerOptions MakeCameraLocalizerOptions(const CaseConfig& config);

enum class LocalizationStatus {
  kTracked = 0,      ///< from the motion-predicted pose
  kRelocalized = 1,  ///< found without a prediction (first frame, after loss)
  kLost = 2,         ///< no pose: too few markers/keypoints agree
};
const char* LocalizationStatusName(LocalizationStatus status);

/// Time per step, milliseconds of this thread's CPU time.
struct LocalizationTimings {
  double detection_ms = 0;   ///< marker detection and corner refinement
  double keypoints_ms = 0;   ///< grey conversion, keypoint extraction and depth
  double matching_ms = 0;    ///< landmark search (tracking) or brute force (relocalisation)
  double pnp_ms = 0;         ///< relocalisation hypotheses (IPPE / PnP RANSAC)
  double refinement_ms = 0;  ///< joint non-linear refinement(s)
  double total_ms = 0;
  /// Step by step sum (two localisations of one frame).
  LocalizationTimings& operator+=(const LocalizationTimings& o) {
    detection_ms += o.detection_ms;
    keypoints_ms += o.keypoints_ms;
    matching_ms += o.matching_ms;
    pnp_ms += o.pnp_ms;
    refinement_ms += o.refinement_ms;
    total_ms += o.total_ms;
    return *this;
  }
};

struct LocalizationResult {
  bool ok = false;
  Rigid3d room_from_camera;  ///< meaningful only when ok
  LocalizationStatus status = LocalizationStatus::kLost;
  int markers_used = 0;      ///< markers with all 4 corners inliers
  int keypoints_used = 0;    ///< keypoint inliers
  /// Of keypoints_used, those on landmarks a body scan placed
  /// (RoomMap::scan_landmarks): they carry the scan's placement in the room.
  int scan_keypoints_used = 0;
  /// Depth samples matched to the map's planes and to its surface (0: none
  /// used, or no depth).
  int plane_depth_samples = 0;
  int surface_depth_samples = 0;
  /// Tracked on the room's depth and the motion filter alone (no marker,
  /// too few keypoints): options.depth_held_tracking.
  bool held_by_depth = false;
  /// Followed from the last frame the map placed by the room's keypoints
  /// (options.follow_room_keypoints), `followed_s` after it; the pose's
  /// sigmas include that frame's.
  bool followed = false;
  double followed_s = 0;
  /// The pose descends from a relocalisation by keypoints alone (at the
  /// start or after a loss), and no room marker has been used since: keypoints can
  /// agree on a wrong place (a repeating floor pattern: measured 0.75 m off
  /// with a 2 mm sigma), so such a pose is not to be trusted within a
  /// tolerance until a marker confirms it.
  bool unconfirmed = false;
  double rms_px = 0;         ///< RMS reprojection error over all inliers
  double marker_rms_px = 0;
  double keypoint_rms_px = 0;
  /// 1-sigma position uncertainty of the camera (largest axis, mm) and
  /// rotation uncertainty (deg) from the refinement's information matrix.
  double position_sigma_mm = 0;
  double rotation_sigma_deg = 0;
  /// The same from the corners of the room markers seen whole alone
  /// (infinite: none). Markers place a frame by themselves only when this
  /// is within max_position_sigma_m; otherwise the keypoints must.
  double marker_position_sigma_mm = std::numeric_limits<double>::infinity();
  /// The pose's full covariance: a left perturbation [rotation; translation]
  /// of camera_from_room (a point p in the camera moves by -[p]x w + dt),
  /// the sigmas above its blocks' largest axes; valid when has_covariance.
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();
  bool has_covariance = false;
  /// 1-sigma error (mm, root of the summed variances of its three axes)
  /// that this pose gives the room position of a point seen at
  /// `point_in_camera` (metres): the camera's share of a patient's error
  /// there. The camera's position and rotation errors largely cancel at
  /// the points the camera sees, so this is well below
  /// hypot(position_sigma_mm, rotation_sigma x distance), which treats them
  /// as independent (SeparateSigmasMm), which is returned when there is
  /// no covariance.
  double PointSigmaMm(const Eigen::Vector3d& point_in_camera) const;
  /// position_sigma_mm and rotation_sigma_deg swinging the point at its
  /// distance, added as if independent (mm): an upper bound of the above.
  double SeparateSigmasMm(const Eigen::Vector3d& point_in_camera) const;
  std::string message;       ///< why, when lost
  LocalizationTimings timings;
  /// The room markers found in this frame (image pixels), for callers that
  /// need them (overlay, audit).
  std::vector<MarkerObservation> markers;
  /// Room markers (ids in the case's room range) read in this frame that the
  /// map does not hold (left out of it, or never seen while mapping): what a
  /// caller names when the frame cannot be placed.
  std::vector<int> unmapped_marker_ids;
  /// Depth of another instant than the colour: the camera's motion between
  /// them as the room's depth measured it (on the left perturbation of
  /// camera_from_room, i.e. in the camera's axes), for the body tracker to
  /// take the frame's depth of the patient at.
  std::optional<DepthCameraMotion> depth_camera_motion;
};

class CameraLocalizer {
 public:
  /// `intrinsics` of the frames to come. Throws arpos::Error for invalid
  /// options or intrinsics, InputError for an unusable map.
  CameraLocalizer(RoomMap map, const CameraIntrinsics& intrinsics,
                  const CameraLocalizerOptions& options);
  ~CameraLocalizer();
  CameraLocalizer(const CameraLocalizer&) = delete;
  CameraLocalizer& operator=(const CameraLocalizer&) = delete;

  /// Localises one frame (colour CV_8UC3 BGR or CV_8UC1, depth CV_16UC1 or
  /// empty). Throws arpos::Error for frames of the wrong type or size.
  LocalizationResult Localize(const RgbdFrame& frame);
  /// Same, with room-marker detections made by the caller on this frame
  /// (image pixels, any ids: those not in the map are ignored). Skips the
  /// localiser's own marker detection. For accurate corners the caller's
  /// detector should refine under the recording's camera response
  /// (options.detector.edge.response), as the localiser's own detection does.
  LocalizationResult Localize(const RgbdFrame& frame,
                              const std::vector<MarkerObservation>& detections);

  /// Forgets the motion model: the next frame is relocalised.
  void Reset();
  /// Where the camera is about to be by other means (e.g. the patient seen
  /// in the last frame and its room pose predicted or expected): if the
  /// next frame must be relocalised, the landmarks are first searched
  /// around this pose (the wide radius), before the whole map. A start
  /// only: the pose found must pass the same acceptance, and the last pose
  /// this localiser found stays its reference. Used by one frame.
  void SuggestSearchStart(const Rigid3d& room_from_camera);
  /// Regions of the room that move (the couch top and the patient, e.g.
  /// CouchExclusionBox at the planned and at the last known pose): the
  /// room is not followed by keypoints inside them. Until this is called
  /// frames are not followed (options.follow_room_keypoints): only a caller
  /// that knows what moves in the room turns it on.
  void SetMovingRegions(std::vector<ExclusionBox> regions);

  const RoomMap& map() const { return map_; }
  const CameraLocalizerOptions& options() const { return options_; }

 private:
  LocalizationResult Run(const RgbdFrame& frame, const std::vector<MarkerObservation>* detections);
  struct Impl;
  RoomMap map_;
  CameraLocalizerOptions options_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace arpos
