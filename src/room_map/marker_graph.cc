#include "room_map/marker_graph.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>

#include "features/marker_pose.h"
#include "room_map/pose_refiner.h"

namespace arpos {
namespace {

double CornerRms(const Rigid3d& camera_from_marker, const std::array<Eigen::Vector3d, 4>& in_marker,
                 const std::array<Eigen::Vector2d, 4>& observed, const CameraIntrinsics& k) {
  double sum = 0;
  for (int c = 0; c < 4; ++c) {
    const Eigen::Vector3d p = camera_from_marker * in_marker[c];
    if (p.z() <= 1e-6) return std::numeric_limits<double>::infinity();
    sum += (k.Project(p) - observed[c]).squaredNorm();
  }
  return std::sqrt(sum / 4);
}

double Median(std::vector<double> v) {
  if (v.empty()) return std::numeric_limits<double>::infinity();
  const size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + mid, v.end());
  return v[mid];
}

}  // namespace

MarkerGraphResult InitializeMarkerPoses(const std::vector<MarkerView>& views, int origin_id,
                                        double marker_size_m, const CameraIntrinsics& intrinsics) {
  MarkerGraphResult result;
  const std::array<Eigen::Vector3d, 4> in_marker = MarkerCornersInMarker(marker_size_m);
  // Views by frame.
  std::map<int, std::vector<const MarkerView*>> by_frame;
  std::set<int> all_markers;
  for (const auto& v : views) {
    by_frame[v.frame].push_back(&v);
    all_markers.insert(v.marker_id);
  }
  if (!all_markers.count(origin_id)) return result;

  // Per pair (a < b): the frames seeing both.
  std::map<std::pair<int, int>, std::vector<std::pair<const MarkerView*, const MarkerView*>>> pairs;
  for (const auto& [frame, fv] : by_frame) {
    for (size_t i = 0; i < fv.size(); ++i) {
      for (size_t j = 0; j < fv.size(); ++j) {
        if (fv[i]->marker_id < fv[j]->marker_id) {
          pairs[{fv[i]->marker_id, fv[j]->marker_id}].push_back({fv[i], fv[j]});
        }
      }
    }
  }
  // Best candidate per pair: each co-visible frame proposes a_from_b; its
  // score is the median, over co-visible frames, of the corner RMS of b
  // predicted through a (and of a predicted through b).
  std::vector<MarkerGraphEdge> edges;
  for (const auto& [key, obs] : pairs) {
    MarkerGraphEdge best;
    best.marker_a = key.first;
    best.marker_b = key.second;
    best.num_frames = static_cast<int>(obs.size());
    best.median_error_px = std::numeric_limits<double>::infinity();
    // Limit the quadratic cost on long sequences: at most 40 candidates.
    const size_t stride = std::max<size_t>(1, obs.size() / 40);
    for (size_t c = 0; c < obs.size(); c += stride) {
      const Rigid3d a_from_b =
          obs[c].first->camera_from_marker.Inverse() * obs[c].second->camera_from_marker;
      const Rigid3d b_from_a = a_from_b.Inverse();
      std::vector<double> errors;
      errors.reserve(obs.size());
      for (const auto& [va, vb] : obs) {
        const double eb = CornerRms(va->camera_from_marker * a_from_b, in_marker, vb->corners_px, intrinsics);
        const double ea = CornerRms(vb->camera_from_marker * b_from_a, in_marker, va->corners_px, intrinsics);
        errors.push_back(0.5 * (ea + eb));
      }
      const double med = Median(errors);
      if (med < best.median_error_px) {
        best.median_error_px = med;
        best.a_from_b = a_from_b;
      }
    }
    edges.push_back(best);
  }

  // Prim's minimum spanning tree from the origin.
  result.room_from_marker[origin_id] = Rigid3d::Identity();
  std::set<int> in_tree = {origin_id};
  while (true) {
    const MarkerGraphEdge* best = nullptr;
    bool forward = true;
    for (const auto& e : edges) {
      const bool a_in = in_tree.count(e.marker_a) > 0, b_in = in_tree.count(e.marker_b) > 0;
      if (a_in == b_in) continue;
      if (!std::isfinite(e.median_error_px)) continue;
      if (best == nullptr || e.median_error_px < best->median_error_px) {
        best = &e;
        forward = a_in;
      }
    }
    if (best == nullptr) break;
    MarkerGraphEdge tree_edge = *best;
    if (forward) {
      result.room_from_marker[best->marker_b] = result.room_from_marker[best->marker_a] * best->a_from_b;
      in_tree.insert(best->marker_b);
    } else {
      result.room_from_marker[best->marker_a] =
          result.room_from_marker[best->marker_b] * best->a_from_b.Inverse();
      in_tree.insert(best->marker_a);
      std::swap(tree_edge.marker_a, tree_edge.marker_b);
      tree_edge.a_from_b = best->a_from_b.Inverse();
    }
    result.tree_edges.push_back(tree_edge);
  }
  for (int id : all_markers) {
    if (!in_tree.count(id)) result.unconnected_markers.push_back(id);
  }
  return result;
}

std::optional<Rigid3d> CameraFromRoomFromMarkers(const std::vector<MarkerView>& frame_views,
                                                 const std::map<int, Rigid3d>& room_from_marker,
                                                 double marker_size_m,
                                                 const CameraIntrinsics& intrinsics, double* rms_px) {
  const std::array<Eigen::Vector3d, 4> in_marker = MarkerCornersInMarker(marker_size_m);
  PoseCorrespondences corr;
  std::vector<Rigid3d> starts;
  for (const auto& v : frame_views) {
    auto it = room_from_marker.find(v.marker_id);
    if (it == room_from_marker.end()) continue;
    for (int c = 0; c < 4; ++c) {
      corr.Add(it->second * in_marker[c], v.corners_px[c], 0.5, CorrespondenceGroup::kMarker,
               v.marker_id * 4 + c);
    }
    starts.push_back(v.camera_from_marker * it->second.Inverse());
  }
  if (starts.empty()) return std::nullopt;
  PoseRefinerOptions options;
  options.max_iterations = 15;
  options.marker_huber = 4.0;
  std::optional<Rigid3d> best;
  double best_rms = std::numeric_limits<double>::infinity();
  for (const auto& start : starts) {
    const PoseRefinementResult r = RefineCameraPose(corr, intrinsics, start, options);
    // RMS over all corners (not just inliers): a wrong start must not win by
    // declaring most corners outliers.
    double sum = 0;
    int n = 0;
    for (size_t i = 0; i < corr.size(); ++i) {
      const Eigen::Vector3d p = r.camera_from_room * corr.points_in_room[i];
      if (p.z() <= 1e-6) {
        sum = std::numeric_limits<double>::infinity();
        break;
      }
      sum += (intrinsics.Project(p) - corr.pixels[i]).squaredNorm();
      ++n;
    }
    const double rms = n ? std::sqrt(sum / n) : std::numeric_limits<double>::infinity();
    if (rms < best_rms) {
      best_rms = rms;
      best = r.camera_from_room;
    }
    if (starts.size() > 6 && best_rms < 0.5) break;  // good enough; spare the rest
  }
  if (rms_px) *rms_px = best_rms;
  return best;
}

}  // namespace arpos
