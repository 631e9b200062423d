#include "tracking/overlay.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <sstream>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "simulation/rasterizer.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos {
namespace {

// Lambert with the light at the camera, plus a floor so that faces seen
// edge-on stay coloured: shade = kAmbient + (1 - kAmbient) cos.
constexpr float kAmbient = 0.35f;
// Silhouette pixels whose centre sample missed the model (supersampling 3)
// have no normal: a mid shade.
constexpr float kEdgeShade = 0.7f;
// The panel's black fill: the background keeps this fraction of itself.
constexpr double kPanelKeep = 0.3;
// The rasteriser's near clipping plane (its default).
constexpr float kNearM = 0.02f;

// Vertex clustering on a grid of `cell_m`: one vertex per occupied cell (the
// mean of its vertices, normal the normalised sum of theirs), faces whose
// corners fall into three different cells, duplicates dropped. Keeps the
// surface within about one cell of the original.
TriangleMesh ClusterVertices(const TriangleMesh& mesh, double cell_m) {
  struct Cell {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    Eigen::Vector3f normal = Eigen::Vector3f::Zero();
    int count = 0;
    int index = -1;
  };
  auto key_of = [cell_m](const Eigen::Vector3f& p) {
    // 21 bits per axis: +-1 million cells, far beyond any body at mm cells.
    const auto axis = [cell_m](float x) {
      return static_cast<uint64_t>(static_cast<int64_t>(std::floor(x / cell_m)) + (1 << 20)) &
             0x1FFFFF;
    };
    return axis(p.x()) | axis(p.y()) << 21 | axis(p.z()) << 42;
  };
  std::unordered_map<uint64_t, Cell> cells;
  cells.reserve(mesh.vertices.size() / 4);
  std::vector<int> cell_index(mesh.vertices.size());
  TriangleMesh out;
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    Cell& cell = cells[key_of(mesh.vertices[i])];
    if (cell.index < 0)
      cell.index = static_cast<int>(out.vertices.size()), out.vertices.emplace_back();
    cell.sum += mesh.vertices[i].cast<double>();
    cell.normal += mesh.vertex_normals[i];
    ++cell.count;
    cell_index[i] = cell.index;
  }
  out.vertex_normals.resize(out.vertices.size());
  for (const auto& [key, cell] : cells) {
    out.vertices[cell.index] = (cell.sum / cell.count).cast<float>();
    const float norm = cell.normal.norm();
    out.vertex_normals[cell.index] =
        norm > 0 ? Eigen::Vector3f(cell.normal / norm) : Eigen::Vector3f::Zero();
  }
  std::unordered_set<uint64_t> seen;
  seen.reserve(mesh.faces.size());
  for (const auto& f : mesh.faces) {
    const int a = cell_index[f[0]], b = cell_index[f[1]], c = cell_index[f[2]];
    if (a == b || b == c || a == c) continue;
    int s[3] = {a, b, c};
    std::sort(s, s + 3);
    if (!seen.insert(static_cast<uint64_t>(s[0]) | static_cast<uint64_t>(s[1]) << 21 |
                     static_cast<uint64_t>(s[2]) << 42)
             .second) {
      continue;
    }
    out.faces.emplace_back(a, b, c);
  }
  return out;
}

// Positive for a closed surface whose faces are counter-clockwise from outside.
double SignedVolume(const TriangleMesh& mesh) {
  double six_volume = 0;
  for (const auto& f : mesh.faces) {
    six_volume += mesh.vertices[f[0]].cast<double>().dot(
        mesh.vertices[f[1]].cast<double>().cross(mesh.vertices[f[2]].cast<double>()));
  }
  return six_volume / 6;
}

