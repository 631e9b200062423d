#include "simulation/camera_response.h"

#include <algorithm>
#include <array>
#include <cmath>

#include "simulation/random.h"
#include "simulation/render_scene.h"

namespace arpos::sim {
namespace {

constexpr double kSCurveContrast = 0.5;  // k of the header's S-curve

double SrgbEncode(double x) { return x <= 0.0031308 ? 12.92 * x : 1.055 * std::pow(x, 1.0 / 2.4) - 0.055; }
double SrgbDecode(double y) { return y <= 0.04045 ? y / 12.92 : std::pow((y + 0.055) / 1.055, 2.4); }

constexpr int kBins = 16384;

const std::vector<float>& Table(CameraResponse response) {
  static const std::array<std::vector<float>, 4> tables = [] {
    std::array<std::vector<float>, 4> t;
    for (CameraResponse r : AllResponses()) {
      std::vector<float>& table = t[static_cast<int>(r)];
      table.resize(kBins + 2);
      for (int i = 0; i <= kBins + 1; ++i) {
        table[i] = static_cast<float>(EncodeResponse(r, std::min(1.0, static_cast<double>(i) / kBins)) * 255.0);
      }
    }
    return t;
  }();
  return tables[static_cast<int>(response)];
}

}  // namespace

std::string ResponseName(CameraResponse response) {
  switch (response) {
    case CameraResponse::kSrgb: return "srgb";
    case CameraResponse::kLinear: return "linear";
    case CameraResponse::kGamma26: return "gamma2.6";
    case CameraResponse::kSCurve: return "scurve";
  }
  return "srgb";
}

bool ParseResponse(const std::string& name, CameraResponse* response) {
  for (CameraResponse r : AllResponses()) {
    if (ResponseName(r) == name) {
      *response = r;
      return true;
    }
  }
  return false;
}

std::vector<CameraResponse> AllResponses() {
  return {CameraResponse::kSrgb, CameraResponse::kLinear, CameraResponse::kGamma26,
          CameraResponse::kSCurve};
}

double EncodeResponse(CameraResponse response, double linear) {
  const double x = std::clamp(linear, 0.0, 1.0);
  switch (response) {
    case CameraResponse::kSrgb: return SrgbEncode(x);
    case CameraResponse::kLinear: return x;
    case CameraResponse::kGamma26: return std::pow(x, 1.0 / 2.6);
    case CameraResponse::kSCurve: {
      const double s = SrgbEncode(x), k = kSCurveContrast;
      return (1 - k) * s + k * s * s * (3 - 2 * s);
    }
  }
  return x;
}

double DecodeResponse(CameraResponse response, double encoded) {
  const double y = std::clamp(encoded, 0.0, 1.0);
  switch (response) {
    case CameraResponse::kSrgb: return SrgbDecode(y);
    case CameraResponse::kLinear: return y;
    case CameraResponse::kGamma26: return std::pow(y, 2.6);
    case CameraResponse::kSCurve: {
      // Monotone in s: bisection on the S-curve, then the sRGB inverse.
      double lo = 0, hi = 1;
      for (int i = 0; i < 60; ++i) {
        const double mid = 0.5 * (lo + hi);
        const double k = kSCurveContrast;
        const double v = (1 - k) * mid + k * mid * mid * (3 - 2 * mid);
        (v < y ? lo : hi) = mid;
      }
      return SrgbDecode(0.5 * (lo + hi));
    }
  }
  return y;
}

uint8_t Encode8Fast(CameraResponse response, float value) {
  if (response == CameraResponse::kSrgb) return Srgb8FromLinearFast(value);
  if (!(value > 0)) return 0;
  if (value >= 1) return 255;
  // Below 1/256 the power law's slope is too steep for the table.
  if (value < 1.0f / 256) {
    return static_cast<uint8_t>(std::lround(EncodeResponse(response, value) * 255.0));
  }
  const std::vector<float>& table = Table(response);
  const float x = value * kBins;
  const int i = static_cast<int>(x);
  const float f = x - i;
  const float s = table[i] + f * (table[i + 1] - table[i]);
  return static_cast<uint8_t>(std::min(255.0f, s + 0.5f));
}

AutoExposure AutoExposure::Draw(uint64_t seed, double max_stops) {
  Rng rng(seed);
  AutoExposure ae;
  const double periods[3][2] = {{15, 30}, {7, 15}, {4, 7}};
  double weights[3] = {rng.Uniform(0.45, 0.6), rng.Uniform(0.25, 0.35), 0};
  weights[2] = 1.0 - weights[0] - weights[1];
  for (int i = 0; i < 3; ++i) {
    Wave w;
    w.frequency_hz = 1.0 / rng.Uniform(periods[i][0], periods[i][1]);
    w.phase_rad = rng.Uniform(0, 2 * M_PI);
    w.weight_stops = weights[i] * max_stops;
    ae.waves.push_back(w);
  }
  return ae;
}

double AutoExposure::Stops(double t_s) const {
  double stops = 0;
  for (const Wave& w : waves) stops += w.weight_stops * std::sin(2 * M_PI * w.frequency_hz * t_s + w.phase_rad);
  return stops;
}

}  // namespace arpos::sim
