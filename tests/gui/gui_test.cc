// Opens every wizard page of the real executable and looks at what it shows.
#include <gtest/gtest.h>
#include <sqlite3.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <iostream>
#include <opencv2/imgcodecs.hpp>
#include <optional>
#include <string>
#include <vector>

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

// Keeps a screenshot in the artefacts folder for a person to look at and
// prints its path.
void KeepScreenshot(const cv::Mat& shot, const std::string& name) {
  if (shot.empty()) return;
  std::filesystem::create_directories(ARPOS_GUI_ARTIFACTS_DIR);
  const auto kept = std::filesystem::path(ARPOS_GUI_ARTIFACTS_DIR) / (name + ".png");
  cv::imwrite(kept.string(), shot);
  std::cout << "screenshot: " << kept.string() << "\n";
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
    const cv::Mat shot = cv::imread(png.string(), cv::IMREAD_COLOR);
    KeepScreenshot(shot, "tiny_case_page" + std::to_string(page));
    return shot;
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
  KeepScreenshot(verified, "audit_verified");
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
  KeepScreenshot(shot, "sample_session_page");
  ASSERT_FALSE(shot.empty());
  int red = 0, green = 0, green_left = shot.cols, green_right = -1;
  for (int y = 0; y < shot.rows; ++y) {
    for (int x = 0; x < shot.cols; ++x) {
      const cv::Vec3b p = shot.at<cv::Vec3b>(y, x);  // BGR
      if (p[2] > p[0] + 50 && p[2] > p[1] + 50) ++red;
      if (p[1] > p[0] + 50 && p[1] > p[2] + 50) {
        ++green;
        green_left = std::min(green_left, x);
        green_right = std::max(green_right, x);
      }
    }
  }
  EXPECT_GT(green, 3000);
  EXPECT_LT(red, green / 5);
  // The view is framed on the patient, not on everything at once: the
  // surface spans over a third of the window (the whole body was a fifth).
  EXPECT_GT(green_right - green_left, shot.cols / 3)
      << "the surface spans x " << green_left << ".." << green_right;
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
  KeepScreenshot(shot, "sample_planning_page");
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
  // Below the view, in red, what the room frame does to tracking when three
  // of its sigmas exceed the default tolerances (2 mm / 1 deg); nothing red
  // otherwise.
  const auto database = SqliteDatabase::Open(store.string());
  const auto map = database->GetRoomMap(*database->LatestRoomMap(PlanId(1)));
  ASSERT_TRUE(map && map->room_frame_couch_sigma_mm && map->room_frame_tilt_sigma_deg &&
              map->room_frame_yaw_sigma_deg);
  const bool blocks =
      3 * *map->room_frame_couch_sigma_mm >= 2.0 ||
      3 * std::hypot(*map->room_frame_tilt_sigma_deg, *map->room_frame_yaw_sigma_deg) >= 1.0;
  int red_text = 0;
  for (int y = shot.rows * 2 / 3; y < shot.rows; ++y) {
    for (int x = 0; x < shot.cols; ++x) {
      const cv::Vec3b p = shot.at<cv::Vec3b>(y, x);  // BGR
      if (p[2] > 120 && p[1] < 80 && p[0] < 50 && p[2] > p[1] + 70) ++red_text;
    }
  }
  if (blocks) {
    EXPECT_GT(red_text, 300) << "room frame " << *map->room_frame_couch_sigma_mm
                             << " mm: no red warning";
  } else {
    EXPECT_LT(red_text, 20) << "room frame " << *map->room_frame_couch_sigma_mm
                            << " mm: a red warning";
  }
}

