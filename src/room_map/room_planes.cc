#include "room_map/room_planes.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <random>
#include <unordered_map>
#include <unordered_set>

#include "geometry/so3.h"

namespace arpos {

std::optional<WeightedPlane> FitWeightedPlane(const std::vector<Eigen::Vector3d>& points,
                                              const std::vector<double>& weights) {
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  double wsum = 0;
  for (size_t i = 0; i < points.size(); ++i) centroid += weights[i] * points[i], wsum += weights[i];
  if (!(wsum > 0)) return std::nullopt;
  centroid /= wsum;
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (size_t i = 0; i < points.size(); ++i) {
    scatter += weights[i] * (points[i] - centroid) * (points[i] - centroid).transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(scatter / wsum);
  return WeightedPlane{centroid, eig.eigenvectors().col(0).normalized(), eig.eigenvalues()};
}

std::vector<MarkerPlane> FindMarkerPlanes(const std::vector<Eigen::Vector3d>& normals,
                                          const std::vector<Eigen::Vector3d>& centres,
                                          const std::vector<std::array<Eigen::Vector3d, 4>>& corners,
                                          int min_markers, double min_spread_m) {
  std::vector<MarkerPlane> planes;
  const size_t n = normals.size();
  std::vector<bool> used(n, false);
  const double cos_tol = std::cos(RadFromDeg(3.0));
  while (true) {
    std::vector<size_t> best;
    for (size_t i = 0; i < n; ++i) {
      if (used[i]) continue;
      const double di = normals[i].dot(centres[i]);
      std::vector<size_t> group;
      for (size_t j = 0; j < n; ++j) {
        if (used[j]) continue;
        if (normals[i].dot(normals[j]) < cos_tol) continue;
        if (std::abs(normals[i].dot(centres[j]) - di) > 0.02) continue;
        group.push_back(j);
      }
      if (group.size() > best.size()) best = group;
    }
    if (static_cast<int>(best.size()) < min_markers) break;
    std::vector<Eigen::Vector3d> points;
    for (size_t j : best) {
      used[j] = true;
      points.insert(points.end(), corners[j].begin(), corners[j].end());
    }
    const WeightedPlane fit = *FitWeightedPlane(points, std::vector<double>(points.size(), 1.0));
    if (std::sqrt(std::max(0.0, fit.spread2(1))) < min_spread_m) continue;
    MarkerPlane plane;
    plane.normal = fit.normal;
    if (plane.normal.dot(normals[best.front()]) < 0) plane.normal = -plane.normal;
    plane.offset = plane.normal.dot(fit.centroid);
    for (size_t j : best) {
      plane.marker_centres.push_back(centres[j]);
      plane.markers.push_back(static_cast<int>(j));
    }
    planes.push_back(std::move(plane));
  }
  return planes;
}

namespace {

// The key of the cell with integer index `i` (21 bits an axis: +-104 km at
// 0.1 m).
int64_t PackCell(const Eigen::Vector3i& i) {
  auto axis = [](int v) { return static_cast<int64_t>(v) & ((int64_t{1} << 21) - 1); };
  return (axis(i.x()) << 42) | (axis(i.y()) << 21) | axis(i.z());
}

Eigen::Vector3i CellIndex(const Eigen::Vector3d& x, double cell_m) {
  return (x / cell_m).array().floor().cast<int>();
}

}  // namespace

int64_t CellKey(const Eigen::Vector3d& x, double cell_m) { return PackCell(CellIndex(x, cell_m)); }

int PlaneNear(const std::vector<MarkerPlane>& planes, const Eigen::Vector3d& x, double gate_m, double support_m) {
  const double support2 = support_m * support_m;
  for (size_t p = 0; p < planes.size(); ++p) {
    if (std::abs(planes[p].normal.dot(x) - planes[p].offset) > gate_m) continue;
    for (const Eigen::Vector3d& c : planes[p].marker_centres) {
      if ((x - c).squaredNorm() < support2) return static_cast<int>(p);
    }
    if (!planes[p].cells.empty() && planes[p].cells.count(CellKey(x, planes[p].cell_m))) return static_cast<int>(p);
  }
  return -1;
}

namespace {

struct Cell {
  Eigen::Vector3i index;
  int64_t key = 0;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  int count = 0;
  std::vector<int> views;  // distinct, ascending as the points come
  Eigen::Vector3d centroid() const { return sum / count; }
};

}  // namespace

int AddDepthPlanes(const std::vector<Eigen::Vector3d>& points, const std::vector<int>& views,
                   const DepthPlaneOptions& options, std::vector<MarkerPlane>* planes) {
  const double s = options.cell_m;
  std::unordered_map<int64_t, size_t> slot;
  std::vector<Cell> cells;
  for (size_t i = 0; i < points.size(); ++i) {
    if (!points[i].allFinite()) continue;
    const Eigen::Vector3i index = CellIndex(points[i], s);
    const int64_t key = PackCell(index);
    auto [it, fresh] = slot.emplace(key, cells.size());
    if (fresh) {
      cells.emplace_back();
      cells.back().index = index;
      cells.back().key = key;
    }
    Cell& c = cells[it->second];
    c.sum += points[i];
    ++c.count;
    if (std::find(c.views.begin(), c.views.end(), views[i]) == c.views.end()) c.views.push_back(views[i]);
  }
  std::vector<size_t> live;  // cells with enough points, not yet in a plane
  for (size_t i = 0; i < cells.size(); ++i) {
    if (cells[i].count >= options.min_points_per_cell) live.push_back(i);
  }
  std::mt19937 rng(20261203u);
  int appended = 0, found = 0;
  const double cos_merge = std::cos(RadFromDeg(options.merge_deg));
  for (int round = 0; round < 3 * options.max_planes && found < options.max_planes && live.size() >= 3; ++round) {
    // RANSAC over the live cells' centroids, a vote a cell.
    std::uniform_int_distribution<size_t> pick(0, live.size() - 1);
    Eigen::Vector3d best_n = Eigen::Vector3d::Zero();
    double best_d = 0, best_score = 0;
    for (int it = 0; it < options.iterations; ++it) {
      const Eigen::Vector3d a = cells[live[pick(rng)]].centroid(), b = cells[live[pick(rng)]].centroid(),
                            c = cells[live[pick(rng)]].centroid();
      Eigen::Vector3d n = (b - a).cross(c - a);
      if (!(n.norm() > 1e-2 * s * s)) continue;
      n.normalize();
      const double d = n.dot(a);
      double score = 0;
      for (size_t k : live) {
        if (std::abs(n.dot(cells[k].centroid()) - d) < options.gate_m) score += 1;
      }
      if (score > best_score) best_score = score, best_n = n, best_d = d;
    }
    if (best_score < 3) break;
    // Fitted to its cells, twice; then the largest connected patch.
    std::vector<size_t> in;
    for (int pass = 0; pass < 2; ++pass) {
      in.clear();
      std::vector<Eigen::Vector3d> pts;
      std::vector<double> w;
      for (size_t k : live) {
        if (std::abs(best_n.dot(cells[k].centroid()) - best_d) < options.gate_m) {
          in.push_back(k);
          pts.push_back(cells[k].centroid());
          w.push_back(cells[k].count);
        }
      }
      const std::optional<WeightedPlane> fit = FitWeightedPlane(pts, w);
      if (!fit) break;
      best_n = fit->normal.dot(best_n) < 0 ? Eigen::Vector3d(-fit->normal) : fit->normal;
      best_d = best_n.dot(fit->centroid);
    }
    std::unordered_map<int64_t, size_t> in_slot;
    for (size_t k : in) in_slot.emplace(cells[k].key, k);
    std::unordered_set<int64_t> component;  // cells already in a patch
    std::vector<size_t> patch;
    for (size_t k : in) {
      if (!component.insert(cells[k].key).second) continue;
      std::vector<size_t> members, stack{k};
      while (!stack.empty()) {
        const size_t m = stack.back();
        stack.pop_back();
        members.push_back(m);
        for (int dx = -1; dx <= 1; ++dx) {
          for (int dy = -1; dy <= 1; ++dy) {
            for (int dz = -1; dz <= 1; ++dz) {
              const int64_t key = PackCell(cells[m].index + Eigen::Vector3i(dx, dy, dz));
              auto found_cell = in_slot.find(key);
              if (found_cell == in_slot.end() || !component.insert(key).second) continue;
              stack.push_back(found_cell->second);
            }
          }
        }
      }
      if (members.size() > patch.size()) patch = std::move(members);
    }
    // Whatever the outcome, the plane's cells leave the pool.
    std::unordered_set<size_t> taken(in.begin(), in.end());
    live.erase(std::remove_if(live.begin(), live.end(), [&](size_t k) { return taken.count(k) > 0; }), live.end());
    std::vector<Eigen::Vector3d> pts;
    std::vector<int> seen_by;
    for (size_t k : patch) {
      pts.push_back(cells[k].centroid());
      seen_by.insert(seen_by.end(), cells[k].views.begin(), cells[k].views.end());
    }
    std::sort(seen_by.begin(), seen_by.end());
    seen_by.erase(std::unique(seen_by.begin(), seen_by.end()), seen_by.end());
    // The patch's extent: each cell once, however many points it holds.
    const std::optional<WeightedPlane> fit = FitWeightedPlane(pts, std::vector<double>(pts.size(), 1.0));
    if (!fit || static_cast<int>(seen_by.size()) < options.min_views) continue;
    const double narrow = std::sqrt(std::max(0.0, fit->spread2(1))) * std::sqrt(12.0);
    if (narrow < options.min_extent_m) continue;
    ++found;
    // The same plane as one given: its markers on the patch's plane, or (a
    // plane of depth alone) the patch's centroid on it. A plane that may not
    // be extended (the origin's: its marker is tied to it, and the far
    // reaches of a wall or floor, seen at the end of the depth's range, would
    // turn the room frame) is passed over; the patch is appended instead.
    const double best_off = best_n.dot(fit->centroid);
    MarkerPlane* target = nullptr;
    for (MarkerPlane& p : *planes) {
      if (std::abs(p.normal.dot(best_n)) < cos_merge || !p.extend_in_depth) continue;
      bool on = true;
      for (const Eigen::Vector3d& c : p.marker_centres) on = on && std::abs(best_n.dot(c) - best_off) < options.merge_m;
      if (p.marker_centres.empty()) on = std::abs(p.normal.dot(fit->centroid) - p.offset) < options.merge_m;
      if (on) {
        target = &p;
        break;
      }
    }
    if (!target) {
      MarkerPlane p;
      p.normal = best_n;
      p.offset = best_off;
      planes->push_back(std::move(p));
      target = &planes->back();
      ++appended;
    }
    if (target->cells.empty()) target->cell_m = s;
    const double cs = target->cell_m;
    for (size_t k : patch) {
      const Eigen::Vector3d c = cells[k].centroid();
      for (int dx = -1; dx <= 1; ++dx) {
        for (int dy = -1; dy <= 1; ++dy) {
          for (int dz = -1; dz <= 1; ++dz) target->cells.insert(CellKey(c + Eigen::Vector3d(dx, dy, dz) * cs, cs));
        }
      }
    }
  }
  return appended;
}

std::vector<size_t> PointsOnViewedPlane(const std::vector<Eigen::Vector3d>& points,
                                        const std::vector<double>& sigma_z, Eigen::Vector3d n, double d) {
  std::vector<double> weight(points.size());
  for (int pass = 0; pass < 3; ++pass) {
    for (size_t k = 0; k < points.size(); ++k) {
      const double across = sigma_z[k] * std::abs(n.dot(points[k].normalized()));
      const bool in = std::abs(n.dot(points[k]) - d) < 2.5 * std::max(across, 1e-3);
      weight[k] = in ? 1.0 / (across * across + 1e-6) : 0.0;
    }
    const std::optional<WeightedPlane> fit = FitWeightedPlane(points, weight);
    if (!fit) break;
    Eigen::Vector3d fitted = fit->normal;
    if (fitted.dot(n) < 0) fitted = -fitted;
    if (fitted.dot(n) < std::cos(RadFromDeg(5.0))) break;  // not the mapped plane
    n = fitted;
    d = n.dot(fit->centroid);
  }
  std::vector<size_t> kept;
  for (size_t k = 0; k < points.size(); ++k) {
    if (weight[k] > 0) kept.push_back(k);
  }
  return kept;
}

}  // namespace arpos
