// Schema migrations: from every earlier version to the latest with the data
// intact, one transaction per step, and refusal of stores from the future.

#include <gtest/gtest.h>
#include <sqlite3.h>

#include <algorithm>
#include <filesystem>
#include <map>

#include "schema/schema_migrations.h"
#include "store/blob_codec.h"
#include "store/migrator.h"
#include "store/sqlite_database.h"
#include "store_test_util.h"
#include "util/file.h"

namespace arpos {
namespace {

namespace fs = std::filesystem;

// A raw connection, as an older ARPos (or a tool) would have used.
class RawDb {
 public:
  explicit RawDb(const std::string& path) {
    EXPECT_EQ(sqlite3_open(path.c_str(), &db_), SQLITE_OK);
  }
  ~RawDb() { sqlite3_close(db_); }
  sqlite3* get() { return db_; }

  // Runs `sql`, binding blobs to ?1, ?2, ...; fails the test on error.
  void Exec(const std::string& sql, const std::vector<Blob>& blobs = {}) {
    sqlite3_stmt* stmt = nullptr;
    ASSERT_EQ(sqlite3_prepare_v2(db_, sql.c_str(), -1, &stmt, nullptr), SQLITE_OK)
        << sqlite3_errmsg(db_) << " in " << sql;
    for (std::size_t i = 0; i < blobs.size(); ++i) {
      sqlite3_bind_blob(stmt, static_cast<int>(i + 1), blobs[i].data(),
                        static_cast<int>(blobs[i].size()), SQLITE_TRANSIENT);
    }
    const int rc = sqlite3_step(stmt);
    sqlite3_finalize(stmt);
    ASSERT_EQ(rc, SQLITE_DONE) << sqlite3_errmsg(db_) << " in " << sql;
  }
  std::string Text(const std::string& sql) {
    sqlite3_stmt* stmt = nullptr;
    EXPECT_EQ(sqlite3_prepare_v2(db_, sql.c_str(), -1, &stmt, nullptr), SQLITE_OK) << sql;
    std::string result;
    while (sqlite3_step(stmt) == SQLITE_ROW) {
      for (int c = 0; c < sqlite3_column_count(stmt); ++c) {
        const unsigned char* text = sqlite3_column_text(stmt, c);
        result += (text != nullptr ? reinterpret_cast<const char*>(text) : "NULL");
        result += "|";
      }
      result += "\n";
    }
    sqlite3_finalize(stmt);
    return result;
  }

