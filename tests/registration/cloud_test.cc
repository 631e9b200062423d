// Point clouds, kd-tree, downsampling, normals, covariances, cropping and
// mesh sampling/distances, each against an independent brute-force answer.
#include <gtest/gtest.h>

#include <algorithm>
#include <limits>
#include <random>

#include "registration/kdtree.h"
#include "registration/mesh_cloud.h"
#include "registration/point_cloud.h"
#include "registration/preprocess.h"
#include "registration/synthetic.h"
#include "util/check.h"

namespace arpos {
namespace {

PointCloud RandomCloud(size_t n, uint64_t seed, double extent = 1.0) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-extent, extent);
  PointCloud cloud;
  for (size_t i = 0; i < n; ++i) cloud.Add(Eigen::Vector3d(u(rng), u(rng), u(rng)));
  return cloud;
}

TEST(KdTree, MatchesBruteForce) {
  const PointCloud cloud = RandomCloud(5000, 1);
  const KdTree tree(cloud);
  ASSERT_EQ(tree.size(), cloud.size());
  const PointCloud queries = RandomCloud(200, 2, 1.2);
  for (size_t q = 0; q < queries.size(); ++q) {
    const Eigen::Vector4d& p = queries.points[q];
    std::vector<std::pair<double, size_t>> all;
    for (size_t i = 0; i < cloud.size(); ++i) {
      all.emplace_back((cloud.points[i] - p).squaredNorm(), i);
    }
    std::sort(all.begin(), all.end());
    size_t index;
    double sq;
    ASSERT_TRUE(tree.Nearest(p, &index, &sq));
    EXPECT_EQ(index, all[0].second);
    EXPECT_DOUBLE_EQ(sq, all[0].first);
    // Bounded search: nothing strictly inside a radius below the nearest.
    EXPECT_FALSE(tree.Nearest(p, &index, &sq, all[0].first * 0.999));

    size_t idx[20];
    double d[20];
    ASSERT_EQ(tree.Knn(p, 20, idx, d), 20u);
    for (int k = 0; k < 20; ++k) {
      EXPECT_EQ(idx[k], all[k].second) << "query " << q << " rank " << k;
      EXPECT_DOUBLE_EQ(d[k], all[k].first);
    }
    const double radius = std::sqrt(all[30].first);
    std::vector<size_t> in_radius;
    tree.RadiusSearch(p, radius, &in_radius);
    std::sort(in_radius.begin(), in_radius.end());
    std::vector<size_t> expected;
    for (const auto& [dist, i] : all) {
      if (dist <= radius * radius) expected.push_back(i);
    }
    std::sort(expected.begin(), expected.end());
    EXPECT_EQ(in_radius, expected);
  }
}

TEST(KdTree, EmptyAndDuplicatePoints) {
  const KdTree empty{PointCloud()};
  size_t index;
  double sq;
  EXPECT_FALSE(empty.Nearest(Eigen::Vector3d(0, 0, 0), &index, &sq));
  PointCloud same;
  for (int i = 0; i < 100; ++i) same.Add(Eigen::Vector3d(1, 2, 3));
  const KdTree tree(same);
  EXPECT_EQ(tree.Knn(Eigen::Vector3d(1, 2, 3), 10).size(), 10u);
  PointCloud bad = same;
  bad.points[5].y() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(KdTree{bad}, Error);
}

