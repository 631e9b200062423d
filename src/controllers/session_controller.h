#pragma once
/// `arpos session`: the session stage of one treatment, with the session
/// store. Checks what the stage reads and where it writes, chooses the plan
/// and loads its room map, reference model and target pose, runs the stage
/// (body_model/session_stage.h: sticker map, reconstruction, mesh,
/// alignment), writes the files asked for and stores everything in one
/// transaction. A command that fails stores nothing.

#include "body_model/session_stage.h"
#include "controllers/controller.h"

namespace arpos {

class Database;

class SessionController : public Controller {
 public:
  SessionController(SessionStageOptions options, Database* database,
                    ControllerCallbacks callbacks = {});
  /// Throws InputError for an unusable case (no plan or room map, no body in
  /// the scan, the camera never localised), Cancelled.
  void Run() override;
  const SessionStageResult& result() const { return result_; }

 private:
  SessionStageOptions options_;
  Database* database_;
  SessionStageResult result_;
};

}  // namespace arpos
