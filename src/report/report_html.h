#pragma once
/// The session report as one HTML document (no Qt).
///
/// Every text from the store is escaped. Images are referenced either as
/// PNG `data:` URIs (a self-contained file for browsers) or by their names,
/// for a QTextDocument that holds them as resources (the PDF). The markup
/// stays within what Qt's rich text understands (tables with border and
/// cellpadding attributes, simple CSS), so the PDF shows the same document.

#include <string>
#include <vector>

#include "report/report_plots.h"
#include "report/session_report.h"

namespace arpos {

enum class ReportImageMode { kDataUri, kResourceName };

std::string RenderReportHtml(const SessionReport& report, const std::vector<ReportImage>& images,
                             ReportImageMode mode);

/// `text` with & < > " ' as character references.
std::string HtmlEscape(const std::string& text);

/// Standard base64 (RFC 4648, with padding).
std::string Base64Encode(const std::string& bytes);

}  // namespace arpos
