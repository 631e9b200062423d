#include "model_import/contour_raster.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "util/check.h"

namespace arpos {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr int kSubRows = 4;

// Newell's normal (length = twice the polygon area for a planar polygon).
Eigen::Vector3d NewellNormal(const std::vector<Eigen::Vector3d>& points) {
  Eigen::Vector3d n = Eigen::Vector3d::Zero();
  const Eigen::Vector3d c = points.front();  // subtract for precision at large coordinates
  for (size_t a = 0; a < points.size(); ++a) {
    const Eigen::Vector3d p = points[a] - c, q = points[(a + 1) % points.size()] - c;
    n += p.cross(q);
  }
  return n;
}

// u, v spanning the plane with normal n (unit), v = n x u; for a normal along
// an axis, u is the next patient axis (x for axial planes).
void PlaneAxes(const Eigen::Vector3d& n, Eigen::Vector3d* u, Eigen::Vector3d* v) {
  int axis = 0;
  n.cwiseAbs().maxCoeff(&axis);
  Eigen::Vector3d seed = Eigen::Vector3d::Zero();
  seed[(axis + 1) % 3] = 1.0;
  if (axis == 2) seed = Eigen::Vector3d::UnitX();
  *u = (seed - n * n.dot(seed)).normalized();
  *v = n.cross(*u);
}

struct Edge2 {
  double x0, y0, x1, y1;
};

// Even-odd area coverage of one plane's polygons on an nx x ny pixel grid
// (pixel (i, j) centred at x = i, y = j in pixel units).
void RasterizePlane(const std::vector<std::vector<Eigen::Vector2d>>& polygons, int nx, int ny,
                    float* out) {
  std::vector<std::vector<int>> bucket(static_cast<size_t>(ny));
  std::vector<Edge2> edges;
  for (const auto& poly : polygons) {
    for (size_t a = 0; a < poly.size(); ++a) {
      const Eigen::Vector2d& p = poly[a];
      const Eigen::Vector2d& q = poly[(a + 1) % poly.size()];
      if (p.y() == q.y()) continue;  // horizontal edges never cross a sub-row
      const int index = static_cast<int>(edges.size());
      edges.push_back({p.x(), p.y(), q.x(), q.y()});
      const int j0 = std::max(0, static_cast<int>(std::floor(std::min(p.y(), q.y()) + 0.5)));
      const int j1 = std::min(ny - 1, static_cast<int>(std::floor(std::max(p.y(), q.y()) + 0.5)));
      for (int j = j0; j <= j1; ++j) bucket[static_cast<size_t>(j)].push_back(index);
    }
  }
  std::vector<double> crossings;
  const float weight = 1.0f / kSubRows;
  for (int j = 0; j < ny; ++j) {
    float* row = out + static_cast<size_t>(j) * nx;
    for (int s = 0; s < kSubRows; ++s) {
      const double y = j - 0.5 + (s + 0.5) / kSubRows;
      crossings.clear();
      for (int e : bucket[static_cast<size_t>(j)]) {
        const Edge2& edge = edges[static_cast<size_t>(e)];
        if ((edge.y0 <= y) == (edge.y1 <= y)) continue;  // half-open: vertices count once
        crossings.push_back(edge.x0 + (y - edge.y0) * (edge.x1 - edge.x0) / (edge.y1 - edge.y0));
      }
      std::sort(crossings.begin(), crossings.end());
      for (size_t c = 0; c + 1 < crossings.size(); c += 2) {
        const double a = std::max(-0.5, crossings[c]);
        const double b = std::min(nx - 0.5, crossings[c + 1]);
        if (!(b > a)) continue;
        const int i0 = static_cast<int>(std::floor(a + 0.5));
        const int i1 = std::min(nx - 1, static_cast<int>(std::floor(b + 0.5)));
        for (int i = i0; i <= i1; ++i) {
          const double overlap = std::min(b, i + 0.5) - std::max(a, i - 0.5);
          if (overlap > 0) row[i] += weight * static_cast<float>(overlap);
        }
      }
    }
  }
  for (size_t n = 0; n < static_cast<size_t>(nx) * ny; ++n) out[n] = std::min(out[n], 1.0f);
}

bool PointInPolygon(const Eigen::Vector2d& p, const std::vector<Eigen::Vector2d>& poly) {
  bool inside = false;
  for (size_t a = 0, b = poly.size() - 1; a < poly.size(); b = a++) {
    if ((poly[a].y() > p.y()) != (poly[b].y() > p.y()) &&
        p.x() < (poly[b].x() - poly[a].x()) * (p.y() - poly[a].y()) / (poly[b].y() - poly[a].y()) +
                    poly[a].x()) {
      inside = !inside;
    }
  }
  return inside;
}

double PolygonArea(const std::vector<Eigen::Vector2d>& poly) {
  double twice = 0;
  for (size_t a = 0, b = poly.size() - 1; a < poly.size(); b = a++) {
    twice += (poly[b].x() - poly[0].x()) * (poly[a].y() - poly[0].y()) -
             (poly[a].x() - poly[0].x()) * (poly[b].y() - poly[0].y());
  }
  return 0.5 * std::abs(twice);
}

}  // namespace

