#include "simulation/world.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <opencv2/aruco.hpp>

#include "geometry/mesh_io.h"
#include "geometry/so3.h"
#include "simulation/random.h"
#include "simulation/textures.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos::sim {
namespace {

// Room layout (room frame = marker 0 frame, z up, metres).
constexpr double kFloorZ = -0.0003;           // paper thickness below marker faces
constexpr double kPaperOffset = 0.0003;       // markers stand off walls by this
constexpr double kCouchCentreX = kCouchCentreX_m;
constexpr double kCouchFootY = kCouchFootY_m, kCouchHeadY = kCouchHeadY_m;
constexpr double kCouchWidth = 0.58;
constexpr double kCouchTopZ = 0.80, kCouchThickness = 0.05;
constexpr double kTexelM = 0.004;

float Smoothstep(float e0, float e1, float x) {
  const float t = std::clamp((x - e0) / (e1 - e0), 0.0f, 1.0f);
  return t * t * (3 - 2 * t);
}

Eigen::Vector3f SrgbToLinear(int r, int g, int b) {
  return {LinearFromSrgb8(static_cast<uint8_t>(r)), LinearFromSrgb8(static_cast<uint8_t>(g)),
          LinearFromSrgb8(static_cast<uint8_t>(b))};
}

int AddTexture(RenderScene* scene, Texture texture) {
  scene->textures.push_back(std::move(texture));
  return static_cast<int>(scene->textures.size()) - 1;
}

int AddMaterial(RenderScene* scene, int texture, const Eigen::Vector3f& albedo,
                bool vertex_colors = false) {
  Material m;
  m.texture = texture;
  m.albedo = albedo;
  m.vertex_colors = vertex_colors;
  scene->materials.push_back(m);
  return static_cast<int>(scene->materials.size()) - 1;
}

int AddMesh(RenderScene* scene, RenderMesh mesh) {
  scene->meshes.push_back(std::move(mesh));
  return static_cast<int>(scene->meshes.size()) - 1;
}

// A textured plane: corners p0..p3 (counter-clockwise from the front), texture
// of its size.
int AddTexturedPlane(RenderScene* scene, const std::string& name, SurfaceStyle style,
                     const Eigen::Vector3d& p0, const Eigen::Vector3d& p1,
                     const Eigen::Vector3d& p2, const Eigen::Vector3d& p3, uint64_t seed,
                     TextureDetail detail = TextureDetail::kRich) {
  const double w = (p1 - p0).norm(), h = (p3 - p0).norm();
  const int tex = AddTexture(scene, MakeSurfaceTexture(style, w, h, kTexelM, seed, detail));
  const int mat = AddMaterial(scene, tex, Eigen::Vector3f(1, 1, 1));
  RenderMesh mesh;
  mesh.name = name;
  mesh.material = mat;
  const int n = std::max(1, static_cast<int>(std::ceil(w / 0.4)));
  const int m = std::max(1, static_cast<int>(std::ceil(h / 0.4)));
  // Texture row 0 is the top: uv v grows from p3 (top) to p0 (bottom).
  mesh.AddQuad(p0.cast<float>(), p1.cast<float>(), p2.cast<float>(), p3.cast<float>(), n, m,
               {0, 1}, {1, 0});
  return AddMesh(scene, std::move(mesh));
}

// A box with one texture wrapped per face (uv per metre).
int AddTexturedBox(RenderScene* scene, const std::string& name, SurfaceStyle style,
                   const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, uint64_t seed,
                   TextureDetail detail = TextureDetail::kRich) {
  const double tex_m = 1.0;
  const int tex = AddTexture(scene, MakeSurfaceTexture(style, tex_m, tex_m, kTexelM, seed, detail));
  scene->textures[tex].wrap = true;
  const int mat = AddMaterial(scene, tex, Eigen::Vector3f(1, 1, 1));
  RenderMesh mesh;
  mesh.name = name;
  mesh.material = mat;
  mesh.AddBox(lo.cast<float>(), hi.cast<float>(), static_cast<float>(1.0 / tex_m));
  return AddMesh(scene, std::move(mesh));
}

// A printed marker: the artwork quad in the marker's frame, then placed.
int AddMarkerMesh(RenderScene* scene, const std::string& name, const MarkerArtwork& art,
                  double size_m) {
  const int tex = AddTexture(scene, art.texture);
  const int mat = AddMaterial(scene, tex, Eigen::Vector3f(1, 1, 1));
  const double cell = size_m / art.marker_cells;
  const double half = size_m / 2 + art.quiet_cells * cell;
  const double bottom = -half - art.label_cells * cell;
  RenderMesh mesh;
  mesh.name = name;
  mesh.material = mat;
  // Texture v = 0 at the top of the page (+y), u = 0 at the left (-x).
  mesh.AddQuad(Eigen::Vector3f(-half, bottom, 0), Eigen::Vector3f(half, bottom, 0),
               Eigen::Vector3f(half, half, 0), Eigen::Vector3f(-half, half, 0), 1, 1, {0, 1},
               {1, 0});
  return AddMesh(scene, std::move(mesh));
}

void TransformMesh(RenderMesh* mesh, const Rigid3d& b_from_a) {
  const Eigen::Matrix3f r = b_from_a.RotationMatrix().cast<float>();
  const Eigen::Vector3f t = b_from_a.translation.cast<float>();
  for (auto& v : mesh->vertices) v = r * v + t;
  for (auto& n : mesh->normals) n = r * n;
}

// Rotation whose columns are the given axes.
Rigid3d FrameFromAxes(const Eigen::Vector3d& x, const Eigen::Vector3d& y, const Eigen::Vector3d& z,
                      const Eigen::Vector3d& origin) {
  Eigen::Matrix3d r;
  r.col(0) = x.normalized();
  r.col(1) = y.normalized();
  r.col(2) = z.normalized();
  return Rigid3d(ProjectToSO3(r), origin);
}

// --- Body -----------------------------------------------------------------

struct BodyRegions {
  // MakeHuman y (metres, after scaling) of landmarks.
  double feet_y, top_y;
};

// Loads the MakeHuman body, lowers the arms (A-pose -> arms along the body,
// so that a supine patient fits on the couch), converts to the LPS model
// frame and moves the origin to the isocentre.
TriangleMesh LoadBody(const std::filesystem::path& path, Eigen::Vector3d* iso_in_mh,
                      std::vector<int>* region_of_vertex, std::vector<float>* arm_weight) {
  MeshLoadOptions load;
  load.units_scale = 0.1;  // MakeHuman decimetres
  load.only_group = "body";
  TriangleMesh mesh = LoadTriangleMesh(path, load);
  // Arms: blend a rotation about each shoulder in the coronal plane (a
  // two-bone linear-blend skin), weight rising across the shoulder.
  const double angle = RadFromDeg(27.0);
  arm_weight->assign(mesh.vertices.size(), 0.0f);
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    Eigen::Vector3f& v = mesh.vertices[i];
    if (v.y() < 0.0f) continue;
    const float w = Smoothstep(0.175f, 0.23f, std::abs(v.x())) * (1.0f - Smoothstep(0.52f, 0.58f, v.y()));
    if (w <= 0) continue;
    (*arm_weight)[i] = w;
    const float side = v.x() > 0 ? 1.0f : -1.0f;
    const Eigen::Vector2f pivot(side * 0.175f, 0.50f);
    const float a = static_cast<float>(-side * angle * w);  // down, towards the body
    const Eigen::Vector2f d(v.x() - pivot.x(), v.y() - pivot.y());
    const Eigen::Vector2f r(std::cos(a) * d.x() - std::sin(a) * d.y(),
                            std::sin(a) * d.x() + std::cos(a) * d.y());
    v.x() = pivot.x() + r.x();
    v.y() = pivot.y() + r.y();
  }
  // The A-pose also holds the hands ~0.3 m in front of the body; swing each
  // arm back about the shoulder (rotation about x, same weights) until the
  // hand's centre is 5 cm in front of the back, so that a supine patient's
  // arms rest by the sides instead of floating above the lap.
  {
    double back_z = 1e9, shoulder_z = 0;
    int shoulder_count = 0;
    for (size_t i = 0; i < mesh.vertices.size(); ++i) {
      const Eigen::Vector3f& v = mesh.vertices[i];
      if ((*arm_weight)[i] == 0 && std::abs(v.x()) < 0.15f && v.y() > 0.0f && v.y() < 0.2f) {
        back_z = std::min<double>(back_z, v.z());
      }
      if (std::abs(std::abs(v.x()) - 0.19f) < 0.02f && std::abs(v.y() - 0.5f) < 0.02f) {
        shoulder_z += v.z();
        ++shoulder_count;
      }
    }
    shoulder_z = shoulder_count > 0 ? shoulder_z / shoulder_count : 0.0;
    Eigen::Vector2d hand = Eigen::Vector2d::Zero();  // (y, z) of the hands' centre
    int hand_count = 0;
    for (size_t i = 0; i < mesh.vertices.size(); ++i) {
      if ((*arm_weight)[i] >= 1.0f && mesh.vertices[i].y() < 0.15f) {
        hand += Eigen::Vector2d(mesh.vertices[i].y(), mesh.vertices[i].z());
        ++hand_count;
      }
    }
    if (hand_count > 0 && back_z < 1e8) {
      hand /= hand_count;
      const Eigen::Vector2d pivot(0.50, shoulder_z);
      const Eigen::Vector2d d = hand - pivot;
      const double target_z = back_z + 0.12;
      // Rotation by phi maps (dy, dz) to (cos dy - sin dz, sin dy + cos dz):
      // search the smallest swing that brings the hand to the target depth.
      double phi = 0, best = 1e9;
      for (int k = -180; k <= 180; ++k) {
        const double a = RadFromDeg(0.25 * k);
        const double y = std::cos(a) * d.x() - std::sin(a) * d.y();
        const double z = std::sin(a) * d.x() + std::cos(a) * d.y();
        const double cost = std::abs(pivot.y() + z - target_z) + (y > -0.2 ? 1.0 : 0.0);
        if (cost < best - 1e-12) {
          best = cost;
          phi = a;
        }
      }
      for (size_t i = 0; i < mesh.vertices.size(); ++i) {
        const float w = (*arm_weight)[i];
        if (w <= 0) continue;
        Eigen::Vector3f& v = mesh.vertices[i];
        const double a = phi * w;
        const double dy = v.y() - pivot.x(), dz = v.z() - pivot.y();
        v.y() = static_cast<float>(pivot.x() + std::cos(a) * dy - std::sin(a) * dz);
        v.z() = static_cast<float>(pivot.y() + std::sin(a) * dy + std::cos(a) * dz);
      }
    }
  }
  Eigen::Vector3f lo, hi;
  mesh.Bounds(&lo, &hi);
  // Isocentre: upper abdomen, midline, halfway between front and back.
  const double iso_y = lo.y() + 0.60 * (hi.y() - lo.y());
  double zmin = 1e9, zmax = -1e9;
  for (const auto& v : mesh.vertices) {
    if (std::abs(v.x()) < 0.03 && std::abs(v.y() - iso_y) < 0.02) {
      zmin = std::min<double>(zmin, v.z());
      zmax = std::max<double>(zmax, v.z());
    }
  }
  ARPOS_CHECK(zmin < zmax, "could not find the torso in " << path.string());
  *iso_in_mh = Eigen::Vector3d(0, iso_y, 0.5 * (zmin + zmax));
  // Regions (for colours and stickers), by height fraction.
  region_of_vertex->assign(mesh.vertices.size(), 0);
  const double height = hi.y() - lo.y();
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    const Eigen::Vector3f& v = mesh.vertices[i];
    const double f = (v.y() - lo.y()) / height;
    const double ax = std::abs(v.x());
    int region = 0;  // skin elsewhere
    if ((*arm_weight)[i] > 0.5f) {
      region = 0;
    } else if (f > 0.435 && f < 0.545 && ax < 0.2) {
      region = 1;  // shorts
    } else if (f > 0.87 && v.z() < iso_in_mh->z() + 0.02) {
      region = 2;  // hair (back and top of the head)
    } else if (f > 0.67 && f < 0.76 && ax < 0.12) {
      region = 3;  // chest
    } else if (f > 0.555 && f < 0.655 && ax < 0.11) {
      region = 4;  // abdomen
    } else if (f > 0.30 && f < 0.42 && ax > 0.03 && ax < 0.17) {
      region = v.x() > 0 ? 5 : 6;  // thighs (left, right)
    }
    (*region_of_vertex)[i] = region;
  }
  // MakeHuman (x = patient left, y up, z anterior) -> LPS (x left, y
  // posterior, z superior), origin at the isocentre.
  Eigen::Matrix3d model_from_mh;
  model_from_mh << 1, 0, 0, 0, 0, -1, 0, 1, 0;
  const Rigid3d model_from_mh_pose(model_from_mh, -(model_from_mh * *iso_in_mh));
  mesh.Transform(model_from_mh_pose);
  mesh.ComputeVertexNormals();
  return mesh;
}