// ---------------------------------------------------------------- tracking page
// The live positioning screen on the sample: a store filled by run-case
// (plan, session, alignment), copied for each test. ctest runs each test in
// its own process, so the store is kept in the artefacts folder and made
// again only when the executable is newer (written aside, then renamed).
class TrackingPageTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    if (!std::getenv("DISPLAY")) return;
    namespace fs = std::filesystem;
    fs::create_directories(ARPOS_GUI_ARTIFACTS_DIR);
    sample_store_ = fs::path(ARPOS_GUI_ARTIFACTS_DIR) / "sample_store.db";
    std::error_code ec;
    if (fs::exists(sample_store_) && fs::last_write_time(sample_store_, ec) > fs::last_write_time(ARPOS_EXECUTABLE, ec)) {
      suite_ok_ = true;
      return;
    }
    TempDir dir("arpos_gui_tracking");
    std::string out;
    suite_ok_ = RunArpos("run-case " + Sample().string() + " --keep-open --store " + (dir.path() / "store.db").string(), &out) == 0;
    if (!suite_ok_) {
      std::cerr << out;
      return;
    }
    const fs::path aside = sample_store_.string() + "." + std::to_string(::getpid());
    fs::copy_file(dir.path() / "store.db", aside, fs::copy_options::overwrite_existing);
    fs::rename(aside, sample_store_);
  }
  void SetUp() override {
    if (!std::getenv("DISPLAY")) GTEST_SKIP() << "no X display: run through tools/test.sh (xvfb-run)";
    ASSERT_TRUE(suite_ok_) << "run-case on the sample failed";
    std::filesystem::copy_file(sample_store_, store());
  }
  static std::filesystem::path Sample() { return std::filesystem::path(ARPOS_SAMPLE_SESSIONS_DIR) / "demo_xtion"; }
  std::filesystem::path store() const { return dir_.path() / "store.db"; }
  // Runs the GUI on the tracking page; returns the screenshot (also kept in
  // the artefacts folder, its path printed).
  cv::Mat RunPage(const std::string& case_dir, const std::string& options, const std::string& artefact,
                  std::string* output) {
    const auto png = dir_.path() / (artefact + ".png");
    EXPECT_EQ(RunArpos("gui --store " + store().string() + " --case " + case_dir + " --page 3 " + options +
                           " --screenshot " + png.string(),
                       output),
              0)
        << *output;
    const cv::Mat shot = cv::imread(png.string(), cv::IMREAD_COLOR);
    if (!shot.empty()) {
      std::filesystem::create_directories(ARPOS_GUI_ARTIFACTS_DIR);
      const auto kept = std::filesystem::path(ARPOS_GUI_ARTIFACTS_DIR) / (artefact + ".png");
      cv::imwrite(kept.string(), shot);
      std::cout << "screenshot: " << kept.string() << "\n";
    }
    return shot;
  }
  // The newest tracking run in the store (run-case stored the first).
  std::optional<TrackingRunRecord> NewestRun(std::vector<TrackingFrameRecord>* frames) {
    auto database = SqliteDatabase::Open(store().string());
    std::optional<TrackingRunRecord> newest;
    for (long long id = 1; id < 100; ++id) {
      auto run = database->GetTrackingRun(TrackingRunId(id));
      if (!run) break;
      newest = run;
    }
    if (newest && frames) *frames = database->GetTrackingFrames(newest->id);
    return newest;
  }
  // Plays the page to the end with `options` (and --play, a screenshot when
  // done): the one run it stored, with its frames; nullopt (and a failure)
  // otherwise.
  std::optional<TrackingRunRecord> PlayToTheEnd(const std::string& options, const std::string& artefact,
                                                cv::Mat* shot, std::vector<TrackingFrameRecord>* frames) {
    const int runs_before = TrackingRunCount();
    std::string out;
    *shot = RunPage(Sample().string(), "--play " + options + " --screenshot-when-done", artefact, &out);
    EXPECT_FALSE(shot->empty());
    EXPECT_NE(out.find("tracking run stored"), std::string::npos) << out;
    EXPECT_EQ(TrackingRunCount(), runs_before + 1);
    if (shot->empty() || TrackingRunCount() != runs_before + 1) return std::nullopt;
    return NewestRun(frames);
  }
  int TrackingRunCount() {
    auto database = SqliteDatabase::Open(store().string());
    int n = 0;
    while (database->GetTrackingRun(TrackingRunId(n + 1))) ++n;
    return n;
  }
  TempDir dir_;
  static std::filesystem::path sample_store_;
  static bool suite_ok_;
};
std::filesystem::path TrackingPageTest::sample_store_;
bool TrackingPageTest::suite_ok_ = false;

// Pixels of `shot` within `roi` for which `pick` (BGR) holds.
template <typename Pick>
int CountPixels(const cv::Mat& shot, const cv::Rect& roi, Pick pick) {
  int n = 0;
  const cv::Rect r = roi & cv::Rect(0, 0, shot.cols, shot.rows);
  for (int y = r.y; y < r.y + r.height; ++y) {
    for (int x = r.x; x < r.x + r.width; ++x) n += pick(shot.at<cv::Vec3b>(y, x));
  }
  return n;
}

