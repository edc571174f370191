#pragma once
// A truth simulator for the calibration tests, written apart from the twin's
// model: the FADAL position law of spec/measured-data.md, a rigid (or
// two-mass) drive integrated by fixed-step RK4 with Karnopp stick/slip, and
// each catalogue effect as its own term. It writes a run folder
// (trace.csv + meta.json) that `calibrate` reads without being told what is in it.
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "tests/feeddrive/fadal_fixture.hpp"

namespace twin::truth {

struct Plant {
  double Ka{0.0}, Kt{0.0}, J{0.0}, B{0.0}, rg{0.0};
  double Tc_pos{0.0}, Tc_neg{0.0};
  double Kp{0.0}, Ki{0.0}, Kd{0.0}, K1{0.0}, K2{0.0}, u_max{0.0};
};

/// A FADAL drive and its position-loop gains as the plant (the numbers of
/// tests/feeddrive/fadal_fixture.hpp: Ozcan et al. 2017, Tables 1 and 3).
inline Plant fadal_plant(const feeddrive::DriveParams& d, const feeddrive::testing::PidGains& g) {
  return {d.Ka_A_per_V,  d.Kt_Nm_per_A,    d.J_kg_m2,        d.B_kg_m2_per_s,  d.rg_mm_per_rad, d.Tc_pos_Nm, d.Tc_neg_Nm,
          g.Kp_V_per_mm, g.Ki_V_per_s_mm, g.Kd_V_s_per_mm, g.K1_V_s2_per_mm, g.K2_V_s_per_mm,  g.u_max_V};
}
inline Plant fadal_x_plant() { return fadal_plant(feeddrive::testing::fadal_x(), feeddrive::testing::fadal_x_gains()); }
inline Plant fadal_y_plant() { return fadal_plant(feeddrive::testing::fadal_y(), feeddrive::testing::fadal_y_gains()); }

/// The plants of the calibration tests and sweep: J, B and Coulomb levels
/// moved from nominal (X: as far as the clean example's X is; Y: as the
/// clean example's Y is), so identification is needed.
inline Plant perturbed(Plant p, double J, double B, double Tc_pos, double Tc_neg) {
  p.J = J;
  p.B = B;
  p.Tc_pos = Tc_pos;
  p.Tc_neg = Tc_neg;
  return p;
}
inline Plant perturbed_x_plant() { return perturbed(fadal_x_plant(), 0.0084, 0.016, 0.23, 0.17); }
inline Plant perturbed_y_plant() { return perturbed(fadal_y_plant(), 0.0105, 0.34, 0.26, 0.32); }

struct Effects {
  double stribeck_Ts{0.0}, stribeck_ws{1.0};               // on when Ts > 0
  double cogging_A{0.0}, cogging_n{1.0}, cogging_phase{0.0};
  double screw_A_mm{0.0}, screw_P_mm{10.0};
  double backlash_mm{0.0};
  /// false: the gap lies between the drive and a massless table that carries
  /// the encoder (the loop closes across the gap); true: the gap lies in the
  /// coupling between motor and table (two masses, friction on the table,
  /// contact stiffness compliance_K or 20000 N m/rad), the encoder on the motor.
  bool backlash_in_coupling{false};
  double load_Nm{0.0};
  double pdf_dTc{0.0}, pdf_x0{0.0}, pdf_x1{0.0};
  int delay_ticks{0};
  bool delay_after_current{false};  // true: the logged current is Ka u undelayed, the torque is delayed
  double compliance_K{0.0}, compliance_C{0.0}, compliance_frac{0.5};
  double i_max_A{0.0};
  /// > 0 (rad/s): friction without stiction, a creep regime below this
  /// speed: Tf = Tc_dir clamp(w / creep_w, -1, 1) (rigid drive only). A
  /// torque below the Coulomb level creeps the axis, so a position loop that
  /// holds it at rest lets its torque relax towards the load.
  double creep_w{0.0};
  // Friction the data path's catalogue does not hold, for runs that rehearse
  // a real machine's undeclared friction (the catalogue's effects beside it).
  /// > 0: friction that rises with the load the screw carries (its
  /// efficiency): the sliding and breakaway levels gain this fraction of |Tm|.
  double load_friction{0.0};
  /// > 0 (N m per sqrt(rad/s)): sliding friction that rises with the square
  /// root of the speed, beside the drive's linear B w.
  double sqrt_friction{0.0};
  /// > 0 (N m/rad): Dahl's pre-sliding friction in place of stick/slip
  /// (rigid drive only): the friction torque F is a state, dF/dt = sigma
  /// (w - |w| F / g(w)) with g the sliding level at w, so the axis moves
  /// elastically, about g / sigma, before it slides, and holds any torque
  /// below g at rest by that deflection.
  double dahl_sigma{0.0};
};

/// The cascade law of spec/measured-data.md ("Position loops of real
/// machines") in place of the FADAL law, written here apart from the twin's:
/// vcmd = Kv e + kff v_ref; a PI velocity loop on the motor's speed; the
/// current loop as a first-order lag; optionally a torque feedforward Jff
/// (N m s^2/rad) on the command's acceleration. The run is then logged as a real CNC
/// logs it: no machine named, the velocity command and the measured speed,
/// the torque in the log's own unit (raw = raw_per_Nm Tm) or the current.
struct CascadeLaw {
  bool on{false};
  double Kv{60.0}, kff{0.0}, Kvp{0.4}, Tn{0.01}, tau_i{0.0}, Jff{0.0};
  double raw_per_Nm{0.0};  ///< > 0: log <a>_torque_raw; 0: log <a>_i_A
  double raw_step{0.0};    ///< > 0: the raw torque logged to multiples of this (a drive's integer counts)
  /// > 0 (N m): the velocity loop's torque command clamped to +-T_max, as
  /// a drive's own torque limit (a logged command then shows it), its
  /// integral running on (no anti-windup); the plant's i_max_A limits the
  /// current behind it, which the command does not show.
  double T_max_Nm{0.0};
  /// With T_max_Nm: the integral frozen on the ticks the limit clamps the
  /// command (conditional integration, the anti-windup most drives have).
  bool anti_windup{false};
  bool log_velocities{true};
  /// With log_velocities: also the motor's speed (false: the velocity
  /// command alone, as a CNC that traces its loop's output but not the
  /// speed it feeds back).
  bool log_motor_speed{true};
  /// With log_velocities: also the velocity command (false: the motor's
  /// speed alone, as a CNC that traces the speed but not its loop's output).
  bool log_velocity_command{true};
  /// Where the torque is logged raw: log the velocity loop's torque command
  /// (the current loop's input, as many drives trace it) in place of the
  /// torque the motor makes after the current loop's lag, any dead time and
  /// any current limit.
  bool log_torque_command{false};
  /// > 0 (s): the logged torque passed through a first-order low-pass of
  /// this time constant, as a drive's smoothed actual-torque monitor; the
  /// loop and the motor do not see it.
  double log_torque_filter_s{0.0};
  /// Log the torque as its mean over the velocity ticks of the period that
  /// ends at the row (a drive that averages what its faster loop made over
  /// the trace's sample period) in place of the tick's own value; with one
  /// tick a period, the torque held over the period before the row.
  bool log_torque_mean{false};
  /// The velocity loop's (and current loop's) ticks per position-loop
  /// period: 1, or more as most drives run it (a 1 ms position loop over a
  /// 250 or 125 us velocity loop). Each tick takes the motor's speed of its
  /// instant; the log samples the torque at the position loop's ticks. A
  /// dead time (effects.delay_ticks) stays that many position-loop periods.
  int velocity_ticks{1};
  /// The position loop's period in the truth's periods Ts_s: 1, or more
  /// where the log samples faster than the position loop runs (a 2 ms
  /// position loop traced every 1 ms). Its velocity command, following
  /// error and the command's speed and acceleration are taken every this
  /// many periods and held between; the velocity loop runs every period
  /// (and velocity_ticks times within it), and the log has every period.
  int position_every{1};
  /// With position_every > 1: the log samples the velocity command before
  /// the position loop updates it at its tick, so each new value shows a
  /// row after the tick (the rest of the row as at the tick).
  bool log_vcmd_before_update{false};
  /// > 1: the position loop follows the reference's moving average over
  /// this many periods (a CNC's smoothing after its interpolator, e.g. a
  /// bell-shaped acceleration), while the log holds the reference before it.
  int command_average_ticks{1};
  /// > 0 (s): then a first-order lag of this time constant (a CNC's
  /// setpoint filter), also not in the log.
  double command_lag_s{0.0};
  /// > 0: the position loop follows the reference this many periods late (a
  /// CNC that delays an axis's setpoint to match a slower axis's response,
  /// or hands it to the drive a few cycles after the interpolator), also not
  /// in the log.
  int command_delay_ticks{0};
  /// With the smoothing above: the velocity feedforward (and the torque
  /// feedforward) taken from the reference as logged, only the position
  /// loop's error from the smoothed one (a CNC that delays the position
  /// setpoint to match its velocity loop while feeding the speed forward).
  bool smooth_position_path_only{false};
};

struct RunSpec {
  Plant plant{fadal_x_plant()};
  CascadeLaw cascade;
  /// > 0: logged positions rounded to this many significant figures (as some
  /// CNCs export them); 0: to the encoder's resolution.
  int log_significant_figures{0};
  /// > 0: the logged reference rounded to this (mm), as a trace that shows
  /// the command at the display's resolution; the loop follows it unrounded.
  double log_reference_quantum_mm{0.0};
  Effects effects;
  double Ts_s{1e-4};
  double resolution_mm{0.001};
  double current_noise_A{0.01};
  int cycles{2};
  unsigned seed{1};
  /// Reference positions, one per controller period; empty: the built-in
  /// program of trapezoidal moves and dwells.
  std::vector<double> reference_mm;
  /// The axis the run is written as ("x" or "y"); its gains and drive
  /// constants must be the shipped machine's for that axis.
  std::string axis{"x"};
  /// Logged as a CNC's trace would: every log_every-th controller sample,
  /// and without the u column when log_current_only.
  int log_every{1};
  bool log_current_only{false};
  /// What meta.json gives as controller_period_s: the loop's period (Ts_s
  /// times the cascade's position_every), the log's own period Ts_s (a log
  /// that states its own rate as the loop's), or null (a log that does not
  /// say how fast its loop runs).
  enum class PeriodInMeta { kLoop, kLog, kNone };
  PeriodInMeta period_in_meta{PeriodInMeta::kLoop};
};

/// A reference of moves at `speeds` (mm/s) for 1.4 s each with 0.6 s dwells
/// between them, accelerations of 500 mm/s^2, from x = 50 mm, one position
/// per `Ts_s` for `seconds`.
std::vector<double> moves_program(double Ts_s, const std::vector<double>& speeds, double seconds);

/// A reference of one axis of circular contours (a part program's pockets
/// and bosses as one axis sees them): per arc (radius mm, feed mm/s),
/// `turns` turns of x = c + R cos(theta) from the axis's position, the feed reached
/// and left at 500 mm/s^2 along the path, 0.3 s dwells between, the arcs in
/// turn for `seconds`. The axis reverses through zero speed at every half
/// turn with the path's acceleration F^2 / R.
std::vector<double> contour_program(double Ts_s, const std::vector<std::pair<double, double>>& arcs, double seconds,
                                    int turns = 2);

/// The contour programs of the data-path tests and calibrate_sweep: the
/// fitting program's arcs, the validation program's, and the turns of each.
/// 1: two turns each; the fitting part (the first 60 %) is its first arc and
/// 1.5 s of the second. 2: a turn each; five arcs and four dwells in the
/// fitting part.
struct ContourPrograms {
  std::vector<std::pair<double, double>> fit_arcs, val_arcs;
  int turns{2};
};
inline ContourPrograms contour_programs(int which) {
  if (which == 2)
    return {{{20.0, 40.0}, {5.0, 45.0}, {4.0, 4.0}, {25.0, 60.0}, {5.0, 20.0}, {10.0, 10.0}},
            {{12.0, 25.0}, {8.0, 50.0}, {6.0, 8.0}, {20.0, 15.0}},
            1};
  return {{{10.0, 10.0}, {20.0, 40.0}, {5.0, 20.0}, {25.0, 60.0}, {15.0, 5.0}, {5.0, 45.0}},
          {{12.0, 25.0}, {8.0, 50.0}, {20.0, 15.0}, {6.0, 8.0}},
          2};
}

/// The cascade runs of the data-path tests: the perturbed X plant with
/// Coulomb 0.25 / 0.15 N m and a 0.05 N m load, Kv 45, kff 0.6, Kvp 0.5,
/// Tn 8 ms, the torque logged raw at `raw_per_Nm`, at 1 kHz unless `Ts_s`.
inline RunSpec cascade_run_spec(double raw_per_Nm, double resolution_mm, double Ts_s = 1e-3) {
  RunSpec sp;
  sp.plant = perturbed_x_plant();
  sp.plant.Tc_pos = 0.25;
  sp.plant.Tc_neg = 0.15;
  sp.effects.load_Nm = 0.05;
  sp.cascade.on = true;
  sp.cascade.Kv = 45.0;
  sp.cascade.kff = 0.6;
  sp.cascade.Kvp = 0.5;
  sp.cascade.Tn = 0.008;
  sp.cascade.raw_per_Nm = raw_per_Nm;
  sp.Ts_s = Ts_s;
  sp.resolution_mm = resolution_mm;
  sp.current_noise_A = 0.002;
  return sp;
}

/// What the truth did that its log may not show.
struct TruthRunStats {
  /// Loop periods at which its current limit (effects.i_max_A) or its
  /// loop's torque limit (cascade.T_max_Nm) clamped: 0 where the program
  /// never reaches the limit, which then is not in the run.
  std::size_t ticks_at_limit{0};
};

/// Simulates and writes dir/trace.csv and dir/meta.json for one axis (spec.axis) of the
/// shipped fadal2216 machine. Returns the number of rows; `stats`, where
/// given, gets what the truth did.
std::size_t write_truth_run(const std::filesystem::path& dir, const RunSpec& spec, TruthRunStats* stats = nullptr);

}  // namespace twin::truth
