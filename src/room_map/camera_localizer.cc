#include "room_map/camera_localizer.h"

#include <time.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <future>
#include <iomanip>
#include <limits>
#include <sstream>

#include <Eigen/Eigenvalues>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

#include "features/edge_refinement.h"
#include "geometry/so3.h"
#include "room_map/bundle_adjustment.h"
#include "room_map/room_planes.h"
#include "sensor/depth_timing.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos {
namespace {

double ThreadCpuMs() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

// Adds the elapsed thread CPU time since `*mark` to `*bucket`, then resets the mark.
void Lap(double* mark, double* bucket) {
  const double now = ThreadCpuMs();
  *bucket += now - *mark;
  *mark = now;
}

// Largest-axis 1-sigma position (mm) and rotation (deg) of a pose covariance
// over [rotation; translation].
void PoseSigmas(const Eigen::Matrix<double, 6, 6>& cov, double* position_mm, double* rotation_deg) {
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> pos(cov.bottomRightCorner<3, 3>(), Eigen::EigenvaluesOnly);
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> rot(cov.topLeftCorner<3, 3>(), Eigen::EigenvaluesOnly);
  *position_mm = 1000 * std::sqrt(std::max(0.0, pos.eigenvalues().maxCoeff()));
  *rotation_deg = DegFromRad(std::sqrt(std::max(0.0, rot.eigenvalues().maxCoeff())));
}

// The covariance of a pose refinement's `information` (J^T W J), when it is
// invertible with every direction constrained; nullopt otherwise.
std::optional<Eigen::Matrix<double, 6, 6>> CovarianceOf(
    const Eigen::Matrix<double, 6, 6>& information) {
  const Eigen::LDLT<Eigen::Matrix<double, 6, 6>> ldlt(information);
  if (ldlt.info() != Eigen::Success || !(information.diagonal().array() > 0).all())
    return std::nullopt;
  return Eigen::Matrix<double, 6, 6>(ldlt.solve(Eigen::Matrix<double, 6, 6>::Identity()));
}

}  // namespace

const char* LocalizationStatusName(LocalizationStatus status) {
  switch (status) {
    case LocalizationStatus::kTracked: return "tracked";
    case LocalizationStatus::kRelocalized: return "relocalized";
    case LocalizationStatus::kLost: return "lost";
  }
  return "unknown";
}

std::string CameraLocalizerOptions::Validate() const {
  std::ostringstream out;
  std::string r;
  if (!detector.Check(&r)) out << "detector: " << r;
  else if (!marker_pose.Check(&r)) out << "marker_pose: " << r;
  else if (!keypoints.Check(&r)) out << "keypoints: " << r;
  else if (!refiner.Check(&r)) out << "refiner: " << r;
  else if (!use_markers && !use_keypoints) out << "at least one of markers and keypoints must be used";
  else if (!(window_margin_px >= 0) || !(window_margin_fraction >= 0)) out << "window margins must not be negative";
  else if (!(marker_corner_sigma_px > 0) || !(keypoint_sigma_px > 0)) out << "pixel sigmas must be positive";
  else if (!(marker_support_side_px > 0)) out << "marker_support_side_px must be positive";
  else if (!(depth_sigma_const_m >= 0 && depth_sigma_quad_per_m >= 0 && depth_sigma_const_m + depth_sigma_quad_per_m > 0))
    out << "depth sigmas must be non-negative and not both zero";
  else if (!(search_radius_px > 0) || !(refined_search_radius_px > 0) || !(wide_search_radius_px > 0))
    out << "search radii must be positive";
  else if (recent_pose_max_frames < 0) out << "recent_pose_max_frames must not be negative";
  else if (!(max_camera_speed_m_s > 0) || !(max_camera_jump_margin_m >= 0) || !(max_camera_turn_deg_s > 0) ||
           !(max_camera_turn_margin_deg >= 0))
    out << "camera speed limits must be positive";
  else if (max_hamming < 1 || max_hamming > 256 || relocalisation_max_hamming < 1 || relocalisation_max_hamming > 256)
    out << "Hamming thresholds must be in 1..256";
  else if (!(match_ratio > 0 && match_ratio <= 1) || !(relocalisation_ratio > 0 && relocalisation_ratio <= 1))
    out << "match ratios must be in (0, 1]";
  else if (!(weak_tracking_fraction >= 0 && weak_tracking_fraction <= 1))
    out << "weak_tracking_fraction must be in [0, 1]";
  else if (relocalisation_max_landmarks < 1) out << "relocalisation_max_landmarks must be at least 1";
  else if (room_plane_min_markers < 2 || !(room_plane_support_m > 0) || !(room_plane_gate_m > 0) ||
           room_plane_step_px < 1 || room_plane_min_samples < 1 || !(room_plane_max_effective >= 1) ||
           !(room_plane_min_spread_m >= 0))
    out << "room plane settings must be positive (at least 2 markers a plane)";
  else if (!(room_surface_gate_m > 0) || !(room_surface_sigma_m >= 0) ||
           !(room_surface_min_incidence >= 0 && room_surface_min_incidence < 1) ||
           room_surface_min_samples < 1 || !(room_surface_max_effective >= 1))
    out << "room surface settings must be positive (incidence a cosine below 1)";
  else if (relocalisation_min_inliers < 4) out << "relocalisation_min_inliers must be at least 4";
  else if (ransac_iterations < 1 || !(ransac_threshold_px > 0)) out << "RANSAC settings must be positive";
  else if (!(max_relocalisation_position_sigma_m > 0)) out << "max_relocalisation_position_sigma_m must be positive";
  else if (relocalisation_leave_out < 0)
    out << "relocalisation_leave_out must not be negative";
  else if (relocalisation_surface_points < 1 || !(relocalisation_surface_min_depth_m > 0) ||
           !(relocalisation_surface_gate_m > 0) || relocalisation_surface_min_beyond < 1 ||
           !(relocalisation_surface_max_beyond_fraction > 0 &&
             relocalisation_surface_max_beyond_fraction <= 1))
    out << "relocalisation surface check settings must be positive (the fraction at most 1)";
  else if (min_depth_held_samples < 1 || !(max_depth_held_position_sigma_m > 0) || max_depth_held_frames < 1) {
    out << "depth-held tracking needs at least one sample and frame and a positive sigma";
  }
  else if (!(max_followed_s > 0) || !(follow_min_depth_m > 0) || !(follow_max_depth_m > follow_min_depth_m) ||
           !(anchor_keep_s >= 0) || !(anchor_keep_ratio >= 1))
    out << "following the room needs a positive time, a depth range (min < max) and an anchor ratio of at least 1";
  else if (!(motion_prior_sigma_m > 0) || !(motion_prior_sigma_deg > 0)) out << "motion prior sigmas must be positive";
  else if (max_frames_lost_before_relocalising < 0) out << "max_frames_lost_before_relocalising must not be negative";
  else if (min_marker_corners < 4 || min_keypoints < 6 || min_keypoints_tracking < 6)
    out << "min_marker_corners must be >= 4 and min_keypoints(_tracking) >= 6";
  else if (!(max_marker_rms_px > 0) || !(max_keypoint_rms_px > 0)) out << "RMS bounds must be positive";
  else if (!(max_position_sigma_m > 0)) out << "max_position_sigma_m must be positive";
  return out.str();
}

bool CameraLocalizerOptions::Check(std::string* reason) const {
  const std::string r = Validate();
  if (reason) *reason = r;
  return r.empty();
}

CameraLocalizerOptions MakeCameraLocalizerOptions(const CaseConfig& config) {
  CameraLocalizerOptions options;
  options.detector.dictionary = config.dictionary;
  options.detector.id_ranges = {{config.room_markers.id_min, config.room_markers.id_max}};
  options.detector.intrinsics = config.camera;
  // Colour cameras mostly encode sRGB; callers set the recording's own
  // estimate (features/response_from_recording.h) when they have one.
  options.detector.edge.response = CameraResponse::Srgb();
  return options;
}

struct CameraLocalizer::Impl {
  const RoomMap& map;
  CameraIntrinsics K;
  const CameraLocalizerOptions& options;
  bool distortion = false;
  PixelUndistorter lens;  ///< ideal <-> image pixels (identity without distortion)
  std::unique_ptr<MarkerDetector> detector;
  KeypointExtractor extractor;
  KeypointGrid grid;

  // Per-frame scratch.
  cv::Mat gray;
  KeypointSet keypoints;
  std::vector<Eigen::Vector2d> keypoint_px;  // ideal pixels
  std::vector<MarkerObservation> markers;    // map markers in this frame (image pixels)
  std::vector<int> unmapped_ids;             // room markers read in this frame, not in the map
  std::vector<std::array<Eigen::Vector2d, 4>> marker_px;  // ideal pixels, parallel
  std::vector<std::vector<DepthSample>> marker_depth;      // parallel
  std::vector<MarkerObservation> scratch;
  PoseCorrespondences corr;
  std::vector<int> match_of_keypoint;        // landmark per keypoint, -1
  std::vector<int> match_distance;
  // Per keypoint of this frame (emptied by Run), the nearest two of the
  // room landmarks both of its relocalisations cover, from the first: the
  // second, with the body scan's landmarks, searches them again.
  std::vector<NearestTwo> shared_nearest;
  // The landmarks a body scan placed (RoomMap::scan_landmarks) are matched
  // only while this is set: for frames the room map alone does not place.
  bool use_scan = false;
  // What this frame's depth is worth less for being of another instant
  // than its colour (sensor/depth_timing.h).
  DelayedDepthSigma delayed;