// The undistorted normalised coordinates whose distortion (OpenCV's model,
// k1 k2 p1 p2 k3) is (xd, yd), by Newton's method from (xd, yd); false if it
// does not converge to 1e-6 (about 1e-3 px) or lands where the lens model
// folds over (Jacobian determinant <= 0: beyond the monotonic range of a
// strong barrel distortion, which has no inverse on its main branch).
bool Undistort(const std::array<double, 5>& d, double xd, double yd, double* x_out, double* y_out) {
  const double k1 = d[0], k2 = d[1], p1 = d[2], p2 = d[3], k3 = d[4];
  double x = xd, y = yd;
  for (int iteration = 0; iteration < 30; ++iteration) {
    const double r2 = x * x + y * y;
    const double radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3));
    const double dradial = k1 + r2 * (2 * k2 + 3 * k3 * r2);  // d radial / d r2
    const double fx = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x) - xd;
    const double fy = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y - yd;
    const double jxx = radial + 2 * x * x * dradial + 2 * p1 * y + 6 * p2 * x;
    const double jxy = 2 * x * y * dradial + 2 * p1 * x + 2 * p2 * y;
    const double jyy = radial + 2 * y * y * dradial + 6 * p1 * y + 2 * p2 * x;
    const double det = jxx * jyy - jxy * jxy;
    if (!(det > 1e-9)) return false;
    if (std::abs(fx) < 1e-6 && std::abs(fy) < 1e-6) {
      *x_out = x;
      *y_out = y;
      return true;
    }
    x -= (jyy * fx - jxy * fy) / det;
    y -= (jxx * fy - jxy * fx) / det;
    if (!std::isfinite(x) || !std::isfinite(y) || x * x + y * y > 100) return false;
  }
  return false;
}

// A number as the panel shows it: rounded to `decimals`, no "-0.0".
std::string Signed(double value, int decimals) {
  const double scale = std::pow(10.0, decimals);
  double rounded = std::round(value * scale) / scale;
  if (rounded == 0) rounded = 0;  // drops the sign of -0
  return StringPrintf("%+.*f", decimals, rounded);
}

std::vector<std::string> PanelLines(const CouchCorrection& c, const std::string& lost_headline) {
  if (c.state == CorrectionState::kLost) {
    return {"LAT --  LNG --  VRT -- mm", "PITCH --  ROLL --  YAW -- deg",
            lost_headline.empty() ? "PATIENT LOST" : lost_headline};
  }
  return {"LAT " + Signed(c.lateral_mm, 1) + " mm  LNG " + Signed(c.longitudinal_mm, 1) +
              " mm  VRT " + Signed(c.vertical_mm, 1) + " mm",
          "PITCH " + Signed(c.pitch_deg, 2) + "  ROLL " + Signed(c.roll_deg, 2) + "  YAW " +
              Signed(c.yaw_deg, 2) + " deg",
          SizeAndState(c)};
}

// `text` broken at spaces into lines no wider than `max_width` pixels (a
// word wider than that is cut), at most `max_lines`; the last ends in
// " ..." when words are left over.
std::vector<std::string> WrapText(const std::string& text, int max_width, int max_lines, int font, double scale,
                                  int thickness) {
  int baseline = 0;
  const auto width = [&](const std::string& s) { return cv::getTextSize(s, font, scale, thickness, &baseline).width; };
  std::vector<std::string> words;
  std::istringstream in(text);
  for (std::string word; in >> word;) words.push_back(word);
  std::vector<std::string> lines;
  size_t next = 0;
  while (next < words.size() && static_cast<int>(lines.size()) < max_lines) {
    std::string line = words[next++];
    while (next < words.size() && width(line + " " + words[next]) <= max_width) line += " " + words[next++];
    while (line.size() > 1 && width(line) > max_width) line.pop_back();
    lines.push_back(line);
  }
  if (next < words.size()) {
    std::string& last = lines.back();
    while (!last.empty() && width(last + " ...") > max_width) last.pop_back();
    last += " ...";
  }
  return lines;
}

// Darkens `rect` of `image` (clipped to it) to kPanelKeep of its brightness.
void DarkPanel(cv::Mat* image, const cv::Rect& rect) {
  const cv::Rect clipped = rect & cv::Rect(0, 0, image->cols, image->rows);
  if (clipped.empty()) return;
  cv::Mat roi = (*image)(clipped);
  roi.convertTo(roi, -1, kPanelKeep, 0);
}

// A model layer to blend: coverage and coverage * shade (CV_32F, image size).
struct Layer {
  cv::Mat coverage, shaded;
  float alpha = 0;
  cv::Scalar colour_bgr;
};

