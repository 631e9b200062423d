// Self-checks of the simulator: every convention it promises (pixel centres,
// marker frames and corner order, depth units, room/model frames, ground-truth
// direction) is checked against an independent measurement, so a wrong
// convention fails here rather than as millimetres of error downstream.
#include <gtest/gtest.h>
#include <omp.h>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <map>
#include <opencv2/aruco.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <set>
#include <sstream>
#include <unordered_map>

#include "geometry/mesh_io.h"
#include "geometry/pose_error.h"
#include "geometry/so3.h"
#include "sensor/case_check.h"
#include "sensor/case_config.h"
#include "sensor/case_folder.h"
#include "sensor/sequence.h"
#include "sensor/tum_io.h"
#include "simulation/conditions.h"
#include "simulation/sensor_model.h"
#include "simulation/simulation_truth.h"
#include "simulation/simulator.h"
#include "util/check.h"
#include "util/file.h"

namespace arpos::sim {
namespace {

namespace fs = std::filesystem;

fs::path BodyMeshPath() { return fs::path(ARPOS_SHARED_DATA_DIR) / "makehuman_base" / "base.obj"; }

SimulationOptions SmallOptions() {
  SimulationOptions o;
  o.body_mesh_path = BodyMeshPath();
  o.room_frames = 3;
  o.body_scan_frames = 4;
  o.tracking_frames = 4;
  o.tracking_sequences = 1;
  o.seed = 5;
  return o;
}

// Built once: the world takes about a second.
const Simulator& ExactSimulator() {
  static const Simulator* simulator = [] {
    SimulationOptions o = SmallOptions();
    o.noise = false;
    return new Simulator(o);
  }();
  return *simulator;
}

// The d435 profile: a principal point off the image centre and fx != fy.
const Simulator& ExactD435Simulator() {
  static const Simulator* simulator = [] {
    SimulationOptions o = SmallOptions();
    o.profile = "d435";
    o.noise = false;
    return new Simulator(o);
  }();
  return *simulator;
}

const Simulator& NoisySimulator() {
  static const Simulator* simulator = [] {
    SimulationOptions o = SmallOptions();
    o.body_scan_frames = 8;
    return new Simulator(o);
  }();
  return *simulator;
}

cv::Ptr<cv::aruco::DetectorParameters> SubpixParams() {
  auto p = cv::aruco::DetectorParameters::create();
  p->cornerRefinementMethod = cv::aruco::CORNER_REFINE_SUBPIX;
  p->cornerRefinementWinSize = 5;
  p->cornerRefinementMaxIterations = 100;
  p->cornerRefinementMinAccuracy = 0.001;
  return p;
}

cv::Ptr<cv::aruco::Dictionary> Dictionary() {
  return cv::aruco::getPredefinedDictionary(cv::aruco::DICT_4X4_250);
}

Eigen::Vector2d ProjectRoomPoint(const CameraIntrinsics& K, const Rigid3d& room_from_camera,
                                 const Eigen::Vector3d& point_in_room) {
  return K.Project(room_from_camera.Inverse() * point_in_room);
}

// --- mesh_io ------------------------------------------------------------------

TEST(MeshIo, LoadsMakeHumanBodyGroupInMetres) {
  MeshLoadOptions o;
  o.units_scale = 0.1;
  o.only_group = "body";
  const TriangleMesh body = LoadTriangleMesh(BodyMeshPath(), o);
  EXPECT_EQ(body.vertices.size(), 13380u);  // SOURCE.txt: group body = 13380 vertices
  EXPECT_EQ(body.faces.size(), 2u * 13378u);
  Eigen::Vector3f lo, hi;
  body.Bounds(&lo, &hi);
  EXPECT_NEAR(hi.y() - lo.y(), 1.666, 0.01);  // ~1.67 m tall
  EXPECT_NEAR(hi.x(), 0.496, 0.002);
  // Everything (all 139 groups) is more.
  const TriangleMesh all = LoadTriangleMesh(BodyMeshPath(), 0.1);
  EXPECT_GT(all.faces.size(), body.faces.size());
}

TEST(MeshIo, PlyRoundTripAndErrorsNameTheFile) {
  TempDir dir("arpos_mesh_io");
  TriangleMesh mesh;
  mesh.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  mesh.faces = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  const fs::path ply = dir.path() / "tet.ply";
  SaveTriangleMeshPly(mesh, ply, "line one\nline two");
  const std::string bytes = ReadTextFile(ply);
  EXPECT_NE(bytes.find("format binary_little_endian 1.0"), std::string::npos);
  EXPECT_NE(bytes.find("comment line two"), std::string::npos);
  MeshLoadOptions keep;
  keep.keep_normals = true;
  keep.merge_identical_positions = false;
  const TriangleMesh back = LoadTriangleMesh(ply, keep);
  ASSERT_EQ(back.vertices.size(), 4u);
  ASSERT_EQ(back.faces.size(), 4u);
  for (size_t i = 0; i < 4; ++i) {
    EXPECT_EQ(back.vertices[i], mesh.vertices[i]);
    EXPECT_EQ(back.faces[i], mesh.faces[i]);
  }
  EXPECT_EQ(back.vertex_normals.size(), 4u);
  EXPECT_NEAR(LoadTriangleMesh(ply, 0.001).vertices[1].x(), 0.001f, 1e-9);

  auto expect_input_error = [](const fs::path& path, const MeshLoadOptions& o) {
    try {
      LoadTriangleMesh(path, o);
      ADD_FAILURE() << "no error for " << path;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(path.filename().string()), std::string::npos) << e.what();
    }
  };
  expect_input_error(dir.path() / "missing.ply", {});
  const fs::path corrupt = dir.path() / "corrupt.ply";
  WriteFileAtomic(corrupt, "ply\nformat binary_little_endian 1.0\nelement vertex 99\nend_header\nxx");
  expect_input_error(corrupt, {});
  const fs::path empty = dir.path() / "empty.obj";
  WriteFileAtomic(empty, "# nothing\nv 0 0 0\n");
  expect_input_error(empty, {});
  MeshLoadOptions group;
  group.only_group = "no-such-group";
  expect_input_error(BodyMeshPath(), group);
}

// --- Rendering conventions ---------------------------------------------------

// Exact corner measurement, independent of OpenCV's refinement (whose
// SUBPIX is biased on L-shaped marker corners, PITFALLS.md): each edge of
// the black square is located along pixel rows (or columns) by area: in a
// box-filtered image the linear-light sum across a step equals the white
// area, which gives the edge position to the supersampling's precision.
// Lines fitted to the edge points are intersected into corners.
std::array<Eigen::Vector2d, 4> MeasureCorners(const cv::Mat& bgr,
                                              const std::vector<cv::Point2f>& initial) {
  cv::Mat gray;
  cv::cvtColor(bgr, gray, cv::COLOR_BGR2GRAY);
  cv::Mat lin(gray.size(), CV_64F);
  for (int y = 0; y < gray.rows; ++y)
    for (int x = 0; x < gray.cols; ++x) {
      const double c = gray.at<uint8_t>(y, x) / 255.0;
      lin.at<double>(y, x) = c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
    }
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
  for (const auto& p : initial) centre += Eigen::Vector2d(p.x, p.y) / 4.0;
  std::array<Eigen::Vector3d, 4> lines;  // a x + b y + c = 0
  for (int e = 0; e < 4; ++e) {
    const Eigen::Vector2d a(initial[e].x, initial[e].y), b(initial[(e + 1) % 4].x, initial[(e + 1) % 4].y);
    const bool steep = std::abs(b.y() - a.y()) > std::abs(b.x() - a.x());  // edge runs along y
    std::vector<Eigen::Vector2d> points;
    const double len = steep ? std::abs(b.y() - a.y()) : std::abs(b.x() - a.x());
    const int n = static_cast<int>(len);
    for (int k = 0; k <= n; ++k) {
      const double s = static_cast<double>(k) / std::max(1, n);
      if (s < 0.2 || s > 0.8) continue;
      const Eigen::Vector2d p = a + s * (b - a);
      const int line = static_cast<int>(std::lround(steep ? p.y() : p.x()));
      // Position of the edge on this row/column from the line through a, b.
      const double t = steep ? (line - a.y()) / (b.y() - a.y()) : (line - a.x()) / (b.x() - a.x());
      const double across0 = steep ? a.x() + t * (b.x() - a.x()) : a.y() + t * (b.y() - a.y());
      const int lo = static_cast<int>(std::floor(across0)) - 5, hi = lo + 11;
      auto value = [&](int i) { return steep ? lin.at<double>(line, i) : lin.at<double>(i, line); };
      const double first = 0.5 * (value(lo) + value(lo + 1)), last = 0.5 * (value(hi) + value(hi - 1));
      const bool dark_first = first < last;
      const double dark = std::min(first, last), bright = std::max(first, last);
      double sum = 0;
      for (int i = lo; i <= hi; ++i) sum += std::clamp((value(i) - dark) / (bright - dark), 0.0, 1.0);
      const double edge = dark_first ? hi + 0.5 - sum : lo - 0.5 + sum;
      points.push_back(steep ? Eigen::Vector2d(edge, line) : Eigen::Vector2d(line, edge));
    }
    // Total least squares line.
    Eigen::Vector2d mean = Eigen::Vector2d::Zero();
    for (const auto& p : points) mean += p / static_cast<double>(points.size());
    Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
    for (const auto& p : points) cov += (p - mean) * (p - mean).transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(cov);
    const Eigen::Vector2d normal = eig.eigenvectors().col(0);
    lines[e] = Eigen::Vector3d(normal.x(), normal.y(), -normal.dot(mean));
  }
  std::array<Eigen::Vector2d, 4> corners;
  for (int c = 0; c < 4; ++c) {
    // Corner c joins edge c-1 (from corner c-1 to c) and edge c.
    const Eigen::Vector3d x = lines[(c + 3) % 4].cross(lines[c]);
    corners[c] = x.head<2>() / x.z();
  }
  return corners;
}

// A close, oblique view of the origin marker (room marker 0 on the floor).
Rigid3d CloseViewOfOriginMarker(double roll_deg) {
  return LookAt(Eigen::Vector3d(0.12, -0.33, 0.40), Eigen::Vector3d(0.01, 0.02, 0),
                RadFromDeg(roll_deg));
}

TEST(Rendering, OriginMarkerDetectedAtTheProjectedCornersAndPnpGivesTheTruePose) {
  // Both camera models: xtion (centred, square pixels) and d435 (neither).
  for (const Simulator* simulator : {&ExactSimulator(), &ExactD435Simulator()}) {
    const Simulator& sim = *simulator;
    SCOPED_TRACE(sim.profile().name);
    const CameraIntrinsics& K = sim.profile().intrinsics;
    const MarkerTruth& origin = sim.world().room_markers.front();
    ASSERT_EQ(origin.id, 0);
    EXPECT_TRUE(origin.parent_from_marker.IsApprox(Rigid3d::Identity(), 0, 0));
    for (double roll : {0.0, 23.0}) {
      const Rigid3d room_from_camera = CloseViewOfOriginMarker(roll);
      const SimulatedFrame frame = sim.RenderView(room_from_camera, std::nullopt, /*noise=*/false);
      cv::Mat gray;
      cv::cvtColor(frame.color, gray, cv::COLOR_BGR2GRAY);
      std::vector<std::vector<cv::Point2f>> corners;
      std::vector<int> ids;
      cv::aruco::detectMarkers(gray, Dictionary(), corners, ids, SubpixParams());
      const auto it = std::find(ids.begin(), ids.end(), 0);
      ASSERT_NE(it, ids.end()) << "origin marker not detected (roll " << roll << ")";
      const auto& detected = corners[it - ids.begin()];
      const std::array<Eigen::Vector2d, 4> measured = MeasureCorners(frame.color, detected);
      double worst_subpix_px = 0, worst_px = 0;
      std::vector<cv::Point2f> refined;
      for (int c = 0; c < 4; ++c) {
        const Eigen::Vector2d truth = ProjectRoomPoint(K, room_from_camera, origin.corners_m[c]);
        worst_subpix_px =
            std::max(worst_subpix_px, (Eigen::Vector2d(detected[c].x, detected[c].y) - truth).norm());
        worst_px = std::max(worst_px, (measured[c] - truth).norm());
        refined.emplace_back(static_cast<float>(measured[c].x()), static_cast<float>(measured[c].y()));
      }
      // OpenCV's SUBPIX is biased on marker corners; the rendering is not.
      EXPECT_LT(worst_subpix_px, 1.0) << "roll " << roll;
      EXPECT_LT(worst_px, 0.1) << "roll " << roll;
      RecordProperty(roll == 0 ? "corner_error_px_roll0" : "corner_error_px_roll23", std::to_string(worst_px));
      // Marker side in pixels: the view is close, as intended.
      EXPECT_GT(cv::norm(detected[0] - detected[1]), 120.0);

      const double h = origin.size_m / 2;
      const std::vector<cv::Point3f> object = {{float(-h), float(h), 0}, {float(h), float(h), 0},
                                               {float(h), float(-h), 0}, {float(-h), float(-h), 0}};
      cv::Vec3d rvec, tvec;
      ASSERT_TRUE(cv::solvePnP(object, refined, K.CvK(), K.CvDistortion(), rvec, tvec, false,
                               cv::SOLVEPNP_IPPE_SQUARE));
      const Rigid3d camera_from_marker = Rigid3d::FromRotationVector(
          Eigen::Vector3d(rvec[0], rvec[1], rvec[2]), Eigen::Vector3d(tvec[0], tvec[1], tvec[2]));
      // Marker 0's frame is the room frame.
      const Rigid3d room_from_camera_est = camera_from_marker.Inverse();
      const PoseError error = ComputePoseError(room_from_camera, room_from_camera_est);
      EXPECT_LT(error.translation_mm, 1.0) << "roll " << roll;
      EXPECT_LT(error.rotation_deg, 0.1) << "roll " << roll;
      std::printf("%s origin marker, roll %.0f deg: corners %.3f px (OpenCV SUBPIX %.3f px), PnP %.3f mm %.4f deg\n",
                  sim.profile().name.c_str(), roll, worst_px, worst_subpix_px, error.translation_mm, error.rotation_deg);
    }
  }
}

// The same at the sub-pixel level for an origin marker that random scene
// conditions put on a wall or far on the floor: the room frame written to
// the case is that marker's frame (a frame off by a tenth of a degree would
// move these corners by a fifth of a pixel).
TEST(Rendering, AMovedOriginMarkerIsTheRoomFrameAtTheSubPixelLevel) {
  for (const std::string placement : {"wall", "floor_far"}) {
    uint64_t seed = 1;
    while (DrawSceneConditions(seed).origin_placement != placement) ++seed;
    SimulationOptions o = SmallOptions();
    o.seed = seed;
    o.noise = false;
    o.room_frames = 30;
    o.random_conditions = true;
    o.response = "srgb";  // what MeasureCorners decodes
    o.auto_exposure = false;
    const Simulator sim(o);
    ASSERT_TRUE(sim.world().origin_moved);
    const CameraIntrinsics& K = sim.profile().intrinsics;
    const double s = sim.world().room_markers.front().size_m;
    const std::array<Eigen::Vector3d, 4> corners_in_room = MarkerCornersInMarker(s);
    for (double roll : {0.0, 23.0}) {
      // A close, oblique view in the room frame (z out of the marker's face),
      // scaled to the marker's size.
      const Rigid3d room_from_camera =
          LookAt(Eigen::Vector3d(0.12, -0.33, 0.40) * (s / 0.15), Eigen::Vector3d(0.01, 0.02, 0) * (s / 0.15),
                 RadFromDeg(roll));
      const SimulatedFrame frame = sim.RenderView(room_from_camera, std::nullopt, /*noise=*/false);
      EXPECT_TRUE(frame.room_from_camera.IsApprox(room_from_camera, 0, 0));
      std::vector<std::vector<cv::Point2f>> corners;
      std::vector<int> ids;
      cv::Mat gray;
      cv::cvtColor(frame.color, gray, cv::COLOR_BGR2GRAY);
      cv::aruco::detectMarkers(gray, Dictionary(), corners, ids, SubpixParams());
      const auto it = std::find(ids.begin(), ids.end(), 0);
      ASSERT_NE(it, ids.end()) << placement << " roll " << roll;
      const std::array<Eigen::Vector2d, 4> measured = MeasureCorners(frame.color, corners[it - ids.begin()]);
      for (int c = 0; c < 4; ++c) {
        const Eigen::Vector2d truth = ProjectRoomPoint(K, room_from_camera, corners_in_room[c]);
        EXPECT_LT((measured[c] - truth).norm(), 0.1) << placement << " roll " << roll << " corner " << c;
      }
    }
  }
}

// --- Depth and frames ----------------------------------------------------------

// Point-to-mesh distance with a uniform grid over triangle bounding boxes.
class MeshDistance {
 public:
  explicit MeshDistance(const TriangleMesh& mesh, double cell_m = 0.01)
      : mesh_(mesh), cell_(cell_m) {
    for (size_t f = 0; f < mesh.faces.size(); ++f) {
      Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e9), hi = -lo;
      for (int k = 0; k < 3; ++k) {
        lo = lo.cwiseMin(mesh.vertices[mesh.faces[f][k]].cast<double>());
        hi = hi.cwiseMax(mesh.vertices[mesh.faces[f][k]].cast<double>());
      }
      const Eigen::Vector3i a = Cell(lo), b = Cell(hi);
      for (int x = a.x(); x <= b.x(); ++x)
        for (int y = a.y(); y <= b.y(); ++y)
          for (int z = a.z(); z <= b.z(); ++z) grid_[Key(x, y, z)].push_back(static_cast<int>(f));
    }
  }
  // Distance to the nearest triangle among cells within `reach` cells.
  double Distance(const Eigen::Vector3d& p, int reach = 1) const {
    const Eigen::Vector3i c = Cell(p);
    double best = 1e9;
    for (int x = c.x() - reach; x <= c.x() + reach; ++x)
      for (int y = c.y() - reach; y <= c.y() + reach; ++y)
        for (int z = c.z() - reach; z <= c.z() + reach; ++z) {
          const auto it = grid_.find(Key(x, y, z));
          if (it == grid_.end()) continue;
          for (int f : it->second) best = std::min(best, PointTriangle(p, f));
        }
    return best;
  }

