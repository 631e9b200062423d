#include "body_model/sticker_motion.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Dense>

#include "features/edge_refinement.h"
#include "features/marker_pose.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos {
namespace {

constexpr double kDegPerRad = 180.0 / M_PI;

// One moving sticker in one view: its displacement from its mapped place
// (room frame) and the displacement's information (inverse covariance).
struct Displacement {
  int view = 0;
  Eigen::Vector3d delta = Eigen::Vector3d::Zero();
  Eigen::Matrix3d info = Eigen::Matrix3d::Zero();
};

// The sticker's translation, in the room frame, that best explains its
// corners in this view with the camera and the sticker's rotation held
// fixed (Gauss-Newton from its mapped place). False when the view cannot
// tell (behind the camera, a singular step) or its corners still miss.
bool ViewDisplacement(const BodyScanView& view, const BodyMarkerView& seen,
                      const Rigid3d& room_from_marker, const CameraIntrinsics& k,
                      const PixelUndistorter& undistorter, const StickerMotionOptions& o,
                      Displacement* out) {
  const std::array<Eigen::Vector3d, 4> corners_in_marker = MarkerCornersInMarker(o.marker_size_m);
  const Rigid3d camera_from_room = view.room_from_camera.Inverse();
  const Eigen::Matrix3d r_cr = camera_from_room.RotationMatrix();
  std::array<Eigen::Vector2d, 4> observed;
  std::array<double, 4> inv_sigma;
  for (int c = 0; c < 4; ++c) {
    observed[c] = undistorter.Undistort(seen.corners_px[c]);
    inv_sigma[c] = 1.0 / std::max(o.min_corner_sigma_px, seen.corner_sigma_px[c]);
  }
  Eigen::Vector3d delta = Eigen::Vector3d::Zero();
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  double sq = 0;
  for (int it = 0; it < 4; ++it) {
    A.setZero();
    Eigen::Vector3d b = Eigen::Vector3d::Zero();
    sq = 0;
    for (int c = 0; c < 4; ++c) {
      const Eigen::Vector3d p =
          camera_from_room * (room_from_marker * corners_in_marker[c] + delta);
      if (!(p.z() > 1e-3)) return false;
      const double iz = 1.0 / p.z();
      const Eigen::Vector2d e = k.Project(p) - observed[c];
      Eigen::Matrix<double, 2, 3> dproj;
      dproj << k.fx * iz, 0, -k.fx * p.x() * iz * iz, 0, k.fy * iz, -k.fy * p.y() * iz * iz;
      const Eigen::Matrix<double, 2, 3> J = inv_sigma[c] * dproj * r_cr;
      A += J.transpose() * J;
      b += J.transpose() * (inv_sigma[c] * e);
      sq += e.squaredNorm();
    }
    const Eigen::LDLT<Eigen::Matrix3d> ldlt(A);
    if (ldlt.info() != Eigen::Success ||
        !(ldlt.vectorD().minCoeff() > 1e-12 * ldlt.vectorD().maxCoeff())) {
      return false;
    }
    const Eigen::Vector3d step = -ldlt.solve(b);
    if (!step.allFinite()) return false;
    delta += step;
    if (step.norm() < 1e-7) break;
  }
  // The corners' RMS at the displacement found (the last pass's residuals
  // are those before its step; one more evaluation).
  sq = 0;
  for (int c = 0; c < 4; ++c) {
    const Eigen::Vector3d p = camera_from_room * (room_from_marker * corners_in_marker[c] + delta);
    if (!(p.z() > 1e-3)) return false;
    sq += (k.Project(p) - observed[c]).squaredNorm();
  }
  if (!(std::sqrt(sq / 4) <= o.max_view_rms_px) || !(delta.norm() < 0.05)) return false;
  const Eigen::Matrix3d cov =
      A.inverse() + o.view_sigma_m * o.view_sigma_m * Eigen::Matrix3d::Identity();
  out->delta = delta;
  out->info = cov.inverse();
  return true;
}

}  // namespace

std::string StickerMotionOptions::Validate() const {
  if (!(marker_size_m > 0 && marker_size_m < 1)) return "marker_size_m must be in (0, 1)";
  if (!(min_corner_sigma_px > 0)) return "min_corner_sigma_px must be > 0";
  if (!(view_sigma_m > 0)) return "view_sigma_m must be > 0";
  if (!(max_view_rms_px > 0)) return "max_view_rms_px must be > 0";
  if (min_views < 3) return "min_views must be >= 3";
  if (!(min_motion_sigmas > 0)) return "min_motion_sigmas must be > 0";
  if (!(min_explained_ratio >= 0)) return "min_explained_ratio must be >= 0";
  if (!(max_normal_disagreement > 0)) return "max_normal_disagreement must be > 0";
  if (!(max_direction_sigma_deg > 0 && max_direction_sigma_deg <= 90))
    return "max_direction_sigma_deg must be in (0, 90]";
  if (iterations < 1) return "iterations must be >= 1";
  return "";
}

