#include "store/record_conversions.h"

namespace arpos {

StoredTriangleMesh ToStoredMesh(const TriangleMesh& mesh) {
  StoredTriangleMesh stored;
  stored.vertices = mesh.vertices;
  stored.faces.reserve(mesh.faces.size());
  for (const auto& f : mesh.faces) {
    stored.faces.push_back({static_cast<std::uint32_t>(f[0]), static_cast<std::uint32_t>(f[1]),
                            static_cast<std::uint32_t>(f[2])});
  }
  return stored;
}

TriangleMesh FromStoredMesh(const StoredTriangleMesh& stored) {
  TriangleMesh mesh;
  mesh.vertices = stored.vertices;
  mesh.faces.reserve(stored.faces.size());
  for (const auto& f : stored.faces) {
    mesh.faces.emplace_back(static_cast<int>(f[0]), static_cast<int>(f[1]), static_cast<int>(f[2]));
  }
  return mesh;
}

RecordingIntrinsics ToRecordingIntrinsics(const CameraIntrinsics& c) {
  RecordingIntrinsics r;
  r.width = c.width;
  r.height = c.height;
  r.fx = c.fx;
  r.fy = c.fy;
  r.cx = c.cx;
  r.cy = c.cy;
  r.distortion = c.distortion;
  r.depth_scale = c.depth_scale;
  return r;
}

}  // namespace arpos
