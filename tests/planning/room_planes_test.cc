// The room's planes: grouping markers by plane, finding planes in depth, and
// the plane-depth terms of the room map's bundle adjustment on a synthetic
// floor; the depth check against the colour geometry on it.
#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "features/marker_pose.h"
#include "geometry/so3.h"
#include "room_map/bundle_adjustment.h"
#include "room_map/depth_check.h"
#include "room_map/room_planes.h"
#include "simulation/trajectory.h"

namespace arpos {
namespace {

std::array<Eigen::Vector3d, 4> Corners(const Rigid3d& room_from_marker, double side) {
  std::array<Eigen::Vector3d, 4> c = MarkerCornersInMarker(side);
  for (auto& p : c) p = room_from_marker * p;
  return c;
}

TEST(RoomPlanes, MarkersAreGroupedByPlaneAndARowIsNoPlane) {
  // Three markers on the floor (z = 0) spread over 2 m, two on a wall
  // (x = 3) side by side, one alone on the other wall.
  const double side = 0.15;
  const Eigen::Matrix3d wall = Eigen::AngleAxisd(-M_PI / 2, Eigen::Vector3d::UnitY()).toRotationMatrix();
  const std::vector<Rigid3d> markers = {
      Rigid3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 0, 0)),
      Rigid3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(1.5, 0.2, 0.004)),
      Rigid3d(wall, Eigen::Vector3d(3, 0, 1.2)),
      Rigid3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.4, 1.8, -0.003)),
      Rigid3d(wall, Eigen::Vector3d(3, 0.3, 1.2)),
      Rigid3d(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitX()).toRotationMatrix(), Eigen::Vector3d(1, 3, 1)),
  };
  std::vector<Eigen::Vector3d> normals, centres;
  std::vector<std::array<Eigen::Vector3d, 4>> corners;
  for (const Rigid3d& m : markers) {
    normals.push_back(m.rotation * Eigen::Vector3d::UnitZ());
    centres.push_back(m.translation);
    corners.push_back(Corners(m, side));
  }
  const std::vector<MarkerPlane> planes = FindMarkerPlanes(normals, centres, corners, 2, 0.2);
  ASSERT_EQ(planes.size(), 1u) << "the wall's two markers side by side are a row, not a plane";
  EXPECT_EQ(planes[0].markers, (std::vector<int>{0, 1, 3}));
  EXPECT_GT(planes[0].normal.z(), 0.9999);
  EXPECT_NEAR(planes[0].offset, 0.0, 0.003);
  // Without the spread test the row is a plane of its own.
  EXPECT_EQ(FindMarkerPlanes(normals, centres, corners, 2, 0.0).size(), 2u);
}

TEST(RoomPlanes, ThePlaneAViewShowsKeepsItsPointsAndLeavesOutTheFootOfAWall) {
  // Points on a plane 2 m in front of the camera, and a band of points 2 cm
  // off it (what the gate lets in of a wall's foot): the band is left out.
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 0.002);
  std::vector<Eigen::Vector3d> points;
  std::vector<double> sigma;
  for (int i = 0; i < 400; ++i) {
    const double x = -1 + 2 * (i % 20) / 19.0, y = -0.7 + 1.4 * (i / 20) / 19.0;
    points.emplace_back(x, y, 2.0 + noise(rng));
    sigma.push_back(0.002);
  }
  for (int i = 0; i < 60; ++i) {
    points.emplace_back(-1 + 2 * i / 59.0, 0.7, 2.02);
    sigma.push_back(0.002);
  }
  // The mapped plane as the view's (slightly wrong) pose puts it.
  const Eigen::Vector3d n = Eigen::AngleAxisd(RadFromDeg(0.5), Eigen::Vector3d::UnitX()) * Eigen::Vector3d::UnitZ();
  const std::vector<size_t> kept = PointsOnViewedPlane(points, sigma, n, 2.0);
  int plane = 0, band = 0;
  for (size_t k : kept) (k < 400 ? plane : band)++;
  EXPECT_GT(plane, 390);
  EXPECT_EQ(band, 0);
}

