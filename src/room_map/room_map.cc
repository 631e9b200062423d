#include "room_map/room_map.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "features/marker_pose.h"
#include "geometry/umeyama.h"
#include "util/check.h"

namespace arpos {

const RoomMapMarkerEntry* RoomMap::FindMarker(int id) const {
  auto it = std::lower_bound(markers.begin(), markers.end(), id,
                             [](const RoomMapMarkerEntry& m, int v) { return m.id < v; });
  return it != markers.end() && it->id == id ? &*it : nullptr;
}

std::string RoomMap::Validate() const {
  std::ostringstream out;
  if (!(marker_size_m > 0)) {
    out << "marker size must be positive, got " << marker_size_m;
    return out.str();
  }
  if (markers.empty()) return "the map has no markers";
  if (scan_landmarks < 0 || scan_landmarks > num_landmarks() ||
      !(scan_landmark_sigma_m >= 0 && scan_landmark_sigma_m < 1)) {
    out << scan_landmarks << " scan landmarks in a map of " << num_landmarks();
    return out.str();
  }
  for (size_t i = 0; i < markers.size(); ++i) {
    if (i > 0 && markers[i].id <= markers[i - 1].id) return "marker ids must be unique and sorted";
    if (!markers[i].room_from_marker.translation.allFinite()) {
      out << "marker " << markers[i].id << " has a non-finite pose";
      return out.str();
    }
  }
  if (FindMarker(origin_marker_id) == nullptr) {
    out << "the origin marker " << origin_marker_id << " is not in the map";
    return out.str();
  }
  if (!landmarks_in_room.empty() || !landmark_descriptors.empty()) {
    if (landmark_descriptors.type() != CV_8UC1 || landmark_descriptors.cols != kDescriptorBytes ||
        landmark_descriptors.rows != static_cast<int>(landmarks_in_room.size())) {
      out << "landmark descriptors must be " << landmarks_in_room.size() << " x "
          << kDescriptorBytes << " bytes";
      return out.str();
    }
  }
  if (std::string r = surface.Validate(); !r.empty()) return r;
  return "";
}

std::array<Eigen::Vector3d, 4> MarkerCornersInRoom(const Rigid3d& room_from_marker,
                                                   double marker_size_m) {
  std::array<Eigen::Vector3d, 4> corners = MarkerCornersInMarker(marker_size_m);
  for (auto& c : corners) c = room_from_marker * c;
  return corners;
}

double MarkerCornerSigmaPx(const MarkerObservation& observation, int corner, double floor_px,
                           double reference_cell_px, int cells_per_side) {
  double shortest = std::numeric_limits<double>::infinity();
  for (int k = 0; k < 4; ++k) {
    shortest = std::min(shortest, (observation.corners_px[(k + 1) % 4] - observation.corners_px[k]).norm());
  }
  const double cell = std::max(1e-3, shortest / cells_per_side);
  const double base = std::max(floor_px, observation.corner_sigma_px[corner]);
  const double ratio = reference_cell_px / cell;
  return base * (1 + ratio * ratio);
}

ByteMatrix DescriptorsToBytes(const cv::Mat& descriptors) {
  ByteMatrix bytes(descriptors.rows, kDescriptorBytes);
  for (int r = 0; r < descriptors.rows; ++r) {
    std::copy_n(descriptors.ptr<std::uint8_t>(r), kDescriptorBytes, bytes.row(r).data());
  }
  return bytes;
}

cv::Mat DescriptorsFromBytes(const ByteMatrix& bytes) {
  cv::Mat descriptors(static_cast<int>(bytes.rows()), kDescriptorBytes, CV_8UC1);
  for (int r = 0; r < descriptors.rows; ++r) {
    std::copy_n(bytes.row(r).data(), kDescriptorBytes, descriptors.ptr<std::uint8_t>(r));
  }
  return descriptors;
}

RoomMapRecord ToRecord(const RoomMap& map, PlanId plan, std::optional<RecordingId> recording) {
  const std::string problem = map.Validate();
  ARPOS_CHECK(problem.empty(), "cannot store an inconsistent room map: " << problem);
  RoomMapRecord record;
  record.plan_id = plan;
  record.recording_id = recording;
  record.origin_marker_id = map.origin_marker_id;
  record.marker_size_m = map.marker_size_m;
  for (const auto& m : map.markers) {
    RoomMapMarker stored;
    stored.marker_id = m.id;
    stored.corners_in_room = MarkerCornersInRoom(m.room_from_marker, map.marker_size_m);
    stored.residual_px = m.residual_px;
    stored.num_observations = m.num_observations;
    record.markers.push_back(stored);
  }
  record.mean_residual_px = map.mean_residual_px;
  record.max_residual_px = std::max(map.max_residual_px, map.mean_residual_px);
  record.landmarks_in_room.points.reserve(map.landmarks_in_room.size());
  for (const auto& p : map.landmarks_in_room) record.landmarks_in_room.points.push_back(p.cast<float>());
  if (!map.landmarks_in_room.empty())
    record.landmark_descriptors = DescriptorsToBytes(map.landmark_descriptors);
  record.camera_response = map.camera_response.Serialize();
  record.depth_correction = map.depth_correction.Serialize();
  if (!map.surface.empty()) {
    record.surface.points = map.surface.points;
    record.surface.normals = map.surface.normals;
    record.surface_voxel_m = map.surface.voxel_m;
  }
  return record;
}

RoomMap FromRecord(const RoomMapRecord& record) {
  RoomMap map;
  map.origin_marker_id = record.origin_marker_id;
  map.marker_size_m = record.marker_size_m;
  if (!(record.marker_size_m > 0)) {
    ARPOS_INPUT_ERROR("room map " << record.id.value() << ": marker size must be positive");
  }
  const std::array<Eigen::Vector3d, 4> in_marker = MarkerCornersInMarker(record.marker_size_m);
  const std::vector<Eigen::Vector3d> source(in_marker.begin(), in_marker.end());
  for (const auto& stored : record.markers) {
    RoomMapMarkerEntry m;
    m.id = stored.marker_id;
    const std::vector<Eigen::Vector3d> target(stored.corners_in_room.begin(),
                                              stored.corners_in_room.end());
    const std::optional<Sim3Result> fit = EstimateRigidTransform(source, target);
    if (!fit) {
      ARPOS_INPUT_ERROR("room map " << record.id.value() << ": marker " << m.id
                                    << " has degenerate corners");
    }
    m.room_from_marker = fit->target_from_source;
    m.corners_in_room = stored.corners_in_room;
    m.residual_px = stored.residual_px;
    m.num_observations = stored.num_observations;
    map.markers.push_back(m);
  }
  std::sort(map.markers.begin(), map.markers.end(),
            [](const RoomMapMarkerEntry& a, const RoomMapMarkerEntry& b) { return a.id < b.id; });
  map.mean_residual_px = record.mean_residual_px;
  map.max_residual_px = record.max_residual_px;
  const auto& points = record.landmarks_in_room.points;
  if (record.landmark_descriptors.rows() != static_cast<Eigen::Index>(points.size()) ||
      (!points.empty() && record.landmark_descriptors.cols() != kDescriptorBytes)) {
    ARPOS_INPUT_ERROR("room map " << record.id.value() << ": " << points.size()
                                  << " landmarks but a " << record.landmark_descriptors.rows()
                                  << " x " << record.landmark_descriptors.cols()
                                  << " descriptor matrix (expected " << kDescriptorBytes
                                  << " bytes per landmark)");
  }
  map.landmarks_in_room.reserve(points.size());
  for (const auto& p : points) map.landmarks_in_room.push_back(p.cast<double>());
  if (!points.empty()) map.landmark_descriptors = DescriptorsFromBytes(record.landmark_descriptors);
  // Empty: a map stored before the store kept these (schema version 4); the
  // RoomMap defaults are what such a map was used with.
  const std::string where = "room map " + std::to_string(record.id.value());
  if (!record.camera_response.empty()) {
    map.camera_response = CameraResponse::Parse(record.camera_response, where + ": stored camera response");
  }
  if (!record.depth_correction.empty()) {
    map.depth_correction = DepthCorrection::Parse(record.depth_correction, where + ": stored depth correction");
  }
  if (!record.surface.points.empty()) {
    map.surface.voxel_m = record.surface_voxel_m;
    map.surface.points = record.surface.points;
    map.surface.normals = record.surface.normals;
  }
  const std::string problem = map.Validate();
  if (!problem.empty()) ARPOS_INPUT_ERROR(where << ": " << problem);
  return map;
}

ExclusionBox CouchExclusionBox(const Rigid3d& room_from_model_target, double half_width_m,
                               double anterior_m, double posterior_m, double half_length_m) {
  ExclusionBox box;
  // Model frame (LPS): y posterior. The box spans y in [-anterior, +posterior].
  const Eigen::Vector3d centre_in_model(0, 0.5 * (posterior_m - anterior_m), 0);
  box.room_from_box = room_from_model_target * Rigid3d(Eigen::Quaterniond::Identity(), centre_in_model);
  box.half_extent_m = Eigen::Vector3d(half_width_m, 0.5 * (posterior_m + anterior_m), half_length_m);
  return box;
}

}  // namespace arpos
