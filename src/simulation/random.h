#pragma once
/// Deterministic randomness for the simulator.
///
/// Everything random in a simulated case derives from the user's seed through
/// these functions, whose results are defined here (not by the standard
/// library's distributions, which are implementation-defined), so a seed gives
/// the same bytes on every run, thread count and libstdc++ version.
/// Per-pixel noise is a pure function of (seed, stream, frame, pixel): OpenMP
/// scheduling cannot change it.

#include <cmath>
#include <cstdint>
#include <random>

namespace arpos::sim {

/// SplitMix64 finaliser: a good 64-bit mixing function.
inline uint64_t Mix64(uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

/// Hash of several integers (order matters).
inline uint64_t HashCombine(uint64_t a, uint64_t b) { return Mix64(a ^ Mix64(b)); }
inline uint64_t Hash3(uint64_t a, uint64_t b, uint64_t c) {
  return HashCombine(HashCombine(a, b), c);
}
inline uint64_t Hash4(uint64_t a, uint64_t b, uint64_t c, uint64_t d) {
  return HashCombine(Hash3(a, b, c), d);
}

/// Uniform in [0, 1) from the top 53 bits.
inline double UniformFromBits(uint64_t bits) {
  return static_cast<double>(bits >> 11) * (1.0 / 9007199254740992.0);
}

/// Standard normal from one 64-bit hash (Box-Muller on its two 32-bit halves).
inline double NormalFromBits(uint64_t bits) {
  const double u1 = (static_cast<double>(bits >> 32) + 0.5) * (1.0 / 4294967296.0);
  const double u2 = static_cast<double>(bits & 0xffffffffULL) * (1.0 / 4294967296.0);
  return std::sqrt(-2.0 * std::log(u1)) * std::cos(6.283185307179586 * u2);
}

/// Cheap approximately standard normal from one 64-bit hash (Irwin-Hall sum
/// of four 16-bit uniforms: mean 0, variance 1, tails cut at +-3.46). For
/// per-pixel sensor noise, where millions are drawn per frame.
inline double FastNormalFromBits(uint64_t bits) {
  const double sum = static_cast<double>(bits & 0xffff) + static_cast<double>((bits >> 16) & 0xffff) +
                     static_cast<double>((bits >> 32) & 0xffff) + static_cast<double>(bits >> 48);
  return (sum * (1.0 / 65536.0) - 2.0 + 2.0 / 65536.0) * 1.7320508075688772;
}

/// Sequential generator: std::mt19937_64 (bit-exact by the standard) with
/// distributions implemented here.
class Rng {
 public:
  explicit Rng(uint64_t seed) : engine_(seed) {}
  /// A child generator for a named sub-task, independent of how many numbers
  /// this one has produced.
  static Rng Derive(uint64_t seed, uint64_t stream) { return Rng(HashCombine(seed, stream)); }

  uint64_t Bits() { return engine_(); }
  double Uniform() { return UniformFromBits(engine_()); }
  double Uniform(double lo, double hi) { return lo + (hi - lo) * Uniform(); }
  /// Integer in [lo, hi] inclusive.
  int UniformInt(int lo, int hi) {
    return lo + static_cast<int>(Uniform() * (hi - lo + 1) * (1.0 - 1e-12));
  }
  double Normal() { return NormalFromBits(engine_()); }
  double Normal(double mean, double sigma) { return mean + sigma * Normal(); }

 private:
  std::mt19937_64 engine_;
};

/// Stream ids, so that adding a random draw to one part of the simulator does
/// not change the others.
enum class Stream : uint64_t {
  kRoomLayout = 1,
  kRoomTexture = 2,
  kBody = 3,
  kStickers = 4,
  kReferenceNoise = 5,
  kTrajectory = 6,
  kBodyMotion = 7,
  kColorNoise = 8,
  kDepthNoise = 9,
  kHard = 10,
  kConditions = 11,      ///< --random-conditions: what is drawn per seed
  kConditionWalk = 12,   ///< --random-conditions: the room walk's origin-marker views
  kExposure = 13,        ///< auto exposure
  kDepthBias = 14,       ///< the depth error field
  kBreathing = 15,       ///< breathing period and phase
};

inline uint64_t StreamSeed(uint64_t seed, Stream stream) {
  return HashCombine(seed, static_cast<uint64_t>(stream));
}

}  // namespace arpos::sim
