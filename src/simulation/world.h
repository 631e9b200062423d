#pragma once
/// The simulated treatment room and patient, with exact ground truth.
///
/// Frames (see DATASET.md):
/// - room: the frame of room marker 0 (the origin marker), which lies on the
///   floor beside the couch foot: origin at the centre of its printed face, x
///   and y along the floor, z up. The floor surface is 0.3 mm below (paper).
///   The couch's long axis runs along +y (head end towards +y, where the
///   gantry stands); couch centre line at x = kCouchCentreX_m.
/// - model: the reference model's frame, patient axes as in DICOM LPS
///   (x to the patient's left, y posterior, z superior), origin at the
///   isocentre (inside the torso, upper abdomen, on the midline).
///   `room_from_model_target` lays the patient supine on the couch, head
///   towards +y.
/// - marker: OpenCV ArUco (origin at the black square's centre, x right, y up,
///   z out of the printed face); corners in ArUco order: top-left, top-right,
///   bottom-right, bottom-left, i.e. (-s/2, s/2), (s/2, s/2), (s/2, -s/2),
///   (-s/2, -s/2) in the marker frame.
/// - hand: the occluder's own frame (capsule along x).
///
/// The world frame. Everything in World is built in the *world* frame: the
/// room's layout frame (floor at z = -0.0003, z up, couch as above). It is
/// the case's room frame when the origin marker lies at its standard place
/// (WorldOptions::world_from_origin_marker = identity, the default); when
/// random scene conditions move the origin marker elsewhere (farther on the
/// floor, on a wall), the room frame is that marker's frame and the Simulator
/// converts every output (World::room_from_world). The `room_*` names of
/// World's members below mean this world frame.
///
/// The couch top moves with the patient (the couch does the positioning):
/// its meshes are stored in the model frame, at their home place for the
/// target pose. The couch base, floor, walls, gantry and room markers are
/// static in the room frame.

#include <array>
#include <filesystem>
#include <string>
#include <vector>

#include "geometry/rigid3.h"
#include "geometry/triangle_mesh.h"
#include "simulation/render_scene.h"

namespace arpos::sim {

/// The couch's centre line (world x, metres) and its top's extent along y.
inline constexpr double kCouchCentreX_m = 0.75;
inline constexpr double kCouchFootY_m = 0.25, kCouchHeadY_m = 2.30;

/// Labels written by the rasteriser (RenderInstance::label).
enum Label : int { kLabelNone = 0, kLabelRoom = 1, kLabelCouchTop = 2, kLabelBody = 3,
                   kLabelSticker = 4, kLabelHand = 5 };

struct MarkerTruth {
  int id = -1;
  double size_m = 0;               ///< black square side
  std::string frame;               ///< "room" or "model": the parent frame
  std::string surface;             ///< floor, wall_*, couch_base, chest, abdomen, thigh_*
  Rigid3d parent_from_marker;      ///< room_from_marker or model_from_marker
  std::array<Eigen::Vector3d, 4> corners_m;  ///< in the parent frame, ArUco order
  double raise_m = 0;              ///< body stickers: lift above the skin point
};

/// Walls and ceiling of the room, world frame (defaults: the standard room).
/// The couch, gantry and floor markers beside the couch do not move with
/// them: left wall < -1.2, right wall > 2.8, foot wall < -1.2, head wall >
/// 4.45, ceiling > 2.75 keep them inside.
struct RoomLayout {
  double wall_left_x_m = -1.9, wall_right_x_m = 3.4;
  double wall_foot_y_m = -1.7, wall_head_y_m = 4.7;
  double ceiling_z_m = 2.8;
  /// Empty if valid, else the problem.
  std::string Check() const;
};

/// Number of standard places for room markers besides the origin marker's
/// (floor around the couch, couch base, walls); WorldOptions::room_marker_places.
inline constexpr int kRoomMarkerPlaces = 25;

struct WorldOptions {
  uint64_t seed = 1;
  std::filesystem::path body_mesh_path;  ///< MakeHuman base.obj
  RoomLayout layout;
  /// The origin marker (room marker 0): its pose in the world frame and the
  /// surface it is on (floor, wall_left, ...). Identity: on the floor beside
  /// the couch foot, where the world frame is the room frame.
  Rigid3d world_from_origin_marker;
  std::string origin_surface = "floor";
  /// Which standard places (kRoomMarkerPlaces) carry a room marker; empty: all.
  std::vector<bool> room_marker_places;
  double room_marker_size_m = 0.15;
  double body_marker_size_m = 0.03;
  /// The room's walls, floor, ceiling, gantry and couch base with little
  /// texture (textures.h, TextureDetail::kPlain) instead of a cluttered room.
  bool plain_room = false;
  /// OpenCV predefined ArUco dictionary (cv::aruco::PREDEFINED_DICTIONARY_NAME)
  /// of every marker: room ids 0-49, stickers 100-199.
  int dictionary = 2;  // DICT_4X4_250
  int min_stickers = 10, max_stickers = 16;  ///< inclusive, within 8..20
  double reference_noise_m = 0.0003;         ///< sigma along normals
  /// Quads whose two triangulations differ by more keep their diagonal.
  double max_tessellation_difference_m = 0.0003;
};

struct World {
  RenderScene scene;
  /// Mesh indices by where they live.
  std::vector<int> room_meshes;       ///< static, room frame (markers included)
  std::vector<int> couch_top_meshes;  ///< model frame (moves with the patient)
  int body_mesh = -1;                 ///< model frame
  std::vector<int> sticker_meshes;    ///< model frame, parallel to body_markers
  int hand_mesh = -1;                 ///< hand frame

