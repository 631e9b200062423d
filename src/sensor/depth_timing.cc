#include "sensor/depth_timing.h"

#include <cmath>

#include "geometry/so3.h"

namespace arpos {

DelayedDepthSigma DelayedDepthSigmaOf(double delay_s, const Rigid3d* step, double step_s) {
  DelayedDepthSigma s;
  const double delay = std::abs(delay_s);
  if (!(delay > 0)) return s;
  double speed = kAssumedHandheldSpeedMS, turn = kAssumedHandheldTurnRadS;
  if (step != nullptr && step_s > 0) {
    speed = step->translation.norm() / step_s;
    turn = RotationVectorFromQuaternion(step->rotation).norm() / step_s;
  }
  s.const_m = delay * speed;
  s.per_m = delay * turn;
  return s;
}

}  // namespace arpos
