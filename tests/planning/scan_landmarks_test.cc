// Room landmarks placed from posed frames (room_map/scan_landmarks.h) and the
// triangulation they share with the room map (room_map/landmark_triangulation.h),
// on synthetic keypoints whose true points are known.
#include <gtest/gtest.h>

#include <random>
#include <set>

#include "room_map/landmark_triangulation.h"
#include "room_map/scan_landmarks.h"
#include "util/check.h"

namespace arpos {
namespace {

CameraIntrinsics TestCamera() {
  CameraIntrinsics K;
  K.width = 640;
  K.height = 480;
  K.fx = K.fy = 525;
  K.cx = 319.5;
  K.cy = 239.5;
  return K;
}

struct Scene {
  std::vector<Eigen::Vector3d> points;
  std::vector<std::array<std::uint8_t, 32>> descriptors;
  std::vector<ScanLandmarkFrame> frames;
};

// `n` points on a wall 2.5-3.5 m in front of cameras spread 0.6 m sideways
// (room frame: x right, y down, z ahead); each frame reads the points it
// sees at their pixel (0.3 px noise) and depth (1 mm), their descriptors
// with up to 4 bits flipped, plus `clutter` keypoints seen once. Frame
// `off_frame` (if >= 0) is posed `off_m` off to the side of where it was.
Scene MakeScene(int n, int frames, int clutter, int off_frame = -1, double off_m = 0) {
  std::mt19937 random(11);
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> px_noise(0, 0.3), z_noise(0, 0.001);
  const CameraIntrinsics K = TestCamera();
  Scene s;
  for (int i = 0; i < n; ++i) {
    s.points.emplace_back(-1.2 + 2.4 * u(random), -0.9 + 1.8 * u(random), 2.5 + u(random));
    std::array<std::uint8_t, 32> d;
    for (auto& b : d) b = static_cast<std::uint8_t>(random());
    s.descriptors.push_back(d);
  }
  for (int f = 0; f < frames; ++f) {
    const double x = -0.3 + 0.6 * f / std::max(1, frames - 1);
    const Rigid3d room_from_camera = Rigid3d::FromRotationVector(
        Eigen::Vector3d(0.02 * f, -0.1 * x, 0.01), Eigen::Vector3d(x, 0.05 * f, 0));
    ScanLandmarkFrame frame;
    frame.room_from_camera = room_from_camera;
    if (f == off_frame) {
      frame.room_from_camera = Rigid3d(room_from_camera.rotation,
                                       room_from_camera.translation + Eigen::Vector3d(off_m, 0, 0));
    }
    KeypointSet& set = frame.keypoints;
    set.image_width = K.width;
    set.image_height = K.height;
    std::vector<std::array<std::uint8_t, 32>> rows;
    const Rigid3d camera_from_room = room_from_camera.Inverse();
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector3d p = camera_from_room * s.points[i];
      const Eigen::Vector2d uv = K.Project(p) + Eigen::Vector2d(px_noise(random), px_noise(random));
      if (uv.x() < 25 || uv.y() < 25 || uv.x() > K.width - 25 || uv.y() > K.height - 25) continue;
      set.keypoints.emplace_back(static_cast<float>(uv.x()), static_cast<float>(uv.y()), 7.f);
      set.depth_m.push_back(static_cast<float>(p.z() + z_noise(random)));
      auto d = s.descriptors[i];
      for (int k = static_cast<int>(random() % 5); k > 0; --k)
        d[random() % 32] ^= static_cast<std::uint8_t>(1u << (random() % 8));
      rows.push_back(d);
    }
    for (int c = 0; c < clutter; ++c) {
      set.keypoints.emplace_back(static_cast<float>(25 + 590 * u(random)),
                                 static_cast<float>(25 + 430 * u(random)), 7.f);
      set.depth_m.push_back(static_cast<float>(1 + 3 * u(random)));
      std::array<std::uint8_t, 32> d;
      for (auto& b : d) b = static_cast<std::uint8_t>(random());
      rows.push_back(d);
    }
    set.descriptors = cv::Mat(static_cast<int>(rows.size()), 32, CV_8UC1);
    for (size_t r = 0; r < rows.size(); ++r)
      std::copy(rows[r].begin(), rows[r].end(),
                set.descriptors.ptr<std::uint8_t>(static_cast<int>(r)));
    s.frames.push_back(std::move(frame));
  }
  return s;
}

// The scene as it is: depth read to 1 mm out to 3.5 m, keypoints to 0.3 px
// (the defaults allow for poses a few tenths of a degree off).
ScanLandmarkOptions TestOptions() {
  ScanLandmarkOptions options;
  options.triangulation.keypoint_sigma_px = 0.5;
  options.max_depth_m = 4;
  options.triangulation.depth_sigma_const_m = 0.001;
  options.triangulation.depth_sigma_quad_per_m = 0;
  return options;
}

int NearestTruthIndex(const Scene& s, const Eigen::Vector3d& x) {
  int at = 0;
  for (size_t i = 1; i < s.points.size(); ++i) {
    if ((s.points[i] - x).norm() < (s.points[at] - x).norm()) at = static_cast<int>(i);
  }
  return at;
}

// Nearest true point and the Hamming distance to its descriptor.
std::pair<double, int> NearestTruth(const Scene& s, const Eigen::Vector3d& x,
                                    const std::uint8_t* descriptor) {
  double best = 1e9;
  int at = -1;
  for (size_t i = 0; i < s.points.size(); ++i) {
    const double d = (s.points[i] - x).norm();
    if (d < best) {
      best = d;
      at = static_cast<int>(i);
    }
  }
  return {best, HammingDistance32(descriptor, s.descriptors[at].data())};
}

TEST(ScanLandmarks, PointsSeenInSeveralPosedFramesArePlacedWhereTheyAre) {
  const Scene s = MakeScene(400, 8, 150);
  ScanLandmarkOptions options = TestOptions();
  // What moves during tracking: a box over the wall's left third.
  ExclusionBox box;
  box.room_from_box = Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(-0.8, 0, 3));
  box.half_extent_m = Eigen::Vector3d(0.4, 1.5, 1.0);
  options.exclude = {box};
  const ScanLandmarks placed = PlaceScanLandmarks(s.frames, TestCamera(), options);
  EXPECT_EQ(placed.frames, 8);
  int outside = 0;
  for (const auto& p : s.points) outside += box.Contains(p) ? 0 : 1;
  // Most points outside the box (each is in view of most frames); none of
  // the keypoints seen once (clutter), none inside the box.
  EXPECT_GT(placed.size(), outside * 8 / 10) << placed.size() << " of " << outside;
  EXPECT_LE(placed.size(), outside + 2);  // a point at the box's edge may fall either side
  ASSERT_EQ(placed.descriptors.rows, placed.size());
  double sum = 0, worst = 0;
  std::set<int> truths;
  for (int i = 0; i < placed.size(); ++i) {
    EXPECT_FALSE(box.Contains(placed.points_in_room[i]));
    EXPECT_TRUE(truths.insert(NearestTruthIndex(s, placed.points_in_room[i])).second)
        << "a point placed twice";
    const auto [distance, hamming] =
        NearestTruth(s, placed.points_in_room[i], placed.descriptors.ptr<std::uint8_t>(i));
    sum += distance;
    worst = std::max(worst, distance);
    EXPECT_LE(hamming, 4) << "landmark " << i;
  }
  // 0.3 px at 3 m is 1.7 mm sideways over one view; the depth reads 1 mm.
  EXPECT_LT(sum / placed.size(), 0.0015);
  EXPECT_LT(worst, 0.005);
}

