#include "body_model/layout_scale.h"

#include <opencv2/calib3d.hpp>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>

#include "features/marker_pose.h"
#include "util/string_util.h"

namespace arpos {
namespace {

// The positions `position(item)` of `items` scaled by `scale` about their
// centroid.
template <typename Items, typename Position>
void ScaleAboutCentroid(double scale, Items* items, Position position) {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (auto& item : *items) centre += position(item);
  if (items->empty()) return;
  centre /= static_cast<double>(items->size());
  for (auto& item : *items) position(item) = centre + scale * (position(item) - centre);
}

// One view's still stickers: their corners and the camera as last solved.
struct LayoutView {
  std::vector<int> ids;
  std::vector<cv::Point2d> image;  // four corners per sticker, in `ids` order
  cv::Mat rvec, tvec;
  bool solved = false;
};

class LayoutFit {
 public:
  LayoutFit(const std::map<int, Rigid3d>& frame_from_marker, const CameraIntrinsics& intrinsics,
            const LayoutScaleOptions& options)
      : markers_(frame_from_marker),
        corners_(MarkerCornersInMarker(options.marker_size_m)),
        K_(intrinsics.CvK()),
        distortion_(intrinsics.CvDistortion()),
        cap_sq_(options.corner_cap_px * options.corner_cap_px) {
    for (const auto& [id, pose] : markers_) centre_ += pose.translation;
    if (!markers_.empty()) centre_ /= static_cast<double>(markers_.size());
  }

  // The view's capped squared reprojection error with the layout scaled by
  // `scale`, its camera solved (from its last pose).
  double Cost(LayoutView* view, double scale) const {
    std::vector<cv::Point3d> object;
    object.reserve(view->image.size());
    for (const int id : view->ids) {
      const Rigid3d& pose = markers_.at(id);
      const Eigen::Vector3d origin = centre_ + scale * (pose.translation - centre_);
      for (const Eigen::Vector3d& c : corners_) {
        const Eigen::Vector3d p = origin + pose.rotation * c;
        object.emplace_back(p.x(), p.y(), p.z());
      }
    }
    bool ok = false;
    try {
      if (!view->solved) {
        ok = cv::solvePnP(object, view->image, K_, distortion_, view->rvec, view->tvec, false,
                          cv::SOLVEPNP_SQPNP);
      }
      ok = cv::solvePnP(object, view->image, K_, distortion_, view->rvec, view->tvec, true,
                        cv::SOLVEPNP_ITERATIVE);
    } catch (const cv::Exception&) {
      ok = false;
    }
    if (!ok) return std::numeric_limits<double>::infinity();
    view->solved = true;
    std::vector<cv::Point2d> projected;
    cv::projectPoints(object, view->rvec, view->tvec, K_, distortion_, projected);
    double cost = 0;
    for (size_t i = 0; i < projected.size(); ++i) {
      const cv::Point2d d = projected[i] - view->image[i];
      cost += std::min(d.dot(d), cap_sq_);
    }
    return cost;
  }

