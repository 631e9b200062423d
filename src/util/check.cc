#include "util/check.h"

#include <filesystem>

namespace arpos::internal {

void ThrowCheckFailure(const char* file, int line, const char* expr, const std::string& message) {
  std::ostringstream out;
  out << message << " [check failed: " << expr << " at "
      << std::filesystem::path(file).filename().string() << ":" << line << "]";
  throw Error(out.str());
}

}  // namespace arpos::internal
