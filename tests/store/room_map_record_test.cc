// The room map through the store: what planning measures about the camera
// (colour response, depth correction) and the room frame's uncertainty survive
// ToRecord -> SqliteDatabase -> FromRecord; maps stored without them read back
// with the RoomMap defaults; malformed stored text names the room map.

#include <gtest/gtest.h>
#include <sqlite3.h>

#include <cmath>
#include <limits>

#include "room_map/plan_stage.h"
#include "room_map/room_map.h"
#include "store/sqlite_database.h"
#include "store_test_util.h"
#include "util/check.h"

namespace arpos {
namespace {

// Two markers (the origin at the room frame) and three landmarks.
RoomMap SomeMap() {
  RoomMap map;
  map.origin_marker_id = 3;
  map.marker_size_m = 0.12;
  for (int id : {3, 9}) {
    RoomMapMarkerEntry m;
    m.id = id;
    if (id == 9) {
      m.room_from_marker = Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitY())),
                                   Eigen::Vector3d(1.2, 0.1, -0.3));
    }
    m.corners_in_room = MarkerCornersInRoom(m.room_from_marker, map.marker_size_m);
    m.residual_px = 0.2;
    m.num_observations = 12;
    map.markers.push_back(m);
  }
  for (int i = 0; i < 3; ++i) map.landmarks_in_room.emplace_back(0.5 * i, 1.0, 2.0 - i);
  map.landmark_descriptors = cv::Mat(3, kDescriptorBytes, CV_8UC1, cv::Scalar(0x3C));
  map.mean_residual_px = 0.2;
  map.max_residual_px = 0.25;
  return map;
}

// Not sRGB: an S-shaped table, as the response estimate can produce.
CameraResponse SomeResponse() {
  std::array<double, 256> linear{};
  for (int v = 0; v < 256; ++v) {
    const double x = v / 255.0;
    linear[v] = 255.0 * x * x * (3 - 2 * x);
  }
  return CameraResponse::FromTable(linear, "estimated");
}

// Not the identity: a scale error and a 3 x 2 field.
DepthCorrection SomeDepthCorrection() {
  DepthCorrection c;
  c.scale = 0.0125;
  c.nx = 3;
  c.ny = 2;
  c.x0 = -0.6;
  c.x1 = 0.6;
  c.y0 = -0.45;
  c.y1 = 0.45;
  c.grid = {0.001, -0.002, 0.0005, 0.0, 0.0031, -0.0007};
  return c;
}

void ExpectResponseNear(const CameraResponse& expected, const CameraResponse& actual) {
  EXPECT_EQ(actual.name(), expected.name());
  for (int v = 0; v < 256; ++v) {
    EXPECT_NEAR(actual.Linearize(v), expected.Linearize(v), 1e-4) << "code " << v;  // stored to 1e-4
  }
}

class RoomMapRecordTest : public ::testing::Test {
 protected:
  void SetUp() override {
    db_ = SqliteDatabase::Open(":memory:");
    store_ = test::WriteFullStore(*db_, 21);
  }
  PlanId plan() const { return store_.plan.id; }
  // Stores `record` and expects reading it back to be an InputError saying
  // "room map N" followed by `what`.
  void ExpectReadRefused(RoomMapRecord record, const std::string& what) {
    record.id = db_->AddRoomMap(record);
    try {
      FromRecord(*db_->GetRoomMap(record.id));
      FAIL() << "expected an InputError";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("room map " + std::to_string(record.id.value()) + what),
                std::string::npos)
          << e.what();
    }
  }
  std::unique_ptr<SqliteDatabase> db_;
  test::FullStore store_;
};

