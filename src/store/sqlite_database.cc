#include "store/sqlite_database.h"

#include <sqlite3.h>

#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>

#include "store/blob_codec.h"
#include "store/migrator.h"
#include "store/sqlite_util.h"
#include "util/logging.h"

namespace arpos {
namespace {

namespace fs = std::filesystem;

std::int64_t NowUnixMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

std::int64_t OrNow(std::int64_t unix_ms) { return unix_ms != 0 ? unix_ms : NowUnixMs(); }

// SQLite reads LIMIT -1 as "no limit".
std::int64_t SqlLimit(std::size_t limit) {
  return limit == 0 ? -1 : static_cast<std::int64_t>(limit);
}

std::string Context(const char* column, const char* owner, std::int64_t id) {
  return std::string(column) + " of " + owner + " " + std::to_string(id);
}

template <typename Id>
std::optional<Id> OptionalId(const SqliteStatement& s, int column) {
  if (s.ColumnIsNull(column)) return std::nullopt;
  return Id(s.ColumnInt64(column));
}

std::optional<double> OptionalDouble(const SqliteStatement& s, int column) {
  if (s.ColumnIsNull(column)) return std::nullopt;
  return s.ColumnDouble(column);
}

void BindOptionalDouble(SqliteStatement& s, int index, const std::optional<double>& value) {
  if (value) {
    s.BindDouble(index, *value);
  } else {
    s.BindNull(index);
  }
}

// Optional text columns hold NULL rather than '' for "not recorded".
void BindTextOrNull(SqliteStatement& s, int index, const std::string& text) {
  if (text.empty()) {
    s.BindNull(index);
  } else {
    s.BindText(index, text);
  }
}

// Finds before SQLite does what it would report as "unable to open database
// file" or, at the first write, "attempt to write a readonly database": a
// missing or unwritable folder (a file store keeps PATH-wal and PATH-shm
// beside it), an unreadable or read-only file. Root passes the permission
// checks, as it passes SQLite's; a read-only file system stops root too.
void CheckStoreLocation(const std::string& path, bool exists) {
  fs::path folder = fs::path(path).parent_path();
  if (folder.empty()) folder = ".";
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) {
    ARPOS_INPUT_ERROR(path << ": the folder " << folder.string()
                           << " does not exist; create it or give --store a file in an existing folder");
  }
  auto refuse = [&](int code) {
    const std::string problem = StoreAccessProblem(code, path, std::strerror(errno), "file system");
    throw StoreAccessError(problem, code);
  };
  if (exists) {
    if (::access(path.c_str(), R_OK) != 0) {
      throw StoreAccessError(path + ": cannot read the store file (file system: \"" + std::strerror(errno) +
                                 "\"); give the program read and write access to it, or give --store another file.",
                             SQLITE_PERM);
    }
    if (::access(path.c_str(), W_OK) != 0) refuse(SQLITE_READONLY);
  }
  if (::access(folder.c_str(), W_OK | X_OK) != 0) refuse(SQLITE_READONLY_DIRECTORY);
}

struct SqliteCloser {
  void operator()(sqlite3* db) const { sqlite3_close(db); }
};

// 4 corners x (x, y, z), one corner per row.
Blob EncodeCorners(const std::array<Eigen::Vector3d, 4>& corners) {
  Eigen::MatrixXd matrix(4, 3);
  for (int i = 0; i < 4; ++i) matrix.row(i) = corners[i].transpose();
  return EncodeMatrix(matrix);
}

std::array<Eigen::Vector3d, 4> DecodeCorners(const Blob& blob, const std::string& context) {
  const Eigen::MatrixXd matrix = DecodeMatrix(blob, context);
  if (matrix.rows() != 4 || matrix.cols() != 3) {
    throw CorruptBlobError(context + ": corrupt blob: marker corners must be 4x3, found " +
                           std::to_string(matrix.rows()) + "x" + std::to_string(matrix.cols()));
  }
  std::array<Eigen::Vector3d, 4> corners;
  for (int i = 0; i < 4; ++i) corners[i] = matrix.row(i).transpose();
  return corners;
}

// Column lists shared by the Get and List queries of a table.
constexpr const char* kPatientColumns =
    "SELECT patient_id, external_id, display_name, created_unix_ms FROM patients ";
constexpr const char* kSessionColumns =
    "SELECT session_id, plan_id, fraction, operator_name, started_unix_ms, status, "
    "ended_unix_ms, notes, on_unapproved_plan, ended_by, end_reason FROM sessions ";
constexpr const char* kAlignmentColumns =
    "SELECT alignment_id, reconstruction_id, parent_alignment_id, method, "
    "reconstruction_from_model, fitness, rmse_m, num_inliers, options, created_unix_ms "
    "FROM alignments ";

PatientRecord ReadPatient(const SqliteStatement& s) {
  PatientRecord patient;
  patient.id = PatientId(s.ColumnInt64(0));
  patient.external_id = s.ColumnText(1);
  patient.display_name = s.ColumnText(2);
  patient.created_unix_ms = s.ColumnInt64(3);
  return patient;
}

SessionRecord ReadSession(const SqliteStatement& s) {
  SessionRecord session;
  session.id = SessionId(s.ColumnInt64(0));
  session.plan_id = PlanId(s.ColumnInt64(1));
  session.fraction = static_cast<int>(s.ColumnInt64(2));
  session.operator_name = s.ColumnText(3);
  session.started_unix_ms = s.ColumnInt64(4);
  session.status = ParseSessionStatus(s.ColumnText(5));
  if (!s.ColumnIsNull(6)) session.ended_unix_ms = s.ColumnInt64(6);
  session.notes = s.ColumnText(7);
  session.on_unapproved_plan = s.ColumnInt64(8) != 0;
  session.ended_by = s.ColumnText(9);
  session.end_reason = s.ColumnText(10);
  return session;
}

AlignmentRecord ReadAlignment(const SqliteStatement& s) {
  AlignmentRecord alignment;
  alignment.id = AlignmentId(s.ColumnInt64(0));
  alignment.reconstruction_id = ReconstructionId(s.ColumnInt64(1));
  alignment.parent_alignment_id = OptionalId<AlignmentId>(s, 2);
  alignment.method = ParseAlignmentMethod(s.ColumnText(3));
  alignment.reconstruction_from_model = DecodePose(
      s.ColumnBlob(4),
      Context("alignments.reconstruction_from_model", "alignment", alignment.id.value()));
  alignment.fitness = s.ColumnDouble(5);
  alignment.rmse_m = s.ColumnDouble(6);
  alignment.num_inliers = s.ColumnInt64(7);
  alignment.options = s.ColumnText(8);
  alignment.created_unix_ms = s.ColumnInt64(9);
  return alignment;
}

}  // namespace

