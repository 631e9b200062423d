// Stickers against the aligned reference surface (body_model/sticker_surface.h).
#include "body_model/sticker_surface.h"

#include <gtest/gtest.h>

#include "registration/kdtree.h"
#include "registration/point_cloud.h"

namespace arpos {
namespace {

// A flat 0.4 m square of skin (z = 0), sampled every 2 mm as the session
// samples the model.
PointCloud FlatSkin() {
  PointCloud cloud;
  for (int i = 0; i <= 200; ++i) {
    for (int j = 0; j <= 200; ++j)
      cloud.Add(Eigen::Vector3d(-0.2 + 0.002 * i, -0.2 + 0.002 * j, 0.0));
  }
  return cloud;
}

Rigid3d At(double x, double y, double z) {
  return Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(x, y, z));
}

TEST(StickerSurface, StickersOffTheSkinBeyondTheirBreathingAreNamed) {
  const PointCloud skin = FlatSkin();
  const KdTree tree(skin);
  const std::map<int, Rigid3d> stickers = {
      {101, At(0.05, 0.05, 0.002)},    // on the skin
      {102, At(-0.1, 0.03, 0.012)},    // 12 mm off, still
      {103, At(0.1, -0.1, 0.012)},     // 12 mm off, but it breathes 2 mm (1 sigma): allowed 14 mm
      {104, At(0.0, 0.0, 0.5)},        // far beyond the search
      {105, At(0.001, 0.001, -0.007)}  // 7 mm under it: within 8 mm
  };
  const std::map<int, double> motion = {{103, 0.002}};
  const StickerSurfaceCheck check = CheckStickersOnSurface(stickers, tree, motion);
  ASSERT_EQ(check.off_m.size(), 5u);
  EXPECT_NEAR(check.off_m.at(101), 0.002, 1e-3);
  EXPECT_NEAR(check.off_m.at(102), 0.012, 1e-3);
  EXPECT_NEAR(check.off_m.at(104), 0.1, 1e-9);  // reads as the search radius
  EXPECT_EQ(check.off, (std::vector<int>{102, 104}));
  EXPECT_EQ(check.DescribeOff(), "102 (12.0 mm), 104 (100.0 mm)");
  EXPECT_NE(check.ToText().find("at most 100.0 mm (sticker 104)"), std::string::npos)
      << check.ToText();

  // At 5 mm: the breathing one too (5 + 3 x 2 < 12 mm) and the one 7 mm under.
  StickerSurfaceOptions tight;
  tight.max_off_m = 0.005;
  const StickerSurfaceCheck strict = CheckStickersOnSurface(stickers, tree, motion, tight);
  EXPECT_EQ(strict.off, (std::vector<int>{102, 103, 104, 105}));
  EXPECT_TRUE(CheckStickersOnSurface({}, tree, motion).ToText().empty());
}

}  // namespace
}  // namespace arpos
