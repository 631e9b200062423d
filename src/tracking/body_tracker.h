#pragma once
/// Patient (reference model) pose in the camera frame, frame after frame: the
/// body half of tracking mode.
///
/// Per frame:
///  1. stickers: the session's body stickers are detected in a window around
///     where the model was last seen (the whole image after a loss);
///  2. start: the candidate pose (the prediction from the last two poses, or
///     a single sticker's own pose, IPPE + depth) that explains every
///     sticker's corners best;
///  3. joint refinement (Gauss-Newton, left perturbation in the camera frame)
///     of the sticker corners (pixels, each with its edge-fit sigma) and the
///     depth against the model's surface points the camera sees
///     (point-to-plane along the model normal, projective association:
///     each visible model point meets the depth pixel it projects to; hidden
///     points removed with a coarse z-buffer, the surface sampled every few
///     mm so close vertices are merged). Depth errors are partly systematic,
///     so all depth terms together count as at most `depth_max_effective`
///     independent readings; a robust kernel keeps breathing, hands and
///     flying pixels from pulling the pose;
///  4. a sticker that disagrees with the others and the surface (moved, fell
///     off, misread) is dropped and the fit repeated;
///  5. acceptance: two stickers, or one with the surface, or, for at most
///     `max_frames_without_stickers` frames, the surface alone from the
///     predicted pose ("carried", and said so). A frame that fails so while
///     tracking is tried once more: from the prediction alone when one
///     sticker's pose put the model off the surface, with the whole image
///     searched when no window held a sticker. Otherwise the patient is lost
///     and nothing is guessed.
/// The pose's covariance comes from the refinement's information matrix,
/// scaled up by the residuals when they exceed their sigmas.
///
/// Frames: camera = OpenCV; model = the reference model's frame (metres).
/// Thread-safety: one BodyTracker per thread; it may run beside a
/// CameraLocalizer on another thread.

#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "features/marker_detector.h"
#include "features/marker_pose.h"
#include "geometry/rigid3.h"
#include "geometry/triangle_mesh.h"
#include "sensor/depth_timing.h"
#include "sensor/intrinsics.h"
#include "sensor/rgbd_frame.h"

namespace arpos {

struct BodyTrackerOptions {
  /// Sticker detection (dictionary, the body id range, the recording's response).
  MarkerDetectorOptions detector;
  MarkerPoseOptions marker_pose;
  double marker_size_m = 0.03;

  /// The model's surface sampled every this many metres (vertices merged).
  double model_spacing_m = 0.008;
  /// Hidden-point removal: z-buffer cells (px) and the depth tolerance behind
  /// the nearest surface point of a cell.
  int zbuffer_cell_px = 4;
  double zbuffer_tolerance_m = 0.012;
  /// At most this many visible model points enter the fit (evenly thinned).
  int max_depth_points = 1000;
  bool use_depth = true;

  /// Corner noise floor (px, 1 sigma); the edge fit's own sigma when larger.
  double corner_sigma_px = 0.15;
  /// Depth noise per reading, sigma(z) = const + quad * z^2, and the number
  /// of independent readings all depth terms together are worth (300: the
  /// still surface holds a breathing patient against the stickers on the
  /// chest; measured on six simulated cases with 3.5-5.7 mm of breathing,
  /// the patient's error 1.04-3.35 mm -> 0.74-3.02 mm against 60, and within
  /// 0.03 mm on the default and --hard cases).
  double depth_sigma_const_m = 0.001;
  double depth_sigma_quad_per_m = 0.0015;
  int depth_max_effective = 300;
  /// Association gate (model point to its depth reading) at the first
  /// iteration and from the third on.
  double depth_gate_initial_m = 0.03;
  double depth_gate_final_m = 0.012;
  /// Huber threshold on normalised residuals (sigmas), corners and depth.
  double huber_sigmas = 2.5;
  int max_iterations = 10;
  /// Converged when an update moves less than both (10 um, 0.0006 deg).
  double convergence_m = 1e-5;
  double convergence_rad = 1e-5;
  /// Start pose: a candidate's cost is its stickers' corner RMS (px, each
  /// capped at 30) plus this many px times the share of the model's surface
  /// that disagrees with the depth.
  double start_depth_weight_px = 10;
  /// After the first fit, each mapped sticker ArUco did not read is refined
  /// at its projected corners; kept when its corners moved at most
  /// max(px, fraction * side) from the projection.
  double max_refinement_shift_px = 1.5;
  double max_refinement_shift_fraction = 0.12;
  /// Starting from a hint (no sticker read, no recent pose), the surface
  /// fit leaves the pose free to slide along the body by a few mm, beyond
  /// the refinement's reach on 10-15 px stickers: the stickers are then
  /// refined at the fitted pose shifted across the view by the offsets of
  /// a grid of this step (mm) and half-width (steps), ring by ring from the
  /// centre; after the first ring where a shift refines at least 2, the
  /// shift that refines the most is kept. 0 steps: off. Each shift
  /// refines only the `hint_search_stickers` largest stickers in view (0:
  /// all), the kept shift then every sticker: a patient whose stickers no
  /// shift refines (beyond their range) costs a frame 48 shifts of every
  /// sticker otherwise (measured on a random-conditions d435 sequence with
  /// 11 stickers of 10-20 px: 514 refinements, ~130 ms a frame).
  double hint_search_step_mm = 2.0;
  int hint_search_steps = 3;
  int hint_search_stickers = 4;

