#include "simulation/simulator.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <future>
#include <opencv2/imgcodecs.hpp>

#include "geometry/mesh_io.h"
#include "geometry/so3.h"
#include "sensor/case_config.h"
#include "sensor/tum_io.h"
#include "simulation/random.h"
#include "util/check.h"
#include "util/file.h"
#include "util/logging.h"
#include "util/string_util.h"

#ifndef ARPOS_DEFAULT_BODY_MESH
#define ARPOS_DEFAULT_BODY_MESH ""
#endif

namespace arpos::sim {
namespace {

constexpr double kFps = 30.0;
constexpr int kBlurTaps = 9;

using V3 = Eigen::Vector3d;

// Nominal sequence lengths (s): frames are spread over at least this.
constexpr double kRoomDurationS = 24, kBodyScanDurationS = 12, kTrackingDurationS = 10;

double FrameInterval(int frames, double nominal_s) {
  const int stride = std::max(1, static_cast<int>(std::floor(nominal_s * kFps / std::max(1, frames))));
  return stride / kFps;
}

std::vector<CameraKey> Jitter(std::vector<CameraKey> keys, Rng* rng, double position_m,
                              double look_m) {
  for (auto& k : keys) {
    k.position_m += V3(rng->Uniform(-1, 1), rng->Uniform(-1, 1), rng->Uniform(-0.5, 0.5)) * position_m;
    k.look_at_m += V3(rng->Uniform(-1, 1), rng->Uniform(-1, 1), rng->Uniform(-0.5, 0.5)) * look_m;
  }
  return keys;
}

// Point on a polyline at fraction s in [0, 1] of its length.
V3 AlongPolyline(const std::vector<V3>& points, double s) {
  if (points.size() == 1) return points.front();
  double total = 0;
  for (size_t i = 1; i < points.size(); ++i) total += (points[i] - points[i - 1]).norm();
  double target = std::clamp(s, 0.0, 1.0) * total;
  for (size_t i = 1; i < points.size(); ++i) {
    const double len = (points[i] - points[i - 1]).norm();
    if (target <= len || i + 1 == points.size()) {
      return points[i - 1] + (len > 0 ? std::min(1.0, target / len) : 0.0) * (points[i] - points[i - 1]);
    }
    target -= len;
  }
  return points.back();
}

uint64_t DirectoryBytes(const std::filesystem::path& root) {
  uint64_t bytes = 0;
  for (const auto& entry : std::filesystem::recursive_directory_iterator(root)) {
    if (entry.is_regular_file()) bytes += entry.file_size();
  }
  return bytes;
}

SimulatedMarker ToSimulated(const MarkerTruth& m) {
  SimulatedMarker s;
  s.id = m.id;
  s.size_m = m.size_m;
  s.surface = m.surface;
  s.raise_m = m.raise_m;
  s.parent_from_marker = m.parent_from_marker;
  s.corners_m = m.corners_m;
  return s;
}

}  // namespace

std::string SimulationOptions::Check() const {
  if (profile != "xtion" && profile != "l515") return "profile: must be xtion or l515, got " + profile;
  if (room_frames < 1 || body_scan_frames < 1 || tracking_frames < 1) {
    return "frames: every sequence needs at least 1 frame";
  }
  if (room_frames > 100000 || body_scan_frames > 100000 || tracking_frames > 100000) {
    return "frames: at most 100000 per sequence";
  }
  if (tracking_sequences < 0 || tracking_sequences > 99) return "tracking-sequences: must be 0..99";
  if (room_walk != "full" && room_walk != "couch") return "room-walk: must be full or couch, got " + room_walk;
  if (png_compression < 0 || png_compression > 9) return "png-compression: must be 0..9";
  if (supersampling != 0 && supersampling != 1 && supersampling != 3 && supersampling != 5) {
    return "supersampling: must be 1, 3 or 5 (or 0 for the profile's)";
  }
  return "";
}

std::filesystem::path DefaultBodyMeshPath() {
  if (const char* env = std::getenv("ARPOS_BODY_MESH"); env != nullptr && *env != '\0') return env;
  return ARPOS_DEFAULT_BODY_MESH;
}

Simulator::Simulator(const SimulationOptions& options) : options_(options) {
  const std::string problem = options_.Check();
  if (!problem.empty()) ARPOS_INPUT_ERROR("simulate: " << problem);
  profile_ = MakeSensorProfile(options_.profile);
  if (options_.supersampling > 0) profile_.supersampling = options_.supersampling;
  WorldOptions wo;
  wo.seed = options_.seed;
  wo.body_mesh_path =
      options_.body_mesh_path.empty() ? DefaultBodyMeshPath() : options_.body_mesh_path;
  world_ = BuildWorld(wo);

  Rng rng(StreamSeed(options_.seed, Stream::kTrajectory));
  Rng body_rng(StreamSeed(options_.seed, Stream::kBodyMotion));
  const double cx = world_.couch_top_home_centre_room_m.x();
  const double top = world_.couch_top_height_m;
  const V3 iso = world_.room_from_model_target.translation;

  // --- room/: empty room, planning lighting, walking around the couch.
  {
    SequencePlan s;
    s.name = "room";
    s.kind = SequenceKind::kRoom;
    s.frames = options_.room_frames;
    s.first_timestamp_s = 10.0;
    s.frame_interval_s = FrameInterval(s.frames, kRoomDurationS);
    std::vector<CameraKey> keys = {
        {V3(-0.35, -0.6, 1.35), V3(0.15, 0.4, 0.0)},   // marker 0 and the couch foot
        {V3(-0.75, 0.2, 1.5), V3(0.6, 1.0, 0.4)},
        {V3(-0.9, 1.2, 1.6), V3(0.8, 1.4, 0.5)},
        {V3(-0.8, 2.4, 1.55), V3(0.6, 2.2, 0.4)},
        {V3(-0.6, 1.5, 1.5), V3(-1.9, 0.9, 1.2)},      // left wall
        {V3(-0.3, -0.9, 1.5), V3(0.8, -1.7, 1.1)},     // foot wall
        {V3(cx, -1.0, 1.6), V3(cx, 1.0, 0.6)},          // along the couch from its foot
        {V3(1.9, -0.4, 1.5), V3(0.9, 0.8, 0.3)},
        {V3(2.3, 0.8, 1.6), V3(0.8, 1.3, 0.5)},
        {V3(2.3, 2.2, 1.55), V3(0.9, 1.8, 0.5)},
        {V3(2.0, 1.2, 1.5), V3(3.4, 1.5, 1.3)},        // right wall
        {V3(1.7, 3.0, 1.6), V3(cx, 2.0, 0.6)},          // head end, gantry in view
        {V3(1.3, 0.1, 1.45), V3(0.0, 0.5, 0.0)},       // floor markers across the couch
        {V3(0.2, -0.7, 1.3), V3(0.0, 0.1, 0.0)},       // back to marker 0
    };
    if (options_.room_walk == "couch") {
      // Around the couch: foot, left side, head end, right side, across, back.
      keys = {keys[0], keys[1], keys[2], keys[3], keys[11], keys[9], keys[8], keys[7], keys[12], keys[13]};
    }
    keys = Jitter(keys, &rng, 0.08, 0.1);
    const double duration = std::max(1.0 / kFps, (s.frames - 1) * s.frame_interval_s);
    s.camera = HandheldTrajectory(keys, duration, rng.Bits());
    s.patient = false;
    sequences_.push_back(std::move(s));
  }
  const auto scan_delta = RandomPoseDelta(body_rng.Bits(), 0.02, 2.0);
  // --- body_scan/: patient still near the target; sweep over the couch.
  {
    SequencePlan s;
    s.name = "body_scan";
    s.kind = SequenceKind::kBodyScan;
    s.frames = options_.body_scan_frames;
    s.first_timestamp_s = 1000.0;
    s.frame_interval_s = FrameInterval(s.frames, kBodyScanDurationS);
    const double z = top + 0.15;  // roughly the body's front surface
    // 0.6-0.9 m from the skin: stickers of 0.03 m span 20-28 px (xtion).
    // The recording starts and ends looking across the body at the floor
    // markers beside the couch (the documented scan protocol: room markers
    // and stickers in view first and last), so the camera is anchored in the
    // room map and the stickers with it.
    std::vector<CameraKey> keys = {
        {V3(cx + 0.3, iso.y() - 0.45, 1.55), V3(cx - 0.35, iso.y() - 0.1, 0.55)},
        {V3(cx - 0.45, iso.y() - 0.35, 1.5), V3(cx, iso.y() - 0.2, z)},
        {V3(cx - 0.4, iso.y() + 0.15, 1.6), V3(cx, iso.y() + 0.12, z)},
        {V3(cx - 0.05, iso.y() + 0.35, 1.68), V3(cx, iso.y() + 0.1, z)},
        {V3(cx + 0.42, iso.y() + 0.1, 1.6), V3(cx, iso.y(), z)},
        {V3(cx + 0.45, iso.y() - 0.4, 1.5), V3(cx, iso.y() - 0.3, z)},
        {V3(cx + 0.05, iso.y() - 0.75, 1.55), V3(cx, iso.y() - 0.25, z)},
        {V3(cx - 0.42, iso.y() - 0.15, 1.55), V3(cx, iso.y(), z)},
        {V3(cx + 0.1, iso.y() - 0.3, 1.6), V3(cx + 0.3, iso.y(), z)},
        {V3(cx - 0.3, iso.y() - 0.35, 1.55), V3(cx + 0.35, iso.y(), 0.55)},
    };
    keys = Jitter(keys, &rng, 0.05, 0.05);
    const double duration = std::max(1.0 / kFps, (s.frames - 1) * s.frame_interval_s);
    s.camera = HandheldTrajectory(keys, duration, rng.Bits());
    s.patient = true;
    s.treatment_lighting = options_.hard;
    s.body = BodyMotion(world_.room_from_model_target, {scan_delta}, 1.0);
    if (options_.hard && s.frames >= 3) {
      s.hand_first = s.frames / 3;
      s.hand_last = std::max(s.hand_first, 2 * s.frames / 3);
      // Over up to three chest/abdomen stickers, left to right.
      const Rigid3d room_from_model = s.body.RoomFromModel(0);
      std::vector<V3> over;
      for (const auto& m : world_.body_markers) {
        if (m.surface == "chest" || m.surface == "abdomen") {
          over.push_back(room_from_model * m.parent_from_marker.translation);
        }
      }
      std::sort(over.begin(), over.end(), [](const V3& a, const V3& b) { return a.x() < b.x(); });
      if (over.size() > 3) over = {over[0], over[over.size() / 2], over.back()};
      if (over.empty()) over.push_back(iso + V3(0, 0, 0.1));
      std::vector<V3>& path = s.hand_path_room_m;
      path.push_back(over.front() + V3(-0.2, 0.05, 0.12));
      for (const V3& p : over) path.push_back(p + V3(0, 0, 0.07));
      path.push_back(over.back() + V3(0.2, -0.05, 0.12));
    }
    sequences_.push_back(std::move(s));
  }
  // --- tracking/seq_NN/: positioning: the couch moves the patient.
  auto delta = scan_delta;
  for (int k = 0; k < options_.tracking_sequences; ++k) {
    SequencePlan s;
    s.name = StringPrintf("tracking/seq_%02d", k);
    s.kind = SequenceKind::kTracking;
    s.frames = options_.tracking_frames;
    s.first_timestamp_s = 2000.0 + 1000.0 * k;
    s.frame_interval_s = FrameInterval(s.frames, kTrackingDurationS);
    const double side = (k % 2 == 0) ? -1.0 : 1.0;  // therapist left, then right of the couch
    const double x0 = cx + side * 0.85;
    const double z = top + 0.15;
    std::vector<CameraKey> keys = {
        {V3(x0, iso.y() + 0.05, 1.65), V3(cx, iso.y() + 0.05, z)},
        {V3(x0 + side * 0.1, iso.y() - 0.25, 1.7), V3(cx, iso.y() - 0.1, z)},
        {V3(x0, iso.y() + 0.35, 1.75), V3(cx, iso.y() + 0.2, z)},
        {V3(x0 - side * 0.05, iso.y(), 1.6), V3(cx, iso.y(), z)},
    };
    keys = Jitter(keys, &rng, 0.05, 0.05);
    const double duration = std::max(1.0 / kFps, (s.frames - 1) * s.frame_interval_s);
    s.camera = HandheldTrajectory(keys, duration, rng.Bits(), 0.002, 0.3);
    std::vector<std::pair<V3, V3>> waypoints = {delta};
    for (int w = 0; w < 3; ++w) waypoints.push_back(RandomPoseDelta(body_rng.Bits(), 0.05, 5.0));
    if (k == 0) {
      // The first positioning ends close to the target.
      auto end = RandomPoseDelta(body_rng.Bits(), 0.003, 0.3);
      waypoints.push_back(end);
    }
    delta = waypoints.back();
    s.body = BodyMotion(world_.room_from_model_target, waypoints, duration);
    s.patient = true;
    s.treatment_lighting = options_.hard;
    sequences_.push_back(std::move(s));
  }
  // --hard: one sticker falls off halfway through the first tracking
  // sequence (or the body scan if there is none).
  if (options_.hard && !world_.body_markers.empty()) {
    Rng hard_rng(StreamSeed(options_.seed, Stream::kHard));
    std::vector<int> candidates;
    for (size_t i = 0; i < world_.body_markers.size(); ++i) {
      const auto& surface = world_.body_markers[i].surface;
      if (surface == "chest" || surface == "abdomen") candidates.push_back(static_cast<int>(i));
    }
    if (candidates.empty()) candidates.push_back(0);
    sticker_off_index_ = candidates[hard_rng.UniformInt(0, static_cast<int>(candidates.size()) - 1)];
    sticker_off_sequence_ = options_.tracking_sequences > 0 ? 2 : 1;
    sticker_off_frame_ = sequences_[sticker_off_sequence_].frames / 2;
  }
}

bool Simulator::StickerOn(int marker_index, int sequence, int frame) const {
  if (marker_index != sticker_off_index_) return true;
  if (sequence < sticker_off_sequence_) return true;
  if (sequence == sticker_off_sequence_ && frame < sticker_off_frame_) return true;
  return false;
}

Simulator::Scene Simulator::SceneAt(int sequence, int frame, double dt_s) const {
  const SequencePlan& s = sequences_.at(sequence);
  const double t = s.time(frame) + dt_s;
  Scene scene;
  scene.room_from_camera = s.camera.RoomFromCamera(t);
  if (s.patient) scene.room_from_model = s.body.RoomFromModel(t);
  scene.lighting = s.treatment_lighting ? &world_.treatment_lighting : &world_.planning_lighting;
  scene.sticker_on.resize(world_.body_markers.size());
  for (size_t i = 0; i < world_.body_markers.size(); ++i) {
    scene.sticker_on[i] = StickerOn(static_cast<int>(i), sequence, frame);
  }
  if (s.hand_first >= 0 && frame >= s.hand_first && frame <= s.hand_last) {
    const double t0 = s.time(s.hand_first), t1 = s.time(s.hand_last);
    const double u = t1 > t0 ? std::clamp((t - t0) / (t1 - t0), 0.0, 1.0) : 0.5;
    const double eased = 0.5 - 0.5 * std::cos(M_PI * u);
    // Palm down, forearm along room x (reaching across from the left).
    scene.room_from_hand =
        Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(RadFromDeg(10), V3::UnitY())),
                AlongPolyline(s.hand_path_room_m, eased));
  }
  return scene;
}

