#include "sensor/yaml_file.h"

#include <map>
#include <string>

#include "util/check.h"
#include "util/file.h"

namespace arpos {
namespace {

// The first key given twice in one mapping, depth first, said as
// "a.b: given twice (lines 3 and 7); keep one"; empty when none is.
std::string RepeatedKey(const YAML::Node& node, const std::string& prefix) {
  if (node.IsSequence()) {
    for (size_t i = 0; i < node.size(); ++i) {
      const std::string found = RepeatedKey(node[i], prefix + "[" + std::to_string(i) + "]");
      if (!found.empty()) return found;
    }
    return "";
  }
  if (!node.IsMap()) return "";
  std::map<std::string, int> first_line;
  for (auto it = node.begin(); it != node.end(); ++it) {
    const std::string key =
        it->first.IsScalar() ? it->first.Scalar() : std::string("(complex key)");
    const std::string full = prefix.empty() ? key : prefix + "." + key;
    const int line = it->first.Mark().line + 1;
    const auto [seen, inserted] = first_line.emplace(key, line);
    if (!inserted) {
      return full + ": given twice (lines " + std::to_string(seen->second) + " and " +
             std::to_string(line) + "); keep one";
    }
    const std::string found = RepeatedKey(it->second, full);
    if (!found.empty()) return found;
  }
  return "";
}

}  // namespace

YAML::Node LoadYamlFile(const std::filesystem::path& path) {
  const std::string text = ReadTextFile(path);
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    ARPOS_INPUT_ERROR(path.string() << ": not valid YAML (line " << e.mark.line + 1 << ", column "
                                    << e.mark.column + 1 << "): " << e.msg);
  }
  const std::string repeated = RepeatedKey(root, "");
  if (!repeated.empty()) ARPOS_INPUT_ERROR(path.string() << ": " << repeated);
  return root;
}

}  // namespace arpos
