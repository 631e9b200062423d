#include "ui/live_tracking.h"

#include <algorithm>

#include "room_map/plan_stage.h"
#include "sensor/case_config.h"
#include "sensor/camera_source.h"
#include "sensor/sequence.h"
#include "sensor/source_plugin.h"
#include "store/sqlite_database.h"
#include "tracking/overlay.h"
#include "tracking/tracking_stage.h"
#include "util/string_util.h"

namespace arpos::ui {

namespace {
using Clock = std::chrono::steady_clock;
// A recorded gap longer than this is replayed as this long.
constexpr double kMaxPaceGapS = 1.0;
}  // namespace

LiveTracking::LiveTracking(QObject* parent) : QObject(parent) {
  qRegisterMetaType<arpos::ui::LiveFrame>("arpos::ui::LiveFrame");
  qRegisterMetaType<cv::Mat>("cv::Mat");
}

LiveTracking::~LiveTracking() {
  {
    std::lock_guard<std::mutex> lock(render_mutex_);
    render_abandon_ = true;
  }
  StopAndWait();
}

bool LiveTracking::paused() const {
  std::lock_guard<std::mutex> lock(control_mutex_);
  return paused_;
}

bool LiveTracking::Start(const LiveRunRequest& request) {
  if (running_) return false;
  Join();
  {
    std::lock_guard<std::mutex> lock(control_mutex_);
    paused_ = request.start_paused;
    cancel_ = false;
    steps_ = 0;
    pause_after_frames_ = request.pause_after_frames;
    recorded_pace_ = request.recorded_pace;
    frame_walls_.clear();
  }
  {
    std::lock_guard<std::mutex> lock(render_mutex_);
    pending_.reset();
    image_in_flight_ = false;
    render_quit_ = false;
    render_abandon_ = false;
  }
  running_ = true;
  thread_ = std::thread([this, request] { Run(request); });
  return true;
}

void LiveTracking::Pause() {
  {
    std::lock_guard<std::mutex> lock(control_mutex_);
    if (paused_ || !running_) return;
    paused_ = true;
  }
  control_cv_.notify_all();
  emit PausedChanged(true);
}

void LiveTracking::Resume() {
  {
    std::lock_guard<std::mutex> lock(control_mutex_);
    if (!paused_) return;
    paused_ = false;
    steps_ = 0;
    last_frame_wall_ = Clock::now();  // pace from here, not from before the pause
  }
  control_cv_.notify_all();
  emit PausedChanged(false);
}

void LiveTracking::Step() {
  {
    std::lock_guard<std::mutex> lock(control_mutex_);
    if (!paused_) return;
    ++steps_;
  }
  control_cv_.notify_all();
}

void LiveTracking::Stop() {
  {
    std::lock_guard<std::mutex> lock(control_mutex_);
    cancel_ = true;
  }
  control_cv_.notify_all();
}

void LiveTracking::StopAndWait() {
  Stop();
  Join();
}

void LiveTracking::Join() {
  if (thread_.joinable()) thread_.join();
}

void LiveTracking::ImageShown() {
  {
    std::lock_guard<std::mutex> lock(render_mutex_);
    image_in_flight_ = false;
  }
  render_cv_.notify_all();
}

bool LiveTracking::BeforeFrame(size_t index, const std::vector<double>& timestamps) {
  std::unique_lock<std::mutex> lock(control_mutex_);
  if (pause_after_frames_ >= 0 && static_cast<int>(index) >= pause_after_frames_ && !paused_) {
    pause_after_frames_ = -1;
    paused_ = true;
    emit PausedChanged(true);
  }
  for (;;) {
    control_cv_.wait(lock, [this] { return cancel_ || !paused_ || steps_ > 0; });
    if (cancel_) return false;
    if (paused_) {  // one step
      --steps_;
      break;
    }
    if (!recorded_pace_ || index == 0 || index >= timestamps.size()) break;
    const double gap = std::clamp(timestamps[index] - timestamps[index - 1], 0.0, kMaxPaceGapS);
    const auto due = last_frame_wall_ + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(gap));
    control_cv_.wait_until(lock, due, [this] { return cancel_ || paused_; });
    if (cancel_) return false;
    if (paused_) continue;  // paused while waiting: wait for play or step
    break;
  }
  last_frame_wall_ = Clock::now();
  return true;
}

void LiveTracking::OnFrame(const TrackedFrameEvent& event) {
  const TrackedFrame& tracked = *event.tracked;
  LiveFrame frame;
  frame.index = static_cast<int>(event.index);
  frame.count = static_cast<int>(event.count);
  frame.timestamp_s = tracked.timestamp_s;
  frame.state = tracked.state;
  frame.correction = tracked.correction;
  frame.loss = tracked.loss;
  frame.latency_ms = tracked.timings.total_ms;
  frame.readable = !event.colour.empty();
  frame.has_depth = event.has_depth;
  frame.note = QString::fromStdString(event.note);
  {
    std::lock_guard<std::mutex> lock(control_mutex_);
    const auto now = Clock::now();
    frame_walls_.push_back(now);
    while (frame_walls_.size() > 2 && now - frame_walls_.front() > std::chrono::seconds(2)) frame_walls_.pop_front();
    const double span = std::chrono::duration<double>(frame_walls_.back() - frame_walls_.front()).count();
    frame.frames_per_s = frame_walls_.size() >= 2 && span > 0 ? (frame_walls_.size() - 1) / span : 0;
  }
  emit FrameTracked(frame);
  if (event.colour.empty()) return;
  {
    std::lock_guard<std::mutex> lock(render_mutex_);
    RenderJob job;
    job.index = frame.index;
    job.colour = event.colour;  // shared, never written
    job.current = event.poses.camera_from_model_current;
    job.planned = event.poses.camera_from_model_planned;
    job.correction = tracked.correction;
    pending_ = std::move(job);  // replaces one not yet drawn
  }
  render_cv_.notify_all();
}

