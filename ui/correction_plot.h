#pragma once
/// The couch correction over the last seconds of the recording: translations
/// (lateral, longitudinal, vertical, mm) above, rotations (pitch, roll, yaw,
/// deg) below, each with its tolerance as dashed lines; frames without a
/// pose as red bands (the lines break there).

#include <QWidget>
#include <array>
#include <deque>
#include <utility>
#include <vector>

#include "feedback/couch_correction.h"

namespace arpos::ui {

class CorrectionPlot : public QWidget {
  Q_OBJECT
 public:
  explicit CorrectionPlot(QWidget* parent = nullptr);
  void SetTolerances(const CouchTolerances& tolerances);
  /// Seconds of recording time shown (default 10).
  void SetWindow(double seconds);
  void Add(double timestamp_s, const CouchCorrection& correction);
  /// A whole stored run at once (the audit page): the time axis spans it
  /// from its first frame (0 s) to its last; nothing is dropped; the
  /// shift's length and the turn's angle (translation_mm, rotation_deg)
  /// are drawn in white over the axes. Add and Clear go back to the live,
  /// sliding window.
  void SetRun(const std::vector<std::pair<double, CouchCorrection>>& frames);
  void Clear();
  QSize sizeHint() const override { return QSize(600, 200); }

 protected:
  void paintEvent(QPaintEvent* event) override;

 private:
  struct Sample {
    double t;
    std::array<double, 6> values;
    CorrectionState state;
    std::array<double, 2> magnitudes{};  ///< |shift| mm and turn angle deg (whole runs draw them)
  };
  void PaintPanel(class QPainter* painter, const QRectF& area, int first_axis, double tolerance,
                  const QString& unit, double t_end) const;
  CouchTolerances tolerances_;
  double window_s_ = 10.0;
  bool whole_run_ = false;  ///< SetRun: time from the first sample, not back from now
  std::deque<Sample> samples_;
};

}  // namespace arpos::ui
