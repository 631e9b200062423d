#pragma once
/// The room recording's depth checked against its colour geometry.
///
/// The markers' printed size fixes the scale of what the colour images
/// measure; the depth sensor measures the same scene on its own. So: the
/// joint adjustment run once without depth terms, then every depth reading
/// inside a marker, and on the planes two or more markers span (the floor,
/// a wall: where a smooth error field shows over much of the image),
/// compared with the depth that depth-free geometry gives it, and a
/// systematic error (scale and a low-frequency field, sensor/depth_correction.h)
/// fitted to the differences. Not landmarks: landmarks placed without depth
/// are triangulated from a few far views and can be centimetres off;
/// comparing depth with them (as this check did at first) blamed the depth
/// for the geometry's own errors.
///
/// What the room map builder does with the result (removing the correction
/// from every depth reading of the adjustment, weighting depth by the spread
/// the check found) stays with the builder; ApplyDepthCorrection does the
/// first.

#include <string>
#include <vector>

#include "room_map/bundle_adjustment.h"
#include "room_map/room_planes.h"
#include "room_map/room_surface.h"
#include "sensor/depth_correction.h"
#include "sensor/intrinsics.h"

namespace arpos {

/// The planes (room_planes.h) that markers of side `marker_size_m` at
/// `room_from_marker` span: at least `min_markers` markers, spread at least
/// `min_spread_m` across the plane's narrower extent.
std::vector<MarkerPlane> PlanesOfMarkers(const std::vector<Rigid3d>& room_from_marker,
                                         double marker_size_m, int min_markers,
                                         double min_spread_m);

struct DepthCheckInput {
  const CameraIntrinsics* intrinsics = nullptr;
  double marker_size_m = 0;
  /// The depth grid every frame was sampled on, and per adjusted camera (in
  /// BaProblem::camera_from_room order) the depth read at its points (m,
  /// 0 = none; nullptr or empty: the frame has no depth grid).
  const DepthSampleGrid* grid = nullptr;
  std::vector<const std::vector<float>*> grid_z;
  /// Plane readings: within this distance of one of the plane's markers (0:
  /// none, readings inside the markers only), within max(plane_gate_m,
  /// 3 sigma(z)) of the plane; planes of at least plane_min_markers markers
  /// (and 2) spread plane_min_spread_m.
  double plane_support_m = 0.5;
  double plane_gate_m = 0.03;
  int plane_min_markers = 2;
  double plane_min_spread_m = 0.2;
};

/// A reading inside a marker more than this fraction of its depth off what
/// the marker's pose without depth gives says nothing about the sensor (a
/// small oblique marker's flipped pose: on an l515 seed one view's expected
/// depth was 10 m beyond the reading); no systematic error the check removes
/// comes near 10 %. Such readings are left out unless they are half or
/// more of those inside the markers, or they agree on one ratio to what
/// the markers give (robust spread under kDepthCheckScaleSpread): then the
/// depth is off (a wrong depth scale), and the check must see it. Readings
/// off every which way are not a scale: on a d435 case with markers on the
/// couch base, 30 % of them read the couch or the floor beyond (-0.7 to
/// +2.1 m), and fitted they made a +2.8 % scale out of a true +0.34 %.
constexpr double kDepthCheckGrossFraction = 0.1;
constexpr double kDepthCheckScaleSpread = 0.03;

struct DepthCheckResult {
  DepthCorrectionFit fit;
  int readings_left_out = 0;  ///< inside markers, grossly off (above)
  /// fit.message, and the readings left out when there are any.
  std::string message;
};

/// The check on `problem` (its marker observations' depth samples, its
/// cameras and markers as the starting point) with `options` (the joint
/// adjustment's; its depth terms are switched off here). `problem` is not
/// changed: the depth-free adjustment runs on a copy.
DepthCheckResult CheckDepthAgainstColourGeometry(const BaProblem& problem, const BaOptions& options,
                                                 const DepthCheckInput& input);

/// Removes `correction` from every depth reading of `problem` (keypoint and
/// marker observations; pixels in `intrinsics`).
void ApplyDepthCorrection(const DepthCorrection& correction, const CameraIntrinsics& intrinsics,
                          BaProblem* problem);

}  // namespace arpos
