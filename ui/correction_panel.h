#pragma once
/// The couch correction in large type for the therapist: one row per couch
/// axis (IEC 61217, feedback/couch_correction.h: lateral, longitudinal,
/// vertical in mm; pitch, roll, yaw in degrees), a banner with the tolerance
/// state (green in tolerance, amber out, red TRACKING LOST), the shift and
/// turn against their tolerances, and the frame rate and latency.

#include <QString>
#include <QWidget>

#include "feedback/couch_correction.h"

class QLabel;

namespace arpos::ui {

class CorrectionPanel : public QWidget {
  Q_OBJECT
 public:
  explicit CorrectionPanel(QWidget* parent = nullptr);
  void SetTolerances(const CouchTolerances& tolerances);
  /// `reason`: why lost (shown under the banner when lost).
  void ShowCorrection(const CouchCorrection& correction, const QString& reason);
  /// Processed frames per second and the frame's latency (ms).
  void ShowRate(double frames_per_s, double latency_ms);
  /// Nothing tracked yet (or the run was reset): grey, no numbers.
  void Clear(const QString& text);

  /// The banner's colours by state (background), also used by the plot.
  static QColor StateColor(CorrectionState state);

 private:
  CouchTolerances tolerances_;
  QLabel* banner_;
  QLabel* reason_;
  QLabel* values_[6];
  QLabel* units_[6];
  QLabel* magnitude_;
  QLabel* rate_;
};

}  // namespace arpos::ui
