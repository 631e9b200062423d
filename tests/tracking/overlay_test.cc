// The AR overlay of tracking mode: the red model sits exactly on the model's
// projection (with and without lens distortion), an absent pose is not drawn,
// the corner panel takes the state's colour, bad inputs are refused; and on
// the bundled sample the red model sits on the person.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <iostream>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "feedback/couch_correction.h"
#include "geometry/mesh_io.h"
#include "sensor/case_config.h"
#include "sensor/tum_io.h"
#include "tracking/overlay.h"
#include "util/check.h"

namespace arpos {
namespace {

namespace fs = std::filesystem;

CameraIntrinsics TestCamera() {
  CameraIntrinsics k;
  k.width = 640;
  k.height = 480;
  k.fx = k.fy = 500;
  k.cx = 319.5;
  k.cy = 239.5;
  return k;
}

// Axis-aligned box [-half, half], faces counter-clockwise from outside.
TriangleMesh BoxMesh(const Eigen::Vector3f& half) {
  TriangleMesh m;
  for (int i = 0; i < 8; ++i) {
    m.vertices.emplace_back(i & 1 ? half.x() : -half.x(), i & 2 ? half.y() : -half.y(),
                            i & 4 ? half.z() : -half.z());
  }
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    m.faces.emplace_back(q[0], q[1], q[2]);
    m.faces.emplace_back(q[0], q[2], q[3]);
  }
  return m;
}

// UV sphere of `radius` about the origin.
TriangleMesh SphereMesh(float radius, int rings, int segments) {
  TriangleMesh m;
  m.vertices.emplace_back(0, 0, radius);
  for (int r = 1; r < rings; ++r) {
    const double theta = M_PI * r / rings;
    for (int s = 0; s < segments; ++s) {
      const double phi = 2 * M_PI * s / segments;
      m.vertices.emplace_back(radius * std::sin(theta) * std::cos(phi),
                              radius * std::sin(theta) * std::sin(phi), radius * std::cos(theta));
    }
  }
  m.vertices.emplace_back(0, 0, -radius);
  const int south = static_cast<int>(m.vertices.size()) - 1;
  auto ring = [&](int r, int s) { return 1 + (r - 1) * segments + (s % segments); };
  for (int s = 0; s < segments; ++s) {
    m.faces.emplace_back(0, ring(1, s), ring(1, s + 1));
    for (int r = 1; r + 1 < rings; ++r) {
      m.faces.emplace_back(ring(r, s), ring(r + 1, s), ring(r + 1, s + 1));
      m.faces.emplace_back(ring(r, s), ring(r + 1, s + 1), ring(r, s + 1));
    }
    m.faces.emplace_back(south, ring(rings - 1, s + 1), ring(rings - 1, s));
  }
  return m;
}

std::vector<cv::Point2f> ProjectVertices(const TriangleMesh& mesh, const Rigid3d& camera_from_model,
                                         const CameraIntrinsics& k) {
  std::vector<cv::Point3f> points;
  for (const auto& v : mesh.vertices) {
    const Eigen::Vector3d p = camera_from_model * v.cast<double>();
    points.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()),
                        static_cast<float>(p.z()));
  }
  std::vector<cv::Point2f> pixels;
  cv::projectPoints(points, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), cv::Mat(k.CvK()),
                    k.CvDistortion(), pixels);
  return pixels;
}

// Pixels the overlay changed relative to `baseline` (same call without poses).
cv::Mat ChangedMask(const cv::Mat& image, const cv::Mat& baseline) {
  cv::Mat diff, channels[3];
  cv::absdiff(image, baseline, diff);
  cv::split(diff, channels);
  return (channels[0] > 0) | (channels[1] > 0) | (channels[2] > 0);
}

