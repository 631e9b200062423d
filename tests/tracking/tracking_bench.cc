// Tracking time per frame, by step, as `arpos track` spends it: frame arrival
// (the decoded frame handed over) to the correction ready, on two threads
// (scene and body at once, the default) and one after the other
// (--sequential).
//
//   ARPOS_TRACK_BENCH_CASE=CASE ARPOS_TRACK_BENCH_STORE=DB tracking_bench [--benchmark_filter=...]
//
// CASE is a case folder, DB a store holding its plan and session (`arpos plan
// CASE --store DB && arpos session CASE --store DB`). The tracking inputs are
// read from DB as `arpos track` reads them (LoadTrackingInputs, the case's
// patient), the camera response is estimated from the sequence once, and the
// frames of CASE/tracking/seq_00 are decoded into memory before any timing.
// Each benchmark iteration is one frame, in recording order; the sequence is
// played ARPOS_TRACK_BENCH_PASSES times (default 2), each pass with a fresh
// Tracker (made and warmed up outside the timing, as `arpos track` does
// before its first frame arrives), so every pass starts by relocalising as
// a real run does. OpenCV keeps its default thread count, as in `arpos track`.
//
// Time is manual: the wall time from arrival to correction, which includes
// the depth correction of the room map (the depth image is copied before the
// clock starts, as the correction works in place). Counters, per frame:
//   camera_ms, body_ms       wall time of the scene / body half
//   body_detection_ms, body_pose_ms   the body half by step
//   combine_ms               pose, uncertainty, correction
//   depth_correction_ms      before the tracker
//   total_ms, p95_total_ms, max_total_ms   arrival to correction
//   fps                      1000 / mean total_ms (end to end, one stream)
//   tracked                  share of frames with a patient pose
//   tracked_total_ms, tracked_p95_total_ms   the same over those frames only
//                            (a lost frame is cheaper: compare on cases
//                            that lose few)
// Without the two environment variables every benchmark is skipped with a
// message saying what to set.
#include <chrono>
#include <cstdlib>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "eval/trajectory_eval.h"
#include "features/response_from_recording.h"
#include "room_map/plan_stage.h"
#include "sensor/case_config.h"
#include "sensor/depth_correction.h"
#include "sensor/sequence.h"
#include "store/sqlite_database.h"
#include "tracking/tracker.h"
#include "tracking/tracking_stage.h"
#include "util/string_util.h"