TEST(ScanLandmarks, AFramePosedOffIsOutvotedNotFollowed) {
  // One of eight frames 3 cm to the side (a frame the stickers posed badly):
  // its readings disagree by ~5 px with the others and are dropped.
  const Scene s = MakeScene(300, 8, 0, /*off_frame=*/3, /*off_m=*/0.03);
  const ScanLandmarks placed = PlaceScanLandmarks(s.frames, TestCamera(), TestOptions());
  ASSERT_GT(placed.size(), 200);
  double sum = 0;
  for (int i = 0; i < placed.size(); ++i)
    sum += NearestTruth(s, placed.points_in_room[i], placed.descriptors.ptr<std::uint8_t>(i)).first;
  EXPECT_LT(sum / placed.size(), 0.002);
}

TEST(ScanLandmarks, TooFewFramesOrNoneAllowedPlaceNothing) {
  const Scene two = MakeScene(100, 2, 0);
  EXPECT_EQ(PlaceScanLandmarks(two.frames, TestCamera(), ScanLandmarkOptions()).size(),
            0);  // 3 views needed
  ScanLandmarkOptions none;
  none.max_landmarks = 0;
  EXPECT_EQ(PlaceScanLandmarks(MakeScene(100, 6, 0).frames, TestCamera(), none).size(), 0);
  ScanLandmarkOptions bad;
  bad.triangulation.min_observations = 1;
  EXPECT_NE(bad.Validate().find("min_observations"), std::string::npos);
}

