#include "sensor/case_check.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgcodecs.hpp>
#include <set>
#include <sstream>

#include "geometry/mesh_io.h"
#include "geometry/rigid3.h"
#include "sensor/case_config.h"
#include "sensor/case_folder.h"
#include "sensor/sequence.h"
#include "sensor/tum_io.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos {
namespace fs = std::filesystem;

std::string CaseProblem::ToString() const {
  return std::string(severity == Severity::kError ? "error: " : "warning: ") + where + ": " +
         message;
}

bool CaseCheckReport::ok() const {
  for (const auto& p : problems) {
    if (p.severity == CaseProblem::Severity::kError) return false;
  }
  return true;
}

namespace {

class Checker {
 public:
  Checker(const fs::path& root, const CaseCheckOptions& options,
          const std::function<void(const std::string&)>& progress)
      : root_(root), options_(options), progress_(progress) {}

  CaseCheckReport Run() {
    if (!fs::is_directory(root_)) {
      Error(root_.string(), "case folder does not exist");
      return report_;
    }
    CheckConfig();
    if (options_.reference_model) CheckReferenceModel();
    if (options_.target_pose) CheckTargetPose();
    if (options_.sequences) {
      for (const auto& sequence : *options_.sequences) CheckSequenceIfPresent(DisplayName(sequence), true);
      return report_;
    }
    CheckSequenceIfPresent("room", /*required=*/true);
    CheckSequenceIfPresent("body_scan", /*required=*/true);
    const fs::path tracking = root_ / "tracking";
    if (!fs::is_directory(tracking)) {
      Warning("tracking/", "no tracking sequences (nothing to track or evaluate)");
    } else {
      std::set<fs::path> dirs;
      for (const auto& entry : fs::directory_iterator(tracking)) {
        if (entry.is_directory()) dirs.insert(entry.path());
      }
      if (dirs.empty()) Warning("tracking/", "holds no sequence folders");
      for (const auto& dir : dirs) {
        CheckSequenceIfPresent("tracking/" + dir.filename().string(), true);
      }
    }
    return report_;
  }

 private:
  void Error(const std::string& where, const std::string& message) {
    report_.problems.push_back({CaseProblem::Severity::kError, where, message});
  }
  void Warning(const std::string& where, const std::string& message) {
    report_.problems.push_back({CaseProblem::Severity::kWarning, where, message});
  }
  // Messages from readers start with the absolute file path; show it relative.
  std::string Relative(const std::string& message) const {
    const std::string prefix = (root_ / "").string();
    std::string out = message;
    for (size_t pos = out.find(prefix); pos != std::string::npos; pos = out.find(prefix)) {
      out.erase(pos, prefix.size());
    }
    return out;
  }
  // A sequence folder as the messages name it: relative to the case if it
  // lies inside it.
  std::string DisplayName(const fs::path& sequence) const {
    if (sequence.is_relative()) return sequence.generic_string();
    const fs::path inside = sequence.lexically_normal().lexically_relative(fs::absolute(root_).lexically_normal());
    if (inside.empty() || *inside.begin() == "..") return sequence.string();
    return inside.generic_string();
  }
  // "file: rest" -> (file, rest) for reader messages.
  void ErrorFromException(const std::string& fallback_where, const std::exception& e) {
    const std::string message = Relative(e.what());
    const size_t colon = message.find(": ");
    if (colon == std::string::npos) {
      Error(fallback_where, message);
    } else {
      Error(message.substr(0, colon), message.substr(colon + 2));
    }
  }

  void CheckConfig() {
    const fs::path yaml = root_ / "case.yaml";
    if (!fs::exists(yaml)) {
      Error("case.yaml", "missing");
      return;
    }
    try {
      config_ = LoadCaseConfig(yaml);
      have_config_ = true;
    } catch (const std::exception& e) {
      ErrorFromException("case.yaml", e);
    }
  }

  void CheckReferenceModel() {
    const fs::path model = FindReferenceModel(root_);
    if (model.empty()) {
      Error("reference_model.ply", "missing (also looked for .stl, .obj, .off)");
      return;
    }
    std::error_code ec;
    if (!fs::is_regular_file(model, ec)) {
      Error(model.filename().string(), "not a regular file");
      return;
    }
    if (fs::file_size(model, ec) == 0 && !ec) {
      Error(model.filename().string(), "empty file (0 bytes)");
      return;
    }
    try {
      const std::string problem = ReferenceModelSizeProblem(LoadTriangleMesh(model));
      if (!problem.empty()) Error(model.filename().string(), problem);
    } catch (const std::exception& e) {
      ErrorFromException(model.filename().string(), e);
    }
  }

