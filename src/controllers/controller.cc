#include "controllers/controller.h"

#include "util/logging.h"

namespace arpos {

void Controller::Step(const std::string& step, double fraction) {
  ARPOS_DEBUG("step: " << step);
  if (callbacks_.progress) callbacks_.progress(step, fraction);
  if (callbacks_.cancel_requested && callbacks_.cancel_requested()) throw Cancelled();
}

}  // namespace arpos
