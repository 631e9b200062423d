#pragma once
/// The patient's body in a CT volume: a binary mask without couch, cushions,
/// cables or air pockets, and a field whose iso-surface is its skin.
///
/// Steps (each a reason in the .cc):
///  1. threshold: HU >= threshold_hu is tissue (-350 HU by default: half-way
///     between air (-1000) and fat (-100) would be about -550 HU, which puts
///     the surface on the partial-volume midpoint of the skin, but also keeps
///     blankets, clothing folds and foam edges; -350 HU drops those, as
///     clinical external-contour tools (Eclipse: -350 HU) do, and moves the
///     skin inwards by well under 1 mm on a CT's ~1 mm blur);
///  2. morphological opening in each axial slice with a disc of
///     opening_radius_mm: breaks thin bridges to the couch top, a mattress or
///     a cable, and removes thin shells;
///  3. largest 6-connected 3D component: the body (the couch and arms lying
///     apart from the trunk are other components);
///  4. holes filled slice by slice (lungs, bowel gas, trachea): every
///     background region of an axial slice not connected to its border.
/// Works on any orientation of the volume's k axis, but "axial slice" means the
/// volume's (i, j) plane, which is what CT scanners store.

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "model_import/dicom_io.h"
#include "model_import/volume.h"

namespace arpos {

/// Outcome of KeepLargestComponent.
struct ComponentStats {
  int num_components = 0;
  size_t kept_voxels = 0;
  size_t dropped_voxels = 0;          ///< in all other components
  size_t second_component_voxels = 0;  ///< the largest dropped one
};

/// Keeps the largest 6-connected component of `inside` (values 0/1) and
/// zeroes the others. Volumes up to 2^32 voxels.
ComponentStats KeepLargestComponent(const VolumeGeometry& geometry, std::vector<uint8_t>* inside);

/// Sets to 1, in every (i, j) slice, the background not 4-connected to the
/// slice's border (enclosed air: lungs, gas, holes of contours). Returns the
/// number of voxels filled.
size_t FillHolesPerSlice(const VolumeGeometry& geometry, std::vector<uint8_t>* inside);

struct BodyMaskOptions {
  double threshold_hu = -350.0;
  /// Radius of the in-plane opening disc; 0 disables the opening.
  double opening_radius_mm = 4.0;
  bool fill_holes = true;
  bool Check(std::string* reason) const;
};

struct BodyMask {
  VolumeGeometry geometry;       ///< same as the CT's
  std::vector<uint8_t> inside;   ///< 1 = body, one per voxel
  size_t body_voxels = 0;
  size_t thresholded_voxels = 0;   ///< after step 1
  int num_components = 0;          ///< 3D components after step 2
  size_t dropped_voxels = 0;       ///< in components other than the largest
  size_t second_component_voxels = 0;  ///< the largest dropped one (arms, couch)
  size_t filled_hole_voxels = 0;
};

/// Throws InputError (naming `source` for the message) if no voxel reaches the
/// threshold; arpos::Error for invalid options.
BodyMask SegmentBody(const CtVolume& ct, const BodyMaskOptions& options, const std::string& source);

/// A field for iso-surfacing at `iso_value` = threshold - 0.5: inside the mask
/// max(HU, threshold), outside min(HU, threshold - 1). Where the mask follows
/// the threshold (the skin) the iso-surface keeps the sub-voxel HU
/// interpolation; where steps 2-4 changed the mask (couch contact, filled
/// lungs) it follows the mask. The field is cropped to the mask's bounding box
/// plus one voxel of padding on every side (padding = outside), so the surface
/// is closed even where the body leaves the scanned volume: there it is a flat
/// cap half a voxel beyond the last sample.
ScalarVolume BodySurfaceField(const CtVolume& ct, const BodyMask& mask, double threshold_hu,
                              double* iso_value);

}  // namespace arpos
