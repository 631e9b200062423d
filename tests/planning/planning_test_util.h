#pragma once
// Shared fixtures for the planning tests and benchmark: a small simulated
// case written once per process into a temporary folder, and its room map.

#include <array>
#include <filesystem>
#include <memory>
#include <string>

#include "room_map/room_map_builder.h"
#include "sensor/case_folder.h"
#include "simulation/simulation_truth.h"
#include "simulation/simulator.h"

namespace arpos::testing {

struct SmallCase {
  std::filesystem::path root;     ///< the case folder
  CaseFolder folder;
  sim::SimulationTruth truth;
};

/// A case simulated with seed 7: `room_frames` frames spread over the room
/// walk and, as tracking/seq_00, `tracking_frames` consecutive frames
/// (15-30 fps) of either the room walk between the mapped frames
/// (`tracking_from_room`: views the small map covers) or the simulator's
/// first tracking sequence (patient present); body_scan/ is absent. The same
/// arguments give the same case (cached per process; written on first use,
/// ~15-30 s). `lens`: rendered through a Kinect-like lens (kKinectLens).
const SmallCase& GetSmallCase(const std::string& profile = "xtion", int room_frames = 40,
                              int tracking_frames = 12, bool tracking_from_room = true, bool lens = false);

/// The simulator options GetSmallCase's cases are rendered with (the whole
/// walks; the case keeps some of their frames).
sim::SimulationOptions SmallCaseSimulationOptions(const std::string& profile, bool lens = false);

/// The distortion of a Kinect's colour camera (OpenCV k1 k2 p1 p2 k3).
inline constexpr std::array<double, 5> kKinectLens = {0.2624, -0.9531, -0.0054, 0.0026, 1.1633};

/// The map of GetSmallCase(profile, ...) built with the default stage options
/// (cached per process).
const RoomMapBuildResult& GetSmallCaseMap(const std::string& profile = "xtion", int room_frames = 40,
                                          int tracking_frames = 12, bool tracking_from_room = true,
                                          bool lens = false);

/// Mean / max corner error (m) of the mapped markers against the truth, over
/// markers with at least `min_views` observations.
struct MarkerErrors {
  double mean_m = 0, max_m = 0;
  int markers = 0;
};
MarkerErrors CompareMarkers(const RoomMap& map, const sim::SimulationTruth& truth, int min_views = 1);

}  // namespace arpos::testing
