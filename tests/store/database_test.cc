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
  EXPECT_EQ(db->ListTrackingRunIds(a.session.id), std::vector<TrackingRunId>{a.tracking_run.id});
  EXPECT_EQ(db->ListTrackingRunIds(b.session.id), std::vector<TrackingRunId>{b.tracking_run.id});
  EXPECT_TRUE(db->ListTrackingRunIds(SessionId(999)).empty());
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
                    "status, room_from_model, source) VALUES (1, 100, 0, 'lost', x'00', 'lost')"),
            SQLITE_CONSTRAINT_CHECK);
  EXPECT_EQ(RawExec(*db,
                    "INSERT INTO tracking_frames (tracking_run_id, frame_index, timestamp_s, "
                    "status, source) VALUES (1, 100, 0, 'in_tolerance', 'tracked')"),
            SQLITE_CONSTRAINT_CHECK);
  EXPECT_EQ(RawExec(*db,
                    "INSERT INTO tracking_frames (tracking_run_id, frame_index, timestamp_s, "
                    "status, source) VALUES (1, 100, 0, 'drifting', 'tracked')"),
            SQLITE_CONSTRAINT_CHECK);
  // Schema version 5: the source is one of three and 'lost' exactly when the
  // status is; the uncertainty comes in pairs, >= 0, never on a lost frame;
  // the time is >= 0; every frame says its source.
  const std::string lost_frame =
      "INSERT INTO tracking_frames (tracking_run_id, frame_index, timestamp_s, status, ";
  for (const std::string& columns_values :
       {std::string("source) VALUES (1, 100, 0, 'lost', 'tracked')"),
        std::string("source) VALUES (1, 100, 0, 'lost', 'guessed')"),
        std::string("source, uncertainty_translation_mm, uncertainty_rotation_deg) "
                    "VALUES (1, 100, 0, 'lost', 'lost', 1, 1)"),
        std::string("source, total_ms) VALUES (1, 100, 0, 'lost', 'lost', -1)")}) {
    EXPECT_EQ(RawExec(*db, lost_frame + columns_values, &message), SQLITE_CONSTRAINT_CHECK)
        << columns_values << ": " << message;
  }
  EXPECT_EQ(RawExec(*db, lost_frame + "room_from_model) VALUES (1, 100, 0, 'lost', NULL)"),
            SQLITE_CONSTRAINT_NOTNULL);
  const std::string posed_frame =
      "INSERT INTO tracking_frames (tracking_run_id, frame_index, timestamp_s, status, room_from_model, "
      "correction_tx_mm, correction_ty_mm, correction_tz_mm, correction_rx_deg, correction_ry_deg, "
      "correction_rz_deg, ";
  for (const std::string& columns_values :
       {std::string("source) VALUES (1, 100, 0, 'in_tolerance', x'00', 0, 0, 0, 0, 0, 0, 'lost')"),
        std::string("source, uncertainty_translation_mm) "
                    "VALUES (1, 100, 0, 'in_tolerance', x'00', 0, 0, 0, 0, 0, 0, 'tracked', 1)"),
        std::string("source, uncertainty_translation_mm, uncertainty_rotation_deg) "
                    "VALUES (1, 100, 0, 'in_tolerance', x'00', 0, 0, 0, 0, 0, 0, 'tracked', 1, -0.1)")}) {
    EXPECT_EQ(RawExec(*db, posed_frame + columns_values, &message), SQLITE_CONSTRAINT_CHECK)
        << columns_values << ": " << message;
  }
  // ...and the same row with a consistent source is taken.
  EXPECT_EQ(RawExec(*db,
                    posed_frame + "source, uncertainty_translation_mm, uncertainty_rotation_deg) VALUES "
                                  "(1, 100, 0, 'in_tolerance', x'00', 0, 0, 0, 0, 0, 0, 'carried', 1, 0.1)",
                    &message),
            SQLITE_OK)
      << message;
  EXPECT_EQ(RawCount(*db, "tracking_frames"), 11);

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