  // Motion model.
  using Mat6 = Eigen::Matrix<double, 6, 6>;
  bool have_cov = false;
  Mat6 last_cov = Mat6::Zero();
  int frames_lost = 1 << 20;
  int last_markers_used = 0;    // markers the last frame's pose used (0 when lost)
  int last_keypoints_used = 0;  // keypoints the last frame's pose used (0 when lost)
  int depth_held_run = 0;       // frames in a row held by depth and the filter
  bool unconfirmed = false;     // relocalised by keypoints alone after a loss, no marker since
  bool have_last = false, have_prev = false;
  Rigid3d last_camera_from_room, prev_camera_from_room;
  double last_t = 0, prev_t = 0;
  // A caller's start for the next relocalisation (SuggestSearchStart).
  std::optional<Rigid3d> search_start;
  // What moves in the room (SetMovingRegions); unset: frames are not followed.
  std::optional<std::vector<ExclusionBox>> moving;
  // The last frame placed by the map (or followed from it, when it became
  // the anchor): its keypoints with depth in the room, for following the
  // room from it (options.follow_room_keypoints).
  struct Anchor {
    bool valid = false;
    std::vector<Eigen::Vector3d> points;
    cv::Mat descriptors;
    Rigid3d camera_from_room;
    Mat6 cov = Mat6::Zero();
    double t = 0;
    double since_map_t = 0;  // when the map placed the frame this anchor descends from
    double position_sigma_mm = 0;  // largest axis of cov's position block
  } anchor;
  // The landmarks matched by projection: the map's, or the anchor's while following.
  const std::vector<Eigen::Vector3d>* landmarks = nullptr;
  const cv::Mat* landmark_descriptors = nullptr;
  Mat6 followed_cov = Mat6::Zero();  // the last followed frame's covariance

  // The map's planes: markers lying in one plane (room frame).
  std::vector<MarkerPlane> planes;
  // Where the planes' and the surface's depth is read.
  DepthSampleGrid depth_grid;
  // The map's still surface (empty: not used).
  RoomSurfaceIndex surface;
  // Depth samples the last AddRoomDepths matched.
  int plane_samples_used = 0, surface_samples_used = 0;

  // The room's still surface as seen through at `camera_from_room`: of the
  // surface points in view with a depth reading at their pixel, how many
  // the reading agrees with and how many it lies clearly beyond (the camera
  // would be seeing through a surface the room recording found still).
  struct SeenThrough {
    int agree = 0;
    int beyond = 0;
  };
  SeenThrough SurfaceSeenThrough(const Rigid3d& camera_from_room) const {
    SeenThrough out;
    if (depth_image == nullptr || depth_image->empty()) return out;
    const RoomSurface& room = map.surface;
    const size_t step = std::max<size_t>(1, room.size() / options.relocalisation_surface_points);
    for (size_t i = 0; i < room.size(); i += step) {
      const Eigen::Vector3d x = camera_from_room * room.points[i].cast<double>();
      if (!(x.z() > options.relocalisation_surface_min_depth_m)) continue;
      const Eigen::Vector2d px = lens.Distort(K.Project(x));
      const int u = static_cast<int>(std::lround(px.x())),
                v = static_cast<int>(std::lround(px.y()));
      if (u < 0 || v < 0 || u >= depth_image->cols || v >= depth_image->rows) continue;
      const uint16_t raw = depth_image->at<uint16_t>(v, u);
      if (raw == 0) continue;
      const double z = raw / K.depth_scale;
      const double gate = std::max(options.relocalisation_surface_gate_m, 4 * DepthSigma(x.z()));
      if (z > x.z() + gate) {
        ++out.beyond;
      } else if (z >= x.z() - gate) {
        ++out.agree;
      }
    }
    return out;
  }

  Impl(const RoomMap& m, const CameraIntrinsics& k, const CameraLocalizerOptions& o)
      : map(m), K(k), options(o), extractor(o.keypoints) {
    landmarks = &map.landmarks_in_room;
    landmark_descriptors = &map.landmark_descriptors;
    distortion = K.HasDistortion();
    lens = PixelUndistorter(K);
    MarkerDetectorOptions d = options.detector;
    d.intrinsics = distortion ? std::optional<CameraIntrinsics>(K) : std::nullopt;
    detector = std::make_unique<MarkerDetector>(d);
    if (options.use_room_planes) FindRoomPlanes();
    if (options.use_room_surface && !map.surface.empty() &&
        (options.room_surface_with_corrected_depth || map.depth_correction.IsIdentity())) {
      surface = RoomSurfaceIndex(map.surface);
    }
    // About 80 depth samples across the image whatever its size (a
    // plane's, or a surface group's, count as 25 at most anyway).
    if (!planes.empty() || !surface.empty()) {
      depth_grid = MakeDepthSampleGrid(K, std::max(options.room_plane_step_px, K.width / 80));
    }
  }

  // The map's marker planes (room_planes.h).
  void FindRoomPlanes() {
    std::vector<Eigen::Vector3d> normals, centres;
    std::vector<std::array<Eigen::Vector3d, 4>> corners;
    for (const auto& m : map.markers) {
      normals.push_back(m.room_from_marker.rotation * Eigen::Vector3d::UnitZ());
      centres.push_back(m.room_from_marker.translation);
      corners.push_back(m.corners_in_room);
    }
    planes = FindMarkerPlanes(normals, centres, corners, options.room_plane_min_markers,
                              options.room_plane_min_spread_m);
  }

  // Depth pixels on the map's planes and its surface at `camera_from_room`
  // (the first refinement's pose), added to corr as plane-depth terms.
  void AddRoomDepths(const Rigid3d& camera_from_room, const Mat6* pose_cov) {
    if ((planes.empty() && surface.empty()) || depth_image == nullptr || depth_image->empty()) return;
    const Rigid3d room_from_camera = camera_from_room.Inverse();
    struct Sample {
      size_t ray;
      double z;
    };
    std::vector<std::vector<Sample>> on(planes.size());
    std::vector<std::vector<Eigen::Vector3d>> on_points(planes.size());  // parallel, camera frame
    // Surface samples by their normal's main room axis.
    struct SurfaceSample {
      size_t ray;
      double z;
      int point;
    };
    std::array<std::vector<SurfaceSample>, 3> on_surface;
    for (size_t i = 0; i < depth_grid.ray.size(); ++i) {
      const uint16_t raw = depth_image->at<uint16_t>(depth_grid.px[i]);
      if (raw == 0) continue;
      const double z = raw / K.depth_scale;  // as the marker depth samples read it
      const Eigen::Vector3d xc(depth_grid.ray[i].x() * z, depth_grid.ray[i].y() * z, z);
      const Eigen::Vector3d x = room_from_camera * xc;
      const double gate = std::max(options.room_plane_gate_m, 3 * DepthSigma(z));
      const int p = PlaneNear(planes, x, gate, options.room_plane_support_m);
      if (p >= 0) {
        on[p].push_back({i, z});
        on_points[p].push_back(xc);
        continue;
      }
      if (surface.empty()) continue;
      const int s = surface.Near(x);
      if (s < 0) continue;
      const Eigen::Vector3d& n = surface.normal(s);
      const double residual = n.dot(x - surface.point(s));
      if (std::abs(residual) > std::max(options.room_surface_gate_m, 3 * DepthSigma(z))) continue;
      const Eigen::Vector3d nc = camera_from_room.rotation * n;
      const double incidence = std::abs(nc.dot(xc.normalized()));
      if (incidence < options.room_surface_min_incidence) continue;
      if (pose_cov != nullptr) {
        // The residual must agree with the first refinement's pose within
        // its uncertainty: a residual r = n.(x - q) moves by
        // -(y x n_c).omega - n_c.dt for a perturbation (omega, dt) of
        // camera_from_room (pose_refiner.cc's update).
        Eigen::Matrix<double, 6, 1> J;
        J << -xc.cross(nc), -nc;
        const double along = DepthSigma(z) * incidence;
        const double var = along * along + J.dot(*pose_cov * J) +
                           options.room_surface_sigma_m * options.room_surface_sigma_m;
        if (residual * residual > 9 * var) continue;
      }
      Eigen::Index axis = 0;
      n.cwiseAbs().maxCoeff(&axis);
      on_surface[axis].push_back({i, z, s});
    }
    for (const std::vector<SurfaceSample>& group : on_surface) {
      if (static_cast<int>(group.size()) < options.room_surface_min_samples) continue;
      const double share = std::sqrt(std::max(1.0, group.size() / options.room_surface_max_effective));
      surface_samples_used += static_cast<int>(group.size());
      for (const SurfaceSample& g : group) {
        corr.AddPlaneDepth(surface.point(g.point), surface.normal(g.point), depth_grid.ray[g.ray], g.z,
                           DepthSigma(g.z) * share);
      }
    }
    for (size_t p = 0; p < planes.size(); ++p) {
      const std::vector<Sample>& cand = on[p];
      const std::vector<Eigen::Vector3d>& points = on_points[p];
      if (static_cast<int>(cand.size()) < options.room_plane_min_samples) continue;
      // The plane as this frame's depth shows it (room_planes.h).
      const Eigen::Vector3d n = camera_from_room.rotation * planes[p].normal;
      const double d = n.dot(camera_from_room * (planes[p].normal * planes[p].offset));
      std::vector<double> sigma_z(cand.size());
      for (size_t k = 0; k < cand.size(); ++k) sigma_z[k] = DepthSigma(cand[k].z);
      std::vector<const Sample*> kept;
      for (size_t k : PointsOnViewedPlane(points, sigma_z, n, d)) kept.push_back(&cand[k]);
      const double count = static_cast<double>(kept.size());
      if (count < options.room_plane_min_samples) continue;
      const double share = std::sqrt(std::max(1.0, count / options.room_plane_max_effective));
      const Eigen::Vector3d point = planes[p].normal * planes[p].offset;
      plane_samples_used += static_cast<int>(kept.size());
      for (const Sample* s : kept) {
        corr.AddPlaneDepth(point, planes[p].normal, depth_grid.ray[s->ray], s->z, DepthSigma(s->z) * share);
      }
    }
  }

