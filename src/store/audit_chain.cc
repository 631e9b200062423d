#include "store/audit_chain.h"

#include <openssl/evp.h>
#include <sqlite3.h>

#include <cctype>
#include <map>
#include <set>
#include <sstream>

#include "store/sqlite_util.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos {
namespace {

// Each field as "<length>:<bytes>\n": unambiguous whatever the text holds.
void AppendField(std::string* out, const std::string& field) {
  *out += std::to_string(field.size());
  *out += ':';
  *out += field;
  *out += '\n';
}

std::string Sha256Hex(const std::string& data) {
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int length = 0;
  ARPOS_CHECK(EVP_Digest(data.data(), data.size(), digest, &length, EVP_sha256(), nullptr) == 1,
              "SHA-256 failed");
  static const char* kHex = "0123456789abcdef";
  std::string hex;
  for (unsigned int i = 0; i < length; ++i) {
    hex += kHex[digest[i] >> 4];
    hex += kHex[digest[i] & 15];
  }
  return hex;
}

// Whitespace runs as one space, for comparing a trigger's SQL with the schema's.
std::string Normalised(const std::string& sql) {
  std::string out;
  bool space = false;
  for (char c : sql) {
    if (std::isspace(static_cast<unsigned char>(c))) {
      space = !out.empty();
      continue;
    }
    if (space) out += ' ';
    space = false;
    out += c;
  }
  return out;
}

// The append-only triggers exactly as schema/0001_initial.sql creates them.
const std::map<std::string, std::string>& ExpectedTriggers() {
  static const std::map<std::string, std::string> triggers = {
      {"audit_log_refuse_replace",
       "CREATE TRIGGER audit_log_refuse_replace BEFORE INSERT ON audit_log WHEN EXISTS (SELECT 1 FROM "
       "audit_log WHERE audit_id = NEW.audit_id) BEGIN SELECT RAISE(ABORT, 'audit_log is append-only: an "
       "existing entry cannot be replaced'); END"},
      {"audit_log_refuse_update",
       "CREATE TRIGGER audit_log_refuse_update BEFORE UPDATE ON audit_log BEGIN SELECT RAISE(ABORT, "
       "'audit_log is append-only: UPDATE refused'); END"},
      {"audit_log_refuse_delete",
       "CREATE TRIGGER audit_log_refuse_delete BEFORE DELETE ON audit_log BEGIN SELECT RAISE(ABORT, "
       "'audit_log is append-only: DELETE refused'); END"},
  };
  return triggers;
}

// Clinical tables, their id column, and the entity prefix of the audit entry
// that records each row's creation.
struct AuditedTable {
  const char* table;
  const char* id_column;
  const char* entity;
};
constexpr AuditedTable kAuditedTables[] = {
    {"patients", "patient_id", "patient"},
    {"plans", "plan_id", "plan"},
    {"room_maps", "room_map_id", "room_map"},
    {"sessions", "session_id", "session"},
    {"body_marker_maps", "body_marker_map_id", "body_marker_map"},
    {"reconstructions", "reconstruction_id", "reconstruction"},
    {"alignments", "alignment_id", "alignment"},
    {"tracking_runs", "tracking_run_id", "tracking_run"},
};

}  // namespace

std::string AuditEntryHash(const AuditEntry& entry, const std::string& prev_hash, const std::string& row_hash) {
  std::string data = "arpos-audit-1\n";
  AppendField(&data, std::to_string(entry.id.value()));
  AppendField(&data, std::to_string(entry.time_unix_ms));
  AppendField(&data, entry.actor);
  AppendField(&data, entry.action);
  AppendField(&data, entry.entity);
  AppendField(&data, entry.details);
  AppendField(&data, prev_hash);
  if (!row_hash.empty()) AppendField(&data, row_hash);  // schema 8; earlier entries hash as before
  return Sha256Hex(data);
}