std::unique_ptr<SqliteDatabase> SqliteDatabase::Open(const std::string& path,
                                                     const SqliteOpenOptions& options) {
  ARPOS_CHECK(options.Check(), "invalid store options (busy_timeout_ms must be >= 0)");
  if (path.empty()) ARPOS_INPUT_ERROR("store path is empty");
  const bool in_memory = path == ":memory:";
  if (!in_memory) {
    std::error_code ec;
    const fs::file_status status = fs::status(path, ec);
    if (!fs::exists(status) && !options.create_if_missing) {
      ARPOS_INPUT_ERROR("no store at " << path);
    }
    if (fs::is_directory(status)) ARPOS_INPUT_ERROR(path << ": is a folder, not a store file");
    CheckStoreLocation(path, fs::exists(status));
  }

  sqlite3* raw = nullptr;
  const int flags = SQLITE_OPEN_READWRITE | (options.create_if_missing ? SQLITE_OPEN_CREATE : 0);
  const int rc = sqlite3_open_v2(path.c_str(), &raw, flags, nullptr);
  std::unique_ptr<sqlite3, SqliteCloser> db(raw);
  if (rc != SQLITE_OK) {
    ARPOS_INPUT_ERROR(path << ": cannot open store: "
                           << (raw != nullptr ? sqlite3_errmsg(raw) : sqlite3_errstr(rc)));
  }
  if (!in_memory && sqlite3_db_readonly(raw, "main") == 1) {
    // SQLite fell back to reading only (a read-only mount, say): every write
    // would fail later, after the work it was to store.
    throw StoreAccessError(StoreAccessProblem(SQLITE_READONLY, path, "opened read-only"), SQLITE_READONLY);
  }
  ARPOS_SQLITE_CHECK(raw, sqlite3_extended_result_codes(raw, 1), "sqlite3_extended_result_codes");
  ARPOS_SQLITE_CHECK(raw, sqlite3_busy_timeout(raw, options.busy_timeout_ms),
                     "sqlite3_busy_timeout");

  // Nothing may be written before this check: a newer store must stay
  // byte-for-byte untouched (switching to WAL alone rewrites the header).
  CheckStoreCompatible(raw, path);

  if (!in_memory) {
    const std::string mode = QueryText(raw, "PRAGMA journal_mode = WAL");
    if (mode != "wal") {
      ARPOS_WARN(path << ": could not switch the store to WAL (journal mode is '" << mode
                      << "'); continuing with synchronous=FULL");
    }
  }
  ExecSql(raw, "PRAGMA synchronous = FULL");
  MigrateSchema(raw, path);
  ExecSql(raw, "PRAGMA foreign_keys = ON");
  ARPOS_CHECK(QueryInt64(raw, "PRAGMA foreign_keys") == 1,
              "this SQLite build cannot enforce foreign keys");
  return std::unique_ptr<SqliteDatabase>(new SqliteDatabase(db.release(), path));
}

SqliteDatabase::SqliteDatabase(sqlite3* db, std::string path) : db_(db), path_(std::move(path)) {}

SqliteDatabase::~SqliteDatabase() {
  statements_.clear();  // finalize before close, or close fails with SQLITE_BUSY
  sqlite3_close(db_);
}

SqliteStatement& SqliteDatabase::Prepared(const char* sql) {
  auto it = statements_.find(sql);
  if (it == statements_.end()) {
    it = statements_.emplace(sql, std::make_unique<SqliteStatement>(db_, sql)).first;
  }
  return *it->second;
}

std::int64_t SqliteDatabase::LastInsertRowId() const { return sqlite3_last_insert_rowid(db_); }

StoreInfo SqliteDatabase::Info() {
  StoreInfo info;
  info.path = path_;
  info.schema_version = ReadSchemaVersion(db_);
  info.program_schema_version = LatestSchemaVersion();
  info.journal_mode = QueryText(db_, "PRAGMA journal_mode");
  info.size_bytes = QueryInt64(db_, "PRAGMA page_count") * QueryInt64(db_, "PRAGMA page_size");
  std::vector<std::string> tables;
  {
    SqliteStatementGuard s(
        Prepared("SELECT name FROM sqlite_master WHERE type = 'table' AND name NOT LIKE 'sqlite_%' "
                 "ORDER BY name"));
    while (s->Step()) tables.push_back(s->ColumnText(0));
  }
  for (const std::string& table : tables) {
    // Names come from sqlite_master; quoting guards against odd characters.
    std::string quoted = "\"";
    for (char c : table) quoted += (c == '"') ? std::string("\"\"") : std::string(1, c);
    quoted += "\"";
    info.table_row_counts.emplace_back(table, QueryInt64(db_, "SELECT COUNT(*) FROM " + quoted));
  }
  return info;
}

void SqliteDatabase::WithTransaction(const std::function<void()>& body) {
  SqliteTransaction transaction(db_);
  body();
  transaction.Commit();
}

// ---------------------------------------------------------------- patients

PatientId SqliteDatabase::AddPatient(const PatientRecord& patient) {
  ARPOS_CHECK(!patient.external_id.empty(), "a patient needs a non-empty external id");
  SqliteStatementGuard s(Prepared(
      "INSERT INTO patients (external_id, display_name, created_unix_ms) VALUES (?1, ?2, ?3)"));
  s->BindText(1, patient.external_id);
  s->BindText(2, patient.display_name);
  s->BindInt64(3, OrNow(patient.created_unix_ms));
  s->Execute();
  return PatientId(LastInsertRowId());
}

std::optional<PatientRecord> SqliteDatabase::GetPatient(PatientId id) {
  static const std::string sql = std::string(kPatientColumns) + "WHERE patient_id = ?1";
  SqliteStatementGuard s(Prepared(sql.c_str()));
  s->BindId(1, id);
  if (!s->Step()) return std::nullopt;
  return ReadPatient(*s);
}

std::optional<PatientRecord> SqliteDatabase::FindPatient(const std::string& external_id) {
  static const std::string sql = std::string(kPatientColumns) + "WHERE external_id = ?1";
  SqliteStatementGuard s(Prepared(sql.c_str()));
  s->BindText(1, external_id);
  if (!s->Step()) return std::nullopt;
  return ReadPatient(*s);
}

// ---------------------------------------------------------------- plans

PlanId SqliteDatabase::AddPlan(const PlanRecord& plan) {
  ARPOS_CHECK(!plan.name.empty(), "a plan needs a non-empty name");
  const Blob mesh = EncodeTriangleMesh(plan.reference_model);
  const Blob target = EncodePose(plan.room_from_model_target);
  SqliteStatementGuard s(
      Prepared("INSERT INTO plans (patient_id, name, reference_model_name, reference_model_mesh, "
               "room_from_model_target, created_unix_ms) VALUES (?1, ?2, ?3, ?4, ?5, ?6)"));
  s->BindId(1, plan.patient_id);
  s->BindText(2, plan.name);
  s->BindText(3, plan.reference_model_name);
  s->BindBlob(4, mesh);
  s->BindBlob(5, target);
  s->BindInt64(6, OrNow(plan.created_unix_ms));
  s->Execute();
  return PlanId(LastInsertRowId());
}

std::optional<PlanRecord> SqliteDatabase::GetPlan(PlanId id) {
  SqliteStatementGuard s(
      Prepared("SELECT patient_id, name, reference_model_name, reference_model_mesh, "
               "room_from_model_target, created_unix_ms, approved_by, approved_unix_ms, approval_note "
               "FROM plans WHERE plan_id = ?1"));
  s->BindId(1, id);
  if (!s->Step()) return std::nullopt;
  PlanRecord plan;
  plan.id = id;
  plan.patient_id = PatientId(s->ColumnInt64(0));
  plan.name = s->ColumnText(1);
  plan.reference_model_name = s->ColumnText(2);
  plan.reference_model = DecodeTriangleMesh(
      s->ColumnBlob(3), Context("plans.reference_model_mesh", "plan", id.value()));
  plan.room_from_model_target =
      DecodePose(s->ColumnBlob(4), Context("plans.room_from_model_target", "plan", id.value()));
  plan.created_unix_ms = s->ColumnInt64(5);
  if (!s->ColumnIsNull(7)) {
    plan.approved_by = s->ColumnIsNull(6) ? "" : s->ColumnText(6);
    plan.approved_unix_ms = s->ColumnInt64(7);
  }
  plan.approval_note = s->ColumnText(8);
  return plan;
}

