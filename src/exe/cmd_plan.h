#pragma once
/// `arpos plan`: builds the room map of a case (src/room_map/plan_stage.h)
/// and stores it in the session store.

#include <string>
#include <vector>

namespace arpos {

/// args: CASE_DIR [--store DB] [--plan ID] [--patient ID] [--frame-step N]
///       [--max-frames N] [--threads N] [--max-landmarks N] [--no-keypoints]
///       [--keep-couch] [--poses FILE]
/// Prints the map summary to stdout, progress to stderr. Returns 0 on
/// success, 2 for a usage or input error (exceptions propagate to the
/// dispatcher, which reports them).
int RunPlanCommand(const std::vector<std::string>& args);

}  // namespace arpos
