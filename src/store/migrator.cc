#include "store/migrator.h"

#include <sqlite3.h>

#include <sstream>

#include "schema/schema_migrations.h"
#include "store/sqlite_util.h"
#include "util/logging.h"

namespace arpos {
namespace {

// 'ARPO', set by 0001_initial.sql.
constexpr std::int64_t kApplicationId = 0x4152504F;

// Restores foreign-key enforcement however the migration ends.
class ForeignKeysOff {
 public:
  explicit ForeignKeysOff(sqlite3* db)
      : db_(db), was_on_(QueryInt64(db, "PRAGMA foreign_keys") != 0) {
    ExecSql(db_, "PRAGMA foreign_keys = OFF");
  }
  ~ForeignKeysOff() {
    if (was_on_) sqlite3_exec(db_, "PRAGMA foreign_keys = ON", nullptr, nullptr, nullptr);
  }

 private:
  sqlite3* db_;
  bool was_on_;
};

// Rows whose references point nowhere before any migration (a store changed
// outside arpos with foreign keys off) are not the migration's fault, and
// are not migrated over: refused, before anything is written.
void RefuseDanglingReferences(sqlite3* db, const std::string& path, int version) {
  const std::int64_t dangling = QueryInt64(db, "SELECT COUNT(*) FROM pragma_foreign_key_check");
  if (dangling == 0) return;
  const std::string tables = QueryText(db,
                                       "SELECT group_concat(t, ', ') FROM (SELECT DISTINCT "
                                       "\"table\" AS t FROM pragma_foreign_key_check)");
  ARPOS_INPUT_ERROR(
      path
      << ": the store holds " << dangling << " row(s) whose references point to rows that are "
      << "not there (in " << tables
      << "), as when rows are deleted outside arpos with foreign keys off; it was not migrated "
         "from schema version "
      << version << " and nothing was changed: use a backup of the store, or a new one");
}

}  // namespace

int LatestSchemaVersion() { return static_cast<int>(SchemaMigrations().size()); }

int ReadSchemaVersion(sqlite3* db) {
  return static_cast<int>(QueryInt64(db, "PRAGMA user_version"));
}

void CheckStoreCompatible(sqlite3* db, const std::string& path) {
  const int version = ReadSchemaVersion(db);
  const std::int64_t application_id = QueryInt64(db, "PRAGMA application_id");
  const int latest = LatestSchemaVersion();
  if (version > latest) {
    ARPOS_INPUT_ERROR(path << ": the store has schema version " << version
                           << " but this program knows versions up to " << latest
                           << "; it was written by a newer ARPos. Refusing to open it (the "
                              "file was not changed); use a newer ARPos.");
  }
  if (application_id != kApplicationId && (application_id != 0 || version != 0)) {
    ARPOS_INPUT_ERROR(path << ": not an ARPos store (SQLite application_id " << application_id
                           << ", user_version " << version << ")");
  }
  if (version > 0 && version < latest) RefuseDanglingReferences(db, path, version);
  if (version == 0) {
    const std::int64_t num_objects = QueryInt64(db, "SELECT COUNT(*) FROM sqlite_master");
    if (num_objects > 0) {
      ARPOS_INPUT_ERROR(path << ": an SQLite database but not an ARPos store (it holds "
                             << num_objects << " schema objects and no schema version)");
    }
  }
}

int MigrateSchema(sqlite3* db, const std::string& path, int target_version) {
  const std::vector<SchemaMigration>& migrations = SchemaMigrations();
  const int latest = LatestSchemaVersion();
  if (target_version < 0) target_version = latest;
  ARPOS_CHECK(target_version <= latest, "cannot migrate to schema version "
                                            << target_version << ", the newest is " << latest);
  const int initial = ReadSchemaVersion(db);
  if (initial > target_version) {
    ARPOS_INPUT_ERROR(path << ": the store has schema version " << initial
                           << ", newer than the requested " << target_version);
  }
  if (initial == target_version) return 0;

  ForeignKeysOff foreign_keys_off(db);
  RefuseDanglingReferences(db, path, initial);
  int applied = 0;
  while (true) {
    SqliteTransaction transaction(db);
    // Re-read under the write lock: another connection may have migrated.
    const int version = ReadSchemaVersion(db);
    if (version >= target_version) break;
    const SchemaMigration& migration = migrations[version];
    ARPOS_CHECK(migration.version == version + 1,
                "embedded migrations out of order at " << migration.file_name);
    try {
      ExecSql(db, migration.sql);
      if (QueryInt64(db, "SELECT COUNT(*) FROM pragma_foreign_key_check") != 0) {
        throw Error("the migration leaves rows that violate foreign keys");
      }
      ExecSql(db, "PRAGMA user_version = " + std::to_string(migration.version));
      transaction.Commit();
    } catch (const StoreAccessError& e) {
      // A problem of the file (read-only, locked, disk full): say that, not
      // that the migration is broken.
      throw StoreAccessError(std::string(e.what()) + " (while migrating the store from schema version " +
                                 std::to_string(version) + " to " + std::to_string(migration.version) +
                                 "; rolled back)",
                             e.sqlite_code());
    } catch (const std::exception& e) {
      std::ostringstream out;
      out << path << ": migration " << migration.file_name << " (schema version " << version
          << " -> " << migration.version << ") failed and was rolled back; the store stays at "
          << "version " << version << ". " << e.what();
      throw Error(out.str());
    }
    ++applied;
  }
  if (applied > 0) {
    ARPOS_INFO(path << ": migrated the store from schema version " << initial << " to "
                    << ReadSchemaVersion(db));
  }
  return applied;
}

}  // namespace arpos