void SqliteDatabase::ApprovePlan(PlanId id, const std::string& by, const std::string& note,
                                 std::int64_t approved_unix_ms) {
  ARPOS_CHECK(!by.empty(), "a plan's approval names who approved it");
  SqliteStatementGuard s(
      Prepared("UPDATE plans SET approved_by = ?1, approved_unix_ms = ?2, approval_note = ?3 "
               "WHERE plan_id = ?4 AND approved_unix_ms IS NULL"));
  s->BindText(1, by);
  s->BindInt64(2, OrNow(approved_unix_ms));
  s->BindText(3, note);
  s->BindId(4, id);
  s->Execute();
  if (sqlite3_changes(db_) != 1) {
    throw Error(path_ + ": plan " + std::to_string(id.value()) + " does not exist or is already approved");
  }
}

std::vector<PlanSummary> SqliteDatabase::ListPlans(std::optional<PatientId> patient,
                                                   std::size_t limit) {
  SqliteStatementGuard s(
      Prepared("SELECT p.plan_id, p.patient_id, pt.external_id, p.name, p.created_unix_ms, "
               "(SELECT COUNT(*) FROM sessions AS s WHERE s.plan_id = p.plan_id), "
               "(SELECT COUNT(*) FROM room_maps AS m WHERE m.plan_id = p.plan_id), "
               "p.approved_by, p.approved_unix_ms "
               "FROM plans AS p JOIN patients AS pt ON pt.patient_id = p.patient_id "
               "WHERE ?1 IS NULL OR p.patient_id = ?1 "
               "ORDER BY p.created_unix_ms DESC, p.plan_id DESC LIMIT ?2"));
  s->BindOptionalId(1, patient);
  s->BindInt64(2, SqlLimit(limit));
  std::vector<PlanSummary> plans;
  while (s->Step()) {
    PlanSummary plan;
    plan.id = PlanId(s->ColumnInt64(0));
    plan.patient_id = PatientId(s->ColumnInt64(1));
    plan.patient_external_id = s->ColumnText(2);
    plan.name = s->ColumnText(3);
    plan.created_unix_ms = s->ColumnInt64(4);
    plan.num_sessions = s->ColumnInt64(5);
    plan.num_room_maps = s->ColumnInt64(6);
    if (!s->ColumnIsNull(8)) {
      plan.approved_by = s->ColumnIsNull(7) ? "" : s->ColumnText(7);
      plan.approved_unix_ms = s->ColumnInt64(8);
    }
    plans.push_back(std::move(plan));
  }
  return plans;
}

// ---------------------------------------------------------------- room maps

RoomMapId SqliteDatabase::AddRoomMap(const RoomMapRecord& room_map) {
  const std::size_t num_landmarks = room_map.landmarks_in_room.points.size();
  ARPOS_CHECK(room_map.landmark_descriptors.rows() == 0 ||
                  static_cast<std::size_t>(room_map.landmark_descriptors.rows()) == num_landmarks,
              "room map has " << num_landmarks << " landmarks but "
                              << room_map.landmark_descriptors.rows() << " descriptors");
  SqliteTransaction transaction(db_);
  {
    SqliteStatementGuard s(
        Prepared("INSERT INTO room_maps (plan_id, recording_id, origin_marker_id, marker_size_m, "
                 "mean_residual_px, max_residual_px, landmarks_in_room, landmark_descriptors, "
                 "created_unix_ms, camera_response, depth_correction, room_frame_tilt_sigma_deg, "
                 "room_frame_yaw_sigma_deg, room_frame_couch_sigma_mm) "
                 "VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14)"));
    s->BindId(1, room_map.plan_id);
    s->BindOptionalId(2, room_map.recording_id);
    s->BindInt64(3, room_map.origin_marker_id);
    s->BindDouble(4, room_map.marker_size_m);
    s->BindDouble(5, room_map.mean_residual_px);
    s->BindDouble(6, room_map.max_residual_px);
    if (num_landmarks > 0) {
      s->BindBlob(7, EncodePointCloud(room_map.landmarks_in_room));
    } else {
      s->BindNull(7);
    }
    if (room_map.landmark_descriptors.size() > 0) {
      s->BindBlob(8, EncodeByteMatrix(room_map.landmark_descriptors));
    } else {
      s->BindNull(8);
    }
    s->BindInt64(9, OrNow(room_map.created_unix_ms));
    BindTextOrNull(*s, 10, room_map.camera_response);
    BindTextOrNull(*s, 11, room_map.depth_correction);
    BindOptionalDouble(*s, 12, room_map.room_frame_tilt_sigma_deg);
    BindOptionalDouble(*s, 13, room_map.room_frame_yaw_sigma_deg);
    BindOptionalDouble(*s, 14, room_map.room_frame_couch_sigma_mm);
    s->Execute();
  }
  const RoomMapId id(LastInsertRowId());
  if (!room_map.surface.points.empty()) {
    ARPOS_CHECK(room_map.surface.normals.size() == room_map.surface.points.size() &&
                    room_map.surface_voxel_m > 0 && room_map.surface_voxel_m < 1,
                "room map surface: " << room_map.surface.points.size() << " points, "
                                     << room_map.surface.normals.size() << " normals, voxel "
                                     << room_map.surface_voxel_m << " m");
    SqliteStatementGuard s(
        Prepared("INSERT INTO room_map_surface (room_map_id, voxel_m, points) VALUES (?1, ?2, ?3)"));
    s->BindId(1, id);
    s->BindDouble(2, room_map.surface_voxel_m);
    s->BindBlob(3, EncodePointCloud(room_map.surface));
    s->Execute();
  }
  for (const RoomMapMarker& marker : room_map.markers) {
    SqliteStatementGuard s(Prepared(
        "INSERT INTO room_map_markers (room_map_id, marker_id, corners_in_room, residual_px, "
        "num_observations) VALUES (?1, ?2, ?3, ?4, ?5)"));
    s->BindId(1, id);
    s->BindInt64(2, marker.marker_id);
    s->BindBlob(3, EncodeCorners(marker.corners_in_room));
    s->BindDouble(4, marker.residual_px);
    s->BindInt64(5, marker.num_observations);
    s->Execute();
  }
  transaction.Commit();
  return id;
}

