#pragma once
/// The OpenNI2 plugin's pure part, which needs no device: an RgbdFrame from
/// the buffers an OpenNI2 device delivers, and the pinhole model of a camera
/// from the fields of view it reports. Tested on a real Kinect v1 frame
/// (tests/plugins/openni2_frame_test.cc).

#include <OniEnums.h>

#include <cstdint>
#include <string>

#include "sensor/intrinsics.h"
#include "sensor/rgbd_frame.h"

namespace arpos {

/// One image as openni::VideoFrameRef hands it over. The bytes are borrowed:
/// they must stay valid during the conversion, which copies them.
struct OpenNi2Image {
  const void* data = nullptr;  ///< getData()
  int data_size = 0;           ///< getDataSize(): bytes readable at `data`
  int width = 0;               ///< getWidth(), pixels
  int height = 0;              ///< getHeight(), pixels
  int stride_bytes = 0;        ///< getStrideInBytes(): from the start of one row to the next
  openni::PixelFormat format = openni::PIXEL_FORMAT_RGB888;  ///< getVideoMode().getPixelFormat()
  uint64_t timestamp_us = 0;   ///< getTimestamp(): microseconds on the device's clock
};

/// "RGB888", "DEPTH_1_MM", ...; "pixel format N" for a value OpenNI2 2.2 does not name.
std::string OpenNi2PixelFormatName(openni::PixelFormat format);

/// Depth units per metre of an OpenNI2 depth format: 1000 for DEPTH_1_MM,
/// 10000 for DEPTH_100_UM, 0 for any other format (shift values, colour).
double OpenNi2DepthScale(openni::PixelFormat format);

/// Copies an RGB888 colour image and a DEPTH_1_MM or DEPTH_100_UM depth image
/// (uint16 per pixel, 0 = no reading; rows `stride_bytes` apart, padding
/// ignored) into a frame of its own:
/// - colour: CV_8UC3 in BGR order (OpenNI2's RGB888 is R, G, B in memory);
/// - depth: CV_16UC1 with the values unchanged, depth_scale 1000 (1 mm) or
///   10000 (100 µm);
/// - timestamp_s: the colour timestamp in seconds on the device's clock
///   (not related to wall time); depth_delay_s: the depth's timestamp minus
///   the colour's, when within kFrameAssociationS (a device without
///   colour-depth sync takes them apart: sensor/depth_timing.h);
/// - index and arrival are left for the source to fill.
/// Depth must have the colour's size: a device that registers depth to
/// colour delivers it so. Depth of another size is not registered to this
/// colour image and is dropped, as is depth in another format.
/// Never throws for bad buffers: what cannot be used is left empty and
/// RgbdFrame::problem says why (a null or short buffer, a stride smaller than
/// a row, an unexpected format, a size mismatch); problems are joined by "; ".
RgbdFrame RgbdFrameFromOpenNi2(const OpenNi2Image& color, const OpenNi2Image& depth);

/// The pinhole model an OpenNI2 device implies by its fields of view
/// (openni::VideoStream::getHorizontalFieldOfView/getVerticalFieldOfView,
/// radians, full angles), the model OpenNI2 itself uses to turn depth pixels
/// into points (CoordinateConverter::convertDepthToWorld):
///   fx = width / (2 tan(hfov / 2)),  fy = height / (2 tan(vfov / 2)),
///   cx = width / 2,                  cy = height / 2.
/// In this project's convention (intrinsics.h: pixel centres at integers) a
/// principal point exactly at the image centre would be (width - 1) / 2;
/// OpenNI2 and the point clouds PCL records from such cameras use width / 2,
/// half a pixel right and down of it (0.86 mm along each axis at 0.9 m for
/// fx 525). We keep OpenNI2's convention so that our points equal the
/// device's own. The result is nominal: devices report no distortion, so the
/// distortion is zero, and a calibrated camera (case.yaml) is better.
/// Throws InputError if a field of view is not in (0, pi) (a device that
/// reports none says 0), or if the result is implausible
/// (CameraIntrinsics::Validate, e.g. pixels far from square).
CameraIntrinsics IntrinsicsFromOpenNi2FieldOfView(int width, int height, double horizontal_fov_rad,
                                                  double vertical_fov_rad, double depth_scale);

}  // namespace arpos
