#include "features/camera_response.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <sstream>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "features/edge_profile.h"
#include "features/edge_refinement.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos {

namespace {

double SrgbToLinear(double c) {
  return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
}

}  // namespace

CameraResponse::CameraResponse() : name_("linear") {
  for (int v = 0; v < 256; ++v) table_[v] = v;
}

CameraResponse CameraResponse::Linear() { return CameraResponse(); }

CameraResponse CameraResponse::Srgb() {
  CameraResponse r;
  for (int v = 0; v < 256; ++v) r.table_[v] = 255.0 * SrgbToLinear(v / 255.0);
  r.name_ = "srgb";
  return r;
}

CameraResponse CameraResponse::Gamma(double gamma) {
  if (!(gamma >= 0.2 && gamma <= 5.0)) {
    ARPOS_INPUT_ERROR("camera response gamma must be in [0.2, 5], got " << gamma);
  }
  CameraResponse r;
  for (int v = 0; v < 256; ++v) r.table_[v] = 255.0 * std::pow(v / 255.0, gamma);
  r.name_ = StringPrintf("gamma%.2f", gamma);
  return r;
}

CameraResponse CameraResponse::FromTable(const std::array<double, 256>& linear_from_code,
                                         std::string name) {
  for (int v = 0; v < 256; ++v) {
    if (!std::isfinite(linear_from_code[v])) {
      ARPOS_INPUT_ERROR("camera response '" << name << "': value for code " << v
                                            << " is not a finite number");
    }
    if (v > 0 && linear_from_code[v] < linear_from_code[v - 1]) {
      ARPOS_INPUT_ERROR("camera response '" << name << "' decreases at code " << v << " ("
                                            << linear_from_code[v - 1] << " -> "
                                            << linear_from_code[v] << ")");
    }
  }
  const double lo = linear_from_code[0], hi = linear_from_code[255];
  if (!(hi > lo)) ARPOS_INPUT_ERROR("camera response '" << name << "' is constant");
  CameraResponse r;
  for (int v = 0; v < 256; ++v) r.table_[v] = 255.0 * (linear_from_code[v] - lo) / (hi - lo);
  r.name_ = std::move(name);
  return r;
}

CameraResponse CameraResponse::FromName(const std::string& name) {
  if (name == "linear") return Linear();
  if (name == "srgb") return Srgb();
  if (name.rfind("gamma", 0) == 0) {
    try {
      size_t used = 0;
      const double g = std::stod(name.substr(5), &used);
      if (used == name.size() - 5) return Gamma(g);
    } catch (const std::logic_error&) {
    }
  }
  ARPOS_INPUT_ERROR("unknown camera response '" << name
                                                << "' (known: linear, srgb, gamma<G> e.g. gamma2.2)");
}

std::string CameraResponse::Serialize() const {
  std::ostringstream out;
  out << name_ << ":";
  for (int v = 0; v < 256; ++v) out << ' ' << StringPrintf("%.4f", table_[v]);
  if (sharpened()) out << " sharpen " << StringPrintf("%.4f %.4f", sharpen_amount_, sharpen_sigma_px_);
  return out.str();
}

CameraResponse CameraResponse::WithSharpening(double amount, double sigma_px) const {
  if (!(amount >= 0 && amount <= 5)) {
    ARPOS_INPUT_ERROR("camera sharpening amount must be within [0, 5], got " << amount);
  }
  if (!(sigma_px >= 0.3 && sigma_px <= 5)) {
    ARPOS_INPUT_ERROR("camera sharpening radius must be within [0.3, 5] px, got " << sigma_px);
  }
  CameraResponse r = *this;
  r.sharpen_amount_ = amount;
  r.sharpen_sigma_px_ = sigma_px;
  return r;
}