  void CheckTargetPose() {
    const fs::path target = root_ / "target_pose.txt";
    if (!fs::exists(target)) {
      Error("target_pose.txt", "missing");
      return;
    }
    try {
      const std::string problem = TargetPoseProblem(ReadMatrix4(target));
      if (!problem.empty()) Error("target_pose.txt", problem);
    } catch (const std::exception& e) {
      ErrorFromException("target_pose.txt", e);
    }
  }

  bool CheckSequenceIfPresent(const std::string& name, bool required) {
    const fs::path dir = root_ / name;
    if (!fs::is_directory(dir)) {
      if (required) Error(name + "/", "sequence folder missing");
      return false;
    }
    ++report_.sequences;
    if (progress_) progress_("checking " + name);
    bool lists_ok = true;
    std::vector<ImageListEntry> lists[2];
    const char* list_names[2] = {"rgb.txt", "depth.txt"};
    for (int k = 0; k < 2; ++k) {
      const fs::path list = dir / list_names[k];
      const std::string where = name + "/" + list_names[k];
      if (!fs::exists(list)) {
        Error(where, "missing");
        lists_ok = false;
        continue;
      }
      try {
        lists[k] = ReadImageList(list);
      } catch (const std::exception& e) {
        ErrorFromException(where, e);
        lists_ok = false;
        continue;
      }
      if (lists[k].empty()) {
        Error(where, "lists no images");
        lists_ok = false;
      }
      if (const std::string problem = ImageListTimestampProblem(lists[k]); !problem.empty()) {
        Error(where, problem);
        lists_ok = false;  // Sequence::Open refuses it too: said once
      }
      int missing = 0;
      for (const auto& entry : lists[k]) {
        if (!fs::exists(dir / entry.relative_path)) {
          if (missing < 3) {
            Error(name + "/" + entry.relative_path,
                  StringPrintf("missing (listed in %s line %d)", list_names[k], entry.line));
          }
          ++missing;
        }
      }
      if (missing > 3) {
        Error(where, StringPrintf("%d listed images are missing in all", missing));
      }
    }
    if (!lists_ok) return true;

    Sequence seq;
    try {
      seq = Sequence::Open(dir);
    } catch (const std::exception& e) {
      ErrorFromException(name + "/", e);
      return true;
    }
    report_.frames += static_cast<int>(seq.size());
    if (seq.unmatched_color() > 0) {
      Warning(name + "/", StringPrintf("%zu colour images have no depth image within %.2f s",
                                       seq.unmatched_color(), kFrameAssociationS));
    }
    CheckDepthTiming(name, seq);
    if (have_config_) CheckImages(name, seq);
    CheckGroundTruth(name, dir / "groundtruth.txt", seq);
    CheckGroundTruth(name, dir / "body_groundtruth.txt", seq);
    return true;
  }

  // Depth listed at other instants than its colour: a camera recording
  // without colour-depth sync. Every stage takes such depth as worth less
  // (sensor/depth_timing.h), which costs accuracy: said here.
  void CheckDepthTiming(const std::string& name, const Sequence& seq) {
    std::vector<double> delays;
    for (size_t i = 0; i < seq.size(); ++i) {
      if (seq.has_depth(i)) delays.push_back(seq.depth_delay_s(i));
    }
    if (delays.empty()) return;
    std::nth_element(delays.begin(), delays.begin() + delays.size() / 2, delays.end());
    const double median = delays[delays.size() / 2];
    if (!(std::abs(median) > kDepthDelayWarningS)) return;
    Warning(name + "/",
            StringPrintf(
                "depth images are a median %.1f ms %s their colour images (depth.txt against "
                "rgb.txt): the camera took them at other instants, and with a hand-held camera "
                "that costs accuracy (measured on a simulated hand-held case: depth 10 ms late "
                "about doubled the tracking error); record with the camera's colour-depth sync "
                "on if it has one",
                1000 * std::abs(median), median > 0 ? "after" : "before"));
  }

  void CheckImages(const std::string& name, const Sequence& seq) {
    const size_t n = seq.size();
    const size_t stride = options_.read_all_images ? 1 : std::max<size_t>(1, n / 10);
    int errors = 0;
    for (size_t i = 0; i < n; i += stride) {
      if (!options_.read_all_images && i + stride >= n && i != n - 1) i = n - 1;
      if (!fs::exists(seq.color_path(i)) || !fs::exists(seq.depth_path(i))) continue;  // reported
      try {
        seq.LoadFrame(i, config_.camera);
        report_.images_read += 2;
      } catch (const std::exception& e) {
        if (++errors <= 5) ErrorFromException(name + "/", e);
      }
    }
    if (errors > 5) Error(name + "/", StringPrintf("%d frames have bad images in all", errors));
  }

