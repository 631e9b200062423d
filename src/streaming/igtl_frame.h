#pragma once
/// What ARPos streams to OpenIGTLink clients (3D Slicer's OpenIGTLinkIF, PLUS,
/// any igtl client) for one tracked camera frame, and how it is encoded.
///
/// Messages of one frame, in this order, all with the frame's timestamp in
/// their header (igtl::TimeStamp, seconds of the recording clock):
///   TRANSFORM "ModelToRoom"   room_from_model; only when the patient is tracked
///   TRANSFORM "TargetToRoom"  room_from_model_target (the planned pose)
///   TRANSFORM "CameraToRoom"  room_from_camera; only when the camera is localised
///   STATUS    "Tolerance"     the tolerance state (see IgtlStatusCode)
///   STRING    "Correction"    the couch correction (see IgtlCorrectionText)
/// Transform names follow PLUS (`FromToTo`: "ModelToRoom" maps model
/// coordinates into the room, i.e. our room_from_model), so in Slicer the
/// transform node of that name moves the patient model, in model coordinates,
/// into the room (Slicer's world). Matrices are 4x4 rigid transforms with the
/// translation in MILLIMETRES (OpenIGTLink's and Slicer's unit; ARPos poses are
/// in metres), sent as the protocol's 32-bit floats.
///
/// Free of OpenIGTLink headers: callers need no igtl include.

#include <chrono>
#include <optional>
#include <string>

#include "feedback/couch_correction.h"
#include "geometry/rigid3.h"

namespace arpos {

/// Device names (at most 20 characters, the protocol's limit).
inline constexpr const char* kIgtlModelToRoom = "ModelToRoom";
inline constexpr const char* kIgtlTargetToRoom = "TargetToRoom";
inline constexpr const char* kIgtlCameraToRoom = "CameraToRoom";
inline constexpr const char* kIgtlToleranceStatus = "Tolerance";
inline constexpr const char* kIgtlCorrectionString = "Correction";

/// One camera frame's tracking result.
struct IgtlFrame {
  /// The frame's timestamp (recording clock, seconds, finite and >= 0); goes
  /// into every message's header time stamp.
  double timestamp_s = 0;
  std::optional<Rigid3d> room_from_model;   ///< TRANSFORM ModelToRoom; absent when the patient is lost
  Rigid3d room_from_model_target;           ///< TRANSFORM TargetToRoom
  std::optional<Rigid3d> room_from_camera;  ///< TRANSFORM CameraToRoom; absent when not localised
  CouchCorrection correction;               ///< STATUS Tolerance + STRING Correction
  /// When the camera frame arrived: IgtlServer's latency is counted from here.
  /// Left default (the clock's epoch), it is counted from the call to Send.
  std::chrono::steady_clock::time_point arrival;
};

/// The STATUS message's code for a tolerance state (OpenIGTLink status codes):
///   in   -> 1 (STATUS_OK)        error name "InTolerance"
///   out  -> 8 (STATUS_OVERFLOW, "over a limit / can't be reached")
///                                error name "OutOfTolerance"
///   lost -> 4 (STATUS_NOT_FOUND, the patient is not found)
///                                error name "PatientLost"
/// Sub code 0. A client that only checks "code is OK" thus reads "in
/// tolerance"; the status string is DescribeCorrection's line for a person.
int IgtlStatusCode(CorrectionState state);
const char* IgtlStatusErrorName(CorrectionState state);

/// The STRING message's text (US-ASCII, one line, `key=value` separated by
/// single spaces, in this order):
///   state=in lateral_mm=+1.200 longitudinal_mm=-0.500 vertical_mm=+0.300
///   pitch_deg=+0.1000 roll_deg=-0.2000 yaw_deg=+0.0500 translation_mm=1.393
///   rotation_deg=0.2291 uncertainty_mm=0.400 uncertainty_deg=0.1000
/// (on one line). state is in / out / lost; the six components are the couch
/// motion to apply (as corrections.csv: lateral, longitudinal, vertical mm;
/// pitch, roll, yaw deg) with a sign; translation_mm and rotation_deg are the
/// correction's magnitude, uncertainty_* the bound the state was decided
/// with. Millimetres to 3 decimals, degrees to 4 (as corrections.csv), never
/// "-0.000". A lost frame is just "state=lost".
std::string IgtlCorrectionText(const CouchCorrection& correction);

/// The frame's messages packed back to back, as they go on the wire.
struct IgtlPackedFrame {
  std::string bytes;
  int messages = 0;
};
/// Throws arpos::Error if the timestamp is negative or not finite.
IgtlPackedFrame PackIgtlFrame(const IgtlFrame& frame);

}  // namespace arpos
