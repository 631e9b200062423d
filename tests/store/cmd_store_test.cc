// `arpos store ...` and the default store path.

#include <gtest/gtest.h>
#include <sqlite3.h>

#include <cstdlib>
#include <filesystem>
#include <sstream>

#include "exe/cmd_store.h"
#include "store/migrator.h"
#include "store/sqlite_database.h"
#include "store/store_path.h"
#include "store_test_util.h"
#include "util/file.h"

namespace arpos {
namespace {

namespace fs = std::filesystem;

struct CommandResult {
  int status = -1;
  std::string out;
  std::string err;
};

CommandResult RunStore(const std::vector<std::string>& args) {
  std::ostringstream out, err;
  CommandResult result;
  result.status = RunStoreCommandWithOutput(args, out, err);
  result.out = out.str();
  result.err = err.str();
  return result;
}

bool Contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// Sets or unsets ARPOS_STORE for a scope, restoring the previous value.
class ScopedStoreEnv {
 public:
  explicit ScopedStoreEnv(const char* value) {
    const char* previous = std::getenv("ARPOS_STORE");
    if (previous != nullptr) previous_ = previous;
    if (value != nullptr) {
      ::setenv("ARPOS_STORE", value, 1);
    } else {
      ::unsetenv("ARPOS_STORE");
    }
  }
  ~ScopedStoreEnv() {
    if (previous_) {
      ::setenv("ARPOS_STORE", previous_->c_str(), 1);
    } else {
      ::unsetenv("ARPOS_STORE");
    }
  }

 private:
  std::optional<std::string> previous_;
};

TEST(StorePath, EnvironmentElseWorkingDirectory) {
  {
    ScopedStoreEnv env(nullptr);
    EXPECT_EQ(DefaultStorePath(), "./arpos_store.db");
  }
  {
    ScopedStoreEnv env("");
    EXPECT_EQ(DefaultStorePath(), "./arpos_store.db");
  }
  {
    ScopedStoreEnv env("/srv/arpos/clinic.db");
    EXPECT_EQ(DefaultStorePath(), "/srv/arpos/clinic.db");
  }
}

TEST(StoreCommand, HelpAndUsageErrors) {
  const CommandResult help = RunStore({"--help"});
  EXPECT_EQ(help.status, 0);
  EXPECT_TRUE(Contains(help.out, "arpos store <command>"));
  EXPECT_TRUE(Contains(help.out, "info [--store DB]"));
  EXPECT_TRUE(Contains(help.out, "$ARPOS_STORE"));
  EXPECT_EQ(RunStore({"info", "--help"}).status, 0);

  EXPECT_EQ(RunStore({}).status, 2);
  const CommandResult unknown = RunStore({"vacuum"});
  EXPECT_EQ(unknown.status, 2);
  EXPECT_TRUE(Contains(unknown.err, "unknown command 'vacuum'"));
  EXPECT_EQ(RunStore({"info", "--store"}).status, 2);
  EXPECT_EQ(RunStore({"info", "--frobnicate"}).status, 2);
}

TEST(StoreCommand, InfoNeverCreatesAStore) {
  TempDir dir;
  const std::string path = (dir.path() / "absent.db").string();
  const CommandResult result = RunStore({"info", "--store", path});
  EXPECT_EQ(result.status, 2);
  EXPECT_TRUE(Contains(result.err, "no store at " + path)) << result.err;
  EXPECT_TRUE(result.out.empty());
  EXPECT_FALSE(fs::exists(path));
  EXPECT_TRUE(fs::is_empty(dir.path()));
}

TEST(StoreCommand, InfoSummarisesTheStore) {
  TempDir dir;
  const std::string path = (dir.path() / "clinic.db").string();
  test::FullStore s;
  {
    auto db = SqliteDatabase::Open(path);
    s = test::WriteFullStore(*db, 21);
  }
  for (const std::vector<std::string>& args :
       {std::vector<std::string>{"info", "--store", path},
        std::vector<std::string>{"info", "--store=" + path}}) {
    const CommandResult result = RunStore(args);
    EXPECT_EQ(result.status, 0) << result.err;
    for (const std::string& part :
         {path, "Schema version: " + std::to_string(LatestSchemaVersion()) + " (current)",
          std::string("Journal mode:   wal"), std::string("tracking_frames"),
          "'" + s.plan.name + "'", s.patient.external_id}) {
      EXPECT_TRUE(Contains(result.out, part)) << "'" << part << "' not in:\n" << result.out;
    }
  }
  // Without --store, $ARPOS_STORE decides.
  ScopedStoreEnv env(path.c_str());
  const CommandResult from_env = RunStore({"info"});
  EXPECT_EQ(from_env.status, 0) << from_env.err;
  EXPECT_TRUE(Contains(from_env.out, "Store:          " + path));
}

TEST(StoreCommand, InfoRefusesANewerStoreAndMigratesAnOlderOne) {
  TempDir dir;
  const std::string newer = (dir.path() / "newer.db").string();
  const std::string older = (dir.path() / "older.db").string();
  for (const auto& [path, version] : {std::pair<std::string, int>{newer, LatestSchemaVersion() + 1},
                                      std::pair<std::string, int>{older, 1}}) {
    sqlite3* raw = nullptr;
    ASSERT_EQ(sqlite3_open(path.c_str(), &raw), SQLITE_OK);
    MigrateSchema(raw, path, std::min(version, LatestSchemaVersion()));
    ASSERT_EQ(sqlite3_exec(raw, ("PRAGMA user_version = " + std::to_string(version)).c_str(),
                           nullptr, nullptr, nullptr),
              SQLITE_OK);
    sqlite3_close(raw);
  }

  const std::string before = test::FileBytes(newer);
  const CommandResult refused = RunStore({"info", "--store", newer});
  EXPECT_EQ(refused.status, 2);
  EXPECT_TRUE(Contains(refused.err, newer));
  EXPECT_TRUE(Contains(refused.err, "schema version " + std::to_string(LatestSchemaVersion() + 1)))
      << refused.err;
  EXPECT_EQ(test::FileBytes(newer), before);

  const CommandResult migrated = RunStore({"info", "--store", older});
  EXPECT_EQ(migrated.status, 0) << migrated.err;
  EXPECT_TRUE(Contains(migrated.out, "Schema version: " + std::to_string(LatestSchemaVersion())));
}

}  // namespace
}  // namespace arpos
