#pragma once
/// Tracking mode live in the GUI: a live camera source, or a recorded
/// sequence played as if live, tracked frame by frame
/// on a worker thread (TrackSequence with its per-frame hooks), the run
/// stored when the sequence ends or the user stops. Every tracked frame
/// reaches the GUI as a queued FrameTracked signal (none dropped); the AR
/// overlay image is drawn on a second thread and handed over as FrameImage,
/// at most one image in flight: when the GUI is slower than tracking, the
/// images in between are skipped (never the tracked frames).
///
/// Pause blocks the tracking thread between frames; Step lets one frame
/// through while paused; Stop ends the run after the current frame and
/// stores the frames so far.

#include <QMetaType>
#include <QObject>
#include <QString>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <opencv2/core.hpp>

#include "feedback/couch_correction.h"
#include "store/records.h"
#include "store/roles.h"
#include "tracking/tracker.h"

namespace arpos {
class OverlayRenderer;
struct TrackedFrameEvent;
}  // namespace arpos

namespace arpos::ui {

/// One tracked frame as the GUI shows it.
struct LiveFrame {
  int index = 0;  ///< frame index in the sequence
  int count = 0;  ///< frames in the sequence (0: a live stream)
  double timestamp_s = 0;
  TrackingState state = TrackingState::kLost;
  CouchCorrection correction;
  TrackingLoss loss = TrackingLoss::kNone;  ///< why there is no pose
  double latency_ms = 0;       ///< frame handed to the tracker to correction ready
  double frames_per_s = 0;     ///< tracked frames per second of wall time, last 2 s
  bool readable = true;        ///< false: the colour image could not be read
  bool has_depth = true;
  QString note;  ///< the frame's stored note (gap, depth problem, why lost)
};

struct LiveRunRequest {
  std::string store_path;
  std::filesystem::path case_dir;
  std::filesystem::path sequence_dir;
  /// A live camera source instead of sequence_dir (`arpos sources`, e.g.
  /// openni2: or sim:CASE); frames come at the camera's pace.
  std::string source_spec;
  std::string name;  ///< the run's sequence name
  std::optional<SessionId> session;  ///< empty: the newest with an alignment
  std::optional<RecordingId> recording_id;  ///< the stored recording of the sequence, if any
  Operator op;  ///< who tracks (checked again by TrackSequence)
  CouchTolerances tolerances;
  /// Frames no sooner than the recording's own spacing (gaps over 1 s count as
  /// 1 s); false: as fast as tracking goes.
  bool recorded_pace = true;
  bool start_paused = false;
  /// Pause by itself once this many frames are tracked (-1: never).
  int pause_after_frames = -1;
};

class LiveTracking : public QObject {
  Q_OBJECT
 public:
  explicit LiveTracking(QObject* parent = nullptr);
  /// Stops a running run and waits for it to be stored.
  ~LiveTracking() override;

  /// Starts a run unless one is running; returns false if busy.
  bool Start(const LiveRunRequest& request);
  void Pause();
  void Resume();
  /// While paused: track one more frame (starts nothing by itself).
  void Step();
  /// Ends the run after the current frame; Finished follows.
  void Stop();
  /// Stop() and wait until the run is stored (GUI thread blocks briefly).
  void StopAndWait();
  /// The GUI has shown the last FrameImage: the next one may be drawn.
  void ImageShown();

  bool running() const { return running_; }
  bool paused() const;

 signals:
  /// Inputs loaded: which session, plan, room map.
  void Started(QString description);
  void FrameTracked(arpos::ui::LiveFrame frame);
  /// The overlay of frame `index` (BGR, 8-bit).
  void FrameImage(cv::Mat image, int index);
  void PausedChanged(bool paused);
  /// ok: the run was stored (message: its summary); else the error.
  void Finished(bool ok, QString message, qint64 run_id, int frames);

 private:
  struct RenderJob {
    int index = 0;
    cv::Mat colour;
    std::optional<Rigid3d> current, planned;
    CouchCorrection correction;
  };
  void Run(LiveRunRequest request);
  bool BeforeFrame(size_t index, const std::vector<double>& timestamps);
  void OnFrame(const TrackedFrameEvent& event);
  void RenderLoop(std::shared_ptr<const OverlayRenderer> renderer);
  void Join();

  std::thread thread_, render_thread_;
  std::atomic<bool> running_{false};

  mutable std::mutex control_mutex_;
  std::condition_variable control_cv_;
  bool paused_ = false;
  bool cancel_ = false;
  int steps_ = 0;
  int pause_after_frames_ = -1;
  bool recorded_pace_ = true;
  std::chrono::steady_clock::time_point last_frame_wall_;
  std::deque<std::chrono::steady_clock::time_point> frame_walls_;

  std::mutex render_mutex_;
  std::condition_variable render_cv_;
  std::optional<RenderJob> pending_;
  bool image_in_flight_ = false;
  bool render_quit_ = false;
  bool render_abandon_ = false;  ///< quit without drawing what is pending
};

}  // namespace arpos::ui

Q_DECLARE_METATYPE(arpos::ui::LiveFrame)
Q_DECLARE_METATYPE(cv::Mat)
