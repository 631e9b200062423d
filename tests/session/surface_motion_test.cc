// Which parts of the surface moved during the scan (body_model/surface_motion.h),
// on a synthetic torso: the front half of a cylinder seen by noisy frames,
// each with its own small registration error, part of it breathing.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <set>

#include "body_model/surface_motion.h"
#include "geometry/so3.h"
#include "registration/kdtree.h"
#include "util/check.h"

namespace arpos {
namespace {

constexpr double kRadius = 0.15;

// The front (model -y) half of a cylinder about the z axis, z in [-0.5, 0.5],
// with outward normals, about `spacing` apart.
PointCloud FrontHalfCylinder(double spacing) {
  PointCloud cloud;
  const int around = static_cast<int>(M_PI * kRadius / spacing);
  for (double z = -0.5; z <= 0.5; z += spacing) {
    for (int k = 0; k <= around; ++k) {
      const double theta = M_PI * k / around;  // 0..pi: from +x over -y to -x
      const Eigen::Vector3d n(std::cos(theta), -std::sin(theta), 0);
      cloud.Add(kRadius * n + Eigen::Vector3d(0, 0, z), n);
    }
  }
  return cloud;
}

// The breathing region: the front of the "chest and abdomen".
bool InMovingRegion(const Eigen::Vector3d& p) { return p.y() < -0.08 && p.z() > -0.1 && p.z() < 0.3; }
// Clearly still: a patch away from the moving region's edges.
bool ClearlyStill(const Eigen::Vector3d& p) { return p.z() < -0.2 || p.z() > 0.4 || p.y() > -0.03; }
// Clearly moving: inside, a patch away from the edges.
bool ClearlyMoving(const Eigen::Vector3d& p) { return p.y() < -0.11 && p.z() > -0.05 && p.z() < 0.25; }

struct Scan {
  std::vector<PointCloud> clouds;
  std::vector<SurfaceMotionFrame> frames;
};

// `frames` frames of the surface with 1.5 mm depth noise, each seeing 70 %
// of it, each placed with a 0.5 mm / 0.05 deg registration error; the
// moving region rises along its normal by amplitude x cos^4 of a breathing
// phase (long dwell at exhale, as the simulator and real breathing do).
Scan MakeScan(double amplitude_m, int frames, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0, 0.0015);
  std::normal_distribution<double> error(0, 1);
  std::uniform_real_distribution<double> uniform(0, 1);
  const PointCloud surface = FrontHalfCylinder(0.004);
  Scan scan;
  scan.clouds.resize(frames);
  for (int f = 0; f < frames; ++f) {
    const double c = std::cos(M_PI * (0.37 * f + 0.2));  // phases spread over the cycle
    const double rise = amplitude_m * c * c * c * c;
    const Eigen::Vector3d rotation_vector = RadFromDeg(0.05) * Eigen::Vector3d(error(rng), error(rng), error(rng));
    const Rigid3d registration_error(
        Eigen::Quaterniond(Eigen::AngleAxisd(rotation_vector.norm(), rotation_vector.normalized())),
        0.0005 * Eigen::Vector3d(error(rng), error(rng), error(rng)));
    // The room is the model frame here (model_from_room = identity); the
    // frame's points are given in its "camera" frame, which is where the
    // (wrong) pose puts them back.
    const Rigid3d room_from_camera = registration_error;
    PointCloud& cloud = scan.clouds[f];
    for (size_t i = 0; i < surface.size(); ++i) {
      if (uniform(rng) > 0.7) continue;
      const Eigen::Vector3d p = surface.point3(i), n = surface.normal3(i);
      const Eigen::Vector3d seen = p + n * ((InMovingRegion(p) ? rise : 0) + noise(rng));
      cloud.Add(room_from_camera.Inverse() * seen);
    }
    scan.frames.push_back({nullptr, room_from_camera});
  }
  for (int f = 0; f < frames; ++f) scan.frames[f].cloud_in_camera = &scan.clouds[f];
  return scan;
}

struct Counts {
  int moving_flagged = 0, moving_total = 0, still_flagged = 0, still_total = 0;
};

Counts CountPatches(const SurfaceMotion& motion, const PointCloud& surface) {
  Counts c;
  std::set<uint64_t> seen;
  for (size_t i = 0; i < surface.size(); ++i) {
    const Eigen::Vector3d p = surface.point3(i);
    const uint64_t key = SurfacePatchKey(p, motion.patch_m);
    if (!seen.insert(key).second || !motion.patch_by_key.count(key)) continue;
    // Judge a patch by its centre's neighbourhood: every point of it must
    // be clearly on one side.
    bool all_moving = true, all_still = true;
    for (size_t j = 0; j < surface.size(); ++j) {
      if (SurfacePatchKey(surface.point3(j), motion.patch_m) != key) continue;
      all_moving = all_moving && ClearlyMoving(surface.point3(j));
      all_still = all_still && ClearlyStill(surface.point3(j));
    }
    const bool flagged = motion.patch_by_key.at(key).moving;
    if (all_moving) c.moving_total++, c.moving_flagged += flagged;
    if (all_still) c.still_total++, c.still_flagged += flagged;
  }
  return c;
}

// The reference surface (finely sampled) and its tree, once.
const PointCloud& Model() {
  static const PointCloud model = FrontHalfCylinder(0.002);
  return model;
}
const KdTree& ModelTree() {
  static const KdTree tree(Model());
  return tree;
}

// MakeScan, measured against the model at its true pose.
SurfaceMotion Measure(double amplitude_m, int frames, uint32_t seed) {
  const Scan scan = MakeScan(amplitude_m, frames, seed);
  return MeasureSurfaceMotion(scan.frames, Model(), ModelTree(), Rigid3d::Identity());
}

TEST(SurfaceMotion, TheBreathingPartIsFoundAndTheStillPartsAreNot) {
  for (const uint32_t seed : {1u, 2u, 3u}) {
    const SurfaceMotion motion = Measure(0.004, 20, seed);
    ASSERT_TRUE(motion.measured) << motion.Describe();
    EXPECT_EQ(motion.frames, 20);
    const Counts c = CountPatches(motion, Model());
    ASSERT_GT(c.moving_total, 5);
    ASSERT_GT(c.still_total, 20);
    EXPECT_GE(c.moving_flagged, 0.9 * c.moving_total) << "seed " << seed << ": " << motion.Describe();
    EXPECT_LE(c.still_flagged, 0.05 * c.still_total) << "seed " << seed << ": " << motion.Describe();
    // A 4 mm rise seen at random phases: peak to peak close to it.
    EXPECT_GT(motion.moving_peak_to_peak_m, 0.0025);
    EXPECT_LT(motion.moving_peak_to_peak_m, 0.007);
    EXPECT_NE(motion.Describe().find("moved during the scan"), std::string::npos);
  }
}

TEST(SurfaceMotion, AStillSurfaceHasNoMovingPart) {
  const SurfaceMotion motion = Measure(0, 20, 4);
  ASSERT_TRUE(motion.measured);
  EXPECT_LE(motion.moving_patches, 0.03 * motion.patches) << motion.Describe();
  // Nothing is what the frames' own errors and noise give: well under a millimetre.
  EXPECT_LT(motion.median_spread_m, 0.0006);
}

TEST(SurfaceMotion, TooFewFramesTellNothing) {
  const SurfaceMotion motion = Measure(0.004, 3, 5);
  EXPECT_FALSE(motion.measured);
  EXPECT_EQ(motion.moving_patches, 0);
  EXPECT_FALSE(motion.IsMoving(Eigen::Vector3d(0, -kRadius, 0.1)));
  EXPECT_NE(motion.Describe().find("not measured"), std::string::npos);
}

TEST(SurfaceMotion, ASurfaceWithoutNormalsIsACallersMistake) {
  const PointCloud model(std::vector<Eigen::Vector3d>{{0, 0, 0}, {0.01, 0, 0}});
  const KdTree tree(model);
  EXPECT_THROW(MeasureSurfaceMotion({}, model, tree, Rigid3d::Identity()), Error);
}

}  // namespace
}  // namespace arpos
