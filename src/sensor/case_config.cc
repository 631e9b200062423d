#include "sensor/case_config.h"

#include <yaml-cpp/yaml.h>

#include <opencv2/aruco.hpp>
#include <sstream>

#include "sensor/yaml_file.h"
#include "util/check.h"
#include "util/file.h"
#include "util/string_util.h"

namespace arpos {
namespace {

struct DictionaryName {
  const char* name;
  int id;
};

const DictionaryName kDictionaries[] = {
    {"DICT_4X4_50", cv::aruco::DICT_4X4_50},
    {"DICT_4X4_100", cv::aruco::DICT_4X4_100},
    {"DICT_4X4_250", cv::aruco::DICT_4X4_250},
    {"DICT_4X4_1000", cv::aruco::DICT_4X4_1000},
    {"DICT_5X5_50", cv::aruco::DICT_5X5_50},
    {"DICT_5X5_100", cv::aruco::DICT_5X5_100},
    {"DICT_5X5_250", cv::aruco::DICT_5X5_250},
    {"DICT_5X5_1000", cv::aruco::DICT_5X5_1000},
    {"DICT_6X6_50", cv::aruco::DICT_6X6_50},
    {"DICT_6X6_100", cv::aruco::DICT_6X6_100},
    {"DICT_6X6_250", cv::aruco::DICT_6X6_250},
    {"DICT_6X6_1000", cv::aruco::DICT_6X6_1000},
    {"DICT_7X7_50", cv::aruco::DICT_7X7_50},
    {"DICT_7X7_100", cv::aruco::DICT_7X7_100},
    {"DICT_7X7_250", cv::aruco::DICT_7X7_250},
    {"DICT_7X7_1000", cv::aruco::DICT_7X7_1000},
    {"DICT_ARUCO_ORIGINAL", cv::aruco::DICT_ARUCO_ORIGINAL},
    {"DICT_APRILTAG_16h5", cv::aruco::DICT_APRILTAG_16h5},
    {"DICT_APRILTAG_25h9", cv::aruco::DICT_APRILTAG_25h9},
    {"DICT_APRILTAG_36h10", cv::aruco::DICT_APRILTAG_36h10},
    {"DICT_APRILTAG_36h11", cv::aruco::DICT_APRILTAG_36h11},
};

int DictionarySize(const std::string& name) {
  const size_t pos = name.rfind('_');
  long long size = 0;
  if (StartsWith(name, "DICT_APRILTAG") || name == "DICT_ARUCO_ORIGINAL") {
    return cv::aruco::getPredefinedDictionary(ArucoDictionaryId(name))->bytesList.rows;
  }
  if (pos != std::string::npos && ParseInt(name.substr(pos + 1), &size)) return static_cast<int>(size);
  return 0;
}

// Reads scalars with messages that name the file and the full key.
class Reader {
 public:
  Reader(const std::filesystem::path& file, const YAML::Node& root) : file_(file), root_(root) {}

  YAML::Node Node(const std::string& key) const {
    YAML::Node node = YAML::Clone(root_);
    std::string done;
    size_t start = 0;
    while (start <= key.size()) {
      const size_t dot = key.find('.', start);
      const std::string part = key.substr(start, dot == std::string::npos ? std::string::npos : dot - start);
      if (!node.IsMap()) Fail(done.empty() ? key : done, "must be a mapping");
      YAML::Node child = node[part];
      if (!child) Fail(key, "missing");
      node = child;
      done = done.empty() ? part : done + "." + part;
      if (dot == std::string::npos) break;
      start = dot + 1;
    }
    return node;
  }

  double Double(const std::string& key) const {
    const YAML::Node node = Node(key);
    double value = 0;
    if (!node.IsScalar() || !ParseDouble(Trim(node.Scalar()), &value)) {
      Fail(key, "must be a number, got '" + Describe(node) + "'");
    }
    return value;
  }