void LiveTracking::RenderLoop(std::shared_ptr<const OverlayRenderer> renderer) {
  for (;;) {
    RenderJob job;
    {
      std::unique_lock<std::mutex> lock(render_mutex_);
      render_cv_.wait(lock, [this] {
        return render_abandon_ || render_quit_ || (pending_.has_value() && !image_in_flight_);
      });
      if (render_abandon_ || (render_quit_ && !pending_)) return;
      // At the end the last frame is drawn even if the GUI has not shown the
      // previous one yet (it must not wait on a GUI that waits on us).
      job = std::move(*pending_);
      pending_.reset();
      image_in_flight_ = true;
    }
    try {
      emit FrameImage(renderer->Render(job.colour, job.current, job.planned, job.correction, ""), job.index);
    } catch (const std::exception&) {
      std::lock_guard<std::mutex> lock(render_mutex_);
      image_in_flight_ = false;  // nothing shown for this frame; the numbers still are
    }
  }
}

void LiveTracking::Run(LiveRunRequest request) {
  bool ok = true;
  QString message;
  qint64 run_id = 0;
  int frames = 0;
  try {
    auto database = SqliteDatabase::Open(request.store_path);
    const CaseConfig config = LoadCaseConfig(request.case_dir / "case.yaml");
    const TrackingInputs inputs = LoadTrackingInputs(database.get(), request.session, CasePatientId(request.case_dir));
    emit Started(QString::fromStdString(StringPrintf(
        "session %lld (plan %lld, room map %lld, alignment %lld, %zu stickers)",
        static_cast<long long>(inputs.session_id.value()), static_cast<long long>(inputs.plan_id.value()),
        static_cast<long long>(inputs.room_map_id.value()), static_cast<long long>(inputs.alignment_id.value()),
        inputs.model_from_marker.size()) + [&] {
          // Said before the first frame: otherwise a therapist sees only
          // `out` and learns why at the end.
          const RoomFrameNote note = DescribeRoomFrame(inputs, request.tolerances);
          const std::string check = DescribeAlignmentCheck(inputs.alignment_status);
          return (note.blocks_in ? "\n" + note.text : std::string()) +
                 (check.empty() ? "" : "\n" + check);
        }()));
    std::vector<double> timestamps;
    std::unique_ptr<CameraSource> source;
    if (!request.source_spec.empty()) {
      // A camera keeps its own pace.
      source = SourceRegistry().Create(request.source_spec);
      recorded_pace_ = false;
    } else {
      const Sequence sequence = Sequence::OpenEveryColourFrame(request.sequence_dir);
      for (size_t i = 0; i < sequence.size(); ++i) timestamps.push_back(sequence.timestamp_s(i));
    }
    OverlayOptions overlay_options;
    overlay_options.correction_panel = false;  // the page shows the numbers
    auto renderer = std::make_shared<const OverlayRenderer>(inputs.model, config.camera, overlay_options);
    render_thread_ = std::thread([this, renderer] { RenderLoop(renderer); });

    TrackSequenceOptions options;
    options.sequence_dir = request.sequence_dir;
    options.source = source.get();
    options.name = request.name;
    options.tolerances = request.tolerances;
    options.op = request.op;
    options.recording_id = request.recording_id;
    options.before_frame = [this, &timestamps](size_t index, size_t) { return BeforeFrame(index, timestamps); };
    options.on_frame = [this](const TrackedFrameEvent& event) { OnFrame(event); };
    TrackSequenceResult result;
    try {
      result = TrackSequence(database.get(), inputs, config, options);
    } catch (...) {
      {
        std::lock_guard<std::mutex> lock(render_mutex_);
        render_quit_ = true;
      }
      render_cv_.notify_all();
      render_thread_.join();
      throw;
    }
    {
      std::lock_guard<std::mutex> lock(render_mutex_);
      render_quit_ = true;
    }
    render_cv_.notify_all();
    render_thread_.join();
    run_id = result.run_id.value();
    frames = result.frames;
    message = QString::fromStdString(result.Summary());
  } catch (const std::exception& e) {
    ok = false;
    message = QString::fromStdString(e.what());
  }
  running_ = false;
  {
    std::lock_guard<std::mutex> lock(control_mutex_);
    if (paused_) {
      paused_ = false;
      emit PausedChanged(false);
    }
  }
  emit Finished(ok, message, run_id, frames);
}

}  // namespace arpos::ui