// Changed pixels whose red dominates by > 10 levels (reddened), or whose blue does.
cv::Mat HueMask(const cv::Mat& image, const cv::Mat& changed, int channel) {
  cv::Mat mask = cv::Mat::zeros(image.size(), CV_8U);
  for (int v = 0; v < image.rows; ++v) {
    for (int u = 0; u < image.cols; ++u) {
      const cv::Vec3b p = image.at<cv::Vec3b>(v, u);
      const int others = channel == 2 ? std::max(p[0], p[1]) : std::max(p[1], p[2]);
      if (changed.at<uint8_t>(v, u) && p[channel] > others + 10) mask.at<uint8_t>(v, u) = 255;
    }
  }
  return mask;
}

struct Extent {
  float xmin = 1e9f, xmax = -1e9f, ymin = 1e9f, ymax = -1e9f;
};
Extent ExtentOf(const std::vector<cv::Point2f>& points) {
  Extent e;
  for (const auto& p : points) {
    e.xmin = std::min(e.xmin, p.x), e.xmax = std::max(e.xmax, p.x);
    e.ymin = std::min(e.ymin, p.y), e.ymax = std::max(e.ymax, p.y);
  }
  return e;
}

double IoU(const cv::Mat& a, const cv::Mat& b) {
  const double inter = cv::countNonZero(a & b), uni = cv::countNonZero(a | b);
  return uni > 0 ? inter / uni : 0;
}

CouchCorrection OutCorrection() {
  CouchCorrection c;
  c.lateral_mm = 1.2;
  c.longitudinal_mm = -0.4;
  c.vertical_mm = 3.0;
  c.pitch_deg = 0.1;
  c.roll_deg = -0.2;
  c.yaw_deg = 0.05;
  c.translation_mm = 3.2;
  c.rotation_deg = 0.23;
  c.state = CorrectionState::kOut;
  return c;
}

const Rigid3d kBoxPose =
    Rigid3d::FromRotationVector(Eigen::Vector3d(0.3, -0.4, 0.2), Eigen::Vector3d(0.03, 0.04, 1.0));

TEST(Overlay, CurrentPoseIsRedExactlyWhereTheModelProjects) {
  const CameraIntrinsics k = TestCamera();
  const TriangleMesh box = BoxMesh(Eigen::Vector3f(0.10f, 0.06f, 0.08f));
  const OverlayRenderer renderer(box, k);
  const cv::Mat frame(k.height, k.width, CV_8UC3, cv::Scalar(128, 128, 128));
  const cv::Mat baseline = renderer.Render(frame, std::nullopt, std::nullopt, OutCorrection(), "t");
  const cv::Mat image = renderer.Render(frame, kBoxPose, std::nullopt, OutCorrection(), "t");

  // The box is convex: its silhouette is the hull of its projected corners.
  std::vector<cv::Point2f> corners = ProjectVertices(box, kBoxPose, k);
  std::vector<cv::Point2f> hull;
  cv::convexHull(corners, hull);
  cv::Mat expected = cv::Mat::zeros(frame.size(), CV_8U);  // pixel centres inside the hull
  for (int v = 0; v < k.height; ++v) {
    for (int u = 0; u < k.width; ++u) {
      if (cv::pointPolygonTest(hull, cv::Point2f(u, v), false) > 0)
        expected.at<uint8_t>(v, u) = 255;
    }
  }
  ASSERT_GT(cv::countNonZero(expected), 5000);

  const cv::Mat changed = ChangedMask(image, baseline);
  const cv::Mat red = HueMask(image, changed, 2);
  EXPECT_GT(IoU(red, expected), 0.9);
  // Edges in place: the pixels that differ, per pixel of outline, are about
  // the mean edge displacement (px); a shift by half a pixel gives 0.24.
  const double displacement = cv::countNonZero(red ^ expected) / cv::arcLength(hull, true);
  EXPECT_LT(displacement, 0.1);
  EXPECT_EQ(cv::countNonZero(changed & ~expected), 0) << "drawn where the model is not";
  EXPECT_EQ(cv::countNonZero(HueMask(image, changed, 0)), 0) << "blue drawn without a planned pose";
  // Shaded, not flat: faces at different angles to the camera differ.
  double lo = 255, hi = 0;
  for (int v = 0; v < k.height; ++v) {
    for (int u = 0; u < k.width; ++u) {
      if (!red.at<uint8_t>(v, u)) continue;
      lo = std::min(lo, static_cast<double>(image.at<cv::Vec3b>(v, u)[2]));
      hi = std::max(hi, static_cast<double>(image.at<cv::Vec3b>(v, u)[2]));
    }
  }
  EXPECT_GT(hi - lo, 15);

  // A closed model wound inwards (faces clockwise from outside) looks the same.
  TriangleMesh inward = box;
  for (auto& f : inward.faces) std::swap(f[1], f[2]);
  const cv::Mat inward_image =
      OverlayRenderer(inward, k).Render(frame, kBoxPose, std::nullopt, OutCorrection(), "t");
  EXPECT_EQ(cv::countNonZero(HueMask(inward_image, ChangedMask(inward_image, baseline), 2) ^ red),
            0);
}

