// SqliteDatabase: round trips of every record type, constraints, foreign keys,
// the append-only audit log, transactions and opening rules.

#include <gtest/gtest.h>
#include <sqlite3.h>

#include <chrono>
#include <fstream>
#include <set>

#include "store/blob_codec.h"
#include "store/describe.h"
#include "store/migrator.h"
#include "store/sqlite_database.h"
#include "store_test_util.h"
#include "util/file.h"

namespace arpos {
namespace {

// Runs SQL straight on the connection (bypassing the typed API) and returns
// SQLite's extended result code; `message` receives the error text.
int RawExec(SqliteDatabase& db, const std::string& sql, std::string* message = nullptr) {
  char* error = nullptr;
  sqlite3_exec(db.RawHandle(), sql.c_str(), nullptr, nullptr, &error);
  if (message != nullptr) *message = error != nullptr ? error : "";
  sqlite3_free(error);
  return sqlite3_extended_errcode(db.RawHandle());
}

std::int64_t RawCount(SqliteDatabase& db, const std::string& table) {
  return db.Info().RowCount(table);
}

// Expects StoreError with the given extended SQLite code.
template <typename Fn>
void ExpectStoreError(Fn&& fn, int sqlite_code, const std::string& message_part = "") {
  try {
    fn();
    ADD_FAILURE() << "no StoreError thrown";
  } catch (const StoreError& e) {
    EXPECT_EQ(e.sqlite_code(), sqlite_code) << e.what();
    EXPECT_NE(std::string(e.what()).find(message_part), std::string::npos) << e.what();
  }
}

std::int64_t NowMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

class StoreKindTest : public ::testing::TestWithParam<bool> {
 protected:
  bool in_file() const { return GetParam(); }
  std::string Path() const { return in_file() ? (dir_.path() / "store.db").string() : ":memory:"; }
  TempDir dir_{"arpos-store-test"};
};

TEST_P(StoreKindTest, EveryRecordTypeRoundTrips) {
  const std::string path = Path();
  test::FullStore written;
  {
    auto db = SqliteDatabase::Open(path);
    written = test::WriteFullStore(*db, 1);
    test::ExpectFullStoreEq(*db, written);
  }
  if (in_file()) {  // and again from disk, by a fresh connection
    auto db = SqliteDatabase::Open(path);
    test::ExpectFullStoreEq(*db, written);
  }
}

TEST_P(StoreKindTest, SeveralCasesKeepTheirOwnRows) {
  auto db = SqliteDatabase::Open(Path());
  const test::FullStore a = test::WriteFullStore(*db, 1);
  const test::FullStore b = test::WriteFullStore(*db, 2);
  EXPECT_NE(a.plan.id, b.plan.id);
  test::ExpectFullStoreEq(*db, a);
  test::ExpectFullStoreEq(*db, b);
  // A session lists its own body marker maps and reconstructions only.
  EXPECT_EQ(db->ListBodyMarkerMapIds(a.session.id), std::vector<BodyMarkerMapId>{a.body_marker_map.id});
  EXPECT_EQ(db->ListReconstructionIds(b.session.id), std::vector<ReconstructionId>{b.reconstruction.id});
  EXPECT_TRUE(db->ListReconstructionIds(SessionId(999)).empty());
  EXPECT_EQ(db->ListPlans().size(), 2u);
  EXPECT_EQ(db->ListPlans(a.patient.id).size(), 1u);
  EXPECT_EQ(db->ListPlans(a.patient.id)[0].id, a.plan.id);
}

INSTANTIATE_TEST_SUITE_P(MemoryAndFile, StoreKindTest, ::testing::Values(false, true),
                         [](const auto& info) { return info.param ? "File" : "Memory"; });

TEST(SqliteDatabase, FileStoresUseTheClinicalPragmas) {
  TempDir dir;
  SqliteOpenOptions options;
  options.busy_timeout_ms = 1234;
  auto db = SqliteDatabase::Open((dir.path() / "s.db").string(), options);
  sqlite3* raw = db->RawHandle();
  auto query = [&](const char* sql) {
    sqlite3_stmt* stmt = nullptr;
    EXPECT_EQ(sqlite3_prepare_v2(raw, sql, -1, &stmt, nullptr), SQLITE_OK);
    EXPECT_EQ(sqlite3_step(stmt), SQLITE_ROW);
    const std::string value = reinterpret_cast<const char*>(sqlite3_column_text(stmt, 0));
    sqlite3_finalize(stmt);
    return value;
  };
  EXPECT_EQ(query("PRAGMA foreign_keys"), "1");
  EXPECT_EQ(query("PRAGMA journal_mode"), "wal");
  EXPECT_EQ(query("PRAGMA synchronous"), "2");  // FULL
  EXPECT_EQ(query("PRAGMA busy_timeout"), "1234");
  EXPECT_EQ(query("PRAGMA user_version"), std::to_string(LatestSchemaVersion()));
  EXPECT_EQ(query("PRAGMA application_id"), "1095913551");
  EXPECT_EQ(db->Info().journal_mode, "wal");
}

TEST(SqliteDatabase, UnknownIdsGiveNothing) {
  auto db = SqliteDatabase::Open(":memory:");
  EXPECT_FALSE(db->GetPatient(PatientId(1)));
  EXPECT_FALSE(db->FindPatient("nobody"));
  EXPECT_FALSE(db->GetPlan(PlanId(1)));
  EXPECT_FALSE(db->GetRoomMap(RoomMapId(1)));
  EXPECT_FALSE(db->LatestRoomMap(PlanId(1)));
  EXPECT_FALSE(db->GetSession(SessionId(1)));
  EXPECT_FALSE(db->GetRecording(RecordingId(1)));
  EXPECT_FALSE(db->GetBodyMarkerMap(BodyMarkerMapId(1)));
  EXPECT_FALSE(db->GetReconstruction(ReconstructionId(1)));
  EXPECT_FALSE(db->GetAlignment(AlignmentId(1)));
  EXPECT_FALSE(db->GetTrackingRun(TrackingRunId(1)));
  EXPECT_TRUE(db->GetTrackingFrames(TrackingRunId(1)).empty());
  EXPECT_TRUE(db->ListPlans().empty());
  EXPECT_TRUE(db->ListSessions().empty());
  EXPECT_TRUE(db->ListAudit().empty());
}

TEST(SqliteDatabase, ZeroTimeMeansNow) {
  auto db = SqliteDatabase::Open(":memory:");
  const std::int64_t before = NowMs();
  PatientRecord patient;
  patient.external_id = "p";
  const PatientId id = db->AddPatient(patient);
  const std::int64_t after = NowMs();
  const std::int64_t created = db->GetPatient(id)->created_unix_ms;
  EXPECT_GE(created, before);
  EXPECT_LE(created, after);
  EXPECT_EQ(db->FindPatient("p")->id, id);
}

TEST(SqliteDatabase, ListsAreNewestFirstFilteredAndLimited) {
  auto db = SqliteDatabase::Open(":memory:");
  const test::FullStore s = test::WriteFullStore(*db, 5);
  PlanRecord plan = s.plan;
  std::vector<PlanId> plans;
  for (int i = 0; i < 4; ++i) {
    plan.name = "plan " + std::to_string(i);
    plan.created_unix_ms = s.plan.created_unix_ms + 1000 * (i + 1);
    plans.push_back(db->AddPlan(plan));
  }
  const std::vector<PlanSummary> latest = db->ListPlans(std::nullopt, 2);
  ASSERT_EQ(latest.size(), 2u);
  EXPECT_EQ(latest[0].id, plans[3]);
  EXPECT_EQ(latest[1].id, plans[2]);
  EXPECT_EQ(latest[0].patient_external_id, s.patient.external_id);
  EXPECT_EQ(db->ListPlans().size(), 5u);
  EXPECT_EQ(db->ListPlans().back().id, s.plan.id);
  EXPECT_EQ(db->ListPlans().back().num_sessions, 1);
  EXPECT_EQ(latest[0].num_sessions, 0);

  SessionRecord session = s.session;
  session.plan_id = plans[0];
  session.started_unix_ms = s.session.started_unix_ms + 10;
  const SessionId newer = db->AddSession(session);
  EXPECT_EQ(db->ListSessions().front().id, newer);
  EXPECT_EQ(db->ListSessions(std::nullopt, 1).size(), 1u);
  ASSERT_EQ(db->ListSessions(s.plan.id).size(), 1u);
  EXPECT_EQ(db->ListSessions(s.plan.id)[0].id, s.session.id);
}

TEST(SqliteDatabase, SessionsAreFinishedOnce) {
  auto db = SqliteDatabase::Open(":memory:");
  const test::FullStore s = test::WriteFullStore(*db, 6);
  EXPECT_EQ(db->GetSession(s.session.id)->status, SessionStatus::kOpen);
  EXPECT_THROW(db->FinishSession(s.session.id, SessionStatus::kOpen), Error);
  db->FinishSession(s.session.id, SessionStatus::kCompleted, s.session.started_unix_ms + 600000);
  const SessionRecord done = *db->GetSession(s.session.id);
  EXPECT_EQ(done.status, SessionStatus::kCompleted);
  EXPECT_EQ(done.ended_unix_ms, s.session.started_unix_ms + 600000);
  EXPECT_THROW(db->FinishSession(s.session.id, SessionStatus::kAborted), Error);
  EXPECT_EQ(db->GetSession(s.session.id)->status, SessionStatus::kCompleted);
  EXPECT_THROW(db->FinishSession(SessionId(999), SessionStatus::kAborted), Error);

  // The schema refuses an end before the start.
  SessionRecord bad = s.session;
  bad.status = SessionStatus::kAborted;
  bad.ended_unix_ms = bad.started_unix_ms - 1;
  ExpectStoreError([&] { db->AddSession(bad); }, SQLITE_CONSTRAINT_CHECK);
  bad.ended_unix_ms.reset();  // not open but no end time: refused before SQL
  EXPECT_THROW(db->AddSession(bad), Error);
}

TEST(SqliteDatabase, ForeignKeysAreEnforced) {
  auto db = SqliteDatabase::Open(":memory:");
  PlanRecord orphan_plan;
  orphan_plan.patient_id = PatientId(42);
  orphan_plan.name = "orphan";
  ExpectStoreError([&] { db->AddPlan(orphan_plan); }, SQLITE_CONSTRAINT_FOREIGNKEY,
                   "FOREIGN KEY constraint failed");
  EXPECT_EQ(RawCount(*db, "plans"), 0);

  const test::FullStore s = test::WriteFullStore(*db, 7);
  SessionRecord orphan_session = s.session;
  orphan_session.plan_id = PlanId(999);
  ExpectStoreError([&] { db->AddSession(orphan_session); }, SQLITE_CONSTRAINT_FOREIGNKEY);
  AlignmentRecord orphan_alignment = s.icp_alignment;
  orphan_alignment.reconstruction_id = ReconstructionId(999);
  ExpectStoreError([&] { db->AddAlignment(orphan_alignment); }, SQLITE_CONSTRAINT_FOREIGNKEY);
  orphan_alignment = s.icp_alignment;
  orphan_alignment.parent_alignment_id = AlignmentId(999);
  ExpectStoreError([&] { db->AddAlignment(orphan_alignment); }, SQLITE_CONSTRAINT_FOREIGNKEY);
  ExpectStoreError([&] { db->AppendTrackingFrames(TrackingRunId(999), s.frames); },
                   SQLITE_CONSTRAINT_FOREIGNKEY);

  // RESTRICT: clinical history is not deleted from under a plan or patient.
  // (SQLite implements RESTRICT with internal triggers, hence the extended
  // code SQLITE_CONSTRAINT_TRIGGER with the foreign-key message.)
  std::string message;
  EXPECT_EQ(RawExec(*db, "DELETE FROM patients", &message) & 0xff, SQLITE_CONSTRAINT);
  EXPECT_EQ(message, "FOREIGN KEY constraint failed");
  EXPECT_EQ(RawExec(*db, "DELETE FROM plans", &message) & 0xff, SQLITE_CONSTRAINT);
  EXPECT_EQ(message, "FOREIGN KEY constraint failed");
  EXPECT_EQ(RawCount(*db, "patients"), 1);
  EXPECT_EQ(RawCount(*db, "plans"), 1);

  // CASCADE: deleting a session removes its data products, nothing else.
  EXPECT_EQ(RawExec(*db, "DELETE FROM sessions", &message), SQLITE_OK) << message;
  for (const char* table : {"body_marker_maps", "body_marker_poses", "reconstructions",
                            "alignments", "tracking_runs", "tracking_frames"}) {
    EXPECT_EQ(RawCount(*db, table), 0) << table;
  }
  EXPECT_EQ(RawCount(*db, "recordings"), 1);  // the plan's room recording
  EXPECT_EQ(RawCount(*db, "room_maps"), 1);
  EXPECT_EQ(RawCount(*db, "room_map_markers"), 3);
  EXPECT_EQ(RawCount(*db, "audit_log"), 2);

  // SET NULL: a room map outlives the recording it was built from.
  EXPECT_EQ(RawExec(*db, "DELETE FROM recordings", &message), SQLITE_OK) << message;
  EXPECT_FALSE(db->GetRoomMap(s.room_map.id)->recording_id.has_value());
}

TEST(SqliteDatabase, SchemaChecksRefuseBadRows) {
  auto db = SqliteDatabase::Open(":memory:");
  const test::FullStore s = test::WriteFullStore(*db, 8);

  AlignmentRecord alignment = s.icp_alignment;
  alignment.fitness = 1.5;
  ExpectStoreError([&] { db->AddAlignment(alignment); }, SQLITE_CONSTRAINT_CHECK, "fitness");
  alignment = s.icp_alignment;
  alignment.rmse_m = -0.001;
  ExpectStoreError([&] { db->AddAlignment(alignment); }, SQLITE_CONSTRAINT_CHECK, "rmse_m");

  RecordingRecord recording = s.body_scan;
  recording.intrinsics.fx = 0;
  ExpectStoreError([&] { db->AddRecording(recording); }, SQLITE_CONSTRAINT_CHECK);
  recording = s.body_scan;
  recording.kind = RecordingKind::kRoom;  // a room recording must belong to a plan
  EXPECT_THROW(db->AddRecording(recording), Error);
  std::string message;
  EXPECT_EQ(RawExec(*db,
                    "INSERT INTO recordings (session_id, kind, path, frame_count, width, height, "
                    "fx, fy, cx, cy, depth_scale, created_unix_ms) "
                    "VALUES (1, 'room', 'x', 1, 1, 1, 1, 1, 0, 0, 1, 0)",
                    &message),
            SQLITE_CONSTRAINT_CHECK)
      << message;

  // Lost frames carry no pose, and only lost frames lack one.
  EXPECT_EQ(RawExec(*db,
                    "INSERT INTO tracking_frames (tracking_run_id, frame_index, timestamp_s, "
                    "status, room_from_model) VALUES (1, 100, 0, 'lost', x'00')"),
            SQLITE_CONSTRAINT_CHECK);
  EXPECT_EQ(RawExec(*db,
                    "INSERT INTO tracking_frames (tracking_run_id, frame_index, timestamp_s, "
                    "status) VALUES (1, 100, 0, 'in_tolerance')"),
            SQLITE_CONSTRAINT_CHECK);
  EXPECT_EQ(RawExec(*db,
                    "INSERT INTO tracking_frames (tracking_run_id, frame_index, timestamp_s, "
                    "status) VALUES (1, 100, 0, 'drifting')"),
            SQLITE_CONSTRAINT_CHECK);
  EXPECT_EQ(RawCount(*db, "tracking_frames"), 10);

  TrackingRunRecord run = s.tracking_run;
  run.tolerance_rotation_deg = 0;
  ExpectStoreError([&] { db->AddTrackingRun(run); }, SQLITE_CONSTRAINT_CHECK);
}

// What planning measures about the camera (schema version 4): kept verbatim
// when given, NULL (not '' or 0) when not, and never negative.
TEST(SqliteDatabase, RoomMapCameraColumnsAreOptional) {
  auto db = SqliteDatabase::Open(":memory:");
  const test::FullStore s = test::WriteFullStore(*db, 10);
  RoomMapRecord bare = s.room_map;
  bare.camera_response.clear();
  bare.depth_correction.clear();
  bare.room_frame_tilt_sigma_deg.reset();
  bare.room_frame_yaw_sigma_deg.reset();
  bare.room_frame_couch_sigma_mm.reset();
  const RoomMapId id = db->AddRoomMap(bare);
  const auto back = db->GetRoomMap(id);
  ASSERT_TRUE(back);
  EXPECT_EQ(back->camera_response, "");
  EXPECT_EQ(back->depth_correction, "");
  EXPECT_FALSE(back->room_frame_tilt_sigma_deg);
  EXPECT_FALSE(back->room_frame_yaw_sigma_deg);
  EXPECT_FALSE(back->room_frame_couch_sigma_mm);
  sqlite3_stmt* stmt = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(db->RawHandle(),
                               "SELECT camera_response IS NULL AND depth_correction IS NULL AND "
                               "room_frame_tilt_sigma_deg IS NULL AND room_frame_yaw_sigma_deg IS NULL AND "
                               "room_frame_couch_sigma_mm IS NULL FROM room_maps WHERE room_map_id = ?1",
                               -1, &stmt, nullptr),
            SQLITE_OK);
  sqlite3_bind_int64(stmt, 1, id.value());
  ASSERT_EQ(sqlite3_step(stmt), SQLITE_ROW);
  EXPECT_EQ(sqlite3_column_int(stmt, 0), 1);
  sqlite3_finalize(stmt);

