#pragma once
/// TUM RGB-D files (DATASET.md): image lists and trajectories.

#include <filesystem>
#include <string>
#include <vector>

#include "geometry/rigid3.h"

namespace arpos {

/// One line of rgb.txt / depth.txt: "timestamp relative/path.png".
struct ImageListEntry {
  double timestamp_s = 0;
  std::string relative_path;
  int line = 0;  ///< 1-based line in the list file, for messages
};

/// Reads a TUM image list; '#' lines and blank lines are skipped. Throws
/// InputError naming the file and line for a malformed line. Timestamps are
/// not required to be monotonic here (case checks report that).
std::vector<ImageListEntry> ReadImageList(const std::filesystem::path& path);
void WriteImageList(const std::filesystem::path& path, const std::vector<ImageListEntry>& entries,
                    const std::string& header_comment);

/// Frames of a recording further apart than this (median) are not a video
/// with timestamps in seconds (DATASET.md): a list in microseconds or
/// nanoseconds reads as frames hours to years apart, and every window
/// counted in seconds (colour-depth association, carried poses, the patient
/// jump check) would silently stop working. Stills of a walk can be tens of
/// seconds apart (a few frames of a 30 s room recording), so milliseconds
/// at video rate (33 "s" apart) cannot be told from them and pass.
constexpr double kMaxMedianFrameSpacingS = 100.0;

/// What is wrong with an image list's timestamps as frame times, "" when
/// nothing: not strictly increasing in list order (frames are used in list
/// order as time order; names the line), or a median spacing beyond
/// kMaxMedianFrameSpacingS (says which unit they look like). The one rule
/// for `arpos check` and every stage that opens a sequence.
std::string ImageListTimestampProblem(const std::vector<ImageListEntry>& entries);

/// One pose of a TUM trajectory: `room_from_x` maps the moving frame x into the room.
struct StampedPose {
  double timestamp_s = 0;
  Rigid3d room_from_x;
};

/// Reads "timestamp tx ty tz qx qy qz qw" lines. Throws InputError naming file
/// and line for a malformed line, a value that is not finite (naming the
/// field and the value, e.g. "tz is 'nan'"), or a quaternion far from unit
/// norm (|q| not within 1e-3 of 1; smaller deviations are normalised).
std::vector<StampedPose> ReadTrajectory(const std::filesystem::path& path);
/// Writes atomically with full precision (timestamps to 1e-6 s, 9 digits).
void WriteTrajectory(const std::filesystem::path& path, const std::vector<StampedPose>& poses,
                     const std::string& header_comment = "");

/// Reads a 4x4 row-major matrix (16 numbers, whitespace separated, '#'
/// comments allowed), e.g. target_pose.txt. Throws InputError naming the file.
Eigen::Matrix4d ReadMatrix4(const std::filesystem::path& path);
void WriteMatrix4(const std::filesystem::path& path, const Eigen::Matrix4d& matrix,
                  const std::string& header_comment = "");

/// Pairs of indices (i into a, j into b) whose timestamps differ by at most
/// `max_difference_s`, each index used at most once, greedy by smallest
/// difference (the TUM associate.py rule). Sorted by i.
std::vector<std::pair<size_t, size_t>> AssociateTimestamps(const std::vector<double>& a,
                                                           const std::vector<double>& b,
                                                           double max_difference_s);

}  // namespace arpos
