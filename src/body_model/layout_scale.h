#pragma once
/// The scale of the body sticker layout, from the stickers' printed size.
///
/// The session places each sticker by the scan's cameras. Those cameras are
/// registered to the reconstruction, whose depth carries what is left of the
/// camera's depth error; each camera so sits a little off along its view,
/// and the stickers it places with the others come out as a layout a little
/// too large or too small (measured over 17 sessions with random conditions:
/// 0.003-0.73 %, mean 0.16 %). Tracking reads that layout against the
/// stickers in its image, and a layout 0.25 % too large puts the patient
/// 2.5 mm too far along the camera's view at a metre, in every frame.
///
/// A sticker's printed size says how far it is from the camera that sees it,
/// whatever that camera's pose; its spread against the other stickers in the
/// same image then says how large the layout is. So: the one scale of the
/// layout about its centre that best explains the corners of the stickers
/// that do not move with the breathing, each view's camera free (a pose per
/// view). Its standard error comes from the spread of each view's own best
/// scale.
///
/// The stickers' size as read carries its own bias: a corner read 0.015 px
/// outward makes a 20 px sticker look 0.1 % larger. Against the truth, the
/// size read the layout's scale 0.01-0.13 % off (sd 0.06 %) on 20 simulated
/// sessions (5 default, 15 with random conditions), about as far as good
/// cameras place it (0.008-0.025 % on the 5 default ones). So only the part
/// of the disagreement beyond that bias and the estimate's standard error is
/// taken as the layout's error and removed; within it, the layout stays as
/// the cameras placed it. On 17 random-condition sessions: the layout's scale
/// error 0.157 -> 0.117 % mean, the patient in the tracking camera 1.53 ->
/// 1.44 mm; the 5 default ones unchanged (one scaled by 0.036 %). Applied in
/// full, the default ones went to 0.066 % and their tracking MTE from 0.73
/// to 0.80 mm (benchmark/accuracy.md, session 51).
///
/// Where the camera response leaves the markers' edges unexplained (the
/// black cells still read wider or narrower than the white ones,
/// ResponseEstimate::widening_px), the size as read is biased by that much
/// and nothing is measured: on two S-curve, auto-exposure sessions whose
/// edges kept 0.15-0.17 px, the size read the layout's scale as +1.10 and
/// -0.73 % where the cameras' layouts were +0.73 and -0.22 % off.

#include <map>
#include <set>
#include <string>
#include <vector>

#include "body_model/body_marker_map.h"
#include "geometry/rigid3.h"
#include "sensor/intrinsics.h"

namespace arpos {

struct LayoutScaleOptions {
  double marker_size_m = 0.03;
  /// A view counts when it sees at least this many still mapped stickers.
  int min_stickers_per_view = 3;
  /// Views needed for an estimate.
  int min_views = 3;
  /// The scale is searched within 1 +- this; an optimum at the edge is no
  /// estimate (the stickers' sizes and spread disagree beyond a scale).
  double max_change = 0.02;
  /// A corner's residual counts at most this far (robust to a misread one).
  double corner_cap_px = 2.0;
  /// The bias the stickers' size as read may carry (relative; see above):
  /// a disagreement within it plus the standard error changes nothing.
  double size_bias = 0.001;
  /// Above this unexplained edge widening (px RMS) the stickers' size as
  /// read is not trusted (see above).
  double max_edge_widening_px = 0.1;

  std::string Validate() const;
};

struct LayoutScaleEstimate {
  bool ok = false;
  /// The factor to apply to the layout about its centre (1: none): the
  /// disagreement beyond the size bias and the standard error.
  double scale = 1.0;
  /// The best scale of all views together.
  double measured = 1.0;
  /// Standard error of `measured`: 1.4826 x the median absolute deviation
  /// of each view's own best scale, over the square root of the views.
  double standard_error = 0;
  int views = 0;
  int stickers = 0;     ///< still stickers seen in those views
  double seconds = 0;   ///< time the estimate took
  std::string why_not;  ///< when !ok

  std::string ToText() const;
};

/// `frame_from_marker`: the mapped stickers in any one frame (the room's, the
/// model's). `left_out`: stickers not to use (those that move with the
/// breathing). `edge_widening_px`: what the scan's camera response leaves
/// of the markers' black widening (px RMS; negative: not measured, and
/// nothing is). Never throws for bad data: !ok with the reason.
LayoutScaleEstimate EstimateLayoutScale(const std::vector<BodyScanView>& views,
                                        const std::map<int, Rigid3d>& frame_from_marker,
                                        const std::set<int>& left_out,
                                        const CameraIntrinsics& intrinsics, double edge_widening_px,
                                        const LayoutScaleOptions& options = {});

/// The stickers' positions scaled by `scale` about their centroid; their
/// orientations kept.
void ScaleLayout(double scale, std::map<int, Rigid3d>* frame_from_marker);
void ScaleLayout(double scale, BodyMarkerMapResult* map);

}  // namespace arpos
