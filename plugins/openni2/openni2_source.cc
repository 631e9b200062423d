#include "plugins/openni2/openni2_source.h"

#include <chrono>
#include <initializer_list>
#include <sstream>
#include <vector>

#include "plugins/openni2/openni2_frame.h"
#include "util/check.h"

namespace arpos {
namespace {

constexpr char kNotAllowedHint[] = "is it plugged in, and is the user allowed to use it?";

/// OpenNI2's last error on one line (it comes with tabs and newlines).
std::string OpenNiError() {
  std::string text;
  for (const char* c = openni::OpenNI::getExtendedError(); c && *c; ++c) {
    const bool space = *c == '\t' || *c == '\n' || *c == '\r' || *c == ' ';
    if (space && (text.empty() || text.back() == ' ')) continue;
    text += space ? ' ' : *c;
  }
  while (!text.empty() && text.back() == ' ') text.pop_back();
  return text.empty() ? "no reason given" : text;
}

std::string ModeText(const openni::VideoMode& mode) {
  std::ostringstream text;
  text << mode.getResolutionX() << "x" << mode.getResolutionY() << "@" << mode.getFps() << " "
       << OpenNi2PixelFormatName(mode.getPixelFormat());
  return text.str();
}

bool SameMode(const openni::VideoMode& a, const openni::VideoMode& b) {
  return a.getResolutionX() == b.getResolutionX() && a.getResolutionY() == b.getResolutionY() &&
         a.getFps() == b.getFps() && a.getPixelFormat() == b.getPixelFormat();
}

/// Sets `stream` to the options' size and rate in the first of `formats` the
/// sensor offers; InputError naming the modes it has otherwise.
void SetMode(openni::VideoStream* stream, const char* what, const OpenNi2Options& options,
             std::initializer_list<openni::PixelFormat> formats, const std::string& name) {
  const openni::Array<openni::VideoMode>& modes = stream->getSensorInfo().getSupportedVideoModes();
  for (const openni::PixelFormat format : formats) {
    for (int i = 0; i < modes.getSize(); ++i) {
      const openni::VideoMode& mode = modes[i];
      if (mode.getResolutionX() != options.width || mode.getResolutionY() != options.height ||
          mode.getFps() != options.fps || mode.getPixelFormat() != format) {
        continue;
      }
      // Some drivers refuse to set the mode they are already in.
      if (SameMode(stream->getVideoMode(), mode)) return;
      if (stream->setVideoMode(mode) != openni::STATUS_OK) {
        ARPOS_INPUT_ERROR(name << ": its " << what << " stream refused the mode " << ModeText(mode) << " ("
                          << OpenNiError() << ")");
      }
      return;
    }
  }
  std::ostringstream wanted, offered;
  for (const openni::PixelFormat format : formats) {
    wanted << (wanted.tellp() > 0 ? " or " : "") << OpenNi2PixelFormatName(format);
  }
  for (int i = 0; i < modes.getSize(); ++i) offered << (i ? ", " : "") << ModeText(modes[i]);
  ARPOS_INPUT_ERROR(name << ": its " << what << " stream has no " << options.width << "x" << options.height << " at "
                    << options.fps << " fps in " << wanted.str() << "; it offers "
                    << (modes.getSize() ? offered.str() : std::string("none"))
                    << " (choose with ?width=W&height=H&fps=F)");
}

OpenNi2Image ImageOf(const openni::VideoFrameRef& frame) {
  OpenNi2Image image;
  image.data = frame.getData();
  image.data_size = frame.getDataSize();
  image.width = frame.getWidth();
  image.height = frame.getHeight();
  image.stride_bytes = frame.getStrideInBytes();
  image.format = frame.getVideoMode().getPixelFormat();
  image.timestamp_us = frame.getTimestamp();
  return image;
}

}  // namespace

OpenNi2Options ParseOpenNi2Uri(const std::string& uri) {
  OpenNi2Options options;
  const SourceUri parsed = ParseSourceUri(uri);
  options.device_uri = parsed.path;
  for (const auto& [key, value] : parsed.options) {
    int* target = key == "width" ? &options.width : key == "height" ? &options.height : key == "fps" ? &options.fps : nullptr;
    if (target == nullptr) {
      ARPOS_INPUT_ERROR("openni2:" << uri << ": unknown option '" << key << "' (known: width, height, fps)");
    }
    *target = SourceUriInt("openni2:" + uri, key, value);
    if (*target <= 0) ARPOS_INPUT_ERROR("openni2:" << uri << ": " << key << " must be positive, got '" << value << "'");
  }
  return options;
}

OpenNi2Source::Runtime::Runtime() {
  if (openni::OpenNI::initialize() != openni::STATUS_OK) {
    ARPOS_INPUT_ERROR("openni2: OpenNI2 could not start (" << OpenNiError() << ")");
  }
}

OpenNi2Source::Runtime::~Runtime() { openni::OpenNI::shutdown(); }

OpenNi2Source::OpenNi2Source(OpenNi2Options options)
    : options_(std::move(options)),
      name_(options_.device_uri.empty() ? "openni2" : "openni2:" + options_.device_uri) {
  const bool any = options_.device_uri.empty();
  if (any) {
    openni::Array<openni::DeviceInfo> devices;
    openni::OpenNI::enumerateDevices(&devices);
    if (devices.getSize() == 0) ARPOS_INPUT_ERROR(name_ << ": no OpenNI2 device attached (" << kNotAllowedHint << ")");
  }
  if (device_.open(any ? openni::ANY_DEVICE : options_.device_uri.c_str()) != openni::STATUS_OK) {
    ARPOS_INPUT_ERROR(name_ << ": cannot open " << (any ? "the attached OpenNI2 device" : "this OpenNI2 device") << " ("
                      << OpenNiError() << "); " << kNotAllowedHint);
  }
  const openni::DeviceInfo& info = device_.getDeviceInfo();
  name_ = std::string("openni2:") + info.getUri();
  for (const auto& [sensor, what] : {std::pair<openni::SensorType, const char*>{openni::SENSOR_COLOR, "colour"},
                                     std::pair<openni::SensorType, const char*>{openni::SENSOR_DEPTH, "depth"}}) {
    openni::VideoStream& stream = sensor == openni::SENSOR_COLOR ? color_ : depth_;
    if (!device_.hasSensor(sensor)) ARPOS_INPUT_ERROR(name_ << ": the device has no " << what << " camera");
    if (stream.create(device_, sensor) != openni::STATUS_OK) {
      ARPOS_INPUT_ERROR(name_ << ": cannot create its " << what << " stream (" << OpenNiError() << ")");
    }
    // Mirrored images flip x: every pose would be one of a mirror world.
    stream.setMirroringEnabled(false);
    if (stream.getMirroringEnabled()) ARPOS_INPUT_ERROR(name_ << ": its " << what << " stream cannot stop mirroring");
  }
  SetMode(&color_, "colour", options_, {openni::PIXEL_FORMAT_RGB888}, name_);
  SetMode(&depth_, "depth", options_, {openni::PIXEL_FORMAT_DEPTH_1_MM, openni::PIXEL_FORMAT_DEPTH_100_UM}, name_);

  std::vector<std::string> notes;
  if (!device_.isImageRegistrationModeSupported(openni::IMAGE_REGISTRATION_DEPTH_TO_COLOR)) {
    notes.push_back("depth NOT registered to colour (the device cannot)");
  } else if (device_.setImageRegistrationMode(openni::IMAGE_REGISTRATION_DEPTH_TO_COLOR) != openni::STATUS_OK) {
    notes.push_back("depth NOT registered to colour (" + OpenNiError() + ")");
  }
  if (device_.setDepthColorSyncEnabled(true) != openni::STATUS_OK) {
    notes.push_back("colour and depth not synchronised by the device");
  }
  const double depth_scale = OpenNi2DepthScale(depth_.getVideoMode().getPixelFormat());
  try {
    // Depth is registered to colour: the colour camera's model serves both.
    intrinsics_ = IntrinsicsFromOpenNi2FieldOfView(options_.width, options_.height, color_.getHorizontalFieldOfView(),
                                                   color_.getVerticalFieldOfView(), depth_scale);
  } catch (const InputError& e) {
    ARPOS_INPUT_ERROR(name_ << ": " << e.what());
  }
  std::ostringstream text;
  text << "OpenNI2 " << info.getVendor() << (*info.getName() ? " " : "") << info.getName() << " (" << name_ << "), "
       << options_.width << "x" << options_.height << " at " << options_.fps << " fps, depth in "
       << (depth_scale == 1000 ? "1 mm" : "0.1 mm") << ", intrinsics from its fields of view (fx " << intrinsics_.fx
       << ", fy " << intrinsics_.fy << ", no distortion)";
  for (const std::string& note : notes) text << "; " << note;
  description_ = text.str();
}

OpenNi2Source::~OpenNi2Source() {
  if (streaming_) CloseImpl();
}

std::string OpenNi2Source::description() const { return description_; }

void OpenNi2Source::OpenImpl() {
  ended_ = false;
  for (const auto& [stream, what] : {std::pair<openni::VideoStream*, const char*>{&color_, "colour"},
                                     std::pair<openni::VideoStream*, const char*>{&depth_, "depth"}}) {
    if (stream->start() != openni::STATUS_OK) {
      const std::string why = OpenNiError();
      CloseImpl();
      ARPOS_INPUT_ERROR(name_ << ": cannot start its " << what << " stream (" << why << ")");
    }
    streaming_ = true;
  }
}

void OpenNi2Source::CloseImpl() {
  depth_.stop();
  color_.stop();
  streaming_ = false;
}

bool OpenNi2Source::ReadNext(openni::VideoStream* stream, const char* what, openni::VideoFrameRef* frame,
                             std::string* why) {
  int ready = -1;
  const openni::Status waited = openni::OpenNI::waitForAnyStream(&stream, 1, &ready, options_.frame_timeout_ms);
  if (waited == openni::STATUS_OK && stream->readFrame(frame) == openni::STATUS_OK && frame->isValid()) return true;
  std::ostringstream text;
  if (waited == openni::STATUS_TIME_OUT) {
    text << name_ << ": no " << what << " frame for " << options_.frame_timeout_ms / 1000.0
         << " s; the camera stopped (unplugged?)";
  } else {
    text << name_ << ": reading its " << what << " stream failed (" << OpenNiError() << "); the camera stopped";
  }
  *why = text.str();
  return false;
}

bool OpenNi2Source::NextImpl(RgbdFrame* frame) {
  if (ended_) return false;
  openni::VideoFrameRef color, depth;
  std::string why;
  bool ok = ReadNext(&depth_, "depth", &depth, &why) && ReadNext(&color_, "colour", &color, &why);
  // With sync on, OpenNI2 gives corresponding frames the same index; a new
  // frame may have arrived between the two reads: catch the other stream up
  // once, no more (a device whose indices never match costs one frame).
  if (ok && color.getFrameIndex() != depth.getFrameIndex()) {
    ok = color.getFrameIndex() < depth.getFrameIndex() ? ReadNext(&color_, "colour", &color, &why)
                                                       : ReadNext(&depth_, "depth", &depth, &why);
  }
  const auto arrival = std::chrono::steady_clock::now();
  if (ok) {
    *frame = RgbdFrameFromOpenNi2(ImageOf(color), ImageOf(depth));
  } else {
    // The camera is gone: one frame that says so, then the end of the stream.
    ended_ = true;
    *frame = RgbdFrame();
    frame->problem = why;
  }
  frame->index = frames_delivered();
  frame->arrival = arrival;
  return true;
}

SourceAvailability ListOpenNi2Devices() {
  SourceAvailability availability;
  try {
    if (openni::OpenNI::initialize() != openni::STATUS_OK) {
      availability.status = "OpenNI2 could not start (" + OpenNiError() + ")";
      return availability;
    }
    openni::Array<openni::DeviceInfo> devices;
    openni::OpenNI::enumerateDevices(&devices);
    for (int i = 0; i < devices.getSize(); ++i) {
      availability.devices.push_back(std::string("openni2:") + devices[i].getUri() + "  " + devices[i].getVendor() +
                                     " " + devices[i].getName());
    }
    openni::OpenNI::shutdown();
    const int n = devices.getSize();
    availability.status = n == 0 ? "no device attached" : std::to_string(n) + (n == 1 ? " device" : " devices");
  } catch (const std::exception& e) {
    availability.status = std::string("OpenNI2 could not list devices (") + e.what() + ")";
  }
  return availability;
}

}  // namespace arpos
