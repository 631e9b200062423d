#include <gtest/gtest.h>

#include <fstream>
#include <opencv2/imgcodecs.hpp>

#include "sensor/case_check.h"
#include "sensor/test_case_builder.h"
#include "util/file.h"

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
  ExpectError("reference_model.ply", "is it in millimetres?");
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
