#pragma once
/// Camera responses of the simulator: how a colour camera turns the linear
/// sensor value (radiance x exposure, 1 = the 8-bit white level) into the
/// 8-bit code it delivers, and auto exposure.
///
/// Responses (x = linear value, clipped to [0, 1]; code = round(255 y)):
/// - srgb:     y = 12.92 x (x <= 0.0031308), else 1.055 x^(1/2.4) - 0.055
///             (IEC 61966-2-1; the simulator's default, what the textures use).
/// - linear:   y = x (raw / linear mode).
/// - gamma2.6: y = x^(1/2.6) (pure power law, no linear toe).
/// - scurve:   y = (1 - k) s + k s^2 (3 - 2 s), s = srgb(x), k = 0.5: the sRGB
///             curve followed by a consumer contrast S-curve (a smoothstep
///             blend), with a toe (slope 0.5 at black) and a shoulder (slope
///             0.5 at white) and slope 1.25 at mid grey. Monotone
///             (dy/ds = 1 - k + 6 k s (1 - s) > 0), y(0) = 0, y(1) = 1.
///
/// Auto exposure (--auto-exposure): the exposure drifts smoothly over the
/// recording, stops(t) = sum_i w_i sin(2 pi f_i t + phi_i) with sum w_i =
/// max_stops (so |stops| <= max_stops, default 1), three waves of periods
/// 4-30 s; the linear value is multiplied by 2^stops before noise and the
/// response (so bright parts clip at 255). t is the frame's timestamp.

#include <cstdint>
#include <string>
#include <vector>

namespace arpos::sim {

enum class CameraResponse { kSrgb, kLinear, kGamma26, kSCurve };

/// "srgb", "linear", "gamma2.6", "scurve".
std::string ResponseName(CameraResponse response);
/// Parses a name above; false for anything else.
bool ParseResponse(const std::string& name, CameraResponse* response);
/// Every response, in the order above.
std::vector<CameraResponse> AllResponses();

/// The encoded value y in [0, 1] for linear x (clipped to [0, 1]), exact.
double EncodeResponse(CameraResponse response, double linear);
/// The inverse: linear x for encoded y in [0, 1].
double DecodeResponse(CameraResponse response, double encoded);
/// The 8-bit code for linear x, rounded: a 16384-bin table with linear
/// interpolation (at most one code from round(255 EncodeResponse(x))).
/// For srgb this is exactly Srgb8FromLinearFast (render_scene.h).
uint8_t Encode8Fast(CameraResponse response, float linear);

/// Smooth exposure drift (see the header comment).
struct AutoExposure {
  struct Wave {
    double frequency_hz = 0, phase_rad = 0, weight_stops = 0;
  };
  std::vector<Wave> waves;  ///< empty: no auto exposure (0 stops)
  /// Three waves drawn from `seed` with weights summing to `max_stops`.
  static AutoExposure Draw(uint64_t seed, double max_stops = 1.0);
  bool enabled() const { return !waves.empty(); }
  /// Exposure relative to the profile's, in stops, at time t (s).
  double Stops(double t_s) const;
};

}  // namespace arpos::sim
