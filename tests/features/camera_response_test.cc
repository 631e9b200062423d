// Camera response: the table types, and its estimation from marker edges on
// synthetic renders with known tone curves (tests/features/marker_render.h,
// independent of src/simulation).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>

#include <unistd.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "features/camera_response.h"
#include "features/edge_refinement.h"
#include "features/marker_detector.h"
#include "features/marker_render.h"
#include "features/response_from_recording.h"
#include "features/sharpening.h"
#include "sensor/sequence.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos::testing {
namespace {

double SrgbEncode(double x) {
  return x <= 0.0031308 ? 12.92 * x : 1.055 * std::pow(x, 1 / 2.4) - 0.055;
}

/// A consumer-style S curve: sRGB, then more contrast in the mid-tones.
double SCurveEncode(double x) {
  const double y = SrgbEncode(x);
  return y - 0.45 * std::sin(2 * M_PI * y) / (2 * M_PI);
}

struct Curve {
  const char* name;
  std::function<double(double)> encode;
};

std::vector<Curve> Curves() {
  return {{"linear", [](double x) { return x; }},
          {"srgb", SrgbEncode},
          {"gamma2.6", [](double x) { return std::pow(x, 1 / 2.6); }},
          {"scurve", SCurveEncode}};
}

/// A small "recording": frames of several markers each, at random sizes,
/// tilts, blur, and exposure (the printed black and white levels vary as
/// under auto exposure and uneven light).
struct Recording {
  std::vector<ResponseFrame> frames;
  std::vector<std::vector<MarkerTruth>> truth;  // per frame, matching the detections by id
};

Recording Render(const std::function<double(double)>& encode, int frames, unsigned seed,
                 double sharpen = 0, double noise_grey = 1.5, double min_side_px = 28,
                 double max_side_px = 90, double exposure_scale = 1.0) {
  Recording rec;
  std::mt19937 rng(seed);
  const CameraIntrinsics cam = VgaCamera();
  std::uniform_real_distribution<double> blur(0.5, 1.2), exposure(0.6, 1.2);
  MarkerDetectorOptions detector;
  detector.refinement = CornerRefinementMethod::kOpenCvNone;
  detector.id_ranges = {{0, 249}};
  for (int f = 0; f < frames; ++f) {
    RenderOptions render;
    render.encode = encode;
    render.blur_sigma_px = blur(rng);
    render.noise_sigma_grey = noise_grey;
    render.sharpen_amount = sharpen;
    std::vector<MarkerPlacement> placements =
        RandomPlacements(cam, 6, min_side_px, max_side_px, 55, 0.1, 10 * f, &rng);
    const double e = exposure_scale * exposure(rng);
    if (exposure_scale != 1.0) {  // a dark scene: the background too
      render.textured_background = false;
      render.background_grey = 255 * encode(0.3 * e);
    }
    for (MarkerPlacement& p : placements) {
      // Levels given as they appear in a linear image, then encoded: black ink
      // reflects ~4 %, white paper ~80 %, times the exposure (marker_render
      // decodes the levels with `encode`).
      p.black_grey = 255 * encode(0.04 * e);
      p.white_grey = 255 * encode(std::min(1.0, 0.8 * e));
    }
    std::vector<MarkerTruth> truth;
    ResponseFrame frame;
    frame.gray = RenderMarkers(cam, placements, render, &rng, &truth);
    frame.markers = MarkerDetector(detector).Detect(frame.gray);
    rec.frames.push_back(std::move(frame));
    rec.truth.push_back(truth);
  }
  return rec;
}

/// Mean signed corner offset from the marker centre relative to the truth
/// (px; positive = the marker looks too large), refining under `response`;
/// `median_px` gets the median corner error.
double CornerScaleBiasPx(const Recording& rec, const CameraResponse& response, int* count,
                         double* median_px = nullptr) {
  EdgeRefinementOptions options;
  options.response = response;
  double sum = 0;
  int n = 0;
  std::vector<double> errors;
  for (size_t f = 0; f < rec.frames.size(); ++f) {
    for (const MarkerObservation& m : rec.frames[f].markers) {
      for (const MarkerTruth& t : rec.truth[f]) {
        if (t.id != m.id) continue;
        const CornerRefinementResult r =
            RefineMarkerCorners(rec.frames[f].gray, m.detected_corners_px, options);
        if (r.status != MarkerStatus::kRefined) continue;
        for (int k = 0; k < 4; ++k) {
          const Eigen::Vector2d radial = (t.corners_px[k] - t.centre_px).normalized();
          sum += radial.dot(r.corners_px[k] - t.corners_px[k]);
          errors.push_back((r.corners_px[k] - t.corners_px[k]).norm());
          ++n;
        }
      }
    }
  }
  *count = n;
  if (median_px != nullptr && !errors.empty()) {
    std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
    *median_px = errors[errors.size() / 2];
  }
  return n > 0 ? sum / n : 0;
}

TEST(CameraResponse, TablesAndNames) {
  EXPECT_EQ(CameraResponse::Linear().Linearize(128), 128);
  EXPECT_NEAR(CameraResponse::Srgb().LinearFraction(128), 0.2158605, 1e-6);
  EXPECT_NEAR(CameraResponse::Gamma(2.6).LinearFraction(128), std::pow(128 / 255.0, 2.6), 1e-12);
  EXPECT_EQ(CameraResponse::FromName("srgb").name(), "srgb");
  EXPECT_NEAR(CameraResponse::FromName("gamma2.2").LinearFraction(64), std::pow(64 / 255.0, 2.2),
              1e-12);
  EXPECT_THROW(CameraResponse::FromName("sepia"), InputError);
  EXPECT_THROW(CameraResponse::FromName("gamma"), InputError);
  EXPECT_THROW(CameraResponse::Gamma(0), InputError);

  const CameraResponse s = CameraResponse::Srgb();
  const CameraResponse back = CameraResponse::Parse(s.Serialize(), "test");
  EXPECT_EQ(back.name(), "srgb");
  EXPECT_LT(back.MaxDifference(s), 1e-6);
  EXPECT_THROW(CameraResponse::Parse("srgb: 1 2 3", "plan 4"), InputError);
  EXPECT_THROW(CameraResponse::Parse("no colon", "plan 4"), InputError);
  std::array<double, 256> decreasing{};
  for (int v = 0; v < 256; ++v) decreasing[v] = 255 - v;
  EXPECT_THROW(CameraResponse::FromTable(decreasing), InputError);
  std::array<double, 256> nan{};
  for (int v = 0; v < 256; ++v) nan[v] = v;
  nan[7] = std::nan("");
  try {
    CameraResponse::FromTable(nan, "x");
    FAIL() << "a NaN table was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("code 7"), std::string::npos) << e.what();
  }
}

// The estimate makes corners unbiased whatever the tone curve, starting from
// the sRGB assumption; assuming sRGB instead leaves them biased by tenths of
// a pixel on the curves that are not sRGB.
TEST(CameraResponse, EstimatedFromMarkerEdgesForEachToneCurve) {
  unsigned seed = 11;
  for (const Curve& curve : Curves()) {
    const Recording rec = Render(curve.encode, 10, seed++);
    MarkerDetectorOptions detector;
    const RecordingResponse est =
        EstimateResponseFromFrames(rec.frames, detector, CameraResponse::Srgb());
    ASSERT_TRUE(est.estimated) << curve.name << ": " << est.message;
    int n_assumed = 0, n_est = 0, n_true = 0;
    const double assumed = CornerScaleBiasPx(rec, CameraResponse::Srgb(), &n_assumed);
    const double estimated = CornerScaleBiasPx(rec, est.response, &n_est);
    const double truth = CornerScaleBiasPx(rec, ResponseOfEncoding(curve.encode), &n_true);
    std::printf(
        "%-9s corner scale bias: sRGB assumed %+.3f px, estimated %+.3f px, true curve %+.3f px "
        "(%d corners); %s\n",
        curve.name, assumed, estimated, truth, n_est, est.message.c_str());
    EXPECT_GT(n_est, 100) << curve.name;
    EXPECT_FALSE(est.response.sharpened()) << curve.name << ": " << est.message;
    EXPECT_LT(std::abs(estimated), 0.04) << curve.name;
    EXPECT_LT(std::abs(estimated - truth), 0.03) << curve.name;
    if (std::string(curve.name) == "linear" || std::string(curve.name) == "gamma2.6") {
      EXPECT_GT(std::abs(assumed), 0.08) << curve.name << ": the test would not tell";
    }
  }
}

TEST(CameraResponse, SharpeningIsStoredWithTheCurve) {
  const CameraResponse s = CameraResponse::Gamma(2.6).WithSharpening(0.8, 1.0);
  const std::string text = s.Serialize();
  EXPECT_NE(text.find(" sharpen 0.8000 1.0000"), std::string::npos) << text.substr(text.size() - 40);
  const CameraResponse back = CameraResponse::Parse(text, "plan 4");
  EXPECT_TRUE(back.sharpened());
  EXPECT_DOUBLE_EQ(back.sharpen_amount(), 0.8);
  EXPECT_DOUBLE_EQ(back.sharpen_sigma_px(), 1.0);
  EXPECT_LT(back.MaxDifference(s), 1e-6);
  EXPECT_FALSE(CameraResponse::Parse(CameraResponse::Srgb().Serialize(), "plan 4").sharpened());
  const std::string table = CameraResponse::Srgb().Serialize();
  EXPECT_THROW(CameraResponse::Parse(table + " sharpen 0.5", "plan 4"), InputError);
  EXPECT_THROW(CameraResponse::Parse(table + " sharpen 0.5 1 7", "plan 4"), InputError);
  EXPECT_THROW(CameraResponse::Parse(table + " sharpen 9 1", "plan 4"), InputError);
  EXPECT_THROW(CameraResponse::Parse(table + " sharpen -0.5 1", "plan 4"), InputError);
  EXPECT_THROW(CameraResponse::Parse(table + " blur 0.5 1", "plan 4"), InputError);
  EXPECT_THROW(CameraResponse::Srgb().WithSharpening(-0.1, 1), InputError);
  EXPECT_THROW(CameraResponse::Srgb().WithSharpening(1, 0.1), InputError);
}

// Undoing the camera's unsharp mask gives back the codes before it where the
// markers are read (noise-free renders of the same markers).
TEST(Sharpening, UndoneWhereTheMarkersAreRead) {
  const Recording plain = Render(SrgbEncode, 3, 21, 0, 0);
  const Recording sharp = Render(SrgbEncode, 3, 21, 1.0, 0);
  const int cells = 6;  // DICT_4X4: 4 bits and a border on each side
  int compared = 0;
  for (size_t f = 0; f < plain.frames.size(); ++f) {
    std::vector<cv::Rect> regions;
    for (const MarkerTruth& t : plain.truth[f]) {
      regions.push_back(MarkerReadRegion(t.corners_px, cells, plain.frames[f].gray.size()));
    }
    cv::Mat undone;
    UndoSharpening(sharp.frames[f].gray, regions, 1.0, 1.0, &undone);
    cv::Mat before_diff, after_diff;
    for (const cv::Rect& r : regions) {
      cv::absdiff(sharp.frames[f].gray(r), plain.frames[f].gray(r), before_diff);
      cv::absdiff(undone(r), plain.frames[f].gray(r), after_diff);
      double before = 0, after = 0;
      cv::minMaxLoc(before_diff, nullptr, &before);
      cv::minMaxLoc(after_diff, nullptr, &after);
      EXPECT_GT(before, 8) << "frame " << f << ": the mask left no halo to undo";
      EXPECT_LE(after, 2) << "frame " << f;
      ++compared;
    }
  }
  EXPECT_GE(compared, 10);
}

// A camera that sharpens: the amount is found from the markers' edges and
// undone, and its corners are as unbiased as an unsharpened camera's; read
// without undoing it (the response estimate alone absorbs part of the halo
// as a steeper curve) they are not.
TEST(Sharpening, FoundFromTheMarkersAndUndone) {
  const Recording rec = Render(SrgbEncode, 12, 31, 1.0);
  MarkerDetectorOptions detector;
  const RecordingResponse est = EstimateResponseFromFrames(rec.frames, detector, CameraResponse::Srgb());
  ASSERT_TRUE(est.estimated) << est.message;
  ASSERT_TRUE(est.sharpening.ok) << est.sharpening.message;
  EXPECT_NEAR(est.response.sharpen_amount(), 1.0, 0.3) << est.message;
  EXPECT_NE(est.message.find("camera sharpening estimated"), std::string::npos) << est.message;
  RecordingResponseOptions without;
  without.estimate_sharpening = false;
  const RecordingResponse blind =
      EstimateResponseFromFrames(rec.frames, detector, CameraResponse::Srgb(), without);
  EXPECT_FALSE(blind.response.sharpened());
  int n_est = 0, n_blind = 0;
  double undone_median = 0, left_median = 0;
  const double undone = CornerScaleBiasPx(rec, est.response, &n_est, &undone_median);
  const double left = CornerScaleBiasPx(rec, blind.response, &n_blind, &left_median);
  std::printf(
      "sharpened camera: corners %.3f px median off (scale bias %+.3f px) undone, %.3f px (%+.3f px) read as "
      "delivered (%d corners); %s\n",
      undone_median, undone, left_median, left, n_est, est.message.c_str());
  EXPECT_GT(n_est, 100);
  EXPECT_LT(std::abs(undone), 0.03);
  EXPECT_LT(undone_median, 0.03);
  EXPECT_GT(left_median, 1.5 * undone_median + 0.01) << "the test would not tell";
}

// A recording folder (rgb/, depth/ with empty depth, the lists) of n frames,
// frame f rendered by `gray_of(f)` at 15 fps; removed when it goes out of scope.
struct RecordingFolder {
  std::filesystem::path dir;
  RecordingFolder(const std::string& name, int n, const CameraIntrinsics& cam,
                  const std::function<cv::Mat(int)>& gray_of) {
    namespace fs = std::filesystem;
    dir = fs::temp_directory_path() / (name + "_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir / "rgb");
    fs::create_directories(dir / "depth");
    std::ofstream rgb(dir / "rgb.txt"), depth(dir / "depth.txt");
    const cv::Mat no_depth = cv::Mat::zeros(cam.height, cam.width, CV_16UC1);
    for (int f = 0; f < n; ++f) {
      cv::Mat bgr;
      cv::cvtColor(gray_of(f), bgr, cv::COLOR_GRAY2BGR);
      const std::string stamp = StringPrintf("%.6f", 1.0 + f / 15.0);
      cv::imwrite((dir / "rgb" / (stamp + ".png")).string(), bgr);
      cv::imwrite((dir / "depth" / (stamp + ".png")).string(), no_depth);
      rgb << stamp << " rgb/" << stamp << ".png\n";
      depth << stamp << " depth/" << stamp << ".png\n";
    }
  }
  ~RecordingFolder() { std::filesystem::remove_all(dir); }
};

// EstimateRecordingResponse on a RecordingFolder, ids 0-249, sRGB fallback.
RecordingResponse EstimateOnFolder(const RecordingFolder& recording, const CameraIntrinsics& cam,
                                   const RecordingResponseOptions& options) {
  MarkerDetectorOptions detector;
  detector.id_ranges = {{0, 249}};
  return EstimateRecordingResponse(Sequence::Open(recording.dir), cam, detector, CameraResponse::Srgb(), options);
}

// Frame f of a recording whose markers are small except in frames f % 7 == 4
// (none of 4 evenly spaced frames over 30): six markers of sides
// [small_min, small_max] px (tilted up to small_tilt_deg) or [large_min,
// large_max] px, printed black and white at those linear levels.
cv::Mat MixedSizeFrame(const CameraIntrinsics& cam, int f, const RenderOptions& render, double small_min,
                       double small_max, double small_tilt_deg, double large_min, double large_max, double black,
                       double white, std::mt19937* rng) {
  std::vector<MarkerPlacement> placements =
      f % 7 == 4 ? RandomPlacements(cam, 6, large_min, large_max, 45, 0.1, 6 * (f % 40), rng)
                 : RandomPlacements(cam, 6, small_min, small_max, small_tilt_deg, 0.1, 6 * (f % 40), rng);
  for (MarkerPlacement& p : placements) {
    p.black_grey = 255 * render.encode(black);
    p.white_grey = 255 * render.encode(white);
  }
  std::vector<MarkerTruth> truth;
  return RenderMarkers(cam, placements, render, rng, &truth);
}

// A recording whose evenly spaced frames show only small markers (cells of
// 4-6 px, too narrow for the sharpening estimate) and whose other frames,
// here and there, show large ones: the recording is searched further for
// those, and the sharpening found; without that search it is not.
TEST(Sharpening, ARecordingIsSearchedForMarkersWideEnough) {
  const CameraIntrinsics cam = VgaCamera();
  std::mt19937 rng(41);
  RenderOptions render;
  render.encode = SrgbEncode;
  render.blur_sigma_px = 0.8;
  render.noise_sigma_grey = 1.5;
  render.sharpen_amount = 1.0;
  const RecordingFolder recording("arpos_sharpening_search", 30, cam, [&](int f) {
    return MixedSizeFrame(cam, f, render, 26, 36, 45, 60, 90, 0.04, 0.8, &rng);
  });
  RecordingResponseOptions options;
  options.max_frames = 4;
  const RecordingResponse searched = EstimateOnFolder(recording, cam, options);
  options.max_sharpening_frames = 0;
  const RecordingResponse evenly = EstimateOnFolder(recording, cam, options);
  std::printf("4 evenly spaced frames: %s\nsearched further: %s\n", evenly.message.c_str(), searched.message.c_str());
  EXPECT_FALSE(evenly.sharpening.ok) << evenly.message;
  ASSERT_TRUE(searched.sharpening.ok) << searched.message;
  EXPECT_NEAR(searched.response.sharpen_amount(), 1.0, 0.3) << searched.message;
  EXPECT_EQ(searched.frames_used, evenly.frames_used) << "the response keeps to the evenly spaced frames";
}

// A linear camera whose evenly spaced frames show markers too small for
// the response (cells of 2.5-3.5 px) while other frames, here and there,
// show larger ones: the recording is searched further for those, they join
// the response's fit, and the response is found (not the sRGB fallback);
// without that search it is not estimated.
TEST(CameraResponse, ARecordingIsSearchedForMarkersLargeEnough) {
  const CameraIntrinsics cam = VgaCamera();
  std::mt19937 rng(43);
  const auto linear = [](double x) { return x; };
  RenderOptions render;
  render.encode = linear;
  render.blur_sigma_px = 0.8;
  render.noise_sigma_grey = 1.0;
  const RecordingFolder recording("arpos_response_search", 30, cam, [&](int f) {
    return MixedSizeFrame(cam, f, render, 15, 21, 30, 34, 48, 0.04, 0.8, &rng);
  });
  RecordingResponseOptions options;
  options.max_frames = 4;
  options.estimate_sharpening = false;
  const RecordingResponse searched = EstimateOnFolder(recording, cam, options);
  options.response_views_sought = 0;
  const RecordingResponse evenly = EstimateOnFolder(recording, cam, options);
  std::printf("4 evenly spaced frames: %s\nsearched further: %s\n", evenly.message.c_str(), searched.message.c_str());
  EXPECT_FALSE(evenly.estimated) << evenly.message;
  ASSERT_TRUE(searched.estimated) << searched.message;
  EXPECT_GT(searched.frames_used, 0);
  // The corners' bias (the black widening) gone under the estimate, and
  // the curve nearer the linear truth than the fallback.
  EXPECT_GT(searched.estimate.widening_prior_px, 0.3) << searched.message;
  EXPECT_LT(std::abs(searched.estimate.widening_px), 0.05) << searched.message;
  double to_linear = 0, fallback_to_linear = 0;
  for (int code = 10; code <= 245; code += 5) {
    to_linear = std::max(to_linear, std::abs(searched.response.LinearFraction(code) - code / 255.0));
    fallback_to_linear =
        std::max(fallback_to_linear, std::abs(CameraResponse::Srgb().LinearFraction(code) - code / 255.0));
  }
  EXPECT_LT(to_linear, 0.8 * fallback_to_linear) << to_linear << " against " << fallback_to_linear;
}

// An earlier recording's sharpening (the plan's, passed as the fallback) is
// replaced by this recording's own estimate only when that comes from
// profiles of full reach; markers whose cells allow shorter ones keep it.
TEST(Sharpening, AnEarlierEstimateIsReplacedOnlyByOneOfFullReach) {
  MarkerDetectorOptions detector;
  const CameraResponse plan = CameraResponse::Srgb().WithSharpening(0.6, 1.0);
  // Cells of 7.7-8.3 px (sides 46-50 px, 6 cells): profiles of +-4.6-5.0 px.
  const Recording narrow = Render(SrgbEncode, 6, 51, 1.0, 1.5, 46, 50);
  const RecordingResponse kept = EstimateResponseFromFrames(narrow.frames, detector, plan);
  EXPECT_NEAR(kept.response.sharpen_amount(), 0.6, 1e-9) << kept.message;
  EXPECT_NE(kept.message.find("kept from before"), std::string::npos) << kept.message;
  EXPECT_NE(kept.message.find("less sure"), std::string::npos) << kept.message;
  // With no earlier estimate the same frames give their own.
  const RecordingResponse own = EstimateResponseFromFrames(narrow.frames, detector, CameraResponse::Srgb());
  EXPECT_TRUE(own.sharpening.ok) << own.message;
  EXPECT_GT(own.response.sharpen_amount(), 0) << own.message;
  // Wide cells: the earlier estimate is replaced.
  const Recording wide = Render(SrgbEncode, 12, 31, 1.0);
  const RecordingResponse replaced = EstimateResponseFromFrames(wide.frames, detector, plan);
  ASSERT_TRUE(replaced.sharpening.ok) << replaced.message;
  EXPECT_NEAR(replaced.response.sharpen_amount(), 1.0, 0.3) << replaced.message;
  std::printf("narrow cells, plan's 0.6 given: %s\nwide cells, plan's 0.6 given: %s\n", kept.message.c_str(),
              replaced.message.c_str());
}

TEST(Sharpening, EdgesWhoseHaloIsClippedAreLeftOut) {
  // A dark linear camera that sharpens by 0.8: black ink at 3-6 codes, the
  // halo's dark side cut off at 0 on many edges. Those edges are left out
  // and the rest give the amount. (This renderer's clipped edges happen to
  // give about the same amount; the simulator's, black at 0 over whole
  // cells, gave 2.3 for a true 0.8: accuracy.md, session 39.)
  const auto linear = [](double x) { return x; };
  const Recording rec = Render(linear, 12, 61, 0.8, 1.5, 28, 90, 0.5);
  MarkerDetectorOptions detector;
  const RecordingResponse est =
      EstimateResponseFromFrames(rec.frames, detector, CameraResponse::Linear());
  RecordingResponseOptions all_edges;
  all_edges.sharpening.max_clipped_fraction = 1.0;
  const RecordingResponse with_clipped =
      EstimateResponseFromFrames(rec.frames, detector, CameraResponse::Linear(), all_edges);
  std::printf("clipped edges left out: %s\nclipped edges used: %s\n",
              est.sharpening.message.c_str(), with_clipped.sharpening.message.c_str());
  ASSERT_TRUE(est.sharpening.ok) << est.message;
  EXPECT_NEAR(est.sharpening.amount, 0.8, 0.3) << est.message;
  EXPECT_LT(est.sharpening.edges_used, with_clipped.sharpening.edges_used - 20);
}

TEST(CameraResponse, FallsBackWhenTheDataCannotTell) {
  // Two frames with one marker each: too few edges to estimate.
  Recording rec = Render([](double x) { return x; }, 2, 5);
  for (ResponseFrame& f : rec.frames) f.markers.resize(std::min<size_t>(1, f.markers.size()));
  MarkerDetectorOptions detector;
  const RecordingResponse est =
      EstimateResponseFromFrames(rec.frames, detector, CameraResponse::Gamma(2.2));
  EXPECT_FALSE(est.estimated);
  EXPECT_EQ(est.response.name(), "gamma2.20");
  EXPECT_NE(est.message.find("not estimated"), std::string::npos) << est.message;
}

TEST(CameraResponse, WithNoMarkerLargeEnoughTheStandardCurveTheEdgesFitIsChosen) {
  // Small markers (cells under 4 px: nothing to estimate from), rendered
  // linear or sRGB; the fallback is sRGB, the plan's standard curves tried.
  RecordingResponseOptions options;
  options.standard_curves = {"linear", "gamma1.6", "srgb", "gamma2.6"};
  MarkerDetectorOptions detector;
  for (const bool linear : {true, false}) {
    SCOPED_TRACE(linear ? "linear camera" : "sRGB camera");
    Recording rec = linear ? Render([](double x) { return x; }, 24, 11, 0, 0.5, 14, 22, 0.2)
                           : Render(SrgbEncode, 24, 11, 0, 0.5, 14, 22, 0.2);
    const RecordingResponse est =
        EstimateResponseFromFrames(rec.frames, detector, CameraResponse::Srgb(), options);
    EXPECT_FALSE(est.estimated);
    EXPECT_EQ(est.chosen_standard, linear) << est.message;
    EXPECT_EQ(est.response.name(), linear ? "linear" : "srgb") << est.message;
    // Without standard curves (a session's, a tracking run's) the fallback stays.
    const RecordingResponse kept =
        EstimateResponseFromFrames(rec.frames, detector, CameraResponse::Srgb());
    EXPECT_FALSE(kept.chosen_standard);
    EXPECT_EQ(kept.response.name(), "srgb");
  }
}

TEST(CameraResponse, AnEstimateIsKeptAndSaidWhenALaterRoundFindsTooFewMarkers) {
  // Estimated in the first round from the few markers large enough; refined
  // under the estimate, fewer of them qualify in the second: the first
  // round's estimate is returned and its message says so (it said the
  // second's "3 markers large enough, 6 needed").
  const Recording rec = Render([](double x) { return x; }, 24, 21, 0, 0.5, 14, 24);
  const RecordingResponse est =
      EstimateResponseFromFrames(rec.frames, MarkerDetectorOptions(), CameraResponse::Srgb());
  ASSERT_TRUE(est.estimated) << est.message;
  EXPECT_EQ(est.message.rfind("camera response estimated from", 0), 0u) << est.message;
  EXPECT_LT(est.response.MaxDifference(CameraResponse::Linear(), 16, 240),
            est.response.MaxDifference(CameraResponse::Srgb(), 16, 240))
      << est.message;
}

}  // namespace
}  // namespace arpos::testing
