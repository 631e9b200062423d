#pragma once
/// Each sticker against the aligned reference surface (session step 6c).
///
/// Stickers sit on the skin, so after the alignment each sticker's centre
/// lies on the reference model's surface, give or take what the breathing
/// moved it (the model is one phase, the sticker map their mean) and how
/// far the model is from today's body. A sticker far off it is one the
/// sticker map placed wrong, or a sign that the alignment is wrong there:
/// tracking would carry either into every pose. Measured on 39 simulated
/// sessions (benchmark/accuracy.md, session 52): at most 5.9 mm where the
/// map and the alignment were right (breathing up to 6 mm peak to peak);
/// 10.3 mm for a sticker the map put 17.6 mm off; 10-23 mm for three of a
/// scan's eight stickers whose model came out 6 deg turned.

#include <map>
#include <string>
#include <vector>

#include "geometry/rigid3.h"

namespace arpos {

class KdTree;

struct StickerSurfaceOptions {
  /// Beyond this (m) plus `breathing_factor` times the sticker's measured
  /// breathing (1 sigma along its normal), a sticker is off the surface.
  double max_off_m = 0.008;
  double breathing_factor = 3;
  /// Distances are searched up to this (m); farther reads as this.
  double search_m = 0.1;
};

struct StickerSurfaceCheck {
  std::map<int, double> off_m;  ///< per sticker: its centre's distance from the surface
  std::vector<int> off;         ///< those beyond what the options allow, by id
  /// "stickers on the aligned reference surface: ..." (empty: no sticker).
  std::string ToText() const;
  /// "134 (23.3 mm), 173 (10.0 mm)" for the stickers off the surface.
  std::string DescribeOff() const;
};

/// `model_from_markers`: each sticker in the model frame; `model_tree`: a
/// dense sampling of the reference surface (model frame); `motion_m`: each
/// breathing sticker's motion (1 sigma, m; absent: still).
StickerSurfaceCheck CheckStickersOnSurface(const std::map<int, Rigid3d>& model_from_markers,
                                           const KdTree& model_tree,
                                           const std::map<int, double>& motion_m,
                                           const StickerSurfaceOptions& options = {});

}  // namespace arpos
