#pragma once
/// The audit log as a hash chain (schema version 6), and its verification.
///
/// Each entry carries entry_hash = SHA-256 over its id, time, actor, action,
/// entity, details and the previous entry's hash (prev_hash), each field
/// length-prefixed so that no two different entries serialise alike. An
/// entry changed, inserted or removed in the middle breaks the chain there;
/// entries removed from the end are found by SQLite's AUTOINCREMENT counter
/// (sqlite_sequence), which remembers the largest id ever given. Someone who
/// can rewrite the whole file can rewrite the whole chain: the chain makes
/// tampering evident to `arpos audit verify`, it does not prevent it (no
/// secret key; real authentication is out of scope, README).

#include <cstdint>
#include <string>
#include <vector>

#include "store/records.h"

struct sqlite3;

namespace arpos {

/// Hex SHA-256 of `entry` (its id and time as stored) chained to `prev_hash`.
/// `row_hash` (schema 8): the audited row's AuditedRowHash, covered by the
/// entry's hash when not empty.
std::string AuditEntryHash(const AuditEntry& entry, const std::string& prev_hash, const std::string& row_hash = "");

/// Hex SHA-256 of the row `entity` names ("plan:3", "tracking_run:7", ... of
/// the audited tables) with every column, and for a room map, body marker
/// map or tracking run its markers, poses or frames; "" if `entity` names
/// no audited row or the row does not exist.
std::string AuditedRowHash(sqlite3* db, const std::string& entity);

struct AuditVerification {
  int entries = 0;          ///< rows in audit_log
  int legacy_entries = 0;   ///< written before the chain (schema < 6): not verifiable
  int chained_entries = 0;  ///< verified links
  /// What does not match, first problem first; empty = the log verifies.
  std::vector<std::string> problems;
  /// The first entry whose link or content does not match (0: none).
  std::int64_t first_bad_entry = 0;
  bool ok() const { return problems.empty(); }
  std::string ToText() const;
};

/// Checks the chain, that the append-only triggers are in place as the
/// schema created them, that no entry was removed from the end, and that
/// every clinical row (patients, plans, room maps, sessions, body marker
/// maps, reconstructions, alignments, tracking runs) has the audit entry
/// that created it; from schema 7 also that the triggers locking approved
/// plans are there and every approved plan and ended session has the entry
/// that approved or ended it; from schema 8 that every row is as the newest
/// entry about it sealed it (row_hash). Reads only.
AuditVerification VerifyAuditLog(sqlite3* db);

}  // namespace arpos
