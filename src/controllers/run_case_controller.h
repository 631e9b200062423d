#pragma once
/// `arpos run-case`: runs every stage that exists on one case folder and
/// stores every artefact in the session store.
///
/// Stages, in order: validate the case (CheckCase); build the room map
/// (planning), then store in one transaction a plan with the reference model
/// and target pose (patient = the case folder's name unless given), its room
/// recording and the map, so a room that cannot be mapped stores nothing;
/// the session stage on body_scan/ (body marker map, reconstruction, mesh,
/// alignment: SessionController); register the tracking recordings in that
/// session. Where the case has ground truth, the body-scan camera poses and
/// the model pose at scan time are evaluated against it (DATASET.md figures).
/// Then tracking mode on every tracking/<name> (outputs in <out>/<name>/).
/// Every write is logged in the audit log with the operator (`op`).
///
/// run-case is a research run (store/roles.h): it plans, runs the session on
/// the plan it just made (not approved: the session is recorded so) and
/// tracks; a clinical role is refused. At the end the session is completed
/// (aborted if a tracking run failed), unless `keep_session_open`.

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "controllers/controller.h"
#include "feedback/couch_correction.h"
#include "store/records.h"
#include "store/roles.h"

namespace arpos {

class Database;

struct RunCaseOptions {
  std::filesystem::path case_dir;
  std::string patient_external_id;  ///< empty: the case folder's name
  Operator op;  ///< a research run (no role, or --role research)
  /// Leave the session open at the end (to track more, e.g. on the GUI's
  /// positioning screen); otherwise it is completed, or aborted if tracking failed.
  bool keep_session_open = false;
  bool read_all_images = true;      ///< false: check a sample of the images
  /// Session outputs (model_pose.txt, ...) and, per tracking/<name>, the
  /// tracking outputs in <out_dir>/<name>/ (DATASET.md).
  std::optional<std::filesystem::path> out_dir;
  bool overlay = true;  ///< with out_dir: the AR overlay of every tracked frame
  CouchTolerances tolerances;
  int threads = 2;

  /// Empty if valid, else what is wrong.
  std::string Check() const;
};

struct RunCaseResult {
  PatientId patient_id;
  PlanId plan_id;
  SessionId session_id;
  std::vector<RecordingId> recordings;
  int reference_model_vertices = 0;
  int frames = 0;
  std::vector<std::string> warnings;  ///< from the case check
  std::vector<std::string> stages_done;
  RoomMapId room_map_id;
  std::string plan_summary;     ///< room map figures
  std::string session_summary;  ///< session stage figures
  std::string tracking_summary;  ///< one block per tracked sequence
  /// Against ground truth, when the case has it (empty otherwise).
  std::string evaluation;
  /// Stages that could not be done, with the reason ("session: ..."). What
  /// earlier stages stored stays stored; later stages that depend on a failed
  /// one are skipped.
  std::vector<std::string> failures;
  bool ok() const { return failures.empty(); }
  /// A person-readable summary of what was done and stored.
  std::string Summary() const;
};

class RunCaseController : public Controller {
 public:
  RunCaseController(RunCaseOptions options, Database* database, ControllerCallbacks callbacks = {});
  void Run() override;
  const RunCaseResult& result() const { return result_; }

 private:
  RunCaseOptions options_;
  Database* database_;
  RunCaseResult result_;
};

}  // namespace arpos
