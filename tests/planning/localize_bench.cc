// Camera localisation time per frame, by step, at 640x480 (xtion) and
// 1280x720 (l515), on one core (cv::setNumThreads(1), one thread).
//
//   localize_bench [--benchmark_filter=...]
//
// Cases: $LOCALIZE_BENCH_XTION / $LOCALIZE_BENCH_L515 may name simulated case
// folders (`arpos simulate`; the figures quoted in the closing notes come from
// 60-frame room walks with the patient in the tracking views); otherwise a
// small case per profile is simulated first (~30 s each) whose tracking
// frames are room-walk frames between the mapped ones. Check `localised`:
// lost frames time failed relocalisation, not tracking. The room map is built from the
// case's room/ sequence; frames of tracking/seq_00 are preloaded and played
// forwards and backwards (so tracking never jumps).
//
// Counters (per frame, milliseconds of thread CPU time as the localiser
// measures them): detection, keypoints, matching, pnp, refinement, total;
// `localised` is the share of frames with a pose; `fps_cpu` = 1000 / total.
// BM_NearestTwoOfRows: the brute-force descriptor search alone, no case.
#include <cstdlib>
#include <map>
#include <memory>

#include <benchmark/benchmark.h>
#include <opencv2/core.hpp>

#include "planning/planning_test_util.h"
#include "room_map/camera_localizer.h"
#include "room_map/keypoints.h"
#include "room_map/plan_stage.h"
#include "sensor/sequence.h"

