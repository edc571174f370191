#include "twin/calibrate/signal.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <complex>
#include <numbers>
#include <optional>
#include <random>

#include <Eigen/Dense>
#include <fmt/format.h>

#include "twin/core/error.hpp"
#include "twin/report/fft.hpp"

namespace twin::analysis {
namespace {

// One pass of the sections over x, each section started in the steady state
// of x[0] (DC gain of every section is 1).
void run_pass(const std::vector<Biquad>& sos, std::vector<double>& x) {
  if (x.empty()) return;
  for (const Biquad& s : sos) {
    const double x0 = x.front();
    double z1 = (1.0 - s.b0) * x0;
    double z2 = (s.b2 - s.a2) * x0;
    for (double& v : x) {
      const double in = v;
      const double out = s.b0 * in + z1;
      z1 = s.b1 * in - s.a1 * out + z2;
      z2 = s.b2 * in - s.a2 * out;
      v = out;
    }
  }
}

}  // namespace

std::vector<Biquad> butterworth_lowpass4(double fc_Hz, double fs_Hz) {
  if (!(fc_Hz > 0.0) || !(fs_Hz > 0.0) || !(fc_Hz < 0.5 * fs_Hz))
    throw ConfigError(fmt::format("butterworth_lowpass4: cutoff {} Hz must lie in (0, {} Hz) for sampling at {} Hz",
                                  fc_Hz, 0.5 * fs_Hz, fs_Hz));
  const double K = std::tan(std::numbers::pi * fc_Hz / fs_Hz);
  std::vector<Biquad> sos;
  // Pole pairs of the 4th-order prototype at pi/8 and 3 pi/8 from the negative real axis.
  for (double phi : {std::numbers::pi / 8.0, 3.0 * std::numbers::pi / 8.0}) {
    const double Q = 1.0 / (2.0 * std::cos(phi));
    const double norm = 1.0 / (1.0 + K / Q + K * K);
    Biquad b;
    b.b0 = K * K * norm;
    b.b1 = 2.0 * b.b0;
    b.b2 = b.b0;
    b.a1 = 2.0 * (K * K - 1.0) * norm;
    b.a2 = (1.0 - K / Q + K * K) * norm;
    sos.push_back(b);
  }
  return sos;
}

std::vector<double> filtfilt(const std::vector<Biquad>& sos, std::span<const double> x) {
  const std::size_t n = x.size();
  if (n == 0) return {};
  if (n == 1) return {x[0]};
  const std::size_t pad = std::min<std::size_t>(n - 1, 6000);
  std::vector<double> ext;
  ext.reserve(n + 2 * pad);
  for (std::size_t i = pad; i >= 1; --i) ext.push_back(2.0 * x[0] - x[i]);
  ext.insert(ext.end(), x.begin(), x.end());
  for (std::size_t i = 1; i <= pad; ++i) ext.push_back(2.0 * x[n - 1] - x[n - 1 - i]);
  run_pass(sos, ext);
  std::reverse(ext.begin(), ext.end());
  run_pass(sos, ext);
  std::reverse(ext.begin(), ext.end());
  return std::vector<double>(ext.begin() + static_cast<std::ptrdiff_t>(pad),
                             ext.begin() + static_cast<std::ptrdiff_t>(pad + n));
}

std::vector<double> lowpass(std::span<const double> x, double fc_Hz, double fs_Hz) {
  return filtfilt(butterworth_lowpass4(fc_Hz, fs_Hz), x);
}

std::vector<double> derivative(std::span<const double> x, double dt_s) {
  const std::size_t n = x.size();
  std::vector<double> d(n, 0.0);
  if (n < 2) return d;
  d[0] = (x[1] - x[0]) / dt_s;
  d[n - 1] = (x[n - 1] - x[n - 2]) / dt_s;
  for (std::size_t i = 1; i + 1 < n; ++i) d[i] = (x[i + 1] - x[i - 1]) / (2.0 * dt_s);
  return d;
}

std::vector<double> derivative_five_point(std::span<const double> x, double dt_s) {
  std::vector<double> d = derivative(x, dt_s);
  for (std::size_t i = 2; i + 2 < x.size(); ++i)
    d[i] = (x[i - 2] - 8.0 * x[i - 1] + 8.0 * x[i + 1] - x[i + 2]) / (12.0 * dt_s);
  return d;
}

double rms(std::span<const double> a, std::size_t from, std::size_t to) {
  to = std::min(to, a.size());
  if (from >= to) return 0.0;
  double s = 0.0;
  for (std::size_t i = from; i < to; ++i) s += a[i] * a[i];
  return std::sqrt(s / static_cast<double>(to - from));
}

double nrms(std::span<const double> a, std::span<const double> b, std::size_t from, std::size_t to) {
  to = std::min({to, a.size(), b.size()});
  if (from >= to) return 0.0;
  double se = 0.0, sa = 0.0;
  for (std::size_t i = from; i < to; ++i) {
    se += (a[i] - b[i]) * (a[i] - b[i]);
    sa += a[i] * a[i];
  }
  if (sa == 0.0) return std::sqrt(se / static_cast<double>(to - from));
  return std::sqrt(se / sa);
}

LsqResult least_squares(const std::vector<const std::vector<double>*>& columns, const std::vector<double>& y,
                        const std::vector<std::size_t>& rows, double correlation_length) {
  LsqResult r;
  const std::size_t p = columns.size();
  r.n = rows.size();
  if (p == 0 || rows.size() < 4 * p + 10) return r;
  // Normal equations with column scaling (the regressors differ by orders of magnitude).
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(p), static_cast<Eigen::Index>(p));
  Eigen::VectorXd b = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(p));
  std::vector<double> row(p);
  for (std::size_t k : rows) {
    for (std::size_t j = 0; j < p; ++j) row[j] = (*columns[j])[k];
    const double yk = y[k];
    for (std::size_t i = 0; i < p; ++i) {
      const auto ii = static_cast<Eigen::Index>(i);
      b(ii) += row[i] * yk;
      for (std::size_t j = i; j < p; ++j) A(ii, static_cast<Eigen::Index>(j)) += row[i] * row[j];
    }
  }
  for (Eigen::Index i = 0; i < A.rows(); ++i)
    for (Eigen::Index j = 0; j < i; ++j) A(i, j) = A(j, i);
  Eigen::VectorXd scale(A.rows());
  for (Eigen::Index i = 0; i < A.rows(); ++i) scale(i) = A(i, i) > 0.0 ? 1.0 / std::sqrt(A(i, i)) : 0.0;
  for (Eigen::Index i = 0; i < A.rows(); ++i)
    if (scale(i) == 0.0) return r;
  const Eigen::MatrixXd As = scale.asDiagonal() * A * scale.asDiagonal();
  const Eigen::VectorXd bs = scale.asDiagonal() * b;
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(As);
  const double ev_min = eig.eigenvalues().minCoeff();
  const double ev_max = eig.eigenvalues().maxCoeff();
  if (!(ev_min > 1e-10 * ev_max)) return r;
  const Eigen::MatrixXd As_inv = eig.eigenvectors() * eig.eigenvalues().cwiseInverse().asDiagonal() *
                                 eig.eigenvectors().transpose();
  const Eigen::VectorXd ts = As_inv * bs;
  const Eigen::VectorXd theta = scale.asDiagonal() * ts;
  double sse = 0.0;
  for (std::size_t k : rows) {
    double pred = 0.0;
    for (std::size_t j = 0; j < p; ++j) pred += (*columns[j])[k] * theta(static_cast<Eigen::Index>(j));
    sse += (y[k] - pred) * (y[k] - pred);
  }
  const double dof = static_cast<double>(rows.size() - p);
  const double sigma2 = sse / dof * std::max(1.0, correlation_length);
  r.theta.resize(p);
  r.stderr_theta.resize(p);
  for (std::size_t j = 0; j < p; ++j) {
    const auto jj = static_cast<Eigen::Index>(j);
    r.theta[j] = theta(jj);
    r.stderr_theta[j] = std::sqrt(sigma2 * As_inv(jj, jj)) * scale(jj);
  }
  r.residual_rms = std::sqrt(sse / static_cast<double>(rows.size()));
  r.ok = std::all_of(r.theta.begin(), r.theta.end(), [](double v) { return std::isfinite(v); });
  return r;
}

