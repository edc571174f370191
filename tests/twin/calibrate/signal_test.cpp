// Signal processing of calibration against closed forms.
#include <cmath>
#include <numbers>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "twin/calibrate/diagnose.hpp"
#include "twin/calibrate/identify.hpp"
#include "twin/calibrate/signal.hpp"
#include "twin/core/error.hpp"

namespace twin::analysis {
namespace {

constexpr double kPi = std::numbers::pi;

std::vector<double> sine(double f_Hz, double fs_Hz, std::size_t n, double phase = 0.0) {
  std::vector<double> x(n);
  for (std::size_t k = 0; k < n; ++k) x[k] = std::sin(2 * kPi * f_Hz * static_cast<double>(k) / fs_Hz + phase);
  return x;
}

// Forward-backward filtering squares the magnitude of the bilinear Butterworth:
// |H(f)|^2 = 1 / (1 + (tan(pi f / fs) / tan(pi fc / fs))^8), and adds no phase.
// Measured on the middle of a long sine (ends excluded), so the tolerance is
// the leakage of a finite record: 1e-3 of the amplitude.
TEST(Signal, FiltfiltMagnitudeIsSquaredButterworthAndPhaseIsZero) {
  const double fs = 10000.0, fc = 200.0;
  for (double f : {20.0, 100.0, 200.0, 300.0}) {
    const auto x = sine(f, fs, 40000, 0.3);
    const auto y = lowpass(x, fc, fs);
    const double r = std::tan(kPi * f / fs) / std::tan(kPi * fc / fs);
    const double g = 1.0 / (1.0 + std::pow(r, 8));
    double err = 0.0;
    for (std::size_t k = 10000; k < 30000; ++k) err = std::max(err, std::abs(y[k] - g * x[k]));
    EXPECT_LT(err, 1e-3) << "f = " << f;
  }
}

// A constant passes unchanged (steady-state start) and a ramp too (odd
// reflection at the ends): exact up to rounding.
TEST(Signal, ConstantAndRampPassWithoutEndTransients) {
  std::vector<double> c(5000, 3.5), ramp(5000);
  for (std::size_t k = 0; k < ramp.size(); ++k) ramp[k] = 0.01 * static_cast<double>(k);
  const auto yc = lowpass(c, 50.0, 10000.0);
  const auto yr = lowpass(ramp, 50.0, 10000.0);
  for (std::size_t k = 0; k < c.size(); ++k) {
    EXPECT_NEAR(yc[k], 3.5, 1e-9);
    EXPECT_NEAR(yr[k], ramp[k], 1e-6 * (1.0 + ramp[k]));
  }
}

TEST(Signal, CutoffOutsideNyquistIsAConfigError) {
  EXPECT_THROW(butterworth_lowpass4(600.0, 1000.0), ConfigError);
  EXPECT_THROW(butterworth_lowpass4(0.0, 1000.0), ConfigError);
}

// Central differences of a quadratic are exact inside.
TEST(Signal, DerivativeOfQuadraticIsExact) {
  std::vector<double> x(100);
  const double dt = 0.01;
  for (std::size_t k = 0; k < x.size(); ++k) x[k] = 2.0 * std::pow(static_cast<double>(k) * dt, 2);
  const auto d = derivative(x, dt);
  for (std::size_t k = 1; k + 1 < x.size(); ++k) EXPECT_NEAR(d[k], 4.0 * static_cast<double>(k) * dt, 1e-9);
}

// The five-point difference is exact on a quartic inside (its truncation
// error is dt^4 x^(5) / 30), and on a sine its gain is the closed form
// (8 sin w - sin 2w) / (6 w), w = 2 pi f dt, with no phase: 0.93 at a fifth
// of the sample rate. Tolerances: rounding of a 1e2-sized polynomial, and the
// double-precision sine.
TEST(Signal, FivePointDerivativeIsExactOnAQuarticAndHasItsClosedFormGain) {
  const double dt = 0.01;
  std::vector<double> x(60);
  for (std::size_t k = 0; k < x.size(); ++k) {
    const double t = static_cast<double>(k) * dt;
    x[k] = 3.0 * std::pow(t, 4) - t * t + 0.5 * t;
  }
  const auto d = derivative_five_point(x, dt);
  for (std::size_t k = 2; k + 2 < x.size(); ++k) {
    const double t = static_cast<double>(k) * dt;
    EXPECT_NEAR(d[k], 12.0 * std::pow(t, 3) - 2.0 * t + 0.5, 1e-9) << k;
  }
  const double fs = 1.0 / dt;
  for (double f : {5.0, 20.0, 40.0}) {
    const auto s = sine(f, fs, 200);
    const auto ds = derivative_five_point(s, dt);
    const double w = 2 * kPi * f * dt;
    const double g = (8.0 * std::sin(w) - std::sin(2.0 * w)) / (6.0 * w);
    for (std::size_t k = 2; k + 2 < s.size(); ++k)
      EXPECT_NEAR(ds[k], g * 2 * kPi * f * std::cos(2 * kPi * f * static_cast<double>(k) * dt), 1e-9 * 2 * kPi * f)
          << f << " Hz, row " << k;
  }
  const double w5 = 2 * kPi / 5.0;
  EXPECT_NEAR((8.0 * std::sin(w5) - std::sin(2.0 * w5)) / (6.0 * w5), 0.93, 0.005);
}

// y = 2 a - 0.5 b + 0.1 + noise (sigma 0.01): the estimate must lie within
// 4 of its own standard errors and the standard errors must match the
// textbook sigma / sqrt(n var) within 20 %.
TEST(Signal, LeastSquaresRecoversLinearModelWithHonestErrors) {
  std::mt19937 rng(7);
  std::normal_distribution<double> n01(0.0, 1.0);
  const std::size_t n = 20000;
  std::vector<double> a(n), b(n), one(n, 1.0), y(n);
  std::vector<std::size_t> rows(n);
  for (std::size_t k = 0; k < n; ++k) {
    a[k] = n01(rng);
    b[k] = n01(rng);
    y[k] = 2.0 * a[k] - 0.5 * b[k] + 0.1 + 0.01 * n01(rng);
    rows[k] = k;
  }
  const auto r = least_squares({&a, &b, &one}, y, rows);
  ASSERT_TRUE(r.ok);
  EXPECT_NEAR(r.theta[0], 2.0, 4 * r.stderr_theta[0]);
  EXPECT_NEAR(r.theta[1], -0.5, 4 * r.stderr_theta[1]);
  EXPECT_NEAR(r.theta[2], 0.1, 4 * r.stderr_theta[2]);
  EXPECT_NEAR(r.stderr_theta[0], 0.01 / std::sqrt(static_cast<double>(n)), 0.2 * 0.01 / std::sqrt(static_cast<double>(n)));
  EXPECT_NEAR(r.residual_rms, 0.01, 0.001);
}

TEST(Signal, LeastSquaresReportsRankDeficiency) {
  std::vector<double> a(100), b(100), y(100);
  std::vector<std::size_t> rows(100);
  for (std::size_t k = 0; k < 100; ++k) {
    a[k] = static_cast<double>(k);
    b[k] = 2.0 * a[k];
    y[k] = a[k];
    rows[k] = k;
  }
  EXPECT_FALSE(least_squares({&a, &b}, y, rows).ok);
}

// A sine on a bin reads its amplitude (Hann coherent gain corrected) at its bin.
TEST(Signal, SpectrumFindsSineAmplitudeAndFrequency) {
  const double fs = 1000.0;
  const std::size_t n = 4096;
  const double f = 125.0 * fs / static_cast<double>(n) * 4.0;  // on bin 500
  const auto x = sine(f, fs, n);
  double df = 0.0;
  const auto s = amplitude_spectrum(x, fs, &df);
  std::size_t kmax = 0;
  for (std::size_t k = 0; k < s.size(); ++k)
    if (s[k] > s[kmax]) kmax = k;
  EXPECT_NEAR(static_cast<double>(kmax) * df, f, df);
  EXPECT_NEAR(s[kmax], 1.0, 1e-6);
}

// NRMS as spec/interfaces.md defines it: rms(a - b) / rms(a).
TEST(Signal, NrmsMatchesDefinition) {
  const std::vector<double> a{1.0, -1.0, 1.0, -1.0}, b{0.5, -0.5, 0.5, -0.5};
  EXPECT_DOUBLE_EQ(nrms(a, b, 0, 4), 0.5);
  EXPECT_DOUBLE_EQ(nrms(a, a, 0, 4), 0.0);
}

// Bin means of y = x over [0, 1) in 4 bins are the bin centres.
// Oracle: a torque made exactly as T = A + f |T| dir (A = 3 a + 0.4 dir +
// 0.1, the friction growing with the torque), so T = A / (1 - f dir sgn A)
// row by row. Fitted on a, dir, 1 and the load column of the fit's own
// torque, the share is recovered: each pass moves the column towards |T|
// (noise-free: one pass, |A^| for |T|, leaves 3e-4 of f = 0.05, two 9e-5,
// three 7e-7), so three are held to 1e-5 and the acceleration's 3 to 1e-4.
// The rows at rest keep the column at 0.
TEST(Signal, OwnTorqueLoadRecoversTheShareOfAnExactTorque) {
  const std::size_t n = 4000;
  const double f = 0.05;
  std::vector<double> a(n), dir(n), one(n, 1.0), T(n);
  std::vector<std::size_t> rows(n);
  for (std::size_t k = 0; k < n; ++k) {
    rows[k] = k;
    a[k] = std::sin(0.013 * static_cast<double>(k)) * (1.0 + 0.5 * std::cos(0.0031 * static_cast<double>(k)));
    dir[k] = (k / 500) % 3 == 0 ? 0.0 : ((k / 500) % 3 == 1 ? 1.0 : -1.0);
    const double A = 3.0 * a[k] + 0.4 * dir[k] + 0.1;
    T[k] = dir[k] == 0.0 ? A : A / (1.0 - f * dir[k] * (A > 0.0 ? 1.0 : -1.0));
  }
  std::vector<double> load;
  const LsqResult fit = fit_with_own_torque_load({&a, &dir, &one}, T, rows, dir, 1.0, 3, load);
  ASSERT_TRUE(fit.ok);
  EXPECT_NEAR(fit.theta[3], f, 1e-5);
  EXPECT_NEAR(fit.theta[0], 3.0, 1e-4);
  for (std::size_t k = 0; k < n; ++k) {
    if (dir[k] == 0.0) {
      ASSERT_EQ(load[k], 0.0);
    }
  }
}

TEST(Signal, BinMeans) {
  std::vector<double> x, y;
  std::vector<std::size_t> rows;
  for (int k = 0; k < 400; ++k) {
    x.push_back((k + 0.5) / 400.0);
    y.push_back(x.back());
    rows.push_back(static_cast<std::size_t>(k));
  }
  const Bins b = bin_means(x, y, rows, 0.0, 1.0, 4);
  for (std::size_t i = 0; i < 4; ++i) {
    EXPECT_EQ(b.count[i], 100u);
    EXPECT_NEAR(b.mean[i], 0.125 + 0.25 * static_cast<double>(i), 1e-12);
  }
}

// window_spread against closed forms: a square wave of amplitude A about any
// offset has spread A in windows holding whole periods; a ramp of slope m over
// w samples has the spread of w equally spaced points, m sqrt((w^2 - 1) / 12);
// a constant has none; the last partial window is dropped. Exact up to rounding.
TEST(WindowSpread, ClosedForms) {
  std::vector<double> e;
  for (int k = 0; k < 45; ++k) e.push_back(3.0 + ((k / 5) % 2 == 0 ? 0.7 : -0.7));
  const auto sq = window_spread(e, 0, e.size(), 20);
  ASSERT_EQ(sq.size(), 2u);
  for (double v : sq) EXPECT_NEAR(v, 0.7, 1e-12);
  std::vector<double> ramp(30);
  for (std::size_t k = 0; k < ramp.size(); ++k) ramp[k] = 0.25 * static_cast<double>(k);
  const auto rs = window_spread(ramp, 5, 30, 10);
  ASSERT_EQ(rs.size(), 2u);
  EXPECT_NEAR(rs[0], 0.25 * std::sqrt((100.0 - 1.0) / 12.0), 1e-12);
  const auto cs = window_spread(std::vector<double>(16, 2.5), 0, 16, 8);
  ASSERT_EQ(cs.size(), 2u);
  EXPECT_NEAR(cs[1], 0.0, 1e-15);
  EXPECT_TRUE(window_spread(ramp, 0, 30, 0).empty());
}

// phase_locked_rows against the arithmetic of sampling a periodic count
// pattern. At a steady speed the loop's count increments per tick,
// floor(r k + phi) - floor(r (k - 1) + phi) with r = v Ts / resolution,
// repeat over L ticks where r = p / L; a log every M ticks sees their true
// mean r only where it visits all L phases, i.e. gcd(M, L) = 1. Checked:
// the rows flagged are exactly those whose sampled mean misses r (by at least
// 1/6 here, for every phase phi of the pattern) and the others hit it to
// rounding over a whole number of patterns.
TEST(PhaseLock, FlagsExactlyTheSpeedsWhoseSampledCountPatternIsBiased) {
  const double Ts = 1e-4, res = 1e-3;
  struct Case {
    double counts_per_tick;
    long M;
    bool locked;
  };
  for (const Case c : {Case{5.0 / 6.0, 10, true},    // 500 mm/min at 1 ms: 3 of 6 phases
                       Case{5.0 / 6.0, 100, true},   // ... at 10 ms
                       Case{5.0 / 6.0, 7, false},    // 7 and 6 coprime: all phases
                       Case{5.0 / 3.0, 10, false},   // 1000 mm/min at 1 ms
                       Case{1.0 / 4.0, 10, true},    // 2 of 4 phases
                       Case{0.3 + 1e-3, 10, false}}) // drifts through a count in 0.1 s
  {
    const double v = c.counts_per_tick * res / Ts;
    const auto flags = phase_locked_rows(std::vector<double>(50, v), c.M * Ts, Ts, res);
    for (char f : flags) ASSERT_EQ(f != 0, c.locked) << "r " << c.counts_per_tick << " M " << c.M;
    if (c.counts_per_tick > 1.0) continue;  // the increments below are for r < 1
    for (double phi : {0.0, 0.1, 0.45, 0.9}) {
      double sum = 0.0;
      const int n = 6000;  // samples: a whole number of patterns of up to 12 ticks
      for (int j = 1; j <= n; ++j) {
        const double k = static_cast<double>(j * c.M);
        sum += std::floor(c.counts_per_tick * k + phi) - std::floor(c.counts_per_tick * (k - 1) + phi);
      }
      const double bias = std::abs(sum / n - c.counts_per_tick);
      if (c.locked) {
        EXPECT_GT(bias, 1.0 / 6.0 - 1e-9) << "r " << c.counts_per_tick << " M " << c.M << " phi " << phi;
      } else if (c.counts_per_tick * 12 == std::round(c.counts_per_tick * 12)) {
        EXPECT_LT(bias, 1e-9);
      }
    }
  }
  // A log at the controller's rate, or no known resolution: nothing to flag.
  for (char f : phase_locked_rows(std::vector<double>(5, 8.333), Ts, Ts, res)) EXPECT_EQ(f, 0);
  for (char f : phase_locked_rows(std::vector<double>(5, 8.333), 10 * Ts, Ts, 0.0)) EXPECT_EQ(f, 0);
}

// The block-resampled comparison of two models, against closed forms:
// - a model that is the other: difference and interval exactly 0;
// - rows that repeat block by block (every block the same): every resample is
//   the whole, so the interval collapses onto the difference, which is the
//   closed form 0.5 - 1 for an error of half the signal against the zero
//   model;
// - two models with independent Gaussian errors of the same spread sigma on
//   n independent rows: the delta method gives the difference of their NRMS
//   a standard error of sigma / sqrt(n) (each NRMS's is sigma / sqrt(2 n) for
//   a unit signal), so the 90 % interval is +-1.645 sigma / sqrt(n) about a
//   difference near 0. Tolerance 20 % on its half width: the 5th and 95th
//   percentiles of 2000 draws scatter by about 5 %, and the delta method
//   drops terms of order sigma^2 / n.
TEST(Signal, PairedDifferenceOfTwoModelsAgainstClosedForms) {
  std::vector<double> meas, half, zero;
  for (int k = 0; k < 400; ++k) {
    meas.push_back(std::sin(2.0 * std::numbers::pi * (k % 20) / 20.0) + 0.3);
    half.push_back(0.5 * meas.back());
    zero.push_back(0.0);
  }
  const PairedDifference same = paired_nrms_difference(meas, half, half, 20);
  EXPECT_EQ(same.difference, 0.0);
  EXPECT_EQ(same.lo, 0.0);
  EXPECT_EQ(same.hi, 0.0);
  const PairedDifference periodic = paired_nrms_difference(meas, half, zero, 20);
  EXPECT_NEAR(periodic.difference, -0.5, 1e-12);
  EXPECT_NEAR(periodic.lo, -0.5, 1e-12);
  EXPECT_NEAR(periodic.hi, -0.5, 1e-12);
  EXPECT_EQ(periodic.blocks, 20u);

  std::mt19937_64 gen(7);
  std::normal_distribution<double> unit(0.0, 1.0);
  const double sigma = 0.3;
  const std::size_t n = 20000;
  std::vector<double> m(n), a(n), b(n);
  for (std::size_t k = 0; k < n; ++k) {
    m[k] = unit(gen);
    a[k] = m[k] + sigma * unit(gen);
    b[k] = m[k] + sigma * unit(gen);
  }
  const PairedDifference noise = paired_nrms_difference(m, a, b, 10);
  const double half_width = 1.645 * sigma / std::sqrt(static_cast<double>(n));
  EXPECT_NEAR(0.5 * (noise.hi - noise.lo), half_width, 0.2 * half_width);
  EXPECT_LT(noise.lo, noise.difference);
  EXPECT_GT(noise.hi, noise.difference);
  EXPECT_EQ(noise.blocks, n / 10);

  // Too few rows for two blocks, and a signal of zeros: said, not computed.
  EXPECT_THROW(paired_nrms_difference(std::vector<double>(15, 1.0), std::vector<double>(15, 0.0),
                                      std::vector<double>(15, 0.0), 10),
               ConfigError);
  EXPECT_THROW(paired_nrms_difference(zero, half, half, 20), ConfigError);
}

// The block where one model loses most to the other, against the sums by
// hand: a is off by 0.1 everywhere but in block 7 (rows 140 to 159), where
// it is off by 1; b by 0.2 everywhere. Block 7 is the only one where a loses,
// and without it a's NRMS is sqrt(380 * 0.01 / S) against b's
// sqrt(380 * 0.04 / S), S the measured signal's sum of squares on the other
// rows. Exact sums, so the tolerance is rounding. Where a wins on every
// block, no block is named.
TEST(Signal, PairedDifferenceNamesTheBlockWhereOneModelLosesMost) {
  std::vector<double> meas, a, b;
  double S = 0.0;
  for (std::size_t k = 0; k < 400; ++k) {
    meas.push_back(std::sin(2.0 * std::numbers::pi * static_cast<double>(k % 20) / 20.0) + 0.3);
    const bool loses = k >= 140 && k < 160;
    a.push_back(meas.back() + (loses ? 1.0 : 0.1));
    b.push_back(meas.back() + 0.2);
    if (!loses) S += meas.back() * meas.back();
  }
  const PairedDifference p = paired_nrms_difference(meas, a, b, 20);
  EXPECT_GT(p.difference, 0.0);
  EXPECT_EQ(p.largest_loss_first_row, 140u);
  EXPECT_EQ(p.largest_loss_rows, 20u);
  EXPECT_NEAR(p.difference_without_largest_loss, std::sqrt(380.0 * 0.01 / S) - std::sqrt(380.0 * 0.04 / S), 1e-12);
  EXPECT_LT(p.difference_without_largest_loss, 0.0);

  std::vector<double> better;
  for (double m : meas) better.push_back(m + 0.1);
  const PairedDifference none = paired_nrms_difference(meas, better, b, 20);
  EXPECT_EQ(none.largest_loss_rows, 0u);
}

}  // namespace
}  // namespace twin::analysis
