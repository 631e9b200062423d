#pragma once
/// Audited changes of state: a plan's approval, a session's end, and the
/// sessions whose run died. Each checks the operator's role (store/roles.h)
/// and the record's state first, then changes the row and appends its audit
/// entry in one transaction. Used by the CLI, run-case and the GUI.
///
/// A session is open from the session stage until a therapist completes or
/// aborts it (`arpos session complete|abort`, the GUI, or run-case at its
/// end). Tracking runs only on open sessions. A command at work on a session
/// registers itself (SessionActivityGuard); a registration left behind by a
/// process that no longer exists on this host is a run that died, and the
/// next command that opens the store marks its session aborted
/// (RecoverInterruptedSessions), saying which command and process.

#include <cstdint>
#include <string>
#include <vector>

#include "store/database.h"
#include "store/roles.h"

namespace arpos {

/// `op` (a physicist) approves `plan`, which must exist, not be approved and
/// have a room map. Throws NotPermitted / InputError saying what is wrong.
PlanRecord ApprovePlan(Database* database, const Operator& op, PlanId plan, const std::string& note);

/// "approved by NAME (physicist) on 2026-12-02 10:00:00 UTC" or "not approved".
std::string DescribeApproval(const PlanRecord& plan);
std::string DescribeApproval(const PlanSummary& plan);

/// Completes (kCompleted) or aborts (kAborted) an open session. Refused
/// while another live process is at work on it. `reason` may be empty for
/// kCompleted.
SessionRecord EndSession(Database* database, const Operator& op, SessionId session, SessionStatus status,
                         const std::string& reason);

/// Throws InputError unless `session` exists and is open, e.g. "session 3 is
/// completed (by ana (therapist) on ...): tracking runs on open sessions;
/// start a new session (arpos session CASE)". `what` names the refused step.
SessionRecord RequireOpenSession(Database* database, SessionId session, const std::string& what);

/// Marks aborted every open session whose registered command's process no
/// longer exists on this host, removes the registrations, and returns a
/// sentence per session for the user. Registrations from other hosts are
/// left alone. Never throws for a store it can read.
std::vector<std::string> RecoverInterruptedSessions(Database* database);

/// Registers `command` (this process) as at work on `session` for its
/// lifetime.
class SessionActivityGuard {
 public:
  SessionActivityGuard(Database* database, SessionId session, const std::string& command);
  ~SessionActivityGuard();
  SessionActivityGuard(const SessionActivityGuard&) = delete;
  SessionActivityGuard& operator=(const SessionActivityGuard&) = delete;

 private:
  Database* database_;
  std::int64_t id_ = 0;
};

/// This machine's host name (for SessionActivity).
std::string ThisHostName();

}  // namespace arpos
