// calibrate_sweep: runs of the truth simulator (truth_sim.cpp) over every
// catalogue effect at several magnitudes and on two motion programs, each
// passed to calibrate() without being told what is in it. Prints one line per
// run: the effect put in, what calibrate added, and the held-out errors before
// and after. Not a test: a table for docs/calibration.md.
//
//   calibrate_sweep [--example RUN_DIR] [--filter NAME] [--program NAME] [--magnitudes 0.5,1,2]
//                   [--log-every M] [--current-only] [--keep DIR] [--verbose]
//   calibrate_sweep --cascade [--filter NAME] [--magnitudes 0.5,1,2] [--noise A] [--no-motor-speed] [--no-velocities]
//                            [--no-velocity-command]
//                            [--encoder-mm Q] [--current-lag S] [--torque-command] [--torque-step R]
//                            [--torque-filter S] [--torque-mean]
//                            [--kff K] [--jff J] [--friction load|sqrt|dahl] [--limit-on-command]
//                            [--anti-windup] [--contour | --contour2] [--log-every M] [--velocity-ticks N]
//                            [--command-average N] [--command-lag S] [--command-delay N] [--smooth-position-only] [--ref-mm Q]
//                            [--keep DIR]
//
// With --example, further motion programs are the x and y reference of that
// measured run, each on the truth's X plant, and its y reference on the Y
// plant written as axis y ("Y example y"). --filter and --program
// keep the cases and programs whose names contain the text; --keep writes the
// runs under DIR (one folder each) instead of one temporary folder;
// --magnitudes sets the multiples m of each effect's middle magnitude;
// --log-every M keeps every M-th row of each run (a coarse log) and
// --current-only drops its u column.
//
// With --cascade the runs are those of a machine the twin does not know, as
// a real CNC with a cascade loop logs it: the truth's cascade law at 1 kHz,
// the velocity command, the speed and the torque in an unstated unit (40 per
// N m) logged, a 1 um encoder, no machine named. Each is fitted on one
// program of moves and validated on another (other speeds, another order,
// never fitted) through the data path (calibrate_from_data), and the line
// gives what the twin is judged on there: the effects kept against the one
// put in, the validation program's tracking-error NRMS (TRACK where above
// 0.01) and its torque NRMS against the rigid-body regression fitted on the
// same rows (TORQUE where not below it), and where the calibration put the
// law's lag in the log's torque monitor, out of the loop; a limit the fitting program never
// reaches (the truth clamps on no period) is not in the run, and is then
// not expected (the line says so); ROSE where the sum of the two
// NRMS is above the identified machine's without effects. --noise sets the
// standard deviation of the noise on the logged torque in N m (0.002 unless
// given; 40 raw per N m); --current-lag gives the truth's current loop a
// first-order lag of S seconds (and its logged torque is the lagged one);
// --torque-command logs the velocity loop's torque command instead, the
// current loop's input, before its lag and any dead time (as many drives
// trace it); --torque-step rounds the logged raw torque to multiples of R
// (a drive's integer counts or percent); --torque-filter passes the logged
// torque through a first-order low-pass of S seconds (a drive's smoothed
// actual-torque monitor, which the loop does not see); --torque-mean logs
// the torque's mean over the velocity ticks of the period ending at the row
// (with --velocity-ticks: a drive averaging its faster loop over the trace's
// sample period);
// --kff sets its velocity feedforward (0.6 unless given), --jff gives it a
// torque feedforward of J N m s^2/rad on the command's acceleration;
// --friction adds to every run a friction law of a real machine: friction
// rising with the screw's load (load: the catalogue's
// load_dependent_friction, then expected beside the run's own effect), with
// the square root of the speed (sqrt), or Dahl's pre-sliding friction in
// place of stick/slip (dahl); the last two are outside the catalogue.
// --limit-on-command makes the limit cases a drive's own torque limit, the
// velocity loop's command clamped (which a logged command shows), in place
// of a current limit behind it; --anti-windup does so with the loop's
// integral frozen while the limit clamps (conditional integration).
// --contour makes both programs circular contours as one axis of them sees
// it (contour_program: reversals through zero speed, no constant-speed
// moves), the fitting program's arcs other than the validation's;
// --contour2 takes other arcs, one turn each, so that the fitting part (the
// program's first 60 %) holds five arcs where --contour's holds one.
// --command-average N makes the truth's position loop follow the reference's
// moving average over N periods, and --command-lag S its first-order lag of
// S seconds after that (a CNC's smoothing after its interpolator), and
// --command-delay N a dead time of N periods after both, while the log holds
// the reference before them; with --smooth-position-only the
// feedforward takes the reference as logged, only the position loop's error
// the smoothed one. --ref-mm Q logs the reference rounded to Q mm (a trace
// that shows the command at the display's resolution). --no-velocities
// leaves the velocity command and the motor's speed out of the log (a trace
// of positions and torque alone), --no-velocity-command the command alone
// (the motor's speed logged).
// --velocity-ticks N runs the truth's velocity and current loops N times a
// position-loop period (a 1 ms position loop over a 125 us velocity loop:
// 8), the log at the position loop's ticks.
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "truth_sim.hpp"
#include "twin/calibrate/calibrate.hpp"
#include "twin/calibrate/machine_from_data.hpp"
#include "twin/core/error.hpp"