  // Only the given sigma is kept; the others stay unknown.
  RoomMapRecord partial = bare;
  partial.room_frame_couch_sigma_mm = 0.4;
  const auto partial_back = db->GetRoomMap(db->AddRoomMap(partial));
  ASSERT_TRUE(partial_back);
  EXPECT_EQ(partial_back->room_frame_couch_sigma_mm, 0.4);
  EXPECT_FALSE(partial_back->room_frame_tilt_sigma_deg);

  RoomMapRecord negative = s.room_map;
  negative.room_frame_yaw_sigma_deg = -0.01;
  ExpectStoreError([&] { db->AddRoomMap(negative); }, SQLITE_CONSTRAINT_CHECK, "room_frame_yaw_sigma_deg");
  EXPECT_EQ(RawCount(*db, "room_maps"), 3);
}

TEST(SqliteDatabase, ChildRowsAreWrittenAllOrNothing) {
  auto db = SqliteDatabase::Open(":memory:");
  const test::FullStore s = test::WriteFullStore(*db, 9);

  RoomMapRecord room_map = s.room_map;
  room_map.markers.push_back(room_map.markers.front());  // duplicate marker id
  ExpectStoreError([&] { db->AddRoomMap(room_map); }, SQLITE_CONSTRAINT_PRIMARYKEY);
  room_map = s.room_map;
  room_map.markers.back().residual_px = -1;
  ExpectStoreError([&] { db->AddRoomMap(room_map); }, SQLITE_CONSTRAINT_CHECK);
  EXPECT_EQ(RawCount(*db, "room_maps"), 1);
  EXPECT_EQ(RawCount(*db, "room_map_markers"), 3);

  BodyMarkerMapRecord body_map = s.body_marker_map;
  body_map.markers.push_back(body_map.markers.front());
  EXPECT_THROW(db->AddBodyMarkerMap(body_map), StoreError);
  EXPECT_EQ(RawCount(*db, "body_marker_maps"), 1);
  EXPECT_EQ(RawCount(*db, "body_marker_poses"), 2);

  // A batch with one duplicate frame index leaves the run as it was.
  std::vector<TrackingFrameRecord> batch = {s.frames[1], s.frames[2]};
  batch[0].frame_index = 10;
  batch[1].frame_index = 3;  // exists
  ExpectStoreError([&] { db->AppendTrackingFrames(s.tracking_run.id, batch); },
                   SQLITE_CONSTRAINT_PRIMARYKEY);
  EXPECT_EQ(db->GetTrackingFrames(s.tracking_run.id).size(), 10u);
  // An inconsistent frame is refused before anything is written.
  batch = {s.frames[1]};
  batch[0].frame_index = 11;
  batch[0].status = TrackingFrameStatus::kLost;
  EXPECT_THROW(db->AppendTrackingFrames(s.tracking_run.id, batch), Error);
  batch[0].status = TrackingFrameStatus::kInTolerance;
  db->AppendTrackingFrames(s.tracking_run.id, batch);
  EXPECT_EQ(db->GetTrackingFrames(s.tracking_run.id).size(), 11u);
}

TEST(SqliteDatabase, AuditLogIsAppendOnly) {
  TempDir dir;
  const std::string path = (dir.path() / "audit.db").string();
  auto db = SqliteDatabase::Open(path);
  AuditEntry entry;
  entry.actor = "physicist:jones";
  entry.action = "approve_plan";
  entry.entity = "plan:1";
  entry.details = "checked target pose";
  const AuditId first = db->AppendAudit(entry);
  entry.action = "open_session";
  const AuditId second = db->AppendAudit(entry);
  EXPECT_LT(first, second);

  std::string message;
  EXPECT_EQ(RawExec(*db, "UPDATE audit_log SET actor = 'someone else'", &message),
            SQLITE_CONSTRAINT_TRIGGER);
  EXPECT_NE(message.find("append-only: UPDATE refused"), std::string::npos) << message;
  EXPECT_EQ(RawExec(*db, "DELETE FROM audit_log WHERE audit_id = 1", &message),
            SQLITE_CONSTRAINT_TRIGGER);
  EXPECT_NE(message.find("append-only: DELETE refused"), std::string::npos) << message;
  EXPECT_EQ(
      RawExec(*db, "INSERT OR REPLACE INTO audit_log VALUES (1, 0, 'x', 'y', '', '')", &message),
      SQLITE_CONSTRAINT_TRIGGER)
      << "REPLACE deletes the old row, which the trigger must refuse: " << message;

  // From another connection too: the rule is in the file, not in this program.
  {
    sqlite3* other = nullptr;
    ASSERT_EQ(sqlite3_open(path.c_str(), &other), SQLITE_OK);
    EXPECT_NE(sqlite3_exec(other, "DELETE FROM audit_log", nullptr, nullptr, nullptr), SQLITE_OK);
    sqlite3_close(other);
  }

  const std::vector<AuditEntry> all = db->ListAudit();
  ASSERT_EQ(all.size(), 2u);
  EXPECT_EQ(all[0].actor, "physicist:jones");
  EXPECT_EQ(all[0].action, "approve_plan");
  EXPECT_EQ(all[1].action, "open_session");
  ASSERT_EQ(db->ListAudit(first).size(), 1u);
  EXPECT_EQ(db->ListAudit(first)[0].id, second);
  EXPECT_EQ(db->ListAudit(AuditId(), 1).size(), 1u);

  entry.actor = "";
  EXPECT_THROW(db->AppendAudit(entry), Error);
}

TEST(SqliteDatabase, WithTransactionCommitsTogetherOrNotAtAll) {
  auto db = SqliteDatabase::Open(":memory:");
  PatientRecord patient;
  patient.external_id = "rolled-back";
  EXPECT_THROW(db->WithTransaction([&] {
    db->AddPatient(patient);
    throw std::runtime_error("operator cancelled");
  }),
               std::runtime_error);
  EXPECT_FALSE(db->FindPatient("rolled-back"));

  db->WithTransaction([&] {
    patient.external_id = "outer";
    db->AddPatient(patient);
    try {
      db->WithTransaction([&] {
        patient.external_id = "inner";
        db->AddPatient(patient);
        throw std::runtime_error("inner fails");
      });
    } catch (const std::runtime_error&) {
    }
    patient.external_id = "outer-2";
    db->AddPatient(patient);
  });
  EXPECT_TRUE(db->FindPatient("outer"));
  EXPECT_FALSE(db->FindPatient("inner"));
  EXPECT_TRUE(db->FindPatient("outer-2"));
}

TEST(SqliteDatabase, StatementsAreReusableAfterAnError) {
  auto db = SqliteDatabase::Open(":memory:");
  PatientRecord patient;
  patient.external_id = "same";
  const PatientId first = db->AddPatient(patient);
  ExpectStoreError([&] { db->AddPatient(patient); }, SQLITE_CONSTRAINT_UNIQUE, "[in: INSERT");
  patient.external_id = "other";
  const PatientId second = db->AddPatient(patient);
  EXPECT_NE(first, second);
  EXPECT_EQ(db->GetPatient(second)->external_id, "other");
  EXPECT_EQ(db->GetPatient(first)->external_id, "same");
}

TEST(SqliteDatabase, CorruptBlobsInTheFileAreReportedWithTheRow) {
  auto db = SqliteDatabase::Open(":memory:");
  const test::FullStore s = test::WriteFullStore(*db, 10);
  ASSERT_EQ(RawExec(*db, "UPDATE plans SET room_from_model_target = x'41525042'"), SQLITE_OK);
  try {
    db->GetPlan(s.plan.id);
    ADD_FAILURE() << "no throw";
  } catch (const CorruptBlobError& e) {
    EXPECT_NE(std::string(e.what()).find("plans.room_from_model_target of plan " +
                                         std::to_string(s.plan.id.value())),
              std::string::npos)
        << e.what();
  }
  // Blob and row disagree about the number of points.
  ASSERT_EQ(RawExec(*db, "UPDATE reconstructions SET num_points = num_points + 1"), SQLITE_OK);
  EXPECT_THROW(db->GetReconstruction(s.reconstruction.id), CorruptBlobError);
}

TEST(SqliteDatabase, InfoAndDescriptionCountEveryTable) {
  TempDir dir;
  const std::string path = (dir.path() / "info.db").string();
  auto db = SqliteDatabase::Open(path);
  const test::FullStore s = test::WriteFullStore(*db, 11);
  const StoreInfo info = db->Info();
  EXPECT_EQ(info.path, path);
  EXPECT_EQ(info.schema_version, LatestSchemaVersion());
  EXPECT_EQ(info.program_schema_version, LatestSchemaVersion());
  EXPECT_GT(info.size_bytes, 0);
  std::set<std::string> tables;
  for (const auto& [table, count] : info.table_row_counts) tables.insert(table);
  const std::set<std::string> expected = {
      "alignments", "audit_log",       "body_marker_maps", "body_marker_poses", "patients",
      "plans",      "reconstructions", "recordings",       "room_maps",         "room_map_markers",
      "sessions",   "tracking_frames", "tracking_runs"};
  EXPECT_EQ(tables, expected);
  EXPECT_EQ(info.RowCount("patients"), 1);
  EXPECT_EQ(info.RowCount("alignments"), 2);
  EXPECT_EQ(info.RowCount("tracking_frames"), 10);
  EXPECT_EQ(info.RowCount("audit_log"), 2);
  EXPECT_EQ(info.RowCount("no_such_table"), -1);

  const std::string text = DescribeStore(*db);
  for (const std::string& part :
       {std::string("Store:          ") + path,
        "Schema version: " + std::to_string(LatestSchemaVersion()) + " (current)",
        std::string("tracking_frames"), "'" + s.plan.name + "'", s.patient.external_id,
        "session " + std::to_string(s.session.id.value()), std::string("2023-11-14 22:13:21 UTC"),
        std::string("operator RTT Smith")}) {
    EXPECT_NE(text.find(part), std::string::npos) << "'" << part << "' not in:\n" << text;
  }
  EXPECT_EQ(FormatUtcTime(0), "1970-01-01 00:00:00 UTC");
  EXPECT_EQ(FormatUtcTime(-1), "1969-12-31 23:59:59 UTC");
}

TEST(SqliteDatabase, OpeningRefusesWhatIsNotAStore) {
  TempDir dir;
  const std::string missing = (dir.path() / "missing.db").string();
  SqliteOpenOptions no_create;
  no_create.create_if_missing = false;
  try {
    SqliteDatabase::Open(missing, no_create);
    ADD_FAILURE() << "no throw";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), "no store at " + missing);
  }
  EXPECT_FALSE(std::filesystem::exists(missing));

  EXPECT_THROW(SqliteDatabase::Open(dir.path().string()), InputError);

  const std::string text = (dir.path() / "notes.txt").string();
  { std::ofstream(text) << "this is not a database, just some text that is long enough"; }
  EXPECT_THROW(SqliteDatabase::Open(text), Error);

  const std::string foreign = (dir.path() / "foreign.db").string();
  {
    sqlite3* raw = nullptr;
    ASSERT_EQ(sqlite3_open(foreign.c_str(), &raw), SQLITE_OK);
    ASSERT_EQ(sqlite3_exec(raw, "CREATE TABLE t (x)", nullptr, nullptr, nullptr), SQLITE_OK);
    sqlite3_close(raw);
  }
  const std::string before = test::FileBytes(foreign);
  try {
    SqliteDatabase::Open(foreign);
    ADD_FAILURE() << "no throw";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("not an ARPos store"), std::string::npos) << e.what();
  }
  EXPECT_EQ(test::FileBytes(foreign), before);
}