bool ContourRasterOptions::Check(std::string* reason) const {
  if (!(pixel_mm > 0.05) || pixel_mm > 20) {
    *reason = "pixel_mm must be within 0.05..20";
    return false;
  }
  if (max_voxels < 1000) {
    *reason = "max_voxels too small";
    return false;
  }
  if (!(planarity_tolerance_mm > 0) || !(parallel_tolerance_deg > 0)) {
    *reason = "tolerances must be positive";
    return false;
  }
  return true;
}

double EvenOddArea(const std::vector<std::vector<Eigen::Vector3d>>& contours_mm,
                   const Eigen::Vector3d& normal) {
  Eigen::Vector3d u, v;
  PlaneAxes(normal.normalized(), &u, &v);
  std::vector<std::vector<Eigen::Vector2d>> polys;
  for (const auto& c : contours_mm) {
    if (c.size() < 3) continue;
    std::vector<Eigen::Vector2d> poly;
    for (const auto& p : c) poly.emplace_back(u.dot(p), v.dot(p));
    polys.push_back(std::move(poly));
  }
  double area = 0;
  for (size_t a = 0; a < polys.size(); ++a) {
    int depth = 0;
    for (size_t b = 0; b < polys.size(); ++b) {
      if (a != b && PointInPolygon(polys[a].front(), polys[b])) ++depth;
    }
    area += (depth % 2 == 0 ? 1.0 : -1.0) * PolygonArea(polys[a]);
  }
  return area;
}

