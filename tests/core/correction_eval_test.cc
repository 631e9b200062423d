// The corrections mode of `arpos evaluate` (eval/correction_eval.h): rows of
// corrections.csv against the true correction from hand-made poses whose
// corrections are known in closed form.
#include <gtest/gtest.h>

#include <sstream>

#include "eval/correction_eval.h"
#include "exe/commands.h"
#include "geometry/so3.h"
#include "util/check.h"
#include "util/file.h"

namespace arpos {
namespace {

// A planned pose with a rotation, so that couch axes (model axes) differ from
// room axes and a mix-up of the two shows.
Rigid3d Target() {
  return Rigid3d(QuaternionFromRotationVector(Eigen::Vector3d(0.3, -0.5, 1.1)), Eigen::Vector3d(0.4, -0.2, 1.0));
}

// The patient displaced from the target by `shift_m` and turned by
// `turn_rad` (rotation vector), both in the model frame. Its correction is
// known: the isocentre moves by -shift in model axes, i.e. couch
// (lateral, longitudinal, vertical) = (-x, -z, +y), and the turn is
// -turn about model axes, i.e. (pitch, roll, yaw) = (-x, -z, +y).
Rigid3d Displaced(const Eigen::Vector3d& shift_m, const Eigen::Vector3d& turn_rad = Eigen::Vector3d::Zero()) {
  const Rigid3d target = Target();
  return Rigid3d(target.rotation * QuaternionFromRotationVector(turn_rad),
                 target.translation + target.RotationMatrix() * shift_m);
}

std::vector<CorrectionRow> Parse(const std::string& text, const std::string& name = "corrections.csv") {
  std::istringstream in(text);
  return ParseCorrectionsCsv(in, name);
}

const char* kHeader =
    "timestamp,lateral_mm,longitudinal_mm,vertical_mm,pitch_deg,roll_deg,yaw_deg,translation_mm,rotation_deg,state\n";

// The message of the InputError `f` throws ("" if none).
template <typename F>
std::string InputErrorOf(F f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(CorrectionEval, ParsesRowsOfEveryState) {
  const auto rows = Parse(std::string(kHeader) +
                          "1.000000,-1.500,0.000,0.250,0.1000,-0.2000,0.3000,1.521,0.3742,in\r\n"
                          "\n"
                          "1.033333,,,,,,,,,lost\n"
                          "1.066667,3.000,-4.000,0.000,0.0000,0.0000,2.0000,5.000,2.0000,out\n");
  ASSERT_EQ(rows.size(), 3u);
  EXPECT_EQ(rows[0].state, CorrectionState::kIn);
  EXPECT_DOUBLE_EQ(rows[0].lateral_mm, -1.5);
  EXPECT_DOUBLE_EQ(rows[0].vertical_mm, 0.25);
  EXPECT_DOUBLE_EQ(rows[0].roll_deg, -0.2);
  EXPECT_DOUBLE_EQ(rows[0].rotation_deg, 0.3742);
  EXPECT_EQ(rows[0].line, 2);
  EXPECT_EQ(rows[1].state, CorrectionState::kLost);
  EXPECT_NEAR(rows[1].timestamp_s, 1.033333, 1e-12);
  EXPECT_EQ(rows[1].line, 4);  // the blank line counts
  EXPECT_EQ(rows[2].state, CorrectionState::kOut);
  EXPECT_DOUBLE_EQ(rows[2].longitudinal_mm, -4.0);
  EXPECT_DOUBLE_EQ(rows[2].yaw_deg, 2.0);
}

TEST(CorrectionEval, MalformedLinesAreNamed) {
  const std::string good = "1.0,0,0,0,0,0,0,0,0,in\n";
  struct Case {
    std::string text;
    std::string expected;  // in the message
  } cases[] = {
      {std::string(kHeader) + good + "2.0,0,0,abc,0,0,0,0,0,in\n", "corrections.csv:3: vertical_mm 'abc' is not a number"},
      {std::string(kHeader) + good + "2.0,0,0,0,0,0,0,0,in\n", "corrections.csv:3: expected 10 comma-separated fields, found 9"},
      {std::string(kHeader) + good + "2.0,0,0,0,0,0,0,0,0,maybe\n", "corrections.csv:3: state 'maybe' is not in, out or lost"},
      {std::string(kHeader) + "x,0,0,0,0,0,0,0,0,in\n", "corrections.csv:2: timestamp 'x' is not a number"},
      {std::string(kHeader) + "2.0,,,,,,,,,out\n", "corrections.csv:2: lateral_mm '' is not a number (state out)"},
      {std::string(kHeader) + "2.0,1.0,,,,,,,,lost\n", "corrections.csv:2: a lost row has no lateral_mm, found '1.0'"},
      {std::string(kHeader) + "2.0,nan,0,0,0,0,0,0,0,in\n", "corrections.csv:2: lateral_mm 'nan' is not a number"},
      {"timestamp,tx,ty,tz\n" + good, "corrections.csv:1: expected the header"},
      {"", "corrections.csv: empty"},
  };
  for (const auto& c : cases) {
    const std::string message = InputErrorOf([&] { Parse(c.text); });
    EXPECT_NE(message.find(c.expected), std::string::npos) << "input:\n" << c.text << "message: " << message;
  }
  // The file's own name, from the reader.
  TempDir dir;
  const auto path = dir.path() / "corrections.csv";
  WriteFileAtomic(path, std::string(kHeader) + good + "2.0,0,0,0,0,0,0,0,0,inn\n");
  const std::string message = InputErrorOf([&] { ReadCorrectionsCsv(path); });
  EXPECT_NE(message.find(path.string() + ":3: state 'inn'"), std::string::npos) << message;
  const std::string missing = InputErrorOf([&] { ReadCorrectionsCsv(dir.path() / "missing.csv"); });
  EXPECT_NE(missing.find("missing.csv: cannot open file for reading"), std::string::npos)
      << missing;
}

// Hand-made frames with known true corrections (see Displaced):
//   t0 at the target                         truly in,  reported in (exact)
//   t1 1 mm along model x: lateral -1        truly in,  reported in, lateral -1.5
//   t2 3 mm along model z: longitudinal -3   truly OUT, reported in (-1.0): unsafe
//   t3 5 mm along model x                    truly out, reported lost
//   t4 2 deg about model z: roll -2          truly out, reported out, pitch +0.3
//   t5 0.5 mm along model y: vertical +0.5   truly in,  reported out, lateral +0.4,
//                                            longitudinal +0.3 (a 0.5 mm shift error)
//   t6 ground truth only; t10 a row only.
struct Scenario {
  std::vector<StampedPose> truth;
  std::vector<CorrectionRow> rows;
};
Scenario MakeScenario() {
  Scenario s;
  s.truth = {{0.0, Displaced(Eigen::Vector3d::Zero())},
             {1.0, Displaced(Eigen::Vector3d(0.001, 0, 0))},
             {2.0, Displaced(Eigen::Vector3d(0, 0, 0.003))},
             {3.0, Displaced(Eigen::Vector3d(0.005, 0, 0))},
             {4.0, Displaced(Eigen::Vector3d::Zero(), Eigen::Vector3d(0, 0, RadFromDeg(2.0)))},
             {5.0, Displaced(Eigen::Vector3d(0, 0.0005, 0))},
             {6.0, Displaced(Eigen::Vector3d::Zero())}};
  s.rows = Parse(std::string(kHeader) +
                 "0.005,0,0,0,0,0,0,0,0,in\n"
                 "1.005,-1.5,0,0,0,0,0,1.5,0,in\n"
                 "2.005,0,-1.0,0,0,0,0,1.0,0,in\n"
                 "3.005,,,,,,,,,lost\n"
                 "4.005,0,0,0,0.3,-2.0,0,0,2.0224,out\n"
                 "5.005,0.4,0.3,0.5,0,0,0,0.7071,0,out\n"
                 "10.0,0,0,0,0,0,0,0,0,in\n");
  return s;
}

TEST(CorrectionEval, CountsStatesAndTheInWhileOutFrame) {
  const Scenario s = MakeScenario();
  const CorrectionEvaluation e = EvaluateCorrections(s.rows, s.truth, Target());
  EXPECT_EQ(e.rows, 7);
  EXPECT_EQ(e.ground_truth_frames, 7);
  EXPECT_EQ(e.matched_frames, 6);
  EXPECT_EQ(e.rows_without_truth, 1);  // t10
  EXPECT_EQ(e.truth_without_row, 1);   // t6
  EXPECT_EQ(e.reported_in, 3);
  EXPECT_EQ(e.reported_out, 2);
  EXPECT_EQ(e.reported_lost, 1);
  EXPECT_EQ(e.truly_in, 3);   // t0, t1, t5
  EXPECT_EQ(e.truly_out, 3);  // t2, t3 (lost), t4
  EXPECT_EQ(e.in_while_out, 1);
  EXPECT_EQ(e.out_while_in, 1);
  const auto unsafe = e.InWhileOut();
  ASSERT_EQ(unsafe.size(), 1u);
  EXPECT_DOUBLE_EQ(unsafe[0].timestamp_s, 2.005);
  EXPECT_EQ(unsafe[0].line, 4);
  EXPECT_NEAR(unsafe[0].truth.translation_mm, 3.0, 1e-9);
  EXPECT_NEAR(unsafe[0].truth.longitudinal_mm, -3.0, 1e-9);
  const std::string text = e.ToText();
  EXPECT_NE(text.find("reported in while truly out: 1"), std::string::npos) << text;
  EXPECT_NE(text.find("t 2.005000 (line 4): true 3.000 mm 0.0000 deg, reported 1.000 mm"), std::string::npos) << text;
  const std::string json = e.ToJson();
  EXPECT_NE(json.find("\"in_while_out\": 1,"), std::string::npos) << json;
  EXPECT_NE(json.find("\"timestamp\": 2.005000, \"line\": 4, \"reported\": \"in\", \"truly\": \"out\", "
                      "\"true_translation_mm\": 3.000000"),
            std::string::npos)
      << json;
  // The lost row is a frame (its truth counted) but has no error figures.
  ASSERT_EQ(e.frames.size(), 6u);
  EXPECT_EQ(e.frames[3].reported, CorrectionState::kLost);
  EXPECT_FALSE(e.frames[3].truly_in());
  EXPECT_NEAR(e.frames[3].truth.lateral_mm, -5.0, 1e-9);
}

TEST(CorrectionEval, ErrorsPerAxisAndMagnitude) {
  const Scenario s = MakeScenario();
  const CorrectionEvaluation e = EvaluateCorrections(s.rows, s.truth, Target());
  ASSERT_TRUE(e.has_errors());
  // Over the 5 frames with a correction: lateral errors {0, 0.5, 0, 0, 0.4},
  // longitudinal {0, 0, 2, 0, 0.3}, vertical all 0 (t5 reports the true
  // +0.5), pitch {0, 0, 0, 0.3, 0}, roll and yaw 0.
  EXPECT_NEAR(e.lateral_mm.mean, 0.18, 1e-9);
  EXPECT_NEAR(e.lateral_mm.max, 0.5, 1e-9);
  EXPECT_NEAR(e.lateral_mm.median, 0.0, 1e-9);
  EXPECT_NEAR(e.longitudinal_mm.mean, 0.46, 1e-9);
  EXPECT_NEAR(e.longitudinal_mm.max, 2.0, 1e-9);
  EXPECT_NEAR(e.longitudinal_mm.p95, 1.66, 1e-9);  // rank 3.8 of {0, 0, 0, 0.3, 2}
  EXPECT_NEAR(e.vertical_mm.max, 0.0, 1e-9);
  EXPECT_NEAR(e.pitch_deg.max, 0.3, 1e-9);
  EXPECT_NEAR(e.roll_deg.max, 0.0, 1e-9);
  EXPECT_NEAR(e.yaw_deg.max, 0.0, 1e-9);
  // Shift vector error {0, 0.5, 2, 0, |(0.4, 0.3, 0)| = 0.5}.
  EXPECT_NEAR(e.translation_mm.mean, 0.6, 1e-9);
  EXPECT_NEAR(e.translation_mm.max, 2.0, 1e-9);
  EXPECT_NEAR(e.frames[5].translation_mm, 0.5, 1e-9);
  // The turns (0.3, -2, 0) and (0, -2, 0) deg differ by about 0.3 deg.
  EXPECT_NEAR(e.rotation_deg.max, 0.3, 2e-3);
  EXPECT_GT(e.rotation_deg.max, 0.29);
  EXPECT_NEAR(e.frames[4].truth.roll_deg, -2.0, 1e-9);
  EXPECT_NEAR(e.frames[4].truth.pitch_deg, 0.0, 1e-9);
  EXPECT_NEAR(e.frames[5].truth.vertical_mm, 0.5, 1e-9);
}

TEST(CorrectionEval, TolerancesDecideTrulyIn) {
  const Scenario s = MakeScenario();
  // With 3.5 mm / 2.5 deg every frame is truly in: t2 is no longer unsafe,
  // and t4 (2 deg) is reported out while truly in.
  CorrectionEvaluationOptions wide;
  wide.tolerances.translation_mm = 3.5;
  wide.tolerances.rotation_deg = 2.5;
  const CorrectionEvaluation e = EvaluateCorrections(s.rows, s.truth, Target(), wide);
  EXPECT_EQ(e.truly_out, 1);  // t3: 5 mm
  EXPECT_EQ(e.in_while_out, 0);
  EXPECT_EQ(e.out_while_in, 2);
  // A window narrower than the rows' 5 ms offset matches nothing.
  CorrectionEvaluationOptions narrow;
  narrow.max_difference_s = 0.001;
  const CorrectionEvaluation none = EvaluateCorrections(s.rows, s.truth, Target(), narrow);
  EXPECT_EQ(none.matched_frames, 0);
  EXPECT_FALSE(none.has_errors());
  CorrectionEvaluationOptions bad;
  bad.tolerances.rotation_deg = 0;
  EXPECT_THROW(EvaluateCorrections(s.rows, s.truth, Target(), bad), InputError);
}

TEST(CorrectionEval, OnlyLostRowsHaveNoFigures) {
  const Scenario s = MakeScenario();
  const auto rows = Parse(std::string(kHeader) + "0.0,,,,,,,,,lost\n1.0,,,,,,,,,lost\n");
  const CorrectionEvaluation e = EvaluateCorrections(rows, s.truth, Target());
  EXPECT_EQ(e.matched_frames, 2);
  EXPECT_EQ(e.reported_lost, 2);
  EXPECT_FALSE(e.has_errors());
  EXPECT_NE(e.ToText().find("correction error: n/a"), std::string::npos) << e.ToText();
  EXPECT_NE(e.ToJson().find("\"translation_mm\": null"), std::string::npos) << e.ToJson();
}

// What the tracker writes (CorrectionsCsvRow) reads back and, against the
// poses it came from, has errors within the CSV's rounding.
TEST(CorrectionEval, WriterAndReaderAgree) {
  const Scenario s = MakeScenario();
  std::string csv = CorrectionsCsvHeader();
  for (size_t i = 0; i < s.truth.size(); ++i) {
    const CouchCorrection c = i == 3 ? LostCorrection()
                                     : ComputeCouchCorrection(s.truth[i].room_from_x, Target(),
                                                              CorrectionUncertainty{0.2, 0.05}, CouchTolerances());
    csv += CorrectionsCsvRow(s.truth[i].timestamp_s, c);
  }
  const CorrectionEvaluation e = EvaluateCorrections(Parse(csv), s.truth, Target());
  EXPECT_EQ(e.matched_frames, 7);
  EXPECT_EQ(e.reported_lost, 1);
  EXPECT_EQ(e.in_while_out, 0);
  EXPECT_LT(e.translation_mm.max, 2e-3);
  EXPECT_LT(e.rotation_deg.max, 2e-4);
}

// The command: 0 when evaluated, 1 when nothing matched, InputError (exit 2
// in main) for a malformed file.
TEST(CorrectionEval, CommandExitStatus) {
  TempDir dir;
  const Scenario s = MakeScenario();
  WriteTrajectory(dir.path() / "gt.txt", s.truth);
  WriteMatrix4(dir.path() / "target.txt", Target().ToMatrix());
  WriteFileAtomic(dir.path() / "c.csv", std::string(kHeader) + "1.0,-1.0,0,0,0,0,0,1.0,0,in\n");
  WriteFileAtomic(dir.path() / "far.csv", std::string(kHeader) + "100.0,-1.0,0,0,0,0,0,1.0,0,in\n");
  WriteFileAtomic(dir.path() / "bad.csv", std::string(kHeader) + "1.0,-1.0,0,0,0,0,0,1.0,0\n");
  auto run = [&](const std::string& csv, std::vector<std::string> extra = {}) {
    std::vector<std::string> argv = {"--corrections", (dir.path() / csv).string(), "--gt",
                                     (dir.path() / "gt.txt").string(), "--target", (dir.path() / "target.txt").string(),
                                     "--json"};
    argv.insert(argv.end(), extra.begin(), extra.end());
    return RunEvaluateCommand(argv);
  };
  EXPECT_EQ(run("c.csv"), 0);
  EXPECT_EQ(run("far.csv"), 1);
  EXPECT_NE(InputErrorOf([&] { run("bad.csv"); }).find("bad.csv:2: expected 10"), std::string::npos);
  EXPECT_THROW(run("c.csv", {"--tolerance-mm", "0"}), InputError);
  EXPECT_THROW(run("c.csv", {"--est", "x.txt"}), InputError);
}

}  // namespace
}  // namespace arpos
