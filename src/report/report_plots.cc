#include "report/report_plots.h"

#include <QBuffer>
#include <QByteArray>
#include <QColor>
#include <QFont>
#include <QFontMetricsF>
#include <QImage>
#include <QPainter>
#include <QPainterPath>
#include <QPen>

#include <algorithm>
#include <cmath>
#include <limits>

namespace arpos {
namespace {

constexpr int kWidth = 1000;
constexpr int kPanelHeight = 270;

struct Series {
  QString name;
  QColor color;
  std::vector<double> y;  ///< one per frame; NaN: no value (breaks the line)
};

struct Panel {
  QString title;
  QString y_label;
  std::vector<Series> series;
  std::optional<double> tolerance;        ///< dashed red line
  bool status_dots = false;               ///< colour the first series' points by in/out
};

// Tick step of about `target` ticks over `span`: 1, 2 or 5 times a power of ten.
double NiceStep(double span, int target) {
  if (!(span > 0)) return 1.0;
  const double raw = span / target;
  const double power = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0, 10.0}) {
    if (m * power >= raw) return m * power;
  }
  return 10.0 * power;
}

QString TickText(double value, double step) {
  const int decimals = step >= 1 ? 0 : std::min(4, static_cast<int>(std::ceil(-std::log10(step))));
  if (std::abs(value) < step * 1e-6) value = 0;
  return QString::number(value, 'f', decimals);
}

