#pragma once
/// Writes small, valid case folders (DATASET.md) for tests, so each test can
/// break one thing and check the message.

#include <filesystem>

#include "sensor/case_config.h"

namespace arpos::testing {

struct TinyCaseOptions {
  int width = 80;
  int height = 60;
  int frames = 3;
  bool with_ground_truth = true;
};

CaseConfig TinyCaseConfig(const TinyCaseOptions& options = {});

/// Writes case.yaml, reference_model.ply (a closed tetrahedron), target_pose.txt,
/// room/, body_scan/ and tracking/a/ with `frames` frames each.
void WriteTinyCase(const std::filesystem::path& root, const TinyCaseOptions& options = {});

}  // namespace arpos::testing
