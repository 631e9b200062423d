#include "store/roles.h"

#include <pwd.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <vector>

namespace arpos {
namespace {

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

std::string LoginName() {
  if (const char* user = std::getenv("USER"); user && *user) return user;
  if (const passwd* pw = getpwuid(getuid()); pw && pw->pw_name && *pw->pw_name) return pw->pw_name;
  return "uid " + std::to_string(getuid());
}

/// Who may, for the message of a refusal.
std::string WhoMay(Action action) {
  std::vector<std::string> roles;
  for (Role r : {Role::kTechnician, Role::kTherapist, Role::kPhysicist, Role::kResearch}) {
    if (Permits(r, action)) roles.push_back(r == Role::kResearch ? "research run" : RoleName(r));
  }
  std::string out;
  for (size_t i = 0; i < roles.size(); ++i) {
    out += (i == 0 ? "" : i + 1 == roles.size() ? " or " : ", ") + ("a " + roles[i]);
  }
  return out.empty() ? "nobody" : out;
}

void CheckUserName(const std::string& user, const std::string& source) {
  if (user.empty()) ARPOS_INPUT_ERROR(source << ": the user name is empty");
  if (user.size() > 100) ARPOS_INPUT_ERROR(source << ": the user name is longer than 100 characters");
  for (unsigned char c : user) {
    if (c < 0x20 || c == 0x7f) ARPOS_INPUT_ERROR(source << ": the user name has a control character");
  }
}

}  // namespace

std::string RoleName(Role role) {
  switch (role) {
    case Role::kTechnician: return "technician";
    case Role::kTherapist: return "therapist";
    case Role::kPhysicist: return "physicist";
    case Role::kResearch: break;
  }
  return "research";
}

std::optional<Role> ParseRole(const std::string& name) {
  const std::string n = Lower(name);
  for (Role r : {Role::kTechnician, Role::kTherapist, Role::kPhysicist, Role::kResearch}) {
    if (n == RoleName(r)) return r;
  }
  return std::nullopt;
}

std::string RoleNames() { return "technician, therapist, physicist, research"; }

std::string ActionName(Action action) {
  switch (action) {
    case Action::kPlan: return "planning (room maps, plans)";
    case Action::kApprovePlan: return "approving plans";
    case Action::kRunSession: return "running sessions";
    case Action::kTrack: return "tracking the patient";
    case Action::kEndSession: return "completing or aborting sessions";
    case Action::kRunCase: return "running every stage at once (run-case)";
  }
  return "this";
}

std::string Operator::Actor() const {
  return (user.empty() ? std::string("unnamed") : user) + " (" + RoleName(role) + (role_given ? "" : ": no role given") + ")";
}

std::string Operator::Actor(const std::string& via) const { return via.empty() ? Actor() : Actor() + ", " + via; }

bool Permits(Role role, Action action) {
  switch (action) {
    case Action::kPlan: return role == Role::kTechnician || role == Role::kResearch;
    case Action::kApprovePlan: return role == Role::kPhysicist;
    case Action::kRunSession:
    case Action::kTrack:
    case Action::kEndSession: return role == Role::kTherapist || role == Role::kResearch;
    case Action::kRunCase: return role == Role::kResearch;
  }
  return false;
}

void RequirePermission(const Operator& op, Action action) {
  if (Permits(op.role, action)) return;
  std::string flag;
  for (Role r : {Role::kTechnician, Role::kTherapist, Role::kPhysicist, Role::kResearch}) {
    if (Permits(r, action)) {
      flag = " (--role " + RoleName(r) + ")";
      break;
    }
  }
  const std::string who = op.role == Role::kResearch ? "on a research run" : "a " + RoleName(op.role);
  throw NotPermitted(op.user + " is " + who + ": " + ActionName(action) + " is for " + WhoMay(action) + flag);
}

Operator ResolveOperator(const std::string& user, const std::string& role) {
  Operator op;
  if (!user.empty()) {
    CheckUserName(user, "--user");
    op.user = user;
  } else if (const char* env = std::getenv("ARPOS_USER"); env && *env) {
    CheckUserName(env, "ARPOS_USER");
    op.user = env;
  } else {
    op.user = LoginName();
  }
  std::string role_text = role, source = "--role";
  if (role_text.empty()) {
    if (const char* env = std::getenv("ARPOS_ROLE"); env && *env) {
      role_text = env;
      source = "ARPOS_ROLE";
    }
  }
  if (!role_text.empty()) {
    const std::optional<Role> parsed = ParseRole(role_text);
    if (!parsed) ARPOS_INPUT_ERROR(source << " '" << role_text << "': not a role; the roles are " << RoleNames());
    op.role = *parsed;
    op.role_given = true;
  }
  return op;
}

}  // namespace arpos
