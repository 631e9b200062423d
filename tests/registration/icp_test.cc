// GICP and point-to-plane ICP recover known random transforms (forward and
// inverse), do not stop early, are thread-count deterministic, resist
// outliers with a robust kernel, and report degenerate geometry.
#include <gtest/gtest.h>

#include <filesystem>
#include <random>

#include <opencv2/imgcodecs.hpp>

#include "geometry/so3.h"
#include "registration/kdtree.h"
#include "registration/mesh_cloud.h"
#include "registration/pcl_gicp.h"
#include "registration/preprocess.h"
#include "registration/registration.h"
#include "registration/synthetic.h"
#include "util/check.h"

namespace arpos {
namespace {

using testing::RotationErrorRad;
using testing::TranslationError;

// Two independent noisy samplings of the MakeHuman body (model frame), 1 cm
// voxels, with covariances and normals: the same surface, different points.
struct BodyPair {
  PointCloud a, b;
};

const BodyPair& Bodies() {
  static const BodyPair* pair = [] {
    auto make = [](uint64_t seed) {
      PointCloud c = SampleMeshSurface(testing::BodyMesh(), 0.004, seed);
      testing::AddNoise(&c, 0.0005, seed + 100);
      c = VoxelDownsample(c, 0.01);
      const KdTree tree(c);
      NormalOptions options;
      EstimateNormalsAndCovariances(&c, tree, options);  // normals keep the mesh's sign
      return c;
    };
    return new BodyPair{make(1), make(2)};
  }();
  return *pair;
}

// Stated tolerances: two samplings of one surface with 0.5 mm noise and 1 cm
// voxels register to well under a tenth of a millimetre.
constexpr double kTolM = 1e-4;
constexpr double kTolRad = 2e-4;  // 0.011 deg

TEST(Gicp, RecoversRandomTransformsForwardAndInverse) {
  const BodyPair& bodies = Bodies();
  std::mt19937_64 rng(42);
  RegistrationOptions options;
  options.max_correspondence_distance_m = 0.15;
  const KdTree tree_a(bodies.a);
  for (int trial = 0; trial < 6; ++trial) {
    const Rigid3d truth = testing::RandomPose(rng, 0.05, RadFromDeg(10));  // a_from_b
    // Forward: source b moved by truth^-1, so target_from_source = truth.
    const PointCloud source = bodies.b.Transformed(truth.Inverse());
    const RegistrationResult forward = AlignGicp(source, bodies.a, tree_a, Rigid3d(), options);
    EXPECT_TRUE(forward.converged) << forward.message;
    EXPECT_LT(TranslationError(truth, forward.target_from_source), kTolM) << trial;
    EXPECT_LT(RotationErrorRad(truth, forward.target_from_source), kTolRad) << trial;
    EXPECT_GT(forward.fitness, 0.95);
    EXPECT_LT(forward.rmse_m, 1e-3);
    // Inverse: align the fixed cloud onto the moved one.
    const KdTree tree_source(source);
    const RegistrationResult inverse = AlignGicp(bodies.a, source, tree_source, Rigid3d(), options);
    EXPECT_TRUE(inverse.converged) << inverse.message;
    EXPECT_LT(TranslationError(truth.Inverse(), inverse.target_from_source), kTolM) << trial;
    EXPECT_LT(RotationErrorRad(truth.Inverse(), inverse.target_from_source), kTolRad) << trial;
  }
}

TEST(PointToPlane, RecoversRandomTransformsForwardAndInverse) {
  const BodyPair& bodies = Bodies();
  std::mt19937_64 rng(43);
  RegistrationOptions options;
  options.max_correspondence_distance_m = 0.15;
  const KdTree tree_a(bodies.a);
  for (int trial = 0; trial < 6; ++trial) {
    const Rigid3d truth = testing::RandomPose(rng, 0.05, RadFromDeg(10));
    const PointCloud source = bodies.b.Transformed(truth.Inverse());
    const RegistrationResult forward =
        AlignPointToPlane(source, bodies.a, tree_a, Rigid3d(), options);
    EXPECT_TRUE(forward.converged) << forward.message;
    EXPECT_LT(TranslationError(truth, forward.target_from_source), kTolM) << trial;
    EXPECT_LT(RotationErrorRad(truth, forward.target_from_source), kTolRad) << trial;
    const KdTree tree_source(source);
    const RegistrationResult inverse =
        AlignPointToPlane(bodies.a, source, tree_source, Rigid3d(), options);
    EXPECT_TRUE(inverse.converged) << inverse.message;
    EXPECT_LT(TranslationError(truth.Inverse(), inverse.target_from_source), kTolM) << trial;
    EXPECT_LT(RotationErrorRad(truth.Inverse(), inverse.target_from_source), kTolRad) << trial;
  }
}

// A depth view (camera frame) against the model: the real use. Exact renders
// plus 1 mm depth noise; 7 mm voxels.
TEST(PointToPlane, DepthViewToModelWithinHalfAMillimetre) {
  const CameraIntrinsics k = testing::TestIntrinsics();
  const Rigid3d model_from_camera = testing::LookAt(
      Eigen::Vector3d(0.1, 0.15, 1.1), Eigen::Vector3d(0, 0.1, 0.1), Eigen::Vector3d(0, 1, 0));
  cv::Mat depth = testing::RenderDepth(testing::BodyMesh(), k, model_from_camera.Inverse());
  PointCloud view = DepthToCloud(depth, 1.0, k);
  testing::AddNoise(&view, 0.001, 5);
  view = VoxelDownsample(view, 0.007);
  const PointCloud& model = Bodies().a;
  const KdTree model_tree(model);
  std::mt19937_64 rng(44);
  RegistrationOptions options;
  options.max_correspondence_distance_m = 0.05;
  for (int trial = 0; trial < 4; ++trial) {
    const Rigid3d start = testing::RandomPose(rng, 0.02, RadFromDeg(3)) * model_from_camera;
    const RegistrationResult r = AlignPointToPlane(view, model, model_tree, start, options);
    EXPECT_TRUE(r.converged) << r.message;
    // Error at the model origin (model_from_camera maps camera -> model).
    const Rigid3d error = model_from_camera * r.target_from_source.Inverse();
    EXPECT_LT(error.translation.norm(), 5e-4) << trial;
    EXPECT_LT(RotationAngleRad(error.rotation), RadFromDeg(0.05)) << trial;
  }
}

// PITFALLS.md: PCL's GICP stopped after 3-4 iterations at millimetres with its
// default tolerances. Ours must reach the same pose with its defaults as with
// absurdly tight settings, from a start several centimetres away.
// Real data: three consecutive Kinect v1 frames (../shared/data/pcl_kinect,
// about 0.26 s apart, hand-held: a few cm of motion; no ground truth). Our
// GICP and PCL's (tuned, PITFALLS.md) agree on each pair, and the pairs
// compose: (1 -> 2) * (0 -> 1) equals 0 -> 2. Measured (1 cm voxels): the
// camera moved 7.8, 4.8 and 12.9 mm; ours and PCL's 0.17, 0.20 and 0.80 mm
// (0.009-0.038 deg) apart; the loop closes within 0.53 mm / 0.019 deg.
TEST(Gicp, RealKinectFramesAgreeWithPclAndCompose) {
  const std::filesystem::path dir =
      std::filesystem::path(ARPOS_SHARED_DATA_DIR) / "pcl_kinect" / "grabber_sequences" / "tiff";
  const char* names[] = {"frame_20121214T142255.814212_depth.tiff", "frame_20121214T142256.068683_depth.tiff",
                         "frame_20121214T142256.332395_depth.tiff"};
  CameraIntrinsics K;  // the sequence's xml: fx = fy = 525, cx = 320, cy = 240, millimetres
  K.width = 640;
  K.height = 480;
  K.fx = K.fy = 525;
  K.cx = 320;
  K.cy = 240;
  K.depth_scale = 1000;
  DepthCloudOptions depth_options;
  depth_options.stride_px = 2;
  depth_options.max_depth_m = 3.0;
  NormalOptions normal_options;
  std::vector<PointCloud> clouds;
  for (const char* name : names) {
    const cv::Mat depth = cv::imread((dir / name).string(), cv::IMREAD_UNCHANGED);
    ASSERT_EQ(depth.type(), CV_16UC1) << dir / name;
    PointCloud cloud = VoxelDownsample(DepthToCloud(depth, K.depth_scale, K, depth_options), 0.01);
    ASSERT_GT(cloud.size(), 2000u);
    const KdTree tree(cloud);
    EstimateCovariances(&cloud, tree, normal_options);
    clouds.push_back(std::move(cloud));
  }
  RegistrationOptions options;
  options.max_correspondence_distance_m = 0.05;
  PclGicpOptions pcl_options;
  pcl_options.max_correspondence_distance_m = 0.05;
  auto align = [&](int s, int t) {
    const KdTree target_tree(clouds[t]);
    const RegistrationResult ours = AlignGicp(clouds[s], clouds[t], target_tree, Rigid3d::Identity(), options);
    EXPECT_TRUE(ours.converged) << s << " -> " << t;
    EXPECT_GT(ours.fitness, 0.8) << s << " -> " << t;
    const RegistrationResult pcl = AlignGicpPcl(clouds[s], clouds[t], Rigid3d::Identity(), pcl_options);
    const Rigid3d diff = pcl.target_from_source.Inverse() * ours.target_from_source;
    EXPECT_LT(1000 * diff.translation.norm(), 1.0) << s << " -> " << t << ": ours and PCL's disagree";
    EXPECT_LT(DegFromRad(diff.RotationVector().norm()), 0.1) << s << " -> " << t;
    return ours.target_from_source;
  };
  const Rigid3d t01 = align(0, 1), t12 = align(1, 2), t02 = align(0, 2);
  // A hand-held camera in 0.26 s: moved, but by centimetres, not metres.
  EXPECT_GT(1000 * t01.translation.norm(), 2.0);
  EXPECT_LT(t01.translation.norm(), 0.15);
  const Rigid3d loop = t02.Inverse() * (t12 * t01);
  EXPECT_LT(1000 * loop.translation.norm(), 2.0);
  EXPECT_LT(DegFromRad(loop.RotationVector().norm()), 0.2);
}

TEST(Gicp, DefaultsDoNotStopEarly) {
  const BodyPair& bodies = Bodies();
  std::mt19937_64 rng(45);
  const KdTree tree_a(bodies.a);
  for (int trial = 0; trial < 4; ++trial) {
    const Rigid3d truth = testing::RandomPose(rng, 0.04, RadFromDeg(6));
    const PointCloud source = bodies.b.Transformed(truth.Inverse());
    RegistrationOptions defaults;
    defaults.max_correspondence_distance_m = 0.15;  // wide enough for the start
    RegistrationOptions tight = defaults;
    tight.translation_tolerance_m = 1e-12;
    tight.rotation_tolerance_rad = 1e-12;
    tight.max_iterations = 200;
    const RegistrationResult d = AlignGicp(source, bodies.a, tree_a, Rigid3d(), defaults);
    const RegistrationResult t = AlignGicp(source, bodies.a, tree_a, Rigid3d(), tight);
    EXPECT_TRUE(d.converged);
    EXPECT_GE(d.iterations, 3);
    EXPECT_LT(TranslationError(t.target_from_source, d.target_from_source), 1e-5);
    EXPECT_LT(RotationErrorRad(t.target_from_source, d.target_from_source), 1e-5);
  }
  // And "converged" is never claimed for a run cut short.
  RegistrationOptions one;
  one.max_correspondence_distance_m = 0.15;
  one.max_iterations = 1;
  const Rigid3d far = Rigid3d::FromRotationVector(Eigen::Vector3d(0, 0, 0.1),
                                                  Eigen::Vector3d(0.03, 0, 0));
  const RegistrationResult r = AlignGicp(bodies.b.Transformed(far), bodies.a, tree_a, Rigid3d(), one);
  EXPECT_FALSE(r.converged);
  EXPECT_EQ(r.iterations, 1);
}

TEST(Gicp, LevenbergMarquardtAgreesWithGaussNewton) {
  const BodyPair& bodies = Bodies();
  const Rigid3d truth = Rigid3d::FromRotationVector(Eigen::Vector3d(0.05, -0.1, 0.08),
                                                    Eigen::Vector3d(0.02, -0.03, 0.01));
  const PointCloud source = bodies.b.Transformed(truth.Inverse());
  RegistrationOptions options;
  options.max_correspondence_distance_m = 0.15;
  options.levenberg_marquardt = true;
  const RegistrationResult r = AlignGicp(source, bodies.a, Rigid3d(), options);
  EXPECT_TRUE(r.converged) << r.message;
  EXPECT_LT(TranslationError(truth, r.target_from_source), kTolM);
  EXPECT_LT(RotationErrorRad(truth, r.target_from_source), kTolRad);
}

TEST(Gicp, ResultIsIndependentOfThreadCount) {
  const BodyPair& bodies = Bodies();
  const Rigid3d truth = Rigid3d::FromRotationVector(Eigen::Vector3d(0.02, 0.03, -0.05),
                                                    Eigen::Vector3d(0.01, 0.02, -0.01));
  const PointCloud source = bodies.b.Transformed(truth.Inverse());
  const KdTree tree(bodies.a);
  RegistrationOptions options;
  options.max_correspondence_distance_m = 0.1;
  options.num_threads = 1;
  const RegistrationResult one = AlignGicp(source, bodies.a, tree, Rigid3d(), options);
  options.num_threads = 2;
  const RegistrationResult two = AlignGicp(source, bodies.a, tree, Rigid3d(), options);
  options.num_threads = 3;
  const RegistrationResult three = AlignGicp(source, bodies.a, tree, Rigid3d(), options);
  EXPECT_EQ(one.target_from_source.ToMatrix(), two.target_from_source.ToMatrix());
  EXPECT_EQ(one.target_from_source.ToMatrix(), three.target_from_source.ToMatrix());
  EXPECT_EQ(one.information, two.information);
  EXPECT_EQ(one.iterations, three.iterations);
}

TEST(Gicp, RobustKernelResistsOutliers) {
  const BodyPair& bodies = Bodies();
  const Rigid3d truth = Rigid3d::FromRotationVector(Eigen::Vector3d(0.01, -0.02, 0.03),
                                                    Eigen::Vector3d(0.01, 0.0, -0.01));
  PointCloud source = bodies.b;
  source.covs.clear();
  source.normals.clear();
  // 30 % clutter within 4 cm of the surface (a sheet, a hand, noise).
  std::mt19937_64 rng(46);
  std::uniform_int_distribution<size_t> pick(0, source.size() - 1);
  std::normal_distribution<double> offset(0.0, 0.02);
  const size_t n = source.size();
  for (size_t i = 0; i < n * 3 / 10; ++i) {
    source.Add(source.point3(pick(rng)) + Eigen::Vector3d(offset(rng), offset(rng), offset(rng)));
  }
  source.Transform(truth.Inverse());
  RegistrationOptions options;
  options.max_correspondence_distance_m = 0.05;
  const RegistrationResult plain = AlignGicp(source, bodies.a, Rigid3d(), options);
  options.robust_kernel = RobustKernel::kTukey;
  options.robust_scale_m = 0.005;
  const RegistrationResult robust = AlignGicp(source, bodies.a, Rigid3d(), options);
  EXPECT_TRUE(robust.converged) << robust.message;
  EXPECT_LT(TranslationError(truth, robust.target_from_source), 3e-4);
  EXPECT_LT(RotationErrorRad(truth, robust.target_from_source), RadFromDeg(0.03));
  EXPECT_LE(TranslationError(truth, robust.target_from_source),
            TranslationError(truth, plain.target_from_source));
}

TEST(Registration, RejectsBadOptionsAndMissingAttributes) {
  RegistrationOptions bad;
  bad.max_correspondence_distance_m = 0;
  EXPECT_FALSE(bad.Validate().empty());
  const PointCloud& a = Bodies().a;
  EXPECT_THROW(AlignGicp(a, a, Rigid3d(), bad), Error);
  PointCloud no_covs = a;
  no_covs.covs.clear();
  const KdTree tree(no_covs);
  EXPECT_THROW(AlignGicp(a, no_covs, tree, Rigid3d(), {}), Error);
  // Expected failures are data: nothing to match.
  PointCloud far = a.Transformed(Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(5, 0, 0)));
  const RegistrationResult r = AlignGicp(far, a, Rigid3d(), {});
  EXPECT_FALSE(r.converged);
  EXPECT_EQ(r.num_inliers, 0);
  EXPECT_FALSE(r.message.empty());
}

// Surfaces that slide or spin on themselves have a near-zero eigenvalue in
// the scaled Hessian; the body does not.
double ConditioningRatio(const TriangleMesh& mesh, uint64_t seed) {
  PointCloud target = SampleMeshSurface(mesh, 0.006, seed);
  PointCloud source = SampleMeshSurface(mesh, 0.006, seed + 1);
  const KdTree tree(target);
  const RegistrationResult r = AlignPointToPlane(source, target, tree, Rigid3d(), {});
  return AnalyseConditioning(r, source).min_max_ratio;
}

TEST(Conditioning, DegenerateShapesAreFlagged) {
  const double plane = ConditioningRatio(testing::MakePlane(0.6), 1);
  const double sphere =
      ConditioningRatio(testing::MakeEllipsoid(Eigen::Vector3d(0.2, 0.2, 0.2), 64, 128), 2);
  const double cylinder = ConditioningRatio(testing::MakeCylinder(0.15, 0.6), 3);
  const double ellipsoid =
      ConditioningRatio(testing::MakeEllipsoid(Eigen::Vector3d(0.3, 0.2, 0.12)), 4);
  PointCloud body_target = Bodies().a;
  const KdTree tree(body_target);
  const RegistrationResult r = AlignPointToPlane(Bodies().b, body_target, tree, Rigid3d(), {});
  const double body = AnalyseConditioning(r, Bodies().b).min_max_ratio;
  // Global registration's default threshold (min_conditioning) is 1e-2.
  EXPECT_LT(plane, 2e-3);
  EXPECT_LT(sphere, 2e-3);
  EXPECT_LT(cylinder, 2e-3);
  EXPECT_GT(ellipsoid, 3e-2);
  EXPECT_GT(body, 3e-2);
  RecordProperty("ratios", std::to_string(plane) + " " + std::to_string(sphere) + " " +
                               std::to_string(cylinder) + " " + std::to_string(ellipsoid) + " " +
                               std::to_string(body));
}

}  // namespace
}  // namespace arpos
