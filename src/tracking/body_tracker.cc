#include "tracking/body_tracker.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <deque>
#include <limits>
#include <unordered_set>

#include <Eigen/Dense>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "features/edge_refinement.h"
#include "features/marker_cells.h"
#include "features/marker_template.h"
#include "geometry/cube_grid.h"
#include "geometry/so3.h"
#include "registration/mesh_cloud.h"
#include "sensor/case_config.h"
#include "sensor/depth_timing.h"
#include "tracking/sticker_terms.h"
#include "util/check.h"
#include "util/logging.h"
#include "util/string_util.h"

namespace arpos {

std::string BodyTrackerOptions::Validate() const {
  if (!(marker_size_m > 0)) return "marker_size_m must be positive";
  if (!(model_spacing_m > 0.0005 && model_spacing_m < 0.05)) return "model_spacing_m must be in (0.5 mm, 5 cm)";
  if (zbuffer_cell_px < 1) return "zbuffer_cell_px must be at least 1";
  if (!(zbuffer_tolerance_m > 0)) return "zbuffer_tolerance_m must be positive";
  if (max_depth_points < 10) return "max_depth_points must be at least 10";
  if (!(corner_sigma_px > 0)) return "corner_sigma_px must be positive";
  if (!(depth_sigma_const_m >= 0) || !(depth_sigma_quad_per_m >= 0) ||
      !(depth_sigma_const_m + depth_sigma_quad_per_m > 0)) {
    return "depth sigmas must be non-negative and not both zero";
  }
  if (depth_max_effective < 1) return "depth_max_effective must be at least 1";
  if (!(depth_gate_initial_m > 0) || !(depth_gate_final_m > 0)) return "depth gates must be positive";
  if (!(huber_sigmas > 0)) return "huber_sigmas must be positive";
  if (max_iterations < 1) return "max_iterations must be at least 1";
  if (!(convergence_m > 0) || !(convergence_rad > 0)) return "convergence tolerances must be positive";
  if (!(max_sticker_rms_px > 0)) return "max_sticker_rms_px must be positive";
  for (const auto& [id, motion] : sticker_motion_m) {
    if (!(motion >= 0 && motion < 0.05)) return "sticker_motion_m of sticker " + std::to_string(id) + " must be in [0, 5 cm)";
  }
  for (const auto& [id, direction] : sticker_motion_direction) {
    if (!direction.allFinite() || !(std::abs(direction.norm() - 1) < 1e-6)) {
      return "sticker_motion_direction of sticker " + std::to_string(id) + " must be a unit vector";
    }
  }
  if (!(shared_breathing_sigmas >= 0 && std::isfinite(shared_breathing_sigmas))) {
    return "shared_breathing_sigmas must be finite and not negative";
  }
  if (!(moving_surface_patch_m > 0)) return "moving_surface_patch_m must be positive";
  if (!(sticker_window_margin_px >= 0)) return "sticker_window_margin_px must not be negative";
  if (max_stickers_searched < 1) return "max_stickers_searched must be at least 1";
  if (!(detection_side_px >= 8)) return "detection_side_px must be at least 8";
  if (!(min_sticker_side_px >= 3)) return "min_sticker_side_px must be at least 3";
  if (!(start_depth_weight_px >= 0)) return "start_depth_weight_px must not be negative";
  if (!(hint_search_step_mm > 0) || hint_search_steps < 0 || hint_search_steps > 10) {
    return "hint_search_step_mm must be positive and hint_search_steps in 0..10";
  }
  if (hint_search_stickers < 0 || hint_search_stickers == 1) {
    return "hint_search_stickers must be 0 (all) or at least 2 (a shift is kept for two refined "
           "stickers)";
  }
  if (!(max_refinement_shift_px > 0) || !(max_refinement_shift_fraction >= 0)) {
    return "max_refinement_shift_px must be positive and max_refinement_shift_fraction not negative";
  }
  if (!(template_max_side_px >= 0) ||
      !(template_max_shift_fraction > 0 && template_max_shift_fraction <= 1) ||
      template_below_stickers < 0 || template_max_misses < 1) {
    return "template_max_side_px must not be negative, template_max_shift_fraction must be in "
           "(0, 1], template_below_stickers not negative and template_max_misses at least 1";
  }
  if (max_frames_without_stickers < 0) return "max_frames_without_stickers must not be negative";
  if (!(min_depth_inlier_fraction >= 0 && min_depth_inlier_fraction <= 1)) {
    return "min_depth_inlier_fraction must be in [0, 1]";
  }
  if (min_depth_inliers < 1) return "min_depth_inliers must be at least 1";
  if (!(min_depth_inlier_fraction_with_stickers >= 0 && min_depth_inlier_fraction_with_stickers <= 1)) {
    return "min_depth_inlier_fraction_with_stickers must be in [0, 1]";
  }
  if (!(max_position_sigma_m > 0)) return "max_position_sigma_m must be positive";
  std::string reason;
  if (!detector.Check(&reason)) return "detector: " + reason;
  if (!marker_pose.Check(&reason)) return "marker_pose: " + reason;
  return "";
}

const char* BodyPoseSourceName(BodyPoseSource source) {
  switch (source) {
    case BodyPoseSource::kStickers: return "stickers";
    case BodyPoseSource::kCarried: return "carried";
    case BodyPoseSource::kLost: return "lost";
  }
  return "lost";
}

namespace {

using Clock = std::chrono::steady_clock;
double MsSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}
using Vector6d = Eigen::Matrix<double, 6, 1>;
// The last pose predicts the next frame for at most this long (s).
constexpr double kPredictionMaxAgeS = 0.5;
using Matrix6d = Eigen::Matrix<double, 6, 6>;


// A sticker seen in this frame: corners in normalised ideal coordinates.
struct SeenSticker {
  int id = -1;
  std::array<Eigen::Vector3d, 4> corners_in_model;
  std::array<Eigen::Vector2d, 4> normalised;
  std::array<double, 4> sigma_px{};
  MarkerPose single_view;
  Rigid3d marker_from_model;
  double motion_m = 0;  ///< breathing along motion_in_model (1 sigma)
  Eigen::Vector3d normal_in_model = Eigen::Vector3d::UnitZ();
  Eigen::Vector3d motion_in_model = Eigen::Vector3d::UnitZ();  ///< which way it breathes (unit)
};

// A sticker observation from an edge-line refinement started at `initial`.
MarkerObservation Refined(int id, const std::array<Eigen::Vector2d, 4>& initial, const CornerRefinementResult& r) {
  MarkerObservation out;
  out.id = id;
  out.detected_corners_px = initial;
  ApplyRefinement(r, &out);
  return out;
}

}  // namespace

