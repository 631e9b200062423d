// `arpos sources`: the camera sources this installation can open.
#include <iostream>

#include "exe/args.h"
#include "exe/commands.h"
#include "sensor/camera_source.h"
#include "sensor/source_plugin.h"

namespace arpos {

int RunSourcesCommand(const std::vector<std::string>& argv) {
  const char* usage =
      "usage: arpos sources\n"
      "Lists the camera sources (plugins loaded from $ARPOS_PLUGIN_PATH, else\n"
      "<install>/lib/arpos/plugins), what each can open now (attached devices), and any\n"
      "plugin that could not be loaded, with why. Use one with `arpos record --source SPEC`\n"
      "or `arpos track --source SPEC`.\n";
  const Args args(argv, {}, {"help"});
  if (auto exit = UsageExit(args, usage, 0)) return *exit;
  const std::vector<SourcePluginLoad>& loads = EnsureSourcePluginsLoaded();
  const auto kinds = SourceRegistry().Kinds();
  if (kinds.empty()) std::cout << "no camera source: no plugin was loaded\n";
  for (const auto& kind : kinds) {
    std::cout << kind.name << "  (" << kind.origin << ")\n  " << kind.help << "\n";
    if (kind.lister) {
      SourceAvailability available;
      try {
        available = kind.lister();
      } catch (const std::exception& e) {
        available.status = std::string("could not list: ") + e.what();
      }
      std::cout << "  now: " << available.status << "\n";
      for (const auto& device : available.devices) std::cout << "    " << device << "\n";
    }
  }
  int failed = 0;
  for (const auto& load : loads) {
    if (load.loaded) continue;
    ++failed;
    std::cout << "not loaded: " << load.path.string() << ": " << load.error << "\n";
  }
  if (loads.empty()) {
    std::cout << "no plugin folder found (searched:";
    for (const auto& dir : DefaultSourcePluginDirs()) std::cout << " " << dir.string();
    std::cout << ")\n";
  }
  return kinds.empty() ? 1 : 0;
}

}  // namespace arpos
