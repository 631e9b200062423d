#include "exe/cmd_track.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <ctime>
#include <iostream>

#include "eval/trajectory_eval.h"
#include "exe/args.h"
#include "room_map/plan_stage.h"
#include "sensor/case_check.h"
#include "sensor/case_config.h"
#include "sensor/recorder.h"
#include "sensor/source_plugin.h"
#ifdef ARPOS_HAVE_STREAMING
#include "streaming/igtl_server.h"
#endif
#include "store/lifecycle.h"
#include "store/sqlite_database.h"
#include "store/store_path.h"
#include "tracking/tracking_stage.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos {

namespace {
std::atomic<bool> g_stop_requested{false};
void OnStopSignal(int) { g_stop_requested = true; }

std::string LocalTimeStamp() {
  const std::time_t now = std::time(nullptr);
  std::tm local{};
  localtime_r(&now, &local);
  char text[32];
  std::strftime(text, sizeof text, "%Y%m%d-%H%M%S", &local);
  return text;
}
}  // namespace

int RunTrackCommand(const std::vector<std::string>& argv) {
  const char* usage =
      "usage: arpos track SEQ_DIR --out DIR [--store DB] [--session ID] [options]\n"
      "       arpos track --source SPEC --case DIR --out DIR [--record SEQ_DIR] [--seconds S] [options]\n"
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
      "  --source SPEC       track a camera source live instead of SEQ_DIR (`arpos sources`:\n"
      "                      sim:CASE_DIR, openni2:, replay:SEQ_DIR?realtime); a frame more than\n"
      "                      two behind the camera is dropped and counted; Ctrl-C stops and stores\n"
      "  --name NAME         the live run's name (default live-YYYYMMDD-HHMMSS)\n"
      "  --record SEQ_DIR    also write every captured frame there (DATASET.md), replayable;\n"
      "                      raw while tracking, the PNGs after the run\n"
      "  --seconds S         stop a live run after S seconds\n"
      "  --frames N          stop after N frames\n"
#ifdef ARPOS_HAVE_STREAMING
      "  --igtl-port PORT    stream every frame to OpenIGTLink clients (3D Slicer's OpenIGTLinkIF,\n"
      "                      PLUS) connecting to this port: TRANSFORM ModelToRoom, TargetToRoom,\n"
      "                      CameraToRoom (mm), STATUS Tolerance, STRING Correction (README)\n"
      "  --igtl-bind ADDR    the address to listen on (default 127.0.0.1; 0.0.0.0: every interface)\n"
      "  --igtl-wait         hold the first frame until a client is connected\n"
#endif
      "  --sequential        scene and body one after the other (default: two threads)\n"
      "  --no-filter         each frame's own pose (default: the patient's room pose through\n"
      "                      a constant-velocity filter weighted by each frame's uncertainty)\n";
  const Args args(argv,
                  {"store", "session", "out", "case", "tolerance-mm", "tolerance-deg", "source", "name", "record",
                   "seconds", "frames", "igtl-port", "igtl-bind"},
                  {"overlay", "sequential", "no-filter", "help", "igtl-wait"});
  if (args.Has("help")) {
    std::cout << usage;
    return 0;
  }
  const bool live = args.Has("source");
  if (args.positional().size() != (live ? 0u : 1u)) {
    std::cerr << usage;
    return 2;
  }
  if (live && !args.Has("case")) ARPOS_INPUT_ERROR("--source needs --case DIR (the case folder of the patient, for case.yaml)");
  if (!live && (args.Has("record") || args.Has("name"))) ARPOS_INPUT_ERROR("--record and --name are for --source");
  const std::filesystem::path seq_dir = live ? std::filesystem::path() : std::filesystem::path(args.positional()[0]);
  const std::filesystem::path out_dir = args.Require("out");
  const double seconds = args.GetDouble("seconds", 0);
  const long long max_frames = args.GetInt("frames", 0);
  if (!(seconds >= 0) || !std::isfinite(seconds)) ARPOS_INPUT_ERROR("--seconds: must be a positive duration");
  if (max_frames < 0) ARPOS_INPUT_ERROR("--frames: must be positive");
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
  options.case_dir = *case_root;
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
  check.sequences = live ? std::vector<std::filesystem::path>{}
                         : std::vector<std::filesystem::path>{std::filesystem::absolute(seq_dir)};
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
  std::cerr << StringPrintf("tracking against session %lld (plan %lld, room map %lld, %zu stickers",
                            static_cast<long long>(inputs.session_id.value()),
                            static_cast<long long>(inputs.plan_id.value()),
                            static_cast<long long>(inputs.room_map_id.value()),
                            inputs.model_from_marker.size());
  if (inputs.scan_landmarks > 0) {
    std::cerr << StringPrintf(
        "; %d room landmarks from its body scan, for frames the room map does not place",
        inputs.scan_landmarks);
  }
  std::cerr << ")\n";
  options.max_frames = static_cast<int>(max_frames);
  // Ctrl-C (or a terminating signal) ends a run at the next frame: what was
  // tracked is written and stored. The server listens before the source and
  // the recording are made: a port in use leaves nothing behind.
  std::signal(SIGINT, OnStopSignal);
  std::signal(SIGTERM, OnStopSignal);
#ifdef ARPOS_HAVE_STREAMING
  std::optional<IgtlServer> igtl;
  if (args.Has("igtl-port")) {
    const long long port = args.GetInt("igtl-port", 0);
    if (port < 0 || port > 65535) ARPOS_INPUT_ERROR("--igtl-port: a TCP port 0..65535, got " << port);
    IgtlServerOptions igtl_options;
    igtl_options.port = static_cast<int>(port);
    igtl_options.bind_address = args.GetOr("igtl-bind", igtl_options.bind_address);
    igtl.emplace(igtl_options);
    std::cerr << StringPrintf("OpenIGTLink: listening on %s:%d\n", igtl_options.bind_address.c_str(), igtl->port());
    if (args.Has("igtl-wait")) {
      std::cerr << "OpenIGTLink: waiting for a client before the first frame (Ctrl-C to stop)\n";
      while (!igtl->WaitForClient(0.25)) {
        if (g_stop_requested) ARPOS_INPUT_ERROR("stopped while waiting for an OpenIGTLink client; nothing tracked");
      }
      std::cerr << "OpenIGTLink: client connected\n";
    }
    const Rigid3d target = inputs.room_from_model_target;
    options.on_result = [&igtl, target](const TrackedFrame& tracked, std::chrono::steady_clock::time_point) {
      IgtlFrame frame;
      frame.timestamp_s = std::max(0.0, tracked.timestamp_s);
      frame.room_from_model = tracked.room_from_model;
      frame.room_from_model_target = target;
      frame.room_from_camera = tracked.room_from_camera;
      frame.correction = tracked.correction;
      // Latency of the stream: from the correction to the wire (the frame's
      // own latency to the correction is timing.csv's total_ms).
      frame.arrival = std::chrono::steady_clock::now();
      igtl->Send(frame);
    };
  } else if (args.Has("igtl-wait") || args.Has("igtl-bind")) {
    ARPOS_INPUT_ERROR("--igtl-wait and --igtl-bind need --igtl-port");
  }
#endif
  std::unique_ptr<CameraSource> source;
  std::optional<SequenceRecorder> recorder;
  if (live) {
    source = SourceRegistry().Create(args.Require("source"));
    options.source = source.get();
    options.name = args.GetOr("name", "live-" + LocalTimeStamp());
    std::cerr << "source: " << source->description() << "\n";
    if (auto record = args.Get("record")) {
      const RecordingFolder folder = PrepareRecordingFolder(*record, source->intrinsics(), config,
                                                          (*case_root / "case.yaml").string());
      if (!folder.note.empty()) std::cerr << "record: " << folder.note << "\n";
      RecorderOptions recorder_options;
      recorder_options.depth_scale = folder.depth_scale;
      // Tracking needs the cores while it runs: raw images now, PNGs after.
      recorder_options.encode_later = true;
      recorder_options.writer_threads = 2;
      recorder.emplace(*record, recorder_options);
      options.record_dir = *record;
      options.on_capture = [&recorder](const RgbdFrame& frame) { recorder->Push(frame); };
    }
  }
  const auto start = std::chrono::steady_clock::now();
  options.before_frame = [&](size_t, size_t) {
    if (g_stop_requested) return false;
    return !(seconds > 0 && std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() >= seconds);
  };
  const TrackSequenceResult result = TrackSequence(database.get(), inputs, config, options);
  std::signal(SIGINT, SIG_DFL);
  std::signal(SIGTERM, SIG_DFL);
  if (recorder) std::cerr << "recorded " << options.record_dir.string() << ": " << recorder->Finish().Summary() << "\n";
#ifdef ARPOS_HAVE_STREAMING
  if (igtl) {
    const IgtlServer::Stats stats = igtl->stats();
    std::cerr << StringPrintf("OpenIGTLink: %ld frames, %ld messages to %ld client(s)", stats.frames, stats.messages,
                              stats.accepted_clients);
    if (!stats.latency_ms.empty()) {
      const ErrorStats latency = ComputeErrorStats(stats.latency_ms);
      std::cerr << StringPrintf("; correction to wire %.2f ms mean, p95 %.2f, max %.2f", latency.mean, latency.p95,
                                latency.max);
    }
    if (stats.dropped_clients) std::cerr << StringPrintf("; %ld client(s) dropped", stats.dropped_clients);
    std::cerr << "\n";
  }
#endif
  if (live) {
    std::cerr << StringPrintf("live: %d frames captured, %d tracked, %d dropped (the tracker too far behind)\n",
                              result.sequence_frames, result.frames, result.dropped);
  }
  std::cerr << result.response_message << "\n";
  if (!result.room_frame.blocks_in) std::cerr << result.room_frame.text << "\n";
  std::cout << result.Summary() << "\n"
            << StringPrintf("stored as tracking run %lld; wrote %s\n", static_cast<long long>(result.run_id.value()),
                            out_dir.string().c_str());
  return 0;
}

}  // namespace arpos