struct BodyTracker::Impl {
  CameraIntrinsics K;
  bool distorted = false;
  cv::Mat rays;  // CV_32FC2: normalised ideal coordinates of every pixel (distorted cameras)
  std::vector<Eigen::Vector3d> model_points, model_normals;
  std::vector<Eigen::Vector3d> coarse_points, coarse_normals;  // ~2 cm apart, for start poses
  std::map<int, Rigid3d> model_from_marker;
  std::array<Eigen::Vector3d, 4> corners_in_marker;
  std::unique_ptr<MarkerDetector> detector;  // whole image, edge-line corners
  std::unique_ptr<MarkerDetector> coarse;    // small upsampled windows, contour corners
  EdgeRefinementOptions edge;
  PixelUndistorter undistorter;
  EdgeRefinementWorkspace workspace;
  // Stickers located by their whole pattern (RefineAtPose).
  std::optional<MarkerCells> sticker_cells;
  MarkerTemplateOptions template_options;
  MarkerTemplateCache template_cache;
  std::vector<MarkerObservation> scratch;
  cv::Mat gray, window_up;

  struct Past {
    double t;
    Rigid3d pose;
  };
  std::deque<Past> past;
  int frames_without_stickers = 0;
  // How much of the surface in view usually agrees with an accepted pose
  // from two or more stickers (running mean; -1: none yet): a depth camera
  // with a bias the plan did not remove agrees less everywhere, and that
  // is not a contradiction.
  double usual_depth_fraction = -1;

  // Per-frame buffers.
  struct RefineCandidate {  // RefineAtPose: a sticker in view, large enough
    int id;
    std::array<Eigen::Vector2d, 4> px;
    double side;
    double depth;  // of its centre, m
  };
  std::vector<RefineCandidate> refine_candidates;
  std::vector<size_t> pattern_candidates;
  std::vector<std::pair<int, float>> candidates;
  std::vector<int> cells;
  std::vector<int> visible;
  std::vector<float> zbuffer;

  Eigen::Vector2d PixelOf(const Eigen::Vector3d& p) const {
    return undistorter.Distort(Eigen::Vector2d(K.fx * p.x() / p.z() + K.cx, K.fy * p.y() / p.z() + K.cy));
  }
  Eigen::Vector2d RayOf(int u, int v) const {
    if (!distorted) return {(u - K.cx) / K.fx, (v - K.cy) / K.fy};
    const cv::Vec2f r = rays.at<cv::Vec2f>(v, u);
    return {r[0], r[1]};
  }

  // Each mapped sticker the pose puts in view, searched in a window around
  // its predicted corners.
  // The largest side (px) of the stickers the last search predicted in view
  // (0: none predicted).
  double predicted_side_px = 0;

  void SearchAround(const Rigid3d& camera_from_model, const BodyTrackerOptions& o,
                    std::vector<MarkerObservation>* found) {
    found->clear();
    predicted_side_px = 0;
    // The largest predicted stickers first: ArUco reads those best, and the
    // others are refined where the fitted pose puts them (RefineAtPose).
    std::vector<std::pair<double, int>> by_size;
    for (const auto& [id, model_from_sticker] : model_from_marker) {
      const Rigid3d camera_from_sticker = camera_from_model * model_from_sticker;
      const Eigen::Vector3d centre = camera_from_sticker.translation;
      const Eigen::Vector3d normal = camera_from_sticker.rotation * Eigen::Vector3d::UnitZ();
      if (centre.z() < 0.1) continue;
      by_size.emplace_back(-normal.dot(centre) / centre.squaredNorm(), id);  // ~ apparent area
    }
    std::sort(by_size.rbegin(), by_size.rend());
    if (static_cast<int>(by_size.size()) > o.max_stickers_searched) by_size.resize(o.max_stickers_searched);
    for (const auto& [size, id] : by_size) {
      const Rigid3d& model_from_sticker = model_from_marker.at(id);
      const Rigid3d camera_from_sticker = camera_from_model * model_from_sticker;
      const Eigen::Vector3d centre = camera_from_sticker.translation;
      const Eigen::Vector3d normal = camera_from_sticker.rotation * Eigen::Vector3d::UnitZ();
      if (centre.z() < 0.1 || normal.dot(centre) > -0.2 * centre.norm()) continue;
      std::array<Eigen::Vector2d, 4> px;
      double perimeter = 0;
      Eigen::AlignedBox2d box;
      for (int c = 0; c < 4; ++c) {
        px[c] = PixelOf(camera_from_sticker * corners_in_marker[c]);
        box.extend(px[c]);
      }
      for (int c = 0; c < 4; ++c) perimeter += (px[(c + 1) % 4] - px[c]).norm();
      const double side = perimeter / 4;
      predicted_side_px = std::max(predicted_side_px, side);
      if (side < o.min_sticker_side_px) continue;
      if (box.min().x() < 2 || box.min().y() < 2 || box.max().x() > K.width - 3 || box.max().y() > K.height - 3) continue;
      const double margin = std::max(o.sticker_window_margin_px, 0.75 * side);
      const int x0 = std::max(0, static_cast<int>(std::floor(box.min().x() - margin)));
      const int y0 = std::max(0, static_cast<int>(std::floor(box.min().y() - margin)));
      const int x1 = std::min(K.width, static_cast<int>(std::ceil(box.max().x() + margin)) + 1);
      const int y1 = std::min(K.height, static_cast<int>(std::ceil(box.max().y() + margin)) + 1);
      if (x1 - x0 < 8 || y1 - y0 < 8) continue;
      const int k = std::clamp(static_cast<int>(std::ceil(o.detection_side_px / side)), 1, 4);
      const cv::Mat crop = gray(cv::Rect(x0, y0, x1 - x0, y1 - y0));
      if (k > 1) {
        cv::resize(crop, window_up, cv::Size(), k, k, cv::INTER_LINEAR);
      } else {
        crop.copyTo(window_up);
      }
      coarse->Detect(window_up, &scratch);
      for (const MarkerObservation& obs : scratch) {
        if (obs.id != id) continue;
        std::array<Eigen::Vector2d, 4> initial;
        for (int c = 0; c < 4; ++c) {
          // Pixel centres: upsampled (u + 0.5) / k - 0.5 in the window.
          initial[c] = (obs.detected_corners_px[c] + Eigen::Vector2d(0.5, 0.5)) / k - Eigen::Vector2d(0.5, 0.5) +
                       Eigen::Vector2d(x0, y0);
        }
        found->push_back(
            Refined(id, initial, RefineMarkerCorners(gray, initial, edge, undistorter, &workspace)));
        break;
      }
    }
  }

