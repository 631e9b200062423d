#include "sensor/depth_timing.h"

#include <algorithm>
#include <cmath>

namespace arpos {

DelayedDepthSigma DelayedDepthSigmaOf(double delay_s, const Rigid3d* step, double step_s) {
  DelayedDepthSigma s;
  const double delay = std::abs(delay_s);
  if (!(delay > 0)) return s;
  double speed = kAssumedHandheldSpeedMS, turn = kAssumedHandheldTurnRadS;
  if (step != nullptr && step_s > 0) {
    speed = step->translation.norm() / step_s;
    turn = step->RotationVector().norm() / step_s;
  }
  s.const_m = delay * speed;
  s.per_m = delay * turn;
  return s;
}

std::optional<Rigid3d> ColourFromDepthCamera(const std::vector<double>& times_s,
                                             const std::vector<Rigid3d>& room_from_camera, size_t k,
                                             double delay_s) {
  const size_t n = std::min(times_s.size(), room_from_camera.size());
  if (delay_s == 0 || k >= n || n < 2) return std::nullopt;
  // The pair around the depth instant: k and the next frame for a later
  // depth, the previous and k for an earlier one; at the ends, the nearest.
  size_t a = delay_s > 0 ? k : (k > 0 ? k - 1 : 0);
  if (a + 1 >= n) a = n - 2;
  const size_t b = a + 1;
  const double gap = times_s[b] - times_s[a];
  if (!(gap > 0 && gap <= kMaxInterpolationGapS)) return std::nullopt;
  // Constant velocity: the motion a -> b scaled to the depth instant.
  const double f = (times_s[k] + delay_s - times_s[a]) / gap;
  const Rigid3d a_from_b = room_from_camera[a].Inverse() * room_from_camera[b];
  const Rigid3d room_from_depth_camera =
      room_from_camera[a] *
      Rigid3d::FromRotationVector(f * a_from_b.RotationVector(), f * a_from_b.translation);
  return room_from_camera[k].Inverse() * room_from_depth_camera;
}

}  // namespace arpos
