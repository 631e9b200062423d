#pragma once
/// The session stage of one treatment: its algorithm (no store, no files)
/// and the one transaction that stores what it built. Used by `arpos session`
/// (controllers/session_controller.h), `arpos run-case` and the GUI.
///
/// From the case's body scan (patient lying still, wearing ArUco stickers):
///  1. localise every used frame's camera in the plan's room map and detect
///     its stickers;
///  2. stickers and cameras made consistent: a seed sticker map from the
///     room-localised frames, every frame with two or more mapped stickers
///     posed from them and the map rebuilt (three rounds), then the one
///     rigid offset between that sticker-consistent frame and the room as
///     the robust mean of what the room-localised frames say (a frame close
///     over the body sees room markers far and oblique: its room pose alone
///     is uncertain by 5-20 mm); the body marker map from the final poses
///     (body_model/);
///  3. reconstruction: depth clouds placed by those poses, refined by GICP
///     against the growing reconstruction (dynamic voxel size), the frames'
///     mean correction taken off, cropped to the body (a box around the
///     reference model at its target pose, the couch plane and everything
///     under it removed, largest cluster), then meshed by Poisson;
///  4. alignment of the reference model to the reconstruction: manual (a
///     given 4x4) or automatic (global registration with the target pose as
///     prior, ambiguity reported), each refined by point-to-plane ICP of the
///     reconstruction onto the densely sampled model surface; then the parts
///     of the surface that moved during the scan (breathing, measured from
///     the fused frames: surface_motion.h) are left out and the ICP repeated
///     on the still parts, so that the model is not lifted by the mean of a
///     breathing chest.
///
/// Frames: the session's body frame is the room frame during the scan, so
/// `body_from_marker` = `room_from_marker` and `reconstruction_from_model` =
/// `room_from_model` at scan time. What tracking needs is
/// `model_from_marker` = `reconstruction_from_model`^-1 * `body_from_marker`
/// per sticker (SessionStageResult::model_from_markers).
/// BuildSession runs these steps and stores nothing; StoreSession writes every
/// artefact with its audit entries in one transaction.

#include <cstdint>
#include <filesystem>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "body_model/body_marker_map.h"
#include "body_model/layout_scale.h"
#include "body_model/sticker_motion.h"
#include "body_model/sticker_surface.h"
#include "body_model/surface_motion.h"
#include "controllers/controller.h"
#include "geometry/rigid3.h"
#include "geometry/triangle_mesh.h"
#include "registration/point_cloud.h"
#include "room_map/room_map.h"
#include "room_map/scan_landmarks.h"
#include "sensor/case_folder.h"
#include "store/records.h"
#include "store/roles.h"

