#include "ui/correction_plot.h"

#include <QPainter>
#include <QPainterPath>
#include <algorithm>
#include <cmath>

namespace arpos::ui {

namespace {

const QColor kAxisColors[3] = {QColor(79, 195, 247), QColor(206, 147, 216), QColor(255, 238, 88)};
const char* kAxisNames[6] = {"lateral", "longitudinal", "vertical", "pitch", "roll", "yaw"};

// The smallest of 1, 1.5, 2, 3, 5, 7.5 x 10^k at or above `value`.
double NiceCeil(double value) {
  if (!(value > 0)) return 1;
  const double p = std::pow(10.0, std::floor(std::log10(value)));
  for (double m : {1.0, 1.5, 2.0, 3.0, 5.0, 7.5, 10.0}) {
    if (m * p >= value - 1e-12) return m * p;
  }
  return 10 * p;
}

}  // namespace

CorrectionPlot::CorrectionPlot(QWidget* parent) : QWidget(parent) {
  setMinimumHeight(170);
  setAttribute(Qt::WA_OpaquePaintEvent);
}

void CorrectionPlot::SetTolerances(const CouchTolerances& tolerances) {
  tolerances_ = tolerances;
  update();
}

void CorrectionPlot::SetWindow(double seconds) {
  window_s_ = std::max(1.0, seconds);
  update();
}

void CorrectionPlot::Clear() {
  samples_.clear();
  whole_run_ = false;
  update();
}

void CorrectionPlot::SetRun(const std::vector<std::pair<double, CouchCorrection>>& frames) {
  samples_.clear();
  whole_run_ = true;
  for (const auto& [t, c] : frames) {
    samples_.push_back({t,
                        {c.lateral_mm, c.longitudinal_mm, c.vertical_mm, c.pitch_deg, c.roll_deg, c.yaw_deg},
                        c.state,
                        {c.translation_mm, c.rotation_deg}});
  }
  const double t0 = samples_.empty() ? 0 : samples_.front().t;
  const double span = samples_.empty() ? 1 : samples_.back().t - t0;
  window_s_ = std::max(1.0, span / 0.98);
  update();
}

void CorrectionPlot::Add(double timestamp_s, const CouchCorrection& c) {
  if (whole_run_) Clear();
  // A replay that starts again (or a step back in time) starts a new plot.
  if (!samples_.empty() && timestamp_s < samples_.back().t) samples_.clear();
  samples_.push_back({timestamp_s,
                      {c.lateral_mm, c.longitudinal_mm, c.vertical_mm, c.pitch_deg, c.roll_deg, c.yaw_deg},
                      c.state});
  // Keep one sample older than the window so the lines reach its left edge.
  while (samples_.size() > 2 && samples_[1].t < timestamp_s - window_s_) samples_.pop_front();
  update();
}

void CorrectionPlot::paintEvent(QPaintEvent*) {
  QPainter painter(this);
  painter.setRenderHint(QPainter::Antialiasing);
  painter.fillRect(rect(), QColor(30, 33, 40));
  // A little room right of the newest frame so its points are not cut.
  const double t_end = whole_run_ ? (samples_.empty() ? 0 : samples_.front().t) + window_s_
                                  : (samples_.empty() ? 0 : samples_.back().t) + 0.02 * window_s_;
  const double gap = 8;
  const double half = (height() - gap - 18) / 2.0;  // 18 px of time labels at the bottom
  PaintPanel(&painter, QRectF(0, 0, width(), half), 0, tolerances_.translation_mm, "mm", t_end);
  PaintPanel(&painter, QRectF(0, half + gap, width(), half), 3, tolerances_.rotation_deg, "deg", t_end);
  // Time axis under both.
  const double left = 56, right = width() - 118;
  painter.setPen(QColor(150, 156, 168));
  QFont font = painter.font();
  font.setPixelSize(11);
  painter.setFont(font);
  if (whole_run_) {
    // Seconds since the run's first frame, at a step that gives ~8 labels.
    const double step = NiceCeil(window_s_ / 8);
    for (double s = 0; s <= 0.98 * window_s_ + 1e-9; s += step) {
      const double x = left + (right - left) * s / window_s_;
      painter.drawText(QRectF(x - 30, height() - 16, 60, 14), Qt::AlignCenter, tr("%1 s").arg(s, 0, 'g', 4));
    }
    if (samples_.empty()) {
      painter.drawText(rect(), Qt::AlignCenter, tr("this run stored no frames"));
    }
    return;
  }
  const int step = window_s_ > 12 ? 5 : 2;
  for (int s = 0; s <= static_cast<int>(0.98 * window_s_); s += step) {
    const double x = right - (right - left) * (s + 0.02 * window_s_) / window_s_;
    painter.drawText(QRectF(x - 30, height() - 16, 60, 14), Qt::AlignCenter,
                     s == 0 ? tr("now") : tr("\u2212%1 s").arg(s));
  }
  if (samples_.empty()) {
    painter.setPen(QColor(150, 156, 168));
    painter.drawText(rect(), Qt::AlignCenter, tr("the correction over the last %1 s appears here").arg(window_s_));
  }
}

void CorrectionPlot::PaintPanel(QPainter* painter, const QRectF& area, int first_axis, double tolerance,
                                const QString& unit, double t_end) const {
  const double left = 56, right = area.width() - 118;
  const QRectF plot(area.left() + left, area.top() + 4, right - left, area.height() - 8);
  const double t_begin = t_end - window_s_;
  // The three axes, and on whole runs the magnitude (shift length, angle).
  const int lines = whole_run_ ? 4 : 3;
  auto value = [first_axis](const Sample& s, int k) {
    return k < 3 ? s.values[first_axis + k] : s.magnitudes[first_axis / 3];
  };
  auto color_of = [](int k) { return k < 3 ? kAxisColors[k] : QColor(245, 245, 245); };
  double extent = 1.5 * tolerance;
  for (const Sample& s : samples_) {
    if (s.state == CorrectionState::kLost || s.t < t_begin) continue;
    for (int k = 0; k < lines; ++k) extent = std::max(extent, 1.1 * std::abs(value(s, k)));
  }
  extent = NiceCeil(extent);
  auto X = [&](double t) { return plot.left() + plot.width() * (t - t_begin) / window_s_; };
  auto Y = [&](double v) { return plot.center().y() - plot.height() / 2 * std::clamp(v / extent, -1.0, 1.0); };

  painter->save();
  painter->fillRect(plot, QColor(22, 24, 30));
  painter->setClipRect(plot);
  // Frames without a pose: red bands up to the next frame.
  for (size_t i = 0; i < samples_.size(); ++i) {
    if (samples_[i].state != CorrectionState::kLost) continue;
    const double t0 = samples_[i].t;
    const double t1 = i + 1 < samples_.size() ? samples_[i + 1].t : t0 + 0.1;
    const double x0 = X(t0), x1 = std::max(X(t1), x0 + 3);
    painter->fillRect(QRectF(x0, plot.top(), x1 - x0, plot.height()), QColor(198, 40, 40, 110));
  }
  // The tolerance band and its edges.
  painter->fillRect(QRectF(plot.left(), Y(tolerance), plot.width(), Y(-tolerance) - Y(tolerance)),
                    QColor(46, 125, 50, 55));
  QPen tol_pen(QColor(102, 187, 106), 1.2, Qt::DashLine);
  painter->setPen(tol_pen);
  painter->drawLine(QPointF(plot.left(), Y(tolerance)), QPointF(plot.right(), Y(tolerance)));
  painter->drawLine(QPointF(plot.left(), Y(-tolerance)), QPointF(plot.right(), Y(-tolerance)));
  painter->setPen(QPen(QColor(90, 96, 108), 1));
  painter->drawLine(QPointF(plot.left(), Y(0)), QPointF(plot.right(), Y(0)));
  // One line per axis, broken where a frame has no pose.
  for (int k = 0; k < lines; ++k) {
    const QColor color = color_of(k);
    painter->setPen(QPen(color, 2));
    QPainterPath path;
    bool open = false;
    for (const Sample& s : samples_) {
      if (s.state == CorrectionState::kLost) {
        open = false;
        continue;
      }
      const QPointF p(X(s.t), Y(value(s, k)));
      if (open) {
        path.lineTo(p);
      } else {
        path.moveTo(p);
        open = true;
      }
    }
    painter->drawPath(path);
    painter->setBrush(color);
    for (const Sample& s : samples_) {
      if (s.state != CorrectionState::kLost) painter->drawEllipse(QPointF(X(s.t), Y(value(s, k))), 2.5, 2.5);
    }
    painter->setBrush(Qt::NoBrush);
  }
  painter->restore();

  painter->save();
  painter->setPen(QColor(70, 76, 88));
  painter->drawRect(plot);
  QFont font = painter->font();
  font.setPixelSize(11);
  painter->setFont(font);
  painter->setPen(QColor(170, 176, 188));
  // Scale and tolerance labels at the left.
  auto label = [&](double v, const QColor& color) {
    painter->setPen(color);
    painter->drawText(QRectF(area.left(), Y(v) - 7, left - 6, 14), Qt::AlignRight | Qt::AlignVCenter,
                      QString::number(v, 'g', 3));
  };
  label(extent, QColor(170, 176, 188));
  label(-extent, QColor(170, 176, 188));
  // The tolerance labels where they do not run into each other or the scale's.
  if (tolerance < 0.8 * extent && Y(-tolerance) - Y(tolerance) > 14) {
    label(tolerance, QColor(102, 187, 106));
    label(-tolerance, QColor(102, 187, 106));
  }
  painter->setPen(QColor(170, 176, 188));
  painter->drawText(QRectF(area.left() + 2, area.top() + area.height() / 2 - 7, 24, 14), Qt::AlignLeft, unit);
  // Legend at the right.
  for (int k = 0; k < lines; ++k) {
    const double y = area.top() + 10 + k * 16;
    painter->setPen(QPen(color_of(k), 3));
    painter->drawLine(QPointF(right + 8, y), QPointF(right + 24, y));
    painter->setPen(QColor(200, 204, 214));
    painter->drawText(QRectF(right + 28, y - 7, 90, 14), Qt::AlignLeft | Qt::AlignVCenter,
                      k < 3 ? tr(kAxisNames[first_axis + k]) : (first_axis == 0 ? tr("|shift|") : tr("angle")));
  }
  painter->setPen(QPen(QColor(102, 187, 106), 1.2, Qt::DashLine));
  const double y = area.top() + 10 + lines * 16;
  painter->drawLine(QPointF(right + 8, y), QPointF(right + 24, y));
  painter->setPen(QColor(200, 204, 214));
  painter->drawText(QRectF(right + 28, y - 7, 90, 14), Qt::AlignLeft | Qt::AlignVCenter,
                    tr("\u00b1%1 %2").arg(tolerance, 0, 'g', 3).arg(unit));
  painter->restore();
}

}  // namespace arpos::ui