namespace {

// Appends every column of every row `sql` (one id parameter) returns.
bool AppendRows(sqlite3* db, const std::string& sql, std::int64_t id, std::string* data) {
  sqlite3_stmt* statement = nullptr;
  if (sqlite3_prepare_v2(db, sql.c_str(), -1, &statement, nullptr) != SQLITE_OK) {
    sqlite3_finalize(statement);
    return false;
  }
  sqlite3_bind_int64(statement, 1, id);
  int rows = 0;
  while (sqlite3_step(statement) == SQLITE_ROW) {
    ++rows;
    const int n = sqlite3_column_count(statement);
    AppendField(data, "row " + std::to_string(n));
    for (int c = 0; c < n; ++c) {
      const int type = sqlite3_column_type(statement, c);
      std::string value = std::to_string(type) + ":";
      if (type == SQLITE_INTEGER) {
        value += std::to_string(sqlite3_column_int64(statement, c));
      } else if (type == SQLITE_FLOAT) {
        value += StringPrintf("%.17g", sqlite3_column_double(statement, c));
      } else if (type != SQLITE_NULL) {
        const void* bytes = sqlite3_column_blob(statement, c);
        const int size = sqlite3_column_bytes(statement, c);
        if (bytes != nullptr && size > 0) value.append(static_cast<const char*>(bytes), static_cast<size_t>(size));
      }
      AppendField(data, value);
    }
  }
  sqlite3_finalize(statement);
  return rows > 0;
}

}  // namespace

std::string AuditedRowHash(sqlite3* db, const std::string& entity) {
  const size_t colon = entity.find(':');
  if (colon == std::string::npos) return "";
  long long id = 0;
  if (!ParseInt(entity.substr(colon + 1), &id) || id <= 0) return "";
  const std::string kind = entity.substr(0, colon);
  for (const AuditedTable& t : kAuditedTables) {
    if (kind != t.entity) continue;
    std::string data = "arpos-row-1\n";
    AppendField(&data, t.table);
    if (!AppendRows(db, StringPrintf("SELECT * FROM %s WHERE %s = ?1", t.table, t.id_column), id, &data)) return "";
    if (kind == "room_map") {
      AppendRows(db, "SELECT * FROM room_map_markers WHERE room_map_id = ?1 ORDER BY marker_id", id, &data);
      // Schema 10; a map without a surface row hashes as before.
      AppendRows(db, "SELECT * FROM room_map_surface WHERE room_map_id = ?1", id, &data);
    } else if (kind == "body_marker_map") {
      AppendRows(db, "SELECT * FROM body_marker_poses WHERE body_marker_map_id = ?1 ORDER BY marker_id", id, &data);
      // Schema 9; a map without breathing rows hashes as before.
      AppendRows(db, "SELECT * FROM body_marker_motion WHERE body_marker_map_id = ?1 ORDER BY marker_id", id, &data);
      AppendRows(db, "SELECT * FROM body_surface_motion WHERE body_marker_map_id = ?1", id, &data);
      // Schema 11; a map without scan landmarks hashes as before.
      AppendRows(db, "SELECT * FROM body_scan_landmarks WHERE body_marker_map_id = ?1", id, &data);
      // Schema 12; a map without direction rows hashes as before.
      AppendRows(db,
                 "SELECT * FROM body_marker_motion_direction WHERE body_marker_map_id = ?1 ORDER "
                 "BY marker_id",
                 id, &data);
    } else if (kind == "tracking_run") {
      AppendRows(db, "SELECT * FROM tracking_frames WHERE tracking_run_id = ?1 ORDER BY frame_index", id, &data);
    }
    return Sha256Hex(data);
  }
  return "";
}

