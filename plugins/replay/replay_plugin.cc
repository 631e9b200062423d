// The replay plugin's entry (sensor/source_plugin.h).
#include "plugins/replay/replay_source.h"
#include "sensor/camera_source.h"
#include "sensor/source_plugin.h"

ARPOS_SOURCE_PLUGIN_EXPORT int arpos_register_camera_sources(arpos::CameraSourceRegistry* registry) {
  registry->Register(
      "replay",
      "replay:SEQUENCE_DIR[?realtime] plays a recorded sequence (DATASET.md layout) as if live; "
      "intrinsics from the case.yaml above it; ?realtime paces frames at the recorded rate",
      [](const std::string& uri) { return arpos::MakeReplaySourceFromUri(uri); },
      [] {
        arpos::SourceAvailability a;
        a.status = "any recorded sequence folder (replay:case/tracking/seq_00)";
        return a;
      });
  return ARPOS_SOURCE_PLUGIN_API_VERSION;
}