namespace arpos {

class Database;

inline constexpr int kMinFramesPerStep = 20;

struct SessionStageOptions {
  std::filesystem::path case_dir;
  /// Else the case's patient's one approved plan with a room map (any plan
  /// with a room map for `unapproved` or a research run); several refused
  /// (room_map/plan_stage.h ChoosePlanForSession).
  std::optional<PlanId> plan_id;
  /// Run on a plan that is not approved (tests, research); recorded in the
  /// session and its audit entry. A research run (no role) always may.
  bool unapproved = false;
  /// Who runs the session (a therapist, or a research run; store/roles.h).
  Operator op;
  /// Manual alignment: a 4x4 row-major room_from_model (= reconstruction_from_model)
  /// file; without it the alignment is automatic.
  std::optional<std::filesystem::path> initial_alignment;
  /// If set: writes model_pose.txt (TUM, every body_scan frame) and the
  /// reconstruction cloud and mesh as PLY files there.
  std::optional<std::filesystem::path> out_dir;
  /// Body marker map from every n-th frame, reconstruction from every l-th
  /// (l of the paper); a scan shorter than kMinFramesPerStep times a step
  /// uses smaller steps (at least kMinFramesPerStep frames, or all).
  int marker_frame_step = 2;
  int reconstruction_frame_step = 10;
  /// Take the mean of the reconstruction frames' GICP corrections off the
  /// fused cloud (it otherwise carries the first frame's pose error).
  bool average_anchor = true;
  /// Rebuild the sticker map from the frames that see stickers, each
  /// registered to the finished reconstruction (GICP), so the stickers sit
  /// where the body surface is (BuildSession, step 4). Off: the map
  /// from the sticker-consistent cameras.
  bool stickers_on_surface = true;
  /// Then the room offset again from every room-localised frame registered
  /// to the reconstruction (BuildSession, step 5).
  bool room_offset_from_surface = true;
  /// The sticker layout scaled to the stickers' printed size, as the still
  /// stickers' corners in the scan's images say (layout_scale.h; after the
  /// alignment, step 6b).
  bool layout_scale_from_sticker_size = true;
  /// Each frame's offset in that mean weighs 1 / (s^2 + floor^2), s the
  /// localiser's 1-sigma error of the frame at the stickers (its position
  /// and rotation sigmas carried there), the floor (mm) standing for what
  /// the frames share and their sigmas leave out (the map's own error near
  /// the couch). 0: every frame weighs the same. Measured on 69 random
  /// xtion scans (benchmark/accuracy.md, session 28): 1.5 mm placed the
  /// near-couch scans better on 22 of 34 (1.40 -> 1.27 and 1.98 -> 1.74 mm
  /// mean model pose on two sets), 3 mm about the same.
  double room_placement_weight_floor_mm = 1.5;
  /// Fewer mapped body stickers than this: the stage stops with an error
  /// (tracking follows the patient by them; one or two give a weak pose).
  int min_stickers = 3;
  /// The scan's placement in the room weaker than this (1 sigma at the
  /// stickers, mm) is reported as a warning with what to record.
  double max_room_placement_sigma_mm = 1.0;
  /// Stickers this camera reads only closer than this (m, face-on) are
  /// reported as a warning: tracking from farther loses the patient.
  double min_sticker_reading_distance_m = 1.2;
  /// Stickers lie on the skin: one whose centre is farther than this from
  /// the aligned reference surface (m), beyond three times the breathing
  /// the session measured at it, is left out of the map while
  /// `min_stickers` remain, with a warning, and the alignment's status asks
  /// for a check (sticker_surface.h, BuildSession step 6c).
  double max_sticker_off_model_m = 0.008;
  /// Breathing: measure which parts of the surface moved during the scan
  /// (surface_motion.h) and refine the alignment once more on the still
  /// parts, when they hold at least `min_still_surface_share` of the
  /// reconstruction's points.
  bool align_on_still_surface = true;
  double min_still_surface_share = 0.3;
  /// Breathing: measure which way each moving sticker moved, from its
  /// corners in the scan's views (sticker_motion.h); where it cannot be
  /// told, or off, a sticker moves along its normal.
  bool sticker_motion_directions = true;
  /// Depth of another instant than its colour (sensor/depth_timing.h): the
  /// first localisation can only take the camera's motion over the delay
  /// out of the room's depth (MarginaliseSharedMotion); once the frames are
  /// posed, the room-localised ones are localised again with their depth as
  /// of their colour instant, by the motion between the posed frames around
  /// them (BuildSession, step 2b), and the scan is placed in the room by
  /// those poses (benchmark/accuracy.md, session 45: six simulated cases
  /// at 15 fps with depth 6-12 ms early or late). Only where the posed
  /// frames around the depth instant are at most `relocalise_max_gap_s`
  /// apart (two frames at 15 fps): the second localisation trusts the
  /// moved depth as synced, and a hand-held camera's motion over longer
  /// gaps is not constant velocity (the sweep's sparse random scans, frames
  /// 0.13-0.23 s apart, came out worse with the pass).
  bool relocalise_delayed_depth = true;
  double relocalise_max_gap_s = 0.15;
  int poisson_depth = 8;
  /// Room landmarks the scan sees (room_map/scan_landmarks.h), stored with
  /// the body marker map for tracking: at most this many (they come first
  /// in the map tracking localises by, before the room map's own).
  bool scan_landmarks = true;
  int max_scan_landmarks = 2000;
  int threads = 2;

