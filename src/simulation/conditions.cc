#include "simulation/conditions.h"

#include <algorithm>
#include <cmath>

#include "geometry/so3.h"
#include "simulation/random.h"

namespace arpos::sim {
namespace {

constexpr double kPaperOffsetM = 0.0003;  // markers stand off walls by this (world.cc)

// Marker pose from its centre, the normal out of its face and its up axis.
Rigid3d MarkerPose(const Eigen::Vector3d& centre, const Eigen::Vector3d& normal,
                   const Eigen::Vector3d& up) {
  const Eigen::Vector3d z = normal.normalized();
  const Eigen::Vector3d y = (up - up.dot(z) * z).normalized();
  Eigen::Matrix3d r;
  r.col(0) = y.cross(z);
  r.col(1) = y;
  r.col(2) = z;
  return Rigid3d(r, centre);
}

}  // namespace

SceneConditions DrawSceneConditions(uint64_t seed) {
  Rng rng(StreamSeed(seed, Stream::kConditions));
  SceneConditions c;
  // Every draw is made whatever the earlier ones gave, in a fixed order, so
  // one condition forced on the command line leaves the others as drawn.
  RoomLayout& lay = c.layout;
  lay.wall_left_x_m = rng.Uniform(-2.4, -1.5);
  lay.wall_right_x_m = rng.Uniform(3.0, 4.0);
  lay.wall_foot_y_m = rng.Uniform(-2.2, -1.4);
  lay.wall_head_y_m = rng.Uniform(4.5, 5.3);
  lay.ceiling_z_m = rng.Uniform(2.75, 3.3);

  // Origin marker.
  const double placement = rng.Uniform();
  const double spot = rng.Uniform(), along = rng.Uniform(), across = rng.Uniform();
  const double height = rng.Uniform(0.9, 1.7);
  const double yaw = rng.Uniform(-M_PI, M_PI), roll = RadFromDeg(rng.Uniform(-10, 10));
  const double jx = rng.Uniform(-0.1, 0.1), jy = rng.Uniform(-0.1, 0.1);
  const Eigen::Vector3d up_z(0, 0, 1);
  const Eigen::Vector3d floor_up = Eigen::AngleAxisd(yaw, up_z) * Eigen::Vector3d(0, 1, 0);
  const double cx = kCouchCentreX_m;
  if (placement < 0.4) {
    c.origin_placement = "floor_near_couch";
    c.origin_surface = "floor";
    c.world_from_origin_marker =
        MarkerPose(Eigen::Vector3d(2 * jx, 0.2 * across - 0.05 + jy, 0), up_z, floor_up);
  } else if (placement < 0.7) {
    c.origin_placement = "floor_far";
    c.origin_surface = "floor";
    const double m = 0.45;  // from the walls
    Eigen::Vector3d centre;
    if (spot < 0.2) {
      centre = {lay.wall_left_x_m + m, lay.wall_foot_y_m + m, 0};
    } else if (spot < 0.4) {
      centre = {lay.wall_right_x_m - m, lay.wall_foot_y_m + m, 0};
    } else if (spot < 0.6) {
      centre = {lay.wall_left_x_m + m, 0.5 + 2.5 * along, 0};
    } else if (spot < 0.8) {
      centre = {lay.wall_right_x_m - m, 0.5 + 2.5 * along, 0};
    } else {
      centre = {cx - 0.5 + along, lay.wall_foot_y_m + m, 0};
    }
    centre += Eigen::Vector3d(jx, jy, 0);
    c.world_from_origin_marker = MarkerPose(centre, up_z, floor_up);
  } else {
    c.origin_placement = "wall";
    Eigen::Vector3d centre, normal;
    if (spot < 0.3) {
      c.origin_surface = "wall_left";
      centre = {lay.wall_left_x_m + kPaperOffsetM, -0.8 + 4.0 * along, height};
      normal = {1, 0, 0};
    } else if (spot < 0.6) {
      c.origin_surface = "wall_right";
      centre = {lay.wall_right_x_m - kPaperOffsetM, -0.8 + 4.0 * along, height};
      normal = {-1, 0, 0};
    } else if (spot < 0.85) {
      c.origin_surface = "wall_foot";
      centre = {lay.wall_left_x_m + 0.5 + along * (lay.wall_right_x_m - lay.wall_left_x_m - 1.0),
                lay.wall_foot_y_m + kPaperOffsetM, height};
      normal = {0, 1, 0};
    } else {
      // Beside the gantry (x within 0.9 m of the couch centre line).
      c.origin_surface = "wall_head";
      const double x = along < 0.5 ? lay.wall_left_x_m + 0.4 + 2 * along * (cx - 1.1 - lay.wall_left_x_m - 0.4)
                                   : cx + 1.1 + (2 * along - 1) * (lay.wall_right_x_m - 0.4 - cx - 1.1);
      centre = {x, lay.wall_head_y_m - kPaperOffsetM, height};
      normal = {0, -1, 0};
    }
    c.world_from_origin_marker =
        MarkerPose(centre, normal, Eigen::AngleAxisd(roll, normal) * up_z);
  }
  const double visibility = rng.Uniform();
  c.origin_visibility = visibility < 0.4 ? "good" : visibility < 0.7 ? "medium" : "poor";

  // Room markers: one size; 6-24 places, the four beside the couch always.
  c.room_marker_size_m = std::round(rng.Uniform(0.10, 0.20) * 100) / 100;
  const int count = rng.UniformInt(6, kRoomMarkerPlaces);
  c.room_marker_places.assign(kRoomMarkerPlaces, false);
  const int beside_couch[4] = {0, 4, 8, 9};  // floor left/right of the couch middle, couch base sides
  std::vector<int> others;
  for (int i = 0; i < kRoomMarkerPlaces; ++i) {
    if (std::find(std::begin(beside_couch), std::end(beside_couch), i) == std::end(beside_couch)) {
      others.push_back(i);
    }
  }
  for (size_t i = others.size() - 1; i > 0; --i) {
    std::swap(others[i], others[rng.UniformInt(0, static_cast<int>(i))]);
  }
  for (int i : beside_couch) c.room_marker_places[i] = true;
  for (int k = 0; k < count - 4; ++k) c.room_marker_places[others[k]] = true;

  // Camera paths and pace.
  c.room_walk = rng.Uniform() < 0.5 ? "full" : "couch";
  c.room_duration_s = rng.Uniform(14, 36);
  c.body_scan_duration_s = rng.Uniform(8, 16);
  c.path_jitter_m = rng.Uniform(0.04, 0.12);

  // Sensor.
  c.response = AllResponses()[rng.UniformInt(0, 3)];
  c.auto_exposure = rng.Uniform() < 0.3;
  const double scale_draw = rng.Uniform(), scale = rng.Uniform(-0.006, 0.006);
  c.depth_scale_error = scale_draw < 0.6 ? std::round(scale * 1e5) / 1e5 : 0.0;
  const double field_draw = rng.Uniform(), field = rng.Uniform(1, 4);
  c.depth_field_mm = field_draw < 0.5 ? std::round(field * 100) / 100 : 0.0;
  c.flying_pixels = rng.Uniform() < 0.5;

  // Patient.
  const double breathing_draw = rng.Uniform(), breathing = rng.Uniform(3, 6);
  c.breathing_mm = breathing_draw < 0.7 ? std::round(breathing * 100) / 100 : 0.0;

  // Colour-depth sync.
  const double delay_draw = rng.Uniform(), delay = rng.Uniform(2, 15), sign = rng.Uniform();
  c.depth_delay_ms = delay_draw < 0.4 ? (sign < 0.5 ? -1 : 1) * std::round(delay * 10) / 10 : 0.0;
  return c;
}

}  // namespace arpos::sim
