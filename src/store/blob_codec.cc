#include "store/blob_codec.h"

#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>

namespace arpos {
namespace {

constexpr std::uint8_t kMagic[4] = {'A', 'R', 'P', 'B'};
constexpr std::uint8_t kFormatVersion = 1;
constexpr std::uint16_t kCloudHasNormals = 1u << 0;
constexpr std::uint16_t kCloudHasColors = 1u << 1;

const char* TypeName(std::uint8_t type) {
  switch (type) {
    case 1:
      return "float64 matrix";
    case 2:
      return "uint8 matrix";
    case 3:
      return "point cloud";
    case 4:
      return "triangle mesh";
    default:
      return "unknown type";
  }
}

[[noreturn]] void ThrowCorrupt(std::string_view context, const std::string& what) {
  std::ostringstream out;
  out << context << ": corrupt blob: " << what;
  throw CorruptBlobError(out.str());
}

// Writes bytes in little-endian order whatever the host (shifts, not memcpy of
// the integer, so the code is endian-neutral).
class Writer {
 public:
  explicit Writer(std::size_t capacity) { blob_.reserve(capacity); }
  void U8(std::uint8_t v) { blob_.push_back(v); }
  void U16(std::uint16_t v) {
    for (int i = 0; i < 2; ++i) blob_.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  }
  void U32(std::uint32_t v) {
    for (int i = 0; i < 4; ++i) blob_.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  }
  void U64(std::uint64_t v) {
    for (int i = 0; i < 8; ++i) blob_.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  }
  void F32(float v) {
    std::uint32_t bits;
    std::memcpy(&bits, &v, sizeof bits);
    U32(bits);
  }
  void F64(double v) {
    std::uint64_t bits;
    std::memcpy(&bits, &v, sizeof bits);
    U64(bits);
  }
  void Header(BlobType type, std::uint16_t flags, std::uint64_t rows, std::uint64_t cols) {
    ARPOS_CHECK(rows <= std::numeric_limits<std::uint32_t>::max() &&
                    cols <= std::numeric_limits<std::uint32_t>::max(),
                "blob dimensions " << rows << " x " << cols << " exceed the 32-bit header");
    for (std::uint8_t m : kMagic) U8(m);
    U8(kFormatVersion);
    U8(static_cast<std::uint8_t>(type));
    U16(flags);
    U32(static_cast<std::uint32_t>(rows));
    U32(static_cast<std::uint32_t>(cols));
  }
  Blob Take() { return std::move(blob_); }

 private:
  Blob blob_;
};

class Reader {
 public:
  Reader(const Blob& blob, std::size_t offset) : blob_(blob), pos_(offset) {}
  std::uint8_t U8() { return blob_[pos_++]; }
  std::uint32_t U32() {
    std::uint32_t v = 0;
    for (int i = 0; i < 4; ++i) v |= static_cast<std::uint32_t>(blob_[pos_++]) << (8 * i);
    return v;
  }
  std::uint64_t U64() {
    std::uint64_t v = 0;
    for (int i = 0; i < 8; ++i) v |= static_cast<std::uint64_t>(blob_[pos_++]) << (8 * i);
    return v;
  }
  float F32() {
    const std::uint32_t bits = U32();
    float v;
    std::memcpy(&v, &bits, sizeof v);
    return v;
  }
  double F64() {
    const std::uint64_t bits = U64();
    double v;
    std::memcpy(&v, &bits, sizeof v);
    return v;
  }

 private:
  const Blob& blob_;
  std::size_t pos_;
};

struct Header {
  std::uint16_t flags = 0;
  std::uint64_t rows = 0;
  std::uint64_t cols = 0;
};

// Checks magic, version and type; returns flags and dimensions. Sizes are
// checked by the caller, which knows the payload layout.
Header ReadHeader(const Blob& blob, BlobType expected, std::string_view context) {
  if (blob.size() < kBlobHeaderSize) {
    ThrowCorrupt(context, "only " + std::to_string(blob.size()) + " bytes, shorter than the " +
                              std::to_string(kBlobHeaderSize) + "-byte header");
  }
  if (std::memcmp(blob.data(), kMagic, sizeof kMagic) != 0) {
    ThrowCorrupt(context, "bad magic (not an ARPos blob)");
  }
  if (blob[4] != kFormatVersion) {
    ThrowCorrupt(context, "format version " + std::to_string(blob[4]) +
                              " (this program reads version " + std::to_string(kFormatVersion) +
                              ")");
  }
  if (blob[5] != static_cast<std::uint8_t>(expected)) {
    ThrowCorrupt(context, std::string("holds a ") + TypeName(blob[5]) + " (type " +
                              std::to_string(blob[5]) + "), expected a " +
                              TypeName(static_cast<std::uint8_t>(expected)));
  }
  Header header;
  header.flags = static_cast<std::uint16_t>(blob[6] | (blob[7] << 8));
  Reader reader(blob, 8);
  header.rows = reader.U32();
  header.cols = reader.U32();
  return header;
}

// The blob must be exactly header + payload. Point and vertex counts come from
// 32-bit fields, so their payload products fit in 64 bits; a matrix's
// rows*cols may not, hence MatrixElements.
void CheckSize(const Blob& blob, std::uint64_t payload_bytes, std::string_view context) {
  const std::uint64_t expected = kBlobHeaderSize + payload_bytes;
  if (blob.size() != expected) {
    ThrowCorrupt(context, "is " + std::to_string(blob.size()) + " bytes but its header implies " +
                              std::to_string(expected));
  }
}

std::uint64_t MatrixElements(const Blob& blob, const Header& header, std::string_view context) {
  if (header.rows != 0 && header.cols > blob.size() / header.rows) {
    ThrowCorrupt(context, "header says " + std::to_string(header.rows) + " x " +
                              std::to_string(header.cols) + " but the blob is only " +
                              std::to_string(blob.size()) + " bytes");
  }
  return header.rows * header.cols;
}

bool AllFinite(const Eigen::Vector3f& v) {
  return std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z());
}

}  // namespace