TEST_F(RoomMapRecordTest, ResponseAndDepthCorrectionRoundTripThroughTheStore) {
  RoomMap map = SomeMap();
  map.camera_response = SomeResponse();
  map.depth_correction = SomeDepthCorrection();
  const RoomMapId id = db_->AddRoomMap(ToRecord(map, plan(), store_.room_recording.id));
  const std::optional<RoomMapRecord> record = db_->GetRoomMap(id);
  ASSERT_TRUE(record);
  const RoomMap back = FromRecord(*record);

  ExpectResponseNear(map.camera_response, back.camera_response);
  EXPECT_GT(back.camera_response.MaxDifference(CameraResponse::Srgb()), 0.01);  // not the default
  const DepthCorrection& c = back.depth_correction;
  EXPECT_EQ(c.scale, map.depth_correction.scale);
  EXPECT_EQ(c.nx, 3);
  EXPECT_EQ(c.ny, 2);
  EXPECT_EQ(c.x0, -0.6);
  EXPECT_EQ(c.x1, 0.6);
  EXPECT_EQ(c.y0, -0.45);
  EXPECT_EQ(c.y1, 0.45);
  EXPECT_EQ(c.grid, map.depth_correction.grid);
  EXPECT_FALSE(c.IsIdentity());
  // The rest of the map as before.
  ASSERT_EQ(back.markers.size(), 2u);
  EXPECT_TRUE(back.markers[1].room_from_marker.IsApprox(map.markers[1].room_from_marker, 1e-9, 1e-9));
  EXPECT_EQ(back.num_landmarks(), 3);
}

TEST_F(RoomMapRecordTest, NullColumnsGiveTheRoomMapDefaults) {
  RoomMapRecord record = ToRecord(SomeMap(), plan());
  record.camera_response.clear();  // as a map stored before schema version 4 reads back
  record.depth_correction.clear();
  const RoomMapId id = db_->AddRoomMap(record);
  const std::optional<RoomMapRecord> stored = db_->GetRoomMap(id);
  ASSERT_TRUE(stored);
  EXPECT_EQ(stored->camera_response, "");
  EXPECT_EQ(stored->depth_correction, "");
  const RoomMap back = FromRecord(*stored);
  const RoomMap defaults;
  EXPECT_EQ(back.camera_response.name(), defaults.camera_response.name());
  EXPECT_EQ(back.camera_response.MaxDifference(CameraResponse::Srgb()), 0.0);
  EXPECT_TRUE(back.depth_correction.IsIdentity());
  EXPECT_EQ(back.depth_correction.nx, 0);
  EXPECT_TRUE(back.depth_correction.grid.empty());
}

TEST_F(RoomMapRecordTest, MalformedStoredTextIsAnInputErrorNamingTheMap) {
  RoomMapRecord record = ToRecord(SomeMap(), plan());
  record.camera_response = "estimated: 0 1 2";  // 3 of 256 values
  ExpectReadRefused(record, ": stored camera response");
  record = ToRecord(SomeMap(), plan());
  record.depth_correction = "depth correction: 0.01 2 2 0 1 0 1 0.5";  // 1 of 4 grid values
  ExpectReadRefused(record, ": stored depth correction");
}

// Localisation reads each landmark's descriptor as 32 bytes: a stored map
// whose descriptor rows are of another width is an input error naming the
// map, before any search reads them.
TEST_F(RoomMapRecordTest, StoredDescriptorsOfAnotherWidthAreAnInputErrorNamingTheMap) {
  RoomMapRecord record = ToRecord(SomeMap(), plan());
  record.landmark_descriptors = ByteMatrix::Constant(3, 16, 7);
  ExpectReadRefused(record, ": 3 landmarks but a 3 x 16 descriptor matrix");
}

