#include "simulation/simulation_truth.h"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <sstream>

#include "sensor/yaml_file.h"
#include "util/check.h"
#include "util/file.h"
#include "util/string_util.h"

namespace arpos::sim {
namespace {

// Rounding noise (1e-16, -0) is printed as 0 so the file reads cleanly.
std::string Num(double v) { return StringPrintf("%.9g", std::abs(v) < 1e-12 ? 0.0 : v); }

std::string Matrix(const Rigid3d& pose) {
  const Eigen::Matrix4d m = pose.ToMatrix();
  std::string s = "[";
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) s += (r || c ? ", " : "") + Num(m(r, c));
  return s + "]";
}

std::string Vec(const Eigen::Vector3d& v) {
  return "[" + Num(v.x()) + ", " + Num(v.y()) + ", " + Num(v.z()) + "]";
}

std::string Quote(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + "\"";
}

void WriteMarkers(std::ostringstream& out, const char* key, const char* pose_key,
                  const std::vector<SimulatedMarker>& markers, bool with_raise) {
  out << key << ":" << (markers.empty() ? " []" : "") << "\n";
  for (const auto& m : markers) {
    out << "  - id: " << m.id << "\n"
        << "    size_m: " << Num(m.size_m) << "\n"
        << "    surface: " << m.surface << "\n";
    if (with_raise) out << "    raise_m: " << Num(m.raise_m) << "\n";
    out << "    " << pose_key << ": " << Matrix(m.parent_from_marker) << "\n"
        << "    corners_m: [" << Vec(m.corners_m[0]) << ", " << Vec(m.corners_m[1]) << ", "
        << Vec(m.corners_m[2]) << ", " << Vec(m.corners_m[3]) << "]\n";
  }
}

// --- Reading --------------------------------------------------------------

struct Reader {
  std::filesystem::path path;
  [[noreturn]] void Fail(const std::string& key, const std::string& what) const {
    ARPOS_INPUT_ERROR(path.string() << ": " << key << ": " << what);
  }
  YAML::Node Need(const YAML::Node& node, const std::string& key, const std::string& where) const {
    if (!node[key]) Fail(where + key, "missing");
    return node[key];
  }
  template <typename T>
  T As(const YAML::Node& node, const std::string& key) const {
    try {
      return node.as<T>();
    } catch (const YAML::Exception& e) {
      Fail(key, std::string("malformed: ") + e.what());
    }
  }
  Rigid3d Pose(const YAML::Node& node, const std::string& key) const {
    const auto v = As<std::vector<double>>(node, key);
    if (v.size() != 16) Fail(key, "expected 16 numbers");
    Eigen::Matrix4d m;
    for (int i = 0; i < 16; ++i) m(i / 4, i % 4) = v[i];
    std::string reason;
    if (!IsRigidTransform(m, 1e-6, &reason)) Fail(key, "not a rigid transform: " + reason);
    return Rigid3d::FromMatrix(m, 1e-6);
  }
  Eigen::Vector3d Vec3(const YAML::Node& node, const std::string& key) const {
    const auto v = As<std::vector<double>>(node, key);
    if (v.size() != 3) Fail(key, "expected 3 numbers");
    return {v[0], v[1], v[2]};
  }
  std::vector<SimulatedMarker> Markers(const YAML::Node& root, const std::string& key,
                                       const std::string& pose_key) const {
    std::vector<SimulatedMarker> markers;
    const YAML::Node list = Need(root, key, "");
    for (size_t i = 0; i < list.size(); ++i) {
      const YAML::Node n = list[i];
      const std::string where = key + "[" + std::to_string(i) + "].";
      SimulatedMarker m;
      m.id = As<int>(Need(n, "id", where), where + "id");
      m.size_m = As<double>(Need(n, "size_m", where), where + "size_m");
      m.surface = As<std::string>(Need(n, "surface", where), where + "surface");
      if (n["raise_m"]) m.raise_m = As<double>(n["raise_m"], where + "raise_m");
      m.parent_from_marker = Pose(Need(n, pose_key, where), where + pose_key);
      const YAML::Node corners = Need(n, "corners_m", where);
      if (corners.size() != 4) Fail(where + "corners_m", "expected 4 corners");
      for (int c = 0; c < 4; ++c) m.corners_m[c] = Vec3(corners[c], where + "corners_m");
      markers.push_back(m);
    }
    return markers;
  }
};

}  // namespace