namespace arpos {
namespace {

struct BenchData {
  CaseFolder folder;
  RoomMap map;
  std::vector<RgbdFrame> frames;
};

const BenchData& Data(const std::string& profile) {
  static std::map<std::string, std::unique_ptr<BenchData>> cache;
  auto& slot = cache[profile];
  if (slot) return *slot;
  slot = std::make_unique<BenchData>();
  const char* env = std::getenv(profile == "xtion" ? "LOCALIZE_BENCH_XTION" : "LOCALIZE_BENCH_L515");
  if (env != nullptr && *env != '\0') {
    slot->folder = LoadCaseFolder(env);
    slot->map = BuildRoomMap(Sequence::Open(slot->folder.room_dir), slot->folder.config,
                             MakeRoomMapBuildOptions(slot->folder, RoomMapStageOptions()))
                    .map;
  } else {
    // Views the small map covers (consecutive room-walk frames): the
    // simulator's own tracking sequence is mostly lost against a 40-frame
    // map, and lost frames would time relocalisation attempts, not tracking.
    slot->folder = testing::GetSmallCase(profile, 40, 30, true).folder;
    slot->map = testing::GetSmallCaseMap(profile, 40, 30, true).map;
  }
  const Sequence seq = Sequence::Open(slot->folder.tracking.at(0).second);
  const size_t n = std::min<size_t>(seq.size(), 60);
  for (size_t i = 0; i < n; ++i) slot->frames.push_back(seq.LoadFrame(i, slot->folder.config.camera));
  return *slot;
}

void Localize(benchmark::State& state, const std::string& profile, bool relocalise_every_frame,
              bool keypoints) {
  cv::setNumThreads(1);
  const BenchData& data = Data(profile);
  CameraLocalizerOptions options = MakeCameraLocalizerOptions(data.folder.config);
  options.use_keypoints = keypoints;
  CameraLocalizer localizer(data.map, data.folder.config.camera, options);
  const int n = static_cast<int>(data.frames.size());
  LocalizationTimings sum;
  int frames = 0, localised = 0, i = 0, step = 1;
  double clock_s = 0;
  for (auto _ : state) {
    if (relocalise_every_frame) localizer.Reset();
    RgbdFrame frame = data.frames[i];  // shallow copy; timestamps must increase
    frame.timestamp_s = clock_s;
    const LocalizationResult r = localizer.Localize(frame);
    benchmark::DoNotOptimize(r.room_from_camera);
    sum.detection_ms += r.timings.detection_ms;
    sum.keypoints_ms += r.timings.keypoints_ms;
    sum.matching_ms += r.timings.matching_ms;
    sum.pnp_ms += r.timings.pnp_ms;
    sum.refinement_ms += r.timings.refinement_ms;
    sum.total_ms += r.timings.total_ms;
    localised += r.ok;
    ++frames;
    // Ping-pong through the sequence at its own frame interval.
    if (i + step < 0 || i + step >= n) step = -step;
    const double dt = n > 1 ? std::abs(data.frames[std::min(n - 1, i + 1)].timestamp_s -
                                       data.frames[std::max(0, std::min(n - 2, i))].timestamp_s)
                            : 1.0 / 30;
    i += step;
    clock_s += dt;
  }
  const double k = frames ? 1.0 / frames : 0;
  state.counters["detection_ms"] = sum.detection_ms * k;
  state.counters["keypoints_ms"] = sum.keypoints_ms * k;
  state.counters["matching_ms"] = sum.matching_ms * k;
  state.counters["pnp_ms"] = sum.pnp_ms * k;
  state.counters["refinement_ms"] = sum.refinement_ms * k;
  state.counters["total_ms"] = sum.total_ms * k;
  state.counters["fps_cpu"] = sum.total_ms > 0 ? 1000.0 * frames / sum.total_ms : 0;
  state.counters["localised"] = localised * k;
  state.SetLabel(std::to_string(data.frames.front().color.cols) + "x" +
                 std::to_string(data.frames.front().color.rows));
}

void BM_Track_640x480(benchmark::State& s) { Localize(s, "xtion", false, true); }
void BM_Track_1280x720(benchmark::State& s) { Localize(s, "l515", false, true); }
void BM_TrackMarkersOnly_640x480(benchmark::State& s) { Localize(s, "xtion", false, false); }
void BM_TrackMarkersOnly_1280x720(benchmark::State& s) { Localize(s, "l515", false, false); }
void BM_Relocalize_640x480(benchmark::State& s) { Localize(s, "xtion", true, true); }
void BM_Relocalize_1280x720(benchmark::State& s) { Localize(s, "l515", true, true); }

// Brute-force matching as relocalisation does it (MatchGlobally): 1000
// keypoints against 4000 map landmarks, random ORB-sized descriptors;
// Arg 0 the SSE2 reference, 1 what NearestTwoOfRows runs on this processor
// (label: avx2 or sse2). ms per 1000 x 4000.
void BM_NearestTwoOfRows(benchmark::State& state) {
  cv::Mat queries(1000, 32, CV_8U), rows(4000, 32, CV_8U);
  cv::randu(queries, 0, 256);
  cv::randu(rows, 0, 256);
  const bool dispatched = state.range(0) == 1;
  long checksum = 0;
  for (auto _ : state) {
    for (int i = 0; i < queries.rows; ++i) {
      const NearestTwo n =
          dispatched ? NearestTwoOfRows(queries.ptr<std::uint8_t>(i), rows, 0, rows.rows)
                     : NearestTwoOfRowsPortable(queries.ptr<std::uint8_t>(i), rows, 0, rows.rows);
      checksum += n.best + n.d1 + n.d2;
    }
  }
  benchmark::DoNotOptimize(checksum);
  state.SetLabel(dispatched ? (NearestTwoOfRowsUsesAvx2() ? "avx2" : "sse2") : "sse2 reference");
}
BENCHMARK(BM_NearestTwoOfRows)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->MinTime(1.0);

BENCHMARK(BM_Track_640x480)->Unit(benchmark::kMillisecond)->MinTime(2.0);
BENCHMARK(BM_Track_1280x720)->Unit(benchmark::kMillisecond)->MinTime(2.0);
BENCHMARK(BM_TrackMarkersOnly_640x480)->Unit(benchmark::kMillisecond)->MinTime(1.0);
BENCHMARK(BM_TrackMarkersOnly_1280x720)->Unit(benchmark::kMillisecond)->MinTime(1.0);
BENCHMARK(BM_Relocalize_640x480)->Unit(benchmark::kMillisecond)->MinTime(1.0);
BENCHMARK(BM_Relocalize_1280x720)->Unit(benchmark::kMillisecond)->MinTime(1.0);

}  // namespace
}  // namespace arpos

BENCHMARK_MAIN();
