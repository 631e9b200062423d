#pragma once
/// A regular grid of cubes of side `side_m`, cells keyed by one integer: the
/// surface patches the session finds moving (body_model/surface_motion.h)
/// and the tracker leaves out (tracking/body_tracker.cc) are the same cells.
/// 21 bits an axis: +-1e6 cells, +-40 km at 4 cm.

#include <cmath>
#include <cstdint>

#include <Eigen/Core>

namespace arpos {

/// The key of the cube holding `p`.
inline uint64_t CubeKey(const Eigen::Vector3d& p, double side_m) {
  const auto cell = [side_m](double v) {
    return static_cast<uint64_t>(static_cast<int64_t>(std::floor(v / side_m)) + (1 << 20)) & 0x1FFFFF;
  };
  return (cell(p.x()) << 42) | (cell(p.y()) << 21) | cell(p.z());
}

/// The centre of the cube with key `key` (CubeKey of it gives `key` back).
inline Eigen::Vector3d CubeCentre(uint64_t key, double side_m) {
  const auto coordinate = [key, side_m](int shift) {
    return (static_cast<double>(static_cast<int64_t>((key >> shift) & 0x1FFFFF) - (1 << 20)) + 0.5) * side_m;
  };
  return Eigen::Vector3d(coordinate(42), coordinate(21), coordinate(0));
}

}  // namespace arpos