SimulatedFrame Simulator::RenderScene(const Scene& scene, bool noise, uint64_t frame_key,
                                      const std::function<Scene(double)>* scene_at) const {
  const Rigid3d camera_from_room = scene.room_from_camera.Inverse();
  std::vector<RenderInstance> instances;
  for (int mesh : world_.room_meshes) instances.push_back({mesh, camera_from_room, kLabelRoom});
  // The couch top moves with the patient; without one it is at home.
  const Rigid3d camera_from_couch =
      camera_from_room * scene.room_from_model.value_or(world_.room_from_model_target);
  for (int mesh : world_.couch_top_meshes) {
    instances.push_back({mesh, camera_from_couch, kLabelCouchTop});
  }
  if (scene.room_from_model) {
    const Rigid3d camera_from_model = camera_from_room * *scene.room_from_model;
    instances.push_back({world_.body_mesh, camera_from_model, kLabelBody});
    for (size_t i = 0; i < world_.sticker_meshes.size(); ++i) {
      if (scene.sticker_on.empty() || scene.sticker_on[i]) {
        instances.push_back({world_.sticker_meshes[i], camera_from_model, kLabelSticker});
      }
    }
  }
  if (scene.room_from_hand) {
    instances.push_back({world_.hand_mesh, camera_from_room * *scene.room_from_hand, kLabelHand});
  }
  RenderOptions ro;
  ro.supersampling = profile_.supersampling;
  SimulatedFrame out;
  out.room_from_camera = scene.room_from_camera;
  out.room_from_model = scene.room_from_model;
  out.exact = Render(world_.scene, instances, profile_.intrinsics, camera_from_room,
                     *scene.lighting, ro);
  cv::Mat radiance = out.exact.color;
  if (noise && options_.hard && scene_at != nullptr) {
    // camera(t+dt) <- camera(t) for points of each label.
    const LabelMotion motion = [&](int label, double dt) -> Rigid3d {
      const Scene later = (*scene_at)(dt);
      const Rigid3d cam2_from_room = later.room_from_camera.Inverse();
      Rigid3d room2_from_room1 = Rigid3d::Identity();
      if ((label == kLabelBody || label == kLabelCouchTop || label == kLabelSticker) &&
          scene.room_from_model && later.room_from_model) {
        room2_from_room1 = *later.room_from_model * scene.room_from_model->Inverse();
      } else if (label == kLabelHand && scene.room_from_hand && later.room_from_hand) {
        room2_from_room1 = *later.room_from_hand * scene.room_from_hand->Inverse();
      }
      return cam2_from_room * room2_from_room1 * scene.room_from_camera;
    };
    radiance = ApplyMotionBlur(radiance, out.exact, profile_.intrinsics, profile_.exposure_time_s,
                               motion, kLabelHand, kBlurTaps);
  }
  out.color = SimulateColor(radiance, profile_, noise, frame_key);
  out.depth = SimulateDepth(out.exact, profile_, noise, frame_key);
  return out;
}

