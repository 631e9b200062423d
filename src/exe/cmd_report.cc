#include "exe/cmd_report.h"

#include <filesystem>
#include <iostream>
#include <memory>

#include "exe/args.h"
#include "report/report_writer.h"
#include "report/session_report.h"
#include "store/sqlite_database.h"
#include "store/store_path.h"
#include "util/check.h"

namespace arpos {
namespace {

namespace fs = std::filesystem;

constexpr const char* kUsage =
    "Usage: arpos report SESSION_ID [--store DB] --out FILE.html|FILE.pdf\n"
    "\n"
    "Writes the session report a medical physicist signs: patient, plan (planned\n"
    "pose), session, body marker map, reconstructions, alignments, every tracking\n"
    "run (frames tracked/carried/lost, time in tolerance, corrections per couch\n"
    "axis, latency, plots of the correction over time), the session's audit trail,\n"
    "the audit log's verification and a signature block. .html: one\n"
    "self-contained file (plots embedded); .pdf: A4 pages. Needs no display.\n"
    "\n"
    "Options:\n"
    "  --store DB          Store file. Default: $ARPOS_STORE if set, else\n"
    "                      ./arpos_store.db\n"
    "  --out FILE          The report, ending in .html or .pdf.\n"
    "  -h, --help          Show this help.\n"
    "\n"
    "Exit status: 0 written (also when the audit log does not verify: the report\n"
    "says so in red, and so does the last line printed), 2 usage or input error\n"
    "(unknown session, bad output name or folder, no store), 1 the report could\n"
    "not be made.\n";

// SESSION_ID as a positive integer, or nullopt.
std::optional<std::int64_t> ParseId(const std::string& text) {
  if (text.empty() || text.size() > 18) return std::nullopt;
  std::int64_t value = 0;
  for (char c : text) {
    if (c < '0' || c > '9') return std::nullopt;
    value = value * 10 + (c - '0');
  }
  if (value <= 0) return std::nullopt;
  return value;
}

int Run(const std::vector<std::string>& argv, std::ostream& out, std::ostream& err) {
  for (const std::string& arg : argv) {
    if (arg == "-h" || arg == "--help") {
      out << kUsage;
      return 0;
    }
  }
  const Args args(argv, {"store", "out"}, {});
  if (args.positional().size() != 1) {
    err << "arpos report: expected one SESSION_ID\n" << kUsage;
    return 2;
  }
  const std::optional<std::int64_t> id = ParseId(args.positional()[0]);
  if (!id) {
    err << "arpos report: the session id '" << args.positional()[0] << "' is not a positive whole number\n";
    return 2;
  }
  const std::optional<std::string> out_path = args.Get("out");
  if (!out_path || out_path->empty()) {
    err << "arpos report: --out FILE.html or --out FILE.pdf is required\n" << kUsage;
    return 2;
  }
  const std::optional<ReportFormat> format = ReportFormatForPath(*out_path);
  if (!format) {
    err << "arpos report: the output '" << *out_path << "' must end in .html or .pdf\n" << kUsage;
    return 2;
  }
  const std::string store_path = args.GetOr("store", DefaultStorePath());
  if (store_path.empty()) {
    err << "arpos report: the store path is empty\n";
    return 2;
  }
  CheckReportOutputWritable(*out_path);  // before any work

  SqliteOpenOptions options;
  options.create_if_missing = false;  // a report must not leave a new empty store behind
  const std::unique_ptr<SqliteDatabase> database = SqliteDatabase::Open(store_path, options);
  // The report names the store by its absolute path: it outlives the working directory.
  std::error_code ec;
  const fs::path absolute = fs::absolute(store_path, ec);
  const SessionReport report =
      GatherSessionReport(database.get(), SessionId(*id), ec ? store_path : absolute.lexically_normal().string());
  WriteSessionReport(report, *format, *out_path);
  out << "report of session " << *id << " written to " << *out_path << " (" << report.runs.size()
      << " tracking run" << (report.runs.size() == 1 ? "" : "s") << ", " << report.audit.size()
      << " audit entries)\n"
      << report.verification_line << "\n";
  return 0;
}

}  // namespace

int RunReportCommandWithOutput(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  try {
    return Run(args, out, err);
  } catch (const InputError& e) {
    err << "arpos report: error: " << e.what() << "\n";
    return 2;
  } catch (const StoreAccessError& e) {
    err << "arpos report: store error: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    err << "arpos report: error: " << e.what() << "\n";
    return 1;
  }
}

int RunReportCommand(const std::vector<std::string>& args) { return RunReportCommandWithOutput(args, std::cout, std::cerr); }

}  // namespace arpos
