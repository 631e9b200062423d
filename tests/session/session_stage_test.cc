// The session stage through its controllers, on copies of the committed
// sample session (small: 24 room, 8 body-scan frames).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <set>
#include <sstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "controllers/run_case_controller.h"
#include "controllers/session_controller.h"
#include "features/marker_detector.h"
#include "geometry/mesh_io.h"
#include "geometry/pose_error.h"
#include "registration/reconstruction.h"
#include "room_map/plan_stage.h"
#include "sensor/case_folder.h"
#include "sensor/sequence.h"
#include "sensor/tum_io.h"
#include "simulation/simulation_truth.h"
#include "simulation/simulator.h"
#include "store/lifecycle.h"
#include "store/sqlite_database.h"
#include "util/check.h"
#include "util/file.h"

namespace arpos {
namespace {

namespace fs = std::filesystem;

fs::path CopySample(const TempDir& dir) {
  const fs::path to = dir.path() / "demo_xtion";
  fs::copy(fs::path(ARPOS_SAMPLE_SESSIONS_DIR) / "demo_xtion", to, fs::copy_options::recursive);
  return to;
}

TEST(AnchorCorrection, MeanOfTheRefinedFramesWithOutliersAndUnrefinedLeftOut) {
  const Eigen::Vector3d centre(0.7, 1.4, 0.9);
  auto report = [](bool used, bool refined, const Rigid3d& correction) {
    ReconstructionFrameReport r;
    r.used = used;
    r.refined = refined;
    r.correction = correction;
    return r;
  };
  const auto shift = [](double x, double y, double z) {
    return Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(x, y, z));
  };
  std::vector<ReconstructionFrameReport> reports = {
      report(true, false, Rigid3d::Identity()),    // the first frame: no correction
      report(false, false, shift(1, 1, 1)),        // skipped by the stride
      report(true, true, shift(0.003, 0, 0)),
      report(true, true, shift(0.003, 0.003, 0)),
      report(true, false, shift(0.5, 0, 0)),       // correction refused
      report(true, true, shift(0.002, -0.003, 0)),
      report(true, true, shift(0.2, 0, 0)),        // outlier
  };
  Rigid3d c = AnchorCorrection(reports, centre);
  EXPECT_NEAR((c.translation - Eigen::Vector3d(0.002, 0, 0)).norm(), 0, 1e-12);
  EXPECT_NEAR(c.RotationVector().norm(), 0, 1e-12);
  // Rotations about the room origin: the mean rotation, and the mean shift
  // of the centre.
  const Rigid3d turn = Rigid3d::FromRotationVector(Eigen::Vector3d(0, 0, 0.002), Eigen::Vector3d::Zero());
  reports = {report(true, false, Rigid3d::Identity()), report(true, true, turn), report(true, true, turn),
             report(true, true, turn)};
  c = AnchorCorrection(reports, centre);
  EXPECT_NEAR((c.RotationVector() - Eigen::Vector3d(0, 0, 0.0015)).norm(), 0, 1e-9);
  EXPECT_NEAR((c * centre - centre - 0.75 * (turn * centre - centre)).norm(), 0, 1e-9);
  // Fewer than three frames: nothing to average.
  reports.resize(2);
  c = AnchorCorrection(reports, centre);
  EXPECT_EQ(c.translation, Eigen::Vector3d::Zero());
  EXPECT_NEAR(c.RotationVector().norm(), 0, 1e-15);
}

// Takes body stickers off the patient after the fact: in every body_scan
// colour frame, each detected sticker whose id `hide` picks is painted over
// (its square enlarged by 80 % about the centre, filled with the median
// colour of a ring around it). Returns the ids painted over.
// `only_frame`: if given, the one colour image (file stem, e.g.
// "1003.000000") painted; else all.
std::set<int> PaintOutStickers(const fs::path& case_dir, const std::function<bool(int)>& hide,
                               const std::string& only_frame = "") {
  MarkerDetectorOptions options;
  options.id_ranges = {{100, 199}};
  std::set<int> painted;
  for (const auto& entry : fs::directory_iterator(case_dir / "body_scan" / "rgb")) {
    if (!only_frame.empty() && entry.path().stem().string() != only_frame) continue;
    cv::Mat image = cv::imread(entry.path().string(), cv::IMREAD_COLOR);
    EXPECT_FALSE(image.empty()) << entry.path();
    bool changed = false;
    for (const MarkerObservation& o : DetectMarkers(image, options)) {
      if (!hide(o.id)) continue;
      Eigen::Vector2d centre = Eigen::Vector2d::Zero();
      for (const auto& c : o.corners_px) centre += c / 4;
      std::vector<cv::Point> inner, outer;
      for (const auto& c : o.corners_px) {
        const Eigen::Vector2d a = centre + 1.8 * (c - centre), b = centre + 2.6 * (c - centre);
        inner.emplace_back(cvRound(a.x()), cvRound(a.y()));
        outer.emplace_back(cvRound(b.x()), cvRound(b.y()));
      }
      cv::Mat ring(image.size(), CV_8UC1, cv::Scalar(0));
      cv::fillConvexPoly(ring, outer, cv::Scalar(255));
      cv::fillConvexPoly(ring, inner, cv::Scalar(0));
      std::vector<cv::Vec3b> around;
      for (int y = 0; y < image.rows; ++y) {
        for (int x = 0; x < image.cols; ++x) {
          if (ring.at<std::uint8_t>(y, x)) around.push_back(image.at<cv::Vec3b>(y, x));
        }
      }
      cv::Vec3b fill(128, 128, 128);
      if (!around.empty()) {
        for (int ch = 0; ch < 3; ++ch) {
          std::vector<std::uint8_t> v;
          for (const auto& p : around) v.push_back(p[ch]);
          std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
          fill[ch] = v[v.size() / 2];
        }
      }
      cv::fillConvexPoly(image, inner, cv::Scalar(fill[0], fill[1], fill[2]));
      painted.insert(o.id);
      changed = true;
    }
    if (changed) {
      EXPECT_TRUE(cv::imwrite(entry.path().string(), image)) << entry.path();
    }
  }
  return painted;
}

// Takes the frame at `stamp` (e.g. "1009.000000") out of the scan's lists.
void DropScanFrame(const fs::path& case_dir, const std::string& stamp) {
  for (const char* list : {"rgb.txt", "depth.txt", "groundtruth.txt", "body_groundtruth.txt"}) {
    const fs::path file = case_dir / "body_scan" / list;
    if (!fs::exists(file)) continue;
    std::ifstream in(file);
    std::ostringstream kept;
    int dropped = 0;
    for (std::string line; std::getline(in, line);) {
      if (line.rfind(stamp + " ", 0) == 0) {
        ++dropped;
        continue;
      }
      kept << line << "\n";
    }
    in.close();
    EXPECT_EQ(dropped, 1) << file;
    std::ofstream(file) << kept.str();
  }
}

// The model pose the session wrote to `out_dir` against the case's body
// ground truth (the patient lies still: the first frame's).
PoseError ModelPoseErrorAtScanTime(const fs::path& case_dir, const fs::path& out_dir) {
  const auto truth = ReadTrajectory(case_dir / "body_scan" / "body_groundtruth.txt");
  const auto estimate = ReadTrajectory(out_dir / "model_pose.txt");
  ARPOS_CHECK(!truth.empty() && !estimate.empty(), "no model pose or no body ground truth");
  return ComputePoseError(truth.front().room_from_x, estimate.front().room_from_x);
}

// run-case on `case_dir` into `db`; session outputs into `out_dir` if given.
RunCaseResult RunCase(const fs::path& case_dir, Database* db, std::optional<fs::path> out_dir = std::nullopt) {
  RunCaseOptions options;
  options.case_dir = case_dir;
  options.out_dir = out_dir;
  options.keep_session_open = true;  // the manual alignment below adds to it
  RunCaseController run(options, db);
  run.Run();
  return run.result();
}

// How far each room landmark a session's scan placed lies from the depth
// the scan's frames read at its pixel, seen from the true cameras: the
// median over its readings (at least three; a reading nearer by more than
// 5 cm is something in front, left out), mm, signed, sorted by size.
std::vector<double> ScanLandmarkDepthOffsetsMm(const fs::path& case_dir,
                                               const BodyMarkerMapRecord& map) {
  const CaseFolder folder = LoadCaseFolder(case_dir);
  const Sequence scan = Sequence::Open(folder.body_scan_dir);
  const auto cameras = ReadTrajectory(folder.body_scan_dir / "groundtruth.txt");
  std::vector<std::vector<double>> readings(map.room_landmarks.points.size());
  for (size_t i = 0; i < scan.size(); ++i) {
    const RgbdFrame frame = scan.LoadFrame(i, folder.config.camera);
    const Rigid3d camera_from_room = cameras[i].room_from_x.Inverse();
    for (size_t l = 0; l < readings.size(); ++l) {
      const Eigen::Vector3d p = camera_from_room * map.room_landmarks.points[l].cast<double>();
      if (p.z() < 0.3) continue;
      const Eigen::Vector2d uv = folder.config.camera.Project(p);
      const int u = static_cast<int>(std::lround(uv.x())),
                v = static_cast<int>(std::lround(uv.y()));
      if (u < 0 || v < 0 || u >= frame.depth.cols || v >= frame.depth.rows) continue;
      const double z = frame.depth.at<std::uint16_t>(v, u) / folder.config.camera.depth_scale;
      if (z > 0 && z > p.z() - 0.05) readings[l].push_back(1000 * (p.z() - z));
    }
  }
  std::vector<double> off_mm;
  for (auto& r : readings) {
    if (r.size() < 3) continue;
    std::nth_element(r.begin(), r.begin() + r.size() / 2, r.end());
    off_mm.push_back(r[r.size() / 2]);
  }
  std::sort(off_mm.begin(), off_mm.end(),
            [](double a, double b) { return std::abs(a) < std::abs(b); });
  return off_mm;
}

TEST(SessionStage, SampleSessionGivesStickersReconstructionAndModelPose) {
  TempDir dir;
  const fs::path case_dir = CopySample(dir);
  auto db = SqliteDatabase::Open((dir.path() / "store.db").string());
  const RunCaseResult r = RunCase(case_dir, db.get(), dir.path() / "out");
  ASSERT_TRUE(r.ok()) << r.Summary();
  EXPECT_NE(r.session_summary.find("more posed from the stickers"), std::string::npos);
  const auto truth = ReadTrajectory(case_dir / "body_scan" / "body_groundtruth.txt");
  const auto estimate = ReadTrajectory(dir.path() / "out" / "model_pose.txt");
  ASSERT_EQ(truth.size(), estimate.size());
  const PoseError e = ComputePoseError(truth.front().room_from_x, estimate.front().room_from_x);
  EXPECT_LT(e.translation_mm, 5.0);
  EXPECT_LT(e.rotation_deg, 0.5);
  EXPECT_EQ(db->ListSessions(r.plan_id).size(), 1u);

  // What tracking uses: each sticker relative to the reference model, here
  // stored sticker pose and estimated model pose against simulation.yaml.
  // Measured: mean 0.25 mm, max 0.41 (1.28 / 2.76 mm from the
  // sticker-consistent cameras before they were registered to the surface).
  const sim::SimulationTruth sim_truth = sim::LoadSimulationTruth(case_dir / "simulation.yaml");
  const auto maps = db->ListBodyMarkerMapIds(r.session_id);
  ASSERT_EQ(maps.size(), 1u);
  const auto map = db->GetBodyMarkerMap(maps[0]);
  ASSERT_TRUE(map.has_value());
  ASSERT_GE(map->markers.size(), 5u);
  for (const auto& m : map->markers) {
    const Rigid3d model_from_marker = estimate.front().room_from_x.Inverse() * m.body_from_marker;
    bool found = false;
    for (const auto& t : sim_truth.body_markers) {
      if (t.id != m.marker_id) continue;
      found = true;
      const PoseError s = ComputePoseError(t.parent_from_marker, model_from_marker);
      EXPECT_LT(s.translation_mm, 1.0) << "sticker " << m.marker_id;
      EXPECT_LT(s.rotation_deg, 0.5) << "sticker " << m.marker_id;
    }
    EXPECT_TRUE(found) << "sticker " << m.marker_id << " is not on the simulated body";
  }

  // Placed by the room map in two frames only, the scan's placement is not
  // known: it adds no room landmarks for tracking (what they would carry
  // could not be bounded).
  EXPECT_NE(r.session_summary.find("uncertainty unknown"), std::string::npos) << r.session_summary;
  EXPECT_TRUE(map->room_landmarks.points.empty());
}

// The stage's algorithm needs no store: the room map built from the case,
// the case's model and target pose in, a model pose and stickers out; a
// cancel request stops it between steps.
// What the session stage takes from a plan, made from the case itself.
SessionPlanInputs PlanInputsOf(const CaseFolder& folder) {
  SessionPlanInputs plan;
  plan.room_map = BuildCaseRoomMap(folder, RoomMapStageOptions()).map;
  plan.model = LoadTriangleMesh(folder.reference_model);
  plan.room_from_model_target = folder.room_from_model_target;
  return plan;
}

TEST(SessionStage, TheStageRunsWithoutAStoreAndStopsWhenCancelled) {
  TempDir dir;
  const fs::path case_dir = CopySample(dir);
  const CaseFolder folder = LoadCaseFolder(case_dir);
  const SessionPlanInputs plan = PlanInputsOf(folder);
  SessionStageOptions options;
  options.case_dir = case_dir;
  std::vector<std::string> steps;
  ControllerCallbacks callbacks;
  callbacks.progress = [&steps](const std::string& step, double) { steps.push_back(step); };
  const SessionStageResult r = BuildSession(folder, plan, options, callbacks);
  EXPECT_GE(r.marker_map.markers.size(), 5u);
  EXPECT_FALSE(r.mesh.empty());
  EXPECT_EQ(r.model_from_markers.size(), r.marker_map.markers.size());
  const auto truth = ReadTrajectory(case_dir / "body_scan" / "body_groundtruth.txt");
  const PoseError e = ComputePoseError(truth.front().room_from_x, r.room_from_model);
  EXPECT_LT(e.translation_mm, 5.0);
  EXPECT_LT(e.rotation_deg, 0.5);
  EXPECT_EQ(r.session_id, SessionId());  // nothing stored
  ASSERT_FALSE(steps.empty());
  EXPECT_EQ(steps.back(), "aligning the reference model");
  // 3 cm stickers: readable (12 px across) up to fx * 0.03 / 12 from this camera.
  EXPECT_NEAR(r.sticker_reading_distance_m, folder.config.camera.fx * folder.config.body_markers.size_m / 12, 1e-9);
  for (const std::string& w : r.warnings) EXPECT_EQ(w.find("stickers ("), std::string::npos) << w;
  EXPECT_NE(r.Summary().find("stickers readable up to"), std::string::npos) << r.Summary();
  // Tracking from 5 m would need larger stickers: said, with the size.
  SessionStageOptions far = options;
  far.min_sticker_reading_distance_m = 5.0;
  const SessionStageResult f = BuildSession(folder, plan, far);
  bool said = false;
  for (const std::string& w : f.warnings) said |= w.find("use stickers of at least") != std::string::npos;
  EXPECT_TRUE(said) << f.Summary();

  // Cancelled after the reconstruction: no result.
  callbacks.cancel_requested = [&steps] { return !steps.empty() && steps.back() == "meshing (Poisson)"; };
  steps.clear();
  EXPECT_THROW(BuildSession(folder, plan, options, callbacks), Cancelled);
  EXPECT_EQ(steps.back(), "meshing (Poisson)");
}

// Stickers against the aligned reference surface (sticker_surface.h): on
// the sample all lie within 2 mm of it; with the limit set between the
// third and second farthest, those two are named, left out of the map and
// the alignment asks for a check; with no sticker within the limit none is
// left out (too few would remain), and the warning says they were kept.
TEST(SessionStage, StickersOffTheAlignedModelAreNamedAndLeftOutWhileEnoughRemain) {
  TempDir dir;
  const fs::path case_dir = CopySample(dir);
  const CaseFolder folder = LoadCaseFolder(case_dir);
  const SessionPlanInputs plan = PlanInputsOf(folder);
  SessionStageOptions options;
  options.case_dir = case_dir;
  const SessionStageResult r = BuildSession(folder, plan, options);
  ASSERT_GE(r.sticker_surface.off_m.size(), 5u);
  EXPECT_TRUE(r.sticker_surface.off.empty());
  EXPECT_EQ(r.alignment_status, "ok");
  EXPECT_NE(r.Summary().find("stickers on the aligned reference surface: "), std::string::npos)
      << r.Summary();
  std::vector<std::pair<double, int>> by_distance;
  for (const auto& [id, d] : r.sticker_surface.off_m) {
    EXPECT_LT(d, 0.004) << "sticker " << id;
    by_distance.emplace_back(d, id);
  }
  std::sort(by_distance.rbegin(), by_distance.rend());
  ASSERT_LT(by_distance[2].first, by_distance[1].first);

  SessionStageOptions two = options;
  two.max_sticker_off_model_m = 0.5 * (by_distance[1].first + by_distance[2].first);
  const SessionStageResult t = BuildSession(folder, plan, two);
  ASSERT_EQ(t.sticker_surface.off.size(), 2u) << t.Summary();
  for (int k = 0; k < 2; ++k) {
    const int id = by_distance[k].second;
    EXPECT_EQ(t.model_from_markers.count(id), 0u) << id;
    for (const auto& m : t.marker_map.markers) EXPECT_NE(m.marker_id, id);
    ASSERT_EQ(t.marker_map.rejected.count(id), 1u) << id;
    EXPECT_NE(t.marker_map.rejected.at(id).find("off the aligned reference surface"),
              std::string::npos);
  }
  EXPECT_EQ(t.model_from_markers.size(), r.model_from_markers.size() - 2);
  EXPECT_EQ(t.alignment_status, "check: 2 sticker(s) off the aligned model");
  bool said = false;
  for (const std::string& w : t.warnings)
    said |= w.find("(left out of the map)") != std::string::npos;
  EXPECT_TRUE(said) << t.Summary();

  SessionStageOptions all = options;
  all.max_sticker_off_model_m = 0;
  const SessionStageResult a = BuildSession(folder, plan, all);
  EXPECT_EQ(a.sticker_surface.off.size(), r.sticker_surface.off_m.size());
  EXPECT_EQ(a.model_from_markers.size(), r.model_from_markers.size());
  said = false;
  for (const std::string& w : a.warnings)
    said |= w.find("(kept: too few would remain)") != std::string::npos;
  EXPECT_TRUE(said) << a.Summary();
}

// A room map that lacks the markers the body scan reads (left out of the
// plan, as a marker seen in too few views of the room is): the stage stops
// naming the markers it read and those the map holds, and says what to
// record, rather than only that no frame could be placed.
TEST(SessionStage, AScanWhoseRoomMarkersTheMapLacksNamesThem) {
  TempDir dir;
  const fs::path case_dir = CopySample(dir);
  const CaseFolder folder = LoadCaseFolder(case_dir);
  SessionPlanInputs plan = PlanInputsOf(folder);
  // Only the origin marker and no keypoint layer: nothing the scan sees.
  std::set<int> removed;
  std::vector<RoomMapMarkerEntry> kept;
  for (const RoomMapMarkerEntry& m : plan.room_map.markers) {
    if (m.id == plan.room_map.origin_marker_id) {
      kept.push_back(m);
    } else {
      removed.insert(m.id);
    }
  }
  ASSERT_FALSE(removed.empty());
  plan.room_map.markers = kept;
  plan.room_map.landmarks_in_room.clear();
  plan.room_map.landmark_descriptors = cv::Mat();
  plan.room_map.surface = RoomSurface();
  ASSERT_EQ(plan.room_map.Validate(), "");
  SessionStageOptions options;
  options.case_dir = case_dir;
  try {
    BuildSession(folder, plan, options);
    FAIL() << "a scan the room map cannot place was accepted";
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("body_scan"), std::string::npos) << what;
    EXPECT_NE(what.find("could not be localised in the room map"), std::string::npos) << what;
    EXPECT_NE(what.find("that the room map does not hold"), std::string::npos) << what;
    // The markers named as read are not the map's (the sample's own plan
    // already leaves some out); at least one is a marker taken out here.
    const size_t at = what.find("reads room marker(s) ");
    ASSERT_NE(at, std::string::npos) << what;
    std::istringstream ids(what.substr(at + 21, what.find(" that the room map") - at - 21));
    std::string item;
    int named_removed = 0;
    while (std::getline(ids, item, ',')) {
      const int id = std::stoi(item);
      EXPECT_NE(id, plan.room_map.origin_marker_id) << what;
      named_removed += static_cast<int>(removed.count(id));
    }
    EXPECT_GE(named_removed, 1) << what;
    EXPECT_NE(what.find("it holds near the couch " + std::to_string(plan.room_map.origin_marker_id)),
              std::string::npos)
        << what;
  }
}