TEST(VoxelDownsample, CentroidPerVoxel) {
  PointCloud cloud;
  // Two points in voxel (0,0,0) and one in voxel (1,0,0) of 0.1 m; negative
  // coordinates fall into voxel -1.
  cloud.Add(Eigen::Vector3d(0.01, 0.02, 0.03), Eigen::Vector3d(0, 0, 1));
  cloud.Add(Eigen::Vector3d(0.03, 0.04, 0.05), Eigen::Vector3d(0, 1, 0));
  cloud.Add(Eigen::Vector3d(0.15, 0.0, 0.0), Eigen::Vector3d(1, 0, 0));
  cloud.Add(Eigen::Vector3d(-0.01, 0.0, 0.0), Eigen::Vector3d(1, 0, 0));
  const PointCloud down = VoxelDownsample(cloud, 0.1);
  ASSERT_EQ(down.size(), 3u);
  ASSERT_TRUE(down.has_normals());
  bool found_pair = false;
  for (size_t i = 0; i < down.size(); ++i) {
    if ((down.point3(i) - Eigen::Vector3d(0.02, 0.03, 0.04)).norm() < 1e-12) {
      found_pair = true;
      EXPECT_NEAR(down.normal3(i).norm(), 1.0, 1e-12);
      EXPECT_NEAR(down.normal3(i).y(), std::sqrt(0.5), 1e-12);
    }
  }
  EXPECT_TRUE(found_pair);
  // Deterministic and order-independent output.
  PointCloud reversed = cloud;
  std::reverse(reversed.points.begin(), reversed.points.end());
  std::reverse(reversed.normals.begin(), reversed.normals.end());
  const PointCloud down2 = VoxelDownsample(reversed, 0.1);
  ASSERT_EQ(down2.size(), down.size());
  for (size_t i = 0; i < down.size(); ++i) {
    EXPECT_LT((down.points[i] - down2.points[i]).norm(), 1e-15);
  }
}

TEST(Normals, SphereNormalsRadialAndTowardsViewpoint) {
  const TriangleMesh sphere = testing::MakeEllipsoid(Eigen::Vector3d(0.2, 0.2, 0.2));
  PointCloud cloud = SampleMeshSurface(sphere, 0.005, 3);
  cloud.normals.clear();
  const KdTree tree(cloud);
  NormalOptions options;
  options.viewpoint = Eigen::Vector3d(0, 0, 0);  // inside: normals must point inwards
  EstimateNormalsAndCovariances(&cloud, tree, options);
  ASSERT_TRUE(cloud.has_normals());
  ASSERT_TRUE(cloud.has_covs());
  double worst = 0;
  for (size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3d radial = -cloud.point3(i).normalized();
    worst = std::max(worst, std::acos(std::min(1.0, cloud.normal3(i).dot(radial))));
    // The covariance's smallest axis is the normal, with eigenvalue eps.
    const Eigen::Matrix3d c = cloud.covs[i].topLeftCorner<3, 3>();
    EXPECT_NEAR(cloud.normal3(i).dot(c * cloud.normal3(i)), options.covariance_epsilon, 1e-9);
    EXPECT_NEAR(c.trace(), 2.0 + options.covariance_epsilon, 1e-9);
  }
  EXPECT_LT(worst, 0.15) << "normal up to " << worst << " rad off radial";
  // Thread count does not change the result.
  PointCloud again = SampleMeshSurface(sphere, 0.005, 3);
  again.normals.clear();
  options.num_threads = 1;
  EstimateNormalsAndCovariances(&again, tree, options);
  for (size_t i = 0; i < cloud.size(); ++i) {
    ASSERT_EQ(cloud.normals[i], again.normals[i]);
  }
}

TEST(DepthToCloud, BackProjectsWithStrideRangeAndMask) {
  const CameraIntrinsics k = testing::TestIntrinsics();
  cv::Mat depth(k.height, k.width, CV_16UC1, cv::Scalar(5000));  // 1 m everywhere
  depth.at<uint16_t>(10, 20) = 25000;                            // 5 m: beyond range
  depth.at<uint16_t>(0, 0) = 0;
  DepthCloudOptions options;
  options.max_depth_m = 3;
  const PointCloud all = DepthToCloud(depth, 5000, k, options);
  EXPECT_EQ(all.size(), static_cast<size_t>(k.width * k.height - 2));
  // Pixel (u, v) = (319.5 + 54, 239.5 - 27) at 1 m -> x = 0.1, y = -0.05 (half pixels
  // are not pixel centres, so check a real one through Unproject).
  const Eigen::Vector3d p = k.Unproject(400, 100, 1.0);
  bool found = false;
  for (size_t i = 0; i < all.size(); ++i) found |= (all.point3(i) - p).norm() < 1e-12;
  EXPECT_TRUE(found);
  options.stride_px = 4;
  EXPECT_EQ(DepthToCloud(depth, 5000, k, options).size(),
            static_cast<size_t>((k.width / 4) * (k.height / 4) - 1));
  cv::Mat mask(k.height, k.width, CV_8UC1, cv::Scalar(0));
  mask(cv::Rect(100, 100, 10, 5)).setTo(255);
  options.stride_px = 1;
  EXPECT_EQ(DepthToCloud(depth, 5000, k, options, mask).size(), 50u);
  options.stride_px = 0;
  EXPECT_THROW(DepthToCloud(depth, 5000, k, options), Error);
}

