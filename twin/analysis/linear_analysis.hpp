#pragma once
/// Linear analysis of one axis' position loop at the loop period Ts.
///
/// Plant, friction and saturation out (Ozcan 2017 Fig. 1):
///   J dw/dt = Ka Kt u - B w,   dx/dt = rg w        (w rad/s, x mm, u V)
/// discretised exactly under the zero-order hold with the matrix exponential:
///   p[k+1] = Phi p[k] + Gamma u[k],  p = [w, x],  y[k] = x[k] (encoder as unity).
/// Controller: the FADAL law of spec/measured-data.md with its backward differences,
///   C(z) = Kp + Ki Ts z/(z-1) + Kd (z-1)/(Ts z)          (feedback, e -> u)
///   F(z) = K2 (1 - z^-1)/Ts + K1 ((1 - z^-1)/Ts)^2       (feedforward, x_ref -> u)
/// Loop broken at u: L(z) = C(z) P(z), P(z) = [0 1] (zI - Phi)^-1 Gamma.
///   S = 1/(1+L) (sensitivity), T = L/(1+L) (feedback position response),
///   X/R = (C + F) P / (1 + L) (position response with feedforward),
///   E/R = (1 - F P) / (1 + L) (tracking error transfer function).
/// Frequencies are reported in Hz; margins follow the usual definitions:
/// gain margin = 1/|L| at the phase crossovers below the unit circle (upward gain
/// margin), phase margin = 180 deg + arg L at the gain crossovers (the smallest).
#include <complex>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "controller/position_loop.hpp"
#include "feeddrive/drive_params.hpp"

namespace twin::analysis {

/// The linearised drive: only the terms that survive linearisation.
struct LinearPlant {
  double Ka_A_per_V{0.0};
  double Kt_Nm_per_A{0.0};
  double J_kg_m2{0.0};
  double B_kg_m2_per_s{0.0};
  double rg_mm_per_rad{0.0};
  /// Throws ConfigError naming `where` and the field when a value is not finite or not physical.
  void validate(const std::string& where) const;
};
LinearPlant linear_plant(const feeddrive::DriveParams& drive);

/// The model-based feedforward gains that cancel the linear plant:
/// K1 = J / (Ka Kt rg) [V s^2/mm], K2 = B / (Ka Kt rg) [V s/mm].
struct FeedforwardGains {
  double K1_V_s2_per_mm{0.0};
  double K2_V_s_per_mm{0.0};
};
FeedforwardGains model_feedforward(const LinearPlant& plant);

/// Matrix exponential exp(M) by scaling and squaring of a Taylor series
/// (for the small, well-scaled matrices of a drive over one period).
Eigen::MatrixXd matrix_exponential(const Eigen::MatrixXd& M);

/// The discrete closed loop of one axis.
class DiscreteLoopModel {
 public:
  /// Throws ConfigError for a non-physical plant or gains (`where` names the axis).
  DiscreteLoopModel(const LinearPlant& plant, const controller::PositionLoopParams& gains,
                    const std::string& where = "axis");

  const Eigen::Matrix2d& Phi() const noexcept { return Phi_; }
  const Eigen::Vector2d& Gamma() const noexcept { return Gamma_; }
  /// Closed-loop feedback matrix, state [w, x, I[k-1], e[k-1]], reference input
  /// x_ref held at 0: s[k+1] = A_fb s[k].
  const Eigen::Matrix4d& A_feedback() const noexcept { return A_fb_; }
  /// Poles of the feedback loop: the eigenvalues of A_feedback (the feedforward
  /// only adds poles at z = 0); with Ki = 0 the disconnected integrator state is left out.
  std::vector<std::complex<double>> poles() const;
  bool stable() const;

