// PCL translation unit #3 (Poisson): keep PCL headers out of everything else.
#include "registration/poisson.h"

#include <omp.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/surface/poisson.h>

#include <fcntl.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>

#include "registration/kdtree.h"
#include "registration/pcl_convert.h"
#include "util/check.h"

namespace arpos {
namespace {

// PCL's Poisson code printf()s diagnostics ("Vertex pair not in list") to
// stdout while extracting the iso-surface, which would mix into the
// program's own output. Standard output is sent to /dev/null for the call.
class MuteStdout {
 public:
  MuteStdout() {
    std::fflush(stdout);
    saved_ = dup(STDOUT_FILENO);
    const int null_fd = open("/dev/null", O_WRONLY);
    if (saved_ >= 0 && null_fd >= 0) dup2(null_fd, STDOUT_FILENO);
    if (null_fd >= 0) close(null_fd);
  }
  ~MuteStdout() {
    std::fflush(stdout);
    if (saved_ >= 0) {
      dup2(saved_, STDOUT_FILENO);
      close(saved_);
    }
  }
  MuteStdout(const MuteStdout&) = delete;
  MuteStdout& operator=(const MuteStdout&) = delete;

 private:
  int saved_ = -1;
};

double NowS() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace

std::string PoissonOptions::Validate() const {
  if (depth < 1 || depth > 14) return "depth: must be in 1..14";
  if (!(point_weight >= 0)) return "point_weight: must be >= 0";
  if (!(samples_per_node >= 1)) return "samples_per_node: must be >= 1";
  if (num_threads < 0) return "num_threads: must be >= 0";
  return "";
}

PoissonResult PoissonMesh(const PointCloud& cloud, const PoissonOptions& options) {
  const std::string problem = options.Validate();
  ARPOS_CHECK(problem.empty(), "PoissonOptions: " << problem);
  ARPOS_CHECK(cloud.empty() || cloud.has_normals(), "PoissonMesh: the cloud needs normals");
  const double start_s = NowS();
  PoissonResult result;
  if (cloud.size() < 3) return result;

  const pcl::PointCloud<pcl::PointNormal>::Ptr input = ToPclPointNormals(cloud);
  pcl::Poisson<pcl::PointNormal> poisson;
  poisson.setDepth(options.depth);
  poisson.setPointWeight(options.point_weight);
  poisson.setSamplesPerNode(options.samples_per_node);
  poisson.setThreads(options.num_threads > 0 ? options.num_threads : omp_get_max_threads());
  poisson.setManifold(true);
  poisson.setInputCloud(input);
  pcl::PointCloud<pcl::PointNormal> vertices;
  std::vector<pcl::Vertices> polygons;
  {
    const MuteStdout mute;
    poisson.reconstruct(vertices, polygons);
  }
  result.poisson_s = NowS() - start_s;

  TriangleMesh full;
  full.vertices.reserve(vertices.size());
  for (const auto& v : vertices) full.vertices.emplace_back(v.x, v.y, v.z);
  for (const auto& poly : polygons) {
    // Triangulate any polygon as a fan (Poisson emits triangles).
    for (size_t k = 2; k < poly.vertices.size(); ++k) {
      full.faces.emplace_back(static_cast<int>(poly.vertices[0]),
                              static_cast<int>(poly.vertices[k - 1]),
                              static_cast<int>(poly.vertices[k]));
    }
  }
  result.faces_before_pruning = static_cast<int>(full.faces.size());
  result.closed_before_pruning = !full.faces.empty() && full.IsClosed();

  // Winding: make faces counter-clockwise seen from the points' normals side.
  const KdTree tree(cloud);
  double agreement = 0;
  for (size_t f = 0; f < full.faces.size(); f += std::max<size_t>(1, full.faces.size() / 2000)) {
    const Eigen::Vector3i& face = full.faces[f];
    const Eigen::Vector3d a = full.vertices[face[0]].cast<double>();
    const Eigen::Vector3d b = full.vertices[face[1]].cast<double>();
    const Eigen::Vector3d c = full.vertices[face[2]].cast<double>();
    const Eigen::Vector3d centroid = (a + b + c) / 3.0;
    size_t nearest;
    double sq;
    if (!tree.Nearest(centroid, &nearest, &sq)) continue;
    agreement += (b - a).cross(c - a).dot(cloud.normal3(nearest));
  }
  if (agreement < 0) {
    for (auto& face : full.faces) std::swap(face[1], face[2]);
  }

  const double prune_start_s = NowS();
  if (options.prune_distance_m > 0) {
    const double max_sq = options.prune_distance_m * options.prune_distance_m;
    std::vector<char> near(full.vertices.size(), 0);
#pragma omp parallel for schedule(static) \
    num_threads(options.num_threads > 0 ? options.num_threads : omp_get_max_threads())
    for (int64_t i = 0; i < static_cast<int64_t>(full.vertices.size()); ++i) {
      size_t nearest;
      double sq;
      near[i] = tree.Nearest(Eigen::Vector3d(full.vertices[i].cast<double>()), &nearest, &sq) &&
                sq <= max_sq;
    }
    std::vector<int> remap(full.vertices.size(), -1);
    for (const auto& face : full.faces) {
      if (!near[face[0]] || !near[face[1]] || !near[face[2]]) continue;
      Eigen::Vector3i out;
      for (int k = 0; k < 3; ++k) {
        int& m = remap[face[k]];
        if (m < 0) {
          m = static_cast<int>(result.mesh.vertices.size());
          result.mesh.vertices.push_back(full.vertices[face[k]]);
        }
        out[k] = m;
      }
      result.mesh.faces.push_back(out);
    }
  } else {
    result.mesh = std::move(full);
  }
  result.mesh.ComputeVertexNormals();
  result.prune_s = NowS() - prune_start_s;
  result.total_s = NowS() - start_s;
  return result;
}

}  // namespace arpos