// Both layers at once, so that where they overlap neither hides the other:
// each takes its own share of the pixel (alpha times coverage; both scaled
// down if they sum above 1) and the frame keeps the rest. An empty layer is
// absent.
void Blend(const Layer& a, const Layer& b, cv::Mat* out) {
  for (int v = 0; v < out->rows; ++v) {
    const float* cov_a = a.coverage.empty() ? nullptr : a.coverage.ptr<float>(v);
    const float* sh_a = a.coverage.empty() ? nullptr : a.shaded.ptr<float>(v);
    const float* cov_b = b.coverage.empty() ? nullptr : b.coverage.ptr<float>(v);
    const float* sh_b = b.coverage.empty() ? nullptr : b.shaded.ptr<float>(v);
    cv::Vec3b* px = out->ptr<cv::Vec3b>(v);
    for (int u = 0; u < out->cols; ++u) {
      const float wa = cov_a != nullptr ? a.alpha * cov_a[u] : 0.0f;
      const float wb = cov_b != nullptr ? b.alpha * cov_b[u] : 0.0f;
      if (!(wa + wb > 0)) continue;
      const float scale = wa + wb > 1 ? 1 / (wa + wb) : 1.0f;
      const float keep = 1 - (wa + wb) * scale;
      const float ka = cov_a != nullptr ? scale * a.alpha * sh_a[u] : 0.0f;
      const float kb = cov_b != nullptr ? scale * b.alpha * sh_b[u] : 0.0f;
      for (int c = 0; c < 3; ++c) {
        px[u][c] =
            cv::saturate_cast<uint8_t>(px[u][c] * keep + ka * static_cast<float>(a.colour_bgr[c]) +
                                       kb * static_cast<float>(b.colour_bgr[c]));
      }
    }
  }
}

}  // namespace

std::string OverlayOptions::Validate() const {
  if (!(current_alpha >= 0 && current_alpha <= 1)) {
    return StringPrintf("current_alpha: must be in [0, 1], got %g", current_alpha);
  }
  if (!(planned_alpha >= 0 && planned_alpha <= 1)) {
    return StringPrintf("planned_alpha: must be in [0, 1], got %g", planned_alpha);
  }
  if (supersampling != 1 && supersampling != 3) {
    return StringPrintf("supersampling: must be 1 or 3, got %d", supersampling);
  }
  if (!(font_scale >= 0 && font_scale <= 10)) {
    return StringPrintf("font_scale: must be in [0, 10] (0 = from the image height), got %g",
                        font_scale);
  }
  if (!(display_cell_m >= 0 && display_cell_m <= 0.05)) {
    return StringPrintf("display_cell_m: must be in [0, 0.05] m (0 = no simplification), got %g",
                        display_cell_m);
  }
  if (max_display_faces < 0) {
    return StringPrintf("max_display_faces: must be >= 0, got %d", max_display_faces);
  }
  return "";
}

cv::Scalar OverlayCurrentColor() { return cv::Scalar(40, 40, 255); }
cv::Scalar OverlayPlannedColor() { return cv::Scalar(255, 120, 20); }
cv::Scalar OverlayPlannedOutlineColor() { return cv::Scalar(255, 200, 90); }

cv::Scalar OverlayStateColor(CorrectionState state) {
  switch (state) {
    case CorrectionState::kIn:
      return cv::Scalar(80, 220, 80);
    case CorrectionState::kOut:
      return cv::Scalar(0, 170, 255);
    case CorrectionState::kLost:
      break;
  }
  return cv::Scalar(70, 70, 255);
}