  double DepthSigma(double z) const {
    const double sensor = options.depth_sigma_const_m + options.depth_sigma_quad_per_m * z * z;
    return delayed.any() ? std::hypot(sensor, delayed.At(z)) : sensor;
  }

  std::vector<Eigen::Vector2d> Ideal(const std::vector<Eigen::Vector2d>& px) const {
    if (!distortion || px.empty()) return px;
    std::vector<cv::Point2d> in, out;
    for (const auto& p : px) in.emplace_back(p.x(), p.y());
    cv::undistortPoints(in, out, K.CvK(), K.CvDistortion(), cv::noArray(), K.CvK());
    std::vector<Eigen::Vector2d> r;
    for (const auto& p : out) r.emplace_back(p.x, p.y);
    return r;
  }

  void AcceptMarker(const MarkerObservation& obs) {
    if (map.FindMarker(obs.id) == nullptr) {
      if (std::find(unmapped_ids.begin(), unmapped_ids.end(), obs.id) == unmapped_ids.end()) {
        unmapped_ids.push_back(obs.id);
      }
      return;
    }
    if (obs.status != MarkerStatus::kRefined && obs.status != MarkerStatus::kPartiallyOccluded) return;
    for (const auto& m : markers) {
      if (m.id == obs.id) return;
    }
    markers.push_back(obs);
    const std::vector<Eigen::Vector2d> ideal = Ideal({obs.corners_px.begin(), obs.corners_px.end()});
    marker_px.push_back({ideal[0], ideal[1], ideal[2], ideal[3]});
  }

  // Depth samples for the markers that have none yet (marker_depth parallel to markers).
  const cv::Mat* depth_image = nullptr;
  void SampleMarkerDepths() {
    while (marker_depth.size() < markers.size()) {
      const MarkerObservation& obs = markers[marker_depth.size()];
      const bool use = options.use_marker_depth && depth_image != nullptr && !depth_image->empty() &&
                       obs.status == MarkerStatus::kRefined;
      marker_depth.push_back(use ? SampleMarkerDepth(*depth_image, obs.corners_px, K, options.marker_depth_samples)
                                 : std::vector<DepthSample>());
    }
  }

  void DetectFull() {
    detector->Detect(gray, &scratch);
    for (const auto& o : scratch) AcceptMarker(o);
  }

  // Searches each map marker the predicted pose puts in view in a window.
  void DetectInWindows(const Rigid3d& camera_from_room) {
    for (const auto& m : map.markers) {
      std::array<Eigen::Vector2d, 4> px;
      bool ok = true;
      double min_u = 1e9, min_v = 1e9, max_u = -1e9, max_v = -1e9, perimeter = 0;
      for (int c = 0; c < 4 && ok; ++c) {
        const Eigen::Vector3d p = camera_from_room * m.corners_in_room[c];
        if (p.z() < 0.1) ok = false;
        px[c] = lens.Distort(K.Project(p));  // where the lens puts it
      }
      if (!ok) continue;
      const Eigen::Vector3d centre = camera_from_room * m.room_from_marker.translation;
      const Eigen::Vector3d normal = camera_from_room.rotation * (m.room_from_marker.rotation * Eigen::Vector3d::UnitZ());
      if (normal.dot(centre) > -0.15 * centre.norm()) continue;  // edge-on or from behind
      for (int c = 0; c < 4; ++c) {
        min_u = std::min(min_u, px[c].x());
        max_u = std::max(max_u, px[c].x());
        min_v = std::min(min_v, px[c].y());
        max_v = std::max(max_v, px[c].y());
        perimeter += (px[(c + 1) % 4] - px[c]).norm();
      }
      const double side = perimeter / 4;
      if (side < options.min_marker_side_px) continue;
      // A marker predicted across the image's border by up to a quarter of
      // its side may be just inside it: the prediction is a few pixels off
      // (measured on a random-conditions l515 sequence: a marker 5-10 px
      // from the bottom edge predicted past it in 20 frames, found there
      // only by the whole-image search that follows a miss, 20-45 ms at
      // 1280x720; with the slack 10 -> 4 frames searched whole). The window
      // is clipped to the image; ArUco reads only a marker wholly inside.
      const double slack = 0.25 * side;
      if (min_u < 2 - slack || min_v < 2 - slack || max_u > K.width - 3 + slack ||
          max_v > K.height - 3 + slack) {
        continue;
      }
      const double margin = std::max(options.window_margin_px, options.window_margin_fraction * side);
      const int x0 = std::max(0, static_cast<int>(std::floor(min_u - margin)));
      const int y0 = std::max(0, static_cast<int>(std::floor(min_v - margin)));
      const int x1 = std::min(gray.cols, static_cast<int>(std::ceil(max_u + margin)) + 1);
      const int y1 = std::min(gray.rows, static_cast<int>(std::ceil(max_v + margin)) + 1);
      if (x1 - x0 < 16 || y1 - y0 < 16) continue;
      bool found = false;
      for (const auto& already : markers) found |= already.id == m.id;
      if (found) continue;
      // Found in the window, refined in the whole image (its pixels are the
      // lens's: the edge fits undo the distortion there).
      detector->Detect(gray, &scratch, cv::Rect(x0, y0, x1 - x0, y1 - y0));
      for (const auto& o : scratch) AcceptMarker(o);
    }
  }

  void ExtractKeypoints(const RgbdFrame& frame) {
    extractor.Extract(gray, frame.depth, frame.depth_scale, &keypoints);
    std::vector<Eigen::Vector2d> px;
    px.reserve(keypoints.size());
    for (const auto& k : keypoints.keypoints) px.emplace_back(k.pt.x, k.pt.y);
    keypoint_px = Ideal(px);
    grid.Build(keypoints, 16);
  }

  // Matches landmarks the pose puts in view to keypoints near their
  // predicted pixels. Returns the number of matches; fills match_of_keypoint.
  int SearchByProjection(const Rigid3d& camera_from_room, double radius_px) {
    const int n_kp = static_cast<int>(keypoints.size());
    match_of_keypoint.assign(n_kp, -1);
    match_distance.assign(n_kp, 2 * 257);
    if (n_kp == 0 || landmarks->empty()) return 0;
    const Eigen::Matrix3d R = camera_from_room.RotationMatrix();
    const Eigen::Vector3d t = camera_from_room.translation;
    const int border = options.keypoints.border_px - 2;
    const int n_landmarks = static_cast<int>(landmarks->size());
    const int first = landmarks == &map.landmarks_in_room && !use_scan ? map.scan_landmarks : 0;
    for (int l = first; l < n_landmarks; ++l) {
      const Eigen::Vector3d p = R * (*landmarks)[l] + t;
      if (p.z() < 0.1) continue;
      double u = K.fx * p.x() / p.z() + K.cx, v = K.fy * p.y() / p.z() + K.cy;
      if (distortion) {
        // The keypoint grid holds image pixels (the lens's); the landmark's
        // ideal pixel is taken through it.
        const Eigen::Vector2d image = lens.Distort(Eigen::Vector2d(u, v));
        u = image.x();
        v = image.y();
      }
      if (u < border || v < border || u >= K.width - border || v >= K.height - border) continue;
      const std::uint8_t* d = landmark_descriptors->ptr<std::uint8_t>(l);
      const double max_dz = std::max(0.05, 5 * DepthSigma(p.z()));
      NearestTwo nearest;
      grid.ForEachInRadius(u, v, radius_px, [&](int i) {
        const float z = keypoints.depth_m[i];
        if (z > 0 && std::abs(z - p.z()) > max_dz) return;
        nearest.Offer(i, HammingDistance32(d, keypoints.descriptors.ptr<std::uint8_t>(i)));
      });
      const int best = nearest.best, d1 = nearest.d1, d2 = nearest.d2;
      if (best < 0 || d1 > options.max_hamming) continue;
      if (d2 <= 256 && d1 > options.match_ratio * d2) continue;
      // A landmark the body scan placed takes only a keypoint no room
      // landmark wants: it looks more like the frame (seen from where
      // tracking looks) but sits less surely (measured on a random case:
      // the scan's landmarks took the room's keypoints and the camera
      // drifted to 12 mm).
      const int rank =
          d1 + (landmarks == &map.landmarks_in_room && l < map.scan_landmarks ? 257 : 0);
      if (rank < match_distance[best]) {
        match_distance[best] = rank;
        match_of_keypoint[best] = l;
      }
    }
    int n = 0;
    for (int i = 0; i < n_kp; ++i) n += match_of_keypoint[i] >= 0;
    return n;
  }

