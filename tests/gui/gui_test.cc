// Opens every wizard page of the real executable and looks at what it shows.
#include <gtest/gtest.h>
#include <sqlite3.h>
#include <sys/wait.h>

#include <cstdlib>
#include <opencv2/imgcodecs.hpp>
#include <string>

#include "sensor/test_case_builder.h"
#include "store/sqlite_database.h"
#include "util/file.h"

namespace arpos {
namespace {

int RunArpos(const std::string& args, std::string* output) {
  const std::string command = std::string(ARPOS_EXECUTABLE) + " " + args + " 2>&1";
  FILE* pipe = popen(command.c_str(), "r");
  if (!pipe) return -1;
  char buffer[4096];
  size_t n;
  while ((n = fread(buffer, 1, sizeof(buffer), pipe)) > 0) output->append(buffer, n);
  const int status = pclose(pipe);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

class GuiTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!std::getenv("DISPLAY")) GTEST_SKIP() << "no X display: run through tools/test.sh (xvfb-run)";
    testing::WriteTinyCase(case_dir());
    // A store with a plan whose reference model is a 10 cm tetrahedron.
    auto database = SqliteDatabase::Open(store().string());
    PatientRecord patient;
    patient.external_id = "case";
    PlanRecord plan;
    plan.patient_id = database->AddPatient(patient);
    database->AppendAudit({AuditId(), 0, "gui_test", "add_patient", "patient:1", ""});
    plan.name = "case plan";
    plan.reference_model_name = "reference_model.ply";
    plan.reference_model.vertices = {{0, 0, 0}, {0.1f, 0, 0}, {0, 0.1f, 0}, {0, 0, 0.1f}};
    plan.reference_model.faces = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
    database->AddPlan(plan);
    database->AppendAudit({AuditId(), 0, "gui_test", "add_plan", "plan:1", ""});
  }
  std::filesystem::path case_dir() const { return dir_.path() / "case"; }
  std::filesystem::path store() const { return dir_.path() / "store.db"; }
  cv::Mat Screenshot(int page) {
    const auto png = dir_.path() / ("page" + std::to_string(page) + ".png");
    std::string out;
    EXPECT_EQ(RunArpos("gui --store " + store().string() + " --case " + case_dir().string() +
                           " --page " + std::to_string(page) + " --screenshot " + png.string(),
                       &out),
              0)
        << out;
    return cv::imread(png.string(), cv::IMREAD_COLOR);
  }
  TempDir dir_;
};

TEST_F(GuiTest, EveryPageDraws) {
  for (int page = 0; page <= 4; ++page) {
    const cv::Mat shot = Screenshot(page);
    ASSERT_FALSE(shot.empty()) << "page " << page;
    EXPECT_GE(shot.cols, 800) << "page " << page;
    EXPECT_GE(shot.rows, 600) << "page " << page;
    cv::Scalar mean, stddev;
    cv::meanStdDev(shot, mean, stddev);
    EXPECT_GT(stddev[0] + stddev[1] + stddev[2], 10.0) << "page " << page << " is blank";
  }
}

// The audit page says whether the log verifies: green when it does, red
// (naming the first problem) once an entry was changed past the program.
TEST_F(GuiTest, AuditPageShowsWhetherTheLogVerifies) {
  auto count = [](const cv::Mat& shot, bool green) {
    int n = 0;
    for (int y = 0; y < shot.rows; ++y) {
      for (int x = 0; x < shot.cols; ++x) {
        const cv::Vec3b p = shot.at<cv::Vec3b>(y, x);  // BGR
        if (green ? (p[1] > 100 && p[1] > p[2] + 50 && p[1] > p[0] + 50)
                  : (p[2] > 150 && p[2] > p[1] + 80 && p[2] > p[0] + 80)) {
          ++n;
        }
      }
    }
    return n;
  };
  const cv::Mat verified = Screenshot(4);
  ASSERT_FALSE(verified.empty());
  EXPECT_GT(count(verified, true), 2000) << "no green verification line";
  EXPECT_LT(count(verified, false), 200);
  cv::imwrite((dir_.path() / "audit_verified.png").string(), verified);
  {
    auto database = SqliteDatabase::Open(store().string());
    char* error = nullptr;
    ASSERT_EQ(sqlite3_exec(database->RawHandle(),
                           "DROP TRIGGER audit_log_refuse_update; UPDATE audit_log SET actor = 'x' WHERE audit_id = 2",
                           nullptr, nullptr, &error),
              SQLITE_OK)
        << (error ? error : "");
  }
  const cv::Mat tampered = Screenshot(4);
  ASSERT_FALSE(tampered.empty());
  EXPECT_GT(count(tampered, false), 2000) << "no red verification line";
  EXPECT_LT(count(tampered, true), 200);
  // The changed entry's row is marked (pale red).
  int marked = 0;
  for (int y = 0; y < tampered.rows; ++y) {
    for (int x = 0; x < tampered.cols; ++x) {
      const cv::Vec3b p = tampered.at<cv::Vec3b>(y, x);
      marked += p[2] > 240 && std::abs(p[1] - 205) < 12 && std::abs(p[0] - 205) < 12;
    }
  }
  EXPECT_GT(marked, 5000) << "the changed entry's row is not marked";
}