// Stickers in view but none mapped, because the room map places the camera
// in one frame of the scan, and that frame shows no sticker (the sticker map
// is seeded from the frames the room map places): the error names the
// placement and what to record, not only the stickers (measured on a random
// case, --hard: a body surface of 177 points was blamed, with 1 of 40
// frames placed).
TEST(SessionStage, StickersLeftUnmappedForWantOfPlacedFramesSaySo) {
  TempDir dir;
  const fs::path case_dir = CopySample(dir);
  // The sample's scan is placed by the room map in two frames (1003, 1009).
  DropScanFrame(case_dir, "1009.000000");
  ASSERT_FALSE(PaintOutStickers(case_dir, [](int) { return true; }, "1003.000000").empty());
  auto db = SqliteDatabase::Open((dir.path() / "store.db").string());
  const RunCaseResult r = RunCase(case_dir, db.get());
  ASSERT_FALSE(r.ok());
  ASSERT_EQ(r.failures.size(), 1u) << r.Summary();
  const std::string& what = r.failures.front();
  EXPECT_NE(what.find("body sticker(s) mapped"), std::string::npos) << what;
  EXPECT_NE(what.find("the camera was placed in 1 of the"), std::string::npos) << what;
  EXPECT_NE(what.find("1 by the room map"), std::string::npos) << what;
  EXPECT_NE(what.find("record the room again"), std::string::npos) << what;
  EXPECT_EQ(db->ListSessions(r.plan_id).size(), 0u);
}

