#include "room_map/scan_landmarks.h"

#include <algorithm>
#include <numeric>
#include <optional>
#include <sstream>

#include "features/edge_refinement.h"
#include "util/check.h"

namespace arpos {
namespace {

// Union-find over (frame, keypoint) slots.
class Groups {
 public:
  explicit Groups(size_t n) : parent_(n) { std::iota(parent_.begin(), parent_.end(), 0); }
  int Find(int a) {
    while (parent_[a] != a) a = parent_[a] = parent_[parent_[a]];
    return a;
  }
  void Join(int a, int b) {
    a = Find(a);
    b = Find(b);
    if (a != b) parent_[std::max(a, b)] = std::min(a, b);
  }

 private:
  std::vector<int> parent_;
};

// Whether the room map holds a landmark near `x` that looks like it.
bool KnownTo(const RoomMap& map, const Eigen::Vector3d& x, const std::uint8_t* descriptor,
             const ScanLandmarkOptions& options) {
  const double r2 = options.duplicate_radius_m * options.duplicate_radius_m;
  for (int l = map.scan_landmarks; l < map.num_landmarks(); ++l) {
    if ((map.landmarks_in_room[l] - x).squaredNorm() > r2) continue;
    if (HammingDistance32(descriptor, map.landmark_descriptors.ptr<std::uint8_t>(l)) <=
        options.duplicate_max_hamming) {
      return true;
    }
  }
  return false;
}

}  // namespace

std::string ScanLandmarkOptions::Validate() const {
  std::ostringstream out;
  if (!(search_radius_px > 0))
    out << "search_radius_px must be positive";
  else if (max_hamming < 0 || max_hamming > 256)
    out << "max_hamming must be in [0, 256]";
  else if (!(match_ratio > 0 && match_ratio <= 1))
    out << "match_ratio must be in (0, 1]";
  else if (!(max_depth_m > 0))
    out << "max_depth_m must be positive";
  else if (max_landmarks < 0)
    out << "max_landmarks must not be negative";
  else if (!(duplicate_radius_m >= 0) || duplicate_max_hamming < 0)
    out << "duplicate limits must not be negative";
  else if (triangulation.min_observations < 2)
    out << "triangulation.min_observations must be at least 2";
  else if (!(triangulation.keypoint_sigma_px > 0 && triangulation.outlier_sigmas > 0))
    out << "triangulation sigmas must be positive";
  return out.str();
}

ScanLandmarks PlaceScanLandmarks(const std::vector<ScanLandmarkFrame>& frames,
                                 const CameraIntrinsics& K, const ScanLandmarkOptions& options,
                                 const RoomMap* room_map) {
  const std::string problem = options.Validate();
  ARPOS_CHECK(problem.empty(), "invalid scan landmark options: " << problem);
  ScanLandmarks out;
  out.descriptors = cv::Mat(0, kDescriptorBytes, CV_8UC1);
  out.frames = static_cast<int>(frames.size());
  if (frames.size() < 2 || options.max_landmarks == 0) return out;
  // Ideal pixels, slots and each keypoint's point in the room (from its depth).
  std::vector<std::vector<Eigen::Vector2d>> ideal(frames.size());
  std::vector<size_t> first_slot(frames.size() + 1, 0);
  std::vector<Rigid3d> camera_from_room(frames.size());
  std::vector<KeypointGrid> grids(frames.size());
  for (size_t f = 0; f < frames.size(); ++f) {
    const KeypointSet& set = frames[f].keypoints;
    std::vector<Eigen::Vector2d> px;
    px.reserve(set.size());
    for (const cv::KeyPoint& k : set.keypoints) px.emplace_back(k.pt.x, k.pt.y);
    ideal[f] = IdealPixels(px, K);
    first_slot[f + 1] = first_slot[f] + set.size();
    camera_from_room[f] = frames[f].room_from_camera.Inverse();
    grids[f].Build(set);
  }
  const PixelUndistorter lens(K);
  Groups groups(first_slot.back());
  const auto usable = [&](size_t f, size_t i) {
    const float z = frames[f].keypoints.depth_m[i];
    return z > 0 && z <= options.max_depth_m;
  };
  const auto excluded = [&](const Eigen::Vector3d& X) {
    for (const ExclusionBox& box : options.exclude) {
      if (box.Contains(X)) return true;
    }
    return false;
  };
  for (size_t a = 0; a < frames.size(); ++a) {
    const KeypointSet& A = frames[a].keypoints;
    for (size_t i = 0; i < A.size(); ++i) {
      if (!usable(a, i)) continue;
      const Eigen::Vector3d X =
          frames[a].room_from_camera * K.Unproject(ideal[a][i].x(), ideal[a][i].y(), A.depth_m[i]);
      if (excluded(X)) continue;
      const std::uint8_t* d = A.descriptors.ptr<std::uint8_t>(static_cast<int>(i));
      for (size_t b = a + 1; b < frames.size(); ++b) {
        const Eigen::Vector3d p = camera_from_room[b] * X;
        if (p.z() < 0.1) continue;
        // The grid holds recorded pixels: search around the distorted projection.
        const Eigen::Vector2d uv = lens.Distort(K.Project(p));
        if (uv.x() < 0 || uv.y() < 0 || uv.x() >= K.width || uv.y() >= K.height) continue;
        const KeypointSet& B = frames[b].keypoints;
        NearestTwo near;
        grids[b].ForEachInRadius(uv.x(), uv.y(), options.search_radius_px, [&](int j) {
          near.Offer(j, HammingDistance32(d, B.descriptors.ptr<std::uint8_t>(j)));
        });
        if (near.best < 0 || near.d1 > options.max_hamming) continue;
        if (near.d2 <= 256 && near.d1 > options.match_ratio * near.d2) continue;
        groups.Join(static_cast<int>(first_slot[a] + i),
                    static_cast<int>(first_slot[b] + near.best));
      }
    }
  }
  // Members per group, at most one keypoint per frame (the first).
  std::vector<std::vector<std::pair<int, int>>> members(first_slot.back());
  for (size_t f = 0; f < frames.size(); ++f) {
    for (size_t i = 0; i < frames[f].keypoints.size(); ++i) {
      auto& list = members[groups.Find(static_cast<int>(first_slot[f] + i))];
      if (!list.empty() && list.back().first == static_cast<int>(f)) continue;
      list.emplace_back(static_cast<int>(f), static_cast<int>(i));
    }
  }
  std::vector<int> order;
  for (size_t r = 0; r < members.size(); ++r) {
    if (static_cast<int>(members[r].size()) >= options.triangulation.min_observations)
      order.push_back(static_cast<int>(r));
  }
  out.groups = static_cast<int>(order.size());
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return members[a].size() > members[b].size(); });
  std::vector<LandmarkObservation> obs;
  std::vector<const std::uint8_t*> descs;
  std::vector<double> spreads;
  for (int r : order) {
    if (out.size() >= options.max_landmarks) break;
    obs.clear();
    for (const auto& [f, i] : members[r]) {
      obs.push_back({f, ideal[f][i],
                     usable(f, i) ? static_cast<double>(frames[f].keypoints.depth_m[i]) : 0.0});
    }
    const std::optional<TriangulatedLandmark> placed =
        TriangulateLandmark(obs, camera_from_room, K, options.triangulation);
    if (!placed || excluded(placed->point_in_room)) continue;
    descs.clear();
    for (size_t k = 0; k < obs.size(); ++k) {
      if (placed->inlier[k]) {
        descs.push_back(frames[members[r][k].first].keypoints.descriptors.ptr<std::uint8_t>(
            members[r][k].second));
      }
    }
    const std::uint8_t* descriptor = MedoidDescriptor(descs);
    if (room_map != nullptr && KnownTo(*room_map, placed->point_in_room, descriptor, options)) {
      ++out.duplicates;
      continue;
    }
    // How far its views disagree, sideways at their distance: the poses'
    // errors (measured: 0.1-0.3 deg on frames posed by the stickers and the
    // body surface) more than the keypoints' own noise.
    double sum_sq = 0;
    int n_in = 0;
    for (size_t k = 0; k < obs.size(); ++k) {
      if (!placed->inlier[k]) continue;
      const Eigen::Vector3d p = camera_from_room[obs[k].camera] * placed->point_in_room;
      sum_sq += (K.Project(p) - obs[k].px).squaredNorm() * p.z() * p.z() / (K.fx * K.fy);
      ++n_in;
    }
    spreads.push_back(std::sqrt(sum_sq / std::max(1, n_in)));
    out.points_in_room.push_back(placed->point_in_room);
    cv::Mat row(1, kDescriptorBytes, CV_8UC1);
    std::copy_n(descriptor, kDescriptorBytes, row.ptr<std::uint8_t>(0));
    out.descriptors.push_back(row);
  }
  if (!spreads.empty()) {
    std::vector<double> sorted = spreads;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    out.spread_m = sorted[sorted.size() / 2];
  }
  return out;
}

