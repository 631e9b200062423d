#include "simulation/simulator.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <future>
#include <opencv2/aruco.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

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
  if (profile != "xtion" && profile != "l515" && profile != "d435") {
    return "profile: must be xtion, l515 or d435, got " + profile;
  }
  if (room_frames < 1 || body_scan_frames < 1 || tracking_frames < 1) {
    return "frames: every sequence needs at least 1 frame";
  }
  if (room_frames > 100000 || body_scan_frames > 100000 || tracking_frames > 100000) {
    return "frames: at most 100000 per sequence";
  }
  if (tracking_sequences < 0 || tracking_sequences > 99) return "tracking-sequences: must be 0..99";
  if (room_walk != "full" && room_walk != "couch") return "room-walk: must be full or couch, got " + room_walk;
  if (room_texture != "rich" && room_texture != "plain") {
    return "room-texture: must be rich or plain, got " + room_texture;
  }
  if (png_compression < 0 || png_compression > 9) return "png-compression: must be 0..9";
  if (supersampling != 0 && supersampling != 1 && supersampling != 3 && supersampling != 5) {
    return "supersampling: must be 1, 3 or 5 (or 0 for the profile's)";
  }
  CameraResponse r;
  if (response && !ParseResponse(*response, &r)) {
    return "response: must be srgb, linear, gamma2.6 or scurve, got " + *response;
  }
  if (depth_scale_error && !(std::abs(*depth_scale_error) <= 0.1)) {
    return "depth-scale-error: must be within +-0.1 (10 %)";
  }
  if (depth_field_mm && !(*depth_field_mm >= 0 && *depth_field_mm <= 50)) {
    return "depth-field-mm: must be 0..50";
  }
  if (breathing_mm && !(*breathing_mm >= 0 && *breathing_mm <= 30)) return "breathing-mm: must be 0..30";
  if (!(sharpen_amount >= 0 && sharpen_amount <= 3)) return "sharpen: must be 0..3";
  // Within the colour-depth association window (sensor/sequence.h: 0.02 s).
  if (depth_delay_s && !(std::abs(*depth_delay_s) <= 0.015))
    return "depth-delay-ms: must be within +-15 ms";
  if (const int id = ArucoDictionaryId(dictionary); id < 0) {
    return "dictionary: unknown ArUco dictionary '" + dictionary + "'";
  } else if (cv::aruco::getPredefinedDictionary(id)->bytesList.rows < 200) {
    return "dictionary: " + dictionary + " has fewer than 200 markers (stickers use ids 100-199)";
  }
  if (!(sticker_size_m >= 0.015 && sticker_size_m <= 0.06)) return "sticker-size-m: must be 0.015..0.06";
  if (distortion) {
    for (double d : *distortion) {
      if (!std::isfinite(d) || std::abs(d) > 10) return "distortion: coefficients must be finite and within +-10";
    }
  }
  return "";
}

std::filesystem::path DefaultBodyMeshPath() {
  if (const char* env = std::getenv("ARPOS_BODY_MESH"); env != nullptr && *env != '\0') return env;
  return ARPOS_DEFAULT_BODY_MESH;
}

