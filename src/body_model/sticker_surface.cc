#include "body_model/sticker_surface.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "registration/kdtree.h"
#include "util/string_util.h"

namespace arpos {

StickerSurfaceCheck CheckStickersOnSurface(const std::map<int, Rigid3d>& model_from_markers,
                                           const KdTree& model_tree,
                                           const std::map<int, double>& motion_m,
                                           const StickerSurfaceOptions& options) {
  StickerSurfaceCheck check;
  for (const auto& [id, model_from_marker] : model_from_markers) {
    const Eigen::Vector3d c = model_from_marker.translation;
    size_t nearest = 0;
    double sq = 0;
    const bool near = model_tree.Nearest(Eigen::Vector4d(c.x(), c.y(), c.z(), 1), &nearest, &sq,
                                         options.search_m * options.search_m);
    const double d = near ? std::sqrt(sq) : options.search_m;
    check.off_m[id] = d;
    const auto motion = motion_m.find(id);
    const double breathing = motion != motion_m.end() ? motion->second : 0.0;
    if (!(d <= options.max_off_m + options.breathing_factor * breathing)) check.off.push_back(id);
  }
  return check;
}

std::string StickerSurfaceCheck::ToText() const {
  if (off_m.empty()) return "";
  std::vector<std::pair<double, int>> by_distance;
  for (const auto& [id, d] : off_m) by_distance.emplace_back(d, id);
  std::sort(by_distance.begin(), by_distance.end());
  return StringPrintf(
      "stickers on the aligned reference surface: %.1f mm off it in median, at most %.1f mm "
      "(sticker %d)",
      1000 * by_distance[by_distance.size() / 2].first, 1000 * by_distance.back().first,
      by_distance.back().second);
}

std::string StickerSurfaceCheck::DescribeOff() const {
  std::string text;
  for (int id : off) {
    text += StringPrintf("%s%d (%.1f mm)", text.empty() ? "" : ", ", id, 1000 * off_m.at(id));
  }
  return text;
}

}  // namespace arpos
