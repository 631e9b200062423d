#include "sensor/camera_source.h"

#include <sstream>

#include "util/check.h"

namespace arpos {

void CameraSource::Open() {
  if (open_) return;
  OpenImpl();
  open_ = true;
  frames_delivered_ = 0;
}

bool CameraSource::Next(RgbdFrame* frame) {
  ARPOS_CHECK(frame != nullptr, "Next() needs a frame to fill");
  if (!open_) return false;
  if (!NextImpl(frame)) return false;
  ++frames_delivered_;
  return true;
}

void CameraSource::Close() {
  if (!open_) return;
  CloseImpl();
  open_ = false;
}

SourceUri ParseSourceUri(const std::string& uri) {
  SourceUri parsed;
  const size_t q = uri.find('?');
  parsed.path = uri.substr(0, q);
  if (q == std::string::npos) return parsed;
  std::stringstream query(uri.substr(q + 1));
  std::string item;
  while (std::getline(query, item, '&')) {
    if (item.empty()) continue;
    const size_t eq = item.find('=');
    parsed.options.emplace_back(item.substr(0, eq), eq == std::string::npos ? "" : item.substr(eq + 1));
  }
  return parsed;
}

int SourceUriInt(const std::string& kind, const std::string& key, const std::string& value) {
  size_t used = 0;
  int number = 0;
  try {
    number = std::stoi(value, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != value.size()) {
    ARPOS_INPUT_ERROR(kind << ": " << key << " must be a whole number, got '" << value << "'");
  }
  return number;
}

CameraSourceRegistry& CameraSourceRegistry::Global() {
  static CameraSourceRegistry registry;
  return registry;
}

void CameraSourceRegistry::Register(const std::string& kind, const std::string& help, Factory factory,
                                    Lister lister) {
  ARPOS_CHECK(!kind.empty() && factory, "a camera source needs a kind and a factory");
  entries_[kind] = {help, std::move(factory), std::move(lister), ""};
}

void CameraSourceRegistry::Merge(CameraSourceRegistry&& other, const std::string& origin) {
  for (auto& [name, entry] : other.entries_) {
    entry.origin = origin;
    entries_[name] = std::move(entry);
  }
  other.entries_.clear();
}

std::unique_ptr<CameraSource> CameraSourceRegistry::Create(const std::string& spec) const {
  const size_t colon = spec.find(':');
  const std::string kind = spec.substr(0, colon);
  const std::string uri = colon == std::string::npos ? "" : spec.substr(colon + 1);
  const auto it = entries_.find(kind);
  if (it == entries_.end()) {
    std::ostringstream known;
    for (const auto& [name, entry] : entries_) known << " " << name;
    ARPOS_INPUT_ERROR("unknown camera source '" << kind << "'; known sources:"
                      << (entries_.empty() ? std::string(" none (no plugin was loaded; see `arpos sources`)")
                                           : known.str()));
  }
  return it->second.factory(uri);
}

std::vector<CameraSourceRegistry::Kind> CameraSourceRegistry::Kinds() const {
  std::vector<Kind> kinds;
  for (const auto& [name, entry] : entries_) kinds.push_back({name, entry.help, entry.origin, entry.lister});
  return kinds;
}

}  // namespace arpos