TEST(RoomPlanes, AWallWithoutMarkersIsFoundInDepthAndTheFloorReachesBeyondItsMarkers) {
  // Depth of ten views (room frame, 5 mm noise): a floor (z = 0, 4 x 5 m)
  // with two markers near one corner, a wall (x = 3, 5 m long, 2.5 m high)
  // and a 0.4 m box on the floor; the origin marker alone on the far wall
  // (y = 6), its plane from its own normal, 2 deg off, not to be extended.
  std::mt19937 rng(5);
  std::normal_distribution<double> noise(0.0, 0.005);
  std::uniform_real_distribution<double> unit(0, 1);
  std::vector<Eigen::Vector3d> points;
  std::vector<int> views;
  auto add = [&](const Eigen::Vector3d& p, int view) {
    points.push_back(p + Eigen::Vector3d(noise(rng), noise(rng), noise(rng)));
    views.push_back(view);
  };
  for (int view = 0; view < 10; ++view) {
    for (int i = 0; i < 1500; ++i) {
      const double u = unit(rng), v = unit(rng);
      add(Eigen::Vector3d(-1 + 4 * u, -1 + 5 * v, 0), view);          // floor
      add(Eigen::Vector3d(3, -1 + 5 * u, 2.5 * v), view);             // wall
      add(Eigen::Vector3d(-1 + 4 * u, 6, 2.5 * v), view);             // far wall
      add(Eigen::Vector3d(0.3 + 0.4 * u, 0.3 + 0.4 * v, 0.4), view);  // box top
      add(Eigen::Vector3d(0.3, 0.3 + 0.4 * u, 0.4 * v), view);        // box side
    }
  }
  MarkerPlane floor;
  floor.normal = Eigen::Vector3d::UnitZ();
  floor.markers = {1, 2};
  floor.marker_centres = {Eigen::Vector3d(-0.8, -0.8, 0.001), Eigen::Vector3d(-0.2, -0.7, -0.001)};
  MarkerPlane origin;
  origin.normal = Eigen::AngleAxisd(RadFromDeg(2.0), Eigen::Vector3d::UnitZ()) * Eigen::Vector3d(0, -1, 0);
  origin.offset = origin.normal.dot(Eigen::Vector3d(1, 6, 1.2));
  origin.markers = {0};
  origin.marker_centres = {Eigen::Vector3d(1, 6, 1.2)};
  origin.extend_in_depth = false;
  std::vector<MarkerPlane> planes = {floor, origin};
  DepthPlaneOptions options;
  EXPECT_EQ(AddDepthPlanes(points, views, options, &planes), 2)
      << "the wall, and the far wall beside the origin's own plane; the floor is the markers'";
  ASSERT_EQ(planes.size(), 4u);
  EXPECT_FALSE(planes[0].cells.empty());
  EXPECT_TRUE(planes[1].cells.empty()) << "the origin's plane is left as it is";
  EXPECT_LT(planes[1].normal.dot(Eigen::Vector3d(0, -1, 0)), std::cos(RadFromDeg(1.9)));
  int wall = -1, far_wall = -1;
  for (int p = 2; p < 4; ++p) (std::abs(planes[p].normal.x()) > 0.9 ? wall : far_wall) = p;
  ASSERT_GE(wall, 0);
  ASSERT_GE(far_wall, 0);
  EXPECT_GT(std::abs(planes[wall].normal.x()), std::cos(RadFromDeg(0.1)));
  EXPECT_NEAR(planes[wall].offset * planes[wall].normal.x(), 3.0, 0.005);
  EXPECT_GT(std::abs(planes[far_wall].normal.y()), std::cos(RadFromDeg(0.1)));
  // A point of the wall, of the floor 4 m from its markers: on their planes;
  // the box's top: on none.
  EXPECT_EQ(PlaneNear(planes, Eigen::Vector3d(3, 3.8, 2.2), 0.03, 2.0), wall);
  EXPECT_EQ(PlaneNear(planes, Eigen::Vector3d(2.8, 3.5, 0.01), 0.03, 2.0), 0);
  EXPECT_EQ(PlaneNear(planes, Eigen::Vector3d(0.5, 0.5, 0.4), 0.03, 2.0), -1);
  // Seen by fewer views than asked: no plane.
  std::vector<MarkerPlane> none;
  options.min_views = 11;
  EXPECT_EQ(AddDepthPlanes(points, views, options, &none), 0);
  EXPECT_TRUE(none.empty());
}

