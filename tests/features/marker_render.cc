#include "features/marker_render.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include <opencv2/aruco.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "geometry/so3.h"
#include "sensor/case_config.h"
#include "util/check.h"

namespace arpos::testing {

namespace {

/// Area of the convex polygon `poly` inside [x0,x1] x [y0,y1] (Sutherland-Hodgman).
double ClippedArea(const Eigen::Vector2d* poly, int n, double x0, double x1, double y0, double y1) {
  Eigen::Vector2d buf_a[16], buf_b[16];
  int count = n;
  for (int i = 0; i < n; ++i) buf_a[i] = poly[i];
  Eigen::Vector2d* in = buf_a;
  Eigen::Vector2d* out = buf_b;
  for (int edge = 0; edge < 4 && count > 0; ++edge) {
    // Keep the side where value(p) >= 0.
    auto value = [&](const Eigen::Vector2d& p) {
      switch (edge) {
        case 0:
          return p.x() - x0;
        case 1:
          return x1 - p.x();
        case 2:
          return p.y() - y0;
        default:
          return y1 - p.y();
      }
    };
    int m = 0;
    for (int i = 0; i < count; ++i) {
      const Eigen::Vector2d& a = in[i];
      const Eigen::Vector2d& b = in[(i + 1) % count];
      const double va = value(a), vb = value(b);
      if (va >= 0) out[m++] = a;
      if ((va >= 0) != (vb >= 0)) out[m++] = a + (b - a) * (va / (va - vb));
    }
    count = m;
    std::swap(in, out);
  }
  double area = 0;
  for (int i = 0; i < count; ++i) {
    const Eigen::Vector2d& a = in[i];
    const Eigen::Vector2d& b = in[(i + 1) % count];
    area += a.x() * b.y() - a.y() * b.x();
  }
  return 0.5 * std::abs(area);
}

/// Adds the coverage of the convex quad `q` (image px) to `cov` (ROI origin at roi.tl()).
void AccumulateQuad(const std::array<Eigen::Vector2d, 4>& q, const cv::Rect& roi, double weight,
                    cv::Mat* cov) {
  double x_min = 1e300, x_max = -1e300, y_min = 1e300, y_max = -1e300;
  for (const auto& p : q) {
    x_min = std::min(x_min, p.x());
    x_max = std::max(x_max, p.x());
    y_min = std::min(y_min, p.y());
    y_max = std::max(y_max, p.y());
  }
  const int i0 = std::max(roi.x, static_cast<int>(std::floor(x_min + 0.5)));
  const int i1 = std::min(roi.x + roi.width - 1, static_cast<int>(std::ceil(x_max - 0.5)));
  const int j0 = std::max(roi.y, static_cast<int>(std::floor(y_min + 0.5)));
  const int j1 = std::min(roi.y + roi.height - 1, static_cast<int>(std::ceil(y_max - 0.5)));
  for (int j = j0; j <= j1; ++j) {
    double* row = cov->ptr<double>(j - roi.y);
    for (int i = i0; i <= i1; ++i) {
      row[i - roi.x] += weight * ClippedArea(q.data(), 4, i - 0.5, i + 0.5, j - 0.5, j + 0.5);
    }
  }
}

cv::Rect BoundingRect(const std::vector<Eigen::Vector2d>& pts, int pad, const cv::Size& size) {
  double x_min = 1e300, x_max = -1e300, y_min = 1e300, y_max = -1e300;
  for (const auto& p : pts) {
    x_min = std::min(x_min, p.x());
    x_max = std::max(x_max, p.x());
    y_min = std::min(y_min, p.y());
    y_max = std::max(y_max, p.y());
  }
  const int x0 = std::max(0, static_cast<int>(std::floor(x_min)) - pad);
  const int y0 = std::max(0, static_cast<int>(std::floor(y_min)) - pad);
  const int x1 = std::min(size.width - 1, static_cast<int>(std::ceil(x_max)) + pad);
  const int y1 = std::min(size.height - 1, static_cast<int>(std::ceil(y_max)) + pad);
  return cv::Rect(x0, y0, std::max(0, x1 - x0 + 1), std::max(0, y1 - y0 + 1));
}

}  // namespace

Eigen::Vector2d ProjectWithDistortion(const CameraIntrinsics& camera, const Eigen::Vector3d& p) {
  const double x = p.x() / p.z(), y = p.y() / p.z();
  const auto& d = camera.distortion;
  const double r2 = x * x + y * y;
  const double radial = 1 + r2 * (d[0] + r2 * (d[1] + r2 * d[4]));
  const double xd = x * radial + 2 * d[2] * x * y + d[3] * (r2 + 2 * x * x);
  const double yd = y * radial + d[2] * (r2 + 2 * y * y) + 2 * d[3] * x * y;
  return {camera.fx * xd + camera.cx, camera.fy * yd + camera.cy};
}

cv::Mat RenderMarkers(const CameraIntrinsics& camera, const std::vector<MarkerPlacement>& markers,
                      const RenderOptions& options, std::mt19937* rng,
                      std::vector<MarkerTruth>* truth) {
  const cv::Size size(camera.width, camera.height);
  cv::Mat image(size, CV_64F);
  if (options.textured_background) {
    std::uniform_real_distribution<double> coarse_u(70, 190), fine_u(-15, 15);
    cv::Mat coarse(size.height / 24 + 2, size.width / 24 + 2, CV_64F);
    cv::Mat fine(size.height / 4 + 1, size.width / 4 + 1, CV_64F);
    for (auto it = coarse.begin<double>(); it != coarse.end<double>(); ++it) *it = coarse_u(*rng);
    for (auto it = fine.begin<double>(); it != fine.end<double>(); ++it) *it = fine_u(*rng);
    cv::Mat a, b;
    cv::resize(coarse, a, size, 0, 0, cv::INTER_CUBIC);
    cv::resize(fine, b, size, 0, 0, cv::INTER_LINEAR);
    image = a + b;
  } else {
    image.setTo(options.background_grey);
  }
  const double gamma = options.gamma;
  const std::function<double(double)> encode_fraction =
      options.encode ? options.encode
                     : std::function<double(double)>([gamma](double x) { return std::pow(x, 1.0 / gamma); });
  const bool identity = !options.encode && gamma == 1.0;
  // Encoded grey -> linear: closed form for a gamma, else a fine table of the
  // inverse of `encode` (found by bisection), interpolated.
  std::vector<double> decode_table;
  if (options.encode) {
    decode_table.resize(4097);
    for (size_t i = 0; i < decode_table.size(); ++i) {
      const double target = static_cast<double>(i) / (decode_table.size() - 1);
      double lo = 0, hi = 1;
      for (int it = 0; it < 50; ++it) {
        const double mid = 0.5 * (lo + hi);
        (encode_fraction(mid) < target ? lo : hi) = mid;
      }
      decode_table[i] = 0.5 * (lo + hi);
    }
  }
  auto to_linear = [&](double v) {
    if (!options.encode) return 255.0 * std::pow(std::max(0.0, v) / 255.0, gamma);
    const double u = std::clamp(v / 255.0, 0.0, 1.0) * (decode_table.size() - 1);
    const size_t i = std::min(decode_table.size() - 2, static_cast<size_t>(u));
    const double f = u - i;
    return 255.0 * (decode_table[i] * (1 - f) + decode_table[i + 1] * f);
  };
  if (!identity) {
    for (auto it = image.begin<double>(); it != image.end<double>(); ++it) *it = to_linear(*it);
  }

  const int dict_id = ArucoDictionaryId(options.dictionary);
  ARPOS_CHECK(dict_id >= 0, "unknown dictionary " << options.dictionary);
  const cv::Ptr<cv::aruco::Dictionary> dict = cv::aruco::getPredefinedDictionary(dict_id);
  const int cells = dict->markerSize + 2;
  const bool distorted = camera.HasDistortion();
  if (truth != nullptr) truth->clear();

  for (const MarkerPlacement& m : markers) {
    cv::Mat bitmap;
    cv::aruco::drawMarker(dict, m.id, cells, bitmap, 1);
    const double cell = m.size_m / cells;
    const double half = 0.5 * m.size_m;
    const double quiet_half = half + options.quiet_zone_cells * cell;
    const Eigen::Matrix3d rot = m.camera_from_marker.RotationMatrix();
    const Eigen::Vector3d t = m.camera_from_marker.translation;
    auto to_camera = [&](double x, double y) {
      return Eigen::Vector3d(rot * Eigen::Vector3d(x, y, 0) + t);
    };
    auto project = [&](double x, double y) {
      return ProjectWithDistortion(camera, to_camera(x, y));
    };

    MarkerTruth tr;
    tr.id = m.id;
    tr.camera_from_marker = m.camera_from_marker;
    tr.size_m = m.size_m;
    const double corner_xy[4][2] = {{-half, half}, {half, half}, {half, -half}, {-half, -half}};
    for (int k = 0; k < 4; ++k) tr.corners_px[k] = project(corner_xy[k][0], corner_xy[k][1]);
    tr.centre_px = project(0, 0);
    for (int k = 0; k < 4; ++k)
      tr.side_px += 0.25 * (tr.corners_px[(k + 1) % 4] - tr.corners_px[k]).norm();
    if (truth != nullptr) truth->push_back(tr);

    std::vector<Eigen::Vector2d> outline;
    const int steps = 16;  // the quiet-zone outline, sampled (curved under distortion)
    for (int s = 0; s <= steps; ++s) {
      const double a = -quiet_half + 2 * quiet_half * s / steps;
      outline.push_back(project(a, quiet_half));
      outline.push_back(project(a, -quiet_half));
      outline.push_back(project(quiet_half, a));
      outline.push_back(project(-quiet_half, a));
    }
    const cv::Rect roi = BoundingRect(outline, 2, size);
    if (roi.area() == 0) continue;
    cv::Mat cov_white = cv::Mat::zeros(roi.size(), CV_64F);
    cv::Mat cov_black = cv::Mat::zeros(roi.size(), CV_64F);

    if (!distorted) {
      AccumulateQuad({project(-quiet_half, quiet_half), project(quiet_half, quiet_half),
                      project(quiet_half, -quiet_half), project(-quiet_half, -quiet_half)},
                     roi, 1.0, &cov_white);
      for (int r = 0; r < cells; ++r) {
        for (int c = 0; c < cells; ++c) {
          if (bitmap.at<uchar>(r, c) != 0) continue;  // white cell
          const double x0 = -half + c * cell, x1 = x0 + cell;
          const double y0 = half - r * cell, y1 = y0 - cell;
          AccumulateQuad({project(x0, y0), project(x1, y0), project(x1, y1), project(x0, y1)}, roi,
                         1.0, &cov_black);
        }
      }
    } else {
      // Supersample: sub-pixel centres -> ideal normalised coordinates -> marker plane.
      const int ss = options.distorted_supersampling;
      std::vector<cv::Point2d> samples;
      samples.reserve(static_cast<size_t>(roi.area()) * ss * ss);
      for (int j = 0; j < roi.height; ++j) {
        for (int i = 0; i < roi.width; ++i) {
          for (int sj = 0; sj < ss; ++sj) {
            for (int si = 0; si < ss; ++si) {
              samples.emplace_back(roi.x + i - 0.5 + (si + 0.5) / ss,
                                   roi.y + j - 0.5 + (sj + 0.5) / ss);
            }
          }
        }
      }
      std::vector<cv::Point2d> normalised;
      cv::undistortPoints(
          samples, normalised, cv::Mat(camera.CvK()), camera.CvDistortion(), cv::noArray(),
          cv::noArray(),
          cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 30, 1e-14));
      Eigen::Matrix3d h;  // marker (x, y, 1) -> normalised homogeneous
      h.col(0) = rot.col(0);
      h.col(1) = rot.col(1);
      h.col(2) = t;
      const Eigen::Matrix3d h_inv = h.inverse();
      const double w = 1.0 / (ss * ss);
      size_t idx = 0;
      for (int j = 0; j < roi.height; ++j) {
        for (int i = 0; i < roi.width; ++i) {
          double white = 0, black = 0;
          for (int s = 0; s < ss * ss; ++s, ++idx) {
            const Eigen::Vector3d q =
                h_inv * Eigen::Vector3d(normalised[idx].x, normalised[idx].y, 1);
            const double x = q.x() / q.z(), y = q.y() / q.z();
            if (std::abs(x) > quiet_half || std::abs(y) > quiet_half) continue;
            white += w;
            if (std::abs(x) >= half || std::abs(y) >= half) continue;
            const int c = std::clamp(static_cast<int>((x + half) / cell), 0, cells - 1);
            const int r = std::clamp(static_cast<int>((half - y) / cell), 0, cells - 1);
            if (bitmap.at<uchar>(r, c) == 0) black += w;
          }
          cov_white.at<double>(j, i) = white;
          cov_black.at<double>(j, i) = black;
        }
      }
    }
    for (int j = 0; j < roi.height; ++j) {
      double* row = image.ptr<double>(roi.y + j);
      for (int i = 0; i < roi.width; ++i) {
        const double cw = std::min(1.0, cov_white.at<double>(j, i));
        const double cb = std::min(cw, cov_black.at<double>(j, i));
        double& v = row[roi.x + i];
        v = v * (1 - cw) + to_linear(m.white_grey) * (cw - cb) + to_linear(m.black_grey) * cb;
      }
    }
  }