  // Brute-force matching against the map's first landmarks (relocalisation),
  // in two stripes over the keypoints: a relocalising frame is mostly the
  // first of a run, where the body waits for this pose and the other core is
  // idle (1280x720: ~14 ms of a 52 ms first frame). The stripe run on
  // OpenCV's worker thread is not in this thread's matching_ms.
  int MatchGlobally() {
    const int n_kp = static_cast<int>(keypoints.size());
    match_of_keypoint.assign(n_kp, -1);
    match_distance.assign(n_kp, 257);
    const int scan = map.scan_landmarks;
    const int first = use_scan ? 0 : scan;
    const int last = std::min(map.num_landmarks(), first + options.relocalisation_max_landmarks);
    // [first, last) in three consecutive parts; the middle one, the room
    // landmarks [scan, shared_last), is the same for both searches of a
    // frame (without and with the scan's landmarks) and searched once: the
    // nearest two of consecutive parts merge into the nearest two of all.
    const int shared_last =
        std::max(scan, std::min(map.num_landmarks(), options.relocalisation_max_landmarks));
    const int s1 = std::clamp(scan, first, std::max(first, last));
    const int s2 = std::clamp(shared_last, s1, std::max(s1, last));
    const bool have_shared = !shared_nearest.empty();
    if (!have_shared) shared_nearest.assign(n_kp, NearestTwo());
    cv::parallel_for_(
        cv::Range(0, n_kp),
        [&](const cv::Range& range) {
          for (int i = range.start; i < range.end; ++i) {
            const std::uint8_t* d = keypoints.descriptors.ptr<std::uint8_t>(i);
            if (!have_shared)
              shared_nearest[i] = NearestTwoOfRows(d, map.landmark_descriptors, scan, shared_last);
            const NearestTwo nearest = MergeNearestTwo(
                MergeNearestTwo(NearestTwoOfRows(d, map.landmark_descriptors, first, s1),
                                shared_nearest[i]),
                NearestTwoOfRows(d, map.landmark_descriptors, s2, last));
            if (nearest.best < 0 || nearest.d1 > options.relocalisation_max_hamming ||
                nearest.d1 > options.relocalisation_ratio * nearest.d2) {
              continue;
            }
            match_of_keypoint[i] = nearest.best;
            match_distance[i] = nearest.d1;
          }
        },
        2);
    int n = 0;
    for (int i = 0; i < n_kp; ++i) n += match_of_keypoint[i] >= 0;
    return n;
  }

  void BuildCorrespondences() {
    corr.clear();
    corr.reserve(4 * markers.size() + keypoints.size());
    // Depth of another instant: one motion shared by all its readings.
    if (delayed.any()) corr.depth_motion_covariance = delayed.Covariance();
    double support = 0;
    for (const auto& obs : markers) {
      if (obs.status != MarkerStatus::kRefined) continue;
      const double r = obs.MeanSidePx() / options.marker_support_side_px;
      support += r * r;
    }
    const double keypoint_sigma = options.keypoint_sigma_px * std::sqrt(1 + support);
    for (size_t m = 0; m < markers.size(); ++m) {
      const RoomMapMarkerEntry* entry = map.FindMarker(markers[m].id);
      const double floor = markers[m].status == MarkerStatus::kRefined ? options.marker_corner_sigma_px
                                                                       : 4 * options.marker_corner_sigma_px;
      for (int c = 0; c < 4; ++c) {
        corr.Add(entry->corners_in_room[c], marker_px[m][c],
                 MarkerCornerSigmaPx(markers[m], c, floor, options.marker_reference_cell_px),
                 CorrespondenceGroup::kMarker, static_cast<int>(m) * 4 + c);
      }
    }
    for (size_t m = 0; m < marker_depth.size() && m < markers.size(); ++m) {
      if (marker_depth[m].empty()) continue;
      const RoomMapMarkerEntry* entry = map.FindMarker(markers[m].id);
      const Eigen::Vector3d normal = entry->room_from_marker.rotation * Eigen::Vector3d::UnitZ();
      const double n = static_cast<double>(marker_depth[m].size());
      const double share = std::sqrt(std::max(1.0, n / options.marker_depth_max_effective));
      for (const auto& sample : marker_depth[m]) {
        const double sensor =
            options.marker_depth_sigma_const_m +
            options.marker_depth_sigma_quad_per_m * sample.depth_m * sample.depth_m;
        const double sigma =
            delayed.any() ? std::hypot(sensor, delayed.At(sample.depth_m)) : sensor;
        corr.AddPlaneDepth(entry->room_from_marker.translation, normal,
                           Eigen::Vector2d((sample.pixel.x() - K.cx) / K.fx, (sample.pixel.y() - K.cy) / K.fy),
                           sample.depth_m, sigma * share);
      }
    }
    for (size_t i = 0; i < match_of_keypoint.size(); ++i) {
      const int l = match_of_keypoint[i];
      if (l < 0) continue;
      const float z = keypoints.depth_m[i];
      const bool depth = options.use_keypoint_depth && z > 0;
      if (landmarks == &map.landmarks_in_room && l < map.scan_landmarks &&
          map.scan_landmark_sigma_m > 0) {
        // A landmark the body scan placed: known to its own sigma, seen
        // sideways at its distance (the keypoint's depth, else 2 m).
        const double s = map.scan_landmark_sigma_m;
        const double at_px = K.fx * s / (z > 0 ? z : 2.0);
        corr.Add((*landmarks)[l], keypoint_px[i], std::hypot(keypoint_sigma, at_px),
                 CorrespondenceGroup::kKeypoint, static_cast<int>(i), depth ? z : 0.0,
                 depth ? std::hypot(DepthSigma(z), s) : 0.0);
        continue;
      }
      corr.Add((*landmarks)[l], keypoint_px[i], keypoint_sigma, CorrespondenceGroup::kKeypoint,
               static_cast<int>(i), depth ? z : 0.0, depth ? DepthSigma(z) : 0.0);
    }
  }

