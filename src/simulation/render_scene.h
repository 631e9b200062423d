#pragma once
/// What the simulator's rasteriser draws: textured triangle meshes, each in
/// its own part frame (room, model, hand), lit by point lights.
///
/// Colours are linear RGB in [0, 1] (albedo, irradiance, radiance); gamma is
/// applied only by the camera model. Texture coordinates: u along image
/// columns (0 = left edge of texel column 0, 1 = right edge of the last), v
/// along image rows (0 = top edge of row 0).

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

namespace arpos::sim {

/// 8-bit sRGB texture sampled in linear RGB.
struct Texture {
  int width = 0;
  int height = 0;
  std::vector<uint8_t> rgb;  ///< row-major, 3 bytes per texel, sRGB-encoded
  /// Nearest texel instead of bilinear: for binary artwork (markers), so that
  /// the black/white edges sit exactly on texel boundaries, with the
  /// supersampling doing the anti-aliasing.
  bool nearest = false;
  bool wrap = false;  ///< repeat outside [0, 1) (else clamp)

  Texture() = default;
  Texture(int w, int h) : width(w), height(h), rgb(static_cast<size_t>(w) * h * 3, 0) {}
  uint8_t* texel(int x, int y) { return &rgb[(static_cast<size_t>(y) * width + x) * 3]; }
  const uint8_t* texel(int x, int y) const {
    return &rgb[(static_cast<size_t>(y) * width + x) * 3];
  }
  /// Linear RGB at (u, v).
  Eigen::Vector3f Sample(float u, float v) const;
};

/// sRGB byte -> linear value (table).
float LinearFromSrgb8(uint8_t value);
/// Linear value in [0, 1] -> sRGB byte, rounded.
uint8_t Srgb8FromLinear(float value);
/// Same through a table (16384 bins, linear interpolation): differs from the
/// exact conversion by at most one code near bin edges; deterministic.
uint8_t Srgb8FromLinearFast(float value);

struct Material {
  int texture = -1;                       ///< index into RenderScene::textures, -1 = none
  Eigen::Vector3f albedo{0.7f, 0.7f, 0.7f};  ///< multiplies texture and vertex colours
  bool vertex_colors = false;             ///< use RenderMesh::colors
};

/// A mesh in its part frame (metres). Normals: one per vertex (smooth
/// shading) or empty (flat shading with face normals). Faces may be seen from
/// either side (no culling); shading uses the side facing the camera.
struct RenderMesh {
  std::string name;
  std::vector<Eigen::Vector3f> vertices;
  std::vector<Eigen::Vector3f> normals;
  std::vector<Eigen::Vector2f> uvs;     ///< one per vertex or empty
  std::vector<Eigen::Vector3f> colors;  ///< linear albedo per vertex or empty
  std::vector<Eigen::Vector3i> faces;
  int material = 0;
  /// Skip faces seen from behind (counter-clockwise = front). Only for
  /// closed meshes, whose back faces are always hidden.
  bool cull_back_faces = false;

  /// Appends an axis-free quad p0..p3 (counter-clockwise seen from the front)
  /// with uv (0,0),(1,0),(1,1),(0,1) at p0..p3 unless `uv` is given,
  /// subdivided into n x m cells (large planes are split so that near-plane
  /// clipping and binning stay cheap).
  void AddQuad(const Eigen::Vector3f& p0, const Eigen::Vector3f& p1, const Eigen::Vector3f& p2,
               const Eigen::Vector3f& p3, int n = 1, int m = 1,
               const Eigen::Vector2f& uv0 = {0, 0}, const Eigen::Vector2f& uv2 = {1, 1});
  /// Axis-aligned box [min, max] with outward faces; every face gets uv 0..1
  /// scaled by its size in metres times `uv_per_m` (0 = 0..1 per face).
  void AddBox(const Eigen::Vector3f& min, const Eigen::Vector3f& max, float uv_per_m = 0);
};

struct PointLight {
  Eigen::Vector3f position_in_room_m{0, 0, 2.5f};
  /// Linear RGB radiant intensity: irradiance at 1 m facing the light.
  Eigen::Vector3f intensity{1, 1, 1};
};

struct Lighting {
  Eigen::Vector3f ambient{0.3f, 0.3f, 0.3f};  ///< irradiance from everywhere
  std::vector<PointLight> lights;
};

struct RenderScene {
  std::vector<Texture> textures;
  std::vector<Material> materials;
  std::vector<RenderMesh> meshes;
};

}  // namespace arpos::sim
