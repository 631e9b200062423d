#include "body_model/body_marker_map.h"

#include <ceres/ceres.h>
#include <ceres/covariance.h>

#include <opencv2/calib3d.hpp>

#include <algorithm>
#include <cmath>

#include "features/edge_refinement.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos {
namespace {

struct CornerResidual {
  CornerResidual(const Rigid3d& camera_from_room, const CameraIntrinsics& k,
                 const Eigen::Vector3d& corner_in_marker, const Eigen::Vector2d& observed_px,
                 double sigma_px)
      : r_cr(camera_from_room.RotationMatrix()),
        t_cr(camera_from_room.translation),
        fx(k.fx), fy(k.fy), cx(k.cx), cy(k.cy),
        corner(corner_in_marker), observed(PixelUndistorter(k).Undistort(observed_px)), inv_sigma(1.0 / sigma_px) {}

  template <typename T>
  bool operator()(const T* q_rm, const T* t_rm, T* residual) const {
    const Eigen::Map<const Eigen::Quaternion<T>> q(q_rm);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> t(t_rm);
    const Eigen::Matrix<T, 3, 1> p_room = q * corner.cast<T>() + t;
    const Eigen::Matrix<T, 3, 1> p_cam = r_cr.cast<T>() * p_room + t_cr.cast<T>();
    if (p_cam.z() <= T(1e-6)) return false;
    residual[0] = (T(fx) * p_cam.x() / p_cam.z() + T(cx) - T(observed.x())) * T(inv_sigma);
    residual[1] = (T(fy) * p_cam.y() / p_cam.z() + T(cy) - T(observed.y())) * T(inv_sigma);
    return true;
  }

  Eigen::Matrix3d r_cr;
  Eigen::Vector3d t_cr;
  double fx, fy, cx, cy;
  Eigen::Vector3d corner;
  Eigen::Vector2d observed;  ///< ideal (undistorted) pixel: the residual is a pinhole one
  double inv_sigma;
};

struct DepthPlaneResidual {
  DepthPlaneResidual(const Rigid3d& camera_from_room, const DepthPlane& plane, double sigma_m)
      : r_cr(camera_from_room.RotationMatrix()), t_cr(camera_from_room.translation),
        normal(plane.normal_in_camera), point(plane.point_in_camera), inv_sigma(1.0 / sigma_m) {}

  template <typename T>
  bool operator()(const T* t_rm, T* residual) const {
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> t(t_rm);
    const Eigen::Matrix<T, 3, 1> centre_cam = r_cr.cast<T>() * t + t_cr.cast<T>();
    residual[0] = normal.cast<T>().dot(centre_cam - point.cast<T>()) * T(inv_sigma);
    return true;
  }