std::string StickerMotion::Describe() const {
  int measured = 0;
  double lo = 0, hi = 0;
  for (const StickerMotionEstimate& s : stickers) {
    if (!s.ok) continue;
    lo = measured == 0 ? s.angle_to_normal_deg : std::min(lo, s.angle_to_normal_deg);
    hi = std::max(hi, s.angle_to_normal_deg);
    ++measured;
  }
  if (stickers.empty()) return "no sticker moved with the breathing";
  if (measured == 0) {
    return StringPrintf(
        "the breathing stickers' directions not measured (sticker %d: %s): each taken along its "
        "normal",
        stickers.front().marker_id, stickers.front().why_not.c_str());
  }
  return StringPrintf(
      "directions of %d of %zu breathing sticker(s) measured in %d views (%.0f-%.0f deg from their "
      "normals)%s",
      measured, stickers.size(), views, lo, hi,
      measured < static_cast<int>(stickers.size()) ? "; the others along their normals" : "");
}

StickerMotion EstimateStickerMotion(const std::vector<BodyScanView>& views,
                                    const BodyMarkerMapResult& map, const CameraIntrinsics& camera,
                                    const std::map<int, double>& normal_motion_m,
                                    const StickerMotionOptions& options) {
  const std::string problem = options.Validate();
  ARPOS_CHECK(problem.empty(), "sticker motion: " << problem);
  StickerMotion out;
  const PixelUndistorter undistorter(camera);
  // Per moving sticker: its mapped pose and its displacement in each view.
  struct Sticker {
    int id = -1;
    Rigid3d room_from_marker;
    std::vector<Displacement> seen;
    Eigen::Vector3d c = Eigen::Vector3d::Zero(), v = Eigen::Vector3d::Zero();
    Eigen::Matrix<double, 6, 6> normal = Eigen::Matrix<double, 6, 6>::Zero();
  };
  std::vector<Sticker> stickers;
  for (const BodyMarkerEstimate& m : map.markers) {
    if (!normal_motion_m.count(m.marker_id)) continue;
    Sticker s;  // c, v and the normal matrix start at zero
    s.id = m.marker_id;
    s.room_from_marker = m.room_from_marker;
    stickers.push_back(std::move(s));
  }
  if (stickers.empty()) return out;
  std::vector<int> seen_in_view(views.size(), 0);
  for (Sticker& s : stickers) {
    for (size_t k = 0; k < views.size(); ++k) {
      for (const BodyMarkerView& seen : views[k].markers) {
        if (seen.marker_id != s.id) continue;
        Displacement d;
        d.view = static_cast<int>(k);
        if (ViewDisplacement(views[k], seen, s.room_from_marker, camera, undistorter, options,
                             &d)) {
          s.seen.push_back(d);
          ++seen_in_view[k];
        }
      }
    }
  }
  out.views = static_cast<int>(
      std::count_if(seen_in_view.begin(), seen_in_view.end(), [](int n) { return n > 0; }));

  // The shared time course, started from the rise along each sticker's
  // normal (the mean over the stickers a view sees).
  std::vector<double> beta(views.size(), 0.0);
  for (size_t k = 0; k < views.size(); ++k) {
    double sum = 0;
    int n = 0;
    for (const Sticker& s : stickers) {
      const Eigen::Vector3d normal = s.room_from_marker.rotation * Eigen::Vector3d::UnitZ();
      for (const Displacement& d : s.seen) {
        if (d.view == static_cast<int>(k)) sum += normal.dot(d.delta), ++n;
      }
    }
    beta[k] = n ? sum / n : 0.0;
  }
  auto normalise_beta = [&]() {
    double sum = 0, sq = 0;
    int n = 0;
    for (size_t k = 0; k < views.size(); ++k) {
      if (seen_in_view[k] == 0) continue;
      sum += beta[k], sq += beta[k] * beta[k], ++n;
    }
    if (n < 2) return false;
    const double mean = sum / n, rms = std::sqrt(std::max(0.0, sq / n - mean * mean));
    if (!(rms > 0)) return false;
    for (size_t k = 0; k < views.size(); ++k)
      beta[k] = seen_in_view[k] ? (beta[k] - mean) / rms : 0.0;
    return true;
  };
  bool fitted = normalise_beta();
  for (int it = 0; fitted && it < options.iterations; ++it) {
    // c_s and v_s per sticker given beta: [I, beta I] [c; v] = delta.
    for (Sticker& s : stickers) {
      Eigen::Matrix<double, 6, 6> N = Eigen::Matrix<double, 6, 6>::Zero();
      Eigen::Matrix<double, 6, 1> r = Eigen::Matrix<double, 6, 1>::Zero();
      for (const Displacement& d : s.seen) {
        const double b = beta[d.view];
        N.block<3, 3>(0, 0) += d.info;
        N.block<3, 3>(0, 3) += b * d.info;
        N.block<3, 3>(3, 0) += b * d.info;
        N.block<3, 3>(3, 3) += b * b * d.info;
        r.head<3>() += d.info * d.delta;
        r.tail<3>() += b * d.info * d.delta;
      }
      s.normal = N;
      if (static_cast<int>(s.seen.size()) < 3) continue;
      const Eigen::Matrix<double, 6, 1> x = N.ldlt().solve(r);
      if (!x.allFinite()) continue;
      s.c = x.head<3>();
      s.v = x.tail<3>();
    }
    // beta per view given them.
    std::vector<double> num(views.size(), 0.0), den(views.size(), 0.0);
    for (const Sticker& s : stickers) {
      for (const Displacement& d : s.seen) {
        num[d.view] += s.v.dot(d.info * (d.delta - s.c));
        den[d.view] += s.v.dot(d.info * s.v);
      }
    }
    for (size_t k = 0; k < views.size(); ++k) beta[k] = den[k] > 0 ? num[k] / den[k] : 0.0;
    fitted = normalise_beta();
  }
  // The sign: the stickers rise, on average, out of their faces.
  double outward = 0;
  for (const Sticker& s : stickers)
    outward += s.v.dot(s.room_from_marker.rotation * Eigen::Vector3d::UnitZ());
  const double sign = outward < 0 ? -1.0 : 1.0;

  for (Sticker& s : stickers) {
    StickerMotionEstimate e;
    e.marker_id = s.id;
    e.views = static_cast<int>(s.seen.size());
    const Eigen::Vector3d v = sign * s.v;
    if (!fitted) {
      e.why_not = "the views do not follow one time course";
    } else if (e.views < options.min_views) {
      e.why_not = StringPrintf("seen in %d usable views, %d needed", e.views, options.min_views);
    } else {
      // The scatter the motion leaves, and what the motion explains.
      double explained = 0, left = 0;
      for (const Displacement& d : s.seen) {
        const Eigen::Vector3d motion_k = beta[d.view] * s.v;
        const Eigen::Vector3d residual = d.delta - s.c - motion_k;
        explained += motion_k.dot(d.info * motion_k);
        left += residual.dot(d.info * residual);
      }
      e.explained_ratio = left > 0 ? explained / left : std::numeric_limits<double>::infinity();
      // v's covariance: the lower right block of the inverse normal matrix,
      // scaled up by the scatter left when it exceeds what the weights say
      // (the views' own errors, the time course's).
      const double dof = 3.0 * static_cast<double>(s.seen.size()) - 6;
      const Eigen::Matrix<double, 6, 6> cov6 =
          s.normal.inverse() * std::max(1.0, dof > 0 ? left / dof : 1.0);
      const Eigen::Matrix3d cov = cov6.block<3, 3>(3, 3);
      const double motion = v.norm();
      const Eigen::Vector3d u = motion > 0 ? Eigen::Vector3d(v / motion) : Eigen::Vector3d::UnitZ();
      e.motion_m = motion;
      e.motion_sigma_m = std::sqrt(std::max(0.0, u.dot(cov * u)));
      const Eigen::Matrix3d across = Eigen::Matrix3d::Identity() - u * u.transpose();
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(across * cov * across);
      e.direction_sigma_deg =
          motion > 0
              ? kDegPerRad *
                    std::atan2(std::sqrt(std::max(0.0, eig.eigenvalues().maxCoeff())), motion)
              : 90;
      const Eigen::Vector3d in_marker = s.room_from_marker.rotation.inverse() * u;
      const Eigen::Vector3d normal = s.room_from_marker.rotation * Eigen::Vector3d::UnitZ();
      e.normal_share_m = v.dot(normal);
      const double surface_m = normal_motion_m.at(s.id);
      const double normal_sigma_m = std::sqrt(std::max(0.0, normal.dot(cov * normal)));
      e.angle_to_normal_deg = kDegPerRad * std::acos(std::clamp(in_marker.z(), -1.0, 1.0));
      if (!cov.allFinite() || !(motion > options.min_motion_sigmas * e.motion_sigma_m)) {
        e.why_not = StringPrintf("its motion (%.2f mm) under %.0f times its uncertainty (%.2f mm)",
                                 1000 * motion, options.min_motion_sigmas, 1000 * e.motion_sigma_m);
      } else if (!(e.explained_ratio >= options.min_explained_ratio)) {
        e.why_not =
            StringPrintf("its motion explains %.1f times the scatter it leaves, %.1f needed",
                         e.explained_ratio, options.min_explained_ratio);
      } else if (!(normal_sigma_m <= options.max_normal_disagreement * surface_m) ||
                 !(std::abs(e.normal_share_m - surface_m) <=
                   options.max_normal_disagreement * surface_m + 2 * normal_sigma_m)) {
        e.why_not = StringPrintf(
            "its motion along its normal (%.2f +- %.2f mm) disagrees with the surface's (%.2f mm)",
            1000 * e.normal_share_m, 1000 * normal_sigma_m, 1000 * surface_m);
      } else if (!(e.direction_sigma_deg <= options.max_direction_sigma_deg)) {
        e.why_not = StringPrintf("its direction uncertain by %.0f deg", e.direction_sigma_deg);
      } else {
        e.ok = true;
        e.direction_in_marker = in_marker.normalized();
      }
    }
    out.stickers.push_back(e);
  }
  return out;
}

}  // namespace arpos
