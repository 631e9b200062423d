#pragma once
/// The boundary between the executable and a camera-source plugin.
///
/// A plugin is a shared library under plugins/<name>/ (CMake:
/// arpos_source_plugin), built as libarpos_source_<name>.so into
/// <build>/lib/arpos/plugins/ and installed beside the executable's lib/.
/// It exports one C function, ARPOS_SOURCE_PLUGIN_ENTRY, which registers its
/// sources with the registry it is handed and returns the API version it was
/// built against. Nothing registers itself from a static initialiser: the
/// executable calls LoadSourcePlugins, which dlopens each plugin and calls
/// its entry explicitly.
///
/// Plugins link the project's static libraries privately and export nothing
/// else (hidden visibility, --exclude-libs): their copies of project code
/// never interpose on the executable's.

#include <filesystem>
#include <string>
#include <vector>

namespace arpos {
class CameraSourceRegistry;
}

/// Bumped whenever CameraSource, CameraSourceRegistry or RgbdFrame change
/// layout or meaning; a plugin built against another version is refused.
#define ARPOS_SOURCE_PLUGIN_API_VERSION 2
#define ARPOS_SOURCE_PLUGIN_ENTRY "arpos_register_camera_sources"

/// What a plugin defines (one per plugin):
///   ARPOS_SOURCE_PLUGIN_EXPORT int arpos_register_camera_sources(
///       arpos::CameraSourceRegistry* registry) {
///     registry->Register(...);
///     return ARPOS_SOURCE_PLUGIN_API_VERSION;
///   }
#define ARPOS_SOURCE_PLUGIN_EXPORT extern "C" __attribute__((visibility("default")))
using ArposRegisterSourcesFn = int (*)(arpos::CameraSourceRegistry*);

namespace arpos {

struct SourcePluginLoad {
  std::filesystem::path path;
  bool loaded = false;
  std::string error;  ///< why it was not loaded (dlopen's words, a missing entry, a version)
};

/// The folders searched for plugins: $ARPOS_PLUGIN_PATH (colon-separated) if
/// set, else <executable's folder>/../lib/arpos/plugins.
std::vector<std::filesystem::path> DefaultSourcePluginDirs();

/// Loads every libarpos_source_*.so in `dirs` (in order; a file name already
/// loaded from an earlier folder is skipped) and calls its entry with
/// `registry`. Never throws for a plugin that cannot be loaded: its report
/// says why, and `arpos sources` shows it. Libraries stay loaded for the
/// life of the process.
std::vector<SourcePluginLoad> LoadSourcePlugins(CameraSourceRegistry* registry,
                                                const std::vector<std::filesystem::path>& dirs);

/// Loads the default folders' plugins into CameraSourceRegistry::Global()
/// the first time it is called (thread-safe) and returns what happened to
/// each plugin. Commands that open a camera source call it.
const std::vector<SourcePluginLoad>& EnsureSourcePluginsLoaded();

/// The registry with the default plugins loaded: EnsureSourcePluginsLoaded()
/// then CameraSourceRegistry::Global().
CameraSourceRegistry& SourceRegistry();

}  // namespace arpos
