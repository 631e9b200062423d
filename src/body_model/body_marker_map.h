#pragma once
/// Body marker map: the poses of the small ArUco stickers on the patient,
/// estimated from the session's body scan.
///
/// The patient lies still during the scan and every frame's camera is
/// localised in the room map, so each sticker is estimated directly in the
/// room frame: `room_from_marker` with the cameras held fixed. The body frame
/// of the session (store/records.h) is the room frame during the scan, so
/// `body_from_marker` = `room_from_marker` at scan time.
///
/// Per sticker: single-view poses (IPPE, disambiguated and refined by depth,
/// features/marker_pose.h) give candidates in the room; the candidate that
/// reprojects best over all views starts a robust least-squares fit (Ceres)
/// of the corner reprojections in every view, weighted by each corner's
/// uncertainty, plus a depth term (the sticker centre on the depth plane
/// measured inside it) whose weight is capped because depth errors are partly
/// systematic. Views that disagree (a hand over the sticker, a flipped pose, a
/// sticker that moved) are rejected and the fit repeated.

#include <array>
#include <map>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "features/marker_detector.h"
#include "features/marker_pose.h"
#include "geometry/rigid3.h"
#include "sensor/intrinsics.h"
#include "sensor/rgbd_frame.h"

namespace arpos {

/// One sticker seen in one frame.
struct BodyMarkerView {
  int marker_id = -1;
  std::array<Eigen::Vector2d, 4> corners_px{};
  std::array<double, 4> corner_sigma_px{{0.05, 0.05, 0.05, 0.05}};
  MarkerPose single_view;  ///< camera_from_marker from this view alone
};

/// One frame of the body scan: its camera pose in the room and its stickers.
struct BodyScanView {
  int frame_index = -1;
  double timestamp_s = 0;
  Rigid3d room_from_camera;
  std::vector<BodyMarkerView> markers;
};

struct BodyMarkerMapOptions {
  double marker_size_m = 0.03;
  /// A sticker needs this many consistent views to enter the map.
  int min_views = 3;
  /// Floor for each corner's 1-sigma noise (px); the detector's own estimate
  /// is used when larger.
  double min_corner_sigma_px = 0.05;
  /// Huber threshold on normalised corner residuals (in sigmas).
  double huber_sigmas = 3.0;
  /// After the fit, a view whose corner RMS exceeds max(this, 4 x the median
  /// view RMS) is rejected and the fit repeated.
  double max_view_rms_px = 0.75;
  bool use_depth = true;
  double depth_sigma_m = 0.0015;
  /// Cap on the weight of all depth terms of one sticker, as a number of
  /// independent views (depth bias does not average out).
  int depth_max_effective_views = 5;
  int max_iterations = 50;

  std::string Validate() const;
};

struct BodyMarkerEstimate {
  int marker_id = -1;
  Rigid3d room_from_marker;
  int num_views = 0;           ///< views used in the final fit
  int num_rejected_views = 0;
  double rms_px = 0;           ///< corner reprojection RMS over the used views
  double max_view_rms_px = 0;
  double depth_rms_mm = 0;     ///< centre-to-depth-plane RMS (0 without depth)
  /// 1-sigma position uncertainty of the marker centre from the fit (mm).
  double position_sigma_mm = 0;
};

struct BodyMarkerMapResult {
  std::vector<BodyMarkerEstimate> markers;  ///< sorted by id
  /// Stickers seen but left out, with the reason (too few views, ambiguous).
  std::map<int, std::string> rejected;
  int views_used = 0;
  double mean_rms_px = 0;
  double max_rms_px = 0;
  bool ok() const { return !markers.empty(); }
};

/// Detects stickers in one frame (detector restricted to the body ids) and
/// computes each one's single-view pose with depth.
BodyScanView MakeBodyScanView(const RgbdFrame& frame, const Rigid3d& room_from_camera,
                              MarkerDetector* detector, const CameraIntrinsics& intrinsics,
                              double marker_size_m, const MarkerPoseOptions& pose_options = {});

/// Estimates every sticker seen in `views`. Never throws for bad data: a
/// sticker that cannot be estimated is listed in `rejected`.
BodyMarkerMapResult BuildBodyMarkerMap(const std::vector<BodyScanView>& views,
                                       const CameraIntrinsics& intrinsics,
                                       const BodyMarkerMapOptions& options = {});

/// The camera of a body-scan frame posed from stickers already in the map
/// (the patient lies still during the scan, so mapped stickers are fixed in
/// the room). For frames the room map cannot localise (the camera close over
/// the body, no room marker or room texture in view): they still add
/// stickers and depth to the session.
struct StickerLocalizationOptions {
  /// Mapped stickers needed in the frame: one 3 cm sticker fixes the camera's
  /// rotation poorly, two or more spread over the body do not.
  int min_markers = 2;
  /// Accepted corner reprojection RMS (px) over the stickers used; a sticker
  /// whose own RMS exceeds it is dropped (moved, misdetected) and the pose
  /// solved again.
  double max_rms_px = 1.0;
};

struct StickerLocalization {
  bool ok = false;
  Rigid3d room_from_camera;
  int num_markers = 0;  ///< mapped stickers used
  double rms_px = 0;
  std::string reason;  ///< why not, when !ok
};

/// `view`: the frame's stickers as MakeBodyScanView returns them (its
/// room_from_camera is ignored). `map`: stickers in the room frame.
StickerLocalization LocalizeFromStickers(const BodyScanView& view, const BodyMarkerMapResult& map,
                                         double marker_size_m, const CameraIntrinsics& intrinsics,
                                         const StickerLocalizationOptions& options = {});

}  // namespace arpos