 private:
  Eigen::Vector3i Cell(const Eigen::Vector3d& p) const {
    return (p / cell_).array().floor().cast<int>();
  }
  static int64_t Key(int x, int y, int z) {
    return (static_cast<int64_t>(x + 100000) * 200000 + (y + 100000)) * 200000 + (z + 100000);
  }
  // Ericson, Real-Time Collision Detection, 5.1.5.
  double PointTriangle(const Eigen::Vector3d& p, int f) const {
    const Eigen::Vector3d a = mesh_.vertices[mesh_.faces[f][0]].cast<double>();
    const Eigen::Vector3d b = mesh_.vertices[mesh_.faces[f][1]].cast<double>();
    const Eigen::Vector3d c = mesh_.vertices[mesh_.faces[f][2]].cast<double>();
    const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
    const double d1 = ab.dot(ap), d2 = ac.dot(ap);
    if (d1 <= 0 && d2 <= 0) return (p - a).norm();
    const Eigen::Vector3d bp = p - b;
    const double d3 = ab.dot(bp), d4 = ac.dot(bp);
    if (d3 >= 0 && d4 <= d3) return (p - b).norm();
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) return (p - (a + d1 / (d1 - d3) * ab)).norm();
    const Eigen::Vector3d cp = p - c;
    const double d5 = ab.dot(cp), d6 = ac.dot(cp);
    if (d6 >= 0 && d5 <= d6) return (p - c).norm();
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) return (p - (a + d2 / (d2 - d6) * ac)).norm();
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
      return (p - (b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b))).norm();
    }
    const double denom = 1.0 / (va + vb + vc);
    return (p - (a + ab * (vb * denom) + ac * (vc * denom))).norm();
  }
  const TriangleMesh& mesh_;
  double cell_;
  std::unordered_map<int64_t, std::vector<int>> grid_;
};