void SaveSimulationTruth(const SimulationTruth& t, const std::filesystem::path& path) {
  std::ostringstream out;
  out << "# ARPos simulated case: ground truth beyond the case folder.\n"
      << "# Format: src/simulation/simulation_truth.h. Poses: 4x4 row-major b_from_a, metres.\n"
      << "format: arpos-simulation-1\n"
      << "generator: arpos simulate\n"
      << "seed: " << t.seed << "\n"
      << "profile: " << t.profile << "\n"
      << "sensor: " << Quote(t.sensor) << "\n"
      << "noise: " << (t.noise ? "true" : "false") << "\n"
      << "hard: " << (t.hard ? "true" : "false") << "\n"
      << "room_walk: " << t.room_walk << "\n"
      << (t.room_texture == "rich" ? "" : "room_texture: " + t.room_texture + "\n")  // rich: as before
      << "frames: {room: " << t.room_frames << ", body_scan: " << t.body_scan_frames
      << ", tracking: " << t.tracking_frames << ", tracking_sequences: " << t.tracking_sequences
      << "}\n"
      << (t.origin_moved
              ? "room_frame: \"room marker 0 (conditions: origin_surface): origin at its printed centre, "
                "x right, y up, z out of its face\"\n"
              : "room_frame: \"room marker 0 on the floor beside the couch foot: origin at its printed "
                "centre, x/y along the floor, z up; floor surface at z = -0.0003\"\n")
      << "model_frame: \"reference model: patient LPS axes (x left, y posterior, z superior), "
         "origin at the isocentre\"\n"
      << "isocentre_in_room_m: " << Vec(t.isocentre_in_room_m) << "\n"
      << "room_from_model_target: " << Matrix(t.room_from_model_target) << "\n"
      << "reference_model:\n"
      << "  file: reference_model.ply\n"
      << "  noise_sigma_m: " << Num(t.reference_noise_sigma_m) << "\n"
      << "  max_tessellation_difference_m: " << Num(t.max_tessellation_difference_m) << "\n"
      << "couch_top_height_m: " << Num(t.couch_top_height_m) << "\n";
  WriteMarkers(out, "room_markers", "room_from_marker", t.room_markers, false);
  WriteMarkers(out, "body_markers", "model_from_marker", t.body_markers, true);
  out << "sequences:\n";
  for (const auto& s : t.sequences) {
    out << "  - name: " << s.name << "\n"
        << "    frames: " << s.frames << "\n"
        << "    first_timestamp_s: " << StringPrintf("%.6f", s.first_timestamp_s) << "\n"
        << "    frame_interval_s: " << Num(s.frame_interval_s) << "\n"
        << "    lighting: " << s.lighting << "\n"
        << "    patient: " << (s.patient ? "true" : "false") << "\n";
    if (!s.exposure_stops.empty()) {
      out << "    exposure_stops: [";
      for (size_t i = 0; i < s.exposure_stops.size(); ++i) {
        out << (i ? ", " : "") << StringPrintf("%.4f", s.exposure_stops[i]);
      }
      out << "]\n";
    }
  }
  if (!t.hard) {
    out << "hard_effects: {}\n";
  } else {
    out << "hard_effects:\n"
        << "  motion_blur: {exposure_s: " << Num(t.motion_blur_exposure_s)
        << ", taps: " << t.motion_blur_taps << "}\n"
        << "  lighting_change: {from_sequence: " << t.lighting_change_from_sequence << "}\n";
    if (t.hand_first_frame >= 0) {
      out << "  hand_occluder: {sequence: " << t.hand_sequence
          << ", first_frame: " << t.hand_first_frame << ", last_frame: " << t.hand_last_frame
          << ", first_timestamp_s: " << StringPrintf("%.6f", t.hand_first_timestamp_s)
          << ", last_timestamp_s: " << StringPrintf("%.6f", t.hand_last_timestamp_s) << "}\n";
    }
    if (t.sticker_off_marker_id >= 0) {
      out << "  sticker_falls_off: {marker_id: " << t.sticker_off_marker_id
          << ", sequence: " << t.sticker_off_sequence << ", frame: " << t.sticker_off_frame
          << ", timestamp_s: " << StringPrintf("%.6f", t.sticker_off_timestamp_s) << "}\n";
    }
  }
  if (t.response != "srgb" || t.auto_exposure || t.sharpen_amount != 0) {
    out << "camera_response:\n"
        << "  response: " << t.response << "\n"
        << "  auto_exposure: " << (t.auto_exposure ? "true" : "false") << "\n";
    if (t.sharpen_amount != 0) out << "  sharpen_amount: " << Num(t.sharpen_amount) << "\n";
    if (!t.exposure_waves.empty()) {
      out << "  exposure_waves: [";
      for (size_t i = 0; i < t.exposure_waves.size(); ++i) {
        const auto& w = t.exposure_waves[i];
        out << (i ? ", " : "") << "[" << Num(w[0]) << ", " << Num(w[1]) << ", " << Num(w[2]) << "]";
      }
      out << "]\n";
    }
  }
  if (t.depth_scale_error != 0 || t.depth_field_mm_at_1m != 0 || t.flying_pixels) {
    out << "depth_bias:\n"
        << "  scale_error: " << Num(t.depth_scale_error) << "\n"
        << "  field_mm_at_1m: " << Num(t.depth_field_mm_at_1m) << "\n"
        << "  field_seed: " << t.depth_field_seed << "\n"
        << "  flying_pixels: " << (t.flying_pixels ? "true" : "false") << "\n";
  }
  if (t.depth_delay_s != 0) out << "depth_timing:\n  delay_s: " << Num(t.depth_delay_s) << "\n";
  if (t.breathing_amplitude_mm > 0) {
    out << "breathing:\n"
        << "  amplitude_mm: " << Num(t.breathing_amplitude_mm) << "\n"
        << "  period_s: " << Num(t.breathing_period_s) << "\n"
        << "  phase_rad: " << Num(t.breathing_phase_rad) << "\n"
        << "  sticker_weights: {";
    for (size_t i = 0; i < t.sticker_breathing_weights.size(); ++i) {
      out << (i ? ", " : "") << t.sticker_breathing_weights[i].first << ": "
          << StringPrintf("%.3f", t.sticker_breathing_weights[i].second);
    }
    out << "}\n";
  }
  if (t.origin_moved) out << "world_from_room: " << Matrix(t.world_from_room) << "\n";
  if (!t.conditions.empty()) {
    out << "conditions:\n";
    for (const auto& [key, value] : t.conditions) out << "  " << key << ": " << value << "\n";
  }
  WriteFileAtomic(path, out.str());
}

