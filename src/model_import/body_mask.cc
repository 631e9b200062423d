#include "model_import/body_mask.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>

#include "util/check.h"

namespace arpos {
namespace {

}  // namespace

ComponentStats KeepLargestComponent(const VolumeGeometry& g, std::vector<uint8_t>* inside) {
  ARPOS_CHECK(inside->size() == g.num_voxels(), "mask does not match its geometry");
  ARPOS_CHECK(g.num_voxels() < std::numeric_limits<uint32_t>::max(), "volume too large");
  const int nx = g.size[0], ny = g.size[1], nz = g.size[2];
  const size_t sy = static_cast<size_t>(nx), sz = static_cast<size_t>(nx) * ny;
  // States: 0 background, 1 unvisited, 2 visited, 3 in the largest component.
  std::vector<uint8_t>& s = *inside;
  std::vector<uint32_t> queue;
  auto flood = [&](size_t seed, uint8_t from, uint8_t to) {
    queue.clear();
    queue.push_back(static_cast<uint32_t>(seed));
    s[seed] = to;
    for (size_t head = 0; head < queue.size(); ++head) {
      const size_t v = queue[head];
      const int i = static_cast<int>(v % sy), j = static_cast<int>((v / sy) % ny),
                k = static_cast<int>(v / sz);
      auto visit = [&](size_t w) {
        if (s[w] == from) {
          s[w] = to;
          queue.push_back(static_cast<uint32_t>(w));
        }
      };
      if (i > 0) visit(v - 1);
      if (i + 1 < nx) visit(v + 1);
      if (j > 0) visit(v - sy);
      if (j + 1 < ny) visit(v + sy);
      if (k > 0) visit(v - sz);
      if (k + 1 < nz) visit(v + sz);
    }
    return queue.size();
  };
  ComponentStats stats;
  size_t best_size = 0, best_seed = 0, total = 0;
  for (size_t seed = 0; seed < s.size(); ++seed) {
    if (s[seed] != 1) continue;
    ++stats.num_components;
    const size_t size = flood(seed, 1, 2);
    total += size;
    if (size > best_size) {
      stats.second_component_voxels = best_size;
      best_size = size;
      best_seed = seed;
    } else {
      stats.second_component_voxels = std::max(stats.second_component_voxels, size);
    }
  }
  if (best_size > 0) flood(best_seed, 2, 3);
  for (auto& v : s) v = v == 3 ? 1 : 0;
  stats.kept_voxels = best_size;
  stats.dropped_voxels = total - best_size;
  return stats;
}

size_t FillHolesPerSlice(const VolumeGeometry& g, std::vector<uint8_t>* inside) {
  ARPOS_CHECK(inside->size() == g.num_voxels(), "mask does not match its geometry");
  const int nx = g.size[0], ny = g.size[1], nz = g.size[2];
  const size_t slice = static_cast<size_t>(nx) * ny;
  size_t filled = 0;
  cv::Mat padded(ny + 2, nx + 2, CV_8U);
  for (int k = 0; k < nz; ++k) {
    cv::Mat plane(ny, nx, CV_8U, inside->data() + k * slice);
    padded.setTo(0);
    plane.copyTo(padded(cv::Rect(1, 1, nx, ny)));
    // Background reachable from outside the slice (4-connected) is air
    // around the body; what stays 0 is enclosed.
    cv::floodFill(padded, cv::Point(0, 0), cv::Scalar(2), nullptr, cv::Scalar(0), cv::Scalar(0), 4);
    for (int j = 0; j < ny; ++j) {
      const uint8_t* src = padded.ptr<uint8_t>(j + 1) + 1;
      uint8_t* dst = plane.ptr<uint8_t>(j);
      for (int i = 0; i < nx; ++i) {
        if (src[i] == 0) {
          dst[i] = 1;
          ++filled;
        }
      }
    }
  }
  return filled;
}

bool BodyMaskOptions::Check(std::string* reason) const {
  if (!std::isfinite(threshold_hu) || threshold_hu < -1000 || threshold_hu > 500) {
    *reason = "threshold_hu must be within -1000..500 HU";
    return false;
  }
  if (!(opening_radius_mm >= 0) || opening_radius_mm > 50) {
    *reason = "opening_radius_mm must be within 0..50";
    return false;
  }
  return true;
}

BodyMask SegmentBody(const CtVolume& ct, const BodyMaskOptions& options, const std::string& source) {
  std::string reason;
  ARPOS_CHECK(options.Check(&reason), "invalid BodyMaskOptions: " << reason);
  const VolumeGeometry& g = ct.geometry;
  ARPOS_CHECK(ct.hu.size() == g.num_voxels(), "CT volume size mismatch");
  ARPOS_CHECK(g.num_voxels() < std::numeric_limits<uint32_t>::max(), "CT volume too large");
  BodyMask mask;
  mask.geometry = g;
  std::vector<uint8_t> state(g.num_voxels());
  for (size_t n = 0; n < state.size(); ++n) {
    state[n] = ct.hu[n] >= options.threshold_hu ? 1 : 0;
    mask.thresholded_voxels += state[n];
  }
  if (mask.thresholded_voxels == 0) {
    ARPOS_INPUT_ERROR(source << ": no voxel reaches " << options.threshold_hu
                             << " HU: no body in this CT (or a wrong --threshold-hu)");
  }
  const int nx = g.size[0], ny = g.size[1], nz = g.size[2];
  const size_t slice = static_cast<size_t>(nx) * ny;
  if (options.opening_radius_mm > 0) {
    // Disc in millimetres: an ellipse in pixels when the pixels are not square.
    const int rx = static_cast<int>(std::round(options.opening_radius_mm / g.spacing_mm.x()));
    const int ry = static_cast<int>(std::round(options.opening_radius_mm / g.spacing_mm.y()));
    if (rx > 0 || ry > 0) {
      const cv::Mat element =
          cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * rx + 1, 2 * ry + 1));
      for (int k = 0; k < nz; ++k) {
        cv::Mat plane(ny, nx, CV_8U, state.data() + k * slice);
        // Border value 0: the body touching the edge of the field of view is
        // eroded there too, like everywhere else (then dilated back).
        cv::morphologyEx(plane, plane, cv::MORPH_OPEN, element, cv::Point(-1, -1), 1,
                         cv::BORDER_CONSTANT, cv::Scalar(0));
      }
    }
  }
  size_t opened = 0;
  for (uint8_t v : state) opened += v;
  if (opened == 0) {
    ARPOS_INPUT_ERROR(source << ": nothing is left after removing structures thinner than "
                             << 2 * options.opening_radius_mm << " mm: no body in this CT");
  }
  const ComponentStats components = KeepLargestComponent(g, &state);
  mask.num_components = components.num_components;
  mask.dropped_voxels = components.dropped_voxels;
  mask.second_component_voxels = components.second_component_voxels;
  mask.inside = std::move(state);
  if (options.fill_holes) mask.filled_hole_voxels = FillHolesPerSlice(g, &mask.inside);
  for (uint8_t v : mask.inside) mask.body_voxels += v;
  return mask;
}

