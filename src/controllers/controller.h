#pragma once
/// Controllers: one per workflow stage, shared by the CLI and the GUI (after
/// COLMAP's controllers). A controller takes a flat options struct, checks it
/// when it starts, reports progress through callbacks and polls a cancel flag
/// between steps. Run() is called on a worker thread by the GUI and on the
/// main thread by the CLI; callbacks are invoked on the thread that runs it.

#include <filesystem>
#include <functional>
#include <string>

#include "util/check.h"

namespace arpos {

struct ControllerCallbacks {
  /// A step started or advanced: `step` names it for a person, `fraction` in
  /// [0, 1] is the progress of the whole run.
  std::function<void(const std::string& step, double fraction)> progress;
  /// Polled between steps; returning true stops the run with Cancelled.
  std::function<bool()> cancel_requested;
};

/// Thrown by a controller that stopped because cancellation was requested.
/// Everything stored before the cancellation point stays stored and valid.
class Cancelled : public Error {
 public:
  Cancelled() : Error("cancelled by the user") {}
};

/// Output checked before a stage runs, so that a command never computes (or
/// stores) what it then cannot write. Creates `folder` if needed and writes
/// and removes a probe file in it. Throws InputError naming `option` and the
/// folder, e.g. "--out /data/out: folder not writable: /data/out (Permission denied)".
void RequireWritableFolder(const std::filesystem::path& folder, const std::string& option);
/// The same for the folder a file will be written to (which must exist);
/// `file` itself must not be a folder.
void RequireWritableFileLocation(const std::filesystem::path& file, const std::string& option);

class Controller {
 public:
  explicit Controller(ControllerCallbacks callbacks) : callbacks_(std::move(callbacks)) {}
  virtual ~Controller() = default;
  /// Runs the stage. Throws InputError for bad input, Cancelled on request.
  virtual void Run() = 0;

 protected:
  /// Reports progress, then throws Cancelled if a cancel was requested.
  void Step(const std::string& step, double fraction);
  /// For a stage function that reports its own steps.
  const ControllerCallbacks& callbacks() const { return callbacks_; }

 private:
  ControllerCallbacks callbacks_;
};

}  // namespace arpos
