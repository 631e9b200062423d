#pragma once
/// Writes the session report (session_report.h) as a self-contained HTML file
/// or an A4 PDF. Used by `arpos report` and by the GUI's audit page.
///
/// The PDF is the same HTML laid out by Qt (QTextDocument, plots as
/// resources) and printed with QPdfWriter: QtGui only. Both need a
/// QGuiApplication for fonts and images; EnsureGuiApplication makes one on the
/// "offscreen" platform if the process has none, so no display is needed.

#include <optional>
#include <string>

#include "report/session_report.h"

namespace arpos {

enum class ReportFormat { kHtml, kPdf };

/// By the file's extension, ".html" or ".pdf" (any case); nullopt otherwise.
std::optional<ReportFormat> ReportFormatForPath(const std::string& path);

/// Throws InputError naming the file if it cannot be written: its folder is
/// missing, not a folder or not writable, or the path is a folder or a
/// read-only file. Writes nothing.
void CheckReportOutputWritable(const std::string& path);

/// Creates a QGuiApplication (platform "offscreen") if there is no Qt
/// application yet; throws if the existing one is a QCoreApplication only.
void EnsureGuiApplication();

/// The document's bytes.
std::string RenderReportHtmlFile(const SessionReport& report);
std::string RenderReportPdf(const SessionReport& report);

/// Renders and writes `path` atomically (temporary file, then rename).
void WriteSessionReport(const SessionReport& report, ReportFormat format, const std::string& path);

}  // namespace arpos