TEST(Overlay, AbsentPoseIsNotDrawnAndOverlapShowsBoth) {
  const CameraIntrinsics k = TestCamera();
  const TriangleMesh box = BoxMesh(Eigen::Vector3f(0.10f, 0.08f, 0.05f));
  const OverlayRenderer renderer(box, k);
  const cv::Mat frame(k.height, k.width, CV_8UC3, cv::Scalar(128, 128, 128));
  // Facing the camera, the planned one 8 cm to the right: they overlap by half.
  const Rigid3d current(Eigen::Quaterniond::Identity(), Eigen::Vector3d(-0.04, 0, 1.0));
  const Rigid3d planned(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.04, 0, 1.0));
  const cv::Mat baseline = renderer.Render(frame, std::nullopt, std::nullopt, OutCorrection(), "");

  const cv::Mat only_current = renderer.Render(frame, current, std::nullopt, OutCorrection(), "");
  const cv::Mat changed_current = ChangedMask(only_current, baseline);
  EXPECT_GT(cv::countNonZero(HueMask(only_current, changed_current, 2)), 5000);
  EXPECT_EQ(cv::countNonZero(HueMask(only_current, changed_current, 0)), 0);

  const cv::Mat only_planned = renderer.Render(frame, std::nullopt, planned, OutCorrection(), "");
  const cv::Mat changed_planned = ChangedMask(only_planned, baseline);
  EXPECT_GT(cv::countNonZero(HueMask(only_planned, changed_planned, 0)), 5000);
  EXPECT_EQ(cv::countNonZero(HueMask(only_planned, changed_planned, 2)), 0);
  // The planned silhouette has its opaque outline.
  cv::Mat outline;
  cv::inRange(only_planned, OverlayPlannedOutlineColor(), OverlayPlannedOutlineColor(), outline);
  EXPECT_GT(cv::countNonZero(outline), 300);

  // Where both are drawn, both tints remain: more blue than red alone gives,
  // more red than blue alone gives. The outline is drawn on top.
  const cv::Mat both = renderer.Render(frame, current, planned, OutCorrection(), "");
  const cv::Point in_overlap(k.width / 2, k.height / 2);
  const cv::Vec3b b = both.at<cv::Vec3b>(in_overlap), r = only_current.at<cv::Vec3b>(in_overlap),
                  p = only_planned.at<cv::Vec3b>(in_overlap);
  EXPECT_GT(b[0] - b[1], r[0] - r[1] + 20) << "blue tint lost under the red";
  EXPECT_GT(b[2] - b[1], p[2] - p[1] + 40) << "red tint lost over the blue";
  cv::inRange(both, OverlayPlannedOutlineColor(), OverlayPlannedOutlineColor(), outline);
  EXPECT_GT(cv::countNonZero(outline), 300);
}

