#pragma once
/// Camera sources: anything that delivers RGB-D frames (a live device, a
/// recorded sequence replayed as if live, the simulator).
///
/// Public Open/Next/Close do the bookkeeping and call the protected hooks
/// (after PLUS's vtkPlusDevice). Sources are registered by an explicit call
/// (RegisterBuiltinCameraSources in plugins/), never by static initialisers.
/// A source is used from one thread at a time.

#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "sensor/intrinsics.h"
#include "sensor/rgbd_frame.h"

namespace arpos {

class CameraSource {
 public:
  virtual ~CameraSource() = default;

  /// Starts delivering frames; throws InputError/Error if the source cannot.
  void Open();
  /// Fills `frame` with the next frame; false at the end of the stream or if
  /// the source is closed. Expected conditions are data, not exceptions.
  bool Next(RgbdFrame* frame);
  void Close();
  bool is_open() const { return open_; }
  int frames_delivered() const { return frames_delivered_; }

  virtual const CameraIntrinsics& intrinsics() const = 0;
  virtual std::string description() const = 0;

 protected:
  virtual void OpenImpl() = 0;
  virtual bool NextImpl(RgbdFrame* frame) = 0;
  virtual void CloseImpl() {}

 private:
  bool open_ = false;
  int frames_delivered_ = 0;
};

/// Factory by kind name, e.g. "replay" with a URI that is a sequence folder.
class CameraSourceRegistry {
 public:
  using Factory = std::function<std::unique_ptr<CameraSource>(const std::string& uri)>;
  static CameraSourceRegistry& Global();

  void Register(const std::string& kind, const std::string& help, Factory factory);
  /// "kind:uri" or a kind alone. Throws InputError listing the known kinds.
  std::unique_ptr<CameraSource> Create(const std::string& spec) const;
  std::vector<std::pair<std::string, std::string>> Kinds() const;  ///< kind, help

 private:
  struct Entry {
    std::string help;
    Factory factory;
  };
  std::map<std::string, Entry> entries_;
};

}  // namespace arpos