std::optional<RoomMapRecord> SqliteDatabase::GetRoomMap(RoomMapId id) {
  RoomMapRecord room_map;
  {
    SqliteStatementGuard s(
        Prepared("SELECT plan_id, recording_id, origin_marker_id, marker_size_m, mean_residual_px, "
                 "max_residual_px, landmarks_in_room, landmark_descriptors, created_unix_ms, "
                 "camera_response, depth_correction, room_frame_tilt_sigma_deg, "
                 "room_frame_yaw_sigma_deg, room_frame_couch_sigma_mm "
                 "FROM room_maps WHERE room_map_id = ?1"));
    s->BindId(1, id);
    if (!s->Step()) return std::nullopt;
    room_map.id = id;
    room_map.plan_id = PlanId(s->ColumnInt64(0));
    room_map.recording_id = OptionalId<RecordingId>(*s, 1);
    room_map.origin_marker_id = static_cast<int>(s->ColumnInt64(2));
    room_map.marker_size_m = s->ColumnDouble(3);
    room_map.mean_residual_px = s->ColumnDouble(4);
    room_map.max_residual_px = s->ColumnDouble(5);
    if (!s->ColumnIsNull(6)) {
      room_map.landmarks_in_room = DecodePointCloud(
          s->ColumnBlob(6), Context("room_maps.landmarks_in_room", "room map", id.value()));
    }
    if (!s->ColumnIsNull(7)) {
      room_map.landmark_descriptors = DecodeByteMatrix(
          s->ColumnBlob(7), Context("room_maps.landmark_descriptors", "room map", id.value()));
    }
    room_map.created_unix_ms = s->ColumnInt64(8);
    if (!s->ColumnIsNull(9)) room_map.camera_response = s->ColumnText(9);
    if (!s->ColumnIsNull(10)) room_map.depth_correction = s->ColumnText(10);
    room_map.room_frame_tilt_sigma_deg = OptionalDouble(*s, 11);
    room_map.room_frame_yaw_sigma_deg = OptionalDouble(*s, 12);
    room_map.room_frame_couch_sigma_mm = OptionalDouble(*s, 13);
  }
  {
    SqliteStatementGuard s(Prepared("SELECT voxel_m, points FROM room_map_surface WHERE room_map_id = ?1"));
    s->BindId(1, id);
    if (s->Step()) {
      const std::string what = Context("room_map_surface.points", "room map", id.value());
      room_map.surface_voxel_m = s->ColumnDouble(0);
      room_map.surface = DecodePointCloud(s->ColumnBlob(1), what);
      if (room_map.surface.normals.size() != room_map.surface.points.size()) {
        throw CorruptBlobError(what + ": " + std::to_string(room_map.surface.points.size()) + " points but " +
                               std::to_string(room_map.surface.normals.size()) + " normals");
      }
    }
  }
  SqliteStatementGuard s(Prepared(
      "SELECT marker_id, corners_in_room, residual_px, num_observations FROM room_map_markers "
      "WHERE room_map_id = ?1 ORDER BY marker_id"));
  s->BindId(1, id);
  while (s->Step()) {
    RoomMapMarker marker;
    marker.marker_id = static_cast<int>(s->ColumnInt64(0));
    marker.corners_in_room =
        DecodeCorners(s->ColumnBlob(1), "room_map_markers.corners_in_room of marker " +
                                            std::to_string(marker.marker_id) + " in room map " +
                                            std::to_string(id.value()));
    marker.residual_px = s->ColumnDouble(2);
    marker.num_observations = static_cast<int>(s->ColumnInt64(3));
    room_map.markers.push_back(marker);
  }
  return room_map;
}

std::optional<RoomMapId> SqliteDatabase::LatestRoomMap(PlanId plan) {
  SqliteStatementGuard s(
      Prepared("SELECT room_map_id FROM room_maps WHERE plan_id = ?1 "
               "ORDER BY created_unix_ms DESC, room_map_id DESC LIMIT 1"));
  s->BindId(1, plan);
  if (!s->Step()) return std::nullopt;
  return RoomMapId(s->ColumnInt64(0));
}

// ---------------------------------------------------------------- sessions

SessionId SqliteDatabase::AddSession(const SessionRecord& session) {
  ARPOS_CHECK((session.status == SessionStatus::kOpen) == !session.ended_unix_ms.has_value(),
              "a session has an end time exactly when it is no longer open (status "
                  << ToString(session.status) << ")");
  SqliteStatementGuard s(
      Prepared("INSERT INTO sessions (plan_id, fraction, operator_name, started_unix_ms, status, "
               "ended_unix_ms, notes, on_unapproved_plan, ended_by, end_reason) "
               "VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10)"));
  s->BindId(1, session.plan_id);
  s->BindInt64(2, session.fraction);
  s->BindText(3, session.operator_name);
  s->BindInt64(4, OrNow(session.started_unix_ms));
  s->BindText(5, ToString(session.status));
  if (session.ended_unix_ms) {
    s->BindInt64(6, *session.ended_unix_ms);
  } else {
    s->BindNull(6);
  }
  s->BindText(7, session.notes);
  s->BindInt64(8, session.on_unapproved_plan ? 1 : 0);
  s->BindText(9, session.ended_by);
  s->BindText(10, session.end_reason);
  s->Execute();
  return SessionId(LastInsertRowId());
}

std::optional<SessionRecord> SqliteDatabase::GetSession(SessionId id) {
  static const std::string sql = std::string(kSessionColumns) + "WHERE session_id = ?1";
  SqliteStatementGuard s(Prepared(sql.c_str()));
  s->BindId(1, id);
  if (!s->Step()) return std::nullopt;
  return ReadSession(*s);
}

std::vector<SessionRecord> SqliteDatabase::ListSessions(std::optional<PlanId> plan,
                                                        std::size_t limit) {
  static const std::string sql = std::string(kSessionColumns) +
                                 "WHERE ?1 IS NULL OR plan_id = ?1 "
                                 "ORDER BY started_unix_ms DESC, session_id DESC LIMIT ?2";
  SqliteStatementGuard s(Prepared(sql.c_str()));
  s->BindOptionalId(1, plan);
  s->BindInt64(2, SqlLimit(limit));
  std::vector<SessionRecord> sessions;
  while (s->Step()) sessions.push_back(ReadSession(*s));
  return sessions;
}

void SqliteDatabase::FinishSession(SessionId id, SessionStatus status, std::int64_t ended_unix_ms,
                                   const std::string& ended_by, const std::string& reason) {
  ARPOS_CHECK(status != SessionStatus::kOpen,
              "FinishSession needs status completed or aborted, not open");
  SqliteStatementGuard s(
      Prepared("UPDATE sessions SET status = ?1, ended_unix_ms = ?2, ended_by = ?4, end_reason = ?5 "
               "WHERE session_id = ?3 AND status = 'open'"));
  s->BindText(1, ToString(status));
  s->BindInt64(2, OrNow(ended_unix_ms));
  s->BindId(3, id);
  s->BindText(4, ended_by);
  s->BindText(5, reason);
  s->Execute();
  if (sqlite3_changes(db_) != 1) {
    throw Error(path_ + ": session " + std::to_string(id.value()) +
                " does not exist or is no longer open");
  }
}

std::int64_t SqliteDatabase::BeginSessionActivity(const SessionActivity& activity) {
  SqliteStatementGuard s(
      Prepared("INSERT INTO session_activity (session_id, pid, host, command, started_unix_ms) "
               "VALUES (?1, ?2, ?3, ?4, ?5)"));
  s->BindId(1, activity.session_id);
  s->BindInt64(2, activity.pid);
  s->BindText(3, activity.host);
  s->BindText(4, activity.command);
  s->BindInt64(5, OrNow(activity.started_unix_ms));
  s->Execute();
  return LastInsertRowId();
}

void SqliteDatabase::EndSessionActivity(std::int64_t activity_id) {
  SqliteStatementGuard s(Prepared("DELETE FROM session_activity WHERE activity_id = ?1"));
  s->BindInt64(1, activity_id);
  s->Execute();
}

std::vector<SessionActivity> SqliteDatabase::ListSessionActivities() {
  SqliteStatementGuard s(
      Prepared("SELECT activity_id, session_id, pid, host, command, started_unix_ms "
               "FROM session_activity ORDER BY activity_id"));
  std::vector<SessionActivity> out;
  while (s->Step()) {
    SessionActivity a;
    a.id = s->ColumnInt64(0);
    a.session_id = SessionId(s->ColumnInt64(1));
    a.pid = s->ColumnInt64(2);
    a.host = s->ColumnText(3);
    a.command = s->ColumnText(4);
    a.started_unix_ms = s->ColumnInt64(5);
    out.push_back(std::move(a));
  }
  return out;
}

