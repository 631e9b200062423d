#include "report/report_test_util.h"

#include <cmath>

namespace arpos::test {
namespace {

void Audit(Database& db, const std::string& action, const std::string& entity, const std::string& details = "") {
  db.AppendAudit({AuditId(), 0, "report test", action, entity, details});
}

template <typename Id>
std::string Entity(const char* kind, Id id) {
  return std::string(kind) + ":" + std::to_string(id.value());
}

TrackingFrameRecord Frame(std::int64_t index, double t, TrackingFrameStatus status, const std::string& source,
                          const Eigen::Vector3d& mm, const Eigen::Vector3d& deg) {
  TrackingFrameRecord f;
  f.frame_index = index;
  f.timestamp_s = t;
  f.status = status;
  f.source = source;
  f.total_ms = 10.0 + index;
  if (status != TrackingFrameStatus::kLost) {
    f.room_from_model = Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.01 * index, 0, 0));
    f.correction = Correction6Dof{mm, deg};
    f.uncertainty_translation_mm = 0.5;
    f.uncertainty_rotation_deg = 0.1;
  } else {
    f.note = "no body marker seen";
  }
  return f;
}

TrackingRunId AddRun(Database& db, SessionId session, AlignmentId alignment, const std::string& name,
                     const std::vector<TrackingFrameRecord>& frames) {
  TrackingRunRecord run;
  run.session_id = session;
  run.alignment_id = alignment;
  run.tolerance_translation_mm = 3.0;
  run.tolerance_rotation_deg = 2.0;
  run.sequence_name = name;
  run.summary = "test run";
  const TrackingRunId id = db.AddTrackingRun(run);
  db.AppendTrackingFrames(id, frames);
  Audit(db, "track", Entity("tracking_run", id), "run " + name);
  return id;
}

}  // namespace

