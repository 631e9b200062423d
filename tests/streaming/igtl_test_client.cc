#include "streaming/igtl_test_client.h"

#include <cmath>

#include <igtlClientSocket.h>
#include <igtlMessageHeader.h>
#include <igtlStatusMessage.h>
#include <igtlStringMessage.h>
#include <igtlTimeStamp.h>
#include <igtlTransformMessage.h>

namespace arpos::testing {

IgtlFrame TestFrame(int index) {
  const double i = index;
  IgtlFrame frame;
  frame.timestamp_s = 100.25 + i / 30.0;
  const auto pose = [&](double offset_m, const Eigen::Vector3d& axis, double deg) {
    return Rigid3d::FromRotationVector(axis.normalized() * deg * 3.14159265358979323846 / 180,
                                       Eigen::Vector3d(0.812345 + 0.0175 * i + offset_m, -0.204 - 0.003 * i,
                                                       1.1235 + 0.001 * i));
  };
  if (index % 3 != 2) frame.room_from_model = pose(0, Eigen::Vector3d(0.3, 1, 0.2 * i), 4 + i);
  frame.room_from_model_target = pose(0.0005, Eigen::Vector3d(0, 0, 1), 90);
  if (index % 4 != 3) frame.room_from_camera = pose(-1.5, Eigen::Vector3d(1, -0.5, 0.1), 120 + 3 * i);
  if (frame.room_from_model) {
    CouchCorrection& c = frame.correction;
    c.lateral_mm = 0.5 + i;
    c.longitudinal_mm = -0.25 * i;
    c.vertical_mm = 0.125;
    c.pitch_deg = 0.1 * i;
    c.roll_deg = -0.2;
    c.yaw_deg = 0.05;
    c.translation_mm = std::sqrt(c.lateral_mm * c.lateral_mm + c.longitudinal_mm * c.longitudinal_mm +
                                 c.vertical_mm * c.vertical_mm);
    c.rotation_deg = 0.3 + 0.1 * i;
    c.uncertainty = {0.4, 0.1};
    c.state = index % 2 == 0 ? CorrectionState::kIn : CorrectionState::kOut;
  } else {
    frame.correction = LostCorrection();
  }
  frame.arrival = std::chrono::steady_clock::now();
  return frame;
}

Eigen::Matrix4d MatrixMm(const Rigid3d& pose) {
  Eigen::Matrix4d m = pose.ToMatrix();
  m.block<3, 1>(0, 3) *= 1000.0;
  return m;
}

int MessageCount(const IgtlFrame& frame) {
  return (frame.room_from_model ? 1 : 0) + 1 + (frame.room_from_camera ? 1 : 0) + 2;
}

struct IgtlTestClient::Impl {
  igtl::ClientSocket::Pointer socket = igtl::ClientSocket::New();
  igtl::MessageHeader::Pointer header = igtl::MessageHeader::New();
  bool connected = false;

  // Receives the body of `message` (whose header is `header`) and unpacks it.
  template <typename Message>
  bool ReceiveBody(Message& message, IgtlReceived* out) {
    message->SetMessageHeader(header);
    message->AllocatePack();
    const int size = message->GetPackBodySize();
    if (size > 0 && socket->Receive(message->GetPackBodyPointer(), size) != size) return false;
    out->crc_ok = (message->Unpack(1) & igtl::MessageHeader::UNPACK_BODY) != 0;
    return true;
  }
};

IgtlTestClient::IgtlTestClient() : impl_(std::make_unique<Impl>()) {}
IgtlTestClient::~IgtlTestClient() { Close(); }

bool IgtlTestClient::Connect(int port, double timeout_s) {
  if (impl_->socket->ConnectToServer("127.0.0.1", port) != 0) return false;
  impl_->connected = true;
  impl_->socket->SetReceiveTimeout(static_cast<int>(std::ceil(timeout_s * 1000)));
  return true;
}

std::optional<IgtlReceived> IgtlTestClient::Receive() {
  if (!impl_->connected) return std::nullopt;
  igtl::MessageHeader::Pointer& header = impl_->header;
  header->InitPack();
  if (impl_->socket->Receive(header->GetPackPointer(), header->GetPackSize()) != header->GetPackSize()) {
    return std::nullopt;
  }
  header->Unpack();
  IgtlReceived out;
  out.type = header->GetDeviceType();
  out.device = header->GetDeviceName();
  igtl::TimeStamp::Pointer stamp = igtl::TimeStamp::New();
  header->GetTimeStamp(stamp);
  igtlUint32 seconds = 0, nanoseconds = 0;
  stamp->GetTimeStamp(&seconds, &nanoseconds);
  out.timestamp_s = seconds + nanoseconds * 1e-9;

  if (out.type == "TRANSFORM") {
    igtl::TransformMessage::Pointer message = igtl::TransformMessage::New();
    if (!impl_->ReceiveBody(message, &out)) return std::nullopt;
    igtl::Matrix4x4 matrix;
    message->GetMatrix(matrix);
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) out.matrix(r, c) = matrix[r][c];
    }
  } else if (out.type == "STATUS") {
    igtl::StatusMessage::Pointer message = igtl::StatusMessage::New();
    if (!impl_->ReceiveBody(message, &out)) return std::nullopt;
    out.status_code = message->GetCode();
    out.error_name = message->GetErrorName();
    out.status_text = message->GetStatusString();
  } else if (out.type == "STRING") {
    igtl::StringMessage::Pointer message = igtl::StringMessage::New();
    if (!impl_->ReceiveBody(message, &out)) return std::nullopt;
    out.text = message->GetString();
  } else {
    impl_->socket->Skip(header->GetBodySizeToRead(), 1);
  }
  return out;
}

void IgtlTestClient::Close() {
  if (impl_->connected) impl_->socket->CloseSocket();
  impl_->connected = false;
}

}  // namespace arpos::testing
