#include "room_map/depth_check.h"

#include <algorithm>
#include <cmath>

#include "features/marker_pose.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos {
namespace {

// Ideal pixel -> normalised image coordinates.
Eigen::Vector2d Normalised(const CameraIntrinsics& K, double u, double v) {
  return Eigen::Vector2d((u - K.cx) / K.fx, (v - K.cy) / K.fy);
}

// The median of `values` (reordered); 0 when empty.
double MedianOf(std::vector<double>* values) {
  if (values->empty()) return 0;
  const auto mid = values->begin() + values->size() / 2;
  std::nth_element(values->begin(), mid, values->end());
  return *mid;
}

}  // namespace

std::vector<MarkerPlane> PlanesOfMarkers(const std::vector<Rigid3d>& room_from_marker,
                                         double marker_size_m, int min_markers,
                                         double min_spread_m) {
  std::vector<Eigen::Vector3d> normals, centres;
  std::vector<std::array<Eigen::Vector3d, 4>> corners;
  const std::array<Eigen::Vector3d, 4> in_marker = MarkerCornersInMarker(marker_size_m);
  for (const Rigid3d& m : room_from_marker) {
    normals.push_back(m.rotation * Eigen::Vector3d::UnitZ());
    centres.push_back(m.translation);
    std::array<Eigen::Vector3d, 4> c;
    for (int k = 0; k < 4; ++k) c[k] = m * in_marker[k];
    corners.push_back(c);
  }
  return FindMarkerPlanes(normals, centres, corners, min_markers, min_spread_m);
}

