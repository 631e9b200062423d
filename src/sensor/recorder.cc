#include "sensor/recorder.h"

#include <algorithm>
#include <atomic>
#include <fstream>
#include <set>
#include <opencv2/imgcodecs.hpp>

#include "util/check.h"
#include "util/file.h"
#include "util/string_util.h"

namespace arpos {

std::string RecorderStats::Summary() const {
  std::string s = StringPrintf("%d frames written (%d with depth) of %d captured; %d dropped (writer behind)", written,
                               depth_written, pushed, dropped);
  if (unusable) s += StringPrintf("; %d without colour not written", unusable);
  if (write_failures) s += StringPrintf("; %d could not be written (%s)", write_failures, first_failure.c_str());
  const double span = last_timestamp_s - first_timestamp_s;
  if (pushed > 1 && span > 0) s += StringPrintf("; %.1f s recorded, %.1f fps captured", span, (pushed - 1) / span);
  s += StringPrintf("; queue at most %d", max_queue);
  if (encode_seconds > 0) s += StringPrintf("; PNGs encoded after capture in %.1f s", encode_seconds);
  return s;
}

SequenceRecorder::SequenceRecorder(const std::filesystem::path& out_dir, const RecorderOptions& options)
    : out_dir_(out_dir), options_(options) {
  std::error_code ec;
  if (std::filesystem::exists(out_dir_, ec)) {
    if (!std::filesystem::is_directory(out_dir_, ec) || !std::filesystem::is_empty(out_dir_, ec)) {
      ARPOS_INPUT_ERROR(out_dir_.string() << ": exists and is not an empty folder; record into a new folder");
    }
  }
  for (const char* sub : {"rgb", "depth", options_.encode_later ? ".spool" : "rgb"}) {
    std::filesystem::create_directories(out_dir_ / sub, ec);
    if (ec) ARPOS_INPUT_ERROR(out_dir_.string() << ": cannot create " << sub << "/ (" << ec.message() << ")");
  }
  const int threads = std::max(1, options_.writer_threads);
  for (int i = 0; i < threads; ++i) writers_.emplace_back([this] { Write(); });
}

SequenceRecorder::~SequenceRecorder() {
  try {
    Finish();
  } catch (...) {
  }
}

void SequenceRecorder::Push(const RgbdFrame& frame) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (finishing_) return;
  if (!started_) {
    started_ = true;
    start_ = std::chrono::steady_clock::now();
    stats_.first_timestamp_s = frame.timestamp_s;
  }
  ++stats_.pushed;
  stats_.last_timestamp_s = frame.timestamp_s;
  if (frame.color.empty()) {
    ++stats_.unusable;
    return;
  }
  if (static_cast<int>(queue_.size()) >= std::max(1, options_.queue_frames)) {
    ++stats_.dropped;
    return;
  }
  queue_.push_back({frame.timestamp_s, frame.color, frame.depth, frame.depth_scale,
                    frame.depth.empty() ? 0.0 : frame.depth_delay_s});
  if (frame.true_room_from_camera) camera_truth_.push_back({frame.timestamp_s, *frame.true_room_from_camera});
  if (frame.true_room_from_model) body_truth_.push_back({frame.timestamp_s, *frame.true_room_from_model});
  stats_.max_queue = std::max(stats_.max_queue, static_cast<int>(queue_.size()));
  ready_.notify_one();
}

namespace {

// A raw image file of the spool: rows, cols, type, then the pixels.
bool WriteRaw(const std::filesystem::path& path, const cv::Mat& image) {
  std::ofstream out(path, std::ios::binary);
  const int header[3] = {image.rows, image.cols, image.type()};
  out.write(reinterpret_cast<const char*>(header), sizeof header);
  const cv::Mat whole = image.isContinuous() ? image : image.clone();
  out.write(reinterpret_cast<const char*>(whole.data), static_cast<std::streamsize>(whole.total() * whole.elemSize()));
  return static_cast<bool>(out);
}

cv::Mat ReadRaw(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  int header[3] = {0, 0, 0};
  in.read(reinterpret_cast<char*>(header), sizeof header);
  if (!in || header[0] <= 0 || header[1] <= 0) return {};
  cv::Mat image(header[0], header[1], header[2]);
  in.read(reinterpret_cast<char*>(image.data), static_cast<std::streamsize>(image.total() * image.elemSize()));
  return in ? image : cv::Mat();
}

}  // namespace