// A floor with the origin marker at one end and markers 1.5 and 3 m away,
// each camera seeing two of them small and at a glancing angle. The floor's depth
// in every view holds the cameras' tilt, and with it the far marker's
// height, far better than the markers' corners alone.
struct FloorScene {
  CameraIntrinsics K;
  double side = 0.12;
  std::vector<Rigid3d> room_from_marker;
  std::vector<Rigid3d> camera_from_room;

  FloorScene() {
    K.width = 640;
    K.height = 480;
    K.fx = K.fy = 525;
    K.cx = 319.5;
    K.cy = 239.5;
    K.depth_scale = 1000;
    for (double x : {0.0, 1.5, 3.0}) {
      room_from_marker.push_back(Rigid3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(x, 0.2, 0)));
    }
    for (double x : {0.0, 0.75, 0.8, 1.5, 2.25, 2.3, 3.0}) {
      camera_from_room.push_back(
          sim::LookAt(Eigen::Vector3d(x - 0.2, -1.8, 1.5), Eigen::Vector3d(x, 0.2, 0)).Inverse());
    }
  }

  // Corners (0.1 px noise) of every marker in view, and the floor's depth on
  // a grid every 16 px (sensor noise 1 mm + 1.5e-3 z^2); from the scene's
  // cameras, or from `cameras` (camera_from_room each).
  BaProblem Observe(uint32_t seed, bool floor_depth,
                    const std::vector<Rigid3d>* cameras = nullptr) const {
    const std::vector<Rigid3d>& views = cameras ? *cameras : camera_from_room;
    std::mt19937 rng(seed);
    std::normal_distribution<double> unit(0.0, 1.0);
    BaProblem P;
    P.intrinsics = K;
    P.marker_size_m = side;
    P.room_from_marker = room_from_marker;
    P.marker_fixed = {true, false, false};
    // The other markers and the cameras start off the truth.
    for (int m = 1; m < 3; ++m) {
      P.room_from_marker[m] = Rigid3d(Eigen::AngleAxisd(0.01, Eigen::Vector3d::UnitX()).toRotationMatrix(),
                                      room_from_marker[m].translation + Eigen::Vector3d(0.01, -0.01, 0.02));
    }
    for (const Rigid3d& c : views) {
      P.camera_from_room.push_back(
          Rigid3d(Eigen::AngleAxisd(0.005, Eigen::Vector3d::UnitY()).toRotationMatrix(), Eigen::Vector3d(0.01, 0, 0)) *
          c);
    }
    for (size_t c = 0; c < views.size(); ++c) {
      for (size_t m = 0; m < room_from_marker.size(); ++m) {
        BaMarkerObservation o;
        o.camera = static_cast<int>(c);
        o.marker = static_cast<int>(m);
        const std::array<Eigen::Vector3d, 4> corners = Corners(room_from_marker[m], side);
        bool in_view = true;
        for (int k = 0; k < 4; ++k) {
          const Eigen::Vector3d p = views[c] * corners[k];
          const Eigen::Vector2d px = K.Project(p);
          in_view &= p.z() > 0 && px.x() > 0 && px.y() > 0 && px.x() < K.width && px.y() < K.height;
          o.corners_px[k] = px + 0.1 * Eigen::Vector2d(unit(rng), unit(rng));
          o.sigma_px[k] = 0.1;
        }
        if (in_view) P.marker_observations.push_back(o);
      }
    }
    if (floor_depth) {
      P.planes.push_back({Eigen::Vector3d(0.002, 0, 1).normalized(), 0.003, {0, 1, 2}, 0.002, RadFromDeg(0.05)});
      for (size_t c = 0; c < views.size(); ++c) {
        const Rigid3d room_from_camera = views[c].Inverse();
        BaPlaneObservation o;
        o.camera = static_cast<int>(c);
        o.plane = 0;
        for (int v = 8; v < K.height; v += 16) {
          for (int u = 8; u < K.width; u += 16) {
            const Eigen::Vector3d ray((u - K.cx) / K.fx, (v - K.cy) / K.fy, 1);
            const Eigen::Vector3d d = room_from_camera.rotation * ray;
            if (!(d.z() < -1e-3)) continue;
            const double z = -room_from_camera.translation.z() / d.z();  // depth along the optical axis
            if (z > 4.5) continue;
            const double sigma = 0.001 + 0.0015 * z * z;
            o.samples.push_back({Eigen::Vector2f(u, v), static_cast<float>(z + sigma * unit(rng))});
          }
        }
        o.share = std::sqrt(std::max(1.0, o.samples.size() / 25.0));
        P.plane_observations.push_back(std::move(o));
      }
    }
    return P;
  }

  // Adds 60 textured points on the floor between the markers, seen by every
  // camera that has them in view (0.7 px noise, depth with the sensor's).
  void AddFloorLandmarks(BaProblem* P, uint32_t seed) const {
    std::mt19937 rng(seed);
    std::normal_distribution<double> unit(0.0, 1.0);
    std::uniform_real_distribution<double> x(-0.3, 3.3), y(-0.6, 1.0);
    for (int l = 0; l < 60; ++l) {
      const Eigen::Vector3d X(x(rng), y(rng), 0);
      const int landmark = static_cast<int>(P->landmarks_in_room.size());
      P->landmarks_in_room.push_back(X + Eigen::Vector3d(0.01, 0.01, 0.01));
      for (size_t c = 0; c < camera_from_room.size(); ++c) {
        const Eigen::Vector3d p = camera_from_room[c] * X;
        const Eigen::Vector2d px = K.Project(p);
        if (p.z() <= 0 || px.x() < 0 || px.y() < 0 || px.x() >= K.width || px.y() >= K.height) continue;
        BaKeypointObservation o;
        o.camera = static_cast<int>(c);
        o.landmark = landmark;
        o.pixel = px + 0.7 * Eigen::Vector2d(unit(rng), unit(rng));
        o.sigma_px = 0.7;
        const double sigma = 0.001 + 0.0015 * p.z() * p.z();
        o.depth_m = static_cast<float>(p.z() + sigma * unit(rng));
        P->keypoint_observations.push_back(o);
      }
    }
  }
};

