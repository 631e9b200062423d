#include "report/session_report.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <set>
#include <type_traits>
#include <utility>

#include "store/sqlite_database.h"
#include "util/check.h"
#include "util/string_util.h"

#ifndef ARPOS_VERSION
#define ARPOS_VERSION "unknown"
#endif

namespace arpos {
namespace {

PlanApprovalInfo ApprovalOf(const PlanRecord& plan) {
  PlanApprovalInfo info;
  info.approved = plan.approved();
  info.approved_by = plan.approved_by;
  info.approved_unix_ms = plan.approved_unix_ms.value_or(0);
  info.note = plan.approval_note;
  return info;
}

std::int64_t NowUnixMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

ReportRun SummariseRun(const TrackingRunRecord& run, const std::vector<TrackingFrameRecord>& frames) {
  ReportRun r;
  r.run = run;
  r.name = !run.sequence_name.empty() ? run.sequence_name : "run " + std::to_string(run.id.value());
  r.num_frames = static_cast<int>(frames.size());
  const double t0 = frames.empty() ? 0.0 : frames.front().timestamp_s;
  std::vector<double> latencies;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const TrackingFrameRecord& f = frames[i];
    ReportFrame rf;
    rf.frame_index = f.frame_index;
    rf.time_s = f.timestamp_s - t0;
    rf.status = f.status;
    rf.source = f.source;
    rf.correction = f.correction;
    rf.total_ms = f.total_ms;
    if (f.source == "tracked") ++r.num_tracked;
    else if (f.source == "carried") ++r.num_carried;
    else ++r.num_lost_source;
    switch (f.status) {
      case TrackingFrameStatus::kInTolerance:
        ++r.num_in;
        if (i + 1 < frames.size()) r.time_in_tolerance_s += std::max(0.0, frames[i + 1].timestamp_s - f.timestamp_s);
        break;
      case TrackingFrameStatus::kOutOfTolerance: ++r.num_out; break;
      case TrackingFrameStatus::kLost: ++r.num_lost; break;
    }
    if (f.correction) {
      if (!r.first_correction) r.first_correction = rf;
      r.last_correction = rf;
      r.max_translation_mm = std::max(r.max_translation_mm, f.correction->translation_mm.norm());
      r.max_rotation_deg = std::max(r.max_rotation_deg, f.correction->rotation_deg.norm());
    }
    if (f.total_ms > 0) latencies.push_back(f.total_ms);
    r.frames.push_back(std::move(rf));
  }
  if (frames.size() >= 2) r.duration_s = frames.back().timestamp_s - t0;
  r.latency_frames = static_cast<int>(latencies.size());
  if (!latencies.empty()) {
    double sum = 0;
    for (double l : latencies) sum += l;
    r.latency_mean_ms = sum / latencies.size();
    std::sort(latencies.begin(), latencies.end());
    // Nearest-rank 95th percentile.
    const std::size_t rank =
        static_cast<std::size_t>(std::ceil(0.95 * static_cast<double>(latencies.size())));
    r.latency_p95_ms = latencies[std::min(latencies.size(), std::max<std::size_t>(rank, 1)) - 1];
  }
  return r;
}

// "kind:N" -> (kind, N); nullopt if the entity is not of that form.
std::optional<std::pair<std::string, std::int64_t>> ParseEntity(const std::string& entity) {
  const std::size_t colon = entity.find(':');
  if (colon == std::string::npos || colon == 0 || colon + 1 >= entity.size()) return std::nullopt;
  std::int64_t value = 0;
  for (std::size_t i = colon + 1; i < entity.size(); ++i) {
    if (entity[i] < '0' || entity[i] > '9') return std::nullopt;
    value = value * 10 + (entity[i] - '0');
    if (value > (std::int64_t(1) << 53)) return std::nullopt;
  }
  return std::make_pair(entity.substr(0, colon), value);
}

}  // namespace

const char* ReportProgramVersion() { return ARPOS_VERSION; }

std::string FormatVector3(const Eigen::Vector3d& v, int decimals) {
  char text[160];
  std::snprintf(text, sizeof text, "%.*f, %.*f, %.*f", decimals, v.x(), decimals, v.y(), decimals, v.z());
  return text;
}