void SequenceRecorder::Write() {
  for (;;) {
    Item item;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      ready_.wait(lock, [&] { return !queue_.empty() || finishing_; });
      if (queue_.empty()) return;
      item = std::move(queue_.front());
      queue_.pop_front();
    }
    if (!options_.encode_later) {
      WritePng(std::move(item));
      continue;
    }
    const std::string stem = StringPrintf("%.6f", item.timestamp_s);
    const std::filesystem::path spool = out_dir_ / ".spool";
    const bool ok = WriteRaw(spool / (stem + ".colour"), item.color) &&
                    (item.depth.empty() || WriteRaw(spool / (stem + ".depth"), item.depth));
    std::lock_guard<std::mutex> lock(mutex_);
    if (ok) {
      spooled_.push_back(
          {item.timestamp_s, item.depth_scale, !item.depth.empty(), item.depth_delay_s});
    } else {
      ++stats_.write_failures;
      if (stats_.first_failure.empty()) stats_.first_failure = (spool / stem).string() + ": could not be written";
    }
  }
}

void SequenceRecorder::WritePng(Item item) {
  const std::vector<int> png = {cv::IMWRITE_PNG_COMPRESSION, options_.png_compression};
  const std::string name = StringPrintf("%.6f.png", item.timestamp_s);
  bool colour_ok = false, depth_ok = false;
  std::string failure;
  try {
    colour_ok = cv::imwrite((out_dir_ / "rgb" / name).string(), item.color, png);
    if (!colour_ok) failure = (out_dir_ / "rgb" / name).string() + ": could not be written";
    if (colour_ok && !item.depth.empty()) {
      // Converted into a new image: the frame's own is shared with the caller.
      cv::Mat depth;
      if (options_.depth_scale > 0 && std::abs(item.depth_scale - options_.depth_scale) > 1e-9) {
        item.depth.convertTo(depth, CV_16U, options_.depth_scale / item.depth_scale);
      } else {
        depth = item.depth;
      }
      depth_ok = cv::imwrite((out_dir_ / "depth" / name).string(), depth, png);
      if (!depth_ok) failure = (out_dir_ / "depth" / name).string() + ": could not be written";
    }
  } catch (const cv::Exception& e) {
    failure = e.what();
  }
  std::lock_guard<std::mutex> lock(mutex_);
  if (colour_ok) {
    ++stats_.written;
    rgb_.push_back({item.timestamp_s, "rgb/" + name, 0});
  }
  if (depth_ok) {
    ++stats_.depth_written;
    // At the depth's own instant when the source knows it (a camera without
    // colour-depth sync): the reader hands the delay on (depth_timing.h).
    depth_.push_back({item.timestamp_s + item.depth_delay_s, "depth/" + name, 0});
  }
  if (!failure.empty()) {
    ++stats_.write_failures;
    if (stats_.first_failure.empty()) stats_.first_failure = failure;
  }
}

