#include "features/edge_refinement.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>

#include "features/edge_profile.h"
#include "features/sharpening.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos {

namespace {

using edge_profile::EdgeProfile;
using edge_profile::Profile;

// Parameters of one marker fit: per edge k (dtheta, rho, sigma) at 3k..3k+2,
// then the illumination: black level k0 + kx x + ky y and white level
// w0 + wx x + wy y over the marker (x, y relative to its centre, in units of
// half its size).
constexpr int kEdgeParams = 3;
constexpr int kLevelParams = 6;
constexpr int kNumParams = 4 * kEdgeParams + kLevelParams;
constexpr int kLevelOffset = 4 * kEdgeParams;
constexpr int kLocal = kEdgeParams + kLevelParams;  // non-zeros of one pixel's Jacobian
constexpr double kMinSigma = 0.02;                  // px; a perfectly sharp render has 0

using VecP = Eigen::Matrix<double, kNumParams, 1>;
using MatP = Eigen::Matrix<double, kNumParams, kNumParams>;

/// Line n . p = offset with unit n; signed distance n . p - offset.
struct Line2 {
  Eigen::Vector2d n = Eigen::Vector2d::UnitX();
  double offset = 0;
  double Distance(const Eigen::Vector2d& p) const { return n.dot(p) - offset; }
};

/// Line through a and b with its normal pointing away from `inside_point`.
Line2 LineThrough(const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                  const Eigen::Vector2d& inside_point) {
  Eigen::Vector2d dir = b - a;
  const double len = dir.norm();
  dir = len > 0 ? Eigen::Vector2d(dir / len) : Eigen::Vector2d::UnitX();
  Line2 line;
  line.n = Eigen::Vector2d(dir.y(), -dir.x());
  line.offset = line.n.dot(a);
  if (line.Distance(inside_point) > 0) {
    line.n = -line.n;
    line.offset = -line.offset;
  }
  return line;
}

bool Intersect(const Line2& l1, const Line2& l2, Eigen::Vector2d* p) {
  Eigen::Matrix2d a;
  a.row(0) = l1.n.transpose();
  a.row(1) = l2.n.transpose();
  const double det = a.determinant();
  if (std::abs(det) < 1e-6) return false;
  *p = a.inverse() * Eigen::Vector2d(l1.offset, l2.offset);
  return true;
}

/// Homography mapping the unit square (0,0),(1,0),(1,1),(0,1) onto `quad`.
bool UnitSquareHomography(const std::array<Eigen::Vector2d, 4>& quad, Eigen::Matrix3d* h) {
  static const double kSquare[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  Eigen::Matrix<double, 8, 8> a;
  Eigen::Matrix<double, 8, 1> b;
  for (int i = 0; i < 4; ++i) {
    const double x = kSquare[i][0], y = kSquare[i][1];
    const double u = quad[i].x(), v = quad[i].y();
    a.row(2 * i) << x, y, 1, 0, 0, 0, -u * x, -u * y;
    a.row(2 * i + 1) << 0, 0, 0, x, y, 1, -v * x, -v * y;
    b(2 * i) = u;
    b(2 * i + 1) = v;
  }
  Eigen::FullPivLU<Eigen::Matrix<double, 8, 8>> lu(a);
  if (!lu.isInvertible()) return false;
  const Eigen::Matrix<double, 8, 1> x = lu.solve(b);
  *h << x(0), x(1), x(2), x(3), x(4), x(5), x(6), x(7), 1.0;
  return std::isfinite(h->sum());
}

Eigen::Vector2d ApplyHomography(const Eigen::Matrix3d& h, double x, double y) {
  const Eigen::Vector3d q = h * Eigen::Vector3d(x, y, 1.0);
  return q.head<2>() / q.z();
}

struct BandPixel {
  double qx, qy;  // ideal position minus the edge's reference point
  double mx, my;  // illumination coordinates (see kLevelOffset)
  double grey;
  int segment;
  bool active;
};

struct EdgeGeometry {
  Eigen::Vector2d ref = Eigen::Vector2d::Zero();  // reference point (edge midpoint)
  double theta0 = 0;                              // angle of the outward normal
  double half_len = 1;
};

struct SegmentCheck {
  int count = 0;
  double offset_px = 0;
  double offset_sigma_px = 0;
  double contrast_change = 0;
  bool inlier = true;
};

/// Per-edge constants of one model evaluation pass.
struct EdgeConst {
  double cos_t, sin_t;
  double sigma, s, inv_s;  // blur; s = sqrt(sigma^2 + narrower box variance)
  double half_a, inv_a;    // the wider box
};

/// Model value and the 9 local Jacobian entries (edge's dtheta, rho, sigma,
/// then k0 kx ky w0 wx wy) at one pixel of edge k. `profile_out` gets the
/// step profile value (used by the segment check).
inline double EvaluateModel(const BandPixel& px, const VecP& x, int k, const EdgeConst& ec,
                            double* jac, double* profile_out = nullptr) {
  const double rho = x(kEdgeParams * k + 1);
  const double d = ec.cos_t * px.qx + ec.sin_t * px.qy - rho;
  const Profile pr = EdgeProfile(d, ec.sigma, ec.inv_s, ec.s, ec.half_a, ec.inv_a);
  const double* lv = x.data() + kLevelOffset;
  const double black = lv[0] + lv[1] * px.mx + lv[2] * px.my;
  const double white = lv[3] + lv[4] * px.mx + lv[5] * px.my;
  const double contrast = white - black;
  if (profile_out != nullptr) *profile_out = pr.value;
  if (jac != nullptr) {
    const double g = contrast * pr.d_dist;
    const double along = -ec.sin_t * px.qx + ec.cos_t * px.qy;
    const double c0 = 1.0 - pr.value;
    jac[0] = g * along;
    jac[1] = -g;
    jac[2] = contrast * pr.d_sigma;
    jac[3] = c0;
    jac[4] = c0 * px.mx;
    jac[5] = c0 * px.my;
    jac[6] = pr.value;
    jac[7] = pr.value * px.mx;
    jac[8] = pr.value * px.my;
  }
  return black + contrast * pr.value;
}

/// Gaussian prior on the parameters; inv_sigma 0 = none. Keeps
/// ill-determined parameters (a thin band's blur on a tiny marker) near
/// marker-wide values.
struct Prior {
  VecP mean = VecP::Zero();
  VecP inv_sigma = VecP::Zero();
};

struct FitOutcome {
  bool ok = false;
  double noise_grey = 1.0;
  MatP normal_matrix = MatP::Zero();  // J^T W J + prior at the solution
};

}  // namespace

struct EdgeRefinementWorkspace::Impl {
  cv::Mat unsharpened;  // the image with a sharpening camera's mask undone around the marker
  std::array<std::vector<BandPixel>, 4> bands;
  std::vector<double> scratch;
  std::array<std::vector<SegmentCheck>, 4> segments;
};

EdgeRefinementWorkspace::EdgeRefinementWorkspace() : impl_(new Impl) {}
EdgeRefinementWorkspace::~EdgeRefinementWorkspace() { delete impl_; }

namespace {

using Bands = std::array<std::vector<BandPixel>, 4>;
using Geoms = std::array<EdgeGeometry, 4>;

using EdgeConsts = std::array<EdgeConst, 4>;

EdgeConsts MakeEdgeConsts(const Geoms& geoms, const VecP& x, bool pixel_footprint) {
  EdgeConsts out;
  for (int k = 0; k < 4; ++k) {
    const double theta = geoms[k].theta0 + x(kEdgeParams * k);
    EdgeConst& e = out[k];
    e.cos_t = std::cos(theta);
    e.sin_t = std::sin(theta);
    const double ax = std::abs(e.cos_t), ay = std::abs(e.sin_t);
    // Without the footprint model: a vanishing box, i.e. a plain erf.
    const double box_a = pixel_footprint ? std::max(ax, ay) : 1e-3;
    const double box_b = pixel_footprint ? std::min(ax, ay) : 0.0;
    e.sigma = x(kEdgeParams * k + 2);
    e.s = std::sqrt(e.sigma * e.sigma + box_b * box_b / 12.0);
    e.inv_s = 1.0 / e.s;
    e.half_a = 0.5 * box_a;
    e.inv_a = 1.0 / box_a;
  }
  return out;
}

/// Robust scale (1.4826 MAD around 0) of the active residuals, floored.
double RobustNoise(const Bands& bands, const EdgeConsts& ec, const VecP& x,
                   std::vector<double>* scratch) {
  scratch->clear();
  for (int k = 0; k < 4; ++k) {
    for (const BandPixel& px : bands[k]) {
      if (!px.active) continue;
      scratch->push_back(std::abs(px.grey - EvaluateModel(px, x, k, ec[k], nullptr)));
    }
  }
  if (scratch->empty()) return 1.0;
  auto mid = scratch->begin() + scratch->size() / 2;
  std::nth_element(scratch->begin(), mid, scratch->end());
  return std::max(0.5, 1.4826 * *mid);
}

double HuberCost(double r, double k) {
  const double ar = std::abs(r);
  return ar <= k ? 0.5 * r * r : k * (ar - 0.5 * k);
}

double PriorCost(const VecP& x, const Prior& prior, double noise_sq) {
  return 0.5 * noise_sq * (x - prior.mean).cwiseProduct(prior.inv_sigma).squaredNorm();
}

double TotalCost(const Bands& bands, const EdgeConsts& ec, const VecP& x, const Prior& prior,
                 double huber_k, double noise_sq) {
  double cost = PriorCost(x, prior, noise_sq);
  for (int k = 0; k < 4; ++k) {
    for (const BandPixel& px : bands[k]) {
      if (!px.active) continue;
      cost += HuberCost(px.grey - EvaluateModel(px, x, k, ec[k], nullptr), huber_k);
    }
  }
  return cost;
}

/// Robust Levenberg-Marquardt fit of the four edges' blurred-step models, with
/// shared illumination, to the active pixels.
FitOutcome FitMarkerModel(const Bands& bands, const Geoms& geoms, int max_iterations,
                          double step_tolerance_px, bool pixel_footprint, const Prior& prior,
                          std::vector<double>* scratch, VecP* x) {
  FitOutcome out;
  double lambda = 1e-3;
  double huber_k = 0, noise_sq = 0;
  for (int iter = 0; iter < max_iterations; ++iter) {
    const EdgeConsts ec = MakeEdgeConsts(geoms, *x, pixel_footprint);
    if (iter == 0 || iter == 3) {  // the scale settles once the fit is close
      out.noise_grey = RobustNoise(bands, ec, *x, scratch);
      huber_k = 2.0 * out.noise_grey;
      noise_sq = out.noise_grey * out.noise_grey;
    }
    MatP jtj = MatP::Zero();
    VecP jtr = VecP::Zero();
    double cost = PriorCost(*x, prior, noise_sq);
    int count = 0;
    double jac[kLocal];
    for (int k = 0; k < 4; ++k) {
      // Local normal equations in flat arrays (row a holds columns a..8), so
      // the inner loop is contiguous.
      double h[kLocal * kLocal] = {};
      double g[kLocal] = {};
      for (const BandPixel& px : bands[k]) {
        if (!px.active) continue;
        const double r = px.grey - EvaluateModel(px, *x, k, ec[k], jac);
        const double ar = std::abs(r);
        const double w = ar <= huber_k ? 1.0 : huber_k / ar;
        cost += HuberCost(r, huber_k);
        const double wr = w * r;
        for (int a = 0; a < kLocal; ++a) {
          const double wa = w * jac[a];
          g[a] += wr * jac[a];
          double* row = h + a * kLocal;
          for (int b = a; b < kLocal; ++b) row[b] += wa * jac[b];
        }
        ++count;
      }
      // Scatter the local block (edge k's 3 + 6 shared) into the global system.
      int idx[kLocal];
      for (int i = 0; i < kEdgeParams; ++i) idx[i] = kEdgeParams * k + i;
      for (int i = 0; i < kLevelParams; ++i) idx[kEdgeParams + i] = kLevelOffset + i;
      for (int a = 0; a < kLocal; ++a) {
        jtr(idx[a]) += g[a];
        for (int b = a; b < kLocal; ++b) {
          const double v = h[a * kLocal + b];
          jtj(idx[a], idx[b]) += v;
          if (b != a) jtj(idx[b], idx[a]) += v;
        }
      }
    }
    if (count < kNumParams + 4) return out;
    const VecP prior_precision = noise_sq * prior.inv_sigma.cwiseAbs2();
    jtj.diagonal() += prior_precision;
    jtr += prior_precision.cwiseProduct(prior.mean - *x);
    out.normal_matrix = jtj;

    bool accepted = false;
    VecP step = VecP::Zero();
    for (int attempt = 0; attempt < 6 && !accepted; ++attempt) {
      MatP damped = jtj;
      damped.diagonal() += lambda * jtj.diagonal().cwiseMax(1e-9);
      step = damped.ldlt().solve(jtr);
      if (!step.allFinite()) return out;
      VecP trial = *x + step;
      for (int k = 0; k < 4; ++k) {
        trial(kEdgeParams * k + 2) = std::clamp(trial(kEdgeParams * k + 2), kMinSigma, 6.0);
      }
      const EdgeConsts trial_ec = MakeEdgeConsts(geoms, trial, pixel_footprint);
      if (TotalCost(bands, trial_ec, trial, prior, huber_k, noise_sq) <= cost) {
        *x = trial;
        lambda = std::max(1e-7, lambda * 0.1);
        accepted = true;
      } else {
        lambda *= 10;
      }
    }
    if (!accepted) break;  // at a minimum to within damping
    bool converged = true;
    for (int k = 0; k < 4; ++k) {
      converged = converged && std::abs(step(kEdgeParams * k + 1)) < step_tolerance_px &&
                  std::abs(step(kEdgeParams * k)) * geoms[k].half_len < step_tolerance_px &&
                  std::abs(step(kEdgeParams * k + 2)) < 10 * step_tolerance_px;
    }
    if (converged) break;
  }
  out.ok = true;
  return out;
}

/// Each segment's own line offset and contrast change with everything else
/// held at the fit; marks inconsistent segments of edge k.
void CheckSegments(const std::vector<BandPixel>& pixels, const EdgeConst& ec, const VecP& x, int k,
                   double noise_grey, const EdgeRefinementOptions& options,
                   std::vector<SegmentCheck>* segments) {
  std::vector<SegmentCheck>& seg = *segments;
  const int n = static_cast<int>(seg.size());
  double acc[64][5];  // per segment: 2x2 normal equations (a00, a01, a11) and (g0, g1)
  for (int s = 0; s < n; ++s) {
    seg[s] = SegmentCheck();
    for (double& v : acc[s]) v = 0;
  }
  double jac[kLocal];
  double cdf = 0;
  for (const BandPixel& px : pixels) {
    const double r = px.grey - EvaluateModel(px, x, k, ec, jac, &cdf);
    double* a = acc[px.segment];
    a[0] += jac[1] * jac[1];
    a[1] += jac[1] * cdf;
    a[2] += cdf * cdf;
    a[3] += jac[1] * r;
    a[4] += cdf * r;
    seg[px.segment].count++;
  }
  int max_count = 0;
  for (int s = 0; s < n; ++s) max_count = std::max(max_count, seg[s].count);
  const double contrast = std::max(1e-6, std::abs(x(kLevelOffset + 3) - x(kLevelOffset)));
  for (int s = 0; s < n; ++s) {
    const double* a = acc[s];
    const double det = a[0] * a[2] - a[1] * a[1];
    if (seg[s].count < 4 || seg[s].count < 0.3 * max_count || !(det > 1e-9 * a[0] * a[2])) {
      seg[s].inlier = false;  // missing (image border) or degenerate
      continue;
    }
    seg[s].offset_px = (a[2] * a[3] - a[1] * a[4]) / det;
    seg[s].contrast_change = (-a[1] * a[3] + a[0] * a[4]) / det / contrast;
    seg[s].offset_sigma_px = noise_grey * std::sqrt(a[2] / det);
    const double tol = std::max(options.max_segment_offset_px, 5.0 * seg[s].offset_sigma_px);
    seg[s].inlier = std::abs(seg[s].offset_px) <= tol &&
                    std::abs(seg[s].contrast_change) <= options.max_segment_contrast_change;
  }
}

Line2 FittedLine(const EdgeGeometry& g, double dtheta, double rho) {
  const double theta = g.theta0 + dtheta;
  Line2 l;
  l.n = Eigen::Vector2d(std::cos(theta), std::sin(theta));
  l.offset = l.n.dot(g.ref) + rho;
  return l;
}

Line2 FittedLine(const Geoms& geoms, const VecP& x, int k) {
  return FittedLine(geoms[k], x(kEdgeParams * k), x(kEdgeParams * k + 1));
}

/// Collects the band pixels of edge k of `quad` (ideal coordinates).
void CollectBand(const cv::Mat& gray, const std::array<Eigen::Vector2d, 4>& quad,
                 const Eigen::Matrix3d& square_to_image, int k,
                 const EdgeRefinementOptions& options, const PixelUndistorter& undistorter,
                 const Eigen::Vector2d& level_origin, double level_scale,
                 const std::array<double, 256>& grey_lut, EdgeGeometry* geom,
                 std::vector<BandPixel>* pixels, int* num_segments) {
  pixels->clear();
  const Eigen::Vector2d centre = 0.25 * (quad[0] + quad[1] + quad[2] + quad[3]);
  const Eigen::Vector2d& a = quad[k];
  const Eigen::Vector2d& b = quad[(k + 1) % 4];
  const Line2 edge = LineThrough(a, b, centre);
  const Line2 prev = LineThrough(quad[(k + 3) % 4], quad[k], centre);
  const Line2 next = LineThrough(b, quad[(k + 2) % 4], centre);

  // Inner side of the border cell and outer limit of the quiet zone, both as
  // images of lines parallel to the edge in the marker square.
  static const double kSquare[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  static const double kInward[4][2] = {{0, 1}, {-1, 0}, {0, -1}, {1, 0}};
  const double cells = options.marker_bits + 2.0 * options.border_bits;
  auto square_line = [&](double shift) {
    const int k1 = (k + 1) % 4;
    const Eigen::Vector2d p0 =
        ApplyHomography(square_to_image, kSquare[k][0] + shift * kInward[k][0],
                        kSquare[k][1] + shift * kInward[k][1]);
    const Eigen::Vector2d p1 =
        ApplyHomography(square_to_image, kSquare[k1][0] + shift * kInward[k][0],
                        kSquare[k1][1] + shift * kInward[k][1]);
    Line2 l = LineThrough(p0, p1, centre);
    if (l.n.dot(edge.n) < 0) {  // orient like the edge: positive = outward
      l.n = -l.n;
      l.offset = -l.offset;
    }
    return l;
  };
  const Line2 inner = square_line(options.border_bits / cells);
  const Line2 outer = square_line(-options.quiet_zone_cells / cells);

  geom->ref = 0.5 * (a + b);
  geom->theta0 = std::atan2(edge.n.y(), edge.n.x());
  geom->half_len = std::max(1.0, 0.5 * (b - a).norm());
  const Eigen::Vector2d along(-edge.n.y(), edge.n.x());

  const double r = options.band_half_width_px;
  const double corner_guard = options.corner_guard_px;
  // On tiny markers the border cell (and quiet zone) may be narrower than
  // twice the nominal guard; keep at least half of it as band.
  // Widths (px) of the border cell and quiet zone at the edge's two ends.
  const double cell_px = std::min(inner.Distance(a), inner.Distance(b));
  const double quiet_px = std::min(-outer.Distance(a), -outer.Distance(b));
  const double guard_in =
      std::min(options.inner_guard_px, std::max(options.min_inner_guard_px, 0.5 * cell_px));
  const double guard_out =
      std::min(options.inner_guard_px, std::max(options.min_inner_guard_px, 0.5 * quiet_px));

  // Bounding box in image pixels.
  double x_min = 1e300, x_max = -1e300, y_min = 1e300, y_max = -1e300;
  for (const Eigen::Vector2d& end : {a, b}) {
    for (double s : {-r, r}) {
      Eigen::Vector2d q = end + s * edge.n;
      if (!undistorter.IsIdentity()) q = undistorter.Distort(q);
      x_min = std::min(x_min, q.x());
      x_max = std::max(x_max, q.x());
      y_min = std::min(y_min, q.y());
      y_max = std::max(y_max, q.y());
    }
  }
  const double pad = undistorter.IsIdentity() ? 1.0 : 3.0;
  const int x0 = std::max(0, static_cast<int>(std::floor(x_min - pad)));
  const int x1 = std::min(gray.cols - 1, static_cast<int>(std::ceil(x_max + pad)));
  const int y0 = std::max(0, static_cast<int>(std::floor(y_min - pad)));
  const int y1 = std::min(gray.rows - 1, static_cast<int>(std::ceil(y_max + pad)));

  // Quality segments along the usable length.
  const double t_lo = -geom->half_len + corner_guard;
  const double t_hi = geom->half_len - corner_guard;
  const double usable = std::max(1.0, t_hi - t_lo);
  *num_segments =
      std::clamp(static_cast<int>(std::lround(usable / options.segment_length_px)), 1, 64);
  const double seg_scale = *num_segments / usable;
  const double inv_level_scale = 1.0 / level_scale;
  // Long edges: keep every stride-th pixel on a diagonal lattice ((x + y) mod
  // stride), which still samples every sub-pixel phase of the edge.
  const double expected =
      usable * (std::min(r, cell_px - guard_in) + std::min(r, quiet_px - guard_out));
  const int stride =
      options.max_pixels_per_edge > 0
          ? std::max(1, static_cast<int>(std::ceil(expected / options.max_pixels_per_edge)))
          : 1;

  for (int y = y0; y <= y1; ++y) {
    const uchar* row = gray.ptr<uchar>(y);
    for (int x = x0; x <= x1; ++x) {
      if (stride > 1 && (x + y) % stride != 0) continue;
      Eigen::Vector2d p(x, y);
      if (!undistorter.IsIdentity()) p = undistorter.Undistort(p);
      const double d = edge.Distance(p);
      if (d < -r || d > r) continue;
      if (inner.Distance(p) < guard_in || outer.Distance(p) > -guard_out) continue;
      if (prev.Distance(p) > -corner_guard || next.Distance(p) > -corner_guard) continue;
      const Eigen::Vector2d q = p - geom->ref;
      const double t = along.dot(q);
      BandPixel px;
      px.qx = q.x();
      px.qy = q.y();
      px.mx = (p.x() - level_origin.x()) * inv_level_scale;
      px.my = (p.y() - level_origin.y()) * inv_level_scale;
      px.grey = grey_lut[row[x]];
      px.segment = std::clamp(static_cast<int>((t - t_lo) * seg_scale), 0, *num_segments - 1);
      px.active = true;
      pixels->push_back(px);
    }
  }
}

/// Black and white levels of a marker from its four bands: low and high
/// percentiles of the pixels well inside / outside the edges.
void EstimateLevels(const Bands& bands, const Geoms& geoms, std::vector<double>* scratch,
                    double* black, double* white) {
  for (int side = 0; side < 2; ++side) {
    scratch->clear();
    for (int k = 0; k < 4; ++k) {
      const double c = std::cos(geoms[k].theta0), s = std::sin(geoms[k].theta0);
      for (const BandPixel& px : bands[k]) {
        const double d = c * px.qx + s * px.qy;
        if (side == 0 ? d < -0.5 : d > 0.5) scratch->push_back(px.grey);
      }
    }
    if (scratch->empty()) {
      for (const auto& band : bands) {
        for (const BandPixel& px : band) scratch->push_back(px.grey);
      }
    }
    double& level = side == 0 ? *black : *white;
    if (scratch->empty()) {
      level = side == 0 ? 0.0 : 255.0;
      continue;
    }
    auto it = scratch->begin() + static_cast<long>((side == 0 ? 0.1 : 0.9) * (scratch->size() - 1));
    std::nth_element(scratch->begin(), it, scratch->end());
    level = *it;
  }
}

}  // namespace

std::string EdgeRefinementOptions::Validate() const {
  if (marker_bits < 1 || marker_bits > 16) {
    return StringPrintf("marker_bits must be in 1..16, got %d", marker_bits);
  }
  if (border_bits < 1 || border_bits > 4) {
    return StringPrintf("border_bits must be in 1..4, got %d", border_bits);
  }
  if (!(quiet_zone_cells > 0)) return "quiet_zone_cells must be positive";
  if (!(band_half_width_px >= 1.0 && band_half_width_px <= 10.0)) {
    return StringPrintf("band_half_width_px must be in [1, 10], got %g", band_half_width_px);
  }
  if (!(inner_guard_px >= 0) || !(corner_guard_px >= 0)) return "guards must be non-negative";
  if (!(min_inner_guard_px >= 0 && min_inner_guard_px <= inner_guard_px)) {
    return "min_inner_guard_px must be in [0, inner_guard_px]";
  }
  if (!(level_prior_sigma_grey > 0) || !(blur_prior_sigma_px > 0)) {
    return "prior sigmas must be positive";
  }
  if (!(convergence_px >= 0)) return "convergence_px must be non-negative";
  if (!(fit_step_tolerance_px > 0)) return "fit_step_tolerance_px must be positive";
  if (max_pixels_per_edge < 0) return "max_pixels_per_edge must be non-negative";
  if (outer_iterations < 1 || outer_iterations > 5) return "outer_iterations must be in 1..5";
  if (max_fit_iterations < 1) return "max_fit_iterations must be positive";
  if (!(segment_length_px >= 1.0)) return "segment_length_px must be at least 1";
  if (!(max_segment_offset_px > 0)) return "max_segment_offset_px must be positive";
  if (!(max_segment_contrast_change > 0)) return "max_segment_contrast_change must be positive";
  if (!(min_contrast_grey >= 0) || !(min_contrast_to_noise >= 0)) {
    return "min_contrast_grey and min_contrast_to_noise must be non-negative";
  }
  if (min_pixels_per_edge < kLocal) {
    return StringPrintf("min_pixels_per_edge must be at least %d", kLocal);
  }
  if (!(max_corner_shift_px > 0)) return "max_corner_shift_px must be positive";
  if (!(max_edge_shift_px > 0)) return "max_edge_shift_px must be positive";
  return "";
}

bool EdgeRefinementOptions::Check(std::string* reason) const {
  const std::string r = Validate();
  if (reason != nullptr) *reason = r;
  return r.empty();
}

PixelUndistorter::PixelUndistorter(const CameraIntrinsics& intrinsics)
    : identity_(!intrinsics.HasDistortion()),
      fx_(intrinsics.fx),
      fy_(intrinsics.fy),
      cx_(intrinsics.cx),
      cy_(intrinsics.cy),
      k1_(intrinsics.distortion[0]),
      k2_(intrinsics.distortion[1]),
      p1_(intrinsics.distortion[2]),
      p2_(intrinsics.distortion[3]),
      k3_(intrinsics.distortion[4]) {
  ARPOS_CHECK(identity_ || (fx_ > 0 && fy_ > 0), "intrinsics with distortion need fx, fy > 0");
}

Eigen::Vector2d PixelUndistorter::Distort(const Eigen::Vector2d& ideal_px) const {
  if (identity_) return ideal_px;
  const double x = (ideal_px.x() - cx_) / fx_, y = (ideal_px.y() - cy_) / fy_;
  const double r2 = x * x + y * y;
  const double radial = 1 + r2 * (k1_ + r2 * (k2_ + r2 * k3_));
  const double xd = x * radial + 2 * p1_ * x * y + p2_ * (r2 + 2 * x * x);
  const double yd = y * radial + p1_ * (r2 + 2 * y * y) + 2 * p2_ * x * y;
  return {fx_ * xd + cx_, fy_ * yd + cy_};
}

Eigen::Vector2d PixelUndistorter::Undistort(const Eigen::Vector2d& distorted_px) const {
  if (identity_) return distorted_px;
  const double xd = (distorted_px.x() - cx_) / fx_, yd = (distorted_px.y() - cy_) / fy_;
  // Newton iterations on the forward model (converges in 3-5 steps for
  // realistic lenses, where the fixed-point iteration of cv::undistortPoints
  // needs many more).
  double x = xd, y = yd;
  for (int i = 0; i < 20; ++i) {
    const double r2 = x * x + y * y;
    const double radial = 1 + r2 * (k1_ + r2 * (k2_ + r2 * k3_));
    const double dradial = k1_ + r2 * (2 * k2_ + 3 * k3_ * r2);  // d radial / d r2
    const double fx = x * radial + 2 * p1_ * x * y + p2_ * (r2 + 2 * x * x) - xd;
    const double fy = y * radial + p1_ * (r2 + 2 * y * y) + 2 * p2_ * x * y - yd;
    const double j00 = radial + 2 * x * x * dradial + 2 * p1_ * y + 6 * p2_ * x;
    const double j01 = 2 * x * y * dradial + 2 * p1_ * x + 2 * p2_ * y;
    const double j10 = 2 * x * y * dradial + 2 * p1_ * x + 2 * p2_ * y;
    const double j11 = radial + 2 * y * y * dradial + 6 * p1_ * y + 2 * p2_ * x;
    const double det = j00 * j11 - j01 * j10;
    if (std::abs(det) < 1e-12) break;
    const double dx = (j11 * fx - j01 * fy) / det, dy = (-j10 * fx + j00 * fy) / det;
    x -= dx;
    y -= dy;
    if (std::abs(dx) + std::abs(dy) < 1e-12) break;
  }
  return {fx_ * x + cx_, fy_ * y + cy_};
}

namespace {

CornerRefinementResult Refine(const cv::Mat& gray, const std::array<Eigen::Vector2d, 4>& initial_px,
                              const EdgeRefinementOptions& options, const PixelUndistorter& undistorter,
                              EdgeRefinementWorkspace::Impl& ws);

}  // namespace

CornerRefinementResult RefineMarkerCorners(const cv::Mat& gray,
                                           const std::array<Eigen::Vector2d, 4>& initial_px,
                                           const EdgeRefinementOptions& options,
                                           const PixelUndistorter& undistorter,
                                           EdgeRefinementWorkspace* workspace) {
  ARPOS_CHECK(gray.type() == CV_8UC1,
              "RefineMarkerCorners needs a CV_8UC1 image, got type " << gray.type());
  ARPOS_CHECK(workspace != nullptr, "RefineMarkerCorners needs a workspace");
  std::string reason;
  ARPOS_CHECK(options.Check(&reason), "invalid EdgeRefinementOptions: " << reason);
  EdgeRefinementWorkspace::Impl& ws = workspace->impl();
  if (!options.response.sharpened()) return Refine(gray, initial_px, options, undistorter, ws);
  // A sharpening camera: its mask undone where this marker's fit reads.
  const CameraResponse& r = options.response;
  const cv::Rect region =
      MarkerReadRegion(initial_px, options.marker_bits + 2 * options.border_bits, gray.size());
  UndoSharpening(gray, {region}, r.sharpen_amount(), r.sharpen_sigma_px(), &ws.unsharpened);
  EdgeRefinementOptions plain = options;
  plain.response = r.WithSharpening(0, r.sharpen_sigma_px());
  return Refine(ws.unsharpened, initial_px, plain, undistorter, ws);
}

namespace {

CornerRefinementResult Refine(const cv::Mat& gray, const std::array<Eigen::Vector2d, 4>& initial_px,
                              const EdgeRefinementOptions& options, const PixelUndistorter& undistorter,
                              EdgeRefinementWorkspace::Impl& ws) {
  CornerRefinementResult result;
  result.corners_px = initial_px;
  auto fail = [&](const std::string& why) {
    result.status = MarkerStatus::kRefinementFailed;
    result.corners_px = initial_px;
    result.failure = why;
    return result;
  };

  // Starting lines: through the detected corners, moved outward by the
  // contour-convention offset, intersected into a starting quadrilateral.
  std::array<Eigen::Vector2d, 4> quad;
  for (int i = 0; i < 4; ++i) {
    if (!initial_px[i].allFinite()) return fail("non-finite initial corner");
    quad[i] = undistorter.Undistort(initial_px[i]);
  }
  {
    const Eigen::Vector2d centre = 0.25 * (quad[0] + quad[1] + quad[2] + quad[3]);
    std::array<Line2, 4> lines;
    for (int k = 0; k < 4; ++k) {
      lines[k] = LineThrough(quad[k], quad[(k + 1) % 4], centre);
      lines[k].offset += options.initial_outward_shift_px;
    }
    for (int k = 0; k < 4; ++k) {
      if (!Intersect(lines[(k + 3) % 4], lines[k], &quad[k])) {
        return fail("degenerate initial quadrilateral");
      }
    }
  }
  double perimeter = 0;
  for (int k = 0; k < 4; ++k) perimeter += (quad[(k + 1) % 4] - quad[k]).norm();
  const Eigen::Vector2d level_origin = 0.25 * (quad[0] + quad[1] + quad[2] + quad[3]);
  const double level_scale = std::max(1.0, perimeter / 8);  // half a side

  VecP x = VecP::Zero();
  Prior prior;
  Geoms geoms;
  std::array<int, 4> num_segments{{1, 1, 1, 1}};
  FitOutcome fit;
  for (int pass = 0; pass < options.outer_iterations; ++pass) {
    Eigen::Matrix3d square_to_image;
    if (!UnitSquareHomography(quad, &square_to_image)) return fail("degenerate quadrilateral");
    const Geoms previous = geoms;
    for (int k = 0; k < 4; ++k) {
      CollectBand(gray, quad, square_to_image, k, options, undistorter, level_origin, level_scale,
                  options.response.linear_from_code(), &geoms[k], &ws.bands[k], &num_segments[k]);
      if (static_cast<int>(ws.bands[k].size()) < options.min_pixels_per_edge) {
        return fail(StringPrintf("edge %d: only %d pixels in its band", k,
                                 static_cast<int>(ws.bands[k].size())));
      }
      ws.segments[k].resize(num_segments[k]);
    }
    if (pass == 0) {
      // Weak priors: blur ~0.6 px, levels from the bands' percentiles, no shading.
      double black = 0, white = 255;
      EstimateLevels(ws.bands, geoms, &ws.scratch, &black, &white);
      const double sigma0 = options.model_pixel_footprint ? 0.6 : 0.75;
      for (int k = 0; k < 4; ++k) {
        x(kEdgeParams * k + 2) = sigma0;
        prior.inv_sigma(kEdgeParams * k + 2) = 1.0 / 0.5;
      }
      x(kLevelOffset) = black;
      x(kLevelOffset + 3) = white;
      prior.mean = x;
      for (int i = 0; i < kLevelParams; ++i) {
        prior.inv_sigma(kLevelOffset + i) = 1.0 / options.level_prior_sigma_grey;
      }
    } else {
      // The new bands are centred on the previous lines.
      std::array<double, 4> sigmas;
      for (int k = 0; k < 4; ++k) {
        const double old_theta = previous[k].theta0 + x(kEdgeParams * k);
        x(kEdgeParams * k) = std::remainder(old_theta - geoms[k].theta0, 2 * M_PI);
        x(kEdgeParams * k + 1) = 0;
        sigmas[k] = x(kEdgeParams * k + 2);
      }
      // Blur prior: the marker's median edge blur.
      std::sort(sigmas.begin(), sigmas.end());
      for (int k = 0; k < 4; ++k) {
        prior.mean(kEdgeParams * k + 2) = 0.5 * (sigmas[1] + sigmas[2]);
        prior.inv_sigma(kEdgeParams * k + 2) = 1.0 / options.blur_prior_sigma_px;
      }
    }

    // Fit, drop inconsistent segments, refit.
    for (int round = 0;; ++round) {
      fit =
          FitMarkerModel(ws.bands, geoms, options.max_fit_iterations, options.fit_step_tolerance_px,
                         options.model_pixel_footprint, prior, &ws.scratch, &x);
      if (!fit.ok) return fail("edge fit did not converge");
      const EdgeConsts ec = MakeEdgeConsts(geoms, x, options.model_pixel_footprint);
      bool changed = false;
      for (int k = 0; k < 4; ++k) {
        CheckSegments(ws.bands[k], ec[k], x, k, fit.noise_grey, options, &ws.segments[k]);
        if (round == 3) continue;
        for (BandPixel& px : ws.bands[k]) {
          const bool inlier = ws.segments[k][px.segment].inlier;
          changed = changed || px.active != inlier;
          px.active = inlier;
        }
      }
      if (!changed || round == 3) break;
    }

    const double contrast = x(kLevelOffset + 3) - x(kLevelOffset);
    for (int k = 0; k < 4; ++k) {
      int inliers = 0;
      for (const SegmentCheck& s : ws.segments[k]) inliers += s.inlier ? 1 : 0;
      const double sigma = x(kEdgeParams * k + 2);
      if (2 * inliers < num_segments[k] || inliers == 0) {
        return fail(StringPrintf("edge %d: only %d of %d segments lie on a line", k, inliers,
                                 num_segments[k]));
      }
      if (!(sigma < 5.0)) {
        return fail(StringPrintf("edge %d: implausible blur %.2f px", k, sigma));
      }
      if (std::abs(x(kEdgeParams * k + 1)) > options.band_half_width_px) {
        return fail(StringPrintf("edge %d moved out of its band", k));
      }
    }
    if (contrast <
        std::max(options.min_contrast_grey, options.min_contrast_to_noise * fit.noise_grey)) {
      return fail(StringPrintf("contrast %.1f grey levels is too low (noise %.2f)", contrast,
                               fit.noise_grey));
    }

    double moved = 0;
    for (int k = 0; k < 4; ++k) {
      Eigen::Vector2d corner;
      if (!Intersect(FittedLine(geoms, x, (k + 3) % 4), FittedLine(geoms, x, k), &corner)) {
        return fail("adjacent edges are parallel");
      }
      moved = std::max(moved, (corner - quad[k]).norm());
      quad[k] = corner;
    }
    if (pass > 0 && moved < options.convergence_px) break;
  }

  // Corners back to image pixels, plausibility, uncertainty.
  double initial_perimeter = 0;
  for (int k = 0; k < 4; ++k) {
    initial_perimeter += (initial_px[(k + 1) % 4] - initial_px[k]).norm();
  }
  const double max_shift = std::max(options.max_corner_shift_px,
                                    options.max_corner_shift_fraction * initial_perimeter / 4);
  for (int k = 0; k < 4; ++k) {
    const Line2 line = FittedLine(geoms, x, k);
    const Eigen::Vector2d a = undistorter.Undistort(initial_px[k]);
    const Eigen::Vector2d b = undistorter.Undistort(initial_px[(k + 1) % 4]);
    for (double f : {0.25, 0.75}) {
      const double shift = std::abs(line.Distance(a + f * (b - a)));
      if (!(shift <= options.max_edge_shift_px)) {
        return fail(StringPrintf("edge %d moved %.2f px from its detection", k, shift));
      }
    }
  }
  const MatP cov =
      fit.normal_matrix.ldlt().solve(MatP::Identity()) * (fit.noise_grey * fit.noise_grey);
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector2d corner = undistorter.Distort(quad[k]);
    if (!corner.allFinite() || (corner - initial_px[k]).norm() > max_shift) {
      return fail(StringPrintf("corner %d moved %.2f px from its detection", k,
                               (corner - initial_px[k]).norm()));
    }
    result.corners_px[k] = corner;
    // Propagate the two lines' (dtheta, rho) covariance by finite differences.
    const int e1 = (k + 3) % 4, e2 = k;
    const int idx[4] = {kEdgeParams * e1, kEdgeParams * e1 + 1, kEdgeParams * e2,
                        kEdgeParams * e2 + 1};
    Eigen::Matrix<double, 2, 4> jac;
    constexpr double kEps = 1e-6;
    for (int j = 0; j < 4; ++j) {
      VecP xp = x;
      xp(idx[j]) += kEps;
      Eigen::Vector2d moved;
      if (!Intersect(FittedLine(geoms, xp, e1), FittedLine(geoms, xp, e2), &moved)) moved = quad[k];
      jac.col(j) = (moved - quad[k]) / kEps;
    }
    Eigen::Matrix4d block;
    for (int i = 0; i < 4; ++i) {
      for (int j = 0; j < 4; ++j) block(i, j) = cov(idx[i], idx[j]);
    }
    const Eigen::Matrix2d corner_cov = jac * block * jac.transpose();
    const double var = 0.5 * corner_cov.trace();
    result.corner_sigma_px[k] = std::isfinite(var) ? std::sqrt(std::max(0.0, var)) : 0.0;
  }

