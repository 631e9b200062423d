#include "report/report_html.h"

#include <cmath>
#include <cstdio>
#include <sstream>

#include "feedback/couch_correction.h"
#include "geometry/rigid3.h"
#include "store/describe.h"
#include "util/string_util.h"

namespace arpos {
namespace {

constexpr double kRadToDeg = 180.0 / M_PI;

std::string E(const std::string& text) { return HtmlEscape(text); }

std::string Fixed(double value, int decimals) {
  char text[64];
  std::snprintf(text, sizeof text, "%.*f", decimals, value);
  return text;
}

std::string Time(std::int64_t unix_ms) { return unix_ms != 0 ? FormatUtcTime(unix_ms) : std::string("-"); }

// Multi-line text: escaped, lines kept.
std::string Lines(const std::string& text) {
  std::string out;
  for (char c : E(text)) {
    if (c == '\n') out += "<br>";
    else out += c;
  }
  return out;
}

// Styles both the browser and Qt's rich text understand.
const char* kCss = R"(
body { font-family: "DejaVu Sans", Arial, Helvetica, sans-serif; font-size: 10pt; color: #111; }
h1 { font-size: 17pt; margin: 0 0 0.3em 0; }
h2 { font-size: 13pt; margin: 1.2em 0 0.4em 0; border-bottom: 1px solid #888; padding-bottom: 2px; }
h3 { font-size: 11pt; margin: 1em 0 0.3em 0; }
table { border-collapse: collapse; margin: 0.3em 0 0.6em 0; }
table.data { width: 100%; }
th, td { border: 1px solid #999; padding: 3px 4px; text-align: left; vertical-align: top; }
th { background-color: #e8e8e8; font-weight: bold; }
table.data th, table.data td { font-size: 8pt; }
td.num { text-align: right; }
tr.bad td { background-color: #fdd8d8; }
table.sign td { border: none; padding: 18px 8px 4px 0; }
p.ok { background-color: #e6f4e6; border: 1px solid #2e7d32; color: #1b5e20; padding: 6px; font-weight: bold; }
p.bad { background-color: #fdecea; border: 1px solid #c62828; color: #b71c1c; padding: 6px; font-weight: bold; }
p.note { color: #444; font-size: 9pt; }
)";

// Only for browsers (Qt's layout of the PDF has its own page margins).
const char* kBrowserCss = R"(
body { margin: 1.5em auto; max-width: 60em; padding: 0 1em; }
img.plot { width: 100%; height: auto; max-width: 1000px; }
@media print {
  body { margin: 0; max-width: none; padding: 0; }
  h2, h3 { page-break-after: avoid; }
  table, img.plot { page-break-inside: avoid; }
  tr { page-break-inside: avoid; }
}
)";

class Html {
 public:
  Html& operator<<(const std::string& s) {
    out_ << s;
    return *this;
  }
  std::string str() const { return out_.str(); }

  // A two-column key/value table.
  void BeginKv() { out_ << "<table class=\"kv\" border=\"1\" cellspacing=\"0\" cellpadding=\"4\">\n"; }
  void Kv(const std::string& key, const std::string& value_html) {
    out_ << "<tr><th>" << E(key) << "</th><td>" << value_html << "</td></tr>\n";
  }
  void EndTable() { out_ << "</table>\n"; }
  // A table with a header row (repeated on each PDF page); `widths` in % of
  // the table, one per column or none.
  void BeginData(const std::vector<std::string>& headers, const std::vector<int>& widths = {}) {
    out_ << "<table class=\"data\" width=\"100%\" border=\"1\" cellspacing=\"0\" cellpadding=\"2\">\n<thead><tr>";
    for (std::size_t i = 0; i < headers.size(); ++i) {
      out_ << "<th";
      if (i < widths.size()) out_ << " width=\"" << widths[i] << "%\"";
      out_ << ">" << E(headers[i]) << "</th>";
    }
    out_ << "</tr></thead>\n";
  }
  void Row(const std::vector<std::string>& cells_html, const std::vector<bool>& numeric = {},
           bool highlight = false) {
    out_ << (highlight ? "<tr class=\"bad\" bgcolor=\"#fdd8d8\">" : "<tr>");
    for (std::size_t i = 0; i < cells_html.size(); ++i) {
      const bool num = i < numeric.size() && numeric[i];
      out_ << (num ? "<td class=\"num\" align=\"right\">" : "<td>") << cells_html[i] << "</td>";
    }
    out_ << "</tr>\n";
  }

 private:
  std::ostringstream out_;
};

std::string PoseTranslationMm(const Rigid3d& pose) { return FormatVector3(pose.translation * 1000.0, 1); }

// Rotation as its rotation vector in degrees and the angle.
std::string PoseRotationDeg(const Rigid3d& pose) {
  const Eigen::Vector3d rv = pose.RotationVector() * kRadToDeg;
  return FormatVector3(rv, 2) + " (angle " + Fixed(rv.norm(), 2) + ")";
}

std::string Percent(int part, int whole) { return Fixed(ReportRun::Percent(part, whole), 1) + " %"; }

std::string CountPercent(int part, int whole) { return std::to_string(part) + " (" + Percent(part, whole) + ")"; }

const ReportImage* FindImage(const std::vector<ReportImage>& images, const std::string& name) {
  for (const ReportImage& image : images) {
    if (image.name == name) return &image;
  }
  return nullptr;
}

void Image(Html& h, const ReportImage& image, ReportImageMode mode) {
  // 640 px: the text width of an A4 page with 2 cm margins at 96 dpi (the PDF);
  // browsers use the CSS width.
  const int width = 640;
  const int height = image.width > 0 ? image.height * width / image.width : 0;
  const std::string src = mode == ReportImageMode::kDataUri
                              ? "data:image/png;base64," + Base64Encode(image.png)
                              : E(image.name);
  h << "<p><img class=\"plot\" src=\"" << src << "\" width=\"" << std::to_string(width) << "\" height=\""
    << std::to_string(height) << "\" alt=\"" << E(image.title) << "\"><br><i>" << E(image.title)
    << "</i></p>\n";
}

void CorrectionRow(Html& h, const std::string& what, const std::optional<ReportFrame>& f) {
  if (!f || !f->correction) {
    h.Row({E(what), "-", "-", "-", "-", "-", "-", "-", "-"});
    return;
  }
  const Correction6Dof& c = *f->correction;
  h.Row({E(what), std::to_string(f->frame_index), Fixed(f->time_s, 2), Fixed(c.translation_mm.x(), 1),
         Fixed(c.translation_mm.y(), 1), Fixed(c.translation_mm.z(), 1), Fixed(c.rotation_deg.x(), 2),
         Fixed(c.rotation_deg.y(), 2), Fixed(c.rotation_deg.z(), 2)},
        {false, true, true, true, true, true, true, true, true});
}

std::string Magnitudes(const std::optional<ReportFrame>& f) {
  if (!f || !f->correction) return "-";
  return Fixed(f->correction->translation_mm.norm(), 1) + " mm, " + Fixed(f->correction->rotation_deg.norm(), 2) +
         " deg (frame " + std::to_string(f->frame_index) + ", t = " + Fixed(f->time_s, 2) + " s)";
}

void RunSection(Html& h, const ReportRun& r, std::size_t index, const std::vector<ReportImage>& images,
                ReportImageMode mode) {
  h << "<h3>Tracking run " << std::to_string(index + 1) << ": " << E(r.name) << "</h3>\n";
  h.BeginKv();
  h.Kv("Run id", std::to_string(r.run.id.value()));
  h.Kv("Started", E(Time(r.run.started_unix_ms)));
  h.Kv("Started from alignment", r.run.alignment_id ? std::to_string(r.run.alignment_id->value()) : "-");
  h.Kv("Tolerance used", Fixed(r.run.tolerance_translation_mm, 1) + " mm, " + Fixed(r.run.tolerance_rotation_deg, 1) +
                             " deg");
  h.Kv("Frames", std::to_string(r.num_frames) + " over " + Fixed(r.duration_s, 2) + " s");
  h.Kv("Pose source (frames)", "tracked " + CountPercent(r.num_tracked, r.num_frames) + ", carried " +
                                   CountPercent(r.num_carried, r.num_frames) + ", lost " +
                                   CountPercent(r.num_lost_source, r.num_frames));
  h.Kv("Verdict (frames)", "in tolerance " + CountPercent(r.num_in, r.num_frames) + ", out of tolerance " +
                               CountPercent(r.num_out, r.num_frames) + ", lost " +
                               CountPercent(r.num_lost, r.num_frames));
  h.Kv("Time in tolerance", Fixed(r.time_in_tolerance_s, 2) + " s of " + Fixed(r.duration_s, 2) + " s (" +
                                (r.duration_s > 0 ? Fixed(100.0 * r.time_in_tolerance_s / r.duration_s, 1) : "0.0") +
                                " % of the time; " + Percent(r.num_in, r.num_frames) + " of the frames)");
  h.Kv("First correction", Magnitudes(r.first_correction));
  h.Kv("Last correction", Magnitudes(r.last_correction));
  h.Kv("Largest correction", r.first_correction ? Fixed(r.max_translation_mm, 1) + " mm, " +
                                                      Fixed(r.max_rotation_deg, 2) + " deg (each over the run)"
                                                : std::string("none (no frame with a pose)"));
  h.Kv("Latency per frame (total_ms)",
       r.latency_mean_ms ? "mean " + Fixed(*r.latency_mean_ms, 1) + " ms, p95 " + Fixed(*r.latency_p95_ms, 1) +
                               " ms over " + std::to_string(r.latency_frames) + " frames"
                         : std::string("not recorded"));
  if (!r.run.summary.empty()) h.Kv("Run record", Lines(r.run.summary));
  h.EndTable();
  h << "<p class=\"note\">Corrections in the couch axes (IEC 61217): translation lateral, longitudinal, "
       "vertical; rotation pitch, roll, yaw (components of the rotation vector). The last row is the "
       "correction the couch was left with.</p>\n";
  h.BeginData({"Correction", "Frame", "Time (s)", "Lateral (mm)", "Longitudinal (mm)", "Vertical (mm)", "Pitch (deg)",
               "Roll (deg)", "Yaw (deg)"},
              {12, 8, 7, 12, 14, 12, 11, 11, 11});
  CorrectionRow(h, "first", r.first_correction);
  CorrectionRow(h, "last", r.last_correction);
  h.EndTable();
  if (r.frames.empty()) {
    h << "<p>This run has no frames: no plots.</p>\n";
    return;
  }
  for (const char* kind : {"magnitude", "axes"}) {
    if (const ReportImage* image = FindImage(images, PlotName(index, kind))) Image(h, *image, mode);
  }
}

}  // namespace

std::string PlotName(std::size_t run_index, const std::string& kind) {
  return "run" + std::to_string(run_index + 1) + "_" + kind + ".png";
}

std::string HtmlEscape(const std::string& text) {
  std::string out;
  out.reserve(text.size());
  for (char c : text) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&#39;"; break;
      default: out += c;
    }
  }
  return out;
}

std::string Base64Encode(const std::string& bytes) {
  static const char* kAlphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const unsigned n = (static_cast<unsigned char>(bytes[i]) << 16) | (static_cast<unsigned char>(bytes[i + 1]) << 8) |
                       static_cast<unsigned char>(bytes[i + 2]);
    out += kAlphabet[(n >> 18) & 63];
    out += kAlphabet[(n >> 12) & 63];
    out += kAlphabet[(n >> 6) & 63];
    out += kAlphabet[n & 63];
  }
  if (i < bytes.size()) {
    unsigned n = static_cast<unsigned char>(bytes[i]) << 16;
    if (i + 1 < bytes.size()) n |= static_cast<unsigned char>(bytes[i + 1]) << 8;
    out += kAlphabet[(n >> 18) & 63];
    out += kAlphabet[(n >> 12) & 63];
    out += i + 1 < bytes.size() ? kAlphabet[(n >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

std::string RenderReportHtml(const SessionReport& r, const std::vector<ReportImage>& images, ReportImageMode mode) {
  Html h;
  h << "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>" << E(r.title) << ", session "
    << std::to_string(r.session.id.value()) << "</title>\n<style>" << kCss << (mode == ReportImageMode::kDataUri ? kBrowserCss : "")
    << "</style>\n</head>\n<body>\n";
  h << "<h1>" << E(r.title) << "</h1>\n";
  h.BeginKv();
  h.Kv("Generated", E(Time(r.generated_unix_ms)));
  h.Kv("Program", "arpos " + E(r.program_version));
  h.Kv("Store", E(r.store_path.empty() ? std::string("-") : r.store_path));
  h.EndTable();
  h << "<p class=\"" << (r.verification.ok() ? "ok" : "bad") << "\">" << E(r.verification_line) << "</p>\n";

  // Patient, plan, session.
  h << "<h2>Patient</h2>\n";
  h.BeginKv();
  h.Kv("Patient id (external)", E(r.patient.external_id));
  h.Kv("Name", E(r.patient.display_name.empty() ? std::string("-") : r.patient.display_name));
  h.EndTable();

  h << "<h2>Plan</h2>\n";
  h.BeginKv();
  h.Kv("Plan", E(r.plan.name) + " (id " + std::to_string(r.plan.id.value()) + ")");
  h.Kv("Reference model", E(r.plan.reference_model_name.empty() ? std::string("-") : r.plan.reference_model_name) +
                              " (" + std::to_string(r.reference_model_vertices) + " vertices, " +
                              std::to_string(r.reference_model_faces) + " triangles)");
  h.Kv("Planned pose: translation (mm)", PoseTranslationMm(r.plan.room_from_model_target) + " (x, y, z in the room)");
  h.Kv("Planned pose: rotation (deg)", PoseRotationDeg(r.plan.room_from_model_target) + " (rotation vector)");
  h.Kv("Created", E(Time(r.plan.created_unix_ms)));
  if (r.approval) {
    std::string text = "not approved";
    if (r.approval->approved) {
      text = "approved";
      if (!r.approval->approved_by.empty()) text += " by " + r.approval->approved_by;
      if (r.approval->approved_unix_ms != 0) text += " on " + FormatUtcTime(r.approval->approved_unix_ms);
      if (!r.approval->note.empty()) text += "; note: " + r.approval->note;
    }
    h.Kv("Approval", E(text));
  }
  if (r.room_map) {
    const ReportRoomMap& m = *r.room_map;
    h.Kv("Room map", "map " + std::to_string(m.id.value()) + ": " + std::to_string(m.num_markers) +
                         " markers (origin " + std::to_string(m.origin_marker_id) + "), " +
                         std::to_string(m.num_landmarks) +
                         " keypoint landmarks; marker corner residual mean " +
                         Fixed(m.mean_residual_px, 3) + " px, max " + Fixed(m.max_residual_px, 3) +
                         " px; built " + E(Time(m.created_unix_ms)));
    if (m.room_frame) {
      h.Kv("Room frame at the couch (1 sigma)",
           Fixed(m.room_frame->position_mm, 2) + " mm, " + Fixed(m.room_frame->rotation_deg, 3) +
               " deg (tilt and yaw together); part of every correction's bound");
      // What it does at the default tolerances, as the planning page and
      // `arpos plan approve` say it (each run below names its own).
      const RoomFrameBound bound = BoundOfRoomFrame(m.room_frame->position_mm,
                                                    m.room_frame->rotation_deg, CouchTolerances());
      if (bound.blocks_in)
        h.Kv("Room frame and tolerance", "<b>" + E(AsSentence(bound.advice)) + "</b>");
    } else {
      h.Kv("Room frame at the couch (1 sigma)", "not measured (a room map from before it was)");
    }
  } else {
    h.Kv("Room map", "none");
  }
  h.EndTable();

  h << "<h2>Session</h2>\n";
  h.BeginKv();
  h.Kv("Session id", std::to_string(r.session.id.value()));
  h.Kv("Fraction", std::to_string(r.session.fraction));
  std::string status = ToString(r.session.status);
  if (!r.session.ended_by.empty()) status += " by " + r.session.ended_by;
  if (!r.session.end_reason.empty()) status += " (" + r.session.end_reason + ")";
  h.Kv("Status", E(status));
  if (r.session.on_unapproved_plan) {
    h.Kv("Plan at the session", "<b>not approved</b> (run with --unapproved, or a research run)");
  }
  h.Kv("Operator", E(r.session.operator_name.empty() ? std::string("-") : r.session.operator_name));
  h.Kv("Started", E(Time(r.session.started_unix_ms)));
  h.Kv("Ended", r.session.ended_unix_ms ? E(Time(*r.session.ended_unix_ms)) : std::string("- (open)"));
  if (!r.session.notes.empty()) h.Kv("Notes", Lines(r.session.notes));
  h.EndTable();

  // Body scan.
  h << "<h2>Body marker map</h2>\n";
  if (r.body_marker_maps.empty()) {
    h << "<p>None.</p>\n";
  } else {
    h.BeginData({"Id", "Markers", "Marker ids", "Marker size (mm)", "Mean residual (px)", "Max residual (px)",
                 "Created"});
    for (const BodyMarkerMapRecord& m : r.body_marker_maps) {
      std::string ids;
      for (const BodyMarker& marker : m.markers) ids += (ids.empty() ? "" : ", ") + std::to_string(marker.marker_id);
      h.Row({std::to_string(m.id.value()), std::to_string(m.markers.size()), ids.empty() ? "-" : ids,
             Fixed(m.marker_size_m * 1000.0, 1), Fixed(m.mean_residual_px, 2), Fixed(m.max_residual_px, 2),
             E(Time(m.created_unix_ms))},
            {true, true, false, true, true, true, false});
    }
    h.EndTable();
    // What the scan measured of the breathing, which tracking allows for.
    for (const BodyMarkerMapRecord& m : r.body_marker_maps) {
      h << "<p>Breathing (map " << std::to_string(m.id.value()) << "): " << E(DescribeBreathing(m)) << ".</p>\n";
      h << "<p>Room landmarks the scan placed (map " << std::to_string(m.id.value())
        << "): " << E(DescribeScanLandmarks(m)) << ".</p>\n";
    }
  }

  h << "<h2>Reconstruction</h2>\n";
  if (r.reconstructions.empty()) {
    h << "<p>None.</p>\n";
  } else {
    h.BeginData({"Id", "Points", "Mesh triangles", "Frames used", "Voxel size (mm)", "Created"});
    for (const ReportReconstruction& rec : r.reconstructions) {
      h.Row({std::to_string(rec.id.value()), std::to_string(rec.num_points),
             rec.num_mesh_faces ? std::to_string(*rec.num_mesh_faces) : "no mesh", std::to_string(rec.num_frames_used),
             rec.voxel_size_m > 0 ? Fixed(rec.voxel_size_m * 1000.0, 1) : "not voxelised", E(Time(rec.created_unix_ms))},
            {true, true, true, true, true, false});
    }
    h.EndTable();
  }

  h << "<h2>Alignments</h2>\n";
  bool any_alignment = false;
  for (const ReportReconstruction& rec : r.reconstructions) any_alignment |= !rec.alignments.empty();
  if (!any_alignment) {
    h << "<p>None.</p>\n";
  } else {
    h << "<p class=\"note\">The model pose at scan is the reference model in the reconstruction's (body scan) "
         "frame: translation t (x, y, z) and rotation vector r. Fitness is the inlier fraction; RMSE is over the "
         "inliers. \"Refines\" names the alignment a refinement started from.</p>\n";
    h.BeginData({"Id", "Method", "Refines", "Fitness (0-1)", "RMSE (mm)", "Inliers", "Model pose at scan",
                 "Used by tracking"},
                {5, 11, 9, 9, 8, 8, 38, 12});
    for (const ReportReconstruction& rec : r.reconstructions) {
      for (const ReportAlignment& ra : rec.alignments) {
        const AlignmentRecord& a = ra.record;
        h.Row({std::to_string(a.id.value()), E(ToString(a.method)),
               a.parent_alignment_id ? std::to_string(a.parent_alignment_id->value()) : "-", Fixed(a.fitness, 3),
               Fixed(a.rmse_m * 1000.0, 2), std::to_string(a.num_inliers),
               "t (mm): " + PoseTranslationMm(a.reconstruction_from_model) +
                   "<br>r (deg): " + PoseRotationDeg(a.reconstruction_from_model),
               ra.used_by_tracking ? "yes" : "no"},
              {true, false, true, true, true, true, false, false});
      }
    }
    h.EndTable();
  }

  // Tracking.
  h << "<h2>Tracking</h2>\n";
  if (r.runs.empty()) {
    h << "<p>No tracking runs in this session.</p>\n";
  } else {
    h << "<p>" << std::to_string(r.runs.size()) << (r.runs.size() == 1 ? " tracking run: " : " tracking runs: ");
    for (std::size_t i = 0; i < r.runs.size(); ++i) {
      const ReportRun& run = r.runs[i];
      h << (i > 0 ? "; " : "") << "<b>" << E(run.name) << "</b> (" << std::to_string(run.num_frames) << " frames, "
        << Percent(run.num_in, run.num_frames) << " in tolerance)";
    }
    h << ".</p>\n";
    h << "<p class=\"note\">Tracked, carried and lost count the frames by where their pose came from (measured "
         "in the frame, carried over from earlier frames, none); in tolerance counts the frames whose "
         "correction plus its uncertainty was within both tolerances. Time in tolerance sums, over the frames "
         "in tolerance, the time to the next frame.</p>\n";
    for (std::size_t i = 0; i < r.runs.size(); ++i) RunSection(h, r.runs[i], i, images, mode);
  }

  // Audit.
  h << "<h2>Audit trail</h2>\n";
  h << "<p class=\"note\">Entries on this session, its body marker maps, reconstructions, alignments and "
       "tracking runs, its plan (and the plan's room maps) and its patient, oldest first. The verification "
       "covers the whole audit log of the store.</p>\n";
  if (r.audit.empty()) {
    h << "<p>No audit entries.</p>\n";
  } else {
    h.BeginData({"Id", "Time (UTC)", "Actor", "Action", "Entity", "Details"}, {4, 13, 12, 23, 18, 30});
    for (const AuditEntry& e : r.audit) {
      const bool bad = r.verification.first_bad_entry == e.id.value();
      h.Row({std::to_string(e.id.value()), E(FormatUtcTime(e.time_unix_ms)), E(e.actor), E(e.action), E(e.entity),
             (bad ? std::string("<b>This entry does not verify.</b><br>") : std::string()) + Lines(e.details)},
            {true, false, false, false, false, false}, bad);
    }
    h.EndTable();
  }
  h << "<p class=\"" << (r.verification.ok() ? "ok" : "bad") << "\">" << E(r.verification_line) << "</p>\n";
  if (r.verification.problems.size() > 1) {
    h << "<ul>\n";
    for (const std::string& problem : r.verification.problems) h << "<li>" << E(problem) << "</li>\n";
    h << "</ul>\n";
  }

  // Signature: on a page of its own, naming what is signed.
  h << "<h2 style=\"page-break-before: always\">Review and signature</h2>\n";
  h.BeginKv();
  h.Kv("Patient", E(r.patient.external_id) +
                      (r.patient.display_name.empty() ? std::string() : ", " + E(r.patient.display_name)));
  h.Kv("Plan", E(r.plan.name) + " (id " + std::to_string(r.plan.id.value()) + ")");
  h.Kv("Session", std::to_string(r.session.id.value()) + ", fraction " + std::to_string(r.session.fraction) + ", " +
                      E(Time(r.session.started_unix_ms)));
  h.Kv("Report generated", E(Time(r.generated_unix_ms)) + " by arpos " + E(r.program_version));
  h.EndTable();
  h << "<p class=\"" << (r.verification.ok() ? "ok" : "bad") << "\">" << E(r.verification_line) << "</p>\n";
  h << "<p>I have reviewed this session's positioning record.</p>\n";
  h << "<table class=\"sign\" width=\"100%\" border=\"0\" cellspacing=\"0\" cellpadding=\"8\">\n";
  for (const char* line : {"Name", "Role", "Date", "Signature"}) {
    h << "<tr><td width=\"20%\"><b>" << line
      << "</b></td><td>______________________________________________</td></tr>\n";
  }
  h << "</table>\n</body>\n</html>\n";
  return h.str();
}

}  // namespace arpos
