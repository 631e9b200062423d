#pragma once
/// The treatment-session simulator behind `arpos simulate`: writes a complete
/// case folder (DATASET.md) with exact ground truth and a simulation.yaml
/// (simulation_truth.h), and renders single frames for tests.
///
/// Sequences, in recording order: room/ (empty room, planning lighting, couch
/// top at home, camera walking around), body_scan/ (patient still near the
/// target, camera sweeping over the couch at 0.6-1.5 m), tracking/seq_NN/
/// (patient moved smoothly by up to +-5 cm / +-5 deg about the target while
/// the camera is hand-held). Timestamps: 30 fps clock; when fewer frames are
/// asked for than a sequence's nominal length (room 24 s, body scan 12 s,
/// tracking 10 s), frames are spaced by a whole number of 1/30 s so the
/// motion keeps a hand-held speed. Ground truth: groundtruth.txt
/// (room_from_camera) for every frame, body_groundtruth.txt
/// (room_from_model) for body_scan and tracking.
///
/// Deterministic: the same options give byte-identical files (any thread count).
///
/// Beyond the default (an sRGB camera with fixed exposure, an unbiased depth
/// sensor, a patient who does not breathe, one room layout), the options ask
/// for other camera responses and auto exposure (camera_response.h), depth
/// bias and flying pixels (sensor_model.h DepthBias), breathing (below), and
/// scene conditions drawn per seed (conditions.h). None of them changes a
/// byte of the default output; simulation.yaml records every one in use.
///
/// Breathing (breathing_mm = A > 0): the anterior torso (World::BreathingWeight
/// w(p), model frame) moves along the model's -y (anterior) by
/// A w(p) cos^4(pi t / T + phase), t the frame's timestamp, period T 3-5 s
/// and phase drawn from the seed: 0 at end-exhale, which is what
/// reference_model.ply shows (a long dwell there, as real breathing, Lujan
/// et al. 1999), A at peak inhale. The back, head, arms and legs do not move,
/// so body_groundtruth.txt (the rigid pose of the non-moving part) is
/// unchanged; stickers ride on the skin (translated by A w(centre) ...).

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "geometry/rigid3.h"
#include "simulation/camera_response.h"
#include "simulation/conditions.h"
#include "simulation/random.h"
#include "simulation/rasterizer.h"
#include "simulation/sensor_model.h"
#include "simulation/simulation_truth.h"
#include "simulation/trajectory.h"
#include "simulation/world.h"