  int Int(const std::string& key) const {
    const YAML::Node node = Node(key);
    long long value = 0;
    if (!node.IsScalar() || !ParseInt(Trim(node.Scalar()), &value) || value < INT32_MIN ||
        value > INT32_MAX) {
      Fail(key, "must be an integer, got '" + Describe(node) + "'");
    }
    return static_cast<int>(value);
  }

  std::string String(const std::string& key) const {
    const YAML::Node node = Node(key);
    if (!node.IsScalar()) Fail(key, "must be a string");
    return node.Scalar();
  }

  std::vector<double> Doubles(const std::string& key) const {
    const YAML::Node node = Node(key);
    if (!node.IsSequence()) Fail(key, "must be a list of numbers");
    std::vector<double> values;
    for (size_t i = 0; i < node.size(); ++i) {
      double value = 0;
      if (!node[i].IsScalar() || !ParseDouble(Trim(node[i].Scalar()), &value)) {
        Fail(key + "[" + std::to_string(i) + "]", "must be a number, got '" + Describe(node[i]) + "'");
      }
      values.push_back(value);
    }
    return values;
  }

  [[noreturn]] void Fail(const std::string& key, const std::string& what) const {
    ARPOS_INPUT_ERROR(file_.string() << ": " << key << ": " << what);
  }

