#include "model_import/surface_extraction.h"

#include <vtkAlgorithm.h>
#include <vtkCellArray.h>
#include <vtkCellArrayIterator.h>
#include <vtkCommand.h>
#include <vtkDecimatePro.h>
#include <vtkFlyingEdges3D.h>
#include <vtkFloatArray.h>
#include <vtkImageData.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkQuadricDecimation.h>
#include <vtkSmartPointer.h>
#include <vtkWindowedSincPolyDataFilter.h>

#include <chrono>
#include <algorithm>
#include <cmath>
#include <unordered_map>

#include "model_import/mesh_stats.h"
#include "util/check.h"

namespace arpos {
namespace {

// With an observer on ErrorEvent/WarningEvent VTK does not print to the
// terminal; errors become exceptions after Update().
class ErrorCollector : public vtkCommand {
 public:
  static ErrorCollector* New() { return new ErrorCollector; }
  void Execute(vtkObject*, unsigned long event, void* data) override {
    if (event == vtkCommand::ErrorEvent) {
      error = data != nullptr ? static_cast<const char*>(data) : "unknown VTK error";
    }
  }
  std::string error;
};

void RunFilter(vtkAlgorithm* filter, const char* what) {
  vtkNew<ErrorCollector> collector;
  filter->AddObserver(vtkCommand::ErrorEvent, collector);
  filter->AddObserver(vtkCommand::WarningEvent, collector);
  filter->Update();
  ARPOS_CHECK(collector->error.empty(), what << " failed: " << collector->error);
}

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Grid edges crossing the iso-value, by axis: flying edges puts exactly one
// vertex on each, so this predicts the vertex count without extracting.
struct CrossingCounts {
  size_t along[3] = {0, 0, 0};
  size_t total() const { return along[0] + along[1] + along[2]; }
};

CrossingCounts CountCrossings(const ScalarVolume& volume, double iso) {
  const VolumeGeometry& g = volume.geometry;
  const float level = static_cast<float>(iso);
  const size_t sy = static_cast<size_t>(g.size[0]), sz = sy * static_cast<size_t>(g.size[1]);
  CrossingCounts counts;
  const std::vector<float>& v = volume.values;
  for (int k = 0; k < g.size[2]; ++k) {
    for (int j = 0; j < g.size[1]; ++j) {
      const size_t row = g.Index(0, j, k);
      for (int i = 0; i < g.size[0]; ++i) {
        const size_t n = row + static_cast<size_t>(i);
        const bool in = v[n] >= level;
        if (i + 1 < g.size[0] && in != (v[n + 1] >= level)) ++counts.along[0];
        if (j + 1 < g.size[1] && in != (v[n + sy] >= level)) ++counts.along[1];
        if (k + 1 < g.size[2] && in != (v[n + sz] >= level)) ++counts.along[2];
      }
    }
  }
  return counts;
}

// In-plane coarsening factor f >= 1 that brings the predicted vertex count to
// `target`: crossings of in-plane edges come from walls and scale with 1/f,
// crossings of k edges come from caps and slopes and scale with 1/f^2.
double CoarseningFactor(const CrossingCounts& counts, double target) {
  const double walls = static_cast<double>(counts.along[0] + counts.along[1]);
  const double caps = static_cast<double>(counts.along[2]);
  if (walls + caps <= target) return 1.0;
  // caps u^2 + walls u - target = 0 for u = 1/f.
  const double u = caps > 0 ? (-walls + std::sqrt(walls * walls + 4 * caps * target)) / (2 * caps)
                            : target / walls;
  return std::max(1.0, 1.0 / u);
}

// Bilinear resampling of every (i, j) plane onto a grid `factor` times
// coarser; the outermost ring of every plane is set below the iso-value so the
// surface stays closed. Geometry (origin, rotation, k spacing) is kept.
ScalarVolume CoarsenInPlane(const ScalarVolume& volume, double factor, double iso) {
  const VolumeGeometry& g = volume.geometry;
  ScalarVolume out;
  out.geometry = g;
  for (int a = 0; a < 2; ++a) {
    out.geometry.size[a] = static_cast<int>(std::floor((g.size[a] - 1) / factor)) + 2;
    out.geometry.spacing_mm[a] = g.spacing_mm[a] * factor;
  }
  const VolumeGeometry& o = out.geometry;
  out.values.resize(o.num_voxels());
  float outside = static_cast<float>(iso) - 1.0f;
  for (float value : volume.values) outside = std::min(outside, value);
  for (int k = 0; k < o.size[2]; ++k) {
    for (int j = 0; j < o.size[1]; ++j) {
      const double y = j * factor;
      const int j0 = std::min(static_cast<int>(y), g.size[1] - 2);
      const float fy = static_cast<float>(std::min(1.0, y - j0));
      for (int i = 0; i < o.size[0]; ++i) {
        float& value = out.values[o.Index(i, j, k)];
        if (i == 0 || j == 0 || i == o.size[0] - 1 || j == o.size[1] - 1) {
          value = outside;
          continue;
        }
        const double x = i * factor;
        const int i0 = std::min(static_cast<int>(x), g.size[0] - 2);
        const float fx = static_cast<float>(std::min(1.0, x - i0));
        const float v00 = volume.values[g.Index(i0, j0, k)], v10 = volume.values[g.Index(i0 + 1, j0, k)];
        const float v01 = volume.values[g.Index(i0, j0 + 1, k)], v11 = volume.values[g.Index(i0 + 1, j0 + 1, k)];
        value = (1 - fy) * ((1 - fx) * v00 + fx * v10) + fy * ((1 - fx) * v01 + fx * v11);
      }
    }
  }
  return out;
}

// Decimation to at most max_vertices. vtkDecimatePro with topology
// preservation first: on this machine it took 3-6 s for 180k-300k vertices
// where vtkQuadricDecimation took 5-37 s (large flat caps are its worst case).
// If topology preservation stops it above the budget, quadric decimation
// finishes the job on the already smaller mesh.
vtkSmartPointer<vtkPolyData> Decimate(vtkSmartPointer<vtkPolyData> surface, int max_vertices) {
  if (max_vertices <= 0 || surface->GetNumberOfPoints() <= max_vertices) return surface;
  auto keep_fraction = [&]() {
    // Aim 2 % under the budget: the vertex count reached is approximate.
    return 0.98 * max_vertices / static_cast<double>(surface->GetNumberOfPoints());
  };
  vtkNew<vtkDecimatePro> pro;
  pro->SetInputData(surface);
  pro->SetTargetReduction(1.0 - keep_fraction());
  pro->PreserveTopologyOn();
  pro->SplittingOff();
  pro->BoundaryVertexDeletionOff();
  pro->SetFeatureAngle(45.0);
  pro->SetMaximumError(VTK_DOUBLE_MAX);
  RunFilter(pro, "decimation");
  surface = pro->GetOutput();
  for (int round = 0; round < 2 && surface->GetNumberOfPoints() > max_vertices; ++round) {
    vtkNew<vtkQuadricDecimation> quadric;
    quadric->SetInputData(surface);
    quadric->SetTargetReduction(1.0 - keep_fraction());
    quadric->VolumePreservationOn();
    RunFilter(quadric, "quadric decimation");
    surface = quadric->GetOutput();
  }
  return surface;
}

// Triangles of `surface` with points mapped by `convert`; unused points and
// degenerate triangles dropped.
template <typename Convert>
TriangleMesh ToTriangleMesh(vtkPolyData* surface, Convert convert) {
  TriangleMesh mesh;
  vtkPoints* points = surface->GetPoints();
  std::vector<int> index_of(static_cast<size_t>(surface->GetNumberOfPoints()), -1);
  auto polys = vtk::TakeSmartPointer(surface->GetPolys()->NewIterator());
  for (polys->GoToFirstCell(); !polys->IsDoneWithTraversal(); polys->GoToNextCell()) {
    vtkIdType n = 0;
    const vtkIdType* ids = nullptr;
    polys->GetCurrentCell(n, ids);
    if (n != 3) continue;
    Eigen::Vector3i face;
    for (int k = 0; k < 3; ++k) {
      int& index = index_of[static_cast<size_t>(ids[k])];
      if (index < 0) {
        double p[3];
        points->GetPoint(ids[k], p);
        index = static_cast<int>(mesh.vertices.size());
        mesh.vertices.push_back(convert(Eigen::Vector3d(p[0], p[1], p[2])));
      }
      face[k] = index;
    }
    if (face[0] == face[1] || face[1] == face[2] || face[0] == face[2]) continue;
    mesh.faces.push_back(face);
  }
  return mesh;
}

// Flying edges on `grid`, then windowed-sinc smoothing.
vtkSmartPointer<vtkPolyData> ExtractAndSmooth(const ScalarVolume& grid, const SurfaceOptions& options,
                                              const std::string& source, SurfaceStats* stats) {
  const VolumeGeometry& g = grid.geometry;
  auto start = std::chrono::steady_clock::now();
  // Index space scaled by the spacing (mm); the rotation and origin are
  // applied when converting, so VTK never sees the patient frame.
  vtkNew<vtkImageData> image;
  image->SetDimensions(g.size[0], g.size[1], g.size[2]);
  image->SetSpacing(g.spacing_mm.x(), g.spacing_mm.y(), g.spacing_mm.z());
  image->SetOrigin(0, 0, 0);
  vtkNew<vtkFloatArray> scalars;
  // save = 1: VTK neither frees nor (in flying edges) writes this buffer.
  scalars->SetArray(const_cast<float*>(grid.values.data()), static_cast<vtkIdType>(grid.values.size()), 1);
  scalars->SetName("field");
  image->GetPointData()->SetScalars(scalars);

  vtkNew<vtkFlyingEdges3D> flying_edges;
  flying_edges->SetInputData(image);
  flying_edges->SetValue(0, options.iso_value);
  flying_edges->ComputeNormalsOff();
  flying_edges->ComputeGradientsOff();
  flying_edges->ComputeScalarsOff();
  flying_edges->InterpolateAttributesOff();
  RunFilter(flying_edges, "flying edges");
  vtkSmartPointer<vtkPolyData> surface = flying_edges->GetOutput();
  stats->extracted_vertices = static_cast<int>(surface->GetNumberOfPoints());
  stats->extracted_faces = static_cast<int>(surface->GetNumberOfPolys());
  stats->extract_s += SecondsSince(start);
  if (surface->GetNumberOfPolys() == 0) {
    ARPOS_INPUT_ERROR(source << ": the volume has no surface at " << options.iso_value);
  }
  start = std::chrono::steady_clock::now();
  if (options.smoothing_iterations > 0) {
    vtkNew<vtkWindowedSincPolyDataFilter> smoother;
    smoother->SetInputData(surface);
    smoother->SetNumberOfIterations(options.smoothing_iterations);
    smoother->SetPassBand(options.smoothing_pass_band);
    smoother->NormalizeCoordinatesOn();  // the pass band is then independent of scale
    smoother->BoundarySmoothingOff();
    smoother->FeatureEdgeSmoothingOff();
    smoother->NonManifoldSmoothingOn();
    RunFilter(smoother, "windowed-sinc smoothing");
    surface = smoother->GetOutput();
  }
  stats->smooth_s += SecondsSince(start);
  return surface;
}

// Every edge shared by exactly two triangles.
bool IsClosedSurface(vtkPolyData* surface) {
  std::unordered_map<uint64_t, int> edges;
  auto polys = vtk::TakeSmartPointer(surface->GetPolys()->NewIterator());
  for (polys->GoToFirstCell(); !polys->IsDoneWithTraversal(); polys->GoToNextCell()) {
    vtkIdType n = 0;
    const vtkIdType* ids = nullptr;
    polys->GetCurrentCell(n, ids);
    for (vtkIdType k = 0; k < n; ++k) {
      uint64_t a = static_cast<uint64_t>(ids[k]), b = static_cast<uint64_t>(ids[(k + 1) % n]);
      if (a > b) std::swap(a, b);
      ++edges[(a << 32) | b];
    }
  }
  for (const auto& [edge, count] : edges) {
    if (count != 2) return false;
  }
  return !edges.empty();
}

}  // namespace

bool SurfaceOptions::Check(std::string* reason) const {
  if (!std::isfinite(iso_value)) {
    *reason = "iso_value must be finite";
    return false;
  }
  if (max_vertices < 0 || (max_vertices > 0 && max_vertices < 100)) {
    *reason = "max_vertices must be 0 (no limit) or at least 100";
    return false;
  }
  if (!(decimation_ratio >= 1.0 && decimation_ratio <= 10.0)) {
    *reason = "decimation_ratio must be within 1..10";
    return false;
  }
  if (smoothing_iterations < 0 || smoothing_iterations > 1000 ||
      !(smoothing_pass_band > 0 && smoothing_pass_band <= 2)) {
    *reason = "smoothing: 0..1000 iterations, pass band in (0, 2]";
    return false;
  }
  return true;
}

TriangleMesh ExtractSurface(const ScalarVolume& volume, const SurfaceOptions& options,
                            const std::string& source, SurfaceStats* stats) {
  std::string reason;
  ARPOS_CHECK(options.Check(&reason), "invalid SurfaceOptions: " << reason);
  ARPOS_CHECK(volume.values.size() == volume.geometry.num_voxels() && volume.geometry.num_voxels() > 0,
              "volume values do not match its geometry");
  SurfaceStats local;
  if (stats == nullptr) stats = &local;
  *stats = SurfaceStats();

  CrossingCounts counts;
  if (options.max_vertices > 0) counts = CountCrossings(volume, options.iso_value);
  stats->full_resolution_vertices = static_cast<int>(counts.total());
  // First try: a grid with up to decimation_ratio x the budget, decimated to
  // the budget (decimation spends few vertices on flat caps). If decimation
  // breaks the closed surface, fall back to a grid within the budget.
  const double first_target = options.decimation_ratio * 0.9 * options.max_vertices;
  vtkSmartPointer<vtkPolyData> surface;
  VolumeGeometry g;
  for (const double target : {first_target, 0.9 * options.max_vertices}) {
    const double factor = options.max_vertices > 0 ? CoarseningFactor(counts, target) : 1.0;
    ScalarVolume coarse;
    if (factor > 1.0) coarse = CoarsenInPlane(volume, factor, options.iso_value);
    const ScalarVolume& grid = factor > 1.0 ? coarse : volume;
    g = grid.geometry;
    stats->coarsening = factor;
    stats->grid_spacing_mm = g.spacing_mm;
    surface = ExtractAndSmooth(grid, options, source, stats);
    const auto decimate_start = std::chrono::steady_clock::now();
    const vtkIdType before = surface->GetNumberOfPoints();
    surface = Decimate(surface, options.max_vertices);
    stats->decimate_s += SecondsSince(decimate_start);
    if (surface->GetNumberOfPoints() == before || IsClosedSurface(surface)) break;
    stats->decimation_broke_surface = true;
  }

  // To the patient frame in metres.
  const Eigen::Matrix3d rotation = g.patient_from_index_rotation;
  const Eigen::Vector3d origin = g.origin_mm;
  TriangleMesh mesh = ToTriangleMesh(surface, [&](const Eigen::Vector3d& p) {
    return ((origin + rotation * p) * 0.001).cast<float>();
  });
  if (mesh.faces.empty()) ARPOS_INPUT_ERROR(source << ": the surface vanished in decimation");
  // A coarse grid can cut thin bridges and leave small islands.
  if (options.largest_component_only) stats->dropped_faces = KeepLargestComponent(&mesh);
  OrientOutwards(&mesh);
  mesh.ComputeVertexNormals();
  return mesh;
}

TriangleMesh DecimateMesh(const TriangleMesh& mesh, int max_vertices) {
  ARPOS_CHECK(max_vertices >= 0, "max_vertices must not be negative");
  if (max_vertices == 0 || static_cast<int>(mesh.vertices.size()) <= max_vertices) return mesh;
  vtkNew<vtkPoints> points;
  points->SetDataTypeToDouble();
  // Relative to the centroid: the quadrics are better conditioned near 0.
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (const auto& v : mesh.vertices) centre += v.cast<double>();
  centre /= static_cast<double>(mesh.vertices.size());
  points->SetNumberOfPoints(static_cast<vtkIdType>(mesh.vertices.size()));
  for (size_t v = 0; v < mesh.vertices.size(); ++v) {
    const Eigen::Vector3d p = mesh.vertices[v].cast<double>() - centre;
    points->SetPoint(static_cast<vtkIdType>(v), p.x(), p.y(), p.z());
  }
  vtkNew<vtkCellArray> polys;
  for (const auto& f : mesh.faces) {
    const vtkIdType ids[3] = {f[0], f[1], f[2]};
    polys->InsertNextCell(3, ids);
  }
  vtkSmartPointer<vtkPolyData> surface = vtkSmartPointer<vtkPolyData>::New();
  surface->SetPoints(points);
  surface->SetPolys(polys);
  surface = Decimate(surface, max_vertices);
  TriangleMesh result = ToTriangleMesh(surface, [&](const Eigen::Vector3d& p) {
    return (p + centre).cast<float>();
  });
  result.ComputeVertexNormals();
  return result;
}

}  // namespace arpos
