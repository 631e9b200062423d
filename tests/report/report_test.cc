// The session report's figures and HTML, without Qt: what GatherSessionReport
// counts for a store with known frames, which audit entries belong to the
// session, the verification line, escaping and base64.
#include <gtest/gtest.h>

#include <cmath>

#include "report/report_html.h"
#include "report/report_test_util.h"
#include "report/session_report.h"
#include "store/sqlite_database.h"
#include "util/check.h"
#include "util/file.h"

namespace arpos {
namespace {

struct Fixture {
  TempDir dir{"arpos_report"};
  std::string path = (dir.path() / "store.db").string();
  std::unique_ptr<SqliteDatabase> db = SqliteDatabase::Open(path);
};

TEST(SessionReport, RunFiguresFromTheFrames) {
  Fixture f;
  const test::ReportStoreIds ids = test::WriteReportStore(*f.db);
  const SessionReport r = GatherSessionReport(f.db.get(), ids.session, f.path);
  EXPECT_EQ(r.patient.external_id, "P-REPORT-7");
  EXPECT_EQ(r.plan.name, "Pelvis plan A");
  EXPECT_EQ(r.reference_model_faces, 4);
  EXPECT_TRUE(r.plan.reference_model.vertices.empty()) << "the report keeps no mesh";
  EXPECT_EQ(r.session.status, SessionStatus::kCompleted);
  ASSERT_EQ(r.body_marker_maps.size(), 1u);
  EXPECT_EQ(r.body_marker_maps[0].markers.size(), 3u);
  ASSERT_EQ(r.reconstructions.size(), 1u);
  EXPECT_EQ(r.reconstructions[0].num_points, 50);
  ASSERT_EQ(r.reconstructions[0].alignments.size(), 2u);
  EXPECT_FALSE(r.reconstructions[0].alignments[0].used_by_tracking);
  EXPECT_TRUE(r.reconstructions[0].alignments[1].used_by_tracking);

  ASSERT_EQ(r.runs.size(), 2u);
  const ReportRun& run = r.runs[0];
  EXPECT_EQ(run.name, "seq_00");
  EXPECT_EQ(run.num_frames, 20);
  EXPECT_EQ(run.num_tracked, 15);
  EXPECT_EQ(run.num_carried, 2);
  EXPECT_EQ(run.num_lost_source, 3);
  EXPECT_EQ(run.num_in, 12);
  EXPECT_EQ(run.num_out, 5);
  EXPECT_EQ(run.num_lost, 3);
  EXPECT_NEAR(run.duration_s, 1.9, 1e-9);
  EXPECT_NEAR(run.time_in_tolerance_s, 1.1, 1e-9);  // frames 8-18 each to the next; 19 is the last
  ASSERT_TRUE(run.first_correction && run.last_correction);
  EXPECT_EQ(run.first_correction->frame_index, 0);
  EXPECT_NEAR(run.first_correction->correction->translation_mm.x(), 10.0, 1e-12);
  EXPECT_EQ(run.last_correction->frame_index, 19);
  EXPECT_NEAR(run.last_correction->correction->translation_mm.y(), -0.3, 1e-12);
  EXPECT_NEAR(run.last_correction->correction->rotation_deg.y(), -0.2, 1e-12);
  EXPECT_NEAR(run.last_correction->time_s, 1.9, 1e-9);
  EXPECT_NEAR(run.max_translation_mm, std::sqrt(102.0), 1e-9);
  EXPECT_NEAR(run.max_rotation_deg, 1.0, 1e-12);
  ASSERT_TRUE(run.latency_mean_ms && run.latency_p95_ms);
  EXPECT_NEAR(*run.latency_mean_ms, 19.5, 1e-9);  // 10 .. 29 ms
  EXPECT_NEAR(*run.latency_p95_ms, 28.0, 1e-9);   // nearest rank 19 of 20
  EXPECT_EQ(r.runs[1].name, "seq_01");
  EXPECT_EQ(r.runs[1].num_in, 5);
}

TEST(SessionReport, AuditTrailHoldsTheSessionsEntriesOnly) {
  Fixture f;
  const test::ReportStoreIds ids = test::WriteReportStore(*f.db);
  const SessionReport r = GatherSessionReport(f.db.get(), ids.session, f.path);
  // patient, plan, session, body marker map, reconstruction, 2 alignments, 2
  // runs, the session's completion.
  ASSERT_EQ(r.audit.size(), 10u);
  EXPECT_EQ(r.audit.back().action, "complete_session");
  EXPECT_EQ(r.audit.front().entity, "patient:" + std::to_string(ids.patient.value()));
  for (const AuditEntry& e : r.audit) {
    EXPECT_NE(e.entity, "session:" + std::to_string(ids.other_session.value()));
    EXPECT_NE(e.details, "run other_seq");
  }
  EXPECT_TRUE(r.verification.ok()) << r.verification.ToText();
  EXPECT_EQ(r.verification_line.rfind("Audit log verifies: ", 0), 0u) << r.verification_line;
  ASSERT_TRUE(r.approval.has_value());
  EXPECT_FALSE(r.approval->approved);
}

TEST(SessionReport, ThePlansApprovalIsReported) {
  Fixture f;
  const test::ReportStoreIds ids = test::WriteReportStore(*f.db);
  f.db->ApprovePlan(ids.plan, "pia (physicist)", "checked");
  f.db->AppendAudit({AuditId(), 0, "pia (physicist)", "approve_plan", "plan:" + std::to_string(ids.plan.value()), ""});
  const SessionReport r = GatherSessionReport(f.db.get(), ids.session, f.path);
  ASSERT_TRUE(r.approval.has_value());
  EXPECT_TRUE(r.approval->approved);
  EXPECT_EQ(r.approval->approved_by, "pia (physicist)");
  EXPECT_EQ(r.approval->note, "checked");
  EXPECT_TRUE(r.verification.ok()) << r.verification.ToText();
  const std::string html = RenderReportHtml(r, {}, ReportImageMode::kDataUri);
  EXPECT_NE(html.find("approved by pia (physicist) on "), std::string::npos);
  EXPECT_NE(html.find("completed by report test (therapist)"), std::string::npos);
}

TEST(SessionReport, UnknownSessionNamesTheStore) {
  Fixture f;
  test::WriteReportStore(*f.db);
  try {
    GatherSessionReport(f.db.get(), SessionId(99), f.path);
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), "session 99 is not in the store " + f.path);
  }
}