namespace arpos {
namespace {

using Clock = std::chrono::steady_clock;
double MsSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

struct BenchData {
  std::string skip_reason;  ///< non-empty: every benchmark skips with it
  CaseConfig config;
  TrackingInputs inputs;
  TrackerOptions options;
  std::vector<RgbdFrame> frames;
  int passes = 2;
  std::string label;  ///< WxH and the case's name
};

BenchData LoadBenchData() {
  BenchData data;
  const char* case_env = std::getenv("ARPOS_TRACK_BENCH_CASE");
  const char* store_env = std::getenv("ARPOS_TRACK_BENCH_STORE");
  if (case_env == nullptr || *case_env == '\0' || store_env == nullptr || *store_env == '\0') {
    data.skip_reason =
        "tracking_bench needs a prepared case: set ARPOS_TRACK_BENCH_CASE (case folder) and "
        "ARPOS_TRACK_BENCH_STORE (its store after `arpos plan CASE --store DB` and `arpos session CASE --store DB`)";
    return data;
  }
  if (const char* passes = std::getenv("ARPOS_TRACK_BENCH_PASSES")) {
    long long n = 0;
    if (!ParseInt(passes, &n) || n < 1 || n > 1000) {
      data.skip_reason = std::string("ARPOS_TRACK_BENCH_PASSES='") + passes + "': expected a count from 1 to 1000";
      return data;
    }
    data.passes = static_cast<int>(n);
  }
  const std::filesystem::path case_root = case_env;
  const std::filesystem::path seq_dir = case_root / "tracking" / "seq_00";
  try {
    data.config = LoadCaseConfig(case_root / "case.yaml");
    SqliteOpenOptions open_options;
    open_options.create_if_missing = false;
    auto database = SqliteDatabase::Open(store_env, open_options);
    data.inputs = LoadTrackingInputs(database.get(), std::nullopt, CasePatientId(case_root));
    // What TrackSequence sets up before the first frame.
    const Sequence sequence = Sequence::OpenEveryColourFrame(seq_dir);
    data.options = MakeTrackerOptions(data.config, data.inputs);
    const RecordingResponse response =
        EstimateRecordingResponse(sequence, data.config, data.inputs.room_map.camera_response);
    data.options.camera.detector.edge.response = response.response;
    data.options.body.detector.edge.response = response.response;
    for (size_t i = 0; i < sequence.size(); ++i) {
      std::string depth_problem;
      data.frames.push_back(sequence.LoadFrameColourFirst(i, data.config.camera, &depth_problem));
    }
  } catch (const std::exception& e) {
    data.skip_reason = std::string("cannot prepare the tracking inputs: ") + e.what();
    return data;
  }
  if (data.frames.empty()) {
    data.skip_reason = seq_dir.string() + ": no frames";
    return data;
  }
  data.label = std::to_string(data.config.camera.width) + "x" + std::to_string(data.config.camera.height) + " " +
               std::filesystem::absolute(case_root).lexically_normal().filename().string();
  return data;
}

void Track(benchmark::State& state, const BenchData& data, bool parallel) {
  if (!data.skip_reason.empty()) {
    state.SkipWithError(data.skip_reason.c_str());
    return;
  }
  TrackerOptions options = data.options;
  options.parallel = parallel;
  const DepthCorrector depth_corrector(data.config.camera, data.inputs.room_map.depth_correction);
  std::unique_ptr<Tracker> tracker;
  double camera_ms = 0, body_ms = 0, body_detection_ms = 0, body_pose_ms = 0, combine_ms = 0, depth_ms = 0;
  std::vector<double> totals, tracked_totals;
  // A pass's first frame (relocalising from nothing) apart from the rest;
  // the very first frame of the benchmark apart again: the process's first
  // (Tracker::WarmUp takes the one-off costs before it: threads, first
  // allocations; without it 50-54 ms at 1280x720 against 31-32 for a later
  // run's first frame).
  double cold_first_frame_ms = -1, first_frame_max_ms = 0, later_max_ms = 0;
  int tracked = 0;
  size_t i = 0;
  for (auto _ : state) {
    if (i == 0) {
      // A new pass: a fresh tracker, as `arpos track` starts it (with the
      // patient's pose at the body scan, where it looks first; not timed).
      tracker.reset();
      tracker = std::make_unique<Tracker>(data.inputs.room_map, data.inputs.model, data.inputs.model_from_marker,
                                          data.inputs.room_from_model_target, data.config.camera, options,
                                          data.inputs.room_from_model_at_scan);
      tracker->WarmUp();
    }
    RgbdFrame frame = data.frames[i];  // shallow: the colour image is only read
    if (!frame.depth.empty()) frame.depth = data.frames[i].depth.clone();
    const auto arrival = Clock::now();
    if (!frame.depth.empty()) depth_corrector.Apply(&frame.depth);
    const double frame_depth_ms = MsSince(arrival);
    const TrackedFrame result = tracker->Process(frame);
    const double total_ms = MsSince(arrival);
    state.SetIterationTime(total_ms / 1000.0);
    benchmark::DoNotOptimize(result.correction);
    depth_ms += frame_depth_ms;
    camera_ms += result.timings.camera_ms;
    body_ms += result.timings.body_ms;
    body_detection_ms += result.timings.body.detection_ms;
    body_pose_ms += result.timings.body.pose_ms;
    combine_ms += result.timings.combine_ms;
    totals.push_back(total_ms);
    if (i == 0 && cold_first_frame_ms < 0) {
      cold_first_frame_ms = total_ms;
    } else {
      double& max_ms = i == 0 ? first_frame_max_ms : later_max_ms;
      max_ms = std::max(max_ms, total_ms);
    }
    if (result.room_from_model) {
      ++tracked;
      tracked_totals.push_back(total_ms);
    }
    i = (i + 1) % data.frames.size();
  }
  const double k = totals.empty() ? 0 : 1.0 / totals.size();
  const ErrorStats total = ComputeErrorStats(totals);
  state.counters["camera_ms"] = camera_ms * k;
  state.counters["body_ms"] = body_ms * k;
  state.counters["body_detection_ms"] = body_detection_ms * k;
  state.counters["body_pose_ms"] = body_pose_ms * k;
  state.counters["combine_ms"] = combine_ms * k;
  state.counters["depth_correction_ms"] = depth_ms * k;
  state.counters["total_ms"] = total.mean;
  state.counters["p95_total_ms"] = total.p95;
  state.counters["max_total_ms"] = total.max;
  state.counters["cold_first_frame_ms"] = cold_first_frame_ms;
  state.counters["first_frame_max_ms"] = first_frame_max_ms;
  state.counters["later_max_ms"] = later_max_ms;
  state.counters["fps"] = total.mean > 0 ? 1000.0 / total.mean : 0;
  state.counters["tracked"] = tracked * k;
  const ErrorStats tracked_total = ComputeErrorStats(tracked_totals);
  state.counters["tracked_total_ms"] = tracked_total.mean;
  state.counters["tracked_p95_total_ms"] = tracked_total.p95;
  state.SetLabel(data.label + (parallel ? " parallel" : " sequential"));
}

}  // namespace
}  // namespace arpos

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  static const arpos::BenchData data = arpos::LoadBenchData();
  if (!data.skip_reason.empty()) std::cerr << "tracking_bench: skipped: " << data.skip_reason << "\n";
  // Whole passes over the sequence: the iteration count is the frame count
  // times the passes, known only once the case is read.
  const benchmark::IterationCount iterations =
      data.skip_reason.empty() ? static_cast<benchmark::IterationCount>(data.frames.size()) * data.passes : 1;
  for (const bool parallel : {true, false}) {
    benchmark::RegisterBenchmark(parallel ? "BM_TrackParallel" : "BM_TrackSequential",
                                 [parallel](benchmark::State& state) { arpos::Track(state, data, parallel); })
        ->Iterations(iterations)
        ->UseManualTime()
        ->Unit(benchmark::kMillisecond);
  }
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
