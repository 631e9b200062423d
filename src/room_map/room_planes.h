#pragma once
/// The room's planes as its markers show them (markers lying in one plane:
/// the floor, a wall), and the depth pixels of one view that lie on such a
/// plane. Shared by the map builder (plane terms in the joint adjustment)
/// and the camera localiser (plane terms in a frame's refinement).

#include <Eigen/Core>
#include <array>
#include <optional>
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

/// A plane of the room from markers lying in it (room frame).
struct MarkerPlane {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  ///< unit, the first marker's side
  double offset = 0;                                  ///< normal . x = offset on the plane
  std::vector<Eigen::Vector3d> marker_centres;
  std::vector<int> markers;  ///< indices into the markers given
};

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
/// and within `support_m` of one of its markers' centres; -1 if none.
int PlaneNear(const std::vector<MarkerPlane>& planes, const Eigen::Vector3d& x, double gate_m, double support_m);

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
