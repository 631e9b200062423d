#pragma once
/// Scene conditions drawn at random per seed (`arpos simulate
/// --random-conditions`), so that the pipeline meets cases it was not tuned
/// on: where the origin marker is and how well the room recording sees it,
/// how many room markers of which size, the room's size, the camera's
/// paths and pace, the colour camera's response and exposure, depth bias and
/// breathing. Deterministic: a pure function of the seed (its own random
/// stream, so the other parts of a case draw as without conditions).
///
/// Probabilities (per seed, independent):
/// - origin marker placement: floor_near_couch 0.4 (within 0.2 m of the
///   standard place beside the couch foot, any yaw), floor_far 0.3 (a floor
///   corner or along a wall, 0.45 m from the walls), wall 0.3 (left, right,
///   foot or head wall beside the gantry, 0.9-1.7 m high, roll +-10 deg);
/// - its visibility in room/: good 0.4 (the walk starts and ends looking at
///   it from 1.2-2 m, 10-35 deg off its normal), medium 0.3 (one view from
///   1.6-2.4 m, 35-55 deg), poor 0.3 (one glancing view: the marker 30-40 px
///   wide, 50-70 deg off its normal, off the image centre: a few frames of a
///   60-frame walk, the best at least 25 px (4x4; more for markers of more
///   cells), else the walk is drawn again);
/// - room markers: one size for all (0.10-0.20 m, case.yaml has one), 6-25
///   of the 25 standard places (the four beside the couch always kept: the
///   body scan starts and ends on them);
/// - room: left wall -2.4..-1.5 m, right 3.0..4.0, foot -2.2..-1.4, head
///   4.5..5.3, ceiling 2.75..3.3 (world frame, world.h);
/// - camera: walk full or couch (0.5 each), room recording 14-36 s, body
///   scan 8-16 s, path jitter 0.04-0.12 m;
/// - response: srgb, linear, gamma2.6, scurve (0.25 each); auto exposure 0.3;
/// - depth: scale error +-0.6 % (0.6, else 0), error field 1-4 mm at 1 m
///   (0.5, else 0), flying pixels 0.5;
/// - breathing: 3-6 mm peak to peak (0.7, else none);
/// - colour-depth sync: depth taken 2-15 ms after or before its colour
///   (0.4: a camera without sync, as OpenNI2 cameras without registration;
///   else of the colour's instant). Drawn last: the draws above are as
///   they were before it was added.

#include <cstdint>
#include <string>
#include <vector>

#include "geometry/rigid3.h"
#include "simulation/camera_response.h"
#include "simulation/world.h"

namespace arpos::sim {

struct SceneConditions {
  // Origin marker (room marker 0).
  std::string origin_placement = "floor_near_couch";  ///< floor_near_couch | floor_far | wall
  std::string origin_surface = "floor";               ///< floor | wall_left | wall_right | wall_foot | wall_head
  Rigid3d world_from_origin_marker;                   ///< world frame (world.h)
  std::string origin_visibility = "good";             ///< good | medium | poor
  // Room markers and room.
  double room_marker_size_m = 0.15;
  std::vector<bool> room_marker_places;  ///< kRoomMarkerPlaces entries
  RoomLayout layout;
  // Camera paths and pace.
  std::string room_walk = "full";  ///< full | couch
  double room_duration_s = 24;
  double body_scan_duration_s = 12;
  double path_jitter_m = 0.08;
  // Sensor.
  CameraResponse response = CameraResponse::kSrgb;
  bool auto_exposure = false;
  double depth_scale_error = 0;
  double depth_field_mm = 0;
  bool flying_pixels = false;
  // Patient.
  double breathing_mm = 0;
  // Colour-depth sync: the depth image's instant after its colour's (ms).
  double depth_delay_ms = 0;
};

/// The conditions of `seed` (see the header comment).
SceneConditions DrawSceneConditions(uint64_t seed);

}  // namespace arpos::sim
