// Live sources: the simulator plugin as a camera, the frame feed between a
// live source and a slower reader, and the recorder.
#include <gtest/gtest.h>

#include <chrono>
#include <opencv2/imgcodecs.hpp>
#include <thread>

#include "geometry/pose_error.h"
#include "sensor/camera_source.h"
#include "sensor/case_config.h"
#include "sensor/frame_feed.h"
#include "sensor/recorder.h"
#include "sensor/sequence.h"
#include "sensor/source_plugin.h"
#include "util/check.h"
#include "util/file.h"

namespace arpos {
namespace {

const std::string kSample = std::string(ARPOS_SAMPLE_SESSIONS_DIR) + "/demo_xtion";

bool SameImage(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0;
}

CameraSourceRegistry& Plugins() {
  static CameraSourceRegistry registry;
  static bool loaded = [] {
    LoadSourcePlugins(&registry, {ARPOS_PLUGIN_DIR});
    return true;
  }();
  (void)loaded;
  return registry;
}

TEST(SimulatorSource, RendersTheCasesOwnTrackingFramesLive) {
  // The world is rebuilt from simulation.yaml: the frames are the case's
  // recorded ones, byte for byte.
  auto source = Plugins().Create("sim:" + kSample + "?fps=200");
  EXPECT_TRUE(source->live());
  const Sequence recorded = Sequence::OpenEveryColourFrame(kSample + "/tracking/seq_00");
  ASSERT_EQ(source->frame_count(), static_cast<int>(recorded.size()));
  const CaseConfig config = LoadCaseConfig(kSample + "/case.yaml");
  EXPECT_EQ(source->intrinsics().width, config.camera.width);
  EXPECT_DOUBLE_EQ(source->intrinsics().fx, config.camera.fx);
  const auto camera_truth = recorded.CameraGroundTruth();
  const auto body_truth = recorded.BodyGroundTruth();
  ASSERT_TRUE(camera_truth && body_truth);
  source->Open();
  RgbdFrame frame;
  size_t n = 0;
  auto previous = std::chrono::steady_clock::time_point{};
  while (source->Next(&frame)) {
    ASSERT_LT(n, recorded.size());
    const RgbdFrame expected = recorded.LoadFrame(n, config.camera);
    EXPECT_NEAR(frame.timestamp_s, expected.timestamp_s, 1e-6);
    EXPECT_TRUE(SameImage(frame.color, expected.color)) << "colour of frame " << n;
    EXPECT_TRUE(SameImage(frame.depth, expected.depth)) << "depth of frame " << n;
    EXPECT_TRUE(frame.problem.empty());
    // The truth it carries is the case's (files round to 1e-6 m).
    ASSERT_TRUE(frame.true_room_from_camera && frame.true_room_from_model);
    EXPECT_LT(ComputePoseError((*camera_truth)[n].room_from_x, *frame.true_room_from_camera).translation_mm, 0.01);
    EXPECT_LT(ComputePoseError((*body_truth)[n].room_from_x, *frame.true_room_from_model).translation_mm, 0.01);
    // Paced: 5 ms apart at 200 fps (not faster; how much slower is the machine's).
    if (n > 0) {
      EXPECT_GE(frame.arrival - previous, std::chrono::microseconds(4000));
    }
    previous = frame.arrival;
    ++n;
  }
  EXPECT_EQ(n, recorded.size());
}

TEST(SimulatorSource, ALongerSequenceIsANewPathInTheSameWorld) {
  auto source = Plugins().Create("sim:" + kSample + "?frames=12&fps=1000");
  EXPECT_EQ(source->frame_count(), 12);
  source->Open();
  RgbdFrame frame;
  std::vector<double> t;
  while (source->Next(&frame)) t.push_back(frame.timestamp_s);
  ASSERT_EQ(t.size(), 12u);
  for (size_t i = 1; i < t.size(); ++i) EXPECT_GT(t[i], t[i - 1]);
}

TEST(SimulatorSource, BadUrisAreInputErrorsNamingTheKey) {
  const auto message = [](const std::string& spec) {
    try {
      Plugins().Create(spec);
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("(no error)");
  };
  EXPECT_NE(message("sim:" + kSample + "?speed=2").find("speed"), std::string::npos);
  EXPECT_NE(message("sim:" + kSample + "?frames=0").find("frames"), std::string::npos);
  EXPECT_NE(message("sim:" + kSample + "?fps=-3").find("fps"), std::string::npos);
  EXPECT_NE(message("sim:" + kSample + "?seq=4").find("seq=4"), std::string::npos);
  EXPECT_NE(message("sim:/nowhere").find("simulation.yaml"), std::string::npos);
  EXPECT_NE(message("sim:").find("sim:CASE_DIR"), std::string::npos);
}

// A live camera of `n` frames, one every `interval`.
class FakeLiveSource : public CameraSource {
 public:
  FakeLiveSource(int n, std::chrono::milliseconds interval) : n_(n), interval_(interval) {
    intrinsics_.width = 8;
    intrinsics_.height = 6;
    intrinsics_.fx = intrinsics_.fy = 10;
    intrinsics_.cx = 4;
    intrinsics_.cy = 3;
  }
  const CameraIntrinsics& intrinsics() const override { return intrinsics_; }
  std::string description() const override { return "fake"; }
  bool live() const override { return live_; }
  bool live_ = true;

 protected:
  void OpenImpl() override { next_ = 0; }
  bool NextImpl(RgbdFrame* frame) override {
    if (next_ >= n_) return false;
    if (live_) std::this_thread::sleep_for(interval_);
    frame->index = next_;
    frame->timestamp_s = next_ * 0.001 * interval_.count();
    frame->color = cv::Mat(6, 8, CV_8UC3, cv::Scalar(next_, 0, 0));
    frame->depth = cv::Mat(6, 8, CV_16UC1, cv::Scalar(1000 + next_));
    frame->arrival = std::chrono::steady_clock::now();
    ++next_;
    return true;
  }

 private:
  CameraIntrinsics intrinsics_;
  int n_;
  std::chrono::milliseconds interval_;
  int next_ = 0;
};

TEST(FrameFeed, ASlowReaderOfALiveSourceLosesFramesThatAreCounted) {
  FakeLiveSource source(40, std::chrono::milliseconds(2));
  int seen_by_capture = 0;
  FrameFeed feed(&source, [&](const RgbdFrame&) { ++seen_by_capture; });
  RgbdFrame frame;
  int taken = 0, last_index = -1;
  while (feed.Take(&frame)) {
    EXPECT_GT(frame.index, last_index);  // never an older frame
    last_index = frame.index;
    ++taken;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_EQ(feed.captured(), 40);
  EXPECT_EQ(seen_by_capture, 40);  // the recorder sees every frame
  EXPECT_EQ(feed.taken(), taken);
  EXPECT_GT(feed.dropped(), 0);
  EXPECT_EQ(feed.taken() + feed.dropped(), 40);
  EXPECT_EQ(last_index, 39);  // the newest frame is never lost at the end
}

TEST(FrameFeed, AQueueCatchesUpASlowFrameWithoutLosingOne) {
  FakeLiveSource source(30, std::chrono::milliseconds(10));
  FrameFeed feed(&source, {}, 3);
  RgbdFrame frame;
  int n = 0;
  while (feed.Take(&frame)) {
    EXPECT_EQ(frame.index, n);  // in order, none missing
    // One slow frame (two intervals), the rest quick.
    std::this_thread::sleep_for(std::chrono::milliseconds(n == 5 ? 20 : 0));
    ++n;
  }
  EXPECT_EQ(n, 30);
  EXPECT_EQ(feed.dropped(), 0);
}

TEST(FrameFeed, ARecordingIsReadWholeAndStopEndsALiveFeed) {
  FakeLiveSource recording(10, std::chrono::milliseconds(0));
  recording.live_ = false;
  {
    FrameFeed feed(&recording);
    RgbdFrame frame;
    int n = 0;
    while (feed.Take(&frame)) {
      EXPECT_EQ(frame.index, n);
      ++n;
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    EXPECT_EQ(n, 10);
    EXPECT_EQ(feed.dropped(), 0);
  }
  FakeLiveSource camera(100000, std::chrono::milliseconds(1));
  FrameFeed feed(&camera);
  RgbdFrame frame;
  ASSERT_TRUE(feed.Take(&frame));
  feed.Stop();
  EXPECT_FALSE(feed.Take(&frame));
  EXPECT_FALSE(camera.is_open());
}

RgbdFrame SyntheticFrame(int i, double depth_scale) {
  RgbdFrame frame;
  frame.index = i;
  frame.timestamp_s = 100 + i / 30.0;
  frame.color = cv::Mat(48, 64, CV_8UC3);
  cv::randu(frame.color, 0, 255);
  frame.depth = cv::Mat(48, 64, CV_16UC1, cv::Scalar(800 + i));
  frame.depth_scale = depth_scale;
  return frame;
}

// The 64x48 camera of SyntheticFrame.
CameraIntrinsics SmallCamera(double depth_scale) {
  CameraIntrinsics camera;
  camera.width = 64;
  camera.height = 48;
  camera.fx = camera.fy = 60;
  camera.cx = 31.5;
  camera.cy = 23.5;
  camera.depth_scale = depth_scale;
  return camera;
}

TEST(Recorder, WritesAReplayableSequenceInTheCasesDepthUnits) {
  TempDir dir;
  const std::filesystem::path seq = dir.path() / "case" / "tracking" / "rec";
  // No case.yaml yet: one is written with the source's camera.
  const CameraIntrinsics camera = SmallCamera(1000);
  CaseConfig markers;
  markers.room_markers = {0.15, 0, 49};
  markers.body_markers = {0.03, 100, 199};
  const RecordingFolder folder = PrepareRecordingFolder(seq, camera, markers, "the test's markers");
  EXPECT_EQ(folder.case_dir, dir.path() / "case");
  EXPECT_FALSE(folder.note.empty());
  EXPECT_EQ(LoadCaseConfig(dir.path() / "case" / "case.yaml").camera.width, 64);
  // A case of another depth unit: frames are converted to it.
  RecorderOptions options;
  options.depth_scale = 5000;
  std::vector<RgbdFrame> frames;
  {
    SequenceRecorder recorder(seq, options);
    for (int i = 0; i < 5; ++i) {
      frames.push_back(SyntheticFrame(i, 1000));
      frames.back().true_room_from_camera = Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(i, 0, 1));
      frames.back().true_room_from_model = Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, i, 1));
      recorder.Push(frames.back());
    }
    RgbdFrame broken = SyntheticFrame(5, 1000);
    broken.color.release();
    broken.problem = "unreadable";
    recorder.Push(broken);
    const RecorderStats stats = recorder.Finish();
    EXPECT_EQ(stats.pushed, 6);
    EXPECT_EQ(stats.written, 5);
    EXPECT_EQ(stats.depth_written, 5);
    EXPECT_EQ(stats.unusable, 1);
    EXPECT_EQ(stats.dropped, 0);
    EXPECT_NE(stats.Summary().find("5 frames written"), std::string::npos) << stats.Summary();
  }
  const Sequence replay = Sequence::OpenEveryColourFrame(seq);
  ASSERT_EQ(replay.size(), 5u);
  // The truth the frames carried, for the frames written.
  ASSERT_TRUE(replay.CameraGroundTruth() && replay.BodyGroundTruth());
  ASSERT_EQ(replay.BodyGroundTruth()->size(), 5u);
  EXPECT_NEAR((*replay.BodyGroundTruth())[3].room_from_x.translation.y(), 3.0, 1e-9);
  const CameraIntrinsics case_camera = SmallCamera(5000);
  for (size_t i = 0; i < 5; ++i) {
    const RgbdFrame f = replay.LoadFrame(i, case_camera);
    EXPECT_NEAR(f.timestamp_s, frames[i].timestamp_s, 1e-6);
    EXPECT_TRUE(SameImage(f.color, frames[i].color));
    EXPECT_NEAR(f.DepthM(3, 3), frames[i].DepthM(3, 3), 1e-9);
  }
  // A folder with something in it is refused, and so is a camera that does
  // not match the case's.
  EXPECT_THROW(SequenceRecorder(seq, options), InputError);
  CameraIntrinsics other = camera;
  other.width = 640;
  EXPECT_THROW(PrepareRecordingFolder(dir.path() / "case" / "tracking" / "two", other, markers, "the test's markers"), InputError);
}

TEST(Recorder, EncodingLaterWritesTheSameSequenceAndLeavesNoSpool) {
  TempDir dir;
  RecorderOptions options;
  options.encode_later = true;
  options.writer_threads = 2;
  options.depth_scale = 5000;
  std::vector<RgbdFrame> frames;
  {
    SequenceRecorder recorder(dir.path() / "seq", options);
    for (int i = 0; i < 6; ++i) {
      frames.push_back(SyntheticFrame(i, 1000));
      if (i == 2) frames.back().depth.release();  // a frame without depth
      recorder.Push(frames.back());
    }
    const RecorderStats stats = recorder.Finish();
    EXPECT_EQ(stats.written, 6);
    EXPECT_EQ(stats.depth_written, 5);
    EXPECT_EQ(stats.write_failures, 0) << stats.first_failure;
  }
  EXPECT_FALSE(std::filesystem::exists(dir.path() / "seq" / ".spool"));
  const Sequence replay = Sequence::OpenEveryColourFrame(dir.path() / "seq");
  ASSERT_EQ(replay.size(), 6u);
  const CameraIntrinsics camera = SmallCamera(5000);
  for (size_t i = 0; i < 6; ++i) {
    std::string depth_problem;
    const RgbdFrame f = replay.LoadFrameColourFirst(i, camera, &depth_problem);
    EXPECT_TRUE(SameImage(f.color, frames[i].color)) << i;
    if (i == 2) {
      EXPECT_TRUE(f.depth.empty());
    } else {
      EXPECT_NEAR(f.DepthM(3, 3), frames[i].DepthM(3, 3), 1e-9) << i;
    }
  }
}

// A source that knows its depth was taken 8 ms after the colour (no
// colour-depth sync): depth.txt lists it at its own time, written at once
// or later, and the reader hands the delay back.
TEST(Recorder, DepthOfItsOwnInstantIsListedAtIt) {
  for (const bool later : {false, true}) {
    TempDir dir;
    RecorderOptions options;
    options.encode_later = later;
    {
      SequenceRecorder recorder(dir.path() / "seq", options);
      for (int i = 0; i < 3; ++i) {
        RgbdFrame frame = SyntheticFrame(i, 1000);
        frame.depth_delay_s = 0.008;
        recorder.Push(frame);
      }
      EXPECT_EQ(recorder.Finish().depth_written, 3);
    }
    const Sequence replay = Sequence::Open(dir.path() / "seq");
    ASSERT_EQ(replay.size(), 3u) << later;
    for (size_t i = 0; i < 3; ++i) {
      EXPECT_NEAR(replay.depth_delay_s(i), 0.008, 1e-6) << later << " " << i;
      EXPECT_NEAR(replay.LoadFrame(i, SmallCamera(1000)).DepthM(3, 3), (800 + i) / 1000.0, 1e-9);
    }
  }
}

TEST(Recorder, AFullQueueDropsFramesAndCountsThemInsteadOfWaiting) {
  TempDir dir;
  RecorderOptions options;
  options.queue_frames = 1;
  options.png_compression = 9;  // slow writes
  SequenceRecorder recorder(dir.path() / "seq", options);
  const RgbdFrame frame = SyntheticFrame(0, 1000);
  const auto start = std::chrono::steady_clock::now();
  for (int i = 0; i < 200; ++i) {
    RgbdFrame f = frame;
    f.timestamp_s = 100 + i / 30.0;
    recorder.Push(f);
  }
  const double push_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const RecorderStats stats = recorder.Finish();
  EXPECT_EQ(stats.pushed, 200);
  EXPECT_GT(stats.dropped, 0);
  EXPECT_EQ(stats.written + stats.dropped, 200);
  EXPECT_EQ(stats.max_queue, 1);
  EXPECT_LT(push_s, 10.0);  // bounded, not a speed check: pushing never waits for a write
  EXPECT_EQ(Sequence::OpenEveryColourFrame(dir.path() / "seq").size(), static_cast<size_t>(stats.written));
}

}  // namespace
}  // namespace arpos
