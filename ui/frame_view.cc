#include "ui/frame_view.h"

#include <opencv2/imgproc.hpp>

namespace arpos::ui {

FrameView::FrameView(QWidget* parent) : QLabel(parent) {
  setAlignment(Qt::AlignCenter);
  setMinimumSize(320, 240);
  setStyleSheet("background: #1e2128; color: #aab;");
  setText("no frame");
}

void FrameView::ShowColor(const cv::Mat& bgr) {
  if (bgr.empty()) {  // nothing to show (a live camera not started)
    image_ = QImage();
    UpdatePixmap();
    return;
  }
  cv::Mat rgb;
  cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
  image_ = QImage(rgb.data, rgb.cols, rgb.rows, static_cast<int>(rgb.step), QImage::Format_RGB888).copy();
  UpdatePixmap();
}

void FrameView::ShowDepth(const cv::Mat& depth, double depth_scale) {
  cv::Mat metres, scaled, colored;
  depth.convertTo(metres, CV_32F, 1.0 / depth_scale);
  metres.convertTo(scaled, CV_8U, 255.0 / 2.7, -255.0 * 0.3 / 2.7);
  cv::applyColorMap(scaled, colored, cv::COLORMAP_TURBO);
  colored.setTo(cv::Scalar(0, 0, 0), depth == 0);
  ShowColor(colored);
}

void FrameView::resizeEvent(QResizeEvent* event) {
  QLabel::resizeEvent(event);
  UpdatePixmap();
}

void FrameView::UpdatePixmap() {
  if (image_.isNull()) {
    clear();
    return;
  }
  setPixmap(QPixmap::fromImage(image_).scaled(size(), Qt::KeepAspectRatio, Qt::SmoothTransformation));
}

}  // namespace arpos::ui
