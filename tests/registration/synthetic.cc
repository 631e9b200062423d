#include "registration/synthetic.h"

#include <cmath>
#include <filesystem>

#include "geometry/mesh_io.h"
#include "geometry/so3.h"

namespace arpos::testing {

TriangleMesh MakeEllipsoid(const Eigen::Vector3d& radii_m, int stacks, int slices) {
  TriangleMesh mesh;
  const double pi = 3.141592653589793;
  mesh.vertices.emplace_back(0.f, 0.f, static_cast<float>(radii_m.z()));  // north pole
  for (int i = 1; i < stacks; ++i) {
    const double theta = pi * i / stacks;
    for (int j = 0; j < slices; ++j) {
      const double phi = 2 * pi * j / slices;
      mesh.vertices.emplace_back(static_cast<float>(radii_m.x() * std::sin(theta) * std::cos(phi)),
                                 static_cast<float>(radii_m.y() * std::sin(theta) * std::sin(phi)),
                                 static_cast<float>(radii_m.z() * std::cos(theta)));
    }
  }
  mesh.vertices.emplace_back(0.f, 0.f, static_cast<float>(-radii_m.z()));  // south pole
  const int south = static_cast<int>(mesh.vertices.size()) - 1;
  auto ring = [&](int i, int j) { return 1 + (i - 1) * slices + (j % slices); };
  for (int j = 0; j < slices; ++j) mesh.faces.emplace_back(0, ring(1, j), ring(1, j + 1));
  for (int i = 1; i < stacks - 1; ++i) {
    for (int j = 0; j < slices; ++j) {
      mesh.faces.emplace_back(ring(i, j), ring(i + 1, j), ring(i + 1, j + 1));
      mesh.faces.emplace_back(ring(i, j), ring(i + 1, j + 1), ring(i, j + 1));
    }
  }
  for (int j = 0; j < slices; ++j) {
    mesh.faces.emplace_back(ring(stacks - 1, j), south, ring(stacks - 1, j + 1));
  }
  return mesh;
}

TriangleMesh MakeCylinder(double radius_m, double length_m, int stacks, int slices) {
  TriangleMesh mesh;
  const double pi = 3.141592653589793;
  for (int i = 0; i <= stacks; ++i) {
    const double z = -0.5 * length_m + length_m * i / stacks;
    for (int j = 0; j < slices; ++j) {
      const double phi = 2 * pi * j / slices;
      mesh.vertices.emplace_back(static_cast<float>(radius_m * std::cos(phi)),
                                 static_cast<float>(radius_m * std::sin(phi)),
                                 static_cast<float>(z));
    }
  }
  auto at = [&](int i, int j) { return i * slices + (j % slices); };
  for (int i = 0; i < stacks; ++i) {
    for (int j = 0; j < slices; ++j) {
      mesh.faces.emplace_back(at(i, j), at(i, j + 1), at(i + 1, j + 1));
      mesh.faces.emplace_back(at(i, j), at(i + 1, j + 1), at(i + 1, j));
    }
  }
  return mesh;
}

TriangleMesh MakePlane(double size_m, int cells) {
  TriangleMesh mesh;
  for (int i = 0; i <= cells; ++i) {
    for (int j = 0; j <= cells; ++j) {
      mesh.vertices.emplace_back(static_cast<float>(size_m * (j / double(cells) - 0.5)),
                                 static_cast<float>(size_m * (i / double(cells) - 0.5)), 0.f);
    }
  }
  auto at = [&](int i, int j) { return i * (cells + 1) + j; };
  for (int i = 0; i < cells; ++i) {
    for (int j = 0; j < cells; ++j) {
      mesh.faces.emplace_back(at(i, j), at(i, j + 1), at(i + 1, j + 1));
      mesh.faces.emplace_back(at(i, j), at(i + 1, j + 1), at(i + 1, j));
    }
  }
  return mesh;
}

const TriangleMesh& BodyMesh() {
  static const TriangleMesh* mesh = [] {
    MeshLoadOptions options;
    options.units_scale = 0.1;  // MakeHuman decimetres
    options.only_group = "body";
    return new TriangleMesh(LoadTriangleMesh(
        std::filesystem::path(ARPOS_SHARED_DATA_DIR) / "makehuman_base" / "base.obj", options));
  }();
  return *mesh;
}

CameraIntrinsics TestIntrinsics() {
  CameraIntrinsics k;
  k.width = 640;
  k.height = 480;
  k.fx = k.fy = 540.0;
  k.cx = 319.5;
  k.cy = 239.5;
  k.depth_scale = 5000;
  return k;
}

cv::Mat RenderDepth(const TriangleMesh& mesh, const CameraIntrinsics& k,
                    const Rigid3d& camera_from_mesh) {
  cv::Mat depth(k.height, k.width, CV_32FC1, cv::Scalar(0));
  std::vector<Eigen::Vector3d> cam(mesh.vertices.size());
  for (size_t i = 0; i < cam.size(); ++i) {
    cam[i] = camera_from_mesh * mesh.vertices[i].cast<double>();
  }
  for (const auto& f : mesh.faces) {
    const Eigen::Vector3d& a = cam[f[0]];
    const Eigen::Vector3d& b = cam[f[1]];
    const Eigen::Vector3d& c = cam[f[2]];
    if (a.z() < 0.05 || b.z() < 0.05 || c.z() < 0.05) continue;
    const Eigen::Vector2d pa = k.Project(a), pb = k.Project(b), pc = k.Project(c);
    const double area = (pb - pa).x() * (pc - pa).y() - (pb - pa).y() * (pc - pa).x();
    if (std::abs(area) < 1e-12) continue;
    const int u0 = std::max(0, static_cast<int>(std::ceil(std::min({pa.x(), pb.x(), pc.x()}))));
    const int u1 = std::min(k.width - 1,
                            static_cast<int>(std::floor(std::max({pa.x(), pb.x(), pc.x()}))));
    const int v0 = std::max(0, static_cast<int>(std::ceil(std::min({pa.y(), pb.y(), pc.y()}))));
    const int v1 = std::min(k.height - 1,
                            static_cast<int>(std::floor(std::max({pa.y(), pb.y(), pc.y()}))));
    for (int v = v0; v <= v1; ++v) {
      for (int u = u0; u <= u1; ++u) {
        const Eigen::Vector2d p(u, v);
        auto edge = [](const Eigen::Vector2d& s, const Eigen::Vector2d& e, const Eigen::Vector2d& q) {
          return (e - s).x() * (q - s).y() - (e - s).y() * (q - s).x();
        };
        const double w0 = edge(pb, pc, p) / area;
        const double w1 = edge(pc, pa, p) / area;
        const double w2 = edge(pa, pb, p) / area;
        if (w0 < 0 || w1 < 0 || w2 < 0) continue;
        // 1/z is affine in screen space: exact depth of the triangle's plane.
        const double z = 1.0 / (w0 / a.z() + w1 / b.z() + w2 / c.z());
        float& d = depth.at<float>(v, u);
        if (d == 0 || z < d) d = static_cast<float>(z);
      }
    }
  }
  return depth;
}

Rigid3d LookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
               const Eigen::Vector3d& up) {
  const Eigen::Vector3d z = (target - eye).normalized();
  const Eigen::Vector3d x = z.cross(up).normalized();  // image right
  const Eigen::Vector3d y = z.cross(x);                 // image down
  Eigen::Matrix3d r;
  r.col(0) = x;
  r.col(1) = y;
  r.col(2) = z;
  return Rigid3d(r, eye);
}

Rigid3d RandomPose(std::mt19937_64& rng, double max_translation_m, double max_angle_rad) {
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  Eigen::Vector3d axis(normal(rng), normal(rng), normal(rng));
  axis.normalize();
  const double angle = uniform(rng) * max_angle_rad;
  Eigen::Vector3d dir(normal(rng), normal(rng), normal(rng));
  dir.normalize();
  const double radius = max_translation_m * std::cbrt(uniform(rng));
  return Rigid3d::FromRotationVector(axis * angle, dir * radius);
}

void AddNoise(PointCloud* cloud, double sigma_m, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0.0, sigma_m);
  for (auto& p : cloud->points) {
    p.x() += normal(rng);
    p.y() += normal(rng);
    p.z() += normal(rng);
  }
}

double TranslationError(const Rigid3d& truth, const Rigid3d& estimate) {
  return (truth.Inverse() * estimate).translation.norm();
}

double RotationErrorRad(const Rigid3d& truth, const Rigid3d& estimate) {
  return RotationAngleRad((truth.Inverse() * estimate).rotation);
}

}  // namespace arpos::testing
