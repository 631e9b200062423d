#include "plugins/simulator/simulator_source.h"

#include <chrono>
#include <thread>

#include "simulation/simulation_truth.h"
#include "simulation/simulator.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos {

namespace {

/// The options that made the case, from its simulation.yaml.
sim::SimulationOptions OptionsOf(const sim::SimulationTruth& truth) {
  sim::SimulationOptions options;
  options.profile = truth.profile;
  options.seed = truth.seed;
  options.hard = truth.hard;
  options.noise = truth.noise;
  options.room_walk = truth.room_walk;
  options.room_frames = truth.room_frames;
  options.body_scan_frames = truth.body_scan_frames;
  options.tracking_frames = truth.tracking_frames;
  options.tracking_sequences = truth.tracking_sequences;
  options.random_conditions = !truth.conditions.empty();
  if (!options.random_conditions) {
    // Forced conditions as the file records them (absent: the defaults).
    if (truth.response != "srgb") options.response = truth.response;
    if (truth.auto_exposure) options.auto_exposure = true;
    if (truth.depth_scale_error != 0) options.depth_scale_error = truth.depth_scale_error;
    if (truth.depth_field_mm_at_1m != 0) options.depth_field_mm = truth.depth_field_mm_at_1m;
    if (truth.flying_pixels) options.flying_pixels = true;
    if (truth.breathing_amplitude_mm != 0) options.breathing_mm = truth.breathing_amplitude_mm;
  }
  return options;
}

}  // namespace

SimulatorSourceOptions ParseSimulatorSourceUri(const std::string& uri) {
  SimulatorSourceOptions options;
  const SourceUri parsed = ParseSourceUri(uri);
  options.case_dir = parsed.path;
  if (options.case_dir.empty()) ARPOS_INPUT_ERROR("sim needs a simulated case folder: sim:CASE_DIR[?seq=N&frames=F&fps=R]");
  for (const auto& [key, value] : parsed.options) {
    if (key == "seq") {
      options.sequence = SourceUriInt("sim", key, value);
    } else if (key == "frames") {
      options.frames = SourceUriInt("sim", key, value);
      if (options.frames < 1 || options.frames > 100000) ARPOS_INPUT_ERROR("sim: frames=" << value << " must be 1..100000");
    } else if (key == "fps") {
      char* end = nullptr;
      options.fps = std::strtod(value.c_str(), &end);
      if (value.empty() || *end != '\0' || !(options.fps > 0 && options.fps <= 1000)) {
        ARPOS_INPUT_ERROR("sim: fps=" << value << " must be a rate in (0, 1000]");
      }
    } else {
      ARPOS_INPUT_ERROR("sim: unknown option '" << key << "' (known: seq, frames, fps)");
    }
  }
  return options;
}

struct SimulatorSource::State {
  SimulatorSourceOptions options;
  sim::SimulationTruth truth;
  std::unique_ptr<sim::Simulator> simulator;
  int sequence_index = -1;  ///< in simulator->sequences()
  CameraIntrinsics intrinsics;
  double interval_s = 1.0 / 30;
  std::vector<RgbdFrame> frames;
  size_t next = 0;
  std::chrono::steady_clock::time_point start;
};

SimulatorSource::SimulatorSource(const SimulatorSourceOptions& options) : state_(std::make_unique<State>()) {
  State& s = *state_;
  s.options = options;
  const std::filesystem::path yaml = options.case_dir / "simulation.yaml";
  if (!std::filesystem::exists(yaml)) {
    ARPOS_INPUT_ERROR(yaml.string() << ": not found; sim: needs a case written by `arpos simulate`");
  }
  s.truth = sim::LoadSimulationTruth(yaml);
  sim::SimulationOptions sim_options = OptionsOf(s.truth);
  if (options.sequence < 0 || options.sequence >= std::max(1, s.truth.tracking_sequences)) {
    ARPOS_INPUT_ERROR("sim: seq=" << options.sequence << " but the case has " << s.truth.tracking_sequences
                                  << " tracking sequence(s)");
  }
  if (options.frames > 0) sim_options.tracking_frames = options.frames;
  s.simulator = std::make_unique<sim::Simulator>(sim_options);
  const std::string name = StringPrintf("tracking/seq_%02d", options.sequence);
  const auto& sequences = s.simulator->sequences();
  for (size_t i = 0; i < sequences.size(); ++i) {
    if (sequences[i].name == name) s.sequence_index = static_cast<int>(i);
  }
  if (s.sequence_index < 0) ARPOS_INPUT_ERROR("sim: the case has no " << name);
  s.intrinsics = s.simulator->profile().intrinsics;
  const double recorded_interval = sequences[s.sequence_index].frame_interval_s;
  s.interval_s = options.fps > 0 ? 1.0 / options.fps : recorded_interval;
}

SimulatorSource::~SimulatorSource() = default;

const CameraIntrinsics& SimulatorSource::intrinsics() const { return state_->intrinsics; }

int SimulatorSource::frame_count() const {
  return state_->simulator->sequences()[state_->sequence_index].frames;
}

std::string SimulatorSource::description() const {
  const State& s = *state_;
  return StringPrintf("simulated %s of %s (seed %llu, %s), %d frames at %.1f fps",
                      s.simulator->sequences()[s.sequence_index].name.c_str(), s.options.case_dir.string().c_str(),
                      static_cast<unsigned long long>(s.truth.seed), s.truth.profile.c_str(), frame_count(),
                      1.0 / s.interval_s);
}

void SimulatorSource::OpenImpl() {
  State& s = *state_;
  if (s.frames.empty()) {
    const int n = frame_count();
    s.frames.reserve(n);
    for (int i = 0; i < n; ++i) {
      sim::SimulatedFrame rendered = s.simulator->RenderFrame(s.sequence_index, i);
      RgbdFrame frame;
      frame.index = i;
      frame.timestamp_s = rendered.timestamp_s;
      frame.color = rendered.color;
      frame.depth = rendered.depth;
      frame.depth_scale = s.intrinsics.depth_scale;
      frame.true_room_from_camera = rendered.room_from_camera;
      frame.true_room_from_model = rendered.room_from_model;
      s.frames.push_back(std::move(frame));
    }
  }
  s.next = 0;
  s.start = std::chrono::steady_clock::now();
}

bool SimulatorSource::NextImpl(RgbdFrame* frame) {
  State& s = *state_;
  if (s.next >= s.frames.size()) return false;
  // Frame k is delivered at start + k * interval, or at once when asked for
  // late. Live readers take frames through a FrameFeed (sensor/frame_feed.h),
  // whose capture thread asks without pause: a reader slower than the camera
  // loses frames there, as with a device.
  const auto due = [&](size_t k) {
    return s.start + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                         std::chrono::duration<double>(k * s.interval_s));
  };
  std::this_thread::sleep_until(due(s.next));
  const RgbdFrame& source = s.frames[s.next];
  frame->index = source.index;
  frame->timestamp_s = source.timestamp_s;
  frame->color = source.color.clone();
  frame->depth = source.depth.clone();
  frame->depth_scale = source.depth_scale;
  frame->problem.clear();
  frame->true_room_from_camera = source.true_room_from_camera;
  frame->true_room_from_model = source.true_room_from_model;
  frame->arrival = std::chrono::steady_clock::now();
  ++s.next;
  return true;
}

}  // namespace arpos
