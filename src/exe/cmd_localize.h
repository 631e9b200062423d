#pragma once
/// `arpos localize`: camera pose of every frame of a sequence against a
/// stored room map (src/room_map/camera_localizer.h), as a TUM pose file.

#include <string>
#include <vector>

namespace arpos {

/// args: SEQ_DIR --out FILE [--store DB] [--plan ID] [--case DIR]
///       [--no-keypoints] [--no-markers] [--timings FILE]
/// Frames that cannot be localised are left out of FILE (DATASET.md counts
/// them as lost). Prints a summary to stdout. Returns 0 on success, 2 for a
/// usage or input error.
int RunLocalizeCommand(const std::vector<std::string>& args);

}  // namespace arpos