// ---------------------------------------------------------------- recordings

RecordingId SqliteDatabase::AddRecording(const RecordingRecord& recording) {
  const bool is_room = recording.kind == RecordingKind::kRoom;
  ARPOS_CHECK(is_room ? (recording.plan_id && !recording.session_id)
                      : (recording.session_id && !recording.plan_id),
              "a " << ToString(recording.kind) << " recording belongs to "
                   << (is_room ? "a plan (plan_id only)" : "a session (session_id only)"));
  const RecordingIntrinsics& k = recording.intrinsics;
  SqliteStatementGuard s(Prepared(
      "INSERT INTO recordings (plan_id, session_id, kind, name, path, frame_count, width, "
      "height, fx, fy, cx, cy, k1, k2, p1, p2, k3, depth_scale, created_unix_ms) "
      "VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15, ?16, ?17, "
      "?18, ?19)"));
  s->BindOptionalId(1, recording.plan_id);
  s->BindOptionalId(2, recording.session_id);
  s->BindText(3, ToString(recording.kind));
  s->BindText(4, recording.name);
  s->BindText(5, recording.path);
  s->BindInt64(6, recording.frame_count);
  s->BindInt64(7, k.width);
  s->BindInt64(8, k.height);
  s->BindDouble(9, k.fx);
  s->BindDouble(10, k.fy);
  s->BindDouble(11, k.cx);
  s->BindDouble(12, k.cy);
  for (int i = 0; i < 5; ++i) s->BindDouble(13 + i, k.distortion[i]);
  s->BindDouble(18, k.depth_scale);
  s->BindInt64(19, OrNow(recording.created_unix_ms));
  s->Execute();
  return RecordingId(LastInsertRowId());
}

std::optional<RecordingRecord> SqliteDatabase::GetRecording(RecordingId id) {
  SqliteStatementGuard s(Prepared(
      "SELECT plan_id, session_id, kind, name, path, frame_count, width, height, fx, fy, cx, "
      "cy, k1, k2, p1, p2, k3, depth_scale, created_unix_ms FROM recordings "
      "WHERE recording_id = ?1"));
  s->BindId(1, id);
  if (!s->Step()) return std::nullopt;
  RecordingRecord recording;
  recording.id = id;
  recording.plan_id = OptionalId<PlanId>(*s, 0);
  recording.session_id = OptionalId<SessionId>(*s, 1);
  recording.kind = ParseRecordingKind(s->ColumnText(2));
  recording.name = s->ColumnText(3);
  recording.path = s->ColumnText(4);
  recording.frame_count = s->ColumnInt64(5);
  RecordingIntrinsics& k = recording.intrinsics;
  k.width = static_cast<int>(s->ColumnInt64(6));
  k.height = static_cast<int>(s->ColumnInt64(7));
  k.fx = s->ColumnDouble(8);
  k.fy = s->ColumnDouble(9);
  k.cx = s->ColumnDouble(10);
  k.cy = s->ColumnDouble(11);
  for (int i = 0; i < 5; ++i) k.distortion[i] = s->ColumnDouble(12 + i);
  k.depth_scale = s->ColumnDouble(17);
  recording.created_unix_ms = s->ColumnInt64(18);
  return recording;
}

// ---------------------------------------------------------------- body marker maps

BodyMarkerMapId SqliteDatabase::AddBodyMarkerMap(const BodyMarkerMapRecord& map) {
  SqliteTransaction transaction(db_);
  {
    SqliteStatementGuard s(Prepared(
        "INSERT INTO body_marker_maps (session_id, recording_id, marker_size_m, "
        "mean_residual_px, max_residual_px, created_unix_ms) VALUES (?1, ?2, ?3, ?4, ?5, ?6)"));
    s->BindId(1, map.session_id);
    s->BindOptionalId(2, map.recording_id);
    s->BindDouble(3, map.marker_size_m);
    s->BindDouble(4, map.mean_residual_px);
    s->BindDouble(5, map.max_residual_px);
    s->BindInt64(6, OrNow(map.created_unix_ms));
    s->Execute();
  }
  const BodyMarkerMapId id(LastInsertRowId());
  for (const BodyMarker& marker : map.markers) {
    SqliteStatementGuard s(
        Prepared("INSERT INTO body_marker_poses (body_marker_map_id, marker_id, body_from_marker, "
                 "residual_px, num_observations) VALUES (?1, ?2, ?3, ?4, ?5)"));
    s->BindId(1, id);
    s->BindInt64(2, marker.marker_id);
    s->BindBlob(3, EncodePose(marker.body_from_marker));
    s->BindDouble(4, marker.residual_px);
    s->BindInt64(5, marker.num_observations);
    s->Execute();
    if (marker.motion_m > 0) {
      SqliteStatementGuard m(
          Prepared("INSERT INTO body_marker_motion (body_marker_map_id, marker_id, motion_m) VALUES (?1, ?2, ?3)"));
      m->BindId(1, id);
      m->BindInt64(2, marker.marker_id);
      m->BindDouble(3, marker.motion_m);
      m->Execute();
      if (marker.HasMotionDirection()) {
        const Eigen::Vector3d& d = marker.motion_direction;
        ARPOS_CHECK(d.allFinite() && std::abs(d.squaredNorm() - 1) < 1e-9,
                    "body marker map: sticker " << marker.marker_id
                                                << "'s motion direction is not a unit vector");
        SqliteStatementGuard dir(Prepared(
            "INSERT INTO body_marker_motion_direction (body_marker_map_id, marker_id, x, y, z) "
            "VALUES (?1, ?2, ?3, ?4, ?5)"));
        dir->BindId(1, id);
        dir->BindInt64(2, marker.marker_id);
        dir->BindDouble(3, d.x());
        dir->BindDouble(4, d.y());
        dir->BindDouble(5, d.z());
        dir->Execute();
      }
    }
  }
  if (!map.moving_surface_patches.empty()) {
    Eigen::MatrixXd centres(map.moving_surface_patches.size(), 3);
    for (size_t i = 0; i < map.moving_surface_patches.size(); ++i) {
      centres.row(static_cast<Eigen::Index>(i)) = map.moving_surface_patches[i].transpose();
    }
    SqliteStatementGuard m(Prepared(
        "INSERT INTO body_surface_motion (body_marker_map_id, patch_m, moving_patches) VALUES (?1, ?2, ?3)"));
    m->BindId(1, id);
    m->BindDouble(2, map.surface_patch_m);
    m->BindBlob(3, EncodeMatrix(centres));
    m->Execute();
  }
  if (!map.room_landmarks.points.empty()) {
    ARPOS_CHECK(map.room_landmark_descriptors.rows() ==
                        static_cast<Eigen::Index>(map.room_landmarks.points.size()) &&
                    map.room_landmark_descriptors.cols() == 32,
                "body marker map room landmarks: "
                    << map.room_landmarks.points.size() << " points but "
                    << map.room_landmark_descriptors.rows() << " x "
                    << map.room_landmark_descriptors.cols() << " descriptors");
    ARPOS_CHECK(
        map.room_landmarks_placement_sigma_m >= 0 && map.room_landmarks_placement_sigma_m < 1 &&
            map.room_landmarks_position_sigma_m >= 0 && map.room_landmarks_position_sigma_m < 1,
        "body marker map room landmarks: sigmas " << map.room_landmarks_placement_sigma_m << ", "
                                                  << map.room_landmarks_position_sigma_m << " m");
    SqliteStatementGuard m(
        Prepared("INSERT INTO body_scan_landmarks (body_marker_map_id, placement_sigma_m, "
                 "position_sigma_m, points, "
                 "descriptors) VALUES (?1, ?2, ?3, ?4, ?5)"));
    m->BindId(1, id);
    m->BindDouble(2, map.room_landmarks_placement_sigma_m);
    m->BindDouble(3, map.room_landmarks_position_sigma_m);
    m->BindBlob(4, EncodePointCloud(map.room_landmarks));
    m->BindBlob(5, EncodeByteMatrix(map.room_landmark_descriptors));
    m->Execute();
  }
  transaction.Commit();
  return id;
}

