// Room map building on a small simulated case (tests/planning/planning_test_util.h).
#include <bitset>
#include <fstream>
#include <iostream>
#include <random>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "planning/planning_test_util.h"
#include "room_map/keypoints.h"
#include "room_map/plan_stage.h"
#include "sensor/sequence.h"
#include "sensor/tum_io.h"
#include "store/sqlite_database.h"
#include "util/file.h"

namespace arpos {
namespace {

namespace fs = std::filesystem;
using testing::CompareMarkers;
using testing::GetSmallCase;
using testing::GetSmallCaseMap;

TEST(Keypoints, HammingDistanceCountsEveryDifferingBit) {
  // Against a plain bit count: all bits differing (32 bytes of 0xff against
  // zeros, where a byte-wise count could overflow), single bits, random.
  auto reference = [](const std::uint8_t* a, const std::uint8_t* b) {
    int d = 0;
    for (int i = 0; i < 32; ++i) d += static_cast<int>(std::bitset<8>(a[i] ^ b[i]).count());
    return d;
  };
  std::uint8_t zeros[32] = {}, ones[32], a[32], b[32];
  std::fill(ones, ones + 32, 0xff);
  EXPECT_EQ(HammingDistance32(zeros, ones), 256);
  EXPECT_EQ(HammingDistance32(ones, ones), 0);
  for (int bit = 0; bit < 256; ++bit) {
    std::fill(a, a + 32, 0);
    a[bit / 8] = static_cast<std::uint8_t>(1u << (bit % 8));
    ASSERT_EQ(HammingDistance32(a, zeros), 1) << "bit " << bit;
  }
  std::mt19937 random(7);
  for (int trial = 0; trial < 2000; ++trial) {
    for (int i = 0; i < 32; ++i) {
      a[i] = static_cast<std::uint8_t>(random());
      b[i] = static_cast<std::uint8_t>(trial % 3 == 0 ? ~a[i] ^ (random() % 2) : random());
    }
    ASSERT_EQ(HammingDistance32(a, b), reference(a, b)) << "trial " << trial;
  }
}

TEST(Keypoints, TheNearestTwoRowsAreTheSameWithAndWithoutAvx2) {
  // Random descriptors with planted near neighbours (exact copies, one or a
  // few bits off, all bits off) and ties, in a view of a larger matrix (rows
  // not contiguous with the query's); every range, including empty ones.
  std::mt19937 random(11);
  cv::Mat big(700, 40, CV_8U);
  cv::randu(big, 0, 256);
  cv::Mat rows = big(cv::Rect(4, 0, 32, 700));
  std::uint8_t query[32];
  for (int trial = 0; trial < 200; ++trial) {
    for (auto& q : query) q = static_cast<std::uint8_t>(random());
    const int plant = static_cast<int>(random() % 700);
    std::copy(query, query + 32, rows.ptr<std::uint8_t>(plant));
    if (trial % 2 == 0) rows.ptr<std::uint8_t>(plant)[random() % 32] ^= 1;
    if (trial % 3 == 0) {  // a tie with the planted row, later in the matrix
      const int twin = std::min(699, plant + 1 + static_cast<int>(random() % 50));
      std::copy(rows.ptr<std::uint8_t>(plant), rows.ptr<std::uint8_t>(plant) + 32,
                rows.ptr<std::uint8_t>(twin));
    }
    if (trial % 5 == 0) {
      for (int i = 0; i < 32; ++i)
        rows.ptr<std::uint8_t>(plant)[i] = static_cast<std::uint8_t>(~query[i]);
    }
    const int first = trial % 4 == 0 ? 0 : static_cast<int>(random() % 700);
    const int last = trial % 7 == 0 ? first : first + static_cast<int>(random() % (701 - first));
    const NearestTwo fast = NearestTwoOfRows(query, rows, first, last);
    const NearestTwo reference = NearestTwoOfRowsPortable(query, rows, first, last);
    ASSERT_EQ(fast.best, reference.best) << "trial " << trial;
    ASSERT_EQ(fast.d1, reference.d1) << "trial " << trial;
    ASSERT_EQ(fast.d2, reference.d2) << "trial " << trial;
    if (last > first) {
      NearestTwo offered;
      for (int l = first; l < last; ++l)
        offered.Offer(l, HammingDistance32(query, rows.ptr<std::uint8_t>(l)));
      ASSERT_EQ(fast.best, offered.best);
      ASSERT_EQ(fast.d2, offered.d2);
    } else {
      ASSERT_EQ(fast.best, -1);
    }
  }
  // Beyond the matrix: clamped, not read.
  EXPECT_EQ(NearestTwoOfRows(query, rows, -5, 10000).best,
            NearestTwoOfRowsPortable(query, rows, 0, 700).best);
  std::cout << "NearestTwoOfRows uses AVX2 here: " << (NearestTwoOfRowsUsesAvx2() ? "yes" : "no")
            << "\n";
}

TEST(Keypoints, TheNearestTwoOfConsecutiveRangesMergeIntoTheNearestTwoOfAll) {
  // Distances with many ties (0-7), split at every place into two and into
  // three consecutive ranges, empty ones included: merged, the same best
  // row (the first of equal distances) and the same two distances as
  // offering every row in order.
  std::mt19937 random(5);
  for (int trial = 0; trial < 300; ++trial) {
    const int n = static_cast<int>(random() % 12);
    std::vector<int> d(n);
    for (int& x : d) x = static_cast<int>(random() % 8);
    auto nearest = [&](int first, int last) {
      NearestTwo out;
      for (int l = first; l < last; ++l) out.Offer(l, d[l]);
      return out;
    };
    const NearestTwo all = nearest(0, n);
    for (int a = 0; a <= n; ++a) {
      for (int b = a; b <= n; ++b) {
        const NearestTwo merged =
            MergeNearestTwo(MergeNearestTwo(nearest(0, a), nearest(a, b)), nearest(b, n));
        ASSERT_EQ(merged.best, all.best) << "trial " << trial << " split " << a << ", " << b;
        ASSERT_EQ(merged.d1, all.d1) << "trial " << trial << " split " << a << ", " << b;
        ASSERT_EQ(merged.d2, all.d2) << "trial " << trial << " split " << a << ", " << b;
      }
    }
  }
}

TEST(Keypoints, NearestTwoKeepsTheSmallestTwoDistancesWhateverTheOrder) {
  NearestTwo none;
  EXPECT_EQ(none.best, -1);
  EXPECT_EQ(none.d1, 257);
  EXPECT_EQ(none.d2, 257);
  const std::vector<int> distances = {40, 12, 90, 12, 30, 7};
  NearestTwo n;
  for (size_t i = 0; i < distances.size(); ++i) n.Offer(static_cast<int>(i), distances[i]);
  EXPECT_EQ(n.best, 5);
  EXPECT_EQ(n.d1, 7);
  EXPECT_EQ(n.d2, 12);
  // A tie for the best: the first offered stays best, the tie is second.
  NearestTwo tie;
  tie.Offer(3, 20);
  tie.Offer(4, 20);
  EXPECT_EQ(tie.best, 3);
  EXPECT_EQ(tie.d2, 20);
  NearestTwo one;
  one.Offer(9, 100);
  EXPECT_EQ(one.best, 9);
  EXPECT_EQ(one.d2, 257);  // no second: the ratio test cannot reject
}

// An underexposed image (the view in grey levels 4-60: a linear camera
// response, an exposure set by a bright window) gives many of the keypoints
// of the same view well exposed, with the same descriptors; without the
// contrast stretch FAST finds few. A well-exposed image is left as it is.
TEST(Keypoints, AnUnderexposedImageGivesTheKeypointsOfAWellExposedOne) {
  cv::RNG rng(11);
  cv::Mat coarse(30, 40, CV_8UC1), fine(120, 160, CV_8UC1), a, b, bright;
  rng.fill(coarse, cv::RNG::UNIFORM, 0, 256);
  rng.fill(fine, cv::RNG::UNIFORM, 0, 256);
  cv::resize(coarse, a, cv::Size(640, 480), 0, 0, cv::INTER_NEAREST);
  cv::resize(fine, b, cv::Size(640, 480), 0, 0, cv::INTER_NEAREST);
  cv::addWeighted(a, 0.6, b, 0.4, 0, bright);
  cv::GaussianBlur(bright, bright, cv::Size(9, 9), 2.0);
  cv::equalizeHist(bright, bright);  // every grey level used: well exposed
  cv::Mat dark;
  bright.convertTo(dark, CV_8U, 56.0 / 255.0, 4.0);
  KeypointOptions on;
  on.max_keypoints = 20000;  // counted, not capped
  KeypointOptions off = on;
  off.max_contrast_gain = 1.0;
  ASSERT_TRUE(on.Check());
  ASSERT_TRUE(off.Check());
  KeypointSet well, dark_on, dark_off, well_off;
  KeypointExtractor(on).Extract(bright, cv::Mat(), 1000, &well);
  KeypointExtractor(on).Extract(dark, cv::Mat(), 1000, &dark_on);
  KeypointExtractor(off).Extract(dark, cv::Mat(), 1000, &dark_off);
  KeypointExtractor(off).Extract(bright, cv::Mat(), 1000, &well_off);
  ASSERT_GT(well.size(), 300u);
  // Left as it is when well exposed.
  ASSERT_EQ(well_off.size(), well.size());
  for (size_t i = 0; i < well.size(); ++i)
    ASSERT_EQ(well.keypoints[i].pt, well_off.keypoints[i].pt);
  // Measured: 4138 well exposed, 2084 dark with the stretch (56 grey levels
  // hold less than 256), 652 without.
  EXPECT_LT(dark_off.size(), 0.25 * well.size()) << "FAST on the dark image alone";
  EXPECT_GT(dark_on.size(), 0.4 * well.size());
  EXPECT_GT(dark_on.size(), 2.5 * dark_off.size());
  // The same corners with (nearly) the same descriptors.
  int same = 0;
  for (size_t i = 0; i < dark_on.size(); ++i) {
    for (size_t j = 0; j < well.size(); ++j) {
      if (cv::norm(dark_on.keypoints[i].pt - well.keypoints[j].pt) > 0.5) continue;
      if (HammingDistance32(dark_on.descriptors.ptr<std::uint8_t>(static_cast<int>(i)),
                            well.descriptors.ptr<std::uint8_t>(static_cast<int>(j))) <= 30) {
        ++same;
      }
      break;
    }
  }
  EXPECT_GT(same, 0.75 * dark_on.size()) << same << " of " << dark_on.size();
  KeypointOptions bad = on;
  bad.max_contrast_gain = 0.5;
  EXPECT_FALSE(bad.Check());
}

// The surface index finds a point of the face near a query beside it, and
// nothing away from every face; a surface spanning more than a room is
// refused when checked.
TEST(RoomSurface, TheIndexFindsTheFaceNearAPointAndNothingAwayFromIt) {
  RoomSurface surface;
  surface.voxel_m = 0.03;
  for (int i = 0; i < 40; ++i) {
    for (int j = 0; j < 30; ++j) {
      surface.points.emplace_back(0.5f, 0.9f + 0.03f * i, 0.015f + 0.03f * j);  // a couch-base face, x = 0.5
      surface.normals.emplace_back(1.f, 0.f, 0.f);
    }
  }
  EXPECT_EQ(surface.Validate(), "");
  const RoomSurfaceIndex index(surface);
  ASSERT_FALSE(index.empty());
  for (const double dx : {-0.02, 0.0, 0.01, 0.03}) {
    const Eigen::Vector3d q(0.5 + dx, 1.3, 0.41);
    const int k = index.Near(q);
    ASSERT_GE(k, 0) << dx;
    EXPECT_NEAR(index.normal(k).dot(q - index.point(k)), dx, 1e-6) << dx;
    EXPECT_LT((index.point(k) - q).norm(), 0.06) << dx;
  }
  EXPECT_EQ(index.Near(Eigen::Vector3d(0.7, 1.3, 0.4)), -1);   // 20 cm off the face
  EXPECT_EQ(index.Near(Eigen::Vector3d(0.5, 5.0, 0.4)), -1);   // beyond its end
  EXPECT_EQ(index.Near(Eigen::Vector3d(-50, 1.3, 0.4)), -1);   // outside the grid
  EXPECT_EQ(RoomSurfaceIndex().Near(Eigen::Vector3d::Zero()), -1);

  surface.points.back() = Eigen::Vector3f(30.f, 0.f, 0.f);
  EXPECT_NE(surface.Validate().find("spans"), std::string::npos) << surface.Validate();
  surface.points.back() = Eigen::Vector3f(0.5f, 1.f, 0.5f);
  surface.normals.back() = Eigen::Vector3f(0.f, 0.f, 0.f);
  EXPECT_NE(surface.Validate().find("not a unit vector"), std::string::npos) << surface.Validate();
}

// The same recording gives the same map, to the bit: a plan is what the
// recording says, not what the threads' order said (with two threads in the
// bundle adjustments, plans of one random d435 room kept 3146 and 3131
// landmarks and put the couch 2.77 and 2.95 mm from where the origin says).
TEST(RoomMap, TheSameRecordingGivesTheSameMapEveryTime) {
  const auto& c = GetSmallCase();
  const RoomMap& first = GetSmallCaseMap().map;
  const Sequence room = Sequence::Open(c.folder.room_dir);
  const RoomMapBuildResult again =
      BuildRoomMap(room, c.folder.config, MakeRoomMapBuildOptions(c.folder, RoomMapStageOptions()));
  ASSERT_EQ(again.map.landmarks_in_room.size(), first.landmarks_in_room.size());
  for (size_t i = 0; i < first.landmarks_in_room.size(); ++i) {
    ASSERT_EQ(again.map.landmarks_in_room[i], first.landmarks_in_room[i]) << "landmark " << i;
  }
  ASSERT_EQ(again.map.markers.size(), first.markers.size());
  for (size_t m = 0; m < first.markers.size(); ++m) {
    for (int k = 0; k < 4; ++k) {
      EXPECT_EQ(again.map.markers[m].corners_in_room[k], first.markers[m].corners_in_room[k])
          << "marker " << first.markers[m].id << " corner " << k;
    }
  }
}

TEST(RoomMap, MarkerCornersAreNearTheTruth) {
  const auto& c = GetSmallCase();
  const RoomMapBuildResult& built = GetSmallCaseMap();
  const RoomMap& map = built.map;
  // Most of the room's markers are mapped (some are seen once or never).
  EXPECT_GE(map.markers.size(), 8u) << built.report.ToText();
  // Tolerance: markers seen at least 3 times within 5 mm at every corner and
  // 2 mm on average; all mapped markers within 15 mm.
  const auto well_seen = CompareMarkers(map, c.truth, 3);
  EXPECT_GE(well_seen.markers, 6);
  EXPECT_LT(well_seen.mean_m, 0.002) << built.report.ToText();
  EXPECT_LT(well_seen.max_m, 0.005);
  EXPECT_LT(CompareMarkers(map, c.truth, 1).max_m, 0.015);
  // Residuals and the depth scale check are reported and plausible.
  EXPECT_GT(map.mean_residual_px, 0.0);
  EXPECT_LT(map.mean_residual_px, 0.3);
  EXPECT_GE(map.max_residual_px, map.mean_residual_px);
  EXPECT_NEAR(built.report.depth_scale_ratio, 1.0, 0.01);
  // A keypoint layer of a few thousand landmarks at most, with descriptors.
  EXPECT_GT(map.num_landmarks(), 200);
  EXPECT_LE(map.num_landmarks(), 4000);
  EXPECT_EQ(map.landmark_descriptors.rows, map.num_landmarks());
  EXPECT_EQ(map.landmark_descriptors.cols, kDescriptorBytes);
}

TEST(RoomMap, OriginMarkerFixesTheRoomFrame) {
  const auto& c = GetSmallCase();
  const RoomMap& map = GetSmallCaseMap().map;
  const RoomMapMarkerEntry* origin = map.FindMarker(c.folder.config.room_origin_id);
  ASSERT_NE(origin, nullptr);
  EXPECT_TRUE(origin->room_from_marker.IsApprox(Rigid3d::Identity(), 1e-12, 1e-12));

  // Another marker as origin: the same map, re-expressed in that marker's frame.
  const RoomMapMarkerEntry* other = nullptr;
  for (const auto& m : map.markers) {
    if (m.id != origin->id && m.num_observations >= 5 && (!other || m.num_observations > other->num_observations)) {
      other = &m;
    }
  }
  ASSERT_NE(other, nullptr);
  CaseConfig config = c.folder.config;
  config.room_origin_id = other->id;
  RoomMapStageOptions stage;
  stage.use_keypoints = false;  // markers decide the frame; keep the test quick
  RoomMapBuildOptions options = MakeRoomMapBuildOptions(c.folder, stage);
  const RoomMap moved = BuildRoomMap(Sequence::Open(c.folder.room_dir), config, options).map;
  ASSERT_NE(moved.FindMarker(other->id), nullptr);
  EXPECT_TRUE(moved.FindMarker(other->id)->room_from_marker.IsApprox(Rigid3d::Identity(), 1e-12, 1e-12));
  // old_room_from_new_room = the new origin's pose in the first map.
  const Rigid3d first_from_second = other->room_from_marker;
  for (const auto& m : moved.markers) {
    const RoomMapMarkerEntry* in_first = map.FindMarker(m.id);
    if (in_first == nullptr || m.num_observations < 3) continue;
    for (int k = 0; k < 4; ++k) {
      EXPECT_LT((first_from_second * m.corners_in_room[k] - in_first->corners_in_room[k]).norm(), 0.006)
          << "marker " << m.id;
    }
  }
}

TEST(RoomMap, RecordRoundTripKeepsMarkersAndLandmarks) {
  const RoomMap& map = GetSmallCaseMap().map;
  const RoomMapRecord record = ToRecord(map, PlanId(3));
  EXPECT_EQ(record.plan_id, PlanId(3));
  const RoomMap back = FromRecord(record);
  ASSERT_EQ(back.markers.size(), map.markers.size());
  for (size_t i = 0; i < map.markers.size(); ++i) {
    EXPECT_EQ(back.markers[i].id, map.markers[i].id);
    EXPECT_TRUE(back.markers[i].room_from_marker.IsApprox(map.markers[i].room_from_marker, 1e-9, 1e-9));
  }
  ASSERT_EQ(back.num_landmarks(), map.num_landmarks());
  for (int i = 0; i < map.num_landmarks(); ++i) {
    EXPECT_LT((back.landmarks_in_room[i] - map.landmarks_in_room[i]).norm(), 1e-6);  // stored as float
  }
  EXPECT_EQ(cv::norm(back.landmark_descriptors, map.landmark_descriptors, cv::NORM_HAMMING), 0);
}

TEST(RoomMap, OriginNeverSeenIsAClearError) {
  const auto& c = GetSmallCase();
  int absent = -1;
  for (int id = c.folder.config.room_markers.id_max; id >= c.folder.config.room_markers.id_min && absent < 0; --id) {
    bool placed = false;
    for (const auto& m : c.truth.room_markers) placed |= m.id == id;
    if (!placed) absent = id;
  }
  ASSERT_GE(absent, 0);
  CaseConfig config = c.folder.config;
  config.room_origin_id = absent;
  RoomMapStageOptions stage;
  stage.use_keypoints = false;
  try {
    BuildRoomMap(Sequence::Open(c.folder.room_dir), config, MakeRoomMapBuildOptions(c.folder, stage));
    FAIL() << "expected an InputError";
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("origin marker (id " + std::to_string(absent)), std::string::npos) << what;
    EXPECT_NE(what.find("never seen"), std::string::npos) << what;
    EXPECT_NE(what.find("room"), std::string::npos) << what;
  }
}

// A copy of the small case's case.yaml and room/ in `dir`/case, to alter.
fs::path CopyRoom(const testing::SmallCase& c, const fs::path& dir) {
  const fs::path case_copy = dir / "case";
  fs::create_directories(case_copy);
  fs::copy(c.root / "case.yaml", case_copy / "case.yaml");
  fs::copy(c.folder.room_dir, case_copy / "room", fs::copy_options::recursive);
  return case_copy;
}

TEST(RoomMap, CorruptFrameErrorNamesTheFile) {
  const auto& c = GetSmallCase();
  TempDir dir("arpos_planning_corrupt");
  const fs::path case_copy = CopyRoom(c, dir.path());
  const Sequence room = Sequence::Open(case_copy / "room");
  const fs::path broken = room.color_path(room.size() / 2);
  {
    std::ofstream out(broken, std::ios::binary | std::ios::trunc);
    out << "this is not a PNG";
  }
  try {
    BuildRoomMap(room, c.folder.config, MakeRoomMapBuildOptions(c.folder.config));
    FAIL() << "expected an InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(broken.filename().string()), std::string::npos) << e.what();
  }
}

// Room-marker views ArUco reads whose edges cannot be fitted (a hand moving
// the camera during the exposure) are counted apart from the views used, and
// when they are as many, the plan says why and what to record; a sharp walk
// says nothing of the kind.
TEST(RoomMap, BlurredMarkerViewsAreCountedAndToldWhatToRecord) {
  const auto& c = GetSmallCase();
  const RoomMapBuildResult& sharp = GetSmallCaseMap();
  auto warned = [](const RoomMapBuildReport& r) {
    for (const std::string& w : r.warnings) {
      if (w.find("edges could not be fitted") != std::string::npos &&
          w.find("more slowly") != std::string::npos) {
        return true;
      }
    }
    return false;
  };
  EXPECT_FALSE(warned(sharp.report)) << sharp.report.ToText();
  EXPECT_LT(2 * sharp.report.unrefined_marker_views, sharp.report.marker_views)
      << sharp.report.ToText();

  TempDir dir("arpos_planning_blurred");
  const fs::path case_copy = CopyRoom(c, dir.path());
  const Sequence room = Sequence::Open(case_copy / "room");
  // Every frame smeared along the image diagonal over 7 px, as a hand-held
  // camera turning during the exposure smears it (in linear light, then
  // the sRGB curve again).
  const cv::Mat smear = cv::Mat::eye(7, 7, CV_32F) / 7;
  for (size_t i = 0; i < room.size(); ++i) {
    const std::string path = room.color_path(i).string();
    cv::Mat bgr = cv::imread(path, cv::IMREAD_COLOR), linear;
    ASSERT_FALSE(bgr.empty()) << path;
    bgr.convertTo(linear, CV_32F, 1.0 / 255);
    cv::pow(linear, 2.2, linear);
    cv::filter2D(linear, linear, -1, smear);
    cv::pow(linear, 1 / 2.2, linear);
    linear.convertTo(bgr, CV_8U, 255);
    ASSERT_TRUE(cv::imwrite(path, bgr)) << path;
  }
  const RoomMapBuildResult blurred =
      BuildRoomMap(Sequence::Open(case_copy / "room"), c.folder.config,
                   MakeRoomMapBuildOptions(c.folder, RoomMapStageOptions()));
  const RoomMapBuildReport& r = blurred.report;
  EXPECT_GE(r.unrefined_marker_views, 5) << r.ToText();
  EXPECT_GE(2 * r.unrefined_marker_views, r.marker_views + r.unrefined_marker_views) << r.ToText();
  EXPECT_LT(r.marker_views, sharp.report.marker_views) << r.ToText();
  EXPECT_TRUE(warned(r)) << r.ToText();
  EXPECT_NE(r.ToText().find("more read whose edges could not be fitted"), std::string::npos)
      << r.ToText();
}

TEST(RoomMap, PlanStageStoresTheMapAndCreatesThePlanOnce) {
  const auto& c = GetSmallCase();
  auto db = SqliteDatabase::Open(":memory:");
  // Nothing stored yet: localisation has no map to use.
  try {
    LoadRoomMapForLocalization(db.get(), std::nullopt, "");
    FAIL() << "expected an InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("no room map"), std::string::npos) << e.what();
  }
  PlanRoomMapOptions options;
  options.case_dir = c.root;
  options.stage.use_keypoints = false;  // quick; the keypoint layer is tested above
  const PlanRoomMapResult first = RunPlanRoomMap(options, db.get());
  EXPECT_TRUE(first.created_plan);
  ASSERT_TRUE(db->FindPatient(CasePatientId(c.root)));
  const auto record = db->GetRoomMap(first.room_map_id);
  ASSERT_TRUE(record);
  EXPECT_EQ(record->plan_id, first.plan_id);
  EXPECT_EQ(record->origin_marker_id, c.folder.config.room_origin_id);
  EXPECT_EQ(record->markers.size(), first.build.map.markers.size());
  EXPECT_GT(record->mean_residual_px, 0);
  for (const auto& m : record->markers) EXPECT_GT(m.num_observations, 0);
  // A second run files the map under the same plan.
  const PlanRoomMapResult second = RunPlanRoomMap(options, db.get());
  EXPECT_FALSE(second.created_plan);
  EXPECT_EQ(second.plan_id, first.plan_id);
  PlanId used;
  RoomMapId used_map;
  const RoomMap loaded = LoadRoomMapForLocalization(db.get(), std::nullopt, CasePatientId(c.root), &used, &used_map);
  EXPECT_EQ(used, first.plan_id);
  EXPECT_EQ(used_map, second.room_map_id);
  EXPECT_EQ(loaded.markers.size(), second.build.map.markers.size());
  // A plan without a map is a clear error too.
  PlanRecord empty_plan;
  empty_plan.patient_id = first.patient_id;
  empty_plan.name = "no map";
  const PlanId bare = db->AddPlan(empty_plan);
  try {
    LoadRoomMapForLocalization(db.get(), bare, "");
    FAIL() << "expected an InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("has no room map"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace arpos
