// `arpos report` through the real executable: HTML with the session's figures
// and embedded plots, a tampered store's report saying the log does not
// verify, the PDF, escaping, and the usage and input errors.
#include <gtest/gtest.h>
#include <sqlite3.h>

#include <cstdlib>
#include <filesystem>
#include <regex>

#include "cli/cli_util.h"
#include "report/report_test_util.h"
#include "store/sqlite_database.h"
#include "util/file.h"

namespace arpos {
namespace {

namespace fs = std::filesystem;
using testing::RunArpos;

void RawExec(const fs::path& path, const std::string& sql) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  char* error = nullptr;
  const int rc = sqlite3_exec(db, sql.c_str(), nullptr, nullptr, &error);
  const std::string message = error != nullptr ? error : "";
  sqlite3_free(error);
  sqlite3_close(db);
  ASSERT_EQ(rc, SQLITE_OK) << message << " in " << sql;
}

std::size_t Count(const std::string& text, const std::string& what) {
  std::size_t n = 0;
  for (std::size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

// With ARPOS_REPORT_TEST_KEEP=DIR set, the reports are also copied there, to
// look at.
void Keep(const fs::path& file) {
  if (const char* dir = std::getenv("ARPOS_REPORT_TEST_KEEP")) {
    fs::copy_file(file, fs::path(dir) / file.filename(), fs::copy_options::overwrite_existing);
  }
}

struct Store {
  TempDir dir{"arpos_report_cli"};
  fs::path path = dir.path() / "store.db";
  test::ReportStoreIds ids;
  explicit Store(const test::ReportStoreOptions& options = {}) {
    const auto db = SqliteDatabase::Open(path.string());
    ids = test::WriteReportStore(*db, options);
  }
  std::string Report(const std::string& out) const {
    return "report " + std::to_string(ids.session.value()) + " --store " + path.string() + " --out " + out;
  }
};

TEST(ReportCli, HtmlHoldsTheSessionPlotsAndAVerifiedLog) {
  test::ReportStoreOptions options;
  options.patient_name = "<b>Doe</b> & 'Roe'";
  Store s(options);
  const fs::path out = s.dir.path() / "report.html";
  const testing::CliResult r = RunArpos(s.Report(out.string()));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("written to " + out.string()), std::string::npos) << r.output;
  Keep(out);
  const std::string html = ReadTextFile(out);
  EXPECT_EQ(html.rfind("<!DOCTYPE html>", 0), 0u);
  EXPECT_NE(html.find("P-REPORT-7"), std::string::npos);
  EXPECT_NE(html.find("Pelvis plan A"), std::string::npos);
  EXPECT_NE(html.find("seq_00"), std::string::npos);
  EXPECT_NE(html.find("seq_01"), std::string::npos);
  EXPECT_EQ(html.find("other_seq"), std::string::npos) << "another session's run";
  // Two plots per run, PNGs (base64 of the PNG signature) inside the file.
  EXPECT_EQ(Count(html, "src=\"data:image/png;base64,iVBORw0KGgo"), 4u);
  EXPECT_EQ(Count(html, "<img"), 4u);
  EXPECT_NE(html.find("Audit log verifies: "), std::string::npos);
  EXPECT_EQ(html.find("does not verify"), std::string::npos);
  // Escaped name; no markup from the store.
  EXPECT_NE(html.find("&lt;b&gt;Doe&lt;/b&gt; &amp; &#39;Roe&#39;"), std::string::npos);
  EXPECT_EQ(html.find("<b>Doe"), std::string::npos);
  // The figures a physicist reads.
  EXPECT_NE(html.find("12 (60.0 %)"), std::string::npos) << "in tolerance frames of seq_00";
  EXPECT_NE(html.find("1.10 s of 1.90 s"), std::string::npos) << "time in tolerance of seq_00";
  EXPECT_NE(html.find("mean 19.5 ms, p95 28.0 ms"), std::string::npos);
  EXPECT_NE(html.find("Signature"), std::string::npos);
}

TEST(ReportCli, TamperedStoreDoesNotVerify) {
  Store s;
  // A forged entry in the middle of the log (the trigger dropped to allow it).
  const fs::path forged = s.dir.path() / "forged.db";
  fs::copy_file(s.path, forged);
  RawExec(forged, "DROP TRIGGER audit_log_refuse_update; UPDATE audit_log SET details = 'forged' WHERE audit_id = 3");
  const fs::path out = s.dir.path() / "forged.html";
  const testing::CliResult r = RunArpos("report " + std::to_string(s.ids.session.value()) + " --store " +
                                        forged.string() + " --out " + out.string());
  ASSERT_EQ(r.status, 0) << r.output;
  const std::string html = ReadTextFile(out);
  EXPECT_NE(html.find("Audit log does not verify"), std::string::npos);
  EXPECT_EQ(html.find("Audit log verifies"), std::string::npos);
  const std::size_t marked = html.find("<tr class=\"bad\"");
  ASSERT_NE(marked, std::string::npos) << "the forged entry's row is marked";
  EXPECT_EQ(html.find("<tr class=\"bad\"", marked + 1), std::string::npos) << "one row only";
  EXPECT_EQ(html.find("<td class=\"num\" align=\"right\">3</td>", marked), html.find("<td", marked));
  EXPECT_NE(html.find("<b>This entry does not verify.</b><br>forged", marked), std::string::npos);
  EXPECT_NE(r.output.find("does not verify"), std::string::npos) << r.output;

  // Only a trigger dropped: the chain is intact, the log still does not verify.
  const fs::path dropped = s.dir.path() / "dropped.db";
  fs::copy_file(s.path, dropped);
  RawExec(dropped, "DROP TRIGGER audit_log_refuse_delete");
  const fs::path out2 = s.dir.path() / "dropped.html";
  ASSERT_EQ(RunArpos("report " + std::to_string(s.ids.session.value()) + " --store " + dropped.string() +
                     " --out " + out2.string())
                .status,
            0);
  EXPECT_NE(ReadTextFile(out2).find("Audit log does not verify"), std::string::npos);
}

TEST(ReportCli, PdfHasPages) {
  Store s;
  const fs::path out = s.dir.path() / "report.pdf";
  const testing::CliResult r = RunArpos(s.Report(out.string()));
  ASSERT_EQ(r.status, 0) << r.output;
  Keep(out);
  const std::string pdf = ReadTextFile(out);
  EXPECT_EQ(pdf.rfind("%PDF-", 0), 0u);
  const std::size_t pages = Count(pdf, "/Type /Page") - Count(pdf, "/Type /Pages");
  EXPECT_GE(pages, 2u) << "the report with two runs and their plots takes more than a page";
  EXPECT_LE(pages, 20u);
  EXPECT_GE(Count(pdf, "/Subtype /Image"), 4u) << "the plots";
}

TEST(ReportCli, SessionWithoutTrackingRunsStillReports) {
  test::ReportStoreOptions options;
  options.num_runs = 0;
  Store s(options);
  const fs::path out = s.dir.path() / "report.html";
  const testing::CliResult r = RunArpos(s.Report(out.string()));
  ASSERT_EQ(r.status, 0) << r.output;
  const std::string html = ReadTextFile(out);
  EXPECT_NE(html.find("No tracking runs in this session."), std::string::npos);
  EXPECT_EQ(html.find("<img"), std::string::npos);
}

TEST(ReportCli, UsageAndInputErrors) {
  Store s;
  const fs::path out = s.dir.path() / "r.html";
  // Unknown session: exit 2, named with the store; nothing written.
  testing::CliResult r = RunArpos("report 999 --store " + s.path.string() + " --out " + out.string());
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("session 999 is not in the store " + s.path.string()), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(out));
  // Wrong extension, missing --out, bad id, unknown option: usage errors.
  r = RunArpos(s.Report((s.dir.path() / "r.txt").string()));
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("must end in .html or .pdf"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(s.dir.path() / "r.txt"));
  EXPECT_EQ(RunArpos("report 1 --store " + s.path.string()).status, 2);
  EXPECT_EQ(RunArpos("report abc --store " + s.path.string() + " --out " + out.string()).status, 2);
  EXPECT_EQ(RunArpos("report 0 --store " + s.path.string() + " --out " + out.string()).status, 2);
  EXPECT_EQ(RunArpos("report --store " + s.path.string() + " --out " + out.string()).status, 2);
  EXPECT_EQ(RunArpos(s.Report(out.string()) + " --bogus").status, 2);
  EXPECT_FALSE(fs::exists(out));
  // An output that cannot be written is refused before the store is opened.
  const fs::path missing_store = s.dir.path() / "missing.db";
  r = RunArpos("report 1 --store " + missing_store.string() + " --out " + (s.dir.path() / "no/such/r.pdf").string());
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("does not exist"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(missing_store));
  r = RunArpos(s.Report((s.path / "r.html").string()));  // the "folder" is the store file
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("is not a folder"), std::string::npos) << r.output;
  r = RunArpos(s.Report(s.dir.path().string() + "/.pdf/"));
  EXPECT_EQ(r.status, 2) << r.output;
  // No store at the path: exit 2, no store created.
  r = RunArpos("report 1 --store " + missing_store.string() + " --out " + out.string());
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_FALSE(fs::exists(missing_store));
  EXPECT_FALSE(fs::exists(out));
  // Help.
  r = RunArpos("report --help");
  EXPECT_EQ(r.status, 0);
  EXPECT_NE(r.output.find("Usage: arpos report SESSION_ID"), std::string::npos);
  EXPECT_NE(RunArpos("--help").output.find("  report"), std::string::npos);
}

// The report of a store the real pipeline wrote (the committed sample case).
TEST(ReportCli, ReportOfARunCaseStore) {
  TempDir dir("arpos_report_case");
  const std::string store = (dir.path() / "store.db").string();
  const testing::CliResult run =
      RunArpos("run-case " + std::string(ARPOS_SAMPLE_SESSIONS_DIR) + "/demo_xtion --store " + store);
  ASSERT_EQ(run.status, 0) << run.output;
  const fs::path out = dir.path() / "report.html";
  const testing::CliResult r = RunArpos("report 1 --store " + store + " --out " + out.string());
  ASSERT_EQ(r.status, 0) << r.output;
  const std::string html = ReadTextFile(out);
  EXPECT_NE(html.find("seq_00"), std::string::npos);
  EXPECT_NE(html.find("Audit log verifies: "), std::string::npos);
  EXPECT_GE(Count(html, "data:image/png;base64,"), 2u);
  EXPECT_NE(html.find("open_session"), std::string::npos);
  EXPECT_NE(html.find("add_plan"), std::string::npos);
}

}  // namespace
}  // namespace arpos
