#pragma once
/// How right the couch corrections of a tracking run are: the rows of
/// corrections.csv (DATASET.md, "Outputs of tracking") against the true
/// correction, computed from the true model pose (body_groundtruth.txt) and
/// the planned pose (target_pose.txt) with the same ComputeCouchCorrection the
/// tracker uses (feedback/couch_correction.h).
///
/// - Association: each row is paired with a ground-truth frame within
///   `max_difference_s` (the TUM rule of `arpos evaluate`, AssociateTimestamps);
///   no interpolation. Rows of every state take part: a `lost` row is a frame.
/// - Truly in: the true correction is within both tolerances (no uncertainty
///   is added to the truth: ComputeCouchCorrection with a zero bound).
/// - Errors (reported minus true, frames reported `in` or `out` only), in
///   couch axes: |lateral|, |longitudinal|, |vertical| in mm, |pitch|, |roll|,
///   |yaw| in degrees; `translation_mm` is the length of the error of the
///   shift vector; `rotation_deg` the angle between the reported turn and the
///   true one (the turn whose rotation vector is (pitch, roll, yaw) about
///   (lateral, longitudinal, vertical)).
/// - Safety: a frame reported `in` while truly out must not happen
///   (DATASET.md); each one is listed. Frames reported `out` while truly in
///   are the price of the uncertainty bound: counted.
///
/// Pure functions; no I/O but the reader. Thread-compatible.

#include <filesystem>
#include <istream>
#include <string>
#include <vector>

#include "eval/trajectory_eval.h"
#include "feedback/couch_correction.h"
#include "geometry/rigid3.h"
#include "sensor/tum_io.h"

namespace arpos {

/// One row of corrections.csv as written (CorrectionsCsvRow). The numbers are
/// meaningful only when `state` is not lost (a lost row has them empty).
struct CorrectionRow {
  double timestamp_s = 0;
  double lateral_mm = 0, longitudinal_mm = 0, vertical_mm = 0;
  double pitch_deg = 0, roll_deg = 0, yaw_deg = 0;
  double translation_mm = 0;  ///< length of the shift, as reported
  double rotation_deg = 0;    ///< angle of the turn, as reported
  CorrectionState state = CorrectionState::kLost;
  int line = 0;  ///< 1-based line in the file, for messages
};

/// Reads corrections.csv: the header line of DATASET.md (exactly those
/// columns, in that order), then one row per frame; blank lines are skipped
/// and a trailing '\r' is ignored. A row has 10 fields: a finite timestamp,
/// for `in`/`out` eight finite numbers, for `lost` eight empty fields, and the
/// state `in`, `out` or `lost`. Throws InputError naming `source` and the line
/// (and the column) for anything else, and for a file with no header.
std::vector<CorrectionRow> ParseCorrectionsCsv(std::istream& in, const std::string& source);
/// The same from a file; InputError names the file when it cannot be read.
std::vector<CorrectionRow> ReadCorrectionsCsv(const std::filesystem::path& path);

struct CorrectionEvaluationOptions {
  CouchTolerances tolerances;  ///< what "truly in" means (default 2 mm, 1 deg)
  double max_difference_s = kEvaluationAssociationS;
};

/// One row matched to ground truth.
struct CorrectionFrame {
  double timestamp_s = 0;  ///< of the row
  int line = 0;            ///< of the row in corrections.csv
  CorrectionState reported = CorrectionState::kLost;
  CouchCorrection truth;   ///< state kIn / kOut: truly in or out
  /// |reported - true| per couch axis (mm, deg) and the magnitudes (see the
  /// file comment); zero for a lost row.
  double lateral_mm = 0, longitudinal_mm = 0, vertical_mm = 0;
  double pitch_deg = 0, roll_deg = 0, yaw_deg = 0;
  double translation_mm = 0, rotation_deg = 0;
  double reported_translation_mm = 0, reported_rotation_deg = 0;
  bool truly_in() const { return truth.state == CorrectionState::kIn; }
};

struct CorrectionEvaluation {
  CouchTolerances tolerances;
  int rows = 0;                  ///< rows of corrections.csv
  int ground_truth_frames = 0;
  int matched_frames = 0;        ///< rows paired with a ground-truth frame
  int rows_without_truth = 0;    ///< rows with no ground truth near them (ignored)
  int truth_without_row = 0;     ///< ground-truth frames no row reports
  /// States of the matched rows as reported.
  int reported_in = 0, reported_out = 0, reported_lost = 0;
  /// Matched frames whose true correction is within / beyond the tolerances.
  int truly_in = 0, truly_out = 0;
  /// The safety figure: reported `in` while truly out (must be 0).
  int in_while_out = 0;
  int out_while_in = 0;          ///< reported `out` while truly in
  /// Errors over the frames reported in or out (reported_in + reported_out).
  ErrorStats lateral_mm, longitudinal_mm, vertical_mm;
  ErrorStats pitch_deg, roll_deg, yaw_deg;
  ErrorStats translation_mm, rotation_deg;
  std::vector<CorrectionFrame> frames;  ///< matched rows, in file order

  /// False when no row reporting a correction (in or out) matched a
  /// ground-truth frame: then there are no error figures (n/a / null, not
  /// zero), and `arpos evaluate` exits 1.
  bool has_errors() const { return reported_in + reported_out > 0; }
  /// The frames reported `in` while truly out, in file order.
  std::vector<CorrectionFrame> InWhileOut() const;
  std::string ToText() const;
  std::string ToJson(bool include_frames = false) const;
};

/// Evaluates `rows` against `ground_truth` (model -> room per timestamp) and
/// `room_from_model_target`. Throws InputError for invalid tolerances or a
/// non-positive `max_difference_s`.
CorrectionEvaluation EvaluateCorrections(const std::vector<CorrectionRow>& rows,
                                         const std::vector<StampedPose>& ground_truth,
                                         const Rigid3d& room_from_model_target,
                                         const CorrectionEvaluationOptions& options = {});

}  // namespace arpos
