// Global registration: the right pose on the (non-symmetric) body from
// arbitrary scene placements; AMBIGUOUS, never a confident answer, on
// symmetric or featureless surfaces.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "geometry/so3.h"
#include "registration/global_registration.h"
#include "registration/mesh_cloud.h"
#include "registration/preprocess.h"
#include "registration/synthetic.h"
#include "util/check.h"

namespace arpos {
namespace {

using testing::RotationErrorRad;
using testing::TranslationError;

// A depth view of `mesh` from a camera ~1 m in front of its +z side, 1 mm
// depth noise, normals towards the camera, then moved into an arbitrary scene
// frame. Returns the cloud and the exact scene_from_model.
struct View {
  PointCloud scene;
  Rigid3d scene_from_model;
};

View MakeView(const TriangleMesh& mesh, uint64_t seed, double max_angle_rad = M_PI) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  const Eigen::Vector3d eye(0.15 * u(rng), 0.3 * u(rng), 1.0 + 0.1 * u(rng));
  const Rigid3d model_from_camera =
      testing::LookAt(eye, Eigen::Vector3d(0.05 * u(rng), 0.2 * u(rng), 0.0), Eigen::Vector3d(0, 1, 0));
  const CameraIntrinsics k = testing::TestIntrinsics();
  PointCloud view = DepthToCloud(testing::RenderDepth(mesh, k, model_from_camera.Inverse()), 1.0, k);
  testing::AddNoise(&view, 0.001, seed);
  view = VoxelDownsample(view, 0.004);
  const KdTree tree(view);
  EstimateNormals(&view, tree);  // towards the camera at the origin
  const Rigid3d scene_from_camera = testing::RandomPose(rng, 0.5, max_angle_rad);
  View v;
  v.scene = view.Transformed(scene_from_camera);
  v.scene_from_model = scene_from_camera * model_from_camera.Inverse();
  return v;
}

const GlobalRegistrationModel& BodyModel() {
  static const GlobalRegistrationModel* model = new GlobalRegistrationModel(
      SampleMeshSurface(testing::BodyMesh(), 0.004, 1), GlobalRegistrationOptions());
  return *model;
}

TEST(GlobalRegistration, FindsTheBodyFromArbitraryPlacementsDeterministically) {
  for (uint64_t seed : {11, 12, 13}) {
    const View view = MakeView(testing::BodyMesh(), seed);
    GlobalRegistrationOptions options;
    options.seed = seed;
    const GlobalRegistrationResult r = AlignGlobal(BodyModel(), view.scene, options);
    EXPECT_EQ(r.status, GlobalRegistrationStatus::kOk) << r.reason;
    EXPECT_LT(TranslationError(view.scene_from_model, r.target_from_source), 1e-3) << seed;
    EXPECT_LT(RotationErrorRad(view.scene_from_model, r.target_from_source), RadFromDeg(0.1))
        << seed;
    EXPECT_GT(r.fitness, 0.9);
    EXPECT_GT(r.conditioning.min_max_ratio, options.min_conditioning);
    if (seed == 11) {
      // The same answer, bit for bit, on one thread.
      options.num_threads = 1;
      const GlobalRegistrationResult one = AlignGlobal(BodyModel(), view.scene, options);
      EXPECT_EQ(one.status, r.status);
      EXPECT_EQ(one.target_from_source.ToMatrix(), r.target_from_source.ToMatrix());
    }
  }
}

TEST(GlobalRegistration, PriorRestrictsTheSearch) {
  const View view = MakeView(testing::BodyMesh(), 31);
  GlobalRegistrationOptions options;
  // A prior 3 cm / 5 deg off, with a search radius that keeps the truth in.
  options.prior_target_from_source =
      view.scene_from_model *
      Rigid3d::FromRotationVector(Eigen::Vector3d(0, 0, RadFromDeg(5)), Eigen::Vector3d(0.03, 0, 0));
  options.max_prior_translation_m = 0.15;
  options.max_prior_rotation_rad = RadFromDeg(20);
  const GlobalRegistrationResult r = AlignGlobal(BodyModel(), view.scene, options);
  EXPECT_EQ(r.status, GlobalRegistrationStatus::kOk) << r.reason;
  EXPECT_LT(TranslationError(view.scene_from_model, r.target_from_source), 1e-3);
  for (const PoseHypothesis& h : r.hypotheses) {
    EXPECT_LT((h.target_from_source.translation - options.prior_target_from_source->translation)
                  .norm(),
              0.15);
  }
}

TEST(GlobalRegistration, SphereIsAmbiguous) {
  const TriangleMesh sphere = testing::MakeEllipsoid(Eigen::Vector3d(0.2, 0.2, 0.2), 64, 128);
  const View view = MakeView(sphere, 41);
  const GlobalRegistrationResult r =
      AlignGlobal(SampleMeshSurface(sphere, 0.004, 2), view.scene, GlobalRegistrationOptions());
  EXPECT_EQ(r.status, GlobalRegistrationStatus::kAmbiguous) << r.reason;
  // Even with a prior the spin about the centre stays undetermined.
  GlobalRegistrationOptions with_prior;
  with_prior.prior_target_from_source = view.scene_from_model;
  const GlobalRegistrationResult p =
      AlignGlobal(SampleMeshSurface(sphere, 0.004, 2), view.scene, with_prior);
  EXPECT_EQ(p.status, GlobalRegistrationStatus::kAmbiguous) << p.reason;
  EXPECT_LT(p.conditioning.min_max_ratio, with_prior.min_conditioning);
}

TEST(GlobalRegistration, CylinderIsAmbiguous) {
  const TriangleMesh cylinder = testing::MakeCylinder(0.12, 0.5);
  const View view = MakeView(cylinder, 51);
  const GlobalRegistrationResult r =
      AlignGlobal(SampleMeshSurface(cylinder, 0.006, 3), view.scene, GlobalRegistrationOptions());
  EXPECT_EQ(r.status, GlobalRegistrationStatus::kAmbiguous) << r.reason;
}

TEST(GlobalRegistration, PlaneIsAmbiguous) {
  const TriangleMesh plane = testing::MakePlane(0.8);
  const View view = MakeView(plane, 61);
  const GlobalRegistrationResult r =
      AlignGlobal(SampleMeshSurface(plane, 0.004, 4), view.scene, GlobalRegistrationOptions());
  EXPECT_EQ(r.status, GlobalRegistrationStatus::kAmbiguous) << r.reason;
}

TEST(GlobalRegistration, RejectsBadOptions) {
  GlobalRegistrationOptions bad;
  bad.feature_radius_m = bad.voxel_m / 2;
  EXPECT_FALSE(bad.Validate().empty());
  const PointCloud small = SampleMeshSurface(testing::MakeEllipsoid(Eigen::Vector3d(0.2, 0.1, 0.1)), 0.01);
  EXPECT_THROW(AlignGlobal(small, small, bad), Error);
  const GlobalRegistrationModel model(small, GlobalRegistrationOptions());
  GlobalRegistrationOptions other;
  other.voxel_m = 0.02;
  EXPECT_FALSE(model.Matches(other));
  EXPECT_THROW(AlignGlobal(model, small, other), Error);
  const GlobalRegistrationResult empty = AlignGlobal(model, PointCloud(), {});
  EXPECT_EQ(empty.status, GlobalRegistrationStatus::kFailed);
  EXPECT_FALSE(empty.reason.empty());
}

}  // namespace
}  // namespace arpos