ScalarVolume BodySurfaceField(const CtVolume& ct, const BodyMask& mask, double threshold_hu,
                              double* iso_value) {
  const VolumeGeometry& g = ct.geometry;
  ARPOS_CHECK(mask.inside.size() == g.num_voxels(), "mask does not match the CT");
  int lo[3] = {g.size[0], g.size[1], g.size[2]}, hi[3] = {-1, -1, -1};
  for (int k = 0; k < g.size[2]; ++k) {
    for (int j = 0; j < g.size[1]; ++j) {
      const uint8_t* row = mask.inside.data() + g.Index(0, j, k);
      for (int i = 0; i < g.size[0]; ++i) {
        if (!row[i]) continue;
        const int ijk[3] = {i, j, k};
        for (int a = 0; a < 3; ++a) {
          lo[a] = std::min(lo[a], ijk[a]);
          hi[a] = std::max(hi[a], ijk[a]);
        }
      }
    }
  }
  ARPOS_CHECK(hi[0] >= 0, "empty body mask");
  const float inside_min = static_cast<float>(std::ceil(threshold_hu));
  const float outside_max = inside_min - 1.0f;
  *iso_value = inside_min - 0.5;
  ScalarVolume field;
  field.geometry = g;
  for (int a = 0; a < 3; ++a) field.geometry.size[a] = hi[a] - lo[a] + 3;  // one padding voxel per side
  field.geometry.origin_mm = g.PatientFromIndexMm(Eigen::Vector3d(lo[0] - 1, lo[1] - 1, lo[2] - 1));
  const float padding = std::min(-1024.0f, outside_max);
  field.values.assign(field.geometry.num_voxels(), padding);
  for (int k = lo[2]; k <= hi[2]; ++k) {
    for (int j = lo[1]; j <= hi[1]; ++j) {
      for (int i = lo[0]; i <= hi[0]; ++i) {
        const size_t n = g.Index(i, j, k);
        const float hu = ct.hu[n];
        field.values[field.geometry.Index(i - lo[0] + 1, j - lo[1] + 1, k - lo[2] + 1)] =
            mask.inside[n] ? std::max(hu, inside_min) : std::min(hu, outside_max);
      }
    }
  }
  // Where the body is cut by the end of the scan (or the edge of the field of
  // view) the padding decides where the cap lies. A constant padding would put
  // it at a tissue-dependent fraction of a voxel (bone reaches further than
  // fat); mirroring the inner value about the iso-value puts the cap exactly
  // half a voxel beyond the last sample, everywhere.
  const float iso = static_cast<float>(*iso_value);
  VolumeGeometry& fg = field.geometry;
  for (int axis = 0; axis < 3; ++axis) {
    const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
    for (int side = 0; side < 2; ++side) {
      const int pad = side == 0 ? 0 : fg.size[axis] - 1;
      const int inner = side == 0 ? 1 : fg.size[axis] - 2;
      for (int u = 1; u + 1 < fg.size[a1]; ++u) {
        for (int w = 1; w + 1 < fg.size[a2]; ++w) {
          int p[3], q[3];
          p[axis] = pad;
          q[axis] = inner;
          p[a1] = q[a1] = u;
          p[a2] = q[a2] = w;
          const float inside_value = field.values[fg.Index(q[0], q[1], q[2])];
          if (inside_value > iso) field.values[fg.Index(p[0], p[1], p[2])] = 2 * iso - inside_value;
        }
      }
    }
  }
  return field;
}

}  // namespace arpos