TEST(RoomPlanes, TheFloorsDepthHoldsAFarMarkersHeightInTheAdjustment) {
  const FloorScene scene;
  BaOptions options;
  options.use_marker_depth = false;
  double without = 0, with = 0, tilt = 0;
  const int draws = 8;
  for (int d = 0; d < draws; ++d) {
    BaProblem a = scene.Observe(100 + d, false), b = scene.Observe(100 + d, true);
    ASSERT_GE(a.marker_observations.size(), 12u);
    ASSERT_TRUE(RunBundleAdjustment(&a, options).usable);
    ASSERT_TRUE(RunBundleAdjustment(&b, options).usable);
    // The far marker's corners' height above the floor (truth: 0).
    for (const Eigen::Vector3d& p : Corners(a.room_from_marker[2], scene.side)) without += std::abs(p.z()) / 4;
    for (const Eigen::Vector3d& p : Corners(b.room_from_marker[2], scene.side)) with += std::abs(p.z()) / 4;
    tilt += std::acos(std::min(1.0, b.planes[0].normal.z()));
  }
  without /= draws;
  with /= draws;
  tilt /= draws;
  std::printf("far marker's height: %.3f mm without the floor's depth, %.3f mm with; floor tilt %.4f deg\n",
              without * 1000, with * 1000, tilt * 180 / M_PI);
  // Measured: 13.5 mm without, 1.3 mm with, the floor within 0.014 deg.
  EXPECT_LT(with, 0.2 * without);
  EXPECT_LT(with, 0.002);
  EXPECT_LT(tilt, RadFromDeg(0.03));
}

