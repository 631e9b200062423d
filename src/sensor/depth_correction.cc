#include "sensor/depth_correction.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <map>
#include <opencv2/core/utility.hpp>
#include <sstream>

#include "util/check.h"
#include "util/string_util.h"

namespace arpos {

namespace {

/// Bilinear weights of (x, y) on the grid: up to 4 (index, weight) pairs.
int GridWeights(const DepthCorrection& c, double x, double y, int* idx, double* w) {
  if (c.nx < 2 || c.ny < 2) return 0;
  const double gx = std::clamp((x - c.x0) / (c.x1 - c.x0) * (c.nx - 1), 0.0, c.nx - 1.0);
  const double gy = std::clamp((y - c.y0) / (c.y1 - c.y0) * (c.ny - 1), 0.0, c.ny - 1.0);
  const int i = std::min(c.nx - 2, static_cast<int>(gx)), j = std::min(c.ny - 2, static_cast<int>(gy));
  const double fx = gx - i, fy = gy - j;
  idx[0] = j * c.nx + i;
  idx[1] = idx[0] + 1;
  idx[2] = idx[0] + c.nx;
  idx[3] = idx[2] + 1;
  w[0] = (1 - fx) * (1 - fy);
  w[1] = fx * (1 - fy);
  w[2] = (1 - fx) * fy;
  w[3] = fx * fy;
  return 4;
}

}  // namespace

double DepthCorrection::Field(double x, double y) const {
  int idx[4];
  double w[4];
  const int n = GridWeights(*this, x, y, idx, w);
  double f = 0;
  for (int k = 0; k < n; ++k) f += w[k] * grid[idx[k]];
  return f;
}

bool DepthCorrection::IsIdentity() const {
  return scale == 0 && std::all_of(grid.begin(), grid.end(), [](double c) { return c == 0; });
}

double DepthCorrection::TrueDepth(double z, double x, double y) const {
  return TrueDepthWithField(z, Field(x, y));
}

double DepthCorrection::TrueDepthWithField(double z, double f) const {
  // z = t (1 + scale) + t^2 f: the root near z.
  const double b = 1 + scale;
  if (std::abs(f) < 1e-12) return z / b;
  const double disc = b * b + 4 * f * z;
  if (disc < 0) return z / b;
  return 2 * z / (b + std::sqrt(disc));  // (-b + sqrt(disc)) / (2 f), without cancellation
}

double DepthCorrection::ErrorAt1mCentreMm() const { return 1000 * (scale + Field(0, 0)); }

std::string DepthCorrection::Describe() const {
  double worst = 0;
  for (double g : grid) worst = std::max(worst, std::abs(scale + g) * 1000);
  return StringPrintf("depth reads %+.2f mm at 1 m in the image centre (scale %+.3f %%), up to %.2f mm "
                      "at 1 m elsewhere in the image",
                      ErrorAt1mCentreMm(), 100 * scale, std::max(worst, std::abs(1000 * scale)));
}

std::string DepthCorrection::Serialize() const {
  std::ostringstream out;
  out << "depth correction:" << StringPrintf(" %.9g %d %d %.9g %.9g %.9g %.9g", scale, nx, ny, x0, x1, y0, y1);
  for (double g : grid) out << StringPrintf(" %.9g", g);
  return out.str();
}

DepthCorrection DepthCorrection::Parse(const std::string& text, const std::string& what) {
  const std::string head = "depth correction:";
  if (text.rfind(head, 0) != 0) {
    ARPOS_INPUT_ERROR(what << ": expected '" << head << " scale nx ny x0 x1 y0 y1 grid...', got '"
                           << text.substr(0, 40) << "'");
  }
  std::istringstream in(text.substr(head.size()));
  DepthCorrection c;
  if (!(in >> c.scale >> c.nx >> c.ny >> c.x0 >> c.x1 >> c.y0 >> c.y1)) {
    ARPOS_INPUT_ERROR(what << ": depth correction header is malformed");
  }
  if (c.nx < 0 || c.ny < 0 || c.nx > 64 || c.ny > 64 || (c.nx * c.ny > 0 && (c.nx < 2 || c.ny < 2)) ||
      (c.nx > 0 && !(c.x1 > c.x0 && c.y1 > c.y0))) {
    ARPOS_INPUT_ERROR(what << ": depth correction grid is malformed");
  }
  c.grid.resize(static_cast<size_t>(c.nx) * c.ny);
  for (double& g : c.grid) {
    if (!(in >> g)) ARPOS_INPUT_ERROR(what << ": depth correction has too few grid values");
  }
  std::string extra;
  if (in >> extra) ARPOS_INPUT_ERROR(what << ": depth correction has too many values");
  if (!std::isfinite(c.scale) || std::any_of(c.grid.begin(), c.grid.end(), [](double v) { return !std::isfinite(v); })) {
    ARPOS_INPUT_ERROR(what << ": depth correction has a non-finite number");
  }
  return c;
}

namespace {

// The shape of a view's own offset over the image (DepthComparison::
// view_offset): a + b x + c y.
Eigen::Vector3d ViewOffsetBasis(const DepthComparison& s) { return {1, s.x, s.y}; }

// Residuals beyond this many sigma (at the noise the fit is made at:
// FitDepthCorrection) are left out of the fit after its first two rounds:
// what stands on a floor seen far away passes the plane's gate, which is a
// few centimetres there (benchmark/accuracy.md).
constexpr double kRejectSigma = 4.0;

// The model fitted to the samples where `use` is set (robust, with the
// priors below), each reading's sigma_m taken as noise_factor times its own.
DepthCorrection FitModel(const std::vector<DepthComparison>& samples, const std::vector<char>& use,
                         const CameraIntrinsics& intrinsics, double noise_factor,
                         bool with_field = true) {
  DepthCorrection c;
  c.nx = 9;
  c.ny = 7;
  c.x0 = (-0.5 - intrinsics.cx) / intrinsics.fx;
  c.x1 = (intrinsics.width - 0.5 - intrinsics.cx) / intrinsics.fx;
  c.y0 = (-0.5 - intrinsics.cy) / intrinsics.fy;
  c.y1 = (intrinsics.height - 0.5 - intrinsics.cy) / intrinsics.fy;
  const int ng = c.nx * c.ny, np = 1 + ng;
  c.grid.assign(ng, 0.0);
  // Priors (1 sigma, field in 1/m = mm at 1 m / 1000): neighbouring nodes
  // differ by ~2 mm at 1 m at most; each node within ~10 mm of zero.
  const double smooth_sigma = 0.002, node_sigma = 0.01;
  Eigen::VectorXd p = Eigen::VectorXd::Zero(np);
  std::vector<double> w(samples.size(), 1.0);
  // Views with an offset of their own (DepthComparison::view_offset): each
  // group's a + b x + c y is eliminated from the normal equations (Schur
  // complement) and recovered for the robust weights. Priors: 5 mm offset,
  // 10 mm per unit of normalised image coordinate.
  struct ViewBlock {
    Eigen::Matrix3d hgg = Eigen::Matrix3d::Zero();
    Eigen::Matrix3d hgg_inverse = Eigen::Matrix3d::Zero();
    Eigen::MatrixXd hgp;
    Eigen::Vector3d bg = Eigen::Vector3d::Zero();
    Eigen::Vector3d value = Eigen::Vector3d::Zero();
  };
  std::map<int, ViewBlock> views;
  const double offset_sigma = 0.005, tilt_sigma = 0.01;
  for (int round = 0; round < 4; ++round) {
    Eigen::MatrixXd ata = Eigen::MatrixXd::Zero(np, np);
    Eigen::VectorXd atb = Eigen::VectorXd::Zero(np);
    views.clear();
    for (size_t i = 0; i < samples.size(); ++i) {
      if (!use[i]) continue;
      const DepthComparison& s = samples[i];
      const double t = s.expected_m;
      int idx[4];
      double gw[4];
      const int n = with_field ? GridWeights(c, s.x, s.y, idx, gw) : 0;
      const double sigma = s.sigma_m * noise_factor;
      const double wi = w[i] / (sigma * sigma);
      const double r = s.measured_m - s.expected_m;
      // Columns: 0 = scale (t), 1 + idx = grid (t^2 gw).
      int cols[5] = {0};
      double a[5] = {t};
      for (int k = 0; k < n; ++k) {
        cols[k + 1] = 1 + idx[k];
        a[k + 1] = t * t * gw[k];
      }
      if (s.view_offset) {
        ViewBlock& v = views[s.group];
        if (v.hgp.size() == 0) {
          v.hgp = Eigen::MatrixXd::Zero(3, np);
          v.hgg.diagonal() << 1 / (offset_sigma * offset_sigma), 1 / (tilt_sigma * tilt_sigma),
              1 / (tilt_sigma * tilt_sigma);
        }
        const Eigen::Vector3d g = ViewOffsetBasis(s);
        v.hgg += wi * g * g.transpose();
        v.bg += wi * g * r;
        for (int u = 0; u <= n; ++u) v.hgp.col(cols[u]) += wi * g * a[u];
      }
      for (int u = 0; u <= n; ++u) {
        atb(cols[u]) += wi * a[u] * r;
        for (int v = 0; v <= n; ++v) ata(cols[u], cols[v]) += wi * a[u] * a[v];
      }
    }
    for (int g = 0; g < ng; ++g) ata(1 + g, 1 + g) += 1.0 / (node_sigma * node_sigma);
    auto smooth = [&](int g1, int g2) {
      const double s2 = 1.0 / (smooth_sigma * smooth_sigma);
      ata(1 + g1, 1 + g1) += s2;
      ata(1 + g2, 1 + g2) += s2;
      ata(1 + g1, 1 + g2) -= s2;
      ata(1 + g2, 1 + g1) -= s2;
    };
    for (int j = 0; j < c.ny; ++j) {
      for (int i = 0; i < c.nx; ++i) {
        if (i + 1 < c.nx) smooth(j * c.nx + i, j * c.nx + i + 1);
        if (j + 1 < c.ny) smooth(j * c.nx + i, (j + 1) * c.nx + i);
      }
    }
    for (auto& [group, v] : views) {
      v.hgg_inverse = v.hgg.inverse();
      ata -= v.hgp.transpose() * v.hgg_inverse * v.hgp;
      atb -= v.hgp.transpose() * v.hgg_inverse * v.bg;
    }
    p = ata.ldlt().solve(atb);
    c.scale = p(0);
    for (int g = 0; g < ng; ++g) c.grid[g] = p(1 + g);
    if (!with_field) std::fill(c.grid.begin(), c.grid.end(), 0.0);
    for (auto& [group, v] : views) v.value = v.hgg_inverse * (v.bg - v.hgp * p);
    // Huber weights at 2 sigma; from the third round none beyond kRejectSigma.
    for (size_t i = 0; i < samples.size(); ++i) {
      if (!use[i]) continue;
      const DepthComparison& s = samples[i];
      double pred = c.scale * s.expected_m + s.expected_m * s.expected_m * c.Field(s.x, s.y);
      if (s.view_offset) pred += views.at(s.group).value.dot(ViewOffsetBasis(s));
      const double r = std::abs(s.measured_m - s.expected_m - pred) / (s.sigma_m * noise_factor);
      w[i] = r <= 2 ? 1.0 : (r <= kRejectSigma || round == 0) ? 2.0 / r : 0.0;
    }
  }
  if (!with_field) {
    c.grid.clear();
    c.nx = c.ny = 0;
  }
  return c;
}

// The fit is made at the noise the recording shows only when that is
// clearly below the sensor model's: the readings' spread holds the
// markers' own pose errors too (depth is weighted down only beyond 1.5x:
// RoomMapBuildOptions::depth_inflation_threshold). Taken at 0.9-1.1x
// (xtion seeds) it changed the correction by nothing that mattered and
// moved the room frame of weak-origin seeds either way (benchmark/accuracy.md).
constexpr double kQuieterThanModel = 1 / 1.5;

// A group's (one marker view's) readings count as at most this many
// independent ones when the support for a correction is weighed.
constexpr double kGroupEffective = 4.0;
// Cross-validated gain (per effective reading) above which a correction is
// kept although it moves the readings' RMS by less than 15 %.
constexpr double kMinCrossValidatedGain = 0.025;

// What one reading counts for: its group's readings count as at most
// kGroupEffective together.
double GroupShare(const DepthComparison& s, const std::map<int, int>& group_size) {
  const int n = s.group < 0 ? 1 : group_size.at(s.group);
  return std::min(1.0, kGroupEffective / n);
}

// Sum over the samples where `use` is set of the squared normalised residual
// after `c`, each weighted by its GroupShare.
double SharedChiSquare(const std::vector<DepthComparison>& samples, const std::vector<char>& use,
                       const std::map<int, int>& group_size, const DepthCorrection& c) {
  double chi = 0;
  for (size_t i = 0; i < samples.size(); ++i) {
    if (!use[i]) continue;
    const DepthComparison& s = samples[i];
    const double r = (c.TrueDepth(s.measured_m, s.x, s.y) - s.expected_m) / s.sigma_m;
    chi += GroupShare(s, group_size) * r * r;
  }
  return chi;
}

}  // namespace

DepthCorrectionFit FitDepthCorrection(const std::vector<DepthComparison>& samples,
                                      const CameraIntrinsics& intrinsics) {
  DepthCorrectionFit out;
  out.samples = static_cast<int>(samples.size());
  // The normalised RMS (the spread of depth around the colour geometry) is
  // taken over the readings whose views have no offset of their own, when
  // there are any: a view's offset over a wide surface is not the camera's.
  const bool any_plain = std::any_of(samples.begin(), samples.end(),
                                     [](const DepthComparison& s) { return !s.view_offset; });
  auto counted = [&](const DepthComparison& s) { return !any_plain || !s.view_offset; };
  double z_min = 1e9, z_max = 0, sum_sq = 0;
  int n_counted = 0;
  for (const DepthComparison& s : samples) {
    z_min = std::min(z_min, s.expected_m);
    z_max = std::max(z_max, s.expected_m);
    if (!counted(s)) continue;
    const double r = (s.measured_m - s.expected_m) / s.sigma_m;
    sum_sq += r * r;
    ++n_counted;
  }
  if (samples.size() < 200 || z_max < 1.3 * z_min) {
    out.message = StringPrintf("depth not checked against the colour geometry (%zu samples, depths %.2f-%.2f m)",
                               samples.size(), z_min, z_max);
    return out;
  }
  out.normalised_rms_before = std::sqrt(sum_sq / n_counted);

  // The readings' noise as this recording shows it: the sensor model's
  // sigma scaled by the robust spread (1.4826 x median) of the readings
  // inside the markers around a first fit at the model's noise; the fit is
  // made again at that noise when it is clearly lower (a sensor quieter
  // than the model, as the simulated l515 is 0.3-0.4x, otherwise lets what
  // stands on a floor far away pass for depth error; benchmark/accuracy.md).
  const std::vector<char> all(samples.size(), 1);
  DepthCorrection c = FitModel(samples, all, intrinsics, 1.0);
  {
    std::vector<double> r;
    for (const DepthComparison& s : samples) {
      if (counted(s)) r.push_back(std::abs(c.TrueDepth(s.measured_m, s.x, s.y) - s.expected_m) / s.sigma_m);
    }
    std::nth_element(r.begin(), r.begin() + r.size() / 2, r.end());
    out.noise_factor = std::clamp(1.4826 * r[r.size() / 2], 0.2, 3.0);
  }
  const double fit_noise = out.noise_factor < kQuieterThanModel ? out.noise_factor : 1.0;
  if (fit_noise != 1.0) c = FitModel(samples, all, intrinsics, fit_noise);
  // Cross-validated: the model fitted to one half of the views (by split)
  // against no correction on the other half, both ways; the gain in
  // squared normalised residual, a view counting as at most a few samples.
  std::map<int, int> group_size;
  for (const DepthComparison& s : samples) ++group_size[s.group];
  std::vector<char> half_a(samples.size()), half_b(samples.size());
  double n_eff = 0;
  for (size_t i = 0; i < samples.size(); ++i) {
    half_a[i] = samples[i].split == 0;
    half_b[i] = !half_a[i];
    n_eff += GroupShare(samples[i], group_size);
  }
  const DepthCorrection none;
  if (std::count(half_a.begin(), half_a.end(), 1) >= 100 && std::count(half_b.begin(), half_b.end(), 1) >= 100) {
    // A model fitted to each half, scored on the other: the summed chi-square.
    auto held_out = [&](const DepthCorrection& fitted_to_a, const DepthCorrection& fitted_to_b) {
      return SharedChiSquare(samples, half_b, group_size, fitted_to_a) +
             SharedChiSquare(samples, half_a, group_size, fitted_to_b);
    };
    const DepthCorrection fit_a = FitModel(samples, half_a, intrinsics, fit_noise);
    const DepthCorrection fit_b = FitModel(samples, half_b, intrinsics, fit_noise);
    const double chi2_none = held_out(none, none);
    const double chi2_full = held_out(fit_a, fit_b);
    out.cross_validated_gain = (chi2_none - chi2_full) / n_eff;
    out.cross_validated = true;
    // The field beyond the scale, cross-validated the same way: a field
    // that does not predict the other half's readings better than the
    // scale alone is left out, and the scale alone is what the gain above
    // then weighs (measured on 19 random-conditions plans: on 7 the
    // field's gain over the scale read -0.195 to 0.012 while its gain over
    // no correction read 0.14-4.1; without it the markers within 1.5 m of
    // the couch came 0.01-2.3 mm nearer the truth on 6 of them and 0.1 mm
    // further on one; the 12 whose field predicted more, 0.03-0.20, or
    // that were not corrected, unchanged).
    const double chi2_scale = held_out(FitModel(samples, half_a, intrinsics, fit_noise, false),
                                       FitModel(samples, half_b, intrinsics, fit_noise, false));
    out.field_gain = (chi2_scale - chi2_full) / n_eff;
    if (!(out.field_gain > kMinCrossValidatedGain)) {
      c = FitModel(samples, all, intrinsics, fit_noise, false);
      out.field_left_out = true;
      out.cross_validated_gain = (chi2_none - chi2_scale) / n_eff;
    }
  }
  sum_sq = 0;
  for (const DepthComparison& s : samples) {
    if (!counted(s)) continue;
    const double r = (c.TrueDepth(s.measured_m, s.x, s.y) - s.expected_m) / s.sigma_m;
    sum_sq += r * r;
  }
  out.normalised_rms_after = std::sqrt(sum_sq / n_counted);
  out.correction = c;
  // Kept when it explains the readings clearly better (their normalised
  // RMS down by 15 %), or when it predicts readings it was not fitted to:
  // on 60-frame random simulated rooms a 2-4 mm field at 1 m moved the RMS
  // by only 6-13 % (each reading's noise is larger at the distances seen),
  // while the cross-validated gain read 0.05-0.14 there and -0.15 to 0.008
  // on the 12 cases without a depth error; the field left in place had biased
  // the body scan's placement by 1-2 mm (benchmark/accuracy.md).
  const bool explains = out.normalised_rms_after < 0.85 * out.normalised_rms_before;
  const bool predicts = out.cross_validated && out.cross_validated_gain > kMinCrossValidatedGain;
  out.applied = (explains || predicts) && std::abs(c.scale) < 0.05;
  // The residual is over the readings it was counted on; the readings on
  // wide surfaces (each view's offset fitted) are named apart.
  const std::string over =
      n_counted < out.samples
          ? StringPrintf("%d readings inside the markers; %d on their planes as well", n_counted,
                         out.samples - n_counted)
          : StringPrintf("%d samples", out.samples);
  out.message =
      out.applied
          ? StringPrintf(
                "%s; removed (depth residual %.2f -> %.2f sigma over %s; "
                "cross-validated gain %.3f%s; the readings' noise %.2fx the sensor model's)",
                c.Describe().c_str(), out.normalised_rms_before, out.normalised_rms_after,
                over.c_str(), out.cross_validated_gain,
                out.field_left_out
                    ? StringPrintf(", a field beyond the scale %.3f: left out", out.field_gain)
                          .c_str()
                    : "",
                out.noise_factor)
          : StringPrintf(
                "depth agrees with the colour geometry (residual %.2f sigma over %s; "
                "a correction would give %.2f, cross-validated gain %.3f): "
                "not corrected",
                out.normalised_rms_before, over.c_str(), out.normalised_rms_after,
                out.cross_validated_gain);
  return out;
}

void CorrectDepthImage(const CameraIntrinsics& intrinsics, const DepthCorrection& correction,
                       cv::Mat* depth) {
  ARPOS_CHECK(depth != nullptr && depth->type() == CV_16UC1, "CorrectDepthImage needs a CV_16UC1 image");
  if (correction.IsIdentity() || depth->empty()) return;
  const double to_m = 1.0 / intrinsics.depth_scale;
  for (int v = 0; v < depth->rows; ++v) {
    uint16_t* row = depth->ptr<uint16_t>(v);
    const double y = (v - intrinsics.cy) / intrinsics.fy;
    for (int u = 0; u < depth->cols; ++u) {
      if (row[u] == 0) continue;
      const double x = (u - intrinsics.cx) / intrinsics.fx;
      const double z = correction.TrueDepth(row[u] * to_m, x, y);
      row[u] = static_cast<uint16_t>(std::clamp(std::lround(z * intrinsics.depth_scale), 1L, 65535L));
    }
  }
}

DepthCorrector::DepthCorrector(const CameraIntrinsics& intrinsics,
                               const DepthCorrection& correction)
    : intrinsics_(intrinsics),
      correction_(correction),
      width_(intrinsics.width),
      height_(intrinsics.height),
      to_m_(1.0 / intrinsics.depth_scale),
      depth_scale_(intrinsics.depth_scale),
      identity_(correction.IsIdentity()) {
  ARPOS_CHECK(width_ > 0 && height_ > 0 && intrinsics.depth_scale > 0,
              "DepthCorrector needs intrinsics with a size and a depth scale");
  if (identity_) return;
  field_.resize(static_cast<size_t>(width_) * height_);
  for (int v = 0; v < height_; ++v) {
    const double y = (v - intrinsics.cy) / intrinsics.fy;
    for (int u = 0; u < width_; ++u) {
      const double x = (u - intrinsics.cx) / intrinsics.fx;
      field_[static_cast<size_t>(v) * width_ + u] = correction.Field(x, y);
    }
  }
}

void DepthCorrector::Apply(cv::Mat* depth) const {
  ARPOS_CHECK(depth != nullptr && depth->type() == CV_16UC1,
              "DepthCorrector needs a CV_16UC1 image");
  if (identity_ || depth->empty()) return;
  if (depth->cols != width_ || depth->rows != height_) {
    CorrectDepthImage(intrinsics_, correction_, depth);  // not this camera's size: as one image
    return;
  }
  cv::parallel_for_(cv::Range(0, height_), [&](const cv::Range& rows) {
    for (int v = rows.start; v < rows.end; ++v) {
      uint16_t* row = depth->ptr<uint16_t>(v);
      const double* field = field_.data() + static_cast<size_t>(v) * width_;
      for (int u = 0; u < width_; ++u) {
        if (row[u] == 0) continue;
        const double t = correction_.TrueDepthWithField(row[u] * to_m_, field[u]);
        row[u] = static_cast<uint16_t>(std::clamp(std::lround(t * depth_scale_), 1L, 65535L));
      }
    }
  });
}

}  // namespace arpos
