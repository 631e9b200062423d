#include "features/corner_study.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <random>

#include "features/marker_pose.h"
#include "geometry/so3.h"

namespace arpos::testing {

std::vector<StudyImage> MakeStudyImages(const CameraIntrinsics& camera, int num_images,
                                        int markers_per_image, double min_side_px,
                                        double max_side_px, double max_tilt_deg,
                                        const RenderOptions& render, unsigned seed) {
  std::mt19937 rng(seed);
  std::vector<StudyImage> out;
  for (int i = 0; i < num_images; ++i) {
    const auto placements = RandomPlacements(camera, markers_per_image, min_side_px, max_side_px,
                                             max_tilt_deg, 0.03, 10 * i % 200, &rng);
    StudyImage s;
    s.image = RenderMarkers(camera, placements, render, &rng, &s.truth);
    out.push_back(std::move(s));
  }
  return out;
}

StudyResult RunStudy(const std::vector<StudyImage>& images, const CameraIntrinsics& camera,
                     const MarkerDetectorOptions& options) {
  StudyResult result;
  MarkerDetector detector(options);
  std::vector<MarkerObservation> observations;
  for (const StudyImage& img : images) {
    const auto t0 = std::chrono::steady_clock::now();
    detector.Detect(img.image, &observations);
    result.total_time_ms +=
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    ++result.num_images;
    result.num_truth += static_cast<int>(img.truth.size());
    for (const MarkerObservation& obs : observations) {
      const MarkerTruth* truth = nullptr;
      for (const MarkerTruth& t : img.truth) {
        if (t.id == obs.id) truth = &t;
      }
      if (truth == nullptr) {
        ++result.num_wrong_ids;
        continue;
      }
      MarkerErrors e;
      e.side_px = truth->side_px;
      e.status = obs.status;
      double scale_sum = 0;
      for (int k = 0; k < 4; ++k) {
        const Eigen::Vector2d d = obs.corners_px[k] - truth->corners_px[k];
        e.corner_error_px[k] = d.norm();
        e.mean_offset_px += 0.25 * d;
        scale_sum += (obs.corners_px[k] - truth->centre_px).norm() /
                     (truth->corners_px[k] - truth->centre_px).norm();
      }
      e.scale_bias = scale_sum / 4 - 1;
      const MarkerPose pose = EstimateMarkerPose(obs, truth->size_m, camera);
      if (pose.status != MarkerPoseStatus::kFailed) {
        const Rigid3d err = truth->camera_from_marker.Inverse() * pose.camera_from_marker;
        e.translation_error_mm =
            1000 *
            (pose.camera_from_marker.translation - truth->camera_from_marker.translation).norm();
        e.rotation_error_deg = DegFromRad(RotationAngleRad(err.rotation));
      } else {
        e.translation_error_mm = e.rotation_error_deg = std::nan("");
      }
      result.markers.push_back(e);
    }
  }
  return result;
}

double Percentile(std::vector<double> values, double q) {
  if (values.empty()) return std::nan("");
  std::sort(values.begin(), values.end());
  const double pos = q * (values.size() - 1);
  const size_t lo = static_cast<size_t>(std::floor(pos));
  const size_t hi = std::min(values.size() - 1, lo + 1);
  return values[lo] + (pos - lo) * (values[hi] - values[lo]);
}

Summary Summarise(const StudyResult& result, double min_side_px, double max_side_px,
                  bool precise_only) {
  Summary s;
  std::vector<double> corners, trans, rots;
  double bias_sum = 0;
  for (const MarkerErrors& e : result.markers) {
    if (e.side_px < min_side_px || e.side_px >= max_side_px) continue;
    if (precise_only && e.status != MarkerStatus::kRefined &&
        e.status != MarkerStatus::kNotRefined) {
      continue;
    }
    ++s.count;
    for (double c : e.corner_error_px) corners.push_back(c);
    bias_sum += e.scale_bias;
    s.mean_offset_px += e.mean_offset_px;
    if (std::isfinite(e.translation_error_mm)) {
      trans.push_back(e.translation_error_mm);
      rots.push_back(e.rotation_error_deg);
    }
  }
  if (s.count == 0) return s;
  s.median_px = Percentile(corners, 0.5);
  s.p95_px = Percentile(corners, 0.95);
  s.max_px = Percentile(corners, 1.0);
  s.scale_bias_percent = 100 * bias_sum / s.count;
  s.mean_offset_px /= s.count;
  s.translation_median_mm = Percentile(trans, 0.5);
  s.translation_p95_mm = Percentile(trans, 0.95);
  s.rotation_median_deg = Percentile(rots, 0.5);
  return s;
}

}  // namespace arpos::testing
