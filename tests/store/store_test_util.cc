#include "store_test_util.h"

#include <fstream>
#include <sstream>

namespace arpos::test {

Rigid3d RandomPose(std::mt19937& rng) {
  std::uniform_real_distribution<double> angle(-3.0, 3.0);
  std::uniform_real_distribution<double> offset(-2.0, 2.0);
  Eigen::Vector3d axis(angle(rng), angle(rng), angle(rng));
  axis = axis.normalized() * std::abs(angle(rng));
  return Rigid3d::FromRotationVector(axis, Eigen::Vector3d(offset(rng), offset(rng), offset(rng)));
}

StoredPointCloud RandomCloud(std::mt19937& rng, int num_points, bool normals, bool colors) {
  std::uniform_real_distribution<float> coordinate(-1.0f, 1.0f);
  std::uniform_int_distribution<int> channel(0, 255);
  StoredPointCloud cloud;
  for (int i = 0; i < num_points; ++i) {
    cloud.points.emplace_back(coordinate(rng), coordinate(rng), coordinate(rng));
    if (normals) {
      cloud.normals.push_back(
          Eigen::Vector3f(coordinate(rng), coordinate(rng), coordinate(rng)).normalized());
    }
    if (colors) {
      cloud.colors.push_back({static_cast<std::uint8_t>(channel(rng)),
                              static_cast<std::uint8_t>(channel(rng)),
                              static_cast<std::uint8_t>(channel(rng))});
    }
  }
  return cloud;
}

StoredTriangleMesh RandomMesh(std::mt19937& rng) {
  std::uniform_real_distribution<float> jitter(-0.01f, 0.01f);
  StoredTriangleMesh mesh;
  mesh.vertices = {{0.0f + jitter(rng), 0.0f, 0.0f},
                   {0.3f, 0.0f + jitter(rng), 0.0f},
                   {0.0f, 0.2f, 0.0f + jitter(rng)},
                   {0.0f, 0.0f, 0.25f}};
  mesh.faces = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  return mesh;
}

RecordingIntrinsics SomeIntrinsics() {
  RecordingIntrinsics k;
  k.width = 640;
  k.height = 480;
  k.fx = 525.0;
  k.fy = 526.5;
  k.cx = 319.5;
  k.cy = 239.5;
  k.distortion = {0.1, -0.05, 0.001, -0.002, 0.01};
  k.depth_scale = 5000.0;
  return k;
}

FullStore WriteFullStore(Database& database, unsigned seed) {
  std::mt19937 rng(seed);
  FullStore s;
  const std::string tag = std::to_string(seed);

  s.patient.external_id = "MRN-" + tag;
  s.patient.display_name = "Test Patient " + tag;
  s.patient.created_unix_ms = 1700000000000 + seed;
  s.patient.id = database.AddPatient(s.patient);

  s.plan.patient_id = s.patient.id;
  s.plan.name = "Pelvis plan " + tag;
  s.plan.reference_model_name = "reference_model.ply";
  s.plan.reference_model = RandomMesh(rng);
  s.plan.room_from_model_target = RandomPose(rng);
  s.plan.created_unix_ms = 1700000001000 + seed;
  s.plan.id = database.AddPlan(s.plan);

  s.room_recording.plan_id = s.plan.id;
  s.room_recording.kind = RecordingKind::kRoom;
  s.room_recording.name = "room";
  s.room_recording.path = "/cases/" + tag + "/room";
  s.room_recording.frame_count = 412;
  s.room_recording.intrinsics = SomeIntrinsics();
  s.room_recording.created_unix_ms = 1700000002000;
  s.room_recording.id = database.AddRecording(s.room_recording);

  s.room_map.plan_id = s.plan.id;
  s.room_map.recording_id = s.room_recording.id;
  s.room_map.origin_marker_id = 0;
  s.room_map.marker_size_m = 0.15;
  for (int id : {0, 7, 12}) {
    RoomMapMarker marker;
    marker.marker_id = id;
    const Rigid3d room_from_marker = RandomPose(rng);
    const double half = 0.075;
    const Eigen::Vector3d corners[4] = {
        {-half, half, 0}, {half, half, 0}, {half, -half, 0}, {-half, -half, 0}};
    for (int c = 0; c < 4; ++c) marker.corners_in_room[c] = room_from_marker * corners[c];
    marker.residual_px = 0.25 + id * 0.01;
    marker.num_observations = 30 + id;
    s.room_map.markers.push_back(marker);
  }
  s.room_map.mean_residual_px = 0.3;
  s.room_map.max_residual_px = 0.9;
  s.room_map.landmarks_in_room = RandomCloud(rng, 25, false, false);
  s.room_map.landmark_descriptors = ByteMatrix::Random(25, 32);
  // The store keeps these as opaque text (the room map layer parses them).
  s.room_map.camera_response = "estimated: 0.0000 0.0771 " + tag;
  s.room_map.depth_correction = "depth correction: 0.0042 0 0 0 0 0 0 " + tag;
  s.room_map.room_frame_tilt_sigma_deg = 0.0125;
  s.room_map.room_frame_yaw_sigma_deg = 0.031;
  s.room_map.room_frame_couch_sigma_mm = 0.27;
  s.room_map.created_unix_ms = 1700000003000;
  s.room_map.id = database.AddRoomMap(s.room_map);

  s.session.plan_id = s.plan.id;
  s.session.fraction = 3;
  s.session.operator_name = "RTT Smith";
  s.session.started_unix_ms = 1700000100000;
  s.session.notes = "first fraction after re-plan";
  s.session.id = database.AddSession(s.session);

  s.body_scan.session_id = s.session.id;
  s.body_scan.kind = RecordingKind::kBodyScan;
  s.body_scan.name = "body_scan";
  s.body_scan.path = "/cases/" + tag + "/body_scan";
  s.body_scan.frame_count = 180;
  s.body_scan.intrinsics = SomeIntrinsics();
  s.body_scan.created_unix_ms = 1700000101000;
  s.body_scan.id = database.AddRecording(s.body_scan);

  s.body_marker_map.session_id = s.session.id;
  s.body_marker_map.recording_id = s.body_scan.id;
  s.body_marker_map.marker_size_m = 0.03;
  for (int id : {101, 105}) {
    BodyMarker marker;
    marker.marker_id = id;
    marker.body_from_marker = RandomPose(rng);
    marker.residual_px = 0.4;
    marker.num_observations = 60;
    marker.motion_m = id == 105 ? 0.0012 : 0.0;  // one sticker moved with the breathing
    if (id == 105)
      marker.motion_direction = Eigen::Vector3d(0.0, 0.6, 0.8);  // which way it measured
    s.body_marker_map.markers.push_back(marker);
  }
  s.body_marker_map.surface_patch_m = 0.04;
  s.body_marker_map.moving_surface_patches = {{0.02, -0.1, 0.06}, {-0.02, -0.1, 0.1}};
  s.body_marker_map.room_landmarks.points = {
      {1.2f, -0.7f, 2.9f}, {0.4f, -1.5f, 3.3f}, {2.0f, 0.3f, 3.1f}};
  s.body_marker_map.room_landmark_descriptors.resize(3, 32);
  s.body_marker_map.room_landmarks_placement_sigma_m = 0.0009;
  s.body_marker_map.room_landmarks_position_sigma_m = 0.0025;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 32; ++c)
      s.body_marker_map.room_landmark_descriptors(r, c) = static_cast<std::uint8_t>(7 * r + c);
  }
  s.body_marker_map.mean_residual_px = 0.4;
  s.body_marker_map.max_residual_px = 1.1;
  s.body_marker_map.created_unix_ms = 1700000102000;
  s.body_marker_map.id = database.AddBodyMarkerMap(s.body_marker_map);

  s.reconstruction.session_id = s.session.id;
  s.reconstruction.recording_id = s.body_scan.id;
  s.reconstruction.cloud = RandomCloud(rng, 200, true, true);
  s.reconstruction.mesh = RandomMesh(rng);
  s.reconstruction.num_frames_used = 150;
  s.reconstruction.voxel_size_m = 0.004;
  s.reconstruction.created_unix_ms = 1700000103000;
  s.reconstruction.id = database.AddReconstruction(s.reconstruction);

  s.manual_alignment.reconstruction_id = s.reconstruction.id;
  s.manual_alignment.method = AlignmentMethod::kManual;
  s.manual_alignment.reconstruction_from_model = RandomPose(rng);
  s.manual_alignment.fitness = 0.5;
  s.manual_alignment.rmse_m = 0.008;
  s.manual_alignment.num_inliers = 4;
  s.manual_alignment.created_unix_ms = 1700000104000;
  s.manual_alignment.id = database.AddAlignment(s.manual_alignment);

  s.icp_alignment.reconstruction_id = s.reconstruction.id;
  s.icp_alignment.parent_alignment_id = s.manual_alignment.id;
  s.icp_alignment.method = AlignmentMethod::kIcp;
  s.icp_alignment.reconstruction_from_model = RandomPose(rng);
  s.icp_alignment.fitness = 0.93;
  s.icp_alignment.rmse_m = 0.0012;
  s.icp_alignment.num_inliers = 180;
  s.icp_alignment.options = "max_iterations: 50\nmax_correspondence_distance_m: 0.01\n";
  s.icp_alignment.created_unix_ms = 1700000105000;
  s.icp_alignment.id = database.AddAlignment(s.icp_alignment);

  s.tracking_run.session_id = s.session.id;
  s.tracking_run.alignment_id = s.icp_alignment.id;
  s.tracking_run.options = "tolerance_translation_mm: 2.5\n";
  s.tracking_run.tolerance_translation_mm = 2.5;
  s.tracking_run.tolerance_rotation_deg = 1.5;
  s.tracking_run.started_unix_ms = 1700000106000;
  s.tracking_run.sequence_name = "fraction_2_" + tag;
  s.tracking_run.summary = "10 frames: 6 tracked, 2 carried, 2 lost; 4 in, 4 out; 21.5 ms/frame";
  s.tracking_run.id = database.AddTrackingRun(s.tracking_run);

  // Frame 4 is lost with the camera not localised, frame 8 lost with the
  // camera localised (patient not found), frames 2 and 3 carried. The camera
  // poses come from a generator of their own so that the other records stay
  // what they were before schema version 5.
  std::mt19937 camera_rng(seed + 1000);
  for (int i = 0; i < 10; ++i) {
    TrackingFrameRecord frame;
    frame.frame_index = i;
    frame.timestamp_s = 1305031102.175304 + i / 30.0;
    frame.total_ms = 15.25 + i;
    if (i == 4 || i == 8) {
      frame.status = TrackingFrameStatus::kLost;
      frame.source = "lost";
      if (i == 8) frame.room_from_camera = RandomPose(camera_rng);
      frame.note = i == 4 ? "camera not localised" : "patient not found: no body marker seen";
    } else {
      frame.status =
          i < 6 ? TrackingFrameStatus::kOutOfTolerance : TrackingFrameStatus::kInTolerance;
      frame.room_from_model = RandomPose(rng);
      Correction6Dof correction;
      correction.translation_mm = Eigen::Vector3d(10.0 - i, -2.5, 0.5 * i);
      correction.rotation_deg = Eigen::Vector3d(0.1 * i, -0.2, 1.0);
      frame.correction = correction;
      frame.room_from_camera = RandomPose(camera_rng);
      frame.source = i == 2 || i == 3 ? "carried" : "tracked";
      if (frame.source == "carried") frame.note = "depth registration rejected; stickers carried";
      frame.uncertainty_translation_mm = 0.25 * i;  // 0 for frame 0: the bound may be 0
      frame.uncertainty_rotation_deg = 0.05 + 0.01 * i;
    }
    s.frames.push_back(frame);
  }
  database.AppendTrackingFrames(s.tracking_run.id, s.frames);

  for (int i = 0; i < 2; ++i) {
    AuditEntry entry;
    entry.time_unix_ms = 1700000200000 + i;
    entry.actor = "operator:smith";
    entry.action = i == 0 ? "approve_alignment" : "start_tracking";
    entry.entity = i == 0 ? "alignment:" + std::to_string(s.icp_alignment.id.value())
                          : "tracking_run:" + std::to_string(s.tracking_run.id.value());
    entry.details = "seed " + tag;
    entry.id = database.AppendAudit(entry);
    s.audit.push_back(entry);
  }
  return s;
}

