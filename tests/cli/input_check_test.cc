// Every stage checks what it reads before it starts, and a failed command
// leaves the store as it was: copies of the committed sample session with one
// thing broken, run through the real `arpos` executable as a user would.
#include <gtest/gtest.h>
#include <sqlite3.h>

#include <cmath>
#include <filesystem>
#include <string>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "cli/cli_util.h"
#include "geometry/mesh_io.h"
#include "sensor/tum_io.h"
#include "util/file.h"

namespace arpos {
namespace {

namespace fs = std::filesystem;
using testing::CliResult;
using testing::RunArpos;

bool Contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// Data problems are input errors for a person: no "internal error", no
// source line.
void ExpectAnInputError(const CliResult& r) {
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_FALSE(Contains(r.output, "internal error")) << r.output;
  EXPECT_FALSE(Contains(r.output, ".cc:")) << r.output;
  EXPECT_FALSE(Contains(r.output, "std::")) << r.output;
}

class CliInputChecks : public ::testing::Test {
 protected:
  void SetUp() override {
    fs::copy(fs::path(ARPOS_SAMPLE_SESSIONS_DIR) / "demo_xtion", case_dir(), fs::copy_options::recursive);
  }
  fs::path case_dir() const { return dir_.path() / "demo_xtion"; }
  std::string store() const { return (dir_.path() / "store.db").string(); }
  std::string Case() const { return case_dir().string(); }
  // `arpos store info` of the test's store.
  std::string StoreInfo() const { return RunArpos("store info --store " + store()).output; }
  // Swaps the second and third entries of a TUM list.
  void SwapListLines(const fs::path& list) const {
    std::vector<ImageListEntry> entries = ReadImageList(list);
    ASSERT_GE(entries.size(), 3u);
    std::swap(entries[1], entries[2]);
    WriteImageList(list, entries, "two entries swapped");
  }
  TempDir dir_;
};

// A target pose in millimetres (1.8 km away) used to be stored with exit 0.
TEST_F(CliInputChecks, PlanStopsAtATargetPoseInMillimetresAndStoresNothing) {
  Eigen::Matrix4d target = ReadMatrix4(case_dir() / "target_pose.txt");
  target.topRightCorner<3, 1>() *= 1000.0;
  WriteMatrix4(case_dir() / "target_pose.txt", target, "in millimetres by mistake");
  const CliResult r = RunArpos("plan " + Case() + " --store " + store());
  ExpectAnInputError(r);
  EXPECT_TRUE(Contains(r.output, "error: target_pose.txt: translation (")) << r.output;
  EXPECT_TRUE(Contains(r.output, "looks like millimetres")) << r.output;
  EXPECT_TRUE(Contains(StoreInfo(), "Latest plans: none")) << StoreInfo();
}

// A reference model scaled to kilometres used to be stored, and the session
// then ran out of memory.
TEST_F(CliInputChecks, PlanStopsAtAReferenceModelThatIsNotBodySized) {
  const fs::path model = case_dir() / "reference_model.ply";
  TriangleMesh mesh = LoadTriangleMesh(model);
  for (auto& v : mesh.vertices) v *= 1000.0f;
  SaveTriangleMeshPly(mesh, model);
  const CliResult r = RunArpos("plan " + Case() + " --store " + store());
  ExpectAnInputError(r);
  EXPECT_TRUE(Contains(r.output, "error: reference_model.ply: largest extent is ")) << r.output;
  EXPECT_TRUE(Contains(r.output, "looks like millimetres")) << r.output;
  EXPECT_TRUE(Contains(StoreInfo(), "Latest plans: none")) << StoreInfo();
}

// A reference model with one NaN vertex used to pass check, import-model and
// run-case (the vertex silently dropped).
TEST_F(CliInputChecks, ANanVertexIsRefusedByCheckImportModelAndRunCase) {
  const fs::path model = case_dir() / "reference_model.ply";
  TriangleMesh mesh = LoadTriangleMesh(model);
  mesh.ComputeVertexNormals();  // finite normals; only the position is broken
  mesh.vertices[7].y() = std::nanf("");
  SaveTriangleMeshPly(mesh, model);
  const std::string expected = "PLY vertex 7 has y = nan: coordinates must be finite numbers";
  const CliResult check = RunArpos("check --quick " + Case());
  EXPECT_EQ(check.status, 1) << check.output;
  EXPECT_TRUE(Contains(check.output, "error: reference_model.ply: " + expected)) << check.output;
  const CliResult import = RunArpos("import-model " + model.string() + " --out " + (dir_.path() / "m.ply").string());
  ExpectAnInputError(import);
  EXPECT_TRUE(Contains(import.output, model.string() + ": " + expected)) << import.output;
  EXPECT_FALSE(fs::exists(dir_.path() / "m.ply"));
  const CliResult run = RunArpos("run-case --quick " + Case() + " --store " + store());
  ExpectAnInputError(run);
  EXPECT_TRUE(Contains(run.output, "error: reference_model.ply: " + expected)) << run.output;
  EXPECT_TRUE(Contains(StoreInfo(), "Latest plans: none")) << StoreInfo();
}

// Out-of-order timestamps used to pass session and localize.
TEST_F(CliInputChecks, SessionAndLocalizeStopAtOutOfOrderTimestamps) {
  SwapListLines(case_dir() / "body_scan" / "rgb.txt");
  const CliResult session = RunArpos("session " + Case() + " --store " + store());
  ExpectAnInputError(session);
  EXPECT_TRUE(Contains(session.output, "the case has problems")) << session.output;
  EXPECT_TRUE(Contains(session.output, "error: body_scan/rgb.txt: timestamps not increasing at line")) << session.output;

  fs::path tracking;
  for (const auto& entry : fs::directory_iterator(case_dir() / "tracking")) tracking = entry.path();
  ASSERT_FALSE(tracking.empty());
  SwapListLines(tracking / "depth.txt");
  const std::string out = (dir_.path() / "poses.txt").string();
  const CliResult localize = RunArpos("localize " + tracking.string() + " --out " + out + " --store " + store());
  ExpectAnInputError(localize);
  EXPECT_TRUE(Contains(localize.output, "error: tracking/" + tracking.filename().string() +
                                            "/depth.txt: timestamps not increasing at line"))
      << localize.output;
  EXPECT_FALSE(fs::exists(out));
}

TEST_F(CliInputChecks, ABinaryGarbageModelIsNotAPlyFile) {
  std::string garbage;
  for (int i = 0; i < 5000; ++i) garbage.push_back(static_cast<char>((i * 7919 + 3) % 256));
  WriteFileAtomic(case_dir() / "reference_model.ply", garbage);
  const CliResult r = RunArpos("check --quick " + Case());
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_TRUE(Contains(r.output, "error: reference_model.ply: not a PLY file")) << r.output;
  EXPECT_FALSE(Contains(r.output, "empty")) << r.output;
}

// `session --out` to a folder that cannot be made used to fail after the
// session was committed.
TEST_F(CliInputChecks, SessionOutputThatCannotBeWrittenStopsBeforeAnythingIsStored) {
  const CliResult plan = RunArpos("plan " + Case() + " --store " + store());
  ASSERT_EQ(plan.status, 0) << plan.output;
  WriteFileAtomic(dir_.path() / "a_file", "not a folder");
  const std::string out = (dir_.path() / "a_file" / "out").string();
  const CliResult r = RunArpos("session " + Case() + " --store " + store() + " --out " + out);
  ExpectAnInputError(r);
  EXPECT_TRUE(Contains(r.output, "--out " + out + ": cannot create the folder")) << r.output;
  EXPECT_FALSE(Contains(r.output, "localising")) << "the stage ran first:\n" << r.output;
  EXPECT_TRUE(Contains(StoreInfo(), "Latest sessions: none")) << StoreInfo();
}

TEST_F(CliInputChecks, AStoreThatIsNotADatabaseIsAStoreErrorNotAnInternalOne) {
  std::string garbage;
  for (int i = 0; i < 8192; ++i) garbage.push_back(static_cast<char>((i * 31 + 5) % 256));
  WriteFileAtomic(store(), garbage);
  for (const std::string& command : {"plan " + Case(), "session " + Case(), "run-case --quick " + Case()}) {
    const CliResult r = RunArpos(command + " --store " + store());
    ExpectAnInputError(r);
    EXPECT_TRUE(Contains(r.output, "store error: " + store() + ": not an ARPos store / not a SQLite database"))
        << command << ":\n" << r.output;
  }
  EXPECT_EQ(ReadTextFile(store()), garbage);
}

// Another program holds the store's write lock while `arpos plan` is about
// to store: the command says it is waiting, and when the lock goes (here: as
// soon as it says so, no timing), it stores its work and succeeds.
TEST_F(CliInputChecks, PlanWaitsForALockedStoreAndStoresItsWork) {
  // Creates the store (then stops: no such case).
  EXPECT_EQ(RunArpos("plan " + (dir_.path() / "none").string() + " --store " + store()).status, 2);
  sqlite3* other = nullptr;
  ASSERT_EQ(sqlite3_open(store().c_str(), &other), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(other, "BEGIN IMMEDIATE", nullptr, nullptr, nullptr), SQLITE_OK) << sqlite3_errmsg(other);
  bool released = false;
  const CliResult r =
      testing::RunArposWatching("plan " + Case() + " --store " + store(), [&](const std::string& line) {
        if (!released && Contains(line, "locked by another program; waiting")) {
          EXPECT_EQ(sqlite3_exec(other, "COMMIT", nullptr, nullptr, nullptr), SQLITE_OK);
          released = true;
        }
      });
  if (!released) sqlite3_exec(other, "COMMIT", nullptr, nullptr, nullptr);
  sqlite3_close(other);
  EXPECT_TRUE(released) << r.output;
  EXPECT_EQ(r.status, 0) << r.output;
  EXPECT_TRUE(Contains(r.output, store() + ": the store is locked by another program; waiting up to 60 s"))
      << r.output;
  EXPECT_TRUE(Contains(StoreInfo(), "plan 1 ")) << StoreInfo();
}

// Rows of `table` in the store file at `path` (opened read-only, as another
// program would look at it).
std::int64_t StoredRows(const std::string& path, const std::string& table) {
  sqlite3* db = nullptr;
  std::int64_t count = -1;
  if (sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) == SQLITE_OK) {
    sqlite3_stmt* stmt = nullptr;
    if (sqlite3_prepare_v2(db, ("SELECT COUNT(*) FROM " + table).c_str(), -1, &stmt, nullptr) == SQLITE_OK &&
        sqlite3_step(stmt) == SQLITE_ROW) {
      count = sqlite3_column_int64(stmt, 0);
    }
    sqlite3_finalize(stmt);
  }
  sqlite3_close(db);
  return count;
}

// A room recording that cannot be mapped used to leave the patient, the plan
// and the room recording stored: they were written before the map was built.
TEST_F(CliInputChecks, PlanThatCannotMapTheRoomStoresNothing) {
  // Every room colour image a uniform grey of the same size: valid images
  // (the case check passes), but no marker anywhere.
  int replaced = 0;
  for (const auto& entry : fs::directory_iterator(case_dir() / "room" / "rgb")) {
    const cv::Mat image = cv::imread(entry.path().string(), cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(image.empty()) << entry.path();
    ASSERT_TRUE(cv::imwrite(entry.path().string(), cv::Mat(image.size(), image.type(), cv::Scalar::all(128))));
    ++replaced;
  }
  ASSERT_GT(replaced, 0);
  const CliResult r = RunArpos("plan " + Case() + " --store " + store());
  ExpectAnInputError(r);
  EXPECT_TRUE(Contains(r.output, "arpos plan: error: ")) << r.output;
  EXPECT_TRUE(Contains(r.output, "the origin marker (id 0, case.yaml markers.room.origin_id) is never seen"))
      << r.output;
  EXPECT_FALSE(Contains(r.output, "room map 1 stored")) << r.output;
  for (const char* table : {"patients", "plans", "recordings", "room_maps", "audit_log"}) {
    EXPECT_EQ(StoredRows(store(), table), 0) << table << " after `arpos plan`:\n" << r.output;
  }
  EXPECT_TRUE(Contains(StoreInfo(), "Latest plans: none")) << StoreInfo();

  // run-case plans the same way.
  const CliResult run = RunArpos("run-case --quick " + Case() + " --store " + store());
  ExpectAnInputError(run);
  EXPECT_TRUE(Contains(run.output, "the origin marker (id 0, case.yaml markers.room.origin_id) is never seen"))
      << run.output;
  for (const char* table : {"patients", "plans", "recordings", "room_maps", "sessions", "audit_log"}) {
    EXPECT_EQ(StoredRows(store(), table), 0) << table << " after `arpos run-case`:\n" << run.output;
  }
}

// A depth_scale of 5000 (TUM's) for depth in millimetres: every marker's
// depth disagrees with its printed size. Was "no room marker is seen sharply
// enough for a pose", which sent the user to the colour images.
TEST_F(CliInputChecks, AWrongDepthScaleIsNamedWithTheScaleTheImagesShow) {
  std::string yaml = ReadTextFile(case_dir() / "case.yaml");
  const size_t at = yaml.find("depth_scale: 1000");
  ASSERT_NE(at, std::string::npos) << yaml;
  yaml.replace(at, 17, "depth_scale: 5000");
  WriteFileAtomic(case_dir() / "case.yaml", yaml);
  const CliResult r = RunArpos("plan " + Case() + " --store " + store());
  ExpectAnInputError(r);
  EXPECT_TRUE(Contains(r.output, "the depth disagrees with the room markers in every view: it reads 0.2")) << r.output;
  EXPECT_TRUE(Contains(r.output, "Check camera.depth_scale in case.yaml (5000 depth units per metre")) << r.output;
  EXPECT_TRUE(Contains(r.output, "these images look like 99") || Contains(r.output, "these images look like 100"))
      << r.output;
  for (const char* table : {"patients", "plans", "room_maps", "audit_log"}) {
    EXPECT_EQ(StoredRows(store(), table), 0) << table << " after `arpos plan`:\n" << r.output;
  }
}

// `evaluate` with nothing matched used to print MTE 0.000 with 100 % lost.
TEST(CliEvaluate, NothingMatchedIsNotAPerfectScore) {
  TempDir dir;
  std::vector<StampedPose> gt, late;
  for (int i = 0; i < 5; ++i) {
    const Rigid3d pose(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.1 * i, 0.5, 1.0));
    gt.push_back({i * 0.1, pose});
    late.push_back({100 + i * 0.1, pose});  // another clock
  }
  WriteTrajectory(dir.path() / "gt.txt", gt);
  WriteTrajectory(dir.path() / "late.txt", late);
  WriteFileAtomic(dir.path() / "empty.txt", "# timestamp tx ty tz qx qy qz qw\n");
  for (const char* est : {"empty.txt", "late.txt"}) {
    const std::string args =
        "evaluate --gt " + (dir.path() / "gt.txt").string() + " --est " + (dir.path() / est).string();
    CliResult r = RunArpos(args);
    EXPECT_EQ(r.status, 1) << r.output;
    EXPECT_TRUE(Contains(r.output, "lost: 5 (100.0 %)")) << r.output;
    EXPECT_TRUE(Contains(r.output, "mean (MTE) n/a")) << r.output;
    EXPECT_TRUE(Contains(r.output, "every frame is lost, MTE/MRE n/a")) << r.output;
    EXPECT_FALSE(Contains(r.output, "0.000")) << r.output;
    r = RunArpos(args + " --json");
    EXPECT_EQ(r.status, 1) << r.output;
    EXPECT_TRUE(Contains(r.output, "\"translation_mm\": null")) << r.output;
  }
}

}  // namespace
}  // namespace arpos
