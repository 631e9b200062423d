#include "sensor/source_plugin.h"

#include <dlfcn.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <mutex>
#include <set>
#include <sstream>

#include "sensor/camera_source.h"

namespace arpos {

std::vector<std::filesystem::path> DefaultSourcePluginDirs() {
  std::vector<std::filesystem::path> dirs;
  if (const char* env = std::getenv("ARPOS_PLUGIN_PATH"); env && *env) {
    std::stringstream list(env);
    std::string dir;
    while (std::getline(list, dir, ':')) {
      if (!dir.empty()) dirs.emplace_back(dir);
    }
    return dirs;
  }
  std::error_code ec;
  const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (!ec) dirs.push_back(exe.parent_path().parent_path() / "lib" / "arpos" / "plugins");
  return dirs;
}

std::vector<SourcePluginLoad> LoadSourcePlugins(CameraSourceRegistry* registry,
                                                const std::vector<std::filesystem::path>& dirs) {
  std::vector<SourcePluginLoad> loads;
  std::set<std::string> seen;
  for (const auto& dir : dirs) {
    std::error_code ec;
    if (!std::filesystem::is_directory(dir, ec)) continue;
    std::vector<std::filesystem::path> files;
    for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
      const std::string name = entry.path().filename().string();
      if (name.rfind("libarpos_source_", 0) == 0 && entry.path().extension() == ".so") files.push_back(entry.path());
    }
    std::sort(files.begin(), files.end());
    for (const auto& file : files) {
      if (!seen.insert(file.filename().string()).second) continue;
      SourcePluginLoad load;
      load.path = file;
      void* handle = dlopen(file.c_str(), RTLD_NOW | RTLD_LOCAL);
      if (!handle) {
        const char* why = dlerror();
        load.error = why ? why : "dlopen failed";
        loads.push_back(load);
        continue;
      }
      auto entry = reinterpret_cast<ArposRegisterSourcesFn>(dlsym(handle, ARPOS_SOURCE_PLUGIN_ENTRY));
      if (!entry) {
        load.error = std::string("no ") + ARPOS_SOURCE_PLUGIN_ENTRY + " entry point";
        dlclose(handle);
        loads.push_back(load);
        continue;
      }
      // The entry registers into a scratch registry first, so that a plugin of
      // another API version leaves nothing behind.
      CameraSourceRegistry scratch;
      int version = 0;
      try {
        version = entry(&scratch);
      } catch (const std::exception& e) {
        load.error = std::string("its registration failed: ") + e.what();
      }
      if (load.error.empty() && version != ARPOS_SOURCE_PLUGIN_API_VERSION) {
        std::ostringstream why;
        why << "built for plugin API " << version << ", this arpos has " << ARPOS_SOURCE_PLUGIN_API_VERSION;
        load.error = why.str();
      }
      if (load.error.empty()) {
        registry->Merge(std::move(scratch), file.filename().string());
        load.loaded = true;
      }
      // Never dlclose a loaded plugin: its code backs the registered factories.
      loads.push_back(load);
    }
  }
  return loads;
}

const std::vector<SourcePluginLoad>& EnsureSourcePluginsLoaded() {
  static std::once_flag once;
  static std::vector<SourcePluginLoad> loads;
  std::call_once(once, [] { loads = LoadSourcePlugins(&CameraSourceRegistry::Global(), DefaultSourcePluginDirs()); });
  return loads;
}

CameraSourceRegistry& SourceRegistry() {
  EnsureSourcePluginsLoaded();
  return CameraSourceRegistry::Global();
}

}  // namespace arpos
