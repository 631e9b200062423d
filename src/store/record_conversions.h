#pragma once
/// Conversions between the store's plain records and the geometry / sensor
/// types the stages work with. Lossless apart from float storage of mesh
/// vertices (records.h).

#include "geometry/triangle_mesh.h"
#include "sensor/intrinsics.h"
#include "store/records.h"

namespace arpos {

StoredTriangleMesh ToStoredMesh(const TriangleMesh& mesh);
/// Vertices and faces; no vertex normals (call ComputeVertexNormals).
TriangleMesh FromStoredMesh(const StoredTriangleMesh& stored);
RecordingIntrinsics ToRecordingIntrinsics(const CameraIntrinsics& camera);

}  // namespace arpos
