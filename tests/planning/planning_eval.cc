// planning_eval: accuracy of the room map and of camera localisation on a
// simulated case (not a test; prints a report).
//
//   planning_eval CASE_DIR [--store DB] [--only SEQ] [--frame-step N] [--no-keypoints]
//                 [--loc-no-keypoints] [--no-marker-depth] [--no-keypoint-depth]
//                 [--response NAME|estimate] [--corner-sigma PX] [--prior-m M] [--prior-deg D]
//                 [--kp-sigma PX] [--min-kp N] [--depth-const M] [--depth-quad M]
//
// --store DB uses the newest room map in DB instead of building one.
// Diagnostics by environment: NO_LOC=1 (map only), TRUTH_MARKERS=1 (localise
// against the true marker poses), AXES=1 (camera error in camera axes),
// NO_DEPTH_CHECK=1 (no depth check against the colour geometry), SUPPORT=1 (with
// the origin's support plane in depth),
// NO_COPLANAR=1 (without the coplanar markers),
// SUPPORT_HW, SUPPORT_MIN_DEG, FIT_FRAME_ERRORS=1 (room frames' errors in the map's
// best rigid fit to the truth: the cameras' own errors without the room frame's),
// MIN_LM_OBS, MAX_LM, LM_VOXEL, SUPPORT_PX, CORNER_FLOOR, RELOC_SIGMA_M, MAX_SIGMA_M (option overrides),
// NO_FILTER=1 (no constant-velocity filter), NO_PRIOR=1 (no motion prior at all),
// TRUTH_START=1 (every frame relocalised from its true pose), TILT_GATE_ONLY=1 (the
// origin's tilt fused with its coplanar markers only when the tilt itself is weak),
// NO_SURFACE=1 (the localiser without the room's surface), SURF_MAXEFF, SURF_GATE, SURF_FLAT, SURF_VOXEL,
// SURF_RADIUS (surface option overrides), SURF_CORRECTED=1 (the surface used after a depth correction too), SURF_KEEP_RADIUS=M (only the stored surface within M of the couch point), SURF_XYZ=FILE (the surface's points
// and normals written one a line), NO_HELD=1 (no frame held by depth and the motion filter alone), HELD_SIGMA=M,
// HELD_FRAMES=N (its limits; FRAME_LOC prints such a frame as "held").
// Besides MTE/MRE it prints the isocentre transfer error: the isocentre as
// the true camera sees it, put into the room by the estimated camera (what a
// camera error does to the patient's position).
//
// Builds the map from CASE_DIR/room (as `arpos plan` does, without a store),
// compares every mapped marker with simulation.yaml (corner errors, mm), then
// localises every sequence (room, body_scan, tracking/*) and evaluates it
// against groundtruth.txt exactly as `arpos evaluate` does (MTE/MRE, lost).
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <string>

#include <opencv2/core.hpp>

#include "eval/trajectory_eval.h"
#include "features/response_from_recording.h"
#include "geometry/so3.h"
#include "geometry/umeyama.h"
#include "room_map/camera_localizer.h"
#include "room_map/plan_stage.h"
#include "sensor/case_folder.h"
#include "sensor/depth_correction.h"
#include "sensor/sequence.h"
#include "store/sqlite_database.h"
#include "simulation/sensor_model.h"
#include "simulation/simulation_truth.h"
#include "util/check.h"
#include "util/string_util.h"

