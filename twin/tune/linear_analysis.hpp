#pragma once
/// Linear analysis of one axis' position loop at the loop period Ts, for either
/// law of controller/position_loop.hpp.
///
/// Plant, friction and saturation out (Ozcan 2017 Fig. 1):
///   J dw/dt = g m - B w,   dx/dt = rg w        (w rad/s, x mm)
/// with m the law's command held over the tick: u in V for the FADAL law
/// (g = Ka Kt), the torque for the cascade (g = 1). Discretised exactly under the
/// zero-order hold with the matrix exponential:
///   p[k+1] = Phi p[k] + Gamma m[k],  p = [w, x],  y[k] = p[k] (encoder and speed sensor as unity).
/// A dead time on the command (the drive's `delay` effect, d whole drive steps) acts
/// as m[k - d]: the plant gains the d commands in flight as states, and its response
/// the factor z^-d. A compliant coupling (the `compliance` effect) splits J into the
/// motor's and the load's behind a spring K and damper C:
///   Jm dwm = g m - B wm - K (xm - xl)/rg - C (wm - wl),  Jl dwl = K (xm - xl)/rg + C (wm - wl);
/// the loop measures the motor's side, and X/R and E/R are of that measured position.
/// Controller: the law exactly as controller::PositionLoop computes it (backward
/// differences, the integrator updated before it acts, the cascade's current loop as
/// its first-order filter sampled at Ts), written by the law itself
/// (controller::Law::realise) as a discrete state-space system from [p, x_ref] to m.
/// A cascade whose velocity loop runs n > 1 times a period (Tv = Ts / n) is a
/// periodic system at Tv; it is analysed lifted to Ts (the product of its n ticks'
/// state maps, the plant discretised over Tv), which is exact at the position
/// loop's samples. Its torque command changes within the period, so the loop is
/// broken where it is held over the period instead: at the position feedback
/// (L = -X/D for a disturbance d added to the measured position, the velocity
/// loop closed); S, T and the margins are the position loop's, the poles those of
/// the whole loop.
/// Loop broken at the command m: L(z) = -K_p(z) P(z), P(z) = (zI - Phi)^-1 Gamma,
/// K_p the controller from p to m (for the FADAL law L = C P with
/// C(z) = Kp + Ki Ts z/(z-1) + Kd (z-1)/(Ts z); for the cascade the position and speed
/// feedback both pass through m, the torque command).
///   S = 1/(1+L) (sensitivity), T = L/(1+L) (complementary, at the break point),
///   X/R = P_x K_r / (1 + L) (position response, K_r the controller from x_ref to m),
///   E/R = 1 - X/R (tracking error transfer function).
/// Frequencies are reported in Hz; margins follow the usual definitions:
/// gain margin = 1/|L| at the phase crossovers below the unit circle (upward gain
/// margin), phase margin = 180 deg + arg L at the gain crossovers (the smallest).
#include <array>
#include <complex>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Dense>

#include "controller/law.hpp"
#include "controller/laws/fadal.hpp"
#include "feeddrive/drive_params.hpp"

namespace twin::analysis {

/// The linearised drive (controller/law.hpp) and the FADAL law's model feedforward.
using controller::LinearPlant;
using controller::laws::FeedforwardGains;
using controller::laws::model_feedforward;
LinearPlant linear_plant(const feeddrive::DriveParams& drive);

/// Matrix exponential exp(M) by scaling and squaring of a Taylor series
/// (for the small, well-scaled matrices of a drive over one period).
Eigen::MatrixXd matrix_exponential(const Eigen::MatrixXd& M);

/// A law's gains and its controller at Ts (controller/law.hpp).
using controller::ControllerRealisation;
using controller::LawGain;

/// One point of a frequency response, for plots and reports.
struct FrequencyPoint {
  double f_Hz{0.0};
  std::complex<double> L, S, T, X_over_R, E_over_R;
  std::complex<double> X_over_R_feedback;  ///< X/R with the feedforward off
};

/// The discrete closed loop of one axis.
class DiscreteLoopModel {
 public:
  /// Throws ConfigError for a non-physical plant, gains or period (`where` names the axis).
  DiscreteLoopModel(const LinearPlant& plant, const controller::PositionLoopParams& gains, double Ts_s,
                    const std::string& where = "axis");

  const controller::Law& law() const noexcept { return *law_; }
  /// The plant over one period Ts under a held command.
  const Eigen::Matrix2d& Phi() const noexcept { return Phi_; }
  /// Per unit of the law's command (mm/V, rad/s per V for the FADAL law).
  const Eigen::Vector2d& Gamma() const noexcept { return Gamma_; }
  const ControllerRealisation& controller() const noexcept { return K_; }
  /// The law's inner ticks per period (1: the command is held over Ts).
  int inner_ticks() const noexcept { return K_.inner_ticks; }
  /// The command's dead time in drive steps (Ts / inner_ticks()), as the drive rounds it.
  int delay_ticks() const noexcept { return delay_ticks_; }
  /// Closed-loop matrix with the reference held at 0, state [w, x (the motor's), the
  /// load's w and x behind a compliant coupling, the commands in flight where the
  /// drive has a dead time, loop states of the controller] (FADAL: I[k-1] when Ki > 0, e[k-1]; cascade: Iv[k-1] when Tn > 0,
  /// Tf[k-1] when tau_i > 0): s[k+1] = A_feedback s[k]; over a whole period where the
  /// law has inner ticks (the held velocity command, set anew at each period's first
  /// tick, left out).
  const Eigen::MatrixXd& A_feedback() const noexcept { return A_fb_; }
  /// Poles of the feedback loop: the eigenvalues of A_feedback (the feedforward
  /// only adds poles at z = 0), largest magnitude first.
  std::vector<std::complex<double>> poles() const;
  bool stable() const;

