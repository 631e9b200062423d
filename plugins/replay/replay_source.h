#pragma once
/// Plays a recorded TUM-layout sequence as if it were a live camera (after
/// PLUS's SavedDataSource), so that every test runs without hardware.
/// Every colour frame is delivered; a frame whose colour cannot be read comes
/// with an empty image and RgbdFrame::problem saying why, one without usable
/// depth with an empty depth image and the reason.

#include <chrono>
#include <memory>
#include <string>

#include "sensor/camera_source.h"
#include "sensor/sequence.h"

namespace arpos {

struct ReplayOptions {
  /// Deliver frames at the recorded rate (sleeping between them) rather than
  /// as fast as they can be read.
  bool realtime = false;
  /// Skip this many frames between delivered ones (0 = every frame).
  int frame_step = 0;
};

class ReplaySource : public CameraSource {
 public:
  /// Opens the sequence's index at once (throws InputError for a missing or
  /// unreadable index), so that frame_count() is known before Open().
  ReplaySource(std::filesystem::path sequence_dir, CameraIntrinsics intrinsics,
               ReplayOptions options = {});
  const CameraIntrinsics& intrinsics() const override { return intrinsics_; }
  std::string description() const override;
  int frame_count() const override;
  bool live() const override { return options_.realtime; }
  std::string recording_path() const override { return dir_.string(); }

 protected:
  void OpenImpl() override;
  bool NextImpl(RgbdFrame* frame) override;

 private:
  std::filesystem::path dir_;
  CameraIntrinsics intrinsics_;
  ReplayOptions options_;
  Sequence sequence_;
  size_t next_ = 0;
  std::chrono::steady_clock::time_point start_wall_;
  double start_timestamp_s_ = 0;
};

/// "SEQUENCE_DIR" or "SEQUENCE_DIR?realtime". Finds case.yaml in the
/// sequence folder's parents (room/ -> case, tracking/x/ -> case) and builds
/// a ReplaySource. Throws InputError if there is none.
std::unique_ptr<CameraSource> MakeReplaySourceFromUri(const std::string& uri);

}  // namespace arpos
