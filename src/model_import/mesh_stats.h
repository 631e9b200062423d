#pragma once
/// Checks and figures of a triangle mesh that the importer reports: extent,
/// connected components, boundary edges, enclosed volume and outward
/// orientation. Pure geometry, any frame; lengths in the mesh's unit.

#include <Eigen/Core>

#include "geometry/triangle_mesh.h"

namespace arpos {

struct MeshSummary {
  int num_vertices = 0;
  int num_faces = 0;
  Eigen::Vector3d min = Eigen::Vector3d::Zero(), max = Eigen::Vector3d::Zero();
  double surface_area = 0;   ///< unit^2
  double signed_volume = 0;  ///< unit^3; > 0 when closed and oriented outwards
  bool closed = false;       ///< TriangleMesh::IsClosed()
  int boundary_edges = 0;    ///< edges used by one face
  int non_manifold_edges = 0;  ///< edges used by three or more faces
  int num_components = 0;    ///< face-connected (through shared vertices)
  Eigen::Vector3d extent() const { return max - min; }
};

MeshSummary SummarizeMesh(const TriangleMesh& mesh);

/// Reverses every face if the signed volume is negative (inward faces).
/// Returns true if it flipped. Meaningful for closed meshes only.
bool OrientOutwards(TriangleMesh* mesh);

/// Keeps the connected piece with the most faces (pieces connect through
/// shared vertices) and drops the others and their unused vertices. Returns
/// the number of faces dropped.
int KeepLargestComponent(TriangleMesh* mesh);

/// Signed volume by the divergence theorem (unit^3).
double SignedVolume(const TriangleMesh& mesh);

}  // namespace arpos