  if (options.blur_sigma_px > 0) {
    cv::GaussianBlur(image, image, cv::Size(0, 0), options.blur_sigma_px, options.blur_sigma_px,
                     cv::BORDER_REFLECT);
  }
  cv::Mat codes(size, CV_64FC1);
  std::normal_distribution<double> noise(0, options.noise_sigma_grey);
  for (int j = 0; j < size.height; ++j) {
    const double* src = image.ptr<double>(j);
    double* dst = codes.ptr<double>(j);
    for (int i = 0; i < size.width; ++i) {
      const double encoded =
          identity ? src[i] : 255.0 * encode_fraction(std::clamp(src[i] / 255.0, 0.0, 1.0));
      dst[i] = encoded + (options.noise_sigma_grey > 0 ? noise(*rng) : 0.0);
    }
  }
  if (options.sharpen_amount > 0) {
    cv::Mat blurred;
    cv::GaussianBlur(codes, blurred, cv::Size(0, 0), options.sharpen_sigma_px, options.sharpen_sigma_px,
                     cv::BORDER_REFLECT);
    codes = codes + options.sharpen_amount * (codes - blurred);
  }
  cv::Mat out;
  codes.convertTo(out, CV_8UC1);  // rounds and saturates
  if (options.jpeg_quality > 0) {
    std::vector<uchar> bytes;
    cv::imencode(".jpg", out, bytes, {cv::IMWRITE_JPEG_QUALITY, options.jpeg_quality});
    out = cv::imdecode(bytes, cv::IMREAD_GRAYSCALE);
  }
  return out;
}

