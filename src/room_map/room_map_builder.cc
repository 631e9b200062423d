#include "room_map/room_map_builder.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <exception>
#include <functional>
#include <map>
#include <set>
#include <mutex>
#include <numeric>
#include <sstream>
#include <thread>
#include <unordered_map>

#include <Eigen/Dense>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "geometry/so3.h"
#include "room_map/depth_check.h"
#include "room_map/landmark_triangulation.h"
#include "room_map/marker_graph.h"
#include "room_map/pose_refiner.h"
#include "room_map/room_planes.h"
#include "sensor/depth_timing.h"
#include "util/check.h"
#include "util/logging.h"
#include "util/string_util.h"

namespace arpos {
namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

// What one frame contributes, computed in parallel.
struct FrameData {
  int index = -1;
  std::vector<MarkerObservation> markers;  // kRefined room markers, corners undistorted
  std::vector<std::array<Eigen::Vector2d, 4>>
      image_corners_px;                    // parallel: as detected (distorted)
  std::vector<MarkerPose> poses;           // parallel
  std::vector<std::vector<DepthSample>> depth_samples;  // parallel
  std::vector<std::vector<DepthSample>> support_samples;  // parallel; the origin's only
  std::vector<int> all_ids_seen;           // every room id detected, refined or not
  std::vector<float> grid_z;               // depth (m, 0: none) at the plane grid's pixels
  KeypointSet keypoints;
  std::vector<Eigen::Vector2d> keypoint_px;  // undistorted
  bool posed = false;
  bool posed_by_keypoints = false;
  Rigid3d camera_from_room;
};

// One landmark candidate while associating.
struct Candidate {
  Eigen::Vector3d weighted_sum = Eigen::Vector3d::Zero();
  double weight = 0;
  std::vector<std::pair<int, int>> observations;  // (frame slot, keypoint index)
  int descriptor_frame = -1, descriptor_index = -1;  // representative for matching
  int last_frame = -1;
  Eigen::Vector3d Position() const { return weighted_sum / weight; }
};

const std::uint8_t* Descriptor(const std::vector<FrameData>& frames, int slot, int kp) {
  return frames[slot].keypoints.descriptors.ptr<std::uint8_t>(kp);
}

// A plane's tilt about the origin's centre, in the origin marker's frame:
// z = a x + b y + c, as the rotation of z onto its normal,
// omega = z x (-a, -b, 1) = (b, -a), with its covariance.
struct TiltEstimate {
  Eigen::Vector2d omega = Eigen::Vector2d::Zero();
  Eigen::Matrix2d cov = Eigen::Matrix2d::Identity();
};

// Points on the origin's support plane, one view's worth: origin frame,
// with the depth noise along the plane's normal (1 sigma).
struct SupportView {
  std::vector<Eigen::Vector3d> points;
  std::vector<double> sigma_m;
};

struct SupportPlaneFit {
  bool ok = false;
  TiltEstimate tilt;
  int views = 0, points = 0;
};

// Robust weighted fit of z = a x + b y + c to every view's points (Tukey
// weights on residuals over sigma times a robust scale, from the plane
// z = 0), then the same fit per view: the tilt's covariance is the pooled
// fit's, scaled up to the spread between views when that is larger (depth
// bias that differs between viewpoints, camera pose errors), and never
// below `floor_sigma_rad` over the square root of the views.
SupportPlaneFit FitSupportPlane(const std::vector<SupportView>& views, double half_width_m,
                                double floor_sigma_rad) {
  SupportPlaneFit fit;
  struct P {
    Eigen::Vector3d p;
    double sigma;
    int view;
  };
  std::vector<P> pts;
  for (size_t v = 0; v < views.size(); ++v) {
    for (size_t i = 0; i < views[v].points.size(); ++i) {
      const Eigen::Vector3d& p = views[v].points[i];
      if (std::abs(p.x()) > half_width_m || std::abs(p.y()) > half_width_m) continue;
      if (!(views[v].sigma_m[i] > 0) || !p.allFinite()) continue;
      if (std::abs(p.z()) > std::max(4 * views[v].sigma_m[i], 0.03)) continue;  // off the plane
      pts.push_back({p, views[v].sigma_m[i], static_cast<int>(v)});
    }
  }
  if (pts.size() < 200) return fit;
  Eigen::Vector3d abc = Eigen::Vector3d::Zero();
  std::vector<double> w(pts.size(), 1.0);
  double scale = 1;
  auto solve = [&](int view, Eigen::Matrix3d* info_out) {
    Eigen::Matrix3d info = Eigen::Matrix3d::Zero();
    Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
    for (size_t i = 0; i < pts.size(); ++i) {
      if (view >= 0 && pts[i].view != view) continue;
      if (w[i] <= 0) continue;
      const Eigen::Vector3d row(pts[i].p.x(), pts[i].p.y(), 1);
      const double wi = w[i] / (pts[i].sigma * pts[i].sigma * scale * scale);
      info.noalias() += wi * row * row.transpose();
      rhs.noalias() += wi * row * pts[i].p.z();
    }
    if (info_out) *info_out = info;
    return Eigen::Vector3d(info.ldlt().solve(rhs));
  };
  Eigen::Matrix3d info;
  for (int iteration = 0; iteration < 6; ++iteration) {
    abc = solve(-1, &info);
    std::vector<double> r(pts.size());
    for (size_t i = 0; i < pts.size(); ++i) {
      r[i] = std::abs(pts[i].p.z() - abc.dot(Eigen::Vector3d(pts[i].p.x(), pts[i].p.y(), 1))) / pts[i].sigma;
    }
    std::vector<double> sorted = r;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    scale = std::max(0.5, 1.4826 * sorted[sorted.size() / 2]);
    for (size_t i = 0; i < pts.size(); ++i) {
      const double u = r[i] / (4.685 * scale);
      w[i] = u < 1 ? (1 - u * u) * (1 - u * u) : 0;
    }
  }
  abc = solve(-1, &info);
  // Spread in x and y: the slopes need the plane seen across, not along a line.
  Eigen::Matrix2d spread = Eigen::Matrix2d::Zero();
  double wsum = 0;
  int used = 0;
  std::vector<int> per_view(views.size(), 0);
  for (size_t i = 0; i < pts.size(); ++i) {
    if (w[i] <= 0) continue;
    spread += w[i] * pts[i].p.head<2>() * pts[i].p.head<2>().transpose();
    wsum += w[i];
    ++used;
    ++per_view[pts[i].view];
  }
  if (used < 200 || !(wsum > 0)) return fit;
  spread /= wsum;
  const double min_spread = 0.15 * half_width_m;
  if (!(Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(spread).eigenvalues().minCoeff() > min_spread * min_spread)) {
    return fit;
  }
  const Eigen::Matrix3d cov3 = info.inverse();
  Eigen::Matrix2d cov = cov3.topLeftCorner<2, 2>();
  // Between views.
  std::vector<Eigen::Vector2d> slopes;
  for (size_t v = 0; v < views.size(); ++v) {
    if (per_view[v] < 100) continue;
    Eigen::Matrix3d view_info;
    const Eigen::Vector3d view_abc = solve(static_cast<int>(v), &view_info);
    if (view_abc.allFinite() && view_info.determinant() > 0) slopes.push_back(view_abc.head<2>());
  }
  fit.views = static_cast<int>(slopes.size());
  if (slopes.size() >= 3) {
    Eigen::Vector2d mean = Eigen::Vector2d::Zero();
    for (const auto& sl : slopes) mean += sl;
    mean /= slopes.size();
    Eigen::Matrix2d between = Eigen::Matrix2d::Zero();
    for (const auto& sl : slopes) between += (sl - mean) * (sl - mean).transpose();
    between /= static_cast<double>((slopes.size() - 1) * slopes.size());
    const double k2 = between.trace() / cov.trace();
    if (k2 > 1) cov *= k2;
  }
  const double floor2 = floor_sigma_rad * floor_sigma_rad / std::max(1, fit.views);
  cov += Eigen::Matrix2d::Identity() * floor2;
  Eigen::Matrix2d flip;
  flip << 0, 1, -1, 0;
  fit.tilt.omega = Eigen::Vector2d(abc.y(), -abc.x());
  fit.tilt.cov = flip * cov * flip.transpose();
  fit.points = used;
  fit.ok = fit.tilt.omega.allFinite() && fit.tilt.cov.allFinite() && fit.views >= 1;
  return fit;
}

}  // namespace

std::optional<int> SolutionBySupportDepth(const MarkerPose& pose, const std::vector<DepthSample>& samples,
                                          const CameraIntrinsics& K, const BaOptions& ba_options) {
  if (pose.num_solutions != 2 || samples.size() < 50) return std::nullopt;
  std::array<double, 2> cost{0, 0};
  std::array<int, 2> on_plane{0, 0};
  std::vector<Eigen::Vector3d> rays;  // each sample's ray at unit depth
  rays.reserve(samples.size());
  for (const DepthSample& sample : samples) {
    rays.push_back(K.Unproject(sample.pixel.x(), sample.pixel.y(), 1.0));
  }
  std::vector<double> offsets(samples.size());
  for (int k = 0; k < 2; ++k) {
    const Rigid3d& m = pose.solutions[k].camera_from_marker;
    const Eigen::Vector3d n = m.rotation * Eigen::Vector3d::UnitZ();
    for (size_t i = 0; i < samples.size(); ++i) offsets[i] = n.dot(samples[i].depth_m * rays[i]);
    std::nth_element(offsets.begin(), offsets.begin() + offsets.size() / 2, offsets.end());
    const double d = offsets[offsets.size() / 2];
    for (size_t i = 0; i < samples.size(); ++i) {
      const DepthSample& sample = samples[i];
      const double denom = n.dot(rays[i]);
      if (std::abs(denom) < 1e-6) continue;
      const double z = d / denom;
      const double sigma = ba_options.DepthSigmaM(sample.depth_m);
      const double r = z > 0 ? (sample.depth_m - z) / sigma : 1e3;
      cost[k] += std::log1p(r * r / 9);
      on_plane[k] += std::abs(r) < 3;
    }
  }
  const int better = cost[0] <= cost[1] ? 0 : 1;
  if (on_plane[better] < 50 || !(cost[1 - better] >= 2 * cost[better])) return std::nullopt;
  return better;
}

namespace {

// The candidates the thinning left out, triangulated against the adjusted
// cameras (held fixed) and appended to the map for localisation only: each
// point starts from its best-depth observation, Gauss-Newton on reprojection
// and depth residuals (the adjustment's sigmas), observations beyond
// outlier_sigmas dropped and the point solved again; kept with at least
// min_landmark_observations inliers, outside the exclusion boxes, in front
// of every camera that saw it. Descriptor: the medoid of its inliers.
void AddLocalizationLandmarks(const std::vector<Candidate>& candidates, const std::vector<bool>& in_adjustment,
                              const std::vector<FrameData>& frames, const std::vector<int>& camera_slot,
                              const std::vector<Rigid3d>& camera_from_room, const CameraIntrinsics& K,
                              const DepthCorrection& depth_correction, const BaOptions& ba_options,
                              const RoomMapBuildOptions& options, RoomMap* map, RoomMapBuildReport* report) {
  std::vector<int> order;
  for (size_t c = 0; c < candidates.size(); ++c) {
    if (in_adjustment[c]) continue;
    if (static_cast<int>(candidates[c].observations.size()) < options.min_landmark_observations) continue;
    order.push_back(static_cast<int>(c));
  }
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return candidates[a].observations.size() > candidates[b].observations.size();
  });
  const bool correct_depth = !depth_correction.IsIdentity();
  LandmarkTriangulationOptions tri;
  tri.keypoint_sigma_px = options.keypoint_sigma_px;
  tri.depth_sigma_const_m = ba_options.depth_sigma_const_m;
  tri.depth_sigma_quad_per_m = ba_options.depth_sigma_quad_per_m;
  tri.outlier_sigmas = options.outlier_sigmas;
  tri.min_observations = options.min_landmark_observations;
  std::vector<LandmarkObservation> obs;
  std::vector<std::pair<int, int>> source;  // (frame slot, keypoint) of each observation
  std::vector<const std::uint8_t*> descs;
  int added = 0;
  for (int c : order) {
    if (added >= options.max_localization_landmarks) break;
    obs.clear();
    source.clear();
    for (const auto& [s, i] : candidates[c].observations) {
      if (s < 0 || s >= static_cast<int>(camera_slot.size()) || camera_slot[s] < 0) continue;
      LandmarkObservation o{camera_slot[s], frames[s].keypoint_px[i],
                            frames[s].keypoints.depth_m[i]};
      if (o.depth_m > 0 && correct_depth) {
        o.depth_m = depth_correction.TrueDepth(o.depth_m, (o.px.x() - K.cx) / K.fx,
                                               (o.px.y() - K.cy) / K.fy);
      }
      obs.push_back(o);
      source.emplace_back(s, i);
    }
    const std::optional<TriangulatedLandmark> placed =
        TriangulateLandmark(obs, camera_from_room, K, tri);
    if (!placed) continue;
    const Eigen::Vector3d& X = placed->point_in_room;
    bool excluded = false;
    for (const auto& box : options.exclude_landmarks) excluded |= box.Contains(X);
    if (excluded) continue;
    descs.clear();
    for (size_t k = 0; k < obs.size(); ++k) {
      if (placed->inlier[k]) descs.push_back(Descriptor(frames, source[k].first, source[k].second));
    }
    map->landmarks_in_room.push_back(X);
    cv::Mat row(1, kDescriptorBytes, CV_8UC1);
    std::copy_n(MedoidDescriptor(descs), kDescriptorBytes, row.ptr<std::uint8_t>(0));
    map->landmark_descriptors.push_back(row);
    ++added;
  }
  report->localization_landmarks = added;
}

}  // namespace