std::string DescribeBreathing(const BodyMarkerMapRecord& map) {
  std::string ids;
  double lo = 0, hi = 0;
  for (const BodyMarker& m : map.markers) {
    if (!(m.motion_m > 0)) continue;
    lo = ids.empty() ? m.motion_m : std::min(lo, m.motion_m);
    hi = std::max(hi, m.motion_m);
    ids += (ids.empty() ? "" : ", ") + std::to_string(m.marker_id);
  }
  if (ids.empty() && map.moving_surface_patches.empty()) {
    return "no sticker or surface patch moved with the breathing (or the scan could not tell)";
  }
  int directed = 0, moving = 0;
  for (const BodyMarker& m : map.markers) {
    if (!(m.motion_m > 0)) continue;
    ++moving;
    if (m.HasMotionDirection()) ++directed;
  }
  const std::string along = directed == 0        ? "along their normals"
                            : directed == moving ? "each along the direction the scan measured"
                                                 : StringPrintf(
                                                       "along the direction the scan measured for "
                                                       "%d of them, the others along their normals",
                                                       directed);
  const std::string stickers =
      ids.empty() ? "no sticker moved with the breathing"
                  : (ids.find(',') == std::string::npos ? "sticker " : "stickers ") + ids +
                        StringPrintf(" moved with the breathing (%.1f-%.1f mm, 1 sigma %s)",
                                     1000 * lo, 1000 * hi, along.c_str());
  return stickers + StringPrintf("; %zu surface patches of %.0f mm moved", map.moving_surface_patches.size(),
                                 1000 * map.surface_patch_m);
}

std::string DescribeScanLandmarks(const BodyMarkerMapRecord& map) {
  const std::size_t n = map.room_landmarks.points.size();
  if (n == 0) {
    return "none (the scan's place in the room was not known well enough, it saw too little of the "
           "room outside the couch, or the map was stored before the scan placed any)";
  }
  return StringPrintf(
      "%zu keypoint(s) around the couch, which tracking uses only for frames the room map does not "
      "place; in the room as the scan was placed (%.1f mm at the stickers, 1 sigma), each to %.1f "
      "mm",
      n, 1000 * map.room_landmarks_placement_sigma_m, 1000 * map.room_landmarks_position_sigma_m);
}

std::string VerificationLine(const AuditVerification& v) {
  std::string line;
  if (v.ok()) {
    line = "Audit log verifies: " + std::to_string(v.chained_entries) + " entries in the hash chain";
    if (v.legacy_entries > 0) {
      line += " (and " + std::to_string(v.legacy_entries) + " older entries from before the chain, not verifiable)";
    }
    line += "; the append-only triggers are in place; every clinical record has its audit entry.";
  } else {
    line = "Audit log does not verify (" + std::to_string(v.problems.size()) +
           (v.problems.size() == 1 ? " problem" : " problems") + "): " + v.problems.front();
  }
  return line;
}