// A plain room (--room-texture plain) gives a corner detector less than half
// of what the cluttered default gives (what is left: markers, tile seams,
// the skirting, the couch top), while its markers read alike: the cases that
// test the localiser without a textured room.
TEST(Rendering, APlainRoomShowsFewCornersAndTheSameMarkers) {
  SimulationOptions o = SmallOptions();
  o.noise = false;
  o.room_texture = "plain";
  const Simulator plain(o);
  const Simulator& rich = ExactSimulator();
  // Towards the couch and gantry, and across the room to a side wall.
  const std::vector<Rigid3d> views = {
      LookAt(Eigen::Vector3d(1.0, -1.2, 1.5), Eigen::Vector3d(0.8, 2.0, 0.7), 0),
      LookAt(Eigen::Vector3d(-0.8, 1.0, 1.4), Eigen::Vector3d(3.4, 1.3, 1.1), 0.1)};
  const cv::Ptr<cv::FastFeatureDetector> fast = cv::FastFeatureDetector::create(20);
  int corners_rich = 0, corners_plain = 0;
  for (const Rigid3d& room_from_camera : views) {
    std::set<int> markers[2];
    int* counts[2] = {&corners_rich, &corners_plain};
    const Simulator* sims[2] = {&rich, &plain};
    for (int k = 0; k < 2; ++k) {
      const SimulatedFrame frame = sims[k]->RenderView(room_from_camera, std::nullopt, /*noise=*/false);
      cv::Mat gray;
      cv::cvtColor(frame.color, gray, cv::COLOR_BGR2GRAY);
      std::vector<cv::KeyPoint> keypoints;
      fast->detect(gray, keypoints);
      *counts[k] += static_cast<int>(keypoints.size());
      std::vector<std::vector<cv::Point2f>> corners;
      std::vector<int> ids;
      cv::aruco::detectMarkers(gray, Dictionary(), corners, ids);
      markers[k].insert(ids.begin(), ids.end());
    }
    EXPECT_FALSE(markers[0].empty());
    EXPECT_EQ(markers[0], markers[1]);
  }
  std::printf("FAST corners in %zu views: rich room %d, plain room %d\n", views.size(), corners_rich,
              corners_plain);
  EXPECT_GT(corners_rich, 1000);
  EXPECT_LT(corners_plain, corners_rich / 2);
}

