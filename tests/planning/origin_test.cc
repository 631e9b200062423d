// The room frame when the origin marker is seen rarely, small and obliquely
// (a simulated case whose drawn conditions give the origin "poor"
// visibility: one glancing view of a 30-40 px marker, a few frames of a
// 60-frame walk).
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <functional>
#include <optional>
#include <string>

#include "geometry/umeyama.h"
#include "planning/planning_test_util.h"
#include "room_map/bundle_adjustment.h"
#include "room_map/plan_stage.h"
#include "room_map/room_map_builder.h"
#include "sensor/case_folder.h"
#include "sensor/sequence.h"
#include "simulation/conditions.h"
#include "simulation/simulation_truth.h"
#include "simulation/simulator.h"
#include "util/check.h"
#include "util/file.h"
#include "util/string_util.h"

namespace arpos {
namespace {

namespace fs = std::filesystem;

/// The first seed whose drawn conditions see the origin poorly with the
/// given response.
uint64_t FirstSeedWith(const std::string& visibility, sim::CameraResponse response) {
  for (uint64_t seed = 1; seed < 2000; ++seed) {
    const sim::SceneConditions c = sim::DrawSceneConditions(seed);
    if (c.origin_visibility == visibility && c.response == response) return seed;
  }
  return 0;
}

struct PoorOriginCase {
  fs::path root;
  CaseFolder folder;
  sim::SimulationTruth truth;
  int origin_views = 0;
};

// Moves a case written to `tmp` to `root` unless another test process (ctest
// runs two at once) put it there first; never removes a case another process
// may be reading (that had failed one run with "missing depth image").
void PublishCase(const fs::path& tmp, const fs::path& root) {
  std::error_code ec;
  if (!fs::exists(root / "simulation.yaml")) {
    fs::remove_all(root, ec);  // an unfinished folder of an older layout, if any
    fs::rename(tmp, root, ec);
  }
  fs::remove_all(tmp, ec);  // left only when the other process won
}

// A 60-frame random-conditions room of `seed` (cached in the build tree),
// with `response` instead of the drawn camera response and `depth_delay_s`
// instead of the drawn colour-depth timing if given.
PoorOriginCase MakeRandomRoomCase(uint64_t seed, const std::string& name,
                                  const std::optional<std::string>& response = std::nullopt,
                                  const std::optional<double>& depth_delay_s = std::nullopt) {
  PoorOriginCase out;
  out.root = fs::path(ARPOS_PLANNING_TEST_CACHE) /
             (name + "_v" + std::to_string(sim::kSimulatorVersion) + "_" + std::to_string(seed) +
              (response ? "_" + *response : "") +
              (depth_delay_s ? StringPrintf("_delay%.0fms", 1000 * *depth_delay_s) : ""));
  sim::SimulationOptions o;
  o.profile = "xtion";
  o.seed = seed;
  o.random_conditions = true;
  o.response = response;
  o.depth_delay_s = depth_delay_s;
  o.body_mesh_path = fs::path(ARPOS_SHARED_DATA_DIR) / "makehuman_base" / "base.obj";
  o.room_frames = 60;
  o.body_scan_frames = 2;
  o.tracking_frames = 1;
  o.tracking_sequences = 1;
  const sim::Simulator simulator(o);
  out.origin_views = simulator.origin_visibility().visible_frames;
  if (!fs::exists(out.root / "simulation.yaml")) {
    const fs::path tmp = out.root.string() + ".tmp" + std::to_string(::getpid());
    fs::remove_all(tmp);
    simulator.WriteCase(tmp);
    PublishCase(tmp, out.root);
  }
  out.folder = LoadCaseFolder(out.root);
  out.truth = sim::LoadSimulationTruth(out.root / "simulation.yaml");
  return out;
}

const PoorOriginCase& GetPoorOriginCase() {
  static const PoorOriginCase c = [] {
    const uint64_t seed = FirstSeedWith("poor", sim::CameraResponse::kLinear);
    ARPOS_CHECK(seed > 0, "no seed draws a poorly seen origin");
    return MakeRandomRoomCase(seed, "poor_origin");
  }();
  return c;
}

// Each mapped marker within 1.5 m of the couch point: its id and how far its
// centre is from the truth (mm), in the room frame.
std::vector<std::pair<int, double>> NearCouchMarkerErrorsMm(const RoomMap& map, const sim::SimulationTruth& truth,
                                                            const Eigen::Vector3d& couch) {
  std::vector<std::pair<int, double>> out;
  for (const RoomMapMarkerEntry& m : map.markers) {
    for (const auto& t : truth.room_markers) {
      if (t.id != m.id || (t.parent_from_marker.translation - couch).norm() > 1.5) continue;
      out.emplace_back(m.id, (m.room_from_marker.translation - t.parent_from_marker.translation).norm() * 1000);
    }
  }
  return out;
}

TEST(RoomMapOrigin, RarelySeenSmallObliqueOriginStillGivesARoomFrame) {
  const PoorOriginCase& c = GetPoorOriginCase();
  std::printf("origin seen (geometrically) in %d of 60 room frames\n", c.origin_views);
  // This room's depth is of another instant than its colour (drawn 14.5 ms
  // early): read again as of its colour instant once the frames are placed,
  // and the progress a person watches runs once from 0 to 1, never back.
  std::vector<std::pair<std::string, double>> steps;
  ControllerCallbacks callbacks;
  callbacks.progress = [&steps](const std::string& step, double fraction) {
    steps.emplace_back(step, fraction);
  };
  const RoomMapBuildResult built =
      BuildRoomMap(Sequence::Open(c.folder.room_dir), c.folder.config,
                   MakeRoomMapBuildOptions(c.folder.config), callbacks);
  std::printf("%s", built.report.ToText().c_str());
  ASSERT_GT(built.report.frames_depth_moved_to_colour, 0);
  ASSERT_FALSE(steps.empty());
  for (size_t i = 1; i < steps.size(); ++i) {
    EXPECT_GE(steps[i].second, steps[i - 1].second)
        << steps[i - 1].first << " -> " << steps[i].first;
  }
  EXPECT_LE(steps.front().second, 0.01);
  EXPECT_GE(steps.back().second, 0.9);
  EXPECT_LE(steps.back().second, 1.0);
  const RoomMapMarkerEntry* origin = built.map.FindMarker(c.folder.config.room_origin_id);
  ASSERT_NE(origin, nullptr);
  EXPECT_TRUE(origin->room_from_marker.IsApprox(Rigid3d::Identity(), 1e-9, 1e-9));
  // The markers well seen are where the truth has them, in the room frame.
  const testing::MarkerErrors errors = testing::CompareMarkers(built.map, c.truth, 3);
  std::printf("markers seen >= 3 times: %d, corner error mean %.2f mm, max %.2f mm\n", errors.markers,
              errors.mean_m * 1000, errors.max_m * 1000);
  EXPECT_GE(errors.markers, 4);
  // The room frame's own uncertainty is reported, and it is honest: the
  // markers' errors (dominated by the room frame's tilt on this case) stay
  // within what it says, with 2 mm for the markers' own errors.
  const RoomMapBuildReport& r = built.report;
  EXPECT_GT(r.origin_observations, 0);
  ASSERT_TRUE(std::isfinite(r.room_frame_tilt_sigma_deg));
  ASSERT_TRUE(std::isfinite(r.room_frame_couch_sigma_mm));
  int within = 0, compared = 0;
  for (const RoomMapMarkerEntry& m : built.map.markers) {
    if (m.num_observations < 3) continue;
    for (const auto& t : c.truth.room_markers) {
      if (t.id != m.id) continue;
      const double error_mm = (m.room_from_marker.translation - t.parent_from_marker.translation).norm() * 1000;
      const double sigma_mm = r.RoomFramePositionSigmaMm(t.parent_from_marker.translation);
      std::printf("marker %d: %.2f mm off, room frame sigma there %.2f mm\n", m.id, error_mm, sigma_mm);
      within += error_mm < 3 * sigma_mm + 2.0 ? 1 : 0;
      ++compared;
    }
  }
  EXPECT_GE(within, compared - 1) << "the reported uncertainty understates the errors";
  // A weak room frame is said in plain words, with what to record.
  if (r.room_frame_tilt_sigma_deg > 0.05) {
    bool said = false;
    for (const std::string& w : r.warnings) said |= w.find("close, sharp views of the origin marker") != std::string::npos;
    EXPECT_TRUE(said) << r.ToText();
  }
}

// The same room (depth drawn 14.5 ms early): its depth, read again as of
// each frame's colour instant once the frames are placed, agrees with what
// the colour places better than the depth as read.
TEST(RoomMapOrigin, DepthOfAnotherInstantIsReadAsOfItsColourInstantBeforeItIsUsed) {
  const PoorOriginCase& c = GetPoorOriginCase();
  RoomMapBuildOptions options = MakeRoomMapBuildOptions(c.folder.config);
  const RoomMapBuildResult moved =
      BuildRoomMap(Sequence::Open(c.folder.room_dir), c.folder.config, options);
  options.move_delayed_depth = false;
  const RoomMapBuildResult as_read =
      BuildRoomMap(Sequence::Open(c.folder.room_dir), c.folder.config, options);
  std::printf("keypoint depth residual: %.2f mm RMS moved (%d of %d frames), %.2f mm as read\n",
              moved.report.keypoint_depth_rms_m * 1000, moved.report.frames_depth_moved_to_colour,
              moved.report.frames_depth_delayed, as_read.report.keypoint_depth_rms_m * 1000);
  ASSERT_GT(moved.report.frames_depth_delayed, 0);
  EXPECT_GE(moved.report.frames_depth_moved_to_colour, moved.report.frames_depth_delayed * 3 / 4);
  EXPECT_EQ(as_read.report.frames_depth_moved_to_colour, 0);
  EXPECT_LT(moved.report.keypoint_depth_rms_m, 0.9 * as_read.report.keypoint_depth_rms_m);
  EXPECT_NE(moved.report.ToText().find("read as of the colour's instant"), std::string::npos);
}

// Seed 13 with an sRGB camera: the origin marker is seen sharply, but only
// in two frames at the start of the walk and six at its end, each time
// alone on a bare tiled floor (19-29 px). The walk reaches it in steps of
// 0.4-0.5 m: the ratio test over the keypoints of the placed frames around
// keeps 39, 57 and 33 matches for the three frames before the origin comes
// into view, of which PnP finds 14, 41 and 22 consistent (20 place a
// frame), so without the search by projection the chain stops there and
// the plan with it, saying why (test below). The search from those poses
// finds 37 inliers in the first of them and places the whole end of the
// walk; the origin then joins from its views there.
TEST(RoomMapOrigin, AnOriginBeyondWideStepsOverABareFloorIsReachedBySearchingByProjection) {
  const PoorOriginCase c = MakeRandomRoomCase(13, "untied_origin", "srgb");
  const RoomMapBuildOptions options = MakeRoomMapBuildOptions(c.folder, RoomMapStageOptions());  // as `arpos plan`
  ASSERT_TRUE(options.keypoint_search_by_projection);
  const RoomMapBuildResult built = BuildRoomMap(Sequence::Open(c.folder.room_dir), c.folder.config, options);
  std::printf("%s", built.report.ToText().c_str());
  ASSERT_NE(built.map.FindMarker(c.folder.config.room_origin_id), nullptr);
  EXPECT_GE(built.report.origin_observations, 6);
  EXPECT_GE(built.report.frames_used, 53);
  // The room frame is weak here (eight views of a 27 px marker far from the
  // couch), and the plan says so; the markers near the couch are within
  // what it says (1 sigma at the couch) and 2 mm.
  const auto near = NearCouchMarkerErrorsMm(built.map, c.truth, options.couch_point_in_room);
  for (const auto& [id, e] : near) {
    std::printf("marker %d near the couch: %.2f mm off (room frame 1 sigma at the couch %.2f mm)\n", id, e,
                built.report.room_frame_couch_sigma_mm);
    EXPECT_LT(e, built.report.room_frame_couch_sigma_mm + 2) << "marker " << id;
  }
  EXPECT_GE(near.size(), 2u);
}

// Seed 13 with a linear camera: the frames that show the origin (the end of
// the walk) are placed through keypoints each seen in two frames only, so
// none of them was in the adjustment, which then held the origin's frames
// to the rest by the floor alone: the plan said the map near the couch was
// known to 1125 mm relative to the origin (the covariance of the whole
// adjustment), although the map itself was right. Such keypoints now join
// the groups of frames nothing else ties, and the figure is what the
// recording supports: a few millimetres, covering the markers' errors.
TEST(RoomMapOrigin, FramesTiedOnlyByTwoViewKeypointsAreTiedInTheAdjustment) {
  const PoorOriginCase c = MakeRandomRoomCase(13, "untied_origin", "linear");
  const RoomMapBuildOptions options = MakeRoomMapBuildOptions(c.folder, RoomMapStageOptions());  // as `arpos plan`
  const RoomMapBuildResult built = BuildRoomMap(Sequence::Open(c.folder.room_dir), c.folder.config, options);
  const RoomMapBuildReport& r = built.report;
  std::printf("%s", r.ToText().c_str());
  ASSERT_NE(built.map.FindMarker(c.folder.config.room_origin_id), nullptr);
  EXPECT_GT(r.landmarks_joining_groups, 0);
  ASSERT_GT(r.map_couch_markers, 0);
  EXPECT_LT(r.map_couch_sigma_mm, 30.0);
  EXPECT_GE(r.CouchSigmaMm(), r.room_frame_couch_sigma_mm);
  // Its orientation near the couch relative to the origin, as stored.
  EXPECT_TRUE(std::isfinite(r.map_couch_tilt_sigma_deg) && r.map_couch_tilt_sigma_deg > 0);
  EXPECT_TRUE(std::isfinite(r.map_couch_yaw_sigma_deg) && r.map_couch_yaw_sigma_deg > 0);
  EXPECT_GE(r.CouchTiltSigmaDeg(), r.room_frame_tilt_sigma_deg);
  EXPECT_GE(r.CouchYawSigmaDeg(), r.room_frame_yaw_sigma_deg);
  EXPECT_NE(r.ToText().find("the map near the couch relative to it"), std::string::npos);
  const auto near = NearCouchMarkerErrorsMm(built.map, c.truth, options.couch_point_in_room);
  for (const auto& [id, e] : near) {
    std::printf("marker %d near the couch: %.2f mm off (the map there 1 sigma %.2f mm)\n", id, e, r.map_couch_sigma_mm);
    EXPECT_LT(e, 3 * r.map_couch_sigma_mm) << "marker " << id;
  }
  EXPECT_GE(near.size(), 2u);
}

// The same recording without the search by projection: the frames that
// show the origin cannot be tied to the map, and the plan stops with an
// input error that says so and what to record (it used to blame the views:
// "never fully and sharply"). Without the detector's second pass too: with
// it the plan reads more small markers and ties the origin (8 markers mapped).
TEST(RoomMapOrigin, AnOriginSeenOnlyInFramesTheMapCannotTieIsNamedAsSuch) {
  const PoorOriginCase c = MakeRandomRoomCase(13, "untied_origin", "srgb");
  RoomMapBuildOptions options = MakeRoomMapBuildOptions(c.folder, RoomMapStageOptions());
  options.keypoint_search_by_projection = false;
  options.detector.second_pass_window_px = 0;
  try {
    const RoomMapBuildResult built = BuildRoomMap(Sequence::Open(c.folder.room_dir), c.folder.config, options);
    ADD_FAILURE() << "expected the plan to stop; it mapped " << built.map.markers.size() << " markers";
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("is seen sharply in"), std::string::npos) << what;
    EXPECT_NE(what.find("none of them could be tied to the rest of the map"), std::string::npos) << what;
    EXPECT_NE(what.find("another room marker in view together with the origin marker"), std::string::npos) << what;
  }
}

// The origin's tilt is fused with the markers coplanar with it when the room
// frame is weak at the couch, even with the tilt itself within its tolerance
// (the tilt acts over the distance to the couch), and not otherwise. Here
// the tolerances are set so that only the couch rule can ask for it. (The
// fusion after the adjustment, for a map whose origin is not tied to a plane
// in the adjustment: room planes off here; see the next test for them.)
TEST(RoomMapOrigin, ARoomFrameWeakAtTheCouchTakesTheTiltOfTheMarkersCoplanarWithTheOrigin) {
  const PoorOriginCase& c = GetPoorOriginCase();
  RoomMapBuildOptions options = MakeRoomMapBuildOptions(c.folder, RoomMapStageOptions());
  options.use_room_planes = false;
  options.max_room_frame_tilt_sigma_deg = 90;     // the tilt never weak by itself
  options.max_room_frame_couch_sigma_mm = 1e-3;   // the room frame always weak at the couch
  const RoomMapBuildResult fused = BuildRoomMap(Sequence::Open(c.folder.room_dir), c.folder.config, options);
  std::printf("%s", fused.report.ToText().c_str());
  ASSERT_GE(fused.report.coplanar_markers, 2) << "this case has markers on the origin's plane";
  options.fuse_tilt_when_weak_at_couch = false;
  const RoomMapBuildResult alone = BuildRoomMap(Sequence::Open(c.folder.room_dir), c.folder.config, options);
  EXPECT_EQ(alone.report.coplanar_markers, 0);
  // Fusing independent information narrows the tilt, and the couch with it.
  EXPECT_LT(fused.report.room_frame_tilt_sigma_deg, alone.report.room_frame_tilt_sigma_deg);
  EXPECT_LT(fused.report.room_frame_couch_sigma_mm, alone.report.room_frame_couch_sigma_mm);
  // And the markers near the couch stay within what the plan says.
  const Eigen::Vector3d couch = options.couch_point_in_room;
  for (const RoomMapMarkerEntry& m : fused.map.markers) {
    if (m.num_observations < 3) continue;
    for (const auto& t : c.truth.room_markers) {
      if (t.id != m.id || (t.parent_from_marker.translation - couch).norm() > 1.5) continue;
      const double e = (m.room_from_marker.translation - t.parent_from_marker.translation).norm() * 1000;
      EXPECT_LT(e, 3 * fused.report.room_frame_couch_sigma_mm + 2) << "marker " << m.id;
    }
  }
}

// The same case as `arpos plan` builds it: the origin, small and rarely
// seen, is tied to its floor in the adjustment, whose depth in every view of
// it holds the origin's tilt. The reported tilt is narrower than the
// origin's corners alone give, and the markers near the couch are within
// what the plan says (3 sigma + 2 mm) and closer than without the planes.
TEST(RoomMapOrigin, TheOriginsPlaneInDepthHoldsItsTiltInTheAdjustment) {
  const PoorOriginCase& c = GetPoorOriginCase();
  RoomMapBuildOptions options = MakeRoomMapBuildOptions(c.folder, RoomMapStageOptions());
  const RoomMapBuildResult tied = BuildRoomMap(Sequence::Open(c.folder.room_dir), c.folder.config, options);
  std::printf("%s", tied.report.ToText().c_str());
  ASSERT_GE(tied.report.origin_plane_views, 10);
  options.use_room_planes = false;
  options.fuse_tilt_when_weak_at_couch = false;
  options.max_room_frame_tilt_sigma_deg = 90;  // the origin's corners alone
  const RoomMapBuildResult alone = BuildRoomMap(Sequence::Open(c.folder.room_dir), c.folder.config, options);
  EXPECT_EQ(alone.report.origin_plane_views, 0);
  EXPECT_LT(tied.report.room_frame_tilt_sigma_deg, 0.5 * alone.report.room_frame_tilt_sigma_deg);
  const Eigen::Vector3d couch = options.couch_point_in_room;
  auto near_error = [&](const RoomMap& map, double* max_excess) {
    double sum = 0;
    int n = 0;
    for (const RoomMapMarkerEntry& m : map.markers) {
      for (const auto& t : c.truth.room_markers) {
        if (t.id != m.id || (t.parent_from_marker.translation - couch).norm() > 1.5) continue;
        const double e = (m.room_from_marker.translation - t.parent_from_marker.translation).norm() * 1000;
        if (max_excess) *max_excess = std::max(*max_excess, e - (3 * tied.report.room_frame_couch_sigma_mm + 2));
        sum += e;
        ++n;
      }
    }
    return n ? sum / n : 1e9;
  };
  double excess = -1e9;
  const double with_planes = near_error(tied.map, &excess), without = near_error(alone.map, nullptr);
  std::printf("markers near the couch: %.2f mm with the planes, %.2f mm without\n", with_planes, without);
  EXPECT_LT(excess, 0.0);
  EXPECT_LT(with_planes, without);
}

// The couch-top exclusion box is in the room frame; a map started from a
// marker other than the poorly seen origin holds its landmarks in that
// marker's frame until the end. No landmark of the finished map lies in the
// box (measured before the fix: a random-conditions case kept 144 there).
// Random conditions, seed 29 (a held-out seed): the origin lies far on the
// floor and is seen in six frames, 17-37 px at 64 deg; only one of them is
// placed by the rest of the map, and that one view's two single-view poses
// reproject alike, so the plan used to stop ("never fully and sharply in a
// frame the rest of the map places"). The floor's depth around the marker
// settles which pose it is; the origin then places the frames that see it
// alone. Depth of the colour's instant: the seed draws depth 13.9 ms
// early, which this 60-frame walk (frames more than 0.5 s apart) cannot
// move to its colour instant, and the floor's depth then settles the view
// 24 mm off at the couch (a finding; recordings at video rate are moved).
TEST(RoomMapOrigin, ALoneAmbiguousViewOfTheOriginIsSettledByTheDepthAroundIt) {
  const PoorOriginCase c = MakeRandomRoomCase(29, "lone_origin_view", std::nullopt, 0.0);
  const auto placement = std::find(c.truth.conditions.begin(), c.truth.conditions.end(),
                                   std::make_pair(std::string("origin_placement"), std::string("floor_far")));
  ASSERT_NE(placement, c.truth.conditions.end()) << "seed 29 no longer draws a far origin";
  const RoomMapBuildOptions options = MakeRoomMapBuildOptions(c.folder, RoomMapStageOptions());  // as `arpos plan`
  const RoomMapBuildResult built = BuildRoomMap(Sequence::Open(c.folder.room_dir), c.folder.config, options);
  std::printf("%s", built.report.ToText().c_str());
  ASSERT_NE(built.map.FindMarker(c.folder.config.room_origin_id), nullptr);
  EXPECT_GE(built.report.origin_observations, 2);
  EXPECT_GE(built.report.frames_used, 55);
  // The markers near the couch, in the room frame, within what the plan
  // says of its room frame (1 sigma at the couch) and 2 mm.
  const auto near = NearCouchMarkerErrorsMm(built.map, c.truth, options.couch_point_in_room);
  for (const auto& [id, e] : near) {
    std::printf("marker %d near the couch: %.2f mm off (room frame 1 sigma at the couch %.2f mm)\n",
                id, e, built.report.room_frame_couch_sigma_mm);
    EXPECT_LT(e, built.report.room_frame_couch_sigma_mm + 2) << "marker " << id;
  }
  EXPECT_GE(near.size(), 2u);
}

TEST(RoomMapOrigin, NoLandmarkInTheExclusionBoxWhenTheMapStartsFromAnotherMarker) {
  // Random-conditions seed 13: the origin far on the floor, not seen clearly
  // with the other markers.
  const PoorOriginCase c = MakeRandomRoomCase(13, "random_room");
  const RoomMapBuildOptions options = MakeRoomMapBuildOptions(c.folder, RoomMapStageOptions());
  ASSERT_FALSE(options.exclude_landmarks.empty());
  const RoomMapBuildResult built = BuildRoomMap(Sequence::Open(c.folder.room_dir), c.folder.config, options);
  const std::string text = built.report.ToText();
  std::printf("%s", text.c_str());
  ASSERT_NE(text.find("the map was started from marker"), std::string::npos) << "this case should start elsewhere";
  int inside = 0;
  for (const Eigen::Vector3d& X : built.map.landmarks_in_room) {
    for (const auto& box : options.exclude_landmarks) inside += box.Contains(X) ? 1 : 0;
  }
  EXPECT_EQ(inside, 0);
  EXPECT_GT(built.report.landmarks_excluded, 0) << "the box should hold some of this room's texture";
  EXPECT_EQ(built.map.landmark_descriptors.rows, built.map.num_landmarks());
}

// A depth camera that reads 0.4 % short: the check of depth against what the
// markers measure finds the scale and removes it, and the map keeps the
// markers' printed scale. (The check compared depth with keypoint landmarks
// too at first; those, placed without depth from a few far views, carried
// errors of their own that it read as depth noise of 2-63 sigma.)
TEST(RoomMapDepth, AScaleErrorOfTheDepthIsFoundFromTheMarkersAndRemoved) {
  const double true_scale = -0.004;
  const fs::path root = fs::path(ARPOS_PLANNING_TEST_CACHE) /
                        ("depth_scale_v" + std::to_string(sim::kSimulatorVersion) + "_7");
  sim::SimulationOptions o;
  o.profile = "xtion";
  o.seed = 7;
  o.body_mesh_path = fs::path(ARPOS_SHARED_DATA_DIR) / "makehuman_base" / "base.obj";
  o.room_frames = 40;
  o.body_scan_frames = 2;
  o.tracking_frames = 1;
  o.tracking_sequences = 1;
  o.depth_scale_error = true_scale;
  if (!fs::exists(root / "simulation.yaml")) {
    const fs::path tmp = root.string() + ".tmp" + std::to_string(::getpid());
    fs::remove_all(tmp);
    sim::Simulator(o).WriteCase(tmp);
    PublishCase(tmp, root);
  }
  const CaseFolder folder = LoadCaseFolder(root);
  const sim::SimulationTruth truth = sim::LoadSimulationTruth(root / "simulation.yaml");
  const RoomMapBuildResult built =
      BuildRoomMap(Sequence::Open(folder.room_dir), folder.config, MakeRoomMapBuildOptions(folder.config));
  std::printf("%s\n", built.report.depth_correction.c_str());
  EXPECT_NEAR(built.map.depth_correction.scale, true_scale, 0.001) << built.report.depth_correction;
  std::vector<Eigen::Vector3d> est, tru;
  for (const RoomMapMarkerEntry& m : built.map.markers) {
    for (const auto& t : truth.room_markers) {
      if (t.id != m.id) continue;
      for (int c = 0; c < 4; ++c) {
        est.push_back(m.corners_in_room[c]);
        tru.push_back(t.corners_m[c]);
      }
    }
  }
  const auto fit = EstimateRigidTransform(est, tru, true);
  ASSERT_TRUE(fit.has_value());
  std::printf("map scale against the truth %.5f, rmse %.2f mm over %zu markers\n", fit->scale,
              fit->rmse_m * 1000, est.size() / 4);
  EXPECT_NEAR(fit->scale, 1.0, 0.001);
}

// A camera of focal length `focal` (640x480) over a floor whose normal is
// turned `down_deg` about the camera's x axis from straight up, and a square
// marker of `side` lying on it at `centre`: the floor's depth image (plus
// `noise_m(u, v)`; readings beyond `max_range_m` left empty), the marker's
// axes in its plane and its projected corners.
struct MarkerOnFloor {
  CameraIntrinsics k;
  Eigen::Vector3d normal, x_axis, y_axis;
  double offset = 0;  ///< normal . p for every point p of the floor
  cv::Mat depth;
  std::array<Eigen::Vector2d, 4> corners;
};

MarkerOnFloor RenderMarkerOnFloor(double focal, double down_deg, const Eigen::Vector3d& centre,
                                  double side, double max_range_m,
                                  const std::function<double(int, int)>& noise_m) {
  MarkerOnFloor out;
  CameraIntrinsics& k = out.k;
  k.width = 640;
  k.height = 480;
  k.fx = k.fy = focal;
  k.cx = 319.5;
  k.cy = 239.5;
  k.depth_scale = 1000;
  out.normal = Eigen::AngleAxisd(-down_deg * M_PI / 180, Eigen::Vector3d::UnitX()) *
               Eigen::Vector3d(0, -1, 0);
  out.offset = out.normal.dot(centre);
  out.depth = cv::Mat(k.height, k.width, CV_16UC1);
  for (int v = 0; v < k.height; ++v) {
    for (int u = 0; u < k.width; ++u) {
      const Eigen::Vector3d ray((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1);
      const double z = out.offset / out.normal.dot(ray);
      out.depth.at<uint16_t>(v, u) =
          z > 0 && z < max_range_m ? static_cast<uint16_t>(std::lround((z + noise_m(u, v)) * 1000))
                                   : 0;
    }
  }
  out.x_axis = Eigen::Vector3d::UnitX();
  out.y_axis = out.normal.cross(out.x_axis).normalized();
  const double h = side / 2;
  const std::array<Eigen::Vector2d, 4> square = {{{-h, h}, {h, h}, {h, -h}, {-h, -h}}};
  for (int c = 0; c < 4; ++c) {
    out.corners[c] = k.Project(centre + square[c].x() * out.x_axis + square[c].y() * out.y_axis);
  }
  return out;
}

// The origin's support plane: depth sampled on a grid around the marker in
// its own plane lands on that plane, within the square asked for, and not
// from behind the camera or outside the image.
TEST(RoomMapOrigin, SupportDepthIsSampledOnTheMarkersPlaneAroundIt) {
  // A floor seen 40 deg down; the marker 2 m ahead.
  const Eigen::Vector3d centre(0.1, 0.4, 2.0);
  const double side = 0.15;
  const MarkerOnFloor f =
      RenderMarkerOnFloor(570, 40, centre, side, 60, [](int, int) { return 0.0; });
  const CameraIntrinsics& k = f.k;
  const Eigen::Vector3d &normal = f.normal, &x_axis = f.x_axis, &y_axis = f.y_axis;
  const double d = f.offset;
  const cv::Mat& depth = f.depth;
  const std::array<Eigen::Vector2d, 4>& corners = f.corners;
  const double half_width = 0.4;
  const std::vector<DepthSample> samples = SampleSupportDepth(depth, corners, k, side, half_width, 900);
  ASSERT_GT(samples.size(), 400u);
  EXPECT_LE(samples.size(), 900u);
  double worst_off_plane = 0, worst_extent = 0;
  for (const DepthSample& s : samples) {
    const Eigen::Vector3d p = k.Unproject(s.pixel.x(), s.pixel.y(), s.depth_m);
    worst_off_plane = std::max(worst_off_plane, std::abs(normal.dot(p) - d));
    const Eigen::Vector3d q = p - centre;
    worst_extent = std::max({worst_extent, std::abs(q.dot(x_axis)), std::abs(q.dot(y_axis))});
  }
  EXPECT_LT(worst_off_plane, 0.005);  // depth rounding and pixel rounding on a slanted plane
  EXPECT_LT(worst_extent, half_width + 0.02);
  EXPECT_GT(worst_extent, half_width - 0.05);
  EXPECT_TRUE(SampleSupportDepth(cv::Mat(), corners, k, side, half_width, 900).empty());
}

// A lone, small, oblique view's two IPPE solutions told apart by the floor
// around it even when the view's distance is off by centimetres (its
// weakest part): each solution's plane takes the offset the depth gives it.
// Random seed 402 of the sweep (a 31 px origin at 59 deg, --hard, linear
// response) stopped the plan when the pose's own offset was used.
TEST(RoomMapOrigin, ALoneViewsSolutionIsToldByItsPlaneEvenWhenItsDistanceIsOff) {
  // A floor seen 31 deg down (59 deg from face-on); the marker 2.3 m ahead;
  // the sensor's noise as a fixed pattern (+-1 sigma at 2.3 m for the xtion).
  const Eigen::Vector3d centre = 2.3 * Eigen::Vector3d(0.05, 0.15, 1).normalized();
  const double side = 0.13;
  const MarkerOnFloor f = RenderMarkerOnFloor(
      540, 31, centre, side, 8, [](int u, int v) { return 0.0074 * std::sin(0.7 * u + 1.3 * v); });
  const CameraIntrinsics& k = f.k;
  const Eigen::Vector3d &normal = f.normal, &x_axis = f.x_axis, &y_axis = f.y_axis;
  const cv::Mat& depth = f.depth;
  const std::array<Eigen::Vector2d, 4>& corners = f.corners;
  const std::vector<DepthSample> samples = SampleSupportDepth(depth, corners, k, side, 0.4, 2500);
  ASSERT_GT(samples.size(), 1000u);

  // The true orientation and one tilted 30 deg about the marker's x axis
  // (the other IPPE solution of an oblique view), both 6 cm too far along
  // the ray.
  Eigen::Matrix3d r_true;
  r_true.col(0) = x_axis;
  r_true.col(1) = y_axis;
  r_true.col(2) = normal;
  const Eigen::Matrix3d r_flip =
      r_true * Eigen::AngleAxisd(30 * M_PI / 180, Eigen::Vector3d::UnitX()).matrix();
  const Eigen::Vector3d too_far = centre + 0.06 * centre.normalized();
  for (const int true_index : {0, 1}) {
    MarkerPose pose;
    pose.num_solutions = 2;
    pose.solutions[true_index].camera_from_marker = Rigid3d(Eigen::Quaterniond(r_true), too_far);
    pose.solutions[1 - true_index].camera_from_marker =
        Rigid3d(Eigen::Quaterniond(r_flip), too_far);
    const std::optional<int> chosen = SolutionBySupportDepth(pose, samples, k, BaOptions());
    ASSERT_TRUE(chosen.has_value()) << "true solution " << true_index;
    EXPECT_EQ(*chosen, true_index);
  }
  // Two solutions the floor cannot tell apart: neither.
  MarkerPose same;
  same.num_solutions = 2;
  same.solutions[0].camera_from_marker = Rigid3d(Eigen::Quaterniond(r_true), too_far);
  same.solutions[1].camera_from_marker = Rigid3d(Eigen::Quaterniond(r_true), centre);
  EXPECT_FALSE(SolutionBySupportDepth(same, samples, k, BaOptions()).has_value());
}

}  // namespace
}  // namespace arpos
