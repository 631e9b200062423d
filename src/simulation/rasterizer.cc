#include "simulation/rasterizer.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "util/check.h"

namespace arpos::sim {
namespace {

// A triangle after near-plane clipping, ready for rasterisation.
struct RasterTri {
  // Edge functions e_i(px, py) = a[i] px + b[i] py + c[i]; all >= 0 inside
  // (sign-normalised). e_i = (d . (p_j x p_k)) for the viewing ray d.
  double a[3], b[3], c[3];
  double det_abs;           // |p0 . (p1 x p2)|: z = det_abs / sum(e)
  float xmin, xmax, ymin, ymax;
  // Barycentric weights of each clipped vertex on the original face.
  Eigen::Vector3f bary[3];
  Eigen::Vector3f face_normal;  // camera frame, unit
  int instance;
  int face;
};

struct ClipVertex {
  Eigen::Vector3d p;
  Eigen::Vector3f w;
};

// Sample positions within a pixel: an n-queens pattern on an S^2 x S^2
// sub-grid (n = S^2) with a queen at the centre. Every sample has its own
// column, row and diagonals, so edges along the axes and the diagonals see
// S^2 coverage levels instead of S (a regular S x S grid quantises an
// axis-aligned edge to 1/S pixel, a bias of up to 1/(2S) px along the whole
// edge). The centre sample lies exactly on the pixel centre.
std::vector<Eigen::Vector2d> SamplePattern(int S) {
  static const int kQueens9[9] = {1, 3, 8, 6, 4, 2, 0, 5, 7};
  static const int kQueens25[25] = {1, 3, 0, 2, 7, 9, 11, 13, 15, 21, 19, 22, 12,
                                    23, 4, 6, 24, 5, 10, 8, 17, 14, 16, 18, 20};
  const int n = S * S;
  std::vector<Eigen::Vector2d> offsets;
  for (int r = 0; r < n; ++r) {
    const int c = S == 1 ? 0 : S == 3 ? kQueens9[r] : kQueens25[r];
    offsets.emplace_back((c + 0.5) / n - 0.5, (r + 0.5) / n - 0.5);
  }
  return offsets;
}

struct PreparedInstance {
  const RenderMesh* mesh;
  const Material* material;
  const Texture* texture;
  std::vector<Eigen::Vector3f> normals_cam;
  int label;
  bool nearest;  // nearest-sampled artwork: always shaded per sample
};

}  // namespace

RenderOutput Render(const RenderScene& scene, const std::vector<RenderInstance>& instances,
                    const CameraIntrinsics& intrinsics, const Rigid3d& camera_from_room,
                    const Lighting& lighting, const RenderOptions& options) {
  const int S = options.supersampling;
  ARPOS_CHECK(S == 1 || S == 3 || S == 5, "supersampling must be 1, 3 or 5, got " << S);
  ARPOS_CHECK(intrinsics.width > 0 && intrinsics.height > 0, "bad image size");
  const int W = intrinsics.width, H = intrinsics.height;
  const double fx = intrinsics.fx, fy = intrinsics.fy, cx = intrinsics.cx, cy = intrinsics.cy;

  // --- Transform and clip every triangle (sequential: fixes the draw order).
  std::vector<PreparedInstance> prepared;
  prepared.reserve(instances.size());
  std::vector<RasterTri> tris;
  for (size_t inst = 0; inst < instances.size(); ++inst) {
    const RenderInstance& instance = instances[inst];
    ARPOS_CHECK(instance.mesh_override != nullptr ||
                    (instance.mesh >= 0 && instance.mesh < static_cast<int>(scene.meshes.size())),
                "bad mesh index " << instance.mesh);
    const RenderMesh& mesh =
        instance.mesh_override != nullptr ? *instance.mesh_override : scene.meshes[instance.mesh];
    ARPOS_CHECK(mesh.material >= 0 && mesh.material < static_cast<int>(scene.materials.size()),
                "mesh " << mesh.name << " has bad material");
    PreparedInstance pi;
    pi.mesh = &mesh;
    pi.material = &scene.materials[mesh.material];
    pi.texture = pi.material->texture >= 0 ? &scene.textures[pi.material->texture] : nullptr;
    pi.label = instance.label;
    pi.nearest = pi.texture != nullptr && pi.texture->nearest;
    const Eigen::Matrix3d r = instance.camera_from_part.RotationMatrix();
    const Eigen::Vector3d t = instance.camera_from_part.translation;
    const Eigen::Matrix3f rf = r.cast<float>();
    pi.normals_cam.reserve(mesh.normals.size());
    for (const auto& n : mesh.normals) pi.normals_cam.push_back(rf * n);
    std::vector<Eigen::Vector3d> verts(mesh.vertices.size());
    for (size_t i = 0; i < mesh.vertices.size(); ++i) {
      verts[i] = r * mesh.vertices[i].cast<double>() + t;
    }
    prepared.push_back(std::move(pi));

    for (size_t f = 0; f < mesh.faces.size(); ++f) {
      const Eigen::Vector3i& face = mesh.faces[f];
      ClipVertex in[3] = {{verts[face[0]], Eigen::Vector3f(1, 0, 0)},
                          {verts[face[1]], Eigen::Vector3f(0, 1, 0)},
                          {verts[face[2]], Eigen::Vector3f(0, 0, 1)}};
      const double near = options.near_m;
      if (in[0].p.z() < near && in[1].p.z() < near && in[2].p.z() < near) continue;
      // Sutherland-Hodgman against z >= near.
      ClipVertex poly[4];
      int count = 0;
      for (int k = 0; k < 3; ++k) {
        const ClipVertex& cur = in[k];
        const ClipVertex& nxt = in[(k + 1) % 3];
        const bool cur_in = cur.p.z() >= near, nxt_in = nxt.p.z() >= near;
        if (cur_in) poly[count++] = cur;
        if (cur_in != nxt_in) {
          const double s = (near - cur.p.z()) / (nxt.p.z() - cur.p.z());
          poly[count++] = {cur.p + s * (nxt.p - cur.p),
                           cur.w + static_cast<float>(s) * (nxt.w - cur.w)};
        }
      }
      const Eigen::Vector3d e1 = verts[face[1]] - verts[face[0]];
      const Eigen::Vector3d e2 = verts[face[2]] - verts[face[0]];
      Eigen::Vector3d fn = e1.cross(e2);
      const double fn_norm = fn.norm();
      if (!(fn_norm > 0)) continue;
      fn /= fn_norm;
      for (int k = 1; k + 1 < count; ++k) {
        const ClipVertex* v[3] = {&poly[0], &poly[k], &poly[k + 1]};
        const Eigen::Vector3d c0 = v[1]->p.cross(v[2]->p);
        const Eigen::Vector3d c1 = v[2]->p.cross(v[0]->p);
        const Eigen::Vector3d c2 = v[0]->p.cross(v[1]->p);
        const double det = v[0]->p.dot(c0);
        const double scale = v[0]->p.norm() * v[1]->p.norm() * v[2]->p.norm();
        if (!(std::abs(det) > 1e-12 * scale)) continue;  // edge-on or degenerate
        // det = p0 . n: positive when the counter-clockwise side faces away.
        if (mesh.cull_back_faces && det > 0) continue;
        const double sgn = det > 0 ? 1.0 : -1.0;
        RasterTri rt;
        const Eigen::Vector3d* cs[3] = {&c0, &c1, &c2};
        for (int i = 0; i < 3; ++i) {
          const Eigen::Vector3d& ci = *cs[i];
          rt.a[i] = sgn * ci.x() / fx;
          rt.b[i] = sgn * ci.y() / fy;
          rt.c[i] = sgn * (ci.z() - ci.x() * cx / fx - ci.y() * cy / fy);
          rt.bary[i] = v[i]->w;
        }
        rt.det_abs = std::abs(det);
        double xmin = 1e300, xmax = -1e300, ymin = 1e300, ymax = -1e300;
        for (int i = 0; i < 3; ++i) {
          const double u = fx * v[i]->p.x() / v[i]->p.z() + cx;
          const double w = fy * v[i]->p.y() / v[i]->p.z() + cy;
          xmin = std::min(xmin, u);
          xmax = std::max(xmax, u);
          ymin = std::min(ymin, w);
          ymax = std::max(ymax, w);
        }
        if (xmax < -1 || ymax < -1 || xmin > W || ymin > H) continue;
        rt.xmin = static_cast<float>(std::max(xmin, -1.0));
        rt.xmax = static_cast<float>(std::min(xmax, static_cast<double>(W)));
        rt.ymin = static_cast<float>(std::max(ymin, -1.0));
        rt.ymax = static_cast<float>(std::min(ymax, static_cast<double>(H)));
        rt.face_normal = fn.cast<float>();
        rt.instance = static_cast<int>(inst);
        rt.face = static_cast<int>(f);
        tris.push_back(rt);
      }
    }
  }

  // --- Bin triangles into bands of pixel rows (in draw order).
  const std::vector<Eigen::Vector2d> offsets = SamplePattern(S);
  const int N = S * S;
  const int centre = N / 2;  // the queen at the centre of the sub-grid
  const int band_rows = std::max(1, options.band_rows);
  const int num_bands = (H + band_rows - 1) / band_rows;
  // Pixels whose sample square [p - 0.5, p + 0.5] can meet the triangle.
  auto pixel_lo = [](double p) { return static_cast<int>(std::ceil(p - 0.5)); };
  auto pixel_hi = [](double p) { return static_cast<int>(std::floor(p + 0.5)); };
  std::vector<std::vector<int>> bands(num_bands);
  for (size_t i = 0; i < tris.size(); ++i) {
    const RasterTri& rt = tris[i];
    const int x0 = std::max(0, pixel_lo(rt.xmin)), x1 = std::min(W - 1, pixel_hi(rt.xmax));
    const int y0 = std::max(0, pixel_lo(rt.ymin)), y1 = std::min(H - 1, pixel_hi(rt.ymax));
    if (x0 > x1 || y0 > y1) continue;
    for (int band = y0 / band_rows; band <= y1 / band_rows; ++band) {
      bands[band].push_back(static_cast<int>(i));
    }
  }

  // Lights in the camera frame.
  std::vector<std::pair<Eigen::Vector3f, Eigen::Vector3f>> lights;
  for (const auto& light : lighting.lights) {
    lights.emplace_back((camera_from_room * light.position_in_room_m.cast<double>()).cast<float>(),
                        light.intensity);
  }

  RenderOutput out;
  out.color.create(H, W, CV_32FC3);
  out.depth.create(H, W, CV_32F);
  out.normal.create(H, W, CV_32FC3);
  out.label.create(H, W, CV_32S);
  const float inv_samples = 1.0f / static_cast<float>(N);

#pragma omp parallel
  {
    std::vector<float> zbuf;
    std::vector<int> ids;
    std::vector<double> step(3 * N), wstep(N);
#pragma omp for schedule(dynamic, 1)
    for (int band = 0; band < num_bands; ++band) {
      const int row0 = band * band_rows, row1 = std::min(H, row0 + band_rows);
      const size_t n = static_cast<size_t>(row1 - row0) * W * N;
      // Inverse depth 1/z = sum(e) / det is linear in the image: compared
      // without a division per sample (larger = nearer).
      zbuf.assign(n, 0.0f);
      ids.assign(n, -1);
      // Visibility: samples of pixel (u, v) are at (u, v) + offsets[k].
      for (int ti : bands[band]) {
        const RasterTri& rt = tris[ti];
        const int x0 = std::max(0, pixel_lo(rt.xmin)), x1 = std::min(W - 1, pixel_hi(rt.xmax));
        const int y0 = std::max(row0, pixel_lo(rt.ymin)), y1 = std::min(row1 - 1, pixel_hi(rt.ymax));
        const double inv_det = 1.0 / rt.det_abs;
        for (int k = 0; k < N; ++k) {
          double sum = 0;
          for (int q = 0; q < 3; ++q) {
            step[3 * k + q] = rt.a[q] * offsets[k].x() + rt.b[q] * offsets[k].y();
            sum += step[3 * k + q];
          }
          wstep[k] = sum * inv_det;
        }
        // How much each edge function can drop within a pixel square.
        const double r0 = 0.5 * (std::abs(rt.a[0]) + std::abs(rt.b[0]));
        const double r1 = 0.5 * (std::abs(rt.a[1]) + std::abs(rt.b[1]));
        const double r2 = 0.5 * (std::abs(rt.a[2]) + std::abs(rt.b[2]));
        for (int v = y0; v <= y1; ++v) {
          for (int u = x0; u <= x1; ++u) {
            const double b0 = rt.a[0] * u + rt.b[0] * v + rt.c[0];
            const double b1 = rt.a[1] * u + rt.b[1] * v + rt.c[1];
            const double b2 = rt.a[2] * u + rt.b[2] * v + rt.c[2];
            const bool covered = b0 >= r0 && b1 >= r1 && b2 >= r2;  // every sample inside
            const double wbase = (b0 + b1 + b2) * inv_det;
            const size_t base = (static_cast<size_t>(v - row0) * W + u) * N;
            for (int k = 0; k < N; ++k) {
              if (!covered) {
                const double e0 = b0 + step[3 * k], e1 = b1 + step[3 * k + 1], e2 = b2 + step[3 * k + 2];
                if (e0 < 0 || e1 < 0 || e2 < 0 || !(e0 + e1 + e2 > 0)) continue;
              }
              const float w = static_cast<float>(wbase + wstep[k]);
              if (w > zbuf[base + k]) {
                zbuf[base + k] = w;
                ids[base + k] = ti;
              }
            }
          }
        }
      }
      // Shading and resolve. A pixel whose samples all hit one mesh with a
      // smooth (bilinear) texture or vertex colours and no depth step is
      // shaded once at its centre: its texture is already band-limited and
      // the samples would agree up to texture detail. Pixels on silhouettes
      // or with nearest-sampled artwork (markers) are shaded per sample,
      // which keeps those edges exact.
      for (int row = row0; row < row1; ++row) {
        auto* color_row = out.color.ptr<cv::Vec3f>(row);
        auto* depth_row = out.depth.ptr<float>(row);
        auto* normal_row = out.normal.ptr<cv::Vec3f>(row);
        auto* label_row = out.label.ptr<int>(row);
        for (int col = 0; col < W; ++col) {
          depth_row[col] = 0;
          normal_row[col] = cv::Vec3f(0, 0, 0);
          label_row[col] = 0;
          const size_t base = (static_cast<size_t>(row - row0) * W + col) * N;
          // Uniform: every sample on the same smooth-textured mesh with no
          // depth step (no silhouette inside the pixel).
          const int centre_id = ids[base + centre];
          bool uniform = centre_id >= 0 && !prepared[tris[centre_id].instance].nearest;
          if (uniform) {
            const int instance = tris[centre_id].instance;
            const float wc = zbuf[base + centre], tolerance = 0.01f * wc;
            for (int k = 0; k < N && uniform; ++k) {
              const int id = ids[base + k];
              uniform = id == centre_id ||
                        (id >= 0 && tris[id].instance == instance &&
                         std::abs(zbuf[base + k] - wc) < tolerance);
            }
          }
          Eigen::Vector3f sum = Eigen::Vector3f::Zero();
          int cached_tri = -2;
          Eigen::Vector3f cached_irradiance = Eigen::Vector3f::Zero();
          const int first_k = uniform ? centre : 0, last_k = uniform ? centre : N - 1;
          for (int k = first_k; k <= last_k; ++k) {
            const int ti = ids[base + k];
            if (ti < 0) {
              sum += options.background;
              continue;
            }
            const double px = col + offsets[k].x(), py = row + offsets[k].y();
            const RasterTri& rt = tris[ti];
            double e[3];
            for (int q = 0; q < 3; ++q) e[q] = rt.a[q] * px + rt.b[q] * py + rt.c[q];
            const double es = e[0] + e[1] + e[2];
            Eigen::Vector3f w = Eigen::Vector3f::Zero();
            for (int q = 0; q < 3; ++q) w += static_cast<float>(e[q] / es) * rt.bary[q];
            const PreparedInstance& pi = prepared[rt.instance];
            const RenderMesh& mesh = *pi.mesh;
            const Eigen::Vector3i& face = mesh.faces[rt.face];
            Eigen::Vector3f albedo = pi.material->albedo;
            if (pi.texture != nullptr && !mesh.uvs.empty()) {
              const Eigen::Vector2f uv =
                  w[0] * mesh.uvs[face[0]] + w[1] * mesh.uvs[face[1]] + w[2] * mesh.uvs[face[2]];
              albedo = albedo.cwiseProduct(pi.texture->Sample(uv.x(), uv.y()));
            }
            if (pi.material->vertex_colors && !mesh.colors.empty()) {
              albedo = albedo.cwiseProduct(w[0] * mesh.colors[face[0]] + w[1] * mesh.colors[face[1]] +
                                           w[2] * mesh.colors[face[2]]);
            }
            const bool is_centre = k == centre;
            if (ti != cached_tri || is_centre) {
              const float z = 1.0f / zbuf[base + k];
              const Eigen::Vector3f point(static_cast<float>((px - cx) / fx) * z,
                                          static_cast<float>((py - cy) / fy) * z, z);
              Eigen::Vector3f normal = rt.face_normal;
              if (!pi.normals_cam.empty()) {
                const Eigen::Vector3f nn = w[0] * pi.normals_cam[face[0]] +
                                           w[1] * pi.normals_cam[face[1]] +
                                           w[2] * pi.normals_cam[face[2]];
                if (nn.squaredNorm() > 0) normal = nn.normalized();
              }
              // Shade the side facing the camera (the geometric side decides).
              if (rt.face_normal.dot(point) > 0) normal = -normal;
              if (ti != cached_tri) {
                Eigen::Vector3f irradiance = lighting.ambient;
                for (const auto& [position, intensity] : lights) {
                  const Eigen::Vector3f to_light = position - point;
                  const float d2 = std::max(to_light.squaredNorm(), 0.01f);
                  const float cosine = normal.dot(to_light) / std::sqrt(d2);
                  if (cosine > 0) irradiance += intensity * (cosine / d2);
                }
                cached_irradiance = irradiance;
                cached_tri = ti;
              }
              if (is_centre) {
                depth_row[col] = z;
                normal_row[col] = cv::Vec3f(normal.x(), normal.y(), normal.z());
                label_row[col] = pi.label;
              }
            }
            sum += albedo.cwiseProduct(cached_irradiance);
          }
          if (!uniform) sum *= inv_samples;
          color_row[col] = cv::Vec3f(sum.x(), sum.y(), sum.z());
        }
      }
    }
  }
  return out;
}

}  // namespace arpos::sim
