#include "geometry/pose_error.h"

#include "geometry/so3.h"

namespace arpos {

PoseError ComputePoseError(const Rigid3d& room_from_x_gt, const Rigid3d& room_from_x_est) {
  const Rigid3d gt_from_est = room_from_x_gt.Inverse() * room_from_x_est;
  PoseError error;
  error.translation_mm = gt_from_est.translation.norm() * 1000.0;
  error.rotation_deg = DegFromRad(RotationAngleRad(gt_from_est.rotation));
  return error;
}

}  // namespace arpos
