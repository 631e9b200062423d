#pragma once
/// `arpos simulate`: writes a synthetic case folder with exact ground truth
/// (src/simulation/simulator.h).

#include <string>
#include <vector>

namespace arpos {

/// args: OUT_DIR [--profile xtion|l515] [--seed N] [--hard] [--no-noise]
///       [--frames room=N,body=N,tracking=N] [--tracking-sequences K]
///       [--body-mesh PATH] [--png-compression 0..9] [--supersampling S]
/// Returns 0 on success, 2 for a usage or input error.
int RunSimulateCommand(const std::vector<std::string>& args);

}  // namespace arpos
