#pragma once
/// Which way each breathing sticker moved during the body scan, measured
/// from the scan's own sticker views.
///
/// Why: the surface's depth (surface_motion.h) tells how far a patch of skin
/// moved along its normal, and until this measurement tracking let each
/// moving sticker rise and fall along its normal. A chest does not
/// necessarily rise along each sticker's normal (a sticker on the flank of
/// the chest rises with it while its normal points sideways), and where it
/// does not, the part of the motion across the normal turns the tracked
/// pose with the breathing (measured on a simulated l515 case with 5.8 mm of
/// breathing: the pose's pitch followed it by up to 0.25 deg, where the
/// motion's own direction left 0.02 deg). A sticker's corners see its motion
/// across the line of sight to a few hundredths of a millimetre per view,
/// so the direction is in the recording.
///
/// How: in every view whose camera was placed without the stickers (the
/// views the sticker map is fitted to), each moving sticker's displacement
/// from its mapped place (a translation in the room frame, from its four
/// corners with the camera held fixed: a 3 x 3 least-squares step, weighted
/// by each corner's noise, plus an isotropic floor for the view's own pose
/// error). The stickers breathe with one time course: displacement of
/// sticker s in view k = c_s + v_s * beta_k, beta of unit RMS over the
/// views, fitted alternately (c_s and v_s per sticker given beta, then beta
/// per view given them). v_s is the sticker's motion (1 sigma over the scan)
/// and its direction; the sign is chosen so that the stickers rise, on
/// average, out of their faces. A sticker whose direction is not well
/// determined (too few views, motion under `min_motion_sigmas` times its
/// standard error or explaining less than `min_explained_ratio` times the
/// scatter it leaves, or a direction uncertain by more than
/// `max_direction_sigma_deg`, or a share along the normal that the surface's
/// depth contradicts) keeps the normal, as before.
///
/// Units: metres, degrees where named; frames as named (room, marker).

#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "body_model/body_marker_map.h"
#include "sensor/intrinsics.h"

namespace arpos {

struct StickerMotionOptions {
  double marker_size_m = 0.03;
  /// Floor on a corner's noise (px); the detector's own estimate when larger.
  double min_corner_sigma_px = 0.1;
  /// What a view's own pose error adds to each displacement (1 sigma, m,
  /// isotropic): the views are registered to the reconstruction to about
  /// this at the stickers.
  double view_sigma_m = 0.0004;
  /// A view whose corners, after the displacement, still miss by more than
  /// this (RMS, px) is left out (a hand over the sticker, a bad read).
  double max_view_rms_px = 2.0;
  int min_views = 6;
  double min_motion_sigmas = 4;
  /// The sticker's motion must explain this many times the scatter left
  /// about it (whitened: the fitted motion's chi-square over the
  /// residuals'): with a time course fitted to the views, noise alone (each
  /// view's own pose error, shared by its stickers) fits as a "motion" well
  /// above its standard error, but explains about as much as it leaves.
  double min_explained_ratio = 1.2;
  /// The motion's share along the sticker's normal must agree with what the
  /// depth of the surface under it measured (surface_motion.h), to this
  /// fraction of that plus 2 of its own sigmas, and be known to this
  /// fraction of it. A view's own pose error is
  /// shared by the stickers it sees and fits as a time course too (as can a
  /// bias that changes with the viewpoint along the camera's path); the
  /// surface, measured by depth, does not share it.
  double max_normal_disagreement = 0.5;
  double max_direction_sigma_deg = 20;
  int iterations = 30;
  std::string Validate() const;
};

struct StickerMotionEstimate {
  int marker_id = -1;
  bool ok = false;  ///< the direction is determined (else: why_not)
  std::string why_not;
  int views = 0;
  /// Unit direction of the motion in the sticker's own frame ((0, 0, 1): its
  /// normal); as the rise goes, on average out of the stickers' faces.
  Eigen::Vector3d direction_in_marker = Eigen::Vector3d::UnitZ();
  double motion_m = 0;        ///< 1 sigma over the scan's views, along the direction
  double motion_sigma_m = 0;  ///< its standard error
  double direction_sigma_deg = 0;
  double angle_to_normal_deg = 0;
  double explained_ratio = 0;  ///< the motion's chi-square over the residuals'
  double normal_share_m =
      0;  ///< the motion's share along the normal (the surface measured `normal_motion_m`)
};

struct StickerMotion {
  std::vector<StickerMotionEstimate> stickers;  ///< one per moving sticker asked for, by id
  int views = 0;                                ///< views with at least one moving sticker
  /// For people: "directions of 4 of 5 moving stickers measured (34-61 deg
  /// from their normals)", or why none.
  std::string Describe() const;
};

/// Measures as in the file comment. `views`: the scan's views with their
/// cameras in the room frame of `map`, placed on the still anatomy;
/// `normal_motion_m`: per sticker that moved, how far the surface under it
/// moved along its normal (1 sigma, m; SurfaceMotion::MotionAt); the others
/// are left out. Throws arpos::Error for invalid options.
StickerMotion EstimateStickerMotion(const std::vector<BodyScanView>& views,
                                    const BodyMarkerMapResult& map, const CameraIntrinsics& camera,
                                    const std::map<int, double>& normal_motion_m,
                                    const StickerMotionOptions& options = {});

}  // namespace arpos
