// The OpenNI2 plugin's entry (sensor/source_plugin.h).
#include "plugins/openni2/openni2_source.h"
#include "sensor/camera_source.h"
#include "sensor/source_plugin.h"

ARPOS_SOURCE_PLUGIN_EXPORT int arpos_register_camera_sources(arpos::CameraSourceRegistry* registry) {
  registry->Register(
      "openni2",
      "openni2:[DEVICE_URI][?width=640&height=480&fps=30] a live OpenNI2 camera (Xtion, Orbbec, Kinect v1 "
      "class); no URI: the first one attached; depth registered to colour by the device where it can; "
      "intrinsics from the device's fields of view, no distortion (a case's calibration is better)",
      [](const std::string& uri) {
        return std::make_unique<arpos::OpenNi2Source>(arpos::ParseOpenNi2Uri(uri));
      },
      [] { return arpos::ListOpenNi2Devices(); });
  return ARPOS_SOURCE_PLUGIN_API_VERSION;
}