  // Mapped stickers not in `have` that the pose puts in view, refined
  // (edge lines) at their projected corners; kept when the fit converged
  // close to the projection. `patterns`: one whose edge lines do not fit
  // (cells of a pixel or two) is located by its whole pattern, searched
  // over a third of its side plus `reach_m` at its distance.
  // `largest` > 0: only that many stickers, the largest in view. `need` > 0:
  // stops once fewer than that many could be refined (what is found then
  // is not used). Stickers smaller than `min_side_px` are left out.
  void RefineAtPose(const Rigid3d& camera_from_model, const std::vector<int>& have,
                    const BodyTrackerOptions& o, std::vector<MarkerObservation>* found,
                    int largest = 0, int need = 0, bool patterns = true, double reach_m = 0,
                    double min_side_px = 0) {
    found->clear();
    std::vector<RefineCandidate>& candidates = refine_candidates;
    candidates.clear();
    for (const auto& [id, model_from_sticker] : model_from_marker) {
      if (std::find(have.begin(), have.end(), id) != have.end()) continue;
      const Rigid3d camera_from_sticker = camera_from_model * model_from_sticker;
      const Eigen::Vector3d centre = camera_from_sticker.translation;
      const Eigen::Vector3d normal = camera_from_sticker.rotation * Eigen::Vector3d::UnitZ();
      if (centre.z() < 0.1 || normal.dot(centre) > -0.3 * centre.norm()) continue;
      std::array<Eigen::Vector2d, 4> px;
      double perimeter = 0;
      bool inside = true;
      for (int c = 0; c < 4; ++c) {
        px[c] = PixelOf(camera_from_sticker * corners_in_marker[c]);
        inside &= px[c].x() > 3 && px[c].y() > 3 && px[c].x() < K.width - 4 && px[c].y() < K.height - 4;
      }
      if (!inside) continue;
      for (int c = 0; c < 4; ++c) perimeter += (px[(c + 1) % 4] - px[c]).norm();
      const double side = perimeter / 4;
      if (side < std::max(o.min_sticker_side_px, min_side_px)) continue;
      candidates.push_back({id, px, side, centre.z()});
    }
    if (largest > 0 && static_cast<int>(candidates.size()) > largest) {
      std::stable_sort(
          candidates.begin(), candidates.end(),
          [](const RefineCandidate& a, const RefineCandidate& b) { return a.side > b.side; });
      candidates.resize(largest);
    }
    // Refined, each corner within `reach` px of its projection.
    auto refined_within = [](const CornerRefinementResult& r, const RefineCandidate& c,
                             double reach) {
      if (r.status != MarkerStatus::kRefined) return false;
      for (int k = 0; k < 4; ++k) {
        if ((r.corners_px[k] - c.px[k]).norm() > reach) return false;
      }
      return true;
    };
    pattern_candidates.clear();
    for (size_t i = 0; i < candidates.size(); ++i) {
      if (static_cast<int>(found->size() + candidates.size() - i) < need) break;
      const RefineCandidate& c = candidates[i];
      const CornerRefinementResult r =
          RefineMarkerCorners(gray, c.px, edge, undistorter, &workspace);
      if (!refined_within(
              r, c,
              std::max(o.max_refinement_shift_px, o.max_refinement_shift_fraction * c.side))) {
        if (patterns && c.side <= o.template_max_side_px) pattern_candidates.push_back(i);
        continue;
      }
      found->push_back(Refined(c.id, c.px, r));
    }
    // Those whose edge lines did not fit (or fitted beyond their reach), by
    // their whole pattern (the largest first), while the frame holds fewer
    // than `template_below_stickers`.
    std::stable_sort(pattern_candidates.begin(), pattern_candidates.end(),
                     [&](size_t a, size_t b) { return candidates[a].side > candidates[b].side; });
    int misses = 0;
    for (const size_t i : pattern_candidates) {
      if (static_cast<int>(have.size() + found->size()) >= o.template_below_stickers) break;
      if (misses >= o.template_max_misses) break;
      const RefineCandidate& c = candidates[i];
      // Searched over the window the pose's own uncertainty spans; a sticker
      // found by its pattern is that sticker (its bits fit, not its turns),
      // so it may lie that far from the projection.
      const double radius = o.template_max_shift_fraction * c.side + K.fx * reach_m / c.depth;
      const CornerRefinementResult r = FromPattern(c, radius);
      if (!refined_within(r, c, radius + o.max_refinement_shift_px)) {
        ++misses;
        continue;
      }
      misses = 0;
      found->push_back(Refined(c.id, c.px, r));
    }
  }

  // A sticker whose edge lines could not be fitted (or fitted beyond their
  // reach), located by its whole pattern from its projected corners.
  CornerRefinementResult FromPattern(const RefineCandidate& c, double search_radius_px) {
    CornerRefinementResult r;
    const cv::Mat& cells = sticker_cells->Of(c.id);
    template_options.search_radius_px = search_radius_px;
    const MarkerTemplateResult t =
        FitMarkerTemplate(gray, cells, c.px, template_options, &template_cache);
    if (!t.ok) {
      r.failure = t.failure;
      return r;
    }
    r.status = MarkerStatus::kRefined;
    r.corners_px = t.corners_px;
    r.corner_sigma_px = t.corner_sigma_px;
    r.edge_inlier_fraction = 1;
    r.contrast_grey = t.contrast_grey;
    r.blur_sigma_px = t.blur_sigma_px;
    r.noise_sigma_grey = t.noise_sigma_grey;
    return r;
  }

  // Share of the coarse model points facing the camera (in the image, with a
  // depth reading) whose depth reading lies within `gate` of them: a cheap
  // test of a candidate pose against the surface.
  double DepthAgreement(const Rigid3d& camera_from_model, const RgbdFrame& frame, double gate) const {
    const Eigen::Matrix3d R = camera_from_model.RotationMatrix();
    int seen = 0, agree = 0;
    for (size_t i = 0; i < coarse_points.size(); ++i) {
      const Eigen::Vector3d p = R * coarse_points[i] + camera_from_model.translation;
      if (p.z() < 0.1 || (R * coarse_normals[i]).dot(p) > -0.1 * p.norm()) continue;
      const Eigen::Vector2d px = PixelOf(p);
      const int u = static_cast<int>(std::lround(px.x())), v = static_cast<int>(std::lround(px.y()));
      if (u < 0 || v < 0 || u >= K.width || v >= K.height) continue;
      const uint16_t raw = frame.depth.at<uint16_t>(v, u);
      if (raw == 0) continue;
      ++seen;
      // Along the ray: the reading may lie behind (hidden) or in front
      // (something over the patient) of a point the camera cannot see.
      agree += std::abs(raw / frame.depth_scale - p.z()) < gate;
    }
    return seen ? static_cast<double>(agree) / seen : 0.0;
  }

  // Model points facing the camera and in front in a coarse z-buffer.
  void FindVisible(const Rigid3d& camera_from_model, int cell, double tolerance, int max_points,
                   Eigen::AlignedBox2d* bounds) {
    const int gw = (K.width + cell - 1) / cell, gh = (K.height + cell - 1) / cell;
    zbuffer.assign(static_cast<size_t>(gw) * gh, std::numeric_limits<float>::infinity());
    const Eigen::Matrix3d R = camera_from_model.RotationMatrix();
    const Eigen::Vector3d t = camera_from_model.translation;
    candidates.clear();
    cells.clear();
    for (size_t i = 0; i < model_points.size(); ++i) {
      const Eigen::Vector3d p = R * model_points[i] + t;
      if (p.z() < 0.1) continue;
      const Eigen::Vector3d n = R * model_normals[i];
      if (n.dot(p) > -0.1 * p.norm()) continue;  // back-facing or edge-on
      const Eigen::Vector2d px = PixelOf(p);
      if (!(px.x() >= 0 && px.y() >= 0 && px.x() <= K.width - 1 && px.y() <= K.height - 1)) continue;
      const int c = static_cast<int>(px.y()) / cell * gw + static_cast<int>(px.x()) / cell;
      zbuffer[c] = std::min(zbuffer[c], static_cast<float>(p.z()));
      candidates.emplace_back(static_cast<int>(i), static_cast<float>(p.z()));
      cells.push_back(c);
    }
    visible.clear();
    for (size_t k = 0; k < candidates.size(); ++k) {
      if (candidates[k].second <= zbuffer[cells[k]] + tolerance) visible.push_back(candidates[k].first);
    }
    if (bounds) {
      bounds->setEmpty();
      for (int i : visible) bounds->extend(PixelOf(R * model_points[i] + t));
    }
    if (static_cast<int>(visible.size()) > max_points) {
      std::vector<int> thinned;
      thinned.reserve(max_points);
      const double step = static_cast<double>(visible.size()) / max_points;
      for (int k = 0; k < max_points; ++k) thinned.push_back(visible[static_cast<size_t>(k * step)]);
      visible.swap(thinned);
    }
  }
};

