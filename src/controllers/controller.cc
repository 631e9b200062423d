#include "controllers/controller.h"

#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>

#include "util/logging.h"

namespace arpos {

namespace {

// Writes and removes a probe file in `folder`: permissions alone do not tell
// (root, read-only mounts, quotas). `name` starts the message.
void ProbeFolder(const std::filesystem::path& folder, const std::string& name) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path probe = folder / (".arpos-write-test-" + std::to_string(::getpid()));
  {
    std::ofstream out(probe, std::ios::binary);
    out << "probe";
    out.flush();
    if (!out) {
      const std::string reason = std::strerror(errno);
      fs::remove(probe, ec);
      ARPOS_INPUT_ERROR(name << ": folder not writable: " << folder.string() << " (" << reason << ")");
    }
  }
  fs::remove(probe, ec);
}

}  // namespace

void RequireWritableFolder(const std::filesystem::path& folder, const std::string& option) {
  namespace fs = std::filesystem;
  const std::string name = option + " " + folder.string();
  std::error_code ec;
  if (fs::exists(folder, ec) && !fs::is_directory(folder, ec)) {
    ARPOS_INPUT_ERROR(name << ": not a folder (a file of that name exists)");
  }
  fs::create_directories(folder, ec);
  if (ec) ARPOS_INPUT_ERROR(name << ": cannot create the folder (" << ec.message() << ")");
  ProbeFolder(folder, name);
}

void RequireWritableFileLocation(const std::filesystem::path& file, const std::string& option) {
  namespace fs = std::filesystem;
  const std::string name = option + " " + file.string();
  std::error_code ec;
  if (fs::is_directory(file, ec)) ARPOS_INPUT_ERROR(name << ": is a folder, not a file");
  const fs::path folder = file.parent_path().empty() ? fs::path(".") : file.parent_path();
  if (!fs::is_directory(folder, ec)) {
    ARPOS_INPUT_ERROR(name << ": the folder " << folder.string() << " does not exist");
  }
  ProbeFolder(folder, name);
}

void Controller::Step(const std::string& step, double fraction) {
  ARPOS_DEBUG("step: " << step);
  if (callbacks_.progress) callbacks_.progress(step, fraction);
  if (callbacks_.cancel_requested && callbacks_.cancel_requested()) throw Cancelled();
}

}  // namespace arpos
