#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <opencv2/imgcodecs.hpp>

#include "geometry/mesh_io.h"
#include "sensor/case_check.h"
#include "sensor/case_folder.h"
#include "sensor/sequence.h"
#include "sensor/test_case_builder.h"
#include "sensor/tum_io.h"
#include "util/check.h"
#include "util/file.h"
#include "util/string_util.h"

namespace arpos {
namespace {
namespace fs = std::filesystem;

class CaseCheckTest : public ::testing::Test {
 protected:
  void SetUp() override { testing::WriteTinyCase(root()); }
  fs::path root() const { return dir_.path() / "case"; }
  // All problems as one string, for substring checks.
  std::string Problems(bool* ok = nullptr) const {
    const CaseCheckReport report = CheckCase(root());
    if (ok) *ok = report.ok();
    std::string all;
    for (const auto& p : report.problems) all += p.ToString() + "\n";
    return all;
  }
  void ExpectError(const std::string& where, const std::string& what) {
    bool ok = true;
    const std::string problems = Problems(&ok);
    EXPECT_FALSE(ok) << problems;
    EXPECT_NE(problems.find("error: " + where), std::string::npos) << problems;
    EXPECT_NE(problems.find(what), std::string::npos) << problems;
  }
  TempDir dir_;
};

TEST_F(CaseCheckTest, ValidCasePasses) {
  bool ok = false;
  const std::string problems = Problems(&ok);
  EXPECT_TRUE(ok) << problems;
  const CaseCheckReport report = CheckCase(root());
  EXPECT_EQ(report.sequences, 3);
  EXPECT_EQ(report.frames, 9);
  EXPECT_EQ(report.images_read, 18);
}

TEST_F(CaseCheckTest, MissingFolderAndFiles) {
  fs::remove(root() / "room" / "rgb" / "1.png");
  ExpectError("room/rgb/1.png", "missing (listed in rgb.txt line");
}

TEST_F(CaseCheckTest, MissingCaseFiles) {
  fs::remove(root() / "case.yaml");
  fs::remove(root() / "reference_model.ply");
  fs::remove(root() / "target_pose.txt");
  fs::remove_all(root() / "body_scan");
  const std::string problems = Problems();
  EXPECT_NE(problems.find("error: case.yaml: missing"), std::string::npos) << problems;
  EXPECT_NE(problems.find("error: reference_model.ply: missing"), std::string::npos);
  EXPECT_NE(problems.find("error: target_pose.txt: missing"), std::string::npos);
  EXPECT_NE(problems.find("error: body_scan/: sequence folder missing"), std::string::npos);
}

TEST_F(CaseCheckTest, CorruptImage) {
  WriteFileAtomic(root() / "body_scan" / "rgb" / "2.png", "\x89PNG this is not an image");
  ExpectError("body_scan/rgb/2.png", "unreadable or corrupt image");
}

TEST_F(CaseCheckTest, WrongSizedImage) {
  cv::imwrite((root() / "room" / "depth" / "0.png").string(), cv::Mat(30, 40, CV_16UC1, cv::Scalar(1)));
  ExpectError("room/depth/0.png", "image is 40x30 but case.yaml camera is 80x60");
}

TEST_F(CaseCheckTest, DepthNot16Bit) {
  cv::imwrite((root() / "tracking" / "a" / "depth" / "1.png").string(),
              cv::Mat(60, 80, CV_8UC1, cv::Scalar(7)));
  ExpectError("tracking/a/depth/1.png", "depth must be 16-bit single-channel");
}

TEST_F(CaseCheckTest, NonMonotonicTimestamps) {
  WriteFileAtomic(root() / "room" / "rgb.txt",
                  "# t file\n1.0 rgb/0.png\n1.066667 rgb/2.png\n1.033333 rgb/1.png\n");
  ExpectError("room/rgb.txt", "timestamps not increasing at line 4");
}

// Timestamps in another unit than seconds (a converter that wrote
// nanoseconds) read as frames years apart; every window counted in seconds
// would stop working without a word. Refused by the check and the reader.
TEST_F(CaseCheckTest, TimestampsThatAreNotSecondsAreNamedWithTheirLikelyUnit) {
  WriteFileAtomic(root() / "room" / "rgb.txt",
                  "1700000001000000000 rgb/0.png\n1700000001033333333 "
                  "rgb/1.png\n1700000001066666667 rgb/2.png\n");
  ExpectError("room/rgb.txt",
              "timestamps must be in seconds (DATASET.md); these look like nanoseconds");
  try {
    Sequence::Open(root() / "room");
    ADD_FAILURE() << "nanosecond timestamps were read as seconds";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("room/rgb.txt: frames are a median"), std::string::npos)
        << e.what();
  }
  WriteFileAtomic(root() / "room" / "rgb.txt", "1000000 rgb/0.png\n1033333 rgb/1.png\n1066667 rgb/2.png\n");
  ExpectError("room/rgb.txt", "these look like microseconds");
}

// Depth listed 8 ms after its colour (a camera without colour-depth sync):
// a warning that says how far and what to do; the case stays usable.
TEST_F(CaseCheckTest, DepthTakenAtOtherInstantsThanItsColourIsAWarning) {
  const std::vector<ImageListEntry> depth = ReadImageList(root() / "room" / "depth.txt");
  std::string text;
  for (const auto& e : depth)
    text += StringPrintf("%.6f %s\n", e.timestamp_s + 0.008, e.relative_path.c_str());
  WriteFileAtomic(root() / "room" / "depth.txt", text);
  const CaseCheckReport report = CheckCase(root());
  EXPECT_TRUE(report.ok());
  bool warned = false;
  for (const auto& p : report.problems) {
    warned |=
        p.ToString().find("room/: depth images are a median 8.0 ms after their colour images") !=
            std::string::npos &&
        p.ToString().find("colour-depth sync") != std::string::npos;
  }
  EXPECT_TRUE(warned) << Problems();
  EXPECT_NEAR(Sequence::Open(root() / "room").depth_delay_s(0), 0.008, 1e-6);
}

// Frames seconds apart (a slow recording, or a few stills of a walk) are
// still seconds.
TEST(ImageListTimestamps, StillsSecondsApartAreSeconds) {
  std::vector<ImageListEntry> list;
  for (int i = 0; i < 3; ++i) list.push_back({10.0 + 30 * i, "rgb/" + std::to_string(i) + ".png", i + 1});
  EXPECT_EQ(ImageListTimestampProblem(list), "");
  list.resize(1);
  EXPECT_EQ(ImageListTimestampProblem(list), "");
}

TEST_F(CaseCheckTest, TargetPoseNotRigid) {
  WriteFileAtomic(root() / "target_pose.txt", "2 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n");
  ExpectError("target_pose.txt", "not a rigid transform: its rotation is not orthonormal");
  WriteFileAtomic(root() / "target_pose.txt", "1 0 0 0\n0 1 0 0\n0 0 1 0\n");
  ExpectError("target_pose.txt", "expected a 4x4 matrix (16 numbers, row-major), found 12");
}

TEST_F(CaseCheckTest, ReferenceModelTruncatedOrInMillimetres) {
  std::string ply = ReadTextFile(root() / "reference_model.ply");
  WriteFileAtomic(root() / "reference_model.ply", ply.substr(0, ply.size() - 12));
  ExpectError("reference_model.ply", "reference_model.ply");
  // The same tetrahedron scaled to millimetres.
  WriteFileAtomic(root() / "reference_model.ply",
                  "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                  "property float z\nelement face 4\nproperty list uchar int vertex_indices\n"
                  "end_header\n0 0 0\n100 0 0\n0 100 0\n0 0 100\n3 0 2 1\n3 0 1 3\n3 0 3 2\n"
                  "3 1 2 3\n");
  ExpectError("reference_model.ply", "largest extent is 100 m: not a body surface in metres");
  ExpectError("reference_model.ply", "looks like millimetres: convert it with arpos import-model");
}

// The tetrahedron as binary PLY with a fifth vertex that one face uses.
std::string BinaryPlyWithFifthVertex(float x) {
  const float vertices[5][3] = {{0, 0, 0}, {0.1f, 0, 0}, {0, 0.1f, 0}, {0, 0, 0.1f}, {x, 0.05f, 0.05f}};
  const int faces[5][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}, {4, 1, 2}};
  std::string ply =
      "ply\nformat binary_little_endian 1.0\nelement vertex 5\nproperty float x\nproperty float y\n"
      "property float z\nelement face 5\nproperty list uchar int vertex_indices\nend_header\n";
  for (const auto& v : vertices) ply.append(reinterpret_cast<const char*>(v), sizeof v);
  for (const auto& f : faces) {
    ply.push_back(3);
    ply.append(reinterpret_cast<const char*>(f), sizeof f);
  }
  return ply;
}

