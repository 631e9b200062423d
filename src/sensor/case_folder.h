#pragma once
/// A case folder (DATASET.md): everything the workflow consumes.

#include <filesystem>
#include <string>
#include <vector>

#include "geometry/rigid3.h"
#include "sensor/case_config.h"

namespace arpos {

struct CaseFolder {
  std::filesystem::path root;
  CaseConfig config;
  std::filesystem::path reference_model;  ///< reference_model.{ply,stl,obj,off}
  Rigid3d room_from_model_target;         ///< target_pose.txt
  std::filesystem::path room_dir;         ///< room/ (may not exist)
  std::filesystem::path body_scan_dir;    ///< body_scan/ (may not exist)
  /// tracking/<name>/ folders, sorted by name.
  std::vector<std::pair<std::string, std::filesystem::path>> tracking;

  std::filesystem::path case_yaml() const { return root / "case.yaml"; }
};

/// Reads case.yaml and target_pose.txt (rigid, in the room: TargetPoseProblem)
/// and locates the rest. Throws InputError naming the file at the first
/// problem; `arpos check` (CheckCase) reports all, and stages call
/// RequireValidCase first (case_check.h).
CaseFolder LoadCaseFolder(const std::filesystem::path& root);

/// Finds reference_model.* in `root` (ply, stl, obj, off in that order).
std::filesystem::path FindReferenceModel(const std::filesystem::path& root);

}  // namespace arpos