// A small case: seed 3, 24 room frames around the couch, 24 body-scan
// frames, one tracking frame.
sim::SimulationOptions SmallCouchCase() {
  sim::SimulationOptions o;
  o.seed = 3;
  o.room_walk = "couch";
  o.room_frames = 24;
  o.body_scan_frames = 24;
  o.tracking_frames = 1;
  o.tracking_sequences = 1;
  return o;
}

// A simulated scan long enough for several frames to see the room: the
// room offset is taken again from the room-localised frames registered to
// the reconstruction (step 5), and the model pose and the stickers on the
// model come out within the goals' order (measured on this case: 1.36 mm,
// 0.056 deg, offset from 6 frames).
TEST(SessionStage, RoomOffsetFromFramesRegisteredToTheSurface) {
  TempDir dir;
  const fs::path case_dir = dir.path() / "case";
  sim::Simulator(SmallCouchCase()).WriteCase(case_dir);
  auto db = SqliteDatabase::Open((dir.path() / "store.db").string());
  const RunCaseResult r = RunCase(case_dir, db.get(), dir.path() / "out");
  ASSERT_TRUE(r.ok()) << r.Summary();
  EXPECT_NE(r.session_summary.find("placed from"), std::string::npos) << r.session_summary;
  EXPECT_NE(r.session_summary.find("room offset from"), std::string::npos) << r.session_summary;
  const PoseError e = ModelPoseErrorAtScanTime(case_dir, dir.path() / "out");
  EXPECT_LT(e.translation_mm, 3.0);
  EXPECT_LT(e.rotation_deg, 0.2);
  // How well the scan is placed in the room is said, stored with the
  // session, and honest (the error within 3 sigma and 1 mm for the rest).
  const size_t at = r.session_summary.find("the scan placed in the room from ");
  ASSERT_NE(at, std::string::npos) << r.session_summary;
  int frames = 0, runs = 0;
  double sigma_mm = 0;
  ASSERT_EQ(std::sscanf(r.session_summary.c_str() + at, "the scan placed in the room from %d frames in %d run(s), %lf mm",
                        &frames, &runs, &sigma_mm),
            3)
      << r.session_summary;
  EXPECT_GE(frames, 3);
  EXPECT_GE(runs, 1);
  EXPECT_LE(runs, frames);
  EXPECT_GT(sigma_mm, 0.0);
  EXPECT_LT(e.translation_mm, 3 * sigma_mm + 1.0);
  const auto session = db->GetSession(r.session_id);
  ASSERT_TRUE(session.has_value());
  EXPECT_NE(session->notes.find("the scan placed in the room from"), std::string::npos) << session->notes;

  // The room landmarks the scan placed for tracking (scan_landmarks.h),
  // stored with its body marker map with how well they sit: where the room
  // is, outside the couch, to the depth noise (xtion: 5-13 mm at 2-3 m).
  // Measured: 277 landmarks, the median of each one's readings 3.3 mm off
  // (median; 8.5 mm at 90 %), 1.0 mm on average.
  const auto maps = db->ListBodyMarkerMapIds(r.session_id);
  ASSERT_EQ(maps.size(), 1u);
  const auto map = db->GetBodyMarkerMap(maps[0]);
  ASSERT_TRUE(map.has_value());
  ASSERT_GE(map->room_landmarks.points.size(), 50u) << r.session_summary;
  EXPECT_NEAR(1000 * map->room_landmarks_placement_sigma_m, sigma_mm, 0.01);
  EXPECT_GT(map->room_landmarks_position_sigma_m, 0.0);
  EXPECT_LT(map->room_landmarks_position_sigma_m, 0.01);
  const CaseFolder folder = LoadCaseFolder(case_dir);
  const ExclusionBox couch = CouchExclusionBox(folder.room_from_model_target);
  for (const Eigen::Vector3f& x : map->room_landmarks.points)
    EXPECT_FALSE(couch.Contains(x.cast<double>()));
  const std::vector<double> off_mm = ScanLandmarkDepthOffsetsMm(case_dir, *map);
  ASSERT_GE(off_mm.size(), 50u);
  double signed_mean = 0;
  for (double o : off_mm) signed_mean += o / off_mm.size();
  std::cout << map->room_landmarks.points.size() << " scan landmarks, " << off_mm.size()
            << " seen in 3+ frames: median |offset| " << std::abs(off_mm[off_mm.size() / 2])
            << " mm, 90 % " << std::abs(off_mm[off_mm.size() * 9 / 10]) << " mm, mean "
            << signed_mean << " mm\n";
  EXPECT_LT(std::abs(off_mm[off_mm.size() / 2]), 4.0);
  EXPECT_LT(std::abs(signed_mean), 3.0);
  EXPECT_NE(r.session_summary.find("room landmarks the scan sees, for tracking"),
            std::string::npos);
}