SimulatedFrame Simulator::RenderFrame(int sequence, int frame) const {
  const SequencePlan& s = sequences_.at(sequence);
  ARPOS_CHECK(frame >= 0 && frame < s.frames, "frame " << frame << " out of range");
  const Scene scene = SceneAt(sequence, frame, 0.0);
  const std::function<Scene(double)> scene_at = [&](double dt) {
    return SceneAt(sequence, frame, dt);
  };
  const uint64_t key = Hash3(options_.seed, static_cast<uint64_t>(sequence + 1),
                             static_cast<uint64_t>(frame));
  SimulatedFrame out = RenderScene(scene, options_.noise, key, &scene_at);
  out.timestamp_s = s.timestamp(frame);
  return out;
}

SimulatedFrame Simulator::RenderView(const Rigid3d& room_from_camera,
                                     const std::optional<Rigid3d>& room_from_model, bool noise,
                                     uint64_t frame_key) const {
  Scene scene;
  scene.room_from_camera = room_from_camera;
  scene.room_from_model = room_from_model;
  scene.lighting = &world_.planning_lighting;
  return RenderScene(scene, noise, Hash3(options_.seed, 0xF1E3ULL, frame_key), nullptr);
}

SimulationTruth Simulator::Truth() const {
  SimulationTruth t;
  t.seed = options_.seed;
  t.profile = profile_.name;
  t.sensor = profile_.Describe();
  t.noise = options_.noise;
  t.hard = options_.hard;
  t.room_walk = options_.room_walk;
  t.room_frames = options_.room_frames;
  t.body_scan_frames = options_.body_scan_frames;
  t.tracking_frames = options_.tracking_frames;
  t.tracking_sequences = options_.tracking_sequences;
  t.isocentre_in_room_m = world_.room_from_model_target.translation;
  t.room_from_model_target = world_.room_from_model_target;
  t.reference_noise_sigma_m = WorldOptions().reference_noise_m;
  t.max_tessellation_difference_m = world_.max_tessellation_difference_m;
  t.couch_top_height_m = world_.couch_top_height_m;
  for (const auto& m : world_.room_markers) t.room_markers.push_back(ToSimulated(m));
  for (const auto& m : world_.body_markers) t.body_markers.push_back(ToSimulated(m));
  for (const auto& s : sequences_) {
    SimulatedSequence q;
    q.name = s.name;
    q.frames = s.frames;
    q.first_timestamp_s = s.first_timestamp_s;
    q.frame_interval_s = s.frame_interval_s;
    q.lighting = s.treatment_lighting ? "treatment" : "planning";
    q.patient = s.patient;
    t.sequences.push_back(q);
  }
  if (options_.hard) {
    t.motion_blur_exposure_s = profile_.exposure_time_s;
    t.motion_blur_taps = kBlurTaps;
    t.lighting_change_from_sequence = "body_scan";
    for (const auto& s : sequences_) {
      if (s.hand_first >= 0) {
        t.hand_sequence = s.name;
        t.hand_first_frame = s.hand_first;
        t.hand_last_frame = s.hand_last;
        t.hand_first_timestamp_s = s.timestamp(s.hand_first);
        t.hand_last_timestamp_s = s.timestamp(s.hand_last);
      }
    }
    if (sticker_off_index_ >= 0) {
      t.sticker_off_marker_id = world_.body_markers[sticker_off_index_].id;
      t.sticker_off_sequence = sequences_[sticker_off_sequence_].name;
      t.sticker_off_frame = sticker_off_frame_;
      t.sticker_off_timestamp_s = sequences_[sticker_off_sequence_].timestamp(sticker_off_frame_);
    }
  }
  return t;
}