// A NaN vertex used to merge silently with another vertex (NaN compares
// equal to everything) and pass.
TEST_F(CaseCheckTest, ReferenceModelWithANanVertexIsRefusedNamingTheVertex) {
  WriteFileAtomic(root() / "reference_model.ply", BinaryPlyWithFifthVertex(std::nanf("")));
  ExpectError("reference_model.ply", "PLY vertex 4 has x = nan: coordinates must be finite numbers");
  WriteFileAtomic(root() / "reference_model.ply", BinaryPlyWithFifthVertex(INFINITY));
  ExpectError("reference_model.ply", "PLY vertex 4 has x = inf");
  WriteFileAtomic(root() / "reference_model.ply",
                  "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                  "property float z\nelement face 4\nproperty list uchar int vertex_indices\n"
                  "end_header\n0 0 0\n0.1 0 0\n0 nan 0\n0 0 0.1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n"
                  "3 1 2 3\n");
  ExpectError("reference_model.ply", "PLY vertex 2: 'nan' is not a finite number");
  // Formats without a structure check: the loader refuses it.
  fs::remove(root() / "reference_model.ply");
  WriteFileAtomic(root() / "reference_model.obj",
                  "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0 0 nan\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n");
  ExpectError("reference_model.obj", "is (0, 0, nan): coordinates must be finite numbers");
  // The valid file still loads, every vertex kept.
  fs::remove(root() / "reference_model.obj");
  WriteFileAtomic(root() / "reference_model.ply", BinaryPlyWithFifthVertex(0.05f));
  EXPECT_EQ(LoadTriangleMesh(root() / "reference_model.ply").vertices.size(), 5u);
}