Blob EncodeMatrix(const Eigen::MatrixXd& matrix) {
  const auto rows = static_cast<std::uint64_t>(matrix.rows());
  const auto cols = static_cast<std::uint64_t>(matrix.cols());
  Writer writer(kBlobHeaderSize + rows * cols * 8);
  writer.Header(BlobType::kFloat64Matrix, 0, rows, cols);
  for (Eigen::Index r = 0; r < matrix.rows(); ++r) {
    for (Eigen::Index c = 0; c < matrix.cols(); ++c) writer.F64(matrix(r, c));
  }
  return writer.Take();
}

Eigen::MatrixXd DecodeMatrix(const Blob& blob, std::string_view context) {
  const Header header = ReadHeader(blob, BlobType::kFloat64Matrix, context);
  if (header.flags != 0) ThrowCorrupt(context, "unknown flags " + std::to_string(header.flags));
  CheckSize(blob, MatrixElements(blob, header, context) * 8, context);
  Eigen::MatrixXd matrix(static_cast<Eigen::Index>(header.rows),
                         static_cast<Eigen::Index>(header.cols));
  Reader reader(blob, kBlobHeaderSize);
  for (Eigen::Index r = 0; r < matrix.rows(); ++r) {
    for (Eigen::Index c = 0; c < matrix.cols(); ++c) matrix(r, c) = reader.F64();
  }
  return matrix;
}

Blob EncodeByteMatrix(const ByteMatrix& matrix) {
  const auto rows = static_cast<std::uint64_t>(matrix.rows());
  const auto cols = static_cast<std::uint64_t>(matrix.cols());
  Writer writer(kBlobHeaderSize + rows * cols);
  writer.Header(BlobType::kUint8Matrix, 0, rows, cols);
  for (Eigen::Index r = 0; r < matrix.rows(); ++r) {
    for (Eigen::Index c = 0; c < matrix.cols(); ++c) writer.U8(matrix(r, c));
  }
  return writer.Take();
}

ByteMatrix DecodeByteMatrix(const Blob& blob, std::string_view context) {
  const Header header = ReadHeader(blob, BlobType::kUint8Matrix, context);
  if (header.flags != 0) ThrowCorrupt(context, "unknown flags " + std::to_string(header.flags));
  CheckSize(blob, MatrixElements(blob, header, context), context);
  ByteMatrix matrix(static_cast<Eigen::Index>(header.rows), static_cast<Eigen::Index>(header.cols));
  if (matrix.size() > 0) std::memcpy(matrix.data(), blob.data() + kBlobHeaderSize, matrix.size());
  return matrix;
}

Blob EncodePose(const Rigid3d& b_from_a) { return EncodeMatrix(b_from_a.ToMatrix()); }

Rigid3d DecodePose(const Blob& blob, std::string_view context) {
  const Eigen::MatrixXd matrix = DecodeMatrix(blob, context);
  if (matrix.rows() != 4 || matrix.cols() != 4) {
    ThrowCorrupt(context, "a pose must be 4x4, found " + std::to_string(matrix.rows()) + "x" +
                              std::to_string(matrix.cols()));
  }
  std::string reason;
  if (!IsRigidTransform(matrix, 1e-6, &reason)) {
    ThrowCorrupt(context, "not a rigid transform: " + reason);
  }
  return Rigid3d::FromMatrix(matrix);
}