namespace {

using twin::truth::Effects;

struct Case {
  std::string name;
  std::string effect;
  std::function<void(Effects&)> set;
};

// Each catalogue effect at m times its middle magnitude.
struct EffectAt {
  std::string name;
  void (*set)(Effects&, double m);
  std::string variant{};  ///< appended to the case name where one effect has two forms
};

std::vector<EffectAt> catalogue() {
  return {
      {"stribeck", [](Effects& e, double m) { e.stribeck_Ts = 0.2 + 0.35 * m; e.stribeck_ws = 2.0; }},
      {"cogging", [](Effects& e, double m) { e.cogging_A = 0.15 * m; e.cogging_n = 6; e.cogging_phase = 1.0; }},
      {"screw_pitch_error", [](Effects& e, double m) { e.screw_A_mm = 0.01 * m; e.screw_P_mm = 9.0; }},
      {"backlash", [](Effects& e, double m) { e.backlash_mm = 0.01 * m; }},
      {"backlash", [](Effects& e, double m) {
         e.backlash_mm = 0.01 * m;
         e.backlash_in_coupling = true;
       }, "in coupling"},
      {"constant_load", [](Effects& e, double m) { e.load_Nm = -0.3 * m; }},
      {"position_dependent_friction", [](Effects& e, double m) { e.pdf_dTc = 0.3 * m; e.pdf_x0 = 4.0; e.pdf_x1 = 10.0; }},
      {"delay", [](Effects& e, double m) { e.delay_ticks = static_cast<int>(4 * m); }},
      {"compliance", [](Effects& e, double m) { e.compliance_K = 2500.0 / m; e.compliance_C = 0.15; }},
      {"current_saturation", [](Effects& e, double m) { e.i_max_A = 16.0 / m; }},
      {"load_dependent_friction", [](Effects& e, double m) { e.load_friction = 0.05 * m; }},
  };
}

using Pairs = std::vector<std::pair<const char*, const char*>>;

// Each of `effects` at each magnitude, and the `pairs` at magnitude 1.
std::vector<Case> cases(const std::vector<EffectAt>& effects, const std::vector<double>& magnitudes, const Pairs& pairs) {
  std::vector<Case> c;
  c.push_back({"none", "none", [](Effects&) {}});
  for (double m : magnitudes) {
    char s_buf[32];
    std::snprintf(s_buf, sizeof s_buf, std::abs(m * 10.0 - std::round(m * 10.0)) < 1e-9 ? "x%.1f" : "x%.2f", m);
    const std::string s = s_buf;
    for (const EffectAt& f : effects) c.push_back({f.name + (f.variant.empty() ? "" : " " + f.variant) + " " + s, f.name, [f, m](Effects& e) { f.set(e, m); }});
  }
  // Two effects at once, at the middle magnitudes.
  auto find = [&](const std::string& name) {
    return *std::find_if(effects.begin(), effects.end(), [&](const EffectAt& f) { return f.name == name; });
  };
  for (const auto& [a, b] : pairs) {
    const std::string both = std::string(a) + "+" + b;
    c.push_back({"pair " + both, both, [fa = find(a), fb = find(b)](Effects& e) {
                   fa.set(e, 1.0);
                   fb.set(e, 1.0);
                 }});
  }
  return c;
}

const Pairs kFadalPairs{{"stribeck", "cogging"},
                        {"constant_load", "cogging"},
                        {"position_dependent_friction", "screw_pitch_error"},
                        {"stribeck", "current_saturation"}};

// The effects the data path looks for on a cascade run, each at m times
// the magnitude of its test in data_effects_test.cpp. A constant load and
// compliance are not among them: the data path's drive carries a constant,
// and it does not search a two-mass resonance.
std::vector<EffectAt> cascade_catalogue() {
  return {
      {"stribeck", [](Effects& e, double m) { e.stribeck_Ts = 0.25 + 0.2 * m; e.stribeck_ws = 3.0; }},
      {"rising_friction", [](Effects& e, double m) { e.stribeck_Ts = 0.15 - 0.03 * m; e.stribeck_ws = 1.0; }},
      {"smooth_friction", [](Effects& e, double m) { e.creep_w = 0.2 * m; }},
      {"cogging", [](Effects& e, double m) { e.cogging_A = 0.06 * m; e.cogging_n = 4.0; }},
      {"position_dependent_friction", [](Effects& e, double m) { e.pdf_dTc = 0.1 * m; e.pdf_x0 = 40.0; e.pdf_x1 = 60.0; }},
      {"screw_pitch_error", [](Effects& e, double m) { e.screw_A_mm = 0.004 * m; e.screw_P_mm = 8.0; }},
      {"backlash", [](Effects& e, double m) { e.backlash_mm = 0.02 * m; }},
      // The truth's cascade loop does not stay stable with 3 ms of delay: 2 at most.
      {"delay", [](Effects& e, double m) { e.delay_ticks = static_cast<int>(std::lround(std::clamp(2.0 * m, 1.0, 2.0))); }},
      {"current_saturation", [](Effects& e, double m) { e.i_max_A = 8.0 * (1.1 - 0.1 * m); }},
  };
}

const Pairs kCascadePairs{{"stribeck", "cogging"},
                          {"position_dependent_friction", "screw_pitch_error"},
                          {"cogging", "delay"},
                          {"smooth_friction", "cogging"}};

// The effect names in `list` ("a+b"), sorted.
std::vector<std::string> split_sorted(const std::string& list) {
  std::vector<std::string> v;
  for (std::size_t p = 0, q; p <= list.size(); p = q + 1) {
    q = list.find('+', p);
    if (q == std::string::npos) q = list.size();
    if (q > p && list.substr(p, q - p) != "none") v.push_back(list.substr(p, q - p));
  }
  std::sort(v.begin(), v.end());
  return v;
}

/// The truth's loop where the sweep changes it from cascade_run_spec's.
struct CascadeOptions {
  double current_lag_s{0.0};  ///< the current loop's first-order lag (0: instant)
  double kff{-1.0};           ///< the velocity feedforward (< 0: the spec's)
  double Jff{0.0};            ///< the torque feedforward on the command's acceleration, N m s^2/rad
  bool log_torque_command{false};  ///< log the current loop's input, not the motor's torque
  double raw_step{0.0};            ///< the raw torque logged to multiples of this (0: as computed)
  double torque_filter_s{0.0};     ///< the logged torque low-passed at this time constant (0: as computed)
  bool torque_mean{false};         ///< the logged torque the mean over the period's velocity ticks
  std::string friction;            ///< a friction law beside every run's effect (empty: none)
  bool limit_on_command{false};    ///< the limit cases clamp the velocity loop's command, not the current
  bool anti_windup{false};         ///< with limit_on_command: the integral frozen while the limit clamps
  int contour{0};                  ///< both programs of circular contours (contour_program): 1 or 2; 0: moves
  int log_every{1};                ///< every log_every-th loop period logged (a log slower than the loop)
  int velocity_ticks{1};           ///< the velocity loop's ticks per position-loop period
  int position_every{1};           ///< the position loop's period in logged periods (a log faster than it)
  bool vcmd_before_update{false};  ///< with position_every: the command logged before the loop updates it
  bool log_velocities{true};       ///< false: neither the velocity command nor the speed in the log
  bool log_velocity_command{true};  ///< false: the velocity command not in the log
  int command_average_ticks{1};    ///< the loop follows the reference's moving average over this many periods
  double command_lag_s{0.0};       ///< and then its first-order lag of this time constant
  int command_delay_ticks{0};      ///< and then this many periods' dead time
  bool position_path_only{false};  ///< the smoothing on the position loop's error only, not the feedforward
  double reference_quantum_mm{0.0};  ///< the logged reference rounded to this (0: as computed)
  /// meta.json's controller period: the loop's, the log's own, or none.
  twin::truth::RunSpec::PeriodInMeta period_in_meta{twin::truth::RunSpec::PeriodInMeta::kLoop};
};

// A friction law added to every run of the sweep (--friction): the truth's
// load_friction, sqrt_friction or dahl_sigma, each about as large as the
// plant's Coulomb level where it shows most. The catalogue name the run
// should then add to its own ("" where the catalogue does not hold the
// law), or nullopt for an unknown kind.
std::optional<std::string> add_friction(const std::string& kind, Effects& e) {
  if (kind == "load") {
    e.load_friction = 0.05;  // 0.13 N m at the program's 2.6 N m accelerations
    return "load_dependent_friction";
  }
  if (kind == "sqrt") {
    e.sqrt_friction = 0.04;  // 0.22 N m at 50 mm/s (31 rad/s), 0.06 N m at 3 mm/s
    return "";
  }
  if (kind == "dahl") {
    e.dahl_sigma = 64.0;  // 0.2 N m over 5 um of the screw's travel (rg 1.59 mm/rad)
    return "";
  }
  if (kind.empty()) return "";
  return std::nullopt;
}

int cascade_sweep(const std::vector<double>& magnitudes, const std::string& filter, double noise_Nm,
                  bool log_motor_speed, double encoder_mm, const CascadeOptions& loop, const std::string& keep) {
  namespace ta = twin::analysis;
  const std::vector<double> fit_speeds{20.0, -35.0, 3.0, -12.0, 50.0, -30.0, 8.0, -4.0, 25.0, -25.0};
  const std::vector<double> val_speeds{30.0, -45.0, 5.0, -15.0, 40.0, -6.0, 12.0, -20.0};
  const auto tmp = std::filesystem::temp_directory_path() / ("calibrate_sweep_" + std::to_string(::getpid()));
  int wrong = 0, track = 0, torque = 0, rose = 0, total = 0;
  const std::string tq = "x_torque_raw", err = "x_err_mm";
  for (const Case& c : cases(cascade_catalogue(), magnitudes, kCascadePairs)) {
    if (!filter.empty() && c.name.find(filter) == std::string::npos) continue;
    std::string folder = "cascade " + c.name;
    std::replace(folder.begin(), folder.end(), ' ', '_');
    const auto dir = (keep.empty() ? tmp : std::filesystem::path(keep)) / folder;
    twin::truth::RunSpec sp = twin::truth::cascade_run_spec(40.0, 0.001);
    sp.current_noise_A = noise_Nm;  // the truth adds it to the torque in N m where the torque is logged raw
    sp.cascade.log_motor_speed = log_motor_speed;
    sp.resolution_mm = encoder_mm;
    sp.cascade.tau_i = loop.current_lag_s;
    if (loop.kff >= 0.0) sp.cascade.kff = loop.kff;
    sp.cascade.Jff = loop.Jff;
    sp.cascade.log_torque_command = loop.log_torque_command;
    sp.cascade.raw_step = loop.raw_step;
    sp.cascade.log_torque_filter_s = loop.torque_filter_s;
    sp.cascade.log_torque_mean = loop.torque_mean;
    sp.log_every = loop.log_every;
    sp.cascade.velocity_ticks = loop.velocity_ticks;
    sp.cascade.position_every = loop.position_every;
    sp.cascade.log_vcmd_before_update = loop.vcmd_before_update;
    sp.cascade.log_velocities = loop.log_velocities;
    sp.cascade.log_velocity_command = loop.log_velocity_command;
    sp.cascade.command_average_ticks = loop.command_average_ticks;
    sp.cascade.command_lag_s = loop.command_lag_s;
    sp.cascade.command_delay_ticks = loop.command_delay_ticks;
    sp.cascade.smooth_position_path_only = loop.position_path_only;
    sp.log_reference_quantum_mm = loop.reference_quantum_mm;
    sp.period_in_meta = loop.period_in_meta;
    const double load = sp.effects.load_Nm;
    c.set(sp.effects);
    sp.effects.load_Nm = load;
    const std::string also = add_friction(loop.friction, sp.effects).value_or("");
    if (loop.limit_on_command && sp.effects.i_max_A > 0.0) {
      sp.cascade.T_max_Nm = sp.plant.Kt * sp.effects.i_max_A;
      sp.cascade.anti_windup = loop.anti_windup;
      sp.effects.i_max_A = 0.0;
    }
    try {
      const twin::truth::ContourPrograms cp = twin::truth::contour_programs(loop.contour);
      sp.reference_mm = loop.contour > 0 ? twin::truth::contour_program(sp.Ts_s, cp.fit_arcs, 24.0, cp.turns)
                                         : twin::truth::moves_program(sp.Ts_s, fit_speeds, 24.0);
      twin::truth::TruthRunStats fit_stats;
      twin::truth::write_truth_run(dir / "fit", sp, &fit_stats);
      sp.reference_mm = loop.contour > 0 ? twin::truth::contour_program(sp.Ts_s, cp.val_arcs, 16.0, cp.turns)
                                         : twin::truth::moves_program(sp.Ts_s, val_speeds, 16.0);
      sp.seed = 7;
      twin::truth::write_truth_run(dir / "validate", sp);
      const ta::MeasuredRun fit = ta::load_run(dir / "fit"), val = ta::load_run(dir / "validate");
      const auto t0 = std::chrono::steady_clock::now();
      const ta::DataCalibration r = ta::calibrate_from_data({fit}, {val}, ta::machine_for_run(fit, "", nullptr));
      const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      std::string kept;
      for (const ta::DataEffect& e : r.effects)
        if (e.kept) kept += (kept.empty() ? "" : "+") + e.effect;
      // A limit the fitting program never reaches is not in the run: the
      // effects expected are the others.
      std::vector<std::string> expected = split_sorted(also.empty() ? c.effect : c.effect + "+" + also);
      const bool unreached = sp.effects.i_max_A + sp.cascade.T_max_Nm > 0.0 && fit_stats.ticks_at_limit == 0;
      if (unreached) std::erase(expected, std::string("current_saturation"));
      const bool ok = split_sorted(kept) == expected;
      if (kept.empty()) kept = "none";
      if (r.validation_runs.size() != 1) throw twin::Error("no validation run in the result");
      const ta::RunErrors& v = r.validation_runs[0];
      auto at = [](const ta::ChannelErrors& e, const std::string& k) {
        const auto it = e.nrms.find(k);
        return it == e.nrms.end() ? std::nan("") : it->second;
      };
      const double e_cal = at(v.calibrated, err), t_cal = at(v.calibrated, tq), t_id = at(v.identified, tq),
                   t_reg = at(v.regression, tq), e_id = at(v.identified, err);
      const bool bad_track = !(e_cal <= 0.01), bad_torque = !(t_cal < t_reg), up = !(t_cal + e_cal <= t_id + e_id);
      const bool monitor = std::any_of(r.axis.begin(), r.axis.end(), [](const ta::AxisFromData& a) {
        return a.lag_in_monitor;
      });
      int inner = 1;
      for (const ta::AxisFromData& a : r.axis) inner = std::max(inner, a.law_inner_ticks);
      const bool mean = std::any_of(r.axis.begin(), r.axis.end(), [](const ta::AxisFromData& a) {
        return a.logs_period_mean();
      });
      const std::string inner_text = inner > 1 ? " (velocity loop at Ts/" + std::to_string(inner) +
                                                     (mean ? ", torque logged as the period's mean" : "") + ")"
                                               : "";
      const std::string period_text =
          std::abs(r.final_machine.Ts_s - sp.Ts_s) > 1e-12
              ? " (position loop at " + std::to_string(r.final_machine.Ts_s * 1e3).substr(0, 5) + " ms)"
              : "";
      wrong += !ok;
      track += bad_track;
      torque += bad_torque;
      rose += up;
      ++total;
      std::printf("%-40s %-44s err %.4f  torque %.4f (identified %.4f, regression %.4f)  %.1f s%s%s%s%s%s%s%s%s\n",
                  c.name.c_str(), kept.c_str(), e_cal, t_cal, t_id, t_reg, wall_s, ok ? "" : " WRONG",
                  bad_track ? " TRACK" : "", bad_torque ? " TORQUE" : "", up ? " ROSE" : "",
                  unreached ? " (the limit is never reached)" : "", monitor ? " (a lag in the torque monitor)" : "",
                  inner_text.c_str(), period_text.c_str());
      std::fflush(stdout);
    } catch (const twin::Error& e) {
      std::printf("%-40s error: %s\n", c.name.c_str(), e.what());
      ++wrong;
      ++total;
    }
    if (keep.empty()) std::filesystem::remove_all(dir);
  }
  if (keep.empty()) std::filesystem::remove_all(tmp);
  std::printf("%d runs: %d named wrong, %d with the validation tracking NRMS above 0.01, %d with the validation "
              "torque not below the regression's, %d with it above the identified machine's\n",
              total, wrong, track, torque, rose);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  std::string example, filter, program, keep;
  std::vector<double> magnitudes{0.5, 1.0, 2.0};
  long log_every = 1;
  bool verbose = false, current_only = false, cascade = false;
  double noise_Nm = 0.002;
  bool log_motor_speed = true;
  double encoder_mm = 0.001;
  CascadeOptions loop;
  // A number >= 0 for `option`, or a message and false.
  auto number_at_least_0 = [](const char* option, const char* t, double& out) {
    char* end = nullptr;
    out = std::strtod(t, &end);
    if (end != t && *end == '\0' && out >= 0.0) return true;
    std::fprintf(stderr, "calibrate_sweep: %s takes a number >= 0, not '%s'\n", option, t);
    return false;
  };
  for (int i = 1; i < argc; ++i) {
    const bool has_value = i + 1 < argc;
    if (!std::strcmp(argv[i], "--verbose")) {
      verbose = true;
    } else if (!std::strcmp(argv[i], "--example") && has_value) {
      example = argv[++i];
    } else if (!std::strcmp(argv[i], "--filter") && has_value) {
      filter = argv[++i];
    } else if (!std::strcmp(argv[i], "--program") && has_value) {
      program = argv[++i];
    } else if (!std::strcmp(argv[i], "--magnitudes") && has_value) {
      magnitudes.clear();
      for (char* t = std::strtok(argv[++i], ","); t; t = std::strtok(nullptr, ",")) {
        char* end = nullptr;
        const double m = std::strtod(t, &end);
        if (end == t || *end != '\0' || !(m > 0.0)) {
          std::fprintf(stderr, "calibrate_sweep: --magnitudes takes positive numbers separated by commas, not '%s'\n", t);
          return 2;
        }
        magnitudes.push_back(m);
      }
    } else if (!std::strcmp(argv[i], "--velocity-ticks") && has_value) {
      const long n = std::strtol(argv[++i], nullptr, 10);
      if (n < 1 || n > 64) {
        std::fprintf(stderr, "calibrate_sweep: --velocity-ticks takes a whole number from 1 to 64\n");
        return 2;
      }
      loop.velocity_ticks = static_cast<int>(n);
    } else if (!std::strcmp(argv[i], "--position-every") && has_value) {
      const long n = std::strtol(argv[++i], nullptr, 10);
      if (n < 1 || n > 16) {
        std::fprintf(stderr, "calibrate_sweep: --position-every takes a whole number of logged periods from 1 to 16\n");
        return 2;
      }
      loop.position_every = static_cast<int>(n);
    } else if (!std::strcmp(argv[i], "--command-average") && has_value) {
      const long n = std::strtol(argv[++i], nullptr, 10);
      if (n < 1 || n > 200) {
        std::fprintf(stderr, "calibrate_sweep: --command-average takes a whole number of periods from 1 to 200\n");
        return 2;
      }
      loop.command_average_ticks = static_cast<int>(n);
    } else if (!std::strcmp(argv[i], "--command-lag") && has_value) {
      if (!number_at_least_0("--command-lag", argv[++i], loop.command_lag_s)) return 2;
    } else if (!std::strcmp(argv[i], "--command-delay") && has_value) {
      const long n = std::strtol(argv[++i], nullptr, 10);
      if (n < 1 || n > 200) {
        std::fprintf(stderr, "calibrate_sweep: --command-delay takes a whole number of periods from 1 to 200\n");
        return 2;
      }
      loop.command_delay_ticks = static_cast<int>(n);
    } else if (!std::strcmp(argv[i], "--ref-mm") && has_value) {
      if (!number_at_least_0("--ref-mm", argv[++i], loop.reference_quantum_mm)) return 2;
    } else if (!std::strcmp(argv[i], "--smooth-position-only")) {
      loop.position_path_only = true;
    } else if (!std::strcmp(argv[i], "--vcmd-before-update")) {
      loop.vcmd_before_update = true;
    } else if (!std::strcmp(argv[i], "--period-in-meta") && has_value) {
      const std::string v = argv[++i];
      using P = twin::truth::RunSpec::PeriodInMeta;
      if (v == "loop") {
        loop.period_in_meta = P::kLoop;
      } else if (v == "log") {
        loop.period_in_meta = P::kLog;
      } else if (v == "none") {
        loop.period_in_meta = P::kNone;
      } else {
        std::fprintf(stderr, "calibrate_sweep: --period-in-meta takes loop, log or none, not '%s'\n", v.c_str());
        return 2;
      }
    } else if (!std::strcmp(argv[i], "--log-every") && has_value) {
      log_every = std::strtol(argv[++i], nullptr, 10);
      if (log_every < 1) {
        std::fprintf(stderr, "calibrate_sweep: --log-every takes a whole number of controller periods >= 1\n");
        return 2;
      }
    } else if (!std::strcmp(argv[i], "--cascade")) {
      cascade = true;
    } else if (!std::strcmp(argv[i], "--noise") && has_value) {
      char* end = nullptr;
      const char* t = argv[++i];
      noise_Nm = std::strtod(t, &end);
      if (end == t || *end != '\0' || !(noise_Nm >= 0.0)) {
        std::fprintf(stderr, "calibrate_sweep: --noise takes a torque in N m >= 0, not '%s'\n", t);
        return 2;
      }
    } else if (!std::strcmp(argv[i], "--encoder-mm") && has_value) {
      char* end = nullptr;
      const char* t = argv[++i];
      encoder_mm = std::strtod(t, &end);
      if (end == t || *end != '\0' || !(encoder_mm > 0.0)) {
        std::fprintf(stderr, "calibrate_sweep: --encoder-mm takes a resolution in mm > 0, not '%s'\n", t);
        return 2;
      }
    } else if (!std::strcmp(argv[i], "--current-lag") && has_value) {
      if (!number_at_least_0("--current-lag", argv[++i], loop.current_lag_s)) return 2;
    } else if (!std::strcmp(argv[i], "--jff") && has_value) {
      if (!number_at_least_0("--jff", argv[++i], loop.Jff)) return 2;
    } else if (!std::strcmp(argv[i], "--kff") && has_value) {
      if (!number_at_least_0("--kff", argv[++i], loop.kff)) return 2;
    } else if (!std::strcmp(argv[i], "--torque-step") && has_value) {
      if (!number_at_least_0("--torque-step", argv[++i], loop.raw_step)) return 2;
    } else if (!std::strcmp(argv[i], "--torque-filter") && has_value) {
      if (!number_at_least_0("--torque-filter", argv[++i], loop.torque_filter_s)) return 2;
    } else if (!std::strcmp(argv[i], "--friction") && has_value) {
      loop.friction = argv[++i];
      Effects probe;
      if (loop.friction.empty() || !add_friction(loop.friction, probe)) {
        std::fprintf(stderr, "calibrate_sweep: --friction takes load, sqrt or dahl, not '%s'\n", loop.friction.c_str());
        return 2;
      }
    } else if (!std::strcmp(argv[i], "--limit-on-command")) {
      loop.limit_on_command = true;
    } else if (!std::strcmp(argv[i], "--contour")) {
      loop.contour = 1;
    } else if (!std::strcmp(argv[i], "--contour2")) {
      loop.contour = 2;
    } else if (!std::strcmp(argv[i], "--anti-windup")) {
      loop.limit_on_command = loop.anti_windup = true;
    } else if (!std::strcmp(argv[i], "--torque-mean")) {
      loop.torque_mean = true;
    } else if (!std::strcmp(argv[i], "--torque-command")) {
      loop.log_torque_command = true;
    } else if (!std::strcmp(argv[i], "--no-velocity-command")) {
      loop.log_velocity_command = false;
    } else if (!std::strcmp(argv[i], "--no-velocities")) {
      loop.log_velocities = false;
    } else if (!std::strcmp(argv[i], "--no-motor-speed")) {
      log_motor_speed = false;
    } else if (!std::strcmp(argv[i], "--current-only")) {
      current_only = true;
    } else if (!std::strcmp(argv[i], "--keep") && has_value) {
      keep = argv[++i];
    } else {
      std::fprintf(stderr, "calibrate_sweep: unknown or incomplete argument '%s'\n", argv[i]);
      return 2;
    }
  }
  loop.log_every = static_cast<int>(log_every);
  if (cascade) return cascade_sweep(magnitudes, filter, noise_Nm, log_motor_speed, encoder_mm, loop, keep);
  // A program: a reference and the drive that follows it (the X plant, or
  // the Y plant written as axis y).
  struct Program {
    std::string name;
    std::vector<double> ref_mm;
    bool y_plant{false};
  };
  std::vector<Program> programs{{"trapezoids", {}, false}};
  if (!example.empty()) {
    const auto run = twin::analysis::load_run(example);
    for (const char* a : {"x", "y"})
      if (const auto* r = run.trace.find(std::string(a) + "_ref_mm")) programs.push_back({std::string("example ") + a, *r, false});
    if (const auto* r = run.trace.find("y_ref_mm")) programs.push_back({"Y example y", *r, true});
  }
  const auto tmp = std::filesystem::temp_directory_path() / ("calibrate_sweep_" + std::to_string(::getpid()));
  int wrong = 0, rose = 0, total = 0;
  for (const auto& [prog, ref, y_plant] : programs)
    for (const Case& c : cases(catalogue(), magnitudes, kFadalPairs)) {
      if (!filter.empty() && c.name.find(filter) == std::string::npos) continue;
      if (!program.empty() && prog.find(program) == std::string::npos) continue;
      std::string folder = prog + " " + c.name;
      std::replace(folder.begin(), folder.end(), ' ', '_');
      const auto dir = keep.empty() ? tmp : std::filesystem::path(keep) / folder;
      twin::truth::RunSpec spec;
      spec.plant = y_plant ? twin::truth::perturbed_y_plant() : twin::truth::perturbed_x_plant();
      if (y_plant) spec.axis = "y";
      spec.reference_mm = ref;
      c.set(spec.effects);
      try {
        spec.log_every = static_cast<int>(log_every);
        spec.log_current_only = current_only;
        twin::truth::write_truth_run(dir, spec);
        const auto run = twin::analysis::load_run(dir);
        std::vector<std::string> notes;
        const auto machine = twin::analysis::machine_for_run(run, "", &notes);
        const auto t0 = std::chrono::steady_clock::now();
        const auto r = twin::analysis::calibrate(run, machine);
        const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        std::string added;
        for (const auto& a : r.added) added += (added.empty() ? "" : "+") + a.candidate.effect;
        if (added.empty()) added = "none";
        const std::size_t ax = twin::index(run.axes.front());
        const auto& b = r.error_before[ax];
        const auto& a = r.error_after[ax];
        // One effect: the first added must be it. Two ("a+b"): exactly those two, in any order.
        std::vector<std::string> want, got;
        for (std::size_t p = 0, q; p <= c.effect.size(); p = q + 1) {
          q = c.effect.find('+', p);
          if (q == std::string::npos) q = c.effect.size();
          want.push_back(c.effect.substr(p, q - p));
        }
        for (const auto& ad : r.added) got.push_back(ad.candidate.effect);
        std::sort(want.begin(), want.end());
        std::sort(got.begin(), got.end());
        const bool ok = want.size() > 1 ? got == want
                                        : (r.added.empty() ? std::string("none") : r.added[0].candidate.effect) == c.effect;
        const bool up = a.err_mm > b.err_mm || a.u > b.u;
        wrong += !ok;
        rose += up;
        ++total;
        std::printf("%-12s %-34s %-40s err %.4f -> %.4f  u %.4f -> %.4f  hunt %.3f -> %.3f  %.1f s%s%s\n", prog.c_str(),
                    c.name.c_str(), added.c_str(), b.err_mm, a.err_mm, b.u, a.u, b.hunt, a.hunt, wall_s, ok ? "" : " WRONG",
                    up ? " ROSE" : "");
        if (verbose) {
          for (const auto& k : r.considered)
            std::printf("    considered %s: gain %.3f t %.1f: %s\n", k.effect.c_str(), k.signal_gain, k.t_stat,
                        k.evidence.c_str());
          for (const auto& k : r.rejected) std::printf("    rejected %s: %s\n", k.effect.c_str(), k.evidence.c_str());
          for (const auto& k : r.added)
            std::printf("    added %s: %s\n", k.candidate.effect.c_str(), k.candidate.evidence.c_str());
        }
        std::fflush(stdout);
      } catch (const twin::Error& e) {
        std::printf("%-12s %-34s error: %s\n", prog.c_str(), c.name.c_str(), e.what());
        ++wrong;
        ++total;
      }
    }
  if (keep.empty()) std::filesystem::remove_all(tmp);
  std::printf("%d runs: %d named wrong, %d with a held-out error above before\n", total, wrong, rose);
  return 0;
}