namespace arpos::sim {

/// Changes whenever the same options and seed render different bytes
/// (scene, trajectories, sensor models); caches of simulated cases key on it.
/// 4: random conditions draw colour-depth sync (depth of another instant).
inline constexpr int kSimulatorVersion = 4;

struct SimulationOptions {
  std::string profile = "xtion";  ///< xtion | l515 | d435
  uint64_t seed = 1;
  bool hard = false;    ///< motion blur, lighting change, hand occluder, sticker falls off
  bool noise = true;    ///< false: exact renders (no blur, noise or dropouts)
  int room_frames = 300;
  int body_scan_frames = 150;
  int tracking_frames = 150;
  int tracking_sequences = 2;
  /// Planning walk: "full" (the couch and every wall) or "couch" (around
  /// the couch only, looking at the floor markers and the couch; the quick
  /// walk a small case of few room frames needs).
  std::string room_walk = "full";
  /// The room's surfaces: "rich" (posters, signs, scattered shapes: many
  /// keypoints) or "plain" (low-contrast paint, tile seams, the gantry's
  /// panels: few keypoints). textures.h, TextureDetail.
  std::string room_texture = "rich";
  /// MakeHuman base.obj; empty = DefaultBodyMeshPath().
  std::filesystem::path body_mesh_path;
  int png_compression = 1;  ///< 0..9 (cv::IMWRITE_PNG_COMPRESSION); 1: fast, 3 % larger than 9
  int supersampling = 0;    ///< 0 = the profile's (3); else 1, 3 or 5
  // Sensor and patient conditions. Unset: the default (sRGB, fixed
  // exposure, no depth bias, no breathing), or drawn per seed with
  // random_conditions; set: forced (also over the drawn value).
  std::optional<std::string> response;      ///< srgb | linear | gamma2.6 | scurve
  std::optional<bool> auto_exposure;        ///< exposure drifting by up to +-1 stop
  std::optional<double> depth_scale_error;  ///< e.g. 0.003 = depth 0.3 % long
  std::optional<double> depth_field_mm;     ///< smooth depth error field, amplitude at 1 m
  std::optional<bool> flying_pixels;        ///< mixed depths at depth edges
  std::optional<double> breathing_mm;       ///< anterior torso, peak to peak
  /// The camera's own sharpening of the encoded image (unsharp mask amount,
  /// Gaussian sigma 1 px; 0 = none), as consumer colour cameras do.
  double sharpen_amount = 0;
  /// Depth captured this long after the colour (s; negative: before), as a
  /// camera without hardware sync between its colour and depth sensors
  /// records: each depth image rendered at its own time and listed in
  /// depth.txt with its own timestamp (0: the same instant). Unset: drawn
  /// with random conditions, else 0.
  std::optional<double> depth_delay_s;
  /// Lens distortion of the colour camera (OpenCV k1 k2 p1 p2 k3; the depth
  /// is registered to it): the frames are rendered through it and case.yaml
  /// lists it. Must be invertible over the image.
  std::optional<std::array<double, 5>> distortion;
  /// ArUco dictionary of every marker (case.yaml markers.dictionary); one of
  /// OpenCV's predefined with at least 200 markers (stickers are 100-199).
  std::string dictionary = "DICT_4X4_250";
  /// Printed side of the body stickers (m; default 0.03).
  double sticker_size_m = 0.03;
  /// Draw the scene conditions from the seed (conditions.h): origin marker
  /// placement and visibility, room markers, room, camera paths and pace
  /// (room_walk is then drawn too), and the sensor and patient conditions
  /// above that are not set.
  bool random_conditions = false;
  /// Empty if valid, else "option: problem".
  std::string Check() const;
};

/// How well the room recording sees the origin marker: geometrically (its
/// four corners inside the image by 4 px, in front of the camera, seen less
/// than 75 deg off its normal, at least 15 px a side on average, not behind
/// the gantry, couch base or couch top), not by running a detector.
struct OriginVisibility {
  int frames = 0;               ///< room frames
  int visible_frames = 0;
  double median_side_px = 0;    ///< mean side length in the image, median over visible frames
  double min_side_px = 0;
  double max_side_px = 0;
  double median_angle_deg = 0;  ///< viewing angle off the marker normal, median over visible frames
};

/// $ARPOS_BODY_MESH if set, else the shared data copy found at build time.
std::filesystem::path DefaultBodyMeshPath();

enum class SequenceKind { kRoom, kBodyScan, kTracking };

struct SequencePlan {
  std::string name;  ///< folder relative to the case: room, body_scan, tracking/seq_00
  SequenceKind kind = SequenceKind::kRoom;
  int frames = 0;
  double first_timestamp_s = 0;
  double frame_interval_s = 1.0 / 30;
  HandheldTrajectory camera;
  BodyMotion body;           ///< meaningful when patient is true
  bool patient = false;      ///< patient (and moving couch top) present
  bool treatment_lighting = false;
  // Hand occluder: frames [hand_first, hand_last] (-1 = none); its path in the room.
  int hand_first = -1, hand_last = -1;
  std::vector<Eigen::Vector3d> hand_path_room_m;
  double timestamp(int frame) const { return first_timestamp_s + frame * frame_interval_s; }
  /// Seconds since the sequence start (trajectory time).
  double time(int frame) const { return frame * frame_interval_s; }
};

struct SimulatedFrame {
  double timestamp_s = 0;        ///< colour
  double depth_timestamp_s = 0;  ///< timestamp_s + SimulationOptions::depth_delay_s
  Rigid3d room_from_camera;
  std::optional<Rigid3d> room_from_model;  ///< set when the patient is present
  cv::Mat color;   ///< CV_8UC3 BGR as written
  cv::Mat depth;   ///< CV_16U as written
  RenderOutput exact;  ///< the exact render (depth in metres, normals, labels)
};

struct SimulationReport {
  int frames = 0;
  double seconds = 0;           ///< wall time of WriteCase
  double render_seconds = 0;    ///< rasterisation + sensor models
  double write_seconds = 0;     ///< waiting for PNG encoding and file writes (overlapped with rendering)
  uint64_t bytes = 0;           ///< size of the written case
};

class Simulator {
 public:
  /// Builds the world and plans every sequence. Throws InputError for bad
  /// options or an unreadable body mesh.
  explicit Simulator(const SimulationOptions& options);

