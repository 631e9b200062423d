#include "model_import/length_units.h"

#include <cmath>

#include "util/string_util.h"

namespace arpos {

double MetresPerUnit(LengthUnit unit) {
  switch (unit) {
    case LengthUnit::kMillimetre: return 0.001;
    case LengthUnit::kCentimetre: return 0.01;
    case LengthUnit::kDecimetre: return 0.1;
    case LengthUnit::kMetre: return 1.0;
  }
  return 1.0;
}

const char* LengthUnitName(LengthUnit unit) {
  switch (unit) {
    case LengthUnit::kMillimetre: return "mm";
    case LengthUnit::kCentimetre: return "cm";
    case LengthUnit::kDecimetre: return "dm";
    case LengthUnit::kMetre: return "m";
  }
  return "?";
}

std::optional<LengthUnit> ParseLengthUnit(const std::string& text) {
  const std::string lower = ToLower(Trim(text));
  if (lower == "mm") return LengthUnit::kMillimetre;
  if (lower == "cm") return LengthUnit::kCentimetre;
  if (lower == "dm") return LengthUnit::kDecimetre;
  if (lower == "m") return LengthUnit::kMetre;
  return std::nullopt;
}

UnitDetection DetectLengthUnit(double extent) {
  UnitDetection result;
  if (!std::isfinite(extent) || !(extent > 0)) {
    result.explanation = "the mesh has no extent";
    return result;
  }
  // Lower bounds of each unit's decade, largest unit first.
  struct Candidate {
    LengthUnit unit;
    double lower;  // file units
  };
  static const Candidate kCandidates[] = {{LengthUnit::kMetre, 0.2},
                                          {LengthUnit::kDecimetre, 2.0},
                                          {LengthUnit::kCentimetre, 20.0},
                                          {LengthUnit::kMillimetre, 200.0}};
  for (const auto& c : kCandidates) {
    const double upper = c.unit == LengthUnit::kMillimetre ? 3000.0 : 10.0 * c.lower;
    const bool last = c.unit == LengthUnit::kMillimetre;
    if (extent >= c.lower && (extent < upper || (last && extent <= upper))) {
      result.unit = c.unit;
      const double ratio_low = extent / c.lower, ratio_high = 10.0 * c.lower / extent;
      result.ambiguous = ratio_low < 1.1 || (!last && ratio_high < 1.1);
      result.explanation = StringPrintf(
          "largest extent %.4g file units read as %s (%.3f m): the unit that makes it 0.2-2 m",
          extent, LengthUnitName(c.unit), extent * MetresPerUnit(c.unit));
      if (result.ambiguous) result.explanation += ", close to a decade boundary (ambiguous)";
      return result;
    }
  }
  result.explanation = StringPrintf(
      "largest extent %.4g file units is no body size in mm, cm, dm or m "
      "(0.2-2 m, or 2-3 m in mm)",
      extent);
  return result;
}

}  // namespace arpos