// Depth taken 12 ms after its colour (a camera without colour-depth sync):
// the room-localised scan frames are localised again with their depth as
// of their colour instant (SessionStageOptions::relocalise_delayed_depth),
// and the scan is placed by those poses; a synced scan has nothing to move.
// This small scan's frames are 0.5 s apart, beyond the motion the default
// trusts (relocalise_max_gap_s): left as read by default, and localised
// again with the limit opened to 0.5 s.
// Measured on six default-like cases with depth 6-12 ms early or late
// (benchmark/accuracy.md, session 45): the model at scan time 0.66 -> 0.51
// mm mean, 1.17 -> 0.68 mm at most.
TEST(SessionStage, DepthOfAnotherInstantIsLocalisedAgainAsOfItsColourInstant) {
  TempDir dir;
  sim::SimulationOptions o = SmallCouchCase();
  o.depth_delay_s = 0.012;
  const fs::path case_dir = dir.path() / "case";
  sim::Simulator(o).WriteCase(case_dir);
  const CaseFolder folder = LoadCaseFolder(case_dir);
  const SessionPlanInputs plan = PlanInputsOf(folder);
  const auto truth = ReadTrajectory(case_dir / "body_scan" / "body_groundtruth.txt");
  SessionStageOptions options;
  options.case_dir = case_dir;
  const SessionStageResult by_default = BuildSession(folder, plan, options);
  EXPECT_GT(by_default.frames_depth_moved_to_colour, 0);
  EXPECT_EQ(by_default.frames_relocalised_with_moved_depth, 0);
  options.relocalise_max_gap_s = 0.5;
  const SessionStageResult again = BuildSession(folder, plan, options);
  SessionStageOptions as_read = options;
  as_read.relocalise_delayed_depth = false;
  const SessionStageResult first = BuildSession(folder, plan, as_read);
  EXPECT_NEAR(ComputePoseError(first.room_from_model, by_default.room_from_model).translation_mm, 0,
              1e-9);
  EXPECT_GT(again.frames_depth_moved_to_colour, 0);
  EXPECT_GE(again.frames_relocalised_with_moved_depth, 3) << again.Summary();
  EXPECT_LE(again.frames_relocalised_with_moved_depth, again.frames_localized);
  EXPECT_NE(again.Summary().find("room-localised frame(s) localised again with it"),
            std::string::npos)
      << again.Summary();
  EXPECT_EQ(first.frames_relocalised_with_moved_depth, 0);
  const PoseError e_again = ComputePoseError(truth.front().room_from_x, again.room_from_model);
  const PoseError e_first = ComputePoseError(truth.front().room_from_x, first.room_from_model);
  std::cout << "model pose at scan time, depth 12 ms late: " << e_first.translation_mm << " mm, "
            << e_first.rotation_deg << " deg as read; " << e_again.translation_mm << " mm, "
            << e_again.rotation_deg << " deg localised again ("
            << again.frames_relocalised_with_moved_depth << " frames; placement "
            << again.room_placement_sigma_mm << " mm 1 sigma)\n";
  EXPECT_LT(e_again.translation_mm, 3.0);
  EXPECT_LT(e_again.rotation_deg, 0.2);
  EXPECT_LT(e_again.translation_mm, 3 * again.room_placement_sigma_mm + 1.0);
  // Measured 1.30 -> 0.75 mm here; not worse beyond run-to-run noise.
  EXPECT_LT(e_again.translation_mm, e_first.translation_mm + 0.3);

  // The same scene with synced depth: nothing to localise again.
  o.depth_delay_s = 0.0;
  const fs::path synced_dir = dir.path() / "synced";
  sim::Simulator(o).WriteCase(synced_dir);
  const CaseFolder synced = LoadCaseFolder(synced_dir);
  SessionStageOptions synced_options;
  synced_options.case_dir = synced_dir;
  const SessionStageResult s = BuildSession(synced, PlanInputsOf(synced), synced_options);
  EXPECT_EQ(s.frames_depth_moved_to_colour, 0);
  EXPECT_EQ(s.frames_relocalised_with_moved_depth, 0);
  EXPECT_EQ(s.Summary().find("localised again"), std::string::npos) << s.Summary();
}