void ExpectPoseEq(const Rigid3d& expected, const Rigid3d& actual) {
  EXPECT_TRUE(expected.IsApprox(actual, 1e-12, 1e-12))
      << "expected " << expected.ToString() << "\n  actual " << actual.ToString();
}

void ExpectCloudEq(const StoredPointCloud& expected, const StoredPointCloud& actual) {
  ASSERT_EQ(expected.points.size(), actual.points.size());
  ASSERT_EQ(expected.normals.size(), actual.normals.size());
  ASSERT_EQ(expected.colors.size(), actual.colors.size());
  for (std::size_t i = 0; i < expected.points.size(); ++i) {
    EXPECT_EQ(expected.points[i], actual.points[i]) << "point " << i;  // bit-exact float32
  }
  for (std::size_t i = 0; i < expected.normals.size(); ++i) {
    EXPECT_EQ(expected.normals[i], actual.normals[i]) << "normal " << i;
  }
  for (std::size_t i = 0; i < expected.colors.size(); ++i) {
    EXPECT_EQ(expected.colors[i], actual.colors[i]) << "colour " << i;
  }
}

void ExpectMeshEq(const StoredTriangleMesh& expected, const StoredTriangleMesh& actual) {
  ASSERT_EQ(expected.vertices.size(), actual.vertices.size());
  for (std::size_t i = 0; i < expected.vertices.size(); ++i) {
    EXPECT_EQ(expected.vertices[i], actual.vertices[i]) << "vertex " << i;
  }
  EXPECT_EQ(expected.faces, actual.faces);
}

