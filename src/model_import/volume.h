#pragma once
/// Voxel grids placed in the DICOM patient coordinate system.
///
/// The patient frame is DICOM's (LPS: +x towards the patient's left, +y
/// posterior, +z head), in millimetres, as stored in ImagePositionPatient and
/// the RTSTRUCT contour points. Voxel (i, j, k) is a sample point (not a box
/// corner); i varies fastest in memory, then j, then k.

#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <vector>

namespace arpos {

struct VolumeGeometry {
  /// Number of samples along i, j, k.
  std::array<int, 3> size = {0, 0, 0};
  /// Distance between neighbouring samples along i, j, k.
  Eigen::Vector3d spacing_mm = Eigen::Vector3d::Ones();
  /// Columns: unit patient-frame directions of +i, +j, +k. Orthonormal with
  /// det +1 (checked by the readers that fill it).
  Eigen::Matrix3d patient_from_index_rotation = Eigen::Matrix3d::Identity();
  /// Patient-frame position of sample (0, 0, 0).
  Eigen::Vector3d origin_mm = Eigen::Vector3d::Zero();

  size_t num_voxels() const {
    return static_cast<size_t>(size[0]) * static_cast<size_t>(size[1]) *
           static_cast<size_t>(size[2]);
  }
  size_t Index(int i, int j, int k) const {
    return (static_cast<size_t>(k) * static_cast<size_t>(size[1]) + static_cast<size_t>(j)) *
               static_cast<size_t>(size[0]) +
           static_cast<size_t>(i);
  }
  /// Patient-frame position (mm) of the (possibly fractional) index (i, j, k).
  Eigen::Vector3d PatientFromIndexMm(const Eigen::Vector3d& ijk) const {
    return origin_mm + patient_from_index_rotation * ijk.cwiseProduct(spacing_mm);
  }
};

/// A float field on a grid (HU, coverage fraction, ...). values.size() ==
/// geometry.num_voxels().
struct ScalarVolume {
  VolumeGeometry geometry;
  std::vector<float> values;
};

}  // namespace arpos
