#pragma once
/// Signal processing for calibration: zero-phase Butterworth low-pass,
/// derivatives, normalised RMS, linear least squares with standard errors,
/// an amplitude spectrum, binning statistics and a block-resampled
/// comparison of two models' errors.
#include <cstddef>
#include <span>
#include <vector>

namespace twin::analysis {

/// One second-order section, direct form II transposed, a0 = 1.
struct Biquad {
  double b0{0.0}, b1{0.0}, b2{0.0}, a1{0.0}, a2{0.0};
};

/// 4th-order Butterworth low-pass (bilinear transform with prewarping) as
/// two sections. ConfigError unless 0 < fc_Hz < fs_Hz / 2.
std::vector<Biquad> butterworth_lowpass4(double fc_Hz, double fs_Hz);

/// Forward-backward (zero-phase) filtering with the sections. The ends are
/// extended by odd reflection and each pass starts in the steady state of its
/// first value, so a constant passes unchanged and ramps have no end transient.
std::vector<double> filtfilt(const std::vector<Biquad>& sos, std::span<const double> x);

/// filtfilt(butterworth_lowpass4(fc_Hz, fs_Hz), x).
std::vector<double> lowpass(std::span<const double> x, double fc_Hz, double fs_Hz);

/// Central differences (one-sided at the ends) of x sampled every dt_s.
std::vector<double> derivative(std::span<const double> x, double dt_s);

/// The five-point central difference (x[i-2] - 8 x[i-1] + 8 x[i+1] - x[i+2])
/// / (12 dt), exact through quartics; central differences at the two rows
/// of each end. Its gain at a frequency f is (8 sin w - sin 2w) / (6 w),
/// w = 2 pi f dt: 0.93 at a fifth of the sample rate, where the central
/// difference's sin(w) / w is 0.76.
std::vector<double> derivative_five_point(std::span<const double> x, double dt_s);

/// rms(a - b) / rms(a) over rows [from, to); 0 when both are zero, and
/// rms(a - b) when rms(a) is zero.
double nrms(std::span<const double> a, std::span<const double> b, std::size_t from, std::size_t to);
double rms(std::span<const double> a, std::size_t from, std::size_t to);

/// Linear least squares y ~ X theta over the rows listed in `rows`.
/// X is given column by column. Standard errors assume residuals that are
/// white over blocks of `correlation_length` samples (the filter makes
/// neighbouring residuals correlated): sigma^2 (X'X)^-1 scaled by it.
struct LsqResult {
  std::vector<double> theta;
  std::vector<double> stderr_theta;
  double residual_rms{0.0};
  std::size_t n{0};
  bool ok{false};  ///< false when the rows are too few or X is rank deficient
};
LsqResult least_squares(const std::vector<const std::vector<double>*>& columns, const std::vector<double>& y,
                        const std::vector<std::size_t>& rows, double correlation_length = 1.0);

/// Friction that grows with the torque, as a column: `load` = |T^| dir on
/// each row where dir (+1, -1, 0 at rest) is not 0, T^ the fit of y on
/// `columns` over `rows` (from the second pass on with `load` itself, times
/// its coefficient), refitted `passes` times. Returns the last fit of y on
/// the columns and `load` (its last coefficient the share), or the first
/// failed one.
LsqResult fit_with_own_torque_load(const std::vector<const std::vector<double>*>& columns,
                                   const std::vector<double>& y, const std::vector<std::size_t>& rows,
                                   const std::vector<double>& dir, double correlation_length, int passes,
                                   std::vector<double>& load);

/// Amplitude spectrum of x (mean removed, Hann window) at bins k fs / N for a
/// power-of-two N = largest power of two <= x.size(): returns |X_k| for
/// k = 0..N/2 and sets df_Hz.
std::vector<double> amplitude_spectrum(std::span<const double> x, double fs_Hz, double* df_Hz);

/// Mean of y over bins of x: edges of `num_bins` equal bins over [lo, hi];
/// rows listed in `rows`. Empty bins have count 0 and mean 0.
struct Bins {
  double lo{0.0}, hi{0.0};
  std::vector<double> mean;
  std::vector<std::size_t> count;
};
Bins bin_means(const std::vector<double>& x, const std::vector<double>& y, const std::vector<std::size_t>& rows,
               double lo, double hi, std::size_t num_bins);

/// Two models compared on the same rows: NRMS(a) - NRMS(b), both normalised
/// by the measured signal, and its 90 % interval from resampling blocks of
/// consecutive rows with replacement (the 5th and 95th percentiles of the
/// difference over `resamples` draws, a fixed seed: the same rows give the
/// same interval). Blocks are taken so that a row's error and its
/// neighbours' (correlated over the drive's and the logger's time constants)
/// stay together; the interval is then the scatter of the rows themselves,
/// not of an assumed independent noise.
struct PairedDifference {
  double difference{0.0};      ///< NRMS(a) - NRMS(b) on all rows
  double lo{0.0}, hi{0.0};     ///< its 90 % interval
  std::size_t blocks{0};       ///< blocks resampled
  /// The block where a's squared error exceeds b's by the most: a's largest
  /// loss to b, which on a short log can decide the comparison alone (one
  /// stop whose braking a 10 Hz sample caught). Its first row and its rows
  /// (0 where a is at least as good as b on every block), and
  /// NRMS(a) - NRMS(b) on all rows but that block.
  std::size_t largest_loss_first_row{0}, largest_loss_rows{0};
  double difference_without_largest_loss{0.0};
};
/// `meas`, `a`, `b`: one value per row, in order; `block_rows`: rows per
/// block (the last block may be shorter). Throws ConfigError where the rows
/// are fewer than two blocks or the measured signal is zero.
PairedDifference paired_nrms_difference(std::span<const double> meas, std::span<const double> a,
                                        std::span<const double> b, std::size_t block_rows,
                                        std::size_t resamples = 2000);

}  // namespace twin::analysis