  const SimulationOptions& options() const { return options_; }
  const World& world() const { return world_; }
  const SensorProfile& profile() const { return profile_; }
  const std::vector<SequencePlan>& sequences() const { return sequences_; }
  /// room_from_world (World is in the world frame, outputs in the room
  /// frame): identity unless the origin marker was moved.
  const Rigid3d& room_from_world() const { return world_.room_from_world; }
  /// The drawn conditions (random_conditions), else nullptr.
  const SceneConditions* conditions() const { return random_conditions_ ? &conditions_ : nullptr; }
  /// The origin marker in room/ (computed for every case).
  const OriginVisibility& origin_visibility() const { return origin_visibility_; }
  CameraResponse response() const { return response_; }
  /// Exposure relative to the profile's (0 without auto exposure), stops.
  double ExposureStops(double timestamp_s) const;
  /// Anterior displacement of a fully breathing point (weight 1) at this
  /// time, metres (0 without breathing).
  double BreathingDisplacementM(double timestamp_s) const;
  const DepthBias& depth_bias() const { return depth_bias_; }
  /// Ground truth beyond the case folder (what simulation.yaml holds).
  SimulationTruth Truth() const;

  /// Frame `frame` of sequence `sequence` exactly as WriteCase writes it.
  SimulatedFrame RenderFrame(int sequence, int frame) const;

  /// An arbitrary view (for tests and previews): the room with the patient
  /// at `room_from_model` if given (all stickers on, planning lighting, no
  /// hand, the profile's exposure), with or without sensor noise; poses in
  /// the room frame. `breathing_fraction` in [0, 1]: 0 end-exhale, 1 peak
  /// inhale (with breathing).
  SimulatedFrame RenderView(const Rigid3d& room_from_camera,
                            const std::optional<Rigid3d>& room_from_model, bool noise,
                            uint64_t frame_key = 0, double breathing_fraction = 0) const;

  /// Writes the case folder into `out_dir` (created; must be empty or
  /// absent). `progress(done, total)` is called after each frame.
  SimulationReport WriteCase(const std::filesystem::path& out_dir,
                             const std::function<void(int, int)>& progress = nullptr) const;

 private:
  struct Scene {
    Rigid3d room_from_camera;
    std::optional<Rigid3d> room_from_model;
    std::optional<Rigid3d> room_from_hand;
    std::vector<bool> sticker_on;
    const Lighting* lighting = nullptr;
    double breathing_m = 0;      ///< anterior displacement at weight 1
    double exposure_stops = 0;
  };
  SimulatedFrame RenderScene(const Scene& scene, bool noise, uint64_t frame_key,
                             const std::function<Scene(double dt)>* scene_at) const;
  Scene SceneAt(int sequence, int frame, double dt_s) const;
  bool StickerOn(int marker_index, int sequence, int frame) const;
  // The body surface displaced by breathing (anterior by breathing_m x weight).
  RenderMesh BreathingBody(double breathing_m) const;
  // --random-conditions: the planning walk with the origin marker's views.
  void PlanRandomRoomWalk(const std::vector<CameraKey>& keys, uint64_t trajectory_seed,
                          SequencePlan* room);
  std::vector<CameraKey> OriginViewKeys(const std::string& visibility, Rng* rng) const;
  OriginVisibility MeasureOriginVisibility(const SequencePlan& room) const;
  bool OriginSeen(const Rigid3d& world_from_camera, double* side_px, double* angle_deg) const;
  SimulatedFrame ToRoomFrame(SimulatedFrame frame) const;
  void SetUpDistortion(const std::array<double, 5>& coefficients);

  SimulationOptions options_;
  // Cells across a printed marker of the case's dictionary (data bits and
  // the black border): what decides the size it can be read at.
  int marker_cells_ = 6;
  SensorProfile profile_;
  World world_;
  std::vector<SequencePlan> sequences_;
  // --hard: sticker that falls off (index into world_.body_markers), where.
  int sticker_off_index_ = -1;
  int sticker_off_sequence_ = -1;
  int sticker_off_frame_ = -1;
  bool random_conditions_ = false;
  SceneConditions conditions_;
  std::vector<std::string> forced_;  ///< conditions set on the command line
  CameraResponse response_ = CameraResponse::kSrgb;
  AutoExposure auto_exposure_;
  DepthBias depth_bias_;
  uint64_t depth_field_seed_ = 0;
  double breathing_m_ = 0, breathing_period_s_ = 0, breathing_phase_rad_ = 0;
  double depth_delay_s_ = 0;                      ///< forced, else drawn (conditions), else 0
  std::vector<double> sticker_breathing_weight_;  ///< parallel to world_.body_markers
  OriginVisibility origin_visibility_;
  // Lens distortion: frames are rendered by an ideal camera wide enough for
  // the distorted image (render_intrinsics_), then resampled: distorted
  // pixel (u, v) shows ideal pixel (distort_map_x_, distort_map_y_)(v, u).
  CameraIntrinsics render_intrinsics_;
  cv::Mat distort_map_x_, distort_map_y_;
};

}  // namespace arpos::sim
