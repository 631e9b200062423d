#include "features/marker_template.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <tuple>

#include <opencv2/imgproc.hpp>

namespace arpos {
namespace {

// Homography from the marker's cells (s, t; the black square is [0, N]^2)
// to image pixels, through the four corners in ArUco order.
Eigen::Matrix3d HomographyOf(const std::array<Eigen::Vector2d, 4>& px, double n) {
  const double src[4][2] = {{0, 0}, {n, 0}, {n, n}, {0, n}};
  Eigen::Matrix<double, 8, 8> A;
  Eigen::Matrix<double, 8, 1> b;
  for (int i = 0; i < 4; ++i) {
    const double s = src[i][0], t = src[i][1], x = px[i].x(), y = px[i].y();
    A.row(2 * i) << s, t, 1, 0, 0, 0, -x * s, -x * t;
    A.row(2 * i + 1) << 0, 0, 0, s, t, 1, -y * s, -y * t;
    b(2 * i) = x;
    b(2 * i + 1) = y;
  }
  const Eigen::Matrix<double, 8, 1> h = A.partialPivLu().solve(b);
  Eigen::Matrix3d H;
  H << h(0), h(1), h(2), h(3), h(4), h(5), h(6), h(7), 1;
  return H;
}

Eigen::Vector2d Apply(const Eigen::Matrix3d& H, double x, double y) {
  const Eigen::Vector3d p = H * Eigen::Vector3d(x, y, 1);
  return p.head<2>() / p.z();
}

// A pixel's predicted value's derivatives in the inverse homography's eight
// entries (its last one 1) and the three levels, from the template's
// samples `v` (with gradients) at its cell coordinates `st`.
Eigen::Matrix<double, 11, 1> HomographyRow(const Eigen::Matrix3d& G, const Eigen::Vector3d& levels,
                                           const float v[6], const Eigen::Vector2d& st, double x,
                                           double y) {
  const double ds = levels(1) * v[2] + levels(2) * v[4];
  const double dt = levels(1) * v[3] + levels(2) * v[5];
  const double w = 1.0 / (G(2, 0) * x + G(2, 1) * y + G(2, 2));
  const double xw = x * w, yw = y * w, along = -(ds * st.x() + dt * st.y());
  Eigen::Matrix<double, 11, 1> j;
  j << ds * xw, ds * yw, ds * w, dt * xw, dt * yw, dt * w, along * xw, along * yw, 1, v[0], v[1];
  return j;
}

// The pattern blurred, sampled `rate` times a cell over [-margin, N +
// margin]^2: white (quiet zone and white cells) and outside (beyond the
// quiet zone) indicators, and (on demand) their gradients per cell.
struct Template {
  double margin = 0;
  int rate = 8;
  int size = 0;
  cv::Mat white, outside;  // CV_32F
  // Interleaved for sampling: white, outside (and, once AddGradients ran,
  // their derivatives in s and t).
  std::vector<float> table2, table6;

  void Interleave() {
    table2.resize(static_cast<size_t>(size) * size * 2);
    for (int y = 0; y < size; ++y) {
      const float* w = white.ptr<float>(y);
      const float* o = outside.ptr<float>(y);
      float* dst = &table2[static_cast<size_t>(y) * size * 2];
      for (int x = 0; x < size; ++x) dst[2 * x] = w[x], dst[2 * x + 1] = o[x];
    }
  }

