#pragma once
/// Thin RAII layer over the SQLite C API, used by the store implementation.
///
/// Every sqlite3 call that returns a result code goes through
/// ARPOS_SQLITE_CHECK, which throws StoreError naming the database file, the
/// SQL statement and SQLite's message (StoreAccessError, without the SQL, for
/// problems of the file: locked, read-only, ...). Statements are prepared once and reused;
/// a SqliteStatementGuard resets a statement (and clears its bindings) when
/// the scope that used it ends, even by exception, so no statement keeps a read
/// transaction open. SqliteTransaction is a scoped transaction that rolls back
/// unless committed.
///
/// Thread-safety: none of these objects may be used from two threads at once;
/// they belong to the connection that created them.

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "store/blob_codec.h"
#include "store/database.h"

struct sqlite3;
struct sqlite3_stmt;

namespace arpos {
/// For an SQLite result code that is a problem of the store file or its
/// folder (locked, read-only, not a database, damaged, disk full, ...), the
/// message of a StoreAccessError about `store`: what is wrong, the words of
/// `source` (SQLite, or the file system for checks made before SQLite opens
/// the file), what to do. Empty for other codes (program errors).
std::string StoreAccessProblem(int extended_code, const std::string& store,
                               const std::string& message, const std::string& source = "SQLite");

namespace internal {
/// Throws StoreAccessError for problems of the file (StoreAccessProblem),
/// else StoreError for result code `rc` of a call on `db` (may be null).
[[noreturn]] void ThrowSqliteError(sqlite3* db, int rc, std::string_view sql, const char* file,
                                   int line);
/// True for SQLITE_OK, SQLITE_ROW and SQLITE_DONE.
bool IsSqliteSuccess(int rc);
}  // namespace internal
}  // namespace arpos

/// ARPOS_SQLITE_CHECK(db, sqlite3_xxx(...), sql): throws StoreError unless the
/// call returns SQLITE_OK, SQLITE_ROW or SQLITE_DONE. Evaluates to nothing.
#define ARPOS_SQLITE_CHECK(db, call, sql)                                                     \
  do {                                                                                        \
    const int arpos_sqlite_rc_ = (call);                                                      \
    if (!::arpos::internal::IsSqliteSuccess(arpos_sqlite_rc_)) {                              \
      ::arpos::internal::ThrowSqliteError((db), arpos_sqlite_rc_, (sql), __FILE__, __LINE__); \
    }                                                                                         \
  } while (false)

namespace arpos {

/// A prepared statement, prepared once (SQLITE_PREPARE_PERSISTENT) and reused.
/// Bind indices are 1-based, column indices 0-based, as in SQLite. Use it only
/// inside a SqliteStatementGuard.
class SqliteStatement {
 public:
  SqliteStatement(sqlite3* db, std::string sql);
  ~SqliteStatement();
  SqliteStatement(const SqliteStatement&) = delete;
  SqliteStatement& operator=(const SqliteStatement&) = delete;

  const std::string& sql() const { return sql_; }

  void BindInt64(int index, std::int64_t value);
  void BindDouble(int index, double value);
  void BindText(int index, std::string_view value);
  void BindBlob(int index, const Blob& value);
  void BindNull(int index);
  template <typename Id>
  void BindId(int index, Id id) {
    BindInt64(index, id.value());
  }
  template <typename Id>
  void BindOptionalId(int index, const std::optional<Id>& id) {
    if (id) {
      BindInt64(index, id->value());
    } else {
      BindNull(index);
    }
  }

  /// Runs one step: true if a row is available, false when done.
  bool Step();
  /// Runs a statement that returns no rows (INSERT, UPDATE, ...).
  void Execute();

  bool ColumnIsNull(int column) const;
  std::int64_t ColumnInt64(int column) const;
  double ColumnDouble(int column) const;
  std::string ColumnText(int column) const;
  Blob ColumnBlob(int column) const;

  /// Resets and clears bindings; never throws (errors were reported by Step).
  void Reset() noexcept;

 private:
  friend class SqliteStatementGuard;
  sqlite3* db_;
  sqlite3_stmt* stmt_ = nullptr;
  std::string sql_;
  bool in_use_ = false;
};

/// Marks a statement in use for a scope and resets it at scope exit. Throws
/// arpos::Error if the statement is already in use (a re-entrant call that
/// would otherwise silently clobber the outer iteration).
class SqliteStatementGuard {
 public:
  explicit SqliteStatementGuard(SqliteStatement& statement);
  ~SqliteStatementGuard();
  SqliteStatementGuard(const SqliteStatementGuard&) = delete;
  SqliteStatementGuard& operator=(const SqliteStatementGuard&) = delete;
  SqliteStatement* operator->() { return &statement_; }
  SqliteStatement& operator*() { return statement_; }

 private:
  SqliteStatement& statement_;
};

/// Scoped transaction. The outermost one is BEGIN IMMEDIATE (takes the write
/// lock up front, so it waits on the busy timeout instead of failing half-way
/// through); nested ones are savepoints. Rolls back in the destructor unless
/// Commit() succeeded. Taking the lock and committing wait for another
/// connection's lock: a wait past one second is logged as a warning ("the
/// store is locked by another program; waiting up to N s"), the whole busy
/// timeout is waited and then the step is tried once more for another busy
/// timeout; after that StoreAccessError ("database is locked by another
/// program") and nothing is written.
class SqliteTransaction {
 public:
  explicit SqliteTransaction(sqlite3* db);
  ~SqliteTransaction();
  SqliteTransaction(const SqliteTransaction&) = delete;
  SqliteTransaction& operator=(const SqliteTransaction&) = delete;
  void Commit();

 private:
  sqlite3* db_;
  bool nested_;
  bool done_ = false;
};

/// Runs one or more ';'-separated statements that return no rows we need.
void ExecSql(sqlite3* db, const std::string& sql);
/// First column of the first row of a one-off query; throws if no row.
std::int64_t QueryInt64(sqlite3* db, const std::string& sql);
std::string QueryText(sqlite3* db, const std::string& sql);

/// The file name of the connection's main database, ":memory:" if none.
std::string DatabaseFileName(sqlite3* db);

}  // namespace arpos
