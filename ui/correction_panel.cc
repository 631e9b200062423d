#include "ui/correction_panel.h"

#include <QGridLayout>
#include <QLabel>
#include <QVBoxLayout>
#include <cmath>

namespace arpos::ui {

namespace {

const char* kAxisNames[6] = {"Lateral", "Longitudinal", "Vertical", "Pitch", "Roll", "Yaw"};

// Value text colour by state, readable on the panel's dark background.
QString ValueColor(CorrectionState state) {
  switch (state) {
    case CorrectionState::kIn: return "#5fd35f";
    case CorrectionState::kOut: return "#ffb300";
    case CorrectionState::kLost: break;
  }
  return "#7a7f8a";
}

// A number as shown: rounded to `decimals`, signed, no "-0.0".
QString Signed(double value, int decimals) {
  const double scale = std::pow(10.0, decimals);
  double rounded = std::round(value * scale) / scale;
  if (rounded == 0) rounded = 0;  // drops the sign of -0
  return (rounded > 0 ? "+" : rounded < 0 ? "\u2212" : "\u2009") + QString::number(std::abs(rounded), 'f', decimals);
}

}  // namespace

QColor CorrectionPanel::StateColor(CorrectionState state) {
  switch (state) {
    case CorrectionState::kIn: return QColor(46, 125, 50);
    case CorrectionState::kOut: return QColor(240, 160, 0);
    case CorrectionState::kLost: break;
  }
  return QColor(198, 40, 40);
}

CorrectionPanel::CorrectionPanel(QWidget* parent) : QWidget(parent) {
  setObjectName("correctionPanel");
  setAttribute(Qt::WA_StyledBackground);
  setStyleSheet("#correctionPanel { background: #1e2128; } QLabel { color: #d8dce4; }");
  setMinimumWidth(340);
  banner_ = new QLabel(this);
  banner_->setAlignment(Qt::AlignCenter);
  banner_->setMinimumHeight(64);
  reason_ = new QLabel(this);
  reason_->setWordWrap(true);
  reason_->setStyleSheet("color: #ff8a80; font-size: 13px;");
  auto* grid = new QGridLayout;
  grid->setHorizontalSpacing(10);
  grid->setVerticalSpacing(0);
  for (int axis = 0; axis < 6; ++axis) {
    auto* name = new QLabel(tr(kAxisNames[axis]), this);
    name->setStyleSheet("font-size: 18px; color: #aab0bc;");
    values_[axis] = new QLabel(this);
    values_[axis]->setAlignment(Qt::AlignRight | Qt::AlignVCenter);
    values_[axis]->setMinimumWidth(150);
    units_[axis] = new QLabel(axis < 3 ? tr("mm") : tr("deg"), this);
    units_[axis]->setStyleSheet("font-size: 18px; color: #aab0bc;");
    // A small gap between the translations and the rotations.
    const int row = axis < 3 ? axis : axis + 1;
    grid->addWidget(name, row, 0);
    grid->addWidget(values_[axis], row, 1);
    grid->addWidget(units_[axis], row, 2);
  }
  grid->setRowMinimumHeight(3, 10);
  grid->setColumnStretch(1, 1);
  magnitude_ = new QLabel(this);
  magnitude_->setStyleSheet("font-size: 15px;");
  magnitude_->setWordWrap(true);
  rate_ = new QLabel(this);
  rate_->setStyleSheet("font-size: 15px; color: #aab0bc;");
  auto* layout = new QVBoxLayout(this);
  layout->setContentsMargins(10, 10, 10, 10);
  layout->addWidget(banner_);
  layout->addWidget(reason_);
  layout->addLayout(grid);
  layout->addWidget(magnitude_);
  layout->addStretch(1);
  layout->addWidget(rate_);
  Clear(tr("Press Play to track"));
}

void CorrectionPanel::SetTolerances(const CouchTolerances& tolerances) { tolerances_ = tolerances; }

void CorrectionPanel::Clear(const QString& text) {
  banner_->setText(text);
  banner_->setStyleSheet("background: #3a3f4b; color: #d8dce4; font-size: 24px; font-weight: bold; padding: 6px;");
  reason_->clear();
  reason_->hide();
  for (int axis = 0; axis < 6; ++axis) {
    values_[axis]->setText("\u2014");
    values_[axis]->setStyleSheet("font-size: 40px; font-weight: bold; color: #7a7f8a;");
  }
  magnitude_->clear();
  rate_->clear();
}

void CorrectionPanel::ShowCorrection(const CouchCorrection& c, const QString& reason) {
  const QString color = ValueColor(c.state);
  const QColor banner = StateColor(c.state);
  const QString banner_text = c.state == CorrectionState::kIn    ? tr("IN TOLERANCE")
                              : c.state == CorrectionState::kOut ? tr("OUT OF TOLERANCE")
                                                                 : tr("TRACKING LOST");
  banner_->setText(banner_text);
  banner_->setStyleSheet(QString("background: %1; color: %2; font-size: %3px; font-weight: bold; padding: 6px;")
                             .arg(banner.name())
                             .arg(c.state == CorrectionState::kOut ? "#111111" : "#ffffff")
                             .arg(c.state == CorrectionState::kLost ? 34 : 28));
  if (c.state == CorrectionState::kLost) {
    reason_->setText(reason.isEmpty() ? tr("No pose in this frame: do not move the couch.")
                                      : tr("No pose: do not move the couch. %1").arg(reason.left(300)));
    reason_->show();
  } else {
    reason_->clear();
    reason_->hide();
  }
  const double values[6] = {c.lateral_mm, c.longitudinal_mm, c.vertical_mm, c.pitch_deg, c.roll_deg, c.yaw_deg};
  for (int axis = 0; axis < 6; ++axis) {
    values_[axis]->setText(c.state == CorrectionState::kLost ? QString("\u2014")
                                                              : Signed(values[axis], axis < 3 ? 1 : 2));
    values_[axis]->setStyleSheet(QString("font-size: 40px; font-weight: bold; color: %1;").arg(color));
  }
  if (c.state == CorrectionState::kLost) {
    magnitude_->clear();
  } else {
    magnitude_->setText(tr("Shift %1 mm (\u00b1%2), tolerance %3 mm\nTurn %4 deg (\u00b1%5), tolerance %6 deg")
                            .arg(c.translation_mm, 0, 'f', 1)
                            .arg(c.uncertainty.translation_mm, 0, 'f', 1)
                            .arg(tolerances_.translation_mm, 0, 'g', 3)
                            .arg(c.rotation_deg, 0, 'f', 2)
                            .arg(c.uncertainty.rotation_deg, 0, 'f', 2)
                            .arg(tolerances_.rotation_deg, 0, 'g', 3));
    magnitude_->setStyleSheet(QString("font-size: 15px; color: %1;").arg(color));
  }
}

void CorrectionPanel::ShowRate(double frames_per_s, double latency_ms) {
  rate_->setText(tr("%1 frames/s   latency %2 ms")
                     .arg(frames_per_s > 0 ? QString::number(frames_per_s, 'f', frames_per_s < 10 ? 1 : 0)
                                           : QString("\u2014"))
                     .arg(latency_ms, 0, 'f', 0));
}

}  // namespace arpos::ui