void Simulator::SetUpDistortion(const std::array<double, 5>& coefficients) {
  CameraIntrinsics& K = profile_.intrinsics;
  for (int i = 0; i < 5; ++i) K.distortion[i] = coefficients[i];
  if (!K.HasDistortion()) return;
  const int W = K.width, H = K.height;
  // Every pixel's ideal (undistorted) position, checked by distorting it back.
  std::vector<cv::Point2f> px;
  px.reserve(static_cast<size_t>(W) * H);
  for (int v = 0; v < H; ++v)
    for (int u = 0; u < W; ++u) px.emplace_back(static_cast<float>(u), static_cast<float>(v));
  std::vector<cv::Point2f> ideal;
  cv::undistortPoints(px, ideal, K.CvK(), K.CvDistortion(), cv::noArray(), cv::noArray(),
                      cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 50, 1e-12));
  std::vector<cv::Point3f> rays;
  rays.reserve(ideal.size());
  for (const auto& p : ideal) rays.emplace_back(p.x, p.y, 1.0f);
  std::vector<cv::Point2f> back;
  cv::projectPoints(rays, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), K.CvK(), K.CvDistortion(), back);
  double worst = 0;
  float lo_x = 1e9f, hi_x = -1e9f, lo_y = 1e9f, hi_y = -1e9f;
  for (size_t i = 0; i < px.size(); ++i) {
    worst = std::max(worst, static_cast<double>(cv::norm(back[i] - px[i])));
    const float x = static_cast<float>(K.fx * ideal[i].x + K.cx), y = static_cast<float>(K.fy * ideal[i].y + K.cy);
    lo_x = std::min(lo_x, x), hi_x = std::max(hi_x, x), lo_y = std::min(lo_y, y), hi_y = std::max(hi_y, y);
    ideal[i] = {x, y};
  }
  if (!(worst < 0.01)) {
    ARPOS_INPUT_ERROR("simulate: distortion: not invertible over the " << W << "x" << H
                      << " image (a pixel maps back " << worst << " px away)");
  }
  // The ideal camera that covers every distorted pixel, 2 px to spare.
  const int left = std::max(0, static_cast<int>(std::ceil(-lo_x)) + 2);
  const int top = std::max(0, static_cast<int>(std::ceil(-lo_y)) + 2);
  const int right = std::max(0, static_cast<int>(std::ceil(hi_x - (W - 1))) + 2);
  const int bottom = std::max(0, static_cast<int>(std::ceil(hi_y - (H - 1))) + 2);
  if (left + right > W || top + bottom > H) {
    ARPOS_INPUT_ERROR("simulate: distortion: too strong (the undistorted image would be more than twice as wide)");
  }
  render_intrinsics_ = K;
  render_intrinsics_.distortion = {0, 0, 0, 0, 0};
  render_intrinsics_.width = W + left + right;
  render_intrinsics_.height = H + top + bottom;
  render_intrinsics_.cx = K.cx + left;
  render_intrinsics_.cy = K.cy + top;
  distort_map_x_.create(H, W, CV_32F);
  distort_map_y_.create(H, W, CV_32F);
  for (int v = 0; v < H; ++v) {
    for (int u = 0; u < W; ++u) {
      const cv::Point2f& p = ideal[static_cast<size_t>(v) * W + u];
      distort_map_x_.at<float>(v, u) = p.x + left;
      distort_map_y_.at<float>(v, u) = p.y + top;
    }
  }
}