RecorderStats SequenceRecorder::Finish() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (finished_) return stats_;
    finishing_ = true;
    ready_.notify_all();
  }
  for (auto& t : writers_) t.join();
  writers_.clear();
  if (options_.encode_later) {
    // The spool to PNGs, on every writer thread, then gone.
    const auto encode_start = std::chrono::steady_clock::now();
    std::atomic<size_t> next{0};
    std::vector<std::thread> encoders;
    for (int t = 0; t < std::max(1, options_.writer_threads); ++t) {
      encoders.emplace_back([&] {
        for (size_t k = next++; k < spooled_.size(); k = next++) {
          const Spooled& s = spooled_[k];
          const std::string stem = StringPrintf("%.6f", s.timestamp_s);
          Item item{s.timestamp_s, ReadRaw(out_dir_ / ".spool" / (stem + ".colour")),
                    s.has_depth ? ReadRaw(out_dir_ / ".spool" / (stem + ".depth")) : cv::Mat(),
                    s.depth_scale, s.depth_delay_s};
          if (item.color.empty()) {
            std::lock_guard<std::mutex> lock(mutex_);
            ++stats_.write_failures;
            if (stats_.first_failure.empty()) stats_.first_failure = stem + ": the spooled frame could not be read";
            continue;
          }
          WritePng(std::move(item));
        }
      });
    }
    for (auto& t : encoders) t.join();
    std::error_code ec;
    std::filesystem::remove_all(out_dir_ / ".spool", ec);
    stats_.encode_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - encode_start).count();
  }
  std::lock_guard<std::mutex> lock(mutex_);
  finished_ = true;
  const auto by_time = [](const ImageListEntry& a, const ImageListEntry& b) { return a.timestamp_s < b.timestamp_s; };
  std::sort(rgb_.begin(), rgb_.end(), by_time);
  std::sort(depth_.begin(), depth_.end(), by_time);
  WriteImageList(out_dir_ / "rgb.txt", rgb_, "colour images (arpos record)");
  WriteImageList(out_dir_ / "depth.txt", depth_, "depth images (arpos record)");
  // Truth of the frames written only (a dropped frame has no images).
  std::set<double> written;
  for (const ImageListEntry& e : rgb_) written.insert(e.timestamp_s);
  const auto kept = [&](std::vector<StampedPose> poses) {
    poses.erase(std::remove_if(poses.begin(), poses.end(),
                               [&](const StampedPose& p) { return written.count(p.timestamp_s) == 0; }),
                poses.end());
    std::sort(poses.begin(), poses.end(),
              [](const StampedPose& a, const StampedPose& b) { return a.timestamp_s < b.timestamp_s; });
    return poses;
  };
  if (!camera_truth_.empty()) {
    WriteTrajectory(out_dir_ / "groundtruth.txt", kept(camera_truth_), "arpos record: true room_from_camera (the source's)");
  }
  if (!body_truth_.empty()) {
    WriteTrajectory(out_dir_ / "body_groundtruth.txt", kept(body_truth_),
                    "arpos record: true room_from_model (the source's)");
  }
  if (started_) stats_.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  return stats_;
}

RecordingFolder PrepareRecordingFolder(const std::filesystem::path& sequence_dir, const CameraIntrinsics& camera,
                                       const CaseConfig& markers_from, const std::string& markers_origin) {
  const std::filesystem::path dir = std::filesystem::absolute(sequence_dir).lexically_normal();
  RecordingFolder folder;
  folder.case_dir = dir.parent_path().filename() == "tracking" ? dir.parent_path().parent_path() : dir.parent_path();
  const std::filesystem::path yaml = folder.case_dir / "case.yaml";
  if (std::filesystem::exists(yaml)) {
    const CaseConfig config = LoadCaseConfig(yaml);
    if (config.camera.width != camera.width || config.camera.height != camera.height) {
      ARPOS_INPUT_ERROR(yaml.string() << ": its camera is " << config.camera.width << "x" << config.camera.height
                                      << " but the source gives " << camera.width << "x" << camera.height
                                      << " images; record into another case folder");
    }
    folder.depth_scale = config.camera.depth_scale;
    return folder;
  }
  CaseConfig config = markers_from;
  config.camera = camera;
  const std::string problem = ValidateCaseConfig(config);
  if (!problem.empty()) ARPOS_INPUT_ERROR("the source's camera cannot describe a case: " << problem);
  std::error_code ec;
  std::filesystem::create_directories(folder.case_dir, ec);
  if (ec) ARPOS_INPUT_ERROR(folder.case_dir.string() << ": cannot create the case folder (" << ec.message() << ")");
  SaveCaseConfig(config, yaml);
  folder.depth_scale = camera.depth_scale;
  folder.note = "wrote " + yaml.string() + " with the source's camera and the markers of " + markers_origin + " (" +
                config.dictionary + "); edit it if your printed markers differ";
  return folder;
}

}  // namespace arpos
