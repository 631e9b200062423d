// Contour stacks -> coverage volume -> closed surface, on synthetic contours
// with known areas and volumes.
#include <gtest/gtest.h>

#include <cmath>

#include "model_import/contour_raster.h"
#include "model_import/mesh_stats.h"
#include "model_import/surface_extraction.h"
#include "model_import/test_util.h"
#include "util/check.h"

namespace arpos {
namespace {

using Contour = std::vector<Eigen::Vector3d>;

Contour Rectangle(double x0, double y0, double x1, double y1, double z, bool clockwise = false) {
  Contour c = {{x0, y0, z}, {x1, y0, z}, {x1, y1, z}, {x0, y1, z}};
  if (clockwise) std::reverse(c.begin(), c.end());
  return c;
}

Contour Circle(double cx, double cy, double r, double z, int n = 180) {
  Contour c;
  for (int i = 0; i < n; ++i) {
    const double a = 2 * M_PI * i / n;
    c.emplace_back(cx + r * std::cos(a), cy + r * std::sin(a), z);
  }
  return c;
}

double SliceCoverageMm2(const ContourRasterResult& r, int k) {
  const VolumeGeometry& g = r.coverage.geometry;
  double sum = 0;
  for (int j = 0; j < g.size[1]; ++j) {
    for (int i = 0; i < g.size[0]; ++i) sum += r.coverage.values[g.Index(i, j, k)];
  }
  return sum * g.spacing_mm.x() * g.spacing_mm.y();
}

SurfaceOptions Raw() {
  SurfaceOptions s;
  s.iso_value = 0.5;
  s.smoothing_iterations = 0;
  s.max_vertices = 0;
  return s;
}

std::string RasterError(const std::vector<Contour>& contours) {
  try {
    RasterizeContours(contours, {}, "test.dcm, ROI 'X'");
  } catch (const InputError& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(EvenOddArea, NestedContoursAlternate) {
  // Outer 100 x 100, a 50 x 50 hole, a 20 x 20 island in the hole, any winding.
  const std::vector<Contour> plane = {Rectangle(0, 0, 100, 100, 5), Rectangle(25, 25, 75, 75, 5, true),
                                      Rectangle(40, 40, 60, 60, 5)};
  EXPECT_NEAR(EvenOddArea(plane, Eigen::Vector3d::UnitZ()), 10000 - 2500 + 400, 1e-6);
  // Two separate outlines add up.
  EXPECT_NEAR(EvenOddArea({Rectangle(0, 0, 10, 10, 0), Rectangle(20, 0, 30, 10, 0, true)},
                          Eigen::Vector3d::UnitZ()),
              200, 1e-9);
}

TEST(ContourRaster, HolesByEvenOddWhateverTheWinding) {
  std::vector<Contour> contours;
  for (int s = 0; s <= 10; ++s) {
    const double z = -30 + 3.0 * s;
    contours.push_back(Rectangle(-50, -30, 50.5, 30, z, s % 2 == 0));
    contours.push_back(Rectangle(-10.3, -10, 10, 10.7, z, s % 3 == 0));  // hole
  }
  const ContourRasterResult r = RasterizeContours(contours, {}, "test");
  EXPECT_EQ(r.num_planes, 11);
  EXPECT_EQ(r.num_contours, 22);
  EXPECT_NEAR(r.slice_spacing_mm, 3.0, 1e-9);
  EXPECT_EQ(r.coverage.geometry.size[2], 13);  // 11 planes + one empty slice each end
  const double expected = 100.5 * 60 - 20.3 * 20.7;
  // Exact along rows; 4 sub-rows per pixel quantise the horizontal edges to 1/8 pixel.
  for (int k = 1; k <= 11; ++k) EXPECT_NEAR(SliceCoverageMm2(r, k), expected, 5e-4 * expected) << k;
  EXPECT_EQ(SliceCoverageMm2(r, 0), 0);
  EXPECT_EQ(SliceCoverageMm2(r, 12), 0);
  // The surface's cross-section follows the polygons to a fraction of a pixel.
  const TriangleMesh mesh = ExtractSurface(r.coverage, Raw(), "test");
  const MeshSummary s = SummarizeMesh(mesh);
  EXPECT_TRUE(s.closed);
  EXPECT_EQ(s.num_components, 1);
  for (double z_mm : {-28.5, -22.5, -9.0, -1.5}) {
    const double area_mm2 = test::CrossSectionAreaZ(mesh, z_mm * 0.001) * 1e6;
    EXPECT_NEAR(area_mm2, expected, 0.005 * expected) << z_mm;
  }
  // Caps half a slice beyond the end planes; frame: axial grid axes are x, y, z.
  EXPECT_NEAR(s.min.z() * 1000, -31.5, 0.01);
  EXPECT_NEAR(s.max.z() * 1000, 1.5, 0.01);
  EXPECT_NEAR(s.min.x() * 1000, -50, 0.3);
  EXPECT_NEAR(s.max.x() * 1000, 50.5, 0.3);
  EXPECT_TRUE(r.coverage.geometry.patient_from_index_rotation.isIdentity(1e-12));
}

TEST(ContourRaster, CylinderVolumeAndSmoothingDoNotShrink) {
  std::vector<Contour> contours;
  for (int s = 0; s <= 20; ++s) contours.push_back(Circle(12, -40, 50, 100 + 3.0 * s));
  const ContourRasterResult r = RasterizeContours(contours, {}, "test");
  const double expected_mm3 = M_PI * 50 * 50 * (60 + 3);  // capped half a slice beyond each end
  SurfaceOptions smooth = Raw();
  smooth.smoothing_iterations = 20;
  smooth.max_vertices = 20000;
  for (const SurfaceOptions& options : {Raw(), smooth}) {
    const TriangleMesh mesh = ExtractSurface(r.coverage, options, "test");
    const MeshSummary s = SummarizeMesh(mesh);
    EXPECT_TRUE(s.closed);
    EXPECT_EQ(s.num_components, 1);
    if (options.max_vertices > 0) {
      EXPECT_LE(s.num_vertices, options.max_vertices);
    }
    EXPECT_NEAR(s.signed_volume * 1e9, expected_mm3, 0.01 * expected_mm3);
    EXPECT_NEAR(test::CrossSectionAreaZ(mesh, 0.130) * 1e6, M_PI * 2500, 0.01 * M_PI * 2500);
  }
}

TEST(ContourRaster, SkippedSliceIsFilledFromTheNearestPlane) {
  std::vector<Contour> contours;
  for (double z : {0.0, 3.0, 6.0, 12.0, 15.0}) contours.push_back(Rectangle(0, 0, 40, 40, z));
  const ContourRasterResult r = RasterizeContours(contours, {}, "test");
  EXPECT_EQ(r.num_planes, 5);
  EXPECT_EQ(r.filled_missing_slices, 1);
  EXPECT_NEAR(SliceCoverageMm2(r, 4), 1600, 1e-6);  // z = 9 mm
}

TEST(ContourRaster, SagittalContoursKeepTheirPlane) {
  // Contours in planes x = const: the grid's k axis is +x.
  std::vector<Contour> contours;
  for (int s = 0; s <= 10; ++s) {
    const double x = 2.0 * s;
    contours.push_back({{x, 0, 0}, {x, 30, 0}, {x, 30, 20}, {x, 0, 20}});
  }
  const ContourRasterResult r = RasterizeContours(contours, {}, "test");
  EXPECT_LT((r.normal - Eigen::Vector3d::UnitX()).norm(), 1e-12);
  const MeshSummary s = SummarizeMesh(ExtractSurface(r.coverage, Raw(), "test"));
  EXPECT_NEAR(s.min.y() * 1000, 0, 0.01);
  EXPECT_NEAR(s.max.y() * 1000, 30, 0.01);
  EXPECT_NEAR(s.max.z() * 1000, 20, 0.01);
  EXPECT_TRUE(s.closed);
  // Marching cubes chamfers the box's sharp edges by half a pixel: -139 mm^3
  // of 13200 here, none of it on the faces (the extent is exact).
  EXPECT_NEAR(s.signed_volume * 1e9, 30 * 20 * 22, 0.015 * 30 * 20 * 22);
  EXPECT_NEAR(s.min.x() * 1000, -1, 0.01);
  EXPECT_NEAR(s.max.x() * 1000, 21, 0.01);
}

TEST(ContourRaster, UnusableContoursAreRefused) {
  EXPECT_NE(RasterError({Rectangle(0, 0, 10, 10, 0), Rectangle(0, 0, 20, 20, 0)}).find("one plane"),
            std::string::npos);
  EXPECT_NE(RasterError({{{0, 0, 0}, {1, 1, 0}}}).find("no contour"), std::string::npos);
  Contour tilted = Rectangle(0, 0, 10, 10, 3);
  tilted[2].z() += 5;
  tilted[3].z() += 5;
  const std::string tilt = RasterError({Rectangle(0, 0, 10, 10, 0), tilted});
  EXPECT_NE(tilt.find("parallel"), std::string::npos) << tilt;
  Contour bent = Circle(0, 0, 20, 3);
  bent[10].z() += 2;
  const std::string bend = RasterError({Circle(0, 0, 20, 0), bent});
  EXPECT_NE(bend.find("not planar"), std::string::npos) << bend;
  Contour nan = Rectangle(0, 0, 10, 10, 0);
  nan[1].x() = std::nan("");
  EXPECT_NE(RasterError({nan, Rectangle(0, 0, 10, 10, 3)}).find("non-finite"), std::string::npos);
  for (const std::string& message : {tilt, bend}) {
    EXPECT_NE(message.find("test.dcm, ROI 'X'"), std::string::npos) << message;
  }
}

}  // namespace
}  // namespace arpos
