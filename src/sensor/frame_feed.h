#pragma once
/// Frames from a camera source to one reader, the way a live camera gives
/// them: a live source (CameraSource::live()) runs on a capture thread of its
/// own and the reader takes frames in order from a queue of at most
/// `max_queue` frames; when a frame arrives at a full queue the oldest is
/// dropped and counted, so capture never waits for processing and the reader
/// is never more than `max_queue` frames behind (1: always the newest). A recording (not live) is read frame by frame on the reader's
/// thread and nothing is dropped.
///
/// `on_capture` sees every frame the source delivers, dropped or not, on the
/// capture thread (the recorder: a live session is written whole even when
/// tracking skips frames). It must be quick (SequenceRecorder::Push is).

#include <condition_variable>
#include <functional>
#include <mutex>
#include <deque>
#include <thread>

#include "sensor/camera_source.h"

namespace arpos {

class FrameFeed {
 public:
  /// Opens `source` (which must outlive the feed) and, when live, starts
  /// capturing at once.
  FrameFeed(CameraSource* source, std::function<void(const RgbdFrame&)> on_capture = {}, int max_queue = 1);
  ~FrameFeed();
  FrameFeed(const FrameFeed&) = delete;
  FrameFeed& operator=(const FrameFeed&) = delete;

  /// The next frame (live: the oldest queued), waiting for it; false
  /// at the end of the stream or after Stop().
  bool Take(RgbdFrame* frame);
  /// Stops capturing and closes the source; Take returns false from then on.
  void Stop();

  int captured() const;  ///< frames the source delivered
  int taken() const;     ///< frames handed to the reader
  int dropped() const;   ///< live: frames pushed out of the queue before they were taken

 private:
  void Capture();

  CameraSource* source_;
  std::function<void(const RgbdFrame&)> on_capture_;
  bool live_ = false;
  mutable std::mutex mutex_;
  std::condition_variable ready_;
  size_t max_queue_ = 1;
  std::deque<RgbdFrame> queue_;
  bool ended_ = false;
  bool stop_ = false;
  int captured_ = 0, taken_ = 0, dropped_ = 0;
  std::thread thread_;
};

}  // namespace arpos
