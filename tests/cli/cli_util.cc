#include "cli/cli_util.h"

#include <sys/wait.h>

#include <array>
#include <cstdio>

namespace arpos::testing {

CliResult RunArposWatching(const std::string& args, const std::function<void(const std::string&)>& on_line) {
  const std::string command = std::string(ARPOS_EXECUTABLE) + " " + args + " 2>&1";
  CliResult result;
  FILE* pipe = popen(command.c_str(), "r");
  if (!pipe) return result;
  std::array<char, 4096> buffer;
  while (fgets(buffer.data(), static_cast<int>(buffer.size()), pipe) != nullptr) {
    const std::string line = buffer.data();
    result.output += line;
    if (on_line) on_line(line);
  }
  const int status = pclose(pipe);
  result.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return result;
}

CliResult RunArpos(const std::string& args) { return RunArposWatching(args, nullptr); }

}  // namespace arpos::testing