// The room's surface (schema 10) round-trips with its voxel size; a map
// without one reads back empty; a stored surface with a bad normal is an
// input error naming the map.
TEST_F(RoomMapRecordTest, TheRoomSurfaceRoundTripsAndABadOneNamesTheMap) {
  RoomMap map = SomeMap();
  map.surface.voxel_m = 0.03;
  map.surface.points = {{0.1f, 0.2f, 0.0f}, {0.55f, 1.3f, 0.4f}};
  map.surface.normals = {{0.f, 0.f, 1.f}, {1.f, 0.f, 0.f}};
  const RoomMapId id = db_->AddRoomMap(ToRecord(map, plan()));
  const RoomMap back = FromRecord(*db_->GetRoomMap(id));
  EXPECT_EQ(back.surface.voxel_m, 0.03);
  ASSERT_EQ(back.surface.size(), 2u);
  EXPECT_EQ(back.surface.points[1], map.surface.points[1]);
  EXPECT_EQ(back.surface.normals[1], map.surface.normals[1]);

  const RoomMapId plain = db_->AddRoomMap(ToRecord(SomeMap(), plan()));
  EXPECT_TRUE(FromRecord(*db_->GetRoomMap(plain)).surface.empty());

  RoomMapRecord record = ToRecord(map, plan());
  record.surface.normals[0] = Eigen::Vector3f(0.f, 0.f, 2.f);
  record.id = db_->AddRoomMap(record);
  try {
    FromRecord(*db_->GetRoomMap(record.id));
    FAIL() << "expected an InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("room map " + std::to_string(record.id.value()) + ": room surface normal 0"),
              std::string::npos)
        << e.what();
  }
}

// The plan stage files the room frame's uncertainty from the build report
// with the map, and says what it measured in the audit log.
TEST_F(RoomMapRecordTest, StoreRoomMapKeepsTheRoomFrameUncertaintyAndAuditsIt) {
  RoomMapBuildResult build;
  build.map = SomeMap();
  build.map.camera_response = SomeResponse();
  build.map.depth_correction = SomeDepthCorrection();
  build.report.origin_observations = 14;
  build.report.room_frame_tilt_sigma_deg = 0.0213;
  build.report.room_frame_yaw_sigma_deg = 0.0457;
  build.report.room_frame_couch_sigma_mm = 0.318;
  build.report.camera_response = "camera response estimated from 40 markers";
  build.report.depth_correction = "depth corrected: reads +12.50 mm at 1 m";
  CaseFolder folder;
  folder.room_dir = "/cases/x/room";
  const RoomMapId id = StoreRoomMap(db_.get(), plan(), store_.room_recording.id, folder, build, "test actor");
  const std::optional<RoomMapRecord> record = db_->GetRoomMap(id);
  ASSERT_TRUE(record);
  EXPECT_EQ(record->room_frame_tilt_sigma_deg, 0.0213);
  EXPECT_EQ(record->room_frame_yaw_sigma_deg, 0.0457);
  EXPECT_EQ(record->room_frame_couch_sigma_mm, 0.318);
  EXPECT_EQ(record->recording_id, store_.room_recording.id);
  ExpectResponseNear(build.map.camera_response, FromRecord(*record).camera_response);

  const std::vector<AuditEntry> audit = db_->ListAudit();
  ASSERT_FALSE(audit.empty());
  const AuditEntry& entry = audit.back();
  EXPECT_EQ(entry.action, "build_room_map");
  EXPECT_EQ(entry.actor, "test actor");
  EXPECT_EQ(entry.entity, "room_map:" + std::to_string(id.value()));
  for (const std::string& part :
       {std::string("room frame (origin marker, 14 views): tilt 0.0213 deg, yaw 0.0457 deg, position at the "
                    "couch 0.318 mm (1 sigma)"),
        build.report.camera_response, build.report.depth_correction, std::string("from /cases/x/room")}) {
    EXPECT_NE(entry.details.find(part), std::string::npos) << "'" << part << "' not in: " << entry.details;
  }

  // A room frame the build could not measure (infinite sigmas) is stored as
  // unknown, not as a number.
  build.report.room_frame_tilt_sigma_deg = std::numeric_limits<double>::infinity();
  build.report.room_frame_yaw_sigma_deg = std::numeric_limits<double>::infinity();
  build.report.room_frame_couch_sigma_mm = std::numeric_limits<double>::infinity();
  const std::optional<RoomMapRecord> unknown =
      db_->GetRoomMap(StoreRoomMap(db_.get(), plan(), std::nullopt, folder, build, "test actor"));
  ASSERT_TRUE(unknown);
  EXPECT_FALSE(unknown->room_frame_tilt_sigma_deg);
  EXPECT_FALSE(unknown->room_frame_yaw_sigma_deg);
  EXPECT_FALSE(unknown->room_frame_couch_sigma_mm);
}

}  // namespace
}  // namespace arpos