// Flips the diagonal of every quad that the loader split into two
// consecutive triangles (a, b, c), (a, c, d), where the two triangulations
// are within `max_difference_m` of each other (nearly planar quads: most of
// the body). Strongly bent quads (fingers, toes, ears) keep their diagonal so
// that the re-tessellated surface stays within that bound everywhere.
// `*flipped_fraction` receives the share of quads flipped and
// `*max_flipped_difference_m` the largest difference among them.
std::vector<Eigen::Vector3i> FlipQuadDiagonals(const TriangleMesh& mesh, double max_difference_m,
                                               double* flipped_fraction,
                                               double* max_flipped_difference_m) {
  const auto& faces = mesh.faces;
  std::vector<Eigen::Vector3i> out;
  out.reserve(faces.size());
  int quads = 0, flipped = 0;
  *max_flipped_difference_m = 0;
  size_t i = 0;
  while (i < faces.size()) {
    if (i + 1 < faces.size()) {
      const Eigen::Vector3i& t1 = faces[i];
      const Eigen::Vector3i& t2 = faces[i + 1];
      // Find the shared directed edge s1->s2 in t1 (it is s2->s1 in t2).
      bool done = false;
      for (int k = 0; k < 3 && !done; ++k) {
        const int s1 = t1[(k + 1) % 3], s2 = t1[(k + 2) % 3], o1 = t1[k];
        for (int q = 0; q < 3; ++q) {
          if (t2[(q + 1) % 3] == s2 && t2[(q + 2) % 3] == s1) {
            const int o2 = t2[q];
            ++quads;
            // Half the distance of o2 from plane (o1, s1, s2) bounds how far
            // the two triangulations are apart.
            const Eigen::Vector3d a = mesh.vertices[o1].cast<double>();
            const Eigen::Vector3d n = (mesh.vertices[s1] - mesh.vertices[o1])
                                          .cast<double>()
                                          .cross((mesh.vertices[s2] - mesh.vertices[o1]).cast<double>());
            const double difference =
                n.norm() > 0 ? 0.5 * std::abs((mesh.vertices[o2].cast<double>() - a).dot(n.normalized()))
                             : 1e9;
            if (difference <= max_difference_m) {
              out.emplace_back(o1, s1, o2);
              out.emplace_back(o1, o2, s2);
              ++flipped;
              *max_flipped_difference_m = std::max(*max_flipped_difference_m, difference);
            } else {
              out.push_back(t1);
              out.push_back(t2);
            }
            done = true;
            break;
          }
        }
      }
      if (done) {
        i += 2;
        continue;
      }
    }
    out.push_back(faces[i]);
    ++i;
  }
  *flipped_fraction = quads > 0 ? static_cast<double>(flipped) / quads : 0.0;
  return out;
}