CameraResponse CameraResponse::Parse(const std::string& text, const std::string& what) {
  const size_t colon = text.find(':');
  if (colon == std::string::npos || colon == 0) {
    ARPOS_INPUT_ERROR(what << ": camera response must read 'name: v0 ... v255', got '"
                           << text.substr(0, 40) << "'");
  }
  std::istringstream in(text.substr(colon + 1));
  std::array<double, 256> table{};
  for (int v = 0; v < 256; ++v) {
    if (!(in >> table[v])) {
      ARPOS_INPUT_ERROR(what << ": camera response has " << v << " values, 256 expected");
    }
  }
  std::string extra;
  double amount = 0, sigma = 1;
  const bool sharpening = static_cast<bool>(in >> extra);
  if (sharpening) {
    if (extra != "sharpen" || !(in >> amount >> sigma)) {
      ARPOS_INPUT_ERROR(what << ": camera response has more than 256 values (or a malformed 'sharpen AMOUNT "
                                "SIGMA' after them)");
    }
    if (in >> extra) ARPOS_INPUT_ERROR(what << ": camera response has text after its sharpening: '" << extra << "'");
  }
  try {
    CameraResponse r = FromTable(table, text.substr(0, colon));
    return sharpening ? r.WithSharpening(amount, sigma) : r;  // checks the stored values
  } catch (const InputError& e) {
    ARPOS_INPUT_ERROR(what << ": " << e.what());
  }
}

double CameraResponse::MaxDifference(const CameraResponse& other, int from_code,
                                     int to_code) const {
  double worst = 0;
  for (int v = std::max(0, from_code); v <= std::min(255, to_code); ++v) {
    worst = std::max(worst, std::abs(table_[v] - other.table_[v]));
  }
  return worst / 255.0;
}

void CameraResponse::LinearizeImage(const cv::Mat& gray, cv::Mat* linear) const {
  ARPOS_CHECK(linear != nullptr, "no output image");
  ARPOS_CHECK(gray.type() == CV_8UC1,
              "LinearizeImage needs an 8-bit grey image, got type " << gray.type());
  cv::Mat lut(1, 256, CV_8UC1);
  for (int v = 0; v < 256; ++v) lut.at<uchar>(0, v) = cv::saturate_cast<uchar>(table_[v]);
  cv::LUT(gray, lut, *linear);
}

std::string CellEdgeOptions::Validate() const {
  if (marker_bits < 1 || marker_bits > 16) return "marker_bits must be in 1..16";
  if (border_bits < 1 || border_bits > 4) return "border_bits must be in 1..4";
  if (!(quiet_zone_cells >= 0.5)) return "quiet_zone_cells must be at least 0.5";
  if (!(min_cell_px >= 2)) return "min_cell_px must be at least 2";
  return "";
}

std::string ResponseEstimationOptions::Validate() const {
  if (basis < 1 || basis > 12) return StringPrintf("basis must be in 1..12, got %d", basis);
  if (min_markers < 1) return "min_markers must be positive";
  if (!(deformation_sigma > 0) || !(widening_floor_px > 0)) return "sigmas must be positive";
  if (iterations < 1 || max_markers < 1) return "iterations and max_markers must be positive";
  return "";
}