TEST(Depth, BodyPixelsBackProjectOntoTheReferenceModel) {
  const Simulator& sim = ExactSimulator();
  const CameraIntrinsics& K = sim.profile().intrinsics;
  static const MeshDistance distance(sim.world().reference_model);
  int body_scan = -1;
  for (size_t i = 0; i < sim.sequences().size(); ++i) {
    if (sim.sequences()[i].kind == SequenceKind::kBodyScan) body_scan = static_cast<int>(i);
  }
  ASSERT_GE(body_scan, 0);
  // Frames over the body (the first and last of a scan look at the room
  // markers beside the couch).
  for (int f : {1, 2}) {
    const SimulatedFrame frame = sim.RenderFrame(body_scan, f);
    ASSERT_TRUE(frame.room_from_model.has_value());
    const Rigid3d model_from_camera = frame.room_from_model->Inverse() * frame.room_from_camera;
    std::vector<double> errors;
    for (int v = 0; v < K.height; v += 3) {
      for (int u = 0; u < K.width; u += 3) {
        if (frame.exact.label.at<int>(v, u) != kLabelBody) continue;
        const uint16_t d = frame.depth.at<uint16_t>(v, u);
        if (d == 0) continue;
        // The written PNG: depth units per metre from case.yaml's depth_scale.
        const Eigen::Vector3d p = model_from_camera * K.Unproject(u, v, d / K.depth_scale);
        errors.push_back(distance.Distance(p, 1));
      }
    }
    ASSERT_GT(errors.size(), 2000u) << "too few body pixels in frame " << f;
    std::sort(errors.begin(), errors.end());
    EXPECT_LT(errors[errors.size() / 2], 0.0005) << "median, frame " << f;
    EXPECT_LT(errors[errors.size() * 99 / 100], 0.0015) << "99th percentile, frame " << f;
    EXPECT_LT(errors.back(), 0.002) << "max, frame " << f;
  }
}