void DrawPanel(QPainter& p, const QRectF& area, const Panel& panel, const std::vector<ReportFrame>& frames,
               double x_max, bool x_label) {
  const QFontMetricsF fm(p.font());
  const QRectF plot(area.left() + 78, area.top() + 30, area.width() - 78 - 190, area.height() - 30 - 44);

  // Y range: the data, 0 and the tolerance, with a margin.
  double lo = 0, hi = 0;
  for (const Series& s : panel.series) {
    for (double v : s.y) {
      if (std::isfinite(v)) {
        lo = std::min(lo, v);
        hi = std::max(hi, v);
      }
    }
  }
  if (panel.tolerance) hi = std::max(hi, *panel.tolerance);
  if (hi - lo < 1e-9) hi = lo + 1.0;
  const double pad = 0.08 * (hi - lo);
  if (lo < 0) lo -= pad;
  hi += pad;
  const double step = NiceStep(hi - lo, 5);
  lo = std::floor(lo / step) * step;
  hi = std::ceil(hi / step) * step;
  const double xs = x_max > 0 ? x_max : 1.0;
  // A margin on both sides, so that the first and last frames' dots show whole.
  const double x_lo = -0.02 * xs, x_hi = 1.02 * xs;
  auto X = [&](double t) { return plot.left() + plot.width() * (t - x_lo) / (x_hi - x_lo); };
  auto Y = [&](double v) { return plot.bottom() - plot.height() * (v - lo) / (hi - lo); };

  // Title and frame.
  QFont bold = p.font();
  bold.setBold(true);
  p.setFont(bold);
  p.setPen(Qt::black);
  p.drawText(QPointF(plot.left(), area.top() + 20), panel.title);
  QFont normal = bold;
  normal.setBold(false);
  p.setFont(normal);
  p.fillRect(plot, QColor(252, 252, 252));

  // Lost frames: grey bars over the whole height.
  // Lost frames: grey bars over the whole height, each from half-way to the
  // frame before to half-way to the frame after (at least 2 px wide).
  p.setPen(Qt::NoPen);
  for (std::size_t i = 0; i < frames.size(); ++i) {
    if (frames[i].status != TrackingFrameStatus::kLost) continue;
    const double t = frames[i].time_s;
    const double a = i > 0 ? (frames[i - 1].time_s + t) / 2 : t;
    const double b = i + 1 < frames.size() ? (t + frames[i + 1].time_s) / 2 : t;
    double left = X(a), right = X(b);
    if (right - left < 2) {
      left = X(t) - 1;
      right = X(t) + 1;
    }
    p.fillRect(QRectF(left, plot.top(), right - left, plot.height()), QColor(150, 150, 150, 90));
  }

  // Grid and ticks.
  p.setPen(QPen(QColor(220, 220, 220), 1));
  for (double v = lo; v <= hi + step * 1e-6; v += step) p.drawLine(QPointF(plot.left(), Y(v)), QPointF(plot.right(), Y(v)));
  const double x_step = NiceStep(xs, 8);
  for (double t = 0; t <= x_hi; t += x_step) p.drawLine(QPointF(X(t), plot.top()), QPointF(X(t), plot.bottom()));
  p.setPen(Qt::black);
  for (double v = lo; v <= hi + step * 1e-6; v += step) {
    const QString text = TickText(v, step);
    p.drawText(QPointF(plot.left() - 8 - fm.horizontalAdvance(text), Y(v) + fm.ascent() / 2 - 2), text);
  }
  for (double t = 0; t <= x_hi; t += x_step) {
    const QString text = TickText(t, x_step);
    p.drawText(QPointF(X(t) - fm.horizontalAdvance(text) / 2, plot.bottom() + fm.ascent() + 4), text);
  }
  if (x_label) {
    const QString text = QStringLiteral("time since the run's first frame (s)");
    p.drawText(QPointF(plot.center().x() - fm.horizontalAdvance(text) / 2, plot.bottom() + 2 * fm.height() + 4), text);
  }
  p.save();
  p.translate(area.left() + 16, plot.center().y());
  p.rotate(-90);
  p.drawText(QPointF(-fm.horizontalAdvance(panel.y_label) / 2, 0), panel.y_label);
  p.restore();
  p.setPen(QPen(Qt::black, 1));
  p.setBrush(Qt::NoBrush);
  p.drawRect(plot);

  // Tolerance.
  double legend_y = plot.top() + 6;
  auto legend = [&](const QColor& color, Qt::PenStyle style, const QString& text, bool box) {
    const double lx = plot.right() + 14;
    if (box) {
      p.fillRect(QRectF(lx, legend_y + 2, 22, 10), color);
    } else {
      p.setPen(QPen(color, 2.5, style));
      p.drawLine(QPointF(lx, legend_y + 7), QPointF(lx + 22, legend_y + 7));
    }
    p.setPen(Qt::black);
    p.drawText(QPointF(lx + 30, legend_y + 7 + fm.ascent() / 2 - 2), text);
    legend_y += fm.height() + 4;
  };
  p.setClipRect(plot);
  if (panel.tolerance) {
    p.setPen(QPen(QColor(200, 0, 0), 2, Qt::DashLine));
    p.drawLine(QPointF(plot.left(), Y(*panel.tolerance)), QPointF(plot.right(), Y(*panel.tolerance)));
  }
  // Series, broken where there is no value.
  for (const Series& s : panel.series) {
    QPainterPath path;
    bool open = false;
    for (std::size_t i = 0; i < frames.size() && i < s.y.size(); ++i) {
      if (!std::isfinite(s.y[i])) {
        open = false;
        continue;
      }
      const QPointF q(X(frames[i].time_s), Y(s.y[i]));
      if (open) path.lineTo(q);
      else path.moveTo(q);
      open = true;
    }
    p.setPen(QPen(s.color, 2));
    p.drawPath(path);
    if (!panel.status_dots) {  // small dots, so that a frame between lost ones shows
      p.setPen(Qt::NoPen);
      p.setBrush(s.color);
      for (std::size_t i = 0; i < frames.size() && i < s.y.size(); ++i) {
        if (std::isfinite(s.y[i])) p.drawEllipse(QPointF(X(frames[i].time_s), Y(s.y[i])), 3.0, 3.0);
      }
      p.setBrush(Qt::NoBrush);
    }
  }
  if (panel.status_dots && !panel.series.empty()) {
    const Series& s = panel.series.front();
    p.setPen(Qt::NoPen);
    for (std::size_t i = 0; i < frames.size() && i < s.y.size(); ++i) {
      if (!std::isfinite(s.y[i])) continue;
      p.setBrush(frames[i].status == TrackingFrameStatus::kInTolerance ? QColor(46, 125, 50) : QColor(239, 108, 0));
      p.drawEllipse(QPointF(X(frames[i].time_s), Y(s.y[i])), 4.5, 4.5);
    }
  }
  p.setClipping(false);
  p.setBrush(Qt::NoBrush);

  for (const Series& s : panel.series) legend(s.color, Qt::SolidLine, s.name, false);
  if (panel.tolerance) {
    legend(QColor(200, 0, 0), Qt::DashLine, QStringLiteral("tolerance %1 %2").arg(*panel.tolerance).arg(panel.y_label),
           false);
  }
  if (panel.status_dots) {
    legend(QColor(46, 125, 50), Qt::SolidLine, QStringLiteral("in tolerance"), true);
    legend(QColor(239, 108, 0), Qt::SolidLine, QStringLiteral("out of tolerance"), true);
  }
  legend(QColor(150, 150, 150, 140), Qt::SolidLine, QStringLiteral("lost frame"), true);
}

