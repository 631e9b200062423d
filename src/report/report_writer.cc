#include "report/report_writer.h"

#include <unistd.h>

#include <QBuffer>
#include <QByteArray>
#include <QCoreApplication>
#include <QtGlobal>
#include <QFont>
#include <QGuiApplication>
#include <QImage>
#include <QMarginsF>
#include <QPageLayout>
#include <QPageSize>
#include <QPdfWriter>
#include <QTextDocument>
#include <QUrl>

#include <algorithm>
#include <cctype>
#include <filesystem>

#include "report/report_html.h"
#include "report/report_plots.h"
#include "util/check.h"
#include "util/file.h"

namespace arpos {

namespace fs = std::filesystem;

std::optional<ReportFormat> ReportFormatForPath(const std::string& path) {
  std::string ext = fs::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  if (ext == ".html") return ReportFormat::kHtml;
  if (ext == ".pdf") return ReportFormat::kPdf;
  return std::nullopt;
}

void CheckReportOutputWritable(const std::string& path) {
  const fs::path file(path);
  if (file.filename().empty()) ARPOS_INPUT_ERROR("cannot write the report to " << path << ": it names no file");
  fs::path folder = file.parent_path();
  if (folder.empty()) folder = ".";
  std::error_code ec;
  if (!fs::exists(folder, ec)) {
    ARPOS_INPUT_ERROR("cannot write the report to " << path << ": the folder " << folder.string()
                                                    << " does not exist");
  }
  if (!fs::is_directory(folder, ec)) {
    ARPOS_INPUT_ERROR("cannot write the report to " << path << ": " << folder.string() << " is not a folder");
  }
  if (::access(folder.c_str(), W_OK | X_OK) != 0) {
    ARPOS_INPUT_ERROR("cannot write the report to " << path << ": the folder " << folder.string()
                                                    << " is not writable");
  }
  if (fs::exists(file, ec)) {
    if (fs::is_directory(file, ec)) ARPOS_INPUT_ERROR("cannot write the report to " << path << ": it is a folder");
    if (::access(file.c_str(), W_OK) != 0) {
      ARPOS_INPUT_ERROR("cannot write the report to " << path << ": the file is not writable");
    }
  }
}

namespace {

QtMessageHandler previous_handler = nullptr;

// Drops Qt's note that XDG_RUNTIME_DIR is not set (the offscreen platform
// does not need it); passes everything else on.
void ReportMessageHandler(QtMsgType type, const QMessageLogContext& context, const QString& message) {
  if (message.startsWith(QLatin1String("QStandardPaths: XDG_RUNTIME_DIR not set"))) return;
  if (previous_handler != nullptr) previous_handler(type, context, message);
}

}  // namespace

void EnsureGuiApplication() {
  if (QCoreApplication* app = QCoreApplication::instance()) {
    ARPOS_CHECK(qobject_cast<QGuiApplication*>(app) != nullptr,
                "the report needs a QGuiApplication, and this program runs a QCoreApplication");
    return;
  }
  // No display is needed to draw plots and lay out a PDF.
  qputenv("QT_QPA_PLATFORM", "offscreen");
  previous_handler = qInstallMessageHandler(ReportMessageHandler);
  static int argc = 1;
  static char name[] = "arpos";
  static char* argv[] = {name, nullptr};
  // Kept for the life of the process: destroying it at exit is not needed.
  static QGuiApplication* app = new QGuiApplication(argc, argv);
  (void)app;
}

std::string RenderReportHtmlFile(const SessionReport& report) {
  EnsureGuiApplication();
  return RenderReportHtml(report, MakeReportPlots(report), ReportImageMode::kDataUri);
}

std::string RenderReportPdf(const SessionReport& report) {
  EnsureGuiApplication();
  const std::vector<ReportImage> images = MakeReportPlots(report);
  QTextDocument document;
  QFont font(QStringLiteral("DejaVu Sans"));
  font.setPointSizeF(9);
  document.setDefaultFont(font);
  for (const ReportImage& image : images) {
    QImage decoded;
    decoded.loadFromData(reinterpret_cast<const uchar*>(image.png.data()), static_cast<int>(image.png.size()), "PNG");
    document.addResource(QTextDocument::ImageResource, QUrl(QString::fromStdString(image.name)), decoded);
  }
  document.setHtml(QString::fromStdString(RenderReportHtml(report, images, ReportImageMode::kResourceName)));

  QByteArray bytes;
  QBuffer buffer(&bytes);
  buffer.open(QIODevice::WriteOnly);
  {
    QPdfWriter writer(&buffer);
    writer.setPageSize(QPageSize(QPageSize::A4));
    writer.setPageOrientation(QPageLayout::Portrait);
    // No printer margins: QTextDocument::print lays the text out with 2 cm
    // margins and numbers the pages.
    writer.setPageMargins(QMarginsF(0, 0, 0, 0), QPageLayout::Millimeter);
    writer.setResolution(300);
    writer.setTitle(QString::fromStdString(report.title + ", session " + std::to_string(report.session.id.value())));
    writer.setCreator(QString::fromStdString("arpos " + report.program_version));
    document.print(&writer);
  }
  buffer.close();
  return std::string(bytes.constData(), static_cast<std::size_t>(bytes.size()));
}

void WriteSessionReport(const SessionReport& report, ReportFormat format, const std::string& path) {
  const std::string bytes = format == ReportFormat::kPdf ? RenderReportPdf(report) : RenderReportHtmlFile(report);
  WriteFileAtomic(path, bytes);
}

}  // namespace arpos
