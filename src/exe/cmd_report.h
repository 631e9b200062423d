#pragma once
/// `arpos report`: the session report a medical physicist signs
/// (src/report): patient, plan, session, body scan, alignments, tracking runs
/// with plots, the session's audit trail, the audit log's verification and a
/// signature block, as one self-contained HTML file or an A4 PDF.
///
///   arpos report SESSION_ID [--store DB] --out FILE.html|FILE.pdf
///
/// Exit status: 0 written (also when the audit log does not verify: the
/// report's verification line says so); 2 usage or input error (no such session, an
/// output that is neither .html nor .pdf or cannot be written, no store at
/// DB); 1 if the report could not be made. The output is checked before any
/// work and written atomically: on an error nothing is written.

#include <ostream>
#include <string>
#include <vector>

namespace arpos {

int RunReportCommand(const std::vector<std::string>& args);
int RunReportCommandWithOutput(const std::vector<std::string>& args, std::ostream& out, std::ostream& err);

}  // namespace arpos
