#include "sensor/tum_io.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "util/check.h"
#include "util/file.h"
#include "util/string_util.h"

namespace arpos {
namespace {

// Calls `fn(tokens, line_number)` for every non-blank, non-comment line.
template <typename Fn>
void ForEachDataLine(const std::filesystem::path& path, Fn fn) {
  const std::string text = ReadTextFile(path);
  std::istringstream in(text);
  std::string line;
  int line_number = 0;
  while (std::getline(in, line)) {
    ++line_number;
    const std::string trimmed = Trim(line);
    if (trimmed.empty() || trimmed[0] == '#') continue;
    fn(SplitWhitespace(trimmed), line_number);
  }
}

// True for a token strtod reads whole as NaN or an infinity ("nan", "-inf",
// "1e999").
bool IsNonFiniteNumber(const std::string& token) {
  if (token.empty()) return false;
  char* end = nullptr;
  const double value = std::strtod(token.c_str(), &end);
  return end == token.c_str() + token.size() && !std::isfinite(value);
}

}  // namespace

std::vector<ImageListEntry> ReadImageList(const std::filesystem::path& path) {
  std::vector<ImageListEntry> entries;
  ForEachDataLine(path, [&](const std::vector<std::string>& tokens, int line) {
    ImageListEntry entry;
    entry.line = line;
    if (tokens.size() != 2 || !ParseDouble(tokens[0], &entry.timestamp_s)) {
      ARPOS_INPUT_ERROR(path.string() << ":" << line
                                      << ": expected 'timestamp path', e.g. '1.000000 rgb/1.png'");
    }
    entry.relative_path = tokens[1];
    if (entry.relative_path.find("..") != std::string::npos || entry.relative_path[0] == '/') {
      ARPOS_INPUT_ERROR(path.string() << ":" << line << ": image path '" << entry.relative_path
                                      << "' must stay inside the sequence folder");
    }
    entries.push_back(entry);
  });
  return entries;
}

std::string ImageListTimestampProblem(const std::vector<ImageListEntry>& entries) {
  for (size_t i = 1; i < entries.size(); ++i) {
    if (!(entries[i].timestamp_s > entries[i - 1].timestamp_s)) {
      return StringPrintf("timestamps not increasing at line %d (%.6f after %.6f)", entries[i].line,
                          entries[i].timestamp_s, entries[i - 1].timestamp_s);
    }
  }
  if (entries.size() < 2) return "";
  std::vector<double> spacing;
  spacing.reserve(entries.size() - 1);
  for (size_t i = 1; i < entries.size(); ++i)
    spacing.push_back(entries[i].timestamp_s - entries[i - 1].timestamp_s);
  std::nth_element(spacing.begin(), spacing.begin() + spacing.size() / 2, spacing.end());
  const double median = spacing[spacing.size() / 2];
  if (!(median > kMaxMedianFrameSpacingS)) return "";
  // At 5-100 frames a second, seconds times 1e3, 1e6 or 1e9.
  const char* unit = median < 1e4 ? "milliseconds" : median < 1e7 ? "microseconds" : "nanoseconds";
  return StringPrintf(
      "frames are a median %.6g s apart: timestamps must be in seconds (DATASET.md); these look "
      "like %s",
      median, unit);
}

void WriteImageList(const std::filesystem::path& path, const std::vector<ImageListEntry>& entries,
                    const std::string& header_comment) {
  std::ostringstream out;
  if (!header_comment.empty()) out << "# " << header_comment << "\n";
  out << "# timestamp filename\n";
  for (const auto& e : entries) out << StringPrintf("%.6f ", e.timestamp_s) << e.relative_path << "\n";
  WriteFileAtomic(path, out.str());
}

std::vector<StampedPose> ReadTrajectory(const std::filesystem::path& path) {
  std::vector<StampedPose> poses;
  ForEachDataLine(path, [&](const std::vector<std::string>& tokens, int line) {
    static const char* const kFields[8] = {"timestamp", "tx", "ty", "tz", "qx", "qy", "qz", "qw"};
    double v[8];
    bool ok = tokens.size() == 8;
    for (size_t i = 0; ok && i < 8; ++i) {
      ok = ParseDouble(tokens[i], &v[i]);
      // ParseDouble refuses nan and inf as it refuses words; a number that is
      // not finite deserves to be named (a NaN in a pose is a broken export,
      // not a miscounted line).
      if (!ok && IsNonFiniteNumber(tokens[i])) {
        ARPOS_INPUT_ERROR(path.string() << ":" << line << ": " << kFields[i] << " is '" << tokens[i]
                                        << "', not a finite number");
      }
    }
    if (!ok) {
      ARPOS_INPUT_ERROR(path.string() << ":" << line
                                      << ": expected 8 numbers 'timestamp tx ty tz qx qy qz qw'");
    }
    const Eigen::Quaterniond q(v[7], v[4], v[5], v[6]);
    if (std::abs(q.norm() - 1.0) > 1e-3) {
      ARPOS_INPUT_ERROR(path.string() << ":" << line << ": quaternion norm is " << q.norm()
                                      << ", not 1");
    }
    poses.push_back({v[0], Rigid3d(q.normalized(), Eigen::Vector3d(v[1], v[2], v[3]))});
  });
  return poses;
}

void WriteTrajectory(const std::filesystem::path& path, const std::vector<StampedPose>& poses,
                     const std::string& header_comment) {
  std::ostringstream out;
  if (!header_comment.empty()) out << "# " << header_comment << "\n";
  out << "# timestamp tx ty tz qx qy qz qw\n";
  for (const auto& p : poses) {
    const Eigen::Quaterniond& q = p.room_from_x.rotation;
    const Eigen::Vector3d& t = p.room_from_x.translation;
    out << StringPrintf("%.6f %.9f %.9f %.9f %.9f %.9f %.9f %.9f\n", p.timestamp_s, t.x(), t.y(),
                        t.z(), q.x(), q.y(), q.z(), q.w());
  }
  WriteFileAtomic(path, out.str());
}

Eigen::Matrix4d ReadMatrix4(const std::filesystem::path& path) {
  std::vector<double> values;
  ForEachDataLine(path, [&](const std::vector<std::string>& tokens, int line) {
    for (const auto& token : tokens) {
      double v = 0;
      if (!ParseDouble(token, &v)) {
        ARPOS_INPUT_ERROR(path.string() << ":" << line << ": '" << token << "' is not a number");
      }
      values.push_back(v);
    }
  });
  if (values.size() != 16) {
    ARPOS_INPUT_ERROR(path.string() << ": expected a 4x4 matrix (16 numbers, row-major), found "
                                    << values.size() << " numbers");
  }
  Eigen::Matrix4d m;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) m(r, c) = values[r * 4 + c];
  }
  return m;
}