BodyTracker::BodyTracker(const TriangleMesh& model, std::map<int, Rigid3d> model_from_marker,
                         const CameraIntrinsics& intrinsics, const BodyTrackerOptions& options)
    : options_(options), impl_(std::make_unique<Impl>()) {
  const std::string problem = options_.Validate();
  ARPOS_CHECK(problem.empty(), "body tracker options: " << problem);
  const std::string k_problem = intrinsics.Validate();
  ARPOS_CHECK(k_problem.empty(), "body tracker intrinsics: " << k_problem);
  if (model.empty()) ARPOS_INPUT_ERROR("body tracking: the reference model has no faces");
  if (model_from_marker.empty()) ARPOS_INPUT_ERROR("body tracking: the session has no mapped stickers");
  Impl& m = *impl_;
  m.K = intrinsics;
  m.distorted = intrinsics.HasDistortion();
  if (m.distorted) {
    std::vector<cv::Point2f> grid;
    grid.reserve(static_cast<size_t>(intrinsics.width) * intrinsics.height);
    for (int v = 0; v < intrinsics.height; ++v) {
      for (int u = 0; u < intrinsics.width; ++u) grid.emplace_back(static_cast<float>(u), static_cast<float>(v));
    }
    std::vector<cv::Point2f> normalised;
    cv::undistortPoints(grid, normalised, cv::Mat(intrinsics.CvK()), intrinsics.CvDistortion());
    m.rays.create(intrinsics.height, intrinsics.width, CV_32FC2);
    for (int v = 0, k = 0; v < intrinsics.height; ++v) {
      for (int u = 0; u < intrinsics.width; ++u, ++k) {
        m.rays.at<cv::Vec2f>(v, u) = cv::Vec2f(normalised[k].x, normalised[k].y);
      }
    }
  }
  const PointCloud surface = SampleMeshSurface(model, options_.model_spacing_m);
  m.model_points.reserve(surface.size());
  m.model_normals.reserve(surface.size());
  // The surface that moved during the scan (breathing) is left out of the
  // depth term.
  const double patch = options_.moving_surface_patch_m;
  std::unordered_set<uint64_t> moving_cells;
  for (const Eigen::Vector3d& c : options_.moving_surface_patches) moving_cells.insert(CubeKey(c, patch));
  for (size_t i = 0; i < surface.size(); ++i) {
    if (!moving_cells.empty() && moving_cells.count(CubeKey(surface.point3(i), patch))) continue;
    m.model_points.push_back(surface.point3(i));
    m.model_normals.push_back(surface.normal3(i));
  }
  const PointCloud coarse_surface = SampleMeshSurface(model, 0.02);
  for (size_t i = 0; i < coarse_surface.size(); ++i) {
    m.coarse_points.push_back(coarse_surface.point3(i));
    m.coarse_normals.push_back(coarse_surface.normal3(i));
  }
  m.model_from_marker = std::move(model_from_marker);
  m.corners_in_marker = MarkerCornersInMarker(options_.marker_size_m);
  MarkerDetectorOptions detector = options_.detector;
  detector.intrinsics = intrinsics;
  detector.keep_unreliable = true;
  // The whole image is searched with the second thresholding pass (it
  // reads stickers with cells of a few pixels: measured on a d435 case with
  // 20-25 px ARUCO_ORIGINAL stickers, none of 12 read in the first 15
  // frames, the patient lost until the camera was placed); frames tracked
  // through windows where the motion puts the stickers (coarse, upsampled)
  // do not pay for it.
  m.detector = std::make_unique<MarkerDetector>(detector);
  MarkerDetectorOptions coarse = options_.detector;
  coarse.refinement = CornerRefinementMethod::kOpenCvNone;
  coarse.intrinsics.reset();
  coarse.min_marker_perimeter_px = 20;
  coarse.second_pass_window_px = 0;
  m.coarse = std::make_unique<MarkerDetector>(coarse);
  m.edge = options_.detector.edge;
  m.edge.marker_bits = m.detector->marker_bits();
  m.sticker_cells.emplace(options_.detector.dictionary, m.edge.border_bits);
  m.template_options.response = m.edge.response;
  m.template_options.quiet_zone_cells = m.edge.quiet_zone_cells;
  m.undistorter = PixelUndistorter(intrinsics);
}

BodyTracker::~BodyTracker() = default;

bool BodyTracker::HasRecentPose(double t) const {
  return !impl_->past.empty() && t >= impl_->past.back().t && t - impl_->past.back().t < kPredictionMaxAgeS;
}

void BodyTracker::Reset() {
  impl_->past.clear();
  impl_->frames_without_stickers = 0;
  impl_->usual_depth_fraction = -1;
}

BodyPoseResult BodyTracker::Track(const RgbdFrame& frame, const std::optional<Rigid3d>& hint,
                                  const DepthCameraMotion* depth_motion) {
  const int frames_without_stickers = impl_->frames_without_stickers;
  BodyPoseResult first = TrackOnce(frame, hint, Search::kWindows, depth_motion);
  if (first.ok || first.retry == 0) return first;
  // 1: one sticker read, and its pose put the model off the surface: a
  // single small sticker's pose is poorly determined (its two IPPE
  // solutions, a blurred corner), while the prediction is a few millimetres
  // off (so is the pose of two small stickers turned about the line through
  // them: min_depth_inlier_fraction_with_stickers). Again from the
  // prediction, the stickers refined where the surface puts them (measured
  // on a case with random conditions: 1-sticker frames fitted with 28 of
  // ~800 depth points, lost; from the prediction 2-3
  // stickers). 2: no window held a sticker and the surface alone did not
  // hold: the prediction may be off after a jerk of the camera; the whole
  // image (measured on a case with random conditions: 7 frames lost with
  // 20 px stickers in plain view). Only then: most frames' stickers are too
  // small for ArUco anyway and the surface places them; the whole image on
  // every such frame took the body's detection from 2.1 to 6.1 ms (640x480)
  // and from 4.1 to 11.9 ms (1280x720) a frame on average (tracking_bench).
  impl_->frames_without_stickers = frames_without_stickers;
  BodyPoseResult second =
      TrackOnce(frame, hint, first.retry == 1 ? Search::kNone : Search::kWholeImage, depth_motion);
  second.timings.detection_ms += first.timings.detection_ms;
  second.timings.pose_ms += first.timings.pose_ms;
  second.timings.total_ms += first.timings.total_ms;
  if (second.ok) return second;
  impl_->frames_without_stickers = frames_without_stickers + 1;
  first.timings = second.timings;
  return first;
}