ReportStoreIds WriteReportStore(Database& db, const ReportStoreOptions& options) {
  ReportStoreIds ids;
  PatientRecord patient;
  patient.external_id = options.patient_external_id;
  patient.display_name = options.patient_name;
  ids.patient = db.AddPatient(patient);
  Audit(db, "add_patient", Entity("patient", ids.patient), "external id " + options.patient_external_id);

  PlanRecord plan;
  plan.patient_id = ids.patient;
  plan.name = options.plan_name;
  plan.reference_model_name = "body.ply";
  plan.reference_model.vertices = {Eigen::Vector3f(0, 0, 0), Eigen::Vector3f(0.1f, 0, 0), Eigen::Vector3f(0, 0.1f, 0),
                                   Eigen::Vector3f(0, 0, 0.1f)};
  plan.reference_model.faces = {{{0, 2, 1}}, {{0, 1, 3}}, {{0, 3, 2}}, {{1, 2, 3}}};
  plan.room_from_model_target =
      Rigid3d::FromRotationVector(Eigen::Vector3d(0, 0, M_PI / 2), Eigen::Vector3d(0.1, -0.2, 0.9));
  ids.plan = db.AddPlan(plan);
  Audit(db, "add_plan", Entity("plan", ids.plan));
  if (options.room_frame_couch_sigma_mm >= 0) {
    RoomMapRecord map;
    map.plan_id = ids.plan;
    map.origin_marker_id = 7;
    map.marker_size_m = 0.15;
    for (int id : {7, 9}) {
      RoomMapMarker marker;
      marker.marker_id = id;
      for (int c = 0; c < 4; ++c)
        marker.corners_in_room[c] = Eigen::Vector3d(id + 0.15 * (c % 2), 0.15 * (c / 2), 0);
      marker.residual_px = 0.05;
      marker.num_observations = 12;
      map.markers.push_back(marker);
    }
    map.mean_residual_px = 0.05;
    map.max_residual_px = 0.06;
    map.room_frame_tilt_sigma_deg = 0.03;
    map.room_frame_yaw_sigma_deg = 0.04;
    map.room_frame_couch_sigma_mm = options.room_frame_couch_sigma_mm;
    map.created_unix_ms = 1700000003000;
    Audit(db, "add_room_map", Entity("room_map", db.AddRoomMap(map)));
  }

  for (int s = 0; s < 2; ++s) {
    SessionRecord session;
    session.plan_id = ids.plan;
    session.fraction = s + 1;
    session.operator_name = "therapist one";
    const SessionId session_id = db.AddSession(session);
    Audit(db, "open_session", Entity("session", session_id), "fraction " + std::to_string(s + 1));

    BodyMarkerMapRecord map;
    map.session_id = session_id;
    map.marker_size_m = 0.04;
    for (int m = 0; m < 3; ++m) {
      BodyMarker marker;
      marker.marker_id = 20 + m;
      marker.residual_px = 0.3 + 0.1 * m;
      marker.num_observations = 12;
      map.markers.push_back(marker);
    }
    map.mean_residual_px = 0.4;
    map.max_residual_px = 0.6;
    const BodyMarkerMapId map_id = db.AddBodyMarkerMap(map);
    Audit(db, "add_body_marker_map", Entity("body_marker_map", map_id));

    ReconstructionRecord rec;
    rec.session_id = session_id;
    for (int i = 0; i < 50; ++i) rec.cloud.points.emplace_back(0.01f * i, 0, 0);
    rec.num_frames_used = 7;
    rec.voxel_size_m = 0.004;
    const ReconstructionId rec_id = db.AddReconstruction(rec);
    Audit(db, "add_reconstruction", Entity("reconstruction", rec_id));

    AlignmentRecord manual;
    manual.reconstruction_id = rec_id;
    manual.method = AlignmentMethod::kManual;
    manual.reconstruction_from_model = Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.001, 0.002, 0.003));
    manual.fitness = 0.8;
    manual.rmse_m = 0.004;
    manual.num_inliers = 40;
    const AlignmentId manual_id = db.AddAlignment(manual);
    Audit(db, "add_alignment", Entity("alignment", manual_id));
    AlignmentRecord icp = manual;
    icp.parent_alignment_id = manual_id;
    icp.method = AlignmentMethod::kIcp;
    icp.fitness = 0.95;
    icp.rmse_m = 0.0012;
    const AlignmentId icp_id = db.AddAlignment(icp);
    Audit(db, "add_alignment", Entity("alignment", icp_id));

    if (s == 1) {
      ids.other_session = session_id;
      AddRun(db, session_id, icp_id, "other_seq",
             {Frame(0, 5.0, TrackingFrameStatus::kInTolerance, "tracked", Eigen::Vector3d(0.1, 0, 0),
                    Eigen::Vector3d::Zero())});
      break;
    }
    ids.session = session_id;
    ids.alignments = {manual_id, icp_id};
    if (options.num_runs >= 1) {
      std::vector<TrackingFrameRecord> frames;
      for (int i = 0; i < 20; ++i) {
        const double t = 100.0 + 0.1 * i;
        if (i < 5) {
          frames.push_back(Frame(i, t, TrackingFrameStatus::kOutOfTolerance, "tracked",
                                 Eigen::Vector3d(10.0 - 2 * i, 1, -1), Eigen::Vector3d(1, 0, 0)));
        } else if (i < 8) {
          frames.push_back(Frame(i, t, TrackingFrameStatus::kLost, "lost", Eigen::Vector3d::Zero(),
                                 Eigen::Vector3d::Zero()));
        } else if (i < 19) {
          frames.push_back(Frame(i, t, TrackingFrameStatus::kInTolerance, i < 10 ? "carried" : "tracked",
                                 Eigen::Vector3d(0.5, 0.2, -0.1), Eigen::Vector3d(0.1, 0.2, 0.3)));
        } else {
          frames.push_back(Frame(i, t, TrackingFrameStatus::kInTolerance, "tracked", Eigen::Vector3d(0.4, -0.3, 0.2),
                                 Eigen::Vector3d(0.1, -0.2, 0.3)));
        }
      }
      ids.runs.push_back(AddRun(db, session_id, icp_id, "seq_00", frames));
    }
    if (options.num_runs >= 2) {
      std::vector<TrackingFrameRecord> frames;
      for (int i = 0; i < 5; ++i) {
        frames.push_back(Frame(i, 0.2 * i, TrackingFrameStatus::kInTolerance, "tracked", Eigen::Vector3d(0.3, 0.1, 0),
                               Eigen::Vector3d(0, 0, 0.1)));
      }
      ids.runs.push_back(AddRun(db, session_id, icp_id, "seq_01", frames));
    }
  }
  db.FinishSession(ids.session, SessionStatus::kCompleted, 0, "report test (therapist)");
  Audit(db, "complete_session", Entity("session", ids.session));
  return ids;
}

}  // namespace arpos::test