TEST(Overlay, DistortedSilhouetteMatchesProjectPoints) {
  CameraIntrinsics k = TestCamera();
  k.distortion = {-0.3, 0, 0, 0, 0};
  const TriangleMesh sphere = SphereMesh(0.09f, 48, 96);
  const OverlayRenderer renderer(sphere, k);
  const cv::Mat frame(k.height, k.width, CV_8UC3, cv::Scalar(128, 128, 128));
  // Near the right edge: the ideal projection leaves the image (the renderer's
  // canvas must extend beyond it); the distorted one stays inside.
  const Rigid3d pose(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.50, 0.18, 0.9));
  const cv::Mat baseline = renderer.Render(frame, std::nullopt, std::nullopt, OutCorrection(), "");
  const cv::Mat image = renderer.Render(frame, pose, std::nullopt, OutCorrection(), "");
  const cv::Rect drawn = cv::boundingRect(HueMask(image, ChangedMask(image, baseline), 2));

  const std::vector<cv::Point2f> distorted = ProjectVertices(sphere, pose, k);
  CameraIntrinsics pinhole = k;
  pinhole.distortion = {0, 0, 0, 0, 0};
  const Extent expected = ExtentOf(distorted);
  const Extent ideal = ExtentOf(ProjectVertices(sphere, pose, pinhole));
  ASSERT_GT(ideal.xmax, k.width + 3) << "the test needs the ideal projection to leave the image";
  ASSERT_LT(expected.xmax, k.width - 10);
  ASSERT_GT(std::abs(ideal.xmin - expected.xmin), 10) << "the distortion must matter for this test";

  EXPECT_NEAR(drawn.x, expected.xmin, 1.0);
  EXPECT_NEAR(drawn.y, expected.ymin, 1.0);
  EXPECT_NEAR(drawn.x + drawn.width - 1, expected.xmax, 1.0);
  EXPECT_NEAR(drawn.y + drawn.height - 1, expected.ymax, 1.0);
}

TEST(Overlay, PanelTakesTheStateColour) {
  const CameraIntrinsics k = TestCamera();
  const OverlayRenderer renderer(BoxMesh(Eigen::Vector3f(0.1f, 0.1f, 0.1f)), k);
  const cv::Mat frame(k.height, k.width, CV_8UC3, cv::Scalar(200, 200, 200));
  CouchCorrection in = OutCorrection();
  in.state = CorrectionState::kIn;
  const CouchCorrection states[] = {in, OutCorrection(), LostCorrection()};
  const cv::Rect corner(0, 0, k.width / 2, k.height / 5);
  for (const CouchCorrection& correction : states) {
    SCOPED_TRACE(CorrectionStateName(correction.state));
    const cv::Mat image = renderer.Render(frame, std::nullopt, std::nullopt, correction, "");
    const cv::Scalar colour = OverlayStateColor(correction.state);
    // The stripe along the panel's left edge.
    const cv::Vec3b stripe = image.at<cv::Vec3b>(30, 8);
    EXPECT_EQ(stripe, cv::Vec3b(colour[0], colour[1], colour[2]));
    // The text is in the state's colour too, and no other state's colour shows.
    for (const CorrectionState other :
         {CorrectionState::kIn, CorrectionState::kOut, CorrectionState::kLost}) {
      const cv::Scalar c = OverlayStateColor(other);
      cv::Mat hits;
      cv::inRange(image(corner), c - cv::Scalar(25, 25, 25), c + cv::Scalar(25, 25, 25), hits);
      if (other == correction.state) {
        EXPECT_GT(cv::countNonZero(hits), 400) << CorrectionStateName(other);
      } else {
        EXPECT_EQ(cv::countNonZero(hits), 0) << CorrectionStateName(other);
      }
    }
    // The panel is dark behind the text: most of the corner's left part is.
    cv::Mat grey, dark;
    cv::cvtColor(image(cv::Rect(12, 8, 150, 50)), grey, cv::COLOR_BGR2GRAY);
    dark = grey < 90;
    EXPECT_GT(cv::countNonZero(dark), 0.7 * dark.total());
  }
  // The caption's strip darkens the bottom-left corner only when there is a caption.
  const cv::Mat with =
      renderer.Render(frame, std::nullopt, std::nullopt, in, "2000.000000  tracked");
  const cv::Mat without = renderer.Render(frame, std::nullopt, std::nullopt, in, "");
  EXPECT_LT(with.at<cv::Vec3b>(k.height - 8, 8)[0], 100);
  EXPECT_EQ(without.at<cv::Vec3b>(k.height - 8, 8)[0], 200);
}