std::optional<MarkerCellEdges> PrepareMarkerCellEdges(const cv::Mat& gray,
                                                      const std::array<Eigen::Vector2d, 4>& corners_px,
                                                      const cv::Mat& bits, double blur_sigma_px,
                                                      const PixelUndistorter& undistorter,
                                                      const CellEdgeOptions& options) {
  const std::string invalid = options.Validate();
  ARPOS_CHECK(invalid.empty(), "invalid CellEdgeOptions: " << invalid);
  ARPOS_CHECK(gray.type() == CV_8UC1, "PrepareMarkerCellEdges needs an 8-bit grey image");
  const int n = options.marker_bits + 2 * options.border_bits;
  ARPOS_CHECK(bits.type() == CV_8UC1 && bits.rows == n && bits.cols == n,
              "the cell matrix must be " << n << "x" << n << " CV_8UC1");

  // Homography unit square -> ideal pixels (TL, TR, BR, BL), and back.
  std::vector<cv::Point2f> src = {{0, 0}, {1, 0}, {1, 1}, {0, 1}}, dst;
  double min_side = 1e300;
  std::array<Eigen::Vector2d, 4> ideal;
  for (int k = 0; k < 4; ++k) {
    ideal[k] = undistorter.Undistort(corners_px[k]);
    if (!ideal[k].allFinite()) return std::nullopt;
    dst.emplace_back(static_cast<float>(ideal[k].x()), static_cast<float>(ideal[k].y()));
  }
  for (int k = 0; k < 4; ++k) min_side = std::min(min_side, (ideal[(k + 1) % 4] - ideal[k]).norm());
  MarkerCellEdges out;
  out.cell_px = min_side / n;
  out.blur_sigma_px = std::max(0.05, blur_sigma_px);
  if (!(out.cell_px >= options.min_cell_px)) return std::nullopt;
  const cv::Mat hm = cv::getPerspectiveTransform(src, dst);
  Eigen::Matrix3d h;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) h(r, c) = hm.at<double>(r, c);
  }
  const Eigen::Matrix3d h_inv = h.inverse();
  auto to_image = [&](double u, double v) {
    const Eigen::Vector3d q = h * Eigen::Vector3d(u, v, 1);
    return Eigen::Vector2d(q.head<2>() / q.z());
  };
  auto to_square = [&](const Eigen::Vector2d& p) {
    const Eigen::Vector3d q = h_inv * Eigen::Vector3d(p.x(), p.y(), 1);
    return Eigen::Vector2d(q.head<2>() / q.z());
  };
  const Eigen::Vector2d centre = to_image(0.5, 0.5);
  auto black = [&](int row, int col) {
    if (row < 0 || row >= n || col < 0 || col >= n) return false;  // quiet zone
    return bits.at<uchar>(row, col) == 0;
  };
  const double cell = 1.0 / n;
  const double across = 0.45 * cell;  // band half-width across a boundary
  const double guard = 0.25 * cell;   // kept from the segment's ends (cell corners)

  // dir 0: boundaries at u = b / n between columns b-1 and b (segment along v
  // in row r); dir 1: at v = b / n between rows b-1 and b (along u in column r).
  for (int dir = 0; dir < 2; ++dir) {
    for (int b = 0; b <= n; ++b) {
      for (int r = 0; r < n; ++r) {
        const bool before = dir == 0 ? black(r, b - 1) : black(b - 1, r);
        const bool after = dir == 0 ? black(r, b) : black(b, r);
        if (before == after) continue;
        const double w = 1.0 / n;
        const double pos = b * w, lo = r * w, hi = (r + 1) * w;
        auto sq = [&](double across_coord, double along_coord) {
          return dir == 0 ? to_image(across_coord, along_coord) : to_image(along_coord, across_coord);
        };
        const Eigen::Vector2d p0 = sq(pos, lo), p1 = sq(pos, hi);
        Eigen::Vector2d normal(-(p1 - p0).y(), (p1 - p0).x());
        normal.normalize();
        // Towards white: the side `after` (larger coordinate) if after is white.
        const Eigen::Vector2d white_side = sq(pos + (after ? -0.5 : 0.5) * w, 0.5 * (lo + hi));
        if (normal.dot(white_side - p0) < 0) normal = -normal;

        // Pixels in the band, away from the segment's ends.
        double x_min = 1e300, x_max = -1e300, y_min = 1e300, y_max = -1e300;
        for (double a : {pos - across, pos + across}) {
          for (double l : {lo + guard, hi - guard}) {
            Eigen::Vector2d q = sq(a, l);
            if (!undistorter.IsIdentity()) q = undistorter.Distort(q);
            x_min = std::min(x_min, q.x());
            x_max = std::max(x_max, q.x());
            y_min = std::min(y_min, q.y());
            y_max = std::max(y_max, q.y());
          }
        }
        const int x0 = static_cast<int>(std::floor(x_min)) - 1, x1 = static_cast<int>(std::ceil(x_max)) + 1;
        const int y0 = static_cast<int>(std::floor(y_min)) - 1, y1 = static_cast<int>(std::ceil(y_max)) + 1;
        if (x0 < 0 || y0 < 0 || x1 >= gray.cols || y1 >= gray.rows) return std::nullopt;
        MarkerCellEdges::Boundary bd;
        for (int y = y0; y <= y1; ++y) {
          const uchar* row = gray.ptr<uchar>(y);
          for (int x = x0; x <= x1; ++x) {
            Eigen::Vector2d p(x, y);
            if (!undistorter.IsIdentity()) p = undistorter.Undistort(p);
            const Eigen::Vector2d s2 = to_square(p);
            const double a = dir == 0 ? s2.x() : s2.y(), l = dir == 0 ? s2.y() : s2.x();
            if (std::abs(a - pos) > across || l < lo + guard || l > hi - guard) continue;
            bd.code.push_back(row[x]);
            bd.distance_px.push_back(static_cast<float>(normal.dot(p - p0)));
          }
        }
        if (bd.code.size() < 8) continue;
        bd.normal_x = normal.x();
        bd.normal_y = normal.y();
        const Eigen::Vector2d mid = 0.5 * (p0 + p1) - centre;
        bd.centre_x = mid.x();
        bd.centre_y = mid.y();
        out.boundaries.push_back(std::move(bd));
      }
    }
  }
  if (out.boundaries.size() < 12) return std::nullopt;
  return out;
}