TEST(SqliteDatabase, ConnectionsShareAFileAndWritersWaitForTheLock) {
  TempDir dir;
  const std::string path = (dir.path() / "shared.db").string();
  auto writer = SqliteDatabase::Open(path);
  SqliteOpenOptions impatient;
  impatient.busy_timeout_ms = 200;
  auto other = SqliteDatabase::Open(path, impatient);

  PatientRecord patient;
  patient.external_id = "from-writer";
  const PatientId id = writer->AddPatient(patient);
  EXPECT_EQ(other->GetPatient(id)->external_id, "from-writer");

  writer->WithTransaction([&] {
    patient.external_id = "pending";
    writer->AddPatient(patient);
    // WAL: the reader sees the last committed state, not the pending row.
    EXPECT_FALSE(other->FindPatient("pending"));
    const auto start = std::chrono::steady_clock::now();
    patient.external_id = "blocked";
    ExpectStoreError([&] { other->AddPatient(patient); }, SQLITE_BUSY);
    const double waited_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    EXPECT_GE(waited_ms, 150.0) << "the busy timeout was not honoured";
  });
  EXPECT_TRUE(other->FindPatient("pending"));
  EXPECT_FALSE(other->FindPatient("blocked"));
}

}  // namespace
}  // namespace arpos