  // Hypotheses without a prediction: single-marker poses (IPPE + depth),
  // then PnP + RANSAC on global keypoint matches. Returns camera_from_room.
  std::optional<Rigid3d> Relocalise(const RgbdFrame& frame, double* pnp_ms, double* matching_ms, double* mark) {
    std::optional<Rigid3d> best;
    double best_rms = std::numeric_limits<double>::infinity();
    // Marker hypotheses, scored over all detected map-marker corners.
    for (size_t m = 0; m < markers.size(); ++m) {
      if (markers[m].status != MarkerStatus::kRefined) continue;
      const RoomMapMarkerEntry* entry = map.FindMarker(markers[m].id);
      const MarkerPose pose = EstimateMarkerPose(markers[m], map.marker_size_m, K, frame.depth, options.marker_pose);
      if (pose.status != MarkerPoseStatus::kOk) continue;
      const Rigid3d camera_from_room = pose.camera_from_marker * entry->room_from_marker.Inverse();
      double sum = 0;
      int n = 0;
      for (size_t k = 0; k < markers.size(); ++k) {
        const RoomMapMarkerEntry* e = map.FindMarker(markers[k].id);
        for (int c = 0; c < 4; ++c) {
          const Eigen::Vector3d p = camera_from_room * e->corners_in_room[c];
          if (p.z() <= 0) continue;
          sum += std::min(100.0, (K.Project(p) - marker_px[k][c]).squaredNorm());
          ++n;
        }
      }
      const double rms = n ? std::sqrt(sum / n) : std::numeric_limits<double>::infinity();
      if (rms < best_rms) {
        best_rms = rms;
        best = camera_from_room;
      }
    }
    Lap(mark, pnp_ms);
    if (best) return best;
    if (!options.use_keypoints || keypoints.size() < 6 || map.landmarks_in_room.empty()) return std::nullopt;
    const int n_matches = MatchGlobally();
    Lap(mark, matching_ms);
    if (n_matches < options.relocalisation_min_inliers) return std::nullopt;
    std::vector<cv::Point3d> object;
    std::vector<cv::Point2d> image;
    for (size_t i = 0; i < match_of_keypoint.size(); ++i) {
      const int l = match_of_keypoint[i];
      if (l < 0) continue;
      const Eigen::Vector3d& X = map.landmarks_in_room[l];
      object.emplace_back(X.x(), X.y(), X.z());
      image.emplace_back(keypoint_px[i].x(), keypoint_px[i].y());
    }
    cv::Mat rvec, tvec;
    std::vector<int> inliers;
    const bool ok = cv::solvePnPRansac(object, image, K.CvK(), cv::noArray(), rvec, tvec, false,
                                       options.ransac_iterations, static_cast<float>(options.ransac_threshold_px),
                                       0.999, inliers, cv::SOLVEPNP_AP3P);
    Lap(mark, pnp_ms);
    if (!ok || static_cast<int>(inliers.size()) < options.relocalisation_min_inliers) return std::nullopt;
    const Eigen::Vector3d rv(rvec.at<double>(0), rvec.at<double>(1), rvec.at<double>(2));
    const Eigen::Vector3d tv(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2));
    return Rigid3d::FromRotationVector(rv, tv);
  }

  std::optional<Rigid3d> Predict(double t) const {
    if (!have_last || frames_lost > options.max_frames_lost_before_relocalising) return std::nullopt;
    if (!have_prev || !(last_t > prev_t)) return last_camera_from_room;
    // Constant velocity: delta per second, applied over t - last_t.
    const Rigid3d delta = last_camera_from_room * prev_camera_from_room.Inverse();
    const double s = std::clamp((t - last_t) / (last_t - prev_t), 0.0, 3.0);
    const Eigen::Vector3d w = RotationVectorFromQuaternion(delta.rotation) * s;
    const Rigid3d scaled(QuaternionFromRotationVector(w), delta.translation * s);
    return scaled * last_camera_from_room;
  }

  // Information of the predicted pose for the motion filter (nullopt: none yet).
  std::optional<Mat6> PredictedInformation(double t) const {
    if (!options.motion_filter || !have_cov || !have_last) return std::nullopt;
    const double dt = std::max(1e-3, std::abs(t - last_t));
    const double ratio = have_prev && last_t > prev_t ? dt / (last_t - prev_t) : 0.0;
    // The velocity comes from the last two poses: their noise propagates.
    Mat6 P = last_cov * (1 + 2 * ratio * ratio);
    const double q_rot = 0.5 * options.motion_angular_accel_rad_s2 * dt * dt;
    const double q_t = 0.5 * options.motion_accel_m_s2 * dt * dt;
    P.topLeftCorner<3, 3>().diagonal().array() += q_rot * q_rot;
    P.bottomRightCorner<3, 3>().diagonal().array() += q_t * q_t;
    const Eigen::LDLT<Mat6> ldlt(P);
    if (ldlt.info() != Eigen::Success) return std::nullopt;
    return ldlt.solve(Mat6::Identity());
  }

  // Refines from `initial` with matching by projection at `radius`, then at
  // the refined pose again with the small radius. Returns the last refinement.
  PoseRefinementResult Track(const Rigid3d& initial, double radius, const std::optional<PosePrior>& prior,
                             double* matching_ms, double* refinement_ms, double* mark) {
    plane_samples_used = surface_samples_used = 0;
    if (options.use_keypoints) SearchByProjection(initial, radius);
    Lap(mark, matching_ms);
    BuildCorrespondences();
    PoseRefinementResult r = RefineCameraPose(corr, K, initial, options.refiner, prior);
    Lap(mark, refinement_ms);
    const bool keypoints = options.use_keypoints && !landmarks->empty();
    if (keypoints || !planes.empty() || !surface.empty()) {
      if (keypoints) SearchByProjection(r.camera_from_room, options.refined_search_radius_px);
      Lap(mark, matching_ms);
      BuildCorrespondences();
      if (r.converged) {
        const std::optional<Mat6> cov = CovarianceOf(r.information);
        AddRoomDepths(r.camera_from_room, cov && cov->allFinite() ? &*cov : nullptr);
      }
      r = RefineCameraPose(corr, K, r.camera_from_room, options.refiner, prior);
      Lap(mark, refinement_ms);
    }
    return r;
  }

  // The position sigma (mm) of refinement r once its `k` keypoint inliers
  // that hold it most are left out, one at a time, each the one whose
  // leaving out widens it most (infinity when the rest leave a direction
  // free). From r's information less their shares at r's pose.
  double SigmaWithoutStrongestKeypoints(const PoseRefinementResult& r, int k) const {
    Mat6 information = r.information;
    std::vector<Mat6> shares;
    for (size_t i = 0; i < corr.size(); ++i) {
      if (corr.group[i] != CorrespondenceGroup::kKeypoint || i >= r.inlier.size() || !r.inlier[i])
        continue;
      shares.push_back(PointInformation(corr, i, K, r.camera_from_room, options.refiner));
    }
    double sigma_mm = -1, rotation_deg = 0;
    for (int round = 0; round < k && !shares.empty(); ++round) {
      size_t strongest = 0;
      sigma_mm = -1;
      for (size_t j = 0; j < shares.size(); ++j) {
        const std::optional<Mat6> cov = CovarianceOf(information - shares[j]);
        if (!cov) return std::numeric_limits<double>::infinity();
        double s_mm = 0;
        PoseSigmas(*cov, &s_mm, &rotation_deg);
        if (s_mm > sigma_mm) {
          sigma_mm = s_mm;
          strongest = j;
        }
      }
      information -= shares[strongest];
      shares.erase(shares.begin() + static_cast<std::ptrdiff_t>(strongest));
    }
    if (sigma_mm < 0) {
      const std::optional<Mat6> cov = CovarianceOf(information);
      if (!cov) return std::numeric_limits<double>::infinity();
      PoseSigmas(*cov, &sigma_mm, &rotation_deg);
    }
    return sigma_mm;
  }

  bool Accept(const PoseRefinementResult& r, bool tracking, LocalizationResult* out) const {
    // Markers used: all four corners inliers.
    int full = 0;
    for (size_t m = 0; m < markers.size(); ++m) {
      int in = 0;
      for (size_t i = 0; i < corr.size(); ++i) {
        if (corr.group[i] == CorrespondenceGroup::kMarker && corr.tag[i] / 4 == static_cast<int>(m)) in += r.inlier[i];
      }
      full += in == 4;
    }
    out->markers_used = full;
    out->keypoints_used = r.keypoint_inliers;
    out->scan_keypoints_used = 0;
    if (landmarks == &map.landmarks_in_room && map.scan_landmarks > 0) {
      for (size_t i = 0; i < corr.size(); ++i) {
        if (corr.group[i] != CorrespondenceGroup::kKeypoint || !r.inlier[i]) continue;
        const int l = match_of_keypoint[corr.tag[i]];
        out->scan_keypoints_used += l >= 0 && l < map.scan_landmarks ? 1 : 0;
      }
    }
    out->plane_depth_samples = plane_samples_used;
    out->surface_depth_samples = surface_samples_used;
    out->rms_px = r.rms_px;
    out->marker_rms_px = r.marker_rms_px;
    out->keypoint_rms_px = r.keypoint_rms_px;
    const std::optional<Mat6> cov = CovarianceOf(r.information);
    if (!cov) return false;
    PoseSigmas(*cov, &out->position_sigma_mm, &out->rotation_sigma_deg);
    out->covariance = *cov;
    out->has_covariance = true;
    if (!(out->position_sigma_mm <= 1000 * options.max_position_sigma_m)) return false;
    // The markers place the frame only when their corners alone hold the
    // pose within the limit (options.markers_alone_must_hold).
    double marker_sigma_mm = std::numeric_limits<double>::infinity();
    if (const std::optional<Mat6> marker_cov =
            full >= 1 ? CovarianceOf(r.marker_information) : std::nullopt) {
      double rotation_deg = 0;
      PoseSigmas(*marker_cov, &marker_sigma_mm, &rotation_deg);
    }
    out->marker_position_sigma_mm = marker_sigma_mm;
    const bool markers_hold =
        !options.markers_alone_must_hold || marker_sigma_mm <= 1000 * options.max_position_sigma_m;
    const bool by_markers = r.marker_inliers >= options.min_marker_corners && full >= 1 &&
                            r.marker_rms_px <= options.max_marker_rms_px && markers_hold;
    const int min_keypoints = tracking ? options.min_keypoints_tracking : options.min_keypoints;
    const bool by_keypoints =
        r.keypoint_inliers >= min_keypoints && r.keypoint_rms_px <= options.max_keypoint_rms_px;
    if (full >= 1 && !markers_hold && !by_keypoints) {
      std::ostringstream why;
      why << std::fixed << std::setprecision(0) << full
          << " room marker(s) seen whole, too small or far to place the camera "
          << "alone (their corners leave it known to " << marker_sigma_mm << " mm, limit "
          << 1000 * options.max_position_sigma_m << " mm), and " << r.keypoint_inliers
          << " keypoints agree (" << min_keypoints << " needed)";
      out->message = why.str();
      return false;
    }
    // Markers that disagree badly with an otherwise keypoint-based pose would
    // mean a wrong pose or a moved marker: require consistency when both exist.
    if (by_keypoints && r.marker_inliers > 0 && r.marker_rms_px > 2 * options.max_marker_rms_px) return false;
    // Keypoints alone, without a motion prior: where the frame's depth sees
    // through the room's still surface, the pose is wrong, however well the
    // keypoints agree (keypoints along one line on a far wall leave the
    // camera free to turn about that line).
    if (!tracking && !by_markers && by_keypoints && options.verify_relocalisation_with_surface) {
      const SeenThrough seen = SurfaceSeenThrough(r.camera_from_room);
      if (seen.beyond >= options.relocalisation_surface_min_beyond &&
          seen.beyond >
              options.relocalisation_surface_max_beyond_fraction * (seen.agree + seen.beyond)) {
        std::ostringstream why;
        why << "keypoints alone give a pose at which the frame's depth sees through the room's "
               "still surface ("
            << seen.beyond << " of " << seen.agree + seen.beyond
            << " surface points in view lie in front of what the depth reads); refused";
        out->message = why.str();
        return false;
      }
    }
    // Keypoints alone, without a motion prior: only a well-conditioned pose,
    // and one that does not hang on a few of them.
    if (!tracking && !by_markers && by_keypoints) {
      const double limit_mm = 1000 * options.max_relocalisation_position_sigma_m;
      if (!(out->position_sigma_mm <= limit_mm)) {
        std::ostringstream why;
        why << "keypoints alone, without a motion prior, give a poorly conditioned pose (sigma "
            << out->position_sigma_mm << " mm, limit " << limit_mm << " mm); refused";
        out->message = why.str();
        return false;
      }
      const double without_mm = SigmaWithoutStrongestKeypoints(r, options.relocalisation_leave_out);
      const double without_limit_mm = 1000 * options.max_position_sigma_m;
      if (!(without_mm <= without_limit_mm)) {
        std::ostringstream why;
        why << std::fixed << std::setprecision(1)
            << "keypoints alone, without a motion prior, give a pose held by "
            << options.relocalisation_leave_out << " of its " << r.keypoint_inliers
            << " keypoints (sigma " << out->position_sigma_mm << " mm, " << without_mm
            << " mm without them, limit " << without_limit_mm << " mm); refused";
        out->message = why.str();
        return false;
      }
    }
    return by_markers || by_keypoints;
  }

  // A tracked frame that Accept refused, held by the room's depth and the
  // filter's prediction (options.depth_held_tracking); `out` as Accept left it.
  // Else false, and `why_not` says why when depth was the reason.
  bool AcceptHeldByDepth(const PoseRefinementResult& r, LocalizationResult* out, std::string* why_not) const {
    if (!r.converged) return false;
    if (depth_held_run >= options.max_depth_held_frames) {
      *why_not = "held by the room's depth for " + std::to_string(depth_held_run) + " frames, the most in a row";
      return false;
    }
    const int samples = plane_samples_used + surface_samples_used;
    if (samples < options.min_depth_held_samples) {
      *why_not = "the room's depth matched at " + std::to_string(samples) + " samples, too few to hold the camera (" +
                 std::to_string(options.min_depth_held_samples) + ")";
      return false;
    }
    if (!(out->position_sigma_mm > 0 && out->position_sigma_mm <= 1000 * options.max_depth_held_position_sigma_m)) {
      std::ostringstream why;
      why << "the room's depth with the camera's motion leaves it known to " << std::fixed << std::setprecision(1)
          << out->position_sigma_mm << " mm (limit " << 1000 * options.max_depth_held_position_sigma_m << " mm)";
      *why_not = why.str();
      return false;
    }
    // What the image does match must agree with the pose.
    if (r.marker_inliers > 0 && r.marker_rms_px > 2 * options.max_marker_rms_px) return false;
    if (r.keypoint_inliers > 0 && r.keypoint_rms_px > options.max_keypoint_rms_px) return false;
    out->held_by_depth = true;
    return true;
  }

  // This frame's keypoints with depth, outside the moving regions, put in
  // the room by `camera_from_room` (covariance `cov` of its left
  // perturbation [rotation; translation]): the anchor the next frames the
  // map does not place are followed from.
  void SetAnchor(const Rigid3d& camera_from_room, const Mat6& cov, double t, double since_map_t) {
    anchor.valid = false;
    if (!moving || !options.follow_room_keypoints || keypoints.size() == 0) return;
    const Rigid3d room_from_camera = camera_from_room.Inverse();
    anchor.points.clear();
    anchor.descriptors.create(0, kDescriptorBytes, CV_8UC1);
    std::vector<int> rows;
    std::vector<std::pair<Rigid3d, Eigen::Vector3d>> boxes;  // box_from_room, half extents
    for (const ExclusionBox& box : *moving) boxes.emplace_back(box.room_from_box.Inverse(), box.half_extent_m);
    for (size_t i = 0; i < keypoints.size(); ++i) {
      const double z = keypoints.depth_m[i];
      if (!(z >= options.follow_min_depth_m && z <= options.follow_max_depth_m)) continue;
      const Eigen::Vector3d xc((keypoint_px[i].x() - K.cx) / K.fx * z, (keypoint_px[i].y() - K.cy) / K.fy * z, z);
      const Eigen::Vector3d x = room_from_camera * xc;
      bool inside = false;
      for (const auto& [box_from_room, half] : boxes) inside |= ((box_from_room * x).cwiseAbs() - half).maxCoeff() <= 0;
      if (inside) continue;
      anchor.points.push_back(x);
      rows.push_back(static_cast<int>(i));
    }
    anchor.descriptors.create(static_cast<int>(rows.size()), kDescriptorBytes, CV_8UC1);
    for (size_t r = 0; r < rows.size(); ++r) keypoints.descriptors.row(rows[r]).copyTo(anchor.descriptors.row(static_cast<int>(r)));
    anchor.camera_from_room = camera_from_room;
    anchor.cov = cov;
    double rotation_deg = 0;
    PoseSigmas(cov, &anchor.position_sigma_mm, &rotation_deg);
    anchor.t = t;
    anchor.since_map_t = since_map_t;
    anchor.valid = static_cast<int>(anchor.points.size()) >= options.min_keypoints_tracking;
  }

  // A frame the map does not place, followed from the anchor: matched by
  // projection from `predicted` against the anchor's points, refined with
  // the room's depth. True with *r and *out filled when accepted; the
  // covariance (the frame's own against the anchor plus the anchor's own,
  // carried to this camera) in followed_cov.
  bool Follow(const Rigid3d& predicted, const std::optional<PosePrior>& prior, double t, PoseRefinementResult* r,
              LocalizationResult* out, LocalizationTimings* tm, double* mark) {
    if (!anchor.valid || !options.use_keypoints || !(t - anchor.since_map_t <= options.max_followed_s)) return false;
    {
      // The anchor's points stand in for the map's landmarks in this Track only.
      struct Restore {
        Impl* m;
        ~Restore() {
          m->landmarks = &m->map.landmarks_in_room;
          m->landmark_descriptors = &m->map.landmark_descriptors;
        }
      } restore{this};
      landmarks = &anchor.points;
      landmark_descriptors = &anchor.descriptors;
      *r = Track(predicted, options.search_radius_px, prior, &tm->matching_ms, &tm->refinement_ms, mark);
    }
    if (!r->converged || r->keypoint_inliers < options.min_keypoints_tracking ||
        !(r->keypoint_rms_px <= options.max_keypoint_rms_px)) {
      return false;
    }
    // The frame's own information against the anchor's points, without the
    // motion prior (which descends from the anchor too).
    const PoseRefinementResult alone = RefineCameraPose(corr, K, r->camera_from_room, options.refiner);
    Lap(mark, &tm->refinement_ms);
    const std::optional<Mat6> alone_cov =
        alone.converged ? CovarianceOf(alone.information) : std::nullopt;
    if (!alone_cov) return false;
    // An error exp(d) of the anchor's camera_from_room moves its points, and
    // so this camera, by exp(Ad_M d), M = camera_from_room * anchor^-1.
    const Rigid3d M = r->camera_from_room * anchor.camera_from_room.Inverse();
    const Eigen::Matrix3d R = M.RotationMatrix();
    Mat6 Ad = Mat6::Zero();
    Ad.topLeftCorner<3, 3>() = R;
    Ad.bottomLeftCorner<3, 3>() = Skew(M.translation) * R;
    Ad.bottomRightCorner<3, 3>() = R;
    const Mat6 cov = *alone_cov + Ad * anchor.cov * Ad.transpose();
    if (!cov.allFinite()) return false;
    out->markers_used = 0;
    out->keypoints_used = r->keypoint_inliers;
    out->plane_depth_samples = plane_samples_used;
    out->surface_depth_samples = surface_samples_used;
    out->rms_px = r->rms_px;
    out->marker_rms_px = r->marker_rms_px;
    out->keypoint_rms_px = r->keypoint_rms_px;
    PoseSigmas(cov, &out->position_sigma_mm, &out->rotation_sigma_deg);
    out->covariance = cov;
    out->has_covariance = true;
    if (!(out->position_sigma_mm <= 1000 * options.max_position_sigma_m)) return false;
    out->followed = true;
    out->followed_s = t - anchor.since_map_t;
    followed_cov = cov;
    return true;
  }
};

