#pragma once
/// Room landmarks seen by the body scan: keypoints of the room around the
/// couch (floor, couch base, walls beside it) placed from the scan's frames,
/// whose poses the session has settled, for tracking to localise the camera
/// by.
///
/// Why: the room recording walks the room from a distance; tracking and the
/// body scan look at the patient from close by, where the map may hold few
/// landmarks (measured: a d435 case whose room walk passed 0.9 m behind the
/// tracking camera's viewpoint, 96 of 150 frames without a room pose: 11-14
/// keypoints matched where 25 are needed). The scan sees the same views as
/// tracking will.
///
/// How: every keypoint with depth of a posed frame is put in the room; those
/// of other frames are searched for around its projection (descriptor
/// distance, ratio test) and joined; each group seen in at least
/// `triangulation.min_observations` frames is placed by
/// TriangulateLandmark against the frames' poses (held fixed) and kept
/// outside the exclusion boxes (the couch and the patient move during
/// tracking). Descriptor: the medoid of its inliers.
///
/// The landmarks inherit the scan's placement in the room (the session's
/// `room placement` sigma): a camera placed by them alone places the patient
/// as the session did.
///
/// Frames: room (DATASET.md); cameras OpenCV; metres.

#include <Eigen/Core>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "geometry/rigid3.h"
#include "room_map/keypoints.h"
#include "room_map/landmark_triangulation.h"
#include "room_map/room_map.h"
#include "sensor/intrinsics.h"
#include "store/records.h"

namespace arpos {

/// One posed frame: its pose and keypoints (KeypointExtractor, on depth the
/// room map's correction has been applied to).
struct ScanLandmarkFrame {
  Rigid3d room_from_camera;
  KeypointSet keypoints;
};

struct ScanLandmarkOptions {
  /// The frames' poses, not the keypoints, limit how well the views agree:
  /// weighted and gated as 1.5 px (measured against the same keypoints
  /// placed from the true poses on three random-conditions cases: 0.7 px
  /// gave 2.3-4.3 mm median error, 1.5 px 1.8-2.8 mm).
  ScanLandmarkOptions() {
    triangulation.keypoint_sigma_px = 1.5;
    triangulation.outlier_sigmas = 3;
  }
  LandmarkTriangulationOptions triangulation;
  /// A keypoint of another frame within this radius of the projection joins.
  double search_radius_px = 6;
  int max_hamming = 50;
  double match_ratio = 0.8;
  /// Keypoints read farther than this are left out (depth noise grows with z^2).
  double max_depth_m = 3.0;
  /// Left out: what moves during tracking (CouchExclusionBox about the
  /// planned pose and about the pose at scan time).
  std::vector<ExclusionBox> exclude;
  int max_landmarks = 4000;
  /// A landmark the room map already holds (one of its landmarks within
  /// this distance, descriptors within this Hamming distance) is left out:
  /// the room's is placed more surely, and two landmarks for one point
  /// would take each other's matches.
  double duplicate_radius_m = 0.03;
  int duplicate_max_hamming = 64;

  std::string Validate() const;
};

struct ScanLandmarks {
  std::vector<Eigen::Vector3d> points_in_room;
  cv::Mat descriptors;  ///< CV_8UC1, one kDescriptorBytes row per point
  int frames = 0;       ///< posed frames offered
  int groups = 0;       ///< keypoint groups seen in enough frames
  int duplicates = 0;   ///< placed, but the room map holds them already
  /// How well the frames' poses are placed in the room together (the
  /// session's placement of the scan, 1 sigma, m): the landmarks carry it.
  /// Set by the caller.
  double placement_sigma_m = 0;
  /// How far each landmark's views disagree sideways at their distance (RMS
  /// reprojection residual times depth over focal length, m), median over
  /// the landmarks.
  double spread_m = 0;
  int size() const { return static_cast<int>(points_in_room.size()); }
};

/// `room_map`: the map tracking will use with them (may be null).
ScanLandmarks PlaceScanLandmarks(const std::vector<ScanLandmarkFrame>& frames,
                                 const CameraIntrinsics& K, const ScanLandmarkOptions& options,
                                 const RoomMap* room_map = nullptr);

/// Into the body marker map's record, for the store.
void ToRecord(const ScanLandmarks& landmarks, BodyMarkerMapRecord* record);

/// The scan landmarks a body marker map's record holds put first among
/// `map`'s landmarks (the localiser's relocalisation matches a prefix of
/// them: those near the couch, where tracking looks, come first). Returns
/// how many; throws InputError naming the map when its points and
/// descriptors disagree.
int AddScanLandmarks(const BodyMarkerMapRecord& record, RoomMap* map);

}  // namespace arpos
