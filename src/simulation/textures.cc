#include "simulation/textures.h"

#include <algorithm>
#include <cmath>
#include <opencv2/aruco.hpp>
#include <opencv2/imgproc.hpp>

#include "simulation/random.h"
#include "util/check.h"

namespace arpos::sim {
namespace {

// Smooth noise in [-1, 1] (roughly) with features of `cell_px` texels.
cv::Mat ValueNoise(int width, int height, double cell_px, Rng* rng) {
  const int gw = std::max(2, static_cast<int>(std::ceil(width / cell_px)) + 2);
  const int gh = std::max(2, static_cast<int>(std::ceil(height / cell_px)) + 2);
  cv::Mat grid(gh, gw, CV_32F);
  for (int y = 0; y < gh; ++y)
    for (int x = 0; x < gw; ++x) grid.at<float>(y, x) = static_cast<float>(rng->Uniform(-1, 1));
  cv::Mat up;
  cv::resize(grid, up, cv::Size(static_cast<int>(gw * cell_px), static_cast<int>(gh * cell_px)), 0,
             0, cv::INTER_CUBIC);
  return up(cv::Rect(0, 0, width, height)).clone();
}

// Multi-scale noise: octaves from `largest_px` down to ~2 texels.
cv::Mat FractalNoise(int width, int height, double largest_px, double persistence, Rng* rng) {
  cv::Mat sum = cv::Mat::zeros(height, width, CV_32F);
  double amplitude = 1.0, total = 0.0;
  for (double cell = largest_px; cell >= 2.0; cell /= 2.0) {
    sum += ValueNoise(width, height, cell, rng) * amplitude;
    total += amplitude;
    amplitude *= persistence;
  }
  return sum / total;
}

cv::Mat ColorizeNoise(const cv::Mat& noise, const cv::Vec3f& base_bgr, const cv::Vec3f& amp_bgr) {
  cv::Mat out(noise.size(), CV_8UC3);
  for (int y = 0; y < noise.rows; ++y) {
    for (int x = 0; x < noise.cols; ++x) {
      const float n = noise.at<float>(y, x);
      cv::Vec3b& p = out.at<cv::Vec3b>(y, x);
      for (int c = 0; c < 3; ++c) {
        p[c] = cv::saturate_cast<uint8_t>(base_bgr[c] + amp_bgr[c] * n);
      }
    }
  }
  return out;
}

cv::Scalar RandomColor(Rng* rng, int lo = 20, int hi = 235) {
  return cv::Scalar(rng->UniformInt(lo, hi), rng->UniformInt(lo, hi), rng->UniformInt(lo, hi));
}

const char* const kWords[] = {"RADIATION", "CAUTION", "LINAC 2", "QA", "ROOM 3", "EXIT",
                              "NO ENTRY", "ISOCENTRE", "DOSE", "PHANTOM", "LASER", "CT-SIM",
                              "ONCOLOGY", "BEAM ON", "HANDLE WITH CARE", "SAFETY"};

void DrawText(cv::Mat* img, Rng* rng, cv::Point origin, double scale, const cv::Scalar& color) {
  const char* word = kWords[rng->UniformInt(0, static_cast<int>(std::size(kWords)) - 1)];
  cv::putText(*img, word, origin, cv::FONT_HERSHEY_SIMPLEX, scale, color,
              std::max(1, static_cast<int>(scale * 2)), cv::LINE_AA);
}

// Random shapes scattered over the image: the corners and blobs keypoint
// detectors need.
void ScatterShapes(cv::Mat* img, Rng* rng, int count, int min_px, int max_px, int lo, int hi) {
  for (int i = 0; i < count; ++i) {
    const cv::Point c(rng->UniformInt(0, img->cols - 1), rng->UniformInt(0, img->rows - 1));
    const int s = rng->UniformInt(min_px, max_px);
    const cv::Scalar color = RandomColor(rng, lo, hi);
    switch (rng->UniformInt(0, 3)) {
      case 0:
        cv::circle(*img, c, s / 2, color, cv::FILLED, cv::LINE_AA);
        break;
      case 1: {
        const cv::RotatedRect rect(c, cv::Size2f(s, s * rng->Uniform(0.3, 1.0)),
                                   static_cast<float>(rng->Uniform(0, 180)));
        cv::Point2f pts[4];
        rect.points(pts);
        std::vector<cv::Point> poly(pts, pts + 4);
        cv::fillConvexPoly(*img, poly, color, cv::LINE_AA);
        break;
      }
      case 2:
        cv::line(*img, c, c + cv::Point(rng->UniformInt(-s, s), rng->UniformInt(-s, s)), color,
                 std::max(1, s / 12), cv::LINE_AA);
        break;
      default: {
        std::vector<cv::Point> tri = {c, c + cv::Point(rng->UniformInt(-s, s), s / 2),
                                      c + cv::Point(s / 2, rng->UniformInt(-s, s))};
        cv::fillConvexPoly(*img, tri, color, cv::LINE_AA);
        break;
      }
    }
  }
}

void DrawPoster(cv::Mat* img, Rng* rng, cv::Rect r) {
  r &= cv::Rect(0, 0, img->cols, img->rows);
  if (r.width < 8 || r.height < 8) return;
  (*img)(r).setTo(cv::Scalar(235, 238, 240));
  cv::rectangle(*img, r, cv::Scalar(60, 60, 60), 2, cv::LINE_AA);
  cv::Mat roi = (*img)(r);
  const int kind = rng->UniformInt(0, 2);
  if (kind == 0) {  // chart: bars
    const int bars = rng->UniformInt(4, 9);
    for (int b = 0; b < bars; ++b) {
      const int h = rng->UniformInt(roi.rows / 6, roi.rows * 3 / 4);
      const int w = roi.cols / (bars + 1);
      cv::rectangle(roi, cv::Rect(w / 2 + b * w, roi.rows - 8 - h, w * 2 / 3, h),
                    RandomColor(rng, 30, 200), cv::FILLED);
    }
  } else if (kind == 1) {  // photo-like blobs
    ScatterShapes(&roi, rng, 25, roi.cols / 10 + 2, roi.cols / 3 + 3, 20, 230);
  } else {  // text sheet
    for (int y = 14; y < roi.rows - 6; y += 16) {
      DrawText(&roi, rng, cv::Point(6, y), 0.4, cv::Scalar(30, 30, 30));
    }
  }
  DrawText(img, rng, cv::Point(r.x + 6, r.y + 22), 0.7, cv::Scalar(20, 20, 200));
}

}  // namespace

Texture TextureFromBgr(const cv::Mat& bgr, bool nearest, bool wrap) {
  ARPOS_CHECK(bgr.type() == CV_8UC3, "texture image must be 8-bit BGR");
  Texture t(bgr.cols, bgr.rows);
  t.nearest = nearest;
  t.wrap = wrap;
  for (int y = 0; y < bgr.rows; ++y) {
    for (int x = 0; x < bgr.cols; ++x) {
      const cv::Vec3b& p = bgr.at<cv::Vec3b>(y, x);
      uint8_t* q = t.texel(x, y);
      q[0] = p[2];
      q[1] = p[1];
      q[2] = p[0];
    }
  }
  return t;
}

MarkerArtwork MakeMarkerArtwork(int dictionary_id, int marker_id, int quiet_cells, int label_cells,
                                int texels_per_cell, const std::string& caption) {
  ARPOS_CHECK(dictionary_id >= 0, "unknown ArUco dictionary");
  const cv::Ptr<cv::aruco::Dictionary> dict = cv::aruco::getPredefinedDictionary(dictionary_id);
  ARPOS_CHECK(marker_id >= 0 && marker_id < dict->bytesList.rows,
              "marker id " << marker_id << " out of range for the dictionary");
  MarkerArtwork art;
  art.marker_cells = dict->markerSize + 2;
  art.quiet_cells = quiet_cells;
  art.label_cells = label_cells;
  cv::Mat cells;
  cv::aruco::drawMarker(dict, marker_id, art.marker_cells, cells, 1);  // one pixel per cell
  const int tpc = texels_per_cell;
  const int width_cells = art.marker_cells + 2 * quiet_cells;
  const int height_cells = width_cells + label_cells;
  // Printed ink and paper are neither pure black nor pure white.
  const cv::Scalar paper(232, 236, 238), ink(28, 26, 24);
  cv::Mat img(height_cells * tpc, width_cells * tpc, CV_8UC3, paper);
  for (int y = 0; y < art.marker_cells; ++y) {
    for (int x = 0; x < art.marker_cells; ++x) {
      if (cells.at<uint8_t>(y, x) < 128) {
        img(cv::Rect((quiet_cells + x) * tpc, (quiet_cells + y) * tpc, tpc, tpc)).setTo(ink);
      }
    }
  }
  if (label_cells > 0 && !caption.empty()) {
    const double scale = 0.035 * tpc * label_cells / 2.0;
    int baseline = 0;
    const cv::Size size =
        cv::getTextSize(caption, cv::FONT_HERSHEY_SIMPLEX, scale, std::max(1, tpc / 6), &baseline);
    const int x = (img.cols - size.width) / 2;
    const int y = (width_cells * tpc) + (label_cells * tpc + size.height) / 2 - tpc / 3;
    cv::putText(img, caption, cv::Point(x, y), cv::FONT_HERSHEY_SIMPLEX, scale,
                cv::Scalar(90, 90, 90), std::max(1, tpc / 6), cv::LINE_AA);
  }
  art.texture = TextureFromBgr(img, /*nearest=*/true, /*wrap=*/false);
  const float w = static_cast<float>(width_cells), h = static_cast<float>(height_cells);
  const float lo = static_cast<float>(quiet_cells), hi = static_cast<float>(quiet_cells + art.marker_cells);
  art.uv_corners[0] = {lo / w, lo / h};
  art.uv_corners[1] = {hi / w, lo / h};
  art.uv_corners[2] = {hi / w, hi / h};
  art.uv_corners[3] = {lo / w, hi / h};
  return art;
}

Texture MakeSurfaceTexture(SurfaceStyle style, double width_m, double height_m, double texel_m,
                           uint64_t seed, TextureDetail detail) {
  Rng rng(seed);
  const bool rich = detail == TextureDetail::kRich;
  // Plain surfaces: a quarter of the mottling's contrast, nothing scattered.
  const float contrast = rich ? 1.0f : 0.25f;
  const int w = std::max(8, static_cast<int>(std::lround(width_m / texel_m)));
  const int h = std::max(8, static_cast<int>(std::lround(height_m / texel_m)));
  const double px_per_m = 1.0 / texel_m;
  cv::Mat img;
  switch (style) {
    case SurfaceStyle::kFloor: {
      // Speckled vinyl: large-scale mottling, fine speckle, tile seams, a few
      // scuffs and one or two floor signs.
      cv::Mat noise = FractalNoise(w, h, 0.6 * px_per_m, 0.75, &rng);
      img = ColorizeNoise(noise, cv::Vec3f(150, 158, 160), contrast * cv::Vec3f(70, 66, 60));
      const int tile = static_cast<int>(0.6 * px_per_m);
      for (int x = tile; x < w; x += tile) cv::line(img, {x, 0}, {x, h}, cv::Scalar(95, 100, 104), 2);
      for (int y = tile; y < h; y += tile) cv::line(img, {0, y}, {w, y}, cv::Scalar(95, 100, 104), 2);
      if (!rich) break;
      ScatterShapes(&img, &rng, static_cast<int>(width_m * height_m * 25), 2,
                    static_cast<int>(0.03 * px_per_m), 80, 170);
      for (int i = 0; i < 2; ++i) {
        DrawText(&img, &rng, cv::Point(rng.UniformInt(0, w / 2), rng.UniformInt(h / 4, h)), 1.2,
                 cv::Scalar(30, 160, 200));
      }
      break;
    }
    case SurfaceStyle::kWall: {
      cv::Mat noise = FractalNoise(w, h, 0.8 * px_per_m, 0.55, &rng);
      img = ColorizeNoise(noise, cv::Vec3f(196, 204, 208), contrast * cv::Vec3f(50, 46, 44));
      if (rich) {
        ScatterShapes(&img, &rng, static_cast<int>(width_m * height_m * 8), 4,
                      static_cast<int>(0.05 * px_per_m), 120, 200);
      }
      const int posters = rich ? static_cast<int>(width_m * height_m * 0.5) + 2 : 0;
      for (int i = 0; i < posters; ++i) {
        const int pw = static_cast<int>(rng.Uniform(0.3, 0.8) * px_per_m);
        const int ph = static_cast<int>(rng.Uniform(0.3, 0.7) * px_per_m);
        DrawPoster(&img, &rng,
                   cv::Rect(rng.UniformInt(0, std::max(1, w - pw)),
                            rng.UniformInt(static_cast<int>(0.2 * h), std::max(1, h - ph)), pw, ph));
      }
      // Skirting board along the bottom.
      cv::rectangle(img, cv::Rect(0, h - static_cast<int>(0.1 * px_per_m), w, h),
                    cv::Scalar(60, 70, 80), cv::FILLED);
      break;
    }
    case SurfaceStyle::kCeiling: {
      cv::Mat noise = FractalNoise(w, h, 0.5 * px_per_m, 0.5, &rng);
      img = ColorizeNoise(noise, cv::Vec3f(220, 222, 222), contrast * cv::Vec3f(20, 20, 20));
      const int tile = static_cast<int>(0.6 * px_per_m);
      for (int x = 0; x < w; x += tile) cv::line(img, {x, 0}, {x, h}, cv::Scalar(150, 150, 150), 2);
      for (int y = 0; y < h; y += tile) cv::line(img, {0, y}, {w, y}, cv::Scalar(150, 150, 150), 2);
      if (!rich) break;
      ScatterShapes(&img, &rng, static_cast<int>(width_m * height_m * 4), 3, 20, 150, 200);
      break;
    }
    case SurfaceStyle::kCouchTop: {
      // Dark carbon fibre with a white index bar every 0.14 m and labels.
      cv::Mat noise = FractalNoise(w, h, 0.05 * px_per_m, 0.7, &rng);
      img = ColorizeNoise(noise, cv::Vec3f(52, 50, 48), cv::Vec3f(18, 18, 18));
      for (double y_m = 0.07; y_m < height_m; y_m += 0.14) {
        const int y = static_cast<int>(y_m * px_per_m);
        cv::line(img, {0, y}, {static_cast<int>(0.05 * px_per_m), y}, cv::Scalar(220, 220, 220), 3);
        cv::line(img, {w - static_cast<int>(0.05 * px_per_m), y}, {w, y}, cv::Scalar(220, 220, 220),
                 3);
        cv::putText(img, std::to_string(static_cast<int>(y_m * 100)),
                    cv::Point(static_cast<int>(0.06 * px_per_m), y + 6), cv::FONT_HERSHEY_SIMPLEX,
                    0.5, cv::Scalar(200, 200, 200), 1, cv::LINE_AA);
      }
      ScatterShapes(&img, &rng, static_cast<int>(width_m * height_m * 60), 2, 10, 20, 110);
      break;
    }
    case SurfaceStyle::kCouchBase: {
      cv::Mat noise = FractalNoise(w, h, 0.3 * px_per_m, 0.5, &rng);
      img = ColorizeNoise(noise, cv::Vec3f(175, 170, 160), contrast * cv::Vec3f(30, 30, 30));
      if (!rich) break;
      ScatterShapes(&img, &rng, static_cast<int>(width_m * height_m * 20), 3, 25, 100, 190);
      DrawText(&img, &rng, cv::Point(10, h / 2), 1.0, cv::Scalar(60, 60, 60));
      break;
    }
    case SurfaceStyle::kGantry: {
      cv::Mat noise = FractalNoise(w, h, 0.5 * px_per_m, 0.5, &rng);
      img = ColorizeNoise(noise, cv::Vec3f(215, 215, 210), contrast * cv::Vec3f(18, 18, 18));
      for (int i = 0; i < (rich ? 12 : 4); ++i) {
        const cv::Rect r(rng.UniformInt(0, w - 20), rng.UniformInt(0, h - 20),
                         rng.UniformInt(20, w / 3 + 21), rng.UniformInt(20, h / 4 + 21));
        cv::rectangle(img, r, cv::Scalar(120, 120, 120), 2, cv::LINE_AA);
      }
      if (rich) ScatterShapes(&img, &rng, static_cast<int>(width_m * height_m * 6), 4, 30, 120, 200);
      for (int i = 0; i < (rich ? 6 : 1); ++i) {
        DrawText(&img, &rng, cv::Point(rng.UniformInt(0, w / 2), rng.UniformInt(20, h)), 1.0,
                 cv::Scalar(140, 90, 40));
      }
      break;
    }
  }
  return TextureFromBgr(img, /*nearest=*/false, /*wrap=*/false);
}

}  // namespace arpos::sim
