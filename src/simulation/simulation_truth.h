#pragma once
/// `simulation.yaml`: what the simulator knows that the case folder does not
/// say (written next to case.yaml by `arpos simulate`; later stages measure
/// marker-map and calibration errors against it).
///
/// Format (YAML; poses are 4x4 row-major matrices `b_from_a` mapping frame a
/// into frame b, metres; corners in OpenCV ArUco order: top-left, top-right,
/// bottom-right, bottom-left of the black square as printed):
///
/// ```yaml
/// format: arpos-simulation-1
/// generator: arpos simulate
/// seed: 42
/// profile: xtion                 # camera profile (sensor: one-line description)
/// sensor: "xtion 640x480 f=540.0 ..."
/// noise: true                    # false: exact renders (no blur/noise/dropouts)
/// hard: false
/// frames: {room: 300, body_scan: 150, tracking: 150, tracking_sequences: 2}
/// room_frame: "..."              # prose: where the room frame is
/// model_frame: "..."
/// isocentre_in_room_m: [x, y, z] # model origin at the target pose
/// room_from_model_target: [16 numbers]     # = target_pose.txt
/// reference_model:
///   file: reference_model.ply
///   noise_sigma_m: 0.0003        # Gaussian along normals
///   max_tessellation_difference_m: 0.0004  # bound, rendered vs reference triangulation
/// couch_top_height_m: 0.8        # at the home (target) pose
/// room_markers:                  # every room marker; parent frame = room
///   - id: 0
///     size_m: 0.15
///     surface: floor             # floor, wall_left/right/foot/head, couch_base
///     room_from_marker: [16 numbers]
///     corners_m: [[x, y, z], [x, y, z], [x, y, z], [x, y, z]]   # in the room frame
/// body_markers:                  # stickers; parent frame = model (they move with it)
///   - id: 137
///     size_m: 0.03
///     surface: chest             # chest, abdomen, thigh_left, thigh_right
///     raise_m: 0.0004            # lift above the skin point (flat sticker on curved skin)
///     model_from_marker: [16 numbers]
///     corners_m: [[x, y, z], ...]                               # in the model frame
/// sequences:                     # in recording order
///   - name: room                 # folder relative to the case
///     frames: 300
///     first_timestamp_s: 10.0
///     frame_interval_s: 0.0333333
///     lighting: planning         # planning | treatment
///     patient: false             # patient and couch-top motion present
///     exposure_stops: [0.12, ...]  # per frame, only with auto exposure
/// hard_effects:                  # present only with --hard (else `hard_effects: {}`)
///   motion_blur: {exposure_s: 0.02, taps: 9}   # every frame of every sequence
///   lighting_change: {from_sequence: body_scan}  # planning -> treatment lighting
///   hand_occluder: {sequence: body_scan, first_frame: 50, last_frame: 99,
///                   first_timestamp_s: ..., last_timestamp_s: ...}
///   sticker_falls_off: {marker_id: 137, sequence: tracking/seq_00, frame: 75,
///                       timestamp_s: ...}   # invisible from this frame on, in all later sequences
/// # The blocks below are present only when in use (absent: the default).
/// camera_response:               # colour camera (camera_response.h)
///   response: linear             # srgb | linear | gamma2.6 | scurve
///   auto_exposure: true
///   exposure_waves: [[f_hz, phase_rad, weight_stops], ...]  # stops(t) = sum w sin(2 pi f t +
///   phase), t = timestamp sharpen_amount: 1.0          # unsharp mask of the encoded codes,
///   Gaussian 1 px (sensor_model.h)
/// depth_bias:                    # z' = z (1 + scale_error) + field_mm_at_1m / 1000 z^2 F(u, v)
/// (sensor_model.h)
///   scale_error: 0.003
///   field_mm_at_1m: 2.5
///   field_seed: 1234             # F = MakeDepthErrorField(width, height, field_seed)
///   flying_pixels: true
/// depth_timing:                  # depth captured after the colour (no hardware sync)
///   delay_s: 0.010               # each depth.txt timestamp = its colour's + delay_s
/// breathing:                     # anterior torso (simulator.h); body_groundtruth is the rigid
/// part
///   amplitude_mm: 4.5            # peak to peak
///   period_s: 3.8
///   phase_rad: 1.1               # displacement = amplitude w(p) cos^4(pi t / period + phase)
///   sticker_weights: {137: 0.98, 150: 0}   # w at each sticker's centre
/// world_from_room: [16 numbers]  # only when the origin marker was moved (world = layout frame,
/// world.h) conditions:                    # only with --random-conditions: what was drawn (flat,
/// one per line)
///   origin_placement: wall       # floor_near_couch | floor_far | wall
///   origin_surface: wall_left
///   origin_visibility: poor      # good | medium | poor (the drawn views)
///   origin_visible_frames: 5     # room frames that see it (geometrically), of
///   room_frames: 60
///   origin_median_side_px: 34.5
///   ...                          # room markers, room, walk, response, depth, breathing, forced
/// ```