TEST(Depth, ExactDepthIsTheZOfTheNearestSurfaceAtThePixelCentre) {
  // Looking straight down at the floor from 1.2 m: z is the same everywhere
  // on the floor plane seen perpendicularly, and marker 0's face is 0.3 mm
  // nearer than the floor.
  const Simulator& sim = ExactSimulator();
  const CameraIntrinsics& K = sim.profile().intrinsics;
  const Rigid3d room_from_camera =
      Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX())),
              Eigen::Vector3d(-0.5, -0.3, 1.2));  // camera z = -room z: looking down
  const SimulatedFrame frame = sim.RenderView(room_from_camera, std::nullopt, false);
  const Eigen::Vector2d centre_px = ProjectRoomPoint(K, room_from_camera, Eigen::Vector3d(0, 0, 0));
  const int u = static_cast<int>(std::lround(centre_px.x())), v = static_cast<int>(std::lround(centre_px.y()));
  EXPECT_NEAR(frame.exact.depth.at<float>(v, u), 1.2, 1e-6);
  EXPECT_NEAR(frame.exact.depth.at<float>(10, 10), 1.2003, 1e-6);  // floor
  EXPECT_NEAR(frame.depth.at<uint16_t>(v, u), std::round(1.2 * K.depth_scale), 0.5);
}

TEST(GroundTruth, StickersAreDetectedWithTheirIdsAtTheTrueCorners) {
  const Simulator& sim = NoisySimulator();
  const CameraIntrinsics& K = sim.profile().intrinsics;
  std::map<int, const MarkerTruth*> body_truth, room_truth;
  for (const auto& m : sim.world().body_markers) body_truth[m.id] = &m;
  for (const auto& m : sim.world().room_markers) room_truth[m.id] = &m;
  ASSERT_GE(body_truth.size(), 8u);
  ASSERT_LE(body_truth.size(), 20u);
  int body_scan = 1;
  ASSERT_EQ(sim.sequences()[body_scan].kind, SequenceKind::kBodyScan);
  std::set<int> seen;
  double worst_px = 0;
  std::vector<double> errors;
  for (int f = 0; f < sim.sequences()[body_scan].frames; ++f) {
    const SimulatedFrame frame = sim.RenderFrame(body_scan, f);
    std::vector<std::vector<cv::Point2f>> corners;
    std::vector<int> ids;
    // Small markers need a small refinement window.
    auto params = SubpixParams();
    params->cornerRefinementWinSize = 2;
    cv::aruco::detectMarkers(frame.color, Dictionary(), corners, ids, params);
    int body_here = 0;
    for (size_t i = 0; i < ids.size(); ++i) {
      if (ids[i] >= 100) {
        ASSERT_TRUE(body_truth.count(ids[i])) << "false body marker id " << ids[i];
        ++body_here;
        seen.insert(ids[i]);
        const MarkerTruth& m = *body_truth[ids[i]];
        for (int c = 0; c < 4; ++c) {
          const Eigen::Vector3d room_point = *frame.room_from_model * m.corners_m[c];
          const Eigen::Vector2d truth = ProjectRoomPoint(K, frame.room_from_camera, room_point);
          const double error = (Eigen::Vector2d(corners[i][c].x, corners[i][c].y) - truth).norm();
          worst_px = std::max(worst_px, error);
          errors.push_back(error);
        }
      } else {
        ASSERT_TRUE(room_truth.count(ids[i])) << "false room marker id " << ids[i];
      }
    }
    // The first and last frames look at the room markers beside the couch.
    const bool over_body = f > 0 && f + 1 < sim.sequences()[body_scan].frames;
    if (over_body) {
      EXPECT_GE(body_here, 2) << "body_scan frame " << f;
    }
  }
  EXPECT_GE(seen.size(), body_truth.size() * 3 / 4);
  // Small (20-30 px) stickers with noise and blur: OpenCV's SUBPIX is good to
  // a few tenths of a pixel; a wrong corner order or frame would be pixels off.
  std::sort(errors.begin(), errors.end());
  ASSERT_FALSE(errors.empty());
  std::printf("stickers: %zu of %zu seen, corner error median %.3f px, max %.3f px\n", seen.size(),
              body_truth.size(), errors[errors.size() / 2], worst_px);
  EXPECT_LT(errors[errors.size() / 2], 1.0);
  EXPECT_LT(worst_px, 2.0);
}

TEST(GroundTruth, StickerCornersAreExactOnTheCurvedSkin) {
  // Close, noiseless views of every chest/abdomen sticker: the printed square
  // is where model_from_marker says, at the sub-pixel level.
  const Simulator& sim = ExactSimulator();
  const CameraIntrinsics& K = sim.profile().intrinsics;
  const Rigid3d room_from_model = sim.world().room_from_model_target;
  int checked = 0;
  std::vector<double> errors;
  for (const MarkerTruth& m : sim.world().body_markers) {
    const Eigen::Vector3d c = room_from_model * m.parent_from_marker.translation;
    const Eigen::Vector3d n = room_from_model.rotation * m.parent_from_marker.rotation * Eigen::Vector3d::UnitZ();
    const Rigid3d room_from_camera = LookAt(c + 0.2 * n + Eigen::Vector3d(0.04, -0.03, 0), c, 0.3);
    const SimulatedFrame frame = sim.RenderView(room_from_camera, room_from_model, false);
    std::vector<std::vector<cv::Point2f>> corners;
    std::vector<int> ids;
    cv::aruco::detectMarkers(frame.color, Dictionary(), corners, ids, SubpixParams());
    const auto it = std::find(ids.begin(), ids.end(), m.id);
    ASSERT_NE(it, ids.end()) << "sticker " << m.id << " (" << m.surface << ") not detected close up";
    const auto measured = MeasureCorners(frame.color, corners[it - ids.begin()]);
    for (int k = 0; k < 4; ++k) {
      const Eigen::Vector2d truth = ProjectRoomPoint(K, room_from_camera, room_from_model * m.corners_m[k]);
      // The edge measurement is less precise on these 80 px markers with
      // 13 px borders than on the big origin marker: the bound is looser.
      EXPECT_LT((measured[k] - truth).norm(), 0.25) << "sticker " << m.id << " corner " << k;
      errors.push_back((measured[k] - truth).norm());
    }
    ++checked;
  }
  EXPECT_GE(checked, 8);
  std::sort(errors.begin(), errors.end());
  std::printf("sticker close-ups: corner error median %.3f px, max %.3f px\n",
              errors[errors.size() / 2], errors.back());
  EXPECT_LT(errors[errors.size() / 2], 0.06);
}