DepthCheckResult CheckDepthAgainstColourGeometry(const BaProblem& problem, const BaOptions& options,
                                                 const DepthCheckInput& input) {
  ARPOS_CHECK(input.intrinsics != nullptr, "the depth check needs the camera's intrinsics");
  const CameraIntrinsics& K = *input.intrinsics;
  // The geometry the colour images give: the same adjustment without depth
  // terms, on a copy (the joint adjustment after the check starts where it
  // would without it; starting it from the depth-free solution measured
  // worse).
  BaOptions vision_options = options;
  vision_options.use_marker_depth = false;
  vision_options.use_keypoint_depth = false;
  BaProblem vision = problem;
  RunBundleAdjustment(&vision, vision_options);
  // Every reading inside a marker against the depth its depth-free pose
  // gives; one group a marker view.
  std::vector<DepthComparison> comparisons, grossly_off;
  for (size_t oi = 0; oi < vision.marker_observations.size(); ++oi) {
    const BaMarkerObservation& o = vision.marker_observations[oi];
    const Rigid3d camera_from_marker =
        vision.camera_from_room[o.camera] * vision.room_from_marker[o.marker];
    const Eigen::Vector3d n = camera_from_marker.rotation * Eigen::Vector3d::UnitZ();
    const double d = n.dot(camera_from_marker.translation);
    for (const DepthSample& sample : o.depth_samples) {
      const Eigen::Vector2d xy = Normalised(K, sample.pixel.x(), sample.pixel.y());
      const double x = xy.x(), y = xy.y();
      const double denom = n.dot(Eigen::Vector3d(x, y, 1));
      if (std::abs(denom) < 0.2 || !(sample.depth_m > 0)) continue;  // grazing
      const double expected = d / denom;
      if (!(expected > 0.1)) continue;
      const DepthComparison comparison{x,
                                       y,
                                       sample.depth_m,
                                       expected,
                                       options.DepthSigmaM(expected),
                                       static_cast<int>(oi),
                                       (o.camera / 5) % 2};
      const bool gross = std::abs(sample.depth_m - expected) > kDepthCheckGrossFraction * expected;
      (gross ? grossly_off : comparisons).push_back(comparison);
    }
  }
  // Gross readings kept only when they are most of them, or agree on one
  // ratio (a wrong depth scale).
  bool leave_out_gross = 2 * grossly_off.size() < comparisons.size() + grossly_off.size();
  if (leave_out_gross && !grossly_off.empty()) {
    std::vector<double> ratio;
    ratio.reserve(grossly_off.size());
    for (const DepthComparison& c : grossly_off) ratio.push_back(c.measured_m / c.expected_m);
    const double median = MedianOf(&ratio);
    for (double& r : ratio) r = std::abs(r - median);
    leave_out_gross = !(1.4826 * MedianOf(&ratio) < kDepthCheckScaleSpread * median &&
                        4 * grossly_off.size() >= comparisons.size() + grossly_off.size());
  }
  if (!leave_out_gross)
    comparisons.insert(comparisons.end(), grossly_off.begin(), grossly_off.end());
  // The depth on the planes the markers span, from the same depth-free
  // geometry: the markers cover a small part of each image, the floor or a
  // wall with markers much of it. Every grid point of a frame's depth within
  // the plane's gate and near one of its markers; one group a frame and
  // plane.
  if (input.plane_support_m > 0 && input.grid != nullptr && !input.grid->px.empty()) {
    ARPOS_CHECK(input.grid_z.size() == vision.camera_from_room.size(),
                "the depth check has " << input.grid_z.size() << " depth grids for "
                                       << vision.camera_from_room.size() << " cameras");
    const std::vector<MarkerPlane> planes =
        PlanesOfMarkers(vision.room_from_marker, input.marker_size_m,
                        std::max(2, input.plane_min_markers), input.plane_min_spread_m);
    const int first_group = static_cast<int>(vision.marker_observations.size());
    for (size_t c = 0; c < vision.camera_from_room.size() && !planes.empty(); ++c) {
      if (input.grid_z[c] == nullptr) continue;
      const std::vector<float>& grid_z = *input.grid_z[c];
      const Rigid3d& camera_from_room = vision.camera_from_room[c];
      const Rigid3d room_from_camera = camera_from_room.Inverse();
      for (size_t i = 0; i < grid_z.size(); ++i) {
        const double z = grid_z[i];
        if (!(z > 0)) continue;
        const Eigen::Vector2d& r = input.grid->ray[i];
        const Eigen::Vector3d ray(r.x(), r.y(), 1);
        const double gate = std::max(input.plane_gate_m, 3 * options.DepthSigmaM(z));
        const int p = PlaneNear(planes, room_from_camera * (z * ray), gate, input.plane_support_m);
        if (p < 0) continue;
        const Eigen::Vector3d n = camera_from_room.rotation * planes[p].normal;
        const double d = planes[p].offset + n.dot(camera_from_room.translation);
        const double denom = n.dot(ray);
        if (std::abs(denom) < 0.2 * ray.norm()) continue;  // grazing
        const double expected = d / denom;
        if (!(expected > 0.1)) continue;
        comparisons.push_back({r.x(), r.y(), z, expected, options.DepthSigmaM(expected),
                               first_group + static_cast<int>(c * planes.size()) + p,
                               static_cast<int>(c / 5) % 2, true});
      }
    }
  }
  DepthCheckResult result;
  result.fit = FitDepthCorrection(comparisons, K);
  result.message = result.fit.message;
  if (leave_out_gross && !grossly_off.empty()) {
    result.readings_left_out = static_cast<int>(grossly_off.size());
    result.message += StringPrintf(
        "; %zu reading(s) inside markers left out, more than %.0f %% off the depth their markers' "
        "poses without depth give (a marker posed wrongly from its colour alone)",
        grossly_off.size(), 100 * kDepthCheckGrossFraction);
  }
  return result;
}

void ApplyDepthCorrection(const DepthCorrection& correction, const CameraIntrinsics& K,
                          BaProblem* problem) {
  auto correct = [&](double z, double u, double v) {
    const Eigen::Vector2d xy = Normalised(K, u, v);
    return correction.TrueDepth(z, xy.x(), xy.y());
  };
  for (BaKeypointObservation& o : problem->keypoint_observations) {
    if (o.depth_m > 0) o.depth_m = correct(o.depth_m, o.pixel.x(), o.pixel.y());
  }
  for (BaMarkerObservation& o : problem->marker_observations) {
    for (DepthSample& sample : o.depth_samples) {
      sample.depth_m =
          static_cast<float>(correct(sample.depth_m, sample.pixel.x(), sample.pixel.y()));
    }
  }
}

}  // namespace arpos
