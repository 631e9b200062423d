#include "sensor/frame_feed.h"

#include <algorithm>

namespace arpos {

FrameFeed::FrameFeed(CameraSource* source, std::function<void(const RgbdFrame&)> on_capture, int max_queue)
    : source_(source), on_capture_(std::move(on_capture)), max_queue_(static_cast<size_t>(std::max(1, max_queue))) {
  source_->Open();
  live_ = source_->live();
  if (live_) thread_ = std::thread([this] { Capture(); });
}

FrameFeed::~FrameFeed() { Stop(); }

void FrameFeed::Capture() {
  for (;;) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (stop_) break;
    }
    RgbdFrame frame;
    if (!source_->Next(&frame)) break;
    if (on_capture_) on_capture_(frame);
    std::lock_guard<std::mutex> lock(mutex_);
    ++captured_;
    if (queue_.size() >= max_queue_) {
      queue_.pop_front();
      ++dropped_;
    }
    queue_.push_back(std::move(frame));
    ready_.notify_one();
  }
  std::lock_guard<std::mutex> lock(mutex_);
  ended_ = true;
  ready_.notify_all();
}

bool FrameFeed::Take(RgbdFrame* frame) {
  if (!live_) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (stop_) return false;
    }
    if (!source_->Next(frame)) return false;
    if (on_capture_) on_capture_(*frame);
    std::lock_guard<std::mutex> lock(mutex_);
    ++captured_;
    ++taken_;
    return true;
  }
  std::unique_lock<std::mutex> lock(mutex_);
  ready_.wait(lock, [&] { return !queue_.empty() || ended_ || stop_; });
  if (stop_ || queue_.empty()) return false;
  *frame = std::move(queue_.front());
  queue_.pop_front();
  ++taken_;
  return true;
}

void FrameFeed::Stop() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (stop_ && !thread_.joinable()) return;
    stop_ = true;
    ready_.notify_all();
  }
  // A live source blocked in Next returns with its next frame (a frame
  // interval at most), then the thread sees stop_.
  if (thread_.joinable()) thread_.join();
  source_->Close();
}

int FrameFeed::captured() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return captured_;
}
int FrameFeed::taken() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return taken_;
}
int FrameFeed::dropped() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return dropped_;
}

}  // namespace arpos