// What tracking produces per frame and per run (schema version 5), every
// field given and every optional one left out.
TEST(SqliteDatabase, TrackingFrameDetailRoundTrips) {
  auto db = SqliteDatabase::Open(":memory:");
  const test::FullStore s = test::WriteFullStore(*db, 11);
  std::mt19937 rng(5);

  TrackingRunRecord run = s.tracking_run;
  run.sequence_name = "couch_shift";
  run.summary = "3 frames: 1 tracked, 1 carried, 1 lost; 1 in, 1 out; 12.0 ms/frame (max 20.5)";
  const TrackingRunId run_id = db->AddTrackingRun(run);
  const auto run_back = db->GetTrackingRun(run_id);
  ASSERT_TRUE(run_back);
  EXPECT_EQ(run_back->sequence_name, "couch_shift");
  EXPECT_EQ(run_back->summary, run.summary);
  TrackingRunRecord bare_run = s.tracking_run;
  bare_run.sequence_name.clear();
  bare_run.summary.clear();
  const auto bare_run_back = db->GetTrackingRun(db->AddTrackingRun(bare_run));
  ASSERT_TRUE(bare_run_back);
  EXPECT_EQ(bare_run_back->sequence_name, "");
  EXPECT_EQ(bare_run_back->summary, "");

  std::vector<TrackingFrameRecord> frames(3);
  Correction6Dof correction;
  correction.translation_mm = Eigen::Vector3d(1.5, -2.0, 0.25);  // lateral, longitudinal, vertical
  correction.rotation_deg = Eigen::Vector3d(0.1, -0.3, 0.7);     // pitch, roll, yaw
  frames[0].frame_index = 0;
  frames[0].timestamp_s = 10.0;
  frames[0].status = TrackingFrameStatus::kInTolerance;
  frames[0].room_from_model = test::RandomPose(rng);
  frames[0].correction = correction;
  frames[0].room_from_camera = test::RandomPose(rng);
  frames[0].source = "tracked";
  frames[0].uncertainty_translation_mm = 0.75;
  frames[0].uncertainty_rotation_deg = 0.125;
  frames[0].total_ms = 20.5;
  frames[1] = frames[0];
  frames[1].frame_index = 1;
  frames[1].status = TrackingFrameStatus::kOutOfTolerance;
  frames[1].room_from_camera.reset();  // the store does not tie the camera pose to the status
  frames[1].source = "carried";
  frames[1].uncertainty_translation_mm = 3.5;
  frames[1].uncertainty_rotation_deg = 0.0;
  frames[1].total_ms = 0.0;
  frames[1].note = "depth registration rejected (fitness 0.2)";
  frames[2].frame_index = 2;
  frames[2].timestamp_s = 10.066;
  frames[2].status = TrackingFrameStatus::kLost;
  frames[2].source = "lost";
  frames[2].total_ms = 15.5;
  frames[2].note = "camera not localised: 2 room markers";
  db->AppendTrackingFrames(run_id, frames);

  const auto back = db->GetTrackingFrames(run_id);
  ASSERT_EQ(back.size(), 3u);
  for (std::size_t i = 0; i < 3; ++i) {
    const TrackingFrameRecord& e = frames[i];
    const TrackingFrameRecord& a = back[i];
    SCOPED_TRACE("frame " + std::to_string(i));
    EXPECT_EQ(a.status, e.status);
    ASSERT_EQ(a.room_from_camera.has_value(), e.room_from_camera.has_value());
    if (e.room_from_camera) test::ExpectPoseEq(*e.room_from_camera, *a.room_from_camera);
    EXPECT_EQ(a.source, e.source);
    EXPECT_EQ(a.uncertainty_translation_mm, e.uncertainty_translation_mm);
    EXPECT_EQ(a.uncertainty_rotation_deg, e.uncertainty_rotation_deg);
    EXPECT_EQ(a.total_ms, e.total_ms);
    EXPECT_EQ(a.note, e.note);
    ASSERT_EQ(a.correction.has_value(), e.correction.has_value());
    if (e.correction) {
      EXPECT_EQ(a.correction->translation_mm, e.correction->translation_mm);
      EXPECT_EQ(a.correction->rotation_deg, e.correction->rotation_deg);
    }
  }
  // Absent is NULL in the file, not a zero pose or a zero bound.
  sqlite3_stmt* stmt = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(db->RawHandle(),
                               "SELECT frame_index, room_from_camera IS NULL, uncertainty_translation_mm IS NULL, "
                               "uncertainty_rotation_deg IS NULL FROM tracking_frames WHERE tracking_run_id = ?1 "
                               "ORDER BY frame_index",
                               -1, &stmt, nullptr),
            SQLITE_OK);
  sqlite3_bind_int64(stmt, 1, run_id.value());
  std::string nulls;
  while (sqlite3_step(stmt) == SQLITE_ROW) {
    for (int c = 0; c < 4; ++c) nulls += std::to_string(sqlite3_column_int(stmt, c));
    nulls += ' ';
  }
  sqlite3_finalize(stmt);
  EXPECT_EQ(nulls, "0000 1100 2111 ");
}

