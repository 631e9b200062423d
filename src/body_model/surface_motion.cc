#include "body_model/surface_motion.h"

#include <algorithm>
#include <cmath>
#include <sstream>


#include "geometry/cube_grid.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos {
namespace {

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  const size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + mid, v.end());
  return v[mid];
}

// Per frame, per patch: the sum and count of signed distances.
struct Cell {
  double sum = 0;  ///< then the mean
  int count = 0;
};
using FramePatches = std::unordered_map<uint64_t, Cell>;

}  // namespace

std::string SurfaceMotionOptions::Validate() const {
  std::ostringstream out;
  if (!(patch_m > 0)) out << "patch_m must be positive";
  else if (!(max_distance_m > 0)) out << "max_distance_m must be positive";
  else if (stride < 1) out << "stride must be at least 1";
  else if (min_points_per_patch < 1) out << "min_points_per_patch must be at least 1";
  else if (min_frames_per_patch < 2) out << "min_frames_per_patch must be at least 2";
  else if (!(min_motion_sigmas > 0)) out << "min_motion_sigmas must be positive";
  else if (!(min_motion_m >= 0)) out << "min_motion_m must be non-negative";
  return out.str();
}

uint64_t SurfacePatchKey(const Eigen::Vector3d& p, double patch_m) { return CubeKey(p, patch_m); }

bool SurfaceMotion::IsMoving(const Eigen::Vector3d& point_in_model) const {
  if (!measured) return false;
  const auto it = patch_by_key.find(SurfacePatchKey(point_in_model, patch_m));
  return it != patch_by_key.end() && it->second.moving;
}

double SurfaceMotion::MotionAt(const Eigen::Vector3d& point_in_model) const {
  if (!measured) return 0;
  const auto it = patch_by_key.find(SurfacePatchKey(point_in_model, patch_m));
  return it != patch_by_key.end() && it->second.moving ? it->second.motion_m : 0;
}

std::vector<Eigen::Vector3d> SurfaceMotion::MovingPatchCentres() const {
  std::vector<uint64_t> keys;
  for (const auto& [key, patch] : patch_by_key) {
    if (measured && patch.moving) keys.push_back(key);
  }
  std::sort(keys.begin(), keys.end());
  std::vector<Eigen::Vector3d> centres;
  for (const uint64_t key : keys) centres.push_back(CubeCentre(key, patch_m));
  return centres;
}

std::string SurfaceMotion::Describe() const {
  if (!measured) {
    return StringPrintf("surface motion not measured (%d frames, %d patches seen often enough)", frames, patches);
  }
  if (moving_patches == 0) {
    return StringPrintf("no part of the surface moved during the scan (%d patches over %d frames, %.2f mm spread)",
                        patches, frames, 1000 * median_spread_m);
  }
  return StringPrintf(
      "%d of %d surface patches moved during the scan (breathing: %.1f mm spread, up to %.1f mm peak to peak, "
      "against %.2f mm where still; %d frames)",
      moving_patches, patches, 1000 * moving_mean_spread_m, 1000 * moving_peak_to_peak_m, 1000 * median_spread_m,
      frames);
}