  std::complex<double> plant_response(double f_Hz) const;       ///< P: mm/V
  std::complex<double> controller_response(double f_Hz) const;  ///< C: V/mm
  std::complex<double> feedforward_response(double f_Hz) const; ///< F: V/mm
  std::complex<double> loop_response(double f_Hz) const;        ///< L = C P
  std::complex<double> sensitivity(double f_Hz) const;          ///< S = 1/(1+L)
  std::complex<double> complementary(double f_Hz) const;        ///< T = L/(1+L)
  std::complex<double> position_response(double f_Hz) const;    ///< X/R with feedforward
  std::complex<double> error_response(double f_Hz) const;       ///< E/R with feedforward

  /// Response of the closed loop (friction and saturation out) to a reference
  /// sequence x_ref[k], k = 0..n-1, starting at rest at x = x_ref[0] = 0 with the
  /// law's start-up convention (v_ref, a_ref 0 at k = 0, e[-1] = e[0]).
  /// Returns x[k] (the measured position at tick k, before u[k] acts).
  std::vector<double> simulate(const std::vector<double>& x_ref_mm) const;

  double Ts_s() const noexcept { return Ts_s_; }
  double nyquist_Hz() const noexcept { return 0.5 / Ts_s_; }
  const controller::PositionLoopParams& gains() const noexcept { return gains_; }
  const LinearPlant& plant() const noexcept { return plant_; }

 private:
  std::complex<double> z_of(double f_Hz) const;
  LinearPlant plant_;
  controller::PositionLoopParams gains_;
  double Ts_s_;
  Eigen::Matrix2d Phi_;
  Eigen::Vector2d Gamma_;
  Eigen::Matrix4d A_fb_;
};

/// One point of a frequency response, for plots and reports.
struct FrequencyPoint {
  double f_Hz{0.0};
  std::complex<double> L, S, T, X_over_R, E_over_R;
};

/// What the analysis reports for one axis and one set of gains.
struct LoopAnalysis {
  bool stable{false};
  std::vector<std::complex<double>> poles;
  double max_pole_magnitude{0.0};
  /// Smallest upward gain margin (dB); +inf when the phase never crosses -180 deg below |L| = 1.
  double gain_margin_dB{0.0};
  double phase_crossover_Hz{0.0};   ///< where the gain margin is read (0 when none)
  /// Smallest phase margin (deg) over the gain crossovers; +inf when |L| never crosses 1.
  double phase_margin_deg{0.0};
  double gain_crossover_Hz{0.0};
  double sensitivity_peak{0.0};     ///< Ms = max |S| (absolute)
  double sensitivity_peak_Hz{0.0};
  double sensitivity_peak_dB{0.0};
  double complementary_peak{0.0};   ///< Mt = max |T|
  /// -3 dB bandwidth of the feedback position loop T (first frequency with |T| < 1/sqrt 2), Hz;
  /// the Nyquist frequency when |T| never drops that far.
  double bandwidth_Hz{0.0};
  /// The same for the position response with feedforward X/R.
  double bandwidth_with_feedforward_Hz{0.0};
  /// Step response of the feedback loop (feedforward off): peak overshoot as a
  /// fraction of the step, and the 2 % settling time.
  double step_overshoot{0.0};
  double step_settling_time_s{0.0};
  /// |E/R| at 1 Hz and 10 Hz: the tracking error per unit of reference at those frequencies.
  double error_gain_1Hz{0.0};
  double error_gain_10Hz{0.0};
};

/// Runs the analysis. The frequency grid is logarithmic from f_min_Hz to Nyquist
/// with `points` points; crossovers and peaks are refined by bisection / golden search.
LoopAnalysis analyse_loop(const DiscreteLoopModel& model, double f_min_Hz = 0.01, int points = 4000);

/// A log-spaced frequency response (for Bode plots and reports).
std::vector<FrequencyPoint> frequency_response(const DiscreteLoopModel& model, double f_min_Hz, int points);

/// A one-line-per-item text of the analysis, for `twin tune --analyse`.
std::string format_analysis(const std::string& title, const controller::PositionLoopParams& gains,
                            const LoopAnalysis& a);

}  // namespace twin::analysis
