#pragma once
/// Camera sources: anything that delivers RGB-D frames (a live device, a
/// recorded sequence replayed as if live, the simulator).
///
/// Public Open/Next/Close do the bookkeeping and call the protected hooks
/// (after PLUS's vtkPlusDevice). Sources live in plugins (plugins/<name>/,
/// shared libraries loaded at run time, sensor/source_plugin.h) and are
/// registered by an explicit call of each plugin's entry, never by static
/// initialisers. A source is used from one thread at a time.

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
  /// Frames in the stream when known in advance (a recording), else -1.
  virtual int frame_count() const { return -1; }
  /// True when frames come at the camera's pace whether or not they are
  /// taken (a device, a paced simulation): a slow reader loses frames.
  virtual bool live() const { return false; }
  /// The recording folder behind the source, if any (for the store).
  virtual std::string recording_path() const { return {}; }

 protected:
  virtual void OpenImpl() = 0;
  virtual bool NextImpl(RgbdFrame* frame) = 0;
  virtual void CloseImpl() {}

 private:
  bool open_ = false;
  int frames_delivered_ = 0;
};

/// A source's URI as the plugins spell it: "PATH?key=value&flag&...".
struct SourceUri {
  std::string path;  ///< before the '?'
  std::vector<std::pair<std::string, std::string>> options;  ///< in order; a flag has an empty value
};
SourceUri ParseSourceUri(const std::string& uri);
/// `value` as a whole number; InputError naming `kind`, `key` and the text otherwise.
int SourceUriInt(const std::string& kind, const std::string& key, const std::string& value);

/// What a source kind can open right now (`arpos sources`): for a device
/// kind the attached devices, for others what the URI names.
struct SourceAvailability {
  std::vector<std::string> devices;  ///< "URI  description" per openable device
  std::string status;                ///< one line: "2 devices", "no device attached", ...
};

/// Factory by kind name, e.g. "replay" with a URI that is a sequence folder.
class CameraSourceRegistry {
 public:
  using Factory = std::function<std::unique_ptr<CameraSource>(const std::string& uri)>;
  using Lister = std::function<SourceAvailability()>;
  static CameraSourceRegistry& Global();

  /// `lister` (optional) says what is available now; it must not throw for
  /// an absent device.
  void Register(const std::string& kind, const std::string& help, Factory factory, Lister lister = {});
  /// Moves every kind of `other` in, noting `origin` (the plugin's file).
  void Merge(CameraSourceRegistry&& other, const std::string& origin);
  /// "kind:uri" or a kind alone. Throws InputError listing the known kinds.
  std::unique_ptr<CameraSource> Create(const std::string& spec) const;

  struct Kind {
    std::string name, help, origin;
    Lister lister;
  };
  std::vector<Kind> Kinds() const;
  bool Has(const std::string& kind) const { return entries_.count(kind) > 0; }

 private:
  struct Entry {
    std::string help;
    Factory factory;
    Lister lister;
    std::string origin;
  };
  std::map<std::string, Entry> entries_;
};

}  // namespace arpos
