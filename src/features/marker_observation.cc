#include "features/marker_observation.h"

namespace arpos {

const char* MarkerStatusName(MarkerStatus status) {
  switch (status) {
    case MarkerStatus::kRefined:
      return "refined";
    case MarkerStatus::kPartiallyOccluded:
      return "partially_occluded";
    case MarkerStatus::kRefinementFailed:
      return "refinement_failed";
    case MarkerStatus::kNotRefined:
      return "not_refined";
  }
  return "unknown";
}

double MarkerObservation::MeanSidePx() const {
  double sum = 0;
  for (int k = 0; k < 4; ++k) sum += (corners_px[(k + 1) % 4] - corners_px[k]).norm();
  return 0.25 * sum;
}

}  // namespace arpos