BodyPoseResult BodyTracker::TrackOnce(const RgbdFrame& frame, const std::optional<Rigid3d>& hint,
                                      Search search, const DepthCameraMotion* depth_motion) {
  const auto start = Clock::now();
  Impl& m = *impl_;
  const BodyTrackerOptions& o = options_;
  BodyPoseResult result;
  auto finish = [&](BodyPoseResult r) {
    r.timings.total_ms = MsSince(start);
    if (!r.ok) {
      ++m.frames_without_stickers;
    }
    return r;
  };
  if (frame.color.empty() || frame.color.cols != m.K.width || frame.color.rows != m.K.height ||
      frame.color.type() != CV_8UC3) {
    result.message = "no usable colour image";
    return finish(result);
  }
  const bool have_depth = o.use_depth && !frame.depth.empty() && frame.depth.type() == CV_16UC1 &&
                          frame.depth.cols == m.K.width && frame.depth.rows == m.K.height;

  // 1. Prediction (constant velocity of camera_from_model) and the window.
  std::optional<Rigid3d> predicted;
  if (!m.past.empty() && frame.timestamp_s - m.past.back().t < kPredictionMaxAgeS &&
      frame.timestamp_s >= m.past.back().t) {
    predicted = m.past.back().pose;
    if (m.past.size() == 2) {
      const double dt01 = m.past[1].t - m.past[0].t, dt12 = frame.timestamp_s - m.past[1].t;
      if (dt01 > 1e-4 && dt01 < 0.5) {
        const Rigid3d step = m.past[1].pose * m.past[0].pose.Inverse();
        const double a = std::min(2.0, dt12 / dt01);
        predicted = Rigid3d::FromRotationVector(a * step.RotationVector(), a * step.translation) * m.past[1].pose;
      }
    }
  }
  // Depth of another instant than its colour (sensor/depth_timing.h): the
  // camera's motion relative to the patient between the two, from the last
  // two poses, else the assumed hand-held motion (each reading's gates and
  // robust weights allow for it); its mean and covariance as the room's
  // depth measured it when the localiser did (the patient still over those
  // few ms), else zero and the motion's size. Measured on simulated xtion
  // tracking (seeds 41 and 42, depth 10 ms late, against plans and sessions
  // of synced depth): the patient in the camera 0.84-1.59 -> 0.61-0.96 mm
  // (0.30-0.41 mm with synced depth).
  DelayedDepthSigma delayed;
  Vector6d delayed_mean = Vector6d::Zero();
  if (have_depth && frame.depth_delay_s != 0) {
    std::optional<Rigid3d> step;
    double step_s = 0;
    if (m.past.size() == 2 && m.past[1].t > m.past[0].t && m.past[1].t - m.past[0].t < 0.5) {
      step = m.past[1].pose * m.past[0].pose.Inverse();
      step_s = m.past[1].t - m.past[0].t;
    }
    delayed = DelayedDepthSigmaOf(frame.depth_delay_s, step ? &*step : nullptr, step_s);
  }
  Matrix6d delayed_cov = delayed.Covariance();
  if (delayed.any() && depth_motion != nullptr) {
    delayed_mean = depth_motion->mean;
    delayed_cov = depth_motion->covariance;
  }
  const bool from_hint = !predicted && hint.has_value();
  if (from_hint) predicted = hint;

  // 2. Stickers: around their predicted corners (small windows, upsampled
  // for ArUco when the sticker is small, corners refined on the frame
  // itself), else in the whole image.
  const auto t_detect = Clock::now();
  cv::cvtColor(frame.color, m.gray, cv::COLOR_BGR2GRAY);
  std::vector<MarkerObservation> found;
  m.predicted_side_px = 0;  // this frame's search says
  if (predicted && search == Search::kWindows) m.SearchAround(*predicted, o, &found);
  const bool whole_image = search == Search::kWholeImage ||
                           (search == Search::kWindows && found.empty() && (!predicted || from_hint));
  if (whole_image) {
    m.detector->Detect(m.gray, &m.scratch);
    found = m.scratch;
  }
  auto make_stickers = [&](const std::vector<MarkerObservation>& observations) {
    std::vector<SeenSticker> out;
    std::vector<cv::Point2d> raw;
    for (const auto& obs : observations) {
      const auto it = m.model_from_marker.find(obs.id);
      if (it == m.model_from_marker.end()) continue;
      if (obs.status != MarkerStatus::kRefined && obs.status != MarkerStatus::kPartiallyOccluded) continue;
      SeenSticker s;
      s.id = obs.id;
      s.marker_from_model = it->second.Inverse();
      s.normal_in_model = it->second.rotation * Eigen::Vector3d::UnitZ();
      const auto direction = o.sticker_motion_direction.find(obs.id);
      s.motion_in_model = direction != o.sticker_motion_direction.end()
                              ? it->second.rotation * direction->second
                              : s.normal_in_model;
      if (const auto motion = o.sticker_motion_m.find(obs.id); motion != o.sticker_motion_m.end()) {
        s.motion_m = motion->second;
      }
      for (int c = 0; c < 4; ++c) {
        s.corners_in_model[c] = it->second * m.corners_in_marker[c];
        s.sigma_px[c] = std::max(o.corner_sigma_px, obs.corner_sigma_px[c]);
        if (obs.status == MarkerStatus::kPartiallyOccluded) s.sigma_px[c] *= 2;
        raw.emplace_back(obs.corners_px[c].x(), obs.corners_px[c].y());
      }
      s.single_view = EstimateMarkerPose(obs, o.marker_size_m, m.K, have_depth ? frame.depth : cv::Mat(),
                                         o.marker_pose);
      out.push_back(s);
    }
    if (!raw.empty()) {
      std::vector<cv::Point2d> normalised;
      if (m.distorted) {
        cv::undistortPoints(raw, normalised, cv::Mat(m.K.CvK()), m.K.CvDistortion());
      } else {
        for (const auto& p : raw) normalised.emplace_back((p.x - m.K.cx) / m.K.fx, (p.y - m.K.cy) / m.K.fy);
      }
      for (size_t i = 0; i < out.size(); ++i) {
        for (int c = 0; c < 4; ++c) out[i].normalised[c] = Eigen::Vector2d(normalised[4 * i + c].x, normalised[4 * i + c].y);
      }
    }
    return out;
  };
  auto sticker_rms = [&](const Rigid3d& camera_from_model, const SeenSticker& s) {
    double sum = 0;
    for (int c = 0; c < 4; ++c) {
      const Eigen::Vector3d p = camera_from_model * s.corners_in_model[c];
      if (p.z() < 1e-3) return 1e3;
      const Eigen::Vector2d e(m.K.fx * (p.x() / p.z() - s.normalised[c].x()),
                              m.K.fy * (p.y() / p.z() - s.normalised[c].y()));
      sum += e.squaredNorm();
    }
    return std::sqrt(sum / 4);
  };
  // 3. Start pose: the candidate (the prediction, each sticker's IPPE
  // solutions) that explains every sticker and the depth best. One small
  // sticker's two solutions explain its corners alike; the surface tells.
  auto choose_start = [&](const std::vector<SeenSticker>& seen) -> std::optional<Rigid3d> {
    std::vector<Rigid3d> candidates;
    if (predicted) candidates.push_back(*predicted);
    for (const auto& s : seen) {
      if (s.single_view.status == MarkerPoseStatus::kOk) {
        candidates.push_back(s.single_view.camera_from_marker * s.marker_from_model);
      }
      for (int k = 0; k < s.single_view.num_solutions; ++k) {
        candidates.push_back(s.single_view.solutions[k].camera_from_marker * s.marker_from_model);
      }
    }
    std::optional<Rigid3d> best_pose;
    double best = std::numeric_limits<double>::infinity();
    for (const auto& c : candidates) {
      double cost = 0;
      for (const auto& s : seen) cost += std::min(sticker_rms(c, s), 30.0);
      if (have_depth) cost += o.start_depth_weight_px * (1.0 - m.DepthAgreement(c, frame, o.depth_gate_initial_m));
      if (cost < best - 1e-9) best = cost, best_pose = c;
    }
    return best_pose;
  };

  std::vector<SeenSticker> stickers = make_stickers(found);
  // No window around the predicted stickers held one: if this attempt fails,
  // the whole image is searched (Track).
  const bool windows_empty = search == Search::kWindows && predicted && !from_hint && stickers.empty();
  std::optional<Rigid3d> start_pose;
  if (!stickers.empty()) {
    start_pose = choose_start(stickers);
    // Found in the whole image (small stickers are often missed there):
    // search again around where the first pose puts every sticker.
    if (start_pose && whole_image) {
      std::vector<MarkerObservation> around;
      m.SearchAround(*start_pose, o, &around);
      std::vector<SeenSticker> more = make_stickers(around);
      if (more.size() > stickers.size()) {
        stickers = std::move(more);
        start_pose = choose_start(stickers);
      }
    }
  } else if (predicted && have_depth) {
    // No sticker read: the surface from the prediction, then the stickers
    // refined where it puts them (step 5). Without any, the pose is carried
    // only for a few frames.
    start_pose = predicted;
  }
  result.timings.detection_ms = MsSince(t_detect);
  const auto t_pose = Clock::now();
  ARPOS_DEBUG("body frame " << frame.index << ": " << (predicted ? (from_hint ? "hint" : "predicted") : "no prediction")
                            << ", " << found.size() << " detections, " << stickers.size() << " mapped stickers");
  // Stickers expected in view but too small for ArUco to read (about 2 px a
  // cell): said, with what to change.
  const double readable_px = ReadableMarkerSidePx(m.detector->marker_bits());
  const std::string too_small =
      stickers.empty() && predicted && m.predicted_side_px > 0 && m.predicted_side_px < readable_px
          ? StringPrintf("; the stickers are about %.0f px across from here, too small to read (%.0f px or more "
                         "are needed): use larger stickers or bring the camera closer",
                         m.predicted_side_px, readable_px)
          : std::string();
  if (!start_pose) {
    if (windows_empty) result.retry = 2;
    result.message = (stickers.empty() ? "no sticker in view" : "no sticker pose") + too_small;
    result.timings.pose_ms = MsSince(t_pose);
    return finish(result);
  }

  // 4. Joint refinement of corners and depth; disagreeing stickers dropped.
  bool carried = stickers.empty();
  std::vector<char> use;
  Rigid3d pose = *start_pose;
  Matrix6d H_final = Matrix6d::Zero();
  double chi2 = 0;
  int dof = 0, depth_inliers = 0, depth_candidates = 0;
  double depth_sq = 0;
  std::optional<Rigid3d> visible_at;  // the pose the visible points were found for
  auto fit = [&](const Rigid3d& from, int max_iterations) {
  use.assign(stickers.size(), 1);
  result.stickers_dropped.clear();
  for (int round = 0; round < 4; ++round) {
    pose = from;
    for (int it = 0; it < max_iterations; ++it) {
      Matrix6d H = Matrix6d::Zero();
      Vector6d g = Vector6d::Zero();
      chi2 = 0;
      dof = -6;
      SharedBreathing breathing;
      for (size_t si = 0; si < stickers.size(); ++si) {
        if (!use[si]) continue;
        const SeenSticker& s = stickers[si];
        // The sticker's whitened corner residuals (up to 8 rows), their
        // Jacobian, and how they move with the sticker as it breathes.
        StickerResiduals r = StickerResiduals::Zero(), b = StickerResiduals::Zero();
        StickerJacobian J = StickerJacobian::Zero();
        const Eigen::Vector3d rise = pose.rotation * s.motion_in_model;
        int rows = 0;
        for (int c = 0; c < 4; ++c) {
          const Eigen::Vector3d p = pose * s.corners_in_model[c];
          if (p.z() < 1e-3) continue;
          const double iz = 1.0 / p.z();
          const Eigen::Vector2d rc(m.K.fx * (p.x() * iz - s.normalised[c].x()) / s.sigma_px[c],
                                   m.K.fy * (p.y() * iz - s.normalised[c].y()) / s.sigma_px[c]);
          Eigen::Matrix<double, 2, 3> dproj;
          dproj << m.K.fx * iz / s.sigma_px[c], 0, -m.K.fx * p.x() * iz * iz / s.sigma_px[c], 0,
              m.K.fy * iz / s.sigma_px[c], -m.K.fy * p.y() * iz * iz / s.sigma_px[c];
          Eigen::Matrix<double, 3, 6> dp;
          dp << -Skew(p), Eigen::Matrix3d::Identity();
          const double norm = rc.norm();
          const double sw = std::sqrt(norm <= o.huber_sigmas ? 1.0 : o.huber_sigmas / norm);
          r.segment<2>(rows) = sw * rc;
          J.middleRows<2>(rows) = sw * dproj * dp;
          b.segment<2>(rows) = sw * dproj * rise;
          rows += 2;
          dof += 2;
        }
        AddStickerTerms(r, J, b, s.motion_m, &H, &g, &chi2, &breathing);
      }
      breathing.Eliminate(o.shared_breathing_sigmas, &H, &g, &chi2);
      // Depth: projective association of the visible model points.
      depth_inliers = 0;
      depth_candidates = 0;
      depth_sq = 0;
      if (have_depth) {
        // Visibility from where the pose is, recomputed only when it has
        // moved (a few mm or a degree change nothing at 8 mm sampling).
        if (!visible_at || (pose.translation - visible_at->translation).norm() > 0.004 ||
            visible_at->rotation.angularDistance(pose.rotation) > 0.02) {
          m.FindVisible(pose, o.zbuffer_cell_px, o.zbuffer_tolerance_m, o.max_depth_points, nullptr);
          visible_at = pose;
        }
        const double gate = it < 2 ? o.depth_gate_initial_m : o.depth_gate_final_m;
        const Eigen::Matrix3d R = pose.RotationMatrix();
        Matrix6d Hd = Matrix6d::Zero();
        Vector6d gd = Vector6d::Zero();
        double chi2d = 0;
        for (int i : m.visible) {
          const Eigen::Vector3d p = R * m.model_points[i] + pose.translation;
          const Eigen::Vector2d px = m.PixelOf(p);
          const int u = static_cast<int>(std::lround(px.x())), v = static_cast<int>(std::lround(px.y()));
          if (u < 0 || v < 0 || u >= m.K.width || v >= m.K.height) continue;
          const uint16_t raw = frame.depth.at<uint16_t>(v, u);
          if (raw == 0) continue;
          ++depth_candidates;
          const double z = raw / frame.depth_scale;
          const Eigen::Vector2d ray = m.RayOf(u, v);
          const Eigen::Vector3d q(ray.x() * z, ray.y() * z, z);
          const Eigen::Vector3d d = p - q;
          if (d.norm() > gate) continue;
          const Eigen::Vector3d n = R * m.model_normals[i];
          const double sensor = o.depth_sigma_const_m + o.depth_sigma_quad_per_m * z * z;
          const double sigma = delayed.any() ? std::hypot(sensor, delayed.At(z)) : sensor;
          const double r = n.dot(d) / sigma;
          Vector6d J;
          J << p.cross(n) / sigma, n / sigma;
          const double w = std::abs(r) <= o.huber_sigmas ? 1.0 : o.huber_sigmas / std::abs(r);
          Hd += w * J * J.transpose();
          gd += w * J * r;
          chi2d += w * r * r;
          ++depth_inliers;
          depth_sq += (n.dot(d)) * (n.dot(d));
        }
        if (depth_inliers > 0) {
          const double scale = depth_inliers > o.depth_max_effective
                                   ? static_cast<double>(o.depth_max_effective) / depth_inliers
                                   : 1.0;
          Hd *= scale;
          gd *= scale;
          // Depth of another instant: the camera's motion over the delay,
          // shared by every reading, marginalised out.
          if (delayed.any()) MarginaliseSharedMotion(delayed_cov, &Hd, &gd, delayed_mean);
          H += Hd;
          g += gd;
          chi2 += scale * chi2d;
          dof += std::min(depth_inliers, o.depth_max_effective);
        }
      }
      // Without stickers the surface can slide along itself: a weak prior
      // on the prediction keeps those directions where they were.
      if (carried && predicted) {
        const Rigid3d delta = pose * predicted->Inverse();
        Vector6d r;
        r << delta.RotationVector() / (3.14159265358979 / 180.0 * 1.0), delta.translation / 0.005;
        Matrix6d J = Matrix6d::Zero();
        J.topLeftCorner<3, 3>() = Eigen::Matrix3d::Identity() / (3.14159265358979 / 180.0);
        J.bottomRightCorner<3, 3>() = Eigen::Matrix3d::Identity() / 0.005;
        J.bottomLeftCorner<3, 3>() = -Skew(predicted->translation) / 0.005;
        H += J.transpose() * J;
        g += J.transpose() * r;
      }
      H_final = H;
      Eigen::LDLT<Matrix6d> ldlt(H + 1e-9 * Matrix6d::Identity());
      const Vector6d step = -ldlt.solve(g);
      if (!step.allFinite()) break;
      pose = Rigid3d::FromRotationVector(step.head<3>(), step.tail<3>()) * pose;
      if (step.head<3>().norm() < o.convergence_rad && step.tail<3>().norm() < o.convergence_m) {
        ARPOS_DEBUG("body fit converged after " << it + 1 << " iterations, round " << round);
        break;
      }
      if (it + 1 == max_iterations) {
        ARPOS_DEBUG("body fit stopped at " << max_iterations << " iterations, round " << round << ", step "
                                           << step.tail<3>().norm() * 1000 << " mm");
      }
    }
    // Drop the worst sticker if it disagrees with the rest and the surface.
    int worst = -1;
    double worst_rms = o.max_sticker_rms_px;
    for (size_t si = 0; si < stickers.size(); ++si) {
      if (!use[si]) continue;
      const double r = sticker_rms(pose, stickers[si]);
      if (r > worst_rms) worst_rms = r, worst = static_cast<int>(si);
    }
    if (worst < 0) break;
    ARPOS_DEBUG("body frame " << frame.index << ": sticker " << stickers[worst].id
                              << " dropped, corner rms " << worst_rms << " px against the fit");
    use[worst] = 0;
    result.stickers_dropped.push_back(stickers[worst].id);
    if (std::count(use.begin(), use.end(), 1) == 0) break;
  }
  };
  // A first fit good to a pixel at the stickers is all step 5 needs.
  fit(*start_pose, std::min(o.max_iterations, 4));
  // 5. Stickers too small or blurred for ArUco to read are refined where
  // the fitted pose puts them (their identity is the prediction's), then
  // the fit is repeated with them; one that disagrees is dropped as above.
  {
    std::vector<int> have;
    for (size_t si = 0; si < stickers.size(); ++si) {
      if (use[si]) have.push_back(stickers[si].id);
    }
    std::vector<MarkerObservation> at_pose;
    // From a hint, stickers located by their pattern are searched as far
    // as the rings below reach.
    m.RefineAtPose(
        pose, have, o, &at_pose, 0, 0, true,
        from_hint && carried ? o.hint_search_steps * o.hint_search_step_mm / 1000.0 : 0.0);
    if (at_pose.empty() && carried && from_hint && o.hint_search_steps > 0) {
      // From a hint the surface alone places the patient to a few mm along
      // the body (measured: stickers of 12 px not refined for the first 10
      // frames of a sequence, the patient reported lost): the stickers where
      // the fitted pose, shifted across the view, puts them.
      // Ring by ring outwards (nearest shifts first), stopping after the
      // first ring where a shift refines two or more: the fit that follows
      // settles the pose from those stickers (the whole 7 x 7 grid took
      // 70 ms of body pose on the frame it was made for, idle; 17 ms now).
      // Each shift refines the largest hint_search_stickers only: where no
      // shift refines two (stickers beyond their range, every ring searched
      // every frame) that took a d435 sequence's body pose from 63 to 38 ms
      // a frame; over 50 random-conditions sequences the rings found
      // stickers in 6 frames, and with 4 a shift in the same 6 (with 3 a
      // shift, 426 tracked 12 frames fewer).
      std::vector<MarkerObservation> shifted;
      const Rigid3d fitted = pose;
      for (int ring = 1; ring <= o.hint_search_steps && at_pose.size() < 2; ++ring) {
        for (int iy = -ring; iy <= ring; ++iy) {
          for (int ix = -ring; ix <= ring; ++ix) {
            if (std::max(std::abs(ix), std::abs(iy)) != ring) continue;
            const Rigid3d shift(Eigen::Quaterniond::Identity(),
                                Eigen::Vector3d(ix, iy, 0) * (o.hint_search_step_mm / 1000.0));
            // A shift is kept for two stickers, and more than one kept before.
            // Stickers small enough for their patterns were searched by them
            // as far as the rings reach already (the largest four at least,
            // `template_max_misses`; measured: over 24 random-conditions
            // sequences that lose the patient, the poses identical to the
            // byte with or without them here).
            m.RefineAtPose(shift * fitted, have, o, &shifted, o.hint_search_stickers,
                           std::max<int>(2, static_cast<int>(at_pose.size()) + 1), false, 0.0,
                           o.template_max_side_px);
            if (shifted.size() >= 2 && shifted.size() > at_pose.size()) {
              at_pose = shifted;
              pose = shift * fitted;
            }
          }
        }
      }
      if (!at_pose.empty()) {
        // Every sticker where the kept shift puts them.
        m.RefineAtPose(pose, have, o, &shifted);
        if (shifted.size() > at_pose.size()) at_pose = shifted;
      }
    }
    std::vector<SeenSticker> extra = make_stickers(at_pose);
    if (!extra.empty()) {
      result.stickers_refined_at_pose = static_cast<int>(extra.size());
      stickers.insert(stickers.end(), extra.begin(), extra.end());
      carried = false;
      fit(pose, o.max_iterations);
    }
  }
  // Every sticker read disagreed with the surface (one the scan placed a
  // few mm off, read alone or with another such): the frame is one without
  // stickers, carried on the surface from the prediction as those are
  // (measured on an l515 `--hard` case with a sharpening camera: two of 12
  // stickers placed 2-3 mm off, dropped at 1.5-5.7 px; 36 of 150 frames
  // lost with only those in view).
  bool all_disagreed = false;
  if (!stickers.empty() && std::count(use.begin(), use.end(), 1) == 0 && predicted && !from_hint &&
      have_depth) {
    const std::vector<int> dropped = result.stickers_dropped;
    stickers.clear();
    carried = true;
    all_disagreed = true;
    fit(*predicted, o.max_iterations);
    result.stickers_dropped = dropped;
  }
  // How a frame carried on the surface (or refused as such) says why.
  const char* what = all_disagreed ? "every sticker read disagreed with the surface" : "no sticker in view";
  // A sticker dropped, found again where the fit put it (step 5) and
  // dropped again is named once.
  std::sort(result.stickers_dropped.begin(), result.stickers_dropped.end());
  result.stickers_dropped.erase(
      std::unique(result.stickers_dropped.begin(), result.stickers_dropped.end()),
      result.stickers_dropped.end());
  double rms_sum = 0;
  for (size_t si = 0; si < stickers.size(); ++si) {
    if (!use[si]) continue;
    result.sticker_ids.push_back(stickers[si].id);
    const double r = sticker_rms(pose, stickers[si]);
    rms_sum += r * r;
  }
  const int n_stickers = static_cast<int>(result.sticker_ids.size());
  result.sticker_rms_px = n_stickers ? std::sqrt(rms_sum / n_stickers) : 0;
  result.depth_inliers = depth_inliers;
  result.depth_rms_mm = depth_inliers ? 1000 * std::sqrt(depth_sq / depth_inliers) : 0;
  const double inlier_fraction = depth_candidates ? static_cast<double>(depth_inliers) / depth_candidates : 0;
  result.depth_inlier_fraction = inlier_fraction;
  const bool surface_ok = depth_inliers >= o.min_depth_inliers && inlier_fraction >= o.min_depth_inlier_fraction;

  ARPOS_DEBUG("body frame " << frame.index << ": " << n_stickers << " stickers (rms " << result.sticker_rms_px
                            << " px), depth " << depth_inliers << "/" << depth_candidates << " inliers, rms "
                            << result.depth_rms_mm << " mm");
  // 5. Acceptance and uncertainty.
  Matrix6d cov = Matrix6d::Identity() * 1e6;
  Eigen::FullPivLU<Matrix6d> lu(H_final);
  if (lu.isInvertible()) cov = lu.inverse();
  const double reduced = dof > 0 ? chi2 / dof : 1.0;
  cov *= std::max(1.0, reduced);
  Eigen::Matrix<double, 3, 6> at_origin;
  at_origin << -Skew(pose.translation), Eigen::Matrix3d::Identity();
  const Eigen::Matrix3d pos_cov = at_origin * cov * at_origin.transpose();
  const Eigen::Matrix3d rot_cov = cov.topLeftCorner<3, 3>();
  result.covariance = cov;
  result.position_sigma_mm = 1000 * std::sqrt(std::max(0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(pos_cov).eigenvalues().maxCoeff()));
  result.rotation_sigma_deg = 180.0 / 3.14159265358979 *
                              std::sqrt(std::max(0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(rot_cov).eigenvalues().maxCoeff()));
  result.timings.pose_ms = MsSince(t_pose);

  bool accept = false;
  const bool surface_counts = have_depth && depth_candidates >= o.min_depth_inliers;
  if (n_stickers >= 2) {
    // Contradicted: little of the surface agrees, and much less than usually
    // does (not before a frame has shown what usually does).
    accept = !(surface_counts && inlier_fraction < o.min_depth_inlier_fraction_with_stickers &&
               m.usual_depth_fraction > 0 && inlier_fraction < 0.5 * m.usual_depth_fraction);
    if (!accept) {
      result.message = StringPrintf("the stickers' pose disagrees with the surface in depth (%d of %d points agree)",
                                    depth_inliers, depth_candidates);
      if (predicted && !from_hint && search == Search::kWindows) result.retry = 1;
    }
  } else if (n_stickers == 1) {
    accept = surface_ok;
    if (!accept) {
      result.message = "one sticker and too little surface in depth";
      if (predicted && !from_hint && have_depth && search == Search::kWindows) result.retry = 1;
    }
  } else if (carried) {
    accept = surface_ok && !from_hint && m.frames_without_stickers < o.max_frames_without_stickers;
    if (!accept) {
      result.message =
          (!surface_ok
               ? StringPrintf("%s; the surface alone does not hold (%d depth inliers, %.0f %%)",
                              what, depth_inliers, 100 * inlier_fraction)
               : StringPrintf("%s for %d frames", what, m.frames_without_stickers + 1)) +
          (all_disagreed ? std::string() : too_small);
    }
  } else {
    result.message = "every sticker disagreed with the others and the surface";
  }
  if (accept && !(result.position_sigma_mm <= 1000 * o.max_position_sigma_m)) {
    accept = false;
    result.message = StringPrintf("pose too uncertain (%.1f mm)", result.position_sigma_mm);
  }
  if (!pose.translation.allFinite() || pose.translation.z() <= 0) accept = false;
  if (!accept) {
    if (result.message.empty()) result.message = "rejected";
    if (windows_empty && result.retry == 0) result.retry = 2;
    return finish(result);
  }
  result.ok = true;
  result.camera_from_model = pose;
  result.source = carried ? BodyPoseSource::kCarried : BodyPoseSource::kStickers;
  if (n_stickers >= 2 && surface_counts) {
    m.usual_depth_fraction =
        m.usual_depth_fraction < 0 ? inlier_fraction : 0.9 * m.usual_depth_fraction + 0.1 * inlier_fraction;
  }
  if (carried) {
    ++m.frames_without_stickers;
    result.message = StringPrintf(
        "%s: carried on the surface (%d of %d frames)",
        what, m.frames_without_stickers, o.max_frames_without_stickers);
  } else {
    m.frames_without_stickers = 0;
  }
  result.frames_without_stickers = m.frames_without_stickers;
  m.past.push_back({frame.timestamp_s, pose});
  while (m.past.size() > 2) m.past.pop_front();
  result.timings.total_ms = MsSince(start);
  return result;
}

}  // namespace arpos
