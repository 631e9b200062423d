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

}  // namespace
}  // namespace arpos
