#include "room_map/room_surface.h"

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cmath>
#include <limits>
#include <sstream>
#include <unordered_map>

#include <Eigen/Eigenvalues>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "sensor/sequence.h"
#include "util/string_util.h"

namespace arpos {
namespace {

// Key of the voxel (i, j, k) on a grid (21 bits a coordinate, offset so
// negative indices work).
std::uint64_t RoomVoxelKey(int i, int j, int k) {
  constexpr std::uint64_t kMask = (1u << 21) - 1;
  constexpr int kOffset = 1 << 20;
  return ((static_cast<std::uint64_t>(i + kOffset) & kMask) << 42) |
         ((static_cast<std::uint64_t>(j + kOffset) & kMask) << 21) |
         (static_cast<std::uint64_t>(k + kOffset) & kMask);
}

}  // namespace

std::string RoomSurface::Validate() const {
  std::ostringstream out;
  if (points.size() != normals.size()) {
    out << "room surface has " << points.size() << " points but " << normals.size() << " normals";
  } else if (!points.empty() && !(voxel_m > 0 && std::isfinite(voxel_m))) {
    out << "room surface voxel size must be positive, got " << voxel_m;
  } else {
    for (size_t i = 0; i < points.size(); ++i) {
      if (!points[i].allFinite() || !normals[i].allFinite()) {
        out << "room surface point " << i << " is not finite";
        break;
      }
      if (std::abs(normals[i].norm() - 1.f) > 1e-3f) {
        out << "room surface normal " << i << " is not a unit vector (length " << normals[i].norm() << ")";
        break;
      }
      if (points[i].cwiseAbs().maxCoeff() > 100.f) {
        out << "room surface point " << i << " is more than 100 m from the origin";
        break;
      }
    }
  }
  if (out.str().empty() && !points.empty()) {
    Eigen::Vector3f lo = points[0], hi = points[0];
    for (const auto& p : points) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
    if ((hi - lo).maxCoeff() > 20.f) out << "room surface spans " << (hi - lo).maxCoeff() << " m (more than 20 m)";
  }
  return out.str();
}

std::string RoomSurfaceOptions::Validate() const {
  std::ostringstream out;
  if (!(voxel_m > 0.001 && voxel_m < 1)) out << "voxel_m must be in (0.001, 1) m, got " << voxel_m;
  else if (!(radius_m > 0)) out << "radius_m must be positive";
  else if (samples_across < 2) out << "samples_across must be at least 2";
  else if (!(min_depth_m >= 0 && max_depth_m > min_depth_m)) out << "depth range must be increasing";
  else if (min_frames < 1) out << "min_frames must be at least 1";
  else if (!(max_unflatness_m > 0) || !(min_extent_m >= 0)) out << "flatness limits must be positive";
  else if (max_points < 1) out << "max_points must be at least 1";
  return out.str();
}

std::string RoomSurfaceReport::ToText() const {
  return StringPrintf("room surface: %d points (flat voxels of %d seen in enough frames), from %d depth samples "
                      "in %d frames, %.2f s",
                      flat_voxels, voxels, samples, frames, seconds) +
         (note.empty() ? "" : "; " + note);
}

namespace {

// Depth samples in a voxel, weighted by their depth noise: the weight, the
// weighted sum and the weighted sum of outer products, and the frames.
struct Voxel {
  double w = 0;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  Eigen::Matrix3d sum2 = Eigen::Matrix3d::Zero();
  int count = 0;
  int frames = 0;
  int last_frame = -1;
};

Eigen::Vector3i VoxelOf(const Eigen::Vector3d& x, double inv_voxel) {
  return Eigen::Vector3i(static_cast<int>(std::floor(x.x() * inv_voxel)), static_cast<int>(std::floor(x.y() * inv_voxel)),
                         static_cast<int>(std::floor(x.z() * inv_voxel)));
}

}  // namespace

DepthSampleGrid MakeDepthSampleGrid(const CameraIntrinsics& K, int step) {
  DepthSampleGrid grid;
  std::vector<cv::Point2d> px, ideal;
  for (int v = step / 2; v < K.height; v += step) {
    for (int u = step / 2; u < K.width; u += step) {
      px.emplace_back(u, v);
      grid.px.emplace_back(u, v);
    }
  }
  if (K.HasDistortion() && !px.empty()) {
    cv::undistortPoints(px, ideal, K.CvK(), K.CvDistortion());
    for (const auto& p : ideal) grid.ray.emplace_back(p.x, p.y);
  } else {
    for (const auto& p : px) grid.ray.emplace_back((p.x - K.cx) / K.fx, (p.y - K.cy) / K.fy);
  }
  return grid;
}

RoomSurface BuildRoomSurface(const Sequence& sequence, const CameraIntrinsics& K, const DepthCorrection& correction,
                             const std::vector<std::pair<int, Rigid3d>>& room_from_camera,
                             const std::function<bool(const Eigen::Vector3d&)>& keep,
                             const Eigen::Vector3d& centre, const RoomSurfaceOptions& options,
                             RoomSurfaceReport* report) {
  const auto start = std::chrono::steady_clock::now();
  RoomSurfaceReport local;
  RoomSurfaceReport& rep = report ? *report : local;
  rep = RoomSurfaceReport();
  RoomSurface surface;
  surface.voxel_m = options.voxel_m;
  if (room_from_camera.empty() || K.width <= 0 || K.height <= 0) return surface;

  const DepthSampleGrid grid = MakeDepthSampleGrid(K, std::max(1, K.width / options.samples_across));
  const std::vector<cv::Point>& px = grid.px;
  const std::vector<Eigen::Vector2d>& ray = grid.ray;
  // The depth correction reads the pixel's position without the lens, as
  // CorrectDepthImage does.
  std::vector<Eigen::Vector2d> plain(px.size());
  for (size_t i = 0; i < px.size(); ++i) plain[i] = Eigen::Vector2d((px[i].x - K.cx) / K.fx, (px[i].y - K.cy) / K.fy);

  const double inv_voxel = 1.0 / options.voxel_m;
  const double radius2 = options.radius_m * options.radius_m;
  std::unordered_map<std::uint64_t, Voxel> voxels;
  voxels.reserve(1 << 18);
  for (const auto& [index, pose] : room_from_camera) {
    if (index < 0 || static_cast<size_t>(index) >= sequence.size() || !sequence.has_depth(index)) continue;
    const cv::Mat depth = cv::imread(sequence.depth_path(index).string(), cv::IMREAD_UNCHANGED);
    if (depth.empty() || depth.type() != CV_16UC1 || depth.cols != K.width || depth.rows != K.height) continue;
    ++rep.frames;
    const Eigen::Matrix3d R = pose.rotation.toRotationMatrix();
    const Eigen::Vector3d t = pose.translation;
    for (size_t i = 0; i < px.size(); ++i) {
      const uint16_t raw = depth.at<uint16_t>(px[i]);
      if (raw == 0) continue;
      double z = raw / K.depth_scale;
      if (!correction.IsIdentity()) z = correction.TrueDepth(z, plain[i].x(), plain[i].y());
      if (!(z >= options.min_depth_m && z <= options.max_depth_m)) continue;
      const Eigen::Vector3d x = R * Eigen::Vector3d(ray[i].x() * z, ray[i].y() * z, z) + t;
      if ((x - centre).squaredNorm() > radius2 || !keep(x)) continue;
      const double sigma = options.depth_sigma_const_m + options.depth_sigma_quad_per_m * z * z;
      const double w = 1.0 / (sigma * sigma);
      const Eigen::Vector3i c = VoxelOf(x, inv_voxel);
      Voxel& vox = voxels[RoomVoxelKey(c.x(), c.y(), c.z())];
      vox.w += w;
      vox.sum += w * x;
      vox.sum2.noalias() += w * x * x.transpose();
      ++vox.count;
      if (vox.last_frame != index) {
        vox.last_frame = index;
        ++vox.frames;
      }
      ++rep.samples;
    }
  }

  // Each voxel seen often enough gets the plane of the samples in its
  // neighbourhood (+-1 voxel), weighted by their noise: depth noise spreads
  // a face over a slab several voxels thick at a few metres, so a voxel's
  // own centroid lies off the face; the plane through the neighbourhood
  // does not. The point is the voxel's centroid moved onto that plane.
  // The neighbourhood must be as flat as the depth noise allows: the
  // weighted variance across the plane at most 4 times what the noise
  // gives (N / sum w) plus max_unflatness^2.
  struct Candidate {
    Eigen::Vector3d point, normal;
    double unflatness;
  };
  std::vector<Candidate> flat;
  for (const auto& [key, vox] : voxels) {
    if (vox.frames < options.min_frames) continue;
    ++rep.voxels;
    const Eigen::Vector3d c = vox.sum / vox.w;
    const Eigen::Vector3i v = VoxelOf(c, inv_voxel);
    double w = 0;
    int n = 0;
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    Eigen::Matrix3d sum2 = Eigen::Matrix3d::Zero();
    for (int di = -1; di <= 1; ++di) {
      for (int dj = -1; dj <= 1; ++dj) {
        for (int dk = -1; dk <= 1; ++dk) {
          const auto it = voxels.find(RoomVoxelKey(v.x() + di, v.y() + dj, v.z() + dk));
          if (it == voxels.end()) continue;
          w += it->second.w;
          sum += it->second.sum;
          sum2 += it->second.sum2;
          n += it->second.count;
        }
      }
    }
    if (n < 10 || !(w > 0)) continue;
    const Eigen::Vector3d mean = sum / w;
    const Eigen::Matrix3d cov = sum2 / w - mean * mean.transpose();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
    if (eig.info() != Eigen::Success) continue;
    const double across = std::max(0.0, eig.eigenvalues()(0));
    const double extent = std::sqrt(std::max(0.0, eig.eigenvalues()(1)));
    const double noise = n / w;
    if (across > 4 * noise + options.max_unflatness_m * options.max_unflatness_m || extent < options.min_extent_m) {
      continue;
    }
    Eigen::Vector3d normal = eig.eigenvectors().col(0).normalized();
    // The sign does not matter to a point-to-plane match; one is chosen
    // for a stable record (largest component positive).
    Eigen::Index largest = 0;
    normal.cwiseAbs().maxCoeff(&largest);
    if (normal(largest) < 0) normal = -normal;
    flat.push_back({c - normal * normal.dot(c - mean), normal, across});
  }
  if (static_cast<int>(flat.size()) > options.max_points) {
    // The flattest first.
    std::nth_element(flat.begin(), flat.begin() + options.max_points, flat.end(),
                     [](const Candidate& a, const Candidate& b) { return a.unflatness < b.unflatness; });
    flat.resize(options.max_points);
  }
  // A stable order (the hash map's is not).
  std::sort(flat.begin(), flat.end(), [](const Candidate& a, const Candidate& b) {
    if (a.point.z() != b.point.z()) return a.point.z() < b.point.z();
    if (a.point.y() != b.point.y()) return a.point.y() < b.point.y();
    return a.point.x() < b.point.x();
  });
  for (const Candidate& f : flat) {
    surface.points.push_back(f.point.cast<float>());
    surface.normals.push_back(f.normal.cast<float>().normalized());
  }
  rep.flat_voxels = static_cast<int>(surface.points.size());
  rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return surface;
}

RoomSurfaceIndex::RoomSurfaceIndex(const RoomSurface& surface) {
  if (surface.empty() || !(surface.voxel_m > 0)) return;
  const double voxel = surface.voxel_m;
  inv_voxel_ = 1.0 / voxel;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d hi = -lo;
  points_.reserve(surface.size());
  normals_.reserve(surface.size());
  for (size_t i = 0; i < surface.size(); ++i) {
    points_.push_back(surface.points[i].cast<double>());
    normals_.push_back(surface.normals[i].cast<double>());
    lo = lo.cwiseMin(points_.back());
    hi = hi.cwiseMax(points_.back());
  }
  // Two cells of margin all round: a query beside the surface finds it.
  origin_ = lo - Eigen::Vector3d::Constant(2 * voxel);
  for (int a = 0; a < 3; ++a) size_(a) = static_cast<int>(std::ceil((hi(a) - origin_(a)) * inv_voxel_)) + 3;
  // A surface near the couch spans a few metres (about a million cells);
  // one far larger is no room surface to index (RoomSurface::Validate
  // refuses it when read from a store): left unused.
  if (static_cast<double>(size_.x()) * size_.y() * size_.z() > 64e6) {
    points_.clear();
    normals_.clear();
    return;
  }
  cell_point_.assign(static_cast<size_t>(size_.x()) * size_.y() * size_.z(), -1);
  std::vector<float> best(cell_point_.size(), std::numeric_limits<float>::infinity());
  for (size_t i = 0; i < points_.size(); ++i) {
    const Eigen::Vector3d g = (points_[i] - origin_) * inv_voxel_;
    const int ci = static_cast<int>(std::floor(g.x())), cj = static_cast<int>(std::floor(g.y())),
              ck = static_cast<int>(std::floor(g.z()));
    for (int k = ck - 1; k <= ck + 1; ++k) {
      for (int j = cj - 1; j <= cj + 1; ++j) {
        for (int c = ci - 1; c <= ci + 1; ++c) {
          if (c < 0 || j < 0 || k < 0 || c >= size_.x() || j >= size_.y() || k >= size_.z()) continue;
          const size_t cell = (static_cast<size_t>(k) * size_.y() + j) * size_.x() + c;
          const Eigen::Vector3d centre = origin_ + (Eigen::Vector3d(c, j, k) + Eigen::Vector3d::Constant(0.5)) * voxel;
          const float d2 = static_cast<float>((points_[i] - centre).squaredNorm());
          if (d2 < best[cell]) {
            best[cell] = d2;
            cell_point_[cell] = static_cast<int>(i);
          }
        }
      }
    }
  }
}

int RoomSurfaceIndex::Near(const Eigen::Vector3d& x) const {
  if (cell_point_.empty()) return -1;
  const Eigen::Vector3d g = (x - origin_) * inv_voxel_;
  if (!(g.minCoeff() >= 0)) return -1;
  const int c = static_cast<int>(g.x()), j = static_cast<int>(g.y()), k = static_cast<int>(g.z());
  if (c >= size_.x() || j >= size_.y() || k >= size_.z()) return -1;
  return cell_point_[(static_cast<size_t>(k) * size_.y() + j) * size_.x() + c];
}

}  // namespace arpos