 private:
  sqlite3* db_ = nullptr;
};

// The data an older program wrote: the columns of schema version 1 only.
struct OldData {
  StoredTriangleMesh mesh;
  Rigid3d room_from_model_target;
  StoredPointCloud landmarks;
  ByteMatrix descriptors;
  std::array<Eigen::Vector3d, 4> corners;
  Rigid3d body_from_marker;
  StoredPointCloud cloud;
  Rigid3d reconstruction_from_model;
  Rigid3d room_from_model;
};

OldData MakeOldData() {
  std::mt19937 rng(99);
  OldData d;
  d.mesh = test::RandomMesh(rng);
  d.room_from_model_target = test::RandomPose(rng);
  d.landmarks = test::RandomCloud(rng, 7, false, false);
  d.descriptors = ByteMatrix::Constant(7, 32, 0xA5);
  for (int c = 0; c < 4; ++c) d.corners[c] = Eigen::Vector3d(c, -c, 0.5 * c);
  d.body_from_marker = test::RandomPose(rng);
  d.cloud = test::RandomCloud(rng, 50, true, false);
  d.reconstruction_from_model = test::RandomPose(rng);
  d.room_from_model = test::RandomPose(rng);
  return d;
}

void WriteOldData(RawDb& raw, const OldData& d, int version) {
  raw.Exec("BEGIN");  // one fsync instead of one per row
  raw.Exec(
      "INSERT INTO patients (patient_id, external_id, display_name, created_unix_ms) "
      "VALUES (1, 'MRN-old', 'Old Patient', 1600000000000)");
  raw.Exec(
      "INSERT INTO plans (plan_id, patient_id, name, reference_model_name, "
      "reference_model_mesh, room_from_model_target, created_unix_ms) VALUES (1, 1, 'old plan', "
      "'model.ply', ?1, ?2, 1600000001000)",
      {EncodeTriangleMesh(d.mesh), EncodePose(d.room_from_model_target)});
  raw.Exec(
      "INSERT INTO recordings (recording_id, plan_id, kind, name, path, frame_count, width, "
      "height, fx, fy, cx, cy, k1, depth_scale, created_unix_ms) VALUES "
      "(1, 1, 'room', 'room', '/old/room', 300, 640, 480, 525, 525, 319.5, 239.5, 0.01, "
      "5000, 1600000002000)");
  Eigen::MatrixXd corners(4, 3);
  for (int c = 0; c < 4; ++c) corners.row(c) = d.corners[c].transpose();
  raw.Exec(
      "INSERT INTO room_maps (room_map_id, plan_id, recording_id, origin_marker_id, "
      "marker_size_m, mean_residual_px, max_residual_px, landmarks_in_room, "
      "landmark_descriptors, created_unix_ms) VALUES (1, 1, 1, 0, 0.15, 0.3, 0.8, ?1, ?2, "
      "1600000003000)",
      {EncodePointCloud(d.landmarks), EncodeByteMatrix(d.descriptors)});
  raw.Exec(
      "INSERT INTO room_map_markers (room_map_id, marker_id, corners_in_room, residual_px, "
      "num_observations) VALUES (1, 0, ?1, 0.2, 10)",
      {EncodeMatrix(corners)});
  raw.Exec(
      "INSERT INTO sessions (session_id, plan_id, fraction, operator_name, started_unix_ms, "
      "notes) VALUES (1, 1, 2, 'RTT Old', 1600000100000, 'old notes')");
  raw.Exec(
      "INSERT INTO recordings (recording_id, session_id, kind, path, frame_count, width, "
      "height, fx, fy, cx, cy, depth_scale, created_unix_ms) VALUES "
      "(2, 1, 'body_scan', '/old/body_scan', 90, 640, 480, 525, 525, 319.5, 239.5, 1000, "
      "1600000101000)");
  raw.Exec(
      "INSERT INTO body_marker_maps (body_marker_map_id, session_id, recording_id, "
      "marker_size_m, mean_residual_px, max_residual_px, created_unix_ms) VALUES (1, 1, 2, 0.03, "
      "0.4, 1.0, 1600000102000)");
  raw.Exec(
      "INSERT INTO body_marker_poses (body_marker_map_id, marker_id, body_from_marker, "
      "residual_px, num_observations) VALUES (1, 101, ?1, 0.4, 12)",
      {EncodePose(d.body_from_marker)});
  raw.Exec(
      "INSERT INTO reconstructions (reconstruction_id, session_id, recording_id, cloud, mesh, "
      "num_points, num_triangles, num_frames_used, voxel_size_m, created_unix_ms) VALUES (1, 1, 2, "
      "?1, NULL, 50, 0, 30, 0.004, "
      "1600000103000)",
      {EncodePointCloud(d.cloud)});
  raw.Exec(
      "INSERT INTO alignments (alignment_id, reconstruction_id, parent_alignment_id, method, "
      "reconstruction_from_model, fitness, rmse_m, num_inliers, options, created_unix_ms) "
      "VALUES (1, 1, NULL, 'icp', ?1, 0.9, 0.001, 100, 'opts', "
      "1600000104000)",
      {EncodePose(d.reconstruction_from_model)});
  raw.Exec(
      "INSERT INTO tracking_runs (tracking_run_id, session_id, alignment_id, recording_id, "
      "options, started_unix_ms) VALUES (1, 1, 1, NULL, 'old options', 1600000105000)");
  // From version 5 on a frame must say where its pose came from.
  const bool with_source = version >= 5;
  raw.Exec(
      "INSERT INTO tracking_frames (tracking_run_id, frame_index, timestamp_s, status, "
      "room_from_model, correction_tx_mm, correction_ty_mm, correction_tz_mm, "
      "correction_rx_deg, correction_ry_deg, correction_rz_deg" +
          std::string(with_source ? ", source" : "") +
          ") VALUES (1, 0, 0.0, 'out_of_tolerance', ?1, 1, 2, 3, 0.1, 0.2, 0.3" +
          (with_source ? ", 'tracked'" : "") + ")",
      {EncodePose(d.room_from_model)});
  raw.Exec("INSERT INTO tracking_frames (tracking_run_id, frame_index, timestamp_s, status" +
           std::string(with_source ? ", source" : "") + ") VALUES (1, 1, 0.033, 'lost'" +
           (with_source ? ", 'lost'" : "") + ")");
  raw.Exec(
      "INSERT INTO audit_log (time_unix_ms, actor, action, entity, details) VALUES "
      "(1600000200000, 'old-arpos', 'approve_alignment', 'alignment:1', 'v" +
      std::to_string(version) + "')");
  if (version >= 2) {
    raw.Exec("UPDATE sessions SET status = 'completed', ended_unix_ms = 1600000900000");
  }
  raw.Exec("COMMIT");
}

void ExpectOldDataIntact(Database& db, const OldData& d, int version) {
  const auto patient = db.GetPatient(PatientId(1));
  ASSERT_TRUE(patient);
  EXPECT_EQ(patient->external_id, "MRN-old");
  EXPECT_EQ(patient->display_name, "Old Patient");

  const auto plan = db.GetPlan(PlanId(1));
  ASSERT_TRUE(plan);
  EXPECT_EQ(plan->name, "old plan");
  test::ExpectMeshEq(d.mesh, plan->reference_model);
  test::ExpectPoseEq(d.room_from_model_target, plan->room_from_model_target);

  const auto room = db.GetRecording(RecordingId(1));
  ASSERT_TRUE(room);
  EXPECT_EQ(room->kind, RecordingKind::kRoom);
  EXPECT_EQ(room->plan_id, PlanId(1));
  EXPECT_EQ(room->intrinsics.distortion[0], 0.01);
  EXPECT_EQ(room->intrinsics.depth_scale, 5000);

  const auto room_map = db.GetRoomMap(RoomMapId(1));
  ASSERT_TRUE(room_map);
  test::ExpectCloudEq(d.landmarks, room_map->landmarks_in_room);
  EXPECT_EQ(room_map->landmark_descriptors, d.descriptors);
  ASSERT_EQ(room_map->markers.size(), 1u);
  for (int c = 0; c < 4; ++c) EXPECT_EQ(room_map->markers[0].corners_in_room[c], d.corners[c]);
  // 0004: a map from before knows nothing of the camera or its room frame's
  // uncertainty (read as sRGB, no depth correction, unknown).
  EXPECT_EQ(room_map->camera_response, "");
  EXPECT_EQ(room_map->depth_correction, "");
  EXPECT_FALSE(room_map->room_frame_tilt_sigma_deg);
  EXPECT_FALSE(room_map->room_frame_yaw_sigma_deg);
  EXPECT_FALSE(room_map->room_frame_couch_sigma_mm);

  const auto session = db.GetSession(SessionId(1));
  ASSERT_TRUE(session);
  EXPECT_EQ(session->fraction, 2);
  EXPECT_EQ(session->operator_name, "RTT Old");
  EXPECT_EQ(session->notes, "old notes");
  if (version < 2) {  // sessions from before 0002 become open, with no end
    EXPECT_EQ(session->status, SessionStatus::kOpen);
    EXPECT_FALSE(session->ended_unix_ms);
  } else {
    EXPECT_EQ(session->status, SessionStatus::kCompleted);
    EXPECT_EQ(session->ended_unix_ms, 1600000900000);
  }

  const auto body_map = db.GetBodyMarkerMap(BodyMarkerMapId(1));
  ASSERT_TRUE(body_map);
  ASSERT_EQ(body_map->markers.size(), 1u);
  EXPECT_EQ(body_map->markers[0].marker_id, 101);
  test::ExpectPoseEq(d.body_from_marker, body_map->markers[0].body_from_marker);

  const auto reconstruction = db.GetReconstruction(ReconstructionId(1));
  ASSERT_TRUE(reconstruction);
  test::ExpectCloudEq(d.cloud, reconstruction->cloud);
  EXPECT_FALSE(reconstruction->mesh);

  const auto alignment = db.GetAlignment(AlignmentId(1));
  ASSERT_TRUE(alignment);
  EXPECT_EQ(alignment->method, AlignmentMethod::kIcp);
  test::ExpectPoseEq(d.reconstruction_from_model, alignment->reconstruction_from_model);

  const auto run = db.GetTrackingRun(TrackingRunId(1));
  ASSERT_TRUE(run);
  EXPECT_EQ(run->options, "old options");
  EXPECT_EQ(run->tolerance_translation_mm, 3.0);  // 0003 defaults
  EXPECT_EQ(run->tolerance_rotation_deg, 2.0);
  const auto frames = db.GetTrackingFrames(TrackingRunId(1));
  ASSERT_EQ(frames.size(), 2u);
  ASSERT_TRUE(frames[0].room_from_model);
  test::ExpectPoseEq(d.room_from_model, *frames[0].room_from_model);
  ASSERT_TRUE(frames[0].correction);
  EXPECT_EQ(frames[0].correction->translation_mm, Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(frames[0].correction->rotation_deg, Eigen::Vector3d(0.1, 0.2, 0.3));
  EXPECT_EQ(frames[1].status, TrackingFrameStatus::kLost);
  // 0005: runs and frames from before know nothing of the sequence, the
  // summary, the camera pose, the uncertainty, the timing or a note; the
  // source follows from the status.
  EXPECT_EQ(run->sequence_name, "");
  EXPECT_EQ(run->summary, "");
  EXPECT_EQ(frames[0].source, "tracked");
  EXPECT_EQ(frames[1].source, "lost");
  for (const TrackingFrameRecord& frame : frames) {
    EXPECT_FALSE(frame.room_from_camera) << "frame " << frame.frame_index;
    EXPECT_FALSE(frame.uncertainty_translation_mm) << "frame " << frame.frame_index;
    EXPECT_FALSE(frame.uncertainty_rotation_deg) << "frame " << frame.frame_index;
    EXPECT_EQ(frame.total_ms, 0.0) << "frame " << frame.frame_index;
    EXPECT_EQ(frame.note, "") << "frame " << frame.frame_index;
  }

  const auto audit = db.ListAudit();
  ASSERT_EQ(audit.size(), 1u);
  EXPECT_EQ(audit[0].details, "v" + std::to_string(version));
}

// Every object of the schema, by name, with its SQL.
std::map<std::string, std::string> SchemaObjects(sqlite3* db) {
  std::map<std::string, std::string> objects;
  sqlite3_stmt* stmt = nullptr;
  sqlite3_prepare_v2(db, "SELECT name, ifnull(sql, '') FROM sqlite_master", -1, &stmt, nullptr);
  while (sqlite3_step(stmt) == SQLITE_ROW) {
    objects[reinterpret_cast<const char*>(sqlite3_column_text(stmt, 0))] =
        reinterpret_cast<const char*>(sqlite3_column_text(stmt, 1));
  }
  sqlite3_finalize(stmt);
  return objects;
}

TEST(Migrations, AreEmbeddedAndNumberedFromOne) {
  const auto& migrations = SchemaMigrations();
  ASSERT_GE(migrations.size(), 2u);
  EXPECT_EQ(LatestSchemaVersion(), static_cast<int>(migrations.size()));
  for (std::size_t i = 0; i < migrations.size(); ++i) {
    EXPECT_EQ(migrations[i].version, static_cast<int>(i + 1));
    char prefix[32];
    std::snprintf(prefix, sizeof prefix, "%04d_", static_cast<int>(i + 1));
    EXPECT_EQ(std::string(migrations[i].file_name).rfind(prefix, 0), 0u) << migrations[i].file_name;
    EXPECT_NE(std::string(migrations[i].sql).find(';'), std::string::npos);
  }
  EXPECT_NE(std::string(migrations[0].sql).find("CREATE TABLE audit_log"), std::string::npos);
}

TEST(Migrations, EachStepBumpsTheVersionByOne) {
  TempDir dir;
  RawDb raw((dir.path() / "steps.db").string());
  EXPECT_EQ(ReadSchemaVersion(raw.get()), 0);
  for (int version = 1; version <= LatestSchemaVersion(); ++version) {
    EXPECT_EQ(MigrateSchema(raw.get(), "steps.db", version), 1);
    EXPECT_EQ(ReadSchemaVersion(raw.get()), version);
  }
  EXPECT_EQ(MigrateSchema(raw.get(), "steps.db"), 0);                 // nothing left to do
  EXPECT_THROW(MigrateSchema(raw.get(), "steps.db", 1), InputError);  // no downgrades
}

class MigrateFromVersion : public ::testing::TestWithParam<int> {};

TEST_P(MigrateFromVersion, ReachesTheLatestWithDataIntact) {
  const int from = GetParam();
  TempDir dir;
  const std::string path = (dir.path() / "old.db").string();
  const OldData data = MakeOldData();
  {
    RawDb raw(path);
    if (from > 0) {
      ASSERT_EQ(MigrateSchema(raw.get(), path, from), from);
      ASSERT_EQ(ReadSchemaVersion(raw.get()), from);
      WriteOldData(raw, data, from);
    }
  }

  auto db = SqliteDatabase::Open(path);
  EXPECT_EQ(db->Info().schema_version, LatestSchemaVersion());
  if (from > 0) ExpectOldDataIntact(*db, data, from);

  // The migrated store has exactly the schema of a fresh one...
  auto fresh = SqliteDatabase::Open(":memory:");
  EXPECT_EQ(SchemaObjects(db->RawHandle()), SchemaObjects(fresh->RawHandle()));
  // ...so it takes new records, and its rules still hold.
  const test::FullStore added = test::WriteFullStore(*db, 1234);
  test::ExpectFullStoreEq(*db, added);
  EXPECT_NE(sqlite3_exec(db->RawHandle(), "DELETE FROM audit_log", nullptr, nullptr, nullptr),
            SQLITE_OK);
  EXPECT_NE(sqlite3_exec(db->RawHandle(), "DELETE FROM patients", nullptr, nullptr, nullptr),
            SQLITE_OK);
}

INSTANTIATE_TEST_SUITE_P(EveryEarlierVersion, MigrateFromVersion,
                         ::testing::Range(0, LatestSchemaVersion()),
                         [](const auto& info) { return "V" + std::to_string(info.param); });

// A store written by the program of schema version 3 (room maps without the
// camera columns) migrates in place: its rows stay, its room map gains the
// new columns as NULL, and it takes a map with them afterwards.
TEST(Migrations, AVersion3StoreGainsTheRoomMapCameraColumnsInPlace) {
  TempDir dir;
  const std::string path = (dir.path() / "v3.db").string();
  const OldData data = MakeOldData();
  const std::string old_columns =
      "SELECT room_map_id, plan_id, recording_id, origin_marker_id, marker_size_m, mean_residual_px, "
      "max_residual_px, hex(landmarks_in_room), hex(landmark_descriptors), created_unix_ms FROM room_maps "
      "WHERE room_map_id = 1";
  std::string old_row;
  {
    RawDb raw(path);
    ASSERT_EQ(MigrateSchema(raw.get(), path, 3), 3);
    WriteOldData(raw, data, 3);
    EXPECT_EQ(raw.Text("SELECT name FROM pragma_table_info('room_maps') WHERE name = 'camera_response'"), "");
    old_row = raw.Text(old_columns);
    ASSERT_FALSE(old_row.empty());
  }
  {
    auto db = SqliteDatabase::Open(path);
    EXPECT_EQ(db->Info().schema_version, LatestSchemaVersion());
    ExpectOldDataIntact(*db, data, 3);
    RoomMapRecord with_camera = *db->GetRoomMap(RoomMapId(1));
    with_camera.camera_response = "srgb: 0 1 2";
    with_camera.depth_correction = "depth correction: 0.01 0 0 0 0 0 0";
    with_camera.room_frame_tilt_sigma_deg = 0.02;
    with_camera.room_frame_yaw_sigma_deg = 0.05;
    with_camera.room_frame_couch_sigma_mm = 0.3;
    const auto back = db->GetRoomMap(db->AddRoomMap(with_camera));
    ASSERT_TRUE(back);
    EXPECT_EQ(back->camera_response, "srgb: 0 1 2");
    EXPECT_EQ(back->depth_correction, "depth correction: 0.01 0 0 0 0 0 0");
    EXPECT_EQ(back->room_frame_tilt_sigma_deg, 0.02);
    EXPECT_EQ(back->room_frame_yaw_sigma_deg, 0.05);
    EXPECT_EQ(back->room_frame_couch_sigma_mm, 0.3);
  }
  RawDb raw(path);
  EXPECT_EQ(ReadSchemaVersion(raw.get()), LatestSchemaVersion());
  // The old row keeps every old column as it was; its new columns are NULL.
  EXPECT_EQ(raw.Text(old_columns), old_row);
  EXPECT_EQ(raw.Text("SELECT camera_response, depth_correction, room_frame_tilt_sigma_deg, "
                     "room_frame_yaw_sigma_deg, room_frame_couch_sigma_mm FROM room_maps WHERE room_map_id = 1"),
            "NULL|NULL|NULL|NULL|NULL|\n");
  EXPECT_EQ(raw.Text("SELECT COUNT(*) FROM room_maps"), "2|\n");
}

// A store written by the program of schema version 4 (tracking runs and
// frames without the per-frame detail) migrates in place: tracking_frames is
// rebuilt with its rows and their old columns unchanged, the new columns read
// back as the documented defaults, and the old run takes new detailed frames.
TEST(Migrations, AVersion4StoreGainsTheTrackingFrameDetailInPlace) {
  TempDir dir;
  const std::string path = (dir.path() / "v4.db").string();
  const OldData data = MakeOldData();
  const std::string old_frame_columns =
      "SELECT tracking_run_id, frame_index, timestamp_s, status, hex(room_from_model), correction_tx_mm, "
      "correction_ty_mm, correction_tz_mm, correction_rx_deg, correction_ry_deg, correction_rz_deg "
      "FROM tracking_frames ORDER BY tracking_run_id, frame_index";
  const std::string old_run_columns =
      "SELECT tracking_run_id, session_id, alignment_id, recording_id, options, tolerance_translation_mm, "
      "tolerance_rotation_deg, started_unix_ms FROM tracking_runs";
  std::string old_frames, old_run;
  {
    RawDb raw(path);
    ASSERT_EQ(MigrateSchema(raw.get(), path, 4), 4);
    WriteOldData(raw, data, 4);
    EXPECT_EQ(raw.Text("SELECT name FROM pragma_table_info('tracking_frames') WHERE name = 'source'"), "");
    old_frames = raw.Text(old_frame_columns);
    old_run = raw.Text(old_run_columns);
    ASSERT_EQ(std::count(old_frames.begin(), old_frames.end(), '\n'), 2);
  }
  {
    auto db = SqliteDatabase::Open(path);
    EXPECT_EQ(db->Info().schema_version, LatestSchemaVersion());
    ExpectOldDataIntact(*db, data, 4);

    const auto run = db->GetTrackingRun(TrackingRunId(1));
    ASSERT_TRUE(run);
    EXPECT_EQ(run->sequence_name, "");
    EXPECT_EQ(run->summary, "");
    const auto frames = db->GetTrackingFrames(TrackingRunId(1));
    ASSERT_EQ(frames.size(), 2u);
    EXPECT_EQ(frames[0].status, TrackingFrameStatus::kOutOfTolerance);
    EXPECT_EQ(frames[0].source, "tracked");
    EXPECT_EQ(frames[1].status, TrackingFrameStatus::kLost);
    EXPECT_EQ(frames[1].source, "lost");
    for (const TrackingFrameRecord& frame : frames) {
      EXPECT_FALSE(frame.room_from_camera);
      EXPECT_FALSE(frame.uncertainty_translation_mm);
      EXPECT_FALSE(frame.uncertainty_rotation_deg);
      EXPECT_EQ(frame.total_ms, 0.0);
      EXPECT_EQ(frame.note, "");
    }

    // The old run takes a frame with every new field.
    TrackingFrameRecord frame = frames[0];
    frame.frame_index = 2;
    frame.source = "carried";
    frame.room_from_camera = data.body_from_marker;
    frame.uncertainty_translation_mm = 1.25;
    frame.uncertainty_rotation_deg = 0.5;
    frame.total_ms = 33.5;
    frame.note = "carried over";
    db->AppendTrackingFrames(TrackingRunId(1), {frame});
    const auto back = db->GetTrackingFrames(TrackingRunId(1));
    ASSERT_EQ(back.size(), 3u);
    EXPECT_EQ(back[2].source, "carried");
    ASSERT_TRUE(back[2].room_from_camera);
    test::ExpectPoseEq(data.body_from_marker, *back[2].room_from_camera);
    EXPECT_EQ(back[2].uncertainty_translation_mm, 1.25);
    EXPECT_EQ(back[2].total_ms, 33.5);
    EXPECT_EQ(back[2].note, "carried over");
  }
  RawDb raw(path);
  EXPECT_EQ(ReadSchemaVersion(raw.get()), LatestSchemaVersion());
  // The old rows keep every old column as they were; the rebuild left nothing behind.
  EXPECT_EQ(raw.Text(old_run_columns), old_run);
  EXPECT_EQ(raw.Text(old_frame_columns + " LIMIT 2"), old_frames);
  EXPECT_EQ(raw.Text("SELECT sequence_name, summary FROM tracking_runs"), "||\n");
  EXPECT_EQ(raw.Text("SELECT frame_index, room_from_camera, source, uncertainty_translation_mm, "
                     "uncertainty_rotation_deg, total_ms, note FROM tracking_frames WHERE frame_index < 2 "
                     "ORDER BY frame_index"),
            "0|NULL|tracked|NULL|NULL|0.0||\n1|NULL|lost|NULL|NULL|0.0||\n");
  EXPECT_EQ(raw.Text("SELECT name FROM sqlite_master WHERE name LIKE 'tracking_frames%'"),
            "tracking_frames|\n");
  // The rebuilt table keeps its foreign key: deleting the run takes the frames.
  raw.Exec("PRAGMA foreign_keys = ON");
  raw.Exec("DELETE FROM tracking_runs");
  EXPECT_EQ(raw.Text("SELECT COUNT(*) FROM tracking_frames"), "0|\n");
}

TEST(Migrations, AFailingStepIsRolledBackWhole) {
  TempDir dir;
  const std::string path = (dir.path() / "conflict.db").string();
  const SchemaMigration& second = SchemaMigrations()[1];
  {
    RawDb raw(path);
    ASSERT_EQ(MigrateSchema(raw.get(), path, 1), 1);
    WriteOldData(raw, MakeOldData(), 1);
    // Someone added an index by hand that 0002 also creates: 0002 fails after
    // its ALTER TABLE statements have already run inside the transaction.
    raw.Exec("CREATE INDEX sessions_by_plan ON sessions(plan_id)");
  }
  try {
    SqliteDatabase::Open(path);
    ADD_FAILURE() << "no throw";
  } catch (const Error& e) {
    const std::string what = e.what();
    for (const std::string& part :
         {path, std::string(second.file_name), std::string("stays at version 1"),
          std::string("sessions_by_plan already exists")}) {
      EXPECT_NE(what.find(part), std::string::npos) << "'" << part << "' not in: " << what;
    }
  }
  RawDb raw(path);
  EXPECT_EQ(ReadSchemaVersion(raw.get()), 1);
  EXPECT_EQ(raw.Text("SELECT name FROM pragma_table_info('sessions') WHERE name = 'status'"), "")
      << "the ALTER TABLE of the failed migration was not rolled back";
  EXPECT_EQ(raw.Text("SELECT external_id FROM patients"), "MRN-old|\n");
}

// A store whose rows point to rows that are gone (deleted outside arpos
// with foreign keys off) is refused before any step runs: the message names
// the tables and says nothing changed; the migration is not blamed.
TEST(Migrations, AStoreWithDanglingReferencesIsRefusedUntouched) {
  TempDir dir;
  const std::string path = (dir.path() / "dangling.db").string();
  {
    RawDb raw(path);
    ASSERT_EQ(MigrateSchema(raw.get(), path, 1), 1);
    WriteOldData(raw, MakeOldData(), 1);
    raw.Exec("PRAGMA foreign_keys = OFF");
    raw.Exec("DELETE FROM plans");
  }
  const std::string before = test::FileBytes(path);
  try {
    SqliteDatabase::Open(path);
    ADD_FAILURE() << "no throw";
  } catch (const InputError& e) {
    const std::string what = e.what();
    for (const std::string& part :
         {path, std::string("references point to rows that are not there"), std::string("sessions"),
          std::string("not migrated from schema version 1"), std::string("nothing was changed")}) {
      EXPECT_NE(what.find(part), std::string::npos) << "'" << part << "' not in: " << what;
    }
    EXPECT_EQ(what.find("migration 0002"), std::string::npos) << what;
  }
  EXPECT_EQ(test::FileBytes(path), before) << "the refused store was modified";
}

// Newer store: refused with both versions named, file bytes unchanged.
void ExpectNewerStoreRefused(const std::string& path) {
  const int newer = LatestSchemaVersion() + 1;
  const std::string before = test::FileBytes(path);
  ASSERT_FALSE(before.empty());
  try {
    SqliteDatabase::Open(path);
    ADD_FAILURE() << "no throw";
  } catch (const InputError& e) {
    const std::string what = e.what();
    for (const std::string& part : {path, "schema version " + std::to_string(newer),
                                    "knows versions up to " + std::to_string(LatestSchemaVersion()),
                                    std::string("not changed")}) {
      EXPECT_NE(what.find(part), std::string::npos) << "'" << part << "' not in: " << what;
    }
  }
  EXPECT_EQ(test::FileBytes(path), before) << "the refused store was modified";
}

TEST(Migrations, ANewerRollbackJournalStoreIsRefusedUntouched) {
  TempDir dir;
  const std::string path = (dir.path() / "future.db").string();
  {
    RawDb raw(path);  // journal_mode stays DELETE: switching to WAL would rewrite the header
    MigrateSchema(raw.get(), path);
    WriteOldData(raw, MakeOldData(), LatestSchemaVersion());
    raw.Exec("PRAGMA user_version = " + std::to_string(LatestSchemaVersion() + 1));
  }
  ExpectNewerStoreRefused(path);
  EXPECT_FALSE(fs::exists(path + "-wal"));
  EXPECT_FALSE(fs::exists(path + "-journal"));
  RawDb raw(path);
  EXPECT_EQ(raw.Text("PRAGMA journal_mode"), "delete|\n");
}

TEST(Migrations, ANewerWalStoreIsRefusedUntouched) {
  TempDir dir;
  const std::string path = (dir.path() / "future-wal.db").string();
  {
    auto db = SqliteDatabase::Open(path);
    test::WriteFullStore(*db, 3);
    ASSERT_EQ(
        sqlite3_exec(db->RawHandle(),
                     ("PRAGMA user_version = " + std::to_string(LatestSchemaVersion() + 1)).c_str(),
                     nullptr, nullptr, nullptr),
        SQLITE_OK);
  }
  ExpectNewerStoreRefused(path);
  ExpectNewerStoreRefused(path);  // and again: the refusal itself changed nothing
}

TEST(Migrations, AStoreOfAnotherApplicationIsRefused) {
  TempDir dir;
  const std::string path = (dir.path() / "other-app.db").string();
  {
    RawDb raw(path);
    raw.Exec("PRAGMA application_id = 1234");
    raw.Exec("PRAGMA user_version = 1");
  }
  try {
    SqliteDatabase::Open(path);
    ADD_FAILURE() << "no throw";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("not an ARPos store (SQLite application_id 1234"),
              std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace arpos
