#pragma once
// An in-process OpenIGTLink client for the streaming tests and benchmark: an
// igtl::ClientSocket on 127.0.0.1 that reads and decodes one message at a
// time, every read bounded by a timeout; and frames with known, distinct
// content to send.

#include <memory>
#include <optional>
#include <string>

#include <Eigen/Core>

#include "streaming/igtl_frame.h"

namespace arpos::testing {

/// Frame `index` of a made-up stream: distinct poses and corrections;
/// every third frame (2, 5, ...) lost (no ModelToRoom, correction lost), every
/// fourth (3, 7, ...) without CameraToRoom; translations whole micrometres.
IgtlFrame TestFrame(int index);
/// The 4x4 matrix OpenIGTLink carries for `pose`: translation in mm.
Eigen::Matrix4d MatrixMm(const Rigid3d& pose);
/// How many messages the server sends for `frame`.
int MessageCount(const IgtlFrame& frame);

struct IgtlReceived {
  std::string type;    ///< TRANSFORM, STATUS, STRING, or another type (body skipped)
  std::string device;  ///< device name
  double timestamp_s = 0;
  bool crc_ok = false;
  Eigen::Matrix4d matrix = Eigen::Matrix4d::Zero();  ///< TRANSFORM, as sent (mm)
  int status_code = 0;                               ///< STATUS
  std::string error_name, status_text;               ///< STATUS
  std::string text;                                  ///< STRING
};

class IgtlTestClient {
 public:
  IgtlTestClient();
  ~IgtlTestClient();
  /// Connects to 127.0.0.1:port; every later read waits at most timeout_s.
  bool Connect(int port, double timeout_s);
  /// The next message, or nothing on timeout, a closed connection or a bad header.
  std::optional<IgtlReceived> Receive();
  void Close();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace arpos::testing
