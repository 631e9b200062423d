#pragma once
/// Schema migrations of the session store.
///
/// The schema lives in schema/NNNN_*.sql (embedded at build time, see
/// schema/schema_migrations.h). A store's version is its `PRAGMA user_version`:
/// 0 for a new, empty file; N after migration NNNN. Each pending migration runs
/// in ONE transaction together with the bump of user_version, so a crash or an
/// error leaves the store at the previous version, never half-way. Foreign-key
/// enforcement is off while migrating (so a migration may rebuild a table, as
/// SQLite's ALTER TABLE procedure requires) and `PRAGMA foreign_key_check`
/// must pass before each migration commits.
///
/// Thread-safety: operate on one connection; concurrent migrations of the same
/// file from several connections are safe (each step re-reads the version
/// after taking the write lock).

#include <string>

struct sqlite3;

namespace arpos {

/// The newest schema version this program knows (the number of migrations).
int LatestSchemaVersion();

/// The connection's `PRAGMA user_version`.
int ReadSchemaVersion(sqlite3* db);

/// Checks, without writing anything, that this program may open the store:
/// throws arpos::InputError naming `path` and both versions if the store's
/// version is newer than LatestSchemaVersion(), or if the file is an SQLite
/// database that is not an ARPos store (foreign application_id, or tables but
/// no version).
void CheckStoreCompatible(sqlite3* db, const std::string& path);

/// Applies the migrations after the store's version up to `target_version`
/// (LatestSchemaVersion() if negative). Returns the number applied. Throws
/// arpos::Error naming `path`, the migration file and SQLite's message if one
/// fails (that migration is rolled back; earlier ones stay applied), and
/// arpos::InputError if the store is newer than `target_version`.
int MigrateSchema(sqlite3* db, const std::string& path, int target_version = -1);

}  // namespace arpos