std::string AuditVerification::ToText() const {
  std::ostringstream out;
  out << StringPrintf("audit log: %d entries, %d verified in the hash chain", entries, chained_entries);
  if (legacy_entries > 0) {
    out << StringPrintf(", %d written before the chain existed (schema < 6; not verifiable)", legacy_entries);
  }
  out << "\n";
  if (problems.empty()) {
    out << "verified: the chain is intact, the append-only triggers are in place, no entry is missing "
           "at the end, and every plan, session, map, alignment and tracking run has its audit entry\n";
  } else {
    out << "NOT verified: " << problems.size() << " problem(s), the first first:\n";
    for (const std::string& p : problems) out << "  " << p << "\n";
  }
  return out.str();
}

AuditVerification VerifyAuditLog(sqlite3* db) {
  AuditVerification v;
  std::set<std::string> entities;
  std::set<std::string> entity_actions;  // "action entity"
  std::map<std::string, std::pair<long long, std::string>> last_row_hash;  // entity -> (entry id, row hash)
  bool has_row_hash = false;

  // The chain, in id order.
  {
    has_row_hash = QueryInt64(db, "SELECT COUNT(*) FROM pragma_table_info('audit_log') WHERE name = 'row_hash'") > 0;
    SqliteStatement s(db, std::string("SELECT audit_id, time_unix_ms, actor, action, entity, details, prev_hash, "
                                      "entry_hash, ") +
                              (has_row_hash ? "row_hash" : "''") + " FROM audit_log ORDER BY audit_id");
    std::string previous_hash;
    bool chain_started = false;
    while (s.Step()) {
      AuditEntry e;
      e.id = AuditId(s.ColumnInt64(0));
      e.time_unix_ms = s.ColumnInt64(1);
      e.actor = s.ColumnText(2);
      e.action = s.ColumnText(3);
      e.entity = s.ColumnText(4);
      e.details = s.ColumnText(5);
      const std::string prev_hash = s.ColumnText(6), entry_hash = s.ColumnText(7), row_hash = s.ColumnText(8);
      if (!row_hash.empty()) last_row_hash[e.entity] = {e.id.value(), row_hash};
      ++v.entries;
      entities.insert(e.entity);
      entity_actions.insert(e.action + " " + e.entity);
      const std::string where = StringPrintf("audit entry %lld (%s %s by %s)", static_cast<long long>(e.id.value()),
                                             e.action.c_str(), e.entity.c_str(), e.actor.c_str());
      if (entry_hash.empty() && prev_hash.empty() && !chain_started) {
        ++v.legacy_entries;  // before schema 6: a prefix of the log
        continue;
      }
      if (entry_hash.empty()) {
        v.problems.push_back(where + ": has no hash, but entries before it are chained (inserted outside the program)");
      } else if (prev_hash != previous_hash) {
        v.problems.push_back(where + ": its previous hash does not match the entry before it (an entry was "
                                     "removed, inserted or changed before it)");
      } else if (AuditEntryHash(e, prev_hash, row_hash) != entry_hash) {
        v.problems.push_back(where + ": its content does not match its hash (changed after it was written)");
      } else {
        ++v.chained_entries;
      }
      if (v.chained_entries + v.legacy_entries < v.entries && v.first_bad_entry == 0) {
        v.first_bad_entry = e.id.value();
      }
      chain_started = true;
      previous_hash = entry_hash;
    }
  }
  // Entries removed from the end: the AUTOINCREMENT counter remembers.
  {
    const std::int64_t max_id = QueryInt64(db, "SELECT COALESCE(MAX(audit_id), 0) FROM audit_log");
    const std::int64_t sequence =
        QueryInt64(db, "SELECT COALESCE((SELECT seq FROM sqlite_sequence WHERE name = 'audit_log'), 0)");
    if (sequence > max_id) {
      v.problems.push_back(StringPrintf("audit entries %lld-%lld were given out and are gone (removed from the end of the log)",
                                        static_cast<long long>(max_id + 1), static_cast<long long>(sequence)));
    }
  }
  // The append-only triggers, as the schema made them.
  {
    std::map<std::string, std::string> found;
    SqliteStatement s(db, "SELECT name, sql FROM sqlite_master WHERE type = 'trigger' AND tbl_name = 'audit_log'");
    while (s.Step()) found[s.ColumnText(0)] = Normalised(s.ColumnText(1));
    for (const auto& [name, sql] : ExpectedTriggers()) {
      auto it = found.find(name);
      if (it == found.end()) {
        v.problems.push_back("trigger " + name + " is missing: the audit log is no longer append-only");
      } else if (it->second != sql) {
        v.problems.push_back("trigger " + name + " differs from the schema's: " + it->second);
      }
    }
  }
  // The triggers that keep an approved plan as it was approved (schema 7).
  if (QueryInt64(db, "SELECT COUNT(*) FROM pragma_table_info('plans') WHERE name = 'approved_unix_ms'") > 0) {
    for (const char* name : {"plans_approved_are_locked", "plans_approval_only", "plans_approved_are_kept",
                             "room_maps_not_for_approved_plans"}) {
      if (QueryInt64(db, StringPrintf("SELECT COUNT(*) FROM sqlite_master WHERE type = 'trigger' AND name = '%s'",
                                      name)) == 0) {
        v.problems.push_back(std::string("trigger ") + name + " is missing: approved plans can be changed");
      }
    }
    // Approvals and session ends are made by audited controllers only.
    SqliteStatement approved(db, "SELECT plan_id FROM plans WHERE approved_unix_ms IS NOT NULL ORDER BY plan_id");
    while (approved.Step()) {
      const long long id = approved.ColumnInt64(0);
      if (!entity_actions.count(StringPrintf("approve_plan plan:%lld", id))) {
        v.problems.push_back(StringPrintf("plan %lld is marked approved but no approve_plan entry records it: "
                                          "approved outside the program",
                                          id));
      }
    }
    SqliteStatement ended(db, "SELECT session_id, status FROM sessions WHERE status <> 'open' ORDER BY session_id");
    while (ended.Step()) {
      const long long id = ended.ColumnInt64(0);
      const std::string status = ended.ColumnText(1);
      const std::string action = status == "completed" ? "complete_session" : "abort_session";
      if (!entity_actions.count(StringPrintf("%s session:%lld", action.c_str(), id))) {
        v.problems.push_back(StringPrintf("session %lld is marked %s but no %s entry records it: changed outside "
                                          "the program",
                                          id, status.c_str(), action.c_str()));
      }
    }
  }
  // Every row as the newest entry about it sealed it (schema 8).
  for (const auto& [entity, sealed] : last_row_hash) {
    const std::string now = AuditedRowHash(db, entity);
    if (now.empty()) {
      v.problems.push_back(StringPrintf("%s, sealed by audit entry %lld, is gone (removed outside the program)",
                                        entity.c_str(), sealed.first));
    } else if (now != sealed.second) {
      v.problems.push_back(StringPrintf("%s differs from what audit entry %lld sealed (changed outside the program)",
                                        entity.c_str(), sealed.first));
    }
  }
  // Every clinical row has the entry that created it.
  for (const AuditedTable& t : kAuditedTables) {
    SqliteStatement s(db, StringPrintf("SELECT %s FROM %s ORDER BY %s", t.id_column, t.table, t.id_column));
    std::vector<long long> missing;
    while (s.Step()) {
      const long long id = s.ColumnInt64(0);
      if (!entities.count(StringPrintf("%s:%lld", t.entity, id))) missing.push_back(id);
    }
    if (!missing.empty()) {
      std::string ids;
      for (size_t i = 0; i < missing.size() && i < 10; ++i) ids += (i ? ", " : "") + std::to_string(missing[i]);
      if (missing.size() > 10) ids += ", ...";
      v.problems.push_back(StringPrintf("%zu row(s) of %s have no audit entry (%s:<id> for id %s): written outside "
                                        "the program",
                                        missing.size(), t.table, t.entity, ids.c_str()));
    }
  }
  return v;
}

}  // namespace arpos
