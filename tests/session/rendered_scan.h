#pragma once
// A simulated body scan rendered and read as the session reads it: each
// frame's stickers (MakeBodyScanView) with the true camera poses.

#include <gtest/gtest.h>

#include <array>
#include <optional>
#include <string>

#include "body_model/body_marker_map.h"
#include "simulation/simulator.h"

namespace arpos {
namespace test {

struct Scan {
  std::vector<BodyScanView> views;
  CameraIntrinsics intrinsics;
  Rigid3d room_from_model;
  sim::SimulationTruth truth;
};

// Renders `frames` body-scan frames and builds views with the true camera poses.
inline Scan RenderScan(const std::string& profile, int frames, uint64_t seed,
                       std::optional<std::array<double, 5>> distortion = std::nullopt) {
  sim::SimulationOptions options;
  options.profile = profile;
  options.seed = seed;
  options.room_frames = 1;
  options.body_scan_frames = frames;
  options.tracking_frames = 1;
  options.tracking_sequences = 1;
  options.distortion = distortion;
  const sim::Simulator simulator(options);
  Scan scan;
  scan.truth = simulator.Truth();
  scan.intrinsics = simulator.profile().intrinsics;
  int body_index = -1;
  for (size_t i = 0; i < simulator.sequences().size(); ++i) {
    if (simulator.sequences()[i].kind == sim::SequenceKind::kBodyScan)
      body_index = static_cast<int>(i);
  }
  EXPECT_GE(body_index, 0);
  MarkerDetectorOptions detector_options;
  detector_options.id_ranges = {{100, 199}};
  detector_options.edge.response =
      CameraResponse::Srgb();                     // the simulator writes sRGB, as cameras do
  detector_options.intrinsics = scan.intrinsics;  // as the session stage's detector
  MarkerDetector detector(detector_options);
  for (int f = 0; f < frames; ++f) {
    const sim::SimulatedFrame frame = simulator.RenderFrame(body_index, f);
    RgbdFrame rgbd;
    rgbd.index = f;
    rgbd.timestamp_s = frame.timestamp_s;
    rgbd.color = frame.color;
    rgbd.depth = frame.depth;
    rgbd.depth_scale = scan.intrinsics.depth_scale;
    scan.room_from_model = *frame.room_from_model;
    scan.views.push_back(
        MakeBodyScanView(rgbd, frame.room_from_camera, &detector, scan.intrinsics, 0.03));
  }
  return scan;
}

}  // namespace test
}  // namespace arpos
