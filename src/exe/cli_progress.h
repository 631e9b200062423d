#pragma once
/// Progress of a controller printed for a person on the terminal (stderr),
/// shared by the subcommands that run controllers.

#include <iostream>

#include "controllers/controller.h"
#include "util/string_util.h"

namespace arpos {

inline ControllerCallbacks CliProgress() {
  ControllerCallbacks callbacks;
  callbacks.progress = [](const std::string& step, double fraction) {
    std::cerr << StringPrintf("[%3.0f%%] ", 100 * fraction) << step << std::endl;
  };
  return callbacks;
}

}  // namespace arpos
