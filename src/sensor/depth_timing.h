#pragma once
/// Depth taken at another instant than its colour image: a camera without
/// colour-depth sync (RgbdFrame::depth_delay_s, from depth.txt's own
/// timestamps). Between the two instants a hand-held camera moves, so the
/// reading at a pixel is of a point the colour image saw a little elsewhere:
/// the camera's translation over the delay along the ray, and its turn over
/// the delay moving the pixel across the surface (by |omega| |delay| z,
/// which on a sloped surface changes the reading by as much). Such depth is
/// worth less, by that much: the localiser and the body tracker add it to
/// each reading's sigma. Not moved back by a known amount: the camera's
/// motion over 10 ms is not known well enough from the frames before it
/// (tried on simulated xtion tracking, seed 41, depth 10 ms late: the depth
/// image warped to the colour instant at the velocity of the last two placed
/// frames tracked at 2.27-2.37 mm MTE against 1.69 mm as it was; the
/// velocity from two poses 67 ms apart was off by as much as the motion).

#include <cstddef>
#include <optional>
#include <vector>

#include "geometry/rigid3.h"

namespace arpos {

/// A hand-held camera's motion when nothing says more (no earlier poses):
/// 0.2 m/s and 0.35 rad/s (20 deg/s), at the faster end of a positioning
/// walk (the simulated tracking walks: median 0.15 m/s, 12 deg/s).
constexpr double kAssumedHandheldSpeedMS = 0.2;
constexpr double kAssumedHandheldTurnRadS = 0.35;

/// The sigma a delay adds to a depth reading at depth z: const_m + per_m * z.
struct DelayedDepthSigma {
  double const_m = 0;  ///< |delay| * speed
  double per_m = 0;    ///< |delay| * turn rate (rad/s)
  double At(double z_m) const { return const_m + per_m * z_m; }
  bool any() const { return const_m > 0 || per_m > 0; }
};

/// For a depth delay of `delay_s`, the camera (relative to what it looks at)
/// having moved by `step` (b_from_a, either direction) over `step_s` seconds;
/// without a step (nullptr, or step_s <= 0) the assumed hand-held motion.
/// Zero for no delay.
DelayedDepthSigma DelayedDepthSigmaOf(double delay_s, const Rigid3d* step, double step_s);

/// Where a recording is processed as a whole (the body scan), the camera's
/// motion over the delay is known from both sides: frame k's
/// colour_from_depth_camera (points of the camera at its depth instant into
/// the camera at its colour instant), the camera at the depth instant
/// interpolated at constant velocity between the two posed frames around it
/// (`room_from_camera` at `times_s`, in time order; beyond the last or before
/// the first, from the nearest two). nullopt without a neighbour within
/// kMaxInterpolationGapS, or with no delay.
constexpr double kMaxInterpolationGapS = 0.5;
std::optional<Rigid3d> ColourFromDepthCamera(const std::vector<double>& times_s,
                                             const std::vector<Rigid3d>& room_from_camera, size_t k,
                                             double delay_s);

}  // namespace arpos
