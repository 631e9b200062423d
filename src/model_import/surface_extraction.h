#pragma once
/// Iso-surface of a volume as a triangle mesh: flying edges on a grid coarse
/// enough for a vertex budget, then light non-shrinking smoothing (windowed
/// sinc). VTK does the work inside the .cc only; no display is needed.
/// Thread-compatible (no shared state).
///
/// Vertex budget: flying edges puts one vertex on every grid edge that crosses
/// the iso-value, so the vertex count is known before extracting. Over the
/// budget, the grid is resampled (bilinear, in the (i, j) planes only: slices
/// are usually the coarse axis already) to give decimation_ratio x the budget,
/// and decimation (vtkDecimatePro, topology preserved) takes it to the budget:
/// decimation spends few vertices on flat caps, resampling keeps it short
/// (decimating 300k vertices 3x took 3-9 s here and once left non-manifold
/// edges). If decimation leaves the surface open, the grid is resampled to
/// fit the budget without decimation (uniform resolution, always closed).

#include <Eigen/Core>
#include <string>

#include "geometry/triangle_mesh.h"
#include "model_import/volume.h"

namespace arpos {

struct SurfaceOptions {
  /// The surface passes where the field equals iso_value; inside is where
  /// the field is greater.
  double iso_value = 0.5;
  /// Upper bound on output vertices; 0 = no limit (full resolution).
  int max_vertices = 100000;
  /// Windowed-sinc smoothing; 0 iterations disables it. A pass band of 0.1
  /// with 20 iterations removes voxel steps (< 1 voxel) and keeps features of
  /// a few voxels; windowed sinc does not shrink the surface the way Laplacian
  /// smoothing does.
  /// Extract at up to this many times max_vertices, then decimate (1 = fit
  /// the budget by resampling alone).
  double decimation_ratio = 2.0;
  /// Keep only the largest connected piece of the surface (a coarse grid can
  /// cut thin bridges and leave islands).
  bool largest_component_only = true;
  int smoothing_iterations = 20;
  double smoothing_pass_band = 0.1;
  bool Check(std::string* reason) const;
};

struct SurfaceStats {
  int full_resolution_vertices = 0;  ///< predicted at the input grid's resolution
  double coarsening = 1.0;           ///< in-plane resampling factor (1 = none)
  Eigen::Vector3d grid_spacing_mm = Eigen::Vector3d::Zero();  ///< grid actually used
  int extracted_vertices = 0;        ///< straight out of flying edges
  int extracted_faces = 0;
  double extract_s = 0, decimate_s = 0, smooth_s = 0;
  bool decimation_broke_surface = false;  ///< fell back to resampling alone
  int dropped_faces = 0;                  ///< in pieces other than the largest
};

/// Returns the mesh in the volume's patient frame converted to METRES
/// (patient-frame mm * 0.001), faces oriented outwards (counter-clockwise
/// seen from outside, the side where the field is below iso_value), with
/// vertex normals. Throws InputError naming `source` if the surface is empty,
/// arpos::Error if VTK reports an error.
TriangleMesh ExtractSurface(const ScalarVolume& volume, const SurfaceOptions& options,
                            const std::string& source, SurfaceStats* stats = nullptr);

/// Quadric decimation to at most max_vertices (0 = no limit); returns the
/// mesh unchanged if it is small enough. Frame and units unchanged; vertex
/// normals recomputed when decimated. Throws arpos::Error if VTK fails.
TriangleMesh DecimateMesh(const TriangleMesh& mesh, int max_vertices);

}  // namespace arpos
