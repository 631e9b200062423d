#include "sensor/case_folder.h"

#include <algorithm>

#include "sensor/case_check.h"
#include "sensor/tum_io.h"
#include "util/check.h"

namespace arpos {

std::filesystem::path FindReferenceModel(const std::filesystem::path& root) {
  for (const char* ext : {".ply", ".stl", ".obj", ".off"}) {
    const auto path = root / (std::string("reference_model") + ext);
    if (std::filesystem::exists(path)) return path;
  }
  return {};
}

CaseFolder LoadCaseFolder(const std::filesystem::path& root) {
  if (!std::filesystem::is_directory(root)) {
    ARPOS_INPUT_ERROR(root.string() << ": case folder does not exist");
  }
  CaseFolder folder;
  folder.root = root;
  folder.config = LoadCaseConfig(root / "case.yaml");
  folder.reference_model = FindReferenceModel(root);
  if (folder.reference_model.empty()) {
    ARPOS_INPUT_ERROR((root / "reference_model.ply").string()
                      << ": missing (also looked for .stl, .obj, .off)");
  }
  const auto target = root / "target_pose.txt";
  if (!std::filesystem::exists(target)) ARPOS_INPUT_ERROR(target.string() << ": missing");
  const Eigen::Matrix4d m = ReadMatrix4(target);
  const std::string problem = TargetPoseProblem(m);
  if (!problem.empty()) ARPOS_INPUT_ERROR(target.string() << ": " << problem);
  folder.room_from_model_target = Rigid3d::FromMatrix(m, 1e-4);
  folder.room_dir = root / "room";
  folder.body_scan_dir = root / "body_scan";
  const auto tracking = root / "tracking";
  if (std::filesystem::is_directory(tracking)) {
    for (const auto& entry : std::filesystem::directory_iterator(tracking)) {
      if (entry.is_directory()) {
        folder.tracking.emplace_back(entry.path().filename().string(), entry.path());
      }
    }
    std::sort(folder.tracking.begin(), folder.tracking.end());
  }
  return folder;
}

}  // namespace arpos