std::string RoomMapBuildOptions::Validate() const {
  std::ostringstream out;
  std::string r;
  if (!detector.Check(&r)) out << "detector: " << r;
  else if (!marker_pose.Check(&r)) out << "marker_pose: " << r;
  else if (!keypoints.Check(&r)) out << "keypoints: " << r;
  else if (!bundle_adjustment.Check(&r)) out << "bundle_adjustment: " << r;
  else if (frame_step < 1) out << "frame_step must be at least 1, got " << frame_step;
  else if (delayed_depth_pose_iterations < 1)
    out << "delayed_depth_pose_iterations must be at least 1";
  else if (max_frames < 0) out << "max_frames must not be negative";
  else if (threads < 1 || adjustment_threads < 1)
    out << "threads must be at least 1";
  else if (!(marker_corner_sigma_px > 0) || !(keypoint_sigma_px > 0)) out << "sigmas must be positive";
  else if (!(marker_reference_cell_px >= 0)) out << "marker_reference_cell_px must not be negative";
  else if (!(max_marker_view_rms_px > 0)) out << "max_marker_view_rms_px must be positive";
  else if (marker_depth_samples < 0) out << "marker_depth_samples must not be negative";
  else if (support_plane_samples < 0) out << "support_plane_samples must not be negative";
  else if (!(support_plane_half_width_m > 0)) out << "support_plane_half_width_m must be positive";
  else if (!(support_plane_min_sigma_deg >= 0)) out << "support_plane_min_sigma_deg must not be negative";
  else if (room_plane_min_markers < 2 || !(room_plane_min_spread_m >= 0) || !(room_plane_support_m > 0) ||
           !(room_plane_gate_m > 0) || room_plane_min_samples < 1 || room_plane_max_samples < 1 ||
           !(room_plane_max_effective >= 1) || !(room_plane_flatness_m > 0) ||
           !(room_plane_marker_tilt_deg >= 0))
    out << "room plane settings must be positive (at least 2 markers a plane)";
  else if (min_marker_observations < 1) out << "min_marker_observations must be at least 1";
  else if (!(association_radius_px > 0)) out << "association_radius_px must be positive";
  else if (max_hamming < 1 || max_hamming > 256) out << "max_hamming must be in 1..256";
  else if (min_landmark_observations < 2) out << "min_landmark_observations must be at least 2";
  else if (max_landmarks < 0) out << "max_landmarks must not be negative";
  else if (!(landmark_voxel_m > 0)) out << "landmark_voxel_m must be positive";
  else if (!(outlier_sigmas > 0)) out << "outlier_sigmas must be positive";
  else if (build_surface && !(r = surface.Validate()).empty()) out << "surface: " << r;
  else if (!(depth_inflation_threshold >= 1)) out << "depth_inflation_threshold must be at least 1";
  else if (!(max_room_frame_tilt_sigma_deg > 0) || !(max_room_frame_couch_sigma_mm > 0)) {
    out << "room frame tolerances must be positive";
  } else if (!couch_point_in_room.allFinite()) {
    out << "couch_point_in_room must be finite";
  } else if (const std::string r2 = response.estimation.Validate(); !r2.empty()) {
    out << "response.estimation: " << r2;
  } else if (response.max_frames < 1 || response.rounds < 1) {
    out << "response: max_frames and rounds must be positive";
  }
  return out.str();
}

bool RoomMapBuildOptions::Check(std::string* reason) const {
  const std::string r = Validate();
  if (reason) *reason = r;
  return r.empty();
}

RoomMapBuildOptions MakeRoomMapBuildOptions(const CaseConfig& config) {
  RoomMapBuildOptions options;
  options.detector.dictionary = config.dictionary;
  options.detector.id_ranges = {{config.room_markers.id_min, config.room_markers.id_max}};
  options.detector.intrinsics = config.camera;
  options.detector.edge.response = CameraResponse::Srgb();  // when the recording cannot tell
  options.keypoints.max_keypoints = 1000;
  return options;
}

double RoomMapBuildReport::RoomFramePositionSigmaMm(const Eigen::Vector3d& p) const {
  // A point moves by d_omega x p + d_t: Jacobian [-[p]x, I].
  Eigen::Matrix<double, 3, 6> jp;
  jp.leftCols<3>() << 0, p.z(), -p.y(), -p.z(), 0, p.x(), p.y(), -p.x(), 0;
  jp.rightCols<3>().setIdentity();
  const double var = (jp * room_frame_covariance * jp.transpose()).trace();
  return std::isfinite(var) ? std::sqrt(std::max(0.0, var)) * 1000 : std::numeric_limits<double>::infinity();
}

std::string RoomMapBuildReport::ToText() const {
  std::ostringstream out;
  out << StringPrintf("frames: %d used of %d (%d with markers, %d posed by keypoints)\n", frames_used,
                      frames_total, frames_with_markers, frames_posed_by_keypoints);
  out << StringPrintf("marker views: %d (%d single-view poses ambiguous, not used to initialise)",
                      marker_views, ambiguous_marker_views);
  if (unrefined_marker_views > 0) {
    out << StringPrintf("; %d more read whose edges could not be fitted (not used)",
                        unrefined_marker_views);
  }
  out << "\n";
  if (!unconnected_markers.empty()) {
    out << "markers not connected to the origin (left out):";
    for (int id : unconnected_markers) out << " " << id;
    out << "\n";
  }
  if (!sparse_markers.empty()) {
    out << "markers seen in too few views (left out):";
    for (int id : sparse_markers) out << " " << id;
    out << "\n";
  }
  out << StringPrintf("landmarks: %d kept of %d candidates (%d in exclusion boxes), %d observations",
                      landmarks, landmark_candidates, landmarks_excluded, keypoint_observations);
  if (landmarks_joining_groups > 0) {
    out << StringPrintf("; %d of them seen in two frames only, kept to tie groups of frames nothing else ties",
                        landmarks_joining_groups);
  }
  if (localization_landmarks > 0) {
    out << StringPrintf("; %d of them placed after the adjustment, for localisation only", localization_landmarks);
  }
  out << "\n";
  out << StringPrintf("residuals: marker corners %.3f px RMS, keypoints %.3f px RMS, keypoint depth %.2f mm RMS\n",
                      marker_rms_px, keypoint_rms_px, keypoint_depth_rms_m * 1000);
  out << StringPrintf("depth scale check (measured / map-predicted depth in markers): %.4f (MAD %.4f)\n",
                      depth_scale_ratio, depth_scale_ratio_mad);
  if (surface.frames > 0) out << surface.ToText() << "\n";
  out << StringPrintf("adjustment: markers %d it %.2f s; joint %d it %.2f s\n",
                      marker_adjustment.iterations, marker_adjustment.seconds,
                      joint_adjustment.iterations, joint_adjustment.seconds);
  out << StringPrintf("time: frames %.2f s, initialisation %.2f s, landmarks %.2f s, ", frames_s,
                      initialisation_s, landmarks_s)
      << StringPrintf("adjustment %.2f s, total %.2f s", adjustment_s, total_s);
  if (frames_depth_moved_to_colour > 0) {
    out << StringPrintf(" (depth read again as of the colour's instant %.2f s of it)",
                        depth_move_s);
  }
  out << "\n";
  if (frames_depth_delayed > 0 && frames_depth_moved_to_colour > 0) {
    out << StringPrintf("depth of another instant (a median %.1f ms after its colour): ",
                        1000 * depth_delay_s)
        << StringPrintf("read as of the colour's instant in %d of %d frames, ",
                        frames_depth_moved_to_colour, frames_depth_delayed)
        << "by the camera's motion between the frames placed around them\n";
  } else if (frames_depth_delayed > 0) {
    out << StringPrintf("depth of another instant (a median %.1f ms after its colour): ",
                        1000 * depth_delay_s)
        << StringPrintf("used as read in all %d frames ", frames_depth_delayed)
        << StringPrintf(
               "(none has a placed frame within %.1f s to take the camera's motion from)\n",
               kMaxInterpolationGapS);
  }
  out << StringPrintf(
      "room frame (origin marker, %d views): tilt %.4f deg, yaw %.4f deg, position at the couch "
      "%.3f mm (1 sigma)",
      origin_observations, room_frame_tilt_sigma_deg, room_frame_yaw_sigma_deg,
      room_frame_couch_sigma_mm);
  if (map_couch_markers > 0) {
    out << StringPrintf("; the map near the couch relative to it %.3f mm, tilt %.4f deg, yaw %.4f deg (1 sigma, "
                        "median of %d marker(s) near the couch, over everything the adjustment estimates; %.2f s)",
                        map_couch_sigma_mm, map_couch_tilt_sigma_deg, map_couch_yaw_sigma_deg, map_couch_markers,
                        map_couch_covariance_s);
  }
  if (origin_plane_views > 0) {
    out << StringPrintf("; tilt from the origin's views and the depth of its plane in %d views", origin_plane_views);
  }
  if (coplanar_markers > 0 || support_plane_views > 0) {
    out << "; tilt from the origin's views";
    if (coplanar_markers > 0) out << StringPrintf(", the plane of %d markers coplanar with it", coplanar_markers);
    if (support_plane_views > 0) {
      out << StringPrintf(", its support plane in depth (%d views, %d points; %.4f deg 1 sigma, %.3f deg from the origin's own)",
                          support_plane_views, support_plane_points, support_plane_tilt_sigma_deg,
                          support_plane_offset_deg);
    }
    out << StringPrintf(" (turned %.3f deg)", room_frame_turn_deg);
  }
  out << "\n";
  if (!camera_response.empty()) out << camera_response << "\n";
  if (!depth_correction.empty()) out << depth_correction << "\n";
  if (!room_planes.empty()) out << room_planes << "\n";
  for (const auto& w : warnings) out << "warning: " << w << "\n";
  return out.str();
}

