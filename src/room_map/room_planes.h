#pragma once
/// The room's planes as its markers show them (markers lying in one plane:
/// the floor, a wall), and the depth pixels of one view that lie on such a
/// plane. Shared by the map builder (plane terms in the joint adjustment)
/// and the camera localiser (plane terms in a frame's refinement).

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <optional>
#include <unordered_set>
#include <vector>

namespace arpos {

/// The plane through weighted points: its weighted centroid and the weighted
/// scatter's eigen decomposition (ascending: `normal` is the first
/// eigenvector, up to sign; spread2(1) the squared spread along the points'
/// narrower extent). nullopt when the weights sum to zero.
struct WeightedPlane {
  Eigen::Vector3d centroid;
  Eigen::Vector3d normal;
  Eigen::Vector3d spread2;  ///< eigenvalues of the weighted covariance
};
std::optional<WeightedPlane> FitWeightedPlane(const std::vector<Eigen::Vector3d>& points,
                                              const std::vector<double>& weights);

/// A plane of the room (room frame): from markers lying in it, or found in
/// depth alone (a wall without markers, the floor beyond its markers' reach;
/// AddDepthPlanes), where `cells` say where it was seen.
struct MarkerPlane {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  ///< unit, the first marker's side
  double offset = 0;                                  ///< normal . x = offset on the plane
  std::vector<Eigen::Vector3d> marker_centres;
  std::vector<int> markers;  ///< indices into the markers given
  /// Cubic cells of side cell_m (CellKey) where depth showed the plane, one
  /// cell around them included; empty for a plane known from markers alone.
  std::unordered_set<int64_t> cells;
  double cell_m = 0;
  /// Whether AddDepthPlanes may extend it (not the plane holding the origin
  /// marker: see there).
  bool extend_in_depth = true;
};

/// The key of the cubic cell of side `cell_m` that room point `x` falls in.
int64_t CellKey(const Eigen::Vector3d& x, double cell_m);

/// Groups markers by plane (normals within 3 deg, centres within 2 cm of the
/// seed marker's plane), largest groups first, each marker in one group; a
/// plane is fitted to the corners of each group of at least `min_markers`.
/// A group whose corners spread less than `min_spread_m` (RMS) along their
/// narrower extent (a row of markers, two side by side) is no plane: its
/// tilt across the row rests on the markers' own width.
/// `normals`, `centres`, `corners`: per marker, room frame.
std::vector<MarkerPlane> FindMarkerPlanes(const std::vector<Eigen::Vector3d>& normals,
                                          const std::vector<Eigen::Vector3d>& centres,
                                          const std::vector<std::array<Eigen::Vector3d, 4>>& corners,
                                          int min_markers, double min_spread_m);

/// The first of `planes` that room point `x` lies on: within `gate_m` of it
/// and within `support_m` of one of its markers' centres or in one of its
/// cells; -1 if none.
int PlaneNear(const std::vector<MarkerPlane>& planes, const Eigen::Vector3d& x, double gate_m, double support_m);

/// Finding planes in depth alone.
struct DepthPlaneOptions {
  double cell_m = 0.1;          ///< points gathered in cubic cells of this side
  int min_points_per_cell = 3;  ///< fewer: the cell is noise
  double gate_m = 0.025;        ///< a cell's centroid this near the plane is on it
  double min_extent_m = 1.0;    ///< the patch spans this much both ways (a uniform rectangle's RMS x sqrt(12))
  int min_views = 5;            ///< views that see the patch
  int max_planes = 6;
  int iterations = 300;  ///< RANSAC draws per plane
  /// A patch within merge_deg of a given plane, with that plane's markers
  /// (or, for one of depth alone, the patch's centroid) within merge_m of
  /// it, extends that plane.
  double merge_deg = 5.0;
  double merge_m = 0.05;
};

/// Planes of the room seen in depth: the points of all views (room frame;
/// `views[i]`: the view point i came from) gathered into cells; the plane
/// through most cells' centroids (RANSAC, then fitted to them), its largest
/// connected patch kept when it spans min_extent_m both ways and is seen by
/// min_views views; again on the cells left, up to max_planes. A patch in a
/// plane of `planes` adds its cells to that plane (if extend_in_depth); any
/// other is appended, with no markers. Deterministic. Returns the number of
/// planes appended.
int AddDepthPlanes(const std::vector<Eigen::Vector3d>& points, const std::vector<int>& views,
                   const DepthPlaneOptions& options, std::vector<MarkerPlane>* planes);

/// Of the candidate points of one view (camera frame) near a mapped plane
/// (n . x = d in the camera frame, from the view's pose), those on the plane
/// as this view's depth shows it: fitted to the candidates with those beyond
/// 2.5 sigma across it left out, three times (the gate that chose the
/// candidates also lets in the foot of what stands on the plane, a wall, the
/// couch base, whose pixels would tilt it). `sigma_z`: each point's depth
/// sigma. Returns the kept indices.
std::vector<size_t> PointsOnViewedPlane(const std::vector<Eigen::Vector3d>& points,
                                        const std::vector<double>& sigma_z, Eigen::Vector3d n, double d);

}  // namespace arpos
