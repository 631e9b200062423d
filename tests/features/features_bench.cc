// Google Benchmark for marker detection + corner refinement, and (with
// --report) the corner-accuracy comparison of OpenCV's refinements with ours
// on synthetic renders. Not part of ctest; run by hand:
//   features_bench                       timing
//   features_bench --report [--quick]    accuracy table (markdown) then timing
#include <benchmark/benchmark.h>

#include <cstdio>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include <opencv2/aruco.hpp>

#include "features/corner_study.h"
#include "features/edge_refinement.h"
#include "features/marker_detector.h"
#include "features/marker_render.h"
#include "features/marker_template.h"
#include "features/response_from_recording.h"

namespace arpos::testing {
namespace {

struct MethodConfig {
  const char* name;
  CornerRefinementMethod method;
  int subpix_window;
};

const MethodConfig kMethods[] = {
    {"OpenCV NONE", CornerRefinementMethod::kOpenCvNone, 5},
    {"OpenCV SUBPIX (win 5)", CornerRefinementMethod::kOpenCvSubpix, 5},
    {"OpenCV SUBPIX (win 2)", CornerRefinementMethod::kOpenCvSubpix, 2},
    {"OpenCV CONTOUR", CornerRefinementMethod::kOpenCvContour, 5},
    {"OpenCV APRILTAG", CornerRefinementMethod::kOpenCvAprilTag, 5},
    {"edge lines (ours)", CornerRefinementMethod::kEdgeLines, 5},
};

MarkerDetectorOptions OptionsFor(const MethodConfig& m) {
  MarkerDetectorOptions o;
  o.refinement = m.method;
  o.opencv_subpix_window_px = m.subpix_window;
  return o;
}

void PrintStudy(const char* title, const CameraIntrinsics& camera,
                const std::vector<StudyImage>& images) {
  std::printf("\n### %s\n\n", title);
  std::printf(
      "| method | side px | n | median px | p95 px | scale bias %% | mean offset px (x, y) | "
      "t err median mm | t err p95 mm | R err median deg | time/frame ms |\n"
      "|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const MethodConfig& m : kMethods) {
    const StudyResult r = RunStudy(images, camera, OptionsFor(m));
    const double bins[][2] = {{15, 30}, {30, 60}, {60, 81}, {0, 1e9}};
    for (const auto& b : bins) {
      const Summary s = Summarise(r, b[0], b[1]);
      char range[32];
      if (b[1] > 1e8) {
        std::snprintf(range, sizeof(range), "all");
      } else {
        std::snprintf(range, sizeof(range), "%.0f-%.0f", b[0], std::min(b[1], 80.0));
      }
      std::printf(
          "| %s | %s | %d | %.3f | %.3f | %+.2f | (%+.3f, %+.3f) | %.1f | %.1f | %.2f | %s |\n",
          m.name, range, s.count, s.median_px, s.p95_px, s.scale_bias_percent, s.mean_offset_px.x(),
          s.mean_offset_px.y(), s.translation_median_mm, s.translation_p95_mm,
          s.rotation_median_deg,
          b[1] > 1e8 ? std::to_string(r.total_time_ms / r.num_images).substr(0, 5).c_str() : "");
    }
    std::printf("| %s | detected %d of %d, wrong ids %d | | | | | | | | | |\n", m.name,
                static_cast<int>(r.markers.size()), r.num_truth, r.num_wrong_ids);
  }
  std::fflush(stdout);
}

double SrgbEncode(double x) { return x <= 0.0031308 ? 12.92 * x : 1.055 * std::pow(x, 1 / 2.4) - 0.055; }

// The camera response (and sharpening) estimated from the images themselves,
// starting from the sRGB assumption.
RecordingResponse EstimateFromImages(const std::vector<StudyImage>& images) {
  MarkerDetectorOptions none;
  none.refinement = CornerRefinementMethod::kOpenCvNone;
  MarkerDetector detector(none);
  std::vector<ResponseFrame> frames;
  for (const StudyImage& img : images) frames.push_back({img.image, detector.Detect(img.image)});
  return EstimateResponseFromFrames(frames, MarkerDetectorOptions(), CameraResponse::Srgb());
}

void RunReport(bool quick) {
  const CameraIntrinsics hd = HdCamera();
  const int n = quick ? 8 : 40;
  {
    RenderOptions render;  // noise 2, blur 0.7
    PrintStudy("1280x720, sides 15-80 px, tilt <= 60 deg, noise 2 grey, blur 0.7 px", hd,
               MakeStudyImages(hd, n, 10, 15, 80, 60, render, 1));
  }
  {
    RenderOptions render;
    render.noise_sigma_grey = 0.5;
    PrintStudy("1280x720, sides 30-60 px, tilt <= 60 deg, low noise 0.5 grey, blur 0.7 px", hd,
               MakeStudyImages(hd, n, 10, 30, 60, 60, render, 2));
  }
  {
    RenderOptions render;
    render.blur_sigma_px = 0;
    PrintStudy("1280x720, sides 15-80 px, tilt <= 60 deg, noise 2 grey, no blur", hd,
               MakeStudyImages(hd, n, 10, 15, 80, 60, render, 3));
  }
  {
    RenderOptions render;
    render.gamma = 2.2;
    render.blur_sigma_px = 1.0;
    const auto images = MakeStudyImages(hd, n, 10, 15, 80, 60, render, 4);
    PrintStudy(
        "1280x720, sides 15-80 px, tilt <= 60 deg, noise 2 grey, blur 1.0 px, camera gamma "
        "2.2 (model mismatch)",
        hd, images);
    auto row = [&](const char* name, const MarkerDetectorOptions& o,
                   const std::vector<StudyImage>& imgs) {
      const StudyResult r = RunStudy(imgs, hd, o);
      const Summary s = Summarise(r, 0, 1e9);
      std::printf(
          "| %s | all | %d | %.3f | %.3f | %+.2f | (%+.3f, %+.3f) | %.1f | %.1f | %.2f | "
          "%.1f |\n",
          name, s.count, s.median_px, s.p95_px, s.scale_bias_percent, s.mean_offset_px.x(),
          s.mean_offset_px.y(), s.translation_median_mm, s.translation_p95_mm,
          s.rotation_median_deg, r.total_time_ms / r.num_images);
    };
    MarkerDetectorOptions linearised;
    linearised.edge.response = CameraResponse::Gamma(2.2);
    row("edge lines, response gamma 2.2", linearised, images);
    std::printf("\nThe same scenes with a linear camera (blur 1.0 px):\n\n");
    RenderOptions linear;
    linear.blur_sigma_px = 1.0;
    row("edge lines, linear camera", MarkerDetectorOptions(),
        MakeStudyImages(hd, n, 10, 15, 80, 60, linear, 4));
  }
  {
    // Corner bias per camera response: assumed sRGB, estimated from the
    // images themselves (camera_response.h), and the true curve.
    std::printf(
        "\n### Corner bias per camera response (1280x720, sides 15-80 px, tilt <= 60 deg, noise 2 "
        "grey, blur 1.0 px)\n\n"
        "| camera response | corners from | n | median px | p95 px | scale bias %% | t err median mm | "
        "R err median deg |\n|---|---|---|---|---|---|---|---|\n");
    auto srgb = SrgbEncode;
    const std::pair<const char*, std::function<double(double)>> curves[] = {
        {"linear", [](double x) { return x; }},
        {"sRGB", srgb},
        {"gamma 2.6", [](double x) { return std::pow(x, 1 / 2.6); }},
        {"S-curve (sRGB + contrast)",
         [srgb](double x) { const double y = srgb(x); return y - 0.45 * std::sin(2 * M_PI * y) / (2 * M_PI); }}};
    unsigned seed = 20;
    for (const auto& [name, encode] : curves) {
      RenderOptions render;
      render.encode = encode;
      render.blur_sigma_px = 1.0;
      const auto images = MakeStudyImages(hd, n, 10, 15, 80, 60, render, seed++);
      const RecordingResponse estimated = EstimateFromImages(images);
      const std::pair<const char*, CameraResponse> uses[] = {
          {"sRGB assumed", CameraResponse::Srgb()},
          {"estimated", estimated.response},
          {"true curve", ResponseOfEncoding(encode)}};
      for (const auto& [what, response] : uses) {
        MarkerDetectorOptions o;
        o.edge.response = response;
        const Summary sum = Summarise(RunStudy(images, hd, o), 0, 1e9);
        std::printf("| %s | %s | %d | %.3f | %.3f | %+.3f | %.2f | %.3f |\n", name, what, sum.count,
                    sum.median_px, sum.p95_px, sum.scale_bias_percent, sum.translation_median_mm,
                    sum.rotation_median_deg);
      }
      std::printf("| %s | (%s) | | | | | | |\n", name, estimated.message.c_str());
      std::fflush(stdout);
    }
  }  {
    // A camera's own processing after the tone curve (sharpening of the
    // encoded codes, JPEG), sRGB encoding, response estimated from the images.
    std::printf(
        "\n### Corner bias under a camera's processing (sRGB, 1280x720, sides 15-80 px, tilt <= 60 deg, "
        "noise 2 grey, blur 1.0 px; response estimated)\n\n"
        "| processing | n | median px | p95 px | scale bias %% | t err median mm | R err median deg | "
        "response estimate |\n|---|---|---|---|---|---|---|---|\n");
    auto srgb = SrgbEncode;
    struct Processing {
      const char* name;
      double sharpen;
      double sharpen_sigma;
      int jpeg;
    };
    const Processing kinds[] = {{"none", 0, 1, 0},
                                {"sharpen 0.5 (sigma 1 px)", 0.5, 1, 0},
                                {"sharpen 1.0 (sigma 1 px)", 1.0, 1, 0},
                                {"sharpen 1.5 (sigma 0.7 px)", 1.5, 0.7, 0},
                                {"JPEG 90", 0, 1, 90},
                                {"JPEG 75", 0, 1, 75},
                                {"sharpen 1.0 + JPEG 85", 1.0, 1, 85}};
    unsigned seed = 40;
    for (const Processing& k : kinds) {
      RenderOptions render;
      render.encode = srgb;
      render.blur_sigma_px = 1.0;
      render.sharpen_amount = k.sharpen;
      render.sharpen_sigma_px = k.sharpen_sigma;
      render.jpeg_quality = k.jpeg;
      const auto images = MakeStudyImages(hd, n, 10, 15, 80, 60, render, seed++);
      const RecordingResponse estimated = EstimateFromImages(images);
      MarkerDetectorOptions o;
      o.edge.response = estimated.response;
      const Summary sum = Summarise(RunStudy(images, hd, o), 0, 1e9);
      std::printf("| %s | %d | %.3f | %.3f | %+.3f | %.2f | %.3f | %s |\n", k.name, sum.count, sum.median_px,
                  sum.p95_px, sum.scale_bias_percent, sum.translation_median_mm, sum.rotation_median_deg,
                  estimated.message.c_str());
      std::fflush(stdout);
    }
  }
}

// ---- timing -----------------------------------------------------------------

const StudyImage& FrameFor(int height) {
  static std::vector<StudyImage> vga, hd;
  std::vector<StudyImage>& cache = height == 480 ? vga : hd;
  if (cache.empty()) {
    RenderOptions render;
    cache = MakeStudyImages(height == 480 ? VgaCamera() : HdCamera(), 1, 10, 15, 60, 45, render, 7);
  }
  return cache[0];
}

void BM_Detect(benchmark::State& state) {
  const MethodConfig& m = kMethods[state.range(0)];
  const StudyImage& frame = FrameFor(static_cast<int>(state.range(1)));
  MarkerDetector detector(OptionsFor(m));
  std::vector<MarkerObservation> obs;
  for (auto _ : state) {
    detector.Detect(frame.image, &obs);
    benchmark::DoNotOptimize(obs.data());
  }
  state.SetLabel(std::string(m.name) + (state.range(1) == 480 ? " 640x480" : " 1280x720"));
  state.counters["markers"] = static_cast<double>(obs.size());
}
BENCHMARK(BM_Detect)
    ->ArgsProduct({{0, 1, 2, 3, 4, 5}, {480, 720}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// range(0): the marker's side (px); range(1): 10 x the camera's sharpening
// amount, undone around the marker before the fit (0: none).
void BM_RefineOnePerMarker(benchmark::State& state) {
  const double side = static_cast<double>(state.range(0));
  const double sharpen = state.range(1) / 10.0;
  const CameraIntrinsics cam = VgaCamera();
  std::mt19937 rng(3);
  MarkerPlacement m;
  m.id = 5;
  m.camera_from_marker = MarkerPoseForView(cam, {320, 240}, side, 0.03, 30, &rng);
  std::vector<MarkerTruth> truth;
  RenderOptions render;
  render.sharpen_amount = sharpen;
  const cv::Mat img = RenderMarkers(cam, {m}, render, &rng, &truth);
  std::array<Eigen::Vector2d, 4> start = truth[0].corners_px;
  for (auto& c : start) c += (truth[0].centre_px - c).normalized() * 0.6;  // like NONE
  EdgeRefinementOptions options;
  if (sharpen > 0) options.response = options.response.WithSharpening(sharpen, 1.0);
  EdgeRefinementWorkspace ws;
  const PixelUndistorter identity;
  for (auto _ : state) {
    const CornerRefinementResult r = RefineMarkerCorners(img, start, options, identity, &ws);
    benchmark::DoNotOptimize(r.corners_px[0]);
  }
}
BENCHMARK(BM_RefineOnePerMarker)
    ->ArgsProduct({{15, 30, 60, 120}, {0, 10}})
    ->Unit(benchmark::kMicrosecond);

// A 6x6 sticker located by its whole pattern (marker_template.h), started
// 1.5 px off. range(0): its side (px); range(1): the search radius (px);
// range(2): 1 = the blurred patterns kept between fits (as a tracker does
// for the same sticker frame after frame), 0 = made anew each fit.
void BM_MarkerTemplate(benchmark::State& state) {
  const double side = static_cast<double>(state.range(0));
  const CameraIntrinsics cam = VgaCamera();
  std::mt19937 rng(5);
  MarkerPlacement m;
  m.id = 17;
  m.camera_from_marker = MarkerPoseForView(cam, {320.3, 240.6}, side, 0.03, 25, &rng);
  std::vector<MarkerTruth> truth;
  RenderOptions render;
  render.dictionary = "DICT_6X6_250";
  render.gamma = 2.2;
  const cv::Mat img = RenderMarkers(cam, {m}, render, &rng, &truth);
  std::array<Eigen::Vector2d, 4> start = truth[0].corners_px;
  for (auto& c : start) c += Eigen::Vector2d(1.2, -0.9);
  cv::Mat cells;
  cv::aruco::drawMarker(cv::aruco::getPredefinedDictionary(cv::aruco::DICT_6X6_250), m.id, 8, cells,
                        1);
  MarkerTemplateOptions options;
  options.response = CameraResponse::Gamma(2.2);
  options.search_radius_px = static_cast<double>(state.range(1));
  MarkerTemplateCache cache;
  double error = 0;
  for (auto _ : state) {
    const MarkerTemplateResult r =
        FitMarkerTemplate(img, cells, start, options, state.range(2) ? &cache : nullptr);
    error = r.ok ? (r.corners_px[0] - truth[0].corners_px[0]).norm() : -1;
    state.counters["iterations"] = r.iterations;
    state.counters["pixels"] = r.pixels;
    benchmark::DoNotOptimize(r.corners_px[0]);
  }
  state.counters["corner0_error_px"] = error;
}
BENCHMARK(BM_MarkerTemplate)
    ->ArgsProduct({{12, 18, 26}, {0, 5}, {0, 1}})
    ->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace arpos::testing

int main(int argc, char** argv) {
  bool report = false, quick = false;
  std::vector<char*> args;
  for (int i = 0; i < argc; ++i) {
    if (std::strcmp(argv[i], "--report") == 0) {
      report = true;
    } else if (std::strcmp(argv[i], "--quick") == 0) {
      quick = true;
    } else {
      args.push_back(argv[i]);
    }
  }
  if (report) arpos::testing::RunReport(quick);
  int n = static_cast<int>(args.size());
  benchmark::Initialize(&n, args.data());
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
