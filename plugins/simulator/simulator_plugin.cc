// The simulator plugin's entry (sensor/source_plugin.h).
#include "plugins/simulator/simulator_source.h"
#include "sensor/camera_source.h"
#include "sensor/source_plugin.h"

ARPOS_SOURCE_PLUGIN_EXPORT int arpos_register_camera_sources(arpos::CameraSourceRegistry* registry) {
  registry->Register(
      "sim",
      "sim:CASE_DIR[?seq=N&frames=F&fps=R] renders tracking sequence N of a case written by `arpos simulate` "
      "(F frames, default the case's) and delivers it live at R fps (default the recording's 30); frames are "
      "rendered when the source opens",
      [](const std::string& uri) {
        return std::make_unique<arpos::SimulatorSource>(arpos::ParseSimulatorSourceUri(uri));
      },
      [] {
        arpos::SourceAvailability a;
        a.status = "any simulated case folder (sim:sample_sessions/demo_xtion?frames=300)";
        return a;
      });
  return ARPOS_SOURCE_PLUGIN_API_VERSION;
}
