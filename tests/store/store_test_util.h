#pragma once
// Shared helpers of the store tests: deterministic synthetic records, one
// complete record of every type, and field-by-field comparisons.

#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <random>
#include <string>

#include "store/database.h"
#include "store/records.h"

namespace arpos::test {

Rigid3d RandomPose(std::mt19937& rng);
StoredPointCloud RandomCloud(std::mt19937& rng, int num_points, bool normals, bool colors);
/// A closed tetrahedron with slightly random vertices.
StoredTriangleMesh RandomMesh(std::mt19937& rng);
RecordingIntrinsics SomeIntrinsics();

/// One of everything, linked: patient -> plan -> (room recording, room map),
/// session -> (body scan, body marker map, reconstruction, alignments,
/// tracking run with frames), plus two audit entries. Ids are filled in.
struct FullStore {
  PatientRecord patient;
  PlanRecord plan;
  RecordingRecord room_recording;
  RoomMapRecord room_map;
  SessionRecord session;
  RecordingRecord body_scan;
  BodyMarkerMapRecord body_marker_map;
  ReconstructionRecord reconstruction;
  AlignmentRecord manual_alignment;
  AlignmentRecord icp_alignment;  ///< child of manual_alignment
  TrackingRunRecord tracking_run;
  std::vector<TrackingFrameRecord> frames;
  std::vector<AuditEntry> audit;
};
/// Writes a FullStore built from `seed` into `database` and returns it.
FullStore WriteFullStore(Database& database, unsigned seed);

// Field-by-field expectations (gtest non-fatal), poses to 1e-12.
void ExpectPoseEq(const Rigid3d& expected, const Rigid3d& actual);
void ExpectCloudEq(const StoredPointCloud& expected, const StoredPointCloud& actual);
void ExpectMeshEq(const StoredTriangleMesh& expected, const StoredTriangleMesh& actual);
void ExpectFullStoreEq(Database& database, const FullStore& expected);

/// The file's bytes, or "" if it does not exist.
std::string FileBytes(const std::filesystem::path& path);

}  // namespace arpos::test
