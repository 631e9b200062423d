#pragma once
/// `arpos track`: tracking mode on a recorded sequence (src/tracking): the
/// camera and the patient every frame, the couch correction to the planned
/// pose, the files of DATASET.md "Outputs of tracking", and the run in the
/// session store.

#include <string>
#include <vector>

namespace arpos {

/// args: SEQ_DIR --out DIR [--store DB] [--session ID] [--case DIR] [--overlay]
///       [--tolerance-mm MM] [--tolerance-deg DEG] [--sequential]
/// Returns 0 on success, 2 for a usage or input error.
int RunTrackCommand(const std::vector<std::string>& args);

}  // namespace arpos