// A patient who breathes (5 mm peak to peak, the simulator lifting the
// anterior torso along the model's -y): the session measures which way each
// breathing sticker moved, stores it with the map, and it is the chest's
// way, not the stickers' normals'.
TEST(SessionStage, BreathingStickersMoveTheWayTheScanSawThem) {
  TempDir dir;
  sim::SimulationOptions o;
  o.seed = 3;
  o.room_walk = "couch";
  o.room_frames = 24;
  o.body_scan_frames = 40;
  o.tracking_frames = 1;
  o.tracking_sequences = 1;
  o.breathing_mm = 5;
  const fs::path case_dir = dir.path() / "case";
  sim::Simulator(o).WriteCase(case_dir);
  auto db = SqliteDatabase::Open((dir.path() / "store.db").string());
  const RunCaseResult r = RunCase(case_dir, db.get(), dir.path() / "out");
  ASSERT_TRUE(r.ok()) << r.Summary();
  EXPECT_NE(r.session_summary.find("breathing stickers: directions of "), std::string::npos)
      << r.session_summary;
  const auto maps = db->ListBodyMarkerMapIds(r.session_id);
  ASSERT_EQ(maps.size(), 1u);
  const auto map = db->GetBodyMarkerMap(maps[0]);
  ASSERT_TRUE(map.has_value());
  const Rigid3d room_from_model =
      ReadTrajectory(case_dir / "body_scan" / "body_groundtruth.txt").front().room_from_x;
  const Eigen::Vector3d up = room_from_model.rotation * Eigen::Vector3d(0, -1, 0);
  int moving = 0, directed = 0;
  double normal_deg = 0, direction_deg = 0;
  for (const BodyMarker& m : map->markers) {
    if (!(m.motion_m > 0)) continue;
    ++moving;
    if (!m.HasMotionDirection()) continue;
    ++directed;
    const Eigen::Vector3d normal = m.body_from_marker.rotation * Eigen::Vector3d::UnitZ();
    const Eigen::Vector3d direction = m.body_from_marker.rotation * m.motion_direction;
    const double to_truth = std::acos(std::clamp(direction.dot(up), -1.0, 1.0)) * 180 / M_PI;
    EXPECT_LT(to_truth, 15.0) << "sticker " << m.marker_id;
    direction_deg += to_truth;
    normal_deg += std::acos(std::clamp(normal.dot(up), -1.0, 1.0)) * 180 / M_PI;
    EXPECT_GT(m.motion_m, 0.0005) << "sticker " << m.marker_id;
    EXPECT_LT(m.motion_m, 0.004) << "sticker " << m.marker_id;
  }
  std::cout << moving << " breathing stickers, " << directed
            << " with a direction: " << direction_deg / directed
            << " deg from the chest's way on average, their normals " << normal_deg / directed
            << " deg\n";
  ASSERT_GE(moving, 3) << r.session_summary;
  EXPECT_GE(directed, moving / 2) << r.session_summary;
  EXPECT_LT(direction_deg, normal_deg);
}