// The covariance the adjustment gives of a marker's centre relative to
// another (the plan's "map near the couch relative to the origin") is
// honest and does not depend on which marker holds the map: over draws of
// the corner noise the far marker's errors match it (mean normalised squared
// error near 3, its three degrees of freedom), with or without keypoints on
// the floor (landmarks, eliminated by their Schur complement), and the same
// quantity with the far marker fixed instead of the origin is the same
// matrix (which checks the cross terms and Ceres's half-angle increments).
TEST(RoomPlanes, AMarkersCovarianceRelativeToTheOriginIsHonestAndTheSameWhicheverMarkerIsFixed) {
  const FloorScene scene;
  BaOptions options;
  options.use_marker_depth = false;
  options.covariance_reference = 0;
  options.covariance_markers = {2, 0};
  // Mean normalised squared error of the far marker and its mean 1 sigma
  // (mm) over 40 draws, with or without keypoints on the floor; and the
  // same for its orientation relative to the origin's.
  double rotation_nees = 0;
  int rotation_draws = 0;
  auto draw = [&](bool keypoints) {
    double nees = 0, sigma_mm = 0;
    const int draws = 40;
    for (int d = 0; d < draws; ++d) {
      BaProblem p = scene.Observe(300 + d, false);
      if (keypoints) scene.AddFloorLandmarks(&p, 500 + d);
      const BaSummary s = RunBundleAdjustment(&p, options);
      EXPECT_TRUE(s.usable);
      EXPECT_EQ(s.relative_centre_covariance.size(), 2u);
      if (s.relative_centre_covariance.size() != 2u) return std::make_pair(1e9, 1e9);
      EXPECT_TRUE(s.relative_centre_covariance[1].isZero()) << "a marker relative to itself";
      const Eigen::Matrix3d& c = s.relative_centre_covariance[0];
      EXPECT_TRUE(c.allFinite());
      const Eigen::Vector3d e = p.room_from_marker[2].translation - scene.room_from_marker[2].translation;
      nees += e.dot(c.ldlt().solve(e));
      sigma_mm += 1000 * std::sqrt(c.trace());
      EXPECT_EQ(s.relative_rotation_covariance.size(), 2u);
      if (s.relative_rotation_covariance.size() == 2u) {
        EXPECT_TRUE(s.relative_rotation_covariance[1].isZero()) << "a marker relative to itself";
        const Eigen::Matrix3d& rc = s.relative_rotation_covariance[0];
        EXPECT_TRUE(rc.allFinite());
        const Eigen::Quaterniond est = p.room_from_marker[0].rotation.inverse() * p.room_from_marker[2].rotation;
        const Eigen::Quaterniond truth =
            scene.room_from_marker[0].rotation.inverse() * scene.room_from_marker[2].rotation;
        const Eigen::Vector3d w = RotationVectorFromQuaternion(est * truth.inverse());
        rotation_nees += w.dot(rc.ldlt().solve(w));
        ++rotation_draws;
      }
    }
    return std::make_pair(nees / draws, sigma_mm / draws);
  };
  const auto [nees, sigma_mm] = draw(false);
  std::printf("far marker: mean NEES %.2f (3 expected), 1 sigma %.2f mm\n", nees, sigma_mm);
  EXPECT_GT(nees, 1.5);
  EXPECT_LT(nees, 6.0);
  // With keypoints on the floor (landmarks, which the covariance takes out
  // by their Schur complement): narrower, and as honest.
  const auto [nees_kp, sigma_kp_mm] = draw(true);
  std::printf("with floor keypoints: mean NEES %.2f, 1 sigma %.2f mm\n", nees_kp, sigma_kp_mm);
  EXPECT_GT(nees_kp, 1.5);
  EXPECT_LT(nees_kp, 6.0);
  EXPECT_LT(sigma_kp_mm, 0.8 * sigma_mm);
  // The orientation's covariance is as honest (80 draws, 3 expected).
  std::printf("far marker's orientation: mean NEES %.2f over %d draws\n", rotation_nees / rotation_draws,
              rotation_draws);
  EXPECT_EQ(rotation_draws, 80);
  EXPECT_GT(rotation_nees / rotation_draws, 1.5);
  EXPECT_LT(rotation_nees / rotation_draws, 6.0);

  // The map held by the far marker instead: its centre in the origin's
  // frame (the origin free, the reference) has the same covariance.
  BaProblem a = scene.Observe(400, false), b = scene.Observe(400, false);
  b.marker_fixed = {false, false, true};
  b.room_from_marker[2] = scene.room_from_marker[2];
  b.room_from_marker[0] = Rigid3d(Eigen::AngleAxisd(0.01, Eigen::Vector3d::UnitX()).toRotationMatrix(),
                                  scene.room_from_marker[0].translation + Eigen::Vector3d(0.01, -0.01, 0.02));
  const BaSummary sa = RunBundleAdjustment(&a, options), sb = RunBundleAdjustment(&b, options);
  ASSERT_EQ(sb.relative_centre_covariance.size(), 2u);
  const Eigen::Matrix3d ca = sa.relative_centre_covariance[0], cb = sb.relative_centre_covariance[0];
  ASSERT_TRUE(cb.allFinite());
  std::printf("origin fixed: sigma %.3f mm; far marker fixed: %.3f mm\n", 1000 * std::sqrt(ca.trace()),
              1000 * std::sqrt(cb.trace()));
  EXPECT_LT((ca - cb).norm(), 0.1 * ca.norm());
  // And its orientation relative to the origin's.
  ASSERT_EQ(sb.relative_rotation_covariance.size(), 2u);
  const Eigen::Matrix3d ra = sa.relative_rotation_covariance[0], rb = sb.relative_rotation_covariance[0];
  ASSERT_TRUE(rb.allFinite());
  std::printf("orientation: origin fixed %.4f deg; far marker fixed %.4f deg\n",
              DegFromRad(std::sqrt(ra.trace())), DegFromRad(std::sqrt(rb.trace())));
  EXPECT_LT((ra - rb).norm(), 0.1 * ra.norm());
}