TEST(ScanLandmarks, StoredWithTheBodyMarkerMapAndPutFirstInTheRoomMap) {
  const ScanLandmarks placed =
      PlaceScanLandmarks(MakeScene(200, 6, 0).frames, TestCamera(), ScanLandmarkOptions());
  ASSERT_GT(placed.size(), 100);
  BodyMarkerMapRecord record;
  record.id = BodyMarkerMapId(4);
  ToRecord(placed, &record);
  RoomMap map;
  map.landmarks_in_room = {Eigen::Vector3d(5, 5, 5)};
  map.landmark_descriptors = cv::Mat(1, kDescriptorBytes, CV_8UC1, cv::Scalar(9));
  EXPECT_EQ(AddScanLandmarks(record, &map), placed.size());
  ASSERT_EQ(map.num_landmarks(), placed.size() + 1);
  EXPECT_EQ(map.landmark_descriptors.rows, placed.size() + 1);
  for (int i = 0; i < placed.size(); ++i) {
    EXPECT_LT((map.landmarks_in_room[i] - placed.points_in_room[i]).norm(), 1e-6);  // float storage
    EXPECT_EQ(HammingDistance32(map.landmark_descriptors.ptr<std::uint8_t>(i),
                                placed.descriptors.ptr<std::uint8_t>(i)),
              0);
  }
  EXPECT_EQ(map.landmarks_in_room.back(), Eigen::Vector3d(5, 5, 5));
  EXPECT_EQ(map.landmark_descriptors.at<std::uint8_t>(placed.size(), 0), 9);
  // A record whose descriptors do not match its points names the map.
  record.room_landmark_descriptors.conservativeResize(3, kDescriptorBytes);
  try {
    AddScanLandmarks(record, &map);
    FAIL() << "accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("body marker map 4"), std::string::npos) << e.what();
  }
  // None stored (a session from before them): the map as it was.
  RoomMap plain = map;
  EXPECT_EQ(AddScanLandmarks(BodyMarkerMapRecord(), &plain), 0);
  EXPECT_EQ(plain.num_landmarks(), map.num_landmarks());
}

TEST(LandmarkTriangulation, AnObservationThatDisagreesIsDroppedAndTheRestDecide) {
  const CameraIntrinsics K = TestCamera();
  const Eigen::Vector3d X(0.2, -0.1, 2.0);
  std::vector<Rigid3d> camera_from_room;
  std::vector<LandmarkObservation> obs;
  for (int c = 0; c < 5; ++c) {
    const Rigid3d room_from_camera(Eigen::Quaterniond::Identity(),
                                   Eigen::Vector3d(0.1 * c - 0.2, 0, 0));
    camera_from_room.push_back(room_from_camera.Inverse());
    const Eigen::Vector3d p = camera_from_room.back() * X;
    obs.push_back({c, K.Project(p), c == 4 ? 0.0 : p.z()});
  }
  obs[2].px += Eigen::Vector2d(9, 0);  // a wrong match
  LandmarkTriangulationOptions options;
  const auto placed = TriangulateLandmark(obs, camera_from_room, K, options);
  ASSERT_TRUE(placed.has_value());
  EXPECT_LT((placed->point_in_room - X).norm(), 1e-4);
  EXPECT_EQ(placed->inliers, 4);
  EXPECT_FALSE(placed->inlier[2]);
  // Without any depth reading there is no start.
  for (auto& o : obs) o.depth_m = 0;
  EXPECT_FALSE(TriangulateLandmark(obs, camera_from_room, K, options).has_value());
}

}  // namespace
}  // namespace arpos