TEST_F(GuiTest, PlanningPageRendersTheReferenceModelInBlue) {
  const cv::Mat shot = Screenshot(1);
  ASSERT_FALSE(shot.empty());
  int blue = 0;
  for (int y = 0; y < shot.rows; ++y) {
    for (int x = 0; x < shot.cols; ++x) {
      const cv::Vec3b p = shot.at<cv::Vec3b>(y, x);  // BGR
      if (p[0] > p[2] + 60 && p[0] > p[1] + 30) ++blue;
    }
  }
  // The VTK view drew the model (no OpenGL context means no blue at all).
  EXPECT_GT(blue, 300);
}

// After run-case on the sample session, the session page shows the
// reconstruction coloured by its distance to the aligned model: on the
// sample's good alignment, mostly green (under 2 mm), little red.
TEST_F(GuiTest, SessionPageColoursTheSurfaceByItsDistanceToTheAlignedModel) {
  const auto sample = std::filesystem::path(ARPOS_SAMPLE_SESSIONS_DIR) / "demo_xtion";
  const auto session_store = dir_.path() / "session.db";
  std::string out;
  ASSERT_EQ(RunArpos("run-case " + sample.string() + " --store " + session_store.string(), &out), 0) << out;
  const auto png = dir_.path() / "session_page.png";
  out.clear();
  ASSERT_EQ(RunArpos("gui --store " + session_store.string() + " --case " + sample.string() +
                         " --page 2 --screenshot " + png.string(),
                     &out),
            0)
      << out;
  const cv::Mat shot = cv::imread(png.string(), cv::IMREAD_COLOR);
  ASSERT_FALSE(shot.empty());
  int red = 0, green = 0;
  for (int y = 0; y < shot.rows; ++y) {
    for (int x = 0; x < shot.cols; ++x) {
      const cv::Vec3b p = shot.at<cv::Vec3b>(y, x);  // BGR
      if (p[2] > p[0] + 50 && p[2] > p[1] + 50) ++red;
      if (p[1] > p[0] + 50 && p[1] > p[2] + 50) ++green;
    }
  }
  EXPECT_GT(green, 3000);
  EXPECT_LT(red, green / 5);
}

// After run-case, the planning page shows the room map: the mapped room
// markers as orange squares (and its residuals in the label).
TEST_F(GuiTest, PlanningPageShowsTheRoomMapMarkers) {
  const auto sample = std::filesystem::path(ARPOS_SAMPLE_SESSIONS_DIR) / "demo_xtion";
  const auto store = dir_.path() / "plan.db";
  std::string out;
  ASSERT_EQ(RunArpos("plan " + sample.string() + " --store " + store.string(), &out), 0) << out;
  const auto png = dir_.path() / "planning_page.png";
  out.clear();
  ASSERT_EQ(RunArpos("gui --store " + store.string() + " --case " + sample.string() + " --page 1 --screenshot " +
                         png.string(),
                     &out),
            0)
      << out;
  const cv::Mat shot = cv::imread(png.string(), cv::IMREAD_COLOR);
  ASSERT_FALSE(shot.empty());
  int orange = 0;
  for (int y = 0; y < shot.rows; ++y) {
    for (int x = 0; x < shot.cols; ++x) {
      const cv::Vec3b p = shot.at<cv::Vec3b>(y, x);  // BGR
      if (p[2] > 180 && p[1] > 90 && p[1] < 200 && p[0] < 80) ++orange;
    }
  }
  // Four or more markers of ~15 px squares seen from above.
  EXPECT_GT(orange, 200);
}

}  // namespace
}  // namespace arpos