// A frame can be lost with the camera localised (the patient was not found):
// the camera pose is kept, the patient pose, correction and bound are not.
TEST(SqliteDatabase, ALostFrameKeepsItsCameraPose) {
  auto db = SqliteDatabase::Open(":memory:");
  const test::FullStore s = test::WriteFullStore(*db, 12);
  std::mt19937 rng(6);
  TrackingFrameRecord frame;
  frame.frame_index = 20;
  frame.timestamp_s = 3.25;
  frame.status = TrackingFrameStatus::kLost;
  frame.source = "lost";
  frame.room_from_camera = test::RandomPose(rng);
  frame.total_ms = 9.75;
  frame.note = "patient not found: no body marker in view";
  db->AppendTrackingFrames(s.tracking_run.id, {frame});
  const auto frames = db->GetTrackingFrames(s.tracking_run.id);
  ASSERT_EQ(frames.size(), 11u);
  const TrackingFrameRecord& back = frames.back();
  EXPECT_EQ(back.frame_index, 20);
  EXPECT_EQ(back.status, TrackingFrameStatus::kLost);
  EXPECT_EQ(back.source, "lost");
  ASSERT_TRUE(back.room_from_camera);
  test::ExpectPoseEq(*frame.room_from_camera, *back.room_from_camera);
  EXPECT_FALSE(back.room_from_model);
  EXPECT_FALSE(back.correction);
  EXPECT_FALSE(back.uncertainty_translation_mm);
  EXPECT_FALSE(back.uncertainty_rotation_deg);
  EXPECT_EQ(back.total_ms, 9.75);
  EXPECT_EQ(back.note, frame.note);
}

// Expects AppendTrackingFrames to refuse `frame` with a message naming the
// frame and containing `part`, writing nothing.
void ExpectFrameRefused(SqliteDatabase& db, TrackingRunId run, const TrackingFrameRecord& frame,
                        const std::string& part) {
  const std::size_t before = db.GetTrackingFrames(run).size();
  try {
    db.AppendTrackingFrames(run, {frame});
    ADD_FAILURE() << "frame with source '" << frame.source << "' and status " << ToString(frame.status)
                  << " was taken";
  } catch (const StoreError& e) {
    ADD_FAILURE() << "refused by SQLite, not by the check before writing: " << e.what();
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("tracking frame " + std::to_string(frame.frame_index)), std::string::npos) << what;
    EXPECT_NE(what.find(part), std::string::npos) << "'" << part << "' not in: " << what;
  }
  EXPECT_EQ(db.GetTrackingFrames(run).size(), before);
}

