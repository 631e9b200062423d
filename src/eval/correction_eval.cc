#include "eval/correction_eval.h"

#include <cmath>
#include <sstream>

#include "geometry/so3.h"
#include "util/check.h"
#include "util/file.h"
#include "util/string_util.h"

namespace arpos {

namespace {

constexpr int kCsvFields = 10;
const char* const kNumberColumns[] = {"lateral_mm", "longitudinal_mm", "vertical_mm", "pitch_deg",
                                      "roll_deg",   "yaw_deg",         "translation_mm", "rotation_deg"};

// Split on ',' keeping empty fields (a lost row is mostly empty fields).
std::vector<std::string> SplitFields(const std::string& line) {
  std::vector<std::string> fields;
  size_t start = 0;
  while (true) {
    const size_t comma = line.find(',', start);
    fields.push_back(Trim(line.substr(start, comma == std::string::npos ? std::string::npos : comma - start)));
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return fields;
}

Eigen::Quaterniond TurnFromDeg(double pitch_deg, double roll_deg, double yaw_deg) {
  return QuaternionFromRotationVector(Eigen::Vector3d(RadFromDeg(pitch_deg), RadFromDeg(roll_deg), RadFromDeg(yaw_deg)));
}

}  // namespace

std::vector<CorrectionRow> ParseCorrectionsCsv(std::istream& in, const std::string& source) {
  const std::string header = Trim(CorrectionsCsvHeader());
  std::vector<CorrectionRow> rows;
  std::string line;
  int line_number = 0;
  bool seen_header = false;
  while (std::getline(in, line)) {
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (Trim(line).empty()) continue;
    if (!seen_header) {
      if (Trim(line) != header) {
        ARPOS_INPUT_ERROR(source << ":" << line_number << ": expected the header '" << header << "', found '"
                                 << line.substr(0, 120) << "'");
      }
      seen_header = true;
      continue;
    }
    const std::vector<std::string> fields = SplitFields(line);
    if (static_cast<int>(fields.size()) != kCsvFields) {
      ARPOS_INPUT_ERROR(source << ":" << line_number << ": expected " << kCsvFields << " comma-separated fields, found "
                               << fields.size());
    }
    CorrectionRow row;
    row.line = line_number;
    if (!ParseDouble(fields[0], &row.timestamp_s)) {
      ARPOS_INPUT_ERROR(source << ":" << line_number << ": timestamp '" << fields[0] << "' is not a number");
    }
    const std::string& state = fields[kCsvFields - 1];
    if (state == "in") {
      row.state = CorrectionState::kIn;
    } else if (state == "out") {
      row.state = CorrectionState::kOut;
    } else if (state == "lost") {
      row.state = CorrectionState::kLost;
    } else {
      ARPOS_INPUT_ERROR(source << ":" << line_number << ": state '" << state << "' is not in, out or lost");
    }
    double* const numbers[] = {&row.lateral_mm, &row.longitudinal_mm, &row.vertical_mm,    &row.pitch_deg,
                               &row.roll_deg,   &row.yaw_deg,         &row.translation_mm, &row.rotation_deg};
    for (int k = 0; k < 8; ++k) {
      const std::string& field = fields[k + 1];
      if (row.state == CorrectionState::kLost) {
        // A lost frame has no correction; a number there means the writer
        // and this reader disagree about the row.
        if (!field.empty()) {
          ARPOS_INPUT_ERROR(source << ":" << line_number << ": a lost row has no " << kNumberColumns[k]
                                   << ", found '" << field << "'");
        }
      } else if (!ParseDouble(field, numbers[k])) {
        ARPOS_INPUT_ERROR(source << ":" << line_number << ": " << kNumberColumns[k] << " '" << field
                                 << "' is not a number (state " << state << ")");
      }
    }
    rows.push_back(row);
  }
  if (!seen_header) ARPOS_INPUT_ERROR(source << ": empty, expected the header '" << header << "'");
  return rows;
}

std::vector<CorrectionRow> ReadCorrectionsCsv(const std::filesystem::path& path) {
  std::istringstream in(ReadTextFile(path));
  return ParseCorrectionsCsv(in, path.string());
}

CorrectionEvaluation EvaluateCorrections(const std::vector<CorrectionRow>& rows,
                                         const std::vector<StampedPose>& ground_truth,
                                         const Rigid3d& room_from_model_target,
                                         const CorrectionEvaluationOptions& options) {
  const std::string tol_problem = options.tolerances.Validate();
  if (!tol_problem.empty()) ARPOS_INPUT_ERROR("tolerances: " << tol_problem);
  if (!(options.max_difference_s > 0)) ARPOS_INPUT_ERROR("the association window must be positive");

  std::vector<double> gt_t, row_t;
  for (const auto& p : ground_truth) gt_t.push_back(p.timestamp_s);
  for (const auto& r : rows) row_t.push_back(r.timestamp_s);
  auto pairs = AssociateTimestamps(row_t, gt_t, options.max_difference_s);  // sorted by row

  CorrectionEvaluation eval;
  eval.tolerances = options.tolerances;
  eval.rows = static_cast<int>(rows.size());
  eval.ground_truth_frames = static_cast<int>(ground_truth.size());
  eval.matched_frames = static_cast<int>(pairs.size());
  eval.rows_without_truth = eval.rows - eval.matched_frames;
  eval.truth_without_row = eval.ground_truth_frames - eval.matched_frames;

  std::vector<double> lat, lng, vrt, pitch, roll, yaw, t_mm, r_deg;
  for (const auto& [i, j] : pairs) {
    const CorrectionRow& row = rows[i];
    CorrectionFrame f;
    f.timestamp_s = row.timestamp_s;
    f.line = row.line;
    f.reported = row.state;
    f.truth = ComputeCouchCorrection(ground_truth[j].room_from_x, room_from_model_target, CorrectionUncertainty(),
                                     options.tolerances);
    if (f.truly_in()) {
      ++eval.truly_in;
    } else {
      ++eval.truly_out;
    }
    switch (row.state) {
      case CorrectionState::kIn: ++eval.reported_in; break;
      case CorrectionState::kOut: ++eval.reported_out; break;
      case CorrectionState::kLost: ++eval.reported_lost; break;
    }
    if (row.state == CorrectionState::kIn && !f.truly_in()) ++eval.in_while_out;
    if (row.state == CorrectionState::kOut && f.truly_in()) ++eval.out_while_in;
    if (row.state != CorrectionState::kLost) {
      const CouchCorrection& c = f.truth;
      f.lateral_mm = std::abs(row.lateral_mm - c.lateral_mm);
      f.longitudinal_mm = std::abs(row.longitudinal_mm - c.longitudinal_mm);
      f.vertical_mm = std::abs(row.vertical_mm - c.vertical_mm);
      f.pitch_deg = std::abs(row.pitch_deg - c.pitch_deg);
      f.roll_deg = std::abs(row.roll_deg - c.roll_deg);
      f.yaw_deg = std::abs(row.yaw_deg - c.yaw_deg);
      f.translation_mm = Eigen::Vector3d(row.lateral_mm - c.lateral_mm, row.longitudinal_mm - c.longitudinal_mm,
                                         row.vertical_mm - c.vertical_mm)
                             .norm();
      // Both turns are rotation vectors in the same (couch) axes, so the
      // angle between them does not depend on the axes.
      const Eigen::Quaterniond reported_turn = TurnFromDeg(row.pitch_deg, row.roll_deg, row.yaw_deg);
      const Eigen::Quaterniond true_turn = TurnFromDeg(c.pitch_deg, c.roll_deg, c.yaw_deg);
      f.rotation_deg = DegFromRad(RotationAngleRad(reported_turn * true_turn.conjugate()));
      f.reported_translation_mm = row.translation_mm;
      f.reported_rotation_deg = row.rotation_deg;
      lat.push_back(f.lateral_mm);
      lng.push_back(f.longitudinal_mm);
      vrt.push_back(f.vertical_mm);
      pitch.push_back(f.pitch_deg);
      roll.push_back(f.roll_deg);
      yaw.push_back(f.yaw_deg);
      t_mm.push_back(f.translation_mm);
      r_deg.push_back(f.rotation_deg);
    }
    eval.frames.push_back(f);
  }
  eval.lateral_mm = ComputeErrorStats(lat);
  eval.longitudinal_mm = ComputeErrorStats(lng);
  eval.vertical_mm = ComputeErrorStats(vrt);
  eval.pitch_deg = ComputeErrorStats(pitch);
  eval.roll_deg = ComputeErrorStats(roll);
  eval.yaw_deg = ComputeErrorStats(yaw);
  eval.translation_mm = ComputeErrorStats(t_mm);
  eval.rotation_deg = ComputeErrorStats(r_deg);
  return eval;
}

std::vector<CorrectionFrame> CorrectionEvaluation::InWhileOut() const {
  std::vector<CorrectionFrame> out;
  for (const auto& f : frames) {
    if (f.reported == CorrectionState::kIn && !f.truly_in()) out.push_back(f);
  }
  return out;
}

std::string CorrectionEvaluation::ToText() const {
  std::ostringstream out;
  out << StringPrintf("rows: %d, matched to ground truth: %d (of %d ground-truth frames)\n", rows, matched_frames,
                      ground_truth_frames);
  if (rows_without_truth > 0) {
    out << StringPrintf("rows without ground truth (ignored): %d\n", rows_without_truth);
  }
  if (truth_without_row > 0) out << StringPrintf("ground-truth frames without a row: %d\n", truth_without_row);
  out << StringPrintf("reported: in %d, out %d, lost %d\n", reported_in, reported_out, reported_lost);
  out << StringPrintf("truly (within %g mm and %g deg): in %d, out %d\n", tolerances.translation_mm,
                      tolerances.rotation_deg, truly_in, truly_out);
  out << StringPrintf("reported in while truly out: %d%s\n", in_while_out, in_while_out > 0 ? "  <-- UNSAFE" : "");
  out << StringPrintf("reported out while truly in: %d\n", out_while_in);
  for (const auto& f : InWhileOut()) {
    out << StringPrintf("  in while out: t %.6f (line %d): true %.3f mm %.4f deg, reported %.3f mm %.4f deg\n",
                        f.timestamp_s, f.line, f.truth.translation_mm, f.truth.rotation_deg,
                        f.reported_translation_mm, f.reported_rotation_deg);
  }
  if (!has_errors()) {
    out << "correction error: n/a (no row with a correction matched a ground-truth frame)\n";
    return out.str();
  }
  out << StringPrintf("correction error over %d frames (|reported - true|):\n", reported_in + reported_out);
  auto line = [&out](const char* name, const ErrorStats& s, const char* format) {
    out << StringPrintf("  %-18s", name)
        << StringPrintf(format, s.mean, s.median, s.p95, s.max) << "\n";
  };
  const char* mm = "mean %.3f  median %.3f  p95 %.3f  max %.3f";
  const char* deg = "mean %.4f  median %.4f  p95 %.4f  max %.4f";
  line("lateral [mm]", lateral_mm, mm);
  line("longitudinal [mm]", longitudinal_mm, mm);
  line("vertical [mm]", vertical_mm, mm);
  line("pitch [deg]", pitch_deg, deg);
  line("roll [deg]", roll_deg, deg);
  line("yaw [deg]", yaw_deg, deg);
  line("translation [mm]", translation_mm, mm);
  line("rotation [deg]", rotation_deg, deg);
  return out.str();
}

std::string CorrectionEvaluation::ToJson(bool include_frames) const {
  auto stats = [this](const ErrorStats& s) {
    if (!has_errors()) return std::string("null");
    return StringPrintf("{\"mean\": %.6f, \"median\": %.6f, \"p95\": %.6f, \"max\": %.6f}", s.mean, s.median, s.p95,
                        s.max);
  };
  auto frame_json = [](const CorrectionFrame& f) {
    std::string s = StringPrintf(
        "{\"timestamp\": %.6f, \"line\": %d, \"reported\": \"%s\", \"truly\": \"%s\", \"true_translation_mm\": %.6f, "
        "\"true_rotation_deg\": %.6f",
        f.timestamp_s, f.line, CorrectionStateName(f.reported), f.truly_in() ? "in" : "out", f.truth.translation_mm,
        f.truth.rotation_deg);
    if (f.reported != CorrectionState::kLost) {
      s += StringPrintf(", \"reported_translation_mm\": %.6f, \"reported_rotation_deg\": %.6f, "
                        "\"translation_error_mm\": %.6f, \"rotation_error_deg\": %.6f",
                        f.reported_translation_mm, f.reported_rotation_deg, f.translation_mm, f.rotation_deg);
    }
    return s + "}";
  };
  std::ostringstream out;
  out << "{\n"
      << StringPrintf("  \"tolerance_mm\": %g,\n  \"tolerance_deg\": %g,\n", tolerances.translation_mm,
                      tolerances.rotation_deg)
      << "  \"rows\": " << rows << ",\n"
      << "  \"ground_truth_frames\": " << ground_truth_frames << ",\n"
      << "  \"matched_frames\": " << matched_frames << ",\n"
      << "  \"rows_without_truth\": " << rows_without_truth << ",\n"
      << "  \"truth_without_row\": " << truth_without_row << ",\n"
      << "  \"reported_in\": " << reported_in << ",\n"
      << "  \"reported_out\": " << reported_out << ",\n"
      << "  \"reported_lost\": " << reported_lost << ",\n"
      << "  \"truly_in\": " << truly_in << ",\n"
      << "  \"truly_out\": " << truly_out << ",\n"
      << "  \"in_while_out\": " << in_while_out << ",\n"
      << "  \"out_while_in\": " << out_while_in << ",\n"
      << "  \"lateral_mm\": " << stats(lateral_mm) << ",\n"
      << "  \"longitudinal_mm\": " << stats(longitudinal_mm) << ",\n"
      << "  \"vertical_mm\": " << stats(vertical_mm) << ",\n"
      << "  \"pitch_deg\": " << stats(pitch_deg) << ",\n"
      << "  \"roll_deg\": " << stats(roll_deg) << ",\n"
      << "  \"yaw_deg\": " << stats(yaw_deg) << ",\n"
      << "  \"translation_mm\": " << stats(translation_mm) << ",\n"
      << "  \"rotation_deg\": " << stats(rotation_deg) << ",\n"
      << "  \"in_while_out_frames\": [";
  const std::vector<CorrectionFrame> unsafe = InWhileOut();
  for (size_t i = 0; i < unsafe.size(); ++i) out << (i ? ",\n    " : "\n    ") << frame_json(unsafe[i]);
  out << (unsafe.empty() ? "]" : "\n  ]");
  if (include_frames) {
    out << ",\n  \"frames\": [";
    for (size_t i = 0; i < frames.size(); ++i) out << (i ? ",\n    " : "\n    ") << frame_json(frames[i]);
    out << (frames.empty() ? "]" : "\n  ]");
  }
  out << "\n}\n";
  return out.str();
}

}  // namespace arpos
