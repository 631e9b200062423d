// Blob codecs: exact round trips, the documented byte layout, and refusal of
// every kind of corrupt blob with a message that names the blob.

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>

#include "store/blob_codec.h"
#include "store_test_util.h"

namespace arpos {
namespace {

// Expects `fn` to throw CorruptBlobError whose message contains every part.
template <typename Fn>
void ExpectCorrupt(Fn&& fn, std::initializer_list<std::string> parts) {
  try {
    fn();
    ADD_FAILURE() << "no CorruptBlobError thrown";
  } catch (const CorruptBlobError& e) {
    const std::string what = e.what();
    for (const std::string& part : parts) {
      EXPECT_NE(what.find(part), std::string::npos) << "'" << part << "' not in: " << what;
    }
  }
}

void PutU32(Blob* blob, std::size_t offset, std::uint32_t value) {
  for (int i = 0; i < 4; ++i) (*blob)[offset + i] = static_cast<std::uint8_t>(value >> (8 * i));
}

TEST(BlobCodec, MatrixRoundTripIsExactIncludingNanAndEmpty) {
  Eigen::MatrixXd matrix(3, 5);
  matrix.setRandom();
  matrix(0, 0) = std::numeric_limits<double>::quiet_NaN();
  matrix(2, 4) = -std::numeric_limits<double>::infinity();
  matrix(1, 1) = std::numeric_limits<double>::denorm_min();
  const Eigen::MatrixXd decoded = DecodeMatrix(EncodeMatrix(matrix), "test");
  ASSERT_EQ(decoded.rows(), 3);
  ASSERT_EQ(decoded.cols(), 5);
  EXPECT_TRUE(std::isnan(decoded(0, 0)));
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 5; ++c) {
      if (r == 0 && c == 0) continue;
      EXPECT_EQ(decoded(r, c), matrix(r, c)) << r << "," << c;
    }
  }
  const Eigen::MatrixXd empty = DecodeMatrix(EncodeMatrix(Eigen::MatrixXd(0, 7)), "test");
  EXPECT_EQ(empty.rows(), 0);
  EXPECT_EQ(empty.cols(), 7);
}

TEST(BlobCodec, MatrixLayoutIsTheDocumentedLittleEndianRowMajor) {
  Eigen::MatrixXd matrix(2, 1);
  matrix << 1.0, -2.0;
  const Blob blob = EncodeMatrix(matrix);
  // Header: "ARPB", version 1, type 1, flags 0, rows 2, cols 1.
  const Blob header = {'A', 'R', 'P', 'B', 1, 1, 0, 0, 2, 0, 0, 0, 1, 0, 0, 0};
  ASSERT_EQ(blob.size(), kBlobHeaderSize + 16);
  EXPECT_EQ(Blob(blob.begin(), blob.begin() + 16), header);
  // 1.0 = 0x3FF0000000000000, -2.0 = 0xC000000000000000, least significant byte first.
  const Blob payload = {0, 0, 0, 0, 0, 0, 0xF0, 0x3F, 0, 0, 0, 0, 0, 0, 0, 0xC0};
  EXPECT_EQ(Blob(blob.begin() + 16, blob.end()), payload);

  Eigen::MatrixXd row_major(1, 2);
  row_major << 1.0, -2.0;
  const Blob transposed = EncodeMatrix(row_major);
  EXPECT_EQ(Blob(transposed.begin() + 16, transposed.end()), payload)
      << "elements must be written row by row";
}

TEST(BlobCodec, ByteMatrixRoundTrip) {
  ByteMatrix descriptors(4, 32);
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 32; ++c) descriptors(r, c) = static_cast<std::uint8_t>(r * 61 + c * 7);
  }
  EXPECT_EQ(DecodeByteMatrix(EncodeByteMatrix(descriptors), "test"), descriptors);
}

TEST(BlobCodec, PoseRoundTripForwardAndInverse) {
  std::mt19937 rng(7);
  for (int i = 0; i < 50; ++i) {
    const Rigid3d b_from_a = test::RandomPose(rng);
    const Rigid3d decoded = DecodePose(EncodePose(b_from_a), "test");
    test::ExpectPoseEq(b_from_a, decoded);
    test::ExpectPoseEq(b_from_a.Inverse(), decoded.Inverse());
    const Eigen::Vector3d point_in_a(0.3, -0.2, 1.5);
    EXPECT_LT((decoded * point_in_a - b_from_a * point_in_a).norm(), 1e-12);
  }
}

TEST(BlobCodec, PointCloudRoundTripWithAndWithoutAttributes) {
  std::mt19937 rng(11);
  for (bool normals : {false, true}) {
    for (bool colors : {false, true}) {
      const StoredPointCloud cloud = test::RandomCloud(rng, 123, normals, colors);
      const Blob blob = EncodePointCloud(cloud);
      EXPECT_EQ(blob.size(), kBlobHeaderSize + 123 * (12 + (normals ? 12 : 0) + (colors ? 3 : 0)));
      test::ExpectCloudEq(cloud, DecodePointCloud(blob, "test"));
    }
  }
  test::ExpectCloudEq(StoredPointCloud(), DecodePointCloud(EncodePointCloud({}), "test"));
}

TEST(BlobCodec, TriangleMeshRoundTrip) {
  std::mt19937 rng(13);
  const StoredTriangleMesh mesh = test::RandomMesh(rng);
  test::ExpectMeshEq(mesh, DecodeTriangleMesh(EncodeTriangleMesh(mesh), "test"));
}

