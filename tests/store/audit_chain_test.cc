// The audit log as a hash chain (schema version 6): every entry verifies;
// an entry changed, inserted, removed in the middle or at the end, a dropped
// trigger and a clinical row written past the program are each named by
// `arpos audit verify`; entries from before the chain are counted apart.
#include <gtest/gtest.h>
#include <sqlite3.h>

#include <filesystem>
#include <sstream>

#include "exe/cmd_store.h"
#include "store/audit_chain.h"
#include "store/migrator.h"
#include "store/sqlite_database.h"
#include "util/file.h"

namespace arpos {
namespace {

namespace fs = std::filesystem;

// Runs SQL on a raw connection (as a tool or someone with the file would).
void RawExec(const fs::path& path, const std::string& sql) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  char* error = nullptr;
  const int rc = sqlite3_exec(db, sql.c_str(), nullptr, nullptr, &error);
  const std::string message = error != nullptr ? error : "";
  sqlite3_free(error);
  sqlite3_close(db);
  ASSERT_EQ(rc, SQLITE_OK) << message << " in " << sql;
}

// A store with a patient, a plan-like history of audit entries, all written
// through the program.
fs::path WriteAuditedStore(const fs::path& dir) {
  const fs::path path = dir / "store.db";
  const auto db = SqliteDatabase::Open(path.string());
  PatientRecord patient;
  patient.external_id = "P-001";
  const PatientId id = db->AddPatient(patient);
  db->AppendAudit({AuditId(), 0, "tech", "add_patient", "patient:" + std::to_string(id.value()), "from a test"});
  db->AppendAudit({AuditId(), 0, "tech", "note", "", "details with\nnew lines, colons: and 12:34"});
  db->AppendAudit({AuditId(), 0, "physicist", "approve", "plan:1", ""});
  db->AppendAudit({AuditId(), 0, "therapist", "note", "", "last"});
  return path;
}

AuditVerification Verify(const fs::path& path) {
  SqliteOpenOptions options;
  options.create_if_missing = false;
  return SqliteDatabase::Open(path.string(), options)->VerifyAudit();
}

fs::path CopyOf(const fs::path& path, const std::string& name) {
  const fs::path copy = path.parent_path() / name;
  fs::copy_file(path, copy, fs::copy_options::overwrite_existing);
  return copy;
}

TEST(AuditChain, EveryEntryWrittenByTheProgramVerifies) {
  TempDir dir("arpos_audit");
  const fs::path path = WriteAuditedStore(dir.path());
  const AuditVerification v = Verify(path);
  EXPECT_TRUE(v.ok()) << v.ToText();
  EXPECT_EQ(v.entries, 4);
  EXPECT_EQ(v.chained_entries, 4);
  EXPECT_EQ(v.legacy_entries, 0);
  EXPECT_EQ(v.first_bad_entry, 0);
  // Each entry's hash is the documented function of its content and the
  // previous hash.
  const auto db = SqliteDatabase::Open(path.string());
  const std::vector<AuditEntry> entries = db->ListAudit();
  ASSERT_EQ(entries.size(), 4u);
  EXPECT_NE(AuditEntryHash(entries[0], ""), AuditEntryHash(entries[1], ""));
  AuditEntry changed = entries[1];
  changed.details += " ";
  EXPECT_NE(AuditEntryHash(changed, "x"), AuditEntryHash(entries[1], "x"));
}

TEST(AuditChain, EachKindOfTamperingIsNamed) {
  TempDir dir("arpos_audit");
  const fs::path path = WriteAuditedStore(dir.path());
  auto first_problem = [](const AuditVerification& v) { return v.problems.empty() ? std::string() : v.problems[0]; };

  // An entry's text changed (the update trigger dropped first).
  fs::path t = CopyOf(path, "changed.db");
  RawExec(t, "DROP TRIGGER audit_log_refuse_update; UPDATE audit_log SET details = 'nothing' WHERE audit_id = 2");
  AuditVerification v = Verify(t);
  ASSERT_FALSE(v.ok());
  EXPECT_NE(first_problem(v).find("audit entry 2"), std::string::npos) << v.ToText();
  EXPECT_NE(first_problem(v).find("does not match its hash"), std::string::npos) << v.ToText();
  EXPECT_EQ(v.first_bad_entry, 2);
  EXPECT_NE(v.ToText().find("trigger audit_log_refuse_update is missing"), std::string::npos) << v.ToText();

  // A forged entry appended with a made-up hash.
  t = CopyOf(path, "forged.db");
  RawExec(t, "INSERT INTO audit_log (time_unix_ms, actor, action, entity, details, prev_hash, entry_hash) "
             "VALUES (1, 'someone', 'approve', 'plan:1', '', 'abc', 'def')");
  v = Verify(t);
  ASSERT_FALSE(v.ok());
  EXPECT_NE(first_problem(v).find("audit entry 5 (approve plan:1 by someone)"), std::string::npos) << v.ToText();

  // A forged entry with no hash at all.
  t = CopyOf(path, "unhashed.db");
  RawExec(t, "INSERT INTO audit_log (time_unix_ms, actor, action) VALUES (1, 'someone', 'approve')");
  v = Verify(t);
  ASSERT_FALSE(v.ok());
  EXPECT_NE(first_problem(v).find("audit entry 5"), std::string::npos) << v.ToText();
  EXPECT_NE(first_problem(v).find("has no hash"), std::string::npos) << v.ToText();

  // An entry removed from the middle: the next one no longer links.
  t = CopyOf(path, "middle.db");
  RawExec(t, "DROP TRIGGER audit_log_refuse_delete; DELETE FROM audit_log WHERE audit_id = 2");
  v = Verify(t);
  ASSERT_FALSE(v.ok());
  EXPECT_NE(first_problem(v).find("audit entry 3"), std::string::npos) << v.ToText();
  EXPECT_NE(first_problem(v).find("previous hash does not match"), std::string::npos) << v.ToText();
  EXPECT_EQ(v.first_bad_entry, 3);

  // The last entry removed: the AUTOINCREMENT counter remembers it.
  t = CopyOf(path, "tail.db");
  RawExec(t, "DROP TRIGGER audit_log_refuse_delete; DELETE FROM audit_log WHERE audit_id = 4");
  v = Verify(t);
  ASSERT_FALSE(v.ok());
  EXPECT_NE(v.ToText().find("audit entries 4-4 were given out and are gone"), std::string::npos) << v.ToText();

  // A trigger replaced by one that lets everything through.
  t = CopyOf(path, "trigger.db");
  RawExec(t, "DROP TRIGGER audit_log_refuse_update; CREATE TRIGGER audit_log_refuse_update BEFORE UPDATE ON "
             "audit_log BEGIN SELECT 1; END");
  v = Verify(t);
  ASSERT_FALSE(v.ok());
  EXPECT_NE(first_problem(v).find("trigger audit_log_refuse_update differs"), std::string::npos) << v.ToText();

  // A clinical row written past the program: no audit entry records it.
  t = CopyOf(path, "row.db");
  RawExec(t, "INSERT INTO patients (external_id, created_unix_ms) VALUES ('P-002', 1)");
  v = Verify(t);
  ASSERT_FALSE(v.ok());
  EXPECT_NE(first_problem(v).find("1 row(s) of patients have no audit entry (patient:<id> for id 2)"),
            std::string::npos)
      << v.ToText();

  // The original still verifies.
  EXPECT_TRUE(Verify(path).ok());
}

// A patient, `plans` plans and session 1 on plan 1, each with its audit entry.
void AddAuditedSession(SqliteDatabase* db, int plans) {
  PatientRecord patient;
  patient.external_id = "P-002";
  PlanRecord plan;
  plan.patient_id = db->AddPatient(patient);
  db->AppendAudit({AuditId(), 0, "tech", "add_patient", "patient:1", ""});
  plan.name = "plan";
  plan.reference_model.vertices = {{0, 0, 0}, {0.1f, 0, 0}, {0, 0.1f, 0}};
  plan.reference_model.faces = {{0, 1, 2}};
  for (int i = 0; i < plans; ++i) {
    const PlanId id = db->AddPlan(plan);
    db->AppendAudit({AuditId(), 0, "tech", "add_plan", "plan:" + std::to_string(id.value()), ""});
  }
  SessionRecord session;
  session.plan_id = PlanId(1);
  db->AddSession(session);
  db->AppendAudit({AuditId(), 0, "ana (therapist)", "open_session", "session:1", ""});
}

// Approvals and session ends are made by the audited controllers
// (store/lifecycle.h); one made with sqlite3, any other edit of an audited
// row, or a dropped plan trigger, is named.
TEST(AuditChain, AnApprovalOrASessionEndWrittenPastTheProgramIsNamed) {
  TempDir dir;
  const fs::path path = dir.path() / "store.db";
  {
    const auto db = SqliteDatabase::Open(path.string());
    AddAuditedSession(db.get(), 2);
    // Plan 2 approved and the session completed the program's way.
    db->ApprovePlan(PlanId(2), "pia (physicist)", "");
    db->AppendAudit({AuditId(), 0, "pia (physicist)", "approve_plan", "plan:2", ""});
  }
  EXPECT_TRUE(Verify(path).ok()) << Verify(path).ToText();

  const fs::path forged = CopyOf(path, "forged.db");
  RawExec(forged, "UPDATE plans SET approved_by = 'pia (physicist)', approved_unix_ms = created_unix_ms + 1 "
                  "WHERE plan_id = 1; UPDATE sessions SET status = 'completed', ended_unix_ms = started_unix_ms");
  const AuditVerification v = Verify(forged);
  EXPECT_FALSE(v.ok());
  EXPECT_NE(v.ToText().find("plan 1 is marked approved but no approve_plan entry records it"), std::string::npos)
      << v.ToText();
  EXPECT_NE(v.ToText().find("session 1 is marked completed but no complete_session entry"), std::string::npos)
      << v.ToText();

  // Any other column of an audited row, edited with sqlite3: the row no
  // longer matches what its newest entry sealed (schema 8).
  const fs::path edited = CopyOf(path, "edited.db");
  RawExec(edited, "UPDATE sessions SET operator_name = 'someone else' WHERE session_id = 1");
  EXPECT_NE(Verify(edited).ToText().find("session:1 differs from what audit entry 4 sealed"), std::string::npos)
      << Verify(edited).ToText();

  const fs::path unlocked = CopyOf(path, "unlocked.db");
  RawExec(unlocked, "DROP TRIGGER plans_approved_are_locked");
  EXPECT_NE(Verify(unlocked).ToText().find("trigger plans_approved_are_locked is missing"), std::string::npos)
      << Verify(unlocked).ToText();
}

// The breathing a session measured (schema 9) and the room landmarks its
// scan placed (schema 11) are part of its body marker map's sealed row:
// changing a sticker's motion, the moving surface or the landmarks with
// sqlite3 is named; a map without them seals as before.
TEST(AuditChain, ABodyMarkerMapsBreathingIsSealedWithIt) {
  TempDir dir;
  const fs::path path = dir.path() / "store.db";
  {
    const auto db = SqliteDatabase::Open(path.string());
    AddAuditedSession(db.get(), 1);
    for (const bool breathing : {true, false}) {
      BodyMarkerMapRecord map;
      map.session_id = SessionId(1);
      map.marker_size_m = 0.03;
      map.markers = {{101, Rigid3d::Identity(), 0.2, 10, breathing ? 0.0012 : 0.0,
                      breathing ? Eigen::Vector3d(0.6, 0.0, 0.8) : Eigen::Vector3d::UnitZ()},
                     {102, Rigid3d::Identity(), 0.2, 10, 0.0}};
      if (breathing) {
        map.surface_patch_m = 0.04;
        map.moving_surface_patches = {{0.02, -0.1, 0.06}};
        map.room_landmarks.points = {{1.1f, -1.5f, 3.0f}, {0.2f, -0.4f, 2.5f}};
        map.room_landmark_descriptors = ByteMatrix::Constant(2, 32, 17);
      }
      const BodyMarkerMapId id = db->AddBodyMarkerMap(map);
      db->AppendAudit({AuditId(), 0, "ana (therapist)", "add_body_marker_map",
                       "body_marker_map:" + std::to_string(id.value()), ""});
    }
    const auto map = db->GetBodyMarkerMap(BodyMarkerMapId(1));
    ASSERT_TRUE(map.has_value());
    EXPECT_EQ(map->markers[0].motion_m, 0.0012);
    EXPECT_EQ(map->markers[1].motion_m, 0.0);
    EXPECT_TRUE(map->markers[0].motion_direction.isApprox(Eigen::Vector3d(0.6, 0.0, 0.8)));
    EXPECT_TRUE(map->markers[1].motion_direction.isApprox(Eigen::Vector3d::UnitZ()));
    ASSERT_EQ(map->moving_surface_patches.size(), 1u);
    EXPECT_TRUE(db->GetBodyMarkerMap(BodyMarkerMapId(2))->moving_surface_patches.empty());
  }
  EXPECT_TRUE(Verify(path).ok()) << Verify(path).ToText();

  const fs::path motion = CopyOf(path, "motion.db");
  RawExec(motion, "UPDATE body_marker_motion SET motion_m = 0.0001 WHERE marker_id = 101");
  EXPECT_NE(Verify(motion).ToText().find("body_marker_map:1 differs from what audit entry"), std::string::npos)
      << Verify(motion).ToText();
  const fs::path surface = CopyOf(path, "surface.db");
  RawExec(surface, "DELETE FROM body_surface_motion WHERE body_marker_map_id = 1");
  EXPECT_NE(Verify(surface).ToText().find("body_marker_map:1 differs from what audit entry"), std::string::npos)
      << Verify(surface).ToText();
  const fs::path landmarks = CopyOf(path, "landmarks.db");
  RawExec(landmarks, "DELETE FROM body_scan_landmarks WHERE body_marker_map_id = 1");
  EXPECT_NE(Verify(landmarks).ToText().find("body_marker_map:1 differs from what audit entry"),
            std::string::npos)
      << Verify(landmarks).ToText();
  const fs::path direction = CopyOf(path, "direction.db");
  RawExec(direction,
          "UPDATE body_marker_motion_direction SET x = 0.8, z = 0.6 WHERE marker_id = 101");
  EXPECT_NE(Verify(direction).ToText().find("body_marker_map:1 differs from what audit entry"),
            std::string::npos)
      << Verify(direction).ToText();
  // A motion row added to the map that had none.
  const fs::path added = CopyOf(path, "added.db");
  RawExec(added, "INSERT INTO body_marker_motion VALUES (2, 102, 0.002)");
  EXPECT_NE(Verify(added).ToText().find("body_marker_map:2 differs from what audit entry"), std::string::npos)
      << Verify(added).ToText();
}

// The room's surface (schema 10) is part of its room map's sealed row:
// changing or removing it with sqlite3 is named; a map without one seals
// as before.
TEST(AuditChain, ARoomMapsSurfaceIsSealedWithIt) {
  TempDir dir;
  const fs::path path = dir.path() / "store.db";
  {
    const auto db = SqliteDatabase::Open(path.string());
    AddAuditedSession(db.get(), 1);
    for (const bool surface : {true, false}) {
      RoomMapRecord map;
      map.plan_id = PlanId(1);
      map.origin_marker_id = 0;
      map.marker_size_m = 0.1;
      RoomMapMarker marker;
      marker.corners_in_room.fill(Eigen::Vector3d::Zero());
      marker.residual_px = 0.1;
      marker.num_observations = 5;
      map.markers = {marker};
      if (surface) {
        map.surface_voxel_m = 0.03;
        map.surface.points = {{0.f, 1.f, 0.f}, {0.5f, 1.f, 0.3f}};
        map.surface.normals = {{0.f, 0.f, 1.f}, {1.f, 0.f, 0.f}};
      }
      const RoomMapId id = db->AddRoomMap(map);
      db->AppendAudit({AuditId(), 0, "tom (technician)", "build_room_map", "room_map:" + std::to_string(id.value()), ""});
    }
    EXPECT_EQ(db->GetRoomMap(RoomMapId(1))->surface.points.size(), 2u);
    EXPECT_TRUE(db->GetRoomMap(RoomMapId(2))->surface.points.empty());
  }
  EXPECT_TRUE(Verify(path).ok()) << Verify(path).ToText();
  const fs::path changed = CopyOf(path, "changed.db");
  RawExec(changed, "UPDATE room_map_surface SET voxel_m = 0.05 WHERE room_map_id = 1");
  EXPECT_NE(Verify(changed).ToText().find("room_map:1 differs from what audit entry"), std::string::npos)
      << Verify(changed).ToText();
  const fs::path removed = CopyOf(path, "removed.db");
  RawExec(removed, "DELETE FROM room_map_surface WHERE room_map_id = 1");
  EXPECT_NE(Verify(removed).ToText().find("room_map:1 differs from what audit entry"), std::string::npos)
      << Verify(removed).ToText();
}

TEST(AuditChain, EntriesFromBeforeTheChainAreCountedApartAndTheChainStartsAfterThem) {
  TempDir dir("arpos_audit");
  const fs::path path = dir.path() / "old.db";
  {
    sqlite3* raw = nullptr;
    ASSERT_EQ(sqlite3_open(path.c_str(), &raw), SQLITE_OK);
    ASSERT_EQ(MigrateSchema(raw, path.string(), 5), 5);
    sqlite3_close(raw);
  }
  RawExec(path, "INSERT INTO audit_log (time_unix_ms, actor, action) VALUES (1, 'arpos plan', 'old entry'); "
                "INSERT INTO audit_log (time_unix_ms, actor, action) VALUES (2, 'arpos plan', 'old entry')");
  {
    const auto db = SqliteDatabase::Open(path.string());  // migrates to the newest schema
    db->AppendAudit({AuditId(), 0, "tech", "note", "", "first chained entry"});
    db->AppendAudit({AuditId(), 0, "tech", "note", "", "second"});
  }
  AuditVerification v = Verify(path);
  EXPECT_TRUE(v.ok()) << v.ToText();
  EXPECT_EQ(v.legacy_entries, 2);
  EXPECT_EQ(v.chained_entries, 2);
  EXPECT_NE(v.ToText().find("2 written before the chain existed"), std::string::npos) << v.ToText();
  // An unhashed entry after the chain started is not taken for an old one.
  RawExec(path, "INSERT INTO audit_log (time_unix_ms, actor, action) VALUES (3, 'someone', 'late')");
  v = Verify(path);
  EXPECT_FALSE(v.ok()) << v.ToText();
}

TEST(AuditChain, VerifyCommandExitsZeroOneOrTwo) {
  TempDir dir("arpos_audit");
  const fs::path path = WriteAuditedStore(dir.path());
  std::ostringstream out, err;
  EXPECT_EQ(RunAuditCommandWithOutput({"verify", "--store", path.string()}, out, err), 0) << err.str();
  EXPECT_NE(out.str().find("verified: the chain is intact"), std::string::npos) << out.str();

  const fs::path t = CopyOf(path, "changed.db");
  RawExec(t, "DROP TRIGGER audit_log_refuse_update; UPDATE audit_log SET actor = 'x' WHERE audit_id = 1");
  std::ostringstream out2, err2;
  EXPECT_EQ(RunAuditCommandWithOutput({"verify", "--store", t.string()}, out2, err2), 1);
  EXPECT_NE(out2.str().find("NOT verified"), std::string::npos) << out2.str();
  EXPECT_NE(out2.str().find("audit entry 1"), std::string::npos) << out2.str();

  std::ostringstream out3, err3;
  const fs::path missing = dir.path() / "missing.db";
  EXPECT_EQ(RunAuditCommandWithOutput({"verify", "--store", missing.string()}, out3, err3), 2);
  EXPECT_FALSE(fs::exists(missing)) << "verify must not create a store";
  EXPECT_NE(err3.str().find("missing.db"), std::string::npos) << err3.str();

  std::ostringstream out4, err4;
  EXPECT_EQ(RunAuditCommandWithOutput({"check"}, out4, err4), 2);
  EXPECT_EQ(RunAuditCommandWithOutput({"verify", "--bogus"}, out4, err4), 2);
}

}  // namespace
}  // namespace arpos