  Eigen::Matrix3d r_cr;
  Eigen::Vector3d t_cr, normal, point;
  double inv_sigma;
};

struct ViewRef {
  const BodyScanView* view;
  const BodyMarkerView* marker;
};

// Corner reprojection RMS (px) of a sticker at `room_from_marker` seen by a
// camera at `room_from_camera`; 1e9 if a corner is behind the camera.
double CornerRmsPx(const Rigid3d& room_from_marker, const Rigid3d& room_from_camera,
                   const BodyMarkerView& seen, const CameraIntrinsics& k,
                   const std::array<Eigen::Vector3d, 4>& corners) {
  const Rigid3d camera_from_marker = room_from_camera.Inverse() * room_from_marker;
  const PixelUndistorter undistorter(k);
  double sum = 0;
  for (int c = 0; c < 4; ++c) {
    const Eigen::Vector3d p = camera_from_marker * corners[c];
    if (p.z() <= 1e-6) return 1e9;
    sum += (k.Project(p) - undistorter.Undistort(seen.corners_px[c])).squaredNorm();
  }
  return std::sqrt(sum / 4);
}

double ViewRmsPx(const Rigid3d& room_from_marker, const ViewRef& ref, const CameraIntrinsics& k,
                 const std::array<Eigen::Vector3d, 4>& corners) {
  return CornerRmsPx(room_from_marker, ref.view->room_from_camera, *ref.marker, k, corners);
}

// Fits one sticker to the given views; returns the final cost summary.
void FitMarker(const std::vector<ViewRef>& views, const CameraIntrinsics& k,
               const BodyMarkerMapOptions& options, Rigid3d* room_from_marker,
               double* position_sigma_mm) {
  const auto corners = MarkerCornersInMarker(options.marker_size_m);
  Eigen::Quaterniond q = room_from_marker->rotation;
  Eigen::Vector3d t = room_from_marker->translation;
  ceres::Problem problem;
  problem.AddParameterBlock(q.coeffs().data(), 4, new ceres::EigenQuaternionManifold);
  problem.AddParameterBlock(t.data(), 3);
  int depth_views = 0;
  for (const auto& ref : views) {
    if (options.use_depth && ref.marker->single_view.depth_plane.valid) ++depth_views;
  }
  // N depth terms weigh at most as much as depth_max_effective_views.
  const double depth_inflation =
      std::sqrt(std::max(1.0, static_cast<double>(depth_views) / options.depth_max_effective_views));
  for (const auto& ref : views) {
    const Rigid3d camera_from_room = ref.view->room_from_camera.Inverse();
    for (int c = 0; c < 4; ++c) {
      const double sigma = std::max(options.min_corner_sigma_px, ref.marker->corner_sigma_px[c]);
      problem.AddResidualBlock(
          new ceres::AutoDiffCostFunction<CornerResidual, 2, 4, 3>(
              new CornerResidual(camera_from_room, k, corners[c], ref.marker->corners_px[c], sigma)),
          new ceres::HuberLoss(options.huber_sigmas), q.coeffs().data(), t.data());
    }
    if (options.use_depth && ref.marker->single_view.depth_plane.valid) {
      problem.AddResidualBlock(
          new ceres::AutoDiffCostFunction<DepthPlaneResidual, 1, 3>(new DepthPlaneResidual(
              camera_from_room, ref.marker->single_view.depth_plane, options.depth_sigma_m * depth_inflation)),
          new ceres::HuberLoss(options.huber_sigmas), t.data());
    }
  }
  ceres::Solver::Options solver;
  solver.logging_type = ceres::SILENT;
  solver.minimizer_progress_to_stdout = false;
  solver.max_num_iterations = options.max_iterations;
  solver.linear_solver_type = ceres::DENSE_QR;
  solver.num_threads = 1;
  ceres::Solver::Summary summary;
  ceres::Solve(solver, &problem, &summary);
  *room_from_marker = Rigid3d(q.normalized(), t);

  *position_sigma_mm = 0;
  ceres::Covariance::Options cov_options;
  ceres::Covariance covariance(cov_options);
  std::vector<std::pair<const double*, const double*>> blocks = {{t.data(), t.data()}};
  if (covariance.Compute(blocks, &problem)) {
    double cov[9];
    covariance.GetCovarianceBlock(t.data(), t.data(), cov);
    *position_sigma_mm = 1000.0 * std::sqrt(std::max(0.0, cov[0] + cov[4] + cov[8]));
  }
}

}  // namespace

std::string BodyMarkerMapOptions::Validate() const {
  if (!(marker_size_m > 0)) return "marker_size_m must be positive";
  if (min_views < 1) return "min_views must be at least 1";
  if (!(min_corner_sigma_px > 0)) return "min_corner_sigma_px must be positive";
  if (!(huber_sigmas > 0)) return "huber_sigmas must be positive";
  if (!(max_view_rms_px > 0)) return "max_view_rms_px must be positive";
  if (!(depth_sigma_m > 0)) return "depth_sigma_m must be positive";
  if (depth_max_effective_views < 1) return "depth_max_effective_views must be at least 1";
  if (max_iterations < 1) return "max_iterations must be at least 1";
  return "";
}

BodyScanView MakeBodyScanView(const RgbdFrame& frame, const Rigid3d& room_from_camera,
                              MarkerDetector* detector, const CameraIntrinsics& intrinsics,
                              double marker_size_m, const MarkerPoseOptions& pose_options) {
  ARPOS_CHECK(detector != nullptr, "a marker detector is needed");
  BodyScanView view;
  view.frame_index = frame.index;
  view.timestamp_s = frame.timestamp_s;
  view.room_from_camera = room_from_camera;
  for (const MarkerObservation& obs : detector->Detect(frame.color)) {
    if (obs.status != MarkerStatus::kRefined) continue;  // occluded or unrefined corners
    BodyMarkerView marker;
    marker.marker_id = obs.id;
    marker.corners_px = obs.corners_px;
    marker.corner_sigma_px = obs.corner_sigma_px;
    marker.single_view = EstimateMarkerPose(obs, marker_size_m, intrinsics, frame.depth, pose_options);
    view.markers.push_back(marker);
  }
  return view;
}

