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

#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "geometry/rigid3.h"
#include "simulation/rasterizer.h"
#include "simulation/sensor_model.h"
#include "simulation/simulation_truth.h"
#include "simulation/trajectory.h"
#include "simulation/world.h"

namespace arpos::sim {

/// Changes whenever the same options and seed render different bytes
/// (scene, trajectories, sensor models); caches of simulated cases key on it.
inline constexpr int kSimulatorVersion = 2;

struct SimulationOptions {
  std::string profile = "xtion";  ///< xtion | l515
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
  /// MakeHuman base.obj; empty = DefaultBodyMeshPath().
  std::filesystem::path body_mesh_path;
  int png_compression = 1;  ///< 0..9 (cv::IMWRITE_PNG_COMPRESSION); 1: fast, 3 % larger than 9
  int supersampling = 0;    ///< 0 = the profile's (3); else 1, 3 or 5
  /// Empty if valid, else "option: problem".
  std::string Check() const;
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
  double timestamp_s = 0;
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
  /// Ground truth beyond the case folder (what simulation.yaml holds).
  SimulationTruth Truth() const;

  /// Frame `frame` of sequence `sequence` exactly as WriteCase writes it.
  SimulatedFrame RenderFrame(int sequence, int frame) const;

  /// An arbitrary view (for tests and previews): the room with the patient
  /// at `room_from_model` if given (all stickers on, planning lighting, no
  /// hand), with or without sensor noise.
  SimulatedFrame RenderView(const Rigid3d& room_from_camera,
                            const std::optional<Rigid3d>& room_from_model, bool noise,
                            uint64_t frame_key = 0) const;

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
  };
  SimulatedFrame RenderScene(const Scene& scene, bool noise, uint64_t frame_key,
                             const std::function<Scene(double dt)>* scene_at) const;
  Scene SceneAt(int sequence, int frame, double dt_s) const;
  bool StickerOn(int marker_index, int sequence, int frame) const;

  SimulationOptions options_;
  SensorProfile profile_;
  World world_;
  std::vector<SequencePlan> sequences_;
  // --hard: sticker that falls off (index into world_.body_markers), where.
  int sticker_off_index_ = -1;
  int sticker_off_sequence_ = -1;
  int sticker_off_frame_ = -1;
};

}  // namespace arpos::sim