  /// A sticker whose corner RMS exceeds this after the fit is dropped.
  double max_sticker_rms_px = 1.2;
  /// Breathing (from the session: body_model/surface_motion.h). Per sticker
  /// id, how far it moves with the breathing (1 sigma, m), along its normal
  /// or along `sticker_motion_direction`: its four corners share that
  /// uncertainty along that way (marginalised in the fit), so the still
  /// stickers and the still surface decide the pose in that direction while
  /// a moving sticker still holds the others. Stickers not listed do not
  /// move.
  std::map<int, double> sticker_motion_m;
  /// Which way each of them moves, a unit vector in the sticker's own frame,
  /// where the session measured it (body_model/sticker_motion.h); a moving
  /// sticker not listed moves along its normal, (0, 0, 1).
  std::map<int, Eigen::Vector3d> sticker_motion_direction;
  /// ... and they rise together: one rise per frame, shared by the moving
  /// stickers (each by its motion_m times it), is estimated with the pose
  /// and left out of it (sticker_terms.h), with this prior (1 sigma, in
  /// units of the stickers' motion_m; 0: off, each sticker on its own).
  /// Measured on six simulated cases with breathing: 1 lowers the patient's
  /// error on every one (with depth_max_effective 300: 0.74 -> 0.60 mm on
  /// the largest change); 3 made one case worse (0.60 -> 1.20 mm, 8 frames
  /// lost): a chest that does not rise along the stickers' normals.
  double shared_breathing_sigmas = 1;
  /// Centres of the surface patches (model frame, cubes of
  /// `moving_surface_patch_m`) that moved during the scan: model points in
  /// them are left out of the depth term.
  std::vector<Eigen::Vector3d> moving_surface_patches;
  double moving_surface_patch_m = 0.04;
  /// While tracking, each sticker is searched in a window around its
  /// predicted corners (margin: max(this, 0.75 side), px), upsampled so the
  /// sticker is about `detection_side_px` across for ArUco (at most 4x), its
  /// corners then refined on the frame itself; stickers predicted smaller
  /// than `min_sticker_side_px` are not searched. Without a prediction the
  /// whole image is searched.
  double sticker_window_margin_px = 12;
  /// At most this many stickers (the largest predicted) are searched so.
  int max_stickers_searched = 4;
  double detection_side_px = 30;
  double min_sticker_side_px = 6;
  /// A sticker refined where the pose puts it whose edge lines cannot be
  /// fitted (cells of a pixel or two), or fitted beyond their reach, and
  /// whose side is at most this (px) is located by its whole pattern
  /// instead (features/marker_template.h); 0: never. It is searched over
  /// `template_max_shift_fraction` of its side (and, from a hint, as far as
  /// the hint search's rings reach) and kept when found within it; the
  /// largest first, only while the frame holds fewer stickers than
  /// `template_below_stickers`. Measured over 50 random-conditions
  /// sequences: the frames lost 21.7 -> 16.9 % with every such sticker,
  /// 16.3 % with 2 (a frame kept from being lost or carried on its surface
  /// alone); every sticker made the patient in the camera worse on the
  /// frames both tracked (1.47 -> 1.58 mm; with 2, 1.48: the stickers carry
  /// the session's placement of the model, the surface does not).
  double template_max_side_px = 30;
  double template_max_shift_fraction = 0.35;
  int template_below_stickers = 2;
  /// ... and until this many in a row were not found (measured over four
  /// random-conditions sequences: where any was found, the first was among
  /// the three largest; a frame that found none tried eight, at 1-3 ms
  /// each).
  int template_max_misses = 4;
  /// Surface-only ("carried") frames allowed after the last frame with a
  /// sticker; and what the surface must show for them.
  int max_frames_without_stickers = 5;
  double min_depth_inlier_fraction = 0.5;
  int min_depth_inliers = 200;
  /// A pose from two or more stickers that the surface contradicts: at
  /// least min_depth_inliers of the model's points in view have a depth
  /// reading, fewer than this share of them agree, and fewer than half the
  /// share that usually agrees in this run (accepted frames so far; none
  /// yet: not refused, so a depth bias the plan left does not lose every
  /// frame). Refused, and tried again from the prediction (two small
  /// stickers can agree on a pose turned about the line through them;
  /// measured on a d435 case with random conditions: 50 deg and 90 mm off,
  /// 4-6 % of ~850 points within the gate, reported with a 16 mm bound;
  /// right poses 0.95).
  double min_depth_inlier_fraction_with_stickers = 0.25;
  /// A pose whose own 1-sigma position uncertainty at the model origin
  /// exceeds this is not reported (m).
  double max_position_sigma_m = 0.01;

