#pragma once
/// The AR overlay image of tracking mode (DATASET.md, "Outputs of tracking",
/// overlay/<timestamp>.png): the colour frame with the reference model drawn
/// at the current (tracked) pose in translucent red, at the planned pose in
/// translucent blue with an opaque silhouette outline, and the couch
/// correction as a small text panel in the top-left corner.
///
/// Drawing: the model is rasterised by the simulator's CPU rasteriser
/// (simulation/rasterizer.h) at the ideal pinhole camera with the recording's
/// K, only over its projected bounding box and, for a closed outward-facing
/// model, front faces only; shaded by Lambert's law with the light at the
/// camera (so the shape reads). When the recording's camera has lens
/// distortion, the render is warped into the distorted image through a
/// per-pixel map computed once in the constructor (each distorted pixel's
/// ideal position, by Newton's method on OpenCV's lens model); the ideal
/// canvas is enlarged to cover every pixel of the distorted image (barrel
/// distortion sees beyond the ideal image's border), and pixels where a
/// strong distortion has no inverse stay undrawn. Where both poses overlap,
/// both colours stay visible: each layer takes its own share of the pixel
/// (purple where red and blue meet); the blue outline is drawn last.
///
/// Cost (sample model, 107k faces, both poses, Release, one core): about
/// 55-75 ms per frame at 640x480 and 175-220 ms at 1280x720, measured on a
/// busy two-core machine (OverlaySample.DISABLED_Timing in
/// tests/tracking/overlay_test.cc).
///
/// Poses: `camera_from_model` maps model points (metres) into the OpenCV
/// camera frame (x right, y down, z forward): p_cam = camera_from_model *
/// p_model. Parts of the model behind the camera's near plane (2 cm) are
/// clipped.
///
/// Thread-safety: Render() is const and touches no shared mutable state; one
/// renderer may serve several threads. It uses OpenMP inside the rasteriser.

#include <opencv2/core.hpp>
#include <optional>
#include <string>

#include "feedback/couch_correction.h"
#include "geometry/rigid3.h"
#include "geometry/triangle_mesh.h"
#include "sensor/intrinsics.h"
#include "simulation/render_scene.h"

namespace arpos {

struct OverlayOptions {
  /// Opacity of the model at the current (tracked) pose, red, in [0, 1].
  double current_alpha = 0.45;
  /// Opacity of the model at the planned pose, blue, in [0, 1]; its
  /// silhouette outline is always drawn opaque.
  double planned_alpha = 0.30;
  /// Rasteriser samples per pixel side: 1 (hard edges, the silhouette
  /// exact at pixel centres) or 3 (anti-aliased edges; 9 samples per pixel,
  /// several times slower).
  int supersampling = 1;
  /// Hershey font scale of the panel and caption; 0 = from the image height
  /// (0.48 at 480 rows, 0.72 at 720). At most 10.
  double font_scale = 0;
  /// Vertex-clustering cell (metres) to simplify, once in the constructor,
  /// a model with more than `max_display_faces` faces; 0 (default) draws the
  /// model as given. Meant for dense or open surfaces: a closed,
  /// outward-facing model is already drawn front faces only, and clustering
  /// opens it where it collapses detail, so a simplified model is drawn with
  /// all its faces (on the 107k-face sample, 3 mm gives 69k faces and no
  /// gain over culling). The silhouette moves by up to about half a cell.
  double display_cell_m = 0;
  int max_display_faces = 60000;  ///< simplify only above this many faces
  /// Draw the correction panel in the top-left corner; false when the numbers
  /// are shown elsewhere (the GUI's correction panel). The caption is drawn
  /// either way when given.
  bool correction_panel = true;

  /// Empty if valid, else "field: problem".
  std::string Validate() const;
};

/// BGR colours of the overlay, for legends and tests.
cv::Scalar OverlayCurrentColor();                     ///< red
cv::Scalar OverlayPlannedColor();                     ///< blue (fill)
cv::Scalar OverlayPlannedOutlineColor();              ///< light blue (outline)
cv::Scalar OverlayStateColor(CorrectionState state);  ///< in: green, out: amber, lost: red

/// Draws overlays for one camera and one model; build once per tracked
/// sequence (the constructor prepares the model and the distortion maps).
class OverlayRenderer {
 public:
  /// Prepares `model` (model frame, metres; vertex normals computed if it has
  /// none) for drawing and, if `intrinsics` has distortion, the map from the
  /// distorted image into the ideal one. Throws arpos::Error if `model` has
  /// no faces, `intrinsics` or `options` are invalid.
  OverlayRenderer(const TriangleMesh& model, const CameraIntrinsics& intrinsics,
                  const OverlayOptions& options = {});

  /// A copy of `colour_bgr` (CV_8UC3 BGR, intrinsics.width x height; throws
  /// arpos::Error otherwise) with the model at either pose that is present
  /// (an absent pose is not drawn), the correction panel in the top-left
  /// corner coloured by `correction.state`:
  ///   "LAT +1.2 mm  LNG -0.4 mm  VRT +3.0 mm"
  ///   "PITCH +0.10  ROLL -0.20  YAW +0.05 deg"
  ///   "3.2 +-1.5 mm  0.23 +-0.10 deg  OUT OF TOLERANCE"   (or IN TOLERANCE;
  ///   the bound the state was decided with, SizeAndState)
  /// with, when the state is lost, dashes and `lost_headline` (e.g.
  /// "CAMERA NOT PLACED IN ROOM"; "PATIENT LOST" when empty) as the third
  /// line; and `caption` (if not empty) at the bottom, wrapped at spaces to
  /// the image's width, at most three lines (cut with "..." beyond). Text
  /// sits on a dark translucent panel so it reads on any background; the
  /// panel has a solid stripe of the state's colour (OverlayStateColor)
  /// along its left edge, starting a few pixels from the image's top-left
  /// corner.
  cv::Mat Render(const cv::Mat& colour_bgr, const std::optional<Rigid3d>& camera_from_model_current,
                 const std::optional<Rigid3d>& camera_from_model_planned,
                 const CouchCorrection& correction, const std::string& caption,
                 const std::string& lost_headline = "") const;

  /// Faces actually drawn (after simplification for display).
  int num_display_faces() const { return static_cast<int>(scene_.meshes[0].faces.size()); }

 private:
  // Coverage (CV_32F, [0, 1]) and coverage * shade (CV_32F) of the model at
  // `camera_from_model` in the distorted image.
  void RenderLayer(const Rigid3d& camera_from_model, cv::Mat* coverage, cv::Mat* shaded) const;

  CameraIntrinsics intrinsics_;
  OverlayOptions options_;
  sim::RenderScene scene_;
  // The pinhole camera rendered: the recording's K on a canvas enlarged to
  // cover the distorted image (principal point shifted accordingly).
  CameraIntrinsics ideal_;
  // Distorted pixel -> ideal canvas pixel (CV_16SC2 + CV_16UC1 fixed point
  // maps for cv::remap); empty without distortion.
  cv::Mat map_xy_, map_fraction_;
};

}  // namespace arpos