void ToRecord(const ScanLandmarks& landmarks, BodyMarkerMapRecord* record) {
  record->room_landmarks.points.clear();
  record->room_landmarks_placement_sigma_m = landmarks.placement_sigma_m;
  record->room_landmarks_position_sigma_m = landmarks.spread_m;
  for (const Eigen::Vector3d& p : landmarks.points_in_room)
    record->room_landmarks.points.push_back(p.cast<float>());
  record->room_landmark_descriptors = DescriptorsToBytes(landmarks.descriptors);
}

int AddScanLandmarks(const BodyMarkerMapRecord& record, RoomMap* map) {
  const auto& stored = record.room_landmarks.points;
  if (stored.empty()) return 0;
  if (record.room_landmark_descriptors.rows() != static_cast<Eigen::Index>(stored.size()) ||
      record.room_landmark_descriptors.cols() != kDescriptorBytes) {
    ARPOS_INPUT_ERROR("body marker map "
                      << record.id.value() << ": " << stored.size() << " room landmarks but a "
                      << record.room_landmark_descriptors.rows() << " x "
                      << record.room_landmark_descriptors.cols() << " descriptor matrix");
  }
  std::vector<Eigen::Vector3d> points;
  points.reserve(stored.size() + map->landmarks_in_room.size());
  for (const Eigen::Vector3f& p : stored) {
    if (!p.allFinite()) {
      ARPOS_INPUT_ERROR("body marker map " << record.id.value()
                                           << ": a room landmark is not a finite point");
    }
    points.push_back(p.cast<double>());
  }
  points.insert(points.end(), map->landmarks_in_room.begin(), map->landmarks_in_room.end());
  cv::Mat rows = DescriptorsFromBytes(record.room_landmark_descriptors);
  if (!map->landmark_descriptors.empty()) rows.push_back(map->landmark_descriptors);
  map->landmarks_in_room = std::move(points);
  map->landmark_descriptors = rows;
  map->scan_landmarks += static_cast<int>(stored.size());
  map->scan_landmark_sigma_m =
      std::max(map->scan_landmark_sigma_m, record.room_landmarks_position_sigma_m);
  return static_cast<int>(stored.size());
}

}  // namespace arpos