TEST_F(CaseCheckTest, GarbageOrEmptyReferenceModelIsNamedAsSuch) {
  std::string garbage;
  for (int i = 0; i < 3000; ++i) garbage.push_back(static_cast<char>((i * 131 + 7) % 256));
  WriteFileAtomic(root() / "reference_model.ply", garbage);
  ExpectError("reference_model.ply", "not a PLY file");
  WriteFileAtomic(root() / "reference_model.ply", "");
  ExpectError("reference_model.ply", "empty file (0 bytes)");
  fs::remove(root() / "reference_model.ply");
  fs::create_directory(root() / "reference_model.ply");
  ExpectError("reference_model.ply", "not a regular file");
}

TEST_F(CaseCheckTest, TargetPoseInMillimetresIsRefusedNamingTheValue) {
  WriteFileAtomic(root() / "target_pose.txt", "1 0 0 1800\n0 1 0 -150\n0 0 1 950\n0 0 0 1\n");
  ExpectError("target_pose.txt", "translation (1800.000, -150.000, 950.000) is 2040.8 m from the room origin");
  ExpectError("target_pose.txt", "looks like millimetres (target_pose.txt is in metres)");
  // The reader the stages use refuses it too.
  try {
    LoadCaseFolder(root());
    ADD_FAILURE() << "a target pose 2 km away was read";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("target_pose.txt: translation"), std::string::npos) << e.what();
  }
  WriteFileAtomic(root() / "target_pose.txt", "1 0 0 nan\n0 1 0 0\n0 0 1 0\n0 0 0 1\n");
  ExpectError("target_pose.txt", "'nan' is not a number");
}

TEST_F(CaseCheckTest, GroundTruthInMillimetresIsRefused) {
  WriteFileAtomic(root() / "body_scan" / "body_groundtruth.txt",
                  "1.0 700 1300 900 0 0 0 1\n1.033333 700 1300 900 0 0 0 1\n");
  ExpectError("body_scan/body_groundtruth.txt", "pose 1 (t = 1.000000) is 1729.2 m from the room origin");
  ExpectError("body_scan/body_groundtruth.txt", "looks like millimetres");
}

