// The OpenNI2 plugin without a camera: its frame conversion and intrinsics
// (plugins/openni2/openni2_frame.cc, compiled in) on a real Kinect v1 frame,
// checked against PCL's organized cloud of the same frame; and the plugin as
// the executable loads it, on a machine with no camera attached.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <pcl/PCLPointCloud2.h>
#include <pcl/io/pcd_io.h>
#include <vector>

#include "plugins/openni2/openni2_frame.h"
#include "sensor/camera_source.h"
#include "sensor/source_plugin.h"
#include "util/check.h"

namespace arpos {
namespace {

// Three consecutive real Kinect v1 frames recorded by PCL's grabber
// (../shared/data/pcl_kinect/SOURCE.txt); the middle one. The colour TIFF
// holds R, G, B (OpenCV reads it as BGR); the depth TIFF holds uint16 mm.
const std::string kFrames = std::string(ARPOS_SHARED_DATA_DIR) + "/pcl_kinect/grabber_sequences/";
const std::string kFrame = "frame_20121214T142256.068683";

constexpr double kPi = 3.14159265358979323846;
double Deg(double rad) { return rad * 180 / kPi; }
double Rad(double deg) { return deg * kPi / 180; }

/// The bytes of one image as an OpenNI2 frame would hold them: rows of
/// `row_bytes` followed by `padding` bytes of junk.
struct Buffer {
  std::vector<unsigned char> bytes;
  OpenNi2Image image;
};

Buffer AsOpenNi2(const cv::Mat& pixels, openni::PixelFormat format, int padding, uint64_t timestamp_us) {
  Buffer b;
  const int row_bytes = pixels.cols * static_cast<int>(pixels.elemSize());
  const int stride = row_bytes + padding;
  b.bytes.assign(static_cast<size_t>(stride) * pixels.rows, 0xAB);
  for (int y = 0; y < pixels.rows; ++y) std::memcpy(&b.bytes[static_cast<size_t>(y) * stride], pixels.ptr(y), row_bytes);
  b.image.data = b.bytes.data();
  b.image.data_size = static_cast<int>(b.bytes.size());
  b.image.width = pixels.cols;
  b.image.height = pixels.rows;
  b.image.stride_bytes = stride;
  b.image.format = format;
  b.image.timestamp_us = timestamp_us;
  return b;
}

struct KinectFrame {
  cv::Mat bgr;    // as OpenCV reads the TIFF
  cv::Mat depth;  // uint16 mm
  Buffer color_buffer, depth_buffer;  // as OpenNI2 delivers them: RGB888 and DEPTH_1_MM, padded rows
};

constexpr uint64_t kTimestampUs = 51234567890ULL;  // ~14 h after the device started

KinectFrame LoadKinectFrame() {
  KinectFrame f;
  f.bgr = cv::imread(kFrames + "tiff/" + kFrame + "_rgb.tiff", cv::IMREAD_UNCHANGED);
  f.depth = cv::imread(kFrames + "tiff/" + kFrame + "_depth.tiff", cv::IMREAD_UNCHANGED);
  ARPOS_CHECK(f.bgr.type() == CV_8UC3 && f.depth.type() == CV_16UC1, "cannot read the Kinect frame's TIFFs");
  cv::Mat rgb;
  cv::cvtColor(f.bgr, rgb, cv::COLOR_BGR2RGB);
  // Odd paddings: strides that are not a multiple of the pixel size.
  f.color_buffer = AsOpenNi2(rgb, openni::PIXEL_FORMAT_RGB888, 7, kTimestampUs);
  f.depth_buffer = AsOpenNi2(f.depth, openni::PIXEL_FORMAT_DEPTH_1_MM, 3, kTimestampUs + 120);
  return f;
}

/// PCL's organized cloud of the frame, read as PCL reads it (binary_compressed).
struct PclCloud {
  int width = 0, height = 0;
  std::vector<float> xyz;      // 3 per pixel, NaN where there is no depth
  std::vector<uint32_t> rgba;  // packed 0xAARRGGBB per pixel
};

PclCloud LoadPclCloud() {
  pcl::PCLPointCloud2 cloud;
  pcl::PCDReader reader;
  const std::string path = kFrames + "pcd/" + kFrame + ".pcd";
  ARPOS_CHECK(reader.read(path, cloud) == 0, "PCL cannot read " << path);
  const auto offset = [&](const std::string& name) {
    for (const auto& field : cloud.fields) {
      if (field.name == name) return static_cast<size_t>(field.offset);
    }
    ARPOS_CHECK(false, path << " has no field " << name);
    return size_t{0};
  };
  const size_t ox = offset("x"), oy = offset("y"), oz = offset("z"), oc = offset("rgba");
  PclCloud out;
  out.width = static_cast<int>(cloud.width);
  out.height = static_cast<int>(cloud.height);
  const size_t n = static_cast<size_t>(out.width) * out.height;
  out.xyz.resize(3 * n);
  out.rgba.resize(n);
  for (size_t i = 0; i < n; ++i) {
    const unsigned char* point = &cloud.data[i * cloud.point_step];
    std::memcpy(&out.xyz[3 * i + 0], point + ox, 4);
    std::memcpy(&out.xyz[3 * i + 1], point + oy, 4);
    std::memcpy(&out.xyz[3 * i + 2], point + oz, 4);
    std::memcpy(&out.rgba[i], point + oc, 4);
  }
  return out;
}

/// The fields of view a camera with these pinhole parameters reports.
double FovRad(int pixels, double focal_px) { return 2 * std::atan(pixels / (2 * focal_px)); }

TEST(Openni2Frame, ARealKinectFrameComesThroughUnchanged) {
  const KinectFrame k = LoadKinectFrame();
  const RgbdFrame frame = RgbdFrameFromOpenNi2(k.color_buffer.image, k.depth_buffer.image);
  EXPECT_EQ(frame.problem, "");
  ASSERT_EQ(frame.color.type(), CV_8UC3);
  ASSERT_EQ(frame.depth.type(), CV_16UC1);
  ASSERT_EQ(frame.color.size(), cv::Size(640, 480));
  ASSERT_EQ(frame.depth.size(), cv::Size(640, 480));
  // BGR, every pixel as the image file has it; depth value for value.
  EXPECT_EQ(cv::norm(frame.color, k.bgr, cv::NORM_INF), 0);
  EXPECT_EQ(cv::norm(frame.depth, k.depth, cv::NORM_INF), 0);
  EXPECT_EQ(frame.depth_scale, 1000);
  EXPECT_DOUBLE_EQ(frame.timestamp_s, 51234.56789);  // the colour's microseconds, in seconds
  EXPECT_NEAR(frame.depth_delay_s, 120e-6, 1e-9);    // the depth's own instant, 120 us later
  EXPECT_EQ(frame.index, -1);  // the source numbers its frames

  std::vector<uint16_t> valid;
  for (int v = 0; v < frame.depth.rows; ++v) {
    for (int u = 0; u < frame.depth.cols; ++u) {
      if (const uint16_t d = frame.depth.at<uint16_t>(v, u)) valid.push_back(d);
    }
  }
  const double valid_fraction = static_cast<double>(valid.size()) / frame.depth.total();
  std::nth_element(valid.begin(), valid.begin() + valid.size() / 2, valid.end());
  const double median_m = valid[valid.size() / 2] / frame.depth_scale;
  EXPECT_NEAR(valid_fraction, 0.883, 0.001);
  EXPECT_NEAR(median_m, 0.880, 0.001);
  EXPECT_DOUBLE_EQ(frame.DepthM(320, 240), 0.860);
  std::printf("Kinect frame: %.1f %% valid depth, median %.3f m\n", 100 * valid_fraction, median_m);
}

TEST(Openni2Frame, DepthIn100MicrometreUnitsKeepsItsValuesAndScale) {
  const KinectFrame k = LoadKinectFrame();
  cv::Mat depth_100um;
  k.depth.convertTo(depth_100um, CV_16UC1, 10);  // mm -> 0.1 mm (max 65535: 6.5 m)
  const Buffer depth = AsOpenNi2(depth_100um, openni::PIXEL_FORMAT_DEPTH_100_UM, 0, kTimestampUs);
  const RgbdFrame frame = RgbdFrameFromOpenNi2(k.color_buffer.image, depth.image);
  EXPECT_EQ(frame.problem, "");
  EXPECT_EQ(frame.depth_scale, 10000);
  EXPECT_EQ(cv::norm(frame.depth, depth_100um, cv::NORM_INF), 0);
  EXPECT_DOUBLE_EQ(frame.DepthM(320, 240), 0.860);
  EXPECT_DOUBLE_EQ(frame.DepthM(100, 100), 1.273);
  // A depth image 25 ms from its colour is not one a frame pairs: no delay.
  const Buffer late =
      AsOpenNi2(depth_100um, openni::PIXEL_FORMAT_DEPTH_100_UM, 0, kTimestampUs + 25000);
  EXPECT_EQ(RgbdFrameFromOpenNi2(k.color_buffer.image, late.image).depth_delay_s, 0.0);
}

TEST(Openni2Frame, KinectFieldsOfViewGiveItsIntrinsics) {
  // The Kinect v1 colour camera's published fields of view (Microsoft's
  // NUI_CAMERA_COLOR_NOMINAL_*_FOV, what libfreenect's OpenNI2 driver
  // reports): 62.0 x 48.6 degrees.
  const CameraIntrinsics published = IntrinsicsFromOpenNi2FieldOfView(640, 480, Rad(62.0), Rad(48.6), 1000);
  EXPECT_NEAR(published.fx, 532.57, 0.01);
  EXPECT_NEAR(published.fy, 531.54, 0.01);
  // The same cameras' usual calibration (the frames' own, pclzf/*.xml):
  // fx = fy = 525; the nominal values are 1.2-1.4 % longer.
  EXPECT_NEAR(published.fx / 525, 1.0, 0.015);
  EXPECT_NEAR(published.fy / 525, 1.0, 0.015);
  EXPECT_EQ(published.cx, 320);
  EXPECT_EQ(published.cy, 240);
  EXPECT_FALSE(published.HasDistortion());
  EXPECT_EQ(published.Validate(), "");
  std::printf("Kinect v1 nominal 62.0 x 48.6 deg: fx %.2f fy %.2f cx %.1f cy %.1f\n", published.fx, published.fy,
              published.cx, published.cy);

  // A camera whose focal length is 525 px reports 62.73 x 49.13 degrees, and
  // they give back exactly its intrinsics.
  const CameraIntrinsics k = IntrinsicsFromOpenNi2FieldOfView(640, 480, FovRad(640, 525), FovRad(480, 525), 1000);
  EXPECT_NEAR(Deg(FovRad(640, 525)), 62.73, 0.01);
  EXPECT_NEAR(Deg(FovRad(480, 525)), 49.13, 0.01);
  EXPECT_NEAR(k.fx, 525, 1e-9);
  EXPECT_NEAR(k.fy, 525, 1e-9);
  EXPECT_EQ(k.depth_scale, 1000);
}

TEST(Openni2Frame, BackProjectedDepthEqualsPclsCloudOfTheSameFrame) {
  const KinectFrame k = LoadKinectFrame();
  const RgbdFrame frame = RgbdFrameFromOpenNi2(k.color_buffer.image, k.depth_buffer.image);
  const CameraIntrinsics intrinsics =
      IntrinsicsFromOpenNi2FieldOfView(640, 480, FovRad(640, 525), FovRad(480, 525), frame.depth_scale);
  const PclCloud cloud = LoadPclCloud();
  ASSERT_EQ(cloud.width, 640);
  ASSERT_EQ(cloud.height, 480);

  // Every pixel: the same pixels have depth, the points agree, and so do the
  // colours (PCL's packed rgba against our BGR: proves the channel order
  // without going through OpenCV's TIFF reader).
  int points = 0, mask_mismatches = 0, colour_mismatches = 0;
  double max_error_m = 0, max_error_centred_m = 0, max_z_m = 0;
  CameraIntrinsics centred = intrinsics;  // the project's "centre of the image" reading
  centred.cx = (640 - 1) / 2.0;
  centred.cy = (480 - 1) / 2.0;
  for (int v = 0; v < 480; ++v) {
    for (int u = 0; u < 640; ++u) {
      const size_t i = static_cast<size_t>(v) * 640 + u;
      const Eigen::Vector3d pcl_point(cloud.xyz[3 * i], cloud.xyz[3 * i + 1], cloud.xyz[3 * i + 2]);
      const double z = frame.DepthM(u, v);
      if (std::isfinite(pcl_point.z()) != (z > 0)) {
        ++mask_mismatches;
        continue;
      }
      const cv::Vec3b bgr = frame.color.at<cv::Vec3b>(v, u);
      const uint32_t c = cloud.rgba[i];
      if (bgr[2] != ((c >> 16) & 0xFF) || bgr[1] != ((c >> 8) & 0xFF) || bgr[0] != (c & 0xFF)) ++colour_mismatches;
      if (z == 0) continue;
      ++points;
      max_z_m = std::max(max_z_m, z);
      max_error_m = std::max(max_error_m, (intrinsics.Unproject(u, v, z) - pcl_point).norm());
      max_error_centred_m = std::max(max_error_centred_m, (centred.Unproject(u, v, z) - pcl_point).norm());
    }
  }
  EXPECT_EQ(mask_mismatches, 0);
  EXPECT_EQ(colour_mismatches, 0);
  EXPECT_GT(points, 270000);
  // PCL stores float32: its rounding is the only difference.
  EXPECT_LT(max_error_m, 1e-5);
  // With the principal point at (w-1)/2, (h-1)/2 every point moves by half a
  // pixel in x and y: sqrt(2)/2 z/f, 2.3 mm at the frame's farthest point
  // (1.73 m).
  EXPECT_NEAR(max_error_centred_m, std::sqrt(0.5) * max_z_m / 525, 1e-5);
  std::printf("Back-projection vs PCL cloud: %d points, max |diff| %.2g m (cx = w/2); %.2f mm with cx = (w-1)/2, "
              "farthest point %.3f m\n",
              points, max_error_m, 1000 * max_error_centred_m, max_z_m);
}

TEST(Openni2Frame, BadBuffersAreProblemsNotCrashes) {
  const KinectFrame k = LoadKinectFrame();
  const OpenNi2Image good_color = k.color_buffer.image, good_depth = k.depth_buffer.image;
  const auto has = [](const RgbdFrame& f, const std::string& text) {
    return f.problem.find(text) != std::string::npos;
  };

  OpenNi2Image short_color = good_color;
  short_color.data_size -= 100;
  RgbdFrame f = RgbdFrameFromOpenNi2(short_color, good_depth);
  EXPECT_TRUE(f.color.empty());
  EXPECT_FALSE(f.depth.empty());  // the depth is still good
  EXPECT_TRUE(has(f, "colour: 924860 bytes for 640x480 pixels (needs 924953)")) << f.problem;

  OpenNi2Image narrow_depth = good_depth;
  narrow_depth.stride_bytes = 1000;
  f = RgbdFrameFromOpenNi2(good_color, narrow_depth);
  EXPECT_FALSE(f.color.empty());
  EXPECT_TRUE(f.depth.empty());
  EXPECT_TRUE(has(f, "depth: rows 1000 bytes apart, shorter than a 640-pixel row (1280 bytes)")) << f.problem;

  OpenNi2Image no_data = good_color;
  no_data.data = nullptr;
  OpenNi2Image no_size = good_depth;
  no_size.height = 0;
  f = RgbdFrameFromOpenNi2(no_data, no_size);
  EXPECT_TRUE(f.color.empty() && f.depth.empty());
  EXPECT_TRUE(has(f, "colour: no image; ")) << f.problem;

  // Depth the device did not register to colour: another size.
  cv::Mat small;
  cv::resize(k.depth, small, cv::Size(320, 240), 0, 0, cv::INTER_NEAREST);
  const Buffer small_depth = AsOpenNi2(small, openni::PIXEL_FORMAT_DEPTH_1_MM, 0, kTimestampUs);
  f = RgbdFrameFromOpenNi2(good_color, small_depth.image);
  EXPECT_FALSE(f.color.empty());
  EXPECT_TRUE(f.depth.empty());
  EXPECT_EQ(f.problem, "depth is 320x240, the colour 640x480: not registered to the colour image");

  OpenNi2Image yuv = good_color, shift = good_depth;
  yuv.format = openni::PIXEL_FORMAT_YUV422;
  shift.format = openni::PIXEL_FORMAT_SHIFT_9_2;
  f = RgbdFrameFromOpenNi2(yuv, shift);
  EXPECT_TRUE(f.color.empty() && f.depth.empty());
  EXPECT_EQ(f.problem, "colour arrives as YUV422, not RGB888; depth arrives as SHIFT_9_2, not DEPTH_1_MM or DEPTH_100_UM");

  // A device that reports no field of view (OpenNI2 says 0) has no intrinsics.
  EXPECT_THROW(IntrinsicsFromOpenNi2FieldOfView(640, 480, 0, Rad(48.6), 1000), InputError);
  EXPECT_THROW(IntrinsicsFromOpenNi2FieldOfView(640, 480, Rad(62), std::nan(""), 1000), InputError);
  EXPECT_THROW(IntrinsicsFromOpenNi2FieldOfView(640, 480, Rad(62), Rad(10), 1000), InputError);  // fx/fy 0.16
  EXPECT_THROW(IntrinsicsFromOpenNi2FieldOfView(0, 480, Rad(62), Rad(48.6), 1000), InputError);
}

// The plugin as the executable loads it. This machine has no camera.
struct LoadedPlugin {
  CameraSourceRegistry registry;
  LoadedPlugin() {
    for (const auto& load : LoadSourcePlugins(&registry, {ARPOS_PLUGIN_DIR})) {
      if (load.path.filename() == "libarpos_source_openni2.so") {
        EXPECT_TRUE(load.loaded) << load.error;
      }
    }
  }
  SourceAvailability List() const {
    for (const auto& kind : registry.Kinds()) {
      if (kind.name == "openni2" && kind.lister) return kind.lister();
    }
    ADD_FAILURE() << "openni2 has no lister";
    return {};
  }
  std::string OpenError(const std::string& spec) const {
    try {
      registry.Create(spec);
    } catch (const InputError& e) {
      return e.what();
    }
    return "(opened)";
  }
};

TEST(Openni2Plugin, WithNoCameraItListsNoneAndSaysSoWhenOpened) {
  LoadedPlugin plugin;
  ASSERT_TRUE(plugin.registry.Has("openni2"));
  const SourceAvailability available = plugin.List();
  if (!available.devices.empty()) GTEST_SKIP() << "a camera is attached: " << available.devices.front();
  EXPECT_EQ(available.status, "no device attached");
  // Twice: OpenNI2 starts and stops cleanly each time.
  EXPECT_EQ(plugin.List().status, "no device attached");

  EXPECT_EQ(plugin.OpenError("openni2"),
            "openni2: no OpenNI2 device attached (is it plugged in, and is the user allowed to use it?)");
  EXPECT_EQ(plugin.OpenError("openni2:?fps=30"),
            "openni2: no OpenNI2 device attached (is it plugged in, and is the user allowed to use it?)");
  const std::string named = plugin.OpenError("openni2:1d27/0601@1/5");
  EXPECT_EQ(named.rfind("openni2:1d27/0601@1/5: cannot open this OpenNI2 device (", 0), 0u) << named;
  EXPECT_NE(named.find("is it plugged in, and is the user allowed to use it?"), std::string::npos) << named;

  EXPECT_EQ(plugin.OpenError("openni2:?width=wide"),
            "openni2:?width=wide: width must be a whole number, got 'wide'");
  EXPECT_EQ(plugin.OpenError("openni2:?fps=0"), "openni2:?fps=0: fps must be positive, got '0'");
  EXPECT_EQ(plugin.OpenError("openni2:?exposure=3"),
            "openni2:?exposure=3: unknown option 'exposure' (known: width, height, fps)");
}

// OpenNI2's own test driver (Debian ships it beside the real ones): a device
// "Dummy" with 320x240 colour and depth and no field of view. It shows that
// the plugin's OpenNI2 finds its drivers, and how a device that cannot do
// what is asked is refused. Its streams are never started (the driver's
// frame threads outlive OpenNI2's shutdown and crash).
TEST(Openni2Plugin, ADeviceIsRefusedForAModeItLacksOrNoFieldOfView) {
  LoadedPlugin plugin;
  const std::string mode = plugin.OpenError("openni2:Dummy");
  if (mode.find("cannot open this OpenNI2 device") != std::string::npos) {
    GTEST_SKIP() << "OpenNI2's DummyDevice driver is not installed: " << mode;
  }
  EXPECT_EQ(mode,
            "openni2:Dummy: its colour stream has no 640x480 at 30 fps in RGB888; it offers 320x240@30 RGB888 "
            "(choose with ?width=W&height=H&fps=F)");
  EXPECT_EQ(plugin.OpenError("openni2:Dummy?width=320&height=240"),
            "openni2:Dummy: the camera reports no usable horizontal field of view (0 rad), so its intrinsics "
            "are unknown");
}

}  // namespace
}  // namespace arpos
