#pragma once
/// The session store: what the workflow persists, behind a small interface.
///
/// Planning writes patients, plans, room recordings and room maps; a session
/// writes its recordings, body marker map, reconstructions and alignments;
/// tracking writes runs and per-frame rows; everyone may append to the audit
/// log. The one implementation is SqliteDatabase (sqlite_database.h); tests
/// and tools may provide others.
///
/// Contract of every method:
/// - Add* inserts one record (with its children, e.g. a room map's markers)
///   atomically and returns the new id; the record's own `id` is ignored. A
///   created/started time of 0 is replaced by the current time.
/// - Get* returns std::nullopt if no row has that id.
/// - A record that breaks the schema's rules (unknown parent id, duplicate
///   marker, negative residual, lost frame with a pose, ...) is refused with
///   StoreError or arpos::Error and nothing is written.
/// - Store-level failures (disk full, file locked past the busy timeout, a
///   corrupt blob) throw arpos::Error subclasses; nothing aborts. Those of
///   the file itself (see StoreAccessError) say so in words a person can act
///   on, with no SQL and no source line.
///
/// Thread-safety: a Database object is not thread-safe; use one per thread.
/// Several Database objects (threads or processes) may open the same file.

#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "store/records.h"
#include "util/check.h"

namespace arpos {

/// An error reported by the database engine. sqlite_code() is SQLite's
/// extended result code (e.g. SQLITE_CONSTRAINT_FOREIGNKEY = 787), or 0 when
/// the error did not come from SQLite.
class StoreError : public Error {
 public:
  StoreError(const std::string& message, int sqlite_code)
      : Error(message), sqlite_code_(sqlite_code) {}
  int sqlite_code() const { return sqlite_code_; }

 private:
  int sqlite_code_;
};

/// A problem with the store file or its folder rather than with the program:
/// locked by another program past the busy timeout, read-only file, folder not
/// writable, not an SQLite database, damaged file, disk full, I/O error.
/// what() names the file or folder, quotes SQLite and says what to do; nothing
/// of the failed step was written. The command-line tools report it as a
/// store error (exit status 2), never as an internal error.
class StoreAccessError : public StoreError {
 public:
  using StoreError::StoreError;
};

/// A snapshot of a store for summaries (see describe.h).
struct StoreInfo {
  std::string path;                ///< file, or ":memory:"
  int schema_version = 0;          ///< PRAGMA user_version of the store
  int program_schema_version = 0;  ///< newest version this program knows
  std::string journal_mode;        ///< "wal" for file stores, "memory" in memory
  std::int64_t size_bytes = 0;     ///< page_count * page_size (excluding the WAL)
  /// Rows per table, every table of the store, by table name.
  std::vector<std::pair<std::string, std::int64_t>> table_row_counts;

  /// Rows in `table`, or -1 if the store has no such table.
  std::int64_t RowCount(const std::string& table) const;
};

class Database {
 public:
  virtual ~Database() = default;

  virtual StoreInfo Info() = 0;

  /// Runs `body` in one transaction: every Add*/Append* it makes commits
  /// together, or none does if `body` throws (the exception propagates).
  /// May be nested; an inner call commits with the outermost.
  virtual void WithTransaction(const std::function<void()>& body) = 0;

  // Planning ----------------------------------------------------------------
  virtual PatientId AddPatient(const PatientRecord& patient) = 0;
  virtual std::optional<PatientRecord> GetPatient(PatientId id) = 0;
  virtual std::optional<PatientRecord> FindPatient(const std::string& external_id) = 0;

  virtual PlanId AddPlan(const PlanRecord& plan) = 0;
  virtual std::optional<PlanRecord> GetPlan(PlanId id) = 0;
  /// Newest first (by created time, then id); all patients if `patient` is
  /// empty; at most `limit` entries, all if 0.
  virtual std::vector<PlanSummary> ListPlans(std::optional<PatientId> patient = std::nullopt,
                                             std::size_t limit = 0) = 0;

  /// Approves an unapproved plan: `by` ("name (role)"), `note`, at
  /// `approved_unix_ms` (0: now). Throws if the plan does not exist or is
  /// already approved. Role checks are the caller's (store/roles.h).
  virtual void ApprovePlan(PlanId id, const std::string& by, const std::string& note,
                           std::int64_t approved_unix_ms = 0) = 0;