#include <array>
#include <filesystem>
#include <string>
#include <vector>

#include "geometry/rigid3.h"

namespace arpos::sim {

struct SimulatedMarker {
  int id = -1;
  double size_m = 0;
  std::string surface;
  double raise_m = 0;
  Rigid3d parent_from_marker;  ///< room_from_marker or model_from_marker
  std::array<Eigen::Vector3d, 4> corners_m;
};

struct SimulatedSequence {
  std::string name;
  int frames = 0;
  double first_timestamp_s = 0;
  double frame_interval_s = 0;
  std::string lighting;
  bool patient = false;
  std::vector<double> exposure_stops;  ///< per frame with auto exposure, else empty
};

struct SimulationTruth {
  uint64_t seed = 0;
  std::string profile;
  std::string sensor;
  bool noise = true;
  bool hard = false;
  std::string room_walk = "full";  ///< planning walk (optional in the file: full)
  std::string room_texture = "rich";  ///< rich or plain (written only when plain; absent: rich)
  int room_frames = 0, body_scan_frames = 0, tracking_frames = 0, tracking_sequences = 0;
  Eigen::Vector3d isocentre_in_room_m = Eigen::Vector3d::Zero();
  Rigid3d room_from_model_target;
  double reference_noise_sigma_m = 0;
  double max_tessellation_difference_m = 0;
  double couch_top_height_m = 0;
  std::vector<SimulatedMarker> room_markers;
  std::vector<SimulatedMarker> body_markers;
  std::vector<SimulatedSequence> sequences;
  // Hard effects (meaningful when hard is true; -1 / empty when absent).
  double motion_blur_exposure_s = 0;
  int motion_blur_taps = 0;
  std::string lighting_change_from_sequence;
  std::string hand_sequence;
  int hand_first_frame = -1, hand_last_frame = -1;
  double hand_first_timestamp_s = 0, hand_last_timestamp_s = 0;
  int sticker_off_marker_id = -1;
  std::string sticker_off_sequence;
  int sticker_off_frame = -1;
  double sticker_off_timestamp_s = 0;
  // Camera response (absent from the file: srgb, fixed exposure).
  std::string response = "srgb";
  bool auto_exposure = false;
  std::vector<std::array<double, 3>> exposure_waves;  ///< frequency_hz, phase_rad, weight_stops
  double sharpen_amount = 0;  ///< the camera's unsharp mask (1 px Gaussian), 0 = none
  // Depth bias (absent: none).
  double depth_scale_error = 0;
  double depth_field_mm_at_1m = 0;
  uint64_t depth_field_seed = 0;
  bool flying_pixels = false;
  double depth_delay_s = 0;  ///< depth captured this long after the colour (absent: 0)
  // Breathing (absent: none).
  double breathing_amplitude_mm = 0, breathing_period_s = 0, breathing_phase_rad = 0;
  std::vector<std::pair<int, double>> sticker_breathing_weights;  ///< marker id, weight
  // A moved origin marker (absent: the world frame is the room frame).
  bool origin_moved = false;
  Rigid3d world_from_room;
  // Drawn scene conditions, key -> value as written (absent: none).
  std::vector<std::pair<std::string, std::string>> conditions;
  /// The value of a condition, or "" if absent.
  std::string Condition(const std::string& key) const;
};

/// Writes the format above atomically.
void SaveSimulationTruth(const SimulationTruth& truth, const std::filesystem::path& path);
/// Reads it back; throws InputError naming the file and key when malformed.
SimulationTruth LoadSimulationTruth(const std::filesystem::path& path);

}  // namespace arpos::sim
