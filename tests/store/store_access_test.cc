// Problems of the store file itself, as a person meets them: a file that is
// not a database, a read-only file, a folder that cannot be written, a store
// locked by another program. Each is named as such (file or folder, SQLite's
// words, what to do), never as an internal error with SQL or a source line,
// and none loses what the store held.

#include <gtest/gtest.h>
#include <sqlite3.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "store/sqlite_database.h"
#include "store_test_util.h"
#include "util/file.h"
#include "util/logging.h"

namespace arpos {
namespace {

namespace fs = std::filesystem;

bool Contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// A message for a person: no SQL statement, no source location.
void ExpectNoInternals(const std::string& message) {
  EXPECT_FALSE(Contains(message, "[at ")) << message;
  EXPECT_FALSE(Contains(message, "[in: ")) << message;
  EXPECT_FALSE(Contains(message, ".cc:")) << message;
}

// What Open says about `path`, or "" if it opened.
std::string OpenProblem(const std::string& path) {
  try {
    SqliteDatabase::Open(path);
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

// Runs `fn` where file permissions apply. Root writes read-only files and
// folders, so as root `fn` runs in a child process as user nobody (which
// cannot write what root made with mode 0644 or 0755); otherwise here.
std::string WithPermissionsApplied(const std::function<std::string()>& fn) {
  if (::geteuid() != 0) return fn();
  int fds[2];
  if (::pipe(fds) != 0) return "pipe failed";
  const pid_t pid = ::fork();
  if (pid < 0) return "fork failed";
  if (pid == 0) {
    ::close(fds[0]);
    std::string out;
    if (::setgid(65534) != 0 || ::setuid(65534) != 0) {
      out = "cannot become user nobody";
    } else {
      try {
        out = fn();
      } catch (const std::exception& e) {
        out = std::string("unexpected exception: ") + e.what();
      }
    }
    const ssize_t written = ::write(fds[1], out.data(), out.size());
    ::_exit(written == static_cast<ssize_t>(out.size()) ? 0 : 1);
  }
  ::close(fds[1]);
  std::string out;
  char buffer[4096];
  ssize_t n;
  while ((n = ::read(fds[0], buffer, sizeof buffer)) > 0) out.append(buffer, static_cast<size_t>(n));
  ::close(fds[0]);
  int status = 0;
  ::waitpid(pid, &status, 0);
  return out;
}

// Read-only to the user `WithPermissionsApplied` runs as.
void MakeReadOnly(const fs::path& path) {
  if (::geteuid() != 0) {
    fs::permissions(path, fs::perms::owner_write | fs::perms::group_write | fs::perms::others_write,
                    fs::perm_options::remove);
  } else {
    // Root-owned, not writable by others; the path to it open to everyone.
    fs::permissions(path, fs::perms::others_write, fs::perm_options::remove);
  }
}

// A store with one patient, closed again.
void MakeStore(const std::string& path) {
  auto db = SqliteDatabase::Open(path);
  PatientRecord patient;
  patient.external_id = "kept";
  db->AddPatient(patient);
}

class StoreAccessTest : public ::testing::Test {
 protected:
  void SetUp() override {
    // Everyone may enter the folder (the read-only tests run as nobody).
    fs::permissions(dir_.path(), fs::perms::all, fs::perm_options::add);
  }
  void TearDown() override {
    // Writable again, so that TempDir can remove everything.
    for (const auto& entry : fs::recursive_directory_iterator(dir_.path())) {
      fs::permissions(entry.path(), fs::perms::owner_all, fs::perm_options::add);
    }
  }
  fs::path path(const std::string& name) const { return dir_.path() / name; }
  TempDir dir_;
};

TEST_F(StoreAccessTest, AFileThatIsNotADatabaseIsNamedAsSuchAndLeftAlone) {
  const std::string store = path("notes.db").string();
  std::string garbage;
  for (int i = 0; i < 4096; ++i) garbage.push_back(static_cast<char>((i * 7919 + 13) % 251));
  WriteFileAtomic(store, garbage);
  const std::string message = OpenProblem(store);
  EXPECT_TRUE(Contains(message, store + ": not an ARPos store / not a SQLite database")) << message;
  EXPECT_TRUE(Contains(message, "file is not a database")) << message;
  ExpectNoInternals(message);
  EXPECT_EQ(test::FileBytes(store), garbage);
  try {
    SqliteDatabase::Open(store);
  } catch (const StoreAccessError& e) {
    EXPECT_EQ(e.sqlite_code(), SQLITE_NOTADB);
  }
}

TEST_F(StoreAccessTest, AReadOnlyFileIsRefusedWhenOpenedNotAtTheFirstWrite) {
  const std::string store = path("store.db").string();
  MakeStore(store);
  MakeReadOnly(store);
  const std::string before = test::FileBytes(store);
  const std::string message = WithPermissionsApplied([&] { return OpenProblem(store); });
  EXPECT_TRUE(Contains(message, store + ": read-only file")) << message;
  EXPECT_TRUE(Contains(message, "chmod u+w")) << message;
  ExpectNoInternals(message);
  EXPECT_EQ(test::FileBytes(store), before);
  EXPECT_TRUE(SqliteDatabase::Open(store)->FindPatient("kept"));
}

TEST_F(StoreAccessTest, AReadOnlyFolderIsBlamedNotTheFile) {
  const fs::path folder = path("shelf");
  fs::create_directory(folder);
  const std::string store = (folder / "store.db").string();
  MakeStore(store);
  fs::permissions(store, fs::perms::all, fs::perm_options::add);  // the file is writable
  MakeReadOnly(folder);
  const std::string message = WithPermissionsApplied([&] { return OpenProblem(store); });
  EXPECT_TRUE(Contains(message, store + ": folder not writable: " + folder.string())) << message;
  EXPECT_FALSE(Contains(message, "read-only file")) << message;
  ExpectNoInternals(message);
  // A new store there: the same.
  const std::string fresh = (folder / "new.db").string();
  const std::string fresh_message = WithPermissionsApplied([&] { return OpenProblem(fresh); });
  EXPECT_TRUE(Contains(fresh_message, fresh + ": folder not writable: " + folder.string())) << fresh_message;
  EXPECT_FALSE(fs::exists(fresh));
  // A folder that does not exist.
  const std::string nowhere = path("no/such/folder/store.db").string();
  const std::string nowhere_message = OpenProblem(nowhere);
  EXPECT_TRUE(Contains(nowhere_message, "does not exist")) << nowhere_message;
  ExpectNoInternals(nowhere_message);
}

// Collects the log for a scope; `on_message` may act on each line.
class LogCapture {
 public:
  explicit LogCapture(std::function<void(const std::string&)> on_message = nullptr)
      : on_message_(std::move(on_message)) {
    previous_ = SetLogSink([this](LogLevel, const std::string& message) {
      lines_.push_back(message);
      if (on_message_) on_message_(message);
    });
  }
  ~LogCapture() { SetLogSink(previous_); }
  std::string All() const {
    std::string all;
    for (const auto& line : lines_) all += line + "\n";
    return all;
  }

 private:
  std::function<void(const std::string&)> on_message_;
  LogSink previous_;
  std::vector<std::string> lines_;
};

// Another program's connection that holds the store's write lock.
class LockHolder {
 public:
  explicit LockHolder(const std::string& path) {
    EXPECT_EQ(sqlite3_open(path.c_str(), &db_), SQLITE_OK);
    EXPECT_EQ(sqlite3_exec(db_,
                           "BEGIN IMMEDIATE; INSERT INTO patients (external_id, display_name, "
                           "created_unix_ms) VALUES ('other program', '', 1)",
                           nullptr, nullptr, nullptr),
              SQLITE_OK)
        << sqlite3_errmsg(db_);
  }
  ~LockHolder() {
    Release();
    sqlite3_close(db_);
  }
  void Release() {
    if (held_) {
      EXPECT_EQ(sqlite3_exec(db_, "COMMIT", nullptr, nullptr, nullptr), SQLITE_OK);
    }
    held_ = false;
  }

 private:
  sqlite3* db_ = nullptr;
  bool held_ = true;
};

// The lock is released when the store says it is waiting (no timing in the
// test): the transaction waits, then commits everything.
TEST_F(StoreAccessTest, ALockedStoreIsWaitedForWithAMessageAndTheWorkIsStored) {
  const std::string store = path("store.db").string();
  MakeStore(store);
  auto db = SqliteDatabase::Open(store);
  LockHolder other(store);
  LogCapture log([&](const std::string& message) {
    if (Contains(message, "locked by another program; waiting")) other.Release();
  });
  PatientRecord patient;
  patient.external_id = "finished work";
  db->WithTransaction([&] { db->AddPatient(patient); });
  EXPECT_TRUE(Contains(log.All(), store + ": the store is locked by another program; waiting up to 60 s"))
      << log.All();
  EXPECT_TRUE(db->FindPatient("finished work"));
  EXPECT_TRUE(db->FindPatient("other program"));
  EXPECT_TRUE(db->FindPatient("kept"));
}

// Held past the timeout and the retry: a clear message, nothing of the
// failed step written, nothing the store or the other program had lost, and
// the same step succeeds once the lock is gone.
TEST_F(StoreAccessTest, ALockHeldBeyondTheTimeoutIsAClearErrorAndLosesNothing) {
  const std::string store = path("store.db").string();
  MakeStore(store);
  SqliteOpenOptions impatient;
  impatient.busy_timeout_ms = 200;
  auto db = SqliteDatabase::Open(store, impatient);
  PatientRecord patient;
  patient.external_id = "finished work";
  {
    LockHolder other(store);
    LogCapture log;
    try {
      db->WithTransaction([&] { db->AddPatient(patient); });
      ADD_FAILURE() << "the locked store was written";
    } catch (const StoreAccessError& e) {
      const std::string message = e.what();
      EXPECT_TRUE(Contains(message, store + ": database is locked by another program")) << message;
      EXPECT_TRUE(Contains(message, "nothing of this step was written")) << message;
      EXPECT_TRUE(Contains(message, "Waited 0.4 s")) << message;
      ExpectNoInternals(message);
    }
    EXPECT_TRUE(Contains(log.All(), "still locked by another program; trying once more")) << log.All();
  }
  EXPECT_FALSE(db->FindPatient("finished work"));
  EXPECT_TRUE(db->FindPatient("other program"));
  EXPECT_TRUE(db->FindPatient("kept"));
  db->WithTransaction([&] { db->AddPatient(patient); });
  EXPECT_TRUE(db->FindPatient("finished work"));
}

}  // namespace
}  // namespace arpos