OverlayRenderer::OverlayRenderer(const TriangleMesh& model, const CameraIntrinsics& intrinsics,
                                 const OverlayOptions& options)
    : intrinsics_(intrinsics), options_(options) {
  const std::string options_error = options.Validate();
  ARPOS_CHECK(options_error.empty(), "invalid overlay options: " << options_error);
  const std::string camera_error = intrinsics.Validate();
  ARPOS_CHECK(camera_error.empty(), "invalid camera intrinsics for the overlay: " << camera_error);
  ARPOS_CHECK(!model.empty(), "the overlay needs a model with faces");
  for (const auto& f : model.faces) {
    ARPOS_CHECK(f.minCoeff() >= 0 && f.maxCoeff() < static_cast<int>(model.vertices.size()),
                "the overlay's model has a face with a vertex index out of range");
  }

  TriangleMesh display = model;
  if (display.vertex_normals.size() != display.vertices.size()) display.ComputeVertexNormals();
  // The back faces of a closed, outward-facing surface are always hidden: the
  // rasteriser skips them (a third less time on the sample model). Vertex
  // clustering opens the surface where it collapses detail (nose, fingers),
  // so a simplified model is drawn with all its faces.
  bool cull = model.IsClosed() && SignedVolume(model) > 0;
  if (options.display_cell_m > 0 &&
      static_cast<int>(display.faces.size()) > options.max_display_faces) {
    TriangleMesh simplified = ClusterVertices(display, options.display_cell_m);
    if (!simplified.faces.empty()) {
      display = std::move(simplified);
      cull = false;
    }
  }
  sim::Material material;
  material.albedo = Eigen::Vector3f(1, 1, 1);  // with ambient 1: colour = coverage
  scene_.materials.push_back(material);
  sim::RenderMesh mesh;
  mesh.name = "overlay model";
  mesh.vertices = std::move(display.vertices);
  mesh.normals = std::move(display.vertex_normals);
  mesh.faces = std::move(display.faces);
  mesh.cull_back_faces = cull;
  scene_.meshes.push_back(std::move(mesh));

  ideal_ = intrinsics_;
  ideal_.distortion = {0, 0, 0, 0, 0};
  if (!intrinsics_.HasDistortion()) return;

  // Where every distorted pixel lies in the ideal image; the canvas may grow
  // to 3x the image per axis, pixels seeing beyond that are left empty.
  const int W = intrinsics_.width, H = intrinsics_.height;
  const double fx = intrinsics_.fx, fy = intrinsics_.fy, cx = intrinsics_.cx, cy = intrinsics_.cy;
  cv::Mat map_x(H, W, CV_32F, cv::Scalar(-10)), map_y(H, W, CV_32F, cv::Scalar(-10));
  double umin = 0, umax = W - 1, vmin = 0, vmax = H - 1;
  for (int v = 0; v < H; ++v) {
    float* mx = map_x.ptr<float>(v);
    float* my = map_y.ptr<float>(v);
    for (int u = 0; u < W; ++u) {
      double x = 0, y = 0;
      if (!Undistort(intrinsics_.distortion, (u - cx) / fx, (v - cy) / fy, &x, &y)) continue;
      const double iu = fx * x + cx, iv = fy * y + cy;
      if (iu < -W || iu > 2.0 * W || iv < -H || iv > 2.0 * H) continue;
      mx[u] = static_cast<float>(iu);
      my[u] = static_cast<float>(iv);
      umin = std::min(umin, iu), umax = std::max(umax, iu), vmin = std::min(vmin, iv),
      vmax = std::max(vmax, iv);
    }
  }
  // One pixel of margin for bilinear interpolation.
  const int ox = static_cast<int>(std::floor(umin)) - 1,
            oy = static_cast<int>(std::floor(vmin)) - 1;
  ideal_.width = static_cast<int>(std::ceil(umax)) + 2 - ox;
  ideal_.height = static_cast<int>(std::ceil(vmax)) + 2 - oy;
  ideal_.cx = cx - ox;
  ideal_.cy = cy - oy;
  // Shift onto the canvas; pixels without an inverse stay outside it
  // (border: nothing drawn).
  for (int v = 0; v < H; ++v) {
    float* mx = map_x.ptr<float>(v);
    float* my = map_y.ptr<float>(v);
    for (int u = 0; u < W; ++u) {
      if (mx[u] == -10.0f) continue;
      mx[u] -= static_cast<float>(ox);
      my[u] -= static_cast<float>(oy);
    }
  }
  cv::convertMaps(map_x, map_y, map_xy_, map_fraction_, CV_16SC2);
}

