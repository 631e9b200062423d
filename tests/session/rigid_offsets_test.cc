// The robust mean of per-frame rigid offsets and how well it is known
// (the session's placement of the body scan in the room).
#include "body_model/rigid_offsets.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

namespace arpos {
namespace {

Offset Shift(double x_mm, double y_mm, double z_mm) {
  Offset v = Offset::Zero();
  v.tail<3>() << x_mm / 1000, y_mm / 1000, z_mm / 1000;
  return v;
}

// Frames come in runs of consecutive frames (0.1 s apart, runs 2 s apart);
// every frame of a run shares the run's error.
struct Runs {
  std::vector<Offset> offsets;
  std::vector<double> times;
};
Runs MakeRuns(const std::vector<Eigen::Vector3d>& run_errors_mm, int frames_per_run, double frame_noise_mm,
              std::mt19937* rng) {
  std::normal_distribution<double> noise(0.0, frame_noise_mm);
  Runs r;
  double t = 100;
  for (const Eigen::Vector3d& e : run_errors_mm) {
    for (int k = 0; k < frames_per_run; ++k, t += 0.1) {
      r.offsets.push_back(Shift(e.x() + noise(*rng), e.y() + noise(*rng), e.z() + noise(*rng)));
      r.times.push_back(t);
    }
    t += 2.0;
  }
  return r;
}

TEST(RigidOffsets, RunsOfConsecutiveFramesCountOnceAndAWrongOffsetIsLeftOut) {
  std::mt19937 rng(7);
  Runs r = MakeRuns({{1, 0, 0}, {-1, 0, 0}, {0, 2, 0}, {0, -2, 0}}, 5, 0.01, &rng);
  // Out of time order, and one frame pulled 50 mm away (left out).
  std::swap(r.offsets[0], r.offsets[12]);
  std::swap(r.times[0], r.times[12]);
  r.offsets.push_back(Shift(50, 0, 0));
  r.times.push_back(r.times.back() + 0.1);
  const OffsetMeanSigma s = MeanOffsetSigma(r.offsets, r.times, 0.002);
  EXPECT_EQ(s.frames, 20);
  EXPECT_EQ(s.runs, 4);
  // Largest axis y: spread sqrt(2 * 5 * 4 / 19) mm, over sqrt(4 runs).
  EXPECT_NEAR(s.sigma_mm, std::sqrt(40.0 / 19) / 2, 0.01);
  const auto mean = RobustMeanOffset(r.offsets, Eigen::Vector3d(0.3, 0.2, 1.0), 0.002, 3);
  ASSERT_TRUE(mean.has_value());
  EXPECT_LT(1000 * mean->translation.norm(), 0.02);
}

TEST(RigidOffsets, OneRunIsOneSampleAndTooFewFramesAreUnknown) {
  std::mt19937 rng(8);
  const Runs one = MakeRuns({{0, 0, 0}}, 12, 0.5, &rng);
  const OffsetMeanSigma s = MeanOffsetSigma(one.offsets, one.times, 0.002);
  EXPECT_EQ(s.runs, 1);
  EXPECT_GT(s.sigma_mm, 0.3);  // the frames' spread itself, not over sqrt(12)
  const Runs two = MakeRuns({{1, 0, 0}, {2, 0, 0}}, 1, 0.0, &rng);
  EXPECT_FALSE(std::isfinite(MeanOffsetSigma(two.offsets, two.times, 0.002).sigma_mm));
  EXPECT_FALSE(std::isfinite(MeanOffsetSigma({}, {}, 0.002).sigma_mm));
}

// Over many scans whose runs carry independent errors, the mean's error
// stays within 2 stated sigmas (largest axis) about as often as it should;
// dividing by the square root of the frames instead would not.
TEST(RigidOffsets, TheStatedSigmaHoldsWhenConsecutiveFramesShareTheirError) {
  std::mt19937 rng(9);
  std::normal_distribution<double> run_error(0.0, 1.0);
  int beyond = 0, beyond_by_frames = 0;
  const int trials = 2000;
  for (int t = 0; t < trials; ++t) {
    std::vector<Eigen::Vector3d> errors;
    for (int k = 0; k < 5; ++k) errors.emplace_back(run_error(rng), run_error(rng), run_error(rng));
    const Runs r = MakeRuns(errors, 5, 0.2, &rng);
    const OffsetMeanSigma s = MeanOffsetSigma(r.offsets, r.times, 0.002);
    ASSERT_EQ(s.runs, 5);
    const auto mean = RobustMeanOffset(r.offsets, Eigen::Vector3d::Zero(), 0.002, 3);
    ASSERT_TRUE(mean.has_value());
    const double error_mm = 1000 * mean->translation.x();  // one axis: the truth is zero
    beyond += std::abs(error_mm) > 2 * s.sigma_mm;
    beyond_by_frames += std::abs(error_mm) > 2 * s.sigma_mm * std::sqrt(5.0 / 25.0);
  }
  // 2.4 % and 24 % with this seed (two-sided 2 sigma of a normal: 4.6 %).
  EXPECT_LT(beyond, trials / 10);
  EXPECT_GT(beyond_by_frames, trials / 6);
}

TEST(RigidOffsets, WeightsMoveTheMeanAndTheRunsCountByWhatTheyWeigh) {
  std::mt19937 rng(10);
  // Two runs of 5 frames, +1 and -1 mm along x; the first weighs 4 per frame.
  const Runs r = MakeRuns({{1, 0, 0}, {-1, 0, 0}}, 5, 0.0, &rng);
  std::vector<double> weights(10, 1.0);
  for (int k = 0; k < 5; ++k) weights[k] = 4.0;
  const auto mean = RobustMeanOffset(r.offsets, Eigen::Vector3d::Zero(), 0.002, 3, weights);
  ASSERT_TRUE(mean.has_value());
  EXPECT_NEAR(1000 * mean->translation.x(), 0.6, 1e-9);
  const OffsetMeanSigma s = MeanOffsetSigma(r.offsets, r.times, 0.002, weights);
  EXPECT_EQ(s.runs, 2);
  EXPECT_NEAR(s.effective_runs, 25.0 * 25.0 / (20.0 * 20.0 + 5.0 * 5.0), 1e-9);
  // Equal weights: the runs themselves.
  EXPECT_NEAR(MeanOffsetSigma(r.offsets, r.times, 0.002).effective_runs, 2.0, 1e-9);
  EXPECT_ANY_THROW(RobustMeanOffset(r.offsets, Eigen::Vector3d::Zero(), 0.002, 3, {1.0, 2.0}));
}

// Runs of unequal quality, each weighed by the inverse of its known error
// variance: the weighted mean is closer to the truth than the plain one, and
// its stated sigma still holds.
TEST(RigidOffsets, WeighingRunsByTheirErrorHelpsAndItsSigmaHolds) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> run_sigma(0.3, 3.0);
  std::normal_distribution<double> unit(0.0, 1.0);
  int beyond = 0;
  double sq_weighted = 0, sq_plain = 0;
  const int trials = 2000;
  for (int t = 0; t < trials; ++t) {
    std::vector<Eigen::Vector3d> errors;
    std::vector<double> sigmas;
    for (int k = 0; k < 5; ++k) {
      sigmas.push_back(run_sigma(rng));
      errors.push_back(sigmas.back() * Eigen::Vector3d(unit(rng), unit(rng), unit(rng)));
    }
    const Runs r = MakeRuns(errors, 5, 0.2, &rng);
    std::vector<double> weights;
    for (double s : sigmas) {
      for (int k = 0; k < 5; ++k) weights.push_back(1.0 / (s * s));
    }
    const OffsetMeanSigma s = MeanOffsetSigma(r.offsets, r.times, 0.002, weights);
    const auto weighted = RobustMeanOffset(r.offsets, Eigen::Vector3d::Zero(), 0.002, 3, weights);
    const auto plain = RobustMeanOffset(r.offsets, Eigen::Vector3d::Zero(), 0.002, 3);
    ASSERT_TRUE(weighted.has_value() && plain.has_value());
    const double error_mm = 1000 * weighted->translation.x();
    sq_weighted += error_mm * error_mm;
    sq_plain += std::pow(1000 * plain->translation.x(), 2);
    beyond += std::abs(error_mm) > 2 * s.sigma_mm;
  }
  EXPECT_LT(sq_weighted, 0.8 * sq_plain);
  EXPECT_LT(beyond, trials / 10);
}

}  // namespace
}  // namespace arpos