  std::vector<MarkerTruth> room_markers;
  std::vector<MarkerTruth> body_markers;

  /// The surface the rasteriser draws for the body (model frame).
  TriangleMesh body_surface;
  /// reference_model.ply: the same surface re-tessellated (the other
  /// diagonal of every nearly planar quad, then one midpoint subdivision) with
  /// Gaussian noise along normals (model frame).
  TriangleMesh reference_model;
  /// Bound on how far the reference's tessellation departs from the rendered
  /// surface (before noise), m, and the share of quads re-triangulated.
  double max_tessellation_difference_m = 0;
  double flipped_quad_fraction = 0;

  Rigid3d room_from_model_target;
  Eigen::Vector3d couch_top_home_centre_room_m;  ///< top surface centre at home
  double couch_top_height_m = 0;                 ///< above the floor (world z)
  RoomLayout layout;
  /// room_from_world: identity unless the origin marker was moved.
  Rigid3d room_from_world;
  bool origin_moved = false;  ///< world_from_origin_marker was not the identity
  /// Solid boxes that can hide a room marker (gantry, couch base, couch top
  /// at home), world frame: (min corner, max corner).
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> occluders;

  /// Breathing: the share (0..1) of the anterior torso's breathing motion
  /// that a body-surface point follows, model frame. 1 on the front of the
  /// chest and abdomen; falling smoothly to 0 towards the pelvis (height
  /// fraction 0.58 -> 0.52 of the body), the neck (0.76 -> 0.82), the sides
  /// (|x| 0.09 -> 0.16 m) and the back (anterior of the isocentre's coronal
  /// plane by 0.05 -> 0 m); 0 on the back, head, arms and legs.
  double BreathingWeight(const Eigen::Vector3d& point_in_model) const;
  std::vector<float> body_breathing_weight;  ///< per body_surface vertex
  double body_lowest_z_m = 0, body_height_m = 1;  ///< model z (superior) range of the body
  Lighting planning_lighting;   ///< room/ (and all sequences unless --hard)
  Lighting treatment_lighting;  ///< body_scan/, tracking/ with --hard
};

/// Builds everything from the seed. Throws InputError naming the body mesh
/// file if it cannot be read.
World BuildWorld(const WorldOptions& options);

/// The four corners of a square marker of side `size_m` in its own frame,
/// ArUco order.
std::array<Eigen::Vector3d, 4> MarkerCornersInMarker(double size_m);

}  // namespace arpos::sim
