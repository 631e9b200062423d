#pragma once
/// Deterministic CPU rasteriser for the simulator.
///
/// Camera: OpenCV pinhole without distortion (x right, y down, z forward;
/// pixel centres at integer coordinates, the top-left pixel's centre at
/// (0, 0)). Visibility is exact per sample: the depth of a sample is the
/// camera z where the sample's viewing ray meets the triangle's plane, and
/// attributes are interpolated perspective-correctly (barycentrics from
/// scalar triple products of the camera-frame vertices).
///
/// Colour is the box-filtered mean of S^2 samples per pixel placed as an
/// n-queens pattern on an S^2 x S^2 sub-grid of the pixel square
/// [u - 0.5, u + 0.5] x [v - 0.5, v + 0.5] (one sample per sub-row, sub-column
/// and diagonal; symmetric about the centre on average), so the pixel value
/// integrates the scene over the pixel without any shift and edges along the
/// axes or diagonals get S^2 coverage levels. Depth, normal and label come
/// from the centre sample only, which lies exactly at the pixel centre: there
/// is no averaging across silhouettes.
///
/// Thread-safety: Render() may use OpenMP over row bands; its result does not
/// depend on the number of threads or their scheduling.

#include <opencv2/core.hpp>
#include <vector>

#include "geometry/rigid3.h"
#include "sensor/intrinsics.h"
#include "simulation/render_scene.h"

namespace arpos::sim {

/// One mesh placed in the camera frame for one frame.
struct RenderInstance {
  int mesh = -1;              ///< index into RenderScene::meshes
  Rigid3d camera_from_part;   ///< maps the mesh's part frame into the camera frame
  int label = 0;              ///< written to RenderOutput::label where visible (> 0)
  /// Drawn instead of scene.meshes[mesh] if set (a per-frame deformed copy,
  /// e.g. a breathing body); must outlive Render().
  const RenderMesh* mesh_override = nullptr;
};

struct RenderOptions {
  int supersampling = 3;   ///< S: 1, 3 or 5
  double near_m = 0.02;    ///< near clipping plane
  int band_rows = 8;       ///< pixel rows per work item
  Eigen::Vector3f background{0, 0, 0};
};

struct RenderOutput {
  cv::Mat color;   ///< CV_32FC3 linear RGB radiance (not BGR), box-filtered
  cv::Mat depth;   ///< CV_32F camera z (m) at the pixel centre, 0 where no surface
  cv::Mat normal;  ///< CV_32FC3 camera-frame unit normal at the centre, facing the camera
  cv::Mat label;   ///< CV_32S label of the instance at the centre, 0 where none
};

/// Renders `instances` of `scene` seen by a camera with `intrinsics`
/// (distortion ignored: the simulator's cameras have none). `lighting`
/// positions are in the room frame; `camera_from_room` places them.
RenderOutput Render(const RenderScene& scene, const std::vector<RenderInstance>& instances,
                    const CameraIntrinsics& intrinsics, const Rigid3d& camera_from_room,
                    const Lighting& lighting, const RenderOptions& options = {});

}  // namespace arpos::sim