namespace {

/// Offset (px, towards white) of one boundary under `g`, with its
/// 1-sigma uncertainty; false if the fit fails. Model: linear values
/// B + C S(d - offset; blur, footprint), Gauss-Newton on (offset, B, C).
bool FitBoundary(const MarkerCellEdges::Boundary& bd, double sigma,
                 const std::array<double, 256>& g, double* offset, double* offset_sigma) {
  double narrow_var, half_a, inv_a;
  edge_profile::FootprintFor(bd.normal_x, bd.normal_y, &narrow_var, &half_a, &inv_a);
  const double s = std::sqrt(sigma * sigma + narrow_var), inv_s = 1.0 / s;
  double lo_sum = 0, hi_sum = 0;
  int lo_n = 0, hi_n = 0;
  for (size_t i = 0; i < bd.code.size(); ++i) {
    if (bd.distance_px[i] < -1.0) lo_sum += g[bd.code[i]], ++lo_n;
    if (bd.distance_px[i] > 1.0) hi_sum += g[bd.code[i]], ++hi_n;
  }
  if (lo_n == 0 || hi_n == 0) return false;
  Eigen::Vector3d x(0, lo_sum / lo_n, hi_sum / hi_n - lo_sum / lo_n);
  Eigen::Matrix3d jtj;
  double rss = 0;
  for (int iter = 0; iter < 8; ++iter) {
    jtj.setZero();
    Eigen::Vector3d jtr = Eigen::Vector3d::Zero();
    rss = 0;
    for (size_t i = 0; i < bd.code.size(); ++i) {
      const edge_profile::Profile pr =
          edge_profile::EdgeProfile(bd.distance_px[i] - x(0), sigma, inv_s, s, half_a, inv_a);
      const double r = x(1) + x(2) * pr.value - g[bd.code[i]];
      const Eigen::Vector3d j(-x(2) * pr.d_dist, 1.0, pr.value);
      jtj.noalias() += j * j.transpose();
      jtr.noalias() += j * r;
      rss += r * r;
    }
    const Eigen::Vector3d step = jtj.ldlt().solve(-jtr);
    if (!step.allFinite()) return false;
    x += step;
    if (std::abs(step(0)) < 1e-4) break;
  }
  if (!(x(2) > 0) || !std::isfinite(x(0))) return false;
  const double var = rss / std::max<double>(1, bd.code.size() - 3);
  const Eigen::Matrix3d cov = jtj.inverse() * var;
  *offset = x(0);
  *offset_sigma = std::sqrt(std::max(1e-12, cov(0, 0)));
  return std::isfinite(*offset_sigma);
}

}  // namespace