CameraResponse ResponseOfEncoding(const std::function<double(double)>& encode) {
  std::array<double, 256> table{};
  for (int v = 0; v < 256; ++v) {
    double lo = 0, hi = 1;
    for (int i = 0; i < 60; ++i) {
      const double mid = 0.5 * (lo + hi);
      (encode(mid) < v / 255.0 ? lo : hi) = mid;
    }
    table[v] = 255 * 0.5 * (lo + hi);
  }
  return CameraResponse::FromTable(table, "truth");
}

Rigid3d MarkerPoseForView(const CameraIntrinsics& camera, const Eigen::Vector2d& centre_px,
                          double side_px, double size_m, double tilt_deg, std::mt19937* rng) {
  std::uniform_real_distribution<double> angle(0, 2 * M_PI);
  // Facing the camera along the line of sight: marker z towards the camera,
  // marker x as close to camera x as possible, marker y = z x x (up).
  const Eigen::Vector3d ray = Eigen::Vector3d((centre_px.x() - camera.cx) / camera.fx,
                                              (centre_px.y() - camera.cy) / camera.fy, 1)
                                  .normalized();
  const Eigen::Vector3d z_axis = -ray;
  const Eigen::Vector3d x_axis =
      (Eigen::Vector3d::UnitX() - Eigen::Vector3d::UnitX().dot(z_axis) * z_axis).normalized();
  Eigen::Matrix3d facing;
  facing.col(0) = x_axis;
  facing.col(1) = z_axis.cross(x_axis);
  facing.col(2) = z_axis;
  // Tilt (the viewing angle) about a random axis in the marker plane.
  const double axis_angle = angle(*rng);
  const Eigen::Vector3d tilt_axis(std::cos(axis_angle), std::sin(axis_angle), 0);
  const Eigen::Matrix3d rot =
      facing * Eigen::AngleAxisd(RadFromDeg(tilt_deg), tilt_axis).toRotationMatrix() *
      Eigen::AngleAxisd(angle(*rng), Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const double distance = camera.fx * size_m / side_px;
  return Rigid3d(rot, distance * ray);
}

std::vector<MarkerPlacement> RandomPlacements(const CameraIntrinsics& camera, int count,
                                              double min_side_px, double max_side_px,
                                              double max_tilt_deg, double size_m, int first_id,
                                              std::mt19937* rng) {
  std::uniform_real_distribution<double> unit(0, 1);
  std::vector<MarkerPlacement> out;
  std::vector<cv::Rect> taken;
  for (int attempt = 0; attempt < 50 * count && static_cast<int>(out.size()) < count; ++attempt) {
    const double side = min_side_px + (max_side_px - min_side_px) * unit(*rng);
    const double reach = 1.0 * side + 8;  // quiet zone and tilt headroom
    const Eigen::Vector2d centre(reach + (camera.width - 2 * reach) * unit(*rng),
                                 reach + (camera.height - 2 * reach) * unit(*rng));
    if (centre.x() < reach || centre.y() < reach) continue;
    const cv::Rect box(static_cast<int>(centre.x() - reach), static_cast<int>(centre.y() - reach),
                       static_cast<int>(2 * reach), static_cast<int>(2 * reach));
    bool overlaps = false;
    for (const cv::Rect& r : taken) overlaps = overlaps || (r & box).area() > 0;
    if (overlaps) continue;
    MarkerPlacement m;
    m.id = first_id + static_cast<int>(out.size());
    m.size_m = size_m;
    m.camera_from_marker =
        MarkerPoseForView(camera, centre, side, size_m, max_tilt_deg * unit(*rng), rng);
    m.black_grey = 15 + 30 * unit(*rng);
    m.white_grey = 170 + 60 * unit(*rng);
    taken.push_back(box);
    out.push_back(m);
  }
  return out;
}

cv::Mat RenderPlaneDepth(const CameraIntrinsics& camera, const Rigid3d& camera_from_plane,
                         double noise_sigma_m, std::mt19937* rng) {
  const Eigen::Vector3d n = camera_from_plane.rotation * Eigen::Vector3d::UnitZ();
  const double offset = n.dot(camera_from_plane.translation);
  std::normal_distribution<double> noise(0, noise_sigma_m);
  cv::Mat depth(camera.height, camera.width, CV_16UC1);
  for (int v = 0; v < camera.height; ++v) {
    uint16_t* row = depth.ptr<uint16_t>(v);
    for (int u = 0; u < camera.width; ++u) {
      const Eigen::Vector3d ray((u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, 1.0);
      const double den = n.dot(ray);
      double z = std::abs(den) > 1e-9 ? offset / den : 0.0;
      if (z > 0) z += noise_sigma_m > 0 ? noise(*rng) : 0.0;
      const double units = z * camera.depth_scale;
      row[u] = (z > 0 && units < 65535) ? static_cast<uint16_t>(std::lround(units)) : 0;
    }
  }
  return depth;
}

CameraIntrinsics VgaCamera() {
  CameraIntrinsics c;
  c.width = 640;
  c.height = 480;
  c.fx = c.fy = 525.0;
  c.cx = 319.5;
  c.cy = 239.5;
  c.depth_scale = 1000;
  return c;
}

CameraIntrinsics HdCamera() {
  CameraIntrinsics c;
  c.width = 1280;
  c.height = 720;
  c.fx = c.fy = 910.0;
  c.cx = 639.5;
  c.cy = 359.5;
  c.depth_scale = 1000;
  return c;
}

}  // namespace arpos::testing
