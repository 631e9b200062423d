#include "planning/planning_test_util.h"

#include <unistd.h>

#include <cstdlib>
#include <map>
#include <mutex>

#include <opencv2/imgcodecs.hpp>

#include "geometry/mesh_io.h"
#include "room_map/plan_stage.h"
#include "simulation/simulator.h"
#include "sensor/case_config.h"
#include "sensor/tum_io.h"
#include "sensor/sequence.h"
#include "simulation/simulator.h"
#include "util/check.h"
#include "util/file.h"
#include "util/string_util.h"

namespace arpos::testing {
namespace {

std::filesystem::path BodyMeshPath() {
  return std::filesystem::path(ARPOS_SHARED_DATA_DIR) / "makehuman_base" / "base.obj";
}

std::string Key(const std::string& profile, int room_frames, int tracking_frames) {
  return profile + "/" + std::to_string(room_frames) + "/" + std::to_string(tracking_frames);
}

// Writes frames `frames` of simulator sequence `q` as a TUM sequence folder.
void WriteFrames(const sim::Simulator& simulator, int q, const std::vector<int>& frames,
                 const std::filesystem::path& dir) {
  CreateDirectories(dir / "rgb");
  CreateDirectories(dir / "depth");
  std::vector<ImageListEntry> rgb, depth;
  std::vector<StampedPose> poses;
  const std::vector<int> params = {cv::IMWRITE_PNG_COMPRESSION, 1};
  for (int f : frames) {
    const sim::SimulatedFrame frame = simulator.RenderFrame(q, f);
    const std::string stamp = StringPrintf("%.6f", frame.timestamp_s);
    rgb.push_back({frame.timestamp_s, "rgb/" + stamp + ".png", 0});
    depth.push_back({frame.timestamp_s, "depth/" + stamp + ".png", 0});
    poses.push_back({frame.timestamp_s, frame.room_from_camera});
    ARPOS_CHECK(cv::imwrite((dir / rgb.back().relative_path).string(), frame.color, params) &&
                    cv::imwrite((dir / depth.back().relative_path).string(), frame.depth, params),
                "cannot write test images into " << dir);
  }
  WriteImageList(dir / "rgb.txt", rgb, "planning test: colour");
  WriteImageList(dir / "depth.txt", depth, "planning test: depth");
  WriteTrajectory(dir / "groundtruth.txt", poses, "planning test: room_from_camera");
}

// Writes the small case (see GetSmallCase) into `root`.
void WriteSmallCase(const std::string& profile, int room_frames, int tracking_frames, bool tracking_from_room,
                    bool lens, const std::filesystem::path& root) {
  // The simulator plans 30 fps sequences (room 300 frames over 20 s,
  // tracking 300 over 10 s); the case gets `room_frames` spread over the
  // whole room walk and `tracking_frames` consecutive frames, so tracking
  // runs at the real frame rate while the case stays small.
  const sim::Simulator simulator(SmallCaseSimulationOptions(profile, lens));
  CreateDirectories(root);
  CaseConfig config;
  config.camera = simulator.profile().intrinsics;
  config.dictionary = "DICT_4X4_250";
  config.room_markers = {simulator.world().room_markers.front().size_m, 0, 49};
  config.room_origin_id = 0;
  config.body_markers = {0.03, 100, 199};
  SaveCaseConfig(config, root / "case.yaml");
  SaveTriangleMeshPly(simulator.world().reference_model, root / "reference_model.ply", "planning test");
  WriteMatrix4(root / "target_pose.txt", simulator.world().room_from_model_target.ToMatrix(), "planning test");
  sim::SaveSimulationTruth(simulator.Truth(), root / "simulation.yaml");
  int room = -1, tracking = -1;
  for (size_t q = 0; q < simulator.sequences().size(); ++q) {
    const auto& plan = simulator.sequences()[q];
    if (plan.kind == sim::SequenceKind::kRoom && room < 0) room = static_cast<int>(q);
    if (plan.kind == sim::SequenceKind::kTracking && tracking < 0) tracking = static_cast<int>(q);
  }
  std::vector<int> room_list, tracking_list;
  const int room_total = simulator.sequences()[room].frames;
  for (int i = 0; i < room_frames; ++i) room_list.push_back(i * room_total / room_frames);
  WriteFrames(simulator, room, room_list, root / "room");
  // Tracking: consecutive frames of the simulator's tracking sequence
  // (patient present), or, for the unit tests, of the room walk between the
  // mapped frames (views the small map covers well).
  if (tracking_from_room) {
    for (int i = 0; i < tracking_frames; ++i) tracking_list.push_back(1 + i);
    WriteFrames(simulator, room, tracking_list, root / "tracking" / "seq_00");
  } else {
    for (int i = 0; i < tracking_frames; ++i) tracking_list.push_back(i);
    WriteFrames(simulator, tracking, tracking_list, root / "tracking" / "seq_00");
  }
}

}  // namespace

sim::SimulationOptions SmallCaseSimulationOptions(const std::string& profile, bool lens) {
  sim::SimulationOptions o;
  o.profile = profile;
  o.seed = 7;
  o.body_mesh_path = BodyMeshPath();
  o.room_frames = 300;
  o.body_scan_frames = 1;
  o.tracking_frames = 300;
  o.tracking_sequences = 1;
  if (lens) o.distortion = kKinectLens;
  return o;
}

const SmallCase& GetSmallCase(const std::string& profile, int room_frames, int tracking_frames,
                              bool tracking_from_room, bool lens) {
  static std::mutex mutex;
  static std::map<std::string, std::unique_ptr<SmallCase>> cases;
  std::lock_guard<std::mutex> lock(mutex);
  const std::string name = "sim" + std::to_string(sim::kSimulatorVersion) + "_case_" + profile + "_" + std::to_string(room_frames) + "_" +
                           std::to_string(tracking_frames) + (tracking_from_room ? "_r" : "_t") + (lens ? "_lens" : "");
  auto& slot = cases[name];
  if (!slot) {
    // Cases are cached on disk (ctest runs every test in its own process):
    // $ARPOS_PLANNING_TEST_CASES, else the build tree's folder. A case is
    // written into a staging folder and renamed into place when complete,
    // so concurrent test processes never see half a case.
    const char* env = std::getenv("ARPOS_PLANNING_TEST_CASES");
    const std::filesystem::path cache = env != nullptr && *env != '\0'
                                            ? std::filesystem::path(env)
                                            : std::filesystem::path(ARPOS_PLANNING_TEST_CACHE);
    auto c = std::make_unique<SmallCase>();
    c->root = cache / name;
    if (!std::filesystem::exists(c->root / "complete")) {
      CreateDirectories(cache);
      const std::filesystem::path staging = cache / (name + ".tmp" + std::to_string(static_cast<long long>(::getpid())));
      std::filesystem::remove_all(staging);
      WriteSmallCase(profile, room_frames, tracking_frames, tracking_from_room, lens, staging);
      WriteFileAtomic(staging / "complete", "ok\n");
      std::error_code ec;
      std::filesystem::rename(staging, c->root, ec);
      if (ec) std::filesystem::remove_all(staging);  // another process finished first
    }
    c->folder = LoadCaseFolder(c->root);
    c->truth = sim::LoadSimulationTruth(c->root / "simulation.yaml");
    slot = std::move(c);
  }
  return *slot;
}

const RoomMapBuildResult& GetSmallCaseMap(const std::string& profile, int room_frames, int tracking_frames,
                                          bool tracking_from_room, bool lens) {
  static std::mutex mutex;
  static std::map<std::string, std::unique_ptr<RoomMapBuildResult>> maps;
  const SmallCase& c = GetSmallCase(profile, room_frames, tracking_frames, tracking_from_room, lens);
  std::lock_guard<std::mutex> lock(mutex);
  auto& slot = maps[Key(profile, room_frames, tracking_frames) + (tracking_from_room ? "/r" : "/t") + (lens ? "/lens" : "")];
  if (!slot) {
    const Sequence room = Sequence::Open(c.folder.room_dir);
    slot = std::make_unique<RoomMapBuildResult>(
        BuildRoomMap(room, c.folder.config, MakeRoomMapBuildOptions(c.folder, RoomMapStageOptions())));
  }
  return *slot;
}

MarkerErrors CompareMarkers(const RoomMap& map, const sim::SimulationTruth& truth, int min_views) {
  MarkerErrors e;
  double sum = 0;
  int n = 0;
  for (const auto& m : map.markers) {
    if (m.num_observations < min_views) continue;
    for (const auto& t : truth.room_markers) {
      if (t.id != m.id) continue;
      ++e.markers;
      for (int c = 0; c < 4; ++c) {
        const double d = (m.corners_in_room[c] - t.corners_m[c]).norm();
        sum += d;
        ++n;
        e.max_m = std::max(e.max_m, d);
      }
    }
  }
  e.mean_m = n ? sum / n : 0;
  return e;
}

}  // namespace arpos::testing
