#pragma once
/// Validation of a case folder: `arpos check` reports every problem, and every
/// stage checks what it reads with the same checker before it starts
/// (RequireValidCase), so bad data stops with a message naming the file and
/// what is wrong instead of reaching the algorithms.

#include <Eigen/Core>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "geometry/triangle_mesh.h"

namespace arpos {

/// A target pose, ground-truth pose or room position farther than this from
/// the room origin is not in the treatment room (millimetres read as metres).
constexpr double kMaxRoomDistanceM = 20.0;
/// Accepted largest extent of a reference body surface (a body part to a
/// tall body with arms raised), metres.
constexpr double kMinReferenceModelExtentM = 0.05;
constexpr double kMaxReferenceModelExtentM = 3.0;
/// Depth images listed further than this (median) from their colour images
/// were taken at other instants (no colour-depth sync): a warning.
constexpr double kDepthDelayWarningS = 0.002;

struct CaseProblem {
  enum class Severity { kWarning, kError };
  Severity severity = Severity::kError;
  std::string where;    ///< file path (relative to the case) or "case.yaml: key"
  std::string message;  ///< what is wrong, as a sentence fragment
  std::string ToString() const;
};

struct CaseCheckOptions {
  /// Read every image (slow on long sequences) rather than a sample of
  /// first/last/every n-th (the quick check). Sizes and types are checked on
  /// what is read.
  bool read_all_images = true;
  /// Check reference_model.* and target_pose.txt (case.yaml always is).
  bool reference_model = true;
  bool target_pose = true;
  /// Only these sequence folders (relative to the case, or absolute), each
  /// required; unset: room/, body_scan/ and every tracking/<name>/.
  std::optional<std::vector<std::filesystem::path>> sequences;
};

struct CaseCheckReport {
  std::vector<CaseProblem> problems;
  int sequences = 0;
  int frames = 0;
  int images_read = 0;
  bool ok() const;  ///< no errors (warnings allowed)
};

/// Checks everything (or what `options` selects): case.yaml keys and ranges,
/// reference model presence, readability, finite vertices and body size,
/// target_pose.txt rigidity and distance, every sequence's lists (format,
/// increasing timestamps, files present, colour/depth association, depth
/// taken at other instants than its colour: a warning beyond
/// kDepthDelayWarningS), images
/// (readable, 8-bit colour / 16-bit depth, size = camera width x height) and
/// ground-truth files (format, increasing timestamps, poses in the room).
/// Never throws for bad input: every defect is a problem.
CaseCheckReport CheckCase(const std::filesystem::path& root, const CaseCheckOptions& options = {},
                          const std::function<void(const std::string&)>& progress = nullptr);

/// The check a stage makes of what it reads before it reads it (plan: room/,
/// session: body_scan/, localize: its sequence, run-case: everything): CheckCase
/// with `options`. Throws InputError listing every error ("CASE: the case has
/// problems (`arpos check CASE` lists them all):" then one "error: FILE: what"
/// line each) if there is one; returns the report (its warnings) otherwise.
CaseCheckReport RequireValidCase(const std::filesystem::path& root, const CaseCheckOptions& options);

/// The problem of a target pose (target_pose.txt, reference model -> room), or
/// empty: not rigid, or a translation farther than kMaxRoomDistanceM from the
/// room origin ("... looks like millimetres" when it does).
std::string TargetPoseProblem(const Eigen::Matrix4d& room_from_model);

/// The problem of a reference model's size, or empty: largest extent outside
/// [kMinReferenceModelExtentM, kMaxReferenceModelExtentM] metres, saying which
/// unit it looks like and how to convert it.
std::string ReferenceModelSizeProblem(const TriangleMesh& model);

}  // namespace arpos