TEST(Filters, BoxPlaneAndLargestCluster) {
  PointCloud cloud;
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> u(-0.5, 0.5);
  // A table plane z = 0 (800 points), a blob above it (400) and a far speck (20).
  for (int i = 0; i < 800; ++i) cloud.Add(Eigen::Vector3d(u(rng), u(rng), 0.0005 * u(rng)));
  for (int i = 0; i < 400; ++i) {
    cloud.Add(Eigen::Vector3d(0.1 * u(rng), 0.1 * u(rng), 0.1 + 0.05 * u(rng)));
  }
  for (int i = 0; i < 20; ++i) {
    cloud.Add(Eigen::Vector3d(0.3 + 0.01 * u(rng), 0.3 + 0.01 * u(rng), 0.3 + 0.01 * u(rng)));
  }
  PlaneFitOptions fit_options;
  fit_options.expected_normal = Eigen::Vector3d(0, 0, 1);
  const auto fit = FitPlaneRansac(cloud, fit_options);
  ASSERT_TRUE(fit.has_value());
  EXPECT_GT(fit->plane.normal.z(), 0.999);
  EXPECT_NEAR(fit->plane.offset_m, 0.0, 1e-3);
  EXPECT_GE(fit->num_inliers, 800);
  const PointCloud above = KeepAbovePlane(cloud, fit->plane, 0.02);
  EXPECT_EQ(above.size(), 420u);
  const PointCloud blob = LargestCluster(above, 0.03);
  EXPECT_EQ(blob.size(), 400u);
  OrientedBox box;
  box.frame_from_box = Rigid3d::FromRotationVector(Eigen::Vector3d(0, 0, 0.7),
                                                   Eigen::Vector3d(0.3, 0.3, 0.3));
  box.half_extents_m = Eigen::Vector3d(0.05, 0.05, 0.05);
  EXPECT_EQ(CropToBox(cloud, box).size(), 20u);
}

TEST(MeshCloud, SamplesLieOnTheSurfaceAndDistancesAreExact) {
  const TriangleMesh ellipsoid = testing::MakeEllipsoid(Eigen::Vector3d(0.3, 0.2, 0.15));
  const PointCloud samples = SampleMeshSurface(ellipsoid, 0.01, 9);
  EXPECT_NEAR(static_cast<double>(samples.size()), ellipsoid.SurfaceArea() / 1e-4,
              0.01 * samples.size());
  const MeshDistance distance(ellipsoid);
  for (size_t i = 0; i < samples.size(); i += 17) {
    EXPECT_LT(distance.Distance(samples.point3(i)), 1e-6);
    // Pushed out along the normal by 5 mm: 5 mm away (nearly flat locally).
    const Eigen::Vector3d out = samples.point3(i) + 0.005 * samples.normal3(i);
    EXPECT_NEAR(distance.Distance(out), 0.005, 2e-4);
  }
  // Against brute force over all faces.
  std::mt19937_64 rng(2);
  std::uniform_real_distribution<double> u(-0.4, 0.4);
  for (int q = 0; q < 100; ++q) {
    const Eigen::Vector3d p(u(rng), u(rng), u(rng));
    double best = 1e9;
    for (const auto& f : ellipsoid.faces) {
      const Eigen::Vector3d c = ClosestPointOnTriangle(
          p, ellipsoid.vertices[f[0]].cast<double>(), ellipsoid.vertices[f[1]].cast<double>(),
          ellipsoid.vertices[f[2]].cast<double>());
      best = std::min(best, (c - p).norm());
    }
    EXPECT_NEAR(distance.Distance(p), best, 1e-12);
  }
}

}  // namespace
}  // namespace arpos
