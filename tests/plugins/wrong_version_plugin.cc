// A plugin built for another plugin API: the loader must refuse it.
#include "sensor/source_plugin.h"

ARPOS_SOURCE_PLUGIN_EXPORT int arpos_register_camera_sources(arpos::CameraSourceRegistry*) {
  return ARPOS_SOURCE_PLUGIN_API_VERSION + 41;
}