// --- Whole cases ---------------------------------------------------------------

std::map<std::string, std::string> ReadTree(const fs::path& root) {
  std::map<std::string, std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(root)) {
    if (e.is_regular_file()) {
      std::ifstream in(e.path(), std::ios::binary);
      std::stringstream s;
      s << in.rdbuf();
      files[fs::relative(e.path(), root).string()] = s.str();
    }
  }
  return files;
}

void ExpectValidCase(const fs::path& root, const SimulationOptions& options) {
  const CaseCheckReport report = CheckCase(root);
  for (const auto& p : report.problems) ADD_FAILURE() << p.ToString();
  EXPECT_TRUE(report.ok());
  EXPECT_EQ(report.sequences, 2 + options.tracking_sequences);
  const CaseFolder folder = LoadCaseFolder(root);
  EXPECT_EQ(folder.config.room_origin_id, 0);
  EXPECT_EQ(folder.tracking.size(), static_cast<size_t>(options.tracking_sequences));
  const SimulationTruth truth = LoadSimulationTruth(root / "simulation.yaml");
  EXPECT_EQ(truth.seed, options.seed);
  EXPECT_EQ(truth.profile, options.profile);
  EXPECT_EQ(truth.hard, options.hard);
  EXPECT_EQ(truth.room_walk, options.room_walk);
  if (options.profile == "xtion") {
    EXPECT_NE(truth.sensor.find("disparity_step=1/8 px"), std::string::npos) << truth.sensor;
  }
  EXPECT_TRUE(truth.room_from_model_target.IsApprox(folder.room_from_model_target, 1e-9, 1e-9));
  EXPECT_GE(truth.room_markers.size(), 10u);
  EXPECT_EQ(truth.room_markers.front().id, 0);
  EXPECT_GE(truth.body_markers.size(), 8u);
  for (const auto& m : truth.body_markers) {
    EXPECT_TRUE(folder.config.body_markers.Contains(m.id));
    // Corners are the marker frame's square (the file is self-consistent).
    EXPECT_NEAR((m.corners_m[0] - m.corners_m[1]).norm(), m.size_m, 1e-7);
    EXPECT_LT((m.parent_from_marker * Eigen::Vector3d(-m.size_m / 2, m.size_m / 2, 0) - m.corners_m[0]).norm(), 1e-7);
  }
  // Body ground truth for the patient sequences only; camera truth everywhere.
  const Sequence room = Sequence::Open(folder.room_dir);
  EXPECT_TRUE(room.CameraGroundTruth().has_value());
  EXPECT_FALSE(room.BodyGroundTruth().has_value());
  const Sequence scan = Sequence::Open(folder.body_scan_dir);
  ASSERT_TRUE(scan.BodyGroundTruth().has_value());
  EXPECT_EQ(scan.BodyGroundTruth()->size(), scan.size());
  for (const auto& [name, dir] : folder.tracking) {
    const auto body = Sequence::Open(dir).BodyGroundTruth();
    ASSERT_TRUE(body.has_value());
    for (const auto& pose : *body) {
      // Within +-5 cm and 5 degrees of the target.
      const PoseError e = ComputePoseError(folder.room_from_model_target, pose.room_from_x);
      EXPECT_LT(std::abs((pose.room_from_x.translation - folder.room_from_model_target.translation)
                             .maxCoeff()), 0.0501);
      EXPECT_LT(e.rotation_deg, 5.01);
    }
  }
}

// Median step between the distinct depth values (mm) occupied in each
// range [lo, lo + 200) mm of a 16-bit millimetre depth image.
std::vector<double> DepthStepsMm(const cv::Mat& depth_mm, const std::vector<int>& lows) {
  std::set<int> values;
  for (int y = 0; y < depth_mm.rows; ++y) {
    for (int x = 0; x < depth_mm.cols; ++x) {
      if (const int v = depth_mm.at<std::uint16_t>(y, x)) values.insert(v);
    }
  }
  const std::vector<int> v(values.begin(), values.end());
  std::vector<double> medians;
  for (int lo : lows) {
    std::vector<int> gaps;
    for (size_t i = 1; i < v.size(); ++i) {
      if (v[i - 1] >= lo && v[i] < lo + 200) gaps.push_back(v[i] - v[i - 1]);
    }
    if (gaps.empty()) {
      medians.push_back(std::nan(""));
      continue;
    }
    std::nth_element(gaps.begin(), gaps.begin() + gaps.size() / 2, gaps.end());
    medians.push_back(gaps[gaps.size() / 2]);
  }
  return medians;
}

// The xtion profile's depth comes in the steps a real structured-light
// sensor gives: a real Kinect v1 frame (../shared/data/pcl_kinect, millimetre
// depth) and the simulated sensor looking at a slanted wall from 0.7 to 1.6 m
// have the same spacing of distinct depth values. Measured: real 2 / 3 / 4 /
// 7 mm at 0.7-0.9 / 0.9-1.1 / 1.1-1.3 / 1.4-1.6 m, simulated the same.
// Without disparity quantisation the simulated steps would all be 1 mm.
TEST(Tracking, TheFirstPositioningEndsWithinToleranceAndIsHeldThere) {
  // A therapist's positioning ends with the patient at the planned pose:
  // the first sequence's last third within 2 mm / 1 deg of the target (so
  // `in` is measured, not only `out`), its start well outside; over seeds.
  for (const uint64_t seed : {5u, 41u, 97u}) {
    SimulationOptions o = SmallOptions();
    o.seed = seed;
    o.tracking_frames = 150;
    o.tracking_sequences = 2;
    const Simulator sim(o);
    const Rigid3d& target = sim.world().room_from_model_target;
    auto offset = [&](int sequence, int frame, double* angle_deg) {
      const SequencePlan& plan = sim.sequences()[sequence];
      const Rigid3d pose = plan.body.RoomFromModel(plan.time(frame));
      *angle_deg = pose.rotation.angularDistance(target.rotation) * 180 / M_PI;
      return 1000 * (pose.translation - target.translation).norm();
    };
    int first = -1;
    for (size_t k = 0; k < sim.sequences().size() && first < 0; ++k) {
      if (sim.sequences()[k].kind == SequenceKind::kTracking) first = static_cast<int>(k);
    }
    ASSERT_GE(first, 0);
    double angle = 0;
    EXPECT_GT(offset(first, 0, &angle), 5.0) << "seed " << seed;
    for (int f = 100; f < 150; ++f) {
      EXPECT_LT(offset(first, f, &angle), 1.25) << "seed " << seed << " frame " << f;
      EXPECT_LT(angle, 0.31) << "seed " << seed << " frame " << f;
    }
    EXPECT_NEAR(offset(first, 100, &angle), offset(first, 149, &angle), 1e-9) << "held still";
  }
}

