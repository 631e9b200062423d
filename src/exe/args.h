#pragma once
/// Minimal command-line parsing for subcommands: positionals, `--flag`,
/// `--key value` and `--key=value`. Unknown options are an error that names
/// the option; every subcommand prints its usage on --help.

#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

namespace arpos {

class Args {
 public:
  /// `value_options`: options that take a value; `flag_options`: those that don't.
  /// Throws InputError for an unknown option or a missing value.
  Args(const std::vector<std::string>& argv, const std::set<std::string>& value_options,
       const std::set<std::string>& flag_options);

  const std::vector<std::string>& positional() const { return positional_; }
  bool Has(const std::string& option) const { return values_.count(option) > 0; }
  std::optional<std::string> Get(const std::string& option) const;
  std::string GetOr(const std::string& option, const std::string& fallback) const;
  /// Throws InputError naming the option if absent.
  std::string Require(const std::string& option) const;
  double GetDouble(const std::string& option, double fallback) const;
  long long GetInt(const std::string& option, long long fallback) const;

 private:
  std::vector<std::string> positional_;
  std::map<std::string, std::string> values_;
};

/// The usual start of a subcommand: with --help, prints `usage` to stdout and
/// returns 0; with other than `positionals` positional arguments, prints it
/// to stderr and returns 2; otherwise nullopt (carry on).
std::optional<int> UsageExit(const Args& args, const char* usage, size_t positionals);

/// Who runs the command: `--user NAME` and `--role ROLE`, accepted anywhere
/// on the command line; the executable removes them before the subcommand
/// parses its own options (store/roles.h ResolveOperator reads them, then
/// ARPOS_USER / ARPOS_ROLE). Empty when not given.
struct OperatorFlags {
  std::string user;
  std::string role;
};
/// Removes --user/--role (`--user NAME` or `--user=NAME`) from `argv` and
/// remembers them; throws InputError for a flag without a value.
void TakeOperatorFlags(std::vector<std::string>* argv);
const OperatorFlags& GivenOperatorFlags();

}  // namespace arpos
