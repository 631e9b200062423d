#include "store/records.h"

#include <cmath>
#include <sstream>
#include <utility>

#include "util/check.h"

namespace arpos {
namespace {

template <typename Enum, std::size_t N>
Enum ParseEnum(const std::string& text, const std::pair<Enum, const char*> (&names)[N],
               const char* what) {
  for (const auto& [value, name] : names) {
    if (text == name) return value;
  }
  std::ostringstream known;
  for (std::size_t i = 0; i < N; ++i) known << (i > 0 ? ", " : "") << names[i].second;
  throw Error("unknown " + std::string(what) + " '" + text + "' (known: " + known.str() + ")");
}

template <typename Enum, std::size_t N>
const char* EnumName(Enum value, const std::pair<Enum, const char*> (&names)[N]) {
  for (const auto& [candidate, name] : names) {
    if (candidate == value) return name;
  }
  return "invalid";
}

// The spellings are the schema's CHECK lists: change both together.
constexpr std::pair<SessionStatus, const char*> kSessionStatusNames[] = {
    {SessionStatus::kOpen, "open"},
    {SessionStatus::kCompleted, "completed"},
    {SessionStatus::kAborted, "aborted"}};
constexpr std::pair<RecordingKind, const char*> kRecordingKindNames[] = {
    {RecordingKind::kRoom, "room"},
    {RecordingKind::kBodyScan, "body_scan"},
    {RecordingKind::kTracking, "tracking"}};
constexpr std::pair<AlignmentMethod, const char*> kAlignmentMethodNames[] = {
    {AlignmentMethod::kManual, "manual"},
    {AlignmentMethod::kIcp, "icp"},
    {AlignmentMethod::kAutomatic, "automatic"}};
constexpr std::pair<TrackingFrameStatus, const char*> kTrackingFrameStatusNames[] = {
    {TrackingFrameStatus::kInTolerance, "in_tolerance"},
    {TrackingFrameStatus::kOutOfTolerance, "out_of_tolerance"},
    {TrackingFrameStatus::kLost, "lost"}};

}  // namespace

const char* ToString(SessionStatus status) { return EnumName(status, kSessionStatusNames); }
const char* ToString(RecordingKind kind) { return EnumName(kind, kRecordingKindNames); }
const char* ToString(AlignmentMethod method) { return EnumName(method, kAlignmentMethodNames); }
const char* ToString(TrackingFrameStatus status) {
  return EnumName(status, kTrackingFrameStatusNames);
}

SessionStatus ParseSessionStatus(const std::string& text) {
  return ParseEnum(text, kSessionStatusNames, "session status");
}
RecordingKind ParseRecordingKind(const std::string& text) {
  return ParseEnum(text, kRecordingKindNames, "recording kind");
}
AlignmentMethod ParseAlignmentMethod(const std::string& text) {
  return ParseEnum(text, kAlignmentMethodNames, "alignment method");
}
TrackingFrameStatus ParseTrackingFrameStatus(const std::string& text) {
  return ParseEnum(text, kTrackingFrameStatusNames, "tracking frame status");
}

std::optional<RoomFrameSigmas> RoomFrameSigmasOf(const RoomMapRecord& map) {
  const auto usable = [](const std::optional<double>& v) {
    return v && std::isfinite(*v) && *v >= 0;
  };
  if (!usable(map.room_frame_couch_sigma_mm) || !usable(map.room_frame_tilt_sigma_deg) ||
      !usable(map.room_frame_yaw_sigma_deg)) {
    return std::nullopt;
  }
  return RoomFrameSigmas{*map.room_frame_couch_sigma_mm,
                         std::hypot(*map.room_frame_tilt_sigma_deg, *map.room_frame_yaw_sigma_deg)};
}

}  // namespace arpos