// A body scan with no patient on the couch (the room recording put in its
// place): the stage stops with a clear error and stores no session.
TEST(SessionStage, ScanWithoutABodyIsAClearErrorAndStoresNoSession) {
  TempDir dir;
  const fs::path case_dir = CopySample(dir);
  fs::remove_all(case_dir / "body_scan");
  fs::copy(case_dir / "room", case_dir / "body_scan", fs::copy_options::recursive);
  // Body ground truth is optional; without it the case stays valid.
  auto db = SqliteDatabase::Open((dir.path() / "store.db").string());
  const RunCaseResult r = RunCase(case_dir, db.get());
  ASSERT_FALSE(r.ok());
  ASSERT_EQ(r.failures.size(), 1u) << r.Summary();
  EXPECT_NE(r.failures.front().find("body_scan"), std::string::npos) << r.failures.front();
  EXPECT_NE(r.failures.front().find("no usable body surface"), std::string::npos) << r.failures.front();
  // What planning stored stays; no half session.
  EXPECT_EQ(db->ListSessions(r.plan_id).size(), 0u);
  EXPECT_TRUE(r.room_map_id.valid());
}

// Stickers the scan does not show (fallen off, covered): the map holds only
// the ones seen, and the model pose stays right. Its rotation here rests on
// the two scan frames that see the room map, each placed with one room
// marker to 0.26-0.32 deg (1 sigma; the session says the placement's
// uncertainty is unknown): measured 0.45 deg, 0.53 deg since the room's
// planes entered the map's adjustment (which moved the sample's room frame
// by 0.02 deg); with every sticker 0.10 deg.
TEST(SessionStage, ScanWithHalfTheStickersHiddenMapsTheRest) {
  TempDir dir;
  const fs::path case_dir = CopySample(dir);
  const std::set<int> hidden = PaintOutStickers(case_dir, [](int id) { return id % 2 == 0; });
  ASSERT_GE(hidden.size(), 2u);
  auto db = SqliteDatabase::Open((dir.path() / "store.db").string());
  const RunCaseResult r = RunCase(case_dir, db.get(), dir.path() / "out");
  ASSERT_TRUE(r.ok()) << r.Summary();
  const auto maps = db->ListBodyMarkerMapIds(r.session_id);
  ASSERT_EQ(maps.size(), 1u);
  const auto map = db->GetBodyMarkerMap(maps[0]);
  ASSERT_TRUE(map.has_value());
  EXPECT_GE(map->markers.size(), 3u);
  for (const auto& m : map->markers) EXPECT_EQ(hidden.count(m.marker_id), 0u) << "sticker " << m.marker_id << " was painted over";
  const PoseError e = ModelPoseErrorAtScanTime(case_dir, dir.path() / "out");
  EXPECT_LT(e.translation_mm, 5.0);
  EXPECT_LT(e.rotation_deg, 0.75);
}