void WriteMatrix4(const std::filesystem::path& path, const Eigen::Matrix4d& m,
                  const std::string& header_comment) {
  std::ostringstream out;
  if (!header_comment.empty()) out << "# " << header_comment << "\n";
  for (int r = 0; r < 4; ++r) {
    out << StringPrintf("%.12f %.12f %.12f %.12f\n", m(r, 0), m(r, 1), m(r, 2), m(r, 3));
  }
  WriteFileAtomic(path, out.str());
}

std::vector<std::pair<size_t, size_t>> AssociateTimestamps(const std::vector<double>& a,
                                                           const std::vector<double>& b,
                                                           double max_difference_s) {
  // Candidate pairs within the window, via a two-pointer sweep over sorted b.
  std::vector<size_t> order_b(b.size());
  for (size_t j = 0; j < b.size(); ++j) order_b[j] = j;
  std::sort(order_b.begin(), order_b.end(), [&](size_t x, size_t y) { return b[x] < b[y]; });
  struct Candidate {
    double difference;
    size_t i, j;
  };
  std::vector<Candidate> candidates;
  for (size_t i = 0; i < a.size(); ++i) {
    auto it = std::lower_bound(order_b.begin(), order_b.end(), a[i] - max_difference_s,
                               [&](size_t j, double value) { return b[j] < value; });
    for (; it != order_b.end() && b[*it] <= a[i] + max_difference_s; ++it) {
      candidates.push_back({std::abs(a[i] - b[*it]), i, *it});
    }
  }
  std::stable_sort(candidates.begin(), candidates.end(),
                   [](const Candidate& x, const Candidate& y) { return x.difference < y.difference; });
  std::vector<char> used_a(a.size(), 0), used_b(b.size(), 0);
  std::vector<std::pair<size_t, size_t>> pairs;
  for (const auto& c : candidates) {
    if (used_a[c.i] || used_b[c.j]) continue;
    used_a[c.i] = used_b[c.j] = 1;
    pairs.emplace_back(c.i, c.j);
  }
  std::sort(pairs.begin(), pairs.end());
  return pairs;
}

}  // namespace arpos