BodyMarkerMapResult BuildBodyMarkerMap(const std::vector<BodyScanView>& views,
                                       const CameraIntrinsics& intrinsics,
                                       const BodyMarkerMapOptions& options) {
  const std::string problem = options.Validate();
  ARPOS_CHECK(problem.empty(), "body marker map options: " << problem);
  const auto corners = MarkerCornersInMarker(options.marker_size_m);

  std::map<int, std::vector<ViewRef>> by_id;
  for (const auto& view : views) {
    for (const auto& marker : view.markers) by_id[marker.marker_id].push_back({&view, &marker});
  }

  BodyMarkerMapResult result;
  std::vector<char> view_used(views.size(), 0);
  double rms_sum = 0;
  for (auto& [id, refs] : by_id) {
    if (static_cast<int>(refs.size()) < options.min_views) {
      result.rejected[id] = StringPrintf("seen in %zu frames, %d needed", refs.size(), options.min_views);
      continue;
    }
    // Start from the single-view candidate that best explains every view
    // (robust to flipped IPPE solutions in a few views).
    double best_cost = std::numeric_limits<double>::infinity();
    Rigid3d best;
    for (const auto& candidate_ref : refs) {
      const MarkerPose& pose = candidate_ref.marker->single_view;
      if (pose.status == MarkerPoseStatus::kFailed) continue;
      const Rigid3d candidate = candidate_ref.view->room_from_camera * pose.camera_from_marker;
      double cost = 0;
      for (const auto& ref : refs) cost += std::min(ViewRmsPx(candidate, ref, intrinsics, corners), 5.0);
      if (cost < best_cost) {
        best_cost = cost;
        best = candidate;
      }
    }
    if (!std::isfinite(best_cost)) {
      result.rejected[id] = "no view gave a pose";
      continue;
    }
    std::vector<ViewRef> inliers;
    for (const auto& ref : refs) {
      if (ViewRmsPx(best, ref, intrinsics, corners) < 5.0) inliers.push_back(ref);
    }
    BodyMarkerEstimate estimate;
    estimate.marker_id = id;
    Rigid3d room_from_marker = best;
    for (int round = 0; round < 3; ++round) {
      if (static_cast<int>(inliers.size()) < options.min_views) break;
      FitMarker(inliers, intrinsics, options, &room_from_marker, &estimate.position_sigma_mm);
      std::vector<double> rms;
      for (const auto& ref : inliers) rms.push_back(ViewRmsPx(room_from_marker, ref, intrinsics, corners));
      std::vector<double> sorted = rms;
      std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
      const double limit = std::max(options.max_view_rms_px, 4.0 * sorted[sorted.size() / 2]);
      std::vector<ViewRef> kept;
      for (size_t i = 0; i < inliers.size(); ++i) {
        if (rms[i] <= limit) kept.push_back(inliers[i]);
      }
      if (kept.size() == inliers.size()) break;
      inliers = std::move(kept);
    }
    if (static_cast<int>(inliers.size()) < options.min_views) {
      result.rejected[id] = StringPrintf("only %zu of %zu views consistent", inliers.size(), refs.size());
      continue;
    }
    estimate.room_from_marker = room_from_marker;
    estimate.num_views = static_cast<int>(inliers.size());
    estimate.num_rejected_views = static_cast<int>(refs.size() - inliers.size());
    double sq = 0, depth_sq = 0;
    int depth_n = 0;
    for (const auto& ref : inliers) {
      const double rms = ViewRmsPx(room_from_marker, ref, intrinsics, corners);
      sq += rms * rms;
      estimate.max_view_rms_px = std::max(estimate.max_view_rms_px, rms);
      const DepthPlane& plane = ref.marker->single_view.depth_plane;
      if (plane.valid) {
        const Eigen::Vector3d centre = ref.view->room_from_camera.Inverse() * room_from_marker.translation;
        depth_sq += std::pow(plane.SignedDistanceM(centre), 2);
        ++depth_n;
      }
      view_used[ref.view - views.data()] = 1;
    }
    estimate.rms_px = std::sqrt(sq / inliers.size());
    estimate.depth_rms_mm = depth_n ? 1000.0 * std::sqrt(depth_sq / depth_n) : 0.0;
    rms_sum += estimate.rms_px;
    result.max_rms_px = std::max(result.max_rms_px, estimate.rms_px);
    result.markers.push_back(estimate);
  }
  result.views_used = static_cast<int>(std::count(view_used.begin(), view_used.end(), 1));
  result.mean_rms_px = result.markers.empty() ? 0 : rms_sum / result.markers.size();
  return result;
}

