// The replay plugin's entry (sensor/source_plugin.h).
#include "plugins/replay/replay_source.h"
#include "sensor/camera_source.h"
#include "sensor/source_plugin.h"

ARPOS_SOURCE_PLUGIN_EXPORT int arpos_register_camera_sources(arpos::CameraSourceRegistry* registry) {
  registry->Register(
      "replay",
      "replay:SEQUENCE_DIR[?realtime&case=DIR] plays a recorded sequence (DATASET.md layout); the camera "
      "from the case.yaml above it (or in DIR); realtime: at the recorded rate, as a live camera",
      [](const std::string& uri) { return arpos::MakeReplaySourceFromUri(uri); },
      [] {
        arpos::SourceAvailability a;
        a.status = "any recorded sequence folder (replay:case/tracking/seq_00)";
        return a;
      });
  return ARPOS_SOURCE_PLUGIN_API_VERSION;
}
