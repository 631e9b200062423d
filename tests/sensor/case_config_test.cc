#include <gtest/gtest.h>

#include "sensor/case_config.h"
#include "sensor/test_case_builder.h"
#include "util/check.h"
#include "util/file.h"

namespace arpos {
namespace {

const char* kValidYaml = R"(camera:
  width: 640
  height: 480
  fx: 525.0
  fy: 525.0
  cx: 319.5
  cy: 239.5
  distortion: [0, 0, 0, 0, 0]     # OpenCV k1 k2 p1 p2 k3
  depth_scale: 5000
markers:
  dictionary: DICT_4X4_250
  room:
    size_m: 0.15
    origin_id: 0
    ids: [0, 49]
  body:
    size_m: 0.03
    ids: [100, 199]
)";

std::string LoadError(const std::string& yaml) {
  TempDir dir;
  WriteFileAtomic(dir.path() / "case.yaml", yaml);
  try {
    LoadCaseConfig(dir.path() / "case.yaml");
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

std::string Replace(std::string text, const std::string& from, const std::string& to) {
  const size_t pos = text.find(from);
  EXPECT_NE(pos, std::string::npos) << from;
  return text.replace(pos, from.size(), to);
}

TEST(CaseConfig, ReadsTheDatasetExample) {
  TempDir dir;
  WriteFileAtomic(dir.path() / "case.yaml", kValidYaml);
  const CaseConfig c = LoadCaseConfig(dir.path() / "case.yaml");
  EXPECT_EQ(c.camera.width, 640);
  EXPECT_DOUBLE_EQ(c.camera.cx, 319.5);
  EXPECT_DOUBLE_EQ(c.camera.depth_scale, 5000);
  EXPECT_EQ(c.dictionary, "DICT_4X4_250");
  EXPECT_DOUBLE_EQ(c.room_markers.size_m, 0.15);
  EXPECT_EQ(c.room_markers.id_max, 49);
  EXPECT_EQ(c.body_markers.id_min, 100);
  EXPECT_EQ(c.room_origin_id, 0);
}

TEST(CaseConfig, RoundTrips) {
  TempDir dir;
  const CaseConfig c = testing::TinyCaseConfig();
  SaveCaseConfig(c, dir.path() / "case.yaml");
  const CaseConfig back = LoadCaseConfig(dir.path() / "case.yaml");
  EXPECT_EQ(back.camera.width, c.camera.width);
  EXPECT_DOUBLE_EQ(back.camera.fx, c.camera.fx);
  EXPECT_DOUBLE_EQ(back.body_markers.size_m, c.body_markers.size_m);
}

TEST(CaseConfig, ErrorsNameFileAndKey) {
  struct Case {
    std::string from, to, expect;
  } cases[] = {
      {"  fx: 525.0\n", "", "camera.fx: missing"},
      {"fx: 525.0", "fx: abc", "camera.fx: must be a number, got 'abc'"},
      {"fx: 525.0", "fx: -5", "camera.fx: must be positive"},
      {"width: 640", "width: 64.5", "camera.width: must be an integer"},
      {"cx: 319.5", "cx: 3195", "camera.cx: must lie inside the image"},
      {"depth_scale: 5000", "depth_scale: 0", "camera.depth_scale: must be positive"},
      {"distortion: [0, 0, 0, 0, 0]", "distortion: [0, 0]", "camera.distortion: must hold 5 numbers"},
      {"DICT_4X4_250", "DICT_9X9_7", "markers.dictionary: unknown dictionary"},
      {"size_m: 0.15", "size_m: 150", "markers.room.size_m: must be between"},
      {"ids: [100, 199]", "ids: [100, 300]", "markers.body.ids: id 300 does not exist"},
      {"ids: [100, 199]", "ids: [40, 60]", "markers.body.ids: overlaps"},
      {"origin_id: 0", "origin_id: 77", "markers.room.origin_id: 77 is outside"},
      {"ids: [0, 49]", "ids: 7", "markers.room.ids: must be a list"},
  };
  for (const auto& c : cases) {
    const std::string error = LoadError(Replace(kValidYaml, c.from, c.to));
    EXPECT_NE(error.find("case.yaml: "), std::string::npos) << error;
    EXPECT_NE(error.find(c.expect), std::string::npos) << "expected '" << c.expect << "' in: " << error;
  }
}

TEST(CaseConfig, MalformedYamlNamesLine) {
  const std::string error = LoadError("camera:\n  width: [640\n  height: 480\n");
  EXPECT_NE(error.find("not valid YAML (line"), std::string::npos) << error;
  EXPECT_NE(LoadError("- just\n- a list\n").find("must be a YAML mapping"), std::string::npos);
  TempDir dir;
  EXPECT_THROW(LoadCaseConfig(dir.path() / "nope.yaml"), InputError);
}

// yaml-cpp keeps both values of a repeated key and a lookup takes the first:
// a corrected size appended below the old one would be ignored in silence.
TEST(CaseConfig, AKeyGivenTwiceIsRefusedWithBothLines) {
  const std::string body_twice =
      Replace(kValidYaml, "    size_m: 0.03\n", "    size_m: 0.03\n    size_m: 0.05\n");
  const std::string error = LoadError(body_twice);
  EXPECT_NE(error.find("case.yaml: markers.body.size_m: given twice (lines 17 and 18)"),
            std::string::npos)
      << error;
  const std::string camera_twice = std::string(kValidYaml) + "camera:\n  width: 320\n";
  EXPECT_NE(LoadError(camera_twice).find("case.yaml: camera: given twice (lines 1 and 19)"),
            std::string::npos)
      << LoadError(camera_twice);
  // The same key in two mappings is not a repeat.
  EXPECT_EQ(LoadError(kValidYaml), "");
}

}  // namespace
}  // namespace arpos