  void AddGradients() {
    if (!table6.empty()) return;
    const float half = 0.5f * static_cast<float>(rate);
    const cv::Mat kx = (cv::Mat_<float>(1, 3) << -half, 0.f, half);
    const cv::Mat ky = kx.t();
    cv::Mat d[4];
    cv::filter2D(white, d[0], CV_32F, kx, cv::Point(-1, -1), 0, cv::BORDER_REPLICATE);
    cv::filter2D(white, d[1], CV_32F, ky, cv::Point(-1, -1), 0, cv::BORDER_REPLICATE);
    cv::filter2D(outside, d[2], CV_32F, kx, cv::Point(-1, -1), 0, cv::BORDER_REPLICATE);
    cv::filter2D(outside, d[3], CV_32F, ky, cv::Point(-1, -1), 0, cv::BORDER_REPLICATE);
    table6.resize(static_cast<size_t>(size) * size * 6);
    for (int y = 0; y < size; ++y) {
      const float* src[6] = {white.ptr<float>(y), outside.ptr<float>(y), d[0].ptr<float>(y),
                             d[1].ptr<float>(y),  d[2].ptr<float>(y),    d[3].ptr<float>(y)};
      float* dst = &table6[static_cast<size_t>(y) * size * 6];
      for (int x = 0; x < size; ++x) {
        for (int k = 0; k < 6; ++k) dst[6 * x + k] = src[k][x];
      }
    }
  }

  // Bilinear samples at (s, t) in cells (`count` 2: the levels' indicators
  // only, 6: with their gradients, after AddGradients); false outside the
  // table.
  bool Sample(double s, double t, float out[6], int count = 6) const {
    const double fx = (s + margin) * rate - 0.5, fy = (t + margin) * rate - 0.5;
    // (Checked before any cast: a degenerate homography gives NaN.)
    if (!(fx >= 0 && fy >= 0 && fx < size - 1 && fy < size - 1)) return false;
    const int x0 = static_cast<int>(fx), y0 = static_cast<int>(fy);
    const float ax = static_cast<float>(fx - x0), ay = static_cast<float>(fy - y0);
    const float* r0 = (count == 2 ? table2.data() : table6.data()) +
                      (static_cast<size_t>(y0) * size + x0) * count;
    const float* r1 = r0 + static_cast<size_t>(size) * count;
    for (int k = 0; k < count; ++k) {
      out[k] = (1 - ay) * ((1 - ax) * r0[k] + ax * r0[count + k]) +
               ay * ((1 - ax) * r1[k] + ax * r1[count + k]);
    }
    return true;
  }
};

Template MakeTemplate(const cv::Mat& cells, double quiet_zone, double extent, double sigma_cells) {
  Template T;
  const int n = cells.cols;
  // A few samples per blur sigma (at least 4, at most 16 a cell).
  T.rate = std::clamp(static_cast<int>(std::ceil(2.5 / sigma_cells)), 4, 16);
  T.margin = extent + 3 * sigma_cells + 1;
  T.size = static_cast<int>(std::ceil((n + 2 * T.margin) * T.rate));
  T.white.create(T.size, T.size, CV_32F);
  T.outside.create(T.size, T.size, CV_32F);
  for (int y = 0; y < T.size; ++y) {
    const double t = (y + 0.5) / T.rate - T.margin;
    float* w = T.white.ptr<float>(y);
    float* o = T.outside.ptr<float>(y);
    for (int x = 0; x < T.size; ++x) {
      const double s = (x + 0.5) / T.rate - T.margin;
      const bool inside = s >= 0 && s < n && t >= 0 && t < n;
      const bool quiet = !inside && s >= -quiet_zone && s < n + quiet_zone && t >= -quiet_zone &&
                         t < n + quiet_zone;
      float white = quiet ? 1.f : 0.f;
      if (inside)
        white = cells.at<uchar>(static_cast<int>(t), static_cast<int>(s)) > 127 ? 1.f : 0.f;
      w[x] = white;
      o[x] = (!inside && !quiet) ? 1.f : 0.f;
    }
  }
  const double sigma = sigma_cells * T.rate;
  const int k = 2 * static_cast<int>(std::ceil(3 * sigma)) + 1;
  cv::GaussianBlur(T.white, T.white, cv::Size(k, k), sigma, sigma, cv::BORDER_REPLICATE);
  cv::GaussianBlur(T.outside, T.outside, cv::Size(k, k), sigma, sigma, cv::BORDER_REPLICATE);
  T.Interleave();
  return T;
}

}  // namespace

struct MarkerTemplateCache::Impl {
  // Cells, blur (2 % steps of sigma in cells), quiet zone and extent (1/64 cell).
  using Key = std::tuple<std::string, long, long, long>;
  std::map<Key, std::shared_ptr<Template>> templates;
  static constexpr size_t kCapacity = 48;

