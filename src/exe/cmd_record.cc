// `arpos record`: any camera source written as a DATASET.md sequence folder.
#include <atomic>
#include <csignal>
#include <chrono>
#include <iostream>
#include <thread>

#include "exe/args.h"
#include "exe/commands.h"
#include "sensor/frame_feed.h"
#include "sensor/recorder.h"
#include "sensor/source_plugin.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos {

namespace {

std::atomic<bool> g_interrupted{false};
void OnInterrupt(int) { g_interrupted = true; }

// The markers of DATASET.md's example, for a case.yaml the recorder writes.
CaseConfig DatasetExampleMarkers() {
  CaseConfig config;
  config.dictionary = "DICT_4X4_250";
  config.room_markers = {0.15, 0, 49};
  config.room_origin_id = 0;
  config.body_markers = {0.03, 100, 199};
  return config;
}

}  // namespace

int RunRecordCommand(const std::vector<std::string>& argv) {
  const char* usage =
      "usage: arpos record --source SPEC --out SEQ_DIR [--seconds S] [--frames N] [options]\n"
      "Writes what a camera source delivers as a sequence folder (DATASET.md: rgb/, depth/,\n"
      "rgb.txt, depth.txt), so a live session can be replayed (replay:SEQ_DIR) and audited.\n"
      "PNGs are written off the capture thread; when writing falls behind, frames are dropped\n"
      "and counted, never waited for. Ctrl-C stops and keeps what was recorded.\n"
      "SEQ_DIR belongs to a case: CASE/tracking/NAME (or CASE/room, CASE/body_scan). When CASE\n"
      "has a case.yaml, the source must match its image size and depth is written in its units;\n"
      "otherwise one is written with the source's camera and DATASET.md's example markers.\n"
      "  --source SPEC   a camera source (`arpos sources` lists them): sim:CASE, openni2:, replay:SEQ\n"
      "  --seconds S     stop after S seconds of capture (default: the end of the stream)\n"
      "  --frames N      stop after N frames\n"
      "  --queue N       frames waiting to be written at most (default 90, ~3 s at 30 fps)\n"
      "  --writers N     PNG writer threads (default 2)\n"
      "  --encode-later  write raw images while capturing and the PNGs at the end (a PNG takes\n"
      "                  25-50 ms a 640x480 frame here; ~1.5 MB of disk a frame until the end)\n";
  const Args args(argv, {"source", "out", "seconds", "frames", "queue", "writers"}, {"help", "encode-later"});
  if (auto exit = UsageExit(args, usage, 0)) return *exit;
  const std::string spec = args.Require("source");
  const std::filesystem::path out = args.Require("out");
  const double seconds = args.GetDouble("seconds", 0);
  const long long max_frames = args.GetInt("frames", 0);
  if (seconds < 0 || !std::isfinite(seconds)) ARPOS_INPUT_ERROR("--seconds: must be a positive duration");
  if (max_frames < 0) ARPOS_INPUT_ERROR("--frames: must be positive");
  RecorderOptions options;
  options.queue_frames = static_cast<int>(args.GetInt("queue", 90));
  options.writer_threads = static_cast<int>(args.GetInt("writers", 2));
  options.encode_later = args.Has("encode-later");
  if (options.queue_frames < 1 || options.queue_frames > 10000) ARPOS_INPUT_ERROR("--queue: 1..10000 frames");
  if (options.writer_threads < 1 || options.writer_threads > 16) ARPOS_INPUT_ERROR("--writers: 1..16 threads");

  std::unique_ptr<CameraSource> source = SourceRegistry().Create(spec);
  const RecordingFolder folder = PrepareRecordingFolder(out, source->intrinsics(), DatasetExampleMarkers(),
                                                        "DATASET.md's example");
  if (!folder.note.empty()) std::cerr << "record: " << folder.note << "\n";
  options.depth_scale = folder.depth_scale;
  SequenceRecorder recorder(out, options);
  std::cerr << "record: " << source->description() << " -> " << out.string() << "\n";

  std::signal(SIGINT, OnInterrupt);
  std::signal(SIGTERM, OnInterrupt);
  // The recorder sees every frame on the capture thread; this thread only
  // counts and watches the clock.
  std::atomic<long long> offered{0};
  FrameFeed feed(source.get(), [&](const RgbdFrame& frame) {
    if (max_frames <= 0 || offered++ < max_frames) recorder.Push(frame);
  });
  const auto start = std::chrono::steady_clock::now();
  RgbdFrame frame;
  int taken = 0;
  std::string stop_reason = "end of the stream";
  while (feed.Take(&frame)) {
    ++taken;
    if (g_interrupted) {
      stop_reason = "interrupted";
      break;
    }
    if (max_frames > 0 && feed.captured() >= max_frames) {
      stop_reason = StringPrintf("%lld frames", max_frames);
      break;
    }
    if (seconds > 0 && std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() >= seconds) {
      stop_reason = StringPrintf("%g s", seconds);
      break;
    }
  }
  feed.Stop();
  std::signal(SIGINT, SIG_DFL);
  std::signal(SIGTERM, SIG_DFL);
  const RecorderStats stats = recorder.Finish();
  std::cout << "recorded " << out.string() << " (" << stop_reason << "): " << stats.Summary() << "\n";
  if (stats.written == 0) {
    std::cerr << "record: no frame was written\n";
    return 1;
  }
  return 0;
}

}  // namespace arpos