  virtual RoomMapId AddRoomMap(const RoomMapRecord& room_map) = 0;
  virtual std::optional<RoomMapRecord> GetRoomMap(RoomMapId id) = 0;
  /// The most recently created room map of a plan.
  virtual std::optional<RoomMapId> LatestRoomMap(PlanId plan) = 0;

  // Session -----------------------------------------------------------------
  virtual SessionId AddSession(const SessionRecord& session) = 0;
  virtual std::optional<SessionRecord> GetSession(SessionId id) = 0;
  /// Newest first (by start time, then id); same filtering as ListPlans.
  virtual std::vector<SessionRecord> ListSessions(std::optional<PlanId> plan = std::nullopt,
                                                  std::size_t limit = 0) = 0;
  /// Moves an open session to kCompleted or kAborted at `ended_unix_ms` (0:
  /// now), by `ended_by` for `reason`. Throws if the session does not exist
  /// or is no longer open.
  virtual void FinishSession(SessionId id, SessionStatus status, std::int64_t ended_unix_ms = 0,
                             const std::string& ended_by = "", const std::string& reason = "") = 0;
  /// Commands at work on sessions (SessionActivity): Begin returns the row's
  /// id, End removes it (no error if it is gone), List gives all, oldest first.
  virtual std::int64_t BeginSessionActivity(const SessionActivity& activity) = 0;
  virtual void EndSessionActivity(std::int64_t activity_id) = 0;
  virtual std::vector<SessionActivity> ListSessionActivities() = 0;

  virtual RecordingId AddRecording(const RecordingRecord& recording) = 0;
  virtual std::optional<RecordingRecord> GetRecording(RecordingId id) = 0;

  virtual BodyMarkerMapId AddBodyMarkerMap(const BodyMarkerMapRecord& map) = 0;
  virtual std::optional<BodyMarkerMapRecord> GetBodyMarkerMap(BodyMarkerMapId id) = 0;

  virtual ReconstructionId AddReconstruction(const ReconstructionRecord& reconstruction) = 0;
  virtual std::optional<ReconstructionRecord> GetReconstruction(ReconstructionId id) = 0;
  /// Ids of a session's body marker maps and reconstructions, oldest first.
  virtual std::vector<BodyMarkerMapId> ListBodyMarkerMapIds(SessionId session) = 0;
  virtual std::vector<ReconstructionId> ListReconstructionIds(SessionId session) = 0;

  virtual AlignmentId AddAlignment(const AlignmentRecord& alignment) = 0;
  virtual std::optional<AlignmentRecord> GetAlignment(AlignmentId id) = 0;
  /// Alignments of a reconstruction, oldest first.
  virtual std::vector<AlignmentRecord> ListAlignments(ReconstructionId reconstruction) = 0;

  // Tracking ----------------------------------------------------------------
  virtual TrackingRunId AddTrackingRun(const TrackingRunRecord& run) = 0;
  virtual std::optional<TrackingRunRecord> GetTrackingRun(TrackingRunId id) = 0;
  /// Ids of a session's tracking runs, oldest first (by id).
  virtual std::vector<TrackingRunId> ListTrackingRunIds(SessionId session) = 0;
  /// Appends a batch of frames to a run in one transaction: all or none.
  /// Frame indices must be new within the run. Throws arpos::Error before
  /// writing anything if a frame breaks the rules of TrackingFrameRecord
  /// (pose, correction, uncertainty and source against its status; total_ms).
  virtual void AppendTrackingFrames(TrackingRunId run,
                                    const std::vector<TrackingFrameRecord>& frames) = 0;
  /// All frames of a run by frame index.
  virtual std::vector<TrackingFrameRecord> GetTrackingFrames(TrackingRunId run) = 0;

  // Audit -------------------------------------------------------------------
  /// Appends an entry (time 0: now). Entries can never be changed or removed.
  virtual AuditId AppendAudit(const AuditEntry& entry) = 0;
  /// Entries with id > `after`, oldest first, at most `limit` (0: all).
  virtual std::vector<AuditEntry> ListAudit(AuditId after = AuditId(), std::size_t limit = 0) = 0;
};

}  // namespace arpos