Simulator::Simulator(const SimulationOptions& options) : options_(options) {
  const std::string problem = options_.Check();
  if (!problem.empty()) ARPOS_INPUT_ERROR("simulation options: " << problem);
  profile_ = MakeSensorProfile(options_.profile);
  if (options_.supersampling > 0) profile_.supersampling = options_.supersampling;
  render_intrinsics_ = profile_.intrinsics;
  if (options_.distortion) SetUpDistortion(*options_.distortion);
  WorldOptions wo;
  wo.seed = options_.seed;
  wo.dictionary = ArucoDictionaryId(options_.dictionary);
  marker_cells_ = cv::aruco::getPredefinedDictionary(wo.dictionary)->markerSize + 2;
  wo.body_marker_size_m = options_.sticker_size_m;
  wo.plain_room = options_.room_texture == "plain";
  wo.body_mesh_path =
      options_.body_mesh_path.empty() ? DefaultBodyMeshPath() : options_.body_mesh_path;
  random_conditions_ = options_.random_conditions;
  SceneConditions& c = conditions_;
  if (random_conditions_) {
    c = DrawSceneConditions(options_.seed);
    wo.layout = c.layout;
    wo.world_from_origin_marker = c.world_from_origin_marker;
    wo.origin_surface = c.origin_surface;
    wo.room_marker_places = c.room_marker_places;
    wo.room_marker_size_m = c.room_marker_size_m;
  }
  // Forced conditions replace the drawn (or default) ones.
  if (options_.response) {
    ParseResponse(*options_.response, &c.response);
    forced_.push_back("response");
  }
  if (options_.auto_exposure) {
    c.auto_exposure = *options_.auto_exposure;
    forced_.push_back("auto_exposure");
  }
  if (options_.depth_scale_error) {
    c.depth_scale_error = *options_.depth_scale_error;
    forced_.push_back("depth_scale_error");
  }
  if (options_.depth_field_mm) {
    c.depth_field_mm = *options_.depth_field_mm;
    forced_.push_back("depth_field_mm");
  }
  if (options_.flying_pixels) {
    c.flying_pixels = *options_.flying_pixels;
    forced_.push_back("flying_pixels");
  }
  if (options_.breathing_mm) {
    c.breathing_mm = *options_.breathing_mm;
    forced_.push_back("breathing_mm");
  }
  if (options_.depth_delay_s) {
    c.depth_delay_ms = 1000 * *options_.depth_delay_s;
    if (random_conditions_) forced_.push_back("depth_delay_ms");
  }
  depth_delay_s_ = c.depth_delay_ms / 1000;
  world_ = BuildWorld(wo);

  response_ = c.response;
  if (c.auto_exposure) auto_exposure_ = AutoExposure::Draw(StreamSeed(options_.seed, Stream::kExposure));
  depth_bias_.scale_error = c.depth_scale_error;
  depth_bias_.field_mm_at_1m = c.depth_field_mm;
  depth_bias_.flying_pixels = c.flying_pixels;
  if (c.depth_field_mm != 0) {
    depth_field_seed_ = StreamSeed(options_.seed, Stream::kDepthBias);
    depth_bias_.field =
        MakeDepthErrorField(profile_.intrinsics.width, profile_.intrinsics.height, depth_field_seed_);
  }
  if (c.breathing_mm > 0) {
    Rng breathing_rng(StreamSeed(options_.seed, Stream::kBreathing));
    breathing_m_ = 0.001 * c.breathing_mm;
    breathing_period_s_ = breathing_rng.Uniform(3.0, 5.0);
    breathing_phase_rad_ = breathing_rng.Uniform(0, M_PI);
    for (const auto& m : world_.body_markers) {
      sticker_breathing_weight_.push_back(world_.BreathingWeight(m.parent_from_marker.translation));
    }
  }

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
    s.frame_interval_s =
        FrameInterval(s.frames, random_conditions_ ? c.room_duration_s : kRoomDurationS);
    const RoomLayout& lay = world_.layout;
    std::vector<CameraKey> keys = {
        {V3(-0.35, -0.6, 1.35), V3(0.15, 0.4, 0.0)},   // marker 0 and the couch foot
        {V3(-0.75, 0.2, 1.5), V3(0.6, 1.0, 0.4)},
        {V3(-0.9, 1.2, 1.6), V3(0.8, 1.4, 0.5)},
        {V3(-0.8, 2.4, 1.55), V3(0.6, 2.2, 0.4)},
        {V3(-0.6, 1.5, 1.5), V3(lay.wall_left_x_m, 0.9, 1.2)},    // left wall
        {V3(-0.3, -0.9, 1.5), V3(0.8, lay.wall_foot_y_m, 1.1)},   // foot wall
        {V3(cx, -1.0, 1.6), V3(cx, 1.0, 0.6)},          // along the couch from its foot
        {V3(1.9, -0.4, 1.5), V3(0.9, 0.8, 0.3)},
        {V3(2.3, 0.8, 1.6), V3(0.8, 1.3, 0.5)},
        {V3(2.3, 2.2, 1.55), V3(0.9, 1.8, 0.5)},
        {V3(2.0, 1.2, 1.5), V3(lay.wall_right_x_m, 1.5, 1.3)},    // right wall
        {V3(1.7, 3.0, 1.6), V3(cx, 2.0, 0.6)},          // head end, gantry in view
        {V3(1.3, 0.1, 1.45), V3(0.0, 0.5, 0.0)},       // floor markers across the couch
        {V3(0.2, -0.7, 1.3), V3(0.0, 0.1, 0.0)},       // back to marker 0
    };
    if ((random_conditions_ ? c.room_walk : options_.room_walk) == "couch") {
      // Around the couch: foot, left side, head end, right side, across, back.
      keys = {keys[0], keys[1], keys[2], keys[3], keys[11], keys[9], keys[8], keys[7], keys[12], keys[13]};
    }
    if (random_conditions_) {
      // The first and last keys look at the standard origin place; the
      // drawn origin marker gets views of its own.
      keys = std::vector<CameraKey>(keys.begin() + 1, keys.end() - 1);
      keys = Jitter(keys, &rng, c.path_jitter_m, 1.25 * c.path_jitter_m);
      PlanRandomRoomWalk(keys, rng.Bits(), &s);
    } else {
      keys = Jitter(keys, &rng, 0.08, 0.1);
      const double duration = std::max(1.0 / kFps, (s.frames - 1) * s.frame_interval_s);
      s.camera = HandheldTrajectory(keys, duration, rng.Bits());
    }
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
    s.frame_interval_s =
        FrameInterval(s.frames, random_conditions_ ? c.body_scan_duration_s : kBodyScanDurationS);
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
      // The first positioning ends as a therapist's does: the patient
      // brought within tolerance of the planned pose (within 0.7 mm on each
      // axis, 0.3 deg) and held there for the last third of the sequence,
      // so that `in` (and the approach to it) is measured, not only `out`.
      // A sequence of under a second (the bundled sample's three frames) is
      // too short for an approach and a hold: it keeps the earlier ending,
      // close to the plan (within 3 mm on each axis) at its last frame.
      const bool hold = s.frames >= 30;
      const auto end = RandomPoseDelta(body_rng.Bits(), hold ? 0.0007 : 0.003, 0.3);
      for (int w = 0; w < (hold ? 3 : 1); ++w) waypoints.push_back(end);
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
  if (!random_conditions_) origin_visibility_ = MeasureOriginVisibility(sequences_.front());
}

