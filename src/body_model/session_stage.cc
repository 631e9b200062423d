#include "body_model/session_stage.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <set>
#include <sstream>

#include <opencv2/imgproc.hpp>

#include "body_model/rigid_offsets.h"
#include "body_model/sticker_surface.h"
#include "features/response_from_recording.h"
#include "geometry/mesh_io.h"
#include "geometry/so3.h"
#include "geometry/umeyama.h"
#include "registration/global_registration.h"
#include "registration/mesh_cloud.h"
#include "registration/poisson.h"
#include "registration/preprocess.h"
#include "registration/reconstruction.h"
#include "registration/registration.h"
#include "room_map/camera_localizer.h"
#include "room_map/plan_stage.h"
#include "sensor/depth_timing.h"
#include "sensor/sequence.h"
#include "sensor/tum_io.h"
#include "store/database.h"
#include "store/lifecycle.h"
#include "store/record_conversions.h"
#include "util/file.h"
#include "util/logging.h"
#include "util/string_util.h"

namespace arpos {
namespace {

using Clock = std::chrono::steady_clock;
double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

StoredPointCloud ToStored(const PointCloud& cloud) {
  StoredPointCloud stored;
  stored.points.reserve(cloud.size());
  for (size_t i = 0; i < cloud.size(); ++i) stored.points.push_back(cloud.point3(i).cast<float>());
  if (cloud.has_normals()) {
    for (size_t i = 0; i < cloud.size(); ++i) stored.normals.push_back(cloud.normal3(i).cast<float>());
  }
  return stored;
}

// Box around the reference model at its target pose, grown by `margin_m`:
// the patient lies within a few centimetres of the target.
OrientedBox BoxAroundModel(const TriangleMesh& model, const Rigid3d& room_from_model, double margin_m) {
  Eigen::Vector3f lo, hi;
  model.Bounds(&lo, &hi);
  const Eigen::Vector3d centre_in_model = 0.5 * (lo + hi).cast<double>();
  OrientedBox box;
  box.frame_from_box = room_from_model * Rigid3d(Eigen::Quaterniond::Identity(), centre_in_model);
  box.half_extents_m = 0.5 * (hi - lo).cast<double>() + Eigen::Vector3d::Constant(margin_m);
  return box;
}

// Point-to-plane ICP of the scene onto the densely sampled model surface,
// coarse to fine; returns model_from_scene.
RegistrationResult RefineOnModel(const PointCloud& scene, const PointCloud& model_dense,
                                 const KdTree& model_tree, const Rigid3d& model_from_scene,
                                 int threads) {
  RegistrationOptions icp;
  icp.num_threads = threads;
  icp.max_iterations = 30;
  icp.robust_kernel = RobustKernel::kHuber;
  icp.robust_scale_m = 0.003;
  Rigid3d estimate = model_from_scene;
  RegistrationResult result;
  for (const double gate_m : {0.03, 0.01, 0.005}) {
    icp.max_correspondence_distance_m = gate_m;
    result = AlignPointToPlane(scene, model_dense, model_tree, estimate, icp);
    estimate = result.target_from_source;
  }
  return result;
}

// Why a scan that reads room markers is placed by few or none of them: the
// room markers it read that the map does not hold, and those the map holds
// near the planned isocentre (within 2 m; every one when none is).
std::string DescribeUnmappedRoomMarkers(const std::vector<std::pair<int, int>>& unmapped, const RoomMap& map,
                                        const Eigen::Vector3d& isocentre_in_room) {
  std::vector<int> near, all;
  for (const RoomMapMarkerEntry& m : map.markers) {
    all.push_back(m.id);
    if ((m.room_from_marker.translation - isocentre_in_room).norm() < 2.0) near.push_back(m.id);
  }
  const std::vector<int>& listed = near.empty() ? all : near;
  std::ostringstream held;
  for (size_t i = 0; i < listed.size(); ++i) held << (i ? ", " : "") << listed[i];
  std::ostringstream out;
  if (unmapped.empty()) {
    out << "the scan reads no room marker the map holds (the map holds " << (near.empty() ? "" : "near the couch ")
        << held.str() << "): record the scan again with those in view for a few seconds";
    return out.str();
  }
  out << "the scan reads room marker(s) ";
  for (size_t i = 0; i < unmapped.size(); ++i) {
    out << (i ? ", " : "") << unmapped[i].first << " (" << unmapped[i].second << " frame"
        << (unmapped[i].second == 1 ? "" : "s") << ")";
  }
  out << " that the room map does not hold (a plan leaves out markers seen in fewer than 3 views of the room "
         "recording, or not linked to the origin marker): record the room again with them in view from several "
         "places, or the scan with the map's markers in view (it holds "
      << (near.empty() ? "" : "near the couch ") << held.str() << ")";
  return out.str();
}

}  // namespace

std::string SessionStageResult::RoomPlacementText() const {
  return std::isfinite(room_placement_sigma_mm)
             ? StringPrintf("the scan placed in the room from %d frames in %d run(s), %.2f mm at the stickers "
                            "(1 sigma)",
                            room_placement_frames, room_placement_runs, room_placement_sigma_mm)
             : StringPrintf("the scan placed in the room from %d frame(s), uncertainty unknown",
                            room_placement_frames);
}

std::string SessionStageResult::SurfaceMotionText() const {
  if (surface_motion.frames == 0) return "";
  if (aligned_on_still_surface) {
    return surface_motion.Describe() + StringPrintf("; the model aligned to the still surface (%d of %d points)",
                                                    still_surface_points, reconstruction_points);
  }
  if (surface_motion.moving_patches > 0) {
    return surface_motion.Describe() +
           StringPrintf("; too little still surface to align on (%d of %d points): aligned to all of it",
                        still_surface_points, reconstruction_points);
  }
  return surface_motion.Describe();
}

std::string SessionStageOptions::Check() const {
  if (case_dir.empty()) return "no case folder given";
  if (!(max_room_placement_sigma_mm > 0)) return "max_room_placement_sigma_mm must be positive";
  if (!(relocalise_max_gap_s > 0)) return "relocalise_max_gap_s must be positive";
  if (!(min_still_surface_share > 0 && min_still_surface_share <= 1)) {
    return "min_still_surface_share must be in (0, 1]";
  }
  if (marker_frame_step < 1) return "marker_frame_step must be at least 1";
  if (reconstruction_frame_step < 1) return "reconstruction_frame_step must be at least 1";
  if (poisson_depth < 4 || poisson_depth > 11) return "poisson_depth must be in 4..11";
  if (min_stickers < 1) return "min_stickers must be at least 1";
  if (!(min_sticker_reading_distance_m >= 0)) return "min_sticker_reading_distance_m must not be negative";
  if (threads < 1) return "threads must be at least 1";
  if (max_scan_landmarks < 0) return "max_scan_landmarks must not be negative";
  return "";
}

std::string SessionStageResult::Summary() const {
  std::ostringstream out;
  if (!plan_choice.empty()) out << "plan: " << plan_choice << "\n";
  if (on_unapproved_plan) out << "note: the plan is not approved; the session is recorded as such\n";
  const Eigen::Vector3d r_deg = room_from_model.RotationVector() * (180.0 / M_PI);
  out << StringPrintf(
      "session %lld of plan %lld: body scan of %d frames, %d considered: %d localised in the room "
      "map, %d more posed from the stickers\n"
      "%s\n"
      "body marker map: %zu stickers (mean corner rms %.3f px), %zu left out; %s\n"
      "reconstruction: %d points from %d of %d frames%s (mean frame correction %.2f mm, %.3f deg "
      "taken off), mesh %d vertices\n"
      "alignment (%s, %s): fitness %.3f, rmse %.2f mm\n"
      "reference model -> room at scan time: t = (%.2f, %.2f, %.2f) mm, r = (%.3f, %.3f, %.3f) "
      "deg\n"
      "times [s]: localisation %.2f, marker map %.2f, reconstruction %.2f, mesh %.2f, alignment "
      "%.2f, room landmarks %.2f, breathing directions %.2f, store %.2f, total %.2f\n",
      static_cast<long long>(session_id.value()), static_cast<long long>(plan_id.value()), frames,
      frames_considered, frames_localized, frames_posed_by_stickers, camera_response.c_str(),
      marker_map.markers.size(), marker_map.mean_rms_px, marker_map.rejected.size(),
      stickers_on_surface ? StringPrintf("placed from %d frames registered to the reconstruction",
                                         frames_registered_for_stickers)
                                .c_str()
                          : "from the sticker-consistent cameras",
      reconstruction_points, reconstruction_frames_fused, reconstruction_frames_offered,
      (reconstruction_frames_fused == reconstruction_frames_offered ? std::string()
       : reconstruction_rebuilt ? StringPrintf(", the others disagreed with it (built from the "
                                               "frame at %.3f s, the one most frames "
                                               "agreed with)",
                                               reconstruction_anchor_frame_s)
                                : std::string(", the others disagreed with it"))
          .c_str(),
      1000 * anchor_shift_m.norm(), anchor_rotation_deg, mesh_vertices, alignment_method.c_str(),
      alignment_status.c_str(), alignment_fitness, 1000 * alignment_rmse_m,
      1000 * room_from_model.translation.x(), 1000 * room_from_model.translation.y(),
      1000 * room_from_model.translation.z(), r_deg.x(), r_deg.y(), r_deg.z(), times.localization_s,
      times.marker_map_s, times.reconstruction_s, times.mesh_s, times.alignment_s,
      times.scan_landmarks_s, times.sticker_motion_s, times.store_s, times.total_s);
  if (surface_offset_frames >= 3) {
    out << StringPrintf("room offset from %d room-localised frames registered to the reconstruction: %.2f mm at "
                        "the stickers\n",
                        surface_offset_frames, 1000 * surface_offset_shift_m.norm());
  }
  if (frames_depth_moved_to_colour > 0) {
    out << StringPrintf(
        "depth of another instant than its colour: moved to the colour instant in %d frame(s); "
        "%d room-localised frame(s) localised again with it\n",
        frames_depth_moved_to_colour, frames_relocalised_with_moved_depth);
  }
  out << RoomPlacementText() << "\n";
  if (scan_landmarks.frames > 0) {
    out << StringPrintf("room landmarks the scan sees, for tracking: %d new to the room map ",
                        scan_landmarks.size())
        << StringPrintf("(of %d keypoints seen in enough of %d frames; %d the map holds), ",
                        scan_landmarks.groups, scan_landmarks.frames, scan_landmarks.duplicates)
        << StringPrintf(
               "outside the couch and the patient, each to %.1f mm, in the room as the scan is "
               "(%.2f mm)\n",
               1000 * scan_landmarks.spread_m, 1000 * scan_landmarks.placement_sigma_m);
  }
  if (surface_motion.frames > 0) out << SurfaceMotionText() << "\n";
  if (!sticker_motion.stickers.empty())
    out << "breathing stickers: " << sticker_motion.Describe() << "\n";
  if (layout_scale.views > 0 || !layout_scale.why_not.empty()) out << layout_scale.ToText() << "\n";
  if (!sticker_surface.off_m.empty()) out << sticker_surface.ToText() << "\n";
  if (sticker_reading_distance_m > 0) {
    out << StringPrintf("stickers readable up to %.2f m from this camera (face-on)\n", sticker_reading_distance_m);
  }
  for (const std::string& w : warnings) out << "warning: " << w << "\n";
  return out.str();
}

namespace {

void SetRoomPlacement(const OffsetMeanSigma& placement, SessionStageResult* result) {
  result->room_placement_frames = placement.frames;
  result->room_placement_runs = placement.runs;
  result->room_placement_sigma_mm = placement.sigma_mm;
}

// A localised frame's 1-sigma error (mm) at a point `distance_m` from the
// camera: its position sigma and its rotation sigma acting over that reach.
double FrameSigmaAtMm(double position_sigma_mm, double rotation_sigma_deg, double distance_m) {
  return std::hypot(position_sigma_mm, rotation_sigma_deg * M_PI / 180 * 1000 * distance_m);
}

// The mean position of the mapped stickers (zero without any).
Eigen::Vector3d StickerCentre(const BodyMarkerMapResult& map) {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (const auto& m : map.markers) centre += m.room_from_marker.translation;
  return map.markers.empty() ? centre : centre / static_cast<double>(map.markers.size());
}

}  // namespace

Rigid3d AnchorCorrection(const std::vector<ReconstructionFrameReport>& reports,
                         const Eigen::Vector3d& centre) {
  // Per refined frame: its correction's rotation vector and the shift it
  // gives the reconstruction's centre; the first fused frame counts as no
  // correction; outlying frames (GICP pulled wrongly) left out.
  std::vector<Offset> offsets;
  bool first = true;
  for (const auto& r : reports) {
    if (!r.used) continue;
    if (!first && !r.refined) continue;  // fused without a consistent correction
    offsets.push_back(first ? Offset::Zero() : OffsetAt(r.correction, centre));
    first = false;
  }
  return RobustMeanOffset(offsets, centre, 1e-4, 3).value_or(Rigid3d::Identity());
}

ManualAlignmentResult AlignStoredReconstruction(Database* database, ReconstructionId reconstruction_id,
                                                const std::vector<Eigen::Vector3d>& model_points,
                                                const std::vector<Eigen::Vector3d>& reconstruction_points,
                                                const Operator& op, double max_pick_rmse_m,
                                                int threads) {
  ARPOS_CHECK(database != nullptr, "manual alignment needs a session store");
  RequirePermission(op, Action::kRunSession);
  const std::string actor = op.Actor("arpos gui");
  if (model_points.size() != reconstruction_points.size()) {
    ARPOS_INPUT_ERROR("manual alignment: " << model_points.size() << " points on the model but "
                                           << reconstruction_points.size() << " on the reconstruction");
  }
  if (model_points.size() < 3) {
    ARPOS_INPUT_ERROR("manual alignment: " << model_points.size() << " point pair(s); pick at least 3");
  }
  const auto reconstruction = database->GetReconstruction(reconstruction_id);
  if (!reconstruction) ARPOS_INPUT_ERROR("reconstruction " << reconstruction_id.value() << " does not exist");
  const SessionRecord session = RequireOpenSession(database, reconstruction->session_id, "a manual alignment");
  const auto plan = database->GetPlan(session.plan_id);
  if (!plan || plan->reference_model.vertices.empty()) {
    ARPOS_INPUT_ERROR("plan " << session.plan_id.value() << " has no reference model");
  }
  const auto fit = EstimateRigidTransform(model_points, reconstruction_points);
  if (!fit) ARPOS_INPUT_ERROR("manual alignment: the picked points lie on a line; pick spread-out points");
  if (fit->rmse_m > max_pick_rmse_m) {
    ARPOS_INPUT_ERROR("manual alignment: the picked pairs disagree by " << 1000 * fit->rmse_m
                      << " mm RMS after the best rigid fit (at most " << 1000 * max_pick_rmse_m
                      << " mm): a pair was picked on different anatomy");
  }
  ManualAlignmentResult out;
  out.pick_rmse_m = fit->rmse_m;
  PointCloud body;
  for (const auto& p : reconstruction->cloud.points) body.Add(p.cast<double>());
  const TriangleMesh model = FromStoredMesh(plan->reference_model);
  const PointCloud model_dense = SampleMeshSurface(model, 0.002);
  const KdTree model_tree(model_dense);
  const RegistrationResult refined =
      RefineOnModel(body, model_dense, model_tree, fit->target_from_source.Inverse(), threads);
  out.room_from_model = refined.target_from_source.Inverse();
  out.fitness = refined.fitness;
  out.rmse_m = refined.rmse_m;
  database->WithTransaction([&] {
    AlignmentRecord manual;
    manual.reconstruction_id = reconstruction_id;
    manual.method = AlignmentMethod::kManual;
    manual.reconstruction_from_model = fit->target_from_source;
    manual.fitness = 0;
    manual.rmse_m = fit->rmse_m;
    manual.num_inliers = static_cast<std::int64_t>(model_points.size());
    manual.options = StringPrintf("picked point pairs: %zu, rmse %.2f mm", model_points.size(), 1000 * fit->rmse_m);
    out.manual_id = database->AddAlignment(manual);
    database->AppendAudit({AuditId(), 0, actor, "add_alignment", "alignment:" + std::to_string(out.manual_id.value()),
                           "manual: " + manual.options});
    AlignmentRecord icp;
    icp.reconstruction_id = reconstruction_id;
    icp.parent_alignment_id = out.manual_id;
    icp.method = AlignmentMethod::kIcp;
    icp.reconstruction_from_model = out.room_from_model;
    icp.fitness = std::clamp(refined.fitness, 0.0, 1.0);
    icp.rmse_m = refined.rmse_m;
    icp.num_inliers = refined.num_inliers;
    icp.options = "point-to-plane, reconstruction onto the model surface, gates 30/10/5 mm; from picked pairs";
    out.icp_id = database->AddAlignment(icp);
    database->AppendAudit({AuditId(), 0, actor, "add_alignment", "alignment:" + std::to_string(out.icp_id.value()),
                           StringPrintf("manual (%zu picked pairs) + ICP: rmse %.2f mm", model_points.size(),
                                        1000 * refined.rmse_m)});
  });
  return out;
}

SessionStageResult BuildSession(const CaseFolder& folder, const SessionPlanInputs& plan,
                                const SessionStageOptions& options, const ControllerCallbacks& callbacks) {
  const std::string problem = options.Check();
  if (!problem.empty()) ARPOS_INPUT_ERROR("session: " << problem);
  // Reports progress, then stops if a cancel was requested.
  const auto step = [&callbacks](const std::string& what, double fraction) {
    if (callbacks.progress) callbacks.progress(what, fraction);
    if (callbacks.cancel_requested && callbacks.cancel_requested()) throw Cancelled();
  };
  SessionStageResult result;
  result.plan_id = plan.plan_id;
  const CameraIntrinsics& camera = folder.config.camera;
  const TriangleMesh& model = plan.model;
  const Sequence scan = Sequence::Open(folder.body_scan_dir);
  result.frames = static_cast<int>(scan.size());

  // 1-3. Localise, collect sticker views, fuse depth.
  step("localising the body scan", 0.05);
  // The scan's camera response from its own markers (room markers and
  // stickers), else the room recording's.
  const RecordingResponse response =
      EstimateRecordingResponse(scan, folder.config, plan.room_map.camera_response);
  result.camera_response = response.message;
  CameraLocalizerOptions localizer_options = MakeCameraLocalizerOptions(folder.config);
  localizer_options.detector.edge.response = response.response;
  // The scan is placed in the room by frames the image localises (equal
  // weights, below): none held by depth and motion alone (2-5 mm).
  localizer_options.depth_held_tracking = false;
  // Frames placed by a small marker and a few keypoints still help the
  // scan's placement, a robust mean over many frames (CameraLocalizerOptions).
  localizer_options.markers_alone_must_hold = false;
  CameraLocalizer localizer(plan.room_map, camera, localizer_options);
  MarkerDetectorOptions detector_options;
  detector_options.dictionary = folder.config.dictionary;
  detector_options.id_ranges = {{folder.config.body_markers.id_min, folder.config.body_markers.id_max}};
  detector_options.intrinsics = camera;
  detector_options.edge.response = response.response;
  MarkerDetector detector(detector_options);

  ReconstructionOptions recon_options;
  recon_options.frame_stride = 1;  // frames are chosen here
  // N = 5e4 (the paper's) gives ~2 cm registration voxels on a body (its
  // bounding box is large, its skin small): measured to make exact poses
  // worse (benchmark/registration.md). 5e5 registers at d_0 = 1 cm.
  recon_options.target_points = 5e5;
  recon_options.crop_box = BoxAroundModel(model, plan.room_from_model_target, 0.12);
  recon_options.num_threads = options.threads;
  result.reconstruction_voxel_m = recon_options.output_voxel_m;
  DepthCloudOptions depth_options;
  depth_options.stride_px = camera.width > 800 ? 4 : 2;
  depth_options.max_depth_m = 2.5;

  // A scan too short for the steps uses more of its frames: at least
  // kMinFramesPerStep of each kind, or all.
  const auto step_for = [&](int step) {
    return std::max(1, std::min(step, static_cast<int>(scan.size()) / kMinFramesPerStep));
  };
  const size_t marker_step = static_cast<size_t>(step_for(options.marker_frame_step));
  const size_t recon_step = static_cast<size_t>(step_for(options.reconstruction_frame_step));
  std::vector<ReconstructionFrameReport> recon_reports;
  const double sticker_size = folder.config.body_markers.size_m;
  // 1. Every considered frame: room localisation, stickers, and the depth
  //    cloud of reconstruction frames.
  struct ScanFrame {
    size_t index = 0;  ///< in the scan
    double timestamp_s = 0;
    bool localized = false;
    Rigid3d room_from_camera;  ///< the room map's pose (when localized)
    double pos_sigma_mm = 0, rot_sigma_deg = 0;  ///< the localiser's (when localized)
    bool posed = false;        ///< a final pose exists
    bool by_stickers = false;  ///< posed from mapped stickers (last round)
    BodyScanView view;         ///< stickers (room_from_camera: the final pose)
    std::optional<PointCloud> cloud;
    std::optional<PointCloud> sticker_cloud;  ///< frames with stickers or a room pose, for steps 4-5
    double depth_delay_s = 0;  ///< the depth's instant after the colour's (RgbdFrame)
    std::optional<Rigid3d> surface_pose;      ///< registered to the reconstruction (step 4)
    KeypointSet keypoints;                    ///< for the room landmarks the scan sees (step 7)
  };
  std::vector<ScanFrame> frames;
  // The posed frames in scan order, their times and poses: the camera's path
  // the motion over a depth delay is taken from (ColourFromDepthCamera).
  struct PosedTrajectory {
    std::vector<size_t> frames;
    std::vector<double> times;
    std::vector<Rigid3d> poses;
  };
  const auto posed_trajectory = [&frames] {
    PosedTrajectory path;
    for (size_t i = 0; i < frames.size(); ++i) {
      if (!frames[i].posed) continue;
      path.frames.push_back(i);
      path.times.push_back(frames[i].timestamp_s);
      path.poses.push_back(frames[i].view.room_from_camera);
    }
    return path;
  };
  std::vector<BodyScanView> surface_views;  // the views the final sticker map is fitted to
  BodyMarkerMapResult surface_views_map;    // that map, in their frame
  std::vector<PointCloud>
      surface_view_clouds;  // their depth (camera frame), when directions are measured
  KeypointExtractor keypoint_extractor(localizer_options.keypoints);
  cv::Mat gray;
  std::map<int, int> unmapped_reads;  // room marker id -> frames that read it, not in the map
  double t_localize = 0, t_markers = 0, t_recon = 0, t_landmarks = 0;
  // The depth camera's systematic error measured in the room (the same
  // camera), removed before the depth is used.
  const DepthCorrector depth_corrector(camera, plan.room_map.depth_correction);
  for (size_t i = 0; i < scan.size(); ++i) {
    const bool for_markers = i % marker_step == 0;
    const bool for_recon = i % recon_step == 0;
    if (!for_markers && !for_recon) continue;
    ++result.frames_considered;
    if (i % 20 == 0) step(StringPrintf("body scan frame %zu of %zu", i + 1, scan.size()), 0.05 + 0.5 * i / scan.size());
    auto t0 = Clock::now();
    RgbdFrame frame = scan.LoadFrame(i, camera);
    if (!frame.depth.empty()) depth_corrector.Apply(&frame.depth);
    const LocalizationResult located = localizer.Localize(frame);
    t_localize += SecondsSince(t0);
    ScanFrame f;
    f.index = i;
    f.timestamp_s = frame.timestamp_s;
    f.localized = located.ok;
    f.room_from_camera = located.room_from_camera;
    f.pos_sigma_mm = located.position_sigma_mm;
    f.rot_sigma_deg = located.rotation_sigma_deg;
    result.frames_localized += located.ok ? 1 : 0;
    for (int id : located.unmapped_marker_ids) ++unmapped_reads[id];
    t0 = Clock::now();
    f.view = MakeBodyScanView(frame, located.ok ? located.room_from_camera : Rigid3d::Identity(), &detector,
                              camera, sticker_size);
    t_markers += SecondsSince(t0);
    t0 = Clock::now();
    if (for_recon) f.cloud = DepthToCloud(frame, camera, depth_options);
    if (!frame.depth.empty()) f.depth_delay_s = frame.depth_delay_s;
    t_recon += SecondsSince(t0);
    if (options.scan_landmarks && for_markers && !frame.depth.empty()) {
      t0 = Clock::now();
      if (frame.color.channels() == 3) {
        cv::cvtColor(frame.color, gray, cv::COLOR_BGR2GRAY);
      } else {
        gray = frame.color;
      }
      keypoint_extractor.Extract(gray, frame.depth, camera.depth_scale, &f.keypoints);
      t_landmarks += SecondsSince(t0);
    }
    t0 = Clock::now();
    if (options.stickers_on_surface && for_markers && (!f.view.markers.empty() || f.localized)) {
      // Kept thinned: registered to the reconstruction at 1 cm voxels (step 4).
      f.sticker_cloud = VoxelDownsample(f.cloud ? *f.cloud : DepthToCloud(frame, camera, depth_options), 0.004);
    }
    t_markers += SecondsSince(t0);
    frames.push_back(std::move(f));
  }
  result.unmapped_room_markers.assign(unmapped_reads.begin(), unmapped_reads.end());
  if (result.frames_localized == 0) {
    ARPOS_INPUT_ERROR(folder.body_scan_dir.string()
                      << ": the camera could not be localised in the room map in any frame; "
                      << DescribeUnmappedRoomMarkers(result.unmapped_room_markers, plan.room_map,
                                                     plan.room_from_model_target.translation));
  }

  // 2. Stickers and cameras made consistent with each other. A body-scan
  //    frame close over the patient sees room markers far and oblique, so its
  //    room pose is uncertain (sigma of 5-20 mm is common); the stickers fix
  //    the cameras relative to the body far better. So: a seed sticker map
  //    from the room-localised frames; every frame with two or more mapped
  //    stickers posed from them and the map rebuilt from those poses (three
  //    rounds); then the one rigid offset between this sticker-consistent
  //    frame and the room, as the robust mean of what each room-localised
  //    frame says, is applied to all. Room-localised frames with fewer than
  //    two stickers keep their room pose.
  step("building the body marker map", 0.55);
  auto t0 = Clock::now();
  BodyMarkerMapOptions map_options;
  map_options.marker_size_m = sticker_size;
  BodyMarkerMapOptions seed_options = map_options;
  seed_options.min_views = 1;
  auto views_of = [&](bool localized_only) {
    std::vector<BodyScanView> v;
    for (const ScanFrame& f : frames) {
      if (f.view.markers.empty()) continue;
      if (localized_only ? f.localized : f.posed) v.push_back(f.view);
    }
    return v;
  };
  BodyMarkerMapResult map = BuildBodyMarkerMap(views_of(true), camera, seed_options);
  int sticker_posed = 0;
  for (int round = 0; round < 3 && map.ok(); ++round) {
    sticker_posed = 0;
    for (ScanFrame& f : frames) {
      f.posed = f.by_stickers = false;
      if (f.view.markers.size() < 2) continue;
      const StickerLocalization p = LocalizeFromStickers(f.view, map, sticker_size, camera);
      if (!p.ok) continue;
      f.view.room_from_camera = p.room_from_camera;
      f.posed = f.by_stickers = true;
      ++sticker_posed;
    }
    if (sticker_posed == 0) break;
    map = BuildBodyMarkerMap(views_of(false), camera, round < 2 ? seed_options : map_options);
  }
  if (sticker_posed > 0) {
    // room_from_camera(room map) * camera_from_room(sticker frame), per frame,
    // as a rotation vector and the shift of the stickers' centre.
    const Eigen::Vector3d centre = StickerCentre(map);
    std::vector<Offset> offsets;
    std::vector<double> times;
    for (const ScanFrame& f : frames) {
      if (!f.localized || !f.posed) continue;
      offsets.push_back(OffsetAt(f.room_from_camera * f.view.room_from_camera.Inverse(), centre));
      times.push_back(f.timestamp_s);
    }
    // Equal weights: the localiser's sigmas leave out map errors (two frames
    // 0.05 deg apart by their sigmas differed by 0.4 deg), and weighting by
    // them (capped at the median or not) measured no better than equal
    // weights over 20 seeds. Identity when no frame is both room-localised
    // and sticker-posed.
    const Rigid3d room_from_sticker_frame =
        RobustMeanOffset(offsets, centre, 0.002, 1).value_or(Rigid3d::Identity());
    SetRoomPlacement(MeanOffsetSigma(offsets, times, 0.002), &result);
    for (ScanFrame& f : frames) {
      if (f.posed) {
        f.view.room_from_camera = room_from_sticker_frame * f.view.room_from_camera;
      } else if (f.localized) {
        f.view.room_from_camera = f.room_from_camera;  // fewer than two stickers: the room pose
        f.posed = true;
      }
    }
    result.frames_posed_by_stickers = 0;
    for (const ScanFrame& f : frames) result.frames_posed_by_stickers += (f.posed && !f.localized) ? 1 : 0;
    result.marker_map = BuildBodyMarkerMap(views_of(false), camera, map_options);
  } else {
    // No frame has two mapped stickers: the room poses as they are (each
    // frame placed on its own; how well together is not known).
    for (ScanFrame& f : frames) {
      f.posed = f.localized;
      if (f.localized) f.view.room_from_camera = f.room_from_camera;
    }
    result.room_placement_frames = result.frames_localized;
    result.marker_map = BuildBodyMarkerMap(views_of(false), camera, map_options);
  }
  t_markers += SecondsSince(t0);

  // 2b. Depth of another instant than its colour: the room-localised frames
  //     localised again with their depth as of their colour instant, by the
  //     camera's motion between the posed frames around them (the stickers
  //     pose them consistently), and the room poses they give replace the
  //     first ones; the scan's placement from them (again in step 5).
  if (options.relocalise_delayed_depth) {
    const PosedTrajectory path = posed_trajectory();
    std::vector<std::pair<size_t, Rigid3d>> to_move;  // frame, colour_from_depth
    for (size_t k = 0; k < path.frames.size(); ++k) {
      const ScanFrame& f = frames[path.frames[k]];
      if (!f.localized || f.depth_delay_s == 0) continue;
      if (const std::optional<Rigid3d> m = ColourFromDepthCamera(
              path.times, path.poses, k, f.depth_delay_s, options.relocalise_max_gap_s))
        to_move.emplace_back(path.frames[k], *m);
    }
    if (!to_move.empty()) {
      step("localising the body scan again with each frame's depth as of its colour instant", 0.56);
      t0 = Clock::now();
      CameraLocalizer again(plan.room_map, camera, localizer_options);
      for (const auto& [i, colour_from_depth] : to_move) {
        ScanFrame& f = frames[i];
        RgbdFrame frame = scan.LoadFrame(f.index, camera);
        depth_corrector.Apply(&frame.depth);
        frame.depth = DepthAtColourInstant(frame.depth, camera.depth_scale, camera.fx, camera.fy,
                                           camera.cx, camera.cy, colour_from_depth);
        frame.depth_delay_s = 0;
        again.SuggestSearchStart(f.room_from_camera);
        const LocalizationResult located = again.Localize(frame);
        if (!located.ok) continue;  // the first pose kept
        f.room_from_camera = located.room_from_camera;
        f.pos_sigma_mm = located.position_sigma_mm;
        f.rot_sigma_deg = located.rotation_sigma_deg;
        ++result.frames_relocalised_with_moved_depth;
      }
      // The scan placed by them: the sticker-posed frames moved by the
      // offset the new room poses give; the others take their new pose.
      std::vector<Offset> offsets;
      std::vector<double> offset_times;
      const Eigen::Vector3d centre = StickerCentre(result.marker_map);
      for (const ScanFrame& f : frames) {
        if (!f.localized || !f.by_stickers) continue;
        offsets.push_back(OffsetAt(f.room_from_camera * f.view.room_from_camera.Inverse(), centre));
        offset_times.push_back(f.timestamp_s);
      }
      const std::optional<Rigid3d> delta = RobustMeanOffset(offsets, centre, 0.002, 1);
      if (delta) SetRoomPlacement(MeanOffsetSigma(offsets, offset_times, 0.002), &result);
      for (ScanFrame& f : frames) {
        if (f.by_stickers) {
          if (delta) f.view.room_from_camera = *delta * f.view.room_from_camera;
        } else if (f.localized) {
          f.view.room_from_camera = f.room_from_camera;
        }
      }
      result.marker_map = BuildBodyMarkerMap(views_of(false), camera, map_options);
      t_localize += SecondsSince(t0);
    }
  }
  result.times.localization_s = t_localize;
  result.times.marker_map_s = t_markers;

  // 3. Reconstruction from the final poses.
  step("fusing the depth", 0.6);
  t0 = Clock::now();
  {
    // Depth of another instant than its colour (sensor/depth_timing.h): each
    // posed frame's depth moved to its colour instant by the camera's motion
    // between the posed frames around its depth instant. Without it the
    // scan's fast turn put the model 0.5 deg off at scan time (simulated
    // xtion seed 41, depth 10 ms late).
    const PosedTrajectory path = posed_trajectory();
    for (size_t k = 0; k < path.frames.size(); ++k) {
      ScanFrame& f = frames[path.frames[k]];
      if (f.depth_delay_s == 0 || (!f.cloud && !f.sticker_cloud)) continue;
      const std::optional<Rigid3d> colour_from_depth =
          ColourFromDepthCamera(path.times, path.poses, k, f.depth_delay_s);
      if (!colour_from_depth) continue;
      if (f.cloud) f.cloud->Transform(*colour_from_depth);
      if (f.sticker_cloud) f.sticker_cloud->Transform(*colour_from_depth);
      ++result.frames_depth_moved_to_colour;
    }
  }
  std::vector<StampedPose> camera_poses;
  Eigen::Vector3d camera_centre_sum = Eigen::Vector3d::Zero();
  std::vector<size_t> recon_candidates;  // posed frames with a depth cloud, in time order
  for (size_t i = 0; i < frames.size(); ++i) {
    const ScanFrame& f = frames[i];
    if (!f.posed) continue;
    camera_poses.push_back({f.timestamp_s, f.view.room_from_camera});
    camera_centre_sum += f.view.room_from_camera.translation;
    if (f.cloud) recon_candidates.push_back(i);
  }
  // A reconstruction follows its first frame: when most frames disagree with
  // it, it is built again from the frames the room map placed most surely
  // (up to three; their poses owe nothing to the stickers). Measured: a frame
  // posed from two 16 px stickers 6.3 deg off started a scan whose five
  // room-placed frames, 0.1-0.3 deg off, were all refused (model pose 24.7
  // mm, 6.3 deg; built again from one of them: 2.9 mm, 0.12 deg).
  std::vector<ReconstructionInput> recon_inputs;
  std::vector<std::pair<double, size_t>> room_placed;  // (sigma at the isocentre, input)
  for (size_t i : recon_candidates) {
    const ScanFrame& f = frames[i];
    if (f.localized && !f.by_stickers) {
      const double distance_m =
          (f.room_from_camera.translation - plan.room_from_model_target.translation).norm();
      room_placed.push_back(
          {FrameSigmaAtMm(f.pos_sigma_mm, f.rot_sigma_deg, distance_m), recon_inputs.size()});
    }
    recon_inputs.push_back({&*f.cloud, f.view.room_from_camera});
  }
  std::sort(room_placed.begin(), room_placed.end());
  std::vector<size_t> alternatives;
  for (size_t k = 0; k < std::min<size_t>(3, room_placed.size()); ++k)
    alternatives.push_back(room_placed[k].second);
  AnchoredReconstruction built =
      BuildAnchoredReconstruction(recon_inputs, alternatives, recon_options);
  std::unique_ptr<ReconstructionBuilder> builder = std::move(built.builder);
  recon_reports = std::move(built.reports);
  std::vector<size_t> recon_frame_of;  // the frame of each recon_reports entry
  for (size_t k : built.order) recon_frame_of.push_back(recon_candidates[k]);
  result.reconstruction_rebuilt = built.rebuilt;
  if (!recon_candidates.empty())
    result.reconstruction_anchor_frame_s = frames[recon_candidates[built.anchor]].timestamp_s;
  t_recon += SecondsSince(t0);

  // Couch and room removal: the couch top is the dominant plane facing the
  // cameras; keep what lies above it and its largest connected part.
  step("cropping the reconstruction to the body", 0.65);
  t0 = Clock::now();
  result.reconstruction_frames_fused = builder->frames_fused();
  result.reconstruction_frames_offered = builder->frames_used();
  if (result.reconstruction_frames_offered >= 3 &&
      2 * result.reconstruction_frames_fused < result.reconstruction_frames_offered) {
    result.warnings.push_back(StringPrintf(
        "only %d of the %d body-scan frames offered to the reconstruction agree on the surface "
        "(the "
        "others' poses differ from it by more than %.0f mm or %.0f deg, or overlap it too little): "
        "the surface covers less of the body and rests on those frames; check the alignment, or "
        "record the scan again with the room markers beside the couch and the stickers in view",
        result.reconstruction_frames_fused, result.reconstruction_frames_offered,
        1000 * recon_options.max_correction_m, DegFromRad(recon_options.max_correction_rad)));
  }
  PointCloud fused = builder->Cloud();
  // GICP makes the frames consistent with the first one fused, so the
  // reconstruction carries that frame's localisation error. Each refined
  // frame's correction is (first frame's error) * (its own error)^-1; their
  // mean estimates the first frame's error (the others average out): its
  // shift at the reconstruction's centre is taken off the whole cloud.
  Rigid3d anchor = Rigid3d::Identity();
  Rigid3d room_offset = Rigid3d::Identity();  // step 5's correction, when applied
  if (options.average_anchor) {
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (size_t i = 0; i < fused.size(); ++i) centre += fused.points[i].head<3>();
    centre /= static_cast<double>(std::max<size_t>(1, fused.size()));
    const Rigid3d correction = AnchorCorrection(recon_reports, centre);
    fused.Transform(correction.Inverse());
    result.anchor_shift_m = correction * centre - centre;
    result.anchor_rotation_deg = DegFromRad(correction.RotationVector().norm());
    anchor = correction;
  }
  t_recon += SecondsSince(t0);  // step 4 counts as the sticker map's time
  // 4. The stickers on today's surface. Cameras posed from 3 cm stickers
  //    keep rotation errors of 0.5-2 deg about the stickers (measured on the
  //    xtion --hard case: camera centres 20 mm off), which place the stickers
  //    consistently with each other but not with the body surface; tracking
  //    needs them on the surface (model_from_marker). So every frame that
  //    sees stickers is registered to the finished reconstruction (GICP) and
  //    the sticker map is rebuilt from those cameras alone.
  if (options.stickers_on_surface) {
    step("placing the stickers on the reconstruction", 0.66);
    const auto t_surface = Clock::now();
    std::vector<BodyScanView> views;
    std::vector<PointCloud> clouds;
    for (ScanFrame& f : frames) {
      if (!f.posed || !f.sticker_cloud) continue;
      const ReconstructionFrameReport r =
          builder->RegisterFrame(*f.sticker_cloud, f.view.room_from_camera);
      PointCloud cloud = std::move(*f.sticker_cloud);
      f.sticker_cloud.reset();
      if (!r.refined) continue;
      f.surface_pose = anchor.Inverse() * r.world_from_camera;
      if (f.view.markers.empty()) continue;
      BodyScanView v = f.view;
      v.room_from_camera = *f.surface_pose;
      views.push_back(v);
      if (options.sticker_motion_directions) clouds.push_back(std::move(cloud));
    }
    BodyMarkerMapResult on_surface = BuildBodyMarkerMap(views, camera, map_options);
    result.frames_registered_for_stickers = static_cast<int>(views.size());
    if (static_cast<int>(on_surface.markers.size()) >= options.min_stickers) {
      result.stickers_on_surface = true;
      result.marker_map = std::move(on_surface);
      // Kept, with the map as fitted to them, for the breathing stickers'
      // directions once the surface says which moved (step 6).
      surface_views = std::move(views);
      surface_view_clouds = std::move(clouds);
      surface_views_map = result.marker_map;
    }
    result.times.marker_map_s += SecondsSince(t_surface);
  }
  // 5. The room offset again, now from every room-localised frame that
  //    registered to the reconstruction (step 2 could use only frames with
  //    two mapped stickers): its room-map pose against its pose on the
  //    surface, robust mean at the stickers' centre, applied to everything.
  if (options.room_offset_from_surface && result.stickers_on_surface) {
    const Eigen::Vector3d centre = StickerCentre(result.marker_map);
    std::vector<Offset> offsets;
    std::vector<double> times;
    std::vector<double> weights;
    const double floor_mm = options.room_placement_weight_floor_mm;
    for (const ScanFrame& f : frames) {
      if (!f.localized || !f.surface_pose) continue;
      offsets.push_back(OffsetAt(f.room_from_camera * f.surface_pose->Inverse(), centre));
      times.push_back(f.timestamp_s);
      if (floor_mm > 0) {
        double at_mm = FrameSigmaAtMm(f.pos_sigma_mm, f.rot_sigma_deg,
                                      (f.room_from_camera.translation - centre).norm());
        if (!(at_mm < 1000)) at_mm = 1000;  // a sigma the localiser could not tell: next to nothing
        weights.push_back(1.0 / (at_mm * at_mm + floor_mm * floor_mm));
      }
    }
    result.surface_offset_frames = static_cast<int>(offsets.size());
    if (const auto delta = RobustMeanOffset(offsets, centre, 0.002, 3, weights)) {
      SetRoomPlacement(MeanOffsetSigma(offsets, times, 0.002, weights), &result);
      const Rigid3d& C = *delta;
      room_offset = C;
      result.surface_offset_shift_m = C * centre - centre;
      fused.Transform(C);
      for (ScanFrame& f : frames) {
        if (f.surface_pose) f.surface_pose = C * *f.surface_pose;
        if (f.posed) f.view.room_from_camera = C * f.view.room_from_camera;
      }
      for (auto& m : result.marker_map.markers) m.room_from_marker = C * m.room_from_marker;
      for (auto& p : camera_poses) p.room_from_x = C * p.room_from_x;
    }
  }
  // How well the scan is placed in the room: the patient's position at scan
  // time inherits this error (tracking does not: it keeps the stickers
  // relative to the model and places the camera in the room every frame).
  if (!(result.room_placement_sigma_mm <= options.max_room_placement_sigma_mm)) {
    result.warnings.push_back(
        result.room_placement_frames < 3
            ? StringPrintf("the body scan is placed in the room by %d frame(s) that see the room map, too few "
                           "to tell how well; record the scan again with the room markers beside the couch "
                           "in view for a few seconds",
                           result.room_placement_frames)
            : StringPrintf("the body scan is placed in the room by %d frames that see the room map, in %d "
                           "run(s) of consecutive frames, known to %.2f mm at the stickers (1 sigma; tolerance "
                           "%.2f mm); record the scan again with the room markers beside the couch in view for "
                           "longer, from several places along the couch",
                           result.room_placement_frames, result.room_placement_runs,
                           result.room_placement_sigma_mm, options.max_room_placement_sigma_mm));
    if (!result.unmapped_room_markers.empty()) {
      result.warnings.back() += "; " + DescribeUnmappedRoomMarkers(result.unmapped_room_markers, plan.room_map,
                                                                   plan.room_from_model_target.translation);
    }
  }
  // How far tracking can read the stickers with this camera.
  const double readable_px = ReadableMarkerSidePx(detector.marker_bits());
  result.sticker_reading_distance_m = camera.fx * sticker_size / readable_px;
  if (result.sticker_reading_distance_m < options.min_sticker_reading_distance_m) {
    result.warnings.push_back(StringPrintf(
        "the stickers (%.3f m) are read only within %.2f m of this camera (%.0f px across, face-on); tracking "
        "from farther loses the patient: use stickers of at least %.3f m",
        sticker_size, result.sticker_reading_distance_m, readable_px,
        options.min_sticker_reading_distance_m * readable_px / camera.fx));
  }
  t0 = Clock::now();
  for (const ScanFrame& f : frames) {
    if (!f.posed) continue;
    ScanCameraPose c;
    c.timestamp_s = f.timestamp_s;
    c.room_from_camera = f.surface_pose.value_or(f.view.room_from_camera);
    c.from_stickers = f.by_stickers;
    c.room_localized = f.localized;
    c.registered_to_surface = f.surface_pose.has_value();
    c.fused_room_from_camera = f.view.room_from_camera;
    c.localized_room_from_camera = f.room_from_camera;
    result.scan_cameras.push_back(c);
  }
  const Eigen::Vector3d box_centre = recon_options.crop_box->frame_from_box.translation;
  const Eigen::Vector3d towards_cameras =
      (camera_centre_sum / camera_poses.size() - box_centre).normalized();
  PlaneFitOptions plane_options;
  plane_options.expected_normal = towards_cameras;
  plane_options.max_angle_rad = RadFromDeg(40);
  plane_options.distance_threshold_m = 0.006;
  const auto couch = FitPlaneRansac(fused, plane_options);
  if (couch) fused = KeepAbovePlane(fused, couch->plane, 0.015);
  PointCloud body = LargestCluster(fused, 0.025);
  t_recon += SecondsSince(t0);
  result.times.reconstruction_s = t_recon;
  result.reconstruction_points = static_cast<int>(body.size());
  result.reconstruction = body;
  // When few frames were placed (in the room, or by the stickers), that is
  // the cause to name with what follows from it.
  int frames_posed = 0;
  for (const ScanFrame& f : frames) frames_posed += f.posed ? 1 : 0;
  const auto few_placed = [&]() -> std::string {
    if (2 * frames_posed >= result.frames_considered) return "";
    return StringPrintf("; the camera was placed in %d of the %d frames used (%d by the room map, %d more by the "
                        "stickers): ",
                        frames_posed, result.frames_considered, result.frames_localized,
                        result.frames_posed_by_stickers) +
           DescribeUnmappedRoomMarkers(result.unmapped_room_markers, plan.room_map,
                                       plan.room_from_model_target.translation);
  };
  if (body.size() < 500) {
    ARPOS_INPUT_ERROR(folder.body_scan_dir.string()
                      << ": no usable body surface in the scan (" << body.size()
                      << " points near the planned patient position after removing the couch)" << few_placed());
  }
  if (static_cast<int>(result.marker_map.markers.size()) < options.min_stickers) {
    // Tracking follows the patient by these stickers: without enough of
    // them the rest of the stage would store a session nobody can track.
    std::ostringstream why;
    why << folder.body_scan_dir.string() << ": " << result.marker_map.markers.size()
        << " body sticker(s) mapped (ids " << folder.config.body_markers.id_min << "-"
        << folder.config.body_markers.id_max << "), tracking needs at least " << options.min_stickers;
    if (!result.marker_map.rejected.empty()) {
      why << "; seen but left out:";
      for (const auto& [id, reason] : result.marker_map.rejected) why << " " << id << " (" << reason << ")";
    }
    // Stickers read in the scan but not mapped: the map is seeded from the
    // frames the room map places; too few of those is the cause.
    int frames_with_stickers = 0;
    for (const ScanFrame& f : frames) frames_with_stickers += f.view.markers.empty() ? 0 : 1;
    const std::string placed = frames_with_stickers >= 3 ? few_placed() : "";
    why << (placed.empty() ? ". Put stickers on skin the camera sees and record the scan again" : placed);
    ARPOS_INPUT_ERROR(why.str());
  }

  step("meshing (Poisson)", 0.7);
  t0 = Clock::now();
  {
    const KdTree tree(body);
    NormalOptions normal_options;
    normal_options.viewpoint = camera_centre_sum / camera_poses.size();
    normal_options.orient_like_existing = false;
    normal_options.num_threads = options.threads;
    EstimateNormals(&body, tree, normal_options);
    // Orient normals towards the cameras' side (the visible skin faces them).
    for (size_t i = 0; i < body.size(); ++i) {
      if (body.normal3(i).dot(towards_cameras) < 0) body.normals[i] = -body.normals[i];
    }
  }
  PoissonOptions poisson;
  poisson.depth = options.poisson_depth;
  poisson.prune_distance_m = 0.01;
  const PoissonResult mesh = PoissonMesh(body, poisson);
  result.mesh_vertices = static_cast<int>(mesh.mesh.vertices.size());
  result.mesh = mesh.mesh;
  result.times.mesh_s = SecondsSince(t0);

  // 6. Alignment.
  step("aligning the reference model", 0.8);
  t0 = Clock::now();
  const PointCloud model_dense = SampleMeshSurface(model, 0.002);
  const KdTree model_tree(model_dense);
  Rigid3d& room_from_model_initial = result.room_from_model_initial;
  std::string status = "ok";
  if (options.initial_alignment) {
    const Eigen::Matrix4d m = ReadMatrix4(*options.initial_alignment);
    std::string reason;
    if (!IsRigidTransform(m, 1e-4, &reason)) {
      ARPOS_INPUT_ERROR(options.initial_alignment->string() << ": not a rigid transform: " << reason);
    }
    room_from_model_initial = Rigid3d::FromMatrix(m, 1e-4);
    result.alignment_method_kind = AlignmentMethod::kManual;
    result.alignment_method = "manual";
  } else {
    GlobalRegistrationOptions global;
    global.prior_target_from_source = plan.room_from_model_target;
    global.max_prior_translation_m = 0.15;
    global.max_prior_rotation_rad = RadFromDeg(20);
    global.num_threads = options.threads;
    const PointCloud model_sparse = SampleMeshSurface(model, 0.005);
    const GlobalRegistrationResult g = AlignGlobal(model_sparse, body, global);
    if (g.status == GlobalRegistrationStatus::kFailed) {
      ARPOS_INPUT_ERROR("automatic alignment failed: " << g.reason
                        << "; give a manual alignment with --initial-alignment");
    }
    if (g.status == GlobalRegistrationStatus::kAmbiguous) status = "ambiguous: " + g.reason;
    room_from_model_initial = g.target_from_source;
    result.initial_fitness = g.fitness;
    result.initial_rmse_m = g.rmse_m;
    result.alignment_method_kind = AlignmentMethod::kAutomatic;
    result.alignment_method = "automatic";
  }
  RegistrationResult refined =
      RefineOnModel(body, model_dense, model_tree, room_from_model_initial.Inverse(), options.threads);
  // Breathing: the parts of the surface that moved during the scan (from
  // the fused frames themselves, surface_motion.h) are left out of a second
  // refinement when enough still surface remains.
  if (options.align_on_still_surface) {
    std::vector<SurfaceMotionFrame> motion_frames;
    for (size_t k = 0; k < recon_reports.size(); ++k) {
      if (!recon_reports[k].fused) continue;
      motion_frames.push_back({&*frames[recon_frame_of[k]].cloud,
                               room_offset * anchor.Inverse() * recon_reports[k].world_from_camera});
    }
    const Rigid3d model_from_room = refined.target_from_source;
    result.surface_motion = MeasureSurfaceMotion(motion_frames, model_dense, model_tree, model_from_room);
    if (result.surface_motion.moving_patches > 0) {
      std::vector<size_t> still;
      const double max_sq = 0.015 * 0.015;
      for (size_t i = 0; i < body.size(); ++i) {
        const Eigen::Vector3d p = model_from_room * body.point3(i);
        size_t nearest = 0;
        double sq = 0;
        if (model_tree.Nearest(Eigen::Vector4d(p.x(), p.y(), p.z(), 1), &nearest, &sq, max_sq) &&
            result.surface_motion.IsMoving(model_dense.point3(nearest))) {
          continue;
        }
        still.push_back(i);
      }
      result.still_surface_points = static_cast<int>(still.size());
      if (static_cast<double>(still.size()) >= options.min_still_surface_share * static_cast<double>(body.size())) {
        const RegistrationResult on_still =
            RefineOnModel(body.Select(still), model_dense, model_tree, refined.target_from_source, options.threads);
        if (on_still.converged) {
          refined = on_still;
          result.aligned_on_still_surface = true;
        }
      }
    }
  }
  result.room_from_model = refined.target_from_source.Inverse();
  // 7. The room around the couch as the scan saw it, for tracking
  //    (scan_landmarks.h): the frames' final poses, what moves left out;
  //    only when how well they sit in the room is known.
  if (options.scan_landmarks && std::isfinite(result.room_placement_sigma_mm)) {
    step("placing the room landmarks the scan sees", 0.95);
    const auto t_scan = Clock::now();
    std::vector<ScanLandmarkFrame> landmark_frames;
    for (ScanFrame& f : frames) {
      if (!f.posed || f.keypoints.size() == 0) continue;
      landmark_frames.push_back(
          {f.surface_pose.value_or(f.view.room_from_camera), std::move(f.keypoints)});
    }
    ScanLandmarkOptions landmark_options;
    landmark_options.exclude = {CouchExclusionBox(plan.room_from_model_target),
                                CouchExclusionBox(result.room_from_model)};
    landmark_options.triangulation.depth_sigma_const_m = localizer_options.depth_sigma_const_m;
    landmark_options.triangulation.depth_sigma_quad_per_m =
        localizer_options.depth_sigma_quad_per_m;
    landmark_options.max_landmarks = options.max_scan_landmarks;
    result.scan_landmarks =
        PlaceScanLandmarks(landmark_frames, camera, landmark_options, &plan.room_map);
    result.scan_landmarks.placement_sigma_m = result.room_placement_sigma_mm / 1000;
    result.times.scan_landmarks_s = t_landmarks + SecondsSince(t_scan);
  }
  result.alignment_fitness = refined.fitness;
  result.alignment_rmse_m = refined.rmse_m;
  result.alignment_inliers = refined.num_inliers;
  if (refined.fitness < 0.5) status = StringPrintf("poor fit: only %.0f %% of the body surface matches", 100 * refined.fitness);
  result.alignment_status = status;
  result.times.alignment_s = SecondsSince(t0);
  for (const auto& m : result.marker_map.markers) {
    result.model_from_markers[m.marker_id] = result.room_from_model.Inverse() * m.room_from_marker;
    // The sticker's patch: that of the surface point nearest its centre.
    const Eigen::Vector3d centre = result.model_from_markers[m.marker_id].translation;
    size_t nearest = 0;
    double sq = 0;
    if (model_tree.Nearest(Eigen::Vector4d(centre.x(), centre.y(), centre.z(), 1), &nearest, &sq, 0.02 * 0.02)) {
      const double motion = result.surface_motion.MotionAt(model_dense.point3(nearest));
      // (5 cm and more is not breathing but a patient who moved: the
      // store keeps motions below that.)
      if (motion > 0 && motion < 0.05) result.sticker_motion_m[m.marker_id] = motion;
    }
  }
  // 6b. The layout's scale against the stickers' printed size
  //     (layout_scale.h): the cameras of step 4 sit off along their views by
  //     what the depth's error left, and the layout they place can come out
  //     a little too large or small. The still stickers' corners in every
  //     frame that sees them, each camera free, say by how much; only what
  //     exceeds the bias of the stickers' size as read is removed.
  if (options.layout_scale_from_sticker_size) {
    std::vector<BodyScanView> seen;
    for (const ScanFrame& f : frames) {
      if (!f.view.markers.empty()) seen.push_back(f.view);
    }
    std::set<int> moving;
    for (const auto& [id, motion] : result.sticker_motion_m) moving.insert(id);
    LayoutScaleOptions scale_options;
    scale_options.marker_size_m = sticker_size;
    const double widening_px = response.estimated ? response.estimate.widening_px : -1.0;
    result.layout_scale = EstimateLayoutScale(seen, result.model_from_markers, moving, camera,
                                              widening_px, scale_options);
    if (result.layout_scale.ok && result.layout_scale.scale != 1.0) {
      ScaleLayout(result.layout_scale.scale, &result.model_from_markers);
      ScaleLayout(result.layout_scale.scale, &result.marker_map);
      ScaleLayout(result.layout_scale.scale, &surface_views_map);
    }
  }
  // Which way the moving stickers moved, from their corners in the views
  // the sticker map is fitted to (sticker_motion.h): where determined, the
  // direction and how far along it; else along the normal, as measured.
  if (options.sticker_motion_directions && !result.sticker_motion_m.empty() &&
      !surface_views.empty()) {
    step("measuring which way the breathing stickers moved", 0.97);
    const auto t_motion = Clock::now();
    // The views placed again, each on the reference model's still surface
    // (what the breathing did not move): registered to the reconstruction,
    // which holds the chest at every phase, a view turns a little with the
    // chest it sees, and the stickers' motion would be measured against
    // that turn. Placed on the still anatomy, it is measured against the
    // body. A view that does not settle there is left out.
    const Rigid3d model_from_room = result.room_from_model.Inverse();
    std::vector<size_t> still_points;
    for (size_t i = 0; i < model_dense.size(); ++i) {
      if (!result.surface_motion.IsMoving(model_dense.point3(i))) still_points.push_back(i);
    }
    const PointCloud model_still = model_dense.Select(still_points);
    const KdTree still_tree(model_still);
    // At most 40 views, spread over the scan; each view's depth cropped to
    // the model's box (2 cm around it) before the registration.
    Eigen::AlignedBox3d box = model_dense.Bounds();
    box.min() -= Eigen::Vector3d::Constant(0.02);
    box.max() += Eigen::Vector3d::Constant(0.02);
    const size_t n_views = std::min(surface_views.size(), surface_view_clouds.size());
    const size_t view_step = (n_views + 39) / 40;
    std::vector<BodyScanView> on_still;
    for (size_t k = 0; k < n_views; k += std::max<size_t>(1, view_step)) {
      BodyScanView v = surface_views[k];
      v.room_from_camera = room_offset * v.room_from_camera;
      const Rigid3d model_from_camera = model_from_room * v.room_from_camera;
      std::vector<size_t> near;
      for (size_t i = 0; i < surface_view_clouds[k].size(); ++i) {
        if (box.contains(model_from_camera * surface_view_clouds[k].point3(i))) near.push_back(i);
      }
      const RegistrationResult r = RefineOnModel(surface_view_clouds[k].Select(near), model_still,
                                                 still_tree, model_from_camera, options.threads);
      if (!r.converged || r.num_inliers < 500) continue;
      v.room_from_camera = result.room_from_model * r.target_from_source;
      on_still.push_back(std::move(v));
    }
    for (auto& m : surface_views_map.markers) m.room_from_marker = room_offset * m.room_from_marker;
    StickerMotionOptions motion_options;
    motion_options.marker_size_m = sticker_size;
    result.sticker_motion = EstimateStickerMotion(on_still, surface_views_map, camera,
                                                  result.sticker_motion_m, motion_options);
    for (const StickerMotionEstimate& e : result.sticker_motion.stickers) {
      if (!e.ok || !(e.motion_m > 0 && e.motion_m < 0.05)) continue;
      result.sticker_motion_direction[e.marker_id] = e.direction_in_marker;
      result.sticker_motion_m[e.marker_id] = e.motion_m;
    }
    result.times.sticker_motion_s = SecondsSince(t_motion);
  }
  // 6c. Each sticker on the aligned reference surface (sticker_surface.h).
  //     One far off it is left out of the map while enough stickers
  //     remain (on a simulated scan whose model came out 6 deg turned,
  //     tracking with its three off-surface stickers left out: 12.8 ->
  //     7.1 mm); the alignment's status asks for a check either way.
  StickerSurfaceOptions surface_check;
  surface_check.max_off_m = options.max_sticker_off_model_m;
  result.sticker_surface = CheckStickersOnSurface(result.model_from_markers, model_tree,
                                                  result.sticker_motion_m, surface_check);
  if (!result.sticker_surface.off.empty()) {
    const size_t mapped = result.model_from_markers.size();
    const size_t off = result.sticker_surface.off.size();
    const bool leave_out = mapped - off >= static_cast<size_t>(std::max(1, options.min_stickers));
    if (leave_out) {
      for (int id : result.sticker_surface.off) {
        result.model_from_markers.erase(id);
        result.sticker_motion_m.erase(id);
        result.sticker_motion_direction.erase(id);
        auto& markers = result.marker_map.markers;
        markers.erase(std::remove_if(markers.begin(), markers.end(),
                                     [id](const auto& m) { return m.marker_id == id; }),
                      markers.end());
        result.marker_map.rejected[id] = StringPrintf("%.1f mm off the aligned reference surface",
                                                      1000 * result.sticker_surface.off_m.at(id));
      }
    }
    result.warnings.push_back(StringPrintf(
        "%zu of %zu sticker(s) lie off the aligned reference surface by more than %.0f mm "
        "beyond their breathing: %s; stickers sit on the skin, so the sticker map or the "
        "alignment is wrong there (%s): check the alignment (arpos gui, the session's surface "
        "against the model) and record the scan again with every sticker seen near and from "
        "several sides",
        off, mapped, 1000 * options.max_sticker_off_model_m,
        result.sticker_surface.DescribeOff().c_str(),
        leave_out ? "left out of the map" : "kept: too few would remain"));
    const std::string check = "check: " + std::to_string(off) + " sticker(s) off the aligned model";
    result.alignment_status =
        result.alignment_status == "ok" ? check : result.alignment_status + "; " + check;
  }
  return result;
}

void WriteSessionOutputs(const std::filesystem::path& out_dir, const CaseFolder& folder,
                         const SessionStageResult& result) {
  const Sequence scan = Sequence::Open(folder.body_scan_dir);
  std::vector<StampedPose> model_poses;
  for (size_t i = 0; i < scan.size(); ++i) model_poses.push_back({scan.timestamp_s(i), result.room_from_model});
  WriteTrajectory(out_dir / "model_pose.txt", model_poses,
                  "reference model -> room at body-scan time (arpos session)");
  std::vector<StampedPose> camera_poses;
  for (const ScanCameraPose& c : result.scan_cameras) camera_poses.push_back({c.timestamp_s, c.fused_room_from_camera});
  WriteTrajectory(out_dir / "camera_pose.txt", camera_poses,
                  "camera -> room, body-scan frames used (arpos session)");
  if (!result.mesh.empty()) SaveTriangleMeshPly(result.mesh, out_dir / "reconstruction_mesh.ply");
}

void StoreSession(Database* database, const CaseFolder& folder, const SessionStageOptions& options,
                  SessionStageResult* result) {
  ARPOS_CHECK(database != nullptr && result != nullptr, "storing a session needs a store and a result");
  const bool may_use_unapproved = options.unapproved || options.op.role == Role::kResearch;
  const std::string actor = options.op.Actor("arpos session");
  const PlanId plan_id = result->plan_id;
  database->WithTransaction([&] {
    SessionRecord session;
    session.plan_id = plan_id;
    session.fraction = static_cast<int>(database->ListSessions(plan_id).size()) + 1;
    session.operator_name = options.op.Actor();
    session.notes = "session stage on " + folder.root.string() + "; " + result->RoomPlacementText();
    if (const std::string motion = result->SurfaceMotionText(); !motion.empty()) session.notes += "; " + motion;
    for (const std::string& w : result->warnings) session.notes += "; warning: " + w;
    session.on_unapproved_plan = result->on_unapproved_plan;
    // The plan's approval as it is when the session opens (inside the
    // transaction: a plan approved meanwhile is seen).
    const std::optional<PlanRecord> plan_now = database->GetPlan(plan_id);
    if (!plan_now) ARPOS_INPUT_ERROR("plan " << plan_id.value() << " does not exist");
    if (!plan_now->approved() && !may_use_unapproved) {
      ARPOS_INPUT_ERROR("plan " << plan_id.value() << " is not approved");
    }
    session.on_unapproved_plan = !plan_now->approved();
    result->on_unapproved_plan = session.on_unapproved_plan;
    result->session_id = database->AddSession(session);
    const std::string session_entity = "session:" + std::to_string(result->session_id.value());
    std::string approval = DescribeApproval(*plan_now);
    if (!plan_now->approved()) {
      approval += options.unapproved ? " (run with --unapproved)" : " (research run)";
    }
    database->AppendAudit({AuditId(), 0, actor, "open_session", session_entity,
                            "plan " + std::to_string(plan_id.value()) + ", " + approval});
    RecordingRecord recording;
    recording.session_id = result->session_id;
    recording.kind = RecordingKind::kBodyScan;
    recording.name = "body_scan";
    recording.path = std::filesystem::absolute(folder.body_scan_dir).lexically_normal().string();
    recording.frame_count = static_cast<std::int64_t>(result->frames);
    recording.intrinsics = ToRecordingIntrinsics(folder.config.camera);
    result->recording_id = database->AddRecording(recording);

    BodyMarkerMapRecord map;
    map.session_id = result->session_id;
    map.recording_id = result->recording_id;
    map.marker_size_m = folder.config.body_markers.size_m;
    for (const auto& m : result->marker_map.markers) {
      const auto motion = result->sticker_motion_m.find(m.marker_id);
      const auto direction = result->sticker_motion_direction.find(m.marker_id);
      map.markers.push_back({m.marker_id, m.room_from_marker, m.rms_px, m.num_views,
                             motion != result->sticker_motion_m.end() ? motion->second : 0.0,
                             motion != result->sticker_motion_m.end() &&
                                     direction != result->sticker_motion_direction.end()
                                 ? direction->second
                                 : Eigen::Vector3d::UnitZ()});
    }
    map.surface_patch_m = result->surface_motion.patch_m;
    map.moving_surface_patches = result->surface_motion.MovingPatchCentres();
    ToRecord(result->scan_landmarks, &map);
    map.mean_residual_px = result->marker_map.mean_rms_px;
    map.max_residual_px = std::max(result->marker_map.max_rms_px, map.mean_residual_px);
    result->body_marker_map_id = database->AddBodyMarkerMap(map);
    database->AppendAudit({AuditId(), 0, actor, "add_body_marker_map",
                            "body_marker_map:" + std::to_string(result->body_marker_map_id.value()),
                            StringPrintf("%zu stickers, mean rms %.3f px, %s", map.markers.size(),
                                         map.mean_residual_px,
                                         result->stickers_on_surface
                                             ? StringPrintf("cameras registered to the reconstruction (%d frames)",
                                                            result->frames_registered_for_stickers)
                                                   .c_str()
                                             : "sticker-consistent cameras")});

    ReconstructionRecord recon;
    recon.session_id = result->session_id;
    recon.recording_id = result->recording_id;
    recon.cloud = ToStored(result->reconstruction);
    if (!result->mesh.empty()) recon.mesh = ToStoredMesh(result->mesh);
    recon.num_frames_used = result->reconstruction_frames_fused;
    recon.voxel_size_m = result->reconstruction_voxel_m;
    result->reconstruction_id = database->AddReconstruction(recon);
    database->AppendAudit({AuditId(), 0, actor, "add_reconstruction",
                            "reconstruction:" + std::to_string(result->reconstruction_id.value()),
                            StringPrintf("%zu points, %zu mesh vertices", result->reconstruction.size(),
                                         result->mesh.vertices.size())});

    AlignmentRecord initial;
    initial.reconstruction_id = result->reconstruction_id;
    initial.method = result->alignment_method_kind;
    initial.reconstruction_from_model = result->room_from_model_initial;
    initial.fitness = std::clamp(result->initial_fitness, 0.0, 1.0);
    initial.rmse_m = std::max(0.0, result->initial_rmse_m);
    initial.options = options.initial_alignment ? "file: " + options.initial_alignment->string()
                                                 : "global registration, target-pose prior";
    const AlignmentId initial_id = database->AddAlignment(initial);
    database->AppendAudit({AuditId(), 0, actor, "add_alignment",
                            "alignment:" + std::to_string(initial_id.value()),
                            result->alignment_method + " (the start of the ICP refinement that follows)"});
    AlignmentRecord icp;
    icp.reconstruction_id = result->reconstruction_id;
    icp.parent_alignment_id = initial_id;
    icp.method = AlignmentMethod::kIcp;
    icp.reconstruction_from_model = result->room_from_model;
    icp.fitness = std::clamp(result->alignment_fitness, 0.0, 1.0);
    icp.rmse_m = result->alignment_rmse_m;
    icp.num_inliers = result->alignment_inliers;
    icp.options = "point-to-plane, reconstruction onto the model surface, gates 30/10/5 mm; " +
                  std::string(AlignmentRecord::kStatusKey) + result->alignment_status;
    result->alignment_id = database->AddAlignment(icp);
    database->AppendAudit({AuditId(), 0, actor, "add_alignment",
                            "alignment:" + std::to_string(result->alignment_id.value()),
                            result->alignment_method + " + ICP: " + result->alignment_status +
                                StringPrintf(", rmse %.2f mm", 1000 * result->alignment_rmse_m)});
  });
}

}  // namespace arpos
