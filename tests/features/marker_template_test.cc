// A small marker located by its whole known pattern (features/marker_template.h),
// on synthetic renders with exactly known corners (tests/features/marker_render.h:
// exact area coverage, blur in linear radiance, a tone curve, noise) that the
// template does not share: they cover each pixel's square exactly, the template
// blurs a Gaussian for it.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include <opencv2/aruco.hpp>

#include "features/edge_refinement.h"
#include "features/marker_cells.h"
#include "features/marker_render.h"
#include "features/marker_template.h"
#include "util/check.h"

namespace arpos::testing {
namespace {

struct Small {
  cv::Mat image;
  MarkerTruth truth;
};

Small RenderSmall(int id, double side_px, double tilt_deg, double blur_px, unsigned seed) {
  std::mt19937 rng(seed);
  const CameraIntrinsics cam = VgaCamera();
  RenderOptions render;
  render.dictionary = "DICT_6X6_250";
  render.gamma = 2.2;
  render.blur_sigma_px = blur_px;
  render.noise_sigma_grey = 2.0;
  MarkerPlacement m;
  m.id = id;
  m.camera_from_marker = MarkerPoseForView(cam, Eigen::Vector2d(300.3 + seed % 7, 220.6 + seed % 5),
                                           side_px, 0.03, tilt_deg, &rng);
  std::vector<MarkerTruth> truth;
  Small out;
  out.image = RenderMarkers(cam, {m}, render, &rng, &truth);
  out.truth = truth[0];
  return out;
}

cv::Mat CellsOf(int id) {
  cv::Mat cells;
  cv::aruco::drawMarker(cv::aruco::getPredefinedDictionary(cv::aruco::DICT_6X6_250), id, 8, cells,
                        1);
  return cells;
}

std::array<Eigen::Vector2d, 4> Shifted(const std::array<Eigen::Vector2d, 4>& corners, double px,
                                       unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> angle(0, 6.283185307179586);
  std::normal_distribution<double> jitter(0, 0.2);
  const double a = angle(rng);
  std::array<Eigen::Vector2d, 4> out = corners;
  for (auto& c : out)
    c += px * Eigen::Vector2d(std::cos(a), std::sin(a)) + Eigen::Vector2d(jitter(rng), jitter(rng));
  return out;
}

TEST(MarkerTemplate, LocatesSixBySixMarkersTooSmallForTheirEdgeLines) {
  // 6x6 markers of 10-22 px (1.2-2.7 px a cell), tilted up to 50 deg,
  // blurred 0.4-1.0 px, gamma-encoded, on a textured background, started
  // 1.5 px off. Measured: 40 of 40 fitted, 0.16 px RMS, 0.40 max (the
  // stated sigma about right); the edge lines refine 2.
  MarkerTemplateOptions options;
  options.response = CameraResponse::Gamma(2.2);
  EdgeRefinementOptions edge;
  edge.marker_bits = 6;
  edge.response = options.response;
  double sum_sq = 0, worst = 0;
  int corners = 0, fitted = 0, edges_refined = 0, trials = 0;
  double normalised_sq = 0;
  for (unsigned seed = 1; seed <= 40; ++seed) {
    const double side = 10 + 0.3 * seed;
    const double tilt = 1.25 * seed;
    const double blur = 0.4 + 0.015 * seed;
    const int id = static_cast<int>(seed * 5 % 250);
    const Small m = RenderSmall(id, side, tilt, blur, seed);
    const auto start = Shifted(m.truth.corners_px, 1.5, seed);
    ++trials;
    edges_refined += RefineMarkerCorners(m.image, start, edge).status == MarkerStatus::kRefined;
    const MarkerTemplateResult r = FitMarkerTemplate(m.image, CellsOf(id), start, options);
    if (!r.ok) {
      std::printf("side %.1f px, tilt %.1f deg: %s\n", side, tilt, r.failure.c_str());
      continue;
    }
    ++fitted;
    for (int k = 0; k < 4; ++k) {
      const double e = (r.corners_px[k] - m.truth.corners_px[k]).norm();
      sum_sq += e * e;
      worst = std::max(worst, e);
      normalised_sq += e * e / (2 * r.corner_sigma_px[k] * r.corner_sigma_px[k]);
      ++corners;
    }
  }
  const double rms = std::sqrt(sum_sq / corners);
  const double normalised = std::sqrt(normalised_sq / corners);
  std::printf(
      "6x6 markers of 10-22 px: %d of %d fitted (edge lines: %d), corner error %.3f px RMS, %.3f "
      "max, "
      "error / stated sigma %.2f RMS\n",
      fitted, trials, edges_refined, rms, worst, normalised);
  EXPECT_GE(fitted, trials - 3);
  EXPECT_LT(rms, 0.2);
  EXPECT_LT(worst, 0.6);
  // The stated sigma is of the right size (not a free pass, not a refusal).
  EXPECT_GT(normalised, 0.4);
  EXPECT_LT(normalised, 2.5);
}

TEST(MarkerTemplate, ASearchFindsAMarkerBeyondTheFitsOwnReach) {
  // Started 4 px off (a pose known to a few millimetres, the sticker 14-20
  // px across): alone the fit mostly stops elsewhere; with the pattern
  // correlated over 6 px first, each is found.
  MarkerTemplateOptions options;
  options.response = CameraResponse::Gamma(2.2);
  MarkerTemplateOptions searching = options;
  searching.search_radius_px = 6;
  int found_alone = 0, found_searching = 0, trials = 0;
  double worst = 0;
  for (unsigned seed = 1; seed <= 12; ++seed) {
    const int id = static_cast<int>(seed * 11 % 250);
    const Small m = RenderSmall(id, 14 + 0.5 * seed, 3.0 * seed, 0.6, 300 + seed);
    const auto start = Shifted(m.truth.corners_px, 4.0, seed);
    ++trials;
    auto close = [&](const MarkerTemplateResult& r) {
      double e = 0;
      for (int k = 0; k < 4; ++k) e = std::max(e, (r.corners_px[k] - m.truth.corners_px[k]).norm());
      return r.ok && e < 0.5;
    };
    found_alone += close(FitMarkerTemplate(m.image, CellsOf(id), start, options));
    const MarkerTemplateResult r = FitMarkerTemplate(m.image, CellsOf(id), start, searching);
    found_searching += close(r);
    for (int k = 0; k < 4 && r.ok; ++k)
      worst = std::max(worst, (r.corners_px[k] - m.truth.corners_px[k]).norm());
  }
  std::printf(
      "started 4 px off: %d of %d found by the fit alone, %d with the search (worst corner %.3f "
      "px)\n",
      found_alone, trials, found_searching, worst);
  EXPECT_EQ(found_searching, trials);
  EXPECT_LT(found_alone, trials / 2);
}

TEST(MarkerTemplate, RefusesAnotherMarkerAndAPlainPatch) {
  MarkerTemplateOptions options;
  options.response = CameraResponse::Gamma(2.2);
  int refused_other = 0, refused_blank = 0, trials = 0;
  for (unsigned seed = 1; seed <= 10; ++seed) {
    const Small m = RenderSmall(17, 16, 20, 0.6, 100 + seed);
    const auto start = Shifted(m.truth.corners_px, 0.5, seed);
    ++trials;
    // The pattern of another marker where this one is.
    refused_other +=
        !FitMarkerTemplate(m.image, CellsOf(18 + static_cast<int>(seed)), start, options).ok;
    // The same corners moved onto empty background.
    std::array<Eigen::Vector2d, 4> away = start;
    for (auto& c : away) c += Eigen::Vector2d(150, 0);
    refused_blank += !FitMarkerTemplate(m.image, CellsOf(17), away, options).ok;
  }
  EXPECT_EQ(refused_other, trials);
  EXPECT_EQ(refused_blank, trials);
}

TEST(MarkerTemplate, StatesWhyOnInputItCannotUse) {
  const cv::Mat cells = CellsOf(3);
  const cv::Mat gray(100, 100, CV_8UC1, cv::Scalar(128));
  std::array<Eigen::Vector2d, 4> corners{Eigen::Vector2d(40, 40), Eigen::Vector2d(55, 40),
                                         Eigen::Vector2d(55, 55), Eigen::Vector2d(40, 55)};
  EXPECT_FALSE(FitMarkerTemplate(cv::Mat(), cells, corners).ok);
  EXPECT_FALSE(FitMarkerTemplate(gray, cv::Mat(), corners).ok);
  auto at_border = corners;
  for (auto& c : at_border) c -= Eigen::Vector2d(45, 0);
  const MarkerTemplateResult border = FitMarkerTemplate(gray, cells, at_border);
  EXPECT_FALSE(border.ok);
  EXPECT_NE(border.failure.find("inside the image"), std::string::npos) << border.failure;
  auto nan = corners;
  nan[2].x() = std::nan("");
  EXPECT_FALSE(FitMarkerTemplate(gray, cells, nan).ok);
  // Three corners on a line: no quadrilateral, said, searched or not.
  const std::array<Eigen::Vector2d, 4> line{Eigen::Vector2d(40, 40), Eigen::Vector2d(50, 40),
                                            Eigen::Vector2d(60, 40), Eigen::Vector2d(45, 52)};
  for (double radius : {0.0, 4.0}) {
    MarkerTemplateOptions searching;
    searching.search_radius_px = radius;
    const MarkerTemplateResult degenerate = FitMarkerTemplate(gray, cells, line, searching);
    EXPECT_FALSE(degenerate.ok);
    EXPECT_FALSE(degenerate.failure.empty());
  }
  // A flat grey patch: no contrast.
  const MarkerTemplateResult flat = FitMarkerTemplate(gray, cells, corners);
  EXPECT_FALSE(flat.ok);
}

// The printed cells both the pattern fit and the response estimate read:
// each marker's bits as the dictionary stores them, inside a black border
// of the asked width; an id beyond the dictionary gives nothing to draw.
TEST(MarkerCells, AreTheDictionaryBitsInsideTheirBorder) {
  for (const int border : {1, 2}) {
    MarkerCells book("DICT_5X5_100", border);
    ASSERT_EQ(book.cells_per_side(), 5 + 2 * border);
    const cv::Ptr<cv::aruco::Dictionary> dict =
        cv::aruco::getPredefinedDictionary(cv::aruco::DICT_5X5_100);
    for (const int id : {0, 17, 99}) {
      const cv::Mat& cells = book.Of(id);
      ASSERT_EQ(cells.type(), CV_8UC1);
      ASSERT_EQ(cells.rows, 5 + 2 * border);
      ASSERT_EQ(cells.cols, 5 + 2 * border);
      const cv::Mat bits =
          cv::aruco::Dictionary::getBitsFromByteList(dict->bytesList.rowRange(id, id + 1), 5);
      int wrong = 0;
      for (int y = 0; y < cells.rows; ++y) {
        for (int x = 0; x < cells.cols; ++x) {
          const bool inner = y >= border && x >= border && y < border + 5 && x < border + 5;
          const int want = inner && bits.at<uchar>(y - border, x - border) ? 255 : 0;
          wrong += cells.at<uchar>(y, x) != want;
        }
      }
      EXPECT_EQ(wrong, 0) << "id " << id << ", border " << border;
      EXPECT_EQ(book.Of(id).data, cells.data) << "drawn once";
    }
    EXPECT_TRUE(book.Of(100).empty());
    EXPECT_TRUE(book.Of(-1).empty());
  }
  EXPECT_THROW(MarkerCells("DICT_NOT_ONE", 1), Error);
}

}  // namespace
}  // namespace arpos::testing