SurfaceMotion MeasureSurfaceMotion(const std::vector<SurfaceMotionFrame>& frames, const PointCloud& model_surface,
                                   const KdTree& model_tree, const Rigid3d& model_from_room,
                                   const SurfaceMotionOptions& options) {
  const std::string problem = options.Validate();
  ARPOS_CHECK(problem.empty(), "surface motion: " << problem);
  ARPOS_CHECK(model_surface.has_normals(), "surface motion: the reference surface needs normals");
  SurfaceMotion out;
  out.patch_m = options.patch_m;
  const double max_sq = options.max_distance_m * options.max_distance_m;

  // 1. Per frame, per patch: the mean signed distance from the surface.
  std::vector<FramePatches> per_frame(frames.size());
  for (size_t f = 0; f < frames.size(); ++f) {
    if (frames[f].cloud_in_camera == nullptr) continue;
    const PointCloud& cloud = *frames[f].cloud_in_camera;
    const Rigid3d model_from_camera = model_from_room * frames[f].room_from_camera;
    const Eigen::Matrix3d R = model_from_camera.rotation.toRotationMatrix();
    FramePatches& patches = per_frame[f];
    for (size_t i = 0; i < cloud.size(); i += static_cast<size_t>(options.stride)) {
      const Eigen::Vector3d p = R * cloud.point3(i) + model_from_camera.translation;
      size_t nearest = 0;
      double sq = 0;
      if (!model_tree.Nearest(Eigen::Vector4d(p.x(), p.y(), p.z(), 1), &nearest, &sq, max_sq)) continue;
      const Eigen::Vector3d q = model_surface.point3(nearest);
      Cell& c = patches[SurfacePatchKey(q, options.patch_m)];
      c.sum += model_surface.normal3(nearest).dot(p - q);
      ++c.count;
    }
    for (auto it = patches.begin(); it != patches.end();) {
      if (it->second.count < options.min_points_per_patch) {
        it = patches.erase(it);
      } else {
        it->second.sum /= it->second.count;  // now the mean
        ++it;
      }
    }
    if (!patches.empty()) ++out.frames;
  }

  // 2. Each frame's offset (its registration error along the surface) is
  //    the median over its still patches; what is left of a patch, frame by
  //    frame, is its motion plus noise. Breathing moves every moving patch
  //    with one time course b(t), each by its own share w: per patch, the
  //    least-squares w against b and its standard error; b from the patches
  //    that move, alternately (rank one, missing entries allowed). A patch
  //    moved when w b is both large (min_motion_m, 1 sigma over the frames)
  //    and well determined (min_motion_sigmas). Two rounds: the second takes
  //    the frames' offsets from the patches the first found still.
  std::unordered_map<uint64_t, bool> moving;
  for (int pass = 0; pass < 2; ++pass) {
    // Residual per patch, per frame (frame index, value).
    std::unordered_map<uint64_t, std::vector<std::pair<int, double>>> series;
    for (size_t f = 0; f < frames.size(); ++f) {
      std::vector<double> still;
      for (const auto& [key, c] : per_frame[f]) {
        const auto m = moving.find(key);
        if (m == moving.end() || !m->second) still.push_back(c.sum);
      }
      const double offset = Median(still);
      for (const auto& [key, c] : per_frame[f]) series[key].emplace_back(static_cast<int>(f), c.sum - offset);
    }
    // Centre each patch's series; keep patches seen often enough.
    std::vector<uint64_t> keys;
    for (auto it = series.begin(); it != series.end();) {
      if (static_cast<int>(it->second.size()) < options.min_frames_per_patch) {
        it = series.erase(it);
        continue;
      }
      double mean = 0;
      for (const auto& [f, v] : it->second) mean += v;
      mean /= static_cast<double>(it->second.size());
      for (auto& [f, v] : it->second) v -= mean;
      keys.push_back(it->first);
      ++it;
    }
    std::sort(keys.begin(), keys.end());  // deterministic order
    // Start b from the patches that vary most.
    std::vector<double> spread(keys.size(), 0);
    for (size_t k = 0; k < keys.size(); ++k) {
      double var = 0;
      for (const auto& [f, v] : series[keys[k]]) var += v * v;
      spread[k] = std::sqrt(var / static_cast<double>(series[keys[k]].size() - 1));
    }
    std::vector<double> w(keys.size(), 0);
    {
      std::vector<double> sorted = spread;
      std::sort(sorted.begin(), sorted.end());
      const double top = sorted.empty() ? 0 : sorted[sorted.size() * 4 / 5];
      for (size_t k = 0; k < keys.size(); ++k) w[k] = spread[k] >= top ? 1 : 0;
    }
    std::vector<double> b(frames.size(), 0);
    for (int iteration = 0; iteration < 10; ++iteration) {
      std::vector<double> num(frames.size(), 0), den(frames.size(), 0);
      for (size_t k = 0; k < keys.size(); ++k) {
        for (const auto& [f, v] : series[keys[k]]) {
          num[f] += w[k] * v;
          den[f] += w[k] * w[k];
        }
      }
      double rms = 0;
      int n = 0;
      for (size_t f = 0; f < frames.size(); ++f) {
        b[f] = den[f] > 0 ? num[f] / den[f] : 0;
        if (den[f] > 0) rms += b[f] * b[f], ++n;
      }
      rms = n > 0 ? std::sqrt(rms / n) : 0;
      if (!(rms > 0)) break;
      for (double& v : b) v /= rms;
      for (size_t k = 0; k < keys.size(); ++k) {
        double bv = 0, bb = 0;
        for (const auto& [f, v] : series[keys[k]]) bv += b[f] * v, bb += b[f] * b[f];
        w[k] = bb > 0 ? bv / bb : 0;
      }
    }
    out.patch_by_key.clear();
    std::vector<double> spreads;
    for (size_t k = 0; k < keys.size(); ++k) {
      const auto& s = series[keys[k]];
      double bb = 0, rr = 0, lo = 0, hi = 0;
      for (const auto& [f, v] : s) {
        bb += b[f] * b[f];
        const double r = v - w[k] * b[f];
        rr += r * r;
        lo = std::min(lo, v), hi = std::max(hi, v);
      }
      SurfaceMotion::Patch patch;
      patch.spread_m = spread[k];
      patch.range_m = hi - lo;
      patch.frames = static_cast<int>(s.size());
      patch.motion_m = std::abs(w[k]) * std::sqrt(bb / static_cast<double>(s.size()));
      const double se = bb > 0 ? std::sqrt(rr / std::max<double>(1, static_cast<double>(s.size()) - 1) / bb) : 0;
      patch.motion_sigmas = se > 0 ? std::abs(w[k]) / se : 0;
      out.patch_by_key[keys[k]] = patch;
      spreads.push_back(patch.spread_m);
    }
    out.patches = static_cast<int>(out.patch_by_key.size());
    out.median_spread_m = Median(spreads);
    moving.clear();
    out.moving_patches = 0;
    out.moving_mean_spread_m = out.moving_peak_to_peak_m = 0;
    for (auto& [key, patch] : out.patch_by_key) {
      patch.moving = patch.motion_m > options.min_motion_m && patch.motion_sigmas > options.min_motion_sigmas;
      moving[key] = patch.moving;
      if (!patch.moving) continue;
      ++out.moving_patches;
      out.moving_mean_spread_m += patch.motion_m;
      out.moving_peak_to_peak_m = std::max(out.moving_peak_to_peak_m, patch.range_m);
    }
    if (out.moving_patches > 0) out.moving_mean_spread_m /= out.moving_patches;
  }
  // Telling needs frames to compare and patches to compare with.
  out.measured = out.frames >= options.min_frames_per_patch && out.patches >= 8;
  if (!out.measured) {
    for (auto& [key, patch] : out.patch_by_key) patch.moving = false;
    out.moving_patches = 0;
  }
  return out;
}

}  // namespace arpos