SimulationReport Simulator::WriteCase(const std::filesystem::path& out_dir,
                                      const std::function<void(int, int)>& progress) const {
  using Clock = std::chrono::steady_clock;
  const auto start = Clock::now();
  std::error_code ec;
  if (std::filesystem::exists(out_dir, ec)) {
    if (!std::filesystem::is_directory(out_dir, ec)) {
      ARPOS_INPUT_ERROR(out_dir.string() << ": exists and is not a folder");
    }
    if (!std::filesystem::is_empty(out_dir, ec)) {
      ARPOS_INPUT_ERROR(out_dir.string() << ": folder is not empty (refusing to overwrite a case)");
    }
  }
  CreateDirectories(out_dir);
  SimulationReport report;

  CaseConfig config;
  config.camera = profile_.intrinsics;
  config.dictionary = "DICT_4X4_250";
  config.room_markers = {0.15, 0, 49};
  config.room_origin_id = 0;
  config.body_markers = {0.03, 100, 199};
  config.room_markers.size_m = world_.room_markers.front().size_m;
  if (!world_.body_markers.empty()) config.body_markers.size_m = world_.body_markers.front().size_m;
  SaveCaseConfig(config, out_dir / "case.yaml");
  SaveTriangleMeshPly(world_.reference_model, out_dir / "reference_model.ply",
                      "ARPos simulated reference model: model frame (LPS, origin at the "
                      "isocentre), metres");
  WriteMatrix4(out_dir / "target_pose.txt", world_.room_from_model_target.ToMatrix(),
               "room_from_model: desired pose of the reference model in the room (row-major)");

  std::vector<int> params = {cv::IMWRITE_PNG_COMPRESSION, options_.png_compression};
  int total = 0, done = 0;
  for (const auto& s : sequences_) total += s.frames;
  for (size_t q = 0; q < sequences_.size(); ++q) {
    const SequencePlan& s = sequences_[q];
    const std::filesystem::path dir = out_dir / s.name;
    CreateDirectories(dir / "rgb");
    CreateDirectories(dir / "depth");
    std::vector<ImageListEntry> rgb, depth;
    std::vector<StampedPose> camera_poses, body_poses;
    // PNG encoding of frame f overlaps the rendering of frame f + 1 (the
    // files do not depend on the order, so the output stays deterministic).
    std::future<bool> pending;
    std::string pending_dir;
    auto finish_pending = [&]() {
      if (!pending.valid()) return;
      const auto t = Clock::now();
      const bool ok = pending.get();
      report.write_seconds += std::chrono::duration<double>(Clock::now() - t).count();
      if (!ok) ARPOS_INPUT_ERROR(pending_dir << ": cannot write images");
    };
    for (int f = 0; f < s.frames; ++f) {
      const auto t0 = Clock::now();
      SimulatedFrame frame = RenderFrame(static_cast<int>(q), f);
      report.render_seconds += std::chrono::duration<double>(Clock::now() - t0).count();
      const std::string stamp = StringPrintf("%.6f", frame.timestamp_s);
      const std::string rgb_name = "rgb/" + stamp + ".png", depth_name = "depth/" + stamp + ".png";
      rgb.push_back({frame.timestamp_s, rgb_name, 0});
      depth.push_back({frame.timestamp_s, depth_name, 0});
      camera_poses.push_back({frame.timestamp_s, frame.room_from_camera});
      if (frame.room_from_model) body_poses.push_back({frame.timestamp_s, *frame.room_from_model});
      finish_pending();
      pending_dir = dir.string();
      pending = std::async(std::launch::async,
                           [color = frame.color, depth_image = frame.depth,
                            rgb_path = (dir / rgb_name).string(),
                            depth_path = (dir / depth_name).string(), params]() {
                             return cv::imwrite(rgb_path, color, params) &&
                                    cv::imwrite(depth_path, depth_image, params);
                           });
      ++report.frames;
      if (progress) progress(++done, total);
    }
    finish_pending();
    const std::string what = "ARPos simulate " + s.name + " (profile " + profile_.name + ")";
    WriteImageList(dir / "rgb.txt", rgb, what + ": colour images");
    WriteImageList(dir / "depth.txt", depth, what + ": depth images, 16-bit, registered to colour");
    WriteTrajectory(dir / "groundtruth.txt", camera_poses,
                    what + ": room_from_camera (camera -> room, exact)");
    if (!body_poses.empty()) {
      WriteTrajectory(dir / "body_groundtruth.txt", body_poses,
                      what + ": room_from_model (reference model -> room, exact)");
    }
  }
  SaveSimulationTruth(Truth(), out_dir / "simulation.yaml");
  report.bytes = DirectoryBytes(out_dir);
  report.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return report;
}

}  // namespace arpos::sim
