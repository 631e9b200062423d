#include "store/sqlite_util.h"

#include <sqlite3.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <sstream>

#include "util/logging.h"
#include "util/string_util.h"

namespace arpos {

std::string StoreAccessProblem(int code, const std::string& store, const std::string& message,
                               const std::string& source) {
  std::string folder = std::filesystem::path(store).parent_path().string();
  if (folder.empty()) folder = ".";
  const std::string said = " (" + source + ": \"" + message + "\")";
  switch (code & 0xff) {
    case SQLITE_BUSY:
    case SQLITE_LOCKED:
    case SQLITE_PROTOCOL:
      return store + ": database is locked by another program" + said +
             "; nothing of this step was written. Close the other program using the store (another "
             "arpos, a database browser) and run the command again.";
    case SQLITE_READONLY:
      if (code == SQLITE_READONLY_DIRECTORY || code == SQLITE_READONLY_CANTINIT ||
          code == SQLITE_READONLY_CANTLOCK) {
        return store + ": folder not writable: " + folder + said + "; the store keeps " + store +
               "-wal and " + store + "-shm beside it. Make the folder writable, or give --store a "
               "file in a writable folder.";
      }
      return store + ": read-only file" + said + "; make it writable (chmod u+w " + store +
             ") or give --store another file.";
    case SQLITE_CANTOPEN:
      return store + ": cannot open the store file or create its journal" + said +
             "; check that the folder " + folder + " exists and is writable.";
    case SQLITE_NOTADB:
      return store + ": not an ARPos store / not a SQLite database" + said +
             "; give --store an ARPos store, or a new file name to start one.";
    case SQLITE_CORRUPT:
      return store + ": the store file is damaged" + said + "; restore it from a backup.";
    case SQLITE_FULL:
      return store + ": the disk is full" + said +
             "; nothing of this step was written. Free some space and run the command again.";
    case SQLITE_IOERR:
      return store + ": input/output error on the store" + said + "; check the disk and the file.";
    case SQLITE_PERM:
    case SQLITE_AUTH:
      return store + ": access to the store denied" + said + ".";
    default:
      return "";
  }
}

namespace internal {

bool IsSqliteSuccess(int rc) { return rc == SQLITE_OK || rc == SQLITE_ROW || rc == SQLITE_DONE; }

void ThrowSqliteError(sqlite3* db, int rc, std::string_view sql, const char* file, int line) {
  // The connection's message is the specific one ("CHECK constraint failed:
  // ..."); sqlite3_errstr(rc) is the fallback when there is no connection.
  const int code = db != nullptr ? sqlite3_extended_errcode(db) : rc;
  const char* message = db != nullptr ? sqlite3_errmsg(db) : sqlite3_errstr(rc);
  // Problems of the file are for the person running the program: no SQL, no
  // source line.
  const std::string access = StoreAccessProblem(
      code, db != nullptr ? DatabaseFileName(db) : std::string("(no database)"), message);
  if (!access.empty()) throw StoreAccessError(access, code);
  std::ostringstream out;
  out << (db != nullptr ? DatabaseFileName(db) : std::string("(no database)")) << ": SQLite error "
      << code << " (" << sqlite3_errstr(code) << "): " << message << " [in: " << sql << "] [at "
      << std::filesystem::path(file).filename().string() << ":" << line << "]";
  throw StoreError(out.str(), code);
}

}  // namespace internal

SqliteStatement::SqliteStatement(sqlite3* db, std::string sql) : db_(db), sql_(std::move(sql)) {
  ARPOS_SQLITE_CHECK(db_,
                     sqlite3_prepare_v3(db_, sql_.c_str(), static_cast<int>(sql_.size()) + 1,
                                        SQLITE_PREPARE_PERSISTENT, &stmt_, nullptr),
                     sql_);
  ARPOS_CHECK(stmt_ != nullptr, "empty SQL statement: '" << sql_ << "'");
}

SqliteStatement::~SqliteStatement() { sqlite3_finalize(stmt_); }

void SqliteStatement::BindInt64(int index, std::int64_t value) {
  ARPOS_SQLITE_CHECK(db_, sqlite3_bind_int64(stmt_, index, value), sql_);
}

void SqliteStatement::BindDouble(int index, double value) {
  ARPOS_SQLITE_CHECK(db_, sqlite3_bind_double(stmt_, index, value), sql_);
}

void SqliteStatement::BindText(int index, std::string_view value) {
  ARPOS_SQLITE_CHECK(
      db_,
      sqlite3_bind_text64(stmt_, index, value.data(), value.size(), SQLITE_TRANSIENT, SQLITE_UTF8),
      sql_);
}

void SqliteStatement::BindBlob(int index, const Blob& value) {
  // A zero-length blob is still a blob, not NULL: bind a valid pointer.
  static const std::uint8_t kEmpty = 0;
  ARPOS_SQLITE_CHECK(db_,
                     sqlite3_bind_blob64(stmt_, index, value.empty() ? &kEmpty : value.data(),
                                         value.size(), SQLITE_TRANSIENT),
                     sql_);
}

void SqliteStatement::BindNull(int index) {
  ARPOS_SQLITE_CHECK(db_, sqlite3_bind_null(stmt_, index), sql_);
}

bool SqliteStatement::Step() {
  const int rc = sqlite3_step(stmt_);
  ARPOS_SQLITE_CHECK(db_, rc, sql_);
  return rc == SQLITE_ROW;
}

void SqliteStatement::Execute() {
  const bool has_row = Step();
  ARPOS_CHECK(!has_row, "statement unexpectedly returned rows: " << sql_);
}

bool SqliteStatement::ColumnIsNull(int column) const {
  return sqlite3_column_type(stmt_, column) == SQLITE_NULL;
}

std::int64_t SqliteStatement::ColumnInt64(int column) const {
  return sqlite3_column_int64(stmt_, column);
}

double SqliteStatement::ColumnDouble(int column) const {
  return sqlite3_column_double(stmt_, column);
}

std::string SqliteStatement::ColumnText(int column) const {
  const unsigned char* text = sqlite3_column_text(stmt_, column);
  const int size = sqlite3_column_bytes(stmt_, column);
  return text != nullptr ? std::string(reinterpret_cast<const char*>(text), size) : std::string();
}

Blob SqliteStatement::ColumnBlob(int column) const {
  const auto* data = static_cast<const std::uint8_t*>(sqlite3_column_blob(stmt_, column));
  const int size = sqlite3_column_bytes(stmt_, column);
  return data != nullptr ? Blob(data, data + size) : Blob();
}

void SqliteStatement::Reset() noexcept {
  sqlite3_reset(stmt_);
  sqlite3_clear_bindings(stmt_);
}

SqliteStatementGuard::SqliteStatementGuard(SqliteStatement& statement) : statement_(statement) {
  ARPOS_CHECK(!statement_.in_use_, "prepared statement used re-entrantly: " << statement_.sql());
  statement_.in_use_ = true;
}

SqliteStatementGuard::~SqliteStatementGuard() {
  statement_.Reset();
  statement_.in_use_ = false;
}

namespace {

// Runs BEGIN IMMEDIATE or COMMIT, the two steps of a transaction that wait
// for another connection's write lock. A wait longer than a second is
// announced (a person may be waiting for the program), then the rest of the
// busy timeout is waited, then the step is tried once more for a whole busy
// timeout: a lock held for a while by another program is never a reason to
// drop the work about to be stored. A failed COMMIT leaves the transaction
// open, so retrying it is safe.
std::string Seconds(double s) { return StringPrintf(s < 10 ? "%.1f s" : "%.0f s", s); }

void ExecWaitingForLock(sqlite3* db, const char* sql) {
  const int total_ms = static_cast<int>(QueryInt64(db, "PRAGMA busy_timeout"));
  const int first_ms = std::min(total_ms, 1000);
  const int waits_ms[3] = {first_ms, total_ms - first_ms, total_ms};
  int rc = SQLITE_BUSY;
  double waited_s = 0;
  for (int attempt = 0; attempt < 3 && (rc & 0xff) == SQLITE_BUSY; ++attempt) {
    if (attempt > 0 && waits_ms[attempt] <= 0) continue;
    if (attempt == 1) {
      ARPOS_WARN(DatabaseFileName(db) << ": the store is locked by another program; waiting up to "
                                      << Seconds(total_ms / 1000.0) << " for it");
    } else if (attempt == 2) {
      ARPOS_WARN(DatabaseFileName(db) << ": the store is still locked by another program; trying once "
                                      << "more for " << Seconds(total_ms / 1000.0));
    }
    sqlite3_busy_timeout(db, waits_ms[attempt]);
    rc = sqlite3_exec(db, sql, nullptr, nullptr, nullptr);
    waited_s += waits_ms[attempt] / 1000.0;
  }
  sqlite3_busy_timeout(db, total_ms);
  if ((rc & 0xff) == SQLITE_BUSY) {
    const int code = sqlite3_extended_errcode(db);
    throw StoreAccessError(StoreAccessProblem(code, DatabaseFileName(db), sqlite3_errmsg(db)) +
                               " (Waited " + Seconds(waited_s) + " for it.)",
                           code);
  }
  ARPOS_SQLITE_CHECK(db, rc, sql);
}

}  // namespace

SqliteTransaction::SqliteTransaction(sqlite3* db)
    : db_(db), nested_(sqlite3_get_autocommit(db) == 0) {
  if (nested_) {
    ExecSql(db_, "SAVEPOINT arpos_nested");
  } else {
    ExecWaitingForLock(db_, "BEGIN IMMEDIATE");
  }
}

SqliteTransaction::~SqliteTransaction() {
  if (done_) return;
  // Errors are ignored: SQLite may already have rolled back by itself (disk
  // full, I/O error), and a destructor must not throw.
  if (nested_) {
    sqlite3_exec(db_, "ROLLBACK TO arpos_nested; RELEASE arpos_nested", nullptr, nullptr, nullptr);
  } else if (sqlite3_get_autocommit(db_) == 0) {
    sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
  }
}

void SqliteTransaction::Commit() {
  ARPOS_CHECK(!done_, "transaction committed twice");
  if (nested_) {
    ExecSql(db_, "RELEASE arpos_nested");
  } else {
    ExecWaitingForLock(db_, "COMMIT");
  }
  done_ = true;
}

void ExecSql(sqlite3* db, const std::string& sql) {
  char* message = nullptr;
  const int rc = sqlite3_exec(db, sql.c_str(), nullptr, nullptr, &message);
  sqlite3_free(message);  // the same text is available from sqlite3_errmsg
  ARPOS_SQLITE_CHECK(db, rc, sql);
}

std::int64_t QueryInt64(sqlite3* db, const std::string& sql) {
  SqliteStatement statement(db, sql);
  SqliteStatementGuard guard(statement);
  ARPOS_CHECK(statement.Step(), "query returned no row: " << sql);
  return statement.ColumnInt64(0);
}

std::string QueryText(sqlite3* db, const std::string& sql) {
  SqliteStatement statement(db, sql);
  SqliteStatementGuard guard(statement);
  ARPOS_CHECK(statement.Step(), "query returned no row: " << sql);
  return statement.ColumnText(0);
}

std::string DatabaseFileName(sqlite3* db) {
  const char* name = sqlite3_db_filename(db, "main");
  return (name == nullptr || name[0] == '\0') ? std::string(":memory:") : std::string(name);
}

}  // namespace arpos