// Played to the end: the run with every frame is stored, and the page shows
// the overlay (red current pose, blue planned pose) and the correction panel.
TEST_F(TrackingPageTest, PlaysTheSequenceToTheEndAndStoresTheRun) {
  cv::Mat shot;
  std::vector<TrackingFrameRecord> frames;
  const auto run = PlayToTheEnd("--fast --sequence tracking/seq_00", "tracking_page_end", &shot, &frames);
  ASSERT_TRUE(run.has_value());
  EXPECT_EQ(run->sequence_name, "seq_00");
  EXPECT_EQ(frames.size(), 3u);  // the sample's tracking/seq_00
  EXPECT_EQ(run->summary.find("stopped"), std::string::npos) << run->summary;

  // The camera image with the overlay fills the left of the page, the
  // correction panel the right. The sample's own frames have about 1000
  // pixels that pass for the red tint (skin does not: its green is higher)
  // and a few hundred blue ones, no light-blue outline.
  const cv::Rect image_area(0, 0, shot.cols * 3 / 5, shot.rows * 3 / 4);
  const int red = CountPixels(shot, image_area, [](const cv::Vec3b& p) {
    return p[2] > 110 && p[2] > p[1] + 60 && p[1] < 130;
  });
  const int blue = CountPixels(shot, image_area, [](const cv::Vec3b& p) {
    const bool fill = p[0] > 120 && p[0] > p[2] + 60 && p[0] > p[1] + 20;
    const bool outline = p[0] > 200 && p[1] > 150 && p[2] < 160;
    return fill || outline;
  });
  EXPECT_GT(red, 10000) << "no model at the current pose (red)";
  EXPECT_GT(blue, 1500) << "no model at the planned pose (blue)";
  // The panel: its dark background and a banner in a state colour (green,
  // amber or red), on the right.
  const cv::Rect panel_area(shot.cols * 3 / 5, 0, shot.cols * 2 / 5, shot.rows * 3 / 4);
  const int panel_background = CountPixels(shot, panel_area, [](const cv::Vec3b& p) {
    return std::abs(p[0] - 0x28) < 4 && std::abs(p[1] - 0x21) < 4 && std::abs(p[2] - 0x1e) < 4;
  });
  EXPECT_GT(panel_background, 20000) << "no correction panel";
  const int banner = CountPixels(shot, panel_area, [](const cv::Vec3b& p) {
    const bool green = std::abs(p[2] - 46) < 6 && std::abs(p[1] - 125) < 6 && std::abs(p[0] - 50) < 6;
    const bool amber = std::abs(p[2] - 240) < 6 && std::abs(p[1] - 160) < 6 && p[0] < 8;
    const bool lost = std::abs(p[2] - 198) < 6 && std::abs(p[1] - 40) < 6 && std::abs(p[0] - 40) < 6;
    return green || amber || lost;
  });
  EXPECT_GT(banner, 5000) << "no state banner";
}

// A live camera (the simulator as one, at 30 fps) chosen on the page: played
// to its end, every frame the camera gave either tracked or counted as
// dropped, the run stored under a live name, the overlay shown.
TEST_F(TrackingPageTest, TracksALiveCameraAndStoresTheRun) {
  cv::Mat shot;
  std::vector<TrackingFrameRecord> frames;
  const auto run = PlayToTheEnd("--source 'sim:" + Sample().string() + "?frames=30&fps=30'", "tracking_page_live", &shot,
                                &frames);
  ASSERT_TRUE(run.has_value());
  EXPECT_EQ(run->sequence_name.rfind("live-", 0), 0u) << run->sequence_name;
  int dropped = 0;
  const size_t at = run->summary.find(" of 30 camera frames dropped");
  if (at != std::string::npos) dropped = std::stoi(run->summary.substr(run->summary.rfind("; ", at) + 2));
  EXPECT_EQ(static_cast<int>(frames.size()) + dropped, 30) << run->summary;
  EXPECT_GE(frames.size(), 15u) << run->summary;
  const cv::Rect image_area(0, 0, shot.cols * 3 / 5, shot.rows * 3 / 4);
  const int red = CountPixels(shot, image_area, [](const cv::Vec3b& p) {
    return p[2] > 110 && p[2] > p[1] + 60 && p[1] < 130;
  });
  EXPECT_GT(red, 5000) << "no model at the current pose (red)";
}

// Pause stops the frames: paused after the first, nothing more is tracked
// for seconds (unpaused, the three frames take well under that); quitting
// stores the one frame as a stopped run.
TEST_F(TrackingPageTest, PauseStopsFrameAdvance) {
  std::string out;
  const cv::Mat shot = RunPage(Sample().string(), "--play --fast --pause-after 1 --screenshot-delay 9000",
                               "tracking_page_paused", &out);
  ASSERT_FALSE(shot.empty());
  std::vector<TrackingFrameRecord> frames;
  const auto run = NewestRun(&frames);
  ASSERT_TRUE(run.has_value());
  EXPECT_EQ(frames.size(), 1u);
  EXPECT_NE(run->summary.find("stopped after 1 of 3 frames"), std::string::npos) << run->summary;
}

// Step tracks one frame at a time: two presses (the first starts the run
// paused), then nothing more until the window closes and the two frames are
// stored as a stopped run.
TEST_F(TrackingPageTest, StepTracksOneFrameAtATime) {
  std::string out;
  const cv::Mat shot = RunPage(Sample().string(), "--steps 2 --screenshot-delay 8000", "tracking_page_stepped", &out);
  ASSERT_FALSE(shot.empty());
  std::vector<TrackingFrameRecord> frames;
  const auto run = NewestRun(&frames);
  ASSERT_TRUE(run.has_value());
  EXPECT_EQ(frames.size(), 2u) << run->summary;
  EXPECT_NE(run->summary.find("stopped after 2 of 3 frames"), std::string::npos) << run->summary;
}