  int segments = 0, inliers = 0;
  double sum_sq = 0;
  const double contrast = x(kLevelOffset + 3) - x(kLevelOffset);
  for (int k = 0; k < 4; ++k) {
    EdgeFit& rep = result.edges[k];
    rep.ok = true;
    const Line2 line = FittedLine(geoms, x, k);
    rep.normal = line.n;
    rep.point_px = geoms[k].ref + x(kEdgeParams * k + 1) * line.n;
    rep.contrast_grey = contrast;
    rep.blur_sigma_px = x(kEdgeParams * k + 2);
    rep.noise_sigma_grey = fit.noise_grey;
    rep.num_pixels = static_cast<int>(ws.bands[k].size());
    rep.num_segments = num_segments[k];
    double edge_sq = 0;
    for (const SegmentCheck& s : ws.segments[k]) {
      rep.max_segment_offset_px = std::max(rep.max_segment_offset_px, std::abs(s.offset_px));
      if (!s.inlier) continue;
      ++rep.num_inlier_segments;
      edge_sq += s.offset_px * s.offset_px;
    }
    rep.segment_offset_rms_px =
        rep.num_inlier_segments > 0 ? std::sqrt(edge_sq / rep.num_inlier_segments) : 0;
    segments += rep.num_segments;
    inliers += rep.num_inlier_segments;
    sum_sq += edge_sq;
    result.max_segment_offset_px =
        std::max(result.max_segment_offset_px, rep.max_segment_offset_px);
    result.blur_sigma_px += 0.25 * rep.blur_sigma_px;
  }
  result.contrast_grey = contrast;
  result.noise_sigma_grey = fit.noise_grey;
  result.edge_fit_rms_px = inliers > 0 ? std::sqrt(sum_sq / inliers) : 0;
  result.edge_inlier_fraction = segments > 0 ? static_cast<double>(inliers) / segments : 0;
  result.status = inliers == segments ? MarkerStatus::kRefined : MarkerStatus::kPartiallyOccluded;
  return result;
}

}  // namespace

CornerRefinementResult RefineMarkerCorners(const cv::Mat& gray,
                                           const std::array<Eigen::Vector2d, 4>& initial_px,
                                           const EdgeRefinementOptions& options) {
  EdgeRefinementWorkspace workspace;
  return RefineMarkerCorners(gray, initial_px, options, PixelUndistorter(), &workspace);
}

void ApplyRefinement(const CornerRefinementResult& r, MarkerObservation* obs) {
  obs->status = r.status;
  obs->corners_px = r.corners_px;
  obs->corner_sigma_px = r.corner_sigma_px;
  obs->edge_fit_rms_px = r.edge_fit_rms_px;
  obs->max_segment_offset_px = r.max_segment_offset_px;
  obs->edge_inlier_fraction = r.edge_inlier_fraction;
  obs->contrast_grey = r.contrast_grey;
  obs->blur_sigma_px = r.blur_sigma_px;
  obs->noise_sigma_grey = r.noise_sigma_grey;
}

}  // namespace arpos