Blob EncodePointCloud(const StoredPointCloud& cloud) {
  const std::size_t n = cloud.points.size();
  ARPOS_CHECK(cloud.normals.empty() || cloud.normals.size() == n,
              "point cloud has " << n << " points but " << cloud.normals.size() << " normals");
  ARPOS_CHECK(cloud.colors.empty() || cloud.colors.size() == n,
              "point cloud has " << n << " points but " << cloud.colors.size() << " colours");
  std::uint16_t flags = 0;
  if (!cloud.normals.empty()) flags |= kCloudHasNormals;
  if (!cloud.colors.empty()) flags |= kCloudHasColors;
  Writer writer(kBlobHeaderSize + n * (12 + 12 + 3));
  writer.Header(BlobType::kPointCloud, flags, n, 3);
  for (const Eigen::Vector3f& p : cloud.points) {
    for (int k = 0; k < 3; ++k) writer.F32(p[k]);
  }
  for (const Eigen::Vector3f& normal : cloud.normals) {
    for (int k = 0; k < 3; ++k) writer.F32(normal[k]);
  }
  for (const auto& color : cloud.colors) {
    for (std::uint8_t channel : color) writer.U8(channel);
  }
  return writer.Take();
}

StoredPointCloud DecodePointCloud(const Blob& blob, std::string_view context) {
  const Header header = ReadHeader(blob, BlobType::kPointCloud, context);
  if ((header.flags & ~(kCloudHasNormals | kCloudHasColors)) != 0) {
    ThrowCorrupt(context, "unknown point cloud flags " + std::to_string(header.flags));
  }
  if (header.cols != 3) {
    ThrowCorrupt(context,
                 "point cloud must have 3 columns, header says " + std::to_string(header.cols));
  }
  const bool has_normals = (header.flags & kCloudHasNormals) != 0;
  const bool has_colors = (header.flags & kCloudHasColors) != 0;
  const std::uint64_t n = header.rows;
  CheckSize(blob, n * (12 + (has_normals ? 12 : 0) + (has_colors ? 3 : 0)), context);

  StoredPointCloud cloud;
  Reader reader(blob, kBlobHeaderSize);
  cloud.points.resize(n);
  for (std::uint64_t i = 0; i < n; ++i) {
    Eigen::Vector3f& p = cloud.points[i];
    for (int k = 0; k < 3; ++k) p[k] = reader.F32();
    if (!AllFinite(p)) ThrowCorrupt(context, "point " + std::to_string(i) + " is not finite");
  }
  if (has_normals) {
    cloud.normals.resize(n);
    for (std::uint64_t i = 0; i < n; ++i) {
      for (int k = 0; k < 3; ++k) cloud.normals[i][k] = reader.F32();
      if (!AllFinite(cloud.normals[i])) {
        ThrowCorrupt(context, "normal " + std::to_string(i) + " is not finite");
      }
    }
  }
  if (has_colors) {
    cloud.colors.resize(n);
    for (std::uint64_t i = 0; i < n; ++i) {
      for (int k = 0; k < 3; ++k) cloud.colors[i][k] = reader.U8();
    }
  }
  return cloud;
}

Blob EncodeTriangleMesh(const StoredTriangleMesh& mesh) {
  const std::size_t num_vertices = mesh.vertices.size();
  Writer writer(kBlobHeaderSize + num_vertices * 12 + mesh.faces.size() * 12);
  writer.Header(BlobType::kTriangleMesh, 0, num_vertices, mesh.faces.size());
  for (const Eigen::Vector3f& v : mesh.vertices) {
    for (int k = 0; k < 3; ++k) writer.F32(v[k]);
  }
  for (std::size_t f = 0; f < mesh.faces.size(); ++f) {
    for (std::uint32_t index : mesh.faces[f]) {
      ARPOS_CHECK(index < num_vertices,
                  "mesh face " << f << " refers to vertex " << index << " of " << num_vertices);
      writer.U32(index);
    }
  }
  return writer.Take();
}

StoredTriangleMesh DecodeTriangleMesh(const Blob& blob, std::string_view context) {
  const Header header = ReadHeader(blob, BlobType::kTriangleMesh, context);
  if (header.flags != 0)
    ThrowCorrupt(context, "unknown mesh flags " + std::to_string(header.flags));
  const std::uint64_t num_vertices = header.rows;
  const std::uint64_t num_faces = header.cols;
  CheckSize(blob, num_vertices * 12 + num_faces * 12, context);

  StoredTriangleMesh mesh;
  Reader reader(blob, kBlobHeaderSize);
  mesh.vertices.resize(num_vertices);
  for (std::uint64_t i = 0; i < num_vertices; ++i) {
    for (int k = 0; k < 3; ++k) mesh.vertices[i][k] = reader.F32();
    if (!AllFinite(mesh.vertices[i])) {
      ThrowCorrupt(context, "vertex " + std::to_string(i) + " is not finite");
    }
  }
  mesh.faces.resize(num_faces);
  for (std::uint64_t f = 0; f < num_faces; ++f) {
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t index = reader.U32();
      if (index >= num_vertices) {
        ThrowCorrupt(context, "face " + std::to_string(f) + " refers to vertex " +
                                  std::to_string(index) + " but the mesh has " +
                                  std::to_string(num_vertices));
      }
      mesh.faces[f][k] = index;
    }
  }
  return mesh;
}

}  // namespace arpos
