#include "features/sharpening.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include <opencv2/imgproc.hpp>

#include "util/check.h"
#include "util/string_util.h"

namespace arpos {
namespace {

// Iterations for the fixed point to settle within ~0.3 % of the halo.
int Iterations(double amount) {
  const double factor = amount / (1 + amount);
  return std::clamp(static_cast<int>(std::ceil(std::log(0.003) / std::log(factor))), 1, 40);
}

// The codes before the mask inside `outer` (float, `outer`'s size).
cv::Mat UndoInside(const cv::Mat& delivered, const cv::Rect& outer, double amount, double sigma_px) {
  cv::Mat s;
  delivered(outer).convertTo(s, CV_32F);
  cv::Mat e = s.clone(), blurred;
  const int n = Iterations(amount);
  const double w = 1.0 / (1 + amount);
  for (int k = 0; k < n; ++k) {
    cv::GaussianBlur(e, blurred, cv::Size(0, 0), sigma_px, sigma_px, cv::BORDER_REPLICATE);
    cv::addWeighted(s, w, blurred, amount * w, 0.0, e);
  }
  return e;
}

cv::Rect Grown(const cv::Rect& r, int margin, const cv::Size& size) {
  const cv::Rect g(r.x - margin, r.y - margin, r.width + 2 * margin, r.height + 2 * margin);
  return g & cv::Rect(0, 0, size.width, size.height);
}

// One outer edge's pixels: offset in the marker's patch and signed distance
// to the edge line (positive towards the white quiet zone).
struct EdgeSamples {
  std::vector<int> index;
  std::vector<float> distance_px;
};

struct MarkerPatch {
  const cv::Mat* gray = nullptr;
  cv::Rect outer;  // read and undone
  std::vector<EdgeSamples> edges;
};

// Pooled normalised profile of every edge under one candidate.
struct Pooled {
  std::vector<double> sum, sum2;
  std::vector<int> count;
  int edges = 0;
};

struct ProfileFigures {
  double overshoot = 0;   // sum of the profile's decreases (fraction of contrast)
  double tolerance = 0;   // what noise alone makes of it
  bool valid = false;
};

ProfileFigures Figures(const Pooled& p, int min_count) {
  ProfileFigures f;
  std::vector<double> mean, se;
  for (size_t i = 0; i < p.sum.size(); ++i) {
    if (p.count[i] < min_count) continue;
    const double m = p.sum[i] / p.count[i];
    const double var = std::max(0.0, p.sum2[i] / p.count[i] - m * m);
    mean.push_back(m);
    se.push_back(std::sqrt(var / p.count[i]));
  }
  if (mean.size() < 8) return f;
  for (size_t i = 0; i + 1 < mean.size(); ++i) {
    const double step = mean[i + 1] - mean[i];
    if (step < 0) f.overshoot -= step;
    // What noise alone gives a step of this size: E[max(0, -step)] for a
    // step of zero mean is 0.4 of its sigma, and fades on the rising part.
    const double s = std::hypot(se[i], se[i + 1]);
    if (s > 0) f.tolerance += 0.4 * s * std::exp(-0.5 * step * step / (s * s));
  }
  f.tolerance += 0.002;
  f.valid = true;
  return f;
}

}  // namespace

void UndoSharpening(const cv::Mat& delivered, const std::vector<cv::Rect>& regions, double amount,
                    double sigma_px, cv::Mat* out) {
  ARPOS_CHECK(out != nullptr && out != &delivered, "UndoSharpening needs a separate output image");
  ARPOS_CHECK(delivered.type() == CV_8UC1, "UndoSharpening needs an 8-bit grey image");
  delivered.copyTo(*out);
  if (!(amount > 0)) return;
  const int margin = static_cast<int>(std::ceil(4 * sigma_px)) + 2;
  for (const cv::Rect& region : regions) {
    const cv::Rect inner = region & cv::Rect(0, 0, delivered.cols, delivered.rows);
    if (inner.area() == 0) continue;
    const cv::Rect outer = Grown(inner, margin, delivered.size());
    const cv::Mat e = UndoInside(delivered, outer, amount, sigma_px);
    const cv::Rect local(inner.x - outer.x, inner.y - outer.y, inner.width, inner.height);
    e(local).convertTo((*out)(inner), CV_8U);  // rounds and saturates
  }
}

cv::Rect MarkerReadRegion(const std::array<Eigen::Vector2d, 4>& corners_px, int cells_per_side,
                          const cv::Size& image_size) {
  double x0 = corners_px[0].x(), x1 = x0, y0 = corners_px[0].y(), y1 = y0, side = 0;
  for (int k = 0; k < 4; ++k) {
    x0 = std::min(x0, corners_px[k].x());
    x1 = std::max(x1, corners_px[k].x());
    y0 = std::min(y0, corners_px[k].y());
    y1 = std::max(y1, corners_px[k].y());
    side = std::max(side, (corners_px[(k + 1) % 4] - corners_px[k]).norm());
  }
  if (!std::isfinite(x0 + x1 + y0 + y1 + side)) return {};
  const double grow = 1.5 * side / std::max(1, cells_per_side) + 4;
  const int left = static_cast<int>(std::floor(x0 - grow)), top = static_cast<int>(std::floor(y0 - grow));
  const int right = static_cast<int>(std::ceil(x1 + grow)), bottom = static_cast<int>(std::ceil(y1 + grow));
  return cv::Rect(left, top, right - left + 1, bottom - top + 1) &
         cv::Rect(0, 0, image_size.width, image_size.height);
}

std::string SharpeningEstimationOptions::Validate() const {
  std::ostringstream out;
  if (!(amount_step > 0) || !(max_amount >= 0) || max_amount > 5) {
    out << "sharpening amounts must be positive steps up to at most 5";
  } else if (!(sigma_px >= 0.3 && sigma_px <= 5)) {
    out << "the sharpening radius must be within [0.3, 5] px";
  } else if (!(profile_half_width_px > 0) || !(bin_px > 0) || min_edges < 1 ||
             max_markers < 1 || !(min_profile_half_width_px > 0 && min_profile_half_width_px <= profile_half_width_px)) {
    out << "sharpening profile settings must be positive";
  } else if (!(min_overshoot >= 0 && min_overshoot < 1)) {
    out << "min_overshoot must be within [0, 1)";
  } else if (clip_codes < 0 || clip_codes > 50 ||
             !(max_clipped_fraction >= 0 && max_clipped_fraction <= 1)) {
    out << "clip_codes must be within [0, 50] and max_clipped_fraction within [0, 1]";
  }
  return out.str();
}

double MarkerCellWidthPx(const MarkerObservation& marker, int cells_per_side) {
  double shortest = 1e9;
  for (int k = 0; k < 4; ++k) {
    shortest = std::min(shortest, (marker.corners_px[(k + 1) % 4] - marker.corners_px[k]).norm());
  }
  return shortest / std::max(1, cells_per_side);
}

int SharpeningViewsNeeded(const SharpeningEstimationOptions& options) { return (options.min_edges + 3) / 4; }

double SharpeningCellNeededPx(const SharpeningEstimationOptions& options) {
  return options.min_profile_half_width_px / 0.6;
}

SharpeningEstimate EstimateSharpening(const std::vector<const cv::Mat*>& grays,
                                      const std::vector<const std::vector<MarkerObservation>*>& markers,
                                      int cells_per_side, const SharpeningEstimationOptions& options) {
  const std::string bad = options.Validate();
  ARPOS_CHECK(bad.empty(), "invalid sharpening options: " << bad);
  ARPOS_CHECK(grays.size() == markers.size(), "one marker list per image");
  SharpeningEstimate out;
  double reach = options.profile_half_width_px;
  const int margin = static_cast<int>(std::ceil(4 * options.sigma_px)) + 2;

  // The edges' pixels, once (largest cells first, at most max_markers).
  struct Candidate {
    size_t frame;
    const MarkerObservation* marker;
    double cell_px;
  };
  // The pixels across the middle of each of a marker's outer edges within
  // `half_width` (indices into `outer`); `clipped` counts the edges left out
  // because their halo is clipped at black or white: it cannot be undone,
  // and what is left of it is not the mask's shape (a linear camera whose
  // black reads 0: amount 2.3 found for a true 0.8).
  const auto edges_of = [&](const cv::Mat& gray, const MarkerObservation& m, const cv::Rect& outer,
                            double half_width, int* clipped) {
    std::vector<EdgeSamples> edges;
    const auto& q = m.corners_px;
    const cv::Rect read = MarkerReadRegion(q, cells_per_side, gray.size());
    const Eigen::Vector2d centre = 0.25 * (q[0] + q[1] + q[2] + q[3]);
    for (int k = 0; k < 4; ++k) {
      const Eigen::Vector2d a = q[k], b = q[(k + 1) % 4];
      const double length = (b - a).norm();
      if (!(length > 4)) continue;
      const Eigen::Vector2d along = (b - a) / length;
      Eigen::Vector2d normal(-along.y(), along.x());
      if (normal.dot(a - centre) < 0) normal = -normal;  // outwards, to the quiet zone
      EdgeSamples edge;
      int at_limit = 0;
      for (int y = read.y; y < read.y + read.height; ++y) {
        for (int x = read.x; x < read.x + read.width; ++x) {
          const Eigen::Vector2d p(x - a.x(), y - a.y());
          const double t = p.dot(along) / length;
          if (t < 0.2 || t > 0.8) continue;
          const double d = p.dot(normal);
          if (std::abs(d) >= half_width) continue;
          edge.index.push_back((y - outer.y) * outer.width + (x - outer.x));
          edge.distance_px.push_back(static_cast<float>(d));
          const int code = gray.at<std::uint8_t>(y, x);
          at_limit += code <= options.clip_codes || code >= 255 - options.clip_codes ? 1 : 0;
        }
      }
      if (at_limit > options.max_clipped_fraction * static_cast<double>(edge.index.size())) {
        ++*clipped;
        continue;
      }
      if (edge.index.size() >= 40) edges.push_back(std::move(edge));
    }
    return edges;
  };

  std::vector<Candidate> candidates;
  int clipped_views = 0;
  for (size_t f = 0; f < grays.size(); ++f) {
    if (grays[f] == nullptr || grays[f]->type() != CV_8UC1 || markers[f] == nullptr) continue;
    for (const MarkerObservation& m : *markers[f]) {
      if (m.status != MarkerStatus::kRefined) continue;
      const double cell = MarkerCellWidthPx(m, cells_per_side);
      if (!(cell > 0)) continue;
      // A view with a clipped edge at the reach it could have is not used.
      int clipped = 0;
      const cv::Rect read = MarkerReadRegion(m.corners_px, cells_per_side, grays[f]->size());
      if (read.area() == 0) continue;
      edges_of(*grays[f], m, read, std::min(reach, 0.6 * cell), &clipped);
      if (clipped > 0) {
        ++clipped_views;
        continue;
      }
      candidates.push_back({f, &m, cell});
    }
  }
  std::sort(candidates.begin(), candidates.end(),
            [](const Candidate& a, const Candidate& b) { return a.cell_px > b.cell_px; });
  // One reach for all (pooled profiles must be alike): the widest that
  // enough markers' quiet zones hold, within 0.6 of a cell.
  const size_t enough = static_cast<size_t>(SharpeningViewsNeeded(options));
  if (candidates.size() >= enough) reach = std::min(reach, 0.6 * candidates[enough - 1].cell_px);
  const double needed_cell_px = SharpeningCellNeededPx(options);
  const long wide_enough = std::count_if(candidates.begin(), candidates.end(),
                                         [&](const Candidate& c) { return c.cell_px >= needed_cell_px - 1e-9; });
  if (candidates.size() < enough || reach < options.min_profile_half_width_px) {  // halos would not fade inside
    out.message = StringPrintf(
        "camera sharpening not estimated (%ld marker view(s) with cells of at least %.1f px, %zu "
        "needed%s)",
        wide_enough, needed_cell_px, enough,
        clipped_views > 0
            ? StringPrintf("; %d other view(s) left out: their edges are clipped at black or white",
                           clipped_views)
                  .c_str()
            : "");
    return out;
  }
  while (!candidates.empty() && 0.6 * candidates.back().cell_px < reach - 1e-9) candidates.pop_back();
  if (static_cast<int>(candidates.size()) > options.max_markers) candidates.resize(options.max_markers);

  std::vector<MarkerPatch> patches;
  int clipped_edges = 0;
  for (const Candidate& c : candidates) {
    const cv::Mat& gray = *grays[c.frame];
    const cv::Rect read = MarkerReadRegion(c.marker->corners_px, cells_per_side, gray.size());
    if (read.area() == 0) continue;
    MarkerPatch patch;
    patch.gray = &gray;
    patch.outer = Grown(read, margin, gray.size());
    patch.edges = edges_of(gray, *c.marker, patch.outer, reach, &clipped_edges);
    if (!patch.edges.empty() && patch.outer.width > 0 && patch.outer.height > 0) patches.push_back(std::move(patch));
  }

  const int bins = static_cast<int>(std::ceil(2 * reach / options.bin_px));
  auto pool = [&](double amount) {
    Pooled p;
    p.sum.assign(bins, 0);
    p.sum2.assign(bins, 0);
    p.count.assign(bins, 0);
    for (const MarkerPatch& patch : patches) {
      cv::Mat e;
      if (amount > 0) {
        e = UndoInside(*patch.gray, patch.outer, amount, options.sigma_px);
      } else {
        (*patch.gray)(patch.outer).convertTo(e, CV_32F);
      }
      if (!e.isContinuous()) e = e.clone();
      const float* v = e.ptr<float>(0);
      for (const EdgeSamples& edge : patch.edges) {
        // The edge's own black and white: the outer pixel of each side.
        double black = 0, white = 0;
        int nb = 0, nw = 0;
        for (size_t i = 0; i < edge.index.size(); ++i) {
          const float d = edge.distance_px[i];
          if (d <= -reach + 1.0) black += v[edge.index[i]], ++nb;
          if (d >= reach - 1.0) white += v[edge.index[i]], ++nw;
        }
        if (nb < 5 || nw < 5) continue;
        black /= nb;
        white /= nw;
        const double contrast = white - black;
        if (!(contrast >= options.min_contrast_codes)) continue;
        for (size_t i = 0; i < edge.index.size(); ++i) {
          const int b = std::clamp(static_cast<int>((edge.distance_px[i] + reach) / options.bin_px), 0, bins - 1);
          const double n = (v[edge.index[i]] - black) / contrast;
          p.sum[b] += n;
          p.sum2[b] += n * n;
          ++p.count[b];
        }
        ++p.edges;
      }
    }
    return p;
  };

  const Pooled delivered = pool(0);
  out.edges_used = delivered.edges;
  out.profile_half_width_px = reach;
  const int min_count = 20;
  const ProfileFigures base = Figures(delivered, min_count);
  if (delivered.edges < options.min_edges || !base.valid) {
    out.message = StringPrintf(
        "camera sharpening not estimated (%ld marker view(s) with cells of at least %.1f px, "
        "%d usable edges of %d needed%s)",
        wide_enough, needed_cell_px, delivered.edges, options.min_edges,
        clipped_views + clipped_edges > 0
            ? StringPrintf("; %d view(s) and %d edge(s) left out: clipped at black or white",
                           clipped_views, clipped_edges)
                  .c_str()
            : "");
    return out;
  }
  out.ok = true;
  out.overshoot_delivered = base.overshoot;
  out.overshoot_after = base.overshoot;
  if (base.overshoot > std::max(2 * base.tolerance, options.min_overshoot)) {
    // The least amount whose undone profile is monotone within its noise
    // (more only blurs).
    for (double amount = options.amount_step; amount <= options.max_amount + 1e-9; amount += options.amount_step) {
      const ProfileFigures f = Figures(pool(amount), min_count);
      if (!f.valid || f.overshoot > f.tolerance) continue;
      out.amount = amount;
      out.overshoot_after = f.overshoot;
      break;
    }
    if (out.amount == 0) {
      out.ok = false;
      out.message = StringPrintf(
          "camera sharpening not estimated (the edges overshoot by %.1f %% of their contrast, but no amount up to "
          "%.1f undoes it)",
          100 * base.overshoot, options.max_amount);
      return out;
    }
  }
  out.sigma_px = options.sigma_px;
  if (out.amount > 0) {
    out.message = StringPrintf(
        "camera sharpening estimated from %d marker edges (profiles +-%.1f px): amount %.1f, radius %.1f px "
        "(overshoot %.1f %% of the edges' contrast as delivered, %.1f %% undone)",
        delivered.edges, reach, out.amount, out.sigma_px, 100 * out.overshoot_delivered, 100 * out.overshoot_after);
  } else {
    out.message = StringPrintf(
        "no camera sharpening (overshoot %.1f %% of the edges' contrast over %d marker edges, profiles +-%.1f px)",
        100 * out.overshoot_delivered, delivered.edges, reach);
  }
  return out;
}

}  // namespace arpos