// Rows from the bottom of column `u` that the caption's strip darkened
// (the frame is a uniform 200 grey).
int DarkRowsFromBottom(const cv::Mat& image, int u) {
  int top = -1;
  for (int v = image.rows - 1; v >= image.rows / 2; --v) {
    if (image.at<cv::Vec3b>(v, u)[0] < 150) top = v;
  }
  return top < 0 ? 0 : image.rows - top;
}

// A lost frame names why in the panel; a caption longer than the image is
// wrapped into at most three lines within the image, not cut off at its edge.
TEST(Overlay, ALostFrameSaysWhyAndALongCaptionIsWrapped) {
  const CameraIntrinsics k = TestCamera();
  const OverlayRenderer renderer(BoxMesh(Eigen::Vector3f(0.1f, 0.1f, 0.1f)), k);
  const cv::Mat frame(k.height, k.width, CV_8UC3, cv::Scalar(200, 200, 200));
  const cv::Rect panel_text(12, 8, 400, 70);
  const cv::Mat plain = renderer.Render(frame, std::nullopt, std::nullopt, LostCorrection(), "");
  const cv::Mat named = renderer.Render(frame, std::nullopt, std::nullopt, LostCorrection(), "",
                                        "CAMERA AND PATIENT NOT FOUND");
  // The third line differs ("PATIENT LOST" by default), the first two not.
  cv::Mat diff;
  cv::absdiff(plain(panel_text), named(panel_text), diff);
  cv::cvtColor(diff, diff, cv::COLOR_BGR2GRAY);
  const cv::Rect first_lines = cv::boundingRect(diff > 40);
  ASSERT_FALSE(first_lines.empty());
  EXPECT_GT(first_lines.y, 35) << "only the third line changes";
  // A headline of a frame with a pose is not shown.
  const cv::Mat out_frame =
      renderer.Render(frame, std::nullopt, std::nullopt, OutCorrection(), "", "CAMERA AND PATIENT NOT FOUND");
  const cv::Mat out_plain = renderer.Render(frame, std::nullopt, std::nullopt, OutCorrection(), "");
  EXPECT_EQ(cv::norm(out_frame, out_plain, cv::NORM_INF), 0);

  const cv::Mat one = renderer.Render(frame, std::nullopt, std::nullopt, LostCorrection(), "t 1.000 s  frame 3  lost");
  std::string words;
  for (int i = 0; i < 80; ++i) words += "word" + std::to_string(i) + " ";
  const cv::Mat many = renderer.Render(frame, std::nullopt, std::nullopt, LostCorrection(), words);
  const int one_line = DarkRowsFromBottom(one, 8);
  const int three_lines = DarkRowsFromBottom(many, 8);
  ASSERT_GT(one_line, 10);
  // The padding above and below is shared: three lines are 2.2-2.3 times one.
  EXPECT_GT(three_lines, 2 * one_line);
  EXPECT_LT(three_lines, 3 * one_line);
  // Within the image: the strip ends before the right edge.
  EXPECT_EQ(many.at<cv::Vec3b>(k.height - 8, k.width - 2)[0], 200);
  EXPECT_LT(many.at<cv::Vec3b>(k.height - 8, k.width - 80)[0], 150) << "the strip spans most of the width";
}

