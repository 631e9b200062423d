#pragma once
/// The camera response of a recording, estimated from the markers it shows
/// (camera_response.h explains the method).
///
/// A few dozen frames spread over the sequence are searched for markers of
/// the given id ranges (room markers and body stickers alike: every printed
/// marker is the same reference), and more frames when they hold too few
/// marker views wide enough for the sharpening estimate (sharpening.h) or,
/// for the response itself, too few large enough;
/// each large enough marker gives its
/// midpoint code, and the response is fitted to all of them, alternating
/// with re-refining the corners under the new estimate. When the data cannot
/// tell (too few markers large enough), `fallback` is returned with
/// `estimated == false` and a message saying so.

#include <string>
#include <vector>

#include "features/camera_response.h"
#include "features/marker_detector.h"
#include "features/sharpening.h"
#include "sensor/case_config.h"
#include "sensor/intrinsics.h"
#include "sensor/sequence.h"

namespace arpos {

struct RecordingResponseOptions {
  int max_frames = 40;  ///< frames sampled evenly over the sequence
  int rounds = 2;       ///< refine / estimate alternations (at most)
  ResponseEstimationOptions estimation;
  /// The camera's sharpening (sharpening.h) is estimated first and undone
  /// before the response is; off: the fallback's sharpening is kept.
  bool estimate_sharpening = true;
  SharpeningEstimationOptions sharpening;
  /// The sharpening estimate needs marker views with wide cells, which
  /// max_frames evenly spaced frames may miss (a 300-frame xtion room
  /// recording: 7 of the 8 needed in its 40 frames): more frames, spread
  /// over the sequence, are searched for such views until there are enough
  /// or this many frames have been read in all; the frames that hold one
  /// join the sharpening estimate, not the response's: a response fitted on
  /// them too moved a tracking sequence's own estimate (11 markers, drawn
  /// to the plan's curve) from gamma 2.3 to 2.0 and its MRE from 0.06 to
  /// 0.17 deg (EstimateRecordingResponse).
  int max_sharpening_frames = 160;
  /// ... and the search goes on until it has this many times the views the
  /// estimate needs: with barely enough views (eight 8 px-cell views of an
  /// xtion walk) amounts of 1.3-1.9 were found for a true 1.0.
  int sharpening_views_sought = 4;
  /// When the evenly spaced frames hold fewer marker views large enough for
  /// the response than it needs (estimation.min_markers), the same search
  /// looks for this many times that number, and the frames that hold such a
  /// view join the response's fit (a 150-frame xtion room walk with a
  /// sharpening gamma-2.6 camera: 4 of the 6 needed in 40 frames; the plan
  /// assumed sRGB, its corners read 0.2 px wide, and the depth check took
  /// the markers' size for the truth: the map 1.2 % small, 25 mm off at the
  /// couch). Only then: see max_sharpening_frames for why not always.
  int response_views_sought = 2;
  /// When the response cannot be estimated (no marker views with cells wide
  /// enough) the fallback is an assumption. These standard curves are then
  /// put to the markers there are: each marker's edges refined under each
  /// curve, and a curve under which clearly more of them fit a blurred step
  /// (at least `standard_min_ratio` times and `standard_min_gain` more than
  /// under the fallback) replaces it. Under a wrong curve a step's two sides
  /// are bent unequally and small markers' edges stop fitting: a dark, linear
  /// xtion recording read as sRGB had 14 of 40 marker views refined, 32 as
  /// linear, and its plan lost a marker beside the couch; on recordings whose
  /// response the cells did tell, the counts under the four curves stayed
  /// within 1.3x of each other. Empty (the default): the fallback is kept,
  /// as it is for a recording whose fallback is an earlier recording's
  /// estimate (a session's, a tracking run's).
  std::vector<std::string> standard_curves;
  double standard_min_ratio = 1.5;
  int standard_min_gain = 8;
};

struct RecordingResponse {
  CameraResponse response;
  bool estimated = false;  ///< false: `response` is the fallback
  ResponseEstimate estimate;  ///< the last round's figures
  SharpeningEstimate sharpening;  ///< ok == false: the fallback's sharpening kept
  /// Why this recording's own estimate did not replace the fallback's, when
  /// it was made but from shorter profiles (empty otherwise).
  std::string kept_sharpening_note;
  /// Not estimated, and a standard curve fitted the markers' edges clearly
  /// better than the fallback (RecordingResponseOptions::standard_curves):
  /// `response` is that curve.
  bool chosen_standard = false;
  int frames_used = 0;
  int markers_used = 0;
  std::string message;  ///< one line for people
};

/// Frames with their marker detections (any refinement: the detected
/// corners are refined again here).
struct ResponseFrame {
  cv::Mat gray;  ///< CV_8UC1, the camera's codes
  std::vector<MarkerObservation> markers;
  /// Read for its wide marker views only: used by the sharpening estimate,
  /// not by the response's (which keeps to the evenly spaced frames and
  /// those its own search found: RecordingResponseOptions).
  bool sharpening_only = false;
};

/// Pure estimation on given frames. `detector` supplies the edge options and
/// intrinsics (for lens distortion).
RecordingResponse EstimateResponseFromFrames(const std::vector<ResponseFrame>& frames,
                                             const MarkerDetectorOptions& detector,
                                             const CameraResponse& fallback,
                                             const RecordingResponseOptions& options = {});

/// Samples `sequence`, detects markers of `detector.id_ranges` and estimates.
/// Throws what loading a frame throws (InputError naming the file).
RecordingResponse EstimateRecordingResponse(const Sequence& sequence,
                                            const CameraIntrinsics& intrinsics,
                                            const MarkerDetectorOptions& detector,
                                            const CameraResponse& fallback,
                                            const RecordingResponseOptions& options = {});

/// For a case's recording: markers of both the room and the body id ranges
/// of `config`, its intrinsics.
RecordingResponse EstimateRecordingResponse(const Sequence& sequence, const CaseConfig& config,
                                            const CameraResponse& fallback,
                                            const RecordingResponseOptions& options = {});

}  // namespace arpos
