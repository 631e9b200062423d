// The sticker layout's scale from the stickers' printed size, on rendered
// body scans (the stickers read by the session's detector).
#include <gtest/gtest.h>

#include "body_model/layout_scale.h"
#include "rendered_scan.h"

namespace arpos {
namespace {

// The true layout of the scan's stickers, in the room.
std::map<int, Rigid3d> TrueLayout(const test::Scan& scan) {
  std::map<int, Rigid3d> layout;
  for (const auto& m : scan.truth.body_markers)
    layout[m.id] = scan.room_from_model * m.parent_from_marker;
  return layout;
}

Eigen::Vector3d Centre(const std::map<int, Rigid3d>& layout) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& [id, pose] : layout) c += pose.translation;
  return c / static_cast<double>(layout.size());
}

TEST(LayoutScale, AScaledLayoutIsMeasuredAndScaledBack) {
  const test::Scan scan = test::RenderScan("xtion", 20, 7);
  const std::map<int, Rigid3d> truth = TrueLayout(scan);
  std::vector<double> read_sizes;  // measured x wrong: the size as read, whatever the layout
  for (const double wrong : {1.0, 1.006, 0.994}) {
    std::map<int, Rigid3d> layout = truth;
    ScaleLayout(wrong, &layout);
    const LayoutScaleEstimate e =
        EstimateLayoutScale(scan.views, layout, {}, scan.intrinsics, 0.01);
    ASSERT_TRUE(e.ok) << e.why_not;
    EXPECT_GE(e.views, 10);
    EXPECT_LT(e.standard_error, 5e-4) << e.ToText();
    // The stickers as read: within the size bias of the truth (this render
    // reads them 0.13 % off), the same for every layout.
    EXPECT_NEAR(e.measured * wrong, 1.0, LayoutScaleOptions().size_bias + 5e-4) << e.ToText();
    read_sizes.push_back(e.measured * wrong);
    EXPECT_NEAR(read_sizes.back(), read_sizes.front(), 2e-4) << "layout scaled by " << wrong;
    // Never past the measurement; a right layout nearly untouched, a wrong
    // one scaled back to within the size bias and this render's (0.6 % ->
    // 0.25 % and 0.02 %).
    EXPECT_LE(std::abs(e.scale - 1), std::abs(e.measured - 1) + 1e-12);
    if (wrong == 1.0) {
      EXPECT_LT(std::abs(e.scale - 1), 5e-4) << e.ToText();
    } else {
      EXPECT_LT(std::abs(e.scale * wrong - 1), 0.5 * std::abs(wrong - 1)) << e.ToText();
      EXPECT_NE(e.ToText().find("scaled by"), std::string::npos) << e.ToText();
    }
    // Applied about the layout's centre, which stays; orientations kept.
    const Eigen::Vector3d centre = Centre(layout);
    ScaleLayout(e.scale, &layout);
    EXPECT_LT((Centre(layout) - centre).norm(), 1e-9);
    const double residual = std::abs(e.scale * wrong - 1);
    for (const auto& [id, pose] : layout) {
      const Eigen::Vector3d true_position = truth.at(id).translation;
      EXPECT_LT((pose.translation - true_position).norm(),
                1e-6 + (true_position - centre).norm() * (residual + 1e-6))
          << "sticker " << id;
      EXPECT_TRUE(pose.rotation.isApprox(truth.at(id).rotation)) << "sticker " << id;
    }
  }
}

TEST(LayoutScale, TooFewViewsOrStickersGiveNoEstimate) {
  const test::Scan scan = test::RenderScan("xtion", 2, 7);
  const std::map<int, Rigid3d> truth = TrueLayout(scan);
  const LayoutScaleEstimate few = EstimateLayoutScale(scan.views, truth, {}, scan.intrinsics, 0.01);
  EXPECT_FALSE(few.ok);
  EXPECT_NE(few.why_not.find("needed"), std::string::npos) << few.why_not;
  EXPECT_EQ(few.scale, 1.0);
  // Every sticker left out (all of them breathing): nothing to measure.
  std::set<int> all;
  for (const auto& [id, pose] : truth) all.insert(id);
  const LayoutScaleEstimate none =
      EstimateLayoutScale(scan.views, truth, all, scan.intrinsics, 0.01);
  EXPECT_FALSE(none.ok);
  EXPECT_EQ(none.views, 0);
  EXPECT_NE(none.ToText().find("not checked"), std::string::npos) << none.ToText();
}

TEST(LayoutScale, EdgesTheResponseLeavesWideOrUnmeasuredGiveNoEstimate) {
  const test::Scan scan = test::RenderScan("xtion", 8, 7);
  std::map<int, Rigid3d> layout = TrueLayout(scan);
  ScaleLayout(1.006, &layout);
  const LayoutScaleEstimate measured =
      EstimateLayoutScale(scan.views, layout, {}, scan.intrinsics, 0.02);
  EXPECT_TRUE(measured.ok) << measured.why_not;
  EXPECT_LT(measured.scale, 1.0);
  const LayoutScaleEstimate wide =
      EstimateLayoutScale(scan.views, layout, {}, scan.intrinsics, 0.17);
  EXPECT_FALSE(wide.ok);
  EXPECT_EQ(wide.scale, 1.0);
  EXPECT_NE(wide.why_not.find("0.170 px"), std::string::npos) << wide.why_not;
  const LayoutScaleEstimate unmeasured =
      EstimateLayoutScale(scan.views, layout, {}, scan.intrinsics, -1);
  EXPECT_FALSE(unmeasured.ok);
  EXPECT_NE(unmeasured.why_not.find("not measured"), std::string::npos) << unmeasured.why_not;
}

TEST(LayoutScale, SizesThatDisagreeBeyondTheSearchAreNoEstimate) {
  const test::Scan scan = test::RenderScan("xtion", 8, 7);
  std::map<int, Rigid3d> layout = TrueLayout(scan);
  ScaleLayout(1.05, &layout);
  const LayoutScaleEstimate e = EstimateLayoutScale(scan.views, layout, {}, scan.intrinsics, 0.01);
  EXPECT_FALSE(e.ok);
  EXPECT_NE(e.why_not.find("disagree"), std::string::npos) << e.why_not;
  EXPECT_EQ(e.scale, 1.0);
}

}  // namespace
}  // namespace arpos
