#pragma once
/// Where the program keeps its session store by default.

#include <string>

namespace arpos {

/// The store file used when no `--store` is given: the value of the
/// environment variable ARPOS_STORE if it is set and not empty, otherwise
/// "./arpos_store.db" (relative to the working directory). The path is
/// returned as given, not checked or made absolute.
///
/// Thread-safety: reads the environment; do not call while another thread
/// calls setenv/putenv.
std::string DefaultStorePath();

}  // namespace arpos