std::optional<BodyMarkerMapRecord> SqliteDatabase::GetBodyMarkerMap(BodyMarkerMapId id) {
  BodyMarkerMapRecord map;
  {
    SqliteStatementGuard s(Prepared(
        "SELECT session_id, recording_id, marker_size_m, mean_residual_px, max_residual_px, "
        "created_unix_ms FROM body_marker_maps WHERE body_marker_map_id = ?1"));
    s->BindId(1, id);
    if (!s->Step()) return std::nullopt;
    map.id = id;
    map.session_id = SessionId(s->ColumnInt64(0));
    map.recording_id = OptionalId<RecordingId>(*s, 1);
    map.marker_size_m = s->ColumnDouble(2);
    map.mean_residual_px = s->ColumnDouble(3);
    map.max_residual_px = s->ColumnDouble(4);
    map.created_unix_ms = s->ColumnInt64(5);
  }
  SqliteStatementGuard s(Prepared(
      "SELECT marker_id, body_from_marker, residual_px, num_observations FROM body_marker_poses "
      "WHERE body_marker_map_id = ?1 ORDER BY marker_id"));
  s->BindId(1, id);
  while (s->Step()) {
    BodyMarker marker;
    marker.marker_id = static_cast<int>(s->ColumnInt64(0));
    marker.body_from_marker =
        DecodePose(s->ColumnBlob(1), "body_marker_poses.body_from_marker of marker " +
                                         std::to_string(marker.marker_id) + " in body marker map " +
                                         std::to_string(id.value()));
    marker.residual_px = s->ColumnDouble(2);
    marker.num_observations = static_cast<int>(s->ColumnInt64(3));
    map.markers.push_back(marker);
  }
  {
    SqliteStatementGuard m(
        Prepared("SELECT marker_id, motion_m FROM body_marker_motion WHERE body_marker_map_id = ?1"));
    m->BindId(1, id);
    while (m->Step()) {
      const int marker_id = static_cast<int>(m->ColumnInt64(0));
      for (BodyMarker& marker : map.markers) {
        if (marker.marker_id == marker_id) marker.motion_m = m->ColumnDouble(1);
      }
    }
  }
  {
    SqliteStatementGuard m(
        Prepared("SELECT marker_id, x, y, z FROM body_marker_motion_direction WHERE "
                 "body_marker_map_id = ?1"));
    m->BindId(1, id);
    while (m->Step()) {
      const int marker_id = static_cast<int>(m->ColumnInt64(0));
      const Eigen::Vector3d d(m->ColumnDouble(1), m->ColumnDouble(2), m->ColumnDouble(3));
      for (BodyMarker& marker : map.markers) {
        if (marker.marker_id == marker_id) marker.motion_direction = d.normalized();
      }
    }
  }
  SqliteStatementGuard m(
      Prepared("SELECT patch_m, moving_patches FROM body_surface_motion WHERE body_marker_map_id = ?1"));
  m->BindId(1, id);
  if (m->Step()) {
    map.surface_patch_m = m->ColumnDouble(0);
    const Eigen::MatrixXd centres = DecodeMatrix(
        m->ColumnBlob(1), "body_surface_motion.moving_patches of body marker map " + std::to_string(id.value()));
    if (centres.rows() > 0 && centres.cols() != 3) {
      throw CorruptBlobError("body_surface_motion.moving_patches of body marker map " +
                             std::to_string(id.value()) + ": " + std::to_string(centres.cols()) +
                             " columns, expected 3");
    }
    for (Eigen::Index i = 0; i < centres.rows(); ++i) map.moving_surface_patches.push_back(centres.row(i).transpose());
  }
  SqliteStatementGuard l(Prepared(
      "SELECT placement_sigma_m, position_sigma_m, points, descriptors FROM body_scan_landmarks "
      "WHERE body_marker_map_id = ?1"));
  l->BindId(1, id);
  if (l->Step()) {
    const std::string what = "body_scan_landmarks of body marker map " + std::to_string(id.value());
    map.room_landmarks_placement_sigma_m = l->ColumnDouble(0);
    map.room_landmarks_position_sigma_m = l->ColumnDouble(1);
    map.room_landmarks = DecodePointCloud(l->ColumnBlob(2), what + " (points)");
    map.room_landmark_descriptors = DecodeByteMatrix(l->ColumnBlob(3), what + " (descriptors)");
    if (map.room_landmark_descriptors.rows() !=
            static_cast<Eigen::Index>(map.room_landmarks.points.size()) ||
        (map.room_landmark_descriptors.rows() > 0 && map.room_landmark_descriptors.cols() != 32)) {
      throw CorruptBlobError(what + ": " + std::to_string(map.room_landmarks.points.size()) +
                             " points but " + std::to_string(map.room_landmark_descriptors.rows()) +
                             " x " + std::to_string(map.room_landmark_descriptors.cols()) +
                             " descriptors");
    }
  }
  return map;
}

// ---------------------------------------------------------------- reconstructions

ReconstructionId SqliteDatabase::AddReconstruction(const ReconstructionRecord& reconstruction) {
  const Blob cloud = EncodePointCloud(reconstruction.cloud);
  SqliteStatementGuard s(
      Prepared("INSERT INTO reconstructions (session_id, recording_id, cloud, mesh, num_points, "
               "num_triangles, num_frames_used, voxel_size_m, created_unix_ms) "
               "VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9)"));
  s->BindId(1, reconstruction.session_id);
  s->BindOptionalId(2, reconstruction.recording_id);
  s->BindBlob(3, cloud);
  if (reconstruction.mesh) {
    s->BindBlob(4, EncodeTriangleMesh(*reconstruction.mesh));
  } else {
    s->BindNull(4);
  }
  s->BindInt64(5, static_cast<std::int64_t>(reconstruction.cloud.points.size()));
  s->BindInt64(
      6, reconstruction.mesh ? static_cast<std::int64_t>(reconstruction.mesh->faces.size()) : 0);
  s->BindInt64(7, reconstruction.num_frames_used);
  s->BindDouble(8, reconstruction.voxel_size_m);
  s->BindInt64(9, OrNow(reconstruction.created_unix_ms));
  s->Execute();
  return ReconstructionId(LastInsertRowId());
}

