#pragma once
/// Validation of a whole case folder for `arpos check`.

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace arpos {

struct CaseProblem {
  enum class Severity { kWarning, kError };
  Severity severity = Severity::kError;
  std::string where;    ///< file path (relative to the case) or "case.yaml: key"
  std::string message;  ///< what is wrong, as a sentence fragment
  std::string ToString() const;
};

struct CaseCheckOptions {
  /// Read every image (slow on long sequences) rather than a sample of
  /// first/last/every n-th. Sizes and types are checked on what is read.
  bool read_all_images = true;
};

struct CaseCheckReport {
  std::vector<CaseProblem> problems;
  int sequences = 0;
  int frames = 0;
  int images_read = 0;
  bool ok() const;  ///< no errors (warnings allowed)
};

/// Checks everything: case.yaml keys and ranges, reference model presence and
/// readability, target_pose.txt rigidity, every sequence's lists (format,
/// monotonic timestamps, files present, colour/depth association), images
/// (readable, 8-bit colour / 16-bit depth, size = camera width x height) and
/// ground-truth files. Never throws for bad input: every defect is a problem.
CaseCheckReport CheckCase(const std::filesystem::path& root, const CaseCheckOptions& options = {},
                          const std::function<void(const std::string&)>& progress = nullptr);

}  // namespace arpos
