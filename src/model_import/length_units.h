#pragma once
/// Length units of mesh files, stated or detected from the size of a body.
///
/// Mesh files carry no unit. A reference surface is a human body or a body
/// part, so its largest axis-aligned extent tells the unit:
///
///   Rule: pick the unit among mm, cm, dm, m that puts the largest extent E
///   (in file units) within [0.2, 2.0) m, i.e.
///     E in [200, 2000) -> mm,  [20, 200) -> cm,  [2, 20) -> dm,  [0.2, 2) -> m;
///   E in [2000, 3000] is taken as mm too (a tall body lying with arms raised;
///   no larger candidate unit exists). Anything else is not detected.
///
/// Each decade maps to exactly one unit, so detection never has two answers,
/// but a body part near a decade boundary (a 19 cm head in mm reads as 1.9 m
/// in cm) can be wrong: detection within 10 % of a boundary sets `ambiguous`
/// and callers should ask for the unit to be stated. Whatever the unit,
/// results whose largest extent is outside [kMinBodyExtentM, kMaxBodyExtentM]
/// are refused by the importer.

#include <optional>
#include <string>

namespace arpos {

enum class LengthUnit { kMillimetre, kCentimetre, kDecimetre, kMetre };

/// Smallest / largest accepted largest-extent of a reference body surface.
constexpr double kMinBodyExtentM = 0.05;
constexpr double kMaxBodyExtentM = 3.0;

/// Metres per unit (0.001 for mm).
double MetresPerUnit(LengthUnit unit);
/// "mm", "cm", "dm", "m".
const char* LengthUnitName(LengthUnit unit);
/// Parses "mm", "cm", "dm", "m" (case-insensitive); nullopt otherwise.
std::optional<LengthUnit> ParseLengthUnit(const std::string& text);

struct UnitDetection {
  std::optional<LengthUnit> unit;  ///< empty: no unit gives a body-sized extent
  bool ambiguous = false;          ///< within 10 % of a decade boundary
  std::string explanation;         ///< one sentence for the user, with the numbers
};

/// Applies the rule above to the largest extent in file units.
UnitDetection DetectLengthUnit(double largest_extent_in_file_units);

}  // namespace arpos
