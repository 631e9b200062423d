#pragma once
/// The planning-stage map of the treatment room, in memory.
///
/// Frames: everything is in the room frame, the frame of the origin marker
/// (DATASET.md: `markers.room.origin_id`; OpenCV ArUco marker frame: origin at
/// the printed centre, x right, y up, z out of the printed face). Metres.
///
/// Two layers:
/// - markers: each room marker's pose `room_from_marker` (its corners follow
///   from the printed side `marker_size_m`, OpenCV ArUco corner order), with
///   its mean reprojection residual over the room sequence;
/// - keypoint landmarks: 3D points with one binary (ORB, 32-byte) descriptor
///   each, for localising the camera where few markers are visible.
///
/// The store keeps a map as a RoomMapRecord (store/records.h); ToRecord and
/// FromRecord convert losslessly except for what the record cannot hold
/// (per-landmark observation counts and the build report).

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "features/camera_response.h"
#include "features/marker_observation.h"
#include "geometry/rigid3.h"
#include "room_map/room_surface.h"
#include "sensor/depth_correction.h"
#include "store/records.h"

namespace arpos {

/// ORB descriptor length in bytes.
constexpr int kDescriptorBytes = 32;

/// An oriented box in the room: landmarks inside it are left out of the map
/// (room_map_builder.h), and the localiser does not follow the room by
/// keypoints inside it (camera_localizer.h).
struct ExclusionBox {
  Rigid3d room_from_box;
  Eigen::Vector3d half_extent_m = Eigen::Vector3d::Zero();
  bool Contains(const Eigen::Vector3d& point_in_room) const {
    const Eigen::Vector3d p = room_from_box.Inverse() * point_in_room;
    return (p.cwiseAbs() - half_extent_m).maxCoeff() <= 0;
  }
};

/// The couch top and everything on it move during positioning: a box about
/// the treatment isocentre, in the reference-model frame at its target pose
/// (patient axes as DICOM LPS: x left, y posterior, z superior). Defaults:
/// 0.45 m either side, from 0.6 m anterior to 0.3 m posterior (below the
/// couch top), 1.4 m head- and footwards.
ExclusionBox CouchExclusionBox(const Rigid3d& room_from_model_target,
                               double half_width_m = 0.45, double anterior_m = 0.6,
                               double posterior_m = 0.3, double half_length_m = 1.4);

struct RoomMapMarkerEntry {
  int id = -1;
  Rigid3d room_from_marker;
  std::array<Eigen::Vector3d, 4> corners_in_room{};  ///< ArUco corner order
  double residual_px = 0;  ///< RMS reprojection residual of its corners over the room sequence
  int num_observations = 0;
};

struct RoomMap {
  int origin_marker_id = 0;
  double marker_size_m = 0;
  std::vector<RoomMapMarkerEntry> markers;  ///< sorted by id, ids unique
  /// Landmark positions in the room frame and, row for row, their descriptors
  /// (CV_8UC1, kDescriptorBytes columns). Both empty without a keypoint layer.
  /// Order: the landmarks of the joint adjustment first (the best-supported,
  /// spread over the room), then those placed afterwards for localisation
  /// only (room_map_builder.h); a prefix is a fair sample of the room.
  std::vector<Eigen::Vector3d> landmarks_in_room;
  cv::Mat landmark_descriptors;
  /// The first this many landmarks came from a session's body scan
  /// (scan_landmarks.h: AddScanLandmarks), not from the room recording; 0
  /// for a map as planned. Not stored with the map.
  int scan_landmarks = 0;
  /// Their position uncertainty each (1 sigma, m): the localiser weights
  /// them by it.
  double scan_landmark_sigma_m = 0;
  double mean_residual_px = 0;  ///< marker corners, over all markers and views
  double max_residual_px = 0;   ///< largest per-marker residual
  /// The response of the camera that recorded the room (estimated from its
  /// markers, else assumed): the fallback for later recordings whose own
  /// markers cannot tell.
  CameraResponse camera_response = CameraResponse::Srgb();
  /// The depth camera's systematic error measured against the room's markers
  /// (identity when the depth agreed): removed from later recordings' depth.
  DepthCorrection depth_correction;
  /// The room's still surface near the couch as the room recording's depth
  /// showed it (room_surface.h); empty for maps stored before it was kept.
  RoomSurface surface;

  /// The marker with this id, or nullptr.
  const RoomMapMarkerEntry* FindMarker(int id) const;
  int num_landmarks() const { return static_cast<int>(landmarks_in_room.size()); }

  /// Empty if consistent, else what is wrong (ids unique and sorted, origin
  /// present, sizes and descriptor rows matching, finite numbers).
  std::string Validate() const;
};

/// The marker's corners in the room frame from its pose and side length.
std::array<Eigen::Vector3d, 4> MarkerCornersInRoom(const Rigid3d& room_from_marker,
                                                   double marker_size_m);

/// Pixel noise (1 sigma) to weight a marker corner with. Edge-fit corners of
/// markers whose code cells are small in the image (far or oblique markers)
/// carry a systematic inward bias, measured on simulated cases at 0.03-0.05 px
/// for 20-30 px markers seen at 45-75 deg and up to 0.16 px beyond (0.4 % of
/// scale, i.e. mm at 2 m), far above their noise. So the sigma grows with the
/// inverse square of the smallest projected cell:
///   sigma = max(floor_px, observation sigma) * (1 + (reference_cell_px / cell_px)^2),
/// cell_px = shortest side of the corner quadrilateral / cells_per_side
/// (6 for 4x4 markers: 4 data cells and 2 border cells).
double MarkerCornerSigmaPx(const MarkerObservation& observation, int corner, double floor_px,
                           double reference_cell_px, int cells_per_side = 6);

/// ORB descriptors (CV_8UC1, kDescriptorBytes columns) as the store keeps
/// them, and back; row for row.
ByteMatrix DescriptorsToBytes(const cv::Mat& descriptors);
cv::Mat DescriptorsFromBytes(const ByteMatrix& bytes);

/// Converts for the store; `plan` becomes the record's plan_id.
RoomMapRecord ToRecord(const RoomMap& map, PlanId plan,
                       std::optional<RecordingId> recording = std::nullopt);
/// Converts a stored map back. Marker poses are recovered from the stored
/// corners (least squares, Kabsch). Throws InputError if the record is not a
/// usable map (no markers, origin missing, malformed descriptors).
RoomMap FromRecord(const RoomMapRecord& record);

}  // namespace arpos