SimulationTruth LoadSimulationTruth(const std::filesystem::path& path) {
  Reader r{path};
  const YAML::Node root = LoadYamlFile(path);
  if (!root.IsMap()) r.Fail("(root)", "expected a mapping");
  if (r.As<std::string>(r.Need(root, "format", ""), "format") != "arpos-simulation-1") {
    r.Fail("format", "expected arpos-simulation-1");
  }
  SimulationTruth t;
  t.seed = r.As<uint64_t>(r.Need(root, "seed", ""), "seed");
  t.profile = r.As<std::string>(r.Need(root, "profile", ""), "profile");
  t.sensor = r.As<std::string>(r.Need(root, "sensor", ""), "sensor");
  t.noise = r.As<bool>(r.Need(root, "noise", ""), "noise");
  t.hard = r.As<bool>(r.Need(root, "hard", ""), "hard");
  if (const YAML::Node walk = root["room_walk"]) t.room_walk = r.As<std::string>(walk, "room_walk");
  if (const YAML::Node tex = root["room_texture"]) t.room_texture = r.As<std::string>(tex, "room_texture");
  const YAML::Node frames = r.Need(root, "frames", "");
  t.room_frames = r.As<int>(r.Need(frames, "room", "frames."), "frames.room");
  t.body_scan_frames = r.As<int>(r.Need(frames, "body_scan", "frames."), "frames.body_scan");
  t.tracking_frames = r.As<int>(r.Need(frames, "tracking", "frames."), "frames.tracking");
  t.tracking_sequences =
      r.As<int>(r.Need(frames, "tracking_sequences", "frames."), "frames.tracking_sequences");
  t.isocentre_in_room_m = r.Vec3(r.Need(root, "isocentre_in_room_m", ""), "isocentre_in_room_m");
  t.room_from_model_target =
      r.Pose(r.Need(root, "room_from_model_target", ""), "room_from_model_target");
  const YAML::Node ref = r.Need(root, "reference_model", "");
  t.reference_noise_sigma_m =
      r.As<double>(r.Need(ref, "noise_sigma_m", "reference_model."), "reference_model.noise_sigma_m");
  t.max_tessellation_difference_m =
      r.As<double>(r.Need(ref, "max_tessellation_difference_m", "reference_model."),
                   "reference_model.max_tessellation_difference_m");
  t.couch_top_height_m = r.As<double>(r.Need(root, "couch_top_height_m", ""), "couch_top_height_m");
  t.room_markers = r.Markers(root, "room_markers", "room_from_marker");
  t.body_markers = r.Markers(root, "body_markers", "model_from_marker");
  const YAML::Node seqs = r.Need(root, "sequences", "");
  for (size_t i = 0; i < seqs.size(); ++i) {
    const std::string where = "sequences[" + std::to_string(i) + "].";
    SimulatedSequence s;
    s.name = r.As<std::string>(r.Need(seqs[i], "name", where), where + "name");
    s.frames = r.As<int>(r.Need(seqs[i], "frames", where), where + "frames");
    s.first_timestamp_s =
        r.As<double>(r.Need(seqs[i], "first_timestamp_s", where), where + "first_timestamp_s");
    s.frame_interval_s =
        r.As<double>(r.Need(seqs[i], "frame_interval_s", where), where + "frame_interval_s");
    s.lighting = r.As<std::string>(r.Need(seqs[i], "lighting", where), where + "lighting");
    s.patient = r.As<bool>(r.Need(seqs[i], "patient", where), where + "patient");
    if (const YAML::Node e = seqs[i]["exposure_stops"]) {
      s.exposure_stops = r.As<std::vector<double>>(e, where + "exposure_stops");
    }
    t.sequences.push_back(s);
  }
  const YAML::Node hard = r.Need(root, "hard_effects", "");
  if (const YAML::Node mb = hard["motion_blur"]) {
    t.motion_blur_exposure_s = r.As<double>(r.Need(mb, "exposure_s", "hard_effects.motion_blur."),
                                            "hard_effects.motion_blur.exposure_s");
    t.motion_blur_taps = r.As<int>(r.Need(mb, "taps", "hard_effects.motion_blur."),
                                   "hard_effects.motion_blur.taps");
  }
  if (const YAML::Node lc = hard["lighting_change"]) {
    t.lighting_change_from_sequence =
        r.As<std::string>(r.Need(lc, "from_sequence", "hard_effects.lighting_change."),
                          "hard_effects.lighting_change.from_sequence");
  }
  if (const YAML::Node h = hard["hand_occluder"]) {
    const std::string w = "hard_effects.hand_occluder.";
    t.hand_sequence = r.As<std::string>(r.Need(h, "sequence", w), w + "sequence");
    t.hand_first_frame = r.As<int>(r.Need(h, "first_frame", w), w + "first_frame");
    t.hand_last_frame = r.As<int>(r.Need(h, "last_frame", w), w + "last_frame");
    t.hand_first_timestamp_s = r.As<double>(r.Need(h, "first_timestamp_s", w), w + "first_timestamp_s");
    t.hand_last_timestamp_s = r.As<double>(r.Need(h, "last_timestamp_s", w), w + "last_timestamp_s");
  }
  if (const YAML::Node s = hard["sticker_falls_off"]) {
    const std::string w = "hard_effects.sticker_falls_off.";
    t.sticker_off_marker_id = r.As<int>(r.Need(s, "marker_id", w), w + "marker_id");
    t.sticker_off_sequence = r.As<std::string>(r.Need(s, "sequence", w), w + "sequence");
    t.sticker_off_frame = r.As<int>(r.Need(s, "frame", w), w + "frame");
    t.sticker_off_timestamp_s = r.As<double>(r.Need(s, "timestamp_s", w), w + "timestamp_s");
  }
  if (const YAML::Node cr = root["camera_response"]) {
    const std::string w = "camera_response.";
    t.response = r.As<std::string>(r.Need(cr, "response", w), w + "response");
    t.auto_exposure = r.As<bool>(r.Need(cr, "auto_exposure", w), w + "auto_exposure");
    if (const YAML::Node a = cr["sharpen_amount"]) t.sharpen_amount = r.As<double>(a, w + "sharpen_amount");
    if (const YAML::Node waves = cr["exposure_waves"]) {
      for (size_t i = 0; i < waves.size(); ++i) {
        const auto v = r.As<std::vector<double>>(waves[i], w + "exposure_waves");
        if (v.size() != 3) r.Fail(w + "exposure_waves", "expected [frequency_hz, phase_rad, weight_stops]");
        t.exposure_waves.push_back({v[0], v[1], v[2]});
      }
    }
  }
  if (const YAML::Node db = root["depth_bias"]) {
    const std::string w = "depth_bias.";
    t.depth_scale_error = r.As<double>(r.Need(db, "scale_error", w), w + "scale_error");
    t.depth_field_mm_at_1m = r.As<double>(r.Need(db, "field_mm_at_1m", w), w + "field_mm_at_1m");
    t.depth_field_seed = r.As<uint64_t>(r.Need(db, "field_seed", w), w + "field_seed");
    t.flying_pixels = r.As<bool>(r.Need(db, "flying_pixels", w), w + "flying_pixels");
  }
  if (const YAML::Node dt = root["depth_timing"]) {
    t.depth_delay_s = r.As<double>(r.Need(dt, "delay_s", "depth_timing."), "depth_timing.delay_s");
  }
  if (const YAML::Node b = root["breathing"]) {
    const std::string w = "breathing.";
    t.breathing_amplitude_mm = r.As<double>(r.Need(b, "amplitude_mm", w), w + "amplitude_mm");
    t.breathing_period_s = r.As<double>(r.Need(b, "period_s", w), w + "period_s");
    t.breathing_phase_rad = r.As<double>(r.Need(b, "phase_rad", w), w + "phase_rad");
    if (const YAML::Node sw = b["sticker_weights"]) {
      for (const auto& kv : sw) {
        t.sticker_breathing_weights.emplace_back(r.As<int>(kv.first, w + "sticker_weights"),
                                                 r.As<double>(kv.second, w + "sticker_weights"));
      }
    }
  }
  if (const YAML::Node wr = root["world_from_room"]) {
    t.origin_moved = true;
    t.world_from_room = r.Pose(wr, "world_from_room");
  }
  if (const YAML::Node c = root["conditions"]) {
    if (!c.IsMap()) r.Fail("conditions", "expected a mapping");
    for (const auto& kv : c) {
      const std::string key = r.As<std::string>(kv.first, "conditions");
      std::string value;
      if (kv.second.IsScalar()) {
        value = kv.second.Scalar();
      } else {
        YAML::Emitter e;
        e << YAML::Flow << kv.second;
        value = e.c_str();
      }
      t.conditions.emplace_back(key, value);
    }
  }
  return t;
}

std::string SimulationTruth::Condition(const std::string& key) const {
  for (const auto& [k, v] : conditions) {
    if (k == key) return v;
  }
  return "";
}

}  // namespace arpos::sim