void OverlayRenderer::RenderLayer(const Rigid3d& camera_from_model, cv::Mat* coverage,
                                  cv::Mat* shaded) const {
  // Coverage and coverage * shade on the ideal canvas, as two channels so one
  // remap warps both.
  cv::Mat layer = cv::Mat::zeros(ideal_.height, ideal_.width, CV_32FC2);

  // The rasteriser's cost grows with the pixels it covers: render only the
  // model's projected bounding box (all of the canvas if part of the model is
  // near or behind the camera).
  const sim::RenderMesh& mesh = scene_.meshes[0];
  const Eigen::Matrix3f rotation = camera_from_model.RotationMatrix().cast<float>();
  const Eigen::Vector3f translation = camera_from_model.translation.cast<float>();
  float umin = std::numeric_limits<float>::max(), umax = -umin, vmin = umin, vmax = -umin;
  bool whole_canvas = false;
  for (const auto& vertex : mesh.vertices) {
    const Eigen::Vector3f p = rotation * vertex + translation;
    if (!(p.z() > kNearM)) {
      whole_canvas = true;
      break;
    }
    const float u = static_cast<float>(ideal_.fx) * p.x() / p.z(),
                v = static_cast<float>(ideal_.fy) * p.y() / p.z();
    umin = std::min(umin, u), umax = std::max(umax, u), vmin = std::min(vmin, v),
    vmax = std::max(vmax, v);
  }
  cv::Rect box(0, 0, ideal_.width, ideal_.height);
  if (!whole_canvas) {
    // Two pixels of margin for rounding and the pixel footprint.
    const double x0 = std::floor(umin + ideal_.cx) - 2, y0 = std::floor(vmin + ideal_.cy) - 2;
    const double x1 = std::ceil(umax + ideal_.cx) + 2, y1 = std::ceil(vmax + ideal_.cy) + 2;
    if (x1 < 0 || y1 < 0 || x0 >= ideal_.width || y0 >= ideal_.height) {
      box = cv::Rect();
    } else {
      const int bx0 = static_cast<int>(std::max(0.0, x0)),
                by0 = static_cast<int>(std::max(0.0, y0));
      const int bx1 = static_cast<int>(std::min(ideal_.width - 1.0, x1));
      const int by1 = static_cast<int>(std::min(ideal_.height - 1.0, y1));
      box = cv::Rect(bx0, by0, bx1 - bx0 + 1, by1 - by0 + 1);
    }
  }
  if (!box.empty()) {
    CameraIntrinsics camera = ideal_;
    camera.width = box.width;
    camera.height = box.height;
    camera.cx = ideal_.cx - box.x;
    camera.cy = ideal_.cy - box.y;
    sim::RenderInstance instance;
    instance.mesh = 0;
    instance.camera_from_part = camera_from_model;
    instance.label = 1;
    sim::Lighting lighting;
    lighting.ambient = Eigen::Vector3f(1, 1, 1);  // no lights: radiance 1 on the model, 0 off it
    sim::RenderOptions render_options;
    render_options.supersampling = options_.supersampling;
    render_options.near_m = kNearM;
    const sim::RenderOutput out =
        sim::Render(scene_, {instance}, camera, Rigid3d::Identity(), lighting, render_options);

    const float fx = static_cast<float>(camera.fx), fy = static_cast<float>(camera.fy);
    const float cx = static_cast<float>(camera.cx), cy = static_cast<float>(camera.cy);
    for (int v = 0; v < box.height; ++v) {
      const cv::Vec3f* colour = out.color.ptr<cv::Vec3f>(v);
      const cv::Vec3f* normal = out.normal.ptr<cv::Vec3f>(v);
      const int* label = out.label.ptr<int>(v);
      cv::Vec2f* dst = layer.ptr<cv::Vec2f>(box.y + v) + box.x;
      const float y = (v - cy) / fy;
      for (int u = 0; u < box.width; ++u) {
        const float c = std::clamp(colour[u][0], 0.0f, 1.0f);
        float shade = kEdgeShade;
        if (label[u] > 0) {
          // The normal faces the camera: cos = -n . ray.
          const float x = (u - cx) / fx;
          const float cosine =
              -(normal[u][0] * x + normal[u][1] * y + normal[u][2]) / std::sqrt(x * x + y * y + 1);
          shade = kAmbient + (1 - kAmbient) * std::max(0.0f, cosine);
        }
        dst[u] = cv::Vec2f(c, c * shade);
      }
    }
  }
  if (!map_xy_.empty()) {
    cv::Mat warped;
    cv::remap(layer, warped, map_xy_, map_fraction_, cv::INTER_LINEAR, cv::BORDER_CONSTANT,
              cv::Scalar());
    layer = warped;
  }
  cv::Mat channels[2];
  cv::split(layer, channels);
  *coverage = channels[0];
  *shaded = channels[1];
}

