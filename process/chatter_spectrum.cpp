#include "process/chatter_spectrum.hpp"

#include <algorithm>
#include <cmath>
#include <complex>
#include <numbers>

#include <unsupported/Eigen/FFT>

namespace twin::process {

ChatterSpectrum chatter_spectrum(const std::vector<std::array<double, 2>>& F, std::size_t b, std::size_t e, double Ts,
                                 double tooth_Hz, double f_lo, double f_hi) {
  constexpr double kPi = std::numbers::pi;
  ChatterSpectrum s;
  if (e <= b + 1 || !(tooth_Hz > 0.0)) return s;
  const std::size_t n = e - b;
  const double L = static_cast<double>(n) * Ts;
  std::vector<double> w(n);
  for (std::size_t i = 0; i < n; ++i) w[i] = 0.5 - 0.5 * std::cos(2.0 * kPi * static_cast<double>(i) / n);
  const auto power = [&](double f) {
    double p = 0.0;
    const std::complex<double> step = std::polar(1.0, -2.0 * kPi * f * Ts);
    for (std::size_t c = 0; c < 2; ++c) {
      std::complex<double> X{};
      std::complex<double> rot{1.0, 0.0};
      for (std::size_t i = 0; i < n; ++i, rot *= step) X += w[i] * F[b + i][c] * rot;
      p += std::norm(X);
    }
    return p;
  };
  double harmonic = 0.0;
  for (int k = 0; k * tooth_Hz < 0.5 / Ts; ++k) harmonic = std::max(harmonic, power(k * tooth_Hz));
  // The non-harmonic lines on the 1/L grid: the FFT's bins of the windowed signal.
  Eigen::FFT<double> fft;
  std::vector<std::complex<double>> X[2];
  for (std::size_t c = 0; c < 2; ++c) {
    std::vector<double> x(n);
    for (std::size_t i = 0; i < n; ++i) x[i] = w[i] * F[b + i][c];
    fft.fwd(X[c], x);
  }
  double best = 0.0;
  const auto m_hi = static_cast<std::size_t>(std::floor(std::min(f_hi, 0.5 / Ts) * L));
  for (auto m = static_cast<std::size_t>(std::ceil(f_lo * L)); m <= m_hi && m < n; ++m) {
    const double f = static_cast<double>(m) / L;
    const double k = std::round(f / tooth_Hz);
    if (std::abs(f - k * tooth_Hz) <= 3.0 / L) continue;
    const double p = std::norm(X[0][m]) + std::norm(X[1][m]);
    if (p > best) best = p, s.chatter_Hz = f;
  }
  s.ratio = harmonic > 0.0 ? std::sqrt(best / harmonic) : 0.0;
  return s;
}

}  // namespace twin::process
