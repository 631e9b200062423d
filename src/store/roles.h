#pragma once
/// Who is doing what: the people of the workflow and what each may do.
///
/// ARPos is used by a planning technician (maps the room, prepares the
/// plan), a therapist (runs the session, positions the patient) and a medical
/// physicist (approves plans, audits). The role is declared, not proven: a
/// user names themselves and their role (`--user NAME --role ROLE`, or
/// ARPOS_USER / ARPOS_ROLE, or the GUI's start dialog). Real authentication
/// is out of scope; the roles keep each person to their part of the workflow
/// and every write names who did it.
///
/// With no role given a command runs as `research` (tests, measurements,
/// `arpos run-case`): it may do every step but approve, and every session it
/// runs is recorded as on an unapproved plan.
///
/// The controllers check permissions (RequirePermission) before they read
/// or write anything; the GUI only hides what the role cannot do.

#include <optional>
#include <string>

#include "util/check.h"

namespace arpos {

enum class Role { kResearch, kTechnician, kTherapist, kPhysicist };

/// "research", "technician", "therapist", "physicist".
std::string RoleName(Role role);
/// The role of that name (case-insensitive); nullopt for anything else.
std::optional<Role> ParseRole(const std::string& name);
/// "technician, therapist, physicist, research".
std::string RoleNames();

/// What a role may be asked to do.
enum class Action {
  kPlan,          ///< patients, plans, room recordings and maps (arpos plan, import in the GUI)
  kApprovePlan,   ///< arpos plan approve
  kRunSession,    ///< the session stage, manual alignment
  kTrack,         ///< tracking runs (arpos track, the positioning screen)
  kEndSession,    ///< complete or abort a session
  kRunCase,       ///< every stage at once (arpos run-case)
};

/// Words for the action, e.g. "approve plans".
std::string ActionName(Action action);

/// The person at the keyboard.
struct Operator {
  std::string user;            ///< non-empty
  Role role = Role::kResearch;
  bool role_given = false;     ///< false: research because no role was given

  /// The audit log's actor: "NAME (ROLE)", e.g. "ana (therapist)"; a
  /// research run without a given role reads "NAME (research: no role given)".
  std::string Actor() const;
  /// Actor() and the program part, e.g. "ana (therapist), arpos track".
  std::string Actor(const std::string& via) const;
};

bool Permits(Role role, Action action);

/// Thrown when the operator's role may not do an action: an input error
/// (exit status 2) whose message says who may.
class NotPermitted : public InputError {
 public:
  using InputError::InputError;
};

/// Throws NotPermitted, e.g. "ana is a therapist: approving plans is for a
/// physicist (--role physicist)".
void RequirePermission(const Operator& op, Action action);

/// The operator from the command line (`user`, `role`: empty if not given),
/// else ARPOS_USER / ARPOS_ROLE, else the login name and research. Throws
/// InputError naming the option or variable for an unknown role or an empty
/// or unprintable user name.
Operator ResolveOperator(const std::string& user, const std::string& role);

}  // namespace arpos
