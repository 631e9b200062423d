#pragma once
/// Shows camera frames (colour, or depth in false colour) scaled to fit.

#include <QLabel>
#include <opencv2/core.hpp>

namespace arpos::ui {

class FrameView : public QLabel {
  Q_OBJECT
 public:
  explicit FrameView(QWidget* parent = nullptr);
  /// BGR 8-bit colour image.
  void ShowColor(const cv::Mat& bgr);
  /// 16-bit depth with its scale (units per metre), shown 0.3–3 m in false colour.
  void ShowDepth(const cv::Mat& depth, double depth_scale);

 protected:
  void resizeEvent(QResizeEvent* event) override;

 private:
  void UpdatePixmap();
  QImage image_;
};

}  // namespace arpos::ui