TEST(SqliteDatabase, AFrameWhoseSourceContradictsItsStatusIsRefused) {
  auto db = SqliteDatabase::Open(":memory:");
  const test::FullStore s = test::WriteFullStore(*db, 13);
  TrackingFrameRecord posed = s.frames[0];  // tracked, in the FullStore
  ASSERT_EQ(posed.source, "tracked");
  posed.frame_index = 30;
  TrackingFrameRecord lost = s.frames[4];  // lost
  ASSERT_EQ(lost.status, TrackingFrameStatus::kLost);
  lost.frame_index = 31;

  TrackingFrameRecord frame = posed;
  frame.source = "lost";  // a pose and a verdict, yet "lost"
  ExpectFrameRefused(*db, s.tracking_run.id, frame, "source 'lost'");
  for (const char* source : {"tracked", "carried"}) {  // lost, yet with a source
    frame = lost;
    frame.source = source;
    ExpectFrameRefused(*db, s.tracking_run.id, frame, "source '" + std::string(source) + "'");
  }
  for (const char* source : {"", "Tracked", "interpolated"}) {  // not a source at all
    frame = posed;
    frame.source = source;
    ExpectFrameRefused(*db, s.tracking_run.id, frame, "source '" + std::string(source) + "'");
  }
  // A bad frame in a batch stops the whole batch.
  frame = posed;
  frame.source = "lost";
  TrackingFrameRecord good = posed;
  good.frame_index = 32;
  EXPECT_THROW(db->AppendTrackingFrames(s.tracking_run.id, {good, frame}), Error);
  EXPECT_EQ(db->GetTrackingFrames(s.tracking_run.id).size(), 10u);

  // The uncertainty is there exactly when not lost, both parts, >= 0; the
  // time is >= 0.
  frame = posed;
  frame.uncertainty_rotation_deg.reset();
  ExpectFrameRefused(*db, s.tracking_run.id, frame, "has an uncertainty");
  frame = posed;
  frame.uncertainty_translation_mm.reset();
  frame.uncertainty_rotation_deg.reset();
  ExpectFrameRefused(*db, s.tracking_run.id, frame, "has an uncertainty");
  frame = posed;
  frame.uncertainty_translation_mm = -0.5;
  ExpectFrameRefused(*db, s.tracking_run.id, frame, "has an uncertainty");
  frame = lost;
  frame.uncertainty_translation_mm = 1.0;
  frame.uncertainty_rotation_deg = 1.0;
  ExpectFrameRefused(*db, s.tracking_run.id, frame, "has an uncertainty");
  frame = posed;
  frame.total_ms = -1;
  ExpectFrameRefused(*db, s.tracking_run.id, frame, "has total_ms -1");

  // The same frames with a consistent source are taken.
  good = posed;
  good.source = "carried";
  frame = lost;
  db->AppendTrackingFrames(s.tracking_run.id, {good, frame});
  EXPECT_EQ(db->GetTrackingFrames(s.tracking_run.id).size(), 12u);
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
      RawExec(*db, "INSERT OR REPLACE INTO audit_log VALUES (1, 0, 'x', 'y', '', '', '', '', '')", &message),
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
  // (The store lets a plan change only by its approval: the trigger goes first.)
  ASSERT_EQ(RawExec(*db, "DROP TRIGGER plans_approval_only"), SQLITE_OK);
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
  const std::set<std::string> expected = {"alignments",
                                          "audit_log",
                                          "body_marker_maps",
                                          "body_marker_poses",
                                          "body_marker_motion",
                                          "body_surface_motion",
                                          "patients",
                                          "plans",
                                          "reconstructions",
                                          "recordings",
                                          "room_maps",
                                          "room_map_markers",
                                          "room_map_surface",
                                          "body_scan_landmarks",
                                          "sessions",
                                          "tracking_frames",
                                          "tracking_runs",
                                          "session_activity",
                                          "body_marker_motion_direction"};
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
