#pragma once
#include <string>
#include <vector>

namespace arpos {
/// `arpos gui`: opens the wizard.
int RunGuiCommand(const std::vector<std::string>& args);
}  // namespace arpos