RoomMapBuildResult BuildRoomMap(const Sequence& sequence, const CaseConfig& config,
                                const RoomMapBuildOptions& options,
                                const ControllerCallbacks& callbacks) {
  std::string reason;
  ARPOS_CHECK(options.Check(&reason), "invalid room map options: " << reason);
  const auto t_start = Clock::now();
  RoomMapBuildResult result;
  RoomMapBuildReport& report = result.report;
  const CameraIntrinsics& K = config.camera;
  const double marker_size = config.room_markers.size_m;
  const int origin_id = config.room_origin_id;

  auto progress = [&](const std::string& step, double fraction) {
    if (callbacks.progress) callbacks.progress(step, fraction);
    if (callbacks.cancel_requested && callbacks.cancel_requested()) throw Cancelled();
  };

  // ---------------------------------------------------------------- 1. frames
  std::vector<int> indices;
  for (size_t i = 0; i < sequence.size(); i += options.frame_step) {
    indices.push_back(static_cast<int>(i));
    if (options.max_frames > 0 && static_cast<int>(indices.size()) >= options.max_frames) break;
  }
  report.frames_total = static_cast<int>(indices.size());
  if (indices.empty()) ARPOS_INPUT_ERROR(sequence.folder().string() << ": the room sequence has no frames");
  // The camera response, from the recording's own markers.
  MarkerDetectorOptions detector_options = options.detector;
  result.map.camera_response = options.detector.edge.response;
  if (options.estimate_response) {
    progress("estimating the camera response", 0.0);
    const RecordingResponse rr = EstimateRecordingResponse(
        sequence, K, options.detector, options.detector.edge.response, options.response);
    detector_options.edge.response = rr.response;
    result.map.camera_response = rr.response;
    report.camera_response = rr.message;
    if (!rr.estimated) {
      // Measured: a gamma-2.6 camera taken for sRGB read its markers 0.2 px
      // wide, and the map came out 1.2 % small (25 mm at the couch).
      report.warnings.push_back(StringPrintf(
          "the camera's tone curve could not be estimated from this recording (%d marker view(s) "
          "large enough, %d needed); %s is %s: if the camera encodes otherwise, the markers read "
          "up to a few tenths of a pixel wide and the map's scale may be off by up to a percent; "
          "record the room again with some room markers seen close (cells of 4 px or more)",
          rr.estimate.markers_used, options.response.estimation.min_markers,
          rr.response.name().c_str(),
          rr.chosen_standard ? "used, the standard curve the markers' edges fit best" : "assumed"));
    }
  } else {
    report.camera_response = "camera response assumed: " + options.detector.edge.response.name();
  }

  std::vector<FrameData> frames(indices.size());
  // Where the room planes' depth is read: about 80 samples across the image.
  const DepthSampleGrid plane_grid =
      options.use_room_planes ? MakeDepthSampleGrid(K, std::max(8, K.width / 80)) : DepthSampleGrid{};
  {
    progress("detecting markers and keypoints", 0.0);
    std::atomic<int> next{0}, done{0};
    std::atomic<bool> stop{false};
    std::exception_ptr error;
    std::mutex error_mutex;
    auto worker = [&]() {
      try {
        MarkerDetector detector(detector_options);
        KeypointExtractor extractor(options.keypoints);
        cv::Mat gray;
        std::vector<MarkerObservation> detected;
        while (!stop) {
          const int slot = next++;
          if (slot >= static_cast<int>(indices.size())) break;
          FrameData& f = frames[slot];
          f.index = indices[slot];
          RgbdFrame frame = sequence.LoadFrame(f.index, K);
          cv::cvtColor(frame.color, gray, cv::COLOR_BGR2GRAY);
          if (!plane_grid.px.empty() && !frame.depth.empty()) {
            f.grid_z.resize(plane_grid.px.size());
            for (size_t i = 0; i < plane_grid.px.size(); ++i) {
              f.grid_z[i] = static_cast<float>(frame.depth.at<uint16_t>(plane_grid.px[i]) / K.depth_scale);
            }
          }
          detector.Detect(gray, &detected);
          for (const auto& obs : detected) {
            f.all_ids_seen.push_back(obs.id);
            if (!obs.IsPrecise()) continue;
            MarkerPose pose = EstimateMarkerPose(obs, marker_size, K, frame.depth, options.marker_pose);
            std::vector<DepthSample> samples =
                SampleMarkerDepth(frame.depth, obs.corners_px, K, options.marker_depth_samples);
            MarkerObservation ideal = obs;
            const std::vector<Eigen::Vector2d> c =
                IdealPixels({obs.corners_px.begin(), obs.corners_px.end()}, K);
            for (int k = 0; k < 4; ++k) ideal.corners_px[k] = c[k];
            f.markers.push_back(ideal);
            f.image_corners_px.push_back(obs.corners_px);
            f.poses.push_back(pose);
            f.depth_samples.push_back(std::move(samples));
            f.support_samples.emplace_back();
            if (obs.id == origin_id) {
              f.support_samples.back() =
                  SampleSupportDepth(frame.depth, obs.corners_px, K, marker_size,
                                     options.support_plane_half_width_m, options.support_plane_samples);
            }
          }
          if (options.use_keypoints) {
            extractor.Extract(gray, frame.depth, K.depth_scale, &f.keypoints);
            std::vector<Eigen::Vector2d> px;
            px.reserve(f.keypoints.size());
            for (const auto& kp : f.keypoints.keypoints) px.emplace_back(kp.pt.x, kp.pt.y);
            f.keypoint_px = IdealPixels(px, K);
          }
          ++done;
        }
      } catch (...) {
        std::lock_guard<std::mutex> lock(error_mutex);
        if (!error) error = std::current_exception();
        stop = true;
      }
    };
    std::vector<std::thread> workers;
    const int n_threads = std::min<int>(options.threads, static_cast<int>(indices.size()));
    for (int t = 0; t < n_threads; ++t) workers.emplace_back(worker);
    try {
      while (done < static_cast<int>(indices.size()) && !stop) {
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
        progress(StringPrintf("detecting markers and keypoints (%d/%zu frames)", done.load(), indices.size()),
                 0.5 * done / indices.size());
      }
    } catch (...) {
      stop = true;
      for (auto& w : workers) w.join();
      throw;
    }
    for (auto& w : workers) w.join();
    if (error) std::rethrow_exception(error);
  }
  report.frames_s = SecondsSince(t_start);

  // ---------------------------------------------------------------- 2. initialisation
  const auto t_init = Clock::now();
  progress("initialising the marker map", 0.5);
  bool origin_seen = false;
  std::vector<MarkerView> views;
  // Views whose depth disagrees with both of the corners' poses: depth over
  // the marker's distance from its printed size (a wrong depth_scale shows
  // as one ratio in every view).
  std::vector<double> depth_ratios;
  for (size_t s = 0; s < frames.size(); ++s) {
    const FrameData& f = frames[s];
    for (int id : f.all_ids_seen) origin_seen |= id == origin_id;
    if (!f.markers.empty()) ++report.frames_with_markers;
    report.marker_views += static_cast<int>(f.markers.size());
    report.unrefined_marker_views += static_cast<int>(f.all_ids_seen.size() - f.markers.size());
    for (size_t m = 0; m < f.markers.size(); ++m) {
      const MarkerPose& p = f.poses[m];
      if (p.status == MarkerPoseStatus::kDepthMismatch && p.depth_plane.valid && p.num_solutions > 0 &&
          p.solutions[0].camera_from_marker.translation.z() > 0) {
        depth_ratios.push_back(p.depth_plane.point_in_camera.z() / p.solutions[0].camera_from_marker.translation.z());
      }
      if (p.status != MarkerPoseStatus::kOk || p.reprojection_rms_px > options.max_marker_view_rms_px) {
        ++report.ambiguous_marker_views;
        continue;
      }
      views.push_back({static_cast<int>(s), f.markers[m].id, p.camera_from_marker, f.markers[m].corners_px,
                       p.reprojection_rms_px});
    }
  }
  if (!origin_seen) {
    ARPOS_INPUT_ERROR(sequence.folder().string()
                      << ": the origin marker (id " << origin_id
                      << ", case.yaml markers.room.origin_id) is never seen in the room sequence (not in view, "
                         "or too small, oblique or blurred to be read in any frame), so the room frame is "
                         "undefined; record the room again with the origin marker in view, close and sharp in a "
                         "few frames (move the camera slowly past it)");
  }
  // The map is built in the frame of a root marker held fixed in the
  // adjustments: the origin marker when one of its views gives a clear
  // single-view pose and its group of markers (those linked by clear views
  // seen together) places the most frames; otherwise (small, oblique, rarely
  // seen, or seen clearly only alone) a marker of the largest group, the
  // origin joining later from all of its views in the frames that group
  // places (directly or through keypoints). The room frame is then moved
  // onto the origin marker's adjusted pose, which rests on all of its corner
  // observations.
  int root_id = origin_id;
  MarkerGraphResult graph = InitializeMarkerPoses(views, origin_id, marker_size, K);
  {
    std::map<int, int> usable_views;
    std::map<int, std::set<int>> frames_of;  // marker -> frames with a clear view
    for (const MarkerView& v : views) {
      ++usable_views[v.marker_id];
      frames_of[v.marker_id].insert(v.frame);
    }
    if (usable_views.empty() && depth_ratios.size() >= 3 &&
        2 * depth_ratios.size() >= static_cast<size_t>(report.marker_views)) {
      std::nth_element(depth_ratios.begin(), depth_ratios.begin() + depth_ratios.size() / 2, depth_ratios.end());
      const double ratio = depth_ratios[depth_ratios.size() / 2];
      ARPOS_INPUT_ERROR(sequence.folder().string()
                        << ": the depth disagrees with the room markers in every view: it reads "
                        << StringPrintf("%.3f", ratio) << " times the distance their printed size ("
                        << marker_size << " m, case.yaml markers.room.size_m) gives (median of "
                        << depth_ratios.size() << " views). Check camera.depth_scale in case.yaml ("
                        << K.depth_scale << " depth units per metre; TUM recordings use 5000, OpenNI and "
                           "RealSense millimetres 1000; these images look like "
                        << StringPrintf("%.0f", K.depth_scale * ratio) << ") and the markers' printed size");
    }
    if (usable_views.empty()) {
      ARPOS_INPUT_ERROR(sequence.folder().string()
                        << ": no room marker is seen sharply enough for a pose (blurred, occluded or "
                           "too small); record the room again with the markers clearly in view");
    }
    auto frames_placed = [&](const MarkerGraphResult& g) {
      std::set<int> placed;
      for (const auto& [id, pose] : g.room_from_marker) placed.insert(frames_of[id].begin(), frames_of[id].end());
      return static_cast<int>(placed.size());
    };
    // The marker groups, each once: the origin's first, then from the most
    // viewed marker not yet in a group.
    int best_frames = frames_placed(graph);
    std::set<int> grouped;
    for (const auto& [id, pose] : graph.room_from_marker) grouped.insert(id);
    while (true) {
      int next = -1, most = 0;
      for (const auto& [id, count] : usable_views) {
        if (!grouped.count(id) && count > most) {
          most = count;
          next = id;
        }
      }
      if (next < 0) break;
      MarkerGraphResult g = InitializeMarkerPoses(views, next, marker_size, K);
      for (const auto& [id, pose] : g.room_from_marker) grouped.insert(id);
      const int placed = frames_placed(g);
      if (placed > best_frames) {
        best_frames = placed;
        root_id = next;
        graph = std::move(g);
      }
    }
    if (root_id != origin_id) {
      report.warnings.push_back(StringPrintf(
          "the origin marker (id %d) is not seen clearly together with the other markers; the map "
          "was started from marker %d and the origin placed from all of its views",
          origin_id, root_id));
    }
  }
  report.unconnected_markers = graph.unconnected_markers;
  if (!graph.unconnected_markers.empty()) {
    report.warnings.push_back(StringPrintf("%zu marker(s) never seen together with the mapped ones; left out",
                                           graph.unconnected_markers.size()));
  }
  // Marker index in the adjustment.
  BaProblem ba;
  ba.intrinsics = K;
  ba.marker_size_m = marker_size;
  std::vector<int> marker_ids;
  std::map<int, int> marker_slot;
  auto add_marker = [&](int id, const Rigid3d& room_from_marker) {
    marker_slot[id] = static_cast<int>(marker_ids.size());
    marker_ids.push_back(id);
    ba.room_from_marker.push_back(room_from_marker);
    ba.marker_fixed.push_back(id == root_id);
  };
  for (const auto& [id, pose] : graph.room_from_marker) add_marker(id, pose);
  auto known_markers = [&]() {
    std::map<int, Rigid3d> known;
    for (size_t m = 0; m < marker_ids.size(); ++m) known[marker_ids[m]] = ba.room_from_marker[m];
    return known;
  };
  // Camera pose of a frame from its known markers.
  auto pose_by_markers = [&](FrameData& f, const std::map<int, Rigid3d>& known) {
    std::vector<MarkerView> fv;
    for (size_t m = 0; m < f.markers.size(); ++m) {
      if (!known.count(f.markers[m].id)) continue;
      const MarkerPose& p = f.poses[m];
      fv.push_back({f.index, f.markers[m].id, p.camera_from_marker, f.markers[m].corners_px, p.reprojection_rms_px});
    }
    double rms = 0;
    const std::optional<Rigid3d> pose = CameraFromRoomFromMarkers(fv, known, marker_size, K, &rms);
    if (pose && rms < 3.0) {
      f.posed = true;
      f.camera_from_room = *pose;
    }
    return f.posed;
  };
  {
    const std::map<int, Rigid3d> known = known_markers();
    for (auto& f : frames) pose_by_markers(f, known);
  }

  // Markers-only adjustment.
  std::vector<int> camera_slot(frames.size(), -1), camera_frame;
  auto rebuild_cameras = [&]() {
    ba.camera_from_room.clear();
    camera_frame.clear();
    for (size_t s = 0; s < frames.size(); ++s) {
      camera_slot[s] = -1;
      if (!frames[s].posed) continue;
      camera_slot[s] = static_cast<int>(ba.camera_from_room.size());
      camera_frame.push_back(static_cast<int>(s));
      ba.camera_from_room.push_back(frames[s].camera_from_room);
    }
  };
  auto collect_marker_observations = [&]() {
    ba.marker_observations.clear();
    for (size_t s = 0; s < frames.size(); ++s) {
      if (camera_slot[s] < 0) continue;
      const FrameData& f = frames[s];
      for (size_t m = 0; m < f.markers.size(); ++m) {
        auto it = marker_slot.find(f.markers[m].id);
        if (it == marker_slot.end()) continue;
        BaMarkerObservation o;
        o.camera = camera_slot[s];
        o.marker = it->second;
        o.corners_px = f.markers[m].corners_px;
        for (int k = 0; k < 4; ++k) {
          o.sigma_px[k] = MarkerCornerSigmaPx(f.markers[m], k, options.marker_corner_sigma_px,
                                              options.marker_reference_cell_px);
        }
        o.depth_samples = f.depth_samples[m];
        ba.marker_observations.push_back(std::move(o));
      }
    }
  };
  auto adjust_markers = [&](BaSummary* summary) {
    rebuild_cameras();
    collect_marker_observations();
    ba.landmarks_in_room.clear();
    ba.keypoint_observations.clear();
    BaOptions marker_ba_options = options.bundle_adjustment;
    marker_ba_options.threads = options.adjustment_threads;
    *summary = RunBundleAdjustment(&ba, marker_ba_options);
    for (size_t c = 0; c < camera_frame.size(); ++c) frames[camera_frame[c]].camera_from_room = ba.camera_from_room[c];
  };
  adjust_markers(&report.marker_adjustment);
  report.initialisation_s = SecondsSince(t_init);

  // ---------------------------------------------------------------- 3. landmarks
  // Frames without known markers are posed by keypoints against landmarks of
  // nearby posed frames; markers seen only there join from those poses; this
  // repeats until nothing changes.
  const auto t_landmarks = Clock::now();
  progress("associating keypoints", 0.6);
  std::vector<Candidate> candidates;
  std::vector<Eigen::Vector3d> landmarks;
  std::vector<BaKeypointObservation> keypoint_observations;
  std::vector<std::pair<int, int>> keypoint_source;  // (frame slot, keypoint), parallel
  std::vector<std::vector<std::pair<int, int>>> frame_candidates(frames.size());  // (keypoint, candidate)
  std::vector<bool> associated(frames.size(), false);
  const BaOptions& bo = options.bundle_adjustment;
  // Associates the keypoints of frame slot s (posed) with the candidates.
  auto associate = [&](int s) {
    associated[s] = true;
    if (!options.use_keypoints) return;
    FrameData& f = frames[s];
    const Rigid3d room_from_camera = f.camera_from_room.Inverse();
    // Project candidates into a coarse grid (CSR layout).
    const int cell = 8;
    const int cols = (K.width + cell - 1) / cell, rows = (K.height + cell - 1) / cell;
    std::vector<std::pair<int, int>> projected;  // (cell, candidate)
    std::vector<Eigen::Vector2d> uv_of(candidates.size());
    for (size_t c = 0; c < candidates.size(); ++c) {
      const Eigen::Vector3d p = f.camera_from_room * candidates[c].Position();
      if (p.z() <= 0.1) continue;
      const Eigen::Vector2d uv = K.Project(p);
      if (uv.x() < 0 || uv.y() < 0 || uv.x() >= K.width || uv.y() >= K.height) continue;
      uv_of[c] = uv;
      projected.emplace_back(static_cast<int>(uv.y() / cell) * cols + static_cast<int>(uv.x() / cell),
                             static_cast<int>(c));
    }
    std::sort(projected.begin(), projected.end());
    std::vector<int> start(cols * rows + 1, 0);
    for (const auto& pc : projected) ++start[pc.first + 1];
    for (int c = 0; c < cols * rows; ++c) start[c + 1] += start[c];
    for (size_t i = 0; i < f.keypoints.size(); ++i) {
      const float z = f.keypoints.depth_m[i];
      if (z <= 0) continue;
      const Eigen::Vector2d& uv = f.keypoint_px[i];
      const Eigen::Vector3d in_room = room_from_camera * K.Unproject(uv.x(), uv.y(), z);
      const double max_dist = std::max(options.association_min_distance_m, 3 * bo.DepthSigmaM(z));
      const std::uint8_t* d = f.keypoints.descriptors.ptr<std::uint8_t>(static_cast<int>(i));
      int best = -1, best_dist = options.max_hamming + 1;
      const int r = static_cast<int>(std::ceil(options.association_radius_px / cell));
      const int cu = static_cast<int>(uv.x() / cell), cv_ = static_cast<int>(uv.y() / cell);
      for (int dv = -r; dv <= r; ++dv) {
        for (int du = -r; du <= r; ++du) {
          const int gu = cu + du, gv = cv_ + dv;
          if (gu < 0 || gv < 0 || gu >= cols || gv >= rows) continue;
          const int g = gv * cols + gu;
          for (int k = start[g]; k < start[g + 1]; ++k) {
            const int c = projected[k].second;
            if ((uv_of[c] - uv).norm() > options.association_radius_px) continue;
            const Candidate& cand = candidates[c];
            if (cand.last_frame == s) continue;
            if ((cand.Position() - in_room).norm() > max_dist) continue;
            const int dist = HammingDistance32(d, Descriptor(frames, cand.descriptor_frame, cand.descriptor_index));
            if (dist < best_dist) {
              best_dist = dist;
              best = c;
            }
          }
        }
      }
      const double sigma = bo.DepthSigmaM(z);
      const double w = 1.0 / (sigma * sigma);
      if (best < 0) {
        best = static_cast<int>(candidates.size());
        candidates.emplace_back();
        candidates.back().descriptor_frame = s;
        candidates.back().descriptor_index = static_cast<int>(i);
      }
      Candidate& cand = candidates[best];
      cand.weighted_sum += w * in_room;
      cand.weight += w;
      cand.observations.push_back({s, static_cast<int>(i)});
      cand.last_frame = s;
      frame_candidates[s].emplace_back(static_cast<int>(i), best);
    }
  };
  // PnP of an unposed frame on the candidates of posed frames near it.
  auto pose_by_keypoints = [&](int s) {
    FrameData& f = frames[s];
    if (!options.use_keypoints || f.keypoints.size() < 20) return false;
    // The pool: every view, in the posed frames around s, of a candidate
    // those frames see, with the descriptor that frame gave it (the views
    // nearest in time look most alike); a keypoint's match is its nearest
    // view, kept when the nearest view of any other candidate is clearly
    // farther (ratio test between candidates, not between views).
    struct View {
      int candidate;
      const std::uint8_t* descriptor;
    };
    std::vector<View> pool;
    for (int n = std::max(0, s - 4); n <= std::min<int>(static_cast<int>(frames.size()) - 1, s + 4); ++n) {
      if (!associated[n]) continue;
      for (const auto& [i, c] : frame_candidates[n]) pool.push_back({c, Descriptor(frames, n, i)});
    }
    if (pool.size() < 20) return false;
    std::vector<cv::Point3d> object;
    std::vector<cv::Point2d> image;
    for (size_t i = 0; i < f.keypoints.size(); ++i) {
      const std::uint8_t* d = f.keypoints.descriptors.ptr<std::uint8_t>(static_cast<int>(i));
      int best = -1, d1 = 257, d2 = 257;
      for (const View& v : pool) {
        const int dist = HammingDistance32(d, v.descriptor);
        if (v.candidate == best) {
          d1 = std::min(d1, dist);
        } else if (dist < d1) {
          d2 = d1;
          d1 = dist;
          best = v.candidate;
        } else if (dist < d2) {
          d2 = dist;
        }
      }
      if (best < 0 || d1 > options.max_hamming || d1 > 0.8 * d2) continue;
      const Eigen::Vector3d X = candidates[best].Position();
      object.emplace_back(X.x(), X.y(), X.z());
      image.emplace_back(f.keypoint_px[i].x(), f.keypoint_px[i].y());
    }
    const bool search = options.keypoint_search_by_projection;
    if (object.size() < (search ? 8u : 15u)) return false;
    cv::Mat rvec, tvec;
    std::vector<int> inliers;
    const bool ok = cv::solvePnPRansac(object, image, K.CvK(), cv::noArray(), rvec, tvec, false, 300, 3.0, 0.999,
                                       inliers, cv::SOLVEPNP_AP3P);
    if (!ok || inliers.size() < (search ? 6u : 20u)) return false;
    Rigid3d camera_from_room = Rigid3d::FromRotationVector(
        Eigen::Vector3d(rvec.at<double>(0), rvec.at<double>(1), rvec.at<double>(2)),
        Eigen::Vector3d(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2)));
    PoseRefinementResult refined;
    if (inliers.size() >= 20) {
      PoseCorrespondences corr;
      for (int i : inliers) {
        corr.Add(Eigen::Vector3d(object[i].x, object[i].y, object[i].z), Eigen::Vector2d(image[i].x, image[i].y),
                 options.keypoint_sigma_px, CorrespondenceGroup::kKeypoint, i);
      }
      refined = RefineCameraPose(corr, K, camera_from_room);
    } else {
      // Too few to trust: the pool searched again from that pose (a wide
      // step between frames or a repeating floor leaves few matches that
      // pass the ratio test over the whole pool): each keypoint takes the
      // nearest view among the candidates that project within a few pixels
      // of it at a depth its own reading agrees with, when the nearest
      // other candidate there is clearly farther; twice, the second time
      // from the pose the first search gave. A wrong pose finds few.
      std::vector<int> index_of(candidates.size(), -1);
      std::vector<int> unique_candidates;
      for (const View& v : pool) {
        if (index_of[v.candidate] < 0) {
          index_of[v.candidate] = static_cast<int>(unique_candidates.size());
          unique_candidates.push_back(v.candidate);
        }
      }
      std::vector<Eigen::Vector2d> uv(unique_candidates.size());
      std::vector<double> z(unique_candidates.size());
      for (int round = 0; round < 2; ++round) {
        for (size_t u = 0; u < unique_candidates.size(); ++u) {
          const Eigen::Vector3d p = camera_from_room * candidates[unique_candidates[u]].Position();
          z[u] = p.z();
          if (p.z() > 0.1) uv[u] = K.Project(p);
        }
        const double radius = round == 0 ? 8.0 : 4.0;
        std::vector<int> best(f.keypoints.size(), -1), d1(f.keypoints.size(), 257), d2(f.keypoints.size(), 257);
        for (const View& v : pool) {
          const int u = index_of[v.candidate];
          if (z[u] <= 0.1) continue;
          for (size_t i = 0; i < f.keypoints.size(); ++i) {
            if ((f.keypoint_px[i] - uv[u]).squaredNorm() > radius * radius) continue;
            const float zi = f.keypoints.depth_m[i];
            if (zi > 0 && std::abs(zi - z[u]) > std::max(options.association_min_distance_m, 3 * bo.DepthSigmaM(zi)))
              continue;
            const int dist =
                HammingDistance32(f.keypoints.descriptors.ptr<std::uint8_t>(static_cast<int>(i)), v.descriptor);
            if (v.candidate == best[i]) {
              d1[i] = std::min(d1[i], dist);
            } else if (dist < d1[i]) {
              d2[i] = d1[i];
              d1[i] = dist;
              best[i] = v.candidate;
            } else if (dist < d2[i]) {
              d2[i] = dist;
            }
          }
        }
        PoseCorrespondences corr;
        for (size_t i = 0; i < f.keypoints.size(); ++i) {
          if (best[i] < 0 || d1[i] > options.max_hamming || d1[i] > 0.8 * d2[i]) continue;
          corr.Add(candidates[best[i]].Position(), f.keypoint_px[i], options.keypoint_sigma_px,
                   CorrespondenceGroup::kKeypoint, static_cast<int>(i));
        }
        refined = RefineCameraPose(corr, K, camera_from_room);
        camera_from_room = refined.camera_from_room;
      }
    }
    // 20 inliers from the ratio test; 15 from the search by projection,
    // whose matches also agree with the depth.
    const int min_inliers = inliers.size() >= 20 ? 20 : 15;
    if (refined.keypoint_inliers < min_inliers || refined.keypoint_rms_px > 2.0) return false;
    f.posed = true;
    f.posed_by_keypoints = true;
    f.camera_from_room = refined.camera_from_room;
    ++report.frames_posed_by_keypoints;
    return true;
  };
  // A marker not yet in the map, from every frame placed so far that sees
  // it: each IPPE solution of each view is a candidate, scored by the corner
  // reprojection over all of those views (a view's cost capped, so one bad
  // view cannot veto the right candidate). nullopt when no candidate
  // explains the views to within a few pixels.
  const std::array<Eigen::Vector3d, 4> marker_corners = MarkerCornersInMarker(marker_size);
  auto place_from_views = [&](int id) -> std::optional<Rigid3d> {
    std::vector<std::pair<int, int>> seen;  // (frame slot, marker index)
    for (size_t s = 0; s < frames.size(); ++s) {
      if (!frames[s].posed) continue;
      for (size_t m = 0; m < frames[s].markers.size(); ++m) {
        if (frames[s].markers[m].id == id) seen.emplace_back(static_cast<int>(s), static_cast<int>(m));
      }
    }
    const double cap = 4 * 10.0 * 10.0;  // px^2 per view: 10 px on every corner
    auto view_cost = [&](const Rigid3d& room_from_marker, int s2, int m2) {
      double cost = 0;
      for (int c = 0; c < 4; ++c) {
        const Eigen::Vector3d p = frames[s2].camera_from_room * (room_from_marker * marker_corners[c]);
        cost += p.z() > 0 ? (K.Project(p) - frames[s2].markers[m2].corners_px[c]).squaredNorm() : cap;
      }
      return cost;
    };
    double best_cost = std::numeric_limits<double>::infinity();
    std::optional<Rigid3d> best;
    for (const auto& [s, m] : seen) {
      const MarkerPose& pose = frames[s].poses[m];
      // One view cannot tell its two solutions apart by reprojection: then
      // only a pose the single-view test settled (error ratio, depth) is used.
      std::vector<Rigid3d> solutions;
      if (seen.size() > 1) {
        for (int k = 0; k < pose.num_solutions; ++k) solutions.push_back(pose.solutions[k].camera_from_marker);
      } else if (pose.status == MarkerPoseStatus::kOk) {
        solutions.push_back(pose.camera_from_marker);
      } else if (const std::optional<int> k =
                     SolutionBySupportDepth(pose, frames[s].support_samples[m], K, options.bundle_adjustment)) {
        // The origin's single view, settled by the plane around it.
        solutions.push_back(pose.solutions[*k].camera_from_marker);
        ARPOS_DEBUG("room marker " << id << ": its single view settled by the depth around it (solution "
                                   << *k << ")");
      }
      for (const Rigid3d& camera_from_marker : solutions) {
        const Rigid3d candidate = frames[s].camera_from_room.Inverse() * camera_from_marker;
        double cost = 0;
        for (const auto& [s2, m2] : seen) cost += std::min(view_cost(candidate, s2, m2), cap);
        if (cost < best_cost) {
          best_cost = cost;
          best = candidate;
        }
      }
    }
    if (!best) return std::nullopt;
    // The views the best candidate explains (mean corner error <= 3 px):
    // all of them, or at least two; the rest are left to the adjustment's
    // outlier test (frames posed through keypoints can be a few px off).
    int explained = 0;
    for (const auto& [s2, m2] : seen) explained += view_cost(*best, s2, m2) <= 4 * 9.0;
    ARPOS_DEBUG("room marker " << id << " placed from " << seen.size() << " view(s) in placed frames: "
                               << explained << " explained within 3 px");
    if (explained < std::min<int>(2, static_cast<int>(seen.size()))) return std::nullopt;
    return best;
  };
  // Markers seen only in frames posed without them.
  auto add_new_markers = [&]() {
    std::set<int> ids;
    for (const auto& f : frames) {
      if (!f.posed) continue;
      for (const auto& marker : f.markers) {
        if (!marker_slot.count(marker.id)) ids.insert(marker.id);
      }
    }
    bool added = false;
    for (int id : ids) {
      if (const std::optional<Rigid3d> pose = place_from_views(id)) {
        add_marker(id, *pose);
        added = true;
      }
    }
    return added;
  };
  for (size_t s = 0; s < frames.size(); ++s) {
    if (frames[s].posed) associate(static_cast<int>(s));
  }
  for (int round = 0; round < 20; ++round) {
    bool changed = false;
    // Forward then backward, so chains of frames propagate both ways.
    for (int pass = 0; pass < 2; ++pass) {
      for (int k = 0; k < static_cast<int>(frames.size()); ++k) {
        const int s = pass == 0 ? k : static_cast<int>(frames.size()) - 1 - k;
        if (frames[s].posed) continue;
        if (pose_by_markers(frames[s], known_markers()) || pose_by_keypoints(s)) {
          associate(s);
          changed = true;
        }
      }
    }
    changed |= add_new_markers();
    if (!changed) break;
  }
  for (const auto& f : frames) {  // with --verbose: how each frame was placed
    if (GetLogLevel() > LogLevel::kDebug) break;
    std::ostringstream line;
    line << "room frame " << f.index << ": "
         << (f.posed ? (f.posed_by_keypoints ? "placed by keypoints" : "placed by markers") : "not placed")
         << ", " << f.keypoints.size() << " keypoints, markers";
    for (const auto& m : f.markers) line << " " << m.id << " (" << static_cast<int>(m.MeanSidePx()) << " px)";
    std::vector<int> unrefined;  // read, but their edge lines did not fit
    for (int id : f.all_ids_seen) {
      const bool refined = std::any_of(f.markers.begin(), f.markers.end(),
                                       [id](const MarkerObservation& m) { return m.id == id; });
      if (!refined) unrefined.push_back(id);
    }
    if (!unrefined.empty()) {
      line << "; read but their edges not fitted:";
      for (int id : unrefined) line << " " << id;
    }
    ARPOS_DEBUG(line.str());
  }
  {
    std::vector<int> still;
    for (int id : graph.unconnected_markers) {
      if (!marker_slot.count(id)) still.push_back(id);
    }
    report.unconnected_markers = still;
    report.warnings.erase(std::remove_if(report.warnings.begin(), report.warnings.end(),
                                         [](const std::string& w) { return w.find("never seen together") != std::string::npos; }),
                          report.warnings.end());
    if (!still.empty()) {
      report.warnings.push_back(StringPrintf("%zu marker(s) could not be linked to the mapped ones; left out", still.size()));
    }
  }
  std::vector<bool> in_adjustment(candidates.size(), false);
  if (options.use_keypoints) {
    report.landmark_candidates = static_cast<int>(candidates.size());

    // Selection: seen often enough, outside the exclusion boxes, spread over
    // voxels. The candidates are in the root marker's frame: the boxes (room
    // frame) are tested here only when that is the origin's, else on the
    // adjusted landmarks in the room frame (below).
    std::vector<int> kept;
    for (size_t c = 0; c < candidates.size(); ++c) {
      if (static_cast<int>(candidates[c].observations.size()) < options.min_landmark_observations) continue;
      const Eigen::Vector3d X = candidates[c].Position();
      bool excluded = false;
      if (root_id == origin_id) {
        for (const auto& box : options.exclude_landmarks) excluded |= box.Contains(X);
      }
      if (excluded) {
        ++report.landmarks_excluded;
        continue;
      }
      kept.push_back(static_cast<int>(c));
    }
    if (static_cast<int>(kept.size()) > options.max_landmarks) {
      std::map<std::tuple<int, int, int>, std::vector<int>> voxels;
      for (int c : kept) {
        const Eigen::Vector3d X = candidates[c].Position() / options.landmark_voxel_m;
        voxels[{static_cast<int>(std::floor(X.x())), static_cast<int>(std::floor(X.y())),
                static_cast<int>(std::floor(X.z()))}]
            .push_back(c);
      }
      for (auto& [key, list] : voxels) {
        std::sort(list.begin(), list.end(), [&](int a, int b) {
          return candidates[a].observations.size() > candidates[b].observations.size();
        });
      }
      std::vector<int> thinned;
      for (size_t rank = 0; static_cast<int>(thinned.size()) < options.max_landmarks; ++rank) {
        std::vector<int> layer;
        for (const auto& [key, list] : voxels) {
          if (rank < list.size()) layer.push_back(list[rank]);
        }
        if (layer.empty()) break;
        std::sort(layer.begin(), layer.end(), [&](int a, int b) {
          return candidates[a].observations.size() > candidates[b].observations.size();
        });
        for (int c : layer) {
          if (static_cast<int>(thinned.size()) >= options.max_landmarks) break;
          thinned.push_back(c);
        }
      }
      kept = std::move(thinned);
    }
    // Groups of frames that neither the kept landmarks nor the mapped
    // markers tie together (a wide step where the frames on either side
    // share their keypoints in pairs only) would be held to each other in
    // the adjustment by the room's planes alone, free to slide along them
    // (random seed 13 with a linear camera: the origin's frames, 1.1 m of
    // uncertainty at the couch). The candidates seen in fewer frames than
    // min_landmark_observations, in two such groups, join them.
    {
      std::vector<int> group(frames.size());
      std::iota(group.begin(), group.end(), 0);
      std::function<int(int)> find = [&](int x) { return group[x] == x ? x : group[x] = find(group[x]); };
      for (int c : kept) {
        const auto& obs = candidates[c].observations;
        for (size_t k = 1; k < obs.size(); ++k) group[find(obs[k].first)] = find(obs[0].first);
      }
      std::map<int, int> seen_in;  // mapped marker id -> a posed frame that sees it
      for (size_t s = 0; s < frames.size(); ++s) {
        if (!frames[s].posed) continue;
        for (const auto& m : frames[s].markers) {
          if (!marker_slot.count(m.id)) continue;
          const auto [it, first] = seen_in.emplace(m.id, static_cast<int>(s));
          if (!first) group[find(static_cast<int>(s))] = find(it->second);
        }
      }
      std::vector<int> linking;
      std::set<std::pair<int, int>> pairs;
      for (size_t c = 0; c < candidates.size(); ++c) {
        const auto& obs = candidates[c].observations;
        if (obs.size() < 2 || static_cast<int>(obs.size()) >= options.min_landmark_observations) continue;
        const int a = find(obs.front().first), b = find(obs.back().first);
        if (a == b) continue;
        bool excluded = false;
        if (root_id == origin_id) {
          for (const auto& box : options.exclude_landmarks) excluded |= box.Contains(candidates[c].Position());
        }
        if (excluded) continue;
        linking.push_back(static_cast<int>(c));
        pairs.emplace(std::min(a, b), std::max(a, b));
      }
      if (!linking.empty()) {
        ARPOS_DEBUG(linking.size() << " keypoint(s) seen in two frames join " << pairs.size()
                                   << " pair(s) of frame groups that nothing else ties");
        kept.insert(kept.end(), linking.begin(), linking.end());
        report.landmarks_joining_groups = static_cast<int>(linking.size());
      }
    }
    // Landmarks and their observations for the adjustment.
    rebuild_cameras();
    for (int c : kept) in_adjustment[c] = true;
    for (int c : kept) {
      const int landmark = static_cast<int>(landmarks.size());
      landmarks.push_back(candidates[c].Position());
      for (const auto& [s, i] : candidates[c].observations) {
        BaKeypointObservation o;
        o.camera = camera_slot[s];
        o.landmark = landmark;
        o.pixel = frames[s].keypoint_px[i];
        o.sigma_px = options.keypoint_sigma_px;
        o.depth_m = frames[s].keypoints.depth_m[i];
        keypoint_observations.push_back(o);
        keypoint_source.emplace_back(s, i);
      }
    }
  }
  report.landmarks_s = SecondsSince(t_landmarks);

  // ---------------------------------------------------------------- 4. joint adjustment
  const auto t_adjust = Clock::now();
  std::vector<double> delays;  // of the frames whose depth is of another instant
  for (const FrameData& f : frames) {
    if (sequence.has_depth(f.index) && sequence.depth_delay_s(f.index) != 0) {
      delays.push_back(sequence.depth_delay_s(f.index));
    }
  }
  const bool depth_to_move = options.move_delayed_depth && !delays.empty();
  progress(depth_to_move ? "reading the depth again as of each frame's colour instant"
                         : "bundle adjustment",
           0.7);
  rebuild_cameras();
  if (!marker_slot.count(origin_id)) {
    const std::optional<Rigid3d> origin = place_from_views(origin_id);
    // Sharp, whole views of the origin in frames the rest of the map could
    // not place (no marker and too few keypoints in common with the frames
    // around them): a link to record, not a better view.
    int sharp_views = 0, sharp_views_placed = 0;
    for (const auto& f : frames) {
      for (const auto& m : f.markers) {
        if (m.id != origin_id) continue;
        ++sharp_views;
        sharp_views_placed += f.posed;
      }
    }
    if (!origin && sharp_views > 0 && sharp_views_placed == 0) {
      ARPOS_INPUT_ERROR(sequence.folder().string()
                        << ": the origin marker (id " << origin_id << ") is seen sharply in " << sharp_views
                        << " frame(s), but none of them could be tied to the rest of the map: they show no "
                           "marker of the map and share too few keypoints with the frames placed around "
                           "them (a bare floor or wall around the origin); record the room again with another "
                           "room marker in view together with the origin marker, or moving slowly from the "
                           "mapped markers to it over textured surroundings");
    }
    if (!origin) {
      ARPOS_INPUT_ERROR(sequence.folder().string()
                        << ": the origin marker (id " << origin_id
                        << ") is seen, but never fully and sharply in a frame the rest of the map "
                           "places (blurred, occluded, cut by the image border or too small); record "
                           "the room again with a close, sharp view of the origin marker together "
                           "with other room markers");
    }
    add_marker(origin_id, *origin);
  }
  collect_marker_observations();
  ba.landmarks_in_room = landmarks;
  ba.keypoint_observations = keypoint_observations;
  // Depth of another instant than its colour (sensor/depth_timing.h): a
  // room walk turns at up to 170 deg/s, so 10 ms moves what the depth saw by
  // centimetres at 3 m, and the adjustment's depth terms would pull each
  // frame towards its depth camera. Every frame the map places is placed by
  // now (markers, then keypoints): each delayed frame's depth is read again
  // as of its colour instant, by the camera's motion between the frames
  // placed around it (as the markers and keypoints alone adjust them),
  // before depth enters the adjustment and the checks.
  std::map<int, Rigid3d> colour_from_depth;  // sequence index -> the camera's motion over the delay
  {
    const auto t_move = Clock::now();
    if (!delays.empty()) {
      std::nth_element(delays.begin(), delays.begin() + delays.size() / 2, delays.end());
      report.depth_delay_s = delays[delays.size() / 2];
      report.frames_depth_delayed = static_cast<int>(delays.size());
    }
    if (depth_to_move) {
      std::vector<size_t> posed;  // frame slots in time order
      for (size_t s = 0; s < frames.size(); ++s) {
        if (camera_slot[s] >= 0) posed.push_back(s);
      }
      std::sort(posed.begin(), posed.end(), [&](size_t a, size_t b) {
        return sequence.timestamp_s(frames[a].index) < sequence.timestamp_s(frames[b].index);
      });
      // The poses to take the motion from: the markers and keypoints alone
      // adjusted, without depth terms (the depth as read would pull each
      // frame towards its depth camera). Against building the whole map
      // twice (the second time from the first's adjusted poses): maps near
      // the couch as good on balance over 22 delayed rooms, in half the
      // time (benchmark/accuracy.md, session 44).
      BaProblem colour_only = ba;
      BaOptions colour_options = options.bundle_adjustment;
      colour_options.use_marker_depth = colour_options.use_keypoint_depth =
          colour_options.use_plane_depth = false;
      colour_options.threads = options.adjustment_threads;
      colour_options.max_iterations = options.delayed_depth_pose_iterations;
      colour_options.covariance_markers.clear();
      const BaSummary colour_summary = RunBundleAdjustment(&colour_only, colour_options);
      std::vector<double> times;
      std::vector<Rigid3d> room_from_camera;
      for (size_t s : posed) {
        times.push_back(sequence.timestamp_s(frames[s].index));
        room_from_camera.push_back((colour_summary.usable
                                        ? colour_only.camera_from_room[camera_slot[s]]
                                        : frames[s].camera_from_room)
                                       .Inverse());
      }
      std::vector<std::pair<size_t, Rigid3d>> to_move;  // frame slot, colour_from_depth
      for (size_t k = 0; k < posed.size(); ++k) {
        const int index = frames[posed[k]].index;
        if (!sequence.has_depth(index) || sequence.depth_delay_s(index) == 0) continue;
        if (const std::optional<Rigid3d> m =
                ColourFromDepthCamera(times, room_from_camera, k, sequence.depth_delay_s(index))) {
          to_move.emplace_back(posed[k], *m);
          colour_from_depth[index] = *m;
        }
      }
      std::atomic<size_t> next{0};
      std::exception_ptr error;
      std::mutex error_mutex;
      auto worker = [&]() {
        try {
          const KeypointExtractor extractor(options.keypoints);
          for (size_t j = next++; j < to_move.size(); j = next++) {
            FrameData& f = frames[to_move[j].first];
            const cv::Mat depth =
                DepthAtColourInstant(sequence.LoadDepth(f.index, K), K.depth_scale, K.fx, K.fy,
                                     K.cx, K.cy, to_move[j].second);
            if (!f.grid_z.empty()) {
              for (size_t i = 0; i < plane_grid.px.size(); ++i) {
                f.grid_z[i] =
                    static_cast<float>(depth.at<uint16_t>(plane_grid.px[i]) / K.depth_scale);
              }
            }
            for (size_t m = 0; m < f.markers.size(); ++m) {
              f.depth_samples[m] =
                  SampleMarkerDepth(depth, f.image_corners_px[m], K, options.marker_depth_samples);
              if (f.markers[m].id == origin_id) {
                f.support_samples[m] = SampleSupportDepth(
                    depth, f.image_corners_px[m], K, marker_size,
                    options.support_plane_half_width_m, options.support_plane_samples);
              }
            }
            if (options.use_keypoints) extractor.ReadDepth(depth, K.depth_scale, &f.keypoints);
          }
        } catch (...) {
          std::lock_guard<std::mutex> lock(error_mutex);
          if (!error) error = std::current_exception();
          next = to_move.size();
        }
      };
      std::vector<std::thread> workers;
      for (int t = 0; t < std::max(1, options.threads); ++t) workers.emplace_back(worker);
      for (auto& w : workers) w.join();
      if (error) std::rethrow_exception(error);
      // The landmarks' observations carry their keypoint's depth.
      for (size_t k = 0; k < keypoint_observations.size(); ++k) {
        const auto& [slot, i] = keypoint_source[k];
        keypoint_observations[k].depth_m = frames[slot].keypoints.depth_m[i];
      }
      report.frames_depth_moved_to_colour = static_cast<int>(to_move.size());
      collect_marker_observations();
      ba.keypoint_observations = keypoint_observations;
      report.depth_move_s = SecondsSince(t_move);
      progress("bundle adjustment", 0.75);
    }
  }
  BaOptions joint_options = options.bundle_adjustment;
  joint_options.threads = options.adjustment_threads;
  if (options.estimate_depth_correction) {
    // Depth against the colour geometry (depth_check.h): on simulated random
    // conditions, comparing with landmarks instead gave residuals of 2-63
    // sigma, depth inflated accordingly and maps up to 120 mm off; with
    // markers alone the residual is ~1 sigma and the depth scale error is
    // found (-0.18 % where the truth is -0.17 %).
    DepthCheckInput check_input;
    check_input.intrinsics = &K;
    check_input.marker_size_m = marker_size;
    check_input.grid = &plane_grid;
    for (size_t c = 0; c < ba.camera_from_room.size(); ++c)
      check_input.grid_z.push_back(&frames[camera_frame[c]].grid_z);
    check_input.plane_support_m = options.depth_check_plane_support_m;
    check_input.plane_gate_m = options.room_plane_gate_m;
    check_input.plane_min_markers = options.room_plane_min_markers;
    check_input.plane_min_spread_m = options.room_plane_min_spread_m;
    const DepthCheckResult check = CheckDepthAgainstColourGeometry(ba, joint_options, check_input);
    const DepthCorrectionFit& fit = check.fit;
    report.depth_correction = check.message;
    // Depth weighted by what it is worth: the noise model scaled to the
    // spread the readings show around the colour geometry (after any
    // correction) when that is clearly beyond the model (below 1.5x nothing
    // changes: the markers' own pose errors are part of the spread; with
    // landmarks compared too it read 1.2-1.3x on cases whose depth follows
    // the model exactly, where inflating made localisation worse).
    const double depth_factor =
        fit.applied ? fit.normalised_rms_after : fit.normalised_rms_before;
    if (depth_factor > options.depth_inflation_threshold) {
      joint_options.depth_sigma_const_m *= depth_factor;
      joint_options.depth_sigma_quad_per_m *= depth_factor;
      report.depth_correction += StringPrintf("; depth weighted as %.2fx the sensor model's noise", depth_factor);
    }
    if (fit.applied) {
      result.map.depth_correction = fit.correction;
      ApplyDepthCorrection(fit.correction, K, &ba);
    }
  }
  // The room's planes (room_planes.h) at the map's current state, and each
  // frame's depth pixels on them; with `from_depth`, the planes found in
  // the depth too (after the first adjustment: the frames' first poses,
  // from a few keypoints where no marker is seen, can be off by centimetres
  // and would split a wall in two).
  auto set_room_planes = [&](bool from_depth) {
    std::vector<MarkerPlane> planes =
        PlanesOfMarkers(ba.room_from_marker, marker_size, options.room_plane_min_markers,
                        options.room_plane_min_spread_m);
    const int origin_slot = marker_slot.at(origin_id);
    const Rigid3d& origin_pose = ba.room_from_marker[origin_slot];
    if (options.room_plane_for_origin &&
        std::none_of(planes.begin(), planes.end(), [&](const MarkerPlane& p) {
          return std::find(p.markers.begin(), p.markers.end(), origin_slot) != p.markers.end();
        })) {
      MarkerPlane p;
      p.normal = origin_pose.rotation * Eigen::Vector3d::UnitZ();
      p.offset = p.normal.dot(origin_pose.translation);
      p.markers = {origin_slot};
      p.marker_centres = {origin_pose.translation};
      planes.push_back(std::move(p));
    }
    // Each depth of camera c's grid (corrected when the depth needed it):
    // fn(grid index, depth, point in the camera, point in the room).
    const DepthCorrection& correction = result.map.depth_correction;
    const bool correct = !correction.IsIdentity();
    auto for_each_grid_point = [&](size_t c, auto&& fn) {
      const FrameData& f = frames[camera_frame[c]];
      const Rigid3d room_from_camera = ba.camera_from_room[c].Inverse();
      for (size_t i = 0; i < f.grid_z.size(); ++i) {
        double z = f.grid_z[i];
        if (!(z > 0)) continue;
        const Eigen::Vector2d& r = plane_grid.ray[i];
        if (correct) z = correction.TrueDepth(z, r.x(), r.y());
        const Eigen::Vector3d xc(r.x() * z, r.y() * z, z);
        fn(i, z, xc, room_from_camera * xc);
      }
    };
    // The plane a room point at depth z lies on (PlaneNear), or -1.
    auto plane_near = [&](const Eigen::Vector3d& x, double z) {
      const double gate = std::max(options.room_plane_gate_m, 3 * joint_options.DepthSigmaM(z));
      return PlaneNear(planes, x, gate, options.room_plane_support_m);
    };
    int depth_planes = 0;
    if (from_depth) {
      std::vector<Eigen::Vector3d> points;
      std::vector<int> views;
      for (size_t c = 0; c < ba.camera_from_room.size(); ++c) {
        const std::vector<float>& grid_z = frames[camera_frame[c]].grid_z;
        for_each_grid_point(c, [&](size_t i, double z, const Eigen::Vector3d&, const Eigen::Vector3d& x) {
          if (grid_z[i] > options.room_plane_depth_max_m) return;  // (the depth as read)
          if (plane_near(x, z) >= 0) return;                        // on a marker plane
          points.push_back(x);
          views.push_back(static_cast<int>(c));
        });
      }
      for (MarkerPlane& p : planes) {  // (AddDepthPlanes: why not the origin's)
        p.extend_in_depth = std::find(p.markers.begin(), p.markers.end(), origin_slot) == p.markers.end();
      }
      depth_planes = AddDepthPlanes(points, views, options.depth_planes, &planes);
    }
    ba.planes.clear();
    ba.plane_observations.clear();
    for (const MarkerPlane& p : planes) {
      BaPlane b;
      b.normal = p.normal;
      b.offset = p.offset;
      if (options.room_plane_ties_markers) b.markers = p.markers;
      b.flatness_sigma_m = options.room_plane_flatness_m;
      b.tilt_sigma_rad = RadFromDeg(options.room_plane_marker_tilt_deg);
      ba.planes.push_back(std::move(b));
    }
    int samples_used = 0, views_used = 0;
    for (size_t c = 0; c < ba.camera_from_room.size(); ++c) {
      const FrameData& f = frames[camera_frame[c]];
      if (f.grid_z.empty()) continue;
      const Rigid3d& camera_from_room = ba.camera_from_room[c];
      std::vector<std::vector<size_t>> on(planes.size());
      std::vector<std::vector<Eigen::Vector3d>> on_points(planes.size());
      std::vector<std::vector<double>> on_sigma(planes.size());
      std::vector<double> z_of(f.grid_z.size(), 0.0);
      for_each_grid_point(c, [&](size_t i, double z, const Eigen::Vector3d& xc, const Eigen::Vector3d& x) {
        z_of[i] = z;
        const int p = plane_near(x, z);
        if (p < 0) return;
        on[p].push_back(i);
        on_points[p].push_back(xc);
        on_sigma[p].push_back(joint_options.DepthSigmaM(z));
      });
      for (size_t p = 0; p < planes.size(); ++p) {
        if (static_cast<int>(on[p].size()) < options.room_plane_min_samples) continue;
        const Eigen::Vector3d n = camera_from_room.rotation * planes[p].normal;
        const double d = n.dot(camera_from_room * (planes[p].normal * planes[p].offset));
        const std::vector<size_t> kept = PointsOnViewedPlane(on_points[p], on_sigma[p], n, d);
        if (static_cast<int>(kept.size()) < options.room_plane_min_samples) continue;
        BaPlaneObservation o;
        o.camera = static_cast<int>(c);
        o.plane = static_cast<int>(p);
        // Evenly thinned to at most room_plane_max_samples; those kept count
        // as room_plane_max_effective independent ones at most.
        const size_t step = (kept.size() + options.room_plane_max_samples - 1) / options.room_plane_max_samples;
        for (size_t k = 0; k < kept.size(); k += step) {
          const size_t i = on[p][kept[k]];
          const Eigen::Vector2d& r = plane_grid.ray[i];
          o.samples.push_back({Eigen::Vector2f(static_cast<float>(r.x() * K.fx + K.cx),
                                               static_cast<float>(r.y() * K.fy + K.cy)),
                               static_cast<float>(z_of[i])});
        }
        o.share = std::sqrt(std::max(1.0, o.samples.size() / options.room_plane_max_effective));
        samples_used += static_cast<int>(o.samples.size());
        ++views_used;
        ba.plane_observations.push_back(std::move(o));
      }
    }
    report.room_planes = StringPrintf("%zu room plane(s) in the adjustment (%d found in depth alone), %d views, %d depth samples",
                                      planes.size(), depth_planes, views_used, samples_used);
  };
  if (options.use_room_planes) set_room_planes(false);
  // The map near the couch as known relative to the origin marker, marginal
  // over everything the adjustment estimates: the markers within 1.5 m of
  // the couch point (or the nearest one), each centre's covariance in the
  // origin's frame, after the last adjustment.
  auto with_couch_covariance = [&](BaOptions o) {
    const int origin_slot = marker_slot.at(origin_id);
    const Eigen::Vector3d couch = ba.room_from_marker[origin_slot] * options.couch_point_in_room;
    o.covariance_reference = origin_slot;
    int nearest = -1;
    double nearest_m = std::numeric_limits<double>::infinity();
    for (size_t m = 0; m < ba.room_from_marker.size(); ++m) {
      if (static_cast<int>(m) == origin_slot) continue;
      const double d = (ba.room_from_marker[m].translation - couch).norm();
      if (d < 1.5) o.covariance_markers.push_back(static_cast<int>(m));
      if (d < nearest_m) {
        nearest_m = d;
        nearest = static_cast<int>(m);
      }
    }
    if (o.covariance_markers.empty() && nearest >= 0) o.covariance_markers.push_back(nearest);
    return o;
  };
  // (Only after the last: with planes found in depth a second one follows.)
  const bool second_follows = options.use_room_planes && options.room_planes_from_depth;
  report.joint_adjustment =
      RunBundleAdjustment(&ba, second_follows ? joint_options : with_couch_covariance(joint_options));
  BaSummary couch_covariance = report.joint_adjustment;
  // Drop outlier observations and adjust again.
  {
    const BaResiduals res = ComputeBaResiduals(ba);
    std::vector<BaKeypointObservation> kept;
    std::vector<std::pair<int, int>> kept_source;
    for (size_t i = 0; i < ba.keypoint_observations.size(); ++i) {
      const auto& o = ba.keypoint_observations[i];
      const bool px_ok = res.keypoint_px[i] < options.outlier_sigmas * o.sigma_px;
      const bool z_ok = !(o.depth_m > 0) ||
                        std::abs(res.keypoint_depth_m[i]) < options.outlier_sigmas * joint_options.DepthSigmaM(o.depth_m);
      if (px_ok && z_ok) {
        kept.push_back(o);
        kept_source.push_back(keypoint_source[i]);
      }
    }
    std::vector<BaMarkerObservation> kept_markers;
    for (size_t i = 0; i < ba.marker_observations.size(); ++i) {
      const auto& o = ba.marker_observations[i];
      const double sigma = *std::max_element(o.sigma_px.begin(), o.sigma_px.end());
      if (res.marker_rms_px[i] < std::max(0.5, options.outlier_sigmas * sigma)) {
        kept_markers.push_back(ba.marker_observations[i]);
      }
    }
    // Landmarks keep at least two observations.
    std::vector<int> count(ba.landmarks_in_room.size(), 0);
    for (const auto& o : kept) ++count[o.landmark];
    std::vector<int> remap(ba.landmarks_in_room.size(), -1);
    std::vector<Eigen::Vector3d> new_landmarks;
    for (size_t l = 0; l < count.size(); ++l) {
      if (count[l] >= 2) {
        remap[l] = static_cast<int>(new_landmarks.size());
        new_landmarks.push_back(ba.landmarks_in_room[l]);
      }
    }
    std::vector<BaKeypointObservation> remapped;
    std::vector<std::pair<int, int>> remapped_source;
    for (size_t i = 0; i < kept.size(); ++i) {
      BaKeypointObservation o = kept[i];
      if (remap[o.landmark] < 0) continue;
      o.landmark = remap[o.landmark];
      remapped.push_back(o);
      remapped_source.push_back(kept_source[i]);
    }
    keypoint_source = std::move(remapped_source);
    const bool changed = remapped.size() != ba.keypoint_observations.size() ||
                         kept_markers.size() != ba.marker_observations.size();
    ba.landmarks_in_room = std::move(new_landmarks);
    ba.keypoint_observations = std::move(remapped);
    ba.marker_observations = std::move(kept_markers);
    const bool depth_planes = options.use_room_planes && options.room_planes_from_depth;
    if (depth_planes) set_room_planes(true);
    if (changed || depth_planes) {
      progress(depth_planes ? "bundle adjustment (outliers removed, planes found in depth)"
                            : "bundle adjustment (outliers removed)",
               0.85);
      const BaSummary second = RunBundleAdjustment(&ba, with_couch_covariance(joint_options));
      couch_covariance = second;
      report.joint_adjustment.iterations += second.iterations;
      report.joint_adjustment.seconds += second.seconds;
      report.joint_adjustment.final_cost = second.final_cost;
      report.joint_adjustment.message = second.message;
      report.joint_adjustment.usable = second.usable;
    }
  }
  if (root_id != origin_id) {  // the room frame: the origin marker's
    const Rigid3d origin_from_root = ba.room_from_marker[marker_slot.at(origin_id)].Inverse();
    const Rigid3d root_from_origin = origin_from_root.Inverse();
    for (Rigid3d& m : ba.room_from_marker) m = origin_from_root * m;
    for (Rigid3d& c : ba.camera_from_room) c = c * root_from_origin;
    for (Eigen::Vector3d& l : ba.landmarks_in_room) l = origin_from_root * l;
    for (BaPlane& p : ba.planes) {  // n . x = o  ->  (R n) . x' = o + (R n) . t
      p.normal = origin_from_root.rotation * p.normal;
      p.offset += p.normal.dot(origin_from_root.translation);
    }
  }
  for (size_t c = 0; c < camera_frame.size(); ++c) frames[camera_frame[c]].camera_from_room = ba.camera_from_room[c];
  report.adjustment_s = SecondsSince(t_adjust);

  // The room frame's own uncertainty: the origin marker's pose from its
  // corner observations alone, the cameras as adjusted (Gauss-Newton
  // covariance, numeric Jacobian, perturbation in the room frame).
  {
    const int slot = marker_slot.at(origin_id);
    const std::array<Eigen::Vector3d, 4> corners = MarkerCornersInMarker(marker_size);
    const Rigid3d room_from_origin = ba.room_from_marker[slot];
    Eigen::Matrix<double, 6, 6> info = Eigen::Matrix<double, 6, 6>::Zero();
    int used = 0;
    for (const BaMarkerObservation& o : ba.marker_observations) {
      if (o.marker != slot) continue;
      ++used;
      const Rigid3d& camera_from_room = ba.camera_from_room[o.camera];
      auto project = [&](const Eigen::Matrix<double, 6, 1>& xi, int c) {
        const Rigid3d moved = Rigid3d::FromRotationVector(xi.head<3>(), xi.tail<3>()) * room_from_origin;
        return K.Project(camera_from_room * (moved * corners[c]));
      };
      for (int c = 0; c < 4; ++c) {
        Eigen::Matrix<double, 2, 6> j;
        for (int k = 0; k < 6; ++k) {
          Eigen::Matrix<double, 6, 1> d = Eigen::Matrix<double, 6, 1>::Zero();
          d(k) = 1e-6;
          j.col(k) = (project(d, c) - project(-d, c)) / 2e-6;
        }
        info.noalias() += j.transpose() * j / (o.sigma_px[c] * o.sigma_px[c]);
      }
    }
    report.origin_observations = used;
    // The plane the origin is tied to in the adjustment (its floor or wall),
    // as the depth of every view of it fixes its tilt given the cameras, and
    // the tie's own slack: information on the origin's tilt.
    int origin_plane = -1;
    for (size_t p = 0; p < ba.planes.size(); ++p) {
      const std::vector<int>& m = ba.planes[p].markers;
      if (ba.planes[p].tilt_sigma_rad > 0 && std::find(m.begin(), m.end(), slot) != m.end()) {
        origin_plane = static_cast<int>(p);
      }
    }
    if (origin_plane >= 0) {
      const BaPlane& plane = ba.planes[origin_plane];
      Eigen::Matrix3d plane_info = Eigen::Matrix3d::Zero();  // rotation about room x, y; offset
      int views = 0;
      for (const BaPlaneObservation& o : ba.plane_observations) {
        if (o.plane != origin_plane) continue;
        ++views;
        const Rigid3d& camera_from_room = ba.camera_from_room[o.camera];
        for (const DepthSample& sample : o.samples) {
          const Eigen::Vector3d ray((sample.pixel.x() - K.cx) / K.fx, (sample.pixel.y() - K.cy) / K.fy, 1.0);
          auto depth = [&](const Eigen::Vector3d& xi) {
            const Eigen::Vector3d n =
                camera_from_room.rotation * (Rigid3d::FromRotationVector(Eigen::Vector3d(xi.x(), xi.y(), 0),
                                                                         Eigen::Vector3d::Zero())
                                                 .rotation *
                                             plane.normal);
            return (plane.offset + xi.z() + n.dot(camera_from_room.translation)) / n.dot(ray);
          };
          Eigen::RowVector3d j;
          for (int k = 0; k < 3; ++k) {
            Eigen::Vector3d d = Eigen::Vector3d::Zero();
            d(k) = 1e-6;
            j(k) = (depth(d) - depth(-d)) / 2e-6;
          }
          const double sigma = o.share * joint_options.DepthSigmaM(sample.depth_m);
          plane_info.noalias() += j.transpose() * j / (sigma * sigma);
        }
      }
      const Eigen::Matrix3d plane_cov = plane_info.ldlt().solve(Eigen::Matrix3d::Identity());
      if (views > 0 && plane_cov.allFinite()) {
        const Eigen::Matrix2d tilt_cov =
            plane_cov.topLeftCorner<2, 2>() + plane.tilt_sigma_rad * plane.tilt_sigma_rad * Eigen::Matrix2d::Identity();
        info.topLeftCorner<2, 2>() += tilt_cov.inverse();
        report.origin_plane_views = views;
      }
    }
    const Eigen::Matrix<double, 6, 6> cov = info.ldlt().solve(Eigen::Matrix<double, 6, 6>::Identity());
    if (used > 0 && cov.allFinite()) {
      // Tilt: rotation about the room's x and y axes (the origin marker's
      // plane); yaw: about its normal; position: at the couch point.
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> tilt(cov.topLeftCorner<2, 2>());
      report.room_frame_tilt_sigma_deg = std::sqrt(std::max(0.0, tilt.eigenvalues().maxCoeff())) * 180 / M_PI;
      report.room_frame_yaw_sigma_deg = std::sqrt(std::max(0.0, cov(2, 2))) * 180 / M_PI;
      report.room_frame_covariance = cov;
      report.room_frame_couch_sigma_mm = report.RoomFramePositionSigmaMm(options.couch_point_in_room);
    }
    // Markers coplanar with the origin (the floor, or the wall it is on)
    // and that plane as depth sees it around the origin constrain its tilt
    // too: the markers' centres spread over metres, the depth over a metre
    // square in every view of the origin, fix the plane's tilt far better
    // than a small, rarely seen origin's own corners. Fused by inverse
    // variance when the origin's own tilt is weaker than its tolerance, or
    // the room frame weaker than its tolerance at the couch (options); the
    // room frame turns onto the fused plane about the origin's centre.
    const bool weak_tilt = report.room_frame_tilt_sigma_deg > options.max_room_frame_tilt_sigma_deg;
    const bool weak_at_couch = options.fuse_tilt_when_weak_at_couch &&
                               report.room_frame_couch_sigma_mm > options.max_room_frame_couch_sigma_mm;
    if ((weak_tilt || weak_at_couch) && std::isfinite(report.room_frame_tilt_sigma_deg) &&
        report.origin_plane_views == 0) {  // (tied to its plane: the adjustment fused them)
      const Rigid3d origin_from_room = ba.room_from_marker[slot].Inverse();
      std::vector<TiltEstimate> estimates;
      TiltEstimate own;
      own.cov = report.room_frame_covariance.topLeftCorner<2, 2>();
      estimates.push_back(own);
      if (options.use_coplanar_markers) {
        std::vector<Eigen::Vector3d> centres;
        for (size_t m = 0; m < ba.room_from_marker.size(); ++m) {
          if (static_cast<int>(m) == slot) continue;
          const Rigid3d origin_from_marker = origin_from_room * ba.room_from_marker[m];
          const Eigen::Vector3d normal = origin_from_marker.rotation * Eigen::Vector3d::UnitZ();
          const Eigen::Vector3d c = origin_from_marker.translation;
          if (normal.z() > std::cos(5 * M_PI / 180) && std::abs(c.z()) < 0.03) centres.push_back(c);
        }
        Eigen::Matrix2d ata = Eigen::Matrix2d::Zero();
        Eigen::Vector2d atb = Eigen::Vector2d::Zero();
        for (const Eigen::Vector3d& c : centres) {
          ata += c.head<2>() * c.head<2>().transpose();
          atb += c.head<2>() * c.z();
        }
        if (centres.size() >= 2 && ata.determinant() > 0.25) {  // spread over ~1 m in both directions
          const Eigen::Vector2d slope = ata.ldlt().solve(atb);  // z = a x + b y
          double rss = 0;
          for (const Eigen::Vector3d& c : centres) rss += std::pow(c.z() - slope.dot(c.head<2>()), 2);
          const double flat_sigma = std::max(options.coplanar_flatness_m,
                                             std::sqrt(rss / std::max<double>(1, centres.size() - 2)));
          const Eigen::Matrix2d slope_cov = ata.inverse() * flat_sigma * flat_sigma;
          Eigen::Matrix2d flip;
          flip << 0, 1, -1, 0;
          TiltEstimate plane;
          plane.omega = Eigen::Vector2d(slope.y(), -slope.x());
          plane.cov = flip * slope_cov * flip.transpose();
          if (plane.omega.allFinite() && plane.cov.allFinite()) {
            estimates.push_back(plane);
            report.coplanar_markers = static_cast<int>(centres.size());
          }
        }
      }
      if (options.use_support_plane) {
        const Eigen::Vector3d z_axis = Eigen::Vector3d::UnitZ();
        std::vector<SupportView> views;
        for (size_t s = 0; s < frames.size(); ++s) {
          if (camera_slot[s] < 0) continue;
          const FrameData& f = frames[s];
          const Rigid3d origin_from_camera = origin_from_room * ba.camera_from_room[camera_slot[s]].Inverse();
          const Eigen::Vector3d centre = origin_from_camera.translation;
          for (size_t m = 0; m < f.markers.size(); ++m) {
            if (f.markers[m].id != origin_id || f.support_samples[m].empty()) continue;
            SupportView view;
            for (const DepthSample& sample : f.support_samples[m]) {
              double z = sample.depth_m;
              if (!(z > 0)) continue;
              const Eigen::Vector2d xy((sample.pixel.x() - K.cx) / K.fx, (sample.pixel.y() - K.cy) / K.fy);
              if (!result.map.depth_correction.IsIdentity()) {
                z = result.map.depth_correction.TrueDepth(z, xy.x(), xy.y());
              }
              const Eigen::Vector3d p = origin_from_camera * Eigen::Vector3d(xy.x() * z, xy.y() * z, z);
              const double along = std::abs((p - centre).normalized().dot(z_axis));
              if (along < 0.2) continue;  // grazing
              view.points.push_back(p);
              view.sigma_m.push_back(joint_options.DepthSigmaM(z) * along);
            }
            views.push_back(std::move(view));
          }
        }
        const SupportPlaneFit plane = FitSupportPlane(views, options.support_plane_half_width_m,
                                                      options.support_plane_min_sigma_deg * M_PI / 180);
        if (plane.ok) {
          estimates.push_back(plane.tilt);
          report.support_plane_views = plane.views;
          report.support_plane_points = plane.points;
          report.support_plane_tilt_sigma_deg =
              std::sqrt(Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(plane.tilt.cov).eigenvalues().maxCoeff()) *
              180 / M_PI;
          report.support_plane_offset_deg = plane.tilt.omega.norm() * 180 / M_PI;
        }
      }
      if (estimates.size() > 1) {
        Eigen::Matrix2d fused_info = Eigen::Matrix2d::Zero();
        Eigen::Vector2d info_omega = Eigen::Vector2d::Zero();
        for (const TiltEstimate& e : estimates) {
          const Eigen::Matrix2d inv = e.cov.inverse();
          fused_info += inv;
          info_omega += inv * e.omega;
        }
        const Eigen::Matrix2d fused_cov = fused_info.inverse();
        const Eigen::Vector2d omega = fused_cov * info_omega;
        if (omega.allFinite() && fused_cov.allFinite()) {
          // New room frame = the origin frame turned by omega about its centre.
          const Rigid3d turned = Rigid3d::FromRotationVector(Eigen::Vector3d(omega.x(), omega.y(), 0),
                                                             Eigen::Vector3d::Zero());
          const Rigid3d new_from_room = turned.Inverse() * origin_from_room;
          const Rigid3d room_from_new = new_from_room.Inverse();
          for (size_t m = 0; m < ba.room_from_marker.size(); ++m) {
            ba.room_from_marker[m] = static_cast<int>(m) == slot ? Rigid3d::Identity()
                                                                 : new_from_room * ba.room_from_marker[m];
          }
          for (Rigid3d& c : ba.camera_from_room) c = c * room_from_new;
          for (Eigen::Vector3d& l : ba.landmarks_in_room) l = new_from_room * l;
          report.room_frame_covariance.topLeftCorner<2, 2>() = fused_cov;
          report.room_frame_covariance.block<2, 4>(0, 2).setZero();
          report.room_frame_covariance.block<4, 2>(2, 0).setZero();
          const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> tilt(fused_cov);
          report.room_frame_tilt_sigma_deg = std::sqrt(std::max(0.0, tilt.eigenvalues().maxCoeff())) * 180 / M_PI;
          report.room_frame_couch_sigma_mm = report.RoomFramePositionSigmaMm(options.couch_point_in_room);
          report.room_frame_turn_deg = omega.norm() * 180 / M_PI;
        }
      }
    }
    if (!(report.room_frame_tilt_sigma_deg <= options.max_room_frame_tilt_sigma_deg) ||
        !(report.room_frame_couch_sigma_mm <= options.max_room_frame_couch_sigma_mm)) {
      report.warnings.push_back(StringPrintf(
          "the room frame is weakly determined: from the origin marker (id %d, %d views) its tilt is "
          "known to %.3f deg and the couch position to %.2f mm (1 sigma; tolerances %.3f deg, %.2f mm); "
          "record the room again with a few close, sharp views of the origin marker from different "
          "sides",
          origin_id, used, report.room_frame_tilt_sigma_deg, report.room_frame_couch_sigma_mm,
          options.max_room_frame_tilt_sigma_deg, options.max_room_frame_couch_sigma_mm));
    }
  }
  {
    // The map near the couch relative to the origin marker: what the
    // frames, markers and landmarks between them let move (the origin's own
    // views included), the median over the markers near the couch.
    std::vector<double> sigmas;
    for (const Eigen::Matrix3d& c : couch_covariance.relative_centre_covariance) {
      if (c.allFinite()) sigmas.push_back(std::sqrt(std::max(0.0, c.trace())) * 1000);
    }
    std::vector<double> tilts, yaws;
    for (const Eigen::Matrix3d& c : couch_covariance.relative_rotation_covariance) {
      if (!c.allFinite()) continue;
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> tilt(c.topLeftCorner<2, 2>());
      tilts.push_back(std::sqrt(std::max(0.0, tilt.eigenvalues().maxCoeff())) * 180 / M_PI);
      yaws.push_back(std::sqrt(std::max(0.0, c(2, 2))) * 180 / M_PI);
    }
    auto median = [](std::vector<double> v) {
      std::sort(v.begin(), v.end());
      const size_t n = v.size();
      return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
    };
    report.map_couch_markers = static_cast<int>(sigmas.size());
    if (!sigmas.empty()) report.map_couch_sigma_mm = median(sigmas);
    if (!tilts.empty()) {
      report.map_couch_tilt_sigma_deg = median(tilts);
      report.map_couch_yaw_sigma_deg = median(yaws);
    }
    report.map_couch_covariance_s = couch_covariance.covariance_seconds;
    // Said when it, not the origin's own views, is what is weak.
    if (report.map_couch_sigma_mm > options.max_room_frame_couch_sigma_mm &&
        !(report.map_couch_sigma_mm <= 1.5 * report.room_frame_couch_sigma_mm)) {
      report.warnings.push_back(StringPrintf(
          "the map near the couch is known to %.2f mm relative to the origin marker (1 sigma, through the "
          "frames and markers that link them; tolerance %.2f mm); record the room again with more room "
          "markers between the origin marker and the couch, each seen together with the next, or with the "
          "origin marker nearer the couch",
          report.map_couch_sigma_mm, options.max_room_frame_couch_sigma_mm));
    }
  }

  // ---------------------------------------------------------------- 5. the map
  progress("residuals and map", 0.95);
  const BaResiduals res = ComputeBaResiduals(ba);
  RoomMap& map = result.map;
  map.origin_marker_id = origin_id;
  map.marker_size_m = marker_size;
  std::vector<double> sum2(marker_ids.size(), 0);
  std::vector<int> n_obs(marker_ids.size(), 0);
  double all2 = 0;
  for (size_t i = 0; i < ba.marker_observations.size(); ++i) {
    const int m = ba.marker_observations[i].marker;
    sum2[m] += res.marker_rms_px[i] * res.marker_rms_px[i];
    all2 += res.marker_rms_px[i] * res.marker_rms_px[i];
    ++n_obs[m];
  }
  double mean_sum = 0;
  int mean_n = 0;
  for (size_t m = 0; m < marker_ids.size(); ++m) {
    if (n_obs[m] == 0 && marker_ids[m] == origin_id) {
      ARPOS_INPUT_ERROR(sequence.folder().string()
                        << ": every view of the origin marker (id " << origin_id
                        << ") disagrees with the rest of the room map (moved during the recording, "
                           "or a second print of it in the room?); record the room again with a "
                           "close, sharp view of the origin marker");
    }
    if (n_obs[m] == 0) continue;  // every observation rejected: not trustworthy
    if (n_obs[m] < options.min_marker_observations && marker_ids[m] != origin_id) {
      report.sparse_markers.push_back(marker_ids[m]);
      continue;
    }
    RoomMapMarkerEntry e;
    e.id = marker_ids[m];
    e.room_from_marker = ba.room_from_marker[m];
    e.corners_in_room = MarkerCornersInRoom(e.room_from_marker, marker_size);
    e.residual_px = std::sqrt(sum2[m] / n_obs[m]);
    e.num_observations = n_obs[m];
    map.max_residual_px = std::max(map.max_residual_px, e.residual_px);
    mean_sum += e.residual_px * n_obs[m];
    mean_n += n_obs[m];
    map.markers.push_back(e);
  }
  std::sort(map.markers.begin(), map.markers.end(),
            [](const RoomMapMarkerEntry& a, const RoomMapMarkerEntry& b) { return a.id < b.id; });
  map.mean_residual_px = mean_n ? mean_sum / mean_n : 0;
  map.max_residual_px = std::max(map.max_residual_px, map.mean_residual_px);
  report.marker_rms_px = ba.marker_observations.empty() ? 0 : std::sqrt(all2 / ba.marker_observations.size());

  // Landmark descriptors: the medoid of each landmark's observations.
  if (!ba.landmarks_in_room.empty()) {
    std::vector<std::vector<const std::uint8_t*>> descs(ba.landmarks_in_room.size());
    for (size_t k = 0; k < ba.keypoint_observations.size(); ++k) {
      const auto& [s, i] = keypoint_source[k];
      descs[ba.keypoint_observations[k].landmark].push_back(Descriptor(frames, s, i));
    }
    map.landmarks_in_room = ba.landmarks_in_room;
    map.landmark_descriptors.create(static_cast<int>(ba.landmarks_in_room.size()), kDescriptorBytes, CV_8UC1);
    for (size_t l = 0; l < descs.size(); ++l) {
      if (const std::uint8_t* d = MedoidDescriptor(descs[l])) {
        std::copy_n(d, kDescriptorBytes, map.landmark_descriptors.ptr<std::uint8_t>(static_cast<int>(l)));
      }
    }
    if (root_id != origin_id && !options.exclude_landmarks.empty()) {
      // The exclusion boxes in the room frame, now that the landmarks are in
      // it (the selection saw them in the root marker's frame). They took
      // part in the adjustment (the couch top stands still while the room is
      // recorded); the map leaves them out.
      std::vector<Eigen::Vector3d> outside;
      cv::Mat rows;
      for (size_t l = 0; l < map.landmarks_in_room.size(); ++l) {
        bool excluded = false;
        for (const auto& box : options.exclude_landmarks) excluded |= box.Contains(map.landmarks_in_room[l]);
        if (excluded) {
          ++report.landmarks_excluded;
          continue;
        }
        outside.push_back(map.landmarks_in_room[l]);
        rows.push_back(map.landmark_descriptors.row(static_cast<int>(l)));
      }
      map.landmarks_in_room = std::move(outside);
      map.landmark_descriptors = rows;
    }
  }
  if (options.use_keypoints && options.max_localization_landmarks > 0) {
    const auto t_more = Clock::now();
    AddLocalizationLandmarks(candidates, in_adjustment, frames, camera_slot, ba.camera_from_room, K,
                             result.map.depth_correction, joint_options, options, &map, &report);
    report.landmarks_s += SecondsSince(t_more);
  }
  if (!report.sparse_markers.empty()) {
    report.warnings.push_back(StringPrintf("%zu marker(s) seen in fewer than %d views; left out of the map",
                                           report.sparse_markers.size(), options.min_marker_observations));
  }
  report.landmarks = map.num_landmarks();
  report.keypoint_observations = static_cast<int>(ba.keypoint_observations.size());
  {
    double s2 = 0, z2 = 0;
    int nz = 0;
    for (size_t i = 0; i < res.keypoint_px.size(); ++i) {
      s2 += res.keypoint_px[i] * res.keypoint_px[i];
      if (std::isfinite(res.keypoint_depth_m[i])) {
        z2 += res.keypoint_depth_m[i] * res.keypoint_depth_m[i];
        ++nz;
      }
    }
    report.keypoint_rms_px = res.keypoint_px.empty() ? 0 : std::sqrt(s2 / res.keypoint_px.size());
    report.keypoint_depth_rms_m = nz ? std::sqrt(z2 / nz) : 0;
  }
  {
    std::vector<double> ratios;
    for (double r : res.marker_depth_ratio) {
      if (std::isfinite(r)) ratios.push_back(r);
    }
    if (!ratios.empty()) {
      std::sort(ratios.begin(), ratios.end());
      report.depth_scale_ratio = ratios[ratios.size() / 2];
      std::vector<double> dev;
      for (double r : ratios) dev.push_back(std::abs(r - report.depth_scale_ratio));
      std::sort(dev.begin(), dev.end());
      report.depth_scale_ratio_mad = dev[dev.size() / 2];
      if (std::abs(report.depth_scale_ratio - 1) > 0.01) {
        report.warnings.push_back(StringPrintf(
            "measured depth in the markers is %.2f %% off the map's: check the printed marker size "
            "(case.yaml markers.room.size_m) and the depth scale",
            100 * (report.depth_scale_ratio - 1)));
      }
    }
  }
  for (size_t c = 0; c < camera_frame.size(); ++c) {
    report.room_from_camera.emplace_back(frames[camera_frame[c]].index, ba.camera_from_room[c].Inverse());
  }
  report.frames_used = static_cast<int>(camera_frame.size());
  if (report.frames_used < report.frames_total) {
    report.warnings.push_back(StringPrintf("%d of %d frames could not be posed and were left out",
                                           report.frames_total - report.frames_used, report.frames_total));
  }
  // Markers read whose corners could not be measured, as many as those used
  // (measured on a simulated hand-held room walk with 20 ms of motion blur
  // and a linear camera: 45 views read, 17 used, the origin's 12 read and 4
  // used, 62 of 90 frames left unplaced, OpenCV's own detector reading 44):
  // say why and what to record.
  const int views_read = report.marker_views + report.unrefined_marker_views;
  if (report.unrefined_marker_views >= 5 && 2 * report.unrefined_marker_views >= views_read) {
    report.warnings.push_back(
        StringPrintf("%d of %d room-marker views read could not be used: their edges could not be "
                     "fitted (motion blur, defocus, or cells of a pixel or two); record the room "
                     "again moving the camera more slowly, with the markers seen closer",
                     report.unrefined_marker_views, views_read));
  }
  // A map that places only a small part of the room recording (the origin
  // marker never seen together with the rest: measured on simulated cases,
  // 5 of 60 frames, the origin alone) cannot localise a session: refused,
  // saying what to record, rather than stored.
  if (report.frames_with_markers > 0 && 3 * report.frames_used < report.frames_with_markers &&
      map.markers.size() < 3) {
    ARPOS_INPUT_ERROR(sequence.folder().string()
                      << ": only " << report.frames_used << " of " << report.frames_total
                      << " frames could be placed in the room frame (" << map.markers.size()
                      << " marker(s) mapped; markers seen but never linked to the mapped ones: "
                      << report.unconnected_markers.size()
                      << "): record the room again with views that show the origin marker together "
                         "with other room markers, e.g. walking from it to the couch");
  }
  if (options.build_surface) {
    const auto keep = [&options](const Eigen::Vector3d& x) {
      for (const auto& box : options.exclude_landmarks) {
        if (box.Contains(x)) return false;
      }
      return true;
    };
    // Depth read as of its colour instant: the depth camera's own pose.
    std::vector<std::pair<int, Rigid3d>> depth_cameras = report.room_from_camera;
    for (auto& [index, pose] : depth_cameras) {
      if (const auto moved = colour_from_depth.find(index); moved != colour_from_depth.end()) {
        pose = pose * moved->second;
      }
    }
    map.surface = BuildRoomSurface(sequence, K, map.depth_correction, depth_cameras, keep,
                                   options.couch_point_in_room, options.surface, &report.surface);
  }
  const std::string problem = map.Validate();
  ARPOS_CHECK(problem.empty(), "built an inconsistent room map: " << problem);
  report.total_s = SecondsSince(t_start);
  ARPOS_DEBUG("room map:\n" << report.ToText());
  return result;
}

}  // namespace arpos
