#include "controllers/session_controller.h"

#include <chrono>

#include "room_map/plan_stage.h"
#include "sensor/case_check.h"
#include "sensor/case_folder.h"
#include "store/database.h"
#include "store/record_conversions.h"
#include "util/logging.h"

namespace arpos {

SessionController::SessionController(SessionStageOptions options, Database* database,
                                     ControllerCallbacks callbacks)
    : Controller(std::move(callbacks)), options_(std::move(options)), database_(database) {}

void SessionController::Run() {
  using Clock = std::chrono::steady_clock;
  const auto start = Clock::now();
  const std::string problem = options_.Check();
  if (!problem.empty()) ARPOS_INPUT_ERROR("session: " << problem);
  ARPOS_CHECK(database_ != nullptr, "the session stage needs a session store");
  RequirePermission(options_.op, Action::kRunSession);
  result_ = SessionStageResult();
  // What the stage reads, checked as `arpos check` does (quick: a sample of
  // the images), and where it writes, before any work.
  CaseCheckOptions check;
  check.read_all_images = false;
  check.sequences = std::vector<std::filesystem::path>{"body_scan"};
  RequireValidCase(options_.case_dir, check);
  if (options_.out_dir) RequireWritableFolder(*options_.out_dir, "--out");

  Step("loading the case and the plan", 0.0);
  const CaseFolder folder = LoadCaseFolder(options_.case_dir);
  const bool may_use_unapproved = options_.unapproved || options_.op.role == Role::kResearch;
  std::string plan_choice;
  PlanId plan_id = ChoosePlanForSession(database_, options_.plan_id, CasePatientId(folder.root),
                                        !may_use_unapproved, options_.op.role == Role::kResearch,
                                        &plan_choice);
  SessionPlanInputs inputs;
  RoomMapId room_map_id;
  inputs.room_map = LoadRoomMapForLocalization(database_, plan_id, CasePatientId(folder.root), &plan_id, &room_map_id);
  const std::optional<PlanRecord> plan = database_->GetPlan(plan_id);
  if (!plan) ARPOS_INPUT_ERROR("plan " << plan_id.value() << " does not exist");
  if (plan->reference_model.vertices.empty()) {
    ARPOS_INPUT_ERROR("plan " << plan_id.value() << " has no reference model");
  }
  inputs.plan_id = plan_id;
  inputs.model = FromStoredMesh(plan->reference_model);
  inputs.room_from_model_target = plan->room_from_model_target;
  // A plan stored before these checks existed may hold what they refuse.
  for (const std::string& why : {ReferenceModelSizeProblem(inputs.model),
                                 TargetPoseProblem(plan->room_from_model_target.ToMatrix())}) {
    if (!why.empty()) {
      ARPOS_INPUT_ERROR("plan " << plan_id.value() << " (" << plan->reference_model_name << "): " << why);
    }
  }

  result_ = BuildSession(folder, inputs, options_, callbacks());
  result_.plan_choice = plan_choice;
  result_.on_unapproved_plan = !plan->approved();

  // Files first: a failed write must not leave a stored session behind, and
  // a store that stays locked must not lose the finished work.
  if (options_.out_dir) WriteSessionOutputs(*options_.out_dir, folder, result_);

  Step("storing the session", 0.95);
  const auto t_store = Clock::now();
  StoreSession(database_, folder, options_, &result_);
  result_.times.store_s = std::chrono::duration<double>(Clock::now() - t_store).count();
  result_.times.total_s = std::chrono::duration<double>(Clock::now() - start).count();
  Step("done", 1.0);
}

}  // namespace arpos
