#pragma once
/// Planar contour stacks (an RTSTRUCT ROI) to a volume whose 0.5 iso-surface
/// is the closed surface they outline.
///
/// All contours must lie in parallel planes (axial in practice). Contours of
/// one plane are combined by the even-odd rule: a point is inside if it lies
/// inside an odd number of them, so holes (a contour inside another) and
/// several separate outlines per slice come out right whatever their winding.
/// Each plane is rasterised as area coverage (the fraction of each pixel
/// inside, 4 sub-rows per pixel and exact coverage along each sub-row), so the
/// iso-surface at 0.5 follows the polygon to a fraction of a pixel.
///
/// Slices: one per distinct contour plane, at the median plane spacing;
/// a grid slice with no contour plane within half a spacing (the contouring
/// skipped a slice) takes the nearest contour plane. One empty slice is added
/// beyond each end and an empty margin around, so the surface is closed: it
/// caps half a spacing beyond the first and last contour, the extent of the
/// slabs the contours stand for.
///
/// Frames: the volume's geometry maps grid indices to the DICOM patient frame
/// (mm). For axial contours (normal +-z) the grid axes are +x, +y, +z.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "model_import/volume.h"

namespace arpos {

struct ContourRasterOptions {
  /// In-plane pixel size; enlarged if the grid would exceed max_voxels.
  double pixel_mm = 1.0;
  size_t max_voxels = 64u << 20;
  /// Largest distance of a contour point from its contour's plane, and
  /// largest angle between contour planes.
  double planarity_tolerance_mm = 0.5;
  double parallel_tolerance_deg = 1.0;
  bool Check(std::string* reason) const;
};

struct ContourRasterResult {
  ScalarVolume coverage;          ///< 0..1; iso-surface at 0.5
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  ///< common plane normal, patient frame
  int num_planes = 0;             ///< distinct contour planes
  int num_contours = 0;           ///< used (3 points or more)
  int skipped_degenerate = 0;     ///< contours with fewer than 3 points
  int filled_missing_slices = 0;  ///< grid slices copied from a neighbour
  double slice_spacing_mm = 0;
  double pixel_mm = 0;
};

/// `contours_mm`: closed polygons (last point joined to the first) in the
/// patient frame. Throws InputError, with `source` (file and ROI) in the
/// message, if there is no usable contour or the contours are not parallel
/// planes; arpos::Error for invalid options.
ContourRasterResult RasterizeContours(const std::vector<std::vector<Eigen::Vector3d>>& contours_mm,
                                      const ContourRasterOptions& options, const std::string& source);

/// Area (mm^2) enclosed by the contours of one plane under the even-odd rule,
/// computed exactly from the polygons (for checks): sum of the absolute
/// polygon areas, each counted negative when it lies inside an odd number of
/// the others. `normal` is the plane normal.
double EvenOddArea(const std::vector<std::vector<Eigen::Vector3d>>& contours_mm,
                   const Eigen::Vector3d& normal);

}  // namespace arpos
