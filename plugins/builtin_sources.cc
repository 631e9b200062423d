#include "plugins/builtin_sources.h"

#include "plugins/replay/replay_source.h"
#include "sensor/camera_source.h"

namespace arpos {

void RegisterBuiltinCameraSources() {
  auto& registry = CameraSourceRegistry::Global();
  registry.Register("replay",
                    "replay:SEQUENCE_DIR plays a recorded sequence as if live (intrinsics from "
                    "the case.yaml two or three folders up)",
                    [](const std::string& uri) { return MakeReplaySourceFromUri(uri); });
}

}  // namespace arpos