  std::shared_ptr<Template> Get(const cv::Mat& cells, double quiet_zone, double extent,
                                double sigma_cells) {
    const long q = std::lround(std::log(sigma_cells) / std::log(1.02));
    Key key{std::string(cells.begin<uchar>(), cells.end<uchar>()), q, std::lround(quiet_zone * 64),
            std::lround(extent * 64)};
    auto it = templates.find(key);
    if (it != templates.end()) return it->second;
    if (templates.size() >= kCapacity) templates.clear();
    auto made =
        std::make_shared<Template>(MakeTemplate(cells, quiet_zone, extent, std::pow(1.02, q)));
    templates.emplace(std::move(key), made);
    return made;
  }
};

MarkerTemplateCache::MarkerTemplateCache() : impl_(std::make_unique<Impl>()) {}
MarkerTemplateCache::~MarkerTemplateCache() = default;

namespace {

struct Pixel {
  int x, y;
  double value;   // linear grey
  double weight;  // robust (Huber) weight of its last residual
};

// The three levels (black, white - black, outside - black) by linear least
// squares at the given geometry; the sum of squared residuals.
double SolveLevels(const std::vector<Pixel>& pixels, const Template& T, const Eigen::Matrix3d& G,
                   Eigen::Vector3d* levels) {
  Eigen::Matrix3d AtA = Eigen::Matrix3d::Zero();
  Eigen::Vector3d Atb = Eigen::Vector3d::Zero();
  double btb = 0;
  float v[6];
  for (const Pixel& p : pixels) {
    const Eigen::Vector2d st = Apply(G, p.x, p.y);
    if (!T.Sample(st.x(), st.y(), v, 2)) continue;
    const Eigen::Vector3d a(1, v[0], v[1]);
    AtA += p.weight * a * a.transpose();
    Atb += p.weight * a * p.value;
    btb += p.weight * p.value * p.value;
  }
  // A level the pixels do not see (no surroundings in reach) stays 0.
  AtA += 1e-6 * Eigen::Matrix3d::Identity();
  *levels = AtA.ldlt().solve(Atb);
  return std::max(0.0, btb - 2 * levels->dot(Atb) + levels->dot(AtA * *levels));
}

// Black and white within the codes' linear range, allowing for the blur
// model's own compromise on cells of a pixel or two (black fitted ~10-20
// levels below 0 on exact renders): levels far beyond it mean a blur that
// mixes the quiet zone with its surroundings to follow their texture.
bool Physical(const Eigen::Vector3d& levels) {
  const double black = levels(0), white = levels(0) + levels(1);
  return black > -50 && white < 290 && white > black;
}

}  // namespace

MarkerTemplateResult FitMarkerTemplate(const cv::Mat& gray, const cv::Mat& cells,
                                       const std::array<Eigen::Vector2d, 4>& initial_px,
                                       const MarkerTemplateOptions& o, MarkerTemplateCache* cache) {
  MarkerTemplateCache local;
  MarkerTemplateCache::Impl& templates = (cache != nullptr ? cache : &local)->impl();
  MarkerTemplateResult out;
  out.corners_px = initial_px;
  if (gray.empty() || gray.type() != CV_8UC1 || cells.empty() || cells.type() != CV_8UC1 ||
      cells.rows != cells.cols) {
    out.failure = "needs an 8-bit grey image and a square cell matrix";
    return out;
  }
  const double n = cells.cols;
  double perimeter = 0;
  for (int c = 0; c < 4; ++c) {
    if (!initial_px[c].allFinite()) {
      out.failure = "corners not finite";
      return out;
    }
    perimeter += (initial_px[(c + 1) % 4] - initial_px[c]).norm();
  }
  const double side = perimeter / 4;
  if (side < o.min_side_px || side > o.max_side_px) {
    out.failure = "side outside the fitted range";
    return out;
  }
  const double extent = o.quiet_zone_cells + o.surround_cells;

  std::array<Eigen::Vector2d, 4> corners = initial_px;
  if (!HomographyOf(corners, n).allFinite()) {
    out.failure = "corners not a quadrilateral";
    return out;
  }
  if (o.search_radius_px > 0) {
    // The pattern as the start's corners project it, correlated with the
    // image over shifts of up to the radius: the fits below start from the
    // best (their own reach is about a cell).
    const Eigen::Matrix3d H = HomographyOf(corners, n);
    const Eigen::Matrix3d G = H.inverse();
    Eigen::AlignedBox2d box;
    for (const auto& [s, t] : {std::pair<double, double>{-o.quiet_zone_cells, -o.quiet_zone_cells},
                               {n + o.quiet_zone_cells, -o.quiet_zone_cells},
                               {n + o.quiet_zone_cells, n + o.quiet_zone_cells},
                               {-o.quiet_zone_cells, n + o.quiet_zone_cells}}) {
      box.extend(Apply(H, s, t));
    }
    const int r = static_cast<int>(std::ceil(o.search_radius_px));
    if (!(box.min().x() - r >= 0 && box.min().y() - r >= 0 && box.max().x() + r + 1 < gray.cols &&
          box.max().y() + r + 1 < gray.rows)) {
      out.failure = "the marker and its surroundings are not inside the image";
      return out;
    }
    const cv::Rect patch(static_cast<int>(std::floor(box.min().x())),
                         static_cast<int>(std::floor(box.min().y())),
                         static_cast<int>(std::ceil(box.max().x())) -
                             static_cast<int>(std::floor(box.min().x())) + 1,
                         static_cast<int>(std::ceil(box.max().y())) -
                             static_cast<int>(std::floor(box.min().y())) + 1);
    const cv::Rect region(patch.x - r, patch.y - r, patch.width + 2 * r, patch.height + 2 * r);
    if (region.x < 0 || region.y < 0 || region.x + region.width > gray.cols ||
        region.y + region.height > gray.rows) {
      out.failure = "the marker and its surroundings are not inside the image";
      return out;
    }
    const std::shared_ptr<Template> T =
        templates.Get(cells, o.quiet_zone_cells, extent,
                      std::sqrt(o.search_blur_px * o.search_blur_px + 1.0 / 12) / (side / n));
    cv::Mat pattern(patch.size(), CV_32F), mask(patch.size(), CV_8U, cv::Scalar(0));
    double sum = 0;
    int count = 0;
    float v[6];
    for (int y = 0; y < patch.height; ++y) {
      for (int x = 0; x < patch.width; ++x) {
        const Eigen::Vector2d st = Apply(G, patch.x + x, patch.y + y);
        const bool in = st.x() >= -o.quiet_zone_cells && st.y() >= -o.quiet_zone_cells &&
                        st.x() <= n + o.quiet_zone_cells && st.y() <= n + o.quiet_zone_cells &&
                        T->Sample(st.x(), st.y(), v, 2);
        pattern.at<float>(y, x) = in ? v[0] : 0.f;
        if (in) sum += v[0], ++count, mask.at<uchar>(y, x) = 1;
      }
    }
    if (count < 16) {
      out.failure = "too few pixels";
      return out;
    }
    // Outside the quiet zone: the pattern's mean (no say in the correlation).
    pattern.setTo(static_cast<float>(sum / count), mask == 0);
    cv::Mat linear(region.size(), CV_32F);
    for (int y = 0; y < region.height; ++y) {
      const uchar* row = gray.ptr<uchar>(region.y + y) + region.x;
      float* dst = linear.ptr<float>(y);
      for (int x = 0; x < region.width; ++x)
        dst[x] = static_cast<float>(o.response.Linearize(row[x]));
    }
    cv::Mat score;
    cv::matchTemplate(linear, pattern, score, cv::TM_CCOEFF_NORMED);
    cv::Point best;
    double best_score = 0;
    cv::minMaxLoc(score, nullptr, &best_score, nullptr, &best);
    Eigen::Vector2d shift(best.x - r, best.y - r);
    // Sub-pixel: a parabola through the peak and its neighbours.
    auto peak = [&](double a, double b, double c) {
      const double d = a - 2 * b + c;
      return d < 0 ? std::clamp(0.5 * (a - c) / d, -0.5, 0.5) : 0.0;
    };
    if (best.x > 0 && best.x + 1 < score.cols) {
      shift.x() += peak(score.at<float>(best.y, best.x - 1), score.at<float>(best.y, best.x),
                        score.at<float>(best.y, best.x + 1));
    }
    if (best.y > 0 && best.y + 1 < score.rows) {
      shift.y() += peak(score.at<float>(best.y - 1, best.x), score.at<float>(best.y, best.x),
                        score.at<float>(best.y + 1, best.x));
    }
    for (auto& c : corners) c += shift;
  }
  auto gather = [&](const Eigen::Matrix3d& H, std::vector<Pixel>* pixels) {
    pixels->clear();
    const Eigen::Matrix3d G = H.inverse();
    Eigen::AlignedBox2d box;
    for (const auto& [s, t] : {std::pair<double, double>{-extent, -extent},
                               {n + extent, -extent},
                               {n + extent, n + extent},
                               {-extent, n + extent}}) {
      box.extend(Apply(H, s, t));
    }
    if (!(box.min().x() > -1 && box.min().y() > -1 && box.max().x() < gray.cols &&
          box.max().y() < gray.rows)) {
      return false;
    }
    const int x0 = static_cast<int>(std::ceil(box.min().x())),
              y0 = static_cast<int>(std::ceil(box.min().y()));
    const int x1 = static_cast<int>(std::floor(box.max().x())),
              y1 = static_cast<int>(std::floor(box.max().y()));
    for (int y = y0; y <= y1; ++y) {
      const uchar* row = gray.ptr<uchar>(y);
      for (int x = x0; x <= x1; ++x) {
        const Eigen::Vector2d st = Apply(G, x, y);
        if (st.x() < -extent || st.y() < -extent || st.x() > n + extent || st.y() > n + extent)
          continue;
        pixels->push_back({x, y, o.response.Linearize(row[x]), 1.0});
      }
    }
    return true;
  };

  std::vector<Pixel> pixels;
  Eigen::Vector3d levels;
  // Levenberg-Marquardt on the inverse homography G (image px -> cells, its
  // last entry 1; a cell coordinate's derivatives are then plain) and the
  // three levels at one blur, Huber-weighted (the surroundings are rarely
  // one flat level: skin, print, texture) with the residuals' scale from
  // their median at the start. `shift_only`: the image moves under the
  // pattern as a whole (a wide basin at a coarse blur: the prediction's
  // shape is good, its place is not).
  auto corners_of = [&](const Eigen::Matrix3d& G) {
    const Eigen::Matrix3d H = G.inverse();
    std::array<Eigen::Vector2d, 4> c;
    const double src[4][2] = {{0, 0}, {n, 0}, {n, n}, {0, n}};
    for (int k = 0; k < 4; ++k) c[k] = Apply(H, src[k][0], src[k][1]);
    return c;
  };
  std::vector<double> magnitudes;
  double huber_k = 1;
  auto residual = [&](const Template& T, const Eigen::Matrix3d& G, const Eigen::Vector3d& l,
                      const Pixel& p, float v[6], int count, Eigen::Vector2d* st, double* r) {
    *st = Apply(G, p.x, p.y);
    if (!T.Sample(st->x(), st->y(), v, count)) return false;
    *r = p.value - (l(0) + l(1) * v[0] + l(2) * v[1]);
    return true;
  };
  auto robust_cost = [&](const Template& T, const Eigen::Matrix3d& G, const Eigen::Vector3d& l) {
    double c = 0;
    float v[6];
    Eigen::Vector2d st;
    double r;
    for (const Pixel& p : pixels) {
      if (!residual(T, G, l, p, v, 2, &st, &r)) continue;
      const double a = std::abs(r);
      c += a <= huber_k ? r * r : 2 * huber_k * a - huber_k * huber_k;
    }
    return c;
  };
  auto fit = [&](double blur_px, int max_iterations, bool shift_only,
                 double convergence_px) -> bool {
    const double cell_px = side / n;
    const std::shared_ptr<Template> held = templates.Get(
        cells, o.quiet_zone_cells, extent, std::sqrt(blur_px * blur_px + 1.0 / 12) / cell_px);
    held->AddGradients();
    const Template& T = *held;
    if (!gather(HomographyOf(corners, n), &pixels)) return false;
    Eigen::Matrix3d G = HomographyOf(corners, n).inverse();
    G /= G(2, 2);
    for (Pixel& p : pixels) p.weight = 1;
    SolveLevels(pixels, T, G, &levels);
    {
      magnitudes.clear();
      float v[6];
      Eigen::Vector2d st;
      double r;
      for (const Pixel& p : pixels) {
        if (residual(T, G, levels, p, v, 2, &st, &r)) magnitudes.push_back(std::abs(r));
      }
      if (magnitudes.empty()) return false;
      std::nth_element(magnitudes.begin(), magnitudes.begin() + magnitudes.size() / 2,
                       magnitudes.end());
      huber_k = o.huber_sigmas * std::max(1e-3, 1.4826 * magnitudes[magnitudes.size() / 2]);
    }
    const int np = shift_only ? 5 : 11;
    double cost = robust_cost(T, G, levels);
    double lambda = 1e-3;
    for (int it = 0; it < max_iterations; ++it) {
      ++out.iterations;
      Eigen::Matrix<double, 11, 11> JtJ = Eigen::Matrix<double, 11, 11>::Zero();
      Eigen::Matrix<double, 11, 1> Jtr = Eigen::Matrix<double, 11, 1>::Zero();
      float v[6];
      Eigen::Vector2d st;
      double r;
      for (Pixel& p : pixels) {
        if (!residual(T, G, levels, p, v, 6, &st, &r)) continue;
        const double a = std::abs(r);
        p.weight = a <= huber_k ? 1.0 : huber_k / a;
        Eigen::Matrix<double, 11, 1> j;
        if (shift_only) {
          // x -> x - d: the cells' coordinates move by -dG/dx d.
          const double ds = levels(1) * v[2] + levels(2) * v[4];
          const double dt = levels(1) * v[3] + levels(2) * v[5];
          const double w = 1.0 / (G(2, 0) * p.x + G(2, 1) * p.y + G(2, 2));
          const double sx = (G(0, 0) - st.x() * G(2, 0)) * w, sy = (G(0, 1) - st.x() * G(2, 1)) * w;
          const double tx = (G(1, 0) - st.y() * G(2, 0)) * w, ty = (G(1, 1) - st.y() * G(2, 1)) * w;
          j(0) = -(ds * sx + dt * tx);
          j(1) = -(ds * sy + dt * ty);
          j(2) = 1;
          j(3) = v[0];
          j(4) = v[1];
        } else {
          j = HomographyRow(G, levels, v, st, p.x, p.y);
        }
        JtJ.topLeftCorner(np, np).selfadjointView<Eigen::Lower>().rankUpdate(j.head(np), p.weight);
        Jtr.head(np) += p.weight * r * j.head(np);
      }
      Eigen::MatrixXd A = JtJ.topLeftCorner(np, np).selfadjointView<Eigen::Lower>();
      const Eigen::VectorXd b = Jtr.head(np);
      bool improved = false;
      for (int tries = 0; tries < 6 && !improved; ++tries) {
        Eigen::MatrixXd D = A;
        D.diagonal() *= 1 + lambda;
        D.diagonal().array() += 1e-12;
        const Eigen::VectorXd step = D.ldlt().solve(b);
        if (!step.allFinite()) return false;
        Eigen::Matrix3d Gm = G;
        Eigen::Vector3d lm = levels;
        if (shift_only) {
          Eigen::Matrix3d shift = Eigen::Matrix3d::Identity();
          shift(0, 2) = -step(0);
          shift(1, 2) = -step(1);
          Gm = G * shift;
          lm += step.tail<3>();
        } else {
          for (int k = 0; k < 8; ++k) Gm(k / 3, k % 3) += step(k);
          lm += step.tail<3>();
        }
        Gm /= Gm(2, 2);
        const double moved_cost = robust_cost(T, Gm, lm);
        if (moved_cost < cost) {
          const std::array<Eigen::Vector2d, 4> before = corners_of(G), after = corners_of(Gm);
          double largest = 0;
          for (int c = 0; c < 4; ++c) largest = std::max(largest, (after[c] - before[c]).norm());
          G = Gm;
          levels = lm;
          cost = moved_cost;
          corners = after;
          lambda = std::max(1e-7, lambda / 4);
          improved = true;
          if (largest < convergence_px) return true;
        } else {
          lambda *= 8;
        }
      }
      if (!improved) return true;  // no step lowers the cost: at the minimum
    }
    return true;
  };

  // The coarse stages need not converge finely: the fine one follows.
  const double coarse_convergence = 0.03;
  if (!fit(o.coarse_blur_px, o.max_iterations, true, coarse_convergence) ||
      !fit(o.coarse_blur_px, o.max_iterations, false, coarse_convergence)) {
    out.failure = "the marker and its surroundings are not inside the image";
    return out;
  }
  // The image's blur at the corners found, then the fit at it.
  double best_blur = o.coarse_blur_px, best_cost = std::numeric_limits<double>::infinity();
  {
    const Eigen::Matrix3d G = HomographyOf(corners, n).inverse();
    for (double blur : o.blur_candidates_px) {
      const std::shared_ptr<Template> T = templates.Get(
          cells, o.quiet_zone_cells, extent, std::sqrt(blur * blur + 1.0 / 12) / (side / n));
      Eigen::Vector3d l;
      const double c = SolveLevels(pixels, *T, G, &l);
      // Levels beyond the codes' range: a blur that mixes the quiet zone
      // with its surroundings to follow their texture.
      if (!Physical(l)) continue;
      if (c < best_cost) best_cost = c, best_blur = blur;
    }
  }
  if (!fit(best_blur, o.max_iterations, false, o.convergence_px)) {
    out.failure = "the marker and its surroundings are not inside the image";
    return out;
  }
  out.blur_sigma_px = best_blur;
  out.corners_px = corners;
  out.pixels = static_cast<int>(pixels.size());

  // Noise and contrast at the corners found; the cheap checks first (a
  // refused fit, most of a frame's misses, skips the rest).
  const double cell_px = side / n;
  const double sigma_cells = std::sqrt(best_blur * best_blur + 1.0 / 12) / cell_px;
  const std::shared_ptr<Template> held =
      templates.Get(cells, o.quiet_zone_cells, extent, sigma_cells);
  held->AddGradients();
  const Template& T = *held;
  const Eigen::Matrix3d G = HomographyOf(corners, n).inverse();
  const double cost = SolveLevels(pixels, T, G, &levels);
  const int dof = static_cast<int>(pixels.size()) - 11;
  if (dof < 10) {
    out.failure = "too few pixels";
    return out;
  }
  out.noise_sigma_grey = std::sqrt(cost / dof);
  out.contrast_grey = levels(1);
  double moved = 0;
  for (int c = 0; c < 4; ++c) moved = std::max(moved, (corners[c] - initial_px[c]).norm());
  if (!(moved <= o.max_shift_fraction * side + o.search_radius_px)) {
    out.failure = "the fit left the start";
  } else if (!Physical(levels)) {
    out.failure = "black and white levels out of the codes' range";
  } else if (!(out.contrast_grey >= o.min_contrast_grey)) {
    out.failure = "too little contrast";
  } else if (!(out.contrast_grey >= o.min_contrast_to_noise * out.noise_sigma_grey)) {
    out.failure = "contrast too low for the residual noise";
  }
  if (!out.failure.empty()) return out;
  // The same marker turned by a quarter, a half, three quarters: its bits,
  // not a dark square (whose turns are alike), must be what fits.
  double turned_cost = std::numeric_limits<double>::infinity();
  for (const int turn : {cv::ROTATE_90_CLOCKWISE, cv::ROTATE_180, cv::ROTATE_90_COUNTERCLOCKWISE}) {
    cv::Mat turned;
    cv::rotate(cells, turned, turn);
    Eigen::Vector3d turned_levels;
    turned_cost = std::min(
        turned_cost,
        SolveLevels(pixels, *templates.Get(turned, o.quiet_zone_cells, extent, sigma_cells), G,
                    &turned_levels));
  }
  out.pattern_gain = turned_cost / std::max(cost, 1e-12);
  if (!(out.pattern_gain >= o.min_pattern_gain)) {
    out.failure = "the pattern does not fit better than the same marker turned";
    return out;
  }
  {
    // The corners' covariance through the inverse homography's.
    Eigen::Matrix3d Gn = G / G(2, 2);
    Eigen::Matrix<double, 11, 11> JtJ = Eigen::Matrix<double, 11, 11>::Zero();
    float v[6];
    for (const Pixel& p : pixels) {
      const Eigen::Vector2d st = Apply(Gn, p.x, p.y);
      if (!T.Sample(st.x(), st.y(), v)) continue;
      const Eigen::Matrix<double, 11, 1> j = HomographyRow(Gn, levels, v, st, p.x, p.y);
      JtJ += p.weight * j * j.transpose();
    }
    const Eigen::Matrix<double, 11, 11> cov_g =
        out.noise_sigma_grey * out.noise_sigma_grey *
        (JtJ + 1e-12 * Eigen::Matrix<double, 11, 11>::Identity()).inverse();
    Eigen::Matrix<double, 8, 8> J_corners;
    const std::array<Eigen::Vector2d, 4> at = corners_of(Gn);
    for (int k = 0; k < 8; ++k) {
      Eigen::Matrix3d Gk = Gn;
      const double eps = 1e-7 * std::max(1.0, std::abs(Gn(k / 3, k % 3)));
      Gk(k / 3, k % 3) += eps;
      const std::array<Eigen::Vector2d, 4> moved_corners = corners_of(Gk);
      for (int c = 0; c < 4; ++c)
        J_corners.block<2, 1>(2 * c, k) = (moved_corners[c] - at[c]) / eps;
    }
    const Eigen::Matrix<double, 8, 8> cov =
        J_corners * cov_g.topLeftCorner<8, 8>() * J_corners.transpose();
    for (int c = 0; c < 4; ++c) {
      const Eigen::Matrix2d block = cov.block<2, 2>(2 * c, 2 * c);
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(block);
      out.corner_sigma_px[c] =
          std::max(o.min_corner_sigma_px, std::sqrt(std::max(0.0, eig.eigenvalues()(1))));
    }
  }
  out.ok = true;
  return out;
}

}  // namespace arpos