ContourRasterResult RasterizeContours(const std::vector<std::vector<Eigen::Vector3d>>& contours_mm,
                                      const ContourRasterOptions& options, const std::string& source) {
  std::string reason;
  ARPOS_CHECK(options.Check(&reason), "invalid ContourRasterOptions: " << reason);
  ContourRasterResult result;

  // Usable contours and their normals.
  std::vector<const std::vector<Eigen::Vector3d>*> used;
  std::vector<Eigen::Vector3d> normals;
  for (const auto& c : contours_mm) {
    bool finite = true;
    for (const auto& p : c) finite = finite && p.allFinite();
    if (!finite) ARPOS_INPUT_ERROR(source << ": contour with non-finite coordinates");
    const Eigen::Vector3d n = c.size() >= 3 ? NewellNormal(c) : Eigen::Vector3d::Zero();
    if (c.size() < 3 || n.norm() < 1e-6) {  // < 3 points or no area
      ++result.skipped_degenerate;
      continue;
    }
    used.push_back(&c);
    normals.push_back(n.normalized());
  }
  if (used.empty()) {
    ARPOS_INPUT_ERROR(source << ": no contour with 3 or more points enclosing an area");
  }
  // Common normal: winding decides the sign of each Newell normal, so align
  // them first, then make the largest component positive (+z for axial).
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  for (const auto& n : normals) normal += n.dot(normals.front()) >= 0 ? n : -n;
  normal.normalize();
  int axis = 0;
  normal.cwiseAbs().maxCoeff(&axis);
  if (normal[axis] < 0) normal = -normal;
  const double cos_tol = std::cos(options.parallel_tolerance_deg * kPi / 180.0);
  std::vector<double> offsets;
  for (size_t c = 0; c < used.size(); ++c) {
    if (std::abs(normals[c].dot(normal)) < cos_tol) {
      ARPOS_INPUT_ERROR(source << ": contours are not in parallel planes (one is tilted by "
                               << std::acos(std::min(1.0, std::abs(normals[c].dot(normal)))) * 180 / kPi
                               << " deg)");
    }
    double mean = 0;
    for (const auto& p : *used[c]) mean += normal.dot(p);
    mean /= static_cast<double>(used[c]->size());
    for (const auto& p : *used[c]) {
      if (std::abs(normal.dot(p) - mean) > options.planarity_tolerance_mm) {
        ARPOS_INPUT_ERROR(source << ": a contour is not planar (a point lies "
                                 << std::abs(normal.dot(p) - mean) << " mm off its plane)");
      }
    }
    offsets.push_back(mean);
  }
  result.normal = normal;
  result.num_contours = static_cast<int>(used.size());

  // Distinct planes (offsets within 0.1 mm are one plane).
  std::vector<size_t> order(used.size());
  for (size_t c = 0; c < order.size(); ++c) order[c] = c;
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return offsets[a] < offsets[b]; });
  std::vector<double> plane_offsets;
  std::vector<std::vector<size_t>> plane_members;
  for (size_t c : order) {
    if (plane_offsets.empty() || offsets[c] - plane_offsets.back() > 0.1) {
      plane_offsets.push_back(offsets[c]);
      plane_members.emplace_back();
    }
    plane_members.back().push_back(c);
  }
  result.num_planes = static_cast<int>(plane_offsets.size());
  if (plane_offsets.size() < 2) {
    ARPOS_INPUT_ERROR(source << ": all contours lie in one plane; a surface needs contours on 2 or more slices");
  }
  std::vector<double> gaps;
  for (size_t p = 1; p < plane_offsets.size(); ++p) gaps.push_back(plane_offsets[p] - plane_offsets[p - 1]);
  std::nth_element(gaps.begin(), gaps.begin() + gaps.size() / 2, gaps.end());
  const double spacing = gaps[gaps.size() / 2];
  result.slice_spacing_mm = spacing;
  const int num_slices =
      static_cast<int>(std::lround((plane_offsets.back() - plane_offsets.front()) / spacing)) + 1;
  if (num_slices > 100000) ARPOS_INPUT_ERROR(source << ": contour planes too irregular to stack");

  Eigen::Vector3d u, v;
  PlaneAxes(normal, &u, &v);
  Eigen::Vector2d lo(1e300, 1e300), hi(-1e300, -1e300);
  for (const auto* c : used) {
    for (const auto& p : *c) {
      const Eigen::Vector2d q(u.dot(p), v.dot(p));
      lo = lo.cwiseMin(q);
      hi = hi.cwiseMax(q);
    }
  }
  double pixel = options.pixel_mm;
  const int margin = 2;
  auto grid_size = [&](double pix, int* nx, int* ny) {
    *nx = static_cast<int>(std::ceil((hi.x() - lo.x()) / pix)) + 1 + 2 * margin;
    *ny = static_cast<int>(std::ceil((hi.y() - lo.y()) / pix)) + 1 + 2 * margin;
  };
  int nx = 0, ny = 0;
  grid_size(pixel, &nx, &ny);
  const double voxels = static_cast<double>(nx) * ny * (num_slices + 2);
  if (voxels > static_cast<double>(options.max_voxels)) {
    pixel *= std::sqrt(voxels / static_cast<double>(options.max_voxels)) * 1.01;
    grid_size(pixel, &nx, &ny);
  }
  result.pixel_mm = pixel;

  VolumeGeometry& g = result.coverage.geometry;
  g.size = {nx, ny, num_slices + 2};
  g.spacing_mm = Eigen::Vector3d(pixel, pixel, spacing);
  g.patient_from_index_rotation.col(0) = u;
  g.patient_from_index_rotation.col(1) = v;
  g.patient_from_index_rotation.col(2) = normal;
  const double u0 = lo.x() - margin * pixel, v0 = lo.y() - margin * pixel;
  const double w0 = plane_offsets.front() - spacing;  // one empty slice before the first plane
  g.origin_mm = u * u0 + v * v0 + normal * w0;
  result.coverage.values.assign(g.num_voxels(), 0.0f);

  const size_t slice_size = static_cast<size_t>(nx) * ny;
  int previous_plane = -1;
  for (int k = 1; k <= num_slices; ++k) {
    const double w = w0 + k * spacing;
    const auto it = std::lower_bound(plane_offsets.begin(), plane_offsets.end(), w);
    size_t p = static_cast<size_t>(it - plane_offsets.begin());
    if (p == plane_offsets.size() ||
        (p > 0 && std::abs(plane_offsets[p - 1] - w) < std::abs(plane_offsets[p] - w))) {
      --p;
    }
    if (std::abs(plane_offsets[p] - w) > 0.5 * spacing) ++result.filled_missing_slices;
    float* out = result.coverage.values.data() + static_cast<size_t>(k) * slice_size;
    if (static_cast<int>(p) == previous_plane) {
      std::copy(out - slice_size, out, out);
      continue;
    }
    previous_plane = static_cast<int>(p);
    std::vector<std::vector<Eigen::Vector2d>> polygons;
    for (size_t c : plane_members[p]) {
      std::vector<Eigen::Vector2d> poly;
      for (const auto& q : *used[c]) poly.emplace_back((u.dot(q) - u0) / pixel, (v.dot(q) - v0) / pixel);
      polygons.push_back(std::move(poly));
    }
    RasterizePlane(polygons, nx, ny, out);
  }
  return result;
}

}  // namespace arpos
