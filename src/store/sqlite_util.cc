#include "store/sqlite_util.h"

#include <sqlite3.h>

#include <cstring>
#include <filesystem>
#include <sstream>

namespace arpos {
namespace internal {

bool IsSqliteSuccess(int rc) { return rc == SQLITE_OK || rc == SQLITE_ROW || rc == SQLITE_DONE; }

void ThrowSqliteError(sqlite3* db, int rc, std::string_view sql, const char* file, int line) {
  // The connection's message is the specific one ("CHECK constraint failed:
  // ..."); sqlite3_errstr(rc) is the fallback when there is no connection.
  const int code = db != nullptr ? sqlite3_extended_errcode(db) : rc;
  const char* message = db != nullptr ? sqlite3_errmsg(db) : sqlite3_errstr(rc);
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

SqliteTransaction::SqliteTransaction(sqlite3* db)
    : db_(db), nested_(sqlite3_get_autocommit(db) == 0) {
  ExecSql(db_, nested_ ? "SAVEPOINT arpos_nested" : "BEGIN IMMEDIATE");
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
  ExecSql(db_, nested_ ? "RELEASE arpos_nested" : "COMMIT");
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
