#include "features/response_from_recording.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <exception>
#include <map>
#include <optional>
#include <thread>

#include <opencv2/imgproc.hpp>

#include "features/edge_refinement.h"
#include "features/marker_cells.h"
#include "features/sharpening.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos {
namespace {

// The cells across one of the detector's markers, black border included.
int CellsPerSide(const MarkerDetectorOptions& detector) {
  return MarkerCells(detector.dictionary, detector.edge.border_bits).cells_per_side();
}

}  // namespace

RecordingResponse EstimateResponseFromFrames(const std::vector<ResponseFrame>& frames,
                                             const MarkerDetectorOptions& detector,
                                             const CameraResponse& fallback,
                                             const RecordingResponseOptions& options) {
  RecordingResponse out;
  out.response = fallback;
  PixelUndistorter undistorter;
  if (detector.intrinsics.has_value()) undistorter = PixelUndistorter(*detector.intrinsics);
  MarkerCells bits(detector.dictionary, detector.edge.border_bits);
  CellEdgeOptions cell_options;
  cell_options.marker_bits = bits.cells_per_side() - 2 * detector.edge.border_bits;
  cell_options.border_bits = detector.edge.border_bits;
  cell_options.quiet_zone_cells = detector.edge.quiet_zone_cells;
  const int cells = bits.cells_per_side();

  EdgeRefinementOptions edge = detector.edge;
  EdgeRefinementWorkspace workspace;
  // The camera's sharpening first: estimated on corners refined under the
  // fallback's curve, then undone around every marker for what follows.
  const CameraResponse plain_fallback = fallback.WithSharpening(0, fallback.sharpen_sigma_px());
  double amount = fallback.sharpen_amount(), sigma = fallback.sharpen_sigma_px();
  if (options.estimate_sharpening) {
    edge.response = plain_fallback;
    std::vector<std::vector<MarkerObservation>> refined(frames.size());
    std::vector<const cv::Mat*> grays;
    std::vector<const std::vector<MarkerObservation>*> lists;
    for (size_t i = 0; i < frames.size(); ++i) {
      for (MarkerObservation m : frames[i].markers) {
        ApplyRefinement(RefineMarkerCorners(frames[i].gray, m.detected_corners_px, edge, undistorter, &workspace),
                        &m);
        if (m.IsPrecise()) refined[i].push_back(m);
      }
      grays.push_back(&frames[i].gray);
      lists.push_back(&refined[i]);
    }
    out.sharpening = EstimateSharpening(grays, lists, cells, options.sharpening);
    // An earlier recording's estimate (the fallback's: the plan's, for a
    // session) is replaced only by one from profiles of full reach: with
    // shorter ones the amount scattered (a body scan's eight views at
    // +-4.6 px gave 1.8 for a true 1.0 that its plan had found as 0.9).
    std::string weaker;
    if (out.sharpening.ok && fallback.sharpened() &&
        out.sharpening.profile_half_width_px < options.sharpening.profile_half_width_px - 1e-9) {
      weaker = StringPrintf(" (this recording's own, amount %.1f from profiles of +-%.1f px, is less sure)",
                            out.sharpening.amount, out.sharpening.profile_half_width_px);
      out.sharpening.ok = false;
    }
    out.kept_sharpening_note = weaker;
    if (out.sharpening.ok) amount = out.sharpening.amount, sigma = out.sharpening.sigma_px;
  }
  std::vector<ResponseFrame> unsharpened;
  if (amount > 0) {
    for (const ResponseFrame& f : frames) {
      if (f.sharpening_only) continue;
      std::vector<cv::Rect> regions;
      for (const MarkerObservation& m : f.markers) {
        regions.push_back(MarkerReadRegion(m.detected_corners_px, cells, f.gray.size()));
      }
      ResponseFrame u;
      UndoSharpening(f.gray, regions, amount, sigma, &u.gray);
      u.markers = f.markers;
      unsharpened.push_back(std::move(u));
    }
  }
  const std::vector<ResponseFrame>& read = amount > 0 ? unsharpened : frames;
  out.response = plain_fallback.WithSharpening(amount, sigma);

  // Corners refined under the current estimate (the cell grid hangs on
  // them), boundaries collected, the response solved; twice is enough: the
  // widening depends on the corners only through the grid's placement.
  CameraResponse current = plain_fallback;
  for (int round = 0; round < options.rounds; ++round) {
    edge.response = current;
    std::vector<MarkerCellEdges> markers;
    int frames_used = 0;
    for (const ResponseFrame& f : read) {
      if (f.sharpening_only) continue;
      bool used = false;
      for (const MarkerObservation& m : f.markers) {
        const CornerRefinementResult r =
            RefineMarkerCorners(f.gray, m.detected_corners_px, edge, undistorter, &workspace);
        if (r.status != MarkerStatus::kRefined) continue;
        std::optional<MarkerCellEdges> edges = PrepareMarkerCellEdges(
            f.gray, r.corners_px, bits.Of(m.id), r.blur_sigma_px, undistorter, cell_options);
        if (!edges) continue;
        markers.push_back(std::move(*edges));
        used = true;
      }
      frames_used += used ? 1 : 0;
    }
    ResponseEstimate est = EstimateCameraResponse(markers, plain_fallback, options.estimation);
    // A later round that finds too few markers under the new curve keeps the
    // earlier round's estimate, and says that one.
    if (!est.ok && round > 0) break;
    out.frames_used = frames_used;
    out.markers_used = static_cast<int>(markers.size());
    out.estimate = est;
    if (!est.ok) break;
    const double change = est.response.MaxDifference(current);
    current = est.response;
    out.response = current.WithSharpening(amount, sigma);
    out.estimated = true;
    if (change < 0.002) break;
  }
  std::string standard_note;
  if (!out.estimated && !options.standard_curves.empty()) {
    // Every marker of the response's frames refined under each standard curve.
    std::vector<std::pair<std::string, int>> counts;
    int views = 0;
    const auto refined_under = [&](const CameraResponse& curve) {
      edge.response = curve;
      int refined = 0;
      views = 0;
      for (const ResponseFrame& f : read) {
        if (f.sharpening_only) continue;
        for (const MarkerObservation& m : f.markers) {
          ++views;
          refined +=
              RefineMarkerCorners(f.gray, m.detected_corners_px, edge, undistorter, &workspace)
                          .status == MarkerStatus::kRefined
                  ? 1
                  : 0;
        }
      }
      return refined;
    };
    const int under_fallback = refined_under(plain_fallback);
    std::string best;
    int best_count = under_fallback;
    for (const std::string& name : options.standard_curves) {
      const CameraResponse curve = CameraResponse::FromName(name);
      const int n =
          curve.MaxDifference(plain_fallback) < 1e-9 ? under_fallback : refined_under(curve);
      counts.emplace_back(name, n);
      if (n > best_count) best = name, best_count = n;
    }
    std::string list;
    for (const auto& [name, n] : counts)
      list += StringPrintf("%s%s %d", list.empty() ? "" : ", ", name.c_str(), n);
    if (!best.empty() && best_count >= options.standard_min_ratio * under_fallback &&
        best_count - under_fallback >= options.standard_min_gain) {
      out.response = CameraResponse::FromName(best).WithSharpening(amount, sigma);
      out.chosen_standard = true;
      standard_note = StringPrintf(
          "; %s chosen: the markers' edges fit it clearly better (of %d marker views, refined: %s)",
          best.c_str(), views, list.c_str());
    } else {
      standard_note = StringPrintf(
          "; no standard curve fitted the markers' edges clearly better (of %d marker views, "
          "refined: %s)",
          views, list.c_str());
    }
  }
  if (out.estimated) {
    out.message = StringPrintf("camera response %s, in %d frames", out.estimate.message.c_str(),
                               out.frames_used);
  } else if (out.chosen_standard) {
    out.message =
        StringPrintf("camera response not estimated (%s, in %d frames)%s",
                     out.estimate.message.c_str(), out.frames_used, standard_note.c_str());
  } else {
    out.message = StringPrintf("camera response not estimated (%s, in %d frames); assumed %s",
                               out.estimate.message.c_str(), out.frames_used,
                               fallback.name().c_str());
    out.message += standard_note;
  }
  if (options.estimate_sharpening && (out.sharpening.ok || amount == 0)) {
    out.message += "; " + out.sharpening.message;
  } else if (amount > 0) {
    out.message += StringPrintf("; camera sharpening kept from before (amount %.1f, radius %.1f px)%s", amount, sigma,
                                out.kept_sharpening_note.c_str());
  }
  return out;
}