TEST_F(CaseCheckTest, OutOfOrderTimestampsAreRefusedByTheSequenceReaderToo) {
  WriteFileAtomic(root() / "body_scan" / "depth.txt",
                  "1.0 depth/0.png\n1.066667 depth/2.png\n1.033333 depth/1.png\n");
  ExpectError("body_scan/depth.txt", "timestamps not increasing at line 3");
  // Said once, not again by the reader.
  EXPECT_EQ(Problems().find("body_scan/: "), std::string::npos) << Problems();
  try {
    Sequence::Open(root() / "body_scan");
    ADD_FAILURE() << "out-of-order timestamps were read";
  } catch (const InputError& e) {
    EXPECT_NE(
        std::string(e.what()).find(
            "body_scan/depth.txt: timestamps not increasing at line 3 (1.033333 after 1.066667)"),
        std::string::npos)
        << e.what();
  }
}

// A stage checks what it reads, with the same messages, quickly.
TEST_F(CaseCheckTest, RequireValidCaseChecksWhatAStageReads) {
  WriteFileAtomic(root() / "body_scan" / "rgb" / "1.png", "garbage");
  CaseCheckOptions room_only;
  room_only.read_all_images = false;
  room_only.sequences = std::vector<fs::path>{"room"};
  EXPECT_TRUE(RequireValidCase(root(), room_only).ok());
  CaseCheckOptions scan_only = room_only;
  scan_only.sequences = std::vector<fs::path>{root() / "body_scan"};
  try {
    RequireValidCase(root(), scan_only);
    ADD_FAILURE() << "a corrupt body-scan image passed";
  } catch (const InputError& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find(root().string() + ": the case has problems (`arpos check " + root().string() +
                           "` lists them all):\n  error: body_scan/rgb/1.png: unreadable or corrupt image"),
              std::string::npos)
        << message;
  }
  // Without the reference model and target pose checks (localisation reads neither).
  fs::remove(root() / "target_pose.txt");
  CaseCheckOptions config_and_sequence = room_only;
  config_and_sequence.target_pose = false;
  config_and_sequence.reference_model = false;
  EXPECT_TRUE(RequireValidCase(root(), config_and_sequence).ok());
  EXPECT_THROW(RequireValidCase(root(), room_only), InputError);
}

TEST_F(CaseCheckTest, BadYamlKeyIsNamed) {
  std::string yaml = ReadTextFile(root() / "case.yaml");
  yaml.replace(yaml.find("fx:"), 3, "fq:");
  WriteFileAtomic(root() / "case.yaml", yaml);
  ExpectError("case.yaml", "camera.fx: missing");
}

TEST_F(CaseCheckTest, WrongIntrinsicsSizeIsCaught) {
  // case.yaml claims 640x480 but images are 80x60: every image is reported.
  std::string yaml = ReadTextFile(root() / "case.yaml");
  yaml.replace(yaml.find("width: 80"), 9, "width: 640");
  yaml.replace(yaml.find("height: 60"), 10, "height: 480");
  WriteFileAtomic(root() / "case.yaml", yaml);
  ExpectError("room/rgb/0.png", "image is 80x60 but case.yaml camera is 640x480");
}

TEST_F(CaseCheckTest, MalformedGroundTruth) {
  WriteFileAtomic(root() / "tracking" / "a" / "body_groundtruth.txt", "1.0 0 0 0 0 0 0\n");
  ExpectError("tracking/a/body_groundtruth.txt:1", "expected 8 numbers");
}

TEST_F(CaseCheckTest, ReportsEveryProblemNotJustTheFirst) {
  fs::remove(root() / "target_pose.txt");
  WriteFileAtomic(root() / "room" / "rgb" / "0.png", "garbage");
  WriteFileAtomic(root() / "body_scan" / "depth.txt", "1.0\n");
  const CaseCheckReport report = CheckCase(root());
  EXPECT_GE(report.problems.size(), 3u);
}

}  // namespace
}  // namespace arpos
