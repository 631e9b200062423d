#pragma once
/// The simulator as a live camera: a tracking sequence of a simulated case
/// (a folder written by `arpos simulate`, with its simulation.yaml) rendered
/// by the same simulator and delivered at the recording's frame rate, so
/// that live tracking, recording and streaming are testable without
/// hardware.
///
/// The case's world (room, markers, patient, stickers, camera and sensor
/// conditions) is rebuilt from simulation.yaml; `frames` other than the
/// case's tracking length plan a new, longer or shorter, hand-held path in
/// the same world (the world does not depend on the sequence lengths).
/// Rendering a frame takes longer than a camera's frame interval on two
/// cores, so every frame is rendered when the source opens; the clock starts
/// after that, and from then on frames are delivered at `fps` whether or not
/// the reader keeps up (live() is true). Each frame carries its true camera
/// and patient poses, so a recording of it can be evaluated.

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "sensor/camera_source.h"

namespace arpos {

struct SimulatorSourceOptions {
  std::filesystem::path case_dir;
  int sequence = 0;   ///< tracking sequence index (tracking/seq_NN)
  int frames = 0;     ///< 0: the case's tracking length
  double fps = 0;     ///< 0: the recording's rate (30)
};

/// "CASE_DIR[?seq=N&frames=F&fps=R]". Throws InputError naming the key.
SimulatorSourceOptions ParseSimulatorSourceUri(const std::string& uri);

class SimulatorSource : public CameraSource {
 public:
  /// Reads simulation.yaml and plans the sequence (no rendering yet).
  explicit SimulatorSource(const SimulatorSourceOptions& options);
  ~SimulatorSource() override;
  const CameraIntrinsics& intrinsics() const override;
  std::string description() const override;
  int frame_count() const override;
  bool live() const override { return true; }

 protected:
  void OpenImpl() override;  ///< renders every frame, then starts the clock
  bool NextImpl(RgbdFrame* frame) override;

 private:
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace arpos
