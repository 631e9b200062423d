#pragma once

#include <yaml-cpp/yaml.h>

#include <filesystem>

namespace arpos {

// Reads and parses a YAML file the user gives (case.yaml, simulation.yaml).
// Refuses, as input errors naming the file and the line: text that is not
// YAML, and a key given twice in one mapping (yaml-cpp keeps both and a
// lookup takes the first, so an edit appended below an old value would be
// silently ignored).
YAML::Node LoadYamlFile(const std::filesystem::path& path);

}  // namespace arpos