double Simulator::ExposureStops(double timestamp_s) const {
  return auto_exposure_.enabled() ? auto_exposure_.Stops(timestamp_s) : 0.0;
}

double Simulator::BreathingDisplacementM(double timestamp_s) const {
  if (breathing_m_ <= 0) return 0;
  const double c = std::cos(M_PI * timestamp_s / breathing_period_s_ + breathing_phase_rad_);
  return breathing_m_ * c * c * c * c;
}

RenderMesh Simulator::BreathingBody(double breathing_m) const {
  RenderMesh body = world_.scene.meshes[world_.body_mesh];
  TriangleMesh surface;
  surface.vertices = body.vertices;
  surface.faces = body.faces;
  for (size_t i = 0; i < surface.vertices.size(); ++i) {
    // Anterior is the model's -y.
    surface.vertices[i].y() -= static_cast<float>(breathing_m * world_.body_breathing_weight[i]);
  }
  surface.ComputeVertexNormals();
  body.vertices = std::move(surface.vertices);
  body.normals = std::move(surface.vertex_normals);
  return body;
}

namespace {

// Segment p -> q against an axis-aligned box (slabs).
bool SegmentHitsBox(const V3& p, const V3& q, const V3& lo, const V3& hi) {
  double t0 = 0, t1 = 1;
  const V3 d = q - p;
  for (int a = 0; a < 3; ++a) {
    if (std::abs(d[a]) < 1e-12) {
      if (p[a] < lo[a] || p[a] > hi[a]) return false;
      continue;
    }
    double ta = (lo[a] - p[a]) / d[a], tb = (hi[a] - p[a]) / d[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
    if (t0 > t1) return false;
  }
  return true;
}

}  // namespace

bool Simulator::OriginSeen(const Rigid3d& world_from_camera, double* side_px,
                           double* angle_deg) const {
  const MarkerTruth& origin = world_.room_markers.front();
  const CameraIntrinsics& K = profile_.intrinsics;
  const Rigid3d camera_from_world = world_from_camera.Inverse();
  const V3 eye = world_from_camera.translation;
  const V3 centre = origin.parent_from_marker.translation;
  const V3 normal = origin.parent_from_marker.rotation * V3::UnitZ();
  const V3 to_eye = eye - centre;
  const double cosine = normal.dot(to_eye) / std::max(1e-9, to_eye.norm());
  *angle_deg = DegFromRad(std::acos(std::clamp(cosine, -1.0, 1.0)));
  if (*angle_deg > 75) return false;
  Eigen::Vector2d px[4];
  for (int k = 0; k < 4; ++k) {
    const V3 p = camera_from_world * origin.corners_m[k];
    if (p.z() < 0.1) return false;
    px[k] = K.Project(p);
    if (px[k].x() < 4 || px[k].y() < 4 || px[k].x() > K.width - 5 || px[k].y() > K.height - 5) return false;
    // The last 2 cm before the marker cannot hide it (its own surface).
    const V3 target = origin.corners_m[k] + 0.02 * (eye - origin.corners_m[k]).normalized();
    for (const auto& [lo, hi] : world_.occluders) {
      if (SegmentHitsBox(eye, target, lo, hi)) return false;
    }
  }
  *side_px = 0;
  for (int k = 0; k < 4; ++k) *side_px += 0.25 * (px[(k + 1) % 4] - px[k]).norm();
  // Too small to decode (cells of 2.5 px: 15 px for a 4x4 marker).
  return *side_px >= 2.5 * marker_cells_;
}

OriginVisibility Simulator::MeasureOriginVisibility(const SequencePlan& room) const {
  OriginVisibility v;
  v.frames = room.frames;
  std::vector<double> sides, angles;
  for (int f = 0; f < room.frames; ++f) {
    double side = 0, angle = 0;
    if (OriginSeen(room.camera.RoomFromCamera(room.time(f)), &side, &angle)) {
      sides.push_back(side);
      angles.push_back(angle);
    }
  }
  v.visible_frames = static_cast<int>(sides.size());
  if (!sides.empty()) {
    std::sort(sides.begin(), sides.end());
    std::sort(angles.begin(), angles.end());
    v.median_side_px = sides[sides.size() / 2];
    v.min_side_px = sides.front();
    v.max_side_px = sides.back();
    v.median_angle_deg = angles[angles.size() / 2];
  }
  return v;
}

std::vector<CameraKey> Simulator::OriginViewKeys(const std::string& visibility, Rng* rng) const {
  const MarkerTruth& origin = world_.room_markers.front();
  const V3 c = origin.parent_from_marker.translation;
  const V3 n = origin.parent_from_marker.rotation * V3::UnitZ();
  const CameraIntrinsics& K = profile_.intrinsics;
  const RoomLayout& lay = world_.layout;
  const bool on_floor = std::abs(n.z()) > 0.5;
  // Every draw is made whatever the class (a fixed sequence per attempt).
  const double theta_good = rng->Uniform(10, 35), theta_medium = rng->Uniform(35, 55);
  const double theta_poor = rng->Uniform(50, 70);
  const double d_good = rng->Uniform(1.2, 2.0), d_medium = rng->Uniform(1.6, 2.4);
  const double px_poor = rng->Uniform(30, 40);
  const double phi0 = RadFromDeg(rng->Uniform(-60, 60));
  const double second_phi = RadFromDeg(rng->Uniform(40, 100)) * (rng->Uniform() < 0.5 ? -1 : 1);
  const double side = rng->Uniform() < 0.5 ? -1.0 : 1.0;
  const V3 look_jitter(rng->Uniform(-0.1, 0.1), rng->Uniform(-0.1, 0.1), rng->Uniform(-0.05, 0.05));
  double theta = theta_good, d = d_good;
  if (visibility == "medium") {
    theta = theta_medium;
    d = d_medium;
  } else if (visibility == "poor") {
    theta = theta_poor;
    d = K.fx * origin.size_m / px_poor;
  }
  theta = RadFromDeg(theta);
  // Azimuths measured from the direction towards the couch, in the
  // marker's plane.
  V3 towards = V3(kCouchCentreX_m, 1.2, 1.2) - c;
  towards -= towards.dot(n) * n;
  if (towards.norm() < 1e-6) towards = n.unitOrthogonal();
  const V3 a0 = towards.normalized(), b0 = n.cross(a0);
  auto inside = [&](const V3& p) {
    if (p.x() < lay.wall_left_x_m + 0.35 || p.x() > lay.wall_right_x_m - 0.35) return false;
    if (p.y() < lay.wall_foot_y_m + 0.35 || p.y() > lay.wall_head_y_m - 0.35) return false;
    for (const auto& [lo, hi] : world_.occluders) {
      if (p.x() > lo.x() - 0.25 && p.x() < hi.x() + 0.25 && p.y() > lo.y() - 0.25 &&
          p.y() < hi.y() + 0.25 && p.z() < std::max(hi.z(), 1.9) + 0.1) {
        return false;
      }
    }
    return true;
  };
  auto place = [&](double phi, V3* eye) {
    for (double scale : {1.0, 0.85, 0.7, 0.6}) {
      for (int k = 0; k < 24; ++k) {
        const double a = phi + (k % 2 ? 1 : -1) * ((k + 1) / 2) * RadFromDeg(15);
        const V3 dir = std::cos(a) * a0 + std::sin(a) * b0;
        V3 p = c + scale * d * (std::cos(theta) * n + std::sin(theta) * dir);
        p.z() = std::clamp(p.z(), on_floor ? 1.0 : 1.1, 1.8);
        if (inside(p)) {
          *eye = p;
          return true;
        }
      }
    }
    return false;
  };
  std::vector<CameraKey> keys;
  V3 eye;
  if (!place(phi0, &eye)) return keys;
  V3 look = c + look_jitter;
  if (visibility == "poor") {
    // Off the image centre: the marker ~55 % of the way to the side edge.
    V3 lateral = (c - eye).cross(V3::UnitZ());
    if (lateral.norm() < 1e-6) lateral = V3::UnitX();
    look = c + side * 0.55 * (c - eye).norm() * (K.width / 2.0) / K.fx * lateral.normalized();
  }
  keys.push_back({eye, look});
  if (visibility == "good") {
    // The walk ends on it too, from another side.
    V3 eye2 = eye;
    place(phi0 + second_phi, &eye2);
    keys.push_back({eye2, c - look_jitter});
  }
  return keys;
}

void Simulator::PlanRandomRoomWalk(const std::vector<CameraKey>& keys, uint64_t trajectory_seed,
                                   SequencePlan* room) {
  Rng walk_rng(StreamSeed(options_.seed, Stream::kConditionWalk));
  const double duration = std::max(1.0 / kFps, (room->frames - 1) * room->frame_interval_s);
  const int needed = std::min(3, room->frames);
  std::string visibility = conditions_.origin_visibility;
  // Poor visibility: the walk's own views do not look at the marker either
  // (the recording glances at it once).
  std::vector<CameraKey> base = keys;
  if (visibility == "poor") {
    base.clear();
    for (const CameraKey& k : keys) {
      double side = 0, angle = 0;
      if (!OriginSeen(LookAt(k.position_m, k.look_at_m), &side, &angle)) base.push_back(k);
    }
  }
  const int poor_at_most = std::max(5, room->frames / 8);
  // The glance of poor visibility is 30-40 px wide at its key view; the walk
  // passes the key at its own pace, so its best frame may be smaller, and the
  // couch may hide the key view: below this the marker is not readable at
  // 50-70 deg (under 2.5 px per cell across its short sides; 25 px for the
  // 6 cells of a 4x4 marker).
  const double poor_at_least_px = 25.0 / 6 * marker_cells_;
  // A drawn view that sees the marker too rarely (hidden, off the image), for
  // poor visibility too often or never at a readable size, is drawn again;
  // after 12 tries the walk falls back to good views.
  for (int attempt = 0; attempt < 16; ++attempt) {
    if (attempt == 12) {
      visibility = "good";
      base = keys;
    }
    const std::vector<CameraKey> views = OriginViewKeys(visibility, &walk_rng);
    std::vector<CameraKey> all = base;
    if (views.size() == 2) {
      all.insert(all.begin(), views[0]);
      all.push_back(views[1]);
    } else if (views.size() == 1) {
      // Where it lengthens the walk least.
      const V3 v = views[0].position_m;
      size_t best = 0;
      double best_cost = (v - all.front().position_m).norm();
      for (size_t i = 1; i <= all.size(); ++i) {
        const double cost = i == all.size()
                                ? (all.back().position_m - v).norm()
                                : (all[i - 1].position_m - v).norm() + (v - all[i].position_m).norm() -
                                      (all[i - 1].position_m - all[i].position_m).norm();
        if (cost < best_cost) {
          best_cost = cost;
          best = i;
        }
      }
      all.insert(all.begin() + static_cast<std::ptrdiff_t>(best), views[0]);
    }
    room->camera = HandheldTrajectory(all, duration, trajectory_seed);
    room->camera.PaceLikeAWalk();
    origin_visibility_ = MeasureOriginVisibility(*room);
    const bool too_often = visibility == "poor" && attempt < 10 && origin_visibility_.visible_frames > poor_at_most;
    const bool too_small = visibility == "poor" && origin_visibility_.max_side_px < poor_at_least_px;
    if (origin_visibility_.visible_frames >= needed && !too_often && !too_small) break;
  }
  conditions_.origin_visibility = visibility;
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
  scene.exposure_stops = ExposureStops(s.first_timestamp_s + t);
  if (s.patient) scene.breathing_m = BreathingDisplacementM(s.first_timestamp_s + t);
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
  RenderMesh breathing_body;  // outlives Render()
  if (scene.room_from_model) {
    const Rigid3d camera_from_model = camera_from_room * *scene.room_from_model;
    RenderInstance body{world_.body_mesh, camera_from_model, kLabelBody};
    if (scene.breathing_m > 0) {
      breathing_body = BreathingBody(scene.breathing_m);
      body.mesh_override = &breathing_body;
    }
    instances.push_back(body);
    for (size_t i = 0; i < world_.sticker_meshes.size(); ++i) {
      if (scene.sticker_on.empty() || scene.sticker_on[i]) {
        Rigid3d camera_from_sticker_part = camera_from_model;
        if (scene.breathing_m > 0) {
          // A sticker rides on the skin under it.
          camera_from_sticker_part =
              camera_from_model *
              Rigid3d(Eigen::Quaterniond::Identity(),
                      V3(0, -scene.breathing_m * sticker_breathing_weight_[i], 0));
        }
        instances.push_back({world_.sticker_meshes[i], camera_from_sticker_part, kLabelSticker});
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
  out.exact = Render(world_.scene, instances, render_intrinsics_, camera_from_room,
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
    radiance = ApplyMotionBlur(radiance, out.exact, render_intrinsics_, profile_.exposure_time_s,
                               motion, kLabelHand, kBlurTaps);
  }
  if (!distort_map_x_.empty()) {
    // Through the lens: colour resampled smoothly, depth, normals and labels
    // taken from the nearest ideal pixel (no depths mixed across edges).
    const auto through_lens = [this](const cv::Mat& in, int interpolation) {
      cv::Mat o;
      cv::remap(in, o, distort_map_x_, distort_map_y_, interpolation, cv::BORDER_CONSTANT, cv::Scalar::all(0));
      return o;
    };
    const bool blurred = radiance.data != out.exact.color.data;
    out.exact.color = through_lens(out.exact.color, cv::INTER_LINEAR);
    radiance = blurred ? through_lens(radiance, cv::INTER_LINEAR) : out.exact.color;
    out.exact.depth = through_lens(out.exact.depth, cv::INTER_NEAREST);
    out.exact.normal = through_lens(out.exact.normal, cv::INTER_NEAREST);
    cv::Mat label;  // remap takes no 32-bit integers; labels are small
    out.exact.label.convertTo(label, CV_32F);
    through_lens(label, cv::INTER_NEAREST).convertTo(out.exact.label, CV_32S);
  }
  ColorEncoding encoding;
  encoding.response = response_;
  encoding.exposure_stops = scene.exposure_stops;
  encoding.sharpen_amount = options_.sharpen_amount;
  out.color = SimulateColor(radiance, profile_, noise, frame_key, encoding);
  out.depth = SimulateDepth(out.exact, profile_, noise, frame_key, depth_bias_);
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
  out.depth_timestamp_s = out.timestamp_s;
  if (depth_delay_s_ != 0) {
    // The depth sensor's exposure at its own time: the scene rendered again
    // there (camera, patient, breathing), its depth kept.
    const Scene later = SceneAt(sequence, frame, depth_delay_s_);
    const uint64_t depth_key = Hash3(key, 0x64657074ULL, 1);
    SimulatedFrame depth_frame = RenderScene(later, options_.noise, depth_key, nullptr);
    out.depth = depth_frame.depth;
    out.depth_timestamp_s = out.timestamp_s + depth_delay_s_;
  }
  return ToRoomFrame(std::move(out));
}

SimulatedFrame Simulator::ToRoomFrame(SimulatedFrame frame) const {
  if (!world_.origin_moved) return frame;
  frame.room_from_camera = world_.room_from_world * frame.room_from_camera;
  if (frame.room_from_model) frame.room_from_model = world_.room_from_world * *frame.room_from_model;
  return frame;
}

SimulatedFrame Simulator::RenderView(const Rigid3d& room_from_camera,
                                     const std::optional<Rigid3d>& room_from_model, bool noise,
                                     uint64_t frame_key, double breathing_fraction) const {
  Scene scene;
  scene.room_from_camera = room_from_camera;
  scene.room_from_model = room_from_model;
  if (world_.origin_moved) {
    const Rigid3d world_from_room = world_.room_from_world.Inverse();
    scene.room_from_camera = world_from_room * room_from_camera;
    if (room_from_model) scene.room_from_model = world_from_room * *room_from_model;
  }
  scene.lighting = &world_.planning_lighting;
  scene.breathing_m = std::clamp(breathing_fraction, 0.0, 1.0) * breathing_m_;
  SimulatedFrame out = RenderScene(scene, noise, Hash3(options_.seed, 0xF1E3ULL, frame_key), nullptr);
  out.room_from_camera = room_from_camera;
  out.room_from_model = room_from_model;
  return out;
}

SimulationTruth Simulator::Truth() const {
  SimulationTruth t;
  t.seed = options_.seed;
  t.profile = profile_.name;
  t.sensor = profile_.Describe();
  t.noise = options_.noise;
  t.hard = options_.hard;
  t.room_walk = random_conditions_ ? conditions_.room_walk : options_.room_walk;
  t.room_texture = options_.room_texture;
  t.room_frames = options_.room_frames;
  t.body_scan_frames = options_.body_scan_frames;
  t.tracking_frames = options_.tracking_frames;
  t.tracking_sequences = options_.tracking_sequences;
  const Rigid3d& room_from_world = world_.room_from_world;
  t.room_from_model_target = world_.origin_moved ? room_from_world * world_.room_from_model_target
                                                 : world_.room_from_model_target;
  t.isocentre_in_room_m = t.room_from_model_target.translation;
  t.reference_noise_sigma_m = WorldOptions().reference_noise_m;
  t.max_tessellation_difference_m = world_.max_tessellation_difference_m;
  t.couch_top_height_m = world_.couch_top_height_m;
  for (const auto& m : world_.room_markers) {
    t.room_markers.push_back(ToSimulated(m));
    if (world_.origin_moved) {
      SimulatedMarker& room = t.room_markers.back();
      room.parent_from_marker = room_from_world * room.parent_from_marker;
      for (auto& corner : room.corners_m) corner = room_from_world * corner;
    }
  }
  for (const auto& m : world_.body_markers) t.body_markers.push_back(ToSimulated(m));
  for (const auto& s : sequences_) {
    SimulatedSequence q;
    q.name = s.name;
    q.frames = s.frames;
    q.first_timestamp_s = s.first_timestamp_s;
    q.frame_interval_s = s.frame_interval_s;
    q.lighting = s.treatment_lighting ? "treatment" : "planning";
    q.patient = s.patient;
    if (auto_exposure_.enabled()) {
      for (int f = 0; f < s.frames; ++f) q.exposure_stops.push_back(ExposureStops(s.timestamp(f)));
    }
    t.sequences.push_back(q);
  }
  t.response = ResponseName(response_);
  t.auto_exposure = auto_exposure_.enabled();
  t.sharpen_amount = options_.sharpen_amount;
  t.depth_delay_s = depth_delay_s_;
  for (const auto& w : auto_exposure_.waves) {
    t.exposure_waves.push_back({w.frequency_hz, w.phase_rad, w.weight_stops});
  }
  t.depth_scale_error = depth_bias_.scale_error;
  t.depth_field_mm_at_1m = depth_bias_.field_mm_at_1m;
  t.depth_field_seed = depth_field_seed_;
  t.flying_pixels = depth_bias_.flying_pixels;
  if (breathing_m_ > 0) {
    t.breathing_amplitude_mm = 1000 * breathing_m_;
    t.breathing_period_s = breathing_period_s_;
    t.breathing_phase_rad = breathing_phase_rad_;
    for (size_t i = 0; i < world_.body_markers.size(); ++i) {
      t.sticker_breathing_weights.emplace_back(world_.body_markers[i].id, sticker_breathing_weight_[i]);
    }
  }
  t.origin_moved = world_.origin_moved;
  if (world_.origin_moved) t.world_from_room = room_from_world.Inverse();
  if (random_conditions_) {
    const SceneConditions& c = conditions_;
    const OriginVisibility& v = origin_visibility_;
    auto add = [&](const std::string& key, const std::string& value) { t.conditions.emplace_back(key, value); };
    auto num = [](double x, const char* format) { return StringPrintf(format, x); };
    add("origin_placement", c.origin_placement);
    add("origin_surface", c.origin_surface);
    add("origin_visibility", c.origin_visibility);
    add("origin_visible_frames", std::to_string(v.visible_frames));
    add("room_frames", std::to_string(v.frames));
    add("origin_median_side_px", num(v.median_side_px, "%.1f"));
    add("origin_min_side_px", num(v.min_side_px, "%.1f"));
    add("origin_max_side_px", num(v.max_side_px, "%.1f"));
    add("origin_median_view_angle_deg", num(v.median_angle_deg, "%.1f"));
    add("room_marker_count", std::to_string(world_.room_markers.size() - 1));
    add("room_marker_size_m", num(c.room_marker_size_m, "%.3f"));
    add("wall_left_x_m", num(c.layout.wall_left_x_m, "%.3f"));
    add("wall_right_x_m", num(c.layout.wall_right_x_m, "%.3f"));
    add("wall_foot_y_m", num(c.layout.wall_foot_y_m, "%.3f"));
    add("wall_head_y_m", num(c.layout.wall_head_y_m, "%.3f"));
    add("ceiling_z_m", num(c.layout.ceiling_z_m, "%.3f"));
    add("room_walk", c.room_walk);
    add("room_duration_s", num(c.room_duration_s, "%.2f"));
    add("body_scan_duration_s", num(c.body_scan_duration_s, "%.2f"));
    add("path_jitter_m", num(c.path_jitter_m, "%.3f"));
    add("response", ResponseName(c.response));
    add("auto_exposure", c.auto_exposure ? "true" : "false");
    add("depth_scale_error", num(c.depth_scale_error, "%.5f"));
    add("depth_field_mm", num(c.depth_field_mm, "%.2f"));
    add("flying_pixels", c.flying_pixels ? "true" : "false");
    add("breathing_mm", num(c.breathing_mm, "%.2f"));
    add("depth_delay_ms", num(c.depth_delay_ms, "%.1f"));
    std::string forced = "[";
    for (size_t i = 0; i < forced_.size(); ++i) forced += (i ? ", " : "") + forced_[i];
    add("forced", forced + "]");
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
  config.dictionary = options_.dictionary;
  config.room_markers = {0.15, 0, 49};
  config.room_origin_id = 0;
  config.body_markers = {0.03, 100, 199};
  config.room_markers.size_m = world_.room_markers.front().size_m;
  if (!world_.body_markers.empty()) config.body_markers.size_m = world_.body_markers.front().size_m;
  SaveCaseConfig(config, out_dir / "case.yaml");
  SaveTriangleMeshPly(world_.reference_model, out_dir / "reference_model.ply",
                      "ARPos simulated reference model: model frame (LPS, origin at the "
                      "isocentre), metres");
  const Rigid3d room_from_model_target = world_.origin_moved
                                             ? world_.room_from_world * world_.room_from_model_target
                                             : world_.room_from_model_target;
  WriteMatrix4(out_dir / "target_pose.txt", room_from_model_target.ToMatrix(),
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
      const std::string rgb_name = "rgb/" + stamp + ".png",
                        depth_name =
                            "depth/" + StringPrintf("%.6f", frame.depth_timestamp_s) + ".png";
      rgb.push_back({frame.timestamp_s, rgb_name, 0});
      depth.push_back({frame.depth_timestamp_s, depth_name, 0});
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