template <typename F>
std::string ErrorOf(F&& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(Overlay, BadInputsAreRefused) {
  const CameraIntrinsics k = TestCamera();
  const TriangleMesh box = BoxMesh(Eigen::Vector3f(0.1f, 0.1f, 0.1f));
  const OverlayRenderer renderer(box, k);
  const CouchCorrection c = OutCorrection();

  const cv::Mat grey(k.height, k.width, CV_8UC1, cv::Scalar(0));
  EXPECT_NE(ErrorOf([&] { renderer.Render(grey, kBoxPose, std::nullopt, c, ""); }).find("CV_8UC3"),
            std::string::npos);
  const cv::Mat small(240, 320, CV_8UC3, cv::Scalar(0));
  EXPECT_NE(ErrorOf([&] {
              renderer.Render(small, kBoxPose, std::nullopt, c, "");
            }).find("320x240 but the camera's is 640x480"),
            std::string::npos);
  EXPECT_NE(
      ErrorOf([&] { renderer.Render(cv::Mat(), kBoxPose, std::nullopt, c, ""); }).find("empty"),
      std::string::npos);
  const cv::Mat frame(k.height, k.width, CV_8UC3, cv::Scalar(0));
  Rigid3d nan_pose = kBoxPose;
  nan_pose.translation.x() = std::nan("");
  EXPECT_NE(
      ErrorOf([&] { renderer.Render(frame, nan_pose, std::nullopt, c, ""); }).find("not finite"),
      std::string::npos);

  EXPECT_NE(ErrorOf([&] { OverlayRenderer(TriangleMesh(), k); }).find("model with faces"),
            std::string::npos);
  CameraIntrinsics bad_camera = k;
  bad_camera.fx = -5;
  EXPECT_NE(ErrorOf([&] { OverlayRenderer(box, bad_camera); }).find("fx must be positive"),
            std::string::npos);

  EXPECT_EQ(OverlayOptions().Validate(), "");
  OverlayOptions o;
  o.current_alpha = 1.5;
  EXPECT_NE(o.Validate().find("current_alpha"), std::string::npos);
  o = OverlayOptions();
  o.planned_alpha = std::nan("");
  EXPECT_NE(o.Validate().find("planned_alpha"), std::string::npos);
  o = OverlayOptions();
  o.supersampling = 2;
  EXPECT_NE(o.Validate().find("supersampling"), std::string::npos);
  o = OverlayOptions();
  o.font_scale = -1;
  EXPECT_NE(o.Validate().find("font_scale"), std::string::npos);
  o = OverlayOptions();
  o.display_cell_m = -0.001;
  EXPECT_NE(o.Validate().find("display_cell_m"), std::string::npos);
  o = OverlayOptions();
  o.supersampling = 5;
  EXPECT_NE(
      ErrorOf([&] { OverlayRenderer(box, k, o); }).find("invalid overlay options: supersampling"),
      std::string::npos);
}

TEST(Overlay, SupersamplingAndSimplificationKeepTheSilhouette) {
  const CameraIntrinsics k = TestCamera();
  const TriangleMesh sphere = SphereMesh(0.1f, 64, 128);  // 16k faces
  OverlayOptions plain;
  plain.display_cell_m = 0;
  OverlayOptions smooth;
  smooth.supersampling = 3;
  OverlayOptions simplified;
  simplified.max_display_faces = 1000;
  simplified.display_cell_m = 0.01;
  const OverlayRenderer a(sphere, k, plain), b(sphere, k, smooth), c(sphere, k, simplified);
  EXPECT_EQ(a.num_display_faces(), static_cast<int>(sphere.faces.size()));
  EXPECT_LT(c.num_display_faces(), static_cast<int>(sphere.faces.size()) / 3);
  const cv::Mat frame(k.height, k.width, CV_8UC3, cv::Scalar(128, 128, 128));
  const Rigid3d pose(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0, 1));
  const cv::Mat ra = HueMask(a.Render(frame, pose, std::nullopt, OutCorrection(), ""),
                             cv::Mat(frame.size(), CV_8U, 255), 2);
  const cv::Mat rb = HueMask(b.Render(frame, pose, std::nullopt, OutCorrection(), ""),
                             cv::Mat(frame.size(), CV_8U, 255), 2);
  const cv::Mat rc = HueMask(c.Render(frame, pose, std::nullopt, OutCorrection(), ""),
                             cv::Mat(frame.size(), CV_8U, 255), 2);
  EXPECT_GT(IoU(ra, rb), 0.97);
  EXPECT_GT(IoU(ra, rc), 0.95);
}