StickerLocalization LocalizeFromStickers(const BodyScanView& view, const BodyMarkerMapResult& map,
                                         double marker_size_m, const CameraIntrinsics& intrinsics,
                                         const StickerLocalizationOptions& options) {
  ARPOS_CHECK(marker_size_m > 0, "sticker size must be positive");
  ARPOS_CHECK(options.min_markers >= 1 && options.max_rms_px > 0, "invalid sticker localisation options");
  const auto corners = MarkerCornersInMarker(marker_size_m);
  struct Use {
    const BodyMarkerView* seen;
    Rigid3d room_from_marker;
  };
  std::vector<Use> used;
  for (const auto& seen : view.markers) {
    for (const auto& mapped : map.markers) {
      if (mapped.marker_id == seen.marker_id) used.push_back({&seen, mapped.room_from_marker});
    }
  }
  StickerLocalization out;
  auto rms_of = [&](const Rigid3d& room_from_camera, const Use& u) {
    return CornerRmsPx(u.room_from_marker, room_from_camera, *u.seen, intrinsics, corners);
  };
  while (true) {
    if (static_cast<int>(used.size()) < options.min_markers) {
      out.ok = false;
      out.reason = StringPrintf("%zu mapped sticker(s) usable, %d needed", used.size(), options.min_markers);
      return out;
    }
    // Start from the single-view pose that explains all stickers best.
    double best_cost = std::numeric_limits<double>::infinity();
    Rigid3d best;
    for (const Use& u : used) {
      const MarkerPose& single = u.seen->single_view;
      if (single.status != MarkerPoseStatus::kOk) continue;
      const Rigid3d candidate = u.room_from_marker * single.camera_from_marker.Inverse();
      double cost = 0;
      for (const Use& v : used) cost += std::min(rms_of(candidate, v), 50.0);
      if (cost < best_cost) best_cost = cost, best = candidate;
    }
    if (!std::isfinite(best_cost)) {
      out.reason = "no sticker in view has an unambiguous single-view pose";
      return out;
    }
    // Joint PnP over every corner of every used sticker.
    std::vector<cv::Point3d> object;
    std::vector<cv::Point2d> image;
    for (const Use& u : used) {
      for (int c = 0; c < 4; ++c) {
        const Eigen::Vector3d p = u.room_from_marker * corners[c];
        object.emplace_back(p.x(), p.y(), p.z());
        image.emplace_back(u.seen->corners_px[c].x(), u.seen->corners_px[c].y());
      }
    }
    const Rigid3d camera_from_room = best.Inverse();
    const Eigen::Vector3d rv = camera_from_room.RotationVector();
    cv::Mat rvec = (cv::Mat_<double>(3, 1) << rv.x(), rv.y(), rv.z());
    cv::Mat tvec = (cv::Mat_<double>(3, 1) << camera_from_room.translation.x(),
                    camera_from_room.translation.y(), camera_from_room.translation.z());
    cv::solvePnP(object, image, cv::Mat(intrinsics.CvK()), intrinsics.CvDistortion(), rvec, tvec, true,
                 cv::SOLVEPNP_ITERATIVE);
    const Rigid3d refined =
        Rigid3d::FromRotationVector(Eigen::Vector3d(rvec.at<double>(0), rvec.at<double>(1), rvec.at<double>(2)),
                                    Eigen::Vector3d(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2)))
            .Inverse();
    // Drop the worst sticker if it disagrees, else accept.
    size_t worst = 0;
    double worst_rms = -1, sum = 0;
    for (size_t i = 0; i < used.size(); ++i) {
      const double r = rms_of(refined, used[i]);
      sum += r * r;
      if (r > worst_rms) worst_rms = r, worst = i;
    }
    if (worst_rms > options.max_rms_px) {
      used.erase(used.begin() + static_cast<std::ptrdiff_t>(worst));
      continue;
    }
    out.ok = true;
    out.room_from_camera = refined;
    out.num_markers = static_cast<int>(used.size());
    out.rms_px = std::sqrt(sum / used.size());
    return out;
  }
}

}  // namespace arpos
