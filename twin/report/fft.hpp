#pragma once
/// The discrete Fourier transform of the spectra the reports show (the
/// residual spectrum of a drive log, the force's spectrum of a cut).
#include <complex>
#include <cstddef>
#include <numbers>
#include <utility>
#include <vector>

namespace twin::analysis {

/// In-place iterative radix-2 FFT, X_k = sum_n x_n exp(-2 pi i k n / N);
/// x.size() must be a power of two.
inline void fft_in_place(std::vector<std::complex<double>>& x) {
  const std::size_t n = x.size();
  for (std::size_t i = 1, j = 0; i < n; ++i) {
    std::size_t bit = n >> 1;
    for (; j & bit; bit >>= 1) j ^= bit;
    j ^= bit;
    if (i < j) std::swap(x[i], x[j]);
  }
  for (std::size_t len = 2; len <= n; len <<= 1) {
    const double ang = -2.0 * std::numbers::pi / static_cast<double>(len);
    const std::complex<double> wl(std::cos(ang), std::sin(ang));
    for (std::size_t i = 0; i < n; i += len) {
      std::complex<double> w(1.0, 0.0);
      for (std::size_t k = 0; k < len / 2; ++k) {
        const auto u = x[i + k];
        const auto v = x[i + k + len / 2] * w;
        x[i + k] = u + v;
        x[i + k + len / 2] = u - v;
        w *= wl;
      }
    }
  }
}

}  // namespace twin::analysis
