#include "exe/cmd_localize.h"

#include <fstream>
#include <iostream>
#include <sstream>

#include "exe/args.h"
#include "features/response_from_recording.h"
#include "room_map/camera_localizer.h"
#include "room_map/plan_stage.h"
#include "sensor/case_check.h"
#include "sensor/case_config.h"
#include "sensor/sequence.h"
#include "sensor/tum_io.h"
#include "store/sqlite_database.h"
#include "store/store_path.h"
#include "util/check.h"
#include "util/file.h"
#include "util/string_util.h"

namespace arpos {

int RunLocalizeCommand(const std::vector<std::string>& argv) {
  const char* usage =
      "usage: arpos localize SEQ_DIR --out FILE [--store DB] [--plan ID] [options]\n"
      "Camera pose (camera -> room) of every frame of the RGB-D sequence SEQ_DIR\n"
      "against a stored room map (see `arpos plan`), written as a TUM trajectory.\n"
      "Frames that cannot be localised are left out (they count as lost).\n"
      "Without --plan, the newest room map of the case's patient is used (the case\n"
      "folder above SEQ_DIR), else the newest in the store.\n"
      "  --store DB       session store (default: $ARPOS_STORE, else ./arpos_store.db)\n"
      "  --plan ID        use the newest room map of this plan\n"
      "  --case DIR       case folder for case.yaml (default: the nearest folder above\n"
      "                   SEQ_DIR holding a case.yaml)\n"
      "  --no-keypoints   markers only\n"
      "  --no-markers     keypoints only\n"
      "  --timings FILE   per-frame status, step times (CPU ms) and why a lost frame is lost, as "
      "CSV\n";
  const Args args(argv, {"store", "plan", "out", "case", "timings"}, {"no-keypoints", "no-markers", "help"});
  if (args.Has("help")) {
    std::cout << usage;
    return 0;
  }
  if (args.positional().size() != 1) {
    std::cerr << usage;
    return 2;
  }
  const std::filesystem::path seq_dir = args.positional()[0];
  const std::string out_path = args.Require("out");
  std::optional<std::filesystem::path> case_root;
  if (args.Has("case")) {
    case_root = args.Require("case");
  } else {
    case_root = FindCaseRoot(seq_dir);
    if (!case_root) {
      ARPOS_INPUT_ERROR(seq_dir.string() << ": no case.yaml in this folder or above it; give --case DIR");
    }
  }
  // What localisation reads (case.yaml, the sequence), checked as `arpos check`
  // does (quick), and where it writes, before any work.
  CaseCheckOptions check;
  check.read_all_images = false;
  check.reference_model = false;
  check.target_pose = false;
  check.sequences = std::vector<std::filesystem::path>{std::filesystem::absolute(seq_dir)};
  RequireValidCase(*case_root, check);
  RequireWritableFileLocation(out_path, "--out");
  if (args.Has("timings")) RequireWritableFileLocation(args.Require("timings"), "--timings");
  const CaseConfig config = LoadCaseConfig(*case_root / "case.yaml");
  std::optional<PlanId> plan;
  if (args.Has("plan")) {
    const long long id = args.GetInt("plan", 0);
    if (id <= 0) ARPOS_INPUT_ERROR("--plan must be a positive id");
    plan = PlanId(id);
  }
  const Sequence sequence = Sequence::Open(seq_dir);

  const std::string store_path = args.GetOr("store", DefaultStorePath());
  SqliteOpenOptions open_options;
  open_options.create_if_missing = false;
  auto database = SqliteDatabase::Open(store_path, open_options);
  PlanId used_plan;
  RoomMapId used_map;
  RoomMap map = LoadRoomMapForLocalization(database.get(), plan, CasePatientId(*case_root), &used_plan, &used_map);
  if (std::abs(map.marker_size_m - config.room_markers.size_m) > 1e-6) {
    ARPOS_INPUT_ERROR("room map " << used_map.value() << " was built with " << map.marker_size_m
                                  << " m markers but " << (*case_root / "case.yaml").string() << " says "
                                  << config.room_markers.size_m << " m");
  }
  CameraLocalizerOptions options = MakeCameraLocalizerOptions(config);
  options.use_keypoints = !args.Has("no-keypoints");
  options.use_markers = !args.Has("no-markers");
  // The recording's camera response from its own markers, else the room's.
  const RecordingResponse response = EstimateRecordingResponse(sequence, config, map.camera_response);
  options.detector.edge.response = response.response;
  std::cerr << response.message << "\n";
  std::string problem;
  if (!options.Check(&problem)) ARPOS_INPUT_ERROR(problem);
  CameraLocalizer localizer(std::move(map), config.camera, options);

  std::vector<StampedPose> poses;
  std::ostringstream csv;
  csv << "timestamp,status,markers,keypoints,rms_px,position_sigma_mm,detection_ms,keypoints_ms,"
         "matching_ms,pnp_ms,refinement_ms,total_ms,why_lost\n";
  int tracked = 0, relocalized = 0, lost = 0;
  double total_ms = 0;
  const DepthCorrector depth_corrector(config.camera, localizer.map().depth_correction);
  for (size_t i = 0; i < sequence.size(); ++i) {
    RgbdFrame frame = sequence.LoadFrame(i, config.camera);
    if (!frame.depth.empty()) depth_corrector.Apply(&frame.depth);
    const LocalizationResult r = localizer.Localize(frame);
    if (r.ok) poses.push_back({frame.timestamp_s, r.room_from_camera});
    tracked += r.status == LocalizationStatus::kTracked;
    relocalized += r.status == LocalizationStatus::kRelocalized;
    lost += r.status == LocalizationStatus::kLost;
    total_ms += r.timings.total_ms;
    const auto& t = r.timings;
    csv << StringPrintf("%.6f,%s,%d,%d,%.4f,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,", frame.timestamp_s,
                        LocalizationStatusName(r.status), r.markers_used, r.keypoints_used,
                        r.rms_px, r.position_sigma_mm, t.detection_ms, t.keypoints_ms,
                        t.matching_ms, t.pnp_ms, t.refinement_ms, t.total_ms);
    // Why a frame is lost, as the localiser says it (a quoted CSV field).
    std::string why;
    for (char c : r.ok ? std::string() : r.message)
      why += c == '"' ? std::string("\"\"") : std::string(1, c);
    csv << '"' << why << "\"\n";
  }
  WriteTrajectory(out_path, poses,
                  StringPrintf("arpos localize %s: room_from_camera (camera -> room), room map %lld of plan %lld",
                               seq_dir.string().c_str(), static_cast<long long>(used_map.value()),
                               static_cast<long long>(used_plan.value())));
  if (args.Has("timings")) WriteFileAtomic(args.Require("timings"), csv.str());
  const size_t n = sequence.size();
  std::cout << StringPrintf(
      "localized %zu of %zu frames (%.1f %%): %d tracked, %d relocalized, %d lost; room map %lld (plan %lld); "
      "mean %.2f ms CPU per frame\nwrote %s\n",
      poses.size(), n, n ? 100.0 * poses.size() / n : 0.0, tracked, relocalized, lost,
      static_cast<long long>(used_map.value()), static_cast<long long>(used_plan.value()),
      n ? total_ms / n : 0.0, out_path.c_str());
  return 0;
}

}  // namespace arpos