double LocalizationResult::SeparateSigmasMm(const Eigen::Vector3d& point_in_camera) const {
  return std::hypot(position_sigma_mm,
                    1000 * RadFromDeg(rotation_sigma_deg) * point_in_camera.norm());
}

double LocalizationResult::PointSigmaMm(const Eigen::Vector3d& point_in_camera) const {
  if (!has_covariance) return SeparateSigmasMm(point_in_camera);
  Eigen::Matrix<double, 3, 6> j;
  j.leftCols<3>() = -Skew(point_in_camera);
  j.rightCols<3>().setIdentity();
  const double var = (j * covariance * j.transpose()).trace();
  return 1000 * std::sqrt(std::max(0.0, var));
}

CameraLocalizer::CameraLocalizer(RoomMap map, const CameraIntrinsics& intrinsics,
                                 const CameraLocalizerOptions& options)
    : map_(std::move(map)), options_(options) {
  std::string reason;
  ARPOS_CHECK(options_.Check(&reason), "invalid localiser options: " << reason);
  const std::string bad = intrinsics.Validate();
  ARPOS_CHECK(bad.empty(), "invalid intrinsics: " << bad);
  const std::string problem = map_.Validate();
  if (!problem.empty()) ARPOS_INPUT_ERROR("the room map cannot be used: " << problem);
  impl_ = std::make_unique<Impl>(map_, intrinsics, options_);
}

CameraLocalizer::~CameraLocalizer() = default;