using namespace arpos;

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: planning_eval CASE_DIR [--frame-step N] [--no-keypoints] [--loc-no-keypoints]\n");
    return 2;
  }
  try {
    const std::filesystem::path case_dir = argv[1];
    RoomMapStageOptions stage;
    bool loc_keypoints = true, marker_depth = true, keypoint_depth = true;
    std::string response = "estimate";
    double corner_sigma = -1, prior_m = -1, prior_deg = -1, kp_sigma = -1;
    int min_kp = -1;
    double depth_quad = -1, depth_const = -1;
    std::string store, only;
    for (int i = 2; i < argc; ++i) {
      if (!std::strcmp(argv[i], "--no-marker-depth")) marker_depth = false;
      if (!std::strcmp(argv[i], "--no-keypoint-depth")) keypoint_depth = false;
      if (!std::strcmp(argv[i], "--response") && i + 1 < argc) response = argv[i + 1];
      if (!std::strcmp(argv[i], "--corner-sigma") && i + 1 < argc) corner_sigma = std::atof(argv[i + 1]);
      if (!std::strcmp(argv[i], "--prior-m") && i + 1 < argc) prior_m = std::atof(argv[i + 1]);
      if (!std::strcmp(argv[i], "--prior-deg") && i + 1 < argc) prior_deg = std::atof(argv[i + 1]);
      if (!std::strcmp(argv[i], "--kp-sigma") && i + 1 < argc) kp_sigma = std::atof(argv[i + 1]);
      if (!std::strcmp(argv[i], "--min-kp") && i + 1 < argc) min_kp = std::atoi(argv[i + 1]);
      if (!std::strcmp(argv[i], "--depth-quad") && i + 1 < argc) depth_quad = std::atof(argv[i + 1]);
      if (!std::strcmp(argv[i], "--depth-const") && i + 1 < argc) depth_const = std::atof(argv[i + 1]);
      if (!std::strcmp(argv[i], "--store") && i + 1 < argc) store = argv[i + 1];
      if (!std::strcmp(argv[i], "--only") && i + 1 < argc) only = argv[i + 1];
      if (!std::strcmp(argv[i], "--frame-step") && i + 1 < argc) stage.frame_step = std::atoi(argv[++i]);
      else if (!std::strcmp(argv[i], "--no-keypoints")) stage.use_keypoints = false;
      else if (!std::strcmp(argv[i], "--loc-no-keypoints")) loc_keypoints = false;
    }
    const CaseFolder folder = LoadCaseFolder(case_dir);
    const Sequence room = Sequence::Open(folder.room_dir);
    RoomMapBuildOptions build_options = MakeRoomMapBuildOptions(folder, stage);
    build_options.bundle_adjustment.use_marker_depth = marker_depth;
    build_options.bundle_adjustment.use_keypoint_depth = keypoint_depth;
    if (const char* v = std::getenv("SURF_FLAT")) build_options.surface.max_unflatness_m = std::atof(v);
    if (const char* v = std::getenv("SURF_VOXEL")) build_options.surface.voxel_m = std::atof(v);
    if (const char* v = std::getenv("SURF_RADIUS")) build_options.surface.radius_m = std::atof(v);
    if (response != "estimate") {
      build_options.estimate_response = false;
      build_options.detector.edge.response = CameraResponse::FromName(response);
    }
    if (corner_sigma > 0) build_options.marker_corner_sigma_px = corner_sigma;
    if (const char* v = std::getenv("MIN_LM_OBS")) build_options.min_landmark_observations = std::atoi(v);
    if (std::getenv("NO_DEPTH_CHECK")) build_options.estimate_depth_correction = false;
    if (const char* v = std::getenv("DEPTH_SUPPORT_M")) build_options.depth_check_plane_support_m = std::atof(v);
    if (std::getenv("SUPPORT")) build_options.use_support_plane = true;
    if (std::getenv("NO_BA_PLANES")) build_options.use_room_planes = false;
    if (std::getenv("NO_ORIGIN_PLANE")) build_options.room_plane_for_origin = false;
    if (std::getenv("NO_PLANE_TIES")) build_options.room_plane_ties_markers = false;
    if (const char* v = std::getenv("PLANE_TILT_DEG")) build_options.room_plane_marker_tilt_deg = std::atof(v);
    if (std::getenv("NO_DEPTH_PLANES")) build_options.room_planes_from_depth = false;
    if (const char* v = std::getenv("DEPTH_PLANE_MAX_M")) build_options.room_plane_depth_max_m = std::atof(v);
    if (const char* v = std::getenv("DEPTH_PLANE_EXTENT_M")) build_options.depth_planes.min_extent_m = std::atof(v);
    if (const char* v = std::getenv("BA_PLANE_EFF")) build_options.room_plane_max_effective = std::atof(v);
    if (std::getenv("NO_COPLANAR")) build_options.use_coplanar_markers = false;
    if (std::getenv("TILT_GATE_ONLY")) build_options.fuse_tilt_when_weak_at_couch = false;
    if (const char* v = std::getenv("SUPPORT_HW")) build_options.support_plane_half_width_m = std::atof(v);
    if (const char* v = std::getenv("SUPPORT_MIN_DEG")) build_options.support_plane_min_sigma_deg = std::atof(v);
    if (const char* v = std::getenv("MAX_LM")) build_options.max_landmarks = std::atoi(v);
    if (const char* v = std::getenv("LM_VOXEL")) build_options.landmark_voxel_m = std::atof(v);
    if (const char* v = std::getenv("LOC_LM")) build_options.max_localization_landmarks = std::atoi(v);
    RoomMapBuildResult build;
    if (!store.empty()) {
      auto db = SqliteDatabase::Open(store);
      build.map = LoadRoomMapForLocalization(db.get(), std::nullopt, "");
    } else {
      build = BuildRoomMap(room, folder.config, build_options);
    }
    std::cout << build.report.ToText();
    if (const char* v = std::getenv("SURF_KEEP_RADIUS")) {
      // Only the surface within this distance of the couch point.
      RoomSurface kept;
      kept.voxel_m = build.map.surface.voxel_m;
      const Eigen::Vector3d centre = folder.room_from_model_target.translation;
      for (size_t i = 0; i < build.map.surface.size(); ++i) {
        if ((build.map.surface.points[i].cast<double>() - centre).norm() > std::atof(v)) continue;
        kept.points.push_back(build.map.surface.points[i]);
        kept.normals.push_back(build.map.surface.normals[i]);
      }
      build.map.surface = kept;
    }
    if (const char* v = std::getenv("SURF_XYZ")) {
      // The map's room surface, one point and normal a line (room frame).
      FILE* f = std::fopen(v, "w");
      for (size_t i = 0; f && i < build.map.surface.size(); ++i) {
        const auto& p = build.map.surface.points[i];
        const auto& n = build.map.surface.normals[i];
        std::fprintf(f, "%.4f %.4f %.4f %.3f %.3f %.3f\n", p.x(), p.y(), p.z(), n.x(), n.y(), n.z());
      }
      if (f) std::fclose(f);
    }

    // Markers against the truth.
    const sim::SimulationTruth truth = sim::LoadSimulationTruth(case_dir / "simulation.yaml");
    double sum = 0, worst = 0;
    int n = 0;
    std::cout << "marker  corner error mean/max (mm)  centre error (mm)  views\n";
    for (const auto& m : build.map.markers) {
      for (const auto& t : truth.room_markers) {
        if (t.id != m.id) continue;
        double e_sum = 0, e_max = 0;
        for (int c = 0; c < 4; ++c) {
          const double e = (m.corners_in_room[c] - t.corners_m[c]).norm() * 1000;
          e_sum += e;
          e_max = std::max(e_max, e);
          sum += e;
          ++n;
          worst = std::max(worst, e);
        }
        const double centre = (m.room_from_marker.translation - t.parent_from_marker.translation).norm() * 1000;
        std::cout << StringPrintf("  %3d   %6.3f / %6.3f           %6.3f           %d\n", m.id, e_sum / 4, e_max,
                                  centre, m.num_observations);
      }
    }
    {
      // What the patient feels: markers within 1.5 m of the couch point, in the map's own room frame.
      double near_sum = 0;
      int near_n = 0;
      for (const auto& m : build.map.markers) {
        for (const auto& t : truth.room_markers) {
          if (t.id != m.id || (t.parent_from_marker.translation - build_options.couch_point_in_room).norm() > 1.5) continue;
          for (int c = 0; c < 4; ++c) near_sum += (m.corners_in_room[c] - t.corners_m[c]).norm() * 1000;
          near_n += 4;
        }
      }
      std::cout << StringPrintf("markers within 1.5 m of the couch point: %d, corner error mean %.3f mm\n", near_n / 4,
                                near_n ? near_sum / near_n : 0.0);
    }
    {
      // The plan's depth correction against the simulated depth error, both
      // at 1 m over the image (every 8th pixel): what the correction leaves.
      const CameraIntrinsics& K = folder.config.camera;
      cv::Mat field;
      if (truth.depth_field_mm_at_1m != 0) field = sim::MakeDepthErrorField(K.width, K.height, truth.depth_field_seed);
      const DepthCorrection& c = build.map.depth_correction;
      double s_true = 0, s_left = 0, max_left = 0;
      int count = 0;
      for (int y = 0; y < K.height; y += 8) {
        for (int x = 0; x < K.width; x += 8) {
          const double t = 1000 * truth.depth_scale_error +
                           (field.empty() ? 0.0 : truth.depth_field_mm_at_1m * field.at<float>(y, x));
          const double xn = (x - K.cx) / K.fx, yn = (y - K.cy) / K.fy;
          const double e = c.IsIdentity() ? 0.0 : 1000 * (1.0 - c.TrueDepth(1.0, xn, yn));
          s_true += t * t;
          s_left += (t - e) * (t - e);
          max_left = std::max(max_left, std::abs(t - e));
          ++count;
        }
      }
      if (std::getenv("FIELD_MAP")) {
        // What the correction leaves (mm at 1 m), over a 8 x 6 grid of the image.
        std::cout << "depth error at 1 m, simulated / left after the plan's correction (mm), 8 x 6 over the image:\n";
        for (int gy = 0; gy < 6; ++gy) {
          for (int gx = 0; gx < 8; ++gx) {
            const int x = (2 * gx + 1) * K.width / 16, y = (2 * gy + 1) * K.height / 12;
            const double t = 1000 * truth.depth_scale_error +
                             (field.empty() ? 0.0 : truth.depth_field_mm_at_1m * field.at<float>(y, x));
            const double e =
                c.IsIdentity() ? 0.0 : 1000 * (1.0 - c.TrueDepth(1.0, (x - K.cx) / K.fx, (y - K.cy) / K.fy));
            std::cout << StringPrintf("%6.2f/%-6.2f", t, t - e);
          }
          std::cout << "\n";
        }
      }
      std::cout << StringPrintf("depth error at 1 m over the image: %.3f mm RMS simulated, %.3f mm RMS left after the "
                                "plan's correction (max %.3f)\n",
                                std::sqrt(s_true / count), std::sqrt(s_left / count), max_left);
    }
    std::cout << StringPrintf("markers mapped: %zu of %zu; corner error mean %.3f mm, max %.3f mm\n",
                              build.map.markers.size(), truth.room_markers.size(), n ? sum / n : 0.0, worst);
    Rigid3d truth_from_map;  // the best rigid fit of the map's corners to the truth
    {
      // Internal consistency: the map's corners after the best rigid fit to the truth.
      std::vector<Eigen::Vector3d> est, tru;
      for (const auto& m : build.map.markers) {
        for (const auto& t : truth.room_markers) {
          if (t.id != m.id) continue;
          for (int c = 0; c < 4; ++c) {
            est.push_back(m.corners_in_room[c]);
            tru.push_back(t.corners_m[c]);
          }
        }
      }
      const auto sim3 = EstimateRigidTransform(est, tru, true);
      if (sim3) std::cout << StringPrintf("similarity fit: scale %.5f, rmse %.3f mm\n", sim3->scale, sim3->rmse_m * 1000);
      const auto fit = EstimateRigidTransform(est, tru);
      if (fit) {
        truth_from_map = fit->target_from_source;
        const Eigen::Vector3d couch = build_options.couch_point_in_room;
        std::cout << StringPrintf("room frame error at the couch point (map's best fit to the truth): %.3f mm\n",
                                  (truth_from_map * couch - couch).norm() * 1000);
        // Its turn about the origin's in-plane axes (tilt) and its normal (yaw).
        const Eigen::Vector3d w = RotationVectorFromQuaternion(truth_from_map.rotation);
        std::cout << StringPrintf("room frame turn (map's best fit to the truth): tilt %.4f deg, yaw %.4f deg\n",
                                  DegFromRad(std::hypot(w.x(), w.y())), DegFromRad(std::abs(w.z())));
        double s2 = 0, mx = 0;
        for (size_t i = 0; i < est.size(); ++i) {
          const double e = (fit->target_from_source * est[i] - tru[i]).norm() * 1000;
          s2 += e;
          mx = std::max(mx, e);
        }
        std::cout << StringPrintf("after a rigid fit to the truth: corner error mean %.3f mm, max %.3f mm; frame offset %s\n",
                                  s2 / est.size(), mx, fit->target_from_source.ToString().c_str());
      }
    }
    if (store.empty()) {
      // The room frames' own poses from the adjustment.
      std::vector<StampedPose> est;
      for (const auto& [index, pose] : build.report.room_from_camera) est.push_back({room.timestamp_s(index), pose});
      const TrajectoryEvaluation e = EvaluateTrajectory(*room.CameraGroundTruth(), est);
      std::cout << StringPrintf("room frames (bundle adjusted): MTE %.3f mm, MRE %.4f deg, max %.3f mm, lost %.1f %%\n",
                                e.translation_mm.mean, e.rotation_deg.mean, e.translation_mm.max, e.lost_percent);
      if (std::getenv("FIT_FRAME_ERRORS")) {
        // The frames in the map's best fit to the truth: camera errors without
        // the room frame's; rotation error as a vector in the room frame (deg).
        const auto truth_poses = *room.CameraGroundTruth();
        for (const StampedPose& p : est) {
          for (const StampedPose& t : truth_poses) {
            if (std::abs(t.timestamp_s - p.timestamp_s) > 1e-4) continue;
            const Rigid3d fitted = truth_from_map * p.room_from_x;
            const Eigen::AngleAxisd aa(fitted.rotation * t.room_from_x.rotation.inverse());
            const Eigen::Vector3d r = aa.axis() * aa.angle() * 180 / M_PI;
            std::cout << StringPrintf("  room frame at %.3f s in the fitted map: %.2f mm, rotation [%.3f %.3f %.3f] deg\n",
                                      p.timestamp_s, (fitted.translation - t.room_from_x.translation).norm() * 1000,
                                      r.x(), r.y(), r.z());
          }
        }
      }
      if (std::getenv("FRAME_ERRORS")) {
        for (const FrameError& f : e.frames) {
          std::cout << StringPrintf("  room frame at %.3f s: %.2f mm %.3f deg\n", f.timestamp_s, f.error.translation_mm, f.error.rotation_deg);
        }
      }
    }

    if (std::getenv("TRUTH_MARKERS")) {
      // Diagnostic: the map's markers replaced by the true ones.
      for (auto& m : build.map.markers) {
        for (const auto& t : truth.room_markers) {
          if (t.id != m.id) continue;
          m.room_from_marker = t.parent_from_marker;
          m.corners_in_room = t.corners_m;
        }
      }
    }
    // Localisation of every sequence.
    CameraLocalizerOptions options = MakeCameraLocalizerOptions(folder.config);
    options.use_keypoints = loc_keypoints;
    if (std::getenv("NO_LOC")) return 0;
    if (prior_m > 0) options.motion_prior_sigma_m = prior_m;
    if (prior_deg > 0) options.motion_prior_sigma_deg = prior_deg;
    if (kp_sigma > 0) options.keypoint_sigma_px = kp_sigma;
    if (min_kp > 0) options.min_keypoints = min_kp;
    if (const char* v = std::getenv("SUPPORT_PX")) options.marker_support_side_px = std::atof(v);
    if (const char* v = std::getenv("CORNER_FLOOR")) options.marker_corner_sigma_px = std::atof(v);
    if (const char* v = std::getenv("RELOC_SIGMA_M")) options.max_relocalisation_position_sigma_m = std::atof(v);
    if (const char* v = std::getenv("MAX_SIGMA_M")) options.max_position_sigma_m = std::atof(v);
    if (const char* v = std::getenv("MAX_EDGE_PX")) options.detector.edge.max_pixels_per_edge = std::atoi(v);
    if (std::getenv("NO_PLANES")) options.use_room_planes = false;
    if (std::getenv("NO_SURFACE")) options.use_room_surface = false;
    if (std::getenv("NO_HELD")) options.depth_held_tracking = false;
    if (const char* v = std::getenv("HELD_SIGMA")) options.max_depth_held_position_sigma_m = std::atof(v);
    if (const char* v = std::getenv("HELD_FRAMES")) options.max_depth_held_frames = std::atoi(v);
    if (const char* v = std::getenv("SURF_MAXEFF")) options.room_surface_max_effective = std::atof(v);
    if (const char* v = std::getenv("SURF_GATE")) options.room_surface_gate_m = std::atof(v);
    if (std::getenv("SURF_CORRECTED")) options.room_surface_with_corrected_depth = true;
    if (const char* v = std::getenv("BAND_PX")) options.detector.edge.band_half_width_px = std::atof(v);
    if (const char* v = std::getenv("ACCEL")) options.motion_accel_m_s2 = std::atof(v);
    if (const char* v = std::getenv("ANG_ACCEL")) options.motion_angular_accel_rad_s2 = std::atof(v);
    if (const char* v = std::getenv("WEAK")) options.weak_tracking_fraction = std::atof(v);
    if (std::getenv("NO_FILTER")) options.motion_filter = false;
    if (std::getenv("NO_PRIOR")) options.use_motion_prior = false;
    if (depth_quad >= 0) options.depth_sigma_quad_per_m = depth_quad;
    if (depth_const >= 0) options.depth_sigma_const_m = depth_const;
    std::vector<std::pair<std::string, std::filesystem::path>> sequences = {{"room", folder.room_dir},
                                                                           {"body_scan", folder.body_scan_dir}};
    for (const auto& t : folder.tracking) sequences.push_back({"tracking/" + t.first, t.second});
    std::cout << "sequence           frames  localised   MTE mm  median  p95     max     MRE deg  ms/frame(CPU)\n";
    for (const auto& [name, dir] : sequences) {
      if (!std::filesystem::is_directory(dir)) continue;
      if (!only.empty() && name.find(only) == std::string::npos) continue;
      const Sequence seq = Sequence::Open(dir);
      if (response == "estimate") {
        const RecordingResponse rr = EstimateRecordingResponse(seq, folder.config, build.map.camera_response);
        options.detector.edge.response = rr.response;
        std::cout << name << ": " << rr.message << "\n";
      } else {
        options.detector.edge.response = build.map.camera_response;
      }
      CameraLocalizer localizer(build.map, folder.config.camera, options);
      std::vector<StampedPose> est;
      int lost = 0, lost_with_marker = 0;  // lost frames, and those with a mapped room marker detected
      double ms = 0;
      LocalizationTimings sum_t;
      // Read once and held: a range-for over *seq.CameraGroundTruth() would
      // walk a vector inside a temporary already destroyed.
      const std::optional<std::vector<StampedPose>> camera_truth = seq.CameraGroundTruth();
      for (size_t i = 0; i < seq.size(); ++i) {
        RgbdFrame frame = seq.LoadFrame(i, folder.config.camera);
        // As tracking reads it: the map's depth correction removed.
        if (!frame.depth.empty()) CorrectDepthImage(folder.config.camera, build.map.depth_correction, &frame.depth);
        if (std::getenv("FLOOR_CHECK") && camera_truth) {
          // The floor (room z = 0) as the depth shows it from the true camera.
          const CameraIntrinsics& K = folder.config.camera;
          for (const auto& g : *camera_truth) {
            if (std::abs(g.timestamp_s - frame.timestamp_s) > 1e-4) continue;
            double n = 0, sz = 0, su = 0, suu = 0, suz = 0, sdz = 0;
            for (int v = 4; v < K.height; v += 8) {
              for (int u = 4; u < K.width; u += 8) {
                const uint16_t raw = frame.depth.at<uint16_t>(v, u);
                if (!raw) continue;
                const double z = raw / K.depth_scale;
                const Eigen::Vector3d x = g.room_from_x * Eigen::Vector3d((u - K.cx) / K.fx * z, (v - K.cy) / K.fy * z, z);
                if (std::abs(x.z()) > 0.05) continue;
                const double uu = (u - K.cx) / K.width;
                n += 1, sz += x.z(), su += uu, suu += uu * uu, suz += uu * x.z(), sdz += z;
              }
            }
            if (n > 10) {
              const double slope = (suz - su * sz / n) / (suu - su * su / n);
              std::printf("    floor f%03zu n %4.0f mean z %+.2f mm slope across the image %+.2f mm, depth %.2f m\n", i, n,
                          1000 * sz / n, 1000 * slope, sdz / n);
            }
          }
        }
        if (std::getenv("TRUTH_START")) {
          // Diagnostic: every frame relocalised from its true pose (what the
          // data alone says near the truth: a wrong pose here is the map's or
          // the matching's, not the search's).
          for (const auto& g : *camera_truth) {
            if (std::abs(g.timestamp_s - frame.timestamp_s) < 1e-4) {
              localizer.Reset();
              localizer.SuggestSearchStart(g.room_from_x);
            }
          }
        }
        const LocalizationResult r = localizer.Localize(frame);
        if (r.ok) est.push_back({frame.timestamp_s, r.room_from_camera});
        if (std::getenv("FRAME_LOC") && camera_truth) {
          // One line a frame: markers (id:side px), keypoints, sigmas, isocentre transfer error.
          std::string ids;
          for (const auto& o : r.markers) ids += StringPrintf(" %d:%.0f", o.id, o.MeanSidePx());
          double iso_err = -1;
          Eigen::Vector3d iso_vec = Eigen::Vector3d::Zero();
          for (const auto& g : *camera_truth) {
            if (r.ok && std::abs(g.timestamp_s - frame.timestamp_s) < 1e-4) {
              iso_vec = (r.room_from_camera * (g.room_from_x.Inverse() * truth.isocentre_in_room_m) -
                         truth.isocentre_in_room_m) * 1000;
              iso_err = iso_vec.norm();
            }
          }
          std::cout << StringPrintf("    f%03zu %-11s m%d k%3d p%4d s%4d sig %.2fmm %.3fdeg iso %.2f (%+.2f %+.2f %+.2f) [%s ]\n", i,
                                    r.held_by_depth ? "held" : LocalizationStatusName(r.status), r.markers_used, r.keypoints_used,
                                    r.plane_depth_samples, r.surface_depth_samples,
                                    r.position_sigma_mm, r.rotation_sigma_deg, iso_err, iso_vec.x(), iso_vec.y(),
                                    iso_vec.z(), ids.c_str());
        }
        if (!r.ok) {
          ++lost;
          bool marker = false;
          for (const auto& o : r.markers) marker |= o.status == MarkerStatus::kRefined;
          lost_with_marker += marker ? 1 : 0;
          if (marker && std::getenv("LOST_DIAG")) {
            std::cout << StringPrintf("    lost t=%.3f: %zu marker(s) [", frame.timestamp_s, r.markers.size());
            for (const auto& o : r.markers) {
              std::cout << StringPrintf(" %d:%s side %.0fpx", o.id, MarkerStatusName(o.status), o.MeanSidePx());
            }
            std::cout << StringPrintf(" ] sigma %.1f mm, marker rms %.2f px, kp rms %.2f: %s\n", r.position_sigma_mm,
                                      r.marker_rms_px, r.keypoint_rms_px, r.message.c_str());
          }
        }
        ms += r.timings.total_ms;
        sum_t.detection_ms += r.timings.detection_ms;
        sum_t.keypoints_ms += r.timings.keypoints_ms;
        sum_t.matching_ms += r.timings.matching_ms;
        sum_t.pnp_ms += r.timings.pnp_ms;
        sum_t.refinement_ms += r.timings.refinement_ms;
      }
      const TrajectoryEvaluation e = EvaluateTrajectory(*seq.CameraGroundTruth(), est);
      std::cout << StringPrintf("  %s lost %d frame(s), %d of them with a mapped room marker detected\n", name.c_str(),
                                lost, lost_with_marker);
      {
        // What the camera error does to the patient: the isocentre seen by
        // the true camera, put into the room by the estimated camera.
        const auto gt = *seq.CameraGroundTruth();
        const Eigen::Vector3d iso = truth.isocentre_in_room_m;
        double sum_iso = 0;
        int count = 0;
        Eigen::Vector3d sum_v = Eigen::Vector3d::Zero();
        Eigen::Matrix3d sum_vv = Eigen::Matrix3d::Zero();
        for (const auto& p : est) {
          for (const auto& g : gt) {
            if (std::abs(g.timestamp_s - p.timestamp_s) > 1e-4) continue;
            const Eigen::Vector3d v = (p.room_from_x * (g.room_from_x.Inverse() * iso) - iso) * 1000;
            sum_iso += v.norm();
            sum_v += v;
            sum_vv += v * v.transpose();
            ++count;
          }
        }
        if (count) {
          // And apart from its mean (a constant offset, e.g. the room frame's
          // own error, which the patient's session shares).
          const Eigen::Vector3d mean = sum_v / count;
          const double spread = std::sqrt(std::max(0.0, (sum_vv / count - mean * mean.transpose()).trace()));
          std::cout << StringPrintf("  %s isocentre transfer error: mean %.3f mm (mean vector %.2f %.2f %.2f, RMS about it %.3f mm)\n",
                                    name.c_str(), sum_iso / count, mean.x(), mean.y(), mean.z(), spread);
        }
      }
      if (std::getenv("AXES")) {
        // Error of the camera centre in the true camera's axes (x right, y down, z forward).
        const auto gt = *seq.CameraGroundTruth();
        Eigen::Vector3d sum_abs = Eigen::Vector3d::Zero(), sum = Eigen::Vector3d::Zero();
        int count = 0;
        for (const auto& p : est) {
          for (const auto& g : gt) {
            if (std::abs(g.timestamp_s - p.timestamp_s) > 1e-4) continue;
            const Eigen::Vector3d d = (g.room_from_x.Inverse() * p.room_from_x).translation * 1000;
            sum_abs += d.cwiseAbs();
            sum += d;
            ++count;
          }
        }
        if (count) {
          std::cout << StringPrintf("  %s camera-axis error mm: mean |x| %.2f |y| %.2f |z| %.2f; signed %.2f %.2f %.2f\n",
                                    name.c_str(), sum_abs.x() / count, sum_abs.y() / count, sum_abs.z() / count,
                                    sum.x() / count, sum.y() / count, sum.z() / count);
        }
      }
      const double k = seq.size() ? 1.0 / seq.size() : 0;
      std::cout << StringPrintf("%-18s %5zu   %6.1f %%  %7.3f %7.3f %7.3f %7.3f  %7.4f   %.2f (det %.2f kp %.2f match %.2f pnp %.2f ref %.2f)\n",
                                name.c_str(), seq.size(), 100.0 - e.lost_percent, e.translation_mm.mean,
                                e.translation_mm.median, e.translation_mm.p95, e.translation_mm.max,
                                e.rotation_deg.mean, ms * k, sum_t.detection_ms * k, sum_t.keypoints_ms * k,
                                sum_t.matching_ms * k, sum_t.pnp_ms * k, sum_t.refinement_ms * k);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "planning_eval: %s\n", e.what());
    return 1;
  }
  return 0;
}