// The bundled sample's first tracking frame with the true poses: the red
// model's visible vertices (those the depth image sees) lie on red pixels.
// With ARPOS_OVERLAY_SAMPLE_PNG set, the overlay is written there.
TEST(OverlaySample, RedModelSitsOnThePatient) {
  const fs::path case_dir = fs::path(ARPOS_SAMPLE_SESSIONS_DIR) / "demo_xtion";
  const fs::path seq = case_dir / "tracking" / "seq_00";
  const CameraIntrinsics k = LoadCaseConfig(case_dir / "case.yaml").camera;
  const TriangleMesh model = LoadTriangleMesh(case_dir / "reference_model.ply");
  const Rigid3d room_from_target =
      Rigid3d::FromMatrix(ReadMatrix4(case_dir / "target_pose.txt"), 1e-6);
  const auto rgb = ReadImageList(seq / "rgb.txt");
  const auto depth = ReadImageList(seq / "depth.txt");
  const auto room_from_camera = ReadTrajectory(seq / "groundtruth.txt");
  const auto room_from_model = ReadTrajectory(seq / "body_groundtruth.txt");
  ASSERT_FALSE(rgb.empty());
  ASSERT_FALSE(room_from_camera.empty());
  ASSERT_FALSE(room_from_model.empty());
  ASSERT_NEAR(room_from_camera[0].timestamp_s, rgb[0].timestamp_s, 1e-6);
  ASSERT_NEAR(room_from_model[0].timestamp_s, rgb[0].timestamp_s, 1e-6);
  const cv::Mat colour = cv::imread((seq / rgb[0].relative_path).string(), cv::IMREAD_COLOR);
  const cv::Mat depth_image =
      cv::imread((seq / depth[0].relative_path).string(), cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(colour.empty());
  ASSERT_EQ(depth_image.type(), CV_16U);

  const Rigid3d camera_from_room = room_from_camera[0].room_from_x.Inverse();
  const Rigid3d camera_from_current = camera_from_room * room_from_model[0].room_from_x;
  const Rigid3d camera_from_planned = camera_from_room * room_from_target;
  const CouchCorrection correction = ComputeCouchCorrection(
      room_from_model[0].room_from_x, room_from_target, {}, CouchTolerances());

  const OverlayRenderer renderer(model, k);
  const cv::Mat baseline = renderer.Render(colour, std::nullopt, std::nullopt, correction, "");
  const cv::Mat image = renderer.Render(colour, camera_from_current, std::nullopt, correction, "");
  const cv::Mat red = HueMask(image, ChangedMask(image, baseline), 2);

  int visible = 0, on_red = 0;
  for (const auto& v : model.vertices) {
    const Eigen::Vector3d p = camera_from_current * v.cast<double>();
    if (p.z() <= 0) continue;
    const Eigen::Vector2d uv = k.Project(p);
    const int u = static_cast<int>(std::lround(uv.x())), w = static_cast<int>(std::lround(uv.y()));
    if (u < 0 || w < 0 || u >= k.width || w >= k.height) continue;
    const double z = depth_image.at<uint16_t>(w, u) / k.depth_scale;
    if (!(z > 0) || std::abs(z - p.z()) > 0.01) continue;  // hidden, or no depth
    ++visible;
    // Within a pixel of a red one (rounding, and the panel over the top-left).
    cv::Rect around(u - 1, w - 1, 3, 3);
    around &= cv::Rect(0, 0, k.width, k.height);
    if (cv::countNonZero(red(around)) > 0) ++on_red;
  }
  ASSERT_GT(visible, 1000);
  EXPECT_GT(on_red, 0.97 * visible);

  if (const char* out = std::getenv("ARPOS_OVERLAY_SAMPLE_PNG")) {
    const cv::Mat both =
        renderer.Render(colour, camera_from_current, camera_from_planned, correction,
                        "t=" + std::to_string(rgb[0].timestamp_s) + "  tracked (ground truth)");
    cv::imwrite(out, both);
  }
}

// Time per frame (both poses drawn) at 640x480 and 1280x720 on the sample
// model. Not part of the suite: run with --gtest_also_run_disabled_tests.
TEST(OverlaySample, DISABLED_Timing) {
  const fs::path case_dir = fs::path(ARPOS_SAMPLE_SESSIONS_DIR) / "demo_xtion";
  const TriangleMesh model = LoadTriangleMesh(case_dir / "reference_model.ply");
  const Rigid3d room_from_target =
      Rigid3d::FromMatrix(ReadMatrix4(case_dir / "target_pose.txt"), 1e-6);
  const auto room_from_camera =
      ReadTrajectory(case_dir / "tracking" / "seq_00" / "groundtruth.txt");
  const Rigid3d camera_from_planned = room_from_camera[0].room_from_x.Inverse() * room_from_target;
  const Rigid3d camera_from_current =
      camera_from_planned *
      Rigid3d::FromRotationVector(Eigen::Vector3d(0, 0.03, 0), Eigen::Vector3d(0.01, 0, 0));
  const CameraIntrinsics base = LoadCaseConfig(case_dir / "case.yaml").camera;
  for (const auto& [width, height] : {std::pair{640, 480}, std::pair{1280, 720}}) {
    for (const bool distorted : {false, true}) {
      for (const double cell : {0.0, 0.003}) {
        CameraIntrinsics k = base;
        k.width = width;
        k.height = height;
        k.fx = k.fy = base.fx * width / 640.0;
        k.cx = (width - 1) / 2.0;
        k.cy = (height - 1) / 2.0;
        if (distorted) k.distortion = {0.05, -0.1, 0, 0, 0};
        OverlayOptions options;
        options.display_cell_m = cell;
        const auto t0 = std::chrono::steady_clock::now();
        const OverlayRenderer renderer(model, k, options);
        const auto t1 = std::chrono::steady_clock::now();
        const std::clock_t c1 = std::clock();
        const cv::Mat frame(height, width, CV_8UC3, cv::Scalar(90, 100, 110));
        const int n = 10;
        for (int i = 0; i < n; ++i) {
          renderer.Render(frame, camera_from_current, camera_from_planned, OutCorrection(),
                          "caption");
        }
        const auto t2 = std::chrono::steady_clock::now();
        const std::clock_t c2 = std::clock();
        std::cout << width << "x" << height << (distorted ? " distorted" : " pinhole   ")
                  << " faces " << renderer.num_display_faces() << ": setup "
                  << std::chrono::duration<double, std::milli>(t1 - t0).count() << " ms, per frame "
                  << std::chrono::duration<double, std::milli>(t2 - t1).count() / n
                  << " ms (CPU, all threads: " << 1000.0 * (c2 - c1) / CLOCKS_PER_SEC / n
                  << " ms)\n";
      }
    }
  }
}

}  // namespace
}  // namespace arpos