  std::string Validate() const;
};

enum class BodyPoseSource {
  kStickers = 0,           ///< stickers (and the surface where depth agreed)
  kCarried = 1,            ///< no sticker: the surface alone from the prediction
  kLost = 2,
};
const char* BodyPoseSourceName(BodyPoseSource source);

struct BodyTrackingTimings {
  double detection_ms = 0;  ///< sticker search, corner refinement, start pose
  double pose_ms = 0;       ///< start pose, refinement with depth, checks
  double total_ms = 0;
};

struct BodyPoseResult {
  bool ok = false;
  Rigid3d camera_from_model;  ///< meaningful only when ok
  BodyPoseSource source = BodyPoseSource::kLost;
  std::vector<int> sticker_ids;     ///< stickers used
  std::vector<int> stickers_dropped;  ///< seen but disagreeing
  int stickers_refined_at_pose = 0;  ///< of sticker_ids, found by refinement at the fitted pose
  double sticker_rms_px = 0;
  int depth_inliers = 0;
  /// Of the model's points the pose puts in view with a depth reading,
  /// the share within the gate (0 without depth).
  double depth_inlier_fraction = 0;
  double depth_rms_mm = 0;
  /// Covariance of a left perturbation (omega, v) of camera_from_model, in
  /// the camera frame (rad, m).
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();
  double position_sigma_mm = 0;  ///< at the model origin, largest axis
  double rotation_sigma_deg = 0;  ///< largest axis
  int frames_without_stickers = 0;
  std::string message;  ///< why, when lost or carried
  BodyTrackingTimings timings;
  /// Internal: how Track may try again when this attempt lost the patient
  /// (0: no; 1: from the prediction, ignoring the one sticker read, whose
  /// pose disagreed with the surface; 2: with the whole image searched, no
  /// window around the predicted stickers having held one).
  int retry = 0;
};

class BodyTracker {
 public:
  /// `model`: the reference model (model frame, metres). `model_from_marker`:
  /// each mapped sticker in the model frame (the session's body marker map
  /// and alignment). Throws arpos::Error for invalid options, InputError for
  /// an empty model or no stickers.
  BodyTracker(const TriangleMesh& model, std::map<int, Rigid3d> model_from_marker,
              const CameraIntrinsics& intrinsics, const BodyTrackerOptions& options);
  ~BodyTracker();
  BodyTracker(const BodyTracker&) = delete;
  BodyTracker& operator=(const BodyTracker&) = delete;

  /// One frame (colour BGR CV_8UC3, depth CV_16UC1 or empty). Never throws for
  /// bad data: an unusable frame is lost with a message.
  /// `hint`: where the caller expects the model (e.g. the patient's last room
  /// pose seen from the camera's last room pose), used when the tracker has
  /// no recent pose of its own.
  /// `depth_motion`: for depth of another instant than the colour, the
  /// camera's motion between them as the room's depth measured it (the
  /// localiser's, same frame; LocalizationResult::depth_camera_motion); the
  /// frame's depth of the patient is taken at a camera moved by it. Without
  /// it, by an unknown motion of the camera's recent speed.
  BodyPoseResult Track(const RgbdFrame& frame, const std::optional<Rigid3d>& hint = std::nullopt,
                       const DepthCameraMotion* depth_motion = nullptr);
  /// Forgets the last poses: the next frame starts from the stickers alone.
  void Reset();
  /// Whether a frame at time `t` has a prediction from the tracker's own
  /// last poses (without one, a caller's hint is what it can start from).
  bool HasRecentPose(double t) const;

  const BodyTrackerOptions& options() const { return options_; }

 private:
  // One attempt. How stickers are looked for: kWindows around the
  // prediction (the whole image when there is none, or only a hint, and
  // the windows hold none); kNone: start from the prediction as if no
  // sticker had been read (they are then refined where the surface fit puts
  // them); kWholeImage: the whole image, then windows where its first pose
  // puts every sticker.
  enum class Search { kWindows, kNone, kWholeImage };
  BodyPoseResult TrackOnce(const RgbdFrame& frame, const std::optional<Rigid3d>& hint,
                           Search search, const DepthCameraMotion* depth_motion);
  struct Impl;
  BodyTrackerOptions options_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace arpos
