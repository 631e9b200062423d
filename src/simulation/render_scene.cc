#include "simulation/render_scene.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

namespace arpos::sim {
namespace {

const std::array<float, 256>& SrgbTable() {
  static const std::array<float, 256> table = [] {
    std::array<float, 256> t{};
    for (int i = 0; i < 256; ++i) {
      const double c = i / 255.0;
      t[i] = static_cast<float>(c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4));
    }
    return t;
  }();
  return table;
}

int WrapOrClamp(int i, int n, bool wrap) {
  if (wrap) {
    i %= n;
    return i < 0 ? i + n : i;
  }
  return std::clamp(i, 0, n - 1);
}

}  // namespace

float LinearFromSrgb8(uint8_t value) { return SrgbTable()[value]; }

uint8_t Srgb8FromLinear(float value) {
  const double c = std::clamp(static_cast<double>(value), 0.0, 1.0);
  const double s = c <= 0.0031308 ? 12.92 * c : 1.055 * std::pow(c, 1.0 / 2.4) - 0.055;
  return static_cast<uint8_t>(std::lround(s * 255.0));
}

uint8_t Srgb8FromLinearFast(float value) {
  constexpr int kBins = 16384;
  static const std::vector<float> table = [] {
    std::vector<float> t(kBins + 2);
    for (int i = 0; i <= kBins + 1; ++i) {
      const double c = std::min(1.0, static_cast<double>(i) / kBins);
      const double s = c <= 0.0031308 ? 12.92 * c : 1.055 * std::pow(c, 1.0 / 2.4) - 0.055;
      t[i] = static_cast<float>(s * 255.0);
    }
    return t;
  }();
  if (!(value > 0)) return 0;
  if (value >= 1) return 255;
  const float x = value * kBins;
  const int i = static_cast<int>(x);
  const float f = x - i;
  const float s = table[i] + f * (table[i + 1] - table[i]);
  return static_cast<uint8_t>(std::min(255.0f, s + 0.5f));
}

Eigen::Vector3f Texture::Sample(float u, float v) const {
  const auto& lut = SrgbTable();
  if (nearest) {
    const int x = WrapOrClamp(static_cast<int>(std::floor(u * width)), width, wrap);
    const int y = WrapOrClamp(static_cast<int>(std::floor(v * height)), height, wrap);
    const uint8_t* t = texel(x, y);
    return {lut[t[0]], lut[t[1]], lut[t[2]]};
  }
  const float fx = u * width - 0.5f, fy = v * height - 0.5f;
  const float x0f = std::floor(fx), y0f = std::floor(fy);
  const float ax = fx - x0f, ay = fy - y0f;
  const int x0 = WrapOrClamp(static_cast<int>(x0f), width, wrap);
  const int x1 = WrapOrClamp(static_cast<int>(x0f) + 1, width, wrap);
  const int y0 = WrapOrClamp(static_cast<int>(y0f), height, wrap);
  const int y1 = WrapOrClamp(static_cast<int>(y0f) + 1, height, wrap);
  const uint8_t* t00 = texel(x0, y0);
  const uint8_t* t10 = texel(x1, y0);
  const uint8_t* t01 = texel(x0, y1);
  const uint8_t* t11 = texel(x1, y1);
  Eigen::Vector3f out;
  for (int c = 0; c < 3; ++c) {
    const float top = lut[t00[c]] + ax * (lut[t10[c]] - lut[t00[c]]);
    const float bottom = lut[t01[c]] + ax * (lut[t11[c]] - lut[t01[c]]);
    out[c] = top + ay * (bottom - top);
  }
  return out;
}

void RenderMesh::AddQuad(const Eigen::Vector3f& p0, const Eigen::Vector3f& p1,
                         const Eigen::Vector3f& p2, const Eigen::Vector3f& p3, int n, int m,
                         const Eigen::Vector2f& uv0, const Eigen::Vector2f& uv2) {
  // Bilinear patch (exactly planar for a planar quad), (n+1) x (m+1) vertices.
  const int base = static_cast<int>(vertices.size());
  for (int j = 0; j <= m; ++j) {
    const float b = static_cast<float>(j) / m;
    for (int i = 0; i <= n; ++i) {
      const float a = static_cast<float>(i) / n;
      vertices.push_back((1 - a) * (1 - b) * p0 + a * (1 - b) * p1 + a * b * p2 +
                         (1 - a) * b * p3);
      uvs.emplace_back(uv0.x() + a * (uv2.x() - uv0.x()), uv0.y() + b * (uv2.y() - uv0.y()));
    }
  }
  for (int j = 0; j < m; ++j) {
    for (int i = 0; i < n; ++i) {
      const int v00 = base + j * (n + 1) + i;
      const int v10 = v00 + 1, v01 = v00 + n + 1, v11 = v01 + 1;
      faces.emplace_back(v00, v10, v11);
      faces.emplace_back(v00, v11, v01);
    }
  }
}

void RenderMesh::AddBox(const Eigen::Vector3f& lo, const Eigen::Vector3f& hi, float uv_per_m) {
  const Eigen::Vector3f d = hi - lo;
  auto p = [&](int x, int y, int z) {
    return Eigen::Vector3f(x ? hi.x() : lo.x(), y ? hi.y() : lo.y(), z ? hi.z() : lo.z());
  };
  auto quad = [&](const Eigen::Vector3f& a, const Eigen::Vector3f& b, const Eigen::Vector3f& c,
                  const Eigen::Vector3f& e, float su, float sv) {
    const int n = std::max(1, static_cast<int>(std::ceil(su / 0.5f)));
    const int m = std::max(1, static_cast<int>(std::ceil(sv / 0.5f)));
    const Eigen::Vector2f uv2 = uv_per_m > 0 ? Eigen::Vector2f(su * uv_per_m, sv * uv_per_m)
                                             : Eigen::Vector2f(1, 1);
    AddQuad(a, b, c, e, n, m, {0, 0}, uv2);
  };
  quad(p(0, 0, 1), p(1, 0, 1), p(1, 1, 1), p(0, 1, 1), d.x(), d.y());  // top (+z)
  quad(p(0, 1, 0), p(1, 1, 0), p(1, 0, 0), p(0, 0, 0), d.x(), d.y());  // bottom
  quad(p(0, 0, 0), p(1, 0, 0), p(1, 0, 1), p(0, 0, 1), d.x(), d.z());  // -y
  quad(p(1, 1, 0), p(0, 1, 0), p(0, 1, 1), p(1, 1, 1), d.x(), d.z());  // +y
  quad(p(0, 1, 0), p(0, 0, 0), p(0, 0, 1), p(0, 1, 1), d.y(), d.z());  // -x
  quad(p(1, 0, 0), p(1, 1, 0), p(1, 1, 1), p(1, 0, 1), d.y(), d.z());  // +x
}

}  // namespace arpos::sim
