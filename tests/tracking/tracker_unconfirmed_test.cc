// The tracker on a small simulated case whose tracking frames see the patient
// and the room's texture but no room marker: the camera is placed by the
// map's keypoints alone, which can agree on a wrong place, so no such frame
// may read `in` however close the patient is to the plan.
#include <cstdio>

#include <gtest/gtest.h>

#include "feedback/couch_correction.h"
#include "planning/planning_test_util.h"
#include "sensor/sequence.h"
#include "simulation/simulator.h"
#include "tracking/tracker.h"
#include "tracking/tracking_stage.h"

namespace arpos {
namespace {

TEST(Tracker, ACameraPlacedByKeypointsAloneNeverLetsAFrameReadIn) {
  // 120 room frames (with 40, keypoints place none of these views), 12
  // consecutive frames of the patient tracking walk.
  const auto& c = testing::GetSmallCase("xtion", 120, 12, /*tracking_from_room=*/false);
  const RoomMap& map = testing::GetSmallCaseMap("xtion", 120, 12, false).map;
  const sim::SimulationTruth& truth = c.truth;
  std::map<int, Rigid3d> model_from_marker;
  for (const auto& m : truth.body_markers) model_from_marker[m.id] = m.parent_from_marker;
  ASSERT_FALSE(model_from_marker.empty());

  const auto& [name, dir] = c.folder.tracking.at(0);
  const Sequence seq = Sequence::Open(dir);
  // The plan: the patient's true pose in the first of these frames (it
  // moves by millimetres over 12 frames), and tolerances wide enough that
  // every placed frame would read `in` on its correction and uncertainty
  // alone.
  const sim::Simulator simulator(testing::SmallCaseSimulationOptions("xtion"));
  int tracking = -1;
  for (size_t q = 0; q < simulator.sequences().size(); ++q) {
    if (simulator.sequences()[q].kind == sim::SequenceKind::kTracking && tracking < 0) tracking = static_cast<int>(q);
  }
  ASSERT_GE(tracking, 0);
  const std::optional<Rigid3d> room_from_model = simulator.RenderFrame(tracking, 0).room_from_model;
  ASSERT_TRUE(room_from_model.has_value());

  TrackingInputs inputs;
  inputs.sticker_size_m = c.folder.config.body_markers.size_m;
  TrackerOptions options = MakeTrackerOptions(c.folder.config, inputs);
  options.tolerances.translation_mm = 100;
  options.tolerances.rotation_deg = 10;
  options.max_position_sigma_mm = 100;
  Tracker tracker(map, simulator.world().reference_model, model_from_marker, *room_from_model,
                  c.folder.config.camera, options, room_from_model);
  int placed = 0, unconfirmed = 0, near_plan = 0, in = 0;
  for (size_t i = 0; i < seq.size(); ++i) {
    const TrackedFrame f = tracker.Process(seq.LoadFrame(i, c.folder.config.camera));
    EXPECT_EQ(f.camera.markers_used, 0) << "frame " << i << ": these frames should show no room marker";
    if (!f.camera.ok) continue;
    ++placed;
    in += f.correction.state == CorrectionState::kIn;
    if (!f.camera.unconfirmed) continue;
    ++unconfirmed;
    EXPECT_NE(f.correction.state, CorrectionState::kIn) << "frame " << i;
    EXPECT_NE(f.message.find("not yet confirmed by a room marker"), std::string::npos) << f.message;
    if (f.room_from_model && f.correction.state != CorrectionState::kLost &&
        f.correction.translation_mm + f.correction.uncertainty.translation_mm < 0.5 * options.tolerances.translation_mm &&
        f.correction.rotation_deg + f.correction.uncertainty.rotation_deg < 0.5 * options.tolerances.rotation_deg) {
      ++near_plan;
    }
  }
  std::printf("%zu frames: %d placed by keypoints, %d unconfirmed, %d of them well within tolerance, %d in\n",
              seq.size(), placed, unconfirmed, near_plan, in);
  ASSERT_GT(placed, 0) << "the map's keypoints should place some of these frames";
  EXPECT_EQ(unconfirmed, placed) << "no room marker ever confirms them";
  EXPECT_GT(near_plan, 0) << "the rule, not the correction, should be what keeps them from `in`";
  EXPECT_EQ(in, 0);
}

// A camera placed without a room marker is refused when the patient seen in
// it would have moved farther than a patient on a couch does between frames
// (0.15 m/s and 2 cm by default); a room marker, the check switched off or
// a last frame too old leave it be, and the reason says how far.
TEST(Tracker, ACameraThatWouldMakeThePatientJumpIsRefused) {
  TrackerOptions options;
  ASSERT_EQ(options.Validate(), "");
  const Rigid3d last(Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ())),
                     Eigen::Vector3d(0.4, 1.2, 0.9));
  auto moved = [&](double x_m) {
    Rigid3d now = last;
    now.translation.x() += x_m;
    return now;
  };
  // 1/15 s: reach 0.15 * 0.067 + 0.02 = 30 mm.
  const double dt = 1.0 / 15;
  EXPECT_EQ(PatientJumpRefusal(options, dt, last, moved(0.029), 0), "");
  const std::string refused = PatientJumpRefusal(options, dt, last, moved(0.065), 0);
  EXPECT_NE(refused.find("the patient would have moved 65 mm in 0.07 s (at most 30 mm); refused"),
            std::string::npos)
      << refused;
  // Measured along any direction, the rotation aside.
  Rigid3d turned = moved(0.0);
  turned.translation.z() -= 0.04;
  turned.rotation =
      Eigen::Quaterniond(Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitX())) * turned.rotation;
  EXPECT_NE(PatientJumpRefusal(options, dt, last, turned, 0), "");
  // A room marker places the camera: the patient may have moved.
  EXPECT_EQ(PatientJumpRefusal(options, dt, last, moved(0.065), 1), "");
  // The last frame too old to compare with, or none before this one.
  EXPECT_EQ(PatientJumpRefusal(options, 0.25, last, moved(0.065), 0), "");
  EXPECT_EQ(PatientJumpRefusal(options, 0.0, last, moved(0.065), 0), "");
  // Longer apart, farther: 0.2 s reaches 50 mm.
  EXPECT_EQ(PatientJumpRefusal(options, 0.2, last, moved(0.049), 0), "");
  EXPECT_NE(PatientJumpRefusal(options, 0.2, last, moved(0.051), 0), "");
  options.max_patient_speed_m_s = 0;
  EXPECT_EQ(options.Validate(), "");
  EXPECT_EQ(PatientJumpRefusal(options, dt, last, moved(0.5), 0), "");
  options.patient_jump_margin_m = -0.01;
  EXPECT_NE(options.Validate(), "");
}

}  // namespace
}  // namespace arpos