LsqResult fit_with_own_torque_load(const std::vector<const std::vector<double>*>& columns,
                                   const std::vector<double>& y, const std::vector<std::size_t>& rows,
                                   const std::vector<double>& dir, double correlation_length, int passes,
                                   std::vector<double>& load) {
  load.assign(y.size(), 0.0);
  LsqResult fit = least_squares(columns, y, rows, correlation_length);
  if (!fit.ok) return fit;
  std::vector<const std::vector<double>*> with = columns;
  with.push_back(&load);
  double share = 0.0;
  for (int pass = 0; pass < passes; ++pass) {
    for (std::size_t k = 0; k < y.size(); ++k) {
      if (dir[k] == 0.0) continue;
      double T_hat = share * load[k];
      for (std::size_t j = 0; j < columns.size(); ++j) T_hat += (*columns[j])[k] * fit.theta[j];
      load[k] = std::abs(T_hat) * dir[k];
    }
    fit = least_squares(with, y, rows, correlation_length);
    if (!fit.ok) return fit;
    share = fit.theta[columns.size()];
  }
  return fit;
}

std::vector<double> amplitude_spectrum(std::span<const double> x, double fs_Hz, double* df_Hz) {
  std::size_t n = 1;
  while (2 * n <= x.size()) n *= 2;
  if (x.size() < 8) {
    if (df_Hz) *df_Hz = 0.0;
    return {};
  }
  double mean = 0.0;
  for (std::size_t i = 0; i < n; ++i) mean += x[i];
  mean /= static_cast<double>(n);
  std::vector<std::complex<double>> a(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double w = 0.5 - 0.5 * std::cos(2.0 * std::numbers::pi * static_cast<double>(i) / static_cast<double>(n));
    a[i] = {(x[i] - mean) * w, 0.0};
  }
  fft_in_place(a);
  std::vector<double> mag(n / 2 + 1);
  // Hann window coherent gain 0.5: a sine of amplitude A reads A.
  for (std::size_t k = 0; k <= n / 2; ++k) mag[k] = std::abs(a[k]) * 4.0 / static_cast<double>(n);
  if (df_Hz) *df_Hz = fs_Hz / static_cast<double>(n);
  return mag;
}