ReportImage Render(const std::string& name, const std::string& title, const std::vector<Panel>& panels,
                   const std::vector<ReportFrame>& frames, double x_max) {
  const int height = kPanelHeight * static_cast<int>(panels.size()) + 10;
  QImage image(kWidth, height, QImage::Format_RGB32);
  image.fill(Qt::white);
  {
    QPainter p(&image);
    p.setRenderHint(QPainter::Antialiasing);
    p.setRenderHint(QPainter::TextAntialiasing);
    QFont font(QStringLiteral("DejaVu Sans"));
    font.setPixelSize(15);
    p.setFont(font);
    for (std::size_t i = 0; i < panels.size(); ++i) {
      const QRectF area(0, 5 + kPanelHeight * static_cast<double>(i), kWidth, kPanelHeight);
      DrawPanel(p, area, panels[i], frames, x_max, true);
    }
  }
  QByteArray bytes;
  QBuffer buffer(&bytes);
  buffer.open(QIODevice::WriteOnly);
  image.save(&buffer, "PNG");
  ReportImage out;
  out.name = name;
  out.title = title;
  out.png.assign(bytes.constData(), static_cast<std::size_t>(bytes.size()));
  out.width = image.width();
  out.height = image.height();
  return out;
}

Series Component(const std::vector<ReportFrame>& frames, const QString& name, const QColor& color, bool rotation,
                 int axis) {
  Series s{name, color, {}};
  for (const ReportFrame& f : frames) {
    if (!f.correction) {
      s.y.push_back(std::numeric_limits<double>::quiet_NaN());
      continue;
    }
    const Eigen::Vector3d& v = rotation ? f.correction->rotation_deg : f.correction->translation_mm;
    s.y.push_back(axis < 0 ? v.norm() : v[axis]);
  }
  return s;
}

}  // namespace

std::vector<ReportImage> MakeReportPlots(const SessionReport& report) {
  std::vector<ReportImage> images;
  const QColor c1(198, 40, 40), c2(46, 125, 50), c3(21, 101, 192), magnitude(33, 33, 120);
  for (std::size_t i = 0; i < report.runs.size(); ++i) {
    const ReportRun& run = report.runs[i];
    if (run.frames.empty()) continue;
    const double x_max = run.frames.back().time_s;
    Panel mm{QStringLiteral("Correction: translation |t|"), QStringLiteral("mm"),
             {Component(run.frames, QStringLiteral("|t| (mm)"), magnitude, false, -1)},
             run.run.tolerance_translation_mm, true};
    Panel deg{QStringLiteral("Correction: rotation angle"), QStringLiteral("deg"),
              {Component(run.frames, QStringLiteral("angle (deg)"), magnitude, true, -1)},
              run.run.tolerance_rotation_deg, true};
    images.push_back(Render(PlotName(i, "magnitude"), "Correction magnitude over time, " + run.name, {mm, deg},
                            run.frames, x_max));
    Panel axes_t{QStringLiteral("Correction per couch axis: translation"), QStringLiteral("mm"),
                 {Component(run.frames, QStringLiteral("lateral"), c1, false, 0),
                  Component(run.frames, QStringLiteral("longitudinal"), c2, false, 1),
                  Component(run.frames, QStringLiteral("vertical"), c3, false, 2)},
                 std::nullopt, false};
    Panel axes_r{QStringLiteral("Correction per couch axis: rotation"), QStringLiteral("deg"),
                 {Component(run.frames, QStringLiteral("pitch"), c1, true, 0),
                  Component(run.frames, QStringLiteral("roll"), c2, true, 1),
                  Component(run.frames, QStringLiteral("yaw"), c3, true, 2)},
                 std::nullopt, false};
    images.push_back(Render(PlotName(i, "axes"), "Correction per couch axis over time, " + run.name,
                            {axes_t, axes_r}, run.frames, x_max));
  }
  return images;
}

}  // namespace arpos