TEST(SessionReport, SessionWithoutTrackingSaysSo) {
  Fixture f;
  test::ReportStoreOptions options;
  options.num_runs = 0;
  const test::ReportStoreIds ids = test::WriteReportStore(*f.db, options);
  const SessionReport r = GatherSessionReport(f.db.get(), ids.session, f.path);
  EXPECT_TRUE(r.runs.empty());
  const std::string html = RenderReportHtml(r, {}, ReportImageMode::kDataUri);
  EXPECT_NE(html.find("No tracking runs in this session."), std::string::npos);
  EXPECT_NE(html.find("Audit log verifies"), std::string::npos);
}

TEST(SessionReport, TheScansRoomLandmarksAreDescribed) {
  BodyMarkerMapRecord map;
  EXPECT_NE(DescribeScanLandmarks(map).find("none ("), std::string::npos);
  map.room_landmarks.points.assign(323, Eigen::Vector3f::Zero());
  map.room_landmarks_placement_sigma_m = 0.00214;
  map.room_landmarks_position_sigma_m = 0.0046;
  const std::string text = DescribeScanLandmarks(map);
  EXPECT_NE(text.find("323 keypoint(s)"), std::string::npos) << text;
  EXPECT_NE(text.find("2.1 mm at the stickers"), std::string::npos) << text;
  EXPECT_NE(text.find("each to 4.6 mm"), std::string::npos) << text;

  // And the report says it for the session's map.
  Fixture f;
  const test::ReportStoreIds ids = test::WriteReportStore(*f.db);
  const SessionReport r = GatherSessionReport(f.db.get(), ids.session, f.path);
  const std::string html = RenderReportHtml(r, {}, ReportImageMode::kDataUri);
  EXPECT_NE(html.find("Room landmarks the scan placed (map "), std::string::npos);
}

