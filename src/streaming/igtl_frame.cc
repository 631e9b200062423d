#include "streaming/igtl_frame.h"

#include <cmath>

#include <igtlMessageBase.h>
#include <igtlStatusMessage.h>
#include <igtlStringMessage.h>
#include <igtlTimeStamp.h>
#include <igtlTransformMessage.h>

#include "util/check.h"
#include "util/string_util.h"

namespace arpos {

int IgtlStatusCode(CorrectionState state) {
  switch (state) {
    case CorrectionState::kIn: return igtl::StatusMessage::STATUS_OK;
    case CorrectionState::kOut: return igtl::StatusMessage::STATUS_OVERFLOW;
    case CorrectionState::kLost: return igtl::StatusMessage::STATUS_NOT_FOUND;
  }
  return igtl::StatusMessage::STATUS_NOT_FOUND;
}

const char* IgtlStatusErrorName(CorrectionState state) {
  switch (state) {
    case CorrectionState::kIn: return "InTolerance";
    case CorrectionState::kOut: return "OutOfTolerance";
    case CorrectionState::kLost: return "PatientLost";
  }
  return "PatientLost";
}

namespace {
// A value as printed with `decimals`, without "-0.000" for what rounds to zero.
double NoNegativeZero(double value, int decimals) {
  return std::abs(value) < 0.5 * std::pow(10.0, -decimals) ? 0.0 : value;
}
}  // namespace

std::string IgtlCorrectionText(const CouchCorrection& c) {
  if (c.state == CorrectionState::kLost) return "state=lost";
  return StringPrintf(
      "state=%s lateral_mm=%+.3f longitudinal_mm=%+.3f vertical_mm=%+.3f pitch_deg=%+.4f roll_deg=%+.4f "
      "yaw_deg=%+.4f translation_mm=%.3f rotation_deg=%.4f uncertainty_mm=%.3f uncertainty_deg=%.4f",
      CorrectionStateName(c.state), NoNegativeZero(c.lateral_mm, 3), NoNegativeZero(c.longitudinal_mm, 3),
      NoNegativeZero(c.vertical_mm, 3), NoNegativeZero(c.pitch_deg, 4), NoNegativeZero(c.roll_deg, 4), NoNegativeZero(c.yaw_deg, 4),
      NoNegativeZero(c.translation_mm, 3), NoNegativeZero(c.rotation_deg, 4), NoNegativeZero(c.uncertainty.translation_mm, 3),
      NoNegativeZero(c.uncertainty.rotation_deg, 4));
}

namespace {

// Appends a packed message (header and body, CRC computed) to `out`.
void Append(igtl::MessageBase* message, igtl::TimeStamp::Pointer& stamp, IgtlPackedFrame* out) {
  message->SetTimeStamp(stamp);
  message->Pack();
  out->bytes.append(static_cast<const char*>(message->GetPackPointer()),
                    static_cast<std::size_t>(message->GetPackSize()));
  ++out->messages;
}

void AppendTransform(const char* name, const Rigid3d& pose_m, igtl::TimeStamp::Pointer& stamp,
                     IgtlPackedFrame* out) {
  const Eigen::Matrix4d m = pose_m.ToMatrix();
  igtl::Matrix4x4 matrix;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) {
      const double value = (c == 3 && r < 3) ? m(r, c) * 1000.0 : m(r, c);  // metres -> mm
      matrix[r][c] = static_cast<float>(value);
    }
  }
  igtl::TransformMessage::Pointer message = igtl::TransformMessage::New();
  message->SetDeviceName(name);
  message->SetMatrix(matrix);
  Append(message, stamp, out);
}

}  // namespace

IgtlPackedFrame PackIgtlFrame(const IgtlFrame& frame) {
  ARPOS_CHECK(std::isfinite(frame.timestamp_s) && frame.timestamp_s >= 0,
              "OpenIGTLink frame timestamp must be finite and >= 0, not " << frame.timestamp_s);
  igtl::TimeStamp::Pointer stamp = igtl::TimeStamp::New();
  stamp->SetTime(frame.timestamp_s);

  IgtlPackedFrame out;
  out.bytes.reserve(768);
  if (frame.room_from_model) AppendTransform(kIgtlModelToRoom, *frame.room_from_model, stamp, &out);
  AppendTransform(kIgtlTargetToRoom, frame.room_from_model_target, stamp, &out);
  if (frame.room_from_camera) AppendTransform(kIgtlCameraToRoom, *frame.room_from_camera, stamp, &out);

  const CouchCorrection& correction = frame.correction;
  igtl::StatusMessage::Pointer status = igtl::StatusMessage::New();
  status->SetDeviceName(kIgtlToleranceStatus);
  status->SetCode(IgtlStatusCode(correction.state));
  status->SetSubCode(0);
  status->SetErrorName(IgtlStatusErrorName(correction.state));
  status->SetStatusString(DescribeCorrection(correction).c_str());
  Append(status, stamp, &out);

  igtl::StringMessage::Pointer text = igtl::StringMessage::New();
  text->SetDeviceName(kIgtlCorrectionString);
  text->SetString(IgtlCorrectionText(correction).c_str());
  Append(text, stamp, &out);
  return out;
}

}  // namespace arpos
