// People and roles, plan approval and the session lifecycle through the real
// `arpos` executable on a copy of the sample case, as the three people of the
// workflow would use it (store/roles.h, store/lifecycle.h).
#include <gtest/gtest.h>
#include <sqlite3.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <string>

#include "cli/cli_util.h"
#include "util/file.h"

namespace arpos {
namespace {

namespace fs = std::filesystem;
using testing::CliResult;
using testing::RunArpos;

bool Contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

// Runs SQL on a store; returns SQLite's error message, "" if it succeeded.
std::string Sql(const std::string& store, const std::string& sql, std::string* first_value = nullptr) {
  sqlite3* db = nullptr;
  if (sqlite3_open(store.c_str(), &db) != SQLITE_OK) return "cannot open";
  char* error = nullptr;
  std::string value;
  auto callback = [](void* out, int n, char** values, char**) {
    if (n > 0 && values[0] && static_cast<std::string*>(out)->empty()) *static_cast<std::string*>(out) = values[0];
    return 0;
  };
  const int rc = sqlite3_exec(db, sql.c_str(), callback, &value, &error);
  std::string message = rc == SQLITE_OK ? "" : (error ? error : "error");
  sqlite3_free(error);
  sqlite3_close(db);
  if (first_value) *first_value = value;
  return message;
}

std::string Value(const std::string& store, const std::string& sql) {
  std::string v;
  const std::string error = Sql(store, sql, &v);
  EXPECT_EQ(error, "") << sql;
  return v;
}

class Roles : public ::testing::Test {
 protected:
  void SetUp() override {
    fs::copy(fs::path(ARPOS_SAMPLE_SESSIONS_DIR) / "demo_xtion", dir_.path() / "demo_xtion",
             fs::copy_options::recursive);
  }
  std::string Case() const { return (dir_.path() / "demo_xtion").string(); }
  std::string Seq() const { return (dir_.path() / "demo_xtion" / "tracking" / "seq_00").string(); }
  std::string store() const { return (dir_.path() / "store.db").string(); }
  std::string S() const { return " --store " + store(); }
  CliResult As(const std::string& who, const std::string& command) { return RunArpos(command + S() + " " + who); }
  static constexpr const char* kTechnician = "--user tom --role technician";
  static constexpr const char* kTherapist = "--user ana --role therapist";
  static constexpr const char* kPhysicist = "--user pia --role physicist";
  TempDir dir_;
};

TEST_F(Roles, EachRoleDoesItsPartAndAnApprovedPlanStaysAsApproved) {
  // Planning is a technician's: a therapist is refused, and nothing is stored.
  CliResult r = As(kTherapist, "plan " + Case());
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(Contains(r.output, "ana is a therapist: planning")) << r.output;
  EXPECT_TRUE(Contains(r.output, "--role technician")) << r.output;
  EXPECT_EQ(Value(store(), "SELECT COUNT(*) FROM plans"), "0");
  r = As(kTechnician, "plan " + Case());
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_TRUE(Contains(r.output, "plan 1 created")) << r.output;
  EXPECT_TRUE(Contains(r.output, "not approved until a physicist approves it")) << r.output;
  // Planning again refines the same unapproved plan: no duplicate.
  r = As(kTechnician, "plan " + Case() + "");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_TRUE(Contains(r.output, "plan: plan 1 (the patient's plan not yet approved)")) << r.output;
  EXPECT_EQ(Value(store(), "SELECT COUNT(*) FROM plans"), "1");

  // Sessions run on approved plans only.
  r = As(kTherapist, "session " + Case());
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(Contains(r.output, "no plan of patient demo_xtion is approved")) << r.output;
  EXPECT_EQ(Value(store(), "SELECT COUNT(*) FROM sessions"), "0");

  // Only a physicist approves.
  for (const char* who : {kTechnician, kTherapist, ""}) {
    r = As(who, "plan approve 1");
    EXPECT_EQ(r.status, 2) << who << ": " << r.output;
    EXPECT_TRUE(Contains(r.output, "approving plans is for a physicist")) << r.output;
  }
  r = As(kPhysicist, "plan approve 1 --note \"checked against the CT\"");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_TRUE(Contains(r.output, "approved by pia (physicist)")) << r.output;
  // The physicist hears what the room frame does to tracking at the default
  // tolerances (2 mm / 1 deg) when three of its sigmas exceed them.
  {
    const double mm = std::stod(
        Value(store(), "SELECT room_frame_couch_sigma_mm FROM room_maps WHERE plan_id = 1"));
    const double tilt = std::stod(
        Value(store(), "SELECT room_frame_tilt_sigma_deg FROM room_maps WHERE plan_id = 1"));
    const double yaw = std::stod(
        Value(store(), "SELECT room_frame_yaw_sigma_deg FROM room_maps WHERE plan_id = 1"));
    const bool blocks = 3 * mm >= 2.0 || 3 * std::hypot(tilt, yaw) >= 1.0;
    EXPECT_EQ(
        Contains(
            r.output,
            "warning: with this room map no tracked frame can read `in` at a tolerance of 2.0 mm"),
        blocks)
        << "room frame " << mm << " mm, " << tilt << " / " << yaw << " deg: " << r.output;
  }
  r = As(kPhysicist, "plan approve 1");
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(Contains(r.output, "already approved")) << r.output;
  EXPECT_EQ(Value(store(), "SELECT approval_note FROM plans WHERE plan_id = 1"), "checked against the CT");

  // An approved plan cannot be changed: not by the program, not in the store.
  r = As(kTechnician, "plan " + Case() + " --plan 1");
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(Contains(r.output, "an approved plan cannot be changed")) << r.output;
  EXPECT_TRUE(Contains(Sql(store(), "UPDATE plans SET name = 'x' WHERE plan_id = 1"), "approved and cannot be changed"));
  EXPECT_TRUE(Contains(Sql(store(), "DELETE FROM plans WHERE plan_id = 1"), "approved and cannot be deleted"));
  EXPECT_TRUE(Contains(Sql(store(), "INSERT INTO room_maps SELECT * FROM room_maps WHERE plan_id = 1"),
                       "no room map can be added"));
  // Without --plan, planning makes a new plan next to the approved one.
  r = As(kTechnician, "plan " + Case() + "");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_TRUE(Contains(r.output, "approved plan(s) cannot be changed): plan 2 created")) << r.output;

  // The therapist's session uses the one approved plan and says so.
  r = As(kTherapist, "session " + Case());
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_TRUE(Contains(r.output, "using plan 1 \"demo_xtion plan\" (approved by pia (physicist)")) << r.output;
  EXPECT_EQ(Value(store(), "SELECT on_unapproved_plan FROM sessions WHERE session_id = 1"), "0");

  // Tracking is a therapist's, on an open session.
  r = As(kTechnician, "track " + Seq() + " --out " + (dir_.path() / "t1").string());
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(Contains(r.output, "tracking the patient is for a therapist")) << r.output;
  r = As(kTherapist, "track " + Seq() + " --out " + (dir_.path() / "t1").string());
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_TRUE(Contains(r.output, "session 1, the only open session of patient demo_xtion")) << r.output;

  // Ending a session: a therapist's; an abort says why.
  r = As(kPhysicist, "session complete 1");
  EXPECT_EQ(r.status, 2) << r.output;
  r = As(kTherapist, "session abort 1");
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(Contains(r.output, "--reason")) << r.output;
  r = As(kTherapist, "session complete 1");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_TRUE(Contains(r.output, "session 1 completed by ana (therapist)")) << r.output;
  r = As(kTherapist, "track " + Seq() + " --out " + (dir_.path() / "t2").string());
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(Contains(r.output, "no open session")) << r.output;
  r = As(kTherapist, "track " + Seq() + " --session 1 --out " + (dir_.path() / "t2").string());
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(Contains(r.output, "session 1 is completed by ana (therapist)")) << r.output;

  // A plan that is not approved: refused, unless --unapproved, which is recorded.
  r = As(kTherapist, "session " + Case() + " --plan 2");
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(Contains(r.output, "plan 2 is not approved")) << r.output;
  r = As(kTherapist, "session " + Case() + " --plan 2 --unapproved");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_TRUE(Contains(r.output, "the plan is not approved; the session is recorded as such")) << r.output;
  EXPECT_EQ(Value(store(), "SELECT on_unapproved_plan FROM sessions WHERE session_id = 2"), "1");
  EXPECT_TRUE(Contains(Value(store(), "SELECT details FROM audit_log WHERE action = 'open_session' AND "
                                      "entity = 'session:2'"),
                       "not approved (run with --unapproved)"));

  // Every write names who made it, and the log verifies.
  EXPECT_EQ(Value(store(), "SELECT COUNT(*) FROM audit_log WHERE actor NOT LIKE 'tom (technician)%' AND actor NOT "
                           "LIKE 'ana (therapist)%' AND actor NOT LIKE 'pia (physicist)%'"),
            "0");
  r = RunArpos("audit verify" + S());
  EXPECT_EQ(r.status, 0) << r.output;
}

TEST_F(Roles, NoRoleIsAResearchRunThatMayDoAllButApprove) {
  // run-case is a research run: its plan stays unapproved and its session is
  // recorded so; the session is completed at the end.
  CliResult r = RunArpos("run-case " + Case() + S() + " --quick --user rex");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(Value(store(), "SELECT status || ' ' || on_unapproved_plan || ' ' || ended_by FROM sessions"),
            "completed 1 rex (research: no role given)");
  EXPECT_EQ(Value(store(), "SELECT approved_unix_ms IS NULL FROM plans"), "1");
  // Tracking after run-case: its session is completed, so tracking says why not.
  r = RunArpos("track " + Seq() + S() + " --out " + (dir_.path() / "t0").string());
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(Contains(r.output, "run-case completes its session at the end unless --keep-open")) << r.output;
  // Two open sessions: a research run takes the newest and says so; a
  // therapist must choose.
  for (int i = 0; i < 2; ++i) {
    r = RunArpos("session " + Case() + S() + " --unapproved");
    ASSERT_EQ(r.status, 0) << r.output;
  }
  r = RunArpos("track " + Seq() + S() + " --out " + (dir_.path() / "t1").string());
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_TRUE(Contains(r.output, "session 3, the newest of the open sessions of patient demo_xtion (3, 2;")) << r.output;
  r = RunArpos("track " + Seq() + S() + " --out " + (dir_.path() / "t2").string() + " " + kTherapist);
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(Contains(r.output, "has 2 open sessions (3, 2): choose one with --session ID")) << r.output;
  r = RunArpos("run-case " + Case() + S() + " --quick " + kTherapist);
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(Contains(r.output, "run-case) is for a research run")) << r.output;
  r = RunArpos("plan approve 1" + S() + " --user rex");
  EXPECT_EQ(r.status, 2) << r.output;
  r = RunArpos("plan list" + S() + " --role nurse");
  EXPECT_EQ(r.status, 0) << r.output;  // reading needs no role
  r = RunArpos("session " + Case() + S() + " --role nurse");
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(Contains(r.output, "--role 'nurse': not a role; the roles are technician, therapist, physicist")) << r.output;
}

TEST_F(Roles, ARunThatDiedLeavesItsSessionAbortedAndSaysSo) {
  CliResult r = RunArpos("run-case " + Case() + S() + " --quick --keep-open");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(Value(store(), "SELECT status FROM sessions"), "open");
  // A tracking run killed mid-way leaves its registration behind: here, the
  // registration of a process that has ended.
  const pid_t child = fork();
  if (child == 0) _exit(0);
  waitpid(child, nullptr, 0);
  char host[256] = {0};
  gethostname(host, sizeof(host) - 1);
  ASSERT_EQ(Sql(store(), "INSERT INTO session_activity (session_id, pid, host, command, started_unix_ms) VALUES (1, " +
                             std::to_string(child) + ", '" + host + "', 'arpos track seq_00', 1)"),
            "");
  // A live process at work on the session blocks ending it.
  ASSERT_EQ(Sql(store(), "INSERT INTO session_activity (session_id, pid, host, command, started_unix_ms) VALUES (1, 1, '" +
                             std::string(host) + "', 'arpos gui', 1)"),
            "");
  r = RunArpos("session complete 1" + S());
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(Contains(r.output, "session 1 marked aborted: arpos track seq_00 (process " + std::to_string(child)))
      << r.output;
  EXPECT_EQ(Value(store(), "SELECT status || ' | ' || ended_by FROM sessions"), "aborted | arpos (recovery)");
  EXPECT_EQ(Value(store(), "SELECT COUNT(*) FROM session_activity"), "1");  // the live one stays
  EXPECT_EQ(Value(store(), "SELECT action FROM audit_log ORDER BY audit_id DESC LIMIT 1"), "abort_session");
  r = RunArpos("audit verify" + S());
  EXPECT_EQ(r.status, 0) << r.output;
}

}  // namespace
}  // namespace arpos