TEST(SensorModel, XtionDepthStepsMatchARealKinectFrame) {
  const fs::path real_path = fs::path(ARPOS_SHARED_DATA_DIR) / "pcl_kinect" / "grabber_sequences" / "tiff" /
                             "frame_20121214T142255.814212_depth.tiff";
  const cv::Mat real = cv::imread(real_path.string(), cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(real.empty()) << real_path;
  ASSERT_EQ(real.type(), CV_16UC1);

  const SensorProfile profile = MakeSensorProfile("xtion");
  ASSERT_EQ(profile.intrinsics.depth_scale, 1000);  // millimetres, as the real frame
  RenderOutput render;
  const int W = profile.intrinsics.width, H = profile.intrinsics.height;
  render.depth.create(H, W, CV_32F);
  render.normal.create(H, W, CV_32FC3);
  render.label.create(H, W, CV_32S);
  render.color = cv::Mat(H, W, CV_32FC3, cv::Scalar(0.5, 0.5, 0.5));
  for (int y = 0; y < H; ++y) {
    for (int x = 0; x < W; ++x) {
      render.depth.at<float>(y, x) = static_cast<float>(0.7 + 0.9 * (y * W + x) / double(W * H));
      render.normal.at<cv::Vec3f>(y, x) = cv::Vec3f(0, 0, -1);
      render.label.at<int>(y, x) = 1;
    }
  }
  const cv::Mat simulated = SimulateDepth(render, profile, true, 7);
  const std::vector<int> lows = {700, 900, 1100, 1400};
  const std::vector<double> real_steps = DepthStepsMm(real, lows);
  const std::vector<double> sim_steps = DepthStepsMm(simulated, lows);
  for (size_t i = 0; i < lows.size(); ++i) {
    ASSERT_FALSE(std::isnan(real_steps[i])) << lows[i];
    EXPECT_NEAR(sim_steps[i], real_steps[i], std::max(1.0, 0.3 * real_steps[i]))
        << "depth steps at " << lows[i] << "-" << lows[i] + 200 << " mm";
  }
}

TEST(Case, XtionCasePassesCheckCase) {
  TempDir dir("arpos_sim_xtion");
  SimulationOptions o = SmallOptions();
  o.room_frames = 3;
  o.body_scan_frames = 3;
  o.tracking_frames = 3;
  const fs::path root = dir.path() / "case";
  Simulator(o).WriteCase(root);
  ExpectValidCase(root, o);
  // groundtruth.txt holds exactly what was rendered.
  const Simulator sim(o);
  const auto gt = ReadTrajectory(root / "body_scan" / "groundtruth.txt");
  ASSERT_EQ(gt.size(), 3u);
  const SimulatedFrame frame = sim.RenderFrame(1, 2);
  EXPECT_NEAR(gt[2].timestamp_s, frame.timestamp_s, 1e-6);
  EXPECT_TRUE(gt[2].room_from_x.IsApprox(frame.room_from_camera, 1e-8, 1e-8));
}

// A camera without colour-depth sync: each depth image is of its own
// instant and depth.txt says when; the reader hands the delay on per frame.
TEST(Case, ADepthDelayIsRenderedAtItsOwnTimeAndListedWithIt) {
  TempDir dir("arpos_sim_delay");
  SimulationOptions o = SmallOptions();
  o.room_frames = 2;
  o.body_scan_frames = 2;
  o.tracking_frames = 2;
  o.noise = false;
  o.depth_delay_s = 0.012;
  const fs::path root = dir.path() / "case";
  Simulator(o).WriteCase(root);
  // A valid case; what check says of it is the delay, in each sequence.
  const CaseCheckReport report = CheckCase(root);
  EXPECT_TRUE(report.ok());
  EXPECT_EQ(report.problems.size(), 3u);
  for (const auto& p : report.problems) {
    EXPECT_NE(p.ToString().find("depth images are a median 12.0 ms after their colour images"),
              std::string::npos)
        << p.ToString();
  }
  const CameraIntrinsics K = LoadCaseConfig(root / "case.yaml").camera;
  const Sequence seq = Sequence::Open(root / "body_scan");
  ASSERT_EQ(seq.size(), 2u);
  for (size_t i = 0; i < seq.size(); ++i) {
    EXPECT_NEAR(seq.depth_delay_s(i), 0.012, 1e-6);
    EXPECT_NEAR(seq.LoadFrame(i, K).depth_delay_s, 0.012, 1e-6);
  }
  EXPECT_NEAR(LoadSimulationTruth(root / "simulation.yaml").depth_delay_s, 0.012, 1e-9);
  // The same colour as without the delay, the depth of a camera 12 ms on
  // (the first frame: the walk rests at its end).
  SimulationOptions same_instant = o;
  same_instant.depth_delay_s = 0;
  const SimulatedFrame a = Simulator(same_instant).RenderFrame(1, 0);
  const SimulatedFrame b = Simulator(o).RenderFrame(1, 0);
  EXPECT_EQ(cv::norm(a.color, b.color, cv::NORM_INF), 0.0);
  EXPECT_GT(cv::countNonZero(a.depth != b.depth), 1000);
  EXPECT_NEAR(b.depth_timestamp_s - b.timestamp_s, 0.012, 1e-9);
  o.depth_delay_s = 0.03;
  EXPECT_NE(o.Check().find("depth-delay-ms"), std::string::npos);
}

// A two-frame case of `profile` passes check-case; its camera as case.yaml has it.
CameraIntrinsics SmallProfileCaseCamera(const std::string& profile) {
  TempDir dir("arpos_sim_" + profile);
  SimulationOptions o = SmallOptions();
  o.profile = profile;
  o.room_frames = 2;
  o.body_scan_frames = 2;
  o.tracking_frames = 2;
  const fs::path root = dir.path() / "case";
  Simulator(o).WriteCase(root);
  ExpectValidCase(root, o);
  return LoadCaseConfig(root / "case.yaml").camera;
}

TEST(Case, L515CasePassesCheckCase) {
  const CameraIntrinsics K = SmallProfileCaseCamera("l515");
  EXPECT_EQ(K.width, 1280);
  EXPECT_EQ(K.height, 720);
}

TEST(Case, D435CasePassesCheckCaseWithItsOffCentreCalibration) {
  const CameraIntrinsics K = SmallProfileCaseCamera("d435");
  EXPECT_EQ(K.width, 848);
  EXPECT_EQ(K.height, 480);
  EXPECT_NE(K.fx, K.fy);
  EXPECT_GT(std::abs(K.cx - (K.width - 1) / 2.0), 3.0);
  EXPECT_GT(std::abs(K.cy - (K.height - 1) / 2.0), 3.0);
  EXPECT_EQ(K.depth_scale, 1000);
}

TEST(Case, HardCasePassesCheckCaseAndRecordsItsEffects) {
  TempDir dir("arpos_sim_hard");
  SimulationOptions o = SmallOptions();
  o.hard = true;
  o.room_frames = 2;
  o.body_scan_frames = 6;
  o.tracking_frames = 4;
  const fs::path root = dir.path() / "case";
  const Simulator sim(o);
  sim.WriteCase(root);
  ExpectValidCase(root, o);
  const SimulationTruth truth = LoadSimulationTruth(root / "simulation.yaml");
  EXPECT_GT(truth.motion_blur_exposure_s, 0);
  EXPECT_EQ(truth.lighting_change_from_sequence, "body_scan");
  EXPECT_EQ(truth.hand_sequence, "body_scan");
  EXPECT_EQ(truth.hand_first_frame, 2);
  EXPECT_EQ(truth.hand_last_frame, 4);
  EXPECT_EQ(truth.sticker_off_sequence, "tracking/seq_00");
  EXPECT_EQ(truth.sticker_off_frame, 2);
  // The hand is in the hand frames (in view in most) and only there.
  int hand_frames_seen = 0;
  for (int f = 0; f < 6; ++f) {
    const SimulatedFrame frame = sim.RenderFrame(1, f);
    const int hand_pixels = cv::countNonZero(frame.exact.label == kLabelHand);
    if (f >= 2 && f <= 4) {
      hand_frames_seen += hand_pixels > 500;
    } else {
      EXPECT_EQ(hand_pixels, 0) << "frame " << f;
    }
  }
  EXPECT_GE(hand_frames_seen, 2);
  // The fallen sticker: rendered before its frame, gone from then on.
  int index = -1;
  for (size_t i = 0; i < sim.world().body_markers.size(); ++i) {
    if (sim.world().body_markers[i].id == truth.sticker_off_marker_id) index = static_cast<int>(i);
  }
  ASSERT_GE(index, 0);
  const MarkerTruth& m = sim.world().body_markers[index];
  const CameraIntrinsics& K = sim.profile().intrinsics;
  int checked_on = 0, checked_off = 0;
  for (int f = 0; f < 4; ++f) {
    const SimulatedFrame frame = sim.RenderFrame(2, f);
    const Eigen::Vector3d centre = *frame.room_from_model * m.parent_from_marker.translation;
    const Eigen::Vector3d in_camera = frame.room_from_camera.Inverse() * centre;
    const Eigen::Vector2d px = K.Project(in_camera);
    const int u = static_cast<int>(std::lround(px.x())), v = static_cast<int>(std::lround(px.y()));
    if (u < 0 || v < 0 || u >= K.width || v >= K.height) continue;
    const int label = frame.exact.label.at<int>(v, u);
    if (f < 2) {
      if (std::abs(frame.exact.depth.at<float>(v, u) - in_camera.z()) < 0.002) {
        EXPECT_EQ(label, kLabelSticker);
        ++checked_on;
      }
    } else {
      EXPECT_NE(label, kLabelSticker) << "frame " << f;
      ++checked_off;
    }
  }
  EXPECT_GT(checked_on + checked_off, 0);
}

TEST(Case, SameSeedSameBytesOtherSeedOtherBytes) {
  TempDir dir("arpos_sim_determinism");
  SimulationOptions o = SmallOptions();
  o.room_frames = 2;
  o.body_scan_frames = 2;
  o.tracking_frames = 2;
  o.seed = 7;
  Simulator(o).WriteCase(dir.path() / "a");
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);  // thread count must not matter
  Simulator(o).WriteCase(dir.path() / "b");
  omp_set_num_threads(threads);
  o.seed = 8;
  Simulator(o).WriteCase(dir.path() / "c");
  const auto a = ReadTree(dir.path() / "a"), b = ReadTree(dir.path() / "b"),
             c = ReadTree(dir.path() / "c");
  ASSERT_EQ(a.size(), b.size());
  for (const auto& [name, bytes] : a) {
    ASSERT_TRUE(b.count(name)) << name;
    EXPECT_TRUE(b.at(name) == bytes) << name << " differs for the same seed";
  }
  int differing = 0;
  for (const auto& [name, bytes] : a) {
    if (c.count(name) && c.at(name) != bytes) ++differing;
  }
  EXPECT_GT(differing, 0);
  EXPECT_NE(a.at("room/rgb/10.000000.png"), c.at("room/rgb/10.000000.png"));
  EXPECT_NE(a.at("reference_model.ply"), c.at("reference_model.ply"));
}

TEST(Case, RefusesANonEmptyFolderAndBadOptions) {
  TempDir dir("arpos_sim_refuse");
  WriteFileAtomic(dir.path() / "something.txt", "x");
  const Simulator& sim = ExactSimulator();
  EXPECT_THROW(sim.WriteCase(dir.path()), InputError);
  SimulationOptions o = SmallOptions();
  o.profile = "kinect9";
  EXPECT_THROW(Simulator{o}, InputError);
  o = SmallOptions();
  o.room_frames = 0;
  EXPECT_FALSE(o.Check().empty());
}

}  // namespace
}  // namespace arpos::sim