// The depth check (depth_check.h) on the floor scene's markers seen from
// 1.2 to 3 m, readings inside the markers only: depth reading 0.6 % long
// (7-18 mm, against a reading's noise of 3-15 mm) is found and removed
// (measured: 14.3 mm RMS at the readings' pixels, 3.0 left); the readings of one
// marker view 50 % off (a marker posed wrongly) are left out and counted;
// so are those of a third of the views off both ways (not a scale: what
// stands in front of a marker or is seen beyond it); when every reading is
// that far off (a wrong depth scale) none is left out and the check sees the
// depth as it is.
TEST(DepthCheck, RemovesADepthScaleErrorAndLeavesOutOnlyAFewGrossReadings) {
  const FloorScene scene;
  const CameraIntrinsics& K = scene.K;
  // The scene's markers seen from 1.2 to 3 m (the check needs depths
  // spread over a range): four cameras on each marker's line of sight.
  std::vector<Rigid3d> cameras;
  for (const Rigid3d& m : scene.room_from_marker) {
    for (double f : {1.0, 1.5, 2.0, 2.5}) {
      const Eigen::Vector3d eye = m.translation + f * 0.5 * Eigen::Vector3d(-0.2, -1.8, 1.5);
      cameras.push_back(sim::LookAt(eye, m.translation).Inverse());
    }
  }
  auto with_depth = [&](double scale, int gross_view, double gross_factor, uint32_t seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> unit(0.0, 1.0);
    BaProblem P = scene.Observe(seed, false, &cameras);
    for (size_t i = 0; i < P.marker_observations.size(); ++i) {
      BaMarkerObservation& o = P.marker_observations[i];
      for (int a = -2; a <= 2; ++a) {
        for (int b = -2; b <= 2; ++b) {
          const Eigen::Vector3d in_marker(0.15 * a * scene.side, 0.15 * b * scene.side, 0);
          const Eigen::Vector3d p =
              cameras[o.camera] * (scene.room_from_marker[o.marker] * in_marker);
          const double sigma = 0.001 + 0.0015 * p.z() * p.z();
          double z = p.z() * (1 + scale) + sigma * unit(rng);
          if (static_cast<int>(i) == gross_view || gross_view == -2) z *= gross_factor;
          // Every third view off, some long and some short (what stands in
          // front of a marker, or is seen beyond its edge).
          if (gross_view == -3 && i % 3 == 0) z *= i % 2 == 1 ? gross_factor : 1 / gross_factor;
          const Eigen::Vector2d px = K.Project(p);
          o.depth_samples.push_back({px.cast<float>(), static_cast<float>(z)});
        }
      }
    }
    return P;
  };
  // RMS over every reading's pixel of what `c` leaves of the 0.6 % error
  // (mm, without the readings' noise).
  auto left_mm = [&](const BaProblem& P, const DepthCorrection& c) {
    double sum = 0;
    int n = 0;
    for (const BaMarkerObservation& o : P.marker_observations) {
      for (const DepthSample& s : o.depth_samples) {
        const double x = (s.pixel.x() - K.cx) / K.fx, y = (s.pixel.y() - K.cy) / K.fy;
        const Eigen::Vector3d ray(x, y, 1);
        // The true depth of the pixel: its ray on the marker's plane.
        const Rigid3d camera_from_marker = cameras[o.camera] * scene.room_from_marker[o.marker];
        const Eigen::Vector3d normal = camera_from_marker.rotation * Eigen::Vector3d::UnitZ();
        const double z_true = normal.dot(camera_from_marker.translation) / normal.dot(ray);
        const double e = 1000 * (c.TrueDepth(z_true * 1.006, x, y) - z_true);
        sum += e * e;
        ++n;
      }
    }
    return std::sqrt(sum / std::max(1, n));
  };
  DepthCheckInput input;
  input.intrinsics = &K;
  input.marker_size_m = scene.side;
  input.plane_support_m = 0;  // the markers' own readings only
  const BaOptions options;

  const BaProblem scaled = with_depth(0.006, -1, 1, 21);
  ASSERT_GE(scaled.marker_observations.size(), 12u);
  const DepthCheckResult found = CheckDepthAgainstColourGeometry(scaled, options, input);
  std::printf("depth left: %.2f mm RMS before, %.2f after (%s)\n",
              left_mm(scaled, DepthCorrection()), left_mm(scaled, found.fit.correction),
              found.message.c_str());
  EXPECT_TRUE(found.fit.applied) << found.message;
  EXPECT_GT(left_mm(scaled, DepthCorrection()), 8.0);
  EXPECT_LT(left_mm(scaled, found.fit.correction), 0.4 * left_mm(scaled, DepthCorrection()));
  EXPECT_EQ(found.readings_left_out, 0);

  const BaProblem one_gross = with_depth(0.006, 3, 1.5, 21);
  const DepthCheckResult left_out = CheckDepthAgainstColourGeometry(one_gross, options, input);
  EXPECT_EQ(left_out.readings_left_out, 25);
  EXPECT_NE(left_out.message.find("25 reading(s) inside markers left out"), std::string::npos)
      << left_out.message;
  EXPECT_TRUE(left_out.fit.applied) << left_out.message;
  EXPECT_NEAR(left_out.fit.correction.ErrorAt1mCentreMm(), found.fit.correction.ErrorAt1mCentreMm(),
              0.5)
      << "the gross readings do not move the correction";

  // A third of the views off every which way: not a scale, left out.
  const BaProblem third_gross = with_depth(0.006, -3, 1.5, 21);
  const DepthCheckResult third = CheckDepthAgainstColourGeometry(third_gross, options, input);
  EXPECT_GT(third.readings_left_out, 0) << third.message;
  EXPECT_TRUE(third.fit.applied) << third.message;
  EXPECT_NEAR(third.fit.correction.ErrorAt1mCentreMm(), found.fit.correction.ErrorAt1mCentreMm(),
              0.5)
      << third.message;

  const BaProblem all_gross = with_depth(0.006, -2, 1.5, 21);
  const DepthCheckResult wrong_scale = CheckDepthAgainstColourGeometry(all_gross, options, input);
  EXPECT_EQ(wrong_scale.readings_left_out, 0);
  EXPECT_EQ(wrong_scale.message.find("left out"), std::string::npos) << wrong_scale.message;
  EXPECT_GT(wrong_scale.fit.normalised_rms_before, 10.0) << "the check sees depth 50 % off";
}

}  // namespace
}  // namespace arpos
