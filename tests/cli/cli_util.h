#pragma once
// Runs the real `arpos` executable (ARPOS_EXECUTABLE) as a user would, for
// the CLI integration tests.

#include <functional>
#include <string>

namespace arpos::testing {

struct CliResult {
  int status = -1;     ///< exit status, -1 if it did not exit normally
  std::string output;  ///< stdout and stderr
};

/// `arpos ARGS` (ARGS as a shell would split them) to completion.
CliResult RunArpos(const std::string& args);

/// The same, calling `on_line` with each line of output as it arrives
/// (stderr is unbuffered: progress and warnings arrive as they are printed).
CliResult RunArposWatching(const std::string& args, const std::function<void(const std::string&)>& on_line);

}  // namespace arpos::testing