TEST(BlobCodec, EncodersRefuseInconsistentInput) {
  StoredPointCloud cloud;
  cloud.points.resize(3, Eigen::Vector3f::Zero());
  cloud.normals.resize(2, Eigen::Vector3f::UnitZ());
  EXPECT_THROW(EncodePointCloud(cloud), Error);
  StoredTriangleMesh mesh;
  mesh.vertices.resize(3, Eigen::Vector3f::Zero());
  mesh.faces = {{0, 1, 3}};
  EXPECT_THROW(EncodeTriangleMesh(mesh), Error);
}

TEST(BlobCodec, EveryTruncationAndExtensionIsRefused) {
  std::mt19937 rng(17);
  const Blob cloud = EncodePointCloud(test::RandomCloud(rng, 5, true, true));
  for (std::size_t size = 0; size < cloud.size(); ++size) {
    const Blob truncated(cloud.begin(), cloud.begin() + size);
    EXPECT_THROW(DecodePointCloud(truncated, "cloud"), CorruptBlobError) << "size " << size;
  }
  Blob extended = cloud;
  extended.push_back(0);
  ExpectCorrupt([&] { DecodePointCloud(extended, "reconstructions.cloud of reconstruction 4"); },
                {"reconstructions.cloud of reconstruction 4", "corrupt blob", "header implies"});

  const Blob mesh = EncodeTriangleMesh(test::RandomMesh(rng));
  for (std::size_t size = 0; size < mesh.size(); ++size) {
    EXPECT_THROW(DecodeTriangleMesh(Blob(mesh.begin(), mesh.begin() + size), "mesh"),
                 CorruptBlobError)
        << "size " << size;
  }
  const Blob pose = EncodePose(Rigid3d::Identity());
  for (std::size_t size = 0; size < pose.size(); ++size) {
    EXPECT_THROW(DecodePose(Blob(pose.begin(), pose.begin() + size), "pose"), CorruptBlobError)
        << "size " << size;
  }
}

TEST(BlobCodec, BadHeadersAreRefusedWithTheReason) {
  const Blob pose = EncodePose(Rigid3d::Identity());

  Blob bad_magic = pose;
  bad_magic[0] = 'X';
  ExpectCorrupt([&] { DecodePose(bad_magic, "plans.room_from_model_target of plan 3"); },
                {"plans.room_from_model_target of plan 3", "bad magic"});

  Blob bad_version = pose;
  bad_version[4] = 9;
  ExpectCorrupt([&] { DecodePose(bad_version, "p"); }, {"format version 9"});

  // A mesh blob where a pose is expected.
  std::mt19937 rng(19);
  ExpectCorrupt([&] { DecodePose(EncodeTriangleMesh(test::RandomMesh(rng)), "p"); },
                {"triangle mesh", "expected a float64 matrix"});

  Blob bad_flags = EncodePointCloud(test::RandomCloud(rng, 2, false, false));
  bad_flags[6] = 0x80;
  ExpectCorrupt([&] { DecodePointCloud(bad_flags, "c"); }, {"flags"});

  // Dimensions whose product overflows 64 bits must not wrap around to "fits".
  Blob huge = EncodeMatrix(Eigen::MatrixXd::Zero(1, 1));
  PutU32(&huge, 8, 0xFFFFFFFFu);
  PutU32(&huge, 12, 0xFFFFFFFFu);
  ExpectCorrupt([&] { DecodeMatrix(huge, "m"); }, {"4294967295"});
  Blob huge_bytes = EncodeByteMatrix(ByteMatrix::Zero(1, 1));
  PutU32(&huge_bytes, 8, 0x10000u);
  PutU32(&huge_bytes, 12, 0x10000u);
  EXPECT_THROW(DecodeByteMatrix(huge_bytes, "b"), CorruptBlobError);
}

TEST(BlobCodec, BadContentsAreRefused) {
  std::mt19937 rng(23);
  // Face index out of range.
  Blob mesh = EncodeTriangleMesh(test::RandomMesh(rng));
  PutU32(&mesh, kBlobHeaderSize + 4 * 12, 4);  // first index of face 0; the mesh has 4 vertices
  ExpectCorrupt([&] { DecodeTriangleMesh(mesh, "plans.reference_model_mesh of plan 1"); },
                {"plans.reference_model_mesh of plan 1", "face 0 refers to vertex 4"});

  // A NaN coordinate.
  Blob cloud = EncodePointCloud(test::RandomCloud(rng, 3, false, false));
  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::uint32_t bits;
  std::memcpy(&bits, &nan, sizeof bits);
  PutU32(&cloud, kBlobHeaderSize + 12 + 4, bits);  // point 1, y
  ExpectCorrupt([&] { DecodePointCloud(cloud, "c"); }, {"point 1 is not finite"});

  // A 4x4 that is not rigid, and a matrix of the wrong shape.
  Eigen::Matrix4d scaled = Eigen::Matrix4d::Identity();
  scaled(0, 0) = 2.0;
  ExpectCorrupt([&] { DecodePose(EncodeMatrix(scaled), "alignments.x of alignment 2"); },
                {"alignments.x of alignment 2", "not a rigid transform"});
  ExpectCorrupt([&] { DecodePose(EncodeMatrix(Eigen::MatrixXd::Identity(3, 4)), "p"); },
                {"must be 4x4", "3x4"});
}

}  // namespace
}  // namespace arpos