// No sticker on the patient at all: tracking would have nothing to follow,
// so the stage stops with a clear error naming the scan and stores no session.
TEST(SessionStage, ScanWithoutStickersIsAClearErrorAndStoresNoSession) {
  TempDir dir;
  const fs::path case_dir = CopySample(dir);
  ASSERT_FALSE(PaintOutStickers(case_dir, [](int) { return true; }).empty());
  auto db = SqliteDatabase::Open((dir.path() / "store.db").string());
  const RunCaseResult r = RunCase(case_dir, db.get());
  ASSERT_FALSE(r.ok());
  ASSERT_EQ(r.failures.size(), 1u) << r.Summary();
  EXPECT_NE(r.failures.front().find("body_scan"), std::string::npos) << r.failures.front();
  EXPECT_NE(r.failures.front().find("sticker"), std::string::npos) << r.failures.front();
  EXPECT_EQ(db->ListSessions(r.plan_id).size(), 0u);
  EXPECT_TRUE(r.room_map_id.valid());
}

TEST(SessionStage, ManualAlignmentThatIsNotRigidIsRefusedNamingTheFile) {
  TempDir dir;
  const fs::path case_dir = CopySample(dir);
  auto db = SqliteDatabase::Open((dir.path() / "store.db").string());
  const RunCaseResult run = RunCase(case_dir, db.get());
  ASSERT_TRUE(run.ok()) << run.Summary();
  const fs::path bad = dir.path() / "initial.txt";
  WriteFileAtomic(bad, "2 0 0 0.7\n0 1 0 1.3\n0 0 1 0.9\n0 0 0 1\n");
  SessionStageOptions session;
  session.case_dir = case_dir;
  session.initial_alignment = bad;
  SessionController controller(session, db.get());
  try {
    controller.Run();
    FAIL() << "a scaled matrix was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(bad.string()), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("not a rigid transform"), std::string::npos) << e.what();
  }
  EXPECT_EQ(db->ListSessions(run.plan_id).size(), 1u);  // only run-case's
}