double MarkerWidening(const MarkerCellEdges& marker, const CameraResponse& response,
                      double* sigma_px) {
  const std::array<double, 256>& g = response.linear_from_code();
  // offset_e = widening + grid terms: scale k (x.n), shift t.n, turn w (x cross n).
  Eigen::Matrix<double, 5, 5> ata = Eigen::Matrix<double, 5, 5>::Zero();
  Eigen::Matrix<double, 5, 1> atb = Eigen::Matrix<double, 5, 1>::Zero();
  std::vector<std::pair<Eigen::Matrix<double, 5, 1>, double>> rows;
  std::vector<double> weights;
  const double max_offset = 0.45 * marker.cell_px;
  for (const MarkerCellEdges::Boundary& bd : marker.boundaries) {
    double offset, sigma;
    if (!FitBoundary(bd, marker.blur_sigma_px, g, &offset, &sigma)) continue;
    if (std::abs(offset) > max_offset) continue;
    const double nx = bd.normal_x, ny = bd.normal_y, cx = bd.centre_x, cy = bd.centre_y;
    Eigen::Matrix<double, 5, 1> a;
    a << 1.0, cx * nx + cy * ny, nx, ny, cx * ny - cy * nx;
    const double w = 1.0 / (sigma * sigma + 1e-4);
    ata.noalias() += w * a * a.transpose();
    atb.noalias() += w * a * offset;
    rows.push_back({a, offset});
    weights.push_back(w);
  }
  if (rows.size() < 10) return std::nan("");
  const Eigen::Matrix<double, 5, 1> x = ata.ldlt().solve(atb);
  double chi2 = 0;
  for (size_t i = 0; i < rows.size(); ++i) {
    const double r = rows[i].first.dot(x) - rows[i].second;
    chi2 += weights[i] * r * r;
  }
  const double scale = std::max(1.0, chi2 / (rows.size() - 5));
  if (sigma_px != nullptr) {
    *sigma_px = std::sqrt(ata.inverse()(0, 0) * scale);
  }
  return x(0);
}

