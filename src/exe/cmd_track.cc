#include "exe/cmd_track.h"

#include <iostream>

#include "exe/args.h"
#include "room_map/plan_stage.h"
#include "sensor/case_check.h"
#include "sensor/case_config.h"
#include "store/lifecycle.h"
#include "store/sqlite_database.h"
#include "store/store_path.h"
#include "tracking/tracking_stage.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos {

int RunTrackCommand(const std::vector<std::string>& argv) {
  const char* usage =
      "usage: arpos track SEQ_DIR --out DIR [--store DB] [--session ID] [options]\n"
      "Tracking mode on the RGB-D sequence SEQ_DIR: every frame, the camera in the room\n"
      "(the plan's room map), the patient (the session's stickers refined with depth on\n"
      "the reference model) and the couch correction that brings the patient to the\n"
      "planned pose, in IEC 61217 couch axes (README: \"Reading the correction\").\n"
      "Writes DIR/poses.txt, camera_poses.txt, corrections.csv, timing.csv (and\n"
      "overlay/<timestamp>.png with --overlay) and stores the run with every frame.\n"
      "Without --session, the one open session of the case's patient is used (the case\n"
      "folder above SEQ_DIR; several open sessions are refused, a research run takes the newest). Tracking is for a\n"
      "therapist (--role therapist) or a research run (no role), on an open session.\n"
      "  --store DB          session store (default: $ARPOS_STORE, else ./arpos_store.db)\n"
      "  --session ID        track against this session's stickers and alignment\n"
      "  --case DIR          case folder for case.yaml (default: the nearest folder above\n"
      "                      SEQ_DIR holding a case.yaml)\n"
      "  --overlay           write the AR overlay of every frame\n"
      "  --tolerance-mm MM   translation tolerance (default 2)\n"
      "  --tolerance-deg DEG rotation tolerance (default 1)\n"
      "  --sequential        scene and body one after the other (default: two threads)\n"
      "  --no-filter         each frame's own pose (default: the patient's room pose through\n"
      "                      a constant-velocity filter weighted by each frame's uncertainty)\n";
  const Args args(argv, {"store", "session", "out", "case", "tolerance-mm", "tolerance-deg"},
                  {"overlay", "sequential", "no-filter", "help"});
  if (args.Has("help")) {
    std::cout << usage;
    return 0;
  }
  if (args.positional().size() != 1) {
    std::cerr << usage;
    return 2;
  }
  const std::filesystem::path seq_dir = args.positional()[0];
  const std::filesystem::path out_dir = args.Require("out");
  std::optional<std::filesystem::path> case_root;
  if (args.Has("case")) {
    case_root = args.Require("case");
  } else {
    case_root = FindCaseRoot(seq_dir);
    if (!case_root) {
      ARPOS_INPUT_ERROR(seq_dir.string() << ": no case.yaml in this folder or above it; give --case DIR");
    }
  }
  TrackSequenceOptions options;
  options.sequence_dir = seq_dir;
  options.out_dir = out_dir;
  options.overlay = args.Has("overlay");
  options.parallel = !args.Has("sequential");
  options.temporal_filter = !args.Has("no-filter");
  options.tolerances.translation_mm = args.GetDouble("tolerance-mm", 2.0);
  options.tolerances.rotation_deg = args.GetDouble("tolerance-deg", 1.0);
  const std::string tol_problem = options.tolerances.Validate();
  if (!tol_problem.empty()) ARPOS_INPUT_ERROR("--tolerance-mm/--tolerance-deg: " << tol_problem);
  std::optional<SessionId> session;
  if (args.Has("session")) {
    const long long id = args.GetInt("session", 0);
    if (id <= 0) ARPOS_INPUT_ERROR("--session must be a positive id");
    session = SessionId(id);
  }
  // What tracking reads (case.yaml, the sequence), checked as `arpos check`
  // does (quick), and where it writes, before any work.
  CaseCheckOptions check;
  check.read_all_images = false;
  check.reference_model = false;
  check.target_pose = false;
  check.sequences = std::vector<std::filesystem::path>{std::filesystem::absolute(seq_dir)};
  RequireValidCase(*case_root, check);
  RequireWritableFolder(out_dir, "--out");
  const CaseConfig config = LoadCaseConfig(*case_root / "case.yaml");

  const std::string store_path = args.GetOr("store", DefaultStorePath());
  SqliteOpenOptions open_options;
  open_options.create_if_missing = false;
  auto database = SqliteDatabase::Open(store_path, open_options);
  RecoverInterruptedSessions(database.get());
  options.op = ResolveOperator(GivenOperatorFlags().user, GivenOperatorFlags().role);
  RequirePermission(options.op, Action::kTrack);
  const TrackingInputs inputs = LoadTrackingInputs(database.get(), session, CasePatientId(*case_root),
                                                   options.op.role == Role::kResearch);
  std::cerr << "session: " << inputs.session_choice << "\n";
  std::cerr << StringPrintf("tracking against session %lld (plan %lld, room map %lld, %zu stickers)\n",
                            static_cast<long long>(inputs.session_id.value()),
                            static_cast<long long>(inputs.plan_id.value()),
                            static_cast<long long>(inputs.room_map_id.value()), inputs.model_from_marker.size());
  const TrackSequenceResult result = TrackSequence(database.get(), inputs, config, options);
  std::cerr << result.response_message << "\n";
  std::cout << result.Summary() << "\n"
            << StringPrintf("stored as tracking run %lld; wrote %s\n", static_cast<long long>(result.run_id.value()),
                            out_dir.string().c_str());
  return 0;
}

}  // namespace arpos
