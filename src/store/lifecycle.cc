#include "store/lifecycle.h"

#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <climits>

#include "store/describe.h"
#include "util/logging.h"

namespace arpos {
namespace {

bool ProcessExists(std::int64_t pid) {
  if (pid <= 0 || pid > INT_MAX) return false;
  return kill(static_cast<pid_t>(pid), 0) == 0 || errno == EPERM;
}

std::string SessionEntity(SessionId id) { return "session:" + std::to_string(id.value()); }

std::string DescribeEnd(const SessionRecord& s) {
  std::string out = std::string(ToString(s.status));
  if (!s.ended_by.empty()) out += " by " + s.ended_by;
  if (s.ended_unix_ms) out += " on " + FormatUtcTime(*s.ended_unix_ms);
  if (!s.end_reason.empty()) out += " (" + s.end_reason + ")";
  return out;
}

}  // namespace

std::string ThisHostName() {
  char name[256] = {0};
  if (gethostname(name, sizeof(name) - 1) != 0 || name[0] == '\0') return "localhost";
  return name;
}

namespace {
std::string DescribeApproval(const std::string& by, const std::optional<std::int64_t>& unix_ms) {
  return unix_ms ? "approved by " + by + " on " + FormatUtcTime(*unix_ms) : std::string("not approved");
}
}  // namespace

std::string DescribeApproval(const PlanRecord& plan) {
  return DescribeApproval(plan.approved_by, plan.approved_unix_ms);
}

std::string DescribeApproval(const PlanSummary& plan) {
  return DescribeApproval(plan.approved_by, plan.approved_unix_ms);
}

PlanRecord ApprovePlan(Database* database, const Operator& op, PlanId plan_id, const std::string& note) {
  RequirePermission(op, Action::kApprovePlan);
  PlanRecord approved;
  database->WithTransaction([&] {
    const std::optional<PlanRecord> plan = database->GetPlan(plan_id);
    if (!plan) ARPOS_INPUT_ERROR("the store has no plan " << plan_id.value());
    if (plan->approved()) {
      ARPOS_INPUT_ERROR("plan " << plan_id.value() << " is already " << DescribeApproval(*plan));
    }
    const std::optional<RoomMapId> room_map = database->LatestRoomMap(plan_id);
    if (!room_map) {
      ARPOS_INPUT_ERROR("plan " << plan_id.value() << " has no room map: a plan is approved with the room it "
                                   "will be used in (a technician runs `arpos plan CASE --plan "
                                << plan_id.value() << "` first)");
    }
    database->ApprovePlan(plan_id, op.Actor(), note);
    database->AppendAudit({AuditId(), 0, op.Actor("arpos"), "approve_plan", "plan:" + std::to_string(plan_id.value()),
                           "room map " + std::to_string(room_map->value()) + ", reference model " +
                               plan->reference_model_name + ", target pose " +
                               plan->room_from_model_target.ToString() + (note.empty() ? "" : "; note: " + note)});
    approved = *database->GetPlan(plan_id);
  });
  return approved;
}

SessionRecord RequireOpenSession(Database* database, SessionId session, const std::string& what) {
  const std::optional<SessionRecord> s = database->GetSession(session);
  if (!s) ARPOS_INPUT_ERROR("the store has no session " << session.value());
  if (s->status != SessionStatus::kOpen) {
    ARPOS_INPUT_ERROR("session " << session.value() << " is " << DescribeEnd(*s) << ": " << what
                                 << " needs an open session; start a new one (arpos session CASE)");
  }
  return *s;
}

SessionRecord EndSession(Database* database, const Operator& op, SessionId session, SessionStatus status,
                         const std::string& reason) {
  RequirePermission(op, Action::kEndSession);
  ARPOS_CHECK(status != SessionStatus::kOpen, "EndSession needs completed or aborted");
  SessionRecord ended;
  database->WithTransaction([&] {
    RequireOpenSession(database, session, status == SessionStatus::kCompleted ? "completing" : "aborting");
    const std::string host = ThisHostName();
    for (const SessionActivity& a : database->ListSessionActivities()) {
      if (a.session_id != session || a.pid == getpid()) continue;
      if (a.host != host || ProcessExists(a.pid)) {
        ARPOS_INPUT_ERROR("session " << session.value() << " is in use: " << a.command << " (process " << a.pid
                                     << " on " << a.host << ") is at work on it; stop it first");
      }
    }
    database->FinishSession(session, status, 0, op.Actor(), reason);
    database->AppendAudit({AuditId(), 0, op.Actor("arpos"),
                           status == SessionStatus::kCompleted ? "complete_session" : "abort_session",
                           SessionEntity(session), reason});
    ended = *database->GetSession(session);
  });
  return ended;
}

std::vector<std::string> RecoverInterruptedSessions(Database* database) {
  std::vector<std::string> said;
  const std::string host = ThisHostName();
  try {
    for (const SessionActivity& a : database->ListSessionActivities()) {
      if (a.host != host || ProcessExists(a.pid)) continue;
      database->WithTransaction([&] {
        const std::optional<SessionRecord> s = database->GetSession(a.session_id);
        if (s && s->status == SessionStatus::kOpen) {
          const std::string reason = a.command + " (process " + std::to_string(a.pid) + ", started " +
                                     FormatUtcTime(a.started_unix_ms) + ") ended without finishing";
          database->FinishSession(a.session_id, SessionStatus::kAborted, 0, "arpos (recovery)", reason);
          database->AppendAudit({AuditId(), 0, "arpos (recovery)", "abort_session", SessionEntity(a.session_id),
                                 reason});
          said.push_back("session " + std::to_string(a.session_id.value()) + " marked aborted: " + reason);
          ARPOS_WARN(said.back());
        }
        database->EndSessionActivity(a.id);
      });
    }
  } catch (const Error& e) {
    // A read-only or busy store: the next writer recovers; say so.
    said.push_back(std::string("could not check for interrupted sessions: ") + e.what());
    ARPOS_WARN(said.back());
  }
  return said;
}

SessionActivityGuard::SessionActivityGuard(Database* database, SessionId session, const std::string& command)
    : database_(database) {
  SessionActivity a;
  a.session_id = session;
  a.pid = getpid();
  a.host = ThisHostName();
  a.command = command;
  id_ = database_->BeginSessionActivity(a);
}

SessionActivityGuard::~SessionActivityGuard() {
  try {
    database_->EndSessionActivity(id_);
  } catch (const std::exception& e) {
    ARPOS_WARN("could not remove the session activity " << id_ << ": " << e.what());
  }
}

}  // namespace arpos