cv::Mat OverlayRenderer::Render(const cv::Mat& colour_bgr,
                                const std::optional<Rigid3d>& camera_from_model_current,
                                const std::optional<Rigid3d>& camera_from_model_planned,
                                const CouchCorrection& correction, const std::string& caption,
                                const std::string& lost_headline) const {
  ARPOS_CHECK(!colour_bgr.empty(), "the overlay's colour image is empty");
  ARPOS_CHECK(colour_bgr.type() == CV_8UC3,
              "the overlay's colour image must be 8-bit BGR (CV_8UC3), got OpenCV type "
                  << colour_bgr.type() << " with " << colour_bgr.channels() << " channel(s)");
  ARPOS_CHECK(colour_bgr.cols == intrinsics_.width && colour_bgr.rows == intrinsics_.height,
              "the overlay's colour image is " << colour_bgr.cols << "x" << colour_bgr.rows
                                               << " but the camera's is " << intrinsics_.width
                                               << "x" << intrinsics_.height);
  for (const auto* pose : {&camera_from_model_current, &camera_from_model_planned}) {
    ARPOS_CHECK(!pose->has_value() ||
                    ((*pose)->translation.allFinite() && (*pose)->rotation.coeffs().allFinite()),
                "the overlay's pose is not finite");
  }
  cv::Mat out = colour_bgr.clone();
  const int H = out.rows;

  // Both blended at once: where they overlap both tints remain.
  Layer planned, current;
  if (camera_from_model_planned) {
    RenderLayer(*camera_from_model_planned, &planned.coverage, &planned.shaded);
    planned.alpha = static_cast<float>(options_.planned_alpha);
    planned.colour_bgr = OverlayPlannedColor();
  }
  if (camera_from_model_current) {
    RenderLayer(*camera_from_model_current, &current.coverage, &current.shaded);
    current.alpha = static_cast<float>(options_.current_alpha);
    current.colour_bgr = OverlayCurrentColor();
  }
  Blend(planned, current, &out);
  const cv::Mat& planned_coverage = planned.coverage;
  if (!planned_coverage.empty()) {
    // Opaque outline inside the planned silhouette: 1 px below 900 rows, 2 px up to 1500.
    const int width = std::clamp(static_cast<int>(std::lround(H / 600.0)), 1, 3);
    cv::Mat mask = planned_coverage >= 0.5f, eroded;
    cv::erode(mask, eroded,
              cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * width + 1, 2 * width + 1)),
              cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, cv::Scalar(0));
    out.setTo(OverlayPlannedOutlineColor(), mask & ~eroded);
  }

  // Text: Hershey simplex on a dark translucent panel.
  const double scale = options_.font_scale > 0 ? options_.font_scale : std::max(0.35, H / 1000.0);
  const int thickness = scale >= 0.65 ? 2 : 1;
  const int font = cv::FONT_HERSHEY_SIMPLEX;
  int baseline = 0;
  const cv::Size glyph = cv::getTextSize("LAT Ag", font, scale, thickness, &baseline);
  const int pad = std::max(3, static_cast<int>(std::lround(glyph.height * 0.6)));
  const int line_step = glyph.height + baseline + pad / 2;
  const int margin = pad;
  const int stripe = std::max(3, static_cast<int>(std::lround(glyph.height * 0.4)));

  const std::vector<std::string> lines =
      options_.correction_panel ? PanelLines(correction, lost_headline) : std::vector<std::string>{};
  // Widest of the lines and of a wide template, so the panel does not jitter.
  int text_width =
      cv::getTextSize("LAT +88.8 mm  LNG +88.8 mm  VRT +88.8 mm", font, scale, thickness, &baseline)
          .width;
  for (const auto& line : lines) {
    text_width =
        std::max(text_width, cv::getTextSize(line, font, scale, thickness, &baseline).width);
  }
  const cv::Rect panel(margin, margin, stripe + 2 * pad + text_width,
                       pad + static_cast<int>(lines.size()) * line_step + pad / 2);
  const cv::Scalar state_colour = OverlayStateColor(correction.state);
  if (options_.correction_panel) {
    DarkPanel(&out, panel);
    cv::rectangle(
        out, cv::Rect(panel.x, panel.y, stripe, panel.height) & cv::Rect(0, 0, out.cols, out.rows),
        state_colour, cv::FILLED);
  }
  for (size_t i = 0; i < lines.size(); ++i) {
    const cv::Point origin(panel.x + stripe + pad,
                           panel.y + pad + glyph.height + static_cast<int>(i) * line_step);
    cv::putText(out, lines[i], origin, font, scale, state_colour, thickness, cv::LINE_AA);
  }

  if (!caption.empty()) {
    const std::vector<std::string> caption_lines =
        WrapText(caption, out.cols - 2 * margin - 2 * pad, 3, font, scale, thickness);
    int caption_width = 0;
    for (const auto& line : caption_lines) {
      caption_width = std::max(caption_width, cv::getTextSize(line, font, scale, thickness, &baseline).width);
    }
    const int n = static_cast<int>(caption_lines.size());
    const int height = pad + n * line_step - pad / 2;
    const cv::Rect strip(margin, H - margin - height, caption_width + 2 * pad, height);
    DarkPanel(&out, strip);
    for (int i = 0; i < n; ++i) {
      cv::putText(out, caption_lines[i], cv::Point(strip.x + pad, strip.y + pad / 2 + glyph.height + i * line_step),
                  font, scale, cv::Scalar(235, 235, 235), thickness, cv::LINE_AA);
    }
  }
  return out;
}

}  // namespace arpos