// Manual alignment from picked point pairs (as the GUI collects them):
// four points on the model and the same anatomy on the reconstruction,
// picked roughly (1 cm off), refined by ICP to the automatic result's
// accuracy; too few or inconsistent pairs are refused, nothing stored.
TEST(SessionStage, ManualAlignmentFromPickedPairsIsRefinedAndStored) {
  TempDir dir;
  const fs::path case_dir = CopySample(dir);
  auto db = SqliteDatabase::Open((dir.path() / "store.db").string());
  const RunCaseResult run = RunCase(case_dir, db.get());
  ASSERT_TRUE(run.ok()) << run.Summary();
  const auto reconstructions = db->ListReconstructionIds(run.session_id);
  ASSERT_EQ(reconstructions.size(), 1u);
  const size_t stored_before = db->ListAlignments(reconstructions[0]).size();
  const Rigid3d truth = ReadTrajectory(case_dir / "body_scan" / "body_groundtruth.txt").front().room_from_x;
  const TriangleMesh model = LoadTriangleMesh(case_dir / "reference_model.ply");
  // Spread-out points of the model's front: extremes along x and z.
  std::vector<Eigen::Vector3d> on_model, on_reconstruction;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e9), hi = -lo;
  for (const auto& v : model.vertices) {
    lo = lo.cwiseMin(v.cast<double>());
    hi = hi.cwiseMax(v.cast<double>());
  }
  const Eigen::Vector3d picks_in_model[] = {{0, lo.y(), 0.25}, {0, lo.y(), -0.3}, {0.15, lo.y(), 0}, {-0.15, lo.y(), 0.1}};
  const Eigen::Vector3d pick_error[] = {{0.01, 0, 0}, {0, 0.008, 0}, {-0.006, 0, 0.005}, {0, -0.01, 0.004}};
  for (int k = 0; k < 4; ++k) {
    // The nearest model vertex (a pick lands on the surface).
    Eigen::Vector3d best = model.vertices.front().cast<double>();
    for (const auto& v : model.vertices) {
      if ((v.cast<double>() - picks_in_model[k]).norm() < (best - picks_in_model[k]).norm()) best = v.cast<double>();
    }
    on_model.push_back(best);
    on_reconstruction.push_back(truth * best + pick_error[k]);
  }
  const ManualAlignmentResult r =
      AlignStoredReconstruction(db.get(), reconstructions[0], on_model, on_reconstruction, Operator{"test", Role::kResearch, false});
  const PoseError e = ComputePoseError(truth, r.room_from_model);
  EXPECT_LT(e.translation_mm, 5.0);
  EXPECT_LT(e.rotation_deg, 0.5);
  EXPECT_GT(r.fitness, 0.9);
  EXPECT_EQ(db->ListAlignments(reconstructions[0]).size(), stored_before + 2);
  const auto icp = db->GetAlignment(r.icp_id);
  ASSERT_TRUE(icp.has_value());
  EXPECT_EQ(icp->parent_alignment_id, r.manual_id);

  // Two pairs: refused. A pair on different anatomy (30 cm off): refused.
  EXPECT_THROW(AlignStoredReconstruction(db.get(), reconstructions[0], {on_model[0], on_model[1]},
                                         {on_reconstruction[0], on_reconstruction[1]}, Operator{"test", Role::kResearch, false}),
               InputError);
  auto wrong = on_reconstruction;
  wrong[2] += Eigen::Vector3d(0.3, 0, 0);
  const Operator research{"test", Role::kResearch, false};
  EXPECT_THROW(AlignStoredReconstruction(db.get(), reconstructions[0], on_model, wrong, research), InputError);
  EXPECT_EQ(db->ListAlignments(reconstructions[0]).size(), stored_before + 2);
  // Only a role that runs sessions aligns, and only on an open session.
  EXPECT_THROW(AlignStoredReconstruction(db.get(), reconstructions[0], on_model, on_reconstruction,
                                         Operator{"pia", Role::kPhysicist, true}),
               NotPermitted);
  EndSession(db.get(), research, run.session_id, SessionStatus::kCompleted, "");
  EXPECT_THROW(AlignStoredReconstruction(db.get(), reconstructions[0], on_model, on_reconstruction, research),
               InputError);
  EXPECT_EQ(db->ListAlignments(reconstructions[0]).size(), stored_before + 2);
}

// A plan stored before the input checks existed, with its reference model in
// millimetres: the session stage refuses it before any work (it used to run
// out of memory on a kilometre-sized crop box), naming the plan and the
// likely unit, and stores nothing.
TEST(SessionStage, AStoredPlanWithAModelInMillimetresIsRefusedBeforeTheStage) {
  TempDir dir;
  const fs::path case_dir = CopySample(dir);
  auto db = SqliteDatabase::Open((dir.path() / "store.db").string());
  PlanRoomMapOptions plan_options;
  plan_options.case_dir = case_dir;
  const PlanRoomMapResult planned = RunPlanRoomMap(plan_options, db.get());
  PlanRecord scaled = *db->GetPlan(planned.plan_id);
  for (auto& v : scaled.reference_model.vertices) v *= 1000.0f;
  scaled.name = "model in millimetres";
  const PlanId bad_plan = db->AddPlan(scaled);
  RoomMapRecord map = *db->GetRoomMap(planned.room_map_id);
  map.plan_id = bad_plan;
  db->AddRoomMap(map);
  SessionStageOptions session;
  session.case_dir = case_dir;
  session.plan_id = bad_plan;
  SessionController controller(session, db.get());
  try {
    controller.Run();
    FAIL() << "a plan with a model in millimetres was used";
  } catch (const InputError& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find("plan " + std::to_string(bad_plan.value()) + " (reference_model.ply): largest extent is"),
              std::string::npos)
        << message;
    EXPECT_NE(message.find("looks like millimetres"), std::string::npos) << message;
  }
  EXPECT_TRUE(db->ListSessions().empty());
}

}  // namespace
}  // namespace arpos