TriangleMesh MidpointSubdivide(const TriangleMesh& mesh) {
  TriangleMesh out;
  out.vertices = mesh.vertices;
  std::map<std::pair<int, int>, int> midpoint;
  auto mid = [&](int a, int b) {
    const auto key = std::minmax(a, b);
    auto it = midpoint.find(key);
    if (it != midpoint.end()) return it->second;
    out.vertices.push_back(0.5f * (mesh.vertices[a] + mesh.vertices[b]));
    const int index = static_cast<int>(out.vertices.size()) - 1;
    midpoint.emplace(key, index);
    return index;
  };
  for (const auto& f : mesh.faces) {
    const int ab = mid(f[0], f[1]), bc = mid(f[1], f[2]), ca = mid(f[2], f[0]);
    out.faces.emplace_back(f[0], ab, ca);
    out.faces.emplace_back(ab, f[1], bc);
    out.faces.emplace_back(ca, bc, f[2]);
    out.faces.emplace_back(ab, bc, ca);
  }
  return out;
}

// Ray from `origin` along `dir` (unit) against triangles `candidates`;
// smallest positive t, or -1.
double RayCast(const TriangleMesh& mesh, const std::vector<int>& candidates,
               const Eigen::Vector3d& origin, const Eigen::Vector3d& dir) {
  double best = -1;
  for (int fi : candidates) {
    const Eigen::Vector3i& f = mesh.faces[fi];
    const Eigen::Vector3d v0 = mesh.vertices[f[0]].cast<double>();
    const Eigen::Vector3d e1 = mesh.vertices[f[1]].cast<double>() - v0;
    const Eigen::Vector3d e2 = mesh.vertices[f[2]].cast<double>() - v0;
    const Eigen::Vector3d p = dir.cross(e2);
    const double det = e1.dot(p);
    if (std::abs(det) < 1e-15) continue;
    const Eigen::Vector3d s = origin - v0;
    const double u = s.dot(p) / det;
    if (u < 0 || u > 1) continue;
    const Eigen::Vector3d q = s.cross(e1);
    const double v = dir.dot(q) / det;
    if (v < 0 || u + v > 1) continue;
    const double t = e2.dot(q) / det;
    if (t > 0 && (best < 0 || t < best)) best = t;
  }
  return best;
}

}  // namespace

