#pragma once
/// Identification of a feed drive's declared parameters (J, B, Tc_pos,
/// Tc_neg) from a measured run by least squares on the inverse dynamics
/// (Erkorkmaz and Altintas): Tm = J dw/dt + B w + Tc_pos [w > 0] - Tc_neg [w < 0],
/// with w and dw/dt from the zero-phase low-passed measured position and Tm
/// from the equally low-passed current (Tm = Kt i) or, where no current is
/// logged, command (Tm = Kt Ka u).
#include <cstddef>
#include <string>
#include <vector>

#include "controller/position_loop.hpp"
#include "feeddrive/drive_params.hpp"
#include "twin/report/replay.hpp"

namespace twin::analysis {

/// The signals of one axis prepared for identification and diagnosis.
struct AxisSignals {
  Axis axis{Axis::kX};
  std::size_t n{0};            ///< rows
  std::size_t n_fit{0};        ///< rows [0, n_fit) are for fitting, the rest is held out
  double dt_s{0.0};
  double controller_period_s{0.0};  ///< the loop's period (u is held over it); dt_s when unknown
  double fc_Hz{0.0};           ///< low-pass cut-off used for the derivatives
  double rg_mm_per_rad{0.0};
  double torque_per_unit{0.0}; ///< N m per V of u (Kt Ka) or per A of current (Kt)
  bool torque_from_u{true};    ///< true only without a current column: Tm = Kt Ka u; else Tm = Kt i
  bool has_current{false};
  bool has_u{false};
  double encoder_resolution_mm{0.0};
  std::vector<double> x_ref_mm, x_mm;  ///< as measured
  std::vector<double> cmd_raw;         ///< u_V or i_A as measured (what torque is made of)
  std::vector<double> u_raw_V, i_raw_A;///< each empty when not measured
  std::vector<double> x_lp_mm;         ///< low-passed measured position
  std::vector<double> w_rad_per_s;     ///< motor speed from x_lp
  std::vector<double> a_rad_per_s2;    ///< motor acceleration
  std::vector<double> v_ref_mm_per_s;  ///< reference speed (backward differences, low-passed)
  std::vector<double> T_Nm;            ///< low-passed motor torque from the command or current
  double w_moving_rad_per_s{0.0};      ///< |w| above this counts as moving
  /// 1 where a log coarser than the loop samples the encoder-count chatter of
  /// a steady speed at only some of its phases (see phase_locked_rows); these
  /// rows are left out of every fit. Empty when no row is.
  std::vector<char> phase_locked;
};

/// Rows of a log sampled every `dt_s` (a whole multiple M > 1 of the loop's
/// period `Ts_s`) whose reference speed makes the loop's encoder-count
/// pattern periodic over L ticks (L up to 12: v Ts / resolution = p / L,
/// held for about half a second) with gcd(M, L) > 1: the samples then visit
/// only L / gcd(M, L) of the pattern's L phases, and the mean of the sampled
/// command or current is off by the chatter's uneven phases (several amperes
/// on the FADAL drives). Returns the flags and, in `pattern`, the speed, L
/// and phases visited of the most frequent such pattern.
std::vector<char> phase_locked_rows(const std::vector<double>& v_ref_mm_per_s, double dt_s, double Ts_s,
                                    double resolution_mm, std::string* pattern = nullptr);

/// Prepares the signals of `axis`; nullopt-like: returns n == 0 and a note
/// when the run lacks what identification needs (position, and u or current).
/// `controller_period_s` is the loop's period of the machine the run is
/// replayed on (the run's own where its meta gives it).
AxisSignals prepare_axis_signals(const MeasuredRun& run, Axis axis, const feeddrive::DriveParams& nominal,
                                 double encoder_resolution_mm, double controller_period_s, double fit_fraction,
                                 std::string* note);

struct DriveIdentification {
  bool ok{false};
  double J_kg_m2{0.0}, B_kg_m2_per_s{0.0}, Tc_pos_Nm{0.0}, Tc_neg_Nm{0.0};
  double J_stderr{0.0}, B_stderr{0.0}, Tc_pos_stderr{0.0}, Tc_neg_stderr{0.0};
  double residual_rms_Nm{0.0};
  std::size_t samples{0};
  std::string note;  ///< what was clamped or could not be identified
};

/// Rows of the signals in [from, to) where the axis moves (|w| above the threshold).
std::vector<std::size_t> moving_rows(const AxisSignals& s, std::size_t from, std::size_t to, double w_min_rad_per_s);

/// How far a machine definition's J, B and Coulomb levels are taken to be
/// from a real drive's (one standard deviation, relative): the example runs'
/// plants differ from the FADAL 2216 definition by 4 to 24 %.
inline constexpr double kNominalRelativeSpread = 0.25;

/// Least squares of the inverse dynamics on the fitting rows, with the
/// torque `T_Nm` (the signals' own, or one from which an effect's torque was
/// taken out). A parameter the rows determine less tightly than
/// kNominalRelativeSpread of its nominal value is weighted with the nominal
/// (inverse-variance mean; said in the note). Parameters that come out
/// non-physical are clamped and said.
DriveIdentification identify_drive(const AxisSignals& s, const std::vector<double>& T_Nm,
                                   const feeddrive::DriveParams& nominal);

/// The FADAL position-loop law (spec/measured-data.md) checked against a
/// run that logs u at the loop's own rate: u[k] regressed on e[k], the
/// integral Ts sum e, the difference (e[k] - e[k-1]) / Ts, the reference's
/// backward-difference acceleration and speed, and a constant (an integrator
/// that did not start at zero), on the rows where u is inside its limit. On
/// the twin's own law the fit is exact to the log's rounding.
struct LoopIdentification {
  bool checked{false};    ///< u at the loop's rate with enough rows: the law could be checked
  bool law_holds{false};  ///< the fit leaves under kLoopLawTolerance of u's RMS
  bool differs{false};    ///< ... and with gains other than the machine's (see identify_loop_gains)
  controller::PositionLoopParams gains;  ///< the machine's, or the identified ones where `differs`
  double residual_rel{0.0};              ///< RMS of the fit's residual over RMS of u
  std::string note;
};
inline constexpr double kLoopLawTolerance = 0.02;

/// Checks the loop law on the signals (see LoopIdentification). A gain
/// differs where replacing the machine's by the fitted one moves u by more
/// than 0.5 % of its RMS; where one does, all fitted gains are taken.
LoopIdentification identify_loop_gains(const AxisSignals& s, const controller::PositionLoopParams& machine_gains);

/// The amplifier checked against a run that logs both u and the current:
/// i[k] against u[k - L] at the lag L (0 to 10 ms) where they correlate
/// best, on the rows where the current is below 90 % of its largest value
/// (a current limit cuts the rest). Where they correlate (|r| >= 0.9), the
/// slope is the amplifier's gain: a slope off the machine's Ka by more than
/// 2 % replaces it, and a negative one says that the current is logged with
/// the opposite sign of u.
struct AmplifierCheck {
  bool checked{false};
  double correlation{0.0};
  double gain_A_per_V{0.0};  ///< the slope
  std::size_t lag_samples{0};
  bool sign_flipped{false};  ///< the slope is negative
  bool gain_differs{false};  ///< positive, and off the machine's Ka by more than 2 %
  std::string note;
};
AmplifierCheck check_amplifier(const AxisSignals& s, double Ka_A_per_V);

/// Sets what the signals' torque is made of, and the torque itself (low-passed
/// as the position is): Kt Ka u from the command (`from_u`), else Kt i from
/// the current. prepare_axis_signals takes the current where it is logged;
/// calibrate switches to u for a current it cannot use (AmplifierCheck::sign_flipped).
void set_torque_source(AxisSignals& s, bool from_u, const feeddrive::DriveParams& drive);

/// The regressor columns of the base model for the signals: a, w, [w>0], -[w<0].
struct BaseRegressors {
  std::vector<double> acc, vel, pos, neg;
};
BaseRegressors base_regressors(const AxisSignals& s);

}  // namespace twin::analysis