RecordingResponse EstimateRecordingResponse(const Sequence& sequence,
                                            const CameraIntrinsics& intrinsics,
                                            const MarkerDetectorOptions& detector,
                                            const CameraResponse& fallback,
                                            const RecordingResponseOptions& options) {
  ARPOS_CHECK(options.max_frames > 0, "max_frames must be positive");
  ARPOS_CHECK(options.max_sharpening_frames >= 0, "max_sharpening_frames must not be negative");
  ARPOS_CHECK(options.sharpening_views_sought >= 1, "sharpening_views_sought must be at least 1");
  ARPOS_CHECK(options.response_views_sought >= 0, "response_views_sought must not be negative");
  MarkerDetectorOptions d = detector;
  d.refinement = CornerRefinementMethod::kOpenCvNone;  // refined under each round's response
  d.intrinsics = intrinsics;
  // Two readers: frames are read and searched two at a time (the colour
  // image alone; decoding and the marker search are most of the time).
  MarkerDetector det_a(d), det_b(d);
  std::vector<ResponseFrame> frames;
  const size_t n = sequence.size();
  const size_t count = std::min<size_t>(n, options.max_frames);
  // Frame i's markers, or nullopt when it cannot be read (tracking goes on
  // past such a frame and says so).
  auto read = [&](size_t i, MarkerDetector* det) -> std::optional<ResponseFrame> {
    cv::Mat colour;
    try {
      colour = sequence.LoadColour(i, intrinsics);
    } catch (const InputError&) {
      return std::nullopt;
    }
    ResponseFrame f;
    cv::cvtColor(colour, f.gray, cv::COLOR_BGR2GRAY);
    det->Detect(f.gray, &f.markers);
    return f;
  };
  // The frames `indices`, in their order.
  auto read_all = [&](const std::vector<size_t>& indices) {
    std::vector<std::optional<ResponseFrame>> out(indices.size());
    if (indices.empty()) return out;
    std::atomic<size_t> next{0};
    std::exception_ptr failure[2];
    auto work = [&](MarkerDetector* det, std::exception_ptr* failed) {
      try {
        for (size_t k; (k = next++) < indices.size();) out[k] = read(indices[k], det);
      } catch (...) {
        *failed = std::current_exception();
        next = indices.size();
      }
    };
    std::thread other(work, &det_b, &failure[1]);
    work(&det_a, &failure[0]);
    other.join();
    for (const std::exception_ptr& f : failure) {
      if (f) std::rethrow_exception(f);
    }
    return out;
  };
  std::vector<bool> done(n, false);
  {
    std::vector<size_t> evenly;
    for (size_t s = 0; s < count; ++s) {
      const size_t i = count > 1 ? s * (n - 1) / (count - 1) : 0;
      if (done[i]) continue;
      done[i] = true;
      evenly.push_back(i);
    }
    for (std::optional<ResponseFrame>& f : read_all(evenly)) {
      if (f && !f->markers.empty()) frames.push_back(std::move(*f));
    }
  }
  if (n > count) {
    // Marker views wide enough for the sharpening estimate, and for the
    // response's, counted as those estimates count them; more frames read
    // while there are too few.
    const int cells = CellsPerSide(detector);
    const double sharpening_px = SharpeningCellNeededPx(options.sharpening);
    const double response_px = CellEdgeOptions{}.min_cell_px;  // as EstimateResponseFromFrames prepares them
    auto views_of = [&](const ResponseFrame& f, double cell_px) {
      return static_cast<int>(std::count_if(f.markers.begin(), f.markers.end(), [&](const MarkerObservation& m) {
        return MarkerCellWidthPx(m, cells) >= cell_px;
      }));
    };
    int wide = 0, response_views = 0;
    for (const ResponseFrame& f : frames) {
      wide += views_of(f, sharpening_px);
      response_views += views_of(f, response_px);
    }
    const int sought = options.estimate_sharpening
                           ? options.sharpening_views_sought * SharpeningViewsNeeded(options.sharpening)
                           : 0;
    // The response's own frames are searched for only when the evenly spaced
    // ones cannot give it (their frames then join its fit; see the option).
    const int needed = options.estimation.min_markers;
    const int response_sought = response_views < needed ? options.response_views_sought * needed : 0;
    auto enough = [&] { return wide >= sought && response_views >= response_sought; };
    const size_t budget = std::min<size_t>(n, std::max<size_t>(count, options.max_sharpening_frames));
    // Spread over the sequence: positions frac(k * golden ratio), read in
    // batches; a batch's frames past the point where enough were found are
    // dropped, so the frames kept do not depend on the batch size.
    constexpr size_t kBatch = 8;
    size_t read_frames = count;
    size_t k = 1;
    while (k <= 4 * n && read_frames < budget && !enough()) {
      std::vector<size_t> batch;
      for (; k <= 4 * n && read_frames + batch.size() < budget && batch.size() < kBatch; ++k) {
        const double u = k * 0.6180339887498949;
        const size_t i = std::min(n - 1, static_cast<size_t>((u - std::floor(u)) * n));
        if (done[i]) continue;
        done[i] = true;
        batch.push_back(i);
      }
      std::vector<std::optional<ResponseFrame>> read_batch = read_all(batch);
      for (std::optional<ResponseFrame>& f : read_batch) {
        if (enough()) break;
        ++read_frames;
        if (!f) continue;
        const int w = options.estimate_sharpening ? views_of(*f, sharpening_px) : 0;
        const int r = response_views < response_sought ? views_of(*f, response_px) : 0;
        if (w == 0 && r == 0) continue;
        wide += w;
        response_views += r;
        f->sharpening_only = r == 0;
        frames.push_back(std::move(*f));
      }
    }
  }
  return EstimateResponseFromFrames(frames, detector, fallback, options);
}

RecordingResponse EstimateRecordingResponse(const Sequence& sequence, const CaseConfig& config,
                                            const CameraResponse& fallback,
                                            const RecordingResponseOptions& options) {
  MarkerDetectorOptions detector;
  detector.dictionary = config.dictionary;
  detector.id_ranges = {{config.room_markers.id_min, config.room_markers.id_max},
                        {config.body_markers.id_min, config.body_markers.id_max}};
  detector.intrinsics = config.camera;
  return EstimateRecordingResponse(sequence, config.camera, detector, fallback, options);
}

}  // namespace arpos