ResponseEstimate EstimateCameraResponse(const std::vector<MarkerCellEdges>& markers,
                                        const CameraResponse& prior,
                                        const ResponseEstimationOptions& options) {
  const std::string invalid = options.Validate();
  ARPOS_CHECK(invalid.empty(), "invalid ResponseEstimationOptions: " << invalid);
  ResponseEstimate out;
  out.response = prior;

  // The largest markers (most pixels per boundary) first, those with a widening.
  std::vector<const MarkerCellEdges*> order;
  for (const MarkerCellEdges& m : markers) order.push_back(&m);
  std::sort(order.begin(), order.end(),
            [](const MarkerCellEdges* a, const MarkerCellEdges* b) { return a->cell_px > b->cell_px; });
  std::vector<const MarkerCellEdges*> used;
  std::vector<double> sigma;
  double sum_sq = 0;
  for (const MarkerCellEdges* m : order) {
    if (static_cast<int>(used.size()) >= options.max_markers) break;
    double s = 0;
    const double w = MarkerWidening(*m, prior, &s);
    if (std::isnan(w)) continue;
    used.push_back(m);
    sigma.push_back(std::max(options.widening_floor_px, s));
    sum_sq += w * w;
  }
  out.markers_used = static_cast<int>(used.size());
  if (out.markers_used < options.min_markers) {
    out.message = StringPrintf("%d markers large enough, %d needed", out.markers_used,
                               options.min_markers);
    return out;
  }
  out.widening_prior_px = std::sqrt(sum_sq / used.size());

  const int K = options.basis;
  const std::array<double, 256>& p = prior.linear_from_code();
  auto curve = [&](const Eigen::VectorXd& a) {
    std::array<double, 256> table{};
    for (int v = 0; v < 256; ++v) {
      table[v] = p[v];
      for (int k = 0; k < K; ++k) table[v] += a(k) * 255.0 * std::sin((k + 1) * M_PI * v / 255.0);
      if (v > 0) table[v] = std::max(table[v], table[v - 1] + 1e-3);  // monotone
    }
    return CameraResponse::FromTable(table, "estimated");
  };
  const int m = static_cast<int>(used.size());
  auto residuals = [&](const Eigen::VectorXd& a, Eigen::VectorXd* r) {
    const CameraResponse g = curve(a);
    r->resize(m + K);
    for (int i = 0; i < m; ++i) {
      const double w = MarkerWidening(*used[i], g);
      (*r)(i) = std::isnan(w) ? 0.0 : w / sigma[i];
    }
    for (int k = 0; k < K; ++k) (*r)(m + k) = a(k) / options.deformation_sigma;
  };
  Eigen::VectorXd a = Eigen::VectorXd::Zero(K), r, r_new;
  residuals(a, &r);
  double lambda = 1e-3;
  for (int iter = 0; iter < options.iterations; ++iter) {
    Eigen::MatrixXd j(m + K, K);
    constexpr double kStep = 0.005;
    for (int k = 0; k < K; ++k) {
      Eigen::VectorXd ak = a;
      ak(k) += kStep;
      Eigen::VectorXd rk;
      residuals(ak, &rk);
      j.col(k) = (rk - r) / kStep;
    }
    const Eigen::MatrixXd jtj = j.transpose() * j;
    const Eigen::VectorXd jtr = j.transpose() * r;
    bool improved = false;
    for (int attempt = 0; attempt < 5 && !improved; ++attempt) {
      Eigen::MatrixXd damped = jtj;
      damped.diagonal() *= 1 + lambda;
      const Eigen::VectorXd step = damped.ldlt().solve(-jtr);
      const Eigen::VectorXd trial = a + step;
      residuals(trial, &r_new);
      if (r_new.squaredNorm() < r.squaredNorm()) {
        const double gain = r.squaredNorm() - r_new.squaredNorm();
        a = trial;
        r = r_new;
        lambda = std::max(1e-6, lambda * 0.3);
        improved = true;
        if (gain < 1e-4 * r.squaredNorm()) iter = options.iterations;
      } else {
        lambda *= 10;
      }
    }
    if (!improved) break;
  }
  out.response = curve(a);
  sum_sq = 0;
  for (int i = 0; i < m; ++i) sum_sq += std::pow(r(i) * sigma[i], 2);
  out.widening_px = std::sqrt(sum_sq / m);

  out.closest_difference = 1e9;
  auto consider = [&](const CameraResponse& c) {
    const double d = out.response.MaxDifference(c, 16, 240);
    if (d < out.closest_difference) {
      out.closest_difference = d;
      out.closest_standard = c.name();
    }
  };
  consider(CameraResponse::Srgb());
  for (int t = 10; t <= 30; ++t) consider(CameraResponse::Gamma(t / 10.0));
  out.ok = true;
  out.message = StringPrintf(
      "estimated from %d markers (black widening %.3f px under %s, %.3f px under the estimate); "
      "closest standard curve %s (within %.1f %% of full scale)",
      out.markers_used, out.widening_prior_px, prior.name().c_str(), out.widening_px,
      out.closest_standard.c_str(), 100 * out.closest_difference);
  return out;
}

}  // namespace arpos
