#pragma once
/// The report's plots, drawn with QPainter on a QImage and kept as PNG bytes
/// (the one place plots are drawn; the HTML embeds them as data: URIs, the
/// PDF registers them as document resources).
///
/// Per tracking run with frames, two images:
///   PlotName(i, "magnitude")  |translation| (mm) and rotation angle (deg) of
///                             the correction over time, the tolerance as a
///                             dashed line, frames in / out of tolerance as
///                             green / orange dots, lost frames as grey bars;
///   PlotName(i, "axes")       the correction per couch axis over time:
///                             lateral, longitudinal, vertical (mm) and pitch,
///                             roll, yaw (deg), broken at lost frames.
///
/// Needs a QGuiApplication (report_writer.h EnsureGuiApplication makes one).

#include <string>
#include <vector>

#include "report/session_report.h"

namespace arpos {

struct ReportImage {
  std::string name;   ///< e.g. "run1_magnitude.png"
  std::string title;  ///< caption
  std::string png;    ///< PNG file bytes
  int width = 0, height = 0;
};

/// "run<i+1>_<kind>.png" for run index i (0-based) of SessionReport::runs
/// (defined with the HTML renderer, which needs no Qt).
std::string PlotName(std::size_t run_index, const std::string& kind);

/// The plots of every run of `report` (runs with no frames have none).
std::vector<ReportImage> MakeReportPlots(const SessionReport& report);

}  // namespace arpos
