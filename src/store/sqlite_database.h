#pragma once
/// The SQLite implementation of the session store.
///
/// One file per store (or ":memory:" for tests). Every connection runs with
/// `foreign_keys=ON`, `synchronous=FULL` (a committed transaction survives a
/// power cut), a busy timeout, and, for files, `journal_mode=WAL` (readers do
/// not block the writer; a killed process leaves the last committed state).
/// Opening a store:
/// - newer schema than this program knows: refused with arpos::InputError
///   naming the file and both versions; the file is not changed;
/// - older schema: migrated (migrator.h), one transaction per migration;
/// - an SQLite file that is not an ARPos store: refused with InputError;
/// - a file that is not an SQLite database, a read-only or unreadable file, a
///   folder that is not writable: refused with StoreAccessError naming the
///   file or folder and what to do, before anything is written (a missing
///   folder: InputError).
///
/// Thread-safety: one SqliteDatabase per thread. Any number of connections,
/// in this or other processes, may open the same file; writers are serialised
/// by SQLite and wait up to the busy timeout.

#include <memory>
#include <string>
#include <unordered_map>

#include "store/audit_chain.h"
#include "store/database.h"

struct sqlite3;

namespace arpos {

class SqliteStatement;

struct SqliteOpenOptions {
  /// If false, a missing file is an InputError ("no store at PATH") instead of
  /// creating an empty store. Ignored for ":memory:".
  bool create_if_missing = true;
  /// How long a write waits for another connection's lock. A transaction
  /// (WithTransaction) says after a second that it is waiting, waits this
  /// long, then tries once more for as long (sqlite_util.h) before it fails
  /// with StoreAccessError: finished work is not dropped for a short lock.
  int busy_timeout_ms = 60000;

  bool Check() const { return busy_timeout_ms >= 0; }
};

class SqliteDatabase final : public Database {
 public:
  /// Opens (creating or migrating as needed) the store at `path`.
  static std::unique_ptr<SqliteDatabase> Open(const std::string& path,
                                              const SqliteOpenOptions& options = {});
  ~SqliteDatabase() override;
  SqliteDatabase(const SqliteDatabase&) = delete;
  SqliteDatabase& operator=(const SqliteDatabase&) = delete;

  const std::string& path() const { return path_; }
  /// The underlying connection, for tests and maintenance tools only: writes
  /// through it bypass the typed API's checks (not the schema's).
  sqlite3* RawHandle() { return db_; }

  StoreInfo Info() override;
  void WithTransaction(const std::function<void()>& body) override;

  PatientId AddPatient(const PatientRecord& patient) override;
  std::optional<PatientRecord> GetPatient(PatientId id) override;
  std::optional<PatientRecord> FindPatient(const std::string& external_id) override;

  PlanId AddPlan(const PlanRecord& plan) override;
  std::optional<PlanRecord> GetPlan(PlanId id) override;
  std::vector<PlanSummary> ListPlans(std::optional<PatientId> patient = std::nullopt,
                                     std::size_t limit = 0) override;

  void ApprovePlan(PlanId id, const std::string& by, const std::string& note,
                   std::int64_t approved_unix_ms = 0) override;
  RoomMapId AddRoomMap(const RoomMapRecord& room_map) override;
  std::optional<RoomMapRecord> GetRoomMap(RoomMapId id) override;
  std::optional<RoomMapId> LatestRoomMap(PlanId plan) override;

  SessionId AddSession(const SessionRecord& session) override;
  std::optional<SessionRecord> GetSession(SessionId id) override;
  std::vector<SessionRecord> ListSessions(std::optional<PlanId> plan = std::nullopt,
                                          std::size_t limit = 0) override;
  void FinishSession(SessionId id, SessionStatus status, std::int64_t ended_unix_ms = 0,
                     const std::string& ended_by = "", const std::string& reason = "") override;
  std::int64_t BeginSessionActivity(const SessionActivity& activity) override;
  void EndSessionActivity(std::int64_t activity_id) override;
  std::vector<SessionActivity> ListSessionActivities() override;

  RecordingId AddRecording(const RecordingRecord& recording) override;
  std::optional<RecordingRecord> GetRecording(RecordingId id) override;

  BodyMarkerMapId AddBodyMarkerMap(const BodyMarkerMapRecord& map) override;
  std::optional<BodyMarkerMapRecord> GetBodyMarkerMap(BodyMarkerMapId id) override;

  ReconstructionId AddReconstruction(const ReconstructionRecord& reconstruction) override;
  std::optional<ReconstructionRecord> GetReconstruction(ReconstructionId id) override;
  std::vector<BodyMarkerMapId> ListBodyMarkerMapIds(SessionId session) override;
  std::vector<ReconstructionId> ListReconstructionIds(SessionId session) override;

  AlignmentId AddAlignment(const AlignmentRecord& alignment) override;
  std::optional<AlignmentRecord> GetAlignment(AlignmentId id) override;
  std::vector<AlignmentRecord> ListAlignments(ReconstructionId reconstruction) override;

  TrackingRunId AddTrackingRun(const TrackingRunRecord& run) override;
  std::optional<TrackingRunRecord> GetTrackingRun(TrackingRunId id) override;
  std::vector<TrackingRunId> ListTrackingRunIds(SessionId session) override;
  void AppendTrackingFrames(TrackingRunId run,
                            const std::vector<TrackingFrameRecord>& frames) override;
  std::vector<TrackingFrameRecord> GetTrackingFrames(TrackingRunId run) override;

  AuditId AppendAudit(const AuditEntry& entry) override;
  std::vector<AuditEntry> ListAudit(AuditId after = AuditId(), std::size_t limit = 0) override;
  /// The audit log's hash chain, triggers and coverage (store/audit_chain.h).
  AuditVerification VerifyAudit();

 private:
  SqliteDatabase(sqlite3* db, std::string path);
  /// The statement for `sql`, prepared on first use and kept until close.
  SqliteStatement& Prepared(const char* sql);
  std::int64_t LastInsertRowId() const;

  sqlite3* db_;
  std::string path_;
  std::unordered_map<std::string, std::unique_ptr<SqliteStatement>> statements_;
};

}  // namespace arpos
