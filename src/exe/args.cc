#include "exe/args.h"

#include <iostream>

#include "util/check.h"
#include "util/string_util.h"

namespace arpos {

Args::Args(const std::vector<std::string>& argv, const std::set<std::string>& value_options,
           const std::set<std::string>& flag_options) {
  for (size_t i = 0; i < argv.size(); ++i) {
    const std::string& arg = argv[i];
    if (arg.size() > 2 && StartsWith(arg, "--")) {
      std::string key = arg.substr(2), value;
      const size_t eq = key.find('=');
      const bool inline_value = eq != std::string::npos;
      if (inline_value) {
        value = key.substr(eq + 1);
        key = key.substr(0, eq);
      }
      if (flag_options.count(key)) {
        if (inline_value) ARPOS_INPUT_ERROR("option --" << key << " takes no value");
        values_[key] = "1";
      } else if (value_options.count(key)) {
        if (!inline_value) {
          if (i + 1 >= argv.size()) ARPOS_INPUT_ERROR("option --" << key << " needs a value");
          value = argv[++i];
        }
        values_[key] = value;
      } else {
        ARPOS_INPUT_ERROR("unknown option --" << key << " (see --help)");
      }
    } else {
      positional_.push_back(arg);
    }
  }
}

std::optional<std::string> Args::Get(const std::string& option) const {
  const auto it = values_.find(option);
  if (it == values_.end()) return std::nullopt;
  return it->second;
}

std::string Args::GetOr(const std::string& option, const std::string& fallback) const {
  return Get(option).value_or(fallback);
}

std::string Args::Require(const std::string& option) const {
  const auto value = Get(option);
  if (!value) ARPOS_INPUT_ERROR("option --" << option << " is required (see --help)");
  return *value;
}

double Args::GetDouble(const std::string& option, double fallback) const {
  const auto value = Get(option);
  if (!value) return fallback;
  double v = 0;
  if (!ParseDouble(*value, &v)) ARPOS_INPUT_ERROR("option --" << option << ": '" << *value << "' is not a number");
  return v;
}

long long Args::GetInt(const std::string& option, long long fallback) const {
  const auto value = Get(option);
  if (!value) return fallback;
  long long v = 0;
  if (!ParseInt(*value, &v)) ARPOS_INPUT_ERROR("option --" << option << ": '" << *value << "' is not an integer");
  return v;
}

std::optional<int> UsageExit(const Args& args, const char* usage, size_t positionals) {
  if (args.Has("help")) {
    std::cout << usage;
    return 0;
  }
  if (args.positional().size() != positionals) {
    std::cerr << usage;
    return 2;
  }
  return std::nullopt;
}

namespace {
OperatorFlags& MutableOperatorFlags() {
  static OperatorFlags flags;
  return flags;
}
}  // namespace

void TakeOperatorFlags(std::vector<std::string>* argv) {
  std::vector<std::string> rest;
  for (size_t i = 0; i < argv->size(); ++i) {
    const std::string& a = (*argv)[i];
    std::string* target = nullptr;
    std::string name;
    for (const char* option : {"--user", "--role"}) {
      const std::string o(option);
      if (a == o || a.rfind(o + "=", 0) == 0) {
        target = o == "--user" ? &MutableOperatorFlags().user : &MutableOperatorFlags().role;
        name = o;
      }
    }
    if (!target) {
      rest.push_back(a);
      continue;
    }
    if (a.size() > name.size()) {
      *target = a.substr(name.size() + 1);
    } else {
      if (i + 1 >= argv->size()) ARPOS_INPUT_ERROR(name << " needs a value");
      *target = (*argv)[++i];
    }
    if (target->empty()) ARPOS_INPUT_ERROR(name << " needs a non-empty value");
  }
  *argv = std::move(rest);
}

const OperatorFlags& GivenOperatorFlags() { return MutableOperatorFlags(); }

}  // namespace arpos