  std::string Check() const;  ///< empty if valid
};

struct SessionStepTimes {
  double localization_s = 0, marker_map_s = 0, reconstruction_s = 0, mesh_s = 0, alignment_s = 0,
         scan_landmarks_s = 0, sticker_motion_s = 0, store_s = 0, total_s = 0;
};

/// The final camera pose of one considered body-scan frame and where it
/// came from: the stickers (a frame with two or more mapped stickers, moved
/// into the room by the one room offset) or the room map alone, then, for
/// frames that see stickers, registration to the reconstruction.
struct ScanCameraPose {
  double timestamp_s = 0;
  Rigid3d room_from_camera;
  bool from_stickers = false;
  bool room_localized = false;  ///< the room map localised this frame too
  /// Registered to the finished reconstruction (then room_from_camera is
  /// that pose; the sticker map is built from these frames).
  bool registered_to_surface = false;
  /// The pose its depth was fused with (the one camera_pose.txt lists).
  Rigid3d fused_room_from_camera;
  /// The room map's own pose of the frame (when room_localized), before the
  /// scan's one room offset; for evaluation.
  Rigid3d localized_room_from_camera;
};

struct SessionStageResult {
  PlanId plan_id;
  std::string plan_choice;  ///< which plan and why (ChoosePlanForSession)
  bool on_unapproved_plan = false;
  SessionId session_id;
  RecordingId recording_id;
  BodyMarkerMapId body_marker_map_id;
  ReconstructionId reconstruction_id;
  AlignmentId alignment_id;  ///< the final (ICP-refined) alignment
  int frames = 0;
  int frames_considered = 0;  ///< every marker_frame_step-th or reconstruction_frame_step-th
  int frames_localized = 0;   ///< in the room map
  /// Room markers the scan read that the room map does not hold (id, frames
  /// that read it): why a scan that sees room markers may still not be placed.
  /// (A frame the localiser tracks searches only where the map's markers
  /// are, so frames after a placed one count less often.)
  std::vector<std::pair<int, int>> unmapped_room_markers;
  /// Frames the room map could not localise, posed from mapped stickers.
  int frames_posed_by_stickers = 0;
  /// Frames whose depth, of another instant than their colour, was moved to
  /// the colour instant (sensor/depth_timing.h: ColourFromDepthCamera).
  int frames_depth_moved_to_colour = 0;
  /// Room-localised frames localised again with their depth as of their
  /// colour instant (SessionStageOptions::relocalise_delayed_depth).
  int frames_relocalised_with_moved_depth = 0;
  /// How the scan's camera response was found (estimated, or assumed).
  std::string camera_response;
  BodyMarkerMapResult marker_map;
  /// Every considered frame that got a final pose, in scan order.
  std::vector<ScanCameraPose> scan_cameras;
  /// Frames registered to the reconstruction for the sticker map, and
  /// whether the final map comes from them (false: too few stickers that way,
  /// the map from the sticker-consistent cameras kept).
  int frames_registered_for_stickers = 0;
  bool stickers_on_surface = false;
  /// Room-localised frames behind the second room offset (step 5; fewer
  /// than 3: none applied) and the shift it gave the stickers' centre (m).
  int surface_offset_frames = 0;
  Eigen::Vector3d surface_offset_shift_m = Eigen::Vector3d::Zero();
  /// How well the scan is placed in the room: the frames the room map
  /// localised whose offsets gave the placement, the runs of consecutive
  /// frames among them, and its 1-sigma error at the stickers (mm, largest
  /// axis; the spread of those offsets over the square root of the runs:
  /// MeanOffsetSigma; infinity below 3 frames).
  int room_placement_frames = 0;
  int room_placement_runs = 0;
  double room_placement_sigma_mm = std::numeric_limits<double>::infinity();
  /// How far this camera reads the stickers face-on (m): where they are
  /// ReadableMarkerSidePx across.
  double sticker_reading_distance_m = 0;
  /// Which parts of the surface moved during the scan (breathing), and
  /// whether the alignment was refined on the still parts alone (their
  /// reconstruction points).
  SurfaceMotion surface_motion;
  bool aligned_on_still_surface = false;
  int still_surface_points = 0;
  /// Per sticker that sits on a moving patch: how far it moved (1 sigma, m;
  /// SurfaceMotion::MotionAt its centre). Stored with the body marker map
  /// for tracking.
  std::map<int, double> sticker_motion_m;
  /// Which way they moved (sticker_motion.h): a unit direction in the
  /// sticker's frame per sticker whose direction the scan determined (the
  /// others along their normals), and the measurement's summary.
  std::map<int, Eigen::Vector3d> sticker_motion_direction;
  StickerMotion sticker_motion;
  /// The sticker layout's scale against the stickers' printed size (step 6b).
  LayoutScaleEstimate layout_scale;
  /// What the user should know (a weakly placed scan, stickers too small for
  /// the tracking distance), with what to do.
  std::vector<std::string> warnings;
  std::string RoomPlacementText() const;
  /// The surface motion and what the alignment made of it, for people;
  /// empty when no frame measured it.
  std::string SurfaceMotionText() const;
  int reconstruction_points = 0;
  /// Frames offered to the reconstruction and those fused (a frame whose
  /// GICP correction is refused is left out).
  int reconstruction_frames_offered = 0, reconstruction_frames_fused = 0;
  /// Fewer than two thirds of the frames joined the reconstruction started
  /// from the first one, so it was built again from the frames the room map
  /// placed most surely; the build most frames joined was kept, started
  /// from the frame at `reconstruction_anchor_frame_s`.
  bool reconstruction_rebuilt = false;
  double reconstruction_anchor_frame_s = 0;
  /// The fused body surface (room frame at scan time), as stored.
  PointCloud reconstruction;
  int mesh_vertices = 0;
  std::string alignment_method;  ///< "manual" or "automatic"
  std::string alignment_status;  ///< ok, or why the automatic result is doubtful
  Rigid3d room_from_model;       ///< reference model pose at scan time
  /// The room around the couch as the scan's frames saw it (step 7).
  ScanLandmarks scan_landmarks;
  double alignment_fitness = 0, alignment_rmse_m = 0;
  std::map<int, Rigid3d> model_from_markers;
  /// Each sticker's centre against the aligned reference surface (step 6c;
  /// the stickers off it as found, before any was left out).
  StickerSurfaceCheck sticker_surface;
  /// The mean correction taken off the reconstruction (none when not
  /// applied): the shift of its centre (m) and the rotation (deg).
  Eigen::Vector3d anchor_shift_m = Eigen::Vector3d::Zero();
  double anchor_rotation_deg = 0;
  /// What StoreSession stores besides the fields above: the Poisson mesh
  /// (empty when meshing gave none), the alignment ICP started from, and
  /// the reconstruction's voxel size.
  TriangleMesh mesh;
  AlignmentMethod alignment_method_kind = AlignmentMethod::kAutomatic;
  Rigid3d room_from_model_initial;
  double initial_fitness = 0, initial_rmse_m = 0;
  std::int64_t alignment_inliers = 0;
  double reconstruction_voxel_m = 0;
  SessionStepTimes times;
  std::string Summary() const;
};

/// What the stage reads from the plan (checked by the caller).
struct SessionPlanInputs {
  PlanId plan_id;
  TriangleMesh model;  ///< the reference model, model frame, metres
  Rigid3d room_from_model_target;
  RoomMap room_map;
};

/// The stage on `folder`'s body scan with the plan's room map, model and
/// target pose; stores and writes nothing. Fills the result but for the
/// store's ids, the plan choice and the approval (the caller's), and the
/// store and total times. Throws InputError (the camera never localised in
/// the room, no body surface, too few stickers, a failed automatic or
/// unusable manual alignment), Cancelled (polled between steps).
SessionStageResult BuildSession(const CaseFolder& folder, const SessionPlanInputs& plan,
                                const SessionStageOptions& options, const ControllerCallbacks& callbacks = {});

/// `out_dir`/model_pose.txt (the model pose at every body-scan frame),
/// camera_pose.txt (the cameras whose depth was fused) and
/// reconstruction_mesh.ply (when there is a mesh).
void WriteSessionOutputs(const std::filesystem::path& out_dir, const CaseFolder& folder,
                         const SessionStageResult& result);

/// Stores a built session under `result->plan_id` in one transaction: the
/// session (its notes say how well the scan is placed in the room, and any
/// warning), the body-scan recording, the body marker map, the
/// reconstruction with its mesh, the initial and the ICP alignment, each
/// with its audit entry; sets the result's ids and approval. The plan's
/// approval is read inside the transaction; an unapproved plan is refused
/// unless `options.unapproved` or a research run. Throws InputError (plan
/// gone or not approved), StoreError; nothing is stored then.
void StoreSession(Database* database, const CaseFolder& folder, const SessionStageOptions& options,
                  SessionStageResult* result);

/// Manual alignment of a stored reconstruction: from point pairs picked on
/// the reference model (model frame) and on the reconstruction (room frame
/// at scan time), a rigid fit (Kabsch), refined by point-to-plane ICP of the
/// reconstruction onto the model surface; both stored (method manual, then
/// ICP as its child) with an audit entry. Needs a role that runs sessions
/// and an open session. Throws InputError for fewer than
/// three pairs, pairs in a line, a reconstruction or plan that does not
/// exist, or picks that disagree by more than `max_pick_rmse_m` after the
/// fit (a pair picked on different anatomy).
struct ManualAlignmentResult {
  AlignmentId manual_id, icp_id;
  Rigid3d room_from_model;     ///< after ICP
  double pick_rmse_m = 0;      ///< of the picked pairs after the rigid fit
  double fitness = 0, rmse_m = 0;
};
ManualAlignmentResult AlignStoredReconstruction(Database* database, ReconstructionId reconstruction,
                                                const std::vector<Eigen::Vector3d>& model_points,
                                                const std::vector<Eigen::Vector3d>& reconstruction_points,
                                                const Operator& op, double max_pick_rmse_m = 0.03,
                                                int threads = 2);

struct ReconstructionFrameReport;
/// The mean of the reconstruction frames' GICP corrections as a rotation
/// about `centre` plus a shift of it (the first fused frame counts as none;
/// refused corrections and shifts far beyond the median left out); identity
/// with fewer than three frames.
Rigid3d AnchorCorrection(const std::vector<ReconstructionFrameReport>& reports,
                         const Eigen::Vector3d& centre);

}  // namespace arpos