 private:
  const std::map<int, Rigid3d>& markers_;
  std::array<Eigen::Vector3d, 4> corners_;
  Eigen::Vector3d centre_ = Eigen::Vector3d::Zero();
  cv::Matx33d K_;
  cv::Mat distortion_;
  double cap_sq_;
};

// Golden-section minimum of `f` on [lo, hi].
double GoldenMinimum(const std::function<double(double)>& f, double lo, double hi,
                     double tolerance) {
  const double ratio = (std::sqrt(5.0) - 1) / 2;
  double a = lo, b = hi;
  double c = b - ratio * (b - a), d = a + ratio * (b - a);
  double fc = f(c), fd = f(d);
  while (b - a > tolerance) {
    if (fc <= fd) {
      b = d, d = c, fd = fc;
      c = b - ratio * (b - a);
      fc = f(c);
    } else {
      a = c, c = d, fc = fd;
      d = a + ratio * (b - a);
      fd = f(d);
    }
  }
  return (a + b) / 2;
}

}  // namespace

std::string LayoutScaleOptions::Validate() const {
  if (!(marker_size_m > 0)) return "marker_size_m must be positive";
  if (min_stickers_per_view < 2) return "min_stickers_per_view must be at least 2";
  if (min_views < 2) return "min_views must be at least 2";
  if (!(max_change > 0 && max_change < 0.5)) return "max_change must lie in (0, 0.5)";
  if (!(corner_cap_px > 0)) return "corner_cap_px must be positive";
  if (!(size_bias >= 0 && size_bias < max_change)) return "size_bias must lie in [0, max_change)";
  if (!(max_edge_widening_px > 0)) return "max_edge_widening_px must be positive";
  return "";
}

std::string LayoutScaleEstimate::ToText() const {
  if (!ok) return "sticker layout's scale not checked against the stickers' size (" + why_not + ")";
  const std::string measured_text =
      StringPrintf("%+.3f %% +- %.3f %% from %d view(s) of %d still sticker(s), %.2f s",
                   100 * (measured - 1), 100 * standard_error, views, stickers, seconds);
  if (scale == 1.0) {
    const std::string kept =
        "sticker layout kept as the cameras placed it: the stickers' printed size agrees";
    return kept + " with it within what their size as read can tell (" + measured_text + ")";
  }
  const std::string scaled = StringPrintf("sticker layout scaled by %+.3f %%", 100 * (scale - 1));
  return scaled + ": the stickers' printed size disagrees with it (" + measured_text + ")";
}

LayoutScaleEstimate EstimateLayoutScale(const std::vector<BodyScanView>& views,
                                        const std::map<int, Rigid3d>& frame_from_marker,
                                        const std::set<int>& left_out,
                                        const CameraIntrinsics& intrinsics, double edge_widening_px,
                                        const LayoutScaleOptions& options) {
  LayoutScaleEstimate out;
  if (const std::string problem = options.Validate(); !problem.empty()) {
    out.why_not = "options: " + problem;
    return out;
  }
  if (!(edge_widening_px >= 0)) {
    out.why_not = "the camera response was not measured from this recording";
    return out;
  }
  if (edge_widening_px > options.max_edge_widening_px) {
    out.why_not = StringPrintf(
        "the camera response leaves the marker edges %.3f px wide of their printed place (at most "
        "%.3f px "
        "to trust the stickers' size)",
        edge_widening_px, options.max_edge_widening_px);
    return out;
  }
  std::vector<LayoutView> used;
  std::set<int> stickers;
  for (const BodyScanView& view : views) {
    LayoutView v;
    for (const BodyMarkerView& m : view.markers) {
      if (left_out.count(m.marker_id) || !frame_from_marker.count(m.marker_id)) continue;
      if (std::find(v.ids.begin(), v.ids.end(), m.marker_id) != v.ids.end()) continue;
      v.ids.push_back(m.marker_id);
      for (const Eigen::Vector2d& c : m.corners_px) v.image.emplace_back(c.x(), c.y());
    }
    if (static_cast<int>(v.ids.size()) < options.min_stickers_per_view) continue;
    stickers.insert(v.ids.begin(), v.ids.end());
    used.push_back(std::move(v));
  }
  out.views = static_cast<int>(used.size());
  out.stickers = static_cast<int>(stickers.size());
  if (out.views < options.min_views) {
    out.why_not = StringPrintf("%d view(s) with %d or more still stickers, %d needed", out.views,
                               options.min_stickers_per_view, options.min_views);
    return out;
  }
  const auto start = std::chrono::steady_clock::now();
  const LayoutFit fit(frame_from_marker, intrinsics, options);
  const double lo = 1 - options.max_change, hi = 1 + options.max_change;
  const double tolerance = 1e-6;
  // Each camera solved once at the layout as mapped; a view no pose
  // explains is left out.
  used.erase(std::remove_if(used.begin(), used.end(),
                            [&](LayoutView& v) { return !std::isfinite(fit.Cost(&v, 1.0)); }),
             used.end());
  if (static_cast<int>(used.size()) < options.min_views) {
    out.why_not = StringPrintf("%zu of %d view(s) gave a camera pose, %d needed", used.size(),
                               out.views, options.min_views);
    out.views = static_cast<int>(used.size());
    return out;
  }
  out.views = static_cast<int>(used.size());
  out.measured = GoldenMinimum(
      [&](double s) {
        double total = 0;
        for (LayoutView& v : used) total += fit.Cost(&v, s);
        return total;
      },
      lo, hi, tolerance);
  std::vector<double> per_view;
  for (LayoutView& v : used) {
    per_view.push_back(GoldenMinimum([&](double s) { return fit.Cost(&v, s); }, lo, hi, tolerance));
  }
  std::vector<double> sorted = per_view;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  const double median = sorted[sorted.size() / 2];
  std::vector<double> deviation;
  for (const double s : per_view) deviation.push_back(std::abs(s - median));
  std::nth_element(deviation.begin(), deviation.begin() + deviation.size() / 2, deviation.end());
  out.standard_error =
      1.4826 * deviation[deviation.size() / 2] / std::sqrt(static_cast<double>(per_view.size()));
  if (!std::isfinite(out.measured) ||
      std::abs(out.measured - 1) > options.max_change - 10 * tolerance) {
    out.why_not = StringPrintf("the stickers' sizes and spread disagree by more than %.1f %%",
                               100 * options.max_change);
    return out;
  }
  const double beyond = std::abs(out.measured - 1) - options.size_bias - out.standard_error;
  out.scale = beyond > 0 ? 1 + std::copysign(beyond, out.measured - 1) : 1.0;
  out.ok = true;
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return out;
}

void ScaleLayout(double scale, std::map<int, Rigid3d>* frame_from_marker) {
  ScaleAboutCentroid(scale, frame_from_marker,
                     [](auto& item) -> Eigen::Vector3d& { return item.second.translation; });
}

void ScaleLayout(double scale, BodyMarkerMapResult* map) {
  ScaleAboutCentroid(scale, &map->markers, [](BodyMarkerEstimate& m) -> Eigen::Vector3d& {
    return m.room_from_marker.translation;
  });
}

}  // namespace arpos
