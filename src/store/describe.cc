#include "store/describe.h"

#include <algorithm>
#include <ctime>
#include <iomanip>
#include <sstream>

namespace arpos {

std::string FormatUtcTime(std::int64_t unix_ms) {
  // Floor division, so times before 1970 still format correctly.
  std::int64_t seconds = unix_ms / 1000;
  if (unix_ms % 1000 < 0) --seconds;
  const std::time_t time = static_cast<std::time_t>(seconds);
  std::tm utc{};
  if (gmtime_r(&time, &utc) == nullptr) return std::to_string(unix_ms) + " ms";
  char text[64];
  std::strftime(text, sizeof text, "%Y-%m-%d %H:%M:%S UTC", &utc);
  return text;
}

std::string DescribeStore(Database& database, std::size_t max_listed) {
  const StoreInfo info = database.Info();
  std::ostringstream out;
  out << "Store:          " << info.path << "\n";
  out << "Schema version: " << info.schema_version;
  if (info.schema_version == info.program_schema_version) {
    out << " (current)\n";
  } else {
    out << " (this program: " << info.program_schema_version << ")\n";
  }
  out << "Journal mode:   " << info.journal_mode << "\n";
  out << "Size:           " << info.size_bytes << " bytes\n";

  std::size_t width = 0;
  for (const auto& [table, count] : info.table_row_counts) width = std::max(width, table.size());
  out << "Rows per table:\n";
  for (const auto& [table, count] : info.table_row_counts) {
    out << "  " << std::left << std::setw(static_cast<int>(width)) << table << "  " << std::right
        << count << "\n";
  }

  const std::vector<PlanSummary> plans = database.ListPlans(std::nullopt, max_listed);
  out << "Latest plans:" << (plans.empty() ? " none" : "") << "\n";
  for (const PlanSummary& plan : plans) {
    out << "  plan " << plan.id.value() << "  '" << plan.name << "'  patient "
        << plan.patient_external_id << "  created " << FormatUtcTime(plan.created_unix_ms)
        << "  sessions " << plan.num_sessions << "  room maps " << plan.num_room_maps << "  "
        << (plan.approved() ? "approved by " + plan.approved_by + " " + FormatUtcTime(*plan.approved_unix_ms)
                            : std::string("not approved"))
        << "\n";
  }
  const std::vector<SessionRecord> sessions = database.ListSessions(std::nullopt, max_listed);
  out << "Latest sessions:" << (sessions.empty() ? " none" : "") << "\n";
  for (const SessionRecord& session : sessions) {
    out << "  session " << session.id.value() << "  plan " << session.plan_id.value()
        << "  fraction " << session.fraction << "  " << ToString(session.status) << "  started "
        << FormatUtcTime(session.started_unix_ms);
    if (session.ended_unix_ms) out << "  ended " << FormatUtcTime(*session.ended_unix_ms);
    if (!session.operator_name.empty()) out << "  operator " << session.operator_name;
    if (!session.ended_by.empty()) out << "  ended by " << session.ended_by;
    if (!session.end_reason.empty()) out << " (" << session.end_reason << ")";
    if (session.on_unapproved_plan) out << "  on a plan not approved";
    out << "\n";
  }
  return out.str();
}

}  // namespace arpos
