#pragma once
/// Writes frames from any camera source as a sequence folder in the
/// DATASET.md layout (rgb/, depth/, rgb.txt, depth.txt), so that a live
/// session can be replayed and audited.
///
/// Push() never blocks the capture thread: frames wait in a bounded queue for
/// the writer threads that encode the PNGs; when the queue is full the frame
/// is dropped and counted. Finish() writes the two lists (only frames whose
/// files were written) and reports what happened.

#include <condition_variable>
#include <deque>
#include <filesystem>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "sensor/case_config.h"
#include "sensor/rgbd_frame.h"
#include "sensor/tum_io.h"

namespace arpos {

struct RecorderOptions {
  /// Frames waiting to be written at most (about 1.5 MB each at 640x480).
  int queue_frames = 90;
  int writer_threads = 1;
  int png_compression = 1;  ///< cv::IMWRITE_PNG_COMPRESSION; 1 is fast
  /// Depth PNG units per metre of the folder's case (case.yaml); frames of
  /// another scale are converted. 0: keep each frame's own.
  double depth_scale = 0;
  /// Spool the raw images to disk while recording and encode the PNGs in
  /// Finish() (on every writer thread): PNG encoding takes about 25-50 ms a
  /// 640x480 frame here, more than a 30 fps camera leaves when tracking runs
  /// on the same two cores; a raw write is a copy. Needs ~1.5 MB of disk a
  /// 640x480 frame until Finish.
  bool encode_later = false;
};

struct RecorderStats {
  int pushed = 0;       ///< frames offered
  int written = 0;      ///< colour images written (a frame without depth has no depth file)
  int depth_written = 0;
  int dropped = 0;      ///< the queue was full
  int unusable = 0;     ///< no colour (the source said why); not written
  int write_failures = 0;
  int max_queue = 0;    ///< deepest the queue got
  double encode_seconds = 0;  ///< encode_later: the PNG encoding in Finish
  double seconds = 0;   ///< from the first push to the end of Finish
  double first_timestamp_s = 0, last_timestamp_s = 0;
  std::string first_failure;  ///< what the first failed write said
  std::string Summary() const;
};

class SequenceRecorder {
 public:
  /// `out_dir` must not exist or be an empty folder; it is created with
  /// rgb/ and depth/. Throws InputError naming the folder otherwise.
  SequenceRecorder(const std::filesystem::path& out_dir, const RecorderOptions& options = {});
  ~SequenceRecorder();  ///< finishes if Finish was not called
  SequenceRecorder(const SequenceRecorder&) = delete;
  SequenceRecorder& operator=(const SequenceRecorder&) = delete;

  /// Queues a copy of the frame's images (shared, not copied: the caller
  /// must not write into them afterwards). Thread-safe, never blocks.
  void Push(const RgbdFrame& frame);
  /// Writes what is queued, the lists, and returns the figures. Throws
  /// InputError if the lists cannot be written.
  RecorderStats Finish();
  const std::filesystem::path& out_dir() const { return out_dir_; }

 private:
  struct Item {
    double timestamp_s;
    cv::Mat color, depth;
    double depth_scale;
    double depth_delay_s = 0;  ///< RgbdFrame::depth_delay_s: depth.txt lists it at its own time
  };
  std::vector<StampedPose> camera_truth_, body_truth_;  ///< frames that carried truth
  void Write();
  /// Writes one frame's PNGs and lists them (any thread).
  void WritePng(Item item);

  std::filesystem::path out_dir_;
  RecorderOptions options_;
  std::mutex mutex_;
  std::condition_variable ready_;
  std::deque<Item> queue_;
  bool finishing_ = false, finished_ = false;
  RecorderStats stats_;
  std::vector<ImageListEntry> rgb_, depth_;
  struct Spooled {
    double timestamp_s;
    double depth_scale;
    bool has_depth;
    double depth_delay_s;
  };
  std::vector<Spooled> spooled_;  ///< encode_later: frames in .spool/
  std::vector<std::thread> writers_;
  std::chrono::steady_clock::time_point start_;
  bool started_ = false;
};

/// Where a recording into `sequence_dir` belongs (DATASET.md): the case
/// folder is the grandparent for tracking/<name>, else the parent. With a
/// case.yaml there, the camera must have its image size (InputError naming
/// both otherwise) and depth is written in its units. Without one, a
/// case.yaml is written with `camera` and the markers of `markers_from`
/// (`markers_origin` says whose, for the note), and `note` says so.
struct RecordingFolder {
  std::filesystem::path case_dir;
  double depth_scale = 1000;
  std::string note;
};
RecordingFolder PrepareRecordingFolder(const std::filesystem::path& sequence_dir, const CameraIntrinsics& camera,
                                       const CaseConfig& markers_from, const std::string& markers_origin);

}  // namespace arpos