Bins bin_means(const std::vector<double>& x, const std::vector<double>& y, const std::vector<std::size_t>& rows,
               double lo, double hi, std::size_t num_bins) {
  Bins b;
  b.lo = lo;
  b.hi = hi;
  b.mean.assign(num_bins, 0.0);
  b.count.assign(num_bins, 0);
  if (num_bins == 0 || !(hi > lo)) return b;
  const double w = (hi - lo) / static_cast<double>(num_bins);
  for (std::size_t k : rows) {
    const double v = (x[k] - lo) / w;
    if (!(v >= 0.0)) continue;
    const auto i = std::min(num_bins - 1, static_cast<std::size_t>(v));
    b.mean[i] += y[k];
    ++b.count[i];
  }
  for (std::size_t i = 0; i < num_bins; ++i)
    if (b.count[i] > 0) b.mean[i] /= static_cast<double>(b.count[i]);
  return b;
}

PairedDifference paired_nrms_difference(std::span<const double> meas, std::span<const double> a,
                                        std::span<const double> b, std::size_t block_rows, std::size_t resamples) {
  const std::size_t n = meas.size();
  if (a.size() != n || b.size() != n)
    throw ConfigError(fmt::format("paired comparison: {} measured rows against {} and {} modelled", n, a.size(),
                                  b.size()));
  if (block_rows == 0 || n < 2 * block_rows)
    throw ConfigError(fmt::format("paired comparison: {} rows are fewer than two blocks of {}", n, block_rows));
  // Per block: the sums of meas^2, (meas - a)^2, (meas - b)^2.
  std::vector<std::array<double, 3>> sums;
  for (std::size_t k = 0; k < n; k += block_rows) {
    std::array<double, 3> s{0.0, 0.0, 0.0};
    for (std::size_t j = k; j < std::min(n, k + block_rows); ++j) {
      s[0] += meas[j] * meas[j];
      s[1] += (meas[j] - a[j]) * (meas[j] - a[j]);
      s[2] += (meas[j] - b[j]) * (meas[j] - b[j]);
    }
    sums.push_back(s);
  }
  const auto difference = [](const std::array<double, 3>& t) {
    return t[0] > 0.0 ? std::sqrt(t[1] / t[0]) - std::sqrt(t[2] / t[0]) : 0.0;
  };
  std::array<double, 3> all{0.0, 0.0, 0.0};
  for (const auto& s : sums)
    for (int c = 0; c < 3; ++c) all[c] += s[c];
  if (!(all[0] > 0.0)) throw ConfigError("paired comparison: the measured signal is zero on the rows compared");
  PairedDifference out;
  out.difference = difference(all);
  out.blocks = sums.size();
  std::optional<std::size_t> worst;
  for (std::size_t i = 0; i < sums.size(); ++i)
    if (const double excess = sums[i][1] - sums[i][2];
        excess > 0.0 && (!worst || excess > sums[*worst][1] - sums[*worst][2]))
      worst = i;
  if (worst) {
    out.largest_loss_first_row = *worst * block_rows;
    out.largest_loss_rows = std::min(n, out.largest_loss_first_row + block_rows) - out.largest_loss_first_row;
    std::array<double, 3> rest = all;
    for (int c = 0; c < 3; ++c) rest[c] -= sums[*worst][c];
    out.difference_without_largest_loss = difference(rest);
  }
  std::mt19937_64 gen(20261127);
  std::uniform_int_distribution<std::size_t> pick(0, sums.size() - 1);
  std::vector<double> d(std::max<std::size_t>(resamples, 1));
  for (double& x : d) {
    std::array<double, 3> t{0.0, 0.0, 0.0};
    for (std::size_t i = 0; i < sums.size(); ++i) {
      const auto& s = sums[pick(gen)];
      for (int c = 0; c < 3; ++c) t[c] += s[c];
    }
    x = difference(t);
  }
  std::sort(d.begin(), d.end());
  const auto at = [&](double q) { return d[static_cast<std::size_t>(q * static_cast<double>(d.size() - 1) + 0.5)]; };
  out.lo = at(0.05);
  out.hi = at(0.95);
  return out;
}

}  // namespace twin::analysis