void CameraLocalizer::Reset() {
  impl_->have_last = impl_->have_prev = impl_->have_cov = false;
  impl_->frames_lost = 1 << 20;
  impl_->last_markers_used = 0;
  impl_->last_keypoints_used = 0;
  impl_->depth_held_run = 0;
  impl_->unconfirmed = false;
  impl_->search_start.reset();
  impl_->anchor.valid = false;
}

void CameraLocalizer::SetMovingRegions(std::vector<ExclusionBox> regions) { impl_->moving = std::move(regions); }

void CameraLocalizer::SuggestSearchStart(const Rigid3d& room_from_camera) {
  impl_->search_start = room_from_camera.Inverse();
}

LocalizationResult CameraLocalizer::Localize(const RgbdFrame& frame) { return Run(frame, nullptr); }

LocalizationResult CameraLocalizer::Localize(const RgbdFrame& frame,
                                             const std::vector<MarkerObservation>& detections) {
  return Run(frame, &detections);
}

LocalizationResult CameraLocalizer::Run(const RgbdFrame& frame,
                                        const std::vector<MarkerObservation>* detections) {
  Impl& m = *impl_;
  m.shared_nearest.clear();
  const bool given = detections != nullptr;
  LocalizationResult out;
  LocalizationTimings& tm = out.timings;
  const double start = ThreadCpuMs();
  double mark = start;
  ARPOS_CHECK(frame.color.type() == CV_8UC3 || frame.color.type() == CV_8UC1,
              "Localize needs a CV_8UC3 (BGR) or CV_8UC1 image, got type " << frame.color.type());
  ARPOS_CHECK(frame.color.cols == m.K.width && frame.color.rows == m.K.height,
              "frame is " << frame.color.cols << "x" << frame.color.rows << ", the camera "
                          << m.K.width << "x" << m.K.height);
  ARPOS_CHECK(frame.depth.empty() || (frame.depth.type() == CV_16UC1 && frame.depth.size() == frame.color.size()),
              "depth must be CV_16UC1 of the colour image's size");
  if (frame.color.type() == CV_8UC3) {
    cv::cvtColor(frame.color, m.gray, cv::COLOR_BGR2GRAY);
  } else {
    m.gray = frame.color;
  }
  const std::optional<Rigid3d> predicted = m.Predict(frame.timestamp_s);
  {
    // The camera's speed and turn rate from its last two poses, else the
    // assumed hand-held motion.
    // Only for depth of another instant: synced frames skip it.
    m.delayed = DelayedDepthSigma();
    if (!frame.depth.empty() && frame.depth_delay_s != 0) {
      std::optional<Rigid3d> step;
      double step_s = 0;
      if (m.have_last && m.have_prev && m.last_t > m.prev_t && frame.timestamp_s - m.last_t < 0.5) {
        step = m.last_camera_from_room * m.prev_camera_from_room.Inverse();
        step_s = m.last_t - m.prev_t;
      }
      m.delayed = DelayedDepthSigmaOf(frame.depth_delay_s, step ? &*step : nullptr, step_s);
    }
  }
  const std::optional<Rigid3d> search_start = m.search_start;  // this frame's only
  m.search_start.reset();
  // Keypoints. Without a prediction the whole image is searched for markers
  // too: both at once on a second thread (the first frame of a run took
  // 16 ms of marker search then 9 ms of keypoints at 1280x720, one after
  // the other). They share only the grey image, which neither writes.
  std::future<void> keypoints_job;
  double keypoints_cpu_ms = 0;
  if (!options_.use_keypoints) {
    m.keypoints.clear();
    m.keypoint_px.clear();
  } else if (!predicted && options_.use_markers && !given) {
    keypoints_job = std::async(std::launch::async, [&m, &frame, &keypoints_cpu_ms] {
      const double t0 = ThreadCpuMs();
      m.ExtractKeypoints(frame);
      keypoints_cpu_ms = ThreadCpuMs() - t0;
    });
  } else {
    m.ExtractKeypoints(frame);
  }
  Lap(&mark, &tm.keypoints_ms);
  m.markers.clear();
  m.unmapped_ids.clear();
  m.marker_px.clear();
  m.marker_depth.clear();
  bool full_detection_done = false;
  if (options_.use_markers) {
    if (given) {
      for (const auto& o : *detections) m.AcceptMarker(o);
      full_detection_done = true;
    } else if (predicted && options_.marker_windows) {
      m.DetectInWindows(*predicted);
      if (m.markers.empty() && m.last_markers_used > 0) {
        // The last frame had a marker and no window holds one now (it may
        // sit at the border, or the prediction is off): the whole image,
        // before keypoints alone decide the pose (measured: two frames
        // 27-28 mm off on 34-43 keypoints beside a marker the windows missed).
        m.DetectFull();
        full_detection_done = true;
      }
    } else {
      m.DetectFull();
      full_detection_done = true;
    }
  }
  m.depth_image = &frame.depth;
  m.SampleMarkerDepths();
  Lap(&mark, &tm.detection_ms);
  if (keypoints_job.valid()) {
    keypoints_job.get();  // rethrows what the extraction threw
    tm.keypoints_ms += keypoints_cpu_ms;
  }

  PoseRefinementResult refined;
  bool ok = false;
  // A tracked pose held by depth and the filter, used only when neither the
  // image nor a relocalisation gives one (options.depth_held_tracking).
  std::optional<PoseRefinementResult> held;
  LocalizationResult held_out;
  std::string not_held;  // why the room's depth did not hold it, if that was tried
  std::optional<PosePrior> prior;
  if (predicted) {
    const std::optional<Impl::Mat6> filter_information = m.PredictedInformation(frame.timestamp_s);
    if (options_.use_motion_prior) {
      const double scale = std::max(1.0, std::abs(frame.timestamp_s - m.last_t) * 30.0);
      prior = PosePrior{*predicted, scale * RadFromDeg(options_.motion_prior_sigma_deg),
                        scale * options_.motion_prior_sigma_m, filter_information};
    }
    refined = m.Track(*predicted, options_.search_radius_px, prior, &tm.matching_ms, &tm.refinement_ms, &mark);
    bool with_prior = prior.has_value();  // the refinement holds the prediction's information
    if (prior && filter_information) {
      // What the frame alone says; if the filtered pose disagrees with it
      // beyond chance, trust the frame and restart the filter. A frame whose
      // data alone leave a direction free (depth of one or two faces, a few
      // keypoints) cannot say: its pose there is the prediction's.
      const PoseRefinementResult alone = RefineCameraPose(m.corr, m.K, refined.camera_from_room, options_.refiner);
      const Eigen::LDLT<Impl::Mat6> data(alone.information);
      const Eigen::LDLT<Impl::Mat6> pred(*filter_information);
      const Eigen::SelfAdjointEigenSolver<Impl::Mat6> spectrum(alone.information, Eigen::EigenvaluesOnly);
      const bool determined = alone.converged && spectrum.eigenvalues().minCoeff() > 1e-9 * spectrum.eigenvalues().maxCoeff() &&
                              spectrum.eigenvalues().minCoeff() > 0;
      if (determined && data.info() == Eigen::Success && pred.info() == Eigen::Success) {
        const Impl::Mat6 cov = data.solve(Impl::Mat6::Identity()) + pred.solve(Impl::Mat6::Identity());
        const Rigid3d diff = alone.camera_from_room * refined.camera_from_room.Inverse();
        Eigen::Matrix<double, 6, 1> e;
        e << RotationVectorFromQuaternion(diff.rotation), diff.translation;
        const double chi2 = e.dot(cov.ldlt().solve(e));
        if (!(chi2 <= options_.filter_reset_chi2)) {
          refined = alone;
          m.have_cov = false;
          with_prior = false;
        }
      }
      Lap(&mark, &tm.refinement_ms);
    }
    ok = m.Accept(refined, true, &out);
    if (ok) out.status = LocalizationStatus::kTracked;
    if (!ok && with_prior && options_.depth_held_tracking) {
      LocalizationResult candidate = out;
      if (m.AcceptHeldByDepth(refined, &candidate, &not_held)) {
        held = refined;
        held_out = candidate;
      }
    }
    if (ok && out.markers_used == 0 && options_.use_keypoints && m.have_last &&
        out.keypoints_used < options_.weak_tracking_fraction * m.last_keypoints_used) {
      // Keypoints alone, on fewer inliers than the last frame had: the
      // prediction may be off and the matches near it agree on a wrong pose
      // (measured on an l515 sequence: 26-155 inliers where the last frame
      // had ~200, 6-41 mm off). The wide search from the last pose as well;
      // the pose more keypoints agree on is kept. That sequence: camera at
      // the isocentre 2.01 -> 1.11 mm mean, max 48 -> 3.8 mm (0.5 of the
      // last frame's inliers as the trigger: 1.48 mm, 0.8: 1.30 mm).
      LocalizationResult wide_out;
      const PoseRefinementResult wide = m.Track(m.last_camera_from_room, options_.wide_search_radius_px, std::nullopt,
                                                &tm.matching_ms, &tm.refinement_ms, &mark);
      if (m.Accept(wide, false, &wide_out) && wide_out.keypoints_used > out.keypoints_used) {
        refined = wide;
        wide_out.status = LocalizationStatus::kRelocalized;
        wide_out.timings = out.timings;
        out = wide_out;
      }
    }
  }
  if (!ok) {
    // Relocalise: the keypoints searched widely around where the camera is
    // about to be or last was, then the whole image for markers (and those
    // searches again if it found more), then the whole map for keypoints.
    auto wide_searches = [&] {
      if (options_.use_keypoints && search_start) {
        refined = m.Track(*search_start, options_.wide_search_radius_px, std::nullopt,
                          &tm.matching_ms, &tm.refinement_ms, &mark);
        ok = m.Accept(refined, false, &out);
        if (ok) out.status = LocalizationStatus::kRelocalized;
      }
      if (!ok && options_.use_keypoints && m.have_last &&
          m.frames_lost <= options_.recent_pose_max_frames) {
        refined = m.Track(m.last_camera_from_room, options_.wide_search_radius_px, std::nullopt,
                          &tm.matching_ms, &tm.refinement_ms, &mark);
        ok = m.Accept(refined, false, &out);
        if (ok) out.status = LocalizationStatus::kRelocalized;
      }
    };
    // The markers the windows found take part; the whole image is searched
    // only when these fail. Measured on random-conditions sequences, where
    // most frames the prediction did not place were placed by the wide
    // search after a whole-image search of 15-45 ms: frames searched whole
    // and then placed 16 -> 6, 14 -> 3 and 40 -> 8 on three of them, the
    // localiser's CPU time a frame 23.4 -> 19.8, 18.5 -> 17.7, 14.1 -> 11.4
    // ms; MTE the same to within 0.03 mm on 23 sequences.
    const size_t markers_before = m.markers.size();
    wide_searches();
    if (!ok && options_.use_markers && !full_detection_done) {
      m.DetectFull();
      m.SampleMarkerDepths();
      Lap(&mark, &tm.detection_ms);
      if (m.markers.size() > markers_before) wide_searches();
    }
    const std::optional<Rigid3d> hypothesis =
        ok ? std::nullopt : m.Relocalise(frame, &tm.pnp_ms, &tm.matching_ms, &mark);
    if (hypothesis) {
      refined = m.Track(*hypothesis, options_.search_radius_px, std::nullopt, &tm.matching_ms, &tm.refinement_ms, &mark);
      ok = m.Accept(refined, false, &out);
      if (ok) out.status = LocalizationStatus::kRelocalized;
    }
    if (!ok && predicted && options_.follow_room_keypoints) {
      LocalizationResult followed_out;
      PoseRefinementResult followed;
      if (m.Follow(*predicted, prior, frame.timestamp_s, &followed, &followed_out, &tm, &mark)) {
        refined = followed;
        followed_out.timings = out.timings;
        out = followed_out;
        out.status = LocalizationStatus::kTracked;
        ok = true;
      }
    }
    if (!ok && held) {
      refined = *held;
      held_out.timings = out.timings;
      out = held_out;
      out.status = LocalizationStatus::kTracked;
      ok = true;
    }
  }
  if (!ok && options_.use_keypoints && options_.use_scan_landmarks && map_.scan_landmarks > 0) {
    // The room map alone does not place this frame: the same tries with the
    // landmarks the body scan placed around the couch (where tracking looks
    // and the room recording may not have gone). Not before: they sit less
    // surely than the room's (measured on a random case where both were
    // matched: the camera pulled 12 mm off where the room's alone held it
    // to 2 mm).
    m.use_scan = true;
    if (predicted) {
      refined = m.Track(*predicted, options_.search_radius_px, prior, &tm.matching_ms,
                        &tm.refinement_ms, &mark);
      ok = m.Accept(refined, true, &out);
      if (ok) out.status = LocalizationStatus::kTracked;
    }
    if (!ok && search_start) {
      refined = m.Track(*search_start, options_.wide_search_radius_px, std::nullopt,
                        &tm.matching_ms, &tm.refinement_ms, &mark);
      ok = m.Accept(refined, false, &out);
      if (ok) out.status = LocalizationStatus::kRelocalized;
    }
    if (!ok && m.have_last && m.frames_lost <= options_.recent_pose_max_frames) {
      refined = m.Track(m.last_camera_from_room, options_.wide_search_radius_px, std::nullopt,
                        &tm.matching_ms, &tm.refinement_ms, &mark);
      ok = m.Accept(refined, false, &out);
      if (ok) out.status = LocalizationStatus::kRelocalized;
    }
    if (!ok) {
      if (const std::optional<Rigid3d> hypothesis =
              m.Relocalise(frame, &tm.pnp_ms, &tm.matching_ms, &mark)) {
        refined = m.Track(*hypothesis, options_.search_radius_px, std::nullopt, &tm.matching_ms,
                          &tm.refinement_ms, &mark);
        ok = m.Accept(refined, false, &out);
        if (ok) out.status = LocalizationStatus::kRelocalized;
      }
    }
    m.use_scan = false;
  }
  if (ok && out.status == LocalizationStatus::kRelocalized && out.markers_used == 0 && m.have_last &&
      m.frames_lost <= options_.recent_pose_max_frames) {
    // Keypoints alone: plausible only within reach of the last pose.
    const double dt = std::abs(frame.timestamp_s - m.last_t);
    const Rigid3d last_room_from_camera = m.last_camera_from_room.Inverse();
    const Rigid3d now_room_from_camera = refined.camera_from_room.Inverse();
    const double jump_m = (now_room_from_camera.translation - last_room_from_camera.translation).norm();
    const double turn_deg =
        DegFromRad(RotationVectorFromQuaternion(now_room_from_camera.rotation * last_room_from_camera.rotation.inverse()).norm());
    const double reach_m = options_.max_camera_speed_m_s * dt + options_.max_camera_jump_margin_m;
    const double reach_deg = options_.max_camera_turn_deg_s * dt + options_.max_camera_turn_margin_deg;
    if (jump_m > reach_m || turn_deg > reach_deg) {
      ok = false;
      std::ostringstream why;
      why << "relocalised by keypoints alone " << jump_m << " m / " << turn_deg << " deg from the pose "
          << dt << " s before: beyond a hand-held camera's reach; refused";
      out.message = why.str();
    }
  }
  if (ok) {
    out.ok = true;
    out.message.clear();
    out.room_from_camera = refined.camera_from_room.Inverse();
    out.depth_camera_motion = refined.depth_camera_motion;
    m.prev_camera_from_room = m.last_camera_from_room;
    m.prev_t = m.last_t;
    m.have_prev = m.have_last && m.frames_lost == 0;
    m.last_camera_from_room = refined.camera_from_room;
    m.last_t = frame.timestamp_s;
    m.have_last = true;
    if (out.followed) {
      m.have_cov = true;
      m.last_cov = m.followed_cov;
      // Far from the anchor (few of its points still matched): this frame
      // becomes the anchor, its uncertainty carried on.
      if (out.keypoints_used < 2 * options_.min_keypoints_tracking) {
        m.SetAnchor(refined.camera_from_room, m.followed_cov, frame.timestamp_s, m.anchor.since_map_t);
      }
    } else {
      const Eigen::LDLT<Impl::Mat6> ldlt(refined.information);
      const bool invertible = ldlt.info() == Eigen::Success;
      const Impl::Mat6 cov = invertible ? Impl::Mat6(ldlt.solve(Impl::Mat6::Identity())) : Impl::Mat6::Zero();
      m.have_cov = invertible && out.status == LocalizationStatus::kTracked;
      if (m.have_cov) m.last_cov = cov;
      if (invertible && !out.held_by_depth) {
        // A frame the map places weakly (a few of its landmarks at the edge
        // of what the room recording covered) does not replace a recent
        // anchor it places much worse than: what follows would inherit it
        // (measured on a random-conditions case: an anchor at 10 mm taking
        // over from one at 2.8 mm 0.1 s older).
        const bool keep = m.anchor.valid && frame.timestamp_s - m.anchor.t <= options_.anchor_keep_s &&
                          out.position_sigma_mm > options_.anchor_keep_ratio * m.anchor.position_sigma_mm;
        if (cov.allFinite() && !keep) m.SetAnchor(refined.camera_from_room, cov, frame.timestamp_s, frame.timestamp_s);
      }
    }
    if (out.markers_used > 0) {
      m.unconfirmed = false;
    } else if (out.status == LocalizationStatus::kRelocalized && m.frames_lost > 0) {
      m.unconfirmed = true;
    }
    out.unconfirmed = m.unconfirmed;
    m.frames_lost = 0;
    m.depth_held_run = out.held_by_depth ? m.depth_held_run + 1 : 0;
  } else {
    out.ok = false;
    out.status = LocalizationStatus::kLost;
    out.markers_used = 0;
    out.keypoints_used = 0;
    ++m.frames_lost;
    m.depth_held_run = 0;
    m.have_prev = false;
    m.have_cov = false;
    if (out.message.empty()) {
      std::ostringstream why;
      why << m.markers.size() << " map marker(s) and " << m.keypoints.size()
          << " keypoints found; too few agree on a pose";
      if (!m.unmapped_ids.empty()) {
        why << "; room marker(s)";
        for (int id : m.unmapped_ids) why << " " << id;
        why << " read but not in the room map";
      }
      if (!not_held.empty()) why << "; " << not_held;
      out.message = why.str();
    }
  }
  m.last_markers_used = out.markers_used;
  m.last_keypoints_used = out.keypoints_used;
  out.markers = m.markers;
  out.unmapped_marker_ids = m.unmapped_ids;
  tm.total_ms = ThreadCpuMs() - start + keypoints_cpu_ms;
  return out;
}

}  // namespace arpos