// The plan's room map and how well it places the room frame at the couch;
// when that alone keeps every frame from reading `in` at the default
// tolerances, the report says so as the planning page does; each run's own
// record (its summary) is in its table.
TEST(SessionReport, ThePlansRoomFrameAndEachRunsRecordAreReported) {
  for (const double sigma_mm : {0.4, 1.9}) {
    Fixture f;
    test::ReportStoreOptions options;
    options.room_frame_couch_sigma_mm = sigma_mm;
    const test::ReportStoreIds ids = test::WriteReportStore(*f.db, options);
    const SessionReport r = GatherSessionReport(f.db.get(), ids.session, f.path);
    ASSERT_TRUE(r.room_map.has_value());
    EXPECT_EQ(r.room_map->num_markers, 2);
    EXPECT_EQ(r.room_map->origin_marker_id, 7);
    ASSERT_TRUE(r.room_map->room_frame.has_value());
    EXPECT_DOUBLE_EQ(r.room_map->room_frame->position_mm, sigma_mm);
    EXPECT_NEAR(r.room_map->room_frame->rotation_deg, 0.05, 1e-12);
    EXPECT_TRUE(r.verification.ok()) << r.verification.ToText();
    const std::string html = RenderReportHtml(r, {}, ReportImageMode::kDataUri);
    EXPECT_NE(html.find("2 markers (origin 7)"), std::string::npos);
    EXPECT_NE(html.find(sigma_mm < 1 ? "0.40 mm, 0.050 deg (tilt and yaw together)"
                                     : "1.90 mm, 0.050 deg (tilt and yaw together)"),
              std::string::npos);
    const bool blocks = sigma_mm * 3 >= 2.0;
    EXPECT_EQ(
        html.find(
            "With this room map no tracked frame can read `in` at a tolerance of 2.0 mm / 1.0 deg: "
            "the room frame alone bounds every correction by 5.7 mm / 0.15 deg") !=
            std::string::npos,
        blocks)
        << sigma_mm;
    EXPECT_NE(html.find("<th>Run record</th><td>test run</td>"), std::string::npos);
  }
  // A plan without a room map says so.
  Fixture f;
  const test::ReportStoreIds ids = test::WriteReportStore(*f.db);
  const SessionReport r = GatherSessionReport(f.db.get(), ids.session, f.path);
  EXPECT_FALSE(r.room_map.has_value());
  EXPECT_NE(
      RenderReportHtml(r, {}, ReportImageMode::kDataUri).find("<th>Room map</th><td>none</td>"),
      std::string::npos);
}

TEST(ReportHtml, EveryStoredTextIsEscaped) {
  Fixture f;
  test::ReportStoreOptions options;
  options.patient_name = "<script>alert(\"x\")</script> O'Neil & Co";
  options.plan_name = "plan </table><h1>";
  const test::ReportStoreIds ids = test::WriteReportStore(*f.db, options);
  const SessionReport r = GatherSessionReport(f.db.get(), ids.session, f.path);
  const std::string html = RenderReportHtml(r, {}, ReportImageMode::kDataUri);
  EXPECT_EQ(html.find("<script>"), std::string::npos);
  EXPECT_EQ(html.find("</table><h1>"), std::string::npos);
  EXPECT_NE(html.find("&lt;script&gt;alert(&quot;x&quot;)&lt;/script&gt; O&#39;Neil &amp; Co"), std::string::npos);
  EXPECT_NE(html.find("plan &lt;/table&gt;&lt;h1&gt;"), std::string::npos);
  EXPECT_EQ(HtmlEscape("a<b>&\"'"), "a&lt;b&gt;&amp;&quot;&#39;");
}

TEST(ReportHtml, ImagesAsDataUrisOrResourceNames) {
  Fixture f;
  const test::ReportStoreIds ids = test::WriteReportStore(*f.db);
  const SessionReport r = GatherSessionReport(f.db.get(), ids.session, f.path);
  ReportImage image;
  image.name = PlotName(0, "magnitude");
  image.title = "a plot";
  image.png = "\x89PNG\r\n";
  image.width = 100;
  image.height = 50;
  const std::string data = RenderReportHtml(r, {image}, ReportImageMode::kDataUri);
  EXPECT_NE(data.find("src=\"data:image/png;base64," + Base64Encode(image.png) + "\""), std::string::npos);
  const std::string named = RenderReportHtml(r, {image}, ReportImageMode::kResourceName);
  EXPECT_NE(named.find("src=\"run1_magnitude.png\""), std::string::npos);
  EXPECT_EQ(named.find("data:image"), std::string::npos);
}

TEST(ReportHtml, Base64) {
  EXPECT_EQ(Base64Encode(""), "");
  EXPECT_EQ(Base64Encode("f"), "Zg==");
  EXPECT_EQ(Base64Encode("fo"), "Zm8=");
  EXPECT_EQ(Base64Encode("foo"), "Zm9v");
  EXPECT_EQ(Base64Encode("foobar"), "Zm9vYmFy");
  EXPECT_EQ(Base64Encode(std::string("\xff\x00\x10", 3)), "/wAQ");
}

}  // namespace
}  // namespace arpos
