#include "registration/preprocess.h"

#include <omp.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <numeric>
#include <opencv2/calib3d.hpp>
#include <random>

#include "util/check.h"

namespace arpos {
namespace {

int ThreadCount(int requested) { return requested > 0 ? requested : omp_get_max_threads(); }

}  // namespace

std::string DepthCloudOptions::Validate() const {
  if (stride_px < 1) return "stride_px: must be >= 1";
  if (!(min_depth_m >= 0)) return "min_depth_m: must be >= 0";
  if (!(max_depth_m > min_depth_m)) return "max_depth_m: must exceed min_depth_m";
  return "";
}

PointCloud DepthToCloud(const cv::Mat& depth, double depth_units_per_m,
                        const CameraIntrinsics& intrinsics, const DepthCloudOptions& options,
                        const cv::Mat& mask) {
  const std::string problem = options.Validate();
  ARPOS_CHECK(problem.empty(), "DepthCloudOptions: " << problem);
  ARPOS_CHECK(depth.type() == CV_16UC1 || depth.type() == CV_32FC1,
              "depth must be CV_16UC1 or CV_32FC1");
  ARPOS_CHECK(depth_units_per_m > 0, "depth_units_per_m must be positive");
  ARPOS_CHECK(mask.empty() || (mask.type() == CV_8UC1 && mask.size() == depth.size()),
              "mask must be empty or CV_8UC1 of the depth's size");
  ARPOS_CHECK(intrinsics.fx > 0 && intrinsics.fy > 0, "intrinsics need positive focal lengths");

  // Per-pixel normalised rays (x/z, y/z); undistorted only when needed.
  const bool undistort = options.undistort && intrinsics.HasDistortion();
  cv::Mat rays;  // CV_64FC2, one per used pixel of the strided grid
  const int cols = (depth.cols + options.stride_px - 1) / options.stride_px;
  const int rows = (depth.rows + options.stride_px - 1) / options.stride_px;
  if (undistort) {
    std::vector<cv::Point2d> pixels;
    pixels.reserve(static_cast<size_t>(rows) * cols);
    for (int v = 0; v < depth.rows; v += options.stride_px) {
      for (int u = 0; u < depth.cols; u += options.stride_px) pixels.emplace_back(u, v);
    }
    std::vector<cv::Point2d> normalised;
    cv::undistortPoints(pixels, normalised, intrinsics.CvK(), intrinsics.CvDistortion());
    rays = cv::Mat(normalised, true).reshape(2, rows);
  }

  const double inv_scale = 1.0 / depth_units_per_m;
  PointCloud cloud;
  cloud.points.reserve(static_cast<size_t>(rows) * cols);
  for (int v = 0, row = 0; v < depth.rows; v += options.stride_px, ++row) {
    const uint8_t* mask_row = mask.empty() ? nullptr : mask.ptr<uint8_t>(v);
    for (int u = 0, col = 0; u < depth.cols; u += options.stride_px, ++col) {
      if (mask_row && !mask_row[u]) continue;
      double z = depth.type() == CV_16UC1 ? depth.at<uint16_t>(v, u) * inv_scale
                                          : static_cast<double>(depth.at<float>(v, u)) * inv_scale;
      if (!(z > 0) || z < options.min_depth_m || z > options.max_depth_m) continue;
      double x_over_z, y_over_z;
      if (undistort) {
        const cv::Vec2d r = rays.at<cv::Vec2d>(row, col);
        x_over_z = r[0];
        y_over_z = r[1];
      } else {
        x_over_z = (u - intrinsics.cx) / intrinsics.fx;
        y_over_z = (v - intrinsics.cy) / intrinsics.fy;
      }
      cloud.points.emplace_back(x_over_z * z, y_over_z * z, z, 1.0);
    }
  }
  return cloud;
}

PointCloud DepthToCloud(const RgbdFrame& frame, const CameraIntrinsics& intrinsics,
                        const DepthCloudOptions& options, const cv::Mat& mask) {
  return DepthToCloud(frame.depth, frame.depth_scale, intrinsics, options, mask);
}

PointCloud VoxelDownsample(const PointCloud& cloud, double voxel_m) {
  if (!(voxel_m > 0) || cloud.empty()) return cloud;
  const double inv = 1.0 / voxel_m;
  constexpr int64_t kOffset = int64_t{1} << 20;  // 21 bits per axis
  const size_t n = cloud.size();
  std::vector<std::pair<uint64_t, uint32_t>> keys(n);
  bool in_range = true;
#pragma omp parallel for schedule(static) reduction(&& : in_range)
  for (int64_t i = 0; i < static_cast<int64_t>(n); ++i) {
    const Eigen::Vector4d& p = cloud.points[i];
    const int64_t x = static_cast<int64_t>(std::floor(p.x() * inv)) + kOffset;
    const int64_t y = static_cast<int64_t>(std::floor(p.y() * inv)) + kOffset;
    const int64_t z = static_cast<int64_t>(std::floor(p.z() * inv)) + kOffset;
    const bool ok = x >= 0 && y >= 0 && z >= 0 && x < 2 * kOffset && y < 2 * kOffset &&
                    z < 2 * kOffset;
    in_range = in_range && ok;
    keys[i] = {(static_cast<uint64_t>(x) << 42) | (static_cast<uint64_t>(y) << 21) |
                   static_cast<uint64_t>(z),
               static_cast<uint32_t>(i)};
  }
  ARPOS_CHECK(in_range, "VoxelDownsample: a point lies too far from the origin for voxel "
                            << voxel_m << " m");
  std::sort(keys.begin(), keys.end());

  const bool normals = cloud.has_normals();
  PointCloud out;
  out.points.reserve(n / 4 + 1);
  if (normals) out.normals.reserve(n / 4 + 1);
  for (size_t begin = 0; begin < n;) {
    size_t end = begin + 1;
    while (end < n && keys[end].first == keys[begin].first) ++end;
    Eigen::Vector4d sum = Eigen::Vector4d::Zero();
    Eigen::Vector4d normal_sum = Eigen::Vector4d::Zero();
    for (size_t j = begin; j < end; ++j) {
      sum += cloud.points[keys[j].second];
      if (normals) normal_sum += cloud.normals[keys[j].second];
    }
    out.points.push_back(sum / static_cast<double>(end - begin));
    if (normals) {
      const double norm = normal_sum.head<3>().norm();
      out.normals.push_back(norm > 1e-12 ? Eigen::Vector4d(normal_sum / norm)
                                         : cloud.normals[keys[begin].second]);
    }
    begin = end;
  }
  return out;
}

std::string NormalOptions::Validate() const {
  if (k < 3) return "k: must be >= 3";
  if (!(covariance_epsilon > 0 && covariance_epsilon <= 1)) {
    return "covariance_epsilon: must be in (0, 1]";
  }
  if (num_threads < 0) return "num_threads: must be >= 0";
  return "";
}

namespace {

void EstimateLocalGeometry(PointCloud* cloud, const KdTree& tree, const NormalOptions& options,
                           bool want_normals, bool want_covs) {
  const std::string problem = options.Validate();
  ARPOS_CHECK(problem.empty(), "NormalOptions: " << problem);
  ARPOS_CHECK(tree.size() == cloud->size(), "the kd-tree must be built over this cloud ("
                                                << tree.size() << " vs " << cloud->size()
                                                << " points)");
  const size_t n = cloud->size();
  const bool had_normals = cloud->has_normals();
  std::vector<Eigen::Vector4d> normals;
  if (want_normals) normals.resize(n);
  if (want_covs) cloud->covs.resize(n);
  const int k = options.k;
  const Eigen::Vector4d viewpoint(options.viewpoint.x(), options.viewpoint.y(),
                                  options.viewpoint.z(), 1.0);
  const double eps = options.covariance_epsilon;

#pragma omp parallel num_threads(ThreadCount(options.num_threads))
  {
    std::vector<size_t> indices(k);
    std::vector<double> dists(k);
    std::vector<Eigen::Vector4d> neighbours(k);
#pragma omp for schedule(dynamic, 256)
    for (int64_t i = 0; i < static_cast<int64_t>(n); ++i) {
      const Eigen::Vector4d& p = cloud->points[i];
      const size_t found =
          tree.KnnWithPoints(p, k, indices.data(), dists.data(), neighbours.data());
      Eigen::Vector4d towards = viewpoint - p;
      if (had_normals && options.orient_like_existing) towards = cloud->normals[i];
      if (found < 3) {
        if (want_normals) {
          const double norm = towards.head<3>().norm();
          normals[i] = norm > 0 ? Eigen::Vector4d(towards / norm) : Eigen::Vector4d::UnitZ();
          normals[i].w() = 0;
        }
        if (want_covs) cloud->covs[i] = Eigen::Matrix4d::Identity();
        if (want_covs) cloud->covs[i](3, 3) = 0;
        continue;
      }
      Eigen::Vector3d mean = Eigen::Vector3d::Zero();
      for (size_t j = 0; j < found; ++j) mean += neighbours[j].head<3>();
      mean /= static_cast<double>(found);
      Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
      for (size_t j = 0; j < found; ++j) {
        const Eigen::Vector3d d = neighbours[j].head<3>() - mean;
        cov.noalias() += d * d.transpose();
      }
      cov /= static_cast<double>(found);
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig;
      eig.computeDirect(cov);
      const Eigen::Matrix3d u = eig.eigenvectors();  // ascending eigenvalues
      if (want_normals) {
        Eigen::Vector3d normal = u.col(0);
        if (normal.dot(towards.head<3>()) < 0) normal = -normal;
        normals[i] << normal, 0.0;
      }
      if (want_covs) {
        const Eigen::Vector3d values(eps, 1.0, 1.0);
        Eigen::Matrix4d c = Eigen::Matrix4d::Zero();
        c.block<3, 3>(0, 0) = u * values.asDiagonal() * u.transpose();
        cloud->covs[i] = c;
      }
    }
  }
  if (want_normals) cloud->normals.swap(normals);
}

}  // namespace

void EstimateNormals(PointCloud* cloud, const KdTree& tree, const NormalOptions& options) {
  EstimateLocalGeometry(cloud, tree, options, true, false);
}

void EstimateCovariances(PointCloud* cloud, const KdTree& tree, const NormalOptions& options) {
  EstimateLocalGeometry(cloud, tree, options, false, true);
}

void EstimateNormalsAndCovariances(PointCloud* cloud, const KdTree& tree,
                                   const NormalOptions& options) {
  EstimateLocalGeometry(cloud, tree, options, true, true);
}

bool OrientedBox::Contains(const Eigen::Vector3d& point_in_frame) const {
  const Eigen::Vector3d p = frame_from_box.Inverse() * point_in_frame;
  return (p.array().abs() <= half_extents_m.array()).all();
}

PointCloud CropToBox(const PointCloud& cloud, const OrientedBox& box) {
  const Rigid3d box_from_frame = box.frame_from_box.Inverse();
  const Eigen::Matrix3d r = box_from_frame.RotationMatrix();
  std::vector<size_t> keep;
  for (size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3d p = r * cloud.point3(i) + box_from_frame.translation;
    if ((p.array().abs() <= box.half_extents_m.array()).all()) keep.push_back(i);
  }
  return cloud.Select(keep);
}

PointCloud KeepAbovePlane(const PointCloud& cloud, const Plane& plane, double min_height_m) {
  std::vector<size_t> keep;
  for (size_t i = 0; i < cloud.size(); ++i) {
    if (plane.SignedDistance(cloud.point3(i)) > min_height_m) keep.push_back(i);
  }
  return cloud.Select(keep);
}

std::string PlaneFitOptions::Validate() const {
  if (!(distance_threshold_m > 0)) return "distance_threshold_m: must be positive";
  if (iterations < 1) return "iterations: must be >= 1";
  if (expected_normal && !(expected_normal->norm() > 0)) {
    return "expected_normal: must be non-zero";
  }
  return "";
}

std::optional<PlaneFitResult> FitPlaneRansac(const PointCloud& cloud,
                                             const PlaneFitOptions& options) {
  const std::string problem = options.Validate();
  ARPOS_CHECK(problem.empty(), "PlaneFitOptions: " << problem);
  const size_t n = cloud.size();
  if (n < 3) return std::nullopt;
  std::mt19937_64 rng(options.seed);
  const double cos_max = std::cos(options.max_angle_rad);
  Eigen::Vector3d expected = Eigen::Vector3d::Zero();
  if (options.expected_normal) expected = options.expected_normal->normalized();

  auto count_inliers = [&](const Plane& plane) {
    int count = 0;
    for (size_t i = 0; i < n; ++i) {
      if (std::abs(plane.SignedDistance(cloud.point3(i))) < options.distance_threshold_m) ++count;
    }
    return count;
  };
  std::optional<PlaneFitResult> best;
  for (int it = 0; it < options.iterations; ++it) {
    const size_t a = rng() % n, b = rng() % n, c = rng() % n;
    const Eigen::Vector3d pa = cloud.point3(a), pb = cloud.point3(b), pc = cloud.point3(c);
    Eigen::Vector3d normal = (pb - pa).cross(pc - pa);
    if (normal.norm() < 1e-12) continue;
    normal.normalize();
    if (options.expected_normal && std::abs(normal.dot(expected)) < cos_max) continue;
    Plane plane{normal, -normal.dot(pa)};
    const int count = count_inliers(plane);
    if (!best || count > best->num_inliers) best = PlaneFitResult{plane, count};
  }
  if (!best) return std::nullopt;
  // Least-squares refit on the inliers.
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  std::vector<size_t> inliers;
  for (size_t i = 0; i < n; ++i) {
    if (std::abs(best->plane.SignedDistance(cloud.point3(i))) < options.distance_threshold_m) {
      inliers.push_back(i);
      mean += cloud.point3(i);
    }
  }
  if (inliers.size() >= 3) {
    mean /= static_cast<double>(inliers.size());
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (size_t i : inliers) {
      const Eigen::Vector3d d = cloud.point3(i) - mean;
      cov += d * d.transpose();
    }
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
    Eigen::Vector3d normal = eig.eigenvectors().col(0);
    if (normal.dot(best->plane.normal) < 0) normal = -normal;
    best->plane = Plane{normal, -normal.dot(mean)};
    best->num_inliers = count_inliers(best->plane);
  }
  if (options.expected_normal && best->plane.normal.dot(expected) < 0) {
    best->plane.normal = -best->plane.normal;
    best->plane.offset_m = -best->plane.offset_m;
  }
  return best;
}

std::vector<int> EuclideanClusterLabels(const PointCloud& cloud, double tolerance_m,
                                        int* num_clusters) {
  const size_t n = cloud.size();
  std::vector<int> raw(n, -1);
  int count = 0;
  if (n > 0) {
    const KdTree tree(cloud);
    std::vector<size_t> stack, neighbours;
    for (size_t seed = 0; seed < n; ++seed) {
      if (raw[seed] >= 0) continue;
      raw[seed] = count;
      stack.assign(1, seed);
      while (!stack.empty()) {
        const size_t i = stack.back();
        stack.pop_back();
        tree.RadiusSearch(cloud.points[i], tolerance_m, &neighbours);
        for (size_t j : neighbours) {
          if (raw[j] < 0) {
            raw[j] = count;
            stack.push_back(j);
          }
        }
      }
      ++count;
    }
  }
  // Renumber by decreasing size (ties by first appearance).
  std::vector<size_t> sizes(count, 0);
  for (int label : raw) ++sizes[label];
  std::vector<int> order(count);
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return sizes[a] > sizes[b]; });
  std::vector<int> rank(count);
  for (int r = 0; r < count; ++r) rank[order[r]] = r;
  for (int& label : raw) label = rank[label];
  if (num_clusters) *num_clusters = count;
  return raw;
}

PointCloud LargestCluster(const PointCloud& cloud, double tolerance_m) {
  const std::vector<int> labels = EuclideanClusterLabels(cloud, tolerance_m);
  std::vector<size_t> keep;
  for (size_t i = 0; i < labels.size(); ++i) {
    if (labels[i] == 0) keep.push_back(i);
  }
  return cloud.Select(keep);
}

}  // namespace arpos
