#include "room_map/room_planes.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>

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

int PlaneNear(const std::vector<MarkerPlane>& planes, const Eigen::Vector3d& x, double gate_m, double support_m) {
  const double support2 = support_m * support_m;
  for (size_t p = 0; p < planes.size(); ++p) {
    if (std::abs(planes[p].normal.dot(x) - planes[p].offset) > gate_m) continue;
    for (const Eigen::Vector3d& c : planes[p].marker_centres) {
      if ((x - c).squaredNorm() < support2) return static_cast<int>(p);
    }
  }
  return -1;
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
