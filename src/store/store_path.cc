#include "store/store_path.h"

#include <cstdlib>

namespace arpos {

std::string DefaultStorePath() {
  const char* from_environment = std::getenv("ARPOS_STORE");
  if (from_environment != nullptr && from_environment[0] != '\0') return from_environment;
  return "./arpos_store.db";
}

}  // namespace arpos
