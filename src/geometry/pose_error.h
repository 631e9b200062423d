#pragma once
/// Pose error as DATASET.md defines it: E = T_gt^-1 * T_est for poses that
/// map a moving frame into the room; translational error |t(E)| and rotational
/// error angle(R(E)).

#include "geometry/rigid3.h"

namespace arpos {

struct PoseError {
  double translation_mm = 0.0;
  double rotation_deg = 0.0;
};

/// `room_from_x_gt` and `room_from_x_est` map the same moving frame x (camera
/// or model) into the room.
PoseError ComputePoseError(const Rigid3d& room_from_x_gt, const Rigid3d& room_from_x_est);

}  // namespace arpos
