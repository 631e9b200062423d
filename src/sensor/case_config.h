#pragma once
/// `case.yaml` of a case folder (DATASET.md), read and written.

#include <filesystem>
#include <string>

#include "sensor/intrinsics.h"

namespace arpos {

struct MarkerSetConfig {
  double size_m = 0;   ///< printed black-square side
  int id_min = 0;      ///< inclusive id range
  int id_max = 0;
  bool Contains(int id) const { return id >= id_min && id <= id_max; }
};

struct CaseConfig {
  CameraIntrinsics camera;
  std::string dictionary = "DICT_4X4_250";  ///< OpenCV predefined dictionary name
  MarkerSetConfig room_markers;
  int room_origin_id = 0;                   ///< marker whose frame is the room frame
  MarkerSetConfig body_markers;
};

/// Reads and validates `case.yaml`. Throws InputError naming the file and the
/// key (e.g. "case.yaml: camera.fx: must be positive, got 0") for anything
/// missing, malformed or out of range.
CaseConfig LoadCaseConfig(const std::filesystem::path& yaml_path);

/// Same checks on a parsed config; empty if valid, else "key: problem".
std::string ValidateCaseConfig(const CaseConfig& config);

/// Writes `case.yaml` atomically in the DATASET.md layout.
void SaveCaseConfig(const CaseConfig& config, const std::filesystem::path& yaml_path);

/// OpenCV predefined dictionary id for a name such as "DICT_4X4_250"; -1 if unknown.
int ArucoDictionaryId(const std::string& name);

}  // namespace arpos
