#pragma once
/// A live OpenNI2 camera (Xtion, Orbbec, Kinect v1 class) as a CameraSource.
///
/// Construction opens the device and configures a colour (RGB888) and a
/// depth (DEPTH_1_MM, else DEPTH_100_UM) stream of the requested size and
/// rate, asks the device to register depth to colour and to synchronise the
/// two, turns mirroring off, and derives the intrinsics from the colour
/// stream's fields of view (openni2_frame.h), so intrinsics() and
/// description() are right before Open(). Open() starts the streams,
/// Close() stops them; the destructor releases the device.
///
/// A missing camera, a mode it does not offer or a camera that reports no
/// field of view is an InputError at construction. A camera that stops
/// delivering (unplugged mid-stream) yields one frame with empty images and
/// RgbdFrame::problem saying so, then Next() returns false.

#include <OpenNI.h>

#include <memory>
#include <string>

#include "sensor/camera_source.h"

namespace arpos {

struct OpenNi2Options {
  std::string device_uri;   ///< OpenNI2's device URI; empty: the first device attached
  int width = 640;          ///< colour and depth, pixels
  int height = 480;
  int fps = 30;
  int frame_timeout_ms = 2000;  ///< no frame for this long: the camera is gone
};

/// "[DEVICE_URI][?width=W&height=H&fps=F]" (the part after "openni2:").
/// Throws InputError for an unknown option or a value that is not a positive
/// integer.
OpenNi2Options ParseOpenNi2Uri(const std::string& uri);

class OpenNi2Source : public CameraSource {
 public:
  /// Opens and configures the device; throws InputError if it cannot.
  explicit OpenNi2Source(OpenNi2Options options);
  ~OpenNi2Source() override;
  OpenNi2Source(const OpenNi2Source&) = delete;
  OpenNi2Source& operator=(const OpenNi2Source&) = delete;

  const CameraIntrinsics& intrinsics() const override { return intrinsics_; }
  /// The device, its mode, and what it could not do (register depth to
  /// colour, synchronise them).
  std::string description() const override;
  bool live() const override { return true; }

 protected:
  void OpenImpl() override;
  bool NextImpl(RgbdFrame* frame) override;
  void CloseImpl() override;

 private:
  /// Waits for the stream's next frame; false with `why` if none came in time.
  bool ReadNext(openni::VideoStream* stream, const char* what, openni::VideoFrameRef* frame, std::string* why);

  /// OpenNI::initialize() for the life of the source, then shutdown()
  /// (OpenNI2 counts them). Declared first: released last.
  struct Runtime {
    Runtime();
    ~Runtime();
  } runtime_;
  OpenNi2Options options_;
  std::string name_;  ///< "openni2:URI" (the device's, once open) or "openni2", for messages
  openni::Device device_;
  openni::VideoStream color_, depth_;
  CameraIntrinsics intrinsics_;
  std::string description_;
  bool streaming_ = false;
  bool ended_ = false;  ///< the camera stopped delivering; Next() says so once
};

/// What `arpos sources` shows for openni2: one line per attached device
/// ("openni2:URI  vendor name"), status "no device attached" when there is
/// none, or why OpenNI2 could not look. Never throws.
SourceAvailability ListOpenNi2Devices();

}  // namespace arpos