std::optional<ReconstructionRecord> SqliteDatabase::GetReconstruction(ReconstructionId id) {
  SqliteStatementGuard s(
      Prepared("SELECT session_id, recording_id, cloud, mesh, num_points, num_triangles, "
               "num_frames_used, voxel_size_m, created_unix_ms FROM reconstructions "
               "WHERE reconstruction_id = ?1"));
  s->BindId(1, id);
  if (!s->Step()) return std::nullopt;
  ReconstructionRecord reconstruction;
  reconstruction.id = id;
  reconstruction.session_id = SessionId(s->ColumnInt64(0));
  reconstruction.recording_id = OptionalId<RecordingId>(*s, 1);
  const std::string cloud_context = Context("reconstructions.cloud", "reconstruction", id.value());
  reconstruction.cloud = DecodePointCloud(s->ColumnBlob(2), cloud_context);
  if (!s->ColumnIsNull(3)) {
    reconstruction.mesh = DecodeTriangleMesh(
        s->ColumnBlob(3), Context("reconstructions.mesh", "reconstruction", id.value()));
  }
  // The counts are denormalised for listings; a mismatch means the row was
  // tampered with or damaged.
  const auto num_points = static_cast<std::size_t>(s->ColumnInt64(4));
  const auto num_triangles = static_cast<std::size_t>(s->ColumnInt64(5));
  if (num_points != reconstruction.cloud.points.size() ||
      num_triangles != (reconstruction.mesh ? reconstruction.mesh->faces.size() : 0)) {
    throw CorruptBlobError(
        cloud_context + ": the blobs hold " + std::to_string(reconstruction.cloud.points.size()) +
        " points and " +
        std::to_string(reconstruction.mesh ? reconstruction.mesh->faces.size() : 0) +
        " triangles but the row says " + std::to_string(num_points) + " and " +
        std::to_string(num_triangles));
  }
  reconstruction.num_frames_used = s->ColumnInt64(6);
  reconstruction.voxel_size_m = s->ColumnDouble(7);
  reconstruction.created_unix_ms = s->ColumnInt64(8);
  return reconstruction;
}

std::vector<BodyMarkerMapId> SqliteDatabase::ListBodyMarkerMapIds(SessionId session) {
  SqliteStatementGuard s(Prepared(
      "SELECT body_marker_map_id FROM body_marker_maps WHERE session_id = ?1 ORDER BY body_marker_map_id"));
  s->BindId(1, session);
  std::vector<BodyMarkerMapId> ids;
  while (s->Step()) ids.emplace_back(s->ColumnInt64(0));
  return ids;
}

std::vector<ReconstructionId> SqliteDatabase::ListReconstructionIds(SessionId session) {
  SqliteStatementGuard s(Prepared(
      "SELECT reconstruction_id FROM reconstructions WHERE session_id = ?1 ORDER BY reconstruction_id"));
  s->BindId(1, session);
  std::vector<ReconstructionId> ids;
  while (s->Step()) ids.emplace_back(s->ColumnInt64(0));
  return ids;
}

// ---------------------------------------------------------------- alignments

AlignmentId SqliteDatabase::AddAlignment(const AlignmentRecord& alignment) {
  SqliteStatementGuard s(
      Prepared("INSERT INTO alignments (reconstruction_id, parent_alignment_id, method, "
               "reconstruction_from_model, fitness, rmse_m, num_inliers, options, created_unix_ms) "
               "VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9)"));
  s->BindId(1, alignment.reconstruction_id);
  s->BindOptionalId(2, alignment.parent_alignment_id);
  s->BindText(3, ToString(alignment.method));
  s->BindBlob(4, EncodePose(alignment.reconstruction_from_model));
  s->BindDouble(5, alignment.fitness);
  s->BindDouble(6, alignment.rmse_m);
  s->BindInt64(7, alignment.num_inliers);
  s->BindText(8, alignment.options);
  s->BindInt64(9, OrNow(alignment.created_unix_ms));
  s->Execute();
  return AlignmentId(LastInsertRowId());
}

std::optional<AlignmentRecord> SqliteDatabase::GetAlignment(AlignmentId id) {
  static const std::string sql = std::string(kAlignmentColumns) + "WHERE alignment_id = ?1";
  SqliteStatementGuard s(Prepared(sql.c_str()));
  s->BindId(1, id);
  if (!s->Step()) return std::nullopt;
  return ReadAlignment(*s);
}

std::vector<AlignmentRecord> SqliteDatabase::ListAlignments(ReconstructionId reconstruction) {
  static const std::string sql = std::string(kAlignmentColumns) +
                                 "WHERE reconstruction_id = ?1 "
                                 "ORDER BY created_unix_ms, alignment_id";
  SqliteStatementGuard s(Prepared(sql.c_str()));
  s->BindId(1, reconstruction);
  std::vector<AlignmentRecord> alignments;
  while (s->Step()) alignments.push_back(ReadAlignment(*s));
  return alignments;
}

// ---------------------------------------------------------------- tracking

TrackingRunId SqliteDatabase::AddTrackingRun(const TrackingRunRecord& run) {
  SqliteStatementGuard s(
      Prepared("INSERT INTO tracking_runs (session_id, alignment_id, recording_id, options, "
               "tolerance_translation_mm, tolerance_rotation_deg, started_unix_ms, sequence_name, "
               "summary) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9)"));
  s->BindId(1, run.session_id);
  s->BindOptionalId(2, run.alignment_id);
  s->BindOptionalId(3, run.recording_id);
  s->BindText(4, run.options);
  s->BindDouble(5, run.tolerance_translation_mm);
  s->BindDouble(6, run.tolerance_rotation_deg);
  s->BindInt64(7, OrNow(run.started_unix_ms));
  s->BindText(8, run.sequence_name);
  s->BindText(9, run.summary);
  s->Execute();
  return TrackingRunId(LastInsertRowId());
}

std::optional<TrackingRunRecord> SqliteDatabase::GetTrackingRun(TrackingRunId id) {
  SqliteStatementGuard s(Prepared(
      "SELECT session_id, alignment_id, recording_id, options, tolerance_translation_mm, "
      "tolerance_rotation_deg, started_unix_ms, sequence_name, summary FROM tracking_runs "
      "WHERE tracking_run_id = ?1"));
  s->BindId(1, id);
  if (!s->Step()) return std::nullopt;
  TrackingRunRecord run;
  run.id = id;
  run.session_id = SessionId(s->ColumnInt64(0));
  run.alignment_id = OptionalId<AlignmentId>(*s, 1);
  run.recording_id = OptionalId<RecordingId>(*s, 2);
  run.options = s->ColumnText(3);
  run.tolerance_translation_mm = s->ColumnDouble(4);
  run.tolerance_rotation_deg = s->ColumnDouble(5);
  run.started_unix_ms = s->ColumnInt64(6);
  run.sequence_name = s->ColumnText(7);
  run.summary = s->ColumnText(8);
  return run;
}

std::vector<TrackingRunId> SqliteDatabase::ListTrackingRunIds(SessionId session) {
  SqliteStatementGuard s(Prepared(
      "SELECT tracking_run_id FROM tracking_runs WHERE session_id = ?1 ORDER BY tracking_run_id"));
  s->BindId(1, session);
  std::vector<TrackingRunId> ids;
  while (s->Step()) ids.emplace_back(s->ColumnInt64(0));
  return ids;
}

