#include "registration/point_cloud.h"

#include "util/check.h"

namespace arpos {

PointCloud::PointCloud(const std::vector<Eigen::Vector3d>& points_m) {
  points.reserve(points_m.size());
  for (const auto& p : points_m) points.emplace_back(p.x(), p.y(), p.z(), 1.0);
}

void PointCloud::Add(const Eigen::Vector3d& point_m) {
  normals.clear();
  covs.clear();
  points.emplace_back(point_m.x(), point_m.y(), point_m.z(), 1.0);
}

void PointCloud::Add(const Eigen::Vector3d& point_m, const Eigen::Vector3d& normal) {
  const bool keep_normals = points.empty() || has_normals();
  covs.clear();
  points.emplace_back(point_m.x(), point_m.y(), point_m.z(), 1.0);
  if (keep_normals) {
    normals.emplace_back(normal.x(), normal.y(), normal.z(), 0.0);
  } else {
    normals.clear();
  }
}

void PointCloud::Append(const PointCloud& other) {
  if (other.empty()) return;
  const bool was_empty = empty();
  const bool normals_ok = other.has_normals() && (was_empty || has_normals());
  const bool covs_ok = other.has_covs() && (was_empty || has_covs());
  points.insert(points.end(), other.points.begin(), other.points.end());
  if (normals_ok) {
    normals.insert(normals.end(), other.normals.begin(), other.normals.end());
  } else {
    normals.clear();
  }
  if (covs_ok) {
    covs.insert(covs.end(), other.covs.begin(), other.covs.end());
  } else {
    covs.clear();
  }
}

void PointCloud::Transform(const Rigid3d& b_from_a) {
  Eigen::Matrix4d t = b_from_a.ToMatrix();
  for (auto& p : points) p = t * p;
  for (auto& n : normals) n = t * n;  // w = 0: rotation only
  if (!covs.empty()) {
    const Eigen::Matrix3d r = t.block<3, 3>(0, 0);
    for (auto& c : covs) c.block<3, 3>(0, 0) = r * c.block<3, 3>(0, 0) * r.transpose();
  }
}

PointCloud PointCloud::Transformed(const Rigid3d& b_from_a) const {
  PointCloud copy = *this;
  copy.Transform(b_from_a);
  return copy;
}

Eigen::AlignedBox3d PointCloud::Bounds() const {
  Eigen::AlignedBox3d box;  // empty
  for (const auto& p : points) box.extend(p.head<3>());
  return box;
}

Eigen::Vector3d PointCloud::Centroid() const {
  if (points.empty()) return Eigen::Vector3d::Zero();
  Eigen::Vector4d sum = Eigen::Vector4d::Zero();
  for (const auto& p : points) sum += p;
  return sum.head<3>() / static_cast<double>(points.size());
}

PointCloud PointCloud::Select(const std::vector<size_t>& indices) const {
  PointCloud out;
  out.points.reserve(indices.size());
  for (size_t i : indices) {
    ARPOS_CHECK(i < points.size(), "index " << i << " out of range " << points.size());
    out.points.push_back(points[i]);
  }
  if (has_normals()) {
    out.normals.reserve(indices.size());
    for (size_t i : indices) out.normals.push_back(normals[i]);
  }
  if (has_covs()) {
    out.covs.reserve(indices.size());
    for (size_t i : indices) out.covs.push_back(covs[i]);
  }
  return out;
}

std::vector<Eigen::Vector3d> PointCloud::Points3d() const {
  std::vector<Eigen::Vector3d> out;
  out.reserve(points.size());
  for (const auto& p : points) out.push_back(p.head<3>());
  return out;
}

void PointCloud::CheckInvariants() const {
  ARPOS_CHECK(normals.empty() || normals.size() == points.size(),
              "point cloud has " << normals.size() << " normals for " << points.size()
                                 << " points");
  ARPOS_CHECK(covs.empty() || covs.size() == points.size(),
              "point cloud has " << covs.size() << " covariances for " << points.size()
                                 << " points");
  for (size_t i = 0; i < points.size(); ++i) {
    ARPOS_CHECK(points[i].w() == 1.0, "point " << i << " has w = " << points[i].w());
  }
}

}  // namespace arpos