  FrequencyPoint at(double f_Hz) const;                          ///< all responses at f
  std::complex<double> plant_response(double f_Hz) const;       ///< P_x: mm per unit command
  std::complex<double> loop_response(double f_Hz) const;        ///< L
  std::complex<double> sensitivity(double f_Hz) const;          ///< S = 1/(1+L)
  std::complex<double> complementary(double f_Hz) const;        ///< T = L/(1+L)
  std::complex<double> position_response(double f_Hz) const;    ///< X/R with feedforward
  std::complex<double> feedback_position_response(double f_Hz) const;  ///< X/R, feedforward off
  std::complex<double> error_response(double f_Hz) const;       ///< E/R with feedforward
  /// A law with inner ticks: the velocity loop alone at Tv = Ts / inner_ticks(),
  /// broken at the torque command with the position loop open (the velocity command
  /// held at 0): L_v = -K_w(z) P_w(z) at z = exp(j 2 pi f Tv). NaN for a law without.
  std::complex<double> velocity_loop_response(double f_Hz) const;

  /// Response of the closed loop (friction and saturation out) to a reference
  /// sequence x_ref[k], k = 0..n-1, starting at rest at x = 0 with the law's
  /// start-up convention (v_ref, a_ref 0 at k = 0, e[-1] = e[0]).
  /// Returns x[k] (the measured position at tick k, before the command of tick k acts).
  std::vector<double> simulate(const std::vector<double>& x_ref_mm) const;

  double Ts_s() const noexcept { return Ts_s_; }
  double nyquist_Hz() const noexcept { return 0.5 / Ts_s_; }
  const controller::PositionLoopParams& gains() const noexcept { return gains_; }
  const LinearPlant& plant() const noexcept { return plant_; }

 private:
  struct Responses {
    std::complex<double> L, Px, X, X_fb;  ///< L, P_x, X/R and X/R with the feedforward off
  };
  /// A law with inner ticks, a dead time or a compliant coupling, over one period Ts, state
  /// [w, x, the load's, the commands in flight, c] (Phi, Gamma: the plant with them over one
  /// drive step): z[k+1] = A z[k] + Br x_ref[k] (closed), and, for a law with inner ticks
  /// (whose responses read them; empty at one tick), with the position feedback of the first
  /// tick cut, z[k+1] = A_open z[k] + Bd d[k] for d fed where the measured position was.
  struct Lifted {
    Eigen::MatrixXd A, A_open;
    Eigen::VectorXd Br, Bd;
  };
  static Lifted lift(const ControllerRealisation& K, const Eigen::MatrixXd& Phi, const Eigen::VectorXd& Gamma);
  Responses responses(double f_Hz) const;
  LinearPlant plant_;
  controller::PositionLoopParams gains_;
  const controller::Law* law_;
  double Ts_s_;
  Eigen::Matrix2d Phi_;
  Eigen::Vector2d Gamma_;
  ControllerRealisation K_, K_fb_;  ///< the law, and the law with its feedforward at 0
  bool same_states_{false};          ///< K_fb_.Ac == K_.Ac
  Lifted lifted_;                    ///< where the plant is stepped as Phi_a_ (else empty)
  Lifted lifted_fb_;                 ///< the law without feedforward, lifted: inner_ticks() > 1 only
  int delay_ticks_{0};
  /// The plant over one drive step with its load side and the commands in flight
  /// (empty for a rigid drive without a dead time at one tick a period).
  Eigen::MatrixXd Phi_a_;
  Eigen::VectorXd Gamma_a_;
  /// [P_w, P_x] of that plant at f (the motor's side: what the loop measures).
  std::array<std::complex<double>, 2> plant_step_response(double f_Hz) const;
  Eigen::MatrixXd A_fb_;
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
  /// -3 dB bandwidth of the position loop with the feedforward off (X/R of the feedback
  /// alone; for the FADAL law that is T): first frequency with |X/R| < 1/sqrt 2, Hz;
  /// the Nyquist frequency when it never drops that far.
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
  /// A velocity loop faster than the position loop: its own margins at Tv, broken at
  /// the torque command with the position loop open (the figures above are then the
  /// position loop's, broken at the position feedback).
  bool velocity_loop{false};
  double velocity_loop_phase_margin_deg{0.0};
  double velocity_loop_gain_crossover_Hz{0.0};
  double velocity_loop_gain_margin_dB{0.0};
  double velocity_loop_phase_crossover_Hz{0.0};
};

/// Runs the analysis. The frequency grid is logarithmic from f_min_Hz to Nyquist
/// with `points` points; crossovers and peaks are refined by bisection / golden search.
LoopAnalysis analyse_loop(const DiscreteLoopModel& model, double f_min_Hz = 0.01, int points = 4000);

/// A log-spaced frequency response (for Bode plots and reports).
std::vector<FrequencyPoint> frequency_response(const DiscreteLoopModel& model, double f_min_Hz, int points);

/// A one-line-per-item text of the analysis, for `twin tune --analyse`.
std::string format_analysis(const std::string& title, const DiscreteLoopModel& model, const LoopAnalysis& a);

}  // namespace twin::analysis
