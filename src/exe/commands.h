#pragma once
/// Subcommands of the `arpos` executable. Each takes the arguments after its
/// name and returns the process exit status (0 ok, 1 failure found, 2 usage or
/// input error). They print to stdout/stderr; the libraries below do not.

#include <string>
#include <vector>

namespace arpos {

int RunCheckCommand(const std::vector<std::string>& args);
int RunEvaluateCommand(const std::vector<std::string>& args);
int RunRunCaseCommand(const std::vector<std::string>& args);
int RunSessionCommand(const std::vector<std::string>& args);
int RunSourcesCommand(const std::vector<std::string>& args);
int RunRecordCommand(const std::vector<std::string>& args);

}  // namespace arpos