void SqliteDatabase::AppendTrackingFrames(TrackingRunId run,
                                          const std::vector<TrackingFrameRecord>& frames) {
  for (const TrackingFrameRecord& frame : frames) {
    const bool lost = frame.status == TrackingFrameStatus::kLost;
    ARPOS_CHECK(lost != frame.room_from_model.has_value() && lost != frame.correction.has_value(),
                "tracking frame " << frame.frame_index << " has status " << ToString(frame.status)
                                  << ": a frame has a pose and a correction exactly when it is "
                                     "not lost");
    const bool known_source =
        frame.source == "tracked" || frame.source == "carried" || frame.source == "lost";
    ARPOS_CHECK(known_source && lost == (frame.source == "lost"),
                "tracking frame " << frame.frame_index << " has status " << ToString(frame.status)
                                  << " and source '" << frame.source
                                  << "': the source is 'tracked', 'carried' or 'lost', and 'lost' "
                                     "exactly when the status is lost");
    const bool has_uncertainty = frame.uncertainty_translation_mm.has_value();
    ARPOS_CHECK(has_uncertainty == frame.uncertainty_rotation_deg.has_value() && lost != has_uncertainty &&
                    (!has_uncertainty ||
                     (*frame.uncertainty_translation_mm >= 0 && *frame.uncertainty_rotation_deg >= 0)),
                "tracking frame " << frame.frame_index << " has status " << ToString(frame.status)
                                  << ": a frame has an uncertainty (translation and rotation, "
                                     ">= 0) exactly when it is not lost");
    // NaN would be stored as NULL: say what is wrong instead of "NOT NULL failed".
    ARPOS_CHECK(frame.total_ms >= 0, "tracking frame " << frame.frame_index << " has total_ms "
                                                       << frame.total_ms << "; it must be >= 0");
  }
  SqliteTransaction transaction(db_);
  for (const TrackingFrameRecord& frame : frames) {
    SqliteStatementGuard s(
        Prepared("INSERT INTO tracking_frames (tracking_run_id, frame_index, timestamp_s, status, "
                 "room_from_model, correction_tx_mm, correction_ty_mm, correction_tz_mm, "
                 "correction_rx_deg, correction_ry_deg, correction_rz_deg, room_from_camera, "
                 "source, uncertainty_translation_mm, uncertainty_rotation_deg, total_ms, note) "
                 "VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15, ?16, "
                 "?17)"));
    s->BindId(1, run);
    s->BindInt64(2, frame.frame_index);
    s->BindDouble(3, frame.timestamp_s);
    s->BindText(4, ToString(frame.status));
    if (frame.room_from_model) {
      s->BindBlob(5, EncodePose(*frame.room_from_model));
    } else {
      s->BindNull(5);
    }
    for (int i = 0; i < 3; ++i) {
      if (frame.correction) {
        s->BindDouble(6 + i, frame.correction->translation_mm[i]);
        s->BindDouble(9 + i, frame.correction->rotation_deg[i]);
      } else {
        s->BindNull(6 + i);
        s->BindNull(9 + i);
      }
    }
    if (frame.room_from_camera) {
      s->BindBlob(12, EncodePose(*frame.room_from_camera));
    } else {
      s->BindNull(12);
    }
    s->BindText(13, frame.source);
    BindOptionalDouble(*s, 14, frame.uncertainty_translation_mm);
    BindOptionalDouble(*s, 15, frame.uncertainty_rotation_deg);
    s->BindDouble(16, frame.total_ms);
    s->BindText(17, frame.note);
    s->Execute();
  }
  transaction.Commit();
}

std::vector<TrackingFrameRecord> SqliteDatabase::GetTrackingFrames(TrackingRunId run) {
  SqliteStatementGuard s(Prepared(
      "SELECT frame_index, timestamp_s, status, room_from_model, correction_tx_mm, "
      "correction_ty_mm, correction_tz_mm, correction_rx_deg, correction_ry_deg, "
      "correction_rz_deg, room_from_camera, source, uncertainty_translation_mm, "
      "uncertainty_rotation_deg, total_ms, note FROM tracking_frames WHERE tracking_run_id = ?1 "
      "ORDER BY frame_index"));
  s->BindId(1, run);
  std::vector<TrackingFrameRecord> frames;
  while (s->Step()) {
    TrackingFrameRecord frame;
    frame.frame_index = s->ColumnInt64(0);
    frame.timestamp_s = s->ColumnDouble(1);
    frame.status = ParseTrackingFrameStatus(s->ColumnText(2));
    if (!s->ColumnIsNull(3)) {
      frame.room_from_model =
          DecodePose(s->ColumnBlob(3), "tracking_frames.room_from_model of frame " +
                                           std::to_string(frame.frame_index) + " in tracking run " +
                                           std::to_string(run.value()));
    }
    if (!s->ColumnIsNull(4)) {
      Correction6Dof correction;
      for (int i = 0; i < 3; ++i) {
        correction.translation_mm[i] = s->ColumnDouble(4 + i);
        correction.rotation_deg[i] = s->ColumnDouble(7 + i);
      }
      frame.correction = correction;
    }
    if (!s->ColumnIsNull(10)) {
      frame.room_from_camera =
          DecodePose(s->ColumnBlob(10), "tracking_frames.room_from_camera of frame " +
                                            std::to_string(frame.frame_index) + " in tracking run " +
                                            std::to_string(run.value()));
    }
    frame.source = s->ColumnText(11);
    frame.uncertainty_translation_mm = OptionalDouble(*s, 12);
    frame.uncertainty_rotation_deg = OptionalDouble(*s, 13);
    frame.total_ms = s->ColumnDouble(14);
    frame.note = s->ColumnText(15);
    frames.push_back(std::move(frame));
  }
  return frames;
}

// ---------------------------------------------------------------- audit

AuditId SqliteDatabase::AppendAudit(const AuditEntry& entry) {
  ARPOS_CHECK(!entry.actor.empty() && !entry.action.empty(),
              "an audit entry needs an actor and an action");
  // The next id and the last entry's hash under the write lock, so the
  // entry's hash covers its final id (store/audit_chain.h).
  SqliteTransaction transaction(db_);
  AuditEntry e = entry;
  e.time_unix_ms = OrNow(entry.time_unix_ms);
  e.id = AuditId(QueryInt64(db_,
                            "SELECT MAX(COALESCE((SELECT seq FROM sqlite_sequence WHERE name = 'audit_log'), 0), "
                            "COALESCE((SELECT MAX(audit_id) FROM audit_log), 0)) + 1"));
  const std::string prev_hash =
      QueryText(db_, "SELECT COALESCE((SELECT entry_hash FROM audit_log ORDER BY audit_id DESC LIMIT 1), '')");
  // The row the entry is about, sealed as it is now (schema 8).
  const std::string row_hash = AuditedRowHash(db_, e.entity);
  SqliteStatementGuard s(
      Prepared("INSERT INTO audit_log (audit_id, time_unix_ms, actor, action, entity, details, prev_hash, "
               "entry_hash, row_hash) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9)"));
  s->BindId(1, e.id);
  s->BindInt64(2, e.time_unix_ms);
  s->BindText(3, e.actor);
  s->BindText(4, e.action);
  s->BindText(5, e.entity);
  s->BindText(6, e.details);
  s->BindText(7, prev_hash);
  s->BindText(8, AuditEntryHash(e, prev_hash, row_hash));
  s->BindText(9, row_hash);
  s->Execute();
  transaction.Commit();
  return e.id;
}

AuditVerification SqliteDatabase::VerifyAudit() { return VerifyAuditLog(db_); }

std::vector<AuditEntry> SqliteDatabase::ListAudit(AuditId after, std::size_t limit) {
  SqliteStatementGuard s(
      Prepared("SELECT audit_id, time_unix_ms, actor, action, entity, details FROM audit_log "
               "WHERE audit_id > ?1 ORDER BY audit_id LIMIT ?2"));
  s->BindId(1, after);
  s->BindInt64(2, SqlLimit(limit));
  std::vector<AuditEntry> entries;
  while (s->Step()) {
    AuditEntry entry;
    entry.id = AuditId(s->ColumnInt64(0));
    entry.time_unix_ms = s->ColumnInt64(1);
    entry.actor = s->ColumnText(2);
    entry.action = s->ColumnText(3);
    entry.entity = s->ColumnText(4);
    entry.details = s->ColumnText(5);
    entries.push_back(std::move(entry));
  }
  return entries;
}

}  // namespace arpos
