#pragma once
/// Binary encodings of the store's BLOB columns.
///
/// Every blob is a 16-byte header followed by a payload; all numbers are
/// little-endian whatever the host, floats are IEEE 754:
///
///   offset size  field
///   0      4     magic "ARPB"
///   4      1     format version, 1
///   5      1     type: 1 float64 matrix, 2 uint8 matrix, 3 point cloud,
///                      4 triangle mesh
///   6      2     flags (uint16): point cloud bit 0 = normals, bit 1 = colours;
///                0 for the other types
///   8      4     rows (uint32)
///   12     4     cols (uint32)
///
/// Payloads:
///   float64 matrix  rows*cols float64, row-major (row 0 first)
///   uint8 matrix    rows*cols bytes, row-major
///   point cloud     rows = N points, cols = 3; N*3 float32 positions (x y z per
///                   point), then if flagged N*3 float32 normals, then if
///                   flagged N*3 uint8 colours (R G B)
///   triangle mesh   rows = V vertices, cols = F faces; V*3 float32 positions,
///                   then F*3 uint32 vertex indices
///
/// A pose (Rigid3d b_from_a) is stored as its 4x4 homogeneous matrix.
///
/// Decoding checks the header, that the blob is exactly as long as the header
/// says, that point and vertex coordinates are finite, that mesh indices are
/// below V and that a pose is a rigid transform; on any failure it throws
/// CorruptBlobError whose message starts with the caller's `context` (e.g.
/// "plans.room_from_model_target of plan 3") and says what is wrong. float64
/// matrices may hold any value, NaN included.
///
/// Thread-safety: pure functions, safe from any thread.

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "geometry/rigid3.h"
#include "store/records.h"
#include "util/check.h"

namespace arpos {

using Blob = std::vector<std::uint8_t>;

/// A blob that does not decode: truncated, wrong type, bad indices, ...
class CorruptBlobError : public Error {
 public:
  explicit CorruptBlobError(const std::string& message) : Error(message) {}
};

/// The kinds of blob, as in header byte 5.
enum class BlobType : std::uint8_t {
  kFloat64Matrix = 1,
  kUint8Matrix = 2,
  kPointCloud = 3,
  kTriangleMesh = 4,
};

constexpr std::size_t kBlobHeaderSize = 16;

Blob EncodeMatrix(const Eigen::MatrixXd& matrix);
Eigen::MatrixXd DecodeMatrix(const Blob& blob, std::string_view context);

Blob EncodeByteMatrix(const ByteMatrix& matrix);
ByteMatrix DecodeByteMatrix(const Blob& blob, std::string_view context);

/// 4x4 float64 matrix of `b_from_a`.
Blob EncodePose(const Rigid3d& b_from_a);
/// Also requires 4x4 and a rigid transform (tolerance 1e-6).
Rigid3d DecodePose(const Blob& blob, std::string_view context);

/// Throws arpos::Error if normals/colors are neither empty nor one per point.
Blob EncodePointCloud(const StoredPointCloud& cloud);
StoredPointCloud DecodePointCloud(const Blob& blob, std::string_view context);

/// Throws arpos::Error if a face index is out of range.
Blob EncodeTriangleMesh(const StoredTriangleMesh& mesh);
StoredTriangleMesh DecodeTriangleMesh(const Blob& blob, std::string_view context);

}  // namespace arpos
