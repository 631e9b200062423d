// Crash safety: a writer process is SIGKILLed while writing; the store must
// reopen intact with every transaction it reported committed, and nothing of
// the transaction that was open.
//
// The child reports each committed row over a pipe only after Commit()
// returned, so the parent knows a lower bound of what must be there; at most
// one more transaction (committed, killed before reporting) may be present.

#include <gtest/gtest.h>
#include <poll.h>
#include <signal.h>
#include <sqlite3.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <random>

#include "store/sqlite_database.h"
#include "store_test_util.h"
#include "util/file.h"

namespace arpos {
namespace {

namespace fs = std::filesystem;

constexpr std::int64_t kInTransaction = -2;  // child: "the open transaction is written"
constexpr std::int64_t kChildFailed = -1;

// Deterministic content of committed row `i`.
struct Row {
  PatientRecord patient;
  PlanRecord plan;
  SessionRecord session;
  ReconstructionRecord reconstruction;
  AuditEntry audit;
};

Row MakeRow(std::int64_t i) {
  std::mt19937 rng(static_cast<unsigned>(1000 + i));
  Row row;
  row.patient.external_id = "crash-" + std::to_string(i);
  row.patient.created_unix_ms = 1700000000000 + i;
  row.plan.name = "plan " + std::to_string(i);
  row.plan.reference_model = test::RandomMesh(rng);
  row.plan.room_from_model_target = test::RandomPose(rng);
  row.plan.created_unix_ms = 1700000000000 + i;
  row.session.started_unix_ms = 1700000000000 + i;
  // ~54 kB per transaction, so a kill often lands in the middle of writing one.
  row.reconstruction.cloud = test::RandomCloud(rng, 2000, true, true);
  row.reconstruction.created_unix_ms = 1700000000000 + i;
  row.audit.actor = "crash-test";
  row.audit.action = "write_row";
  row.audit.details = "row " + std::to_string(i);
  row.audit.time_unix_ms = 1700000000000 + i;
  return row;
}

void WriteRow(Database& db, std::int64_t i) {
  Row row = MakeRow(i);
  db.WithTransaction([&] {
    row.plan.patient_id = db.AddPatient(row.patient);
    row.session.plan_id = db.AddPlan(row.plan);
    row.reconstruction.session_id = db.AddSession(row.session);
    db.AddReconstruction(row.reconstruction);
    row.audit.entity = "patient:" + std::to_string(row.plan.patient_id.value());
    db.AppendAudit(row.audit);
  });
}

void Report(int fd, std::int64_t value) {
  // 8 bytes < PIPE_BUF: atomic, never split.
  if (::write(fd, &value, sizeof value) != static_cast<ssize_t>(sizeof value)) ::_exit(4);
}

enum class ChildMode {
  kWriteUntilKilled,       // parent kills at an arbitrary point
  kKillSelfInTransaction,  // child kills itself with a large transaction open
};

[[noreturn]] void RunChild(const std::string& path, int fd, ChildMode mode, int committed_first) {
  try {
    auto db = SqliteDatabase::Open(path);
    const std::int64_t rows = mode == ChildMode::kWriteUntilKilled ? 1000000 : committed_first;
    for (std::int64_t i = 0; i < rows; ++i) {
      WriteRow(*db, i);
      Report(fd, i);
    }
    // A small page cache forces the open transaction's pages out to the WAL
    // before the kill, so recovery really has uncommitted frames to ignore.
    sqlite3_exec(db->RawHandle(), "PRAGMA cache_size = -64", nullptr, nullptr, nullptr);
    db->WithTransaction([&] {
      PatientRecord patient;
      patient.display_name = std::string(4000, 'x');
      for (int i = 0; i < 2000; ++i) {
        patient.external_id = "uncommitted-" + std::to_string(i);
        db->AddPatient(patient);
      }
      Report(fd, kInTransaction);
      ::raise(SIGKILL);
    });
  } catch (...) {
    Report(fd, kChildFailed);
    ::_exit(3);
  }
  ::_exit(5);  // not reached: killed above
}

// Reads one report; false on EOF. Fails the test after `timeout_ms` of silence.
bool ReadReport(int fd, std::int64_t* value, int timeout_ms = 60000) {
  pollfd p{fd, POLLIN, 0};
  if (::poll(&p, 1, timeout_ms) <= 0) {
    ADD_FAILURE() << "child went silent for " << timeout_ms << " ms";
    return false;
  }
  const ssize_t n = ::read(fd, value, sizeof *value);
  if (n == 0) return false;
  EXPECT_EQ(n, static_cast<ssize_t>(sizeof *value));
  return n == static_cast<ssize_t>(sizeof *value);
}

std::string IntegrityCheck(SqliteDatabase& db) {
  sqlite3_stmt* stmt = nullptr;
  sqlite3_prepare_v2(db.RawHandle(), "PRAGMA integrity_check", -1, &stmt, nullptr);
  std::string result;
  while (sqlite3_step(stmt) == SQLITE_ROW) {
    result += reinterpret_cast<const char*>(sqlite3_column_text(stmt, 0));
  }
  sqlite3_finalize(stmt);
  return result;
}

// The first column of the first row of `sql` (a count or an id), -1 if none.
std::int64_t CountRows(SqliteDatabase& db, const std::string& sql) {
  sqlite3_stmt* stmt = nullptr;
  EXPECT_EQ(sqlite3_prepare_v2(db.RawHandle(), sql.c_str(), -1, &stmt, nullptr), SQLITE_OK);
  std::int64_t count = -1;
  if (sqlite3_step(stmt) == SQLITE_ROW) count = sqlite3_column_int64(stmt, 0);
  sqlite3_finalize(stmt);
  return count;
}

// Checks that row i is present and exactly as written.
void ExpectRowIntact(SqliteDatabase& db, std::int64_t i) {
  const Row expected = MakeRow(i);
  const auto patient = db.FindPatient(expected.patient.external_id);
  ASSERT_TRUE(patient) << "committed row " << i << " is missing";
  const auto plans = db.ListPlans(patient->id);
  ASSERT_EQ(plans.size(), 1u) << "row " << i;
  const auto plan = db.GetPlan(plans[0].id);
  ASSERT_TRUE(plan);
  test::ExpectMeshEq(expected.plan.reference_model, plan->reference_model);
  test::ExpectPoseEq(expected.plan.room_from_model_target, plan->room_from_model_target);
  const auto sessions = db.ListSessions(plan->id);
  ASSERT_EQ(sessions.size(), 1u) << "row " << i;
  const std::int64_t reconstruction_id =
      CountRows(db, "SELECT reconstruction_id FROM reconstructions WHERE session_id = " +
                        std::to_string(sessions[0].id.value()));
  const auto reconstruction = db.GetReconstruction(ReconstructionId(reconstruction_id));
  ASSERT_TRUE(reconstruction) << "row " << i;
  test::ExpectCloudEq(expected.reconstruction.cloud, reconstruction->cloud);
}

struct ChildResult {
  std::vector<std::int64_t> committed;  // reported rows, in order
  bool saw_in_transaction = false;
  bool failed = false;
  int wait_status = 0;
};

// Forks a writer on `path`; `kill_after` > 0: the parent SIGKILLs it after that
// many reports.
ChildResult RunWriter(const std::string& path, ChildMode mode, int committed_first,
                      std::size_t kill_after) {
  ChildResult result;
  int fds[2];
  if (::pipe(fds) != 0) {
    ADD_FAILURE() << "pipe: " << std::strerror(errno);
    return result;
  }
  const pid_t pid = ::fork();
  if (pid < 0) {
    ADD_FAILURE() << "fork: " << std::strerror(errno);
    return result;
  }
  if (pid == 0) {
    ::close(fds[0]);
    RunChild(path, fds[1], mode, committed_first);
  }
  ::close(fds[1]);
  std::int64_t value = 0;
  bool killed = false;
  while (ReadReport(fds[0], &value)) {
    if (value == kChildFailed) {
      result.failed = true;
    } else if (value == kInTransaction) {
      result.saw_in_transaction = true;
    } else {
      result.committed.push_back(value);
    }
    if (!killed && kill_after > 0 && result.committed.size() >= kill_after) {
      ::kill(pid, SIGKILL);  // reports already in the pipe stay readable
      killed = true;
    }
  }
  if (!killed) ::kill(pid, SIGKILL);  // no-op if it is dead; never leave it running
  ::close(fds[0]);
  ::waitpid(pid, &result.wait_status, 0);
  return result;
}

void ExpectKilled(const ChildResult& result) {
  EXPECT_FALSE(result.failed) << "the writer threw before it was killed";
  EXPECT_TRUE(WIFSIGNALED(result.wait_status) && WTERMSIG(result.wait_status) == SIGKILL)
      << "wait status " << result.wait_status;
}

TEST(CrashSafety, WriterKilledMidStreamLosesNothingItCommitted) {
  TempDir dir;
  const std::string path = (dir.path() / "crash.db").string();
  const ChildResult result = RunWriter(path, ChildMode::kWriteUntilKilled, 0, 40);
  ExpectKilled(result);
  ASSERT_GE(result.committed.size(), 40u);
  for (std::size_t i = 0; i < result.committed.size(); ++i) {
    ASSERT_EQ(result.committed[i], static_cast<std::int64_t>(i));
  }

  auto db = SqliteDatabase::Open(path);
  EXPECT_EQ(IntegrityCheck(*db), "ok");
  EXPECT_EQ(CountRows(*db, "SELECT COUNT(*) FROM pragma_foreign_key_check"), 0);
  const std::int64_t reported = static_cast<std::int64_t>(result.committed.size());
  const std::int64_t present = CountRows(*db, "SELECT COUNT(*) FROM patients");
  EXPECT_GE(present, reported);
  EXPECT_LE(present, reported + 1) << "more rows than were ever committed";
  // Whole transactions only: every patient has its plan, session,
  // reconstruction and audit entry.
  for (const char* table : {"plans", "sessions", "reconstructions", "audit_log"}) {
    EXPECT_EQ(CountRows(*db, std::string("SELECT COUNT(*) FROM ") + table), present) << table;
  }
  for (std::int64_t i = 0; i < present; ++i) ExpectRowIntact(*db, i);
  // The store is usable after recovery.
  WriteRow(*db, present);
  ExpectRowIntact(*db, present);
}

TEST(CrashSafety, WriterKilledInsideATransactionLeavesNoTraceOfIt) {
  TempDir dir;
  const std::string path = (dir.path() / "crash-tx.db").string();
  constexpr int kCommitted = 12;
  const ChildResult result = RunWriter(path, ChildMode::kKillSelfInTransaction, kCommitted, 0);
  ExpectKilled(result);
  ASSERT_EQ(result.committed.size(), static_cast<std::size_t>(kCommitted));
  ASSERT_TRUE(result.saw_in_transaction);
  // ~8 MB of uncommitted pages were spilled to the WAL before the kill; the
  // test only means something if they really reached the file.
  ASSERT_TRUE(fs::exists(path + "-wal"));
  EXPECT_GT(fs::file_size(path + "-wal"), 1u << 20);

  auto db = SqliteDatabase::Open(path);
  EXPECT_EQ(IntegrityCheck(*db), "ok");
  EXPECT_EQ(CountRows(*db, "SELECT COUNT(*) FROM patients"), kCommitted);
  EXPECT_EQ(CountRows(*db, "SELECT COUNT(*) FROM patients WHERE external_id LIKE 'uncommitted%'"),
            0);
  for (std::int64_t i = 0; i < kCommitted; ++i) ExpectRowIntact(*db, i);
}

}  // namespace
}  // namespace arpos