// A frame without its depth image is a frame with a stated state and note:
// paused on it, the page says so (red line under the plot) and shows the
// frame lost; played through, the run goes on to the end.
TEST_F(TrackingPageTest, MissingDepthFrameIsStatedNotFatal) {
  const auto case_dir = dir_.path() / "demo_xtion";
  std::filesystem::copy(Sample(), case_dir, std::filesystem::copy_options::recursive);
  // The second frame's depth image goes missing.
  std::vector<std::filesystem::path> depth;
  for (const auto& e : std::filesystem::directory_iterator(case_dir / "tracking" / "seq_00" / "depth")) {
    depth.push_back(e.path());
  }
  std::sort(depth.begin(), depth.end());
  ASSERT_EQ(depth.size(), 3u);
  std::filesystem::remove(depth[1]);

  std::string out;
  const cv::Mat paused = RunPage(case_dir.string(), "--play --fast --pause-after 2 --screenshot-delay 7000",
                                 "tracking_page_no_depth_frame", &out);
  ASSERT_FALSE(paused.empty());
  std::vector<TrackingFrameRecord> frames;
  auto run = NewestRun(&frames);
  ASSERT_TRUE(run.has_value());
  ASSERT_EQ(frames.size(), 2u) << run->summary;
  EXPECT_NE(frames[1].note.find("depth"), std::string::npos) << frames[1].note;
  // The frame line (under the plot) in red: "(no depth image)".
  const cv::Rect lines(0, paused.rows * 84 / 100, paused.cols * 7 / 10, paused.rows * 11 / 100);
  const int red_text = CountPixels(paused, lines, [](const cv::Vec3b& p) {
    return p[2] > 150 && p[1] < 90 && p[0] < 90;
  });
  EXPECT_GT(red_text, 100) << "the missing depth image is not stated";
  const cv::Rect panel_area(paused.cols * 3 / 5, 0, paused.cols * 2 / 5, paused.rows * 3 / 4);
  const int lost_banner = CountPixels(paused, panel_area, [](const cv::Vec3b& p) {
    return std::abs(p[2] - 198) < 6 && std::abs(p[1] - 40) < 6 && std::abs(p[0] - 40) < 6;
  });
  EXPECT_GT(lost_banner, 5000) << "no TRACKING LOST banner";

  out.clear();
  const cv::Mat end = RunPage(case_dir.string(), "--play --fast --screenshot-when-done", "tracking_page_no_depth_end", &out);
  ASSERT_FALSE(end.empty());
  EXPECT_NE(out.find("tracking run stored"), std::string::npos) << out;
  run = NewestRun(&frames);
  ASSERT_TRUE(run.has_value());
  ASSERT_EQ(frames.size(), 3u);
  EXPECT_NE(frames[1].note.find("depth"), std::string::npos) << frames[1].note;
}

// Closing the window while a run goes on asks first. No: the window stays
// (the screenshot is taken later). Yes: it closes at once and the frames
// tracked so far are stored as a stopped run.
TEST_F(TrackingPageTest, ClosingWhileTrackingAsksFirst) {
  const int runs_before = TrackingRunCount();
  std::string out;
  const auto common = "gui --store " + store().string() + " --case " + Sample().string() +
                      " --page 3 --play --fast --pause-after 1 --close-after 4000 --screenshot-delay 8000";
  const auto kept_png = dir_.path() / "kept.png";
  ASSERT_EQ(RunArpos(common + " --answer-close no --screenshot " + kept_png.string(), &out), 0) << out;
  EXPECT_NE(out.find("asked \"Stop tracking?"), std::string::npos) << out;
  EXPECT_TRUE(std::filesystem::exists(kept_png)) << "the window closed although the answer was no";

  out.clear();
  const auto closed_png = dir_.path() / "closed.png";
  ASSERT_EQ(RunArpos(common + " --answer-close yes --screenshot " + closed_png.string(), &out), 0) << out;
  EXPECT_NE(out.find("asked \"Stop tracking?"), std::string::npos) << out;
  EXPECT_FALSE(std::filesystem::exists(closed_png)) << "the window stayed open although the answer was yes";
  EXPECT_NE(out.find("tracking run stored: stopped after 1 of 3 frames"), std::string::npos) << out;
  EXPECT_EQ(TrackingRunCount(), runs_before + 2);
  std::vector<TrackingFrameRecord> frames;
  ASSERT_TRUE(NewestRun(&frames).has_value());
  EXPECT_EQ(frames.size(), 1u);
}

}  // namespace
}  // namespace arpos
