#include "exe/cmd_store.h"

#include <iostream>
#include <optional>

#include "store/describe.h"
#include "store/sqlite_database.h"
#include "store/store_path.h"
#include "util/check.h"
#include "util/string_util.h"

namespace arpos {
namespace {

constexpr const char* kUsage =
    "Usage: arpos store <command> [options]\n"
    "\n"
    "Commands:\n"
    "  info [--store DB]   Print a summary of the session store: schema version,\n"
    "                      rows per table, latest plans and sessions.\n"
    "\n"
    "Options:\n"
    "  --store DB          Store file. Default: $ARPOS_STORE if set, else\n"
    "                      ./arpos_store.db\n"
    "  -h, --help          Show this help.\n";

bool IsHelp(const std::string& arg) { return arg == "-h" || arg == "--help"; }

// The options of `arpos store info` and `arpos audit verify`: --store DB and
// --help. Returns the exit status when the command is done here (help, a
// usage error), nullopt to go on with *store_path.
std::optional<int> ParseStoreOption(const std::vector<std::string>& args, const char* command, const char* usage,
                                    std::string* store_path, std::ostream& out, std::ostream& err) {
  *store_path = DefaultStorePath();
  for (std::size_t i = 1; i < args.size(); ++i) {
    const std::string& arg = args[i];
    if (IsHelp(arg)) {
      out << usage;
      return 0;
    } else if (arg == "--store") {
      if (i + 1 >= args.size()) {
        err << command << ": --store needs a file name\n" << usage;
        return 2;
      }
      *store_path = args[++i];
    } else if (StartsWith(arg, "--store=")) {
      *store_path = arg.substr(std::string("--store=").size());
    } else {
      err << command << ": unknown argument '" << arg << "'\n" << usage;
      return 2;
    }
  }
  if (store_path->empty()) {
    err << command << ": the store path is empty\n";
    return 2;
  }
  return std::nullopt;
}

int RunInfo(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  std::string store_path;
  if (const auto done = ParseStoreOption(args, "arpos store info", kUsage, &store_path, out, err)) return *done;
  SqliteOpenOptions options;
  options.create_if_missing = false;  // `info` must not leave a new empty store behind
  const std::unique_ptr<SqliteDatabase> database = SqliteDatabase::Open(store_path, options);
  out << DescribeStore(*database);
  return 0;
}

constexpr const char* kAuditUsage =
    "Usage: arpos audit verify [--store DB]\n"
    "\n"
    "Checks that the audit log is intact: every entry's hash over its content and\n"
    "the entry before it, no entry removed from the end, the append-only triggers\n"
    "as the schema made them, and an audit entry for every patient, plan, room\n"
    "map, session, body marker map, reconstruction, alignment and tracking run.\n"
    "Names the first entry or row that does not match. Exit status: 0 verified,\n"
    "1 not verified, 2 usage or store error.\n"
    "\n"
    "Options:\n"
    "  --store DB          Store file. Default: $ARPOS_STORE if set, else\n"
    "                      ./arpos_store.db\n"
    "  -h, --help          Show this help.\n";

int RunAuditVerify(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  std::string store_path;
  if (const auto done = ParseStoreOption(args, "arpos audit verify", kAuditUsage, &store_path, out, err)) {
    return *done;
  }
  SqliteOpenOptions options;
  options.create_if_missing = false;  // verifying must not leave a new empty store behind
  const std::unique_ptr<SqliteDatabase> database = SqliteDatabase::Open(store_path, options);
  const AuditVerification v = database->VerifyAudit();
  out << "store: " << store_path << "\n" << v.ToText();
  return v.ok() ? 0 : 1;
}

}  // namespace

int RunAuditCommandWithOutput(const std::vector<std::string>& args, std::ostream& out,
                              std::ostream& err) {
  if (args.empty()) {
    err << "arpos audit: missing command\n" << kAuditUsage;
    return 2;
  }
  if (IsHelp(args[0])) {
    out << kAuditUsage;
    return 0;
  }
  if (args[0] != "verify") {
    err << "arpos audit: unknown command '" << args[0] << "'\n" << kAuditUsage;
    return 2;
  }
  try {
    return RunAuditVerify(args, out, err);
  } catch (const InputError& e) {
    err << "arpos audit verify: error: " << e.what() << "\n";
    return 2;
  } catch (const StoreAccessError& e) {
    err << "arpos audit verify: store error: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    err << "arpos audit verify: error: " << e.what() << "\n";
    return 2;
  }
}

int RunAuditCommand(const std::vector<std::string>& args) {
  return RunAuditCommandWithOutput(args, std::cout, std::cerr);
}

int RunStoreCommandWithOutput(const std::vector<std::string>& args, std::ostream& out,
                              std::ostream& err) {
  if (args.empty()) {
    err << "arpos store: missing command\n" << kUsage;
    return 2;
  }
  if (IsHelp(args[0])) {
    out << kUsage;
    return 0;
  }
  try {
    if (args[0] == "info") return RunInfo(args, out, err);
  } catch (const InputError& e) {
    err << "arpos store " << args[0] << ": error: " << e.what() << "\n";
    return 2;
  } catch (const StoreAccessError& e) {
    err << "arpos store " << args[0] << ": store error: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    err << "arpos store " << args[0] << ": error: " << e.what() << "\n";
    return 1;
  }
  err << "arpos store: unknown command '" << args[0] << "'\n" << kUsage;
  return 2;
}

int RunStoreCommand(const std::vector<std::string>& args) {
  return RunStoreCommandWithOutput(args, std::cout, std::cerr);
}

}  // namespace arpos