std::string RoomLayout::Check() const {
  if (!(wall_left_x_m < -1.2) || !(wall_right_x_m > 2.8) || !(wall_foot_y_m < -1.2) ||
      !(wall_head_y_m > 4.45) || !(ceiling_z_m > 2.75)) {
    return "room layout: walls or ceiling too close to the couch, gantry or lights";
  }
  return "";
}

double World::BreathingWeight(const Eigen::Vector3d& p) const {
  const float f = static_cast<float>((p.z() - body_lowest_z_m) / body_height_m);
  const float along = Smoothstep(0.52f, 0.58f, f) * (1.0f - Smoothstep(0.76f, 0.82f, f));
  const float lateral = 1.0f - Smoothstep(0.09f, 0.16f, static_cast<float>(std::abs(p.x())));
  const float front = Smoothstep(0.0f, 0.05f, static_cast<float>(-p.y()));  // y is posterior
  return along * lateral * front;
}

std::array<Eigen::Vector3d, 4> MarkerCornersInMarker(double size_m) {
  const double h = size_m / 2;
  return {Eigen::Vector3d(-h, h, 0), Eigen::Vector3d(h, h, 0), Eigen::Vector3d(h, -h, 0),
          Eigen::Vector3d(-h, -h, 0)};
}

World BuildWorld(const WorldOptions& options) {
  if (const std::string problem = options.layout.Check(); !problem.empty()) ARPOS_INPUT_ERROR(problem);
  ARPOS_CHECK(options.room_marker_places.empty() ||
                  options.room_marker_places.size() == static_cast<size_t>(kRoomMarkerPlaces),
              "room_marker_places: expected " << kRoomMarkerPlaces << " entries");
  World world;
  RenderScene& scene = world.scene;
  world.layout = options.layout;
  world.origin_moved = !options.world_from_origin_marker.IsApprox(Rigid3d::Identity(), 0, 0);
  world.room_from_world = options.world_from_origin_marker.Inverse();
  if (!world.origin_moved) world.room_from_world = Rigid3d::Identity();
  const int dictionary = options.dictionary;

  // --- Patient ---------------------------------------------------------------
  Eigen::Vector3d iso_in_mh;
  std::vector<int> region;
  std::vector<float> arm_weight;
  TriangleMesh body = LoadBody(options.body_mesh_path, &iso_in_mh, &region, &arm_weight);
  world.body_surface = body;

  // Target: supine, head towards +y, on the couch centre line, resting on
  // the couch top (the most posterior point touches it).
  Eigen::Matrix3d room_from_model_r;
  room_from_model_r << 1, 0, 0, 0, 0, 1, 0, -1, 0;  // x->x, y(posterior)->-z, z(superior)->+y
  double max_posterior = -1e9, min_superior = 1e9;
  for (const auto& v : body.vertices) {
    max_posterior = std::max<double>(max_posterior, v.y());
    min_superior = std::min<double>(min_superior, v.z());
  }
  const Eigen::Vector3d iso_room(kCouchCentreX, kCouchFootY + 0.12 - min_superior,
                                 kCouchTopZ + max_posterior + 0.0005);
  world.room_from_model_target = Rigid3d(room_from_model_r, iso_room);
  world.couch_top_height_m = kCouchTopZ;
  world.couch_top_home_centre_room_m =
      Eigen::Vector3d(kCouchCentreX, 0.5 * (kCouchFootY + kCouchHeadY), kCouchTopZ);
  {
    Eigen::Vector3f lo, hi;
    body.Bounds(&lo, &hi);
    world.body_lowest_z_m = lo.z();
    world.body_height_m = std::max(1e-6f, hi.z() - lo.z());
    world.body_breathing_weight.resize(body.vertices.size());
    for (size_t i = 0; i < body.vertices.size(); ++i) {
      // The arms lie beside the chest: they do not breathe.
      const double w = world.BreathingWeight(body.vertices[i].cast<double>());
      world.body_breathing_weight[i] = static_cast<float>(w * (1.0 - arm_weight[i]));
    }
  }

  // Skin, shorts and hair as vertex colours with a little low-frequency
  // variation (freckles of the texture would not survive a 1.5 cm mesh).
  {
    Rng rng(StreamSeed(options.seed, Stream::kBody));
    const Eigen::Vector3f skin = SrgbToLinear(214, 164, 134);
    const Eigen::Vector3f shorts = SrgbToLinear(40, 58, 104);
    const Eigen::Vector3f hair = SrgbToLinear(70, 50, 36);
    Eigen::Vector3d k1(rng.Uniform(20, 40), rng.Uniform(20, 40), rng.Uniform(20, 40));
    const double ph = rng.Uniform(0, 6.28);
    RenderMesh mesh;
    mesh.name = "body";
    mesh.vertices = body.vertices;
    mesh.normals = body.vertex_normals;
    mesh.faces = body.faces;
    for (size_t i = 0; i < body.vertices.size(); ++i) {
      const Eigen::Vector3d p = body.vertices[i].cast<double>();
      const float n = static_cast<float>(0.06 * std::sin(k1.x() * p.x() + ph) *
                                         std::sin(k1.y() * p.y()) * std::cos(k1.z() * p.z()));
      Eigen::Vector3f c = skin;
      if (region[i] == 1) c = shorts;
      if (region[i] == 2) c = hair;
      mesh.colors.push_back(c * (1.0f + n));
    }
    mesh.material = AddMaterial(&scene, -1, Eigen::Vector3f(1, 1, 1), true);
    mesh.cull_back_faces = body.IsClosed();
    world.body_mesh = AddMesh(&scene, std::move(mesh));
  }

  // Reference model: other diagonals, one midpoint subdivision, noise.
  {
    TriangleMesh flipped;
    flipped.vertices = body.vertices;
    flipped.faces = FlipQuadDiagonals(body, options.max_tessellation_difference_m,
                                      &world.flipped_quad_fraction,
                                      &world.max_tessellation_difference_m);
    TriangleMesh reference = MidpointSubdivide(flipped);
    reference.ComputeVertexNormals();
    Rng rng(StreamSeed(options.seed, Stream::kReferenceNoise));
    for (size_t i = 0; i < reference.vertices.size(); ++i) {
      reference.vertices[i] +=
          static_cast<float>(rng.Normal() * options.reference_noise_m) * reference.vertex_normals[i];
    }
    reference.ComputeVertexNormals();
    world.reference_model = std::move(reference);
  }

  // --- Body stickers (model frame) -------------------------------------------
  {
    Rng rng(StreamSeed(options.seed, Stream::kStickers));
    const int count = rng.UniformInt(std::max(8, options.min_stickers),
                                     std::min(20, options.max_stickers));
    // Region quotas: chest, abdomen, left thigh, right thigh.
    std::vector<int> plan;
    const int regions[4] = {3, 4, 5, 6};
    const int quota[4] = {count * 3 / 10, count * 4 / 10, 0, 0};
    for (int r = 0; r < 2; ++r)
      for (int k = 0; k < quota[r]; ++k) plan.push_back(regions[r]);
    for (int k = 0; static_cast<int>(plan.size()) < count; ++k) plan.push_back(k % 2 ? 6 : 5);
    std::vector<std::vector<int>> faces_in_region(7);
    for (size_t f = 0; f < body.faces.size(); ++f) {
      const Eigen::Vector3i& face = body.faces[f];
      if (region[face[0]] == region[face[1]] && region[face[1]] == region[face[2]]) {
        faces_in_region[region[face[0]]].push_back(static_cast<int>(f));
      }
    }
    const double size = options.body_marker_size_m;
    const double sticker_half = size / 2 + size / 6;  // one quiet cell of white
    std::vector<int> ids;
    for (int id = 100; id <= 199; ++id) ids.push_back(id);
    for (size_t i = ids.size() - 1; i > 0; --i) {
      std::swap(ids[i], ids[rng.UniformInt(0, static_cast<int>(i))]);
    }
    const Eigen::Vector3d anterior(0, -1, 0);
    const char* const region_names[7] = {"skin", "shorts", "hair", "chest", "abdomen",
                                         "thigh_left", "thigh_right"};
    for (int r : plan) {
      const auto& candidates = faces_in_region[r];
      if (candidates.empty()) continue;
      for (int attempt = 0; attempt < 400; ++attempt) {
        const Eigen::Vector3i& face = body.faces[candidates[rng.UniformInt(
            0, static_cast<int>(candidates.size()) - 1)]];
        double a = rng.Uniform(), b = rng.Uniform();
        if (a + b > 1) {
          a = 1 - a;
          b = 1 - b;
        }
        const Eigen::Vector3d p = body.vertices[face[0]].cast<double>() +
                                  a * (body.vertices[face[1]] - body.vertices[face[0]]).cast<double>() +
                                  b * (body.vertices[face[2]] - body.vertices[face[0]]).cast<double>();
        bool too_close = false;
        for (const auto& m : world.body_markers) {
          if ((m.parent_from_marker.translation - p).norm() < 0.075) too_close = true;
        }
        if (too_close) continue;
        // Tangent plane: area-weighted face normals within 2.5 cm.
        Eigen::Vector3d n = Eigen::Vector3d::Zero();
        std::vector<int> nearby;
        for (size_t f = 0; f < body.faces.size(); ++f) {
          const Eigen::Vector3i& g = body.faces[f];
          const Eigen::Vector3d c = (body.vertices[g[0]] + body.vertices[g[1]] + body.vertices[g[2]])
                                        .cast<double>() / 3.0;
          const double d = (c - p).norm();
          if (d < 0.06) nearby.push_back(static_cast<int>(f));
          if (d < 0.025) {
            n += (body.vertices[g[1]] - body.vertices[g[0]])
                     .cast<double>()
                     .cross((body.vertices[g[2]] - body.vertices[g[0]]).cast<double>());
          }
        }
        if (n.norm() <= 0) continue;
        n.normalize();
        if (n.dot(anterior) < std::cos(RadFromDeg(35))) continue;
        // Orientation in the tangent plane: random.
        Eigen::Vector3d x = (Eigen::Vector3d(0, 0, 1) - n * n.z()).normalized();
        const double yaw = rng.Uniform(-M_PI, M_PI);
        x = Eigen::AngleAxisd(yaw, n) * x;
        const Eigen::Vector3d y = n.cross(x);
        // Surface height above the tangent plane over the sticker's footprint.
        double hmax = -1e9, hmin = 1e9;
        bool ok = true;
        for (int gy = 0; gy <= 8 && ok; ++gy) {
          for (int gx = 0; gx <= 8; ++gx) {
            const Eigen::Vector3d q = p + (-sticker_half + gx * sticker_half / 4) * x +
                                      (-sticker_half + gy * sticker_half / 4) * y;
            const double t = RayCast(body, nearby, q + 0.03 * n, -n);
            if (t < 0) {
              ok = false;
              break;
            }
            const double h = 0.03 - t;
            hmax = std::max(hmax, h);
            hmin = std::min(hmin, h);
          }
        }
        if (!ok || hmax - hmin > 0.004) continue;
        MarkerTruth m;
        m.id = ids[world.body_markers.size()];
        m.size_m = size;
        m.frame = "model";
        m.surface = region_names[r];
        m.raise_m = std::max(0.0, hmax) + 0.0003;
        m.parent_from_marker = FrameFromAxes(x, y, n, p + m.raise_m * n);
        const auto corners = MarkerCornersInMarker(size);
        for (int k = 0; k < 4; ++k) m.corners_m[k] = m.parent_from_marker * corners[k];
        world.body_markers.push_back(m);
        break;
      }
    }
    for (const auto& m : world.body_markers) {
      const MarkerArtwork art = MakeMarkerArtwork(dictionary, m.id, 1, 0, 8, "");
      const int mesh = AddMarkerMesh(&scene, StringPrintf("sticker_%d", m.id), art, m.size_m);
      TransformMesh(&scene.meshes[mesh], m.parent_from_marker);
      world.sticker_meshes.push_back(mesh);
    }
  }

  // --- Room ------------------------------------------------------------------
  Rng layout(StreamSeed(options.seed, Stream::kRoomLayout));
  const uint64_t tex_seed = StreamSeed(options.seed, Stream::kRoomTexture);
  const TextureDetail detail = options.plain_room ? TextureDetail::kPlain : TextureDetail::kRich;
  {
    using V = Eigen::Vector3d;
    const RoomLayout& lay = options.layout;
    const double L = lay.wall_left_x_m, R = lay.wall_right_x_m, F = lay.wall_foot_y_m,
                 Hd = lay.wall_head_y_m, C = lay.ceiling_z_m;
    world.room_meshes.push_back(AddTexturedPlane(&scene, "floor", SurfaceStyle::kFloor,
                                                 V(L, F, kFloorZ), V(R, F, kFloorZ),
                                                 V(R, Hd, kFloorZ), V(L, Hd, kFloorZ), tex_seed + 1, detail));
    world.room_meshes.push_back(AddTexturedPlane(&scene, "ceiling", SurfaceStyle::kCeiling,
                                                 V(L, Hd, C), V(R, Hd, C), V(R, F, C), V(L, F, C),
                                                 tex_seed + 2, detail));
    world.room_meshes.push_back(AddTexturedPlane(&scene, "wall_left", SurfaceStyle::kWall,
                                                 V(L, F, 0), V(L, Hd, 0), V(L, Hd, C), V(L, F, C),
                                                 tex_seed + 3, detail));
    world.room_meshes.push_back(AddTexturedPlane(&scene, "wall_right", SurfaceStyle::kWall,
                                                 V(R, Hd, 0), V(R, F, 0), V(R, F, C), V(R, Hd, C),
                                                 tex_seed + 4, detail));
    world.room_meshes.push_back(AddTexturedPlane(&scene, "wall_foot", SurfaceStyle::kWall,
                                                 V(R, F, 0), V(L, F, 0), V(L, F, C), V(R, F, C),
                                                 tex_seed + 5, detail));
    world.room_meshes.push_back(AddTexturedPlane(&scene, "wall_head", SurfaceStyle::kWall,
                                                 V(L, Hd, 0), V(R, Hd, 0), V(R, Hd, C), V(L, Hd, C),
                                                 tex_seed + 6, detail));
    // Gantry at the head end and the couch base (static).
    world.room_meshes.push_back(AddTexturedBox(&scene, "gantry", SurfaceStyle::kGantry,
                                               V(kCouchCentreX - 0.9, 3.35, kFloorZ),
                                               V(kCouchCentreX + 0.9, 4.35, 2.45), tex_seed + 7, detail));
    world.room_meshes.push_back(AddTexturedBox(&scene, "couch_base", SurfaceStyle::kCouchBase,
                                               V(kCouchCentreX - 0.2, 0.95, kFloorZ),
                                               V(kCouchCentreX + 0.2, 1.75, 0.72), tex_seed + 8, detail));
    world.occluders = {
        {V(kCouchCentreX - 0.9, 3.35, kFloorZ), V(kCouchCentreX + 0.9, 4.35, 2.45)},
        {V(kCouchCentreX - 0.2, 0.95, kFloorZ), V(kCouchCentreX + 0.2, 1.75, 0.72)},
        {V(kCouchCentreX - kCouchWidth / 2, kCouchFootY, kCouchTopZ - kCouchThickness),
         V(kCouchCentreX + kCouchWidth / 2, kCouchHeadY, kCouchTopZ)}};
    // Couch top: moves with the patient, so it lives in the model frame.
    const int top = AddTexturedPlane(
        &scene, "couch_top", SurfaceStyle::kCouchTop,
        V(kCouchCentreX - kCouchWidth / 2, kCouchFootY, kCouchTopZ),
        V(kCouchCentreX + kCouchWidth / 2, kCouchFootY, kCouchTopZ),
        V(kCouchCentreX + kCouchWidth / 2, kCouchHeadY, kCouchTopZ),
        V(kCouchCentreX - kCouchWidth / 2, kCouchHeadY, kCouchTopZ), tex_seed + 9);
    const int top_sides = AddTexturedBox(
        &scene, "couch_top_body", SurfaceStyle::kCouchTop,
        V(kCouchCentreX - kCouchWidth / 2, kCouchFootY, kCouchTopZ - kCouchThickness),
        V(kCouchCentreX + kCouchWidth / 2, kCouchHeadY, kCouchTopZ - 0.0005), tex_seed + 10);
    const Rigid3d model_from_room = world.room_from_model_target.Inverse();
    TransformMesh(&scene.meshes[top], model_from_room);
    TransformMesh(&scene.meshes[top_sides], model_from_room);
    world.couch_top_meshes = {top, top_sides};
  }

  // Room markers: marker 0 on the floor at the origin (identity pose), more
  // on the floor around the couch, on the couch base and on the walls.
  {
    struct Placement {
      std::string surface;
      Eigen::Vector3d centre;
      Eigen::Vector3d normal;  // out of the printed face
      double jitter_m;
    };
    using V = Eigen::Vector3d;
    const double cx = kCouchCentreX;
    std::vector<Placement> places = {
        {"floor", V(0, 0, 0), V(0, 0, 1), 0},
        {"floor", V(-0.05, 1.35, 0), V(0, 0, 1), 0.1},
        {"floor", V(-0.1, 2.7, 0), V(0, 0, 1), 0.1},
        {"floor", V(cx, -0.45, 0), V(0, 0, 1), 0.1},
        {"floor", V(1.6, 0.1, 0), V(0, 0, 1), 0.1},
        {"floor", V(1.65, 1.4, 0), V(0, 0, 1), 0.1},
        {"floor", V(1.6, 2.75, 0), V(0, 0, 1), 0.1},
        {"floor", V(-0.9, 0.6, 0), V(0, 0, 1), 0.15},
        {"floor", V(2.5, 0.9, 0), V(0, 0, 1), 0.15},
        {"couch_base", V(cx - 0.2 - kPaperOffset, 1.35, 0.42), V(-1, 0, 0), 0.05},
        {"couch_base", V(cx + 0.2 + kPaperOffset, 1.35, 0.42), V(1, 0, 0), 0.05},
        {"couch_base", V(cx, 0.95 - kPaperOffset, 0.42), V(0, -1, 0), 0.03},
    };
    const RoomLayout& lay = options.layout;
    for (double y : {-0.8, 0.5, 1.7, 3.0}) {
      places.push_back({"wall_left", V(lay.wall_left_x_m + kPaperOffset, y, 1.25), V(1, 0, 0), 0.2});
      places.push_back({"wall_right", V(lay.wall_right_x_m - kPaperOffset, y, 1.35), V(-1, 0, 0), 0.2});
    }
    for (double x : {-1.0, 0.4, 1.6, 2.7}) {
      places.push_back({"wall_foot", V(x, lay.wall_foot_y_m + kPaperOffset, 1.3), V(0, 1, 0), 0.2});
    }
    for (double x : {-1.2, 2.6}) {
      places.push_back({"wall_head", V(x, lay.wall_head_y_m - kPaperOffset, 1.4), V(0, -1, 0), 0.15});
    }
    ARPOS_CHECK(places.size() == static_cast<size_t>(kRoomMarkerPlaces) + 1, "room marker places");
    std::vector<int> ids;
    for (int id = 1; id <= 49; ++id) ids.push_back(id);
    for (size_t i = ids.size() - 1; i > 0; --i) {
      std::swap(ids[i], ids[layout.UniformInt(0, static_cast<int>(i))]);
    }
    const double size = options.room_marker_size_m;
    for (size_t k = 0; k < places.size(); ++k) {
      const Placement& pl = places[k];
      MarkerTruth m;
      m.id = k == 0 ? 0 : ids[k - 1];
      m.size_m = size;
      m.frame = "room";
      m.surface = k == 0 ? options.origin_surface : pl.surface;
      Eigen::Vector3d centre = pl.centre;
      const Eigen::Vector3d n = pl.normal;
      // In-plane jitter and rotation (none for the origin marker).
      Eigen::Vector3d up = std::abs(n.z()) > 0.5 ? Eigen::Vector3d(0, 1, 0) : Eigen::Vector3d(0, 0, 1);
      if (k > 0) {
        Eigen::Vector3d t1 = up.cross(n).normalized();
        centre += layout.Uniform(-pl.jitter_m, pl.jitter_m) * t1;
        if (std::abs(n.z()) > 0.5) centre += layout.Uniform(-pl.jitter_m, pl.jitter_m) * up;
        else centre.z() += layout.Uniform(-0.25, 0.35) * (pl.surface == "couch_base" ? 0.2 : 1.0);
        const double roll = std::abs(n.z()) > 0.5 ? layout.Uniform(-M_PI, M_PI)
                                                  : RadFromDeg(layout.Uniform(-12, 12));
        up = Eigen::AngleAxisd(roll, n) * up;
      }
      const Eigen::Vector3d x = up.cross(n);
      m.parent_from_marker = FrameFromAxes(x, up, n, centre);
      if (k == 0) m.parent_from_marker = options.world_from_origin_marker;
      // Places left empty still drew their jitter: the others stay put.
      if (k > 0 && !options.room_marker_places.empty() && !options.room_marker_places[k - 1]) continue;
      // A moved origin marker takes the place of any marker it would overlap.
      if (k > 0 && world.origin_moved &&
          (centre - options.world_from_origin_marker.translation).norm() < 2.5 * size) {
        continue;
      }
      const auto corners = MarkerCornersInMarker(size);
      for (int c = 0; c < 4; ++c) m.corners_m[c] = m.parent_from_marker * corners[c];
      world.room_markers.push_back(m);
      const MarkerArtwork art =
          MakeMarkerArtwork(dictionary, m.id, 1, 1, 16, StringPrintf("ARPOS ROOM %d", m.id));
      const int mesh = AddMarkerMesh(&scene, StringPrintf("room_marker_%d", m.id), art, size);
      TransformMesh(&scene.meshes[mesh], m.parent_from_marker);
      world.room_meshes.push_back(mesh);
    }
  }

  // --- Hand occluder: a capsule (forearm + hand) along +x, radius 4 cm. ---
  {
    RenderMesh hand;
    hand.name = "hand";
    const int half_rings = 6, segments = 16;
    const int rings = 2 * half_rings + 1;  // the equator ring appears twice
    const double radius = 0.04, half_length = 0.12, flatten = 0.55;
    for (int r = 0; r <= rings; ++r) {
      const bool far_end = r > half_rings;
      const double phi = M_PI * (far_end ? r - 1 : r) / (2 * half_rings);
      const double sx = -std::cos(phi), ring_r = std::sin(phi);
      const double offset = far_end ? half_length : -half_length;
      for (int s = 0; s < segments; ++s) {
        const double theta = 2 * M_PI * s / segments;
        const Eigen::Vector3d n(sx, ring_r * std::cos(theta), ring_r * std::sin(theta));
        hand.vertices.emplace_back(static_cast<float>(offset + radius * n.x()),
                                   static_cast<float>(radius * n.y()),
                                   static_cast<float>(radius * flatten * n.z()));
        hand.normals.push_back(Eigen::Vector3d(n.x(), n.y(), n.z() / flatten).normalized().cast<float>());
      }
    }
    for (int r = 0; r < rings; ++r) {
      for (int s = 0; s < segments; ++s) {
        const int a = r * segments + s, b = r * segments + (s + 1) % segments;
        const int c = a + segments, d = b + segments;
        hand.faces.emplace_back(a, b, d);
        hand.faces.emplace_back(a, d, c);
      }
    }
    hand.material = AddMaterial(&scene, -1, SrgbToLinear(200, 150, 120));
    world.hand_mesh = AddMesh(&scene, std::move(hand));
  }

  // --- Lighting ----------------------------------------------------------------
  world.planning_lighting.ambient = Eigen::Vector3f(0.34f, 0.34f, 0.35f);
  for (const Eigen::Vector3f& p :
       {Eigen::Vector3f(0.75f, 0.6f, 2.7f), Eigen::Vector3f(0.75f, 2.0f, 2.7f),
        Eigen::Vector3f(-0.9f, 1.2f, 2.7f), Eigen::Vector3f(2.4f, 1.2f, 2.7f)}) {
    world.planning_lighting.lights.push_back({p, Eigen::Vector3f(1.15f, 1.15f, 1.1f)});
  }
  world.treatment_lighting = world.planning_lighting;
  world.treatment_lighting.ambient = Eigen::Vector3f(0.20f, 0.18f, 0.15f);
  for (auto& light : world.treatment_lighting.lights) {
    light.intensity = Eigen::Vector3f(0.95f, 0.78f, 0.58f);
  }
  world.treatment_lighting.lights[2].intensity *= 0.0f;  // one light off
  world.treatment_lighting.lights[0].position_in_room_m = Eigen::Vector3f(-0.2f, 0.2f, 2.3f);
  world.treatment_lighting.lights[0].intensity = Eigen::Vector3f(1.6f, 1.35f, 1.0f);
  return world;
}

}  // namespace arpos::sim