  void CheckGroundTruth(const std::string& name, const fs::path& file, const Sequence& seq) {
    const std::string where = name + "/" + file.filename().string();
    if (!fs::exists(file)) return;  // optional by DATASET.md
    std::vector<StampedPose> poses;
    try {
      poses = ReadTrajectory(file);
    } catch (const std::exception& e) {
      ErrorFromException(where, e);
      return;
    }
    for (size_t i = 1; i < poses.size(); ++i) {
      if (!(poses[i].timestamp_s > poses[i - 1].timestamp_s)) {
        Error(where, StringPrintf("timestamps not increasing at pose %zu", i + 1));
        return;
      }
    }
    for (size_t i = 0; i < poses.size(); ++i) {
      const Eigen::Vector3d& t = poses[i].room_from_x.translation;
      if (t.norm() > kMaxRoomDistanceM) {
        Error(where, StringPrintf("pose %zu (t = %.6f) is %.1f m from the room origin, farther than %.0f m%s",
                                  i + 1, poses[i].timestamp_s, t.norm(), kMaxRoomDistanceM,
                                  t.norm() / 1000 <= kMaxRoomDistanceM
                                      ? ": looks like millimetres (poses are in metres)"
                                      : ": not a pose in the room"));
        return;
      }
    }
    std::vector<double> frame_t, gt_t;
    for (size_t i = 0; i < seq.size(); ++i) frame_t.push_back(seq.timestamp_s(i));
    for (const auto& p : poses) gt_t.push_back(p.timestamp_s);
    const size_t matched = AssociateTimestamps(frame_t, gt_t, kFrameAssociationS).size();
    if (matched < seq.size()) {
      Warning(where, StringPrintf("covers %zu of %zu frames", matched, seq.size()));
    }
  }

  fs::path root_;
  CaseCheckOptions options_;
  std::function<void(const std::string&)> progress_;
  CaseCheckReport report_;
  CaseConfig config_;
  bool have_config_ = false;
};

}  // namespace

CaseCheckReport CheckCase(const fs::path& root, const CaseCheckOptions& options,
                          const std::function<void(const std::string&)>& progress) {
  return Checker(root, options, progress).Run();
}

CaseCheckReport RequireValidCase(const fs::path& root, const CaseCheckOptions& options) {
  CaseCheckReport report = CheckCase(root, options);
  if (report.ok()) return report;
  std::ostringstream errors;
  for (const auto& p : report.problems) {
    if (p.severity == CaseProblem::Severity::kError) errors << "\n  " << p.ToString();
  }
  ARPOS_INPUT_ERROR(root.string() << ": the case has problems (`arpos check " << root.string()
                                  << "` lists them all):" << errors.str());
}

std::string TargetPoseProblem(const Eigen::Matrix4d& room_from_model) {
  std::string reason;
  if (!IsRigidTransform(room_from_model, 1e-4, &reason)) return "not a rigid transform: " + reason;
  const Eigen::Vector3d t = room_from_model.topRightCorner<3, 1>();
  if (t.norm() <= kMaxRoomDistanceM) return "";
  return StringPrintf("translation (%.3f, %.3f, %.3f) is %.1f m from the room origin, farther than %.0f m: %s", t.x(),
                      t.y(), t.z(), t.norm(), kMaxRoomDistanceM,
                      t.norm() / 1000 <= kMaxRoomDistanceM
                          ? "looks like millimetres (target_pose.txt is in metres)"
                          : "not a pose in the treatment room (target_pose.txt is in metres)");
}

std::string ReferenceModelSizeProblem(const TriangleMesh& model) {
  Eigen::Vector3f lo, hi;
  model.Bounds(&lo, &hi);
  const double extent = (hi - lo).cast<double>().maxCoeff();
  if (extent >= kMinReferenceModelExtentM && extent <= kMaxReferenceModelExtentM) return "";
  // The unit that would make it body-sized, as arpos import-model detects it.
  const char* unit = nullptr;
  if (extent > kMaxReferenceModelExtentM) {
    if (extent <= 1000 * kMaxReferenceModelExtentM && extent >= 1000 * kMinReferenceModelExtentM) {
      unit = "mm";
    } else if (extent < 200) {
      unit = extent >= 20 ? "cm" : "dm";
    }
  }
  std::string problem = StringPrintf(
      "largest extent is %g m: not a body surface in metres (%.2f-%.0f m)", extent, kMinReferenceModelExtentM,
      kMaxReferenceModelExtentM);
  if (unit != nullptr) {
    problem += StringPrintf("; looks like %s: convert it with arpos import-model MODEL --units %s --out MODEL.ply",
                            std::string(unit) == "mm" ? "millimetres"
                            : std::string(unit) == "cm" ? "centimetres"
                                                        : "decimetres",
                            unit);
  } else if (extent > kMaxReferenceModelExtentM) {
    problem += ": far too large in any length unit";
  } else {
    problem += ": too small for a body surface in metres";
  }
  return problem;
}

}  // namespace arpos
