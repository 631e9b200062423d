#pragma once
/// File helpers. Paths are std::filesystem::path; errors name the file.

#include <filesystem>
#include <string>

namespace arpos {

namespace fs = std::filesystem;

/// Reads a whole file; throws InputError naming the file if it cannot. A
/// leading UTF-8 byte-order mark (what many Windows editors and .NET tools
/// write first) is dropped: it is invisible, and a parser would read it as
/// part of the first token.
std::string ReadTextFile(const fs::path& path);

/// Writes through a temporary file in the same folder, flushed to disk, then
/// renamed over `path`: a crash leaves either the old or the new file, never a
/// half-written one.
void WriteFileAtomic(const fs::path& path, const std::string& contents);

/// Creates `path` and its parents; throws naming the folder on failure.
void CreateDirectories(const fs::path& path);

/// A fresh folder under the system temp dir, removed by the destructor.
class TempDir {
 public:
  explicit TempDir(const std::string& prefix = "arpos");
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

}  // namespace arpos