 private:
  static std::string Describe(const YAML::Node& node) {
    if (node.IsScalar()) return node.Scalar();
    if (node.IsSequence()) return "a list";
    if (node.IsMap()) return "a mapping";
    return "nothing";
  }
  std::filesystem::path file_;
  YAML::Node root_;
};

MarkerSetConfig ReadMarkerSet(const Reader& reader, const std::string& prefix) {
  MarkerSetConfig set;
  set.size_m = reader.Double(prefix + ".size_m");
  const std::vector<double> ids = reader.Doubles(prefix + ".ids");
  if (ids.size() != 2) reader.Fail(prefix + ".ids", "must be an inclusive range [first, last]");
  for (double v : ids) {
    if (v != static_cast<int>(v)) reader.Fail(prefix + ".ids", "must hold integers");
  }
  set.id_min = static_cast<int>(ids[0]);
  set.id_max = static_cast<int>(ids[1]);
  return set;
}

}  // namespace

int ArucoDictionaryId(const std::string& name) {
  for (const auto& d : kDictionaries) {
    if (name == d.name) return d.id;
  }
  return -1;
}

std::string ValidateCaseConfig(const CaseConfig& config) {
  const std::string camera = config.camera.Validate();
  if (!camera.empty()) {
    // Validate() names the field first: "fx must be..." -> "camera.fx: must be...".
    const size_t space = camera.find(' ');
    const std::string field = camera.substr(0, space);
    const bool named = field == "width" || field == "height" || field == "fx" || field == "fy" ||
                       field == "cx" || field == "cy" || field == "depth_scale";
    return named ? "camera." + field + ": " + camera.substr(space + 1)
                 : "camera: " + camera;
  }
  const int dict = ArucoDictionaryId(config.dictionary);
  if (dict < 0) return "markers.dictionary: unknown dictionary '" + config.dictionary + "'";
  const int dict_size = DictionarySize(config.dictionary);
  auto check_set = [&](const MarkerSetConfig& set, const std::string& key) -> std::string {
    if (!(set.size_m > 0.005 && set.size_m < 2.0)) {
      return key + ".size_m: must be between 0.005 and 2 metres, got " + std::to_string(set.size_m) +
             " (is it in millimetres?)";
    }
    if (set.id_min < 0 || set.id_max < set.id_min) {
      return key + ".ids: must be [first, last] with 0 <= first <= last";
    }
    if (dict_size > 0 && set.id_max >= dict_size) {
      return key + ".ids: id " + std::to_string(set.id_max) + " does not exist in " +
             config.dictionary + " (" + std::to_string(dict_size) + " markers)";
    }
    return "";
  };
  std::string problem = check_set(config.room_markers, "markers.room");
  if (!problem.empty()) return problem;
  problem = check_set(config.body_markers, "markers.body");
  if (!problem.empty()) return problem;
  if (!config.room_markers.Contains(config.room_origin_id)) {
    return "markers.room.origin_id: " + std::to_string(config.room_origin_id) +
           " is outside markers.room.ids";
  }
  const bool overlap = config.room_markers.id_min <= config.body_markers.id_max &&
                       config.body_markers.id_min <= config.room_markers.id_max;
  if (overlap) return "markers.body.ids: overlaps markers.room.ids";
  return "";
}

CaseConfig LoadCaseConfig(const std::filesystem::path& yaml_path) {
  const YAML::Node root = LoadYamlFile(yaml_path);
  if (!root.IsMap()) ARPOS_INPUT_ERROR(yaml_path.string() << ": must be a YAML mapping");
  const Reader reader(yaml_path, root);

  CaseConfig config;
  CameraIntrinsics& cam = config.camera;
  cam.width = reader.Int("camera.width");
  cam.height = reader.Int("camera.height");
  cam.fx = reader.Double("camera.fx");
  cam.fy = reader.Double("camera.fy");
  cam.cx = reader.Double("camera.cx");
  cam.cy = reader.Double("camera.cy");
  if (root["camera"]["distortion"]) {
    const std::vector<double> d = reader.Doubles("camera.distortion");
    if (d.size() != 5 && d.size() != 4) {
      reader.Fail("camera.distortion", "must hold 5 numbers (k1 k2 p1 p2 k3), got " +
                                           std::to_string(d.size()));
    }
    for (size_t i = 0; i < d.size(); ++i) cam.distortion[i] = d[i];
  }
  cam.depth_scale = reader.Double("camera.depth_scale");
  config.dictionary = reader.String("markers.dictionary");
  config.room_markers = ReadMarkerSet(reader, "markers.room");
  config.room_origin_id = reader.Int("markers.room.origin_id");
  config.body_markers = ReadMarkerSet(reader, "markers.body");

  const std::string problem = ValidateCaseConfig(config);
  if (!problem.empty()) ARPOS_INPUT_ERROR(yaml_path.string() << ": " << problem);
  return config;
}

void SaveCaseConfig(const CaseConfig& config, const std::filesystem::path& yaml_path) {
  const CameraIntrinsics& c = config.camera;
  std::ostringstream out;
  out.precision(17);
  out << "# ARPos case (layout: DATASET.md)\n"
      << "camera:\n"
      << "  width: " << c.width << "\n"
      << "  height: " << c.height << "\n"
      << "  fx: " << c.fx << "\n"
      << "  fy: " << c.fy << "\n"
      << "  cx: " << c.cx << "\n"
      << "  cy: " << c.cy << "\n"
      << "  distortion: [" << c.distortion[0] << ", " << c.distortion[1] << ", " << c.distortion[2]
      << ", " << c.distortion[3] << ", " << c.distortion[4] << "]   # OpenCV k1 k2 p1 p2 k3\n"
      << "  depth_scale: " << c.depth_scale << "   # depth PNG units per metre\n"
      << "markers:\n"
      << "  dictionary: " << config.dictionary << "\n"
      << "  room:\n"
      << "    size_m: " << config.room_markers.size_m << "\n"
      << "    origin_id: " << config.room_origin_id << "\n"
      << "    ids: [" << config.room_markers.id_min << ", " << config.room_markers.id_max << "]\n"
      << "  body:\n"
      << "    size_m: " << config.body_markers.size_m << "\n"
      << "    ids: [" << config.body_markers.id_min << ", " << config.body_markers.id_max << "]\n";
  WriteFileAtomic(yaml_path, out.str());
}

}  // namespace arpos