void ExpectFullStoreEq(Database& database, const FullStore& s) {
  const auto patient = database.GetPatient(s.patient.id);
  ASSERT_TRUE(patient.has_value());
  EXPECT_EQ(patient->external_id, s.patient.external_id);
  EXPECT_EQ(patient->display_name, s.patient.display_name);
  EXPECT_EQ(patient->created_unix_ms, s.patient.created_unix_ms);

  const auto plan = database.GetPlan(s.plan.id);
  ASSERT_TRUE(plan.has_value());
  EXPECT_EQ(plan->patient_id, s.patient.id);
  EXPECT_EQ(plan->name, s.plan.name);
  EXPECT_EQ(plan->reference_model_name, s.plan.reference_model_name);
  ExpectMeshEq(s.plan.reference_model, plan->reference_model);
  ExpectPoseEq(s.plan.room_from_model_target, plan->room_from_model_target);
  EXPECT_EQ(plan->created_unix_ms, s.plan.created_unix_ms);

  for (const RecordingRecord* expected : {&s.room_recording, &s.body_scan}) {
    const auto recording = database.GetRecording(expected->id);
    ASSERT_TRUE(recording.has_value());
    EXPECT_EQ(recording->plan_id, expected->plan_id);
    EXPECT_EQ(recording->session_id, expected->session_id);
    EXPECT_EQ(recording->kind, expected->kind);
    EXPECT_EQ(recording->name, expected->name);
    EXPECT_EQ(recording->path, expected->path);
    EXPECT_EQ(recording->frame_count, expected->frame_count);
    EXPECT_EQ(recording->intrinsics.width, expected->intrinsics.width);
    EXPECT_EQ(recording->intrinsics.height, expected->intrinsics.height);
    EXPECT_EQ(recording->intrinsics.fx, expected->intrinsics.fx);
    EXPECT_EQ(recording->intrinsics.fy, expected->intrinsics.fy);
    EXPECT_EQ(recording->intrinsics.cx, expected->intrinsics.cx);
    EXPECT_EQ(recording->intrinsics.cy, expected->intrinsics.cy);
    EXPECT_EQ(recording->intrinsics.distortion, expected->intrinsics.distortion);
    EXPECT_EQ(recording->intrinsics.depth_scale, expected->intrinsics.depth_scale);
    EXPECT_EQ(recording->created_unix_ms, expected->created_unix_ms);
  }

  const auto room_map = database.GetRoomMap(s.room_map.id);
  ASSERT_TRUE(room_map.has_value());
  EXPECT_EQ(room_map->plan_id, s.plan.id);
  EXPECT_EQ(room_map->recording_id, s.room_recording.id);
  EXPECT_EQ(room_map->origin_marker_id, s.room_map.origin_marker_id);
  EXPECT_EQ(room_map->marker_size_m, s.room_map.marker_size_m);
  EXPECT_EQ(room_map->mean_residual_px, s.room_map.mean_residual_px);
  EXPECT_EQ(room_map->max_residual_px, s.room_map.max_residual_px);
  ASSERT_EQ(room_map->markers.size(), s.room_map.markers.size());
  for (std::size_t i = 0; i < s.room_map.markers.size(); ++i) {
    const RoomMapMarker& e = s.room_map.markers[i];
    const RoomMapMarker& a = room_map->markers[i];
    EXPECT_EQ(a.marker_id, e.marker_id);
    for (int c = 0; c < 4; ++c) EXPECT_EQ(a.corners_in_room[c], e.corners_in_room[c]);
    EXPECT_EQ(a.residual_px, e.residual_px);
    EXPECT_EQ(a.num_observations, e.num_observations);
  }
  ExpectCloudEq(s.room_map.landmarks_in_room, room_map->landmarks_in_room);
  EXPECT_EQ(room_map->landmark_descriptors, s.room_map.landmark_descriptors);
  EXPECT_EQ(room_map->camera_response, s.room_map.camera_response);
  EXPECT_EQ(room_map->depth_correction, s.room_map.depth_correction);
  EXPECT_EQ(room_map->room_frame_tilt_sigma_deg, s.room_map.room_frame_tilt_sigma_deg);
  EXPECT_EQ(room_map->room_frame_yaw_sigma_deg, s.room_map.room_frame_yaw_sigma_deg);
  EXPECT_EQ(room_map->room_frame_couch_sigma_mm, s.room_map.room_frame_couch_sigma_mm);
  EXPECT_EQ(room_map->created_unix_ms, s.room_map.created_unix_ms);
  EXPECT_EQ(database.LatestRoomMap(s.plan.id), s.room_map.id);

  const auto session = database.GetSession(s.session.id);
  ASSERT_TRUE(session.has_value());
  EXPECT_EQ(session->plan_id, s.plan.id);
  EXPECT_EQ(session->fraction, s.session.fraction);
  EXPECT_EQ(session->operator_name, s.session.operator_name);
  EXPECT_EQ(session->started_unix_ms, s.session.started_unix_ms);
  EXPECT_EQ(session->status, s.session.status);
  EXPECT_EQ(session->ended_unix_ms, s.session.ended_unix_ms);
  EXPECT_EQ(session->notes, s.session.notes);

  const auto body_map = database.GetBodyMarkerMap(s.body_marker_map.id);
  ASSERT_TRUE(body_map.has_value());
  EXPECT_EQ(body_map->session_id, s.session.id);
  EXPECT_EQ(body_map->recording_id, s.body_scan.id);
  EXPECT_EQ(body_map->marker_size_m, s.body_marker_map.marker_size_m);
  EXPECT_EQ(body_map->mean_residual_px, s.body_marker_map.mean_residual_px);
  EXPECT_EQ(body_map->max_residual_px, s.body_marker_map.max_residual_px);
  EXPECT_EQ(body_map->created_unix_ms, s.body_marker_map.created_unix_ms);
  ASSERT_EQ(body_map->markers.size(), s.body_marker_map.markers.size());
  for (std::size_t i = 0; i < s.body_marker_map.markers.size(); ++i) {
    EXPECT_EQ(body_map->markers[i].marker_id, s.body_marker_map.markers[i].marker_id);
    ExpectPoseEq(s.body_marker_map.markers[i].body_from_marker,
                 body_map->markers[i].body_from_marker);
    EXPECT_EQ(body_map->markers[i].residual_px, s.body_marker_map.markers[i].residual_px);
    EXPECT_EQ(body_map->markers[i].num_observations, s.body_marker_map.markers[i].num_observations);
    EXPECT_EQ(body_map->markers[i].motion_m, s.body_marker_map.markers[i].motion_m);
    EXPECT_TRUE(body_map->markers[i].motion_direction.isApprox(
        s.body_marker_map.markers[i].motion_direction, 1e-12))
        << body_map->markers[i].motion_direction.transpose();
  }
  EXPECT_EQ(body_map->surface_patch_m, s.body_marker_map.surface_patch_m);
  ASSERT_EQ(body_map->moving_surface_patches.size(), s.body_marker_map.moving_surface_patches.size());
  for (std::size_t i = 0; i < s.body_marker_map.moving_surface_patches.size(); ++i) {
    EXPECT_EQ(body_map->moving_surface_patches[i], s.body_marker_map.moving_surface_patches[i]);
  }
  ExpectCloudEq(s.body_marker_map.room_landmarks, body_map->room_landmarks);
  EXPECT_EQ(body_map->room_landmark_descriptors, s.body_marker_map.room_landmark_descriptors);
  EXPECT_EQ(body_map->room_landmarks_placement_sigma_m,
            s.body_marker_map.room_landmarks_placement_sigma_m);
  EXPECT_EQ(body_map->room_landmarks_position_sigma_m,
            s.body_marker_map.room_landmarks_position_sigma_m);

  const auto reconstruction = database.GetReconstruction(s.reconstruction.id);
  ASSERT_TRUE(reconstruction.has_value());
  EXPECT_EQ(reconstruction->session_id, s.session.id);
  EXPECT_EQ(reconstruction->recording_id, s.body_scan.id);
  ExpectCloudEq(s.reconstruction.cloud, reconstruction->cloud);
  ASSERT_EQ(reconstruction->mesh.has_value(), s.reconstruction.mesh.has_value());
  if (s.reconstruction.mesh) ExpectMeshEq(*s.reconstruction.mesh, *reconstruction->mesh);
  EXPECT_EQ(reconstruction->num_frames_used, s.reconstruction.num_frames_used);
  EXPECT_EQ(reconstruction->voxel_size_m, s.reconstruction.voxel_size_m);
  EXPECT_EQ(reconstruction->created_unix_ms, s.reconstruction.created_unix_ms);

  const std::vector<AlignmentRecord> alignments = database.ListAlignments(s.reconstruction.id);
  ASSERT_EQ(alignments.size(), 2u);
  for (std::size_t i = 0; i < 2; ++i) {
    const AlignmentRecord& e = i == 0 ? s.manual_alignment : s.icp_alignment;
    const AlignmentRecord& a = alignments[i];
    EXPECT_EQ(a.id, e.id);
    EXPECT_EQ(a.reconstruction_id, e.reconstruction_id);
    EXPECT_EQ(a.parent_alignment_id, e.parent_alignment_id);
    EXPECT_EQ(a.method, e.method);
    ExpectPoseEq(e.reconstruction_from_model, a.reconstruction_from_model);
    EXPECT_EQ(a.fitness, e.fitness);
    EXPECT_EQ(a.rmse_m, e.rmse_m);
    EXPECT_EQ(a.num_inliers, e.num_inliers);
    EXPECT_EQ(a.options, e.options);
    EXPECT_EQ(a.created_unix_ms, e.created_unix_ms);
  }

  const auto run = database.GetTrackingRun(s.tracking_run.id);
  ASSERT_TRUE(run.has_value());
  EXPECT_EQ(run->session_id, s.session.id);
  EXPECT_EQ(run->alignment_id, s.tracking_run.alignment_id);
  EXPECT_EQ(run->recording_id, s.tracking_run.recording_id);
  EXPECT_EQ(run->options, s.tracking_run.options);
  EXPECT_EQ(run->tolerance_translation_mm, s.tracking_run.tolerance_translation_mm);
  EXPECT_EQ(run->tolerance_rotation_deg, s.tracking_run.tolerance_rotation_deg);
  EXPECT_EQ(run->started_unix_ms, s.tracking_run.started_unix_ms);
  EXPECT_EQ(run->sequence_name, s.tracking_run.sequence_name);
  EXPECT_EQ(run->summary, s.tracking_run.summary);

  const std::vector<TrackingFrameRecord> frames = database.GetTrackingFrames(s.tracking_run.id);
  ASSERT_EQ(frames.size(), s.frames.size());
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const TrackingFrameRecord& e = s.frames[i];
    const TrackingFrameRecord& a = frames[i];
    EXPECT_EQ(a.frame_index, e.frame_index);
    EXPECT_EQ(a.timestamp_s, e.timestamp_s);
    EXPECT_EQ(a.status, e.status);
    ASSERT_EQ(a.room_from_model.has_value(), e.room_from_model.has_value()) << "frame " << i;
    if (e.room_from_model) ExpectPoseEq(*e.room_from_model, *a.room_from_model);
    ASSERT_EQ(a.correction.has_value(), e.correction.has_value()) << "frame " << i;
    if (e.correction) {
      EXPECT_EQ(a.correction->translation_mm, e.correction->translation_mm);
      EXPECT_EQ(a.correction->rotation_deg, e.correction->rotation_deg);
    }
    ASSERT_EQ(a.room_from_camera.has_value(), e.room_from_camera.has_value()) << "frame " << i;
    if (e.room_from_camera) ExpectPoseEq(*e.room_from_camera, *a.room_from_camera);
    EXPECT_EQ(a.source, e.source) << "frame " << i;
    EXPECT_EQ(a.uncertainty_translation_mm, e.uncertainty_translation_mm) << "frame " << i;
    EXPECT_EQ(a.uncertainty_rotation_deg, e.uncertainty_rotation_deg) << "frame " << i;
    EXPECT_EQ(a.total_ms, e.total_ms) << "frame " << i;
    EXPECT_EQ(a.note, e.note) << "frame " << i;
  }

  const std::vector<AuditEntry> audit = database.ListAudit();
  ASSERT_GE(audit.size(), s.audit.size());
  for (const AuditEntry& e : s.audit) {
    bool found = false;
    for (const AuditEntry& a : audit) {
      if (a.id != e.id) continue;
      found = true;
      EXPECT_EQ(a.time_unix_ms, e.time_unix_ms);
      EXPECT_EQ(a.actor, e.actor);
      EXPECT_EQ(a.action, e.action);
      EXPECT_EQ(a.entity, e.entity);
      EXPECT_EQ(a.details, e.details);
    }
    EXPECT_TRUE(found) << "audit entry " << e.id.value();
  }
}

std::string FileBytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return "";
  std::ostringstream bytes;
  bytes << in.rdbuf();
  return bytes.str();
}

}  // namespace arpos::test
