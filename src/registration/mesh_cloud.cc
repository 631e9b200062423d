#include "registration/mesh_cloud.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include "util/check.h"

namespace arpos {

PointCloud SampleMeshSurface(const TriangleMesh& mesh, double spacing_m, uint64_t seed) {
  ARPOS_CHECK(spacing_m > 0, "SampleMeshSurface: spacing must be positive");
  std::vector<double> cumulative;
  std::vector<int> faces;
  double total = 0;
  for (size_t f = 0; f < mesh.faces.size(); ++f) {
    const Eigen::Vector3i& face = mesh.faces[f];
    const Eigen::Vector3d a = mesh.vertices[face[0]].cast<double>();
    const Eigen::Vector3d b = mesh.vertices[face[1]].cast<double>();
    const Eigen::Vector3d c = mesh.vertices[face[2]].cast<double>();
    const double area = 0.5 * (b - a).cross(c - a).norm();
    if (!(area > 0)) continue;
    total += area;
    cumulative.push_back(total);
    faces.push_back(static_cast<int>(f));
  }
  PointCloud cloud;
  if (faces.empty()) return cloud;
  const size_t count = static_cast<size_t>(std::ceil(total / (spacing_m * spacing_m)));
  std::mt19937_64 rng(seed);
  auto uniform = [&rng] { return static_cast<double>(rng() >> 11) * (1.0 / 9007199254740992.0); };
  cloud.points.reserve(count);
  cloud.normals.reserve(count);
  for (size_t i = 0; i < count; ++i) {
    const double pick = uniform() * total;
    const size_t k = std::min<size_t>(
        std::upper_bound(cumulative.begin(), cumulative.end(), pick) - cumulative.begin(),
        faces.size() - 1);
    const Eigen::Vector3i& face = mesh.faces[faces[k]];
    const Eigen::Vector3d a = mesh.vertices[face[0]].cast<double>();
    const Eigen::Vector3d b = mesh.vertices[face[1]].cast<double>();
    const Eigen::Vector3d c = mesh.vertices[face[2]].cast<double>();
    double u = uniform(), v = uniform();
    if (u + v > 1) {
      u = 1 - u;
      v = 1 - v;
    }
    const Eigen::Vector3d p = a + u * (b - a) + v * (c - a);
    const Eigen::Vector3d n = (b - a).cross(c - a).normalized();
    cloud.points.emplace_back(p.x(), p.y(), p.z(), 1.0);
    cloud.normals.emplace_back(n.x(), n.y(), n.z(), 0.0);
  }
  return cloud;
}

Eigen::Vector3d ClosestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                       const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double denom = d1 - d3;
    return denom > 0 ? Eigen::Vector3d(a + (d1 / denom) * ab) : a;
  }
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double denom = d2 - d6;
    return denom > 0 ? Eigen::Vector3d(a + (d2 / denom) * ac) : a;
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double denom = (d4 - d3) + (d5 - d6);
    return denom > 0 ? Eigen::Vector3d(b + ((d4 - d3) / denom) * (c - b)) : b;
  }
  const double sum = va + vb + vc;
  if (!(std::abs(sum) > 0)) return a;
  const double v = vb / sum, w = vc / sum;
  return a + ab * v + ac * w;
}

MeshDistance::MeshDistance(const TriangleMesh& mesh) {
  std::vector<Eigen::Vector3d> centroids;
  for (const auto& face : mesh.faces) {
    const Eigen::Vector3d a = mesh.vertices[face[0]].cast<double>();
    const Eigen::Vector3d b = mesh.vertices[face[1]].cast<double>();
    const Eigen::Vector3d c = mesh.vertices[face[2]].cast<double>();
    const Eigen::Vector3d centroid = (a + b + c) / 3.0;
    a_.push_back(a);
    b_.push_back(b);
    c_.push_back(c);
    centroids.push_back(centroid);
    max_radius_m_ = std::max({max_radius_m_, (a - centroid).norm(), (b - centroid).norm(),
                              (c - centroid).norm()});
  }
  centroid_tree_ = KdTree(centroids);
}

double MeshDistance::Distance(const Eigen::Vector3d& point, Eigen::Vector3d* closest) const {
  if (a_.empty()) return std::numeric_limits<double>::infinity();
  // A first bound from the nearest centroids, then every face whose centroid
  // could still hold a closer point (within bound + the largest face radius).
  constexpr int kFirst = 8;
  size_t idx[kFirst];
  double sq[kFirst];
  const Eigen::Vector4d q(point.x(), point.y(), point.z(), 1.0);
  const size_t found = centroid_tree_.Knn(q, kFirst, idx, sq);
  double best = std::numeric_limits<double>::infinity();
  Eigen::Vector3d best_point = point;
  auto consider = [&](size_t f) {
    const Eigen::Vector3d c = ClosestPointOnTriangle(point, a_[f], b_[f], c_[f]);
    const double d = (c - point).norm();
    if (d < best) {
      best = d;
      best_point = c;
    }
  };
  for (size_t k = 0; k < found; ++k) consider(idx[k]);
  std::vector<size_t> candidates;
  centroid_tree_.RadiusSearch(q, best + max_radius_m_, &candidates);
  for (size_t f : candidates) consider(f);
  if (closest) *closest = best_point;
  return best;
}

std::vector<double> MeshDistance::Distances(const PointCloud& cloud, int num_threads) const {
  std::vector<double> out(cloud.size());
#pragma omp parallel for schedule(dynamic, 64) \
    num_threads(num_threads > 0 ? num_threads : omp_get_max_threads())
  for (int64_t i = 0; i < static_cast<int64_t>(cloud.size()); ++i) {
    out[i] = Distance(cloud.point3(i));
  }
  return out;
}

DistanceStats SummariseDistances(std::vector<double> d) {
  DistanceStats s;
  s.count = d.size();
  if (d.empty()) return s;
  double sum = 0, sq = 0;
  for (double v : d) {
    sum += v;
    sq += v * v;
  }
  s.mean_m = sum / d.size();
  s.rms_m = std::sqrt(sq / d.size());
  std::sort(d.begin(), d.end());
  auto quantile = [&](double q) {
    const double pos = q * (d.size() - 1);
    const size_t lo = static_cast<size_t>(std::floor(pos));
    const size_t hi = std::min(lo + 1, d.size() - 1);
    return d[lo] + (pos - lo) * (d[hi] - d[lo]);
  };
  s.median_m = quantile(0.5);
  s.p95_m = quantile(0.95);
  s.max_m = d.back();
  return s;
}

}  // namespace arpos
