#include "plugins/replay/replay_source.h"

#include <thread>

#include "sensor/case_config.h"
#include "util/check.h"

namespace arpos {

ReplaySource::ReplaySource(std::filesystem::path sequence_dir, CameraIntrinsics intrinsics,
                           ReplayOptions options)
    : dir_(std::move(sequence_dir)),
      intrinsics_(intrinsics),
      options_(options),
      sequence_(Sequence::OpenEveryColourFrame(dir_)) {}

std::string ReplaySource::description() const {
  return "replay of " + dir_.string() + (options_.realtime ? " at the recorded rate" : "");
}

int ReplaySource::frame_count() const {
  const int step = 1 + std::max(0, options_.frame_step);
  return static_cast<int>((sequence_.size() + step - 1) / step);
}

void ReplaySource::OpenImpl() {
  next_ = 0;
  start_wall_ = std::chrono::steady_clock::now();
  start_timestamp_s_ = sequence_.size() ? sequence_.timestamp_s(0) : 0;
}

bool ReplaySource::NextImpl(RgbdFrame* frame) {
  if (next_ >= sequence_.size()) return false;
  if (options_.realtime) {
    const double offset_s = sequence_.timestamp_s(next_) - start_timestamp_s_;
    std::this_thread::sleep_until(start_wall_ + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                                    std::chrono::duration<double>(offset_s)));
  }
  std::string depth_problem;
  try {
    *frame = sequence_.LoadFrameColourFirst(next_, intrinsics_, &depth_problem);
    frame->problem = depth_problem;
  } catch (const InputError& e) {
    *frame = RgbdFrame();
    frame->index = static_cast<int>(next_);
    frame->timestamp_s = sequence_.timestamp_s(next_);
    frame->problem = e.what();
  }
  // Arrival: once the frame is in memory (reading the files is not part of
  // the latency, timing.csv's load_ms).
  frame->arrival = std::chrono::steady_clock::now();
  next_ += 1 + std::max(0, options_.frame_step);
  return true;
}

std::unique_ptr<CameraSource> MakeReplaySourceFromUri(const std::string& uri) {
  const SourceUri parsed = ParseSourceUri(uri);
  const std::string& path = parsed.path;
  ReplayOptions options;
  std::filesystem::path case_dir;
  for (const auto& [key, value] : parsed.options) {
    if (key == "realtime" && value.empty()) {
      options.realtime = true;
    } else if (key == "case" && !value.empty()) {
      case_dir = value;
    } else {
      ARPOS_INPUT_ERROR("replay:" << uri << ": unknown option '" << key << "' (known: realtime, case=DIR)");
    }
  }
  if (path.empty()) ARPOS_INPUT_ERROR("replay needs a sequence folder: replay:SEQUENCE_DIR");
  const std::filesystem::path dir = std::filesystem::absolute(path).lexically_normal();
  if (!std::filesystem::is_directory(dir)) {
    ARPOS_INPUT_ERROR(dir.string() << ": sequence folder does not exist");
  }
  if (!case_dir.empty()) {
    if (!std::filesystem::exists(case_dir / "case.yaml")) ARPOS_INPUT_ERROR((case_dir / "case.yaml").string() << ": not found");
    return std::make_unique<ReplaySource>(dir, LoadCaseConfig(case_dir / "case.yaml").camera, options);
  }
  std::filesystem::path probe = dir;
  for (int up = 0; up < 3 && probe.has_parent_path(); ++up) {
    probe = probe.parent_path();
    if (std::filesystem::exists(probe / "case.yaml")) {
      return std::make_unique<ReplaySource>(dir, LoadCaseConfig(probe / "case.yaml").camera, options);
    }
  }
  ARPOS_INPUT_ERROR(dir.string() << ": no case.yaml found above this sequence folder");
}

}  // namespace arpos