SessionReport GatherSessionReport(Database* database, SessionId session_id, const std::string& store_path) {
  ARPOS_CHECK(database != nullptr, "GatherSessionReport needs a store");
  SessionReport report;
  report.generated_unix_ms = NowUnixMs();
  report.program_version = ReportProgramVersion();
  report.store_path = store_path;

  const std::optional<SessionRecord> session = database->GetSession(session_id);
  if (!session) {
    ARPOS_INPUT_ERROR("session " << session_id.value() << " is not in the store "
                                 << (store_path.empty() ? std::string("(in memory)") : store_path));
  }
  report.session = *session;
  if (std::optional<PlanRecord> plan = database->GetPlan(session->plan_id)) {
    report.reference_model_vertices = static_cast<std::int64_t>(plan->reference_model.vertices.size());
    report.reference_model_faces = static_cast<std::int64_t>(plan->reference_model.faces.size());
    plan->reference_model = StoredTriangleMesh();
    report.approval = ApprovalOf(*plan);
    if (const auto map_id = database->LatestRoomMap(plan->id)) {
      if (const std::optional<RoomMapRecord> map = database->GetRoomMap(*map_id)) {
        ReportRoomMap summary;
        summary.id = map->id;
        summary.origin_marker_id = map->origin_marker_id;
        summary.num_markers = static_cast<int>(map->markers.size());
        summary.num_landmarks = static_cast<std::int64_t>(map->landmarks_in_room.points.size());
        summary.mean_residual_px = map->mean_residual_px;
        summary.max_residual_px = map->max_residual_px;
        summary.created_unix_ms = map->created_unix_ms;
        summary.room_frame = RoomFrameSigmasOf(*map);
        report.room_map = summary;
      }
    }
    report.plan = std::move(*plan);
    if (std::optional<PatientRecord> patient = database->GetPatient(report.plan.patient_id)) {
      report.patient = std::move(*patient);
    }
  }

  // What belongs to the session, by audit entity kind.
  std::map<std::string, std::set<std::int64_t>> mine;
  mine["session"].insert(session_id.value());
  mine["plan"].insert(report.plan.id.value());
  mine["patient"].insert(report.patient.id.value());

  for (const BodyMarkerMapId id : database->ListBodyMarkerMapIds(session_id)) {
    if (std::optional<BodyMarkerMapRecord> map = database->GetBodyMarkerMap(id)) {
      report.body_marker_maps.push_back(std::move(*map));
      mine["body_marker_map"].insert(id.value());
    }
  }
  std::vector<TrackingRunRecord> runs;
  for (const TrackingRunId id : database->ListTrackingRunIds(session_id)) {
    if (std::optional<TrackingRunRecord> run = database->GetTrackingRun(id)) runs.push_back(std::move(*run));
  }
  for (const ReconstructionId id : database->ListReconstructionIds(session_id)) {
    const std::optional<ReconstructionRecord> rec = database->GetReconstruction(id);
    if (!rec) continue;
    mine["reconstruction"].insert(id.value());
    ReportReconstruction r;
    r.id = id;
    r.num_points = static_cast<std::int64_t>(rec->cloud.points.size());
    if (rec->mesh) r.num_mesh_faces = static_cast<std::int64_t>(rec->mesh->faces.size());
    r.num_frames_used = rec->num_frames_used;
    r.voxel_size_m = rec->voxel_size_m;
    r.created_unix_ms = rec->created_unix_ms;
    for (AlignmentRecord& a : database->ListAlignments(id)) {
      mine["alignment"].insert(a.id.value());
      ReportAlignment ra;
      ra.used_by_tracking = std::any_of(runs.begin(), runs.end(), [&](const TrackingRunRecord& run) {
        return run.alignment_id && *run.alignment_id == a.id;
      });
      ra.record = std::move(a);
      r.alignments.push_back(std::move(ra));
    }
    report.reconstructions.push_back(std::move(r));
  }
  for (const TrackingRunRecord& run : runs) {
    mine["tracking_run"].insert(run.id.value());
    report.runs.push_back(SummariseRun(run, database->GetTrackingFrames(run.id)));
  }

  // Room maps belong to the plan: their entries are part of its trail.
  std::map<std::int64_t, bool> room_map_of_plan;
  for (const AuditEntry& e : database->ListAudit()) {
    const auto entity = ParseEntity(e.entity);
    if (!entity) continue;
    bool belongs = false;
    if (entity->first == "room_map") {
      auto it = room_map_of_plan.find(entity->second);
      if (it == room_map_of_plan.end()) {
        const std::optional<RoomMapRecord> map = database->GetRoomMap(RoomMapId(entity->second));
        it = room_map_of_plan.emplace(entity->second, map && map->plan_id == report.plan.id).first;
      }
      belongs = it->second;
    } else {
      const auto kind = mine.find(entity->first);
      belongs = kind != mine.end() && kind->second.count(entity->second) > 0;
    }
    if (belongs) report.audit.push_back(e);
  }

  if (auto* sqlite = dynamic_cast<SqliteDatabase*>(database)) {
    report.verification = sqlite->VerifyAudit();
  } else {
    report.verification.problems.push_back("this store cannot verify its audit log");
  }
  report.verification_line = VerificationLine(report.verification);
  return report;
}

}  // namespace arpos
