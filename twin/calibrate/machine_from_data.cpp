#include "twin/calibrate/machine_from_data.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <numeric>
#include <sstream>
#include <tuple>
#include <utility>

#include <fmt/format.h>

#include "feeddrive/effect_torques.hpp"
#include "twin/calibrate/effect_detectors.hpp"
#include "twin/calibrate/signal.hpp"
#include "twin/core/error.hpp"
#include "twin/core/golden_section.hpp"
#include "twin/core/text.hpp"

namespace twin::analysis {
namespace {

std::string col(Axis a, const char* suffix) { return std::string(axis_name(a)) + suffix; }

/// A column filtered as the speed taken from the position was (see
/// add_speed_from_position), beside the column as logged.
std::string lowpassed(const std::string& column) { return column + "@lowpassed"; }

/// The column filtered alike where the speed was taken from the position,
/// else as logged: a law fitted on that speed is fitted on the other
/// channels through the same zero-phase filter, so the filter cancels out.
const std::vector<double>* filtered_alike(const io::TraceTable& t, const std::string& column) {
  const auto* f = t.find(lowpassed(column));
  return f ? f : t.find(column);
}

/// Whether `column` has a low-passed twin: the speed was taken from the
/// position (add_speed_from_position) and laws on it are fitted through the
/// low-pass.
bool has_lowpassed_twin(const io::TraceTable& t, const std::string& column) {
  return t.find(lowpassed(column)) != nullptr;
}

/// A channel the identification reads in place of the logged one: a
/// velocity command rebuilt from the torque where the log has none
/// (rebuild_velocity_commands), or the logged one moved to the rows it
/// belongs to (align_velocity_commands). A column of the calibration's own
/// copy of a run under this name, so that it is never compared as a logged
/// channel (the errors compare the log as it is).
std::string for_identification(const std::string& column) { return column + "@identification"; }

/// The velocity command the identification reads: as rebuilt or aligned,
/// else as logged.
std::string velocity_command_column(const io::TraceTable& t, Axis a) {
  const std::string logged = col(a, "_vcmd_mm_s");
  return t.find(for_identification(logged)) != nullptr ? for_identification(logged) : logged;
}

/// A log at 5 ms or faster resolves the velocity loop: its PI law is fitted
/// from the log where the speed and the velocity command are logged
/// (identify_velocity_loop; up to kLawFitMaxPeriod_s, judged row to row
/// beyond 5 ms), the drive on the logged speed, and the
/// detectors that read the torque row by row (delay, cogging, load
/// friction, lead error) run on it. Held at 2 ms for the detectors, a 1 ms
/// loop logged every 4 ms was named wrong on 9 of the cascade sweep's 14
/// runs of one magnitude (2 since).
bool resolves_velocity_loop(double dt_s) { return dt_s <= 5e-3 + 1e-12; }

/// A log at 2 ms or faster resolves how the held torque settles at rest;
/// on a slower one a rest period is a handful of samples of a loop that
/// still settles, so what the log holds there is not read as an effect's
/// signature (smooth_friction, rising_friction) and the replay rule alone
/// decides.
bool resolves_rest(double dt_s) { return dt_s <= 2e-3 + 1e-12; }

/// The slowest log the velocity loop's PI law is fitted from: a loop of
/// 10 Hz (the cascade sweep's 59 rad/s, its integral's zero at 125 rad/s)
/// sampled at 50 Hz. At 50 ms the law's misfit from row to row is near the
/// torque's own change, and the loop is chosen on the replay instead.
constexpr double kLawFitMaxPeriod_s = 20e-3;

/// The cubic through p0..p3 at equal spacing (Catmull-Rom) at u in [0, 1]
/// of the way from p1 to p2: a log's value between two rows.
double catmull_rom(double p0, double p1, double p2, double p3, double u) {
  return p1 + 0.5 * u * (p2 - p0 + u * (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3 + u * (3.0 * (p1 - p2) + p3 - p0)));
}

/// The command's speed as the position loop takes it at each row: the
/// backward difference over one controller period Ts of the reference as the
/// replay rebuilds it between the log's rows (upsample_reference's monotone
/// cubic, evaluated at that one point, so a slow log of a fast loop costs no
/// memory), within each segment (0 on its first row). Where the log samples
/// every period, the log's own backward difference. A law fitted on the log's
/// difference over a longer period is fitted on a smoothed speed: at a 2 ms
/// log of a 1 ms cascade, Kv 43.8 and kff 0.61 came out for 45 and 0.6.
std::vector<double> loop_reference_speed(const std::vector<double>& ref, const std::vector<Segment>& segs, double dt,
                                         double Ts) {
  std::vector<double> vr(ref.size(), 0.0);
  const auto m = Ts > 0.0 ? std::max<std::int64_t>(1, std::llround(dt / Ts)) : std::int64_t{1};
  const double period = m > 1 ? Ts : dt;
  // The cubic one period before the row, on the interval that ends at it
  // (the point upsample_reference puts there), without building the rest.
  const double f = static_cast<double>(m - 1) / static_cast<double>(m);
  const double f2 = f * f, f3 = f2 * f;
  for (const Segment& sg : segs) {
    if (sg.end < sg.begin + 2) continue;
    const std::vector<double> sub(ref.begin() + static_cast<std::ptrdiff_t>(sg.begin),
                                  ref.begin() + static_cast<std::ptrdiff_t>(sg.end));
    const std::vector<double> slope = m > 1 ? monotone_slopes(sub) : std::vector<double>(sub.size(), 0.0);
    for (std::size_t j = 1; j < sub.size(); ++j) {
      const double before = m > 1 ? (2 * f3 - 3 * f2 + 1) * sub[j - 1] + (f3 - 2 * f2 + f) * slope[j - 1] +
                                        (-2 * f3 + 3 * f2) * sub[j] + (f3 - f2) * slope[j]
                                  : sub[j - 1];
      vr[sg.begin + j] = (sub[j] - before) / period;
    }
  }
  return vr;
}

/// The speed taken from the position: its low-pass, and the shortest segment
/// it is applied to (a shorter one is differentiated as logged).
constexpr double kSpeedCutoff_Hz = 50.0;
constexpr std::size_t kSpeedFilterRows = 64;

/// Per segment, a column low-passed at kSpeedCutoff_Hz without phase (where
/// the segment is long enough; a shorter one as logged).
std::vector<double> lowpass_in_segments(const std::vector<double>& c, const std::vector<Segment>& segs, double dt,
                                        double cutoff_Hz = kSpeedCutoff_Hz) {
  std::vector<double> y = c;
  for (const Segment& sg : segs) {
    if (sg.end < sg.begin + kSpeedFilterRows) continue;
    const std::vector<double> yf =
        lowpass(std::span<const double>(c.data() + sg.begin, sg.end - sg.begin), cutoff_Hz, 1.0 / dt);
    std::copy(yf.begin(), yf.end(), y.begin() + static_cast<std::ptrdiff_t>(sg.begin));
  }
  return y;
}

/// The share of a white noise's RMS that lowpass_in_segments lets through
/// at sample period dt: the root of the sum of squares of its response to a
/// unit impulse (0.30 at 1 kHz, 0.42 at 500 Hz: about the root of the
/// cutoff over the Nyquist frequency).
double lowpass_noise_gain(double dt) {
  std::vector<double> impulse(16 * kSpeedFilterRows, 0.0);
  impulse[impulse.size() / 2] = 1.0;
  double s2 = 0.0;
  for (double y : lowpass(std::span<const double>(impulse), kSpeedCutoff_Hz, 1.0 / dt)) s2 += y * y;
  return std::sqrt(s2);
}

bool is_multiple(double x, double q) {
  const double r = x / q;
  return std::abs(r - std::round(r)) < 1e-6 * std::max(1.0, std::abs(r)) + 1e-9;
}

double round_significant(double x, int digits) {
  if (x == 0.0 || !std::isfinite(x)) return x;
  const int e = static_cast<int>(std::floor(std::log10(std::abs(x))));
  const double q = std::pow(10.0, e - digits + 1);
  return std::round(x / q) * q;
}

/// Sums of squares of a channel over rows, pooled over runs: NRMS = sqrt(res / meas).
struct Pool {
  double res2{0.0}, meas2{0.0};
  std::size_t n{0};
  void add(double meas, double model) {
    res2 += (meas - model) * (meas - model);
    meas2 += meas * meas;
    ++n;
  }
  void add(const Pool& o) {
    res2 += o.res2;
    meas2 += o.meas2;
    n += o.n;
  }
};
using PoolSet = std::map<std::string, Pool>;

void pools_to_errors(const PoolSet& pools, ChannelErrors& out) {
  for (const auto& [key, p] : pools) {
    if (p.n < 3) {
      out.not_computed[key] = fmt::format("{} rows compared: too few", p.n);
    } else if (!(p.meas2 > 0.0)) {
      out.not_computed[key] = "the measured signal is zero on the rows compared";
    } else {
      const double v = std::sqrt(p.res2 / p.meas2);
      // 4 significant digits, as the drive calibration reports them.
      const double mag = std::pow(10.0, std::floor(std::log10(std::max(v, 1e-300))) - 3);
      out.nrms[key] = std::round(v / mag) * mag;
    }
  }
}

/// Commanded kinematics of an axis at the samples, segment by segment (the
/// monotone cubic the replay follows): speed and acceleration.
struct Kinematics {
  std::vector<double> v_mm_per_s, a_mm_per_s2;
};
Kinematics commanded_kinematics(const MeasuredRun& run, Axis a, const std::vector<Segment>& segs) {
  const auto& ref = run.trace.at(col(a, "_ref_mm"));
  const double dt = run.sample_period_s;
  Kinematics k;
  k.v_mm_per_s.assign(ref.size(), 0.0);
  k.a_mm_per_s2.assign(ref.size(), 0.0);
  for (const Segment& s : segs) {
    if (s.end - s.begin < 2) continue;
    const std::vector<double> r(ref.begin() + static_cast<std::ptrdiff_t>(s.begin),
                                ref.begin() + static_cast<std::ptrdiff_t>(s.end));
    const std::vector<double> sl = monotone_slopes(r);
    for (std::size_t i = 0; i < r.size(); ++i) k.v_mm_per_s[s.begin + i] = sl[i] / dt;
    for (std::size_t i = 0; i < r.size(); ++i) {
      const std::size_t lo = i == 0 ? 0 : i - 1, hi = std::min(i + 1, r.size() - 1);
      if (hi > lo) k.a_mm_per_s2[s.begin + i] = (sl[hi] - sl[lo]) / (static_cast<double>(hi - lo) * dt * dt);
    }
  }
  return k;
}

/// Rows inside segments away from their ends (the cubic's end slopes are one-sided).
std::vector<char> interior_rows(std::size_t n, const std::vector<Segment>& segs) {
  std::vector<char> in(n, 0);
  for (const Segment& s : segs) {
    if (s.end - s.begin < 5) continue;
    for (std::size_t r = s.begin + 2; r + 1 < s.end; ++r) in[r] = 1;
  }
  return in;
}

double percentile_abs(const std::vector<double>& v, double q) {
  std::vector<double> a;
  a.reserve(v.size());
  for (double x : v) a.push_back(std::abs(x));
  if (a.empty()) return 0.0;
  const auto k = static_cast<std::size_t>(q * static_cast<double>(a.size() - 1));
  std::nth_element(a.begin(), a.begin() + static_cast<std::ptrdiff_t>(k), a.end());
  return a[k];
}

/// A log whose rounding is coarser than the motion between two samples: its
/// positions rounded coarser than 5 um and sampled slower than 2 ms. A slow
/// move reads there as a staircase (prepare_run rebuilds it), and a slow
/// axis's steps round to zero about a jump (find_segments).
bool staircase_log(const MeasuredRun& run, double quantum_mm) {
  return quantum_mm > 0.005 && run.sample_period_s > 2e-3 + 1e-12;
}

/// Everything derived from one run that the fits and the errors use.
struct RunData {
  const MeasuredRun* run{nullptr};
  /// The run with its references rebuilt from the rounding staircase
  /// (dequantize_reference): what the replay follows and the kinematics come from.
  std::shared_ptr<MeasuredRun> smooth;
  std::vector<Segment> segments;
  std::vector<char> interior;
  std::size_t n{0}, n_fit{0};
  AxisArray<Kinematics> kin;
  AxisArray<double> v_move{};
};

RunData prepare_run(const MeasuredRun& run, const std::vector<Axis>& axes, const PositionRounding& rounding,
                    double fit_fraction, std::vector<std::string>& notes) {
  RunData d;
  d.run = &run;
  d.n = run.trace.num_rows();
  d.n_fit = static_cast<std::size_t>(fit_fraction * static_cast<double>(d.n));
  std::string seg_note;
  d.segments = find_segments(run, rounding.quantum_mm, std::nullopt, &seg_note);
  if (!seg_note.empty()) notes.push_back(fmt::format("{}: {}", run.dir.string(), seg_note));
  d.interior = interior_rows(d.n, d.segments);
  d.smooth = std::make_shared<MeasuredRun>(run);
  // A log at 2 ms or faster with its reference rounded to 1 um or coarser
  // (all positions agree with the rounding, so the command is rounded too:
  // an interpolator's own is finer; at 1 um, 1 kHz and kff 0.6 the replay's
  // torque error was 0.171 and tracking 0.0068 against 0.014 and 0.0019
  // with the reference as computed): several quanta a row,
  // and the staircase's rebuild keeps the rows themselves there, whose steps
  // the replayed loop's velocity feedforward turns into torque (at 10 um and
  // 1 kHz, kff times 10 mm/s a row: the cascade sweep's runs validated at a
  // torque error near 1). Low-passed without phase at the identification's
  // 50 Hz instead (torque 0.05 to 0.15 there; 25 to 200 Hz moved the
  // tracking error by under 5 %, and 50 Hz gave the lowest torque error).
  const bool fast = run.sample_period_s <= 2e-3 + 1e-12;
  if (fast && rounding.kind != PositionRounding::Kind::kNone && rounding.quantum_mm >= 0.001 - 1e-12) {
    for (Axis a : axes) {
      const std::string name = col(a, "_ref_mm");
      auto it = std::find(d.smooth->trace.names.begin(), d.smooth->trace.names.end(), name);
      auto& dst = d.smooth->trace.columns[static_cast<std::size_t>(it - d.smooth->trace.names.begin())];
      dst = lowpass_in_segments(dst, d.segments, run.sample_period_s);
    }
  } else if (rounding.kind != PositionRounding::Kind::kNone && staircase_log(run, rounding.quantum_mm)) {
    const auto& t = run.trace.at("t_s");
    for (Axis a : axes) {
      const std::string name = col(a, "_ref_mm");
      auto it = std::find(d.smooth->trace.names.begin(), d.smooth->trace.names.end(), name);
      auto& dst = d.smooth->trace.columns[static_cast<std::size_t>(it - d.smooth->trace.names.begin())];
      for (const Segment& sg : d.segments) {
        const std::vector<double> ts(t.begin() + static_cast<std::ptrdiff_t>(sg.begin),
                                     t.begin() + static_cast<std::ptrdiff_t>(sg.end));
        const std::vector<double> rs(dst.begin() + static_cast<std::ptrdiff_t>(sg.begin),
                                     dst.begin() + static_cast<std::ptrdiff_t>(sg.end));
        const std::vector<double> sm = dequantize_reference(ts, rs, rounding);
        std::copy(sm.begin(), sm.end(), dst.begin() + static_cast<std::ptrdiff_t>(sg.begin));
      }
    }
  }
  for (Axis a : axes) {
    d.kin[index(a)] = commanded_kinematics(*d.smooth, a, d.segments);
    d.v_move[index(a)] = std::max(0.02 * percentile_abs(d.kin[index(a)].v_mm_per_s, 0.99), 1e-9);
  }
  return d;
}

int direction(double v, double v_move) { return v > v_move ? 1 : (v < -v_move ? -1 : 0); }

/// The RMS of white noise from the |second differences| of a signal: their
/// median over 0.6745 is their standard deviation, 6 sigma^2 for white noise.
/// A smooth signal adds little where it is sampled at its loop's rate.
double white_noise_rms(std::vector<double> abs_d2) {
  if (abs_d2.empty()) return 0.0;
  const auto mid = abs_d2.begin() + static_cast<std::ptrdiff_t>(abs_d2.size() / 2);
  std::nth_element(abs_d2.begin(), mid, abs_d2.end());
  return *mid / 0.6745 / std::sqrt(6.0);
}

/// The white noise on a logged channel over the fitting rows of the runs'
/// segments.
double fitting_rows_noise_rms(const std::vector<RunData>& runs, const std::string& channel) {
  std::vector<double> d2;
  for (const auto& rd : runs) {
    const auto& ch = rd.run->trace.at(channel);
    for (const Segment& sg : rd.segments) {
      const std::size_t end = std::min(sg.end, rd.n_fit);
      for (std::size_t k = sg.begin + 1; k + 1 < end; ++k) d2.push_back(std::abs(ch[k + 1] - 2.0 * ch[k] + ch[k - 1]));
    }
  }
  return white_noise_rms(std::move(d2));
}

/// The white noise on a logged channel as a fit on it sees it: through the
/// speed's low-pass where laws on it are fitted so (has_lowpassed_twin).
double noise_as_fitted(const std::vector<RunData>& runs, const std::string& channel) {
  const double noise = fitting_rows_noise_rms(runs, channel);
  return has_lowpassed_twin(runs.front().run->trace, channel)
             ? noise * lowpass_noise_gain(runs.front().run->sample_period_s)
             : noise;
}

/// Rows a torque limit holds before the limit is taken for one (as many as
/// the saturation detector asks for).
constexpr std::size_t kClippedRows = 10;

/// The rows a limit must hold for the law's fit to leave them out and for
/// the saturation detector to look at it: kClippedRows (10 ms at 1 kHz), and
/// 4 on a log slower than 5 ms that the law is read from (up to
/// kLawFitMaxPeriod_s), where a limit reached in a move holds for a few rows
/// only: 6 fitting rows at 20 ms on the cascade sweep's run of twice the
/// middle limit, whose law was then not read and whose limit was not looked
/// at (the other program tracked at 0.034; 0.020 now, the limit named).
std::size_t clipped_rows(double dt_s) {
  return resolves_velocity_loop(dt_s) || dt_s > kLawFitMaxPeriod_s + 1e-12 ? kClippedRows : 4;
}

/// A torque limit seen in the log: a row is held by it where its |torque| is
/// within 10 % of the largest (less three times the white noise on the log:
/// the largest value of a noisy log sits some noise above the limit, and the
/// samples held scatter by the noise about it) and a first fit of the law
/// asks for more than the log, the same way, by over 2 % of that largest
/// value and three times the noise (else the samples the noise takes below
/// the law read as held: a 2 ms delay under 0.2 N m of noise was said to
/// flatten at a limit it does not have).
struct TorqueClip {
  std::vector<double> theta;  ///< the first fit's Kvp, Kvp / Tn
  std::vector<double> c_seg;  ///< and its constant per segment (VelocityLoopFit::c_seg)
  double T_abs_max{0.0};
  double noise_rms{0.0};
  bool holds(double law, double T) const {
    return std::abs(T) >= 0.9 * T_abs_max - 3.0 * noise_rms && law * T > 0.0 &&
           std::abs(law) > std::abs(T) + 0.02 * T_abs_max + 3.0 * noise_rms;
  }
};

/// The log's rows at a limit, fit_velocity_loop's limit_rows: per run, the
/// rows whose |torque| lies within 2 % of the fitting rows' largest (and
/// four times the white noise on the logged channel: the largest sits the
/// noise's reach above the limit), stretches under 5 rows apart joined (a
/// limit that holds the integral lets the command off it for a tick and
/// back), each widened by 2 rows (a current loop's lag rounds the log's
/// corners) and, where the law is fitted through the speed's low-pass, by
/// that filter's support (its columns spread the integral's step over it).
/// Returns the fitting rows at the limit and the median of their |torque|
/// (the limit's level).
struct RowsAtLimit {
  std::size_t held{0};
  double level{0.0};
};
/// The mark of a row at the limit itself in rows_at_limit's `at` (1: a row
/// about one, or between two a few rows apart).
constexpr char kAtLimitItself = 2;
RowsAtLimit rows_at_limit(const std::vector<RunData>& runs, const std::string& channel,
                          std::vector<std::vector<char>>& at) {
  const double noise_rms = fitting_rows_noise_rms(runs, channel);
  double T_max = 0.0;
  for (const RunData& rd : runs) {
    const std::vector<double>& T = rd.run->trace.at(channel);
    for (std::size_t k = 0; k < rd.n_fit; ++k) T_max = std::max(T_max, std::abs(T[k]));
  }
  const double from = T_max - std::max(0.02 * T_max, 4.0 * noise_rms);
  std::vector<double> held;
  at.assign(runs.size(), {});
  for (std::size_t r = 0; r < runs.size(); ++r) {
    const RunData& rd = runs[r];
    const std::vector<double>& T = rd.run->trace.at(channel);
    const double dt = rd.run->sample_period_s;
    const auto widen = static_cast<std::ptrdiff_t>(
        2 + (has_lowpassed_twin(rd.run->trace, channel) ? std::lround(1.0 / (kSpeedCutoff_Hz * dt)) : 0));
    const auto n = static_cast<std::ptrdiff_t>(rd.n_fit);
    std::vector<char>& m = at[r];
    m.assign(rd.n, 0);
    std::ptrdiff_t last = -1000;  // the last row at the limit
    for (std::ptrdiff_t k = 0; k < n; ++k) {
      if (!(std::abs(T[static_cast<std::size_t>(k)]) >= from && from > 0.0)) continue;
      held.push_back(std::abs(T[static_cast<std::size_t>(k)]));
      const std::ptrdiff_t lo = k - last < 5 ? last : k - widen;
      for (std::ptrdiff_t j = std::max<std::ptrdiff_t>(lo, 0); j <= std::min(k + widen, n - 1); ++j)
        m[static_cast<std::size_t>(j)] = std::max<char>(m[static_cast<std::size_t>(j)], 1);
      m[static_cast<std::size_t>(k)] = kAtLimitItself;
      last = k;
    }
  }
  if (held.empty()) return {};
  std::nth_element(held.begin(), held.begin() + static_cast<std::ptrdiff_t>(held.size() / 2), held.end());
  return {held.size(), held[held.size() / 2]};
}

/// The command's acceleration as the loop takes it for a torque
/// feedforward, on a log that samples every loop period: the backward
/// difference of the backward difference of the reference, within each
/// segment (0 on its first two rows), low-passed alike where the law is
/// fitted through the low-pass (the speed taken from the position).
std::vector<double> reference_acceleration(const RunData& rd, Axis a, const std::string& channel) {
  const io::TraceTable& t = rd.run->trace;
  const std::vector<double>& ref = t.at(col(a, "_ref_mm"));
  const double dt = rd.run->sample_period_s;
  std::vector<double> acc(ref.size(), 0.0);
  for (const Segment& sg : rd.segments)
    for (std::size_t k = sg.begin + 2; k < sg.end; ++k)
      acc[k] = (ref[k] - 2.0 * ref[k - 1] + ref[k - 2]) / (dt * dt);
  return has_lowpassed_twin(t, channel) ? lowpass_in_segments(acc, rd.segments, dt) : acc;
}

/// The PI velocity law fitted on the fitting rows: the logged torque at row k
/// against the speed error (vcmd - v) and its integral at row k - lag (within
/// a segment), and a constant per segment: the integral's value where the
/// segment starts, which a log that starts (or resumes after a stitch or a
/// gap) with the axis under load or in motion does not hold. Fitted on the
/// rows less their segment's means, which gives the gains of the fit with a
/// constant per segment without a column for each. With `clip`, the rows a
/// torque limit holds are left out (the limit sets the torque there, not the
/// law). With `current_lag`, the previous row's torque is a third column: a
/// current loop that lags the law as a first order at the log's period,
/// T[k] = a T[k-1] + (1 - a) law[k], gives a as its coefficient and the law's
/// gains times (1 - a) as the others. With `lag_a` > 0 the law's columns pass
/// through that lag, y[k] = a y[k-1] + (1 - a) x[k] from the segment's first
/// value, before they are fitted: a current loop whose lag is given (output
/// error, which noise on the speed does not bias towards a slow lag). With
/// `lead_period_mm` > 0, four columns of an encoder that reads the motor's
/// travel plus e(x) = s sin(w x) + c cos(w x), w = 2 pi / that period, come
/// before Jff: where the speed is the encoder's own, the law's integral of
/// the speed error is short by e and its speed error by de/dt, so the law
/// gains Ki e + Kvp de/dt: sin(w x), cos(w x), w v cos(w x), -w v sin(w x)
/// (x the logged position, v the speed; through the same lag and dead time).
/// With `by_table_motion`, the constants are per stretch of the axis's own
/// motion (the speed beyond the moving threshold one way, less a low-pass
/// support, 1 / cutoff, at each end), not per segment, and only those rows
/// are fitted: where the speed is the encoder's own, a gap between the motor
/// and the encoder parts them only while the encoder's side stands, and
/// shifts the law's integral by the part between stretches. With
/// `limit_rows` (per run, the log's rows a limit holds the torque at), those
/// rows are not fitted and (with `constant_after_limit`) each row after such
/// a stretch starts a new constant: a limit that holds the integral while
/// it clamps (anti-windup) leaves it short of the running sum by what the
/// stretch would have added.
struct VelocityLoopFit {
  LsqResult ls;  ///< Kvp, Kvp / Tn (then a, with current_lag; then the lead columns; then Jff, with torque_ff)
  bool torque_ff{false};
  /// The constant of each segment (or stretch of motion, by_table_motion),
  /// in the order of the runs' segments (0 where it has no row fitted), its
  /// rows fitted, and the direction of the motion (0: a whole segment).
  std::vector<double> c_seg, rows_seg;
  std::vector<int> dir_seg;
  /// With a new constant after each stretch at a limit: the constant before
  /// and after it, and the speed error's integral over the stretch's rows
  /// (mm), which a limit that holds the integral leaves out of the sum.
  struct LimitStep {
    std::size_t before{0}, after{0};
    double held_integral_mm{0.0};
  };
  std::vector<LimitStep> limit_steps;
  /// Where the law has limit_steps: how much of the held integrals the
  /// constants' steps carry (the least-squares slope of each step on -Ki
  /// times its held integral, over the rows at the limit itself): near 1
  /// where the limit holds the integral, 0 where it runs on; 0 where no step
  /// has rows on both sides.
  double held_share() const {
    double num = 0.0, den = 0.0;
    for (const LimitStep& st : limit_steps) {
      if (!(st.before < rows_seg.size() && st.after < rows_seg.size() && rows_seg[st.before] > 0.0 &&
            rows_seg[st.after] > 0.0 && ls.ok))
        continue;
      const double step = c_seg[st.after] - c_seg[st.before], held = -ls.theta[1] * st.held_integral_mm;
      num += step * held;
      den += held * held;
    }
    return den > 0.0 ? num / den : 0.0;
  }
  double T_rms{0.0};
  /// The largest |torque| of the rows fitted, and how many of those rows a
  /// limit at it holds by this fit (TorqueClip).
  double T_abs_max{0.0};
  std::size_t held_by_limit{0};
  /// The white noise on the logged torque: from the median |second
  /// difference| within segments (6 sigma^2 for white noise; a smooth torque
  /// adds little at the loop's rate, a filtered noise shows less).
  double noise_rms{0.0};
  /// The RMS of the residual's change from one fitted row to the next, and
  /// of the torque's (rows of the same constant).
  double step_residual_rms{0.0}, step_T_rms{0.0};
  /// An RMS of the logged torque (or of a residual of it) less the white
  /// noise, which no law fits.
  double less_noise(double rms) const { return std::sqrt(std::max(rms * rms - noise_rms * noise_rms, 0.0)); }
  /// The same of a change from row to row, which carries twice the noise's variance.
  double step_less_noise(double rms) const {
    return std::sqrt(std::max(rms * rms - 2.0 * noise_rms * noise_rms, 0.0));
  }
  /// Gains a loop can have: Kvp > 0, Kvp / Tn >= 0, and Jff >= 0 where fitted.
  /// On a log slower than the loop by `excess_s` a row, the law's integral
  /// summed once a row is short by half that excess of the speed error,
  /// which the first coefficient takes off Kvp (set_velocity_loop).
  bool gains_physical(double excess_s = 0.0) const {
    return ls.ok && ls.theta[0] + 0.5 * ls.theta[1] * excess_s > 0.0 && ls.theta[1] >= 0.0 &&
           (!torque_ff || ls.theta.back() >= 0.0);
  }
};
/// The columns and rows fit_velocity_loop fits with (see above).
struct LawFitOptions {
  std::size_t lag{0};
  double lag_fraction{0.0};  ///< a part of a row beyond `lag` (0 to 1): the columns taken between two rows
  const TorqueClip* clip{nullptr};
  bool current_lag{false};
  double lag_a{0.0};
  bool torque_ff{false};
  double lead_period_mm{0.0};
  bool by_table_motion{false};
  const std::vector<std::vector<char>>* limit_rows{nullptr};
  bool constant_after_limit{true};  ///< with limit_rows: false leaves the rows out, the constants as they are
  /// The velocity loop's ticks per row: its integral summed over them (see
  /// fit_velocity_loop); 1: once a row, on the row's speed error.
  int inner_ticks{1};
  /// With inner_ticks > 1: the drive's inertia (the channel's unit per
  /// mm/s^2) the loop's speed bends by within the row (see
  /// fit_velocity_loop; 0: the speed taken as a line); law_options sets it.
  double bend_J{0.0};
  /// The bend's part of the sum per unit of the speed's change (s), from
  /// bend_J and the law's Kvp (fit_velocity_loop sets it).
  double bend_s{0.0};
  /// With inner_ticks > 1: the logged torque at a row is the mean of the
  /// law's torques over the ticks of the period before it (a drive that
  /// averages what it traces), not the torque of the row's own tick.
  bool period_mean{false};
};
/// The velocity loop's ticks before the row's own that `o` takes the law's
/// columns at (LawFitOptions::lag_fraction times inner_ticks, where that is
/// a whole count of ticks of a law that logs its tick's torque), else 0.
int tick_lag_of(const LawFitOptions& o) {
  if (o.inner_ticks <= 1 || o.period_mean || !(o.lag_fraction > 0.0)) return 0;
  const double t = o.lag_fraction * o.inner_ticks;
  const long r = std::lround(t);
  return r >= 1 && r < o.inner_ticks && std::abs(t - static_cast<double>(r)) < 1e-9 ? static_cast<int>(r) : 0;
}
/// The share of the integral held over the stretches at a limit that the
/// law's constants must step by after them for the limit to be read as
/// holding the integral (VelocityLoopFit::held_share: 0.42 and 0.43 on the
/// truth's limits that hold it, 0.000 and 0.003 on those that let it run on).
constexpr double kHeldShareOfAntiWindup = 0.15;
/// The rows over which the integral of a law taken at a tick between rows
/// is pulled to the one the position's change gives (fit_velocity_loop).
constexpr double kTickSumDriftRows = 10.0;
/// Where the lead columns start in VelocityLoopFit::ls.theta.
std::size_t lead_column(const LawFitOptions& o) { return o.current_lag ? 3 : 2; }
/// `o` with what the axis's law has been found to need where the speed is
/// the encoder's own: its lead error's columns, its constants by the
/// stretches of motion (a gap).
LawFitOptions law_options(const AxisFromData& ax, LawFitOptions o) {
  o.lead_period_mm = ax.law_lead_period_mm;
  o.by_table_motion = ax.law_gap_mm > 0.0;
  if (ax.law_holds_integral_at_limit()) o.limit_rows = &ax.law_limit_rows;
  o.inner_ticks = ax.law_inner_ticks;
  o.bend_J = ax.law_inner_ticks > 1 ? ax.J : 0.0;
  o.period_mean = ax.logs_period_mean();
  return o;
}
VelocityLoopFit fit_velocity_loop(const std::vector<RunData>& runs, Axis a, const std::string& channel,
                                  const LawFitOptions& o = {}) {
  const auto [lag, lag_fraction, clip, current_lag, lag_a, torque_ff, lead_period_mm, by_table_motion, limit_rows,
              constant_after_limit, inner_ticks, bend_J, bend_s, period_mean] = o;
  // The bend's share (below) from the law's Kvp: the law fitted without it
  // first. Not at a tick before the row's (a dead time of part of a row):
  // the speed then bends by the torques the ticks apply, the dead time's
  // ticks behind the law's, not by the law's own (with it, a 1 ms dead time
  // under a 2 ms loop left twice the residual of the straight line).
  const int tick_lag = tick_lag_of(o);
  if (inner_ticks > 1 && bend_J > 0.0 && bend_s == 0.0 && !runs.empty() && tick_lag == 0) {
    LawFitOptions straight_o = o;
    straight_o.bend_J = 0.0;
    VelocityLoopFit straight = fit_velocity_loop(runs, a, channel, straight_o);
    const double Kvp = straight.ls.ok ? straight.ls.theta[0] : 0.0, dt = runs.front().run->sample_period_s;
    if (!(Kvp > 0.0)) return straight;
    LawFitOptions bent = o;
    bent.bend_s = dt * dt * Kvp / bend_J / 12.0 * (1.0 - 1.0 / (inner_ticks * inner_ticks));
    return fit_velocity_loop(runs, a, channel, bent);
  }
  // A velocity loop that runs n times a row sums its speed error at each of
  // its ticks: from row k-1 to row k, n - 1 ticks on the command of row k-1
  // and the last on row k's (the tick the row is logged at), the speed
  // taken as moving linearly between the rows. The sum is then dt times the
  // command's (1 - 1/n, 1/n) and the speed's (1 - b, b) mix of the two
  // rows, b = (n + 1) / (2 n): the row's own error for n = 1, the
  // trapezoid for a loop much faster than the log.
  const double w_cmd = 1.0 / inner_ticks, w_speed = (inner_ticks + 1.0) / (2.0 * inner_ticks);
  // Within the row the loop's own proportional action bends the speed off
  // that line: the torque falls by Kvp times the speed's rise, so the
  // acceleration falls over the row by the share dt Kvp / J, and the sum of
  // the ticks' speeds exceeds the line's by bend_s = dt^2 Kvp / (12 J)
  // (1 - 1/n^2) times the row's change of speed. Over a segment that is
  // bend_s times the speed's change since it began, taken off the integral
  // (a 125 us loop under a 1 ms one: residual 0.16 without it, 0.080 with it
  // against the log's 0.080 of noise; Kvp and Ki within 0.1 %; a free column
  // of the speed fitted it as well, 5.0e-6 s against 4.9e-6 s so, but took
  // the count of ticks' share of the sum and the steps of a gap too).
  const bool speed_col = inner_ticks > 1 && bend_s > 0.0 && tick_lag == 0;
  // A column `lag` (and lag_fraction) rows back, from row j of its segment;
  // 0 before its first row. Between two rows a cubic through the four
  // about (Catmull-Rom), linear where the outer two are not in the segment.
  const std::size_t back = lag + (lag_fraction > 0.0 ? 1 : 0);
  // With inner_ticks > 1 (the row's own tick logged), a part of a row that
  // is a whole count of the velocity loop's ticks is taken at that tick
  // exactly (below), not off the cubic: the tick holds row k-1's command,
  // which the cubic mixes with row k's.
  const auto lagged = [&](const std::vector<double>& c, std::size_t j) {
    if (j < back) return 0.0;
    if (lag_fraction == 0.0 || tick_lag > 0) return c[j - lag];
    const double u = lag_fraction, p1 = c[j - lag], p2 = c[j - lag - 1];
    if (j < lag + 2 || j - lag + 1 >= c.size()) return (1.0 - u) * p1 + u * p2;
    return catmull_rom(c[j - lag + 1], p1, p2, c[j - lag - 2], u);
  };
  const bool lead = lead_period_mm > 0.0;
  const double w = lead ? 2.0 * M_PI / lead_period_mm : 0.0;
  std::vector<double> ev, iev, Tm, Tp, aff;
  std::array<std::vector<double>, 4> ld;  // the lead columns
  std::vector<std::size_t> vrows, seg_of_row;
  std::vector<int> dir_of;
  std::vector<VelocityLoopFit::LimitStep> limit_steps;
  std::size_t g = 0;  // the constants' count over all runs
  for (std::size_t ri = 0; ri < runs.size(); ++ri) {
    const RunData& rd = runs[ri];
    const auto& t = rd.run->trace;
    const std::vector<char>* at_limit = limit_rows ? &(*limit_rows)[ri] : nullptr;
    const auto& vc = *filtered_alike(t, velocity_command_column(t, a));
    const auto& v = t.at(col(a, "_v_mm_s"));
    const auto& ch = *filtered_alike(t, channel);
    const std::vector<double> a_ref = torque_ff ? reference_acceleration(rd, a, channel) : std::vector<double>{};
    const std::vector<double>* xm = lead ? &t.at(col(a, "_mm")) : nullptr;
    for (std::size_t si = 0; si < rd.segments.size(); ++si) {
      const Segment& s = rd.segments[si];
      const std::size_t seg_group = g++;
      dir_of.push_back(0);
      const std::size_t end = std::min(s.end, rd.n_fit);
      if (end <= s.begin) continue;
      // The constant each row is fitted with; rows of seg_group are not
      // fitted where the constants follow the motion.
      std::vector<std::size_t> group(end - s.begin, seg_group);
      if (by_table_motion) {
        const auto margin =
            static_cast<std::size_t>(std::lround(1.0 / (kSpeedCutoff_Hz * rd.run->sample_period_s)));
        for (std::size_t k = s.begin; k < end;) {
          const int d = direction(v[k], rd.v_move[index(a)]);
          std::size_t j = k + 1;
          while (j < end && direction(v[j], rd.v_move[index(a)]) == d) ++j;
          if (d != 0 && j - k > 2 * margin + 10) {
            for (std::size_t r = k + margin; r < j - margin; ++r) group[r - s.begin] = g;
            dir_of.push_back(d);
            ++g;
          }
          k = j;
        }
      }
      // A new constant from each row after a stretch at the limit on, to
      // the end of its segment or stretch of motion.
      if (at_limit && constant_after_limit)
        for (std::size_t k = s.begin + 1; k < end; ++k) {
          const std::size_t old = group[k - s.begin];
          if (!(*at_limit)[k - 1] || (*at_limit)[k] || (by_table_motion && old == seg_group)) continue;
          dir_of.push_back(dir_of[old]);
          const std::size_t fresh = g++;
          for (std::size_t j = k; j < end && group[j - s.begin] == old; ++j) group[j - s.begin] = fresh;
          double held = 0.0;
          for (std::size_t j = k; j > s.begin && (*at_limit)[j - 1]; --j)
            if ((*at_limit)[j - 1] == kAtLimitItself) held += rd.run->sample_period_s * (vc[j - 1] - v[j - 1]);
          limit_steps.push_back({old, fresh, held});
        }
      std::vector<double> e(end - s.begin), ie(end - s.begin), ar, sv;
      // The speed's change summed over the rows the law's torque drives;
      // on a limit's rows the torque stands, the speed moves on the line
      // and the sum takes nothing.
      if (speed_col) {
        sv.assign(end - s.begin, v[s.begin]);
        for (std::size_t k = s.begin + 1; k < end; ++k)
          sv[k - s.begin] = sv[k - 1 - s.begin] + (at_limit && (*at_limit)[k] ? 0.0 : v[k] - v[k - 1]);
      }
      std::array<std::vector<double>, 4> l;
      if (torque_ff) ar.assign(a_ref.begin() + static_cast<std::ptrdiff_t>(s.begin),
                               a_ref.begin() + static_cast<std::ptrdiff_t>(end));
      double integral = 0.0;
      for (std::size_t k = s.begin; k < end; ++k) {
        e[k - s.begin] = vc[k] - v[k];
        if (inner_ticks > 1 && k > s.begin)
          integral += rd.run->sample_period_s * (w_cmd * vc[k] + (1.0 - w_cmd) * vc[k - 1] - w_speed * v[k] -
                                                 (1.0 - w_speed) * v[k - 1]);
        else
          integral += e[k - s.begin] * rd.run->sample_period_s;
        ie[k - s.begin] = integral - (speed_col ? bend_s * sv[k - s.begin] : 0.0);
        if (lead) {
          const double sn = std::sin(w * (*xm)[k]), cs = std::cos(w * (*xm)[k]);
          l[0].push_back(sn);
          l[1].push_back(cs);
          l[2].push_back(w * v[k] * cs);
          l[3].push_back(-w * v[k] * sn);
        }
      }
      // A logged mean over the period before row k (ticks q = 0 .. n-1 from
      // row k-1's, all on row k-1's command, the speed moving linearly to
      // row k's by dv): the ticks' mean speed error is row k-1's command
      // less the speed's mix ((n+1)/(2n), (n-1)/(2n)) of the two rows, and
      // their mean integral is row k-1's plus Tv (n-1)/2 of its error less
      // Tv dv (n^2-1)/(6n); the speed's bend within the row (above) raises
      // its mean over the ticks by bend_s / dt times dv. The feedforward
      // is row k-1's, a lead error's columns the two rows' mean.
      if (period_mean && inner_ticks > 1) {
        const double n = inner_ticks, dt = rd.run->sample_period_s;
        const std::vector<double> e_tick = e, ie_tick = ie, ar_tick = ar;
        std::array<std::vector<double>, 4> l_tick = l;
        for (std::size_t j = 1; j < e.size(); ++j) {
          const std::size_t k = s.begin + j;
          const double dv = v[k] - v[k - 1];
          e[j] = vc[k - 1] - (n + 1.0) / (2.0 * n) * v[k - 1] - (n - 1.0) / (2.0 * n) * v[k] -
                 (speed_col ? bend_s / dt * dv : 0.0);
          ie[j] = ie_tick[j - 1] + dt * (n - 1.0) / (2.0 * n) * e_tick[j - 1] - dt * dv * (n * n - 1.0) / (6.0 * n * n);
          if (torque_ff) ar[j] = ar_tick[j - 1];
          if (lead)
            for (std::size_t c = 0; c < 4; ++c) l[c][j] = 0.5 * (l_tick[c][j - 1] + l_tick[c][j]);
        }
      }
      // The tick tick_lag ticks before row k's, q = n - tick_lag ticks after
      // row k-1's: its error is on row k-1's command and the speed at q/n of
      // the row; its integral is the ticks' errors times dt / n summed to it.
      // The speed between two rows is read off the cubic through the four
      // about (the line where those are not in the segment): on the line, a
      // 2 ms dead time under a 4 ms loop over a 1 ms velocity loop fitted
      // best a tick early. Summed a whole row at a time, the cubic's small
      // error each row (0.016 mm/s RMS at the middle tick of a 4 ms row)
      // drifts through the integral, whose gain is large (1570 raw per mm
      // there): where the drive's speed and the position are logged (no
      // lead error's or gap's columns, which part the two), the row's sum of
      // the ticks' speeds is also the position's change plus Tv/2 the
      // speed's (the speed moves linearly over each tick under its held
      // torque), and the integral is pulled to that over kTickSumDriftRows
      // rows (the position's change alone carries its rounding into every
      // row: residual 0.46 against 0.31 so at 4 ms, 0.26 against 0.17 at 2
      // ms; the cubic alone 1.41 and 0.50). The feedforward is row k-1's, a
      // lead error's columns taken at q/n between the rows.
      if (tick_lag > 0) {
        const int n = inner_ticks, q = n - tick_lag;
        const double Tv = rd.run->sample_period_s / n;
        const auto speed_at = [&](std::size_t k, int tk) {  // tk ticks after row k - 1's, 0 < tk <= n
          const double u = static_cast<double>(tk) / n;
          if (tk == n) return v[k];
          if (k < s.begin + 2 || k + 1 >= end) return (1.0 - u) * v[k - 1] + u * v[k];
          return catmull_rom(v[k - 2], v[k - 1], v[k], v[k + 1], u);
        };
        const std::vector<double> ar_tick = ar;
        std::array<std::vector<double>, 4> l_tick = l;
        const std::vector<double>* x_row =
            lead || by_table_motion || has_lowpassed_twin(t, channel) ? nullptr : t.find(col(a, "_mm"));
        const double keep_drift = std::exp(-1.0 / kTickSumDriftRows);
        double I_cubic = ie[0];  // the integral at row k - 1's tick, summed off the cubic alone
        double I_pos = ie[0];    // the same from the position's change
        double drift = 0.0;      // I_pos - I_cubic, low-passed
        for (std::size_t j = 1; j < e.size(); ++j) {
          const std::size_t k = s.begin + j;
          double row_sum = 0.0;  // the ticks' errors times Tv from row k - 1's on
          for (int tk = 1; tk < n; ++tk) {
            const double speed = speed_at(k, tk);
            row_sum += Tv * (vc[k - 1] - speed);
            if (tk == q) {
              e[j] = vc[k - 1] - speed;
              ie[j] = I_cubic + drift + row_sum;
            }
          }
          I_cubic += row_sum + Tv * (vc[k] - v[k]);
          if (x_row != nullptr) {
            I_pos += Tv * ((n - 1) * vc[k - 1] + vc[k]) - ((*x_row)[k] - (*x_row)[k - 1]) -
                     0.5 * Tv * (v[k] - v[k - 1]);
            drift = keep_drift * drift + (1.0 - keep_drift) * (I_pos - I_cubic);
          }
          const double sq = static_cast<double>(q) / n;
          if (torque_ff) ar[j] = ar_tick[j - 1];
          if (lead)
            for (std::size_t c = 0; c < 4; ++c) l[c][j] = (1.0 - sq) * l_tick[c][j - 1] + sq * l_tick[c][j];
        }
      }
      if (lag_a > 0.0)
        for (std::vector<double>* c : {&e, &ie, &ar, &l[0], &l[1], &l[2], &l[3]}) {
          if (c->empty()) continue;
          double y = c->front();
          for (double& x : *c) x = y = lag_a * y + (1.0 - lag_a) * x;
        }
      for (std::size_t k = s.begin; k < end; ++k) {
        const std::size_t j = k - s.begin;
        ev.push_back(lagged(e, j));
        iev.push_back(lagged(ie, j));
        if (torque_ff) aff.push_back(lagged(ar, j));
        if (lead)
          for (std::size_t c = 0; c < 4; ++c) ld[c].push_back(lagged(l[c], j));
        Tm.push_back(ch[k]);
        Tp.push_back(j >= 1 ? ch[k - 1] : 0.0);
        const std::size_t grp = group[j];
        seg_of_row.push_back(grp);
        if (k < s.begin + 2 + back || (by_table_motion && grp == seg_group) || (at_limit && (*at_limit)[k])) continue;
        if (clip && clip->holds(clip->theta[0] * ev.back() + clip->theta[1] * iev.back() + clip->c_seg[grp], ch[k]))
          continue;
        vrows.push_back(ev.size() - 1);
      }
    }
  }
  // Each constant's (segment's or stretch's) means over its rows fitted, taken off.
  std::vector<double> n_seg(g, 0.0), me(g, 0.0), mie(g, 0.0), mT(g, 0.0), mTp(g, 0.0), ma(g, 0.0);
  std::array<std::vector<double>, 4> ml;
  for (auto& m : ml) m.assign(lead ? g : 0, 0.0);
  for (std::size_t k : vrows) {
    const std::size_t sg = seg_of_row[k];
    n_seg[sg] += 1.0;
    me[sg] += ev[k];
    mie[sg] += iev[k];
    mT[sg] += Tm[k];
    mTp[sg] += Tp[k];
    if (torque_ff) ma[sg] += aff[k];
    if (lead)
      for (std::size_t c = 0; c < 4; ++c) ml[c][sg] += ld[c][k];
  }
  for (std::size_t sg = 0; sg < g; ++sg)
    if (n_seg[sg] > 0.0) {
      me[sg] /= n_seg[sg];
      mie[sg] /= n_seg[sg];
      mT[sg] /= n_seg[sg];
      mTp[sg] /= n_seg[sg];
      ma[sg] /= n_seg[sg];
      if (lead)
        for (auto& m : ml) m[sg] /= n_seg[sg];
    }
  std::vector<double> ev0(ev.size()), iev0(ev.size()), Tm0(ev.size()), Tp0(ev.size()), a0(aff.size());
  std::array<std::vector<double>, 4> l0;
  for (std::size_t c = 0; c < 4; ++c) l0[c].resize(ld[c].size());
  for (std::size_t k = 0; k < ev.size(); ++k) {
    const std::size_t sg = seg_of_row[k];
    ev0[k] = ev[k] - me[sg];
    iev0[k] = iev[k] - mie[sg];
    Tm0[k] = Tm[k] - mT[sg];
    Tp0[k] = Tp[k] - mTp[sg];
    if (torque_ff) a0[k] = aff[k] - ma[sg];
    if (lead)
      for (std::size_t c = 0; c < 4; ++c) l0[c][k] = ld[c][k] - ml[c][sg];
  }
  VelocityLoopFit f;
  f.torque_ff = torque_ff;
  std::vector<const std::vector<double>*> cols{&ev0, &iev0};
  if (current_lag) cols.push_back(&Tp0);
  if (lead)
    for (const auto& c : l0) cols.push_back(&c);
  if (torque_ff) cols.push_back(&a0);
  f.ls = least_squares(cols, Tm0, vrows);
  f.c_seg.assign(g, 0.0);
  f.rows_seg = n_seg;
  f.dir_seg = dir_of;
  f.limit_steps = std::move(limit_steps);
  if (f.ls.ok)
    for (std::size_t sg = 0; sg < g; ++sg)
      if (n_seg[sg] > 0.0) {
        f.c_seg[sg] = mT[sg] - f.ls.theta[0] * me[sg] - f.ls.theta[1] * mie[sg] -
                      (current_lag ? f.ls.theta[2] * mTp[sg] : 0.0) - (torque_ff ? f.ls.theta.back() * ma[sg] : 0.0);
        if (lead)
          for (std::size_t c = 0; c < 4; ++c) f.c_seg[sg] -= f.ls.theta[lead_column(o) + c] * ml[c][sg];
      }
  double t2 = 0.0;
  for (std::size_t k : vrows) {
    t2 += Tm[k] * Tm[k];
    f.T_abs_max = std::max(f.T_abs_max, std::abs(Tm[k]));
  }
  f.T_rms = vrows.empty() ? 0.0 : std::sqrt(t2 / static_cast<double>(vrows.size()));
  // Where the law is fitted through the speed's low-pass, the noise left in
  // its torque is the logged noise through that filter (taken whole, it
  // exceeded the filtered law's residual, and every rule that asks a
  // residual less the noise to fall compared zero with zero).
  f.noise_rms = noise_as_fitted(runs, channel);
  // The law's misfit from one fitted row to the next (of the same
  // constant), against the torque's own change: where the integral is
  // summed between the rows of a log slower than the loop, its small error
  // each row adds up over a segment to a drift the constant does not take,
  // and the misfit in levels tells that drift, not the law.
  if (f.ls.ok) {
    std::vector<double> r(ev.size(), 0.0);
    std::vector<char> fitted(ev.size(), 0);
    for (std::size_t k : vrows) {
      double pred = f.ls.theta[0] * ev[k] + f.ls.theta[1] * iev[k] + f.c_seg[seg_of_row[k]];
      if (current_lag) pred += f.ls.theta[2] * Tp[k];
      if (lead)
        for (std::size_t c = 0; c < 4; ++c) pred += f.ls.theta[lead_column(o) + c] * ld[c][k];
      if (torque_ff) pred += f.ls.theta.back() * aff[k];
      r[k] = Tm[k] - pred;
      fitted[k] = 1;
    }
    double sr = 0.0, sT = 0.0, n = 0.0;
    for (std::size_t k : vrows)
      if (k > 0 && fitted[k - 1] && seg_of_row[k - 1] == seg_of_row[k]) {
        sr += (r[k] - r[k - 1]) * (r[k] - r[k - 1]);
        sT += (Tm[k] - Tm[k - 1]) * (Tm[k] - Tm[k - 1]);
        n += 1.0;
      }
    if (n > 0.0) {
      f.step_residual_rms = std::sqrt(sr / n);
      f.step_T_rms = std::sqrt(sT / n);
    }
  }
  if (f.ls.ok && !current_lag) {
    const TorqueClip c{f.ls.theta, f.c_seg, f.T_abs_max, f.noise_rms};
    for (std::size_t k : vrows)
      if (c.holds(f.ls.theta[0] * ev[k] + f.ls.theta[1] * iev[k] + f.c_seg[seg_of_row[k]], Tm[k])) ++f.held_by_limit;
  }
  return f;
}

}  // namespace

// ---------------------------------------------------------------------------
// Data checks

double PositionRounding::round(double x) const {
  switch (kind) {
    case Kind::kDecimals:
      return std::round(x / quantum_mm) * quantum_mm;
    case Kind::kSignificant:
      return round_significant(x, digits);
    case Kind::kNone:
      break;
  }
  return x;
}

std::string PositionRounding::describe() const {
  switch (kind) {
    case Kind::kDecimals:
      return fmt::format("positions logged to {} decimal(s) ({:g} mm)", digits, quantum_mm);
    case Kind::kSignificant:
      return fmt::format("positions logged to {} significant figures ({:g} mm at the run's largest position)", digits,
                         quantum_mm);
    case Kind::kNone:
      break;
  }
  return "positions logged at full precision";
}

namespace {

/// The coarsest rounding the columns `suffixes` of every axis agree with.
PositionRounding detect_rounding_of(const MeasuredRun& run, std::initializer_list<const char*> suffixes) {
  std::vector<const std::vector<double>*> cols;
  for (Axis a : run.axes)
    for (const char* s : suffixes)
      if (const auto* c = run.trace.find(col(a, s))) cols.push_back(c);
  PositionRounding r;
  double max_abs = 0.0;
  for (const auto* c : cols)
    for (double x : *c) max_abs = std::max(max_abs, std::abs(x));
  auto all = [&](auto pred) {
    for (const auto* c : cols)
      for (double x : *c)
        if (!pred(x)) return false;
    return true;
  };
  int decimals = -1;
  for (int d = 0; d <= 6 && decimals < 0; ++d) {
    const double q = std::pow(10.0, -d);
    if (all([&](double x) { return is_multiple(x, q); })) decimals = d;
  }
  int sig = -1;
  for (int s = 1; s <= 7 && sig < 0; ++s)
    if (all([&](double x) { return std::abs(round_significant(x, s) - x) <= 1e-9 * std::max(1.0, std::abs(x)); }))
      sig = s;
  const double q_sig =
      sig > 0 && max_abs > 0.0 ? std::pow(10.0, std::floor(std::log10(max_abs)) - sig + 1) : 0.0;
  const double q_dec = decimals >= 0 ? std::pow(10.0, -decimals) : 0.0;
  if (sig > 0 && sig <= 5 && q_sig > 1.5 * q_dec) {
    r.kind = PositionRounding::Kind::kSignificant;
    r.digits = sig;
    r.quantum_mm = q_sig;
  } else if (decimals >= 0) {
    r.kind = PositionRounding::Kind::kDecimals;
    r.digits = decimals;
    r.quantum_mm = q_dec;
  }
  return r;
}

}  // namespace

PositionRounding detect_rounding(const MeasuredRun& run) { return detect_rounding_of(run, {"_ref_mm", "_mm"}); }

namespace {

/// The largest change of an axis's step at row k against both neighbouring
/// steps: a speed held for one row only, as a stitch leaves it. 0 where row k
/// has no step on both sides.
double one_row_speed_change(const std::vector<double>& c, std::size_t k) {
  if (k < 2 || k + 1 >= c.size()) return 0.0;
  const double s = c[k] - c[k - 1];
  return std::min(std::abs(s - (c[k - 1] - c[k - 2])), std::abs(s - (c[k + 1] - c[k])));
}

/// A logger that writes its samples in blocks of P rows and drops some blocks
/// leaves jumps every P rows (or P + 1, where its clock drifts by a row); on
/// the U-Mich logs most intervals between the jumps found are 10 rows and
/// most of the rest 11, 20 or 21. Between two jumps a block or more apart, the
/// boundary a dropped block left can be a smaller jump than the rules above
/// see: a speed held for one row only (umich10, t = 113.0 s: x steps 1, 6
/// then -2 mm while y and z step for that row alone). There, at least P - 1
/// rows from either jump, the row whose one-row speed change is largest
/// starts a segment where that change is over 3 quanta and over any the axis
/// shows inside a block bounded by two jumps P or P + 1 rows apart (the
/// axis's own moves, its rapids' starts and stops among them) by more than
/// the rounding can add to it (2 quanta: each of the three rows is off by
/// half a quantum at most, the middle one counting twice). Adds the rows
/// to `cuts` (kept in order) and says how many, and P.
struct BlockJumps {
  std::size_t added{0};       ///< rows added to the cuts
  std::size_t block_rows{0};  ///< P: the logger's block (0 where none recurs)
};
BlockJumps block_boundary_jumps(std::size_t n, const std::vector<std::vector<const std::vector<double>*>>& axis_cols,
                                double quantum_mm, std::vector<std::size_t>& cuts) {
  if (cuts.size() < 6) return {};
  std::map<std::size_t, std::size_t> intervals;
  for (std::size_t i = 1; i < cuts.size(); ++i) ++intervals[cuts[i] - cuts[i - 1]];
  std::size_t P = 0, best = 0;
  for (const auto& [len, count] : intervals)
    if (count > best) {
      best = count;
      P = len;
    }
  const auto count_of = [&](std::size_t len) {
    const auto it = intervals.find(len);
    return it == intervals.end() ? std::size_t{0} : it->second;
  };
  if (P < 4 || 2 * (count_of(P) + count_of(P + 1)) < cuts.size() - 1) return {};
  // What each axis shows inside the blocks the jumps found bound.
  std::vector<double> inside(axis_cols.size(), 0.0);
  for (std::size_t i = 1; i < cuts.size(); ++i) {
    if (cuts[i] - cuts[i - 1] > P + 1) continue;
    for (std::size_t k = cuts[i - 1] + 2; k + 2 <= cuts[i]; ++k)
      for (std::size_t a = 0; a < axis_cols.size(); ++a)
        for (const auto* c : axis_cols[a]) inside[a] = std::max(inside[a], one_row_speed_change(*c, k));
  }
  const auto excess = [&](std::size_t k) {
    double e = 0.0;
    for (std::size_t a = 0; a < axis_cols.size(); ++a) {
      const double limit = std::max(inside[a] + 2.0 * quantum_mm, 3.0 * quantum_mm);
      for (const auto* c : axis_cols[a]) e = std::max(e, one_row_speed_change(*c, k) / limit);
    }
    return e;
  };
  std::vector<std::size_t> found;
  // Between boundaries a and b: the most telling row at least P - 1 from both.
  std::function<void(std::size_t, std::size_t)> split = [&](std::size_t a, std::size_t b) {
    if (b < a + 2 * (P - 1)) return;
    std::size_t k_best = 0;
    double e_best = 1.0;
    for (std::size_t k = a + P - 1; k + P - 1 <= b; ++k)
      if (const double e = excess(k); e > e_best) {
        e_best = e;
        k_best = k;
      }
    if (k_best == 0) return;
    found.push_back(k_best);
    split(a, k_best);
    split(k_best, b);
  };
  std::size_t a = 0;
  for (std::size_t c : cuts) {
    split(a, c);
    a = c;
  }
  split(a, n);
  cuts.insert(cuts.end(), found.begin(), found.end());
  std::sort(cuts.begin(), cuts.end());
  return {found.size(), P};
}

}  // namespace

std::vector<Segment> find_segments(const MeasuredRun& run, double quantum_mm, std::optional<double> v_max_mm_per_s,
                                   std::string* note) {
  const std::size_t n = run.trace.num_rows();
  // Per axis: its reference and position columns, and the limit of a step.
  struct AxisCols {
    std::vector<const std::vector<double>*> cols;
    double limit{0.0};
    /// A step this large that stands alone (4 times both neighbouring
    /// steps) or turns the motion back at twice its speed is a stitch too:
    /// the axis would have to start and stop, or reverse, within one sample.
    double isolated{0.0};
  };
  std::vector<AxisCols> axes;
  double limit_max = 0.0;
  for (Axis a : run.axes) {
    AxisCols ac;
    for (const char* s : {"_ref_mm", "_mm"})
      if (const auto* c = run.trace.find(col(a, s))) ac.cols.push_back(c);
    // The largest step the axis holds over three consecutive samples: a speed
    // the machine shows this axis moves at.
    double held = 0.0;
    for (const auto* c : ac.cols)
      for (std::size_t k = 2; k + 1 < n; ++k)
        held = std::max(held, std::min({std::abs((*c)[k - 1] - (*c)[k - 2]), std::abs((*c)[k] - (*c)[k - 1]),
                                        std::abs((*c)[k + 1] - (*c)[k])}));
    ac.limit = v_max_mm_per_s ? 1.2 * *v_max_mm_per_s * run.sample_period_s
                              : std::max(3.0 * held, 5.0 * quantum_mm);
    ac.isolated = v_max_mm_per_s ? ac.limit : std::max(1.5 * held, 5.0 * quantum_mm);
    limit_max = std::max(limit_max, ac.limit);
    axes.push_back(ac);
  }
  // The same columns taken together, per kind (references, positions): a
  // row where several axes step at once and the path's step is over 4 times
  // the steps either side is a jump even where no single axis's step exceeds
  // what it holds (umich13, t = 136.3 s: x 158 to 162 mm, y 75.8 to 79.9 mm
  // and z 27.7 to 29.7 mm in one row, 0.2 and 0.3 mm steps either side, y
  // turning back after it). Over 3 quanta: two axes stepping one quantum in
  // the same row, as a rounded slow move does, make a path step of 1.4.
  std::vector<std::vector<const std::vector<double>*>> path_cols;
  for (const char* s : {"_ref_mm", "_mm"}) {
    std::vector<const std::vector<double>*> cs;
    for (Axis a : run.axes)
      if (const auto* c = run.trace.find(col(a, s))) cs.push_back(c);
    if (cs.size() >= 2) path_cols.push_back(std::move(cs));
  }
  auto path_step = [&](const std::vector<const std::vector<double>*>& cs, std::size_t k) {
    if (k < 1 || k >= n) return 0.0;
    double s2 = 0.0;
    for (const auto* c : cs) s2 += ((*c)[k] - (*c)[k - 1]) * ((*c)[k] - (*c)[k - 1]);
    return std::sqrt(s2);
  };
  // Only on a staircase log: there a slow axis's steps round to zero about
  // a jump, and the other axes' give no scale. On a fine log the noise of a
  // few counts on two axes at once would read as jumps.
  const bool staircase = staircase_log(run, quantum_mm);
  auto path_jump = [&](std::size_t k) {
    if (v_max_mm_per_s || !staircase) return false;
    for (const auto& cs : path_cols) {
      int moving = 0;
      for (const auto* c : cs)
        if ((*c)[k] != (*c)[k - 1]) ++moving;
      const double d = path_step(cs, k);
      if (moving >= 2 && d > 3.0 * quantum_mm && d > 4.0 * std::max(path_step(cs, k - 1), path_step(cs, k + 1)))
        return true;
    }
    return false;
  };
  // Rows that start a segment, in order.
  std::vector<std::size_t> cuts;
  std::size_t jumps = 0, path_jumps = 0;
  double largest = 0.0;
  auto next_break = run.time_breaks.begin();
  for (std::size_t k = 1; k < n; ++k) {
    // A gap in the log's clock ends a segment too (load_run's note says so).
    if (next_break != run.time_breaks.end() && *next_break == k) {
      ++next_break;
      cuts.push_back(k);
      continue;
    }
    double step = 0.0;
    bool jump = false;
    for (const auto& ac : axes)
      for (const auto* c : ac.cols) {
        const double d = std::abs((*c)[k] - (*c)[k - 1]);
        const double before = k >= 2 ? std::abs((*c)[k - 1] - (*c)[k - 2]) : 0.0;
        const double after = k + 1 < n ? std::abs((*c)[k + 1] - (*c)[k]) : 0.0;
        // Or turning back at once, faster than it came: the axis cannot
        // reverse a motion and run at twice its speed the other way within one sample.
        const double prev_step = k >= 2 ? (*c)[k - 1] - (*c)[k - 2] : 0.0;
        const bool turns = prev_step * ((*c)[k] - (*c)[k - 1]) < 0.0 && d > 2.0 * before;
        const bool alone = ac.isolated > 0.0 && d > ac.isolated && (d > 4.0 * std::max(before, after) || turns);
        if ((ac.limit > 0.0 && d > ac.limit) || alone) {
          jump = true;
          step = std::max(step, d);
        }
      }
    if (!jump && path_jump(k)) {
      jump = true;
      ++path_jumps;
      for (const auto& cs : path_cols) step = std::max(step, path_step(cs, k));
    }
    if (jump) {
      cuts.push_back(k);
      ++jumps;
      largest = std::max(largest, step);
    }
  }
  std::vector<std::vector<const std::vector<double>*>> axis_columns;
  for (const auto& ac : axes) axis_columns.push_back(ac.cols);
  const BlockJumps blocks =
      (v_max_mm_per_s || !staircase) ? BlockJumps{} : block_boundary_jumps(n, axis_columns, quantum_mm, cuts);
  jumps += blocks.added;
  std::vector<Segment> segs;
  std::size_t start = 0;
  for (std::size_t k : cuts) {
    segs.push_back({start, k});
    start = k;
  }
  segs.push_back({start, n});
  const double limit = limit_max;
  if (note && jumps > 0) {
    std::size_t short_rows = 0;
    for (const auto& s : segs)
      if (s.end - s.begin < 5) short_rows += s.end - s.begin;
    *note = fmt::format(
        "stitched from {} segments: {} jumps of up to {:.4g} mm between two rows, beyond the {:.4g} mm a sample "
        "allows on the axis that jumps, at most ({}; or a step of over 1.5 times that held step standing alone (4 times its neighbours) or turning back at twice the speed it came){}{}; each segment is replayed from its own start{}",
        segs.size(), jumps, largest, limit,
        v_max_mm_per_s ? "the machine's rapid" : "3 times the largest step the axis holds over 3 samples",
        path_jumps ? fmt::format("; {} of them where several axes step at once, the path's step over 3 quanta and 4 times "
                                 "the steps either side",
                                 path_jumps)
                   : "",
        blocks.added ? fmt::format("; the jumps recur every {} rows (a logger writing blocks of that many rows and "
                                   "dropping some), and {} more at a block's boundary where an axis's speed "
                                   "changes for one row by more than it does inside any block",
                                   blocks.block_rows, blocks.added)
                     : "",
        short_rows ? fmt::format(", {} rows in segments under 5 rows are not compared", short_rows) : "");
  }
  return segs;
}

namespace {

/// A value a rounded position holds over rows [s, e].
struct HeldValue {
  std::size_t s, e;
  double v;
};

/// A segment of a stitched log is cut from a longer program: it can begin
/// or end in the middle of a move. A slow move (under half a quantum a
/// sample: the short side of a diagonal line) holds its rounded value at the
/// segment's ends not because it stands but because it has not reached the
/// next rounding boundary. Held flat there, the rebuild makes it a step of
/// one quantum within a sample and rest about it, a move the axis's own
/// current says it did not make (on umich04, 7-row stretches at the x
/// axis's Coulomb level, 3 to 4.6 A, that the flat rebuild put at rest).
/// The ends are carried on at a constant speed where the values allow it:
/// the speed of the one-quantum ramp next to the end, or, where the segment
/// crosses a single boundary, half the largest speed that keeps both held
/// values within their quantum; a move seen crossing is carried on after
/// it, and carried back before it only where the value held before is the
/// shorter (held longer, the axis may have set off from rest there: on
/// umich10, two such stretches held the other way's current). An end is
/// left flat where that speed would carry it past the next boundary within
/// the held rows (the axis stopped there), or where the values turn back
/// next to it.
template <typename OneQuantum>
void extend_held_ends(const std::vector<double>& t, const std::vector<HeldValue>& runs, OneQuantum one_quantum,
                      std::vector<double>& kt, std::vector<double>& kv) {
  const std::size_t R = runs.size();
  if (R < 2 || kt.empty()) return;
  auto crossing_t = [&](std::size_t j) { return 0.5 * (t[runs[j].e] + t[runs[j + 1].s]); };
  auto crossing_v = [&](std::size_t j) { return 0.5 * (runs[j].v + runs[j + 1].v); };
  auto ramp = [&](std::size_t j) {  // runs j, j+1, j+2 step one quantum each, the same way
    return one_quantum(runs[j].v, runs[j + 1].v) && one_quantum(runs[j + 1].v, runs[j + 2].v) &&
           (runs[j + 1].v - runs[j].v) * (runs[j + 2].v - runs[j + 1].v) > 0.0;
  };
  const double t0 = t[runs.front().s], t1 = t[runs.back().e];
  std::optional<double> s_first, s_last;
  if (R == 2) {
    if (one_quantum(runs[0].v, runs[1].v)) {
      const double before = crossing_t(0) - t0, after = t1 - crossing_t(0);
      const double L = std::max(before, after);
      if (L > 0.0) s_last = 0.5 * std::abs(runs[1].v - runs[0].v) / L;
      if (before <= after) s_first = s_last;
    }
  } else {
    if (ramp(0)) s_first = std::abs(crossing_v(1) - crossing_v(0)) / (crossing_t(1) - crossing_t(0));
    if (ramp(R - 3))
      s_last = std::abs(crossing_v(R - 2) - crossing_v(R - 3)) / (crossing_t(R - 2) - crossing_t(R - 3));
  }
  // Only a slow move: under half a quantum a sample. A faster one holds a
  // value for a row or so at an end, and the rebuild's stop there is half a
  // sample from its crossing at most.
  const double dt = (t1 - t0) / static_cast<double>(std::max<std::size_t>(1, runs.back().e - runs.front().s));
  auto slow = [&](const std::optional<double>& s, double q) { return s && *s * dt < 0.5 * q; };
  if (slow(s_first, std::abs(runs[1].v - runs[0].v))) {
    const double tc = crossing_t(0), vc = crossing_v(0), q = std::abs(runs[1].v - runs[0].v);
    const double L = tc - t0;
    if (*s_first * L <= q) {
      const double dir = runs[1].v > runs[0].v ? 1.0 : -1.0;
      std::size_t k = 0;
      while (k < kt.size() && kt[k] < tc) ++k;
      kt.erase(kt.begin(), kt.begin() + static_cast<std::ptrdiff_t>(k));
      kv.erase(kv.begin(), kv.begin() + static_cast<std::ptrdiff_t>(k));
      if (L > 0.0) {
        kt.insert(kt.begin(), t0);
        kv.insert(kv.begin(), vc - dir * *s_first * L);
      }
    }
  }
  if (slow(s_last, std::abs(runs[R - 1].v - runs[R - 2].v))) {
    const double tc = crossing_t(R - 2), vc = crossing_v(R - 2), q = std::abs(runs[R - 1].v - runs[R - 2].v);
    const double L = t1 - tc;
    if (*s_last * L <= q) {
      const double dir = runs[R - 1].v > runs[R - 2].v ? 1.0 : -1.0;
      while (!kt.empty() && kt.back() > tc) {
        kt.pop_back();
        kv.pop_back();
      }
      if (L > 0.0) {
        kt.push_back(t1);
        kv.push_back(vc + dir * *s_last * L);
      }
    }
  }
}

}  // namespace

std::vector<double> dequantize_reference(const std::vector<double>& t, const std::vector<double>& r0,
                                         const PositionRounding& rounding) {
  const std::size_t n0 = r0.size();
  if (n0 < 3 || rounding.kind == PositionRounding::Kind::kNone) return r0;
  // A single row off by more than one quantum between two equal neighbours is
  // a logging glitch, not a motion (the axis would move out and back within
  // two samples): it takes its neighbours' value.
  std::vector<double> r = r0;
  for (std::size_t k = 1; k + 1 < n0; ++k)
    if (r0[k - 1] == r0[k + 1] && std::abs(r0[k] - r0[k - 1]) > 1.5 * rounding.quantum_mm) r[k] = r0[k - 1];
  const std::size_t n = n0;
  std::vector<HeldValue> runs;
  for (std::size_t k = 0; k < n; ++k) {
    if (runs.empty() || r[k] != runs.back().v) runs.push_back({k, k, r[k]});
    runs.back().e = k;
  }
  auto quantum_at = [&](double a, double b) {
    if (rounding.kind == PositionRounding::Kind::kDecimals) return rounding.quantum_mm;
    const double m = std::max(std::abs(a), std::abs(b));
    return m > 0.0 ? std::pow(10.0, std::floor(std::log10(m)) - rounding.digits + 1) : rounding.quantum_mm;
  };
  auto one_quantum = [&](double a, double b) { return std::abs(b - a) <= 1.5 * quantum_at(a, b); };
  std::vector<double> kt, kv;
  auto knot = [&](double tk, double vk) {
    if (kt.empty() || tk > kt.back()) {
      kt.push_back(tk);
      kv.push_back(vk);
    }
  };
  for (std::size_t j = 0; j < runs.size(); ++j) {
    const HeldValue& u = runs[j];
    const bool has_prev = j > 0, has_next = j + 1 < runs.size();
    const bool through = has_prev && has_next && (u.v - runs[j - 1].v) * (runs[j + 1].v - u.v) > 0.0;
    const bool small_in = has_prev && one_quantum(runs[j - 1].v, u.v);
    const bool small_out = has_next && one_quantum(u.v, runs[j + 1].v);
    if (!through) {
      // Flat: where the values turn back, and at the segment's ends.
      knot(t[u.s], u.v);
      knot(t[u.e], u.v);
    } else if (!(small_in && small_out)) {
      // A step of several quanta on one side: the samples hold information.
      if (!small_in) knot(t[u.s], u.v);
      if (!small_out) knot(t[u.e], u.v);
    }
    if (has_next && small_out) knot(0.5 * (t[u.e] + t[runs[j + 1].s]), 0.5 * (u.v + runs[j + 1].v));
  }
  extend_held_ends(t, runs, one_quantum, kt, kv);
  std::vector<double> out(n);
  std::size_t j = 0;
  for (std::size_t k = 0; k < n; ++k) {
    if (t[k] <= kt.front()) {
      out[k] = kv.front();
    } else if (t[k] >= kt.back()) {
      out[k] = kv.back();
    } else {
      while (kt[j + 1] < t[k]) ++j;
      out[k] = kv[j] + (t[k] - kt[j]) / (kt[j + 1] - kt[j]) * (kv[j + 1] - kv[j]);
    }
  }
  return out;
}

TorqueChannel torque_channel(const MeasuredRun& run, Axis a) {
  for (const auto& [suffix, unit] : std::vector<std::pair<const char*, const char*>>{
           {"_torque_Nm", "N m"}, {"_torque_raw", "raw"}, {"_i_A", "A"}, {"_u_V", "V"}})
    if (run.trace.find(col(a, suffix))) return {col(a, suffix), unit};
  return {};
}

nlohmann::json ChannelErrors::to_json() const {
  nlohmann::json j = nlohmann::json::object();
  for (const auto& [k, v] : nrms) j[k] = v;
  for (const auto& [k, why] : not_computed) j[k] = nullptr;
  return j;
}

// ---------------------------------------------------------------------------
// Replay

ReplayResult replay_segments(const MeasuredRun& run, const sim::MachineDefinition& machine,
                             const std::vector<Segment>& segments, const PositionRounding& rounding,
                             std::vector<char>* compared, Segment rows) {
  const std::size_t n = run.trace.num_rows();
  ReplayResult out;
  for (Axis a : run.axes)
    if (machine.axes[index(a)].present) out.axes.push_back(a);
  const auto& t = run.trace.at("t_s");
  out.t_s = t;
  for (Axis a : out.axes) {
    const auto& ref = run.trace.at(col(a, "_ref_mm"));
    out.x_ref_mm[index(a)] = ref;
    out.x_mm[index(a)] = ref;
    for (auto* v : {&out.u_V, &out.i_A, &out.Tm, &out.vcmd_mm_per_s}) (*v)[index(a)].assign(n, 0.0);
  }
  if (compared) compared->assign(n, 0);
  // Each segment is replayed from its time and references alone.
  std::vector<std::string> reference_columns{"t_s"};
  for (Axis a : out.axes) reference_columns.push_back(col(a, "_ref_mm"));
  // The reference's speed at the rows where the machine's law reads it off
  // the logged velocity command (law_reference_speed), as replay_run would.
  AxisArray<std::vector<double>> speed{};
  for (Axis a : out.axes) speed[index(a)] = law_reference_speed(run, a, machine.axes[index(a)]);
  // The channels at a row are their mean over the two periods about it
  // where the rebuilt reference places a change of speed at a time inside
  // them that the log does not give; where the rebuild passes through every
  // axis's speed at the rows, the value at the row's tick is the log's (on
  // the cascade sweep's 50 ms logs without the motor's speed: the other
  // program's torque NRMS 0.40 against 0.58 with the mean).
  const bool every_speed = std::all_of(out.axes.begin(), out.axes.end(),
                                       [&](Axis a) { return speed[index(a)].size() == n; });
  const ChannelSampling sampling =
      every_speed && !out.axes.empty() ? ChannelSampling::kInstant : ChannelSampling::kMeanOverNeighbours;
  for (const Segment& s : segments) {
    if (s.end - s.begin < 5 || s.end <= rows.begin || s.begin >= rows.end) continue;
    MeasuredRun sub = rows_of(run, s.begin, s.end, reference_columns);
    sub.axes = out.axes;
    for (Axis a : out.axes) {
      const auto& v = speed[index(a)];
      if (v.size() < s.end) continue;
      sub.trace.names.push_back(reference_speed_column(a));
      sub.trace.columns.emplace_back(v.begin() + static_cast<std::ptrdiff_t>(s.begin),
                                     v.begin() + static_cast<std::ptrdiff_t>(s.end));
    }
    const ReplayResult r = replay_run(sub, machine, 0, {}, sampling);
    for (Axis a : out.axes) {
      const std::size_t i = index(a);
      // The torque channels in the log's sign.
      const double sign = machine.axes[i].logged_torque_sign;
      for (std::size_t k = 0; k < r.t_s.size(); ++k) {
        out.x_mm[i][s.begin + k] = rounding.round(r.x_mm[i][k]);
        out.u_V[i][s.begin + k] = sign * r.u_V[i][k];
        out.i_A[i][s.begin + k] = sign * r.i_A[i][k];
        out.Tm[i][s.begin + k] = sign * r.Tm[i][k];
        out.vcmd_mm_per_s[i][s.begin + k] = r.vcmd_mm_per_s[i][k];
      }
    }
    if (compared)
      for (std::size_t k = s.begin; k < s.end; ++k) (*compared)[k] = 1;
    // What the segments' replays say, each thing once.
    for (const auto& note : r.notes)
      if (std::find(out.notes.begin(), out.notes.end(), note) == out.notes.end()) out.notes.push_back(note);
  }
  return out;
}

namespace {

/// The model's value of a channel: what the replay gives in the channel's unit.
const std::vector<double>* model_channel(const ReplayResult& r, Axis a, const TorqueChannel& ch,
                                         bool same_unit_machine) {
  const std::size_t i = index(a);
  if (ch.unit == "A") return &r.i_A[i];
  if (ch.unit == "V") return &r.u_V[i];
  if (ch.unit == "N m") return &r.Tm[i];
  return same_unit_machine ? &r.Tm[i] : nullptr;  // raw: only a machine identified in the log's unit
}

/// Adds a model's errors on rows [from, to) where compared to `pools`.
/// `has_vcmd`: the model's loop is a cascade, so its velocity command compares
/// with a logged one.
void add_errors(PoolSet& pools, const MeasuredRun& run, const ReplayResult& model, const std::vector<char>& compared,
                const std::vector<Axis>& axes, std::size_t from, std::size_t to, bool same_unit_machine,
                bool has_vcmd, std::map<std::string, std::string>* not_comparable) {
  for (Axis a : axes) {
    const std::size_t i = index(a);
    if (model.x_mm[i].empty()) continue;
    const auto& ref = run.trace.at(col(a, "_ref_mm"));
    if (const auto* x = run.trace.find(col(a, "_mm"))) {
      Pool& p = pools[col(a, "_err_mm")];
      for (std::size_t k = from; k < to; ++k)
        if (compared[k]) p.add(ref[k] - (*x)[k], ref[k] - model.x_mm[i][k]);
    }
    if (const auto* vc = run.trace.find(col(a, "_vcmd_mm_s"))) {
      if (has_vcmd) {
        Pool& p = pools[col(a, "_vcmd_mm_s")];
        for (std::size_t k = from; k < to; ++k)
          if (compared[k]) p.add((*vc)[k], model.vcmd_mm_per_s[i][k]);
      } else if (not_comparable) {
        (*not_comparable)[col(a, "_vcmd_mm_s")] = "the machine's loop (FADAL) has no velocity command";
      }
    }
    const TorqueChannel ch = torque_channel(run, a);
    if (!ch.present()) continue;
    const std::string key = ch.column;
    const auto* m = model_channel(model, a, ch, same_unit_machine);
    if (m == nullptr) {
      if (not_comparable) (*not_comparable)[key] = "the log's torque unit is not stated: the nominal machine's N m cannot be compared";
      continue;
    }
    const auto& meas = run.trace.at(ch.column);
    Pool& p = pools[key];
    for (std::size_t k = from; k < to; ++k)
      if (compared[k]) p.add(meas[k], (*m)[k]);
  }
}

/// The rigid-body regression of one axis: T = m a + Fc sgn(v) + b v + c.
struct Regression {
  bool ok{false};
  std::vector<double> theta;  // m, Fc, b, c
  double lag_s{0.0};          // tracking baseline: e = lag v
};

ChannelErrors errors_from(const PoolSet& pools) {
  ChannelErrors e;
  pools_to_errors(pools, e);
  return e;
}

struct Fitter {
  const std::vector<RunData>& runs;

  /// Rows of the fitting part (interior rows of segments), per run.
  template <typename F>
  void for_fit_rows(F f) const {
    for (std::size_t r = 0; r < runs.size(); ++r)
      for (std::size_t k = 0; k < runs[r].n_fit; ++k)
        if (runs[r].interior[k]) f(r, k);
  }
};

// ---------------------------------------------------------------------------
// Catalogue effects on the residual of the identified machine

/// Errors of a machine on the fitting runs, fitting rows and held-out rows,
/// from one replay of each run (kept for the detectors that read the replay).
struct FitRunErrors {
  bool ok{false};
  ChannelErrors fit, held;
  std::vector<ReplayResult> replays;
  std::vector<std::vector<char>> compared;  ///< per run: the rows compared
};

FitRunErrors errors_on_fit_runs(const std::vector<RunData>& runs, const sim::MachineDefinition& machine,
                                const std::vector<Axis>& axes, const PositionRounding& rounding, int& replays) {
  FitRunErrors out;
  PoolSet fit, held;
  try {
    for (const RunData& rd : runs) {
      std::vector<char> cmp;
      ReplayResult rr = replay_segments(*rd.smooth, machine, rd.segments, rounding, &cmp);
      ++replays;
      for (std::size_t k = 0; k < cmp.size(); ++k) cmp[k] = static_cast<char>(cmp[k] && rd.interior[k]);
      add_errors(fit, *rd.run, rr, cmp, axes, 0, rd.n_fit, true, true, nullptr);
      add_errors(held, *rd.run, rr, cmp, axes, rd.n_fit, rd.n, true, true, nullptr);
      out.replays.push_back(std::move(rr));
      out.compared.push_back(std::move(cmp));
    }
  } catch (const Error&) {
    return out;
  }
  out.fit = errors_from(fit);
  out.held = errors_from(held);
  out.ok = true;
  return out;
}

/// The channels an effect on an axis is judged on: its torque channel, its
/// tracking error and its velocity command (those the log has).
std::vector<std::string> axis_keys(const AxisFromData& ax) {
  return {ax.channel.column, col(ax.axis, "_err_mm"), col(ax.axis, "_vcmd_mm_s")};
}

/// An effect is kept where the sum of the axis's held-out NRMS falls by more
/// than kKeepMargin (relative) and no channel of the axis rises by more than
/// kRiseAllowed: a fall within the scatter of two replays that differ only
/// in where the encoder counts fall is not evidence.
constexpr double kKeepMargin = 0.01;
constexpr double kRiseAllowed = 0.02;

double keys_sum(const ChannelErrors& e, const std::vector<std::string>& keys) {
  double s = 0.0;
  for (const auto& k : keys)
    if (const auto it = e.nrms.find(k); it != e.nrms.end()) s += it->second;
  return s;
}

/// Rows of the fitting part of every fitting run an effect's detector fits
/// on (interior rows of segments), with the drive's regressors there.
struct AxisRows {
  std::vector<std::pair<std::size_t, std::size_t>> at;  ///< (run, row)
  /// The axis's own motion where its speed is logged (the speed and its
  /// central difference; the friction acts on it), else the commanded one.
  std::vector<double> acc, vel, pos, neg, one, dir, x, T;
  std::vector<double> vel_m;  ///< the logged speed (vel where logged)
  bool measured_speed{true};
  std::vector<std::size_t> all, moving;
  double v_move{0.0}, v_high{0.0}, x_lo{0.0}, x_hi{0.0};
  /// The drive's columns a, v, [v > 0], -[v < 0], 1.
  std::vector<const std::vector<double>*> drive_columns() const { return {&acc, &vel, &pos, &neg, &one}; }
};

/// The logged torque paired with the motion at row k: the row's own; where
/// the log gives at each row the mean over the period before it
/// (AxisFromData::logs_period_mean), the next row's against the speed's
/// forward difference (the mean over the same period), and the two rows'
/// mean against an acceleration about row k.
double logged_torque_at(const std::vector<double>& T, std::size_t k, bool period_mean, bool forward) {
  if (!period_mean || k + 1 >= T.size()) return T[k];
  return forward ? T[k + 1] : 0.5 * (T[k] + T[k + 1]);
}

/// The motor's torque rebuilt from a logged torque command, within each
/// segment: the command `rows` rows late through the current loop's
/// first-order lag of coefficient a (started at the segment's first value).
std::vector<double> motor_torque_from_command(const std::vector<double>& T, const std::vector<Segment>& segs,
                                              std::size_t rows, double a) {
  std::vector<double> out = T;
  for (const Segment& sg : segs) {
    if (sg.end <= sg.begin) continue;
    double y = T[sg.begin];
    for (std::size_t k = sg.begin; k < sg.end; ++k) {
      y = a * y + (1.0 - a) * T[k >= sg.begin + rows ? k - rows : sg.begin];
      out[k] = y;
    }
  }
  return out;
}

AxisRows axis_rows(const std::vector<RunData>& runs, const AxisFromData& ax) {
  AxisRows r;
  const std::size_t i = index(ax.axis);
  for (const RunData& rd : runs)
    r.measured_speed = r.measured_speed && rd.run->trace.find(col(ax.axis, "_v_mm_s")) != nullptr;
  std::vector<double> speeds;
  for (std::size_t run = 0; run < runs.size(); ++run) {
    const RunData& rd = runs[run];
    const auto& t = rd.run->trace;
    // Where the speed is taken from the position, the torque low-passed
    // alike (as the drive is fitted, drive_rows).
    const auto* ch = filtered_alike(t, ax.channel.column);
    if (ch == nullptr) continue;
    // A logged torque command: the motor's torque it makes, which the drive's
    // motion answers to (the detectors read the drive's residual).
    std::vector<double> motor;
    if (ax.torque_command_logged) {
      const double tau = ax.gains.tau_i_s;
      motor = motor_torque_from_command(*ch, rd.segments, ax.torque_lag_samples,
                                        tau > 0.0 ? std::exp(-rd.run->sample_period_s / tau) : 0.0);
      ch = &motor;
    }
    const auto* xm = t.find(col(ax.axis, "_mm"));
    const auto& xs = xm ? *xm : rd.smooth->trace.at(col(ax.axis, "_ref_mm"));
    const auto* vm = r.measured_speed ? t.find(col(ax.axis, "_v_mm_s")) : nullptr;
    const double dt = rd.run->sample_period_s;
    r.v_move = std::max(r.v_move, rd.v_move[i]);
    for (std::size_t k = 0; k < rd.n_fit; ++k) {
      if (!rd.interior[k]) continue;
      const double v = vm ? (*vm)[k] : rd.kin[i].v_mm_per_s[k];
      const int d = direction(v, rd.v_move[i]);
      r.at.emplace_back(run, k);
      r.acc.push_back(!vm                     ? rd.kin[i].a_mm_per_s2[k]
                      : ax.torque_held_over_row ? ((*vm)[k + 1] - (*vm)[k]) / dt
                                                : ((*vm)[k + 1] - (*vm)[k - 1]) / (2.0 * dt));
      r.vel.push_back(v);
      r.pos.push_back(d > 0 ? 1.0 : 0.0);
      r.neg.push_back(d < 0 ? -1.0 : 0.0);
      r.one.push_back(1.0);
      r.dir.push_back(d);
      r.x.push_back(xs[k]);
      r.T.push_back(logged_torque_at(*ch, k, ax.logs_period_mean(), vm && ax.torque_held_over_row));
      r.vel_m.push_back(v);
      r.all.push_back(r.all.size());
      if (d != 0) {
        r.moving.push_back(r.all.back());
        speeds.push_back(v);
      }
    }
  }
  r.v_high = percentile_abs(speeds, 0.99);
  if (!r.moving.empty()) {
    r.x_lo = r.x_hi = r.x[r.moving.front()];
    for (std::size_t k : r.moving) {
      r.x_lo = std::min(r.x_lo, r.x[k]);
      r.x_hi = std::max(r.x_hi, r.x[k]);
    }
  }
  return r;
}

/// The drive refitted with an effect: J and B stay (or move too:
/// drive_moved's move_J_B); the Coulomb levels and the constant load move
/// by what fitting the effect beside them moves them
/// (the joint fit against the same fit without it, both with the drive's
/// columns a, v, [v > 0], -[v < 0], 1 first), since a Coulomb level fitted
/// without the effect takes up part of it.
struct DriveRefit {
  double J{0.0}, B{0.0}, Tc_pos{0.0}, Tc_neg{0.0}, c{0.0};
};
/// The rigid-body drive (and its constant load) of a refit, set on `drive`.
void set_drive(feeddrive::DriveParams& drive, const DriveRefit& d) {
  drive.J_kg_m2 = d.J;
  drive.B_kg_m2_per_s = d.B;
  drive.Tc_pos_Nm = d.Tc_pos;
  drive.Tc_neg_Nm = d.Tc_neg;
  drive.effects.constant_load.enabled = d.c != 0.0;
  drive.effects.constant_load.torque_Nm = d.c;
}
/// `one_level`: the drive has one Coulomb level for both directions, which
/// moves by the mean of what the two move by. With `move_J_B`, J and B move
/// so too: where the motion lines the effect up with the acceleration or
/// the speed (a contour reverses through zero speed where its acceleration
/// is largest), the rigid-body fit takes part of the effect into them.
DriveRefit drive_moved(const feeddrive::DriveParams& cur, const LsqResult& joint, const LsqResult& without,
                       bool one_level, bool move_J_B = false) {
  const double c0 = cur.effects.constant_load.enabled ? cur.effects.constant_load.torque_Nm : 0.0;
  double dpos = joint.theta[2] - without.theta[2];
  double dneg = joint.theta[3] - without.theta[3];
  if (one_level) dpos = dneg = 0.5 * (dpos + dneg);
  const double dJ = move_J_B ? joint.theta[0] - without.theta[0] : 0.0;
  const double dB = move_J_B ? joint.theta[1] - without.theta[1] : 0.0;
  return {std::max(cur.J_kg_m2 + dJ, 0.0), std::max(cur.B_kg_m2_per_s + dB, 0.0), std::max(cur.Tc_pos_Nm + dpos, 0.0),
          std::max(cur.Tc_neg_Nm + dneg, 0.0), c0 + joint.theta[4] - without.theta[4]};
}

/// What a drive refit with J and B moved says in the evidence ("" without).
std::string moved_J_B_note(bool moved, const feeddrive::DriveParams& cur, const DriveRefit& d) {
  if (!moved) return "";
  return fmt::format("; the drive's J and B moved with it ({:.4g} -> {:.4g}, {:.4g} -> {:.4g}, in the channel's unit)",
                     cur.J_kg_m2, d.J, cur.B_kg_m2_per_s, d.B);
}

/// A candidate: the effect, one or more parameter sets (the fitting rows'
/// replay chooses among them), the drive refitted with each, the loop
/// gains it carries, and the torque it adds at the detector's rows (taken
/// out of the torque the later detectors fit, where kept). The channels it
/// is judged on are the registry's.
struct Trial {
  EffectKind kind{EffectKind::kStribeck};
  std::vector<ParamSet> sets;
  std::vector<DriveRefit> drives;  ///< one per set, or empty: the drive stays
  std::optional<controller::CascadeGains> gains;
  std::string evidence;
  std::function<double(std::size_t row, const ParamSet& p, const DriveRefit* d)> torque;
  std::vector<std::string> set_notes;  ///< said of each set where it is the one chosen (or empty)
  /// The log read as the loop's command, before the current loop
  /// (AxisDefinition::torque_command_logged), from this effect on.
  bool reads_command{false};
};

sim::MachineDefinition with_trial(const sim::MachineDefinition& base, Axis a, const Trial& t, std::size_t set) {
  sim::MachineDefinition m = base;
  sim::AxisDefinition& def = m.axes[index(a)];
  if (!t.drives.empty()) set_drive(def.drive, t.drives[set]);
  if (t.gains) {
    const double in_loop_s = def.loop.cascade.tau_i_s;
    def.loop.cascade = *t.gains;
    // A lag the log's monitor holds stays outside the loop (but for the
    // share of it the loop holds: split_monitor_lag).
    if (def.logged_torque_filter_s > 0.0) def.loop.cascade.tau_i_s = in_loop_s;
  }
  if (t.reads_command) def.torque_command_logged = 1.0;
  // Two effects that describe the same thing: the drive holds one.
  for (const EffectKind replaced : replaced_by(t.kind))
    feeddrive::effect_def(replaced).enabled(def.drive.effects) = false;
  for (const auto& [param, value] : t.sets[set]) {
    const std::string_view name = feeddrive::effect_param_def(param).qualified;
    const sim::AxisParamSpec* spec = sim::find_axis_param(name);
    if (spec == nullptr) throw InternalError(fmt::format("calibrate: no machine parameter {}", name));
    sim::set_axis_param(def, *spec, value);
  }
  return m;
}

double t_of(const LsqResult& ls, std::size_t j) {
  return ls.stderr_theta[j] > 0.0 ? ls.theta[j] / ls.stderr_theta[j] : 0.0;
}

/// t of a pair of columns (a sine and a cosine): the RMS of their t values.
double t_pair(const LsqResult& ls, std::size_t j) {
  return std::sqrt(0.5 * (std::pow(t_of(ls, j), 2) + std::pow(t_of(ls, j + 1), 2)));
}

/// What a detector needs to reach before its candidate is replayed: the
/// fitted size over its standard error (the residual's correlation over
/// 10 ms of rows counted), high enough that a scan over hundreds of periods
/// or speeds does not pass on noise alone.
constexpr double kMinT = 8.0;
/// The same for a detector that fits one column of given shape, no scan:
/// one one-sided test, at about 1 in 1000 on noise alone.
constexpr double kMinTOneColumn = 3.0;

/// The step of the logged positions: the coarsest power of ten all measured
/// positions are multiples of (the reference may be logged finer), at least
/// the rounding's quantum.
double measured_position_step(const DataCalibration& out, const std::vector<RunData>& runs) {
  double q = 0.0;
  for (int d = 0; d <= 6 && q == 0.0; ++d) {
    const double step = std::pow(10.0, -d);
    bool all = true;
    for (const RunData& rd : runs)
      for (Axis a : out.axes)
        if (const auto* x = rd.run->trace.find(col(a, "_mm")))
          for (double v : *x) all = all && is_multiple(v, step);
    if (all) q = step;
  }
  if (q == 0.0) q = out.identified.encoder_resolution_mm;
  return std::max(q, out.rounding.kind == PositionRounding::Kind::kSignificant ? out.rounding.quantum_mm : 0.0);
}

/// A scan of a period over [P_min, P_max] (steps of 1.5 %, then refined
/// to 0.1 % and 0.01 % about the best): the period whose fit leaves the
/// smallest residual.
std::pair<double, LsqResult> scan_period(double P_min, double P_max, const std::function<LsqResult(double)>& fit) {
  std::pair<double, LsqResult> best{0.0, LsqResult{}};
  double best_res = 1e300;
  auto one = [&](double P) {
    LsqResult ls = fit(P);
    if (ls.ok && ls.residual_rms < best_res) {
      best_res = ls.residual_rms;
      best = {P, std::move(ls)};
    }
  };
  for (double P = P_min; P <= P_max; P *= 1.015) one(P);
  for (const auto& [span, step] : {std::pair{1.015, 1.001}, std::pair{1.001, 1.0001}}) {
    if (best.first <= 0.0) break;
    const double P0 = best.first;
    for (double P = P0 / span; P <= std::min(P_max, P0 * span); P *= step) one(P);
  }
  return best;
}

/// A lead error the velocity law shows where the speed is the encoder's own
/// (fit_velocity_loop's lead columns): its period, the law fitted with it,
/// its t and the law's residual without it.
struct LeadInLaw {
  double P_mm{0.0};  ///< 0: none shown
  LsqResult ls;
  double t{0.0}, base_residual{0.0};
  std::size_t column{0};  ///< where the lead columns start in ls.theta
  double amplitude_mm() const { return std::hypot(ls.theta[column], ls.theta[column + 1]) / ls.theta[1]; }
  double phase_rad() const { return std::atan2(ls.theta[column + 1], ls.theta[column]); }
};

/// The law `o` fitted with the lead columns at each period of a scan from
/// the period whose ripple passes the speed's low-pass unchanged (at most
/// half its cutoff at the fastest speed of the fitting rows) to half their
/// travel. Shown where the pair's t reaches kMinT, counting the rows the
/// low-pass correlates (1 / (2 cutoff)) as one, the residual falls by 2 %
/// below the same law's without them and Ki stays positive.
LeadInLaw lead_error_in_law(const std::vector<RunData>& runs, const AxisFromData& ax, LawFitOptions o) {
  LeadInLaw out;
  o.lead_period_mm = 0.0;
  const VelocityLoopFit base = fit_velocity_loop(runs, ax.axis, ax.channel.column, o);
  out.base_residual = base.ls.residual_rms;
  double v_high = 0.0, x_lo = 1e300, x_hi = -1e300;
  for (const RunData& rd : runs) {
    const auto& v = rd.run->trace.at(col(ax.axis, "_v_mm_s"));
    const auto& x = rd.run->trace.at(col(ax.axis, "_mm"));
    for (std::size_t k = 0; k < rd.n_fit; ++k)
      if (rd.interior[k]) {
        v_high = std::max(v_high, std::abs(v[k]));
        x_lo = std::min(x_lo, x[k]);
        x_hi = std::max(x_hi, x[k]);
      }
  }
  const double dt = runs.front().run->sample_period_s;
  const double P_min = std::max(0.5, 2.0 * v_high / kSpeedCutoff_Hz), P_max = (x_hi - x_lo) / 2.0;
  if (!(base.ls.ok && P_max > P_min)) return out;
  const auto [P, ls] = scan_period(P_min, P_max, [&](double period) {
    o.lead_period_mm = period;
    return fit_velocity_loop(runs, ax.axis, ax.channel.column, o).ls;
  });
  out.column = lead_column(o);
  if (!(P > 0.0 && ls.theta[1] > 0.0)) return out;
  out.t = t_pair(ls, out.column) / std::sqrt(std::max(1.0, 1.0 / (2.0 * kSpeedCutoff_Hz * dt)));
  if (!(out.t >= kMinT && ls.residual_rms < 0.98 * base.ls.residual_rms)) return out;
  out.P_mm = P;
  out.ls = ls;
  return out;
}

/// A gap between the motor and the encoder the velocity law shows where the
/// speed is the encoder's own. Moving +, the motor pushes the encoder's side
/// from half the gap behind it, moving - from half the gap ahead, and the
/// two part only while the encoder's side stands: the law fitted with its
/// constants by the stretches of motion (by_table_motion) gives the
/// stretches moving - a constant Ki times the gap above those moving +. The
/// gap is the difference of the two directions' mean constants over Ki, its
/// t that difference over its standard error from the constants' scatter
/// about their direction's mean (two stretches each way at least).
struct GapInLaw {
  double gap_mm{0.0}, t{0.0};
  std::size_t stretches{0};
};
GapInLaw gap_in_law(const std::vector<RunData>& runs, const AxisFromData& ax, LawFitOptions o) {
  o.by_table_motion = true;
  const VelocityLoopFit f = fit_velocity_loop(runs, ax.axis, ax.channel.column, o);
  GapInLaw out;
  if (!(f.ls.ok && f.ls.theta[1] > 0.0)) return out;
  std::array<double, 2> mean{};
  std::array<std::size_t, 2> n{};
  auto side = [&](std::size_t j) { return f.dir_seg[j] > 0 ? 0 : 1; };
  for (std::size_t j = 0; j < f.c_seg.size(); ++j)
    if (f.dir_seg[j] != 0 && f.rows_seg[j] > 0.0) {
      mean[side(j)] += f.c_seg[j];
      ++n[side(j)];
    }
  if (n[0] < 2 || n[1] < 2) return out;
  for (std::size_t d = 0; d < 2; ++d) mean[d] /= static_cast<double>(n[d]);
  double s2 = 0.0;
  for (std::size_t j = 0; j < f.c_seg.size(); ++j)
    if (f.dir_seg[j] != 0 && f.rows_seg[j] > 0.0) s2 += std::pow(f.c_seg[j] - mean[side(j)], 2);
  s2 /= static_cast<double>(n[0] + n[1] - 2);
  const double se = std::sqrt(s2 * (1.0 / static_cast<double>(n[0]) + 1.0 / static_cast<double>(n[1])));
  out.stretches = n[0] + n[1];
  out.gap_mm = (mean[1] - mean[0]) / f.ls.theta[1];
  out.t = se > 0.0 ? std::abs(mean[1] - mean[0]) / se : 1e300;
  return out;
}

}  // namespace

namespace {

// The white noise on the detector's logged channel (as logged, not
// low-passed), from its second differences over consecutive fitting rows.
double channel_noise_rms(const AxisRows& rows, const std::vector<RunData>& runs, const std::string& column) {
  std::vector<double> d2;
  for (std::size_t k = 1; k + 1 < rows.all.size(); ++k) {
    const auto [r0, k0] = rows.at[k - 1];
    const auto [r1, k1] = rows.at[k];
    const auto [r2, k2] = rows.at[k + 1];
    if (r0 != r1 || r1 != r2 || k1 != k0 + 1 || k2 != k1 + 1) continue;
    const auto& T = runs[r1].run->trace.at(column);
    d2.push_back(std::abs(T[k2] - 2.0 * T[k1] + T[k0]));
  }
  return white_noise_rms(std::move(d2));
}

// The rows over which the drive fit's residual is correlated, for the
// detectors' standard errors: a model error stays for about 10 ms, white
// noise on the log for one row, each counted by its share of the residual's
// variance (a log whose residual is mostly noise is not taken as ten times
// fewer independent rows than it has).
double residual_correlation_rows(const AxisRows& rows, const std::vector<const std::vector<double>*>& base_cols,
                                 double noise_rms, double dt) {
  const double corr = std::max(1.0, 0.01 / dt);
  const LsqResult base = least_squares(base_cols, rows.T, rows.all);
  if (!(base.ok && base.residual_rms > 0.0)) return corr;
  const double white = std::min(1.0, noise_rms * noise_rms / (base.residual_rms * base.residual_rms));
  return white + (1.0 - white) * corr;
}

}  // namespace

/// A detector's view of one identified axis: the runs, the axis's rows with
/// the torque the machine so far leaves, the replays of that machine, and
/// the rule every candidate is kept by (attempt).
struct DataSearch {
  DataCalibration& out;
  const std::vector<RunData>& runs;
  const AxisFromData& ax;
  FitRunErrors& current;  ///< the machine so far on the fitting runs
  AxisRows rows;
  std::vector<std::string> keys;  ///< the axis's channels
  std::vector<const std::vector<double>*> base_cols;
  double dt{0.0};    ///< the log's sample period
  double q{0.0};     ///< the logged positions' step
  double corr{1.0};  ///< rows over which the residual is correlated
  double noise_rms{0.0};  ///< the white noise on the logged channel (fast logs; else 0)
  bool fast{false};  ///< the log resolves the velocity loop (resolves_velocity_loop)
  bool fine{false};  ///< positions to 5 um or finer

  Axis axis() const { return ax.axis; }
  std::size_t ai() const { return index(ax.axis); }
  /// The drive's columns and `extra`.
  std::vector<const std::vector<double>*> with_base(std::vector<const std::vector<double>*> extra) const {
    std::vector<const std::vector<double>*> c = base_cols;
    c.insert(c.end(), extra.begin(), extra.end());
    return c;
  }
  /// The channel the replay gives at the detector's row k.
  double model_at(std::size_t k) const {
    const auto [run, row] = rows.at[k];
    const auto* m = model_channel(current.replays[run], ax.axis, ax.channel, true);
    return m ? (*m)[row] : 0.0;
  }
  /// Whether every fitting run logs the axis's measured position.
  bool logs_position() const {
    bool logs_x = true;
    for (const RunData& rd : runs) logs_x = logs_x && rd.run->trace.find(col(ax.axis, "_mm")) != nullptr;
    return logs_x;
  }
  /// The channels `kind` is judged on (the registry's), as keys.
  std::vector<std::string> judged_keys(EffectKind kind) const {
    const std::uint8_t on = registry_entry(kind).judged_on;
    std::vector<std::string> jk;
    if (on & kJudgeTorque) jk.push_back(ax.channel.column);
    if (on & kJudgeTracking) jk.push_back(col(ax.axis, "_err_mm"));
    return jk;
  }
  void attempt(const Trial& t);

 private:
  struct BestSet {
    std::size_t set{0};
    FitRunErrors errors;
  };
  BestSet best_set_on_fit_rows(const Trial& t);
  void judge_held_out(const Trial& t, const FitRunErrors& best_e, DataEffect& eff) const;
  void keep(const Trial& t, std::size_t best, FitRunErrors&& best_e);
};

/// The set whose replay has the lowest error on the fitting rows, in the
/// channels the effect is judged on (judged_keys): a size is chosen on what
/// the effect shows in. (On all the axis's channels, the cascade sweep's
/// backlash of 20 um, found at 19.97 um, was replayed at 23 um, whose torque
/// at the reversals fitted better and whose tracking, what backlash is
/// judged on, was worse: 0.0032 against 0.0018 on the fitting run.)
DataSearch::BestSet DataSearch::best_set_on_fit_rows(const Trial& t) {
  BestSet b;
  double best_fit = 1e300;
  const std::vector<std::string> jk = judged_keys(t.kind);
  for (std::size_t s = 0; s < t.sets.size(); ++s) {
    FitRunErrors e;
    try {
      e = errors_on_fit_runs(runs, with_trial(out.final_machine, ax.axis, t, s), out.axes, out.rounding, out.replays);
    } catch (const Error&) {
      continue;
    }
    if (!e.ok || !e.fit.nrms.count(ax.channel.column)) continue;
    const double f = keys_sum(e.fit, jk);
    if (f < best_fit) {
      best_fit = f;
      b.set = s;
      b.errors = std::move(e);
    }
  }
  return b;
}

/// Kept where no channel of the axis rises by more than kRiseAllowed and the
/// channels the effect is judged on fall by more than kKeepMargin.
void DataSearch::judge_held_out(const Trial& t, const FitRunErrors& best_e, DataEffect& eff) const {
  bool no_rise = true;
  for (const auto& [k, b] : eff.before_channels) {
    const auto it = best_e.held.nrms.find(k);
    if (it == best_e.held.nrms.end()) {
      no_rise = false;
      continue;
    }
    eff.after_channels[k] = it->second;
    no_rise = no_rise && it->second <= b * (1.0 + kRiseAllowed);
  }
  eff.after = eff.after_channels.count(ax.channel.column) ? eff.after_channels.at(ax.channel.column) : eff.before;
  const std::vector<std::string> jk = judged_keys(t.kind);
  const double sb = keys_sum(current.held, jk), sa = keys_sum(best_e.held, jk);
  eff.kept = no_rise && sa < (1.0 - kKeepMargin) * sb;
  eff.evidence += fmt::format("; held-out NRMS of {} {:.4g} -> {:.4g}{}", fmt::join(jk, " + "), sb, sa,
                              eff.kept ? "" : " (not kept)");
}

/// The kept effect goes into the machine (an effect it replaces on the axis
/// is dropped), its torque out of the rows the later detectors fit.
void DataSearch::keep(const Trial& t, std::size_t best, FitRunErrors&& best_e) {
  const Axis a = ax.axis;
  for (const EffectKind replaced : replaced_by(t.kind))
    for (DataEffect& other : out.effects)
      if (other.kind == replaced && other.axis == a && other.kept &&
          feeddrive::effect_def(replaced).enabled(out.final_machine.axes[ai()].drive.effects)) {
        other.kept = false;
        other.evidence += fmt::format("; replaced by {}, which lowers the held-out error further",
                                      feeddrive::effect_name(t.kind));
      }
  out.final_machine = with_trial(out.final_machine, a, t, best);
  if (t.torque) {
    const DriveRefit* d = t.drives.empty() ? nullptr : &t.drives[best];
    for (std::size_t k : rows.all) rows.T[k] -= t.torque(k, t.sets[best], d);
  }
  current = std::move(best_e);
}

/// `set` offered twice, with the drive refitted from `joint` against
/// `without` (drive_moved) keeping J and B and moving them, each with its note.
void offer_with_drive_refits(Trial& t, const DataSearch& s, const ParamSet& set, const LsqResult& joint,
                             const LsqResult& without) {
  const feeddrive::DriveParams& cur = s.out.final_machine.axes[s.ai()].drive;
  for (const bool move_J_B : {false, true}) {
    t.sets.push_back(set);
    t.drives.push_back(drive_moved(cur, joint, without, s.ax.one_coulomb_level, move_J_B));
    t.set_notes.push_back(moved_J_B_note(move_J_B, cur, t.drives.back()));
  }
}

/// Replays each of the trial's sets on the fitting rows, the best on the
/// held-out rows, and keeps the effect where the held-out error falls.
void DataSearch::attempt(const Trial& t) {
  DataEffect eff;
  eff.set_kind(t.kind);
  eff.axis = ax.axis;
  eff.evidence = t.evidence;
  BestSet b = best_set_on_fit_rows(t);
  if (b.set < t.set_notes.size()) eff.evidence += t.set_notes[b.set];
  for (const auto& [k, v] : t.sets[b.set]) eff.params[param_key(t.kind, k)] = v;
  for (const auto& k : keys)
    if (const auto it = current.held.nrms.find(k); it != current.held.nrms.end()) eff.before_channels[k] = it->second;
  eff.before = eff.before_channels.count(ax.channel.column) ? eff.before_channels.at(ax.channel.column) : 0.0;
  eff.after = eff.before;
  if (b.errors.ok)
    judge_held_out(t, b.errors, eff);
  else
    eff.evidence += "; the replay with it failed (not kept)";
  if (eff.kept) keep(t, b.set, std::move(b.errors));
  out.effects.push_back(std::move(eff));
}

// delay: a torque that follows the loop's command late.
void detect_delay_in_data(DataSearch& s) {
  if (!s.fast) return;
  const AxisFromData& ax = s.ax;
  const AxisRows& rows = s.rows;
  const double dt = s.dt;
  double lag = 0.0;  // rows of the log, whole or part (AxisFromData::torque_lag_fraction)
  std::optional<controller::CascadeGains> gains;
  std::string why;
  if (ax.velocity_loop_from_data) {
    lag = ax.torque_lag_rows();
    gains = ax.gains_at_lag;
    const std::string late = fmt::format("{:.3g} ms ({:g} samples) late", 1e3 * lag * dt, lag);
    why = ax.torque_command_logged
              ? fmt::format("the motion answers to the logged torque command {} beyond the current loop's lag (the "
                            "drive fitted so)",
                            late)
              : fmt::format("the logged torque follows the PI law on the logged speed error best {} (the law "
                            "refitted at that lag: Kvp {:.4g}, Tn {:.4g} s)",
                            late, ax.gains_at_lag.Kvp_torque_s_per_rad, ax.gains_at_lag.Tn_s);
  } else {
    const auto max_lag = static_cast<std::size_t>(std::clamp(std::lround(0.01 / dt), 1L, 10L));
    std::vector<double> mse(max_lag + 1, 0.0);
    for (std::size_t L = 0; L <= max_lag; ++L)
      for (std::size_t k : rows.all) {
        const auto [run, row] = rows.at[k];
        if (row < L) continue;
        const auto* m = model_channel(s.current.replays[run], ax.axis, ax.channel, true);
        const double d = rows.T[k] - (m ? (*m)[row - L] : 0.0);
        mse[L] += d * d;
      }
    const auto it = std::min_element(mse.begin(), mse.end());
    const auto L = static_cast<std::size_t>(it - mse.begin());
    if (L > 0 && *it < 0.8 * mse[0]) {
      lag = static_cast<double>(L);
      why = fmt::format("the logged torque matches the replay's {} samples later (mean square {:.3g} of {:.3g} "
                        "at no lag)",
                        L, *it / static_cast<double>(rows.all.size()), mse[0] / static_cast<double>(rows.all.size()));
    }
  }
  if (lag == 0.0) return;
  Trial t;
  t.kind = EffectKind::kDelay;
  t.sets = {{{EffectParam::delay_delay_s, lag * dt}}};
  t.gains = gains;
  t.evidence = why;
  s.attempt(t);
}

namespace {

// current_saturation where the log holds the loop's torque command, before
// the current loop: a limit on the motor's current never shows there (the
// command runs on past it, the more as the loop falls behind the motion it
// cannot get); it shows in the motion, which answers to the clipped torque.
// The drive (the columns a, v, [v > 0], -[v < 0], 1) is fitted on the
// motor's torque rebuilt from the command (AxisRows::T) clipped at levels
// from the rows' largest down to their 90th percentile, in steps of 1 %:
// clipping below what the motion took raises the residual, at the limit it
// falls. The level with the least residual is shown where it leaves under
// kLimitGain of the unclipped fit's, the fall is kMinT standard errors of
// the rows' sum of squares (n (r0^2 - r1^2) / (r1^2 corr), as a t squared),
// and at least 10 rows lie beyond it. On the sweep's runs with a logged
// command the level comes out within 1 % at all three magnitudes, and the
// residual falls by 1.7, 8.6 and 45 %: the smallest limit is touched by a
// few rows, whose torque the replay without it already gets to 0.10.
// Behind a current loop with no lag the command and the motor's torque are
// the same channel but for the limit, so the log was read as the motor's
// (choose_torque_command has no lag to find) and the limit never looked
// for: the limit at twice the sweep's size was taken for load-dependent,
// position-dependent and rising friction, tracking at 0.030 on the other
// program. A log read as the motor's is therefore searched too, and the
// trial reads it as the command (Trial::reads_command): a log of the
// motor's own torque, which the motion cannot answer to clipped, replays
// worse so and is refused. Only on logs that resolve the velocity loop
// (DataSearch::fast), where a current loop's lag would have shown: on the
// U-Mich runs (100 ms, the drive fitted on the commanded kinematics) the
// scan found levels on x and y of umich05 whose replays were refused, at a
// cost of minutes of replays a run.
constexpr double kLimitGain = 0.98;
struct LimitInMotion {
  double level{0.0};
  std::size_t beyond{0};
  LsqResult clipped, plain;
};
std::optional<LimitInMotion> limit_in_motion(const AxisRows& rows, double corr) {
  const std::vector<const std::vector<double>*> cols = rows.drive_columns();
  std::vector<double> mag;
  mag.reserve(rows.all.size());
  for (std::size_t k : rows.all) mag.push_back(std::abs(rows.T[k]));
  if (mag.size() < 100) return std::nullopt;
  std::sort(mag.begin(), mag.end());
  const double top = mag.back(), p90 = mag[(9 * mag.size()) / 10];
  LimitInMotion out;
  out.plain = least_squares(cols, rows.T, rows.all, corr);
  if (!(out.plain.ok && top > 0.0)) return std::nullopt;
  std::vector<double> clipped(rows.T.size(), 0.0);
  for (double L = 0.99 * top; L > p90; L *= 0.99) {
    for (std::size_t k : rows.all) clipped[k] = std::clamp(rows.T[k], -L, L);
    const LsqResult ls = least_squares(cols, clipped, rows.all, corr);
    if (ls.ok && ls.residual_rms < (out.clipped.ok ? out.clipped.residual_rms : out.plain.residual_rms)) {
      out.clipped = ls;
      out.level = L;
    }
  }
  if (!out.clipped.ok) return std::nullopt;
  const double r0 = out.plain.residual_rms, r1 = out.clipped.residual_rms;
  const double F = static_cast<double>(mag.size()) * (r0 * r0 - r1 * r1) / (r1 * r1 * corr);
  if (!(r1 < kLimitGain * r0 && F >= kMinT * kMinT)) return std::nullopt;
  out.beyond = static_cast<std::size_t>(
      std::count_if(mag.begin(), mag.end(), [&out](double m) { return m > out.level; }));
  if (out.beyond < 10) return std::nullopt;
  return out;
}

void current_limit_from_motion(DataSearch& s) {
  const std::optional<LimitInMotion> lim = limit_in_motion(s.rows, s.corr);
  if (!lim) return;
  Trial t;
  t.kind = EffectKind::kCurrentSaturation;
  t.reads_command = !s.ax.torque_command_logged;
  offer_with_drive_refits(t, s, {{EffectParam::current_saturation_i_max_A, lim->level}}, lim->clipped, lim->plain);
  t.evidence = fmt::format(
      "the log's {} is the loop's command, which a limit on the motor's current does not clip{}: the motion "
      "answers to that command clipped at {:.4g} (in the channel's unit; {} of its rows beyond), which takes the "
      "drive's residual from {:.4g} to {:.4g}",
      s.ax.channel.column,
      t.reads_command ? " (the motion behind it shows no current loop's lag, so only the limit tells the two apart)"
                      : "",
      lim->level, lim->beyond, lim->plain.residual_rms, lim->clipped.residual_rms);
  const AxisRows& rows = s.rows;
  t.torque = [&rows](std::size_t k, const ParamSet& p, const DriveRefit*) {
    const double L = param_value(p, EffectParam::current_saturation_i_max_A);
    return rows.T[k] - std::clamp(rows.T[k], -L, L);
  };
  s.attempt(t);
}

}  // namespace

// current_saturation: the log's torque clips where the replay's goes beyond.
// Under noise the log's largest value sits about four noise RMS above the
// limit (the largest of some hundred held samples), so the band the held
// samples are looked for in, and the level the replay must ask beyond, are
// widened and lowered by the noise the channel shows.
// Where the log shows no flat top, the limit is looked for in the motion
// (current_limit_from_motion): on a log read as the command, and on a fast
// log read as the motor's, which the candidate then reads as the command.
void detect_current_saturation_in_data(DataSearch& s) {
  const AxisFromData& ax = s.ax;
  const AxisRows& rows = s.rows;
  double log_max = 0.0, model_max = 0.0;
  for (std::size_t k : rows.all) {
    const auto [run, row] = rows.at[k];
    log_max = std::max(log_max, std::abs(s.runs[run].run->trace.at(ax.channel.column)[row]));
    model_max = std::max(model_max, std::abs(s.model_at(k)));
  }
  const double noise = s.noise_rms;
  const double band = std::max(0.02 * log_max, 4.0 * noise);
  // The largest level the log surely shows held: its largest value less the
  // noise's reach.
  const double held_max = log_max - 3.0 * noise;
  std::vector<double> top;
  for (std::size_t k : rows.all) {
    const auto [run, row] = rows.at[k];
    const double v = std::abs(s.runs[run].run->trace.at(ax.channel.column)[row]);
    if (v >= log_max - band) top.push_back(v);
  }
  if (!(held_max > 0.0 && model_max > 1.05 * held_max &&
        top.size() >= clipped_rows(s.runs.front().run->sample_period_s))) {
    if (ax.torque_command_logged || s.fast) current_limit_from_motion(s);
    return;
  }
  auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
    return v[v.size() / 2];
  };
  // The level: the log's median where the replay asks, the same way, for
  // more than the log surely shows held (the limit surely holds there; the
  // largest value itself sits the noise above the limit), or else the median
  // of the samples in the band below the largest.
  std::vector<double> held;
  for (std::size_t k : rows.all) {
    const auto [run, row] = rows.at[k];
    const double T = s.runs[run].run->trace.at(ax.channel.column)[row], m = s.model_at(k);
    if (m * T > 0.0 && std::abs(m) > held_max) held.push_back(std::abs(T));
  }
  const bool from_held = held.size() >= 10;
  const double level = median(from_held ? held : top);
  Trial t;
  t.kind = EffectKind::kCurrentSaturation;
  t.sets = {{{EffectParam::current_saturation_i_max_A, level}}};
  // Where the law holds its integral at a limit (AxisFromData::law_limit_rows)
  // the limit clamps the law's command, which holds it alike.
  if (ax.law_holds_integral_at_limit()) {
    t.gains = s.out.final_machine.axes[s.ai()].loop.cascade;
    t.gains->T_max = level;
  }
  t.evidence = fmt::format(
      "the log's {} holds {} samples within {:.3g} of its largest value {:.4g} (noise {:.3g} RMS) while the replay "
      "asks for up to {:.4g}: a limit at {:.4g} (in the channel's unit; {})",
      ax.channel.column, top.size(), band, log_max, noise, model_max, level,
      from_held ? fmt::format("the log's median over the {} samples where the replay asks for more than {:.4g}",
                              held.size(), held_max)
                : std::string("the median of those samples"));
  s.attempt(t);
}

// stribeck: friction above the Coulomb level at low speed, the drive
// refitted with the curve, T = J a + B v + Tc_dir [dir] (1 - g) + Ts sgn g + c, g = exp(-(v/ws)^2).
void detect_stribeck_in_data(DataSearch& s) {
  const AxisRows& rows = s.rows;
  std::vector<double> p1(rows.all.size()), n1(rows.all.size()), sg(rows.all.size());
  // The drive with the curve at speed scale ws on `fit_rows`: the columns a,
  // v, [v > 0] (1 - g), -[v < 0] (1 - g), the constant, dir g, with
  // g = exp(-(v/ws)^2).
  auto fit_at = [&](double ws, const std::vector<std::size_t>& fit_rows) {
    for (std::size_t k : fit_rows) {
      const double g = feeddrive::stribeck_shape(rows.vel[k], ws);
      p1[k] = rows.pos[k] * (1.0 - g);
      n1[k] = rows.neg[k] * (1.0 - g);
      sg[k] = rows.dir[k] * g;
    }
    return least_squares({&rows.acc, &rows.vel, &p1, &n1, &rows.one, &sg}, rows.T, fit_rows, s.corr);
  };
  // The drive without the curve on every row: what the drive refits move
  // from (to the curve's fit on the moving rows too, where that is the one
  // taken). The moving rows' own comparison fit, below, leaves the constant
  // out: there it is one with the two levels.
  const LsqResult base = least_squares(s.base_cols, rows.T, rows.all, s.corr);
  if (!base.ok) return;
  struct Scan {
    LsqResult best;
    double ws{0.0}, t{0.0}, base_res{0.0};
    bool shown{false};
  };
  // Steps of 1.35, then of 1.02 about the best (the levels are linear
  // given ws, so the scan is the whole search); shown where the curve's
  // level over the Coulomb mean has kMinT standard errors and the residual
  // falls by 1 %.
  auto scan = [&](const std::vector<std::size_t>& fit_rows, const LsqResult& without) {
    Scan sc;
    sc.base_res = without.residual_rms;
    double best_res = sc.base_res;
    auto try_ws = [&](double ws) {
      const LsqResult ls = fit_at(ws, fit_rows);
      if (ls.ok && ls.residual_rms < best_res) {
        best_res = ls.residual_rms;
        sc.ws = ws;
        sc.best = ls;
      }
    };
    for (double ws = rows.v_move; ws < 0.5 * rows.v_high; ws *= 1.35) try_ws(ws);
    if (sc.ws > 0.0) {
      const double w0 = sc.ws;
      for (double ws = w0 / 1.35; ws <= w0 * 1.35; ws *= 1.02) try_ws(ws);
    }
    if (!(sc.ws > 0.0)) return sc;
    const double Tc_mean = 0.5 * (sc.best.theta[2] + sc.best.theta[3]);
    sc.t = sc.best.stderr_theta[5] > 0.0 ? (sc.best.theta[5] - Tc_mean) / sc.best.stderr_theta[5] : 0.0;
    sc.shown = sc.t >= kMinT && sc.best.residual_rms < 0.99 * sc.base_res;
    return sc;
  };
  // On every row, and where that does not show the curve, on the moving rows
  // alone: rows at rest held by stiction hold any torque within the
  // breakaway, and where they are few (a contour's sticks at its reversals
  // and a few dwells) they set the constant, and the levels and B with it,
  // off what the moving rows show (on a contour program: the constant 9.5
  // raw for the truth's 2, the levels 7.8 and 20 for 10 and 6, and the curve
  // not shown). There the constant is told from the levels by the curve's
  // rows at low speed.
  bool moving_only = false;
  Scan sc = scan(rows.all, base);
  if (!sc.shown) {
    const LsqResult moving_base =
        least_squares({&rows.acc, &rows.vel, &rows.pos, &rows.neg}, rows.T, rows.moving, s.corr);
    if (!moving_base.ok) return;
    sc = scan(rows.moving, moving_base);
    moving_only = true;
  }
  if (!sc.shown) return;
  const double best_ws = sc.ws, Ts = sc.best.theta[5], t_ex = sc.t, best_res = sc.best.residual_rms;
  const double Tc_mean = 0.5 * (sc.best.theta[2] + sc.best.theta[3]);
  Trial t;
  t.kind = EffectKind::kStribeck;
  for (double f : {0.7, 1.0, 1.4}) {
    const LsqResult ls = fit_at(f * best_ws, moving_only ? rows.moving : rows.all);
    if (!ls.ok) continue;
    // The breakaway level as fitted on the axis's own motion.
    const double Ts_set = ls.theta[5];
    for (const bool move_J_B : {false, true}) {
      const DriveRefit d =
          drive_moved(s.out.final_machine.axes[s.ai()].drive, ls, base, s.ax.one_coulomb_level, move_J_B);
      if (!(Ts_set > std::max(d.Tc_pos, d.Tc_neg))) continue;
      t.sets.push_back({{EffectParam::stribeck_Ts_static, Ts_set}, {EffectParam::stribeck_ws, f * best_ws}});
      t.drives.push_back(d);
      t.set_notes.push_back(moved_J_B_note(move_J_B, s.out.final_machine.axes[s.ai()].drive, d));
    }
  }
  t.evidence = fmt::format("friction rising to {:.4g} (t = {:.1f} over the Coulomb mean {:.4g}) below "
                           "{:.3g} mm/s cuts the fitting rows' torque residual from {:.4g} to {:.4g}{}",
                           Ts, t_ex, Tc_mean, best_ws, sc.base_res, best_res,
                           moving_only ? " (on the rows where the axis moves, the held torques at rest left out)"
                                       : "");
  t.torque = [&rows](std::size_t k, const ParamSet& p, const DriveRefit* d) {
    const double Tc = rows.dir[k] > 0 ? d->Tc_pos : d->Tc_neg;
    return rows.dir[k] * feeddrive::stribeck_excess_Nm(param_value(p, EffectParam::stribeck_Ts_static), Tc,
                                                       rows.vel[k], param_value(p, EffectParam::stribeck_ws));
  };
  if (!t.sets.empty()) s.attempt(t);
}

namespace {

/// The band of bins along the travel with the largest excess of the signed
/// residual (sum squared over count), at least `min_rows` rows and under
/// three quarters of the travel: its first and last bin, or nullopt.
std::optional<std::pair<std::size_t, std::size_t>> friction_band(const Bins& bins, std::size_t n_bins,
                                                                 double min_rows) {
  double best = 0.0;
  std::size_t bi = 0, bj = 0;
  for (std::size_t i = 0; i < n_bins; ++i) {
    double sum = 0.0, cnt = 0.0;
    for (std::size_t j = i; j < n_bins && j - i + 1 < (3 * n_bins) / 4; ++j) {
      sum += bins.mean[j] * static_cast<double>(bins.count[j]);
      cnt += static_cast<double>(bins.count[j]);
      if (cnt < min_rows || sum <= 0.0) continue;
      if (sum * sum / cnt > best) {
        best = sum * sum / cnt;
        bi = i;
        bj = j;
      }
    }
  }
  if (!(best > 0.0)) return std::nullopt;
  return std::pair{bi, bj};
}

}  // namespace

// position_dependent_friction: the base fit's residual, signed by the
// direction of motion, averaged in 60 bins along the travel; the band of
// bins with the largest excess, fitted with the drive.
void detect_position_dependent_friction_in_data(DataSearch& s) {
  const AxisRows& rows = s.rows;
  // On moving rows the constant is the mean of the two Coulomb columns.
  const std::vector<const std::vector<double>*> moving_cols{&rows.acc, &rows.vel, &rows.pos, &rows.neg};
  const LsqResult b = least_squares(moving_cols, rows.T, rows.moving, s.corr);
  if (!(b.ok && rows.x_hi > rows.x_lo)) return;
  std::vector<double> rho(rows.all.size(), 0.0);
  for (std::size_t k : rows.moving) {
    double pred = 0.0;
    for (std::size_t j = 0; j < moving_cols.size(); ++j) pred += (*moving_cols[j])[k] * b.theta[j];
    rho[k] = (rows.T[k] - pred) * rows.dir[k];
  }
  constexpr std::size_t kBins = 60;
  const Bins bins = bin_means(rows.x, rho, rows.moving, rows.x_lo, rows.x_hi, kBins);
  const double min_rows = std::max(200.0, 0.02 * static_cast<double>(rows.moving.size()));
  const auto band = friction_band(bins, kBins, min_rows);
  if (!band) return;
  const double w = (rows.x_hi - rows.x_lo) / static_cast<double>(kBins);
  double x0 = rows.x_lo + w * static_cast<double>(band->first);
  double x1 = rows.x_lo + w * static_cast<double>(band->second + 1);
  // A band that reaches an end of the travel the axis moves over goes on
  // past it as far as the data shows: to the rows at rest beyond it, and
  // half a bin further. A program that stops at the end of its travel
  // (a contour's dwells where its arcs start and end) holds its stops
  // there, and their breakaway is the band's: cut at the last moving row,
  // the replay's stops slipped out of the held torque (on the contour sweep,
  // held-out torque 0.25 against 0.13 without the band).
  double x_rest_lo = x0, x_rest_hi = x1;
  for (std::size_t k : rows.all) {
    x_rest_lo = std::min(x_rest_lo, rows.x[k]);
    x_rest_hi = std::max(x_rest_hi, rows.x[k]);
  }
  if (band->first == 0) x0 = x_rest_lo - 0.5 * w;
  if (band->second + 1 == kBins) x1 = x_rest_hi + 0.5 * w;
  std::vector<double> psi(rows.all.size(), 0.0);
  for (std::size_t k : rows.all)
    if (feeddrive::in_friction_band(rows.x[k], x0, x1)) psi[k] = rows.dir[k];
  const LsqResult f = least_squares(s.with_base({&psi}), rows.T, rows.all, s.corr);
  const LsqResult f0 = least_squares(s.base_cols, rows.T, rows.all, s.corr);
  if (!(f.ok && f0.ok && f.theta[5] > 0.0 && t_of(f, 5) >= kMinT)) return;
  Trial t;
  t.kind = EffectKind::kPositionDependentFriction;
  offer_with_drive_refits(t, s,
                          {{EffectParam::position_dependent_friction_dTc_Nm, f.theta[5]},
                           {EffectParam::position_dependent_friction_x_start_mm, x0},
                           {EffectParam::position_dependent_friction_x_end_mm, x1}},
                          f, f0);
  t.evidence = fmt::format("friction {:+.4g} (t = {:.1f}) between x = {:.4g} and {:.4g} mm, in the "
                           "channel's unit",
                           f.theta[5], t_of(f, 5), x0, x1);
  t.torque = [&rows](std::size_t k, const ParamSet& p, const DriveRefit*) {
    return feeddrive::in_friction_band(rows.x[k], param_value(p, EffectParam::position_dependent_friction_x_start_mm),
                                       param_value(p, EffectParam::position_dependent_friction_x_end_mm))
               ? param_value(p, EffectParam::position_dependent_friction_dTc_Nm) * rows.dir[k]
               : 0.0;
  };
  s.attempt(t);
}

// load_dependent_friction: friction that grows with the torque the drive
// transmits, Tf = dir (Tc_dir + f |Tm|). Fitted with the drive as a column
// |T^| dir, T^ the drive's own torque on the row (its a, v, direction and
// constant columns, and the friction found so far, refined twice): the
// logged torque's noise is then on one side of the fit only (|T| dir
// against T would read white noise, which a driving row adds to both, as
// friction). Proposed where its share is positive at kMinTOneColumn, as
// 0.7, 1 and 1.4 times the fitted share with the Coulomb levels and the
// constant refitted beside each: the fitting rows' replay chooses, since
// the share also raises the breakaway, which the loop's tracking through
// stops and reversals answers to and the regression on moving rows does not
// see (one share: the sweep's delay with it tracked the other program at
// 0.0102, against 0.0073 chosen among three). Judged on the replay as every
// candidate.
void detect_load_dependent_friction_in_data(DataSearch& s) {
  if (!s.fast) return;
  const AxisRows& rows = s.rows;
  const std::size_t nb = s.base_cols.size();
  const LsqResult base = least_squares(s.base_cols, rows.T, rows.all, s.corr);
  if (!base.ok) return;
  std::vector<double> psi;
  const LsqResult joint = fit_with_own_torque_load(s.base_cols, rows.T, rows.all, rows.dir, s.corr, 3, psi);
  if (!joint.ok) return;
  const double f = joint.theta[nb];
  const double t_f = t_of(joint, nb);
  if (!(f > 0.0 && f <= 0.5 && t_f >= kMinTOneColumn)) return;
  Trial t;
  t.kind = EffectKind::kLoadDependentFriction;
  std::vector<double> rest(rows.all.size(), 0.0);
  for (const double m : {0.7, 1.0, 1.4}) {
    const double fm = std::min(m * f, 0.5);
    for (std::size_t k : rows.all) rest[k] = rows.T[k] - fm * psi[k];
    const LsqResult ls = least_squares(s.base_cols, rest, rows.all, s.corr);
    if (!ls.ok) continue;
    t.sets.push_back({{EffectParam::load_dependent_friction_fraction, fm}});
    t.drives.push_back(drive_moved(s.out.final_machine.axes[s.ai()].drive, ls, base, s.ax.one_coulomb_level));
  }
  if (t.sets.empty()) return;
  t.evidence = fmt::format("friction that grows with the drive's load, {:.3g} % of the motor's torque (t = {:.1f}), "
                           "as a screw loses under load, cuts the fitting rows' torque residual from {:.4g} to "
                           "{:.4g}",
                           100.0 * f, t_f, base.residual_rms, joint.residual_rms);
  t.torque = [psi](std::size_t k, const ParamSet& p, const DriveRefit*) {
    return param_value(p, EffectParam::load_dependent_friction_fraction) * psi[k];
  };
  s.attempt(t);
}

// cogging: a torque ripple periodic in the motor angle (x / rg, rg = 1
// mm/rad here), fitted with the drive on the axis's own motion (its
// logged speed, where there is one: a ripple the loop does not follow
// shows in the speed, not in the commanded motion).
void detect_cogging_in_data(DataSearch& s) {
  if (!s.fast) return;
  const AxisRows& rows = s.rows;
  const double P_min = std::max(0.1, 8.0 * s.dt * rows.v_high), P_max = std::min(40.0, (rows.x_hi - rows.x_lo) / 3.0);
  std::vector<double> sn(rows.all.size()), cs(rows.all.size());
  const std::vector<const std::vector<double>*> cols{&rows.acc, &rows.vel, &rows.pos, &rows.neg, &sn, &cs};
  auto fit = [&](double P) {
    for (std::size_t k : rows.all) {
      sn[k] = std::sin(2.0 * M_PI * rows.x[k] / P);
      cs[k] = std::cos(2.0 * M_PI * rows.x[k] / P);
    }
    return least_squares(cols, rows.T, rows.moving, s.corr);
  };
  const LsqResult base = least_squares({&rows.acc, &rows.vel, &rows.pos, &rows.neg}, rows.T, rows.moving, s.corr);
  if (!(base.ok && P_max > P_min)) return;
  const auto [P, ls] = scan_period(P_min, P_max, fit);
  if (!(P > 0.0 && t_pair(ls, 4) >= kMinT && ls.residual_rms < 0.98 * base.residual_rms)) return;
  const double A = std::hypot(ls.theta[4], ls.theta[5]), phase = std::atan2(ls.theta[5], ls.theta[4]);
  Trial t;
  t.kind = EffectKind::kCogging;
  t.sets = {{{EffectParam::cogging_amplitude_Nm, A},
             {EffectParam::cogging_cycles_per_rev, 2.0 * M_PI / P},
             {EffectParam::cogging_phase_rad, phase}}};
  t.evidence = fmt::format("a ripple of {:.4g} (in the channel's unit) with a period of {:.4g} mm of travel "
                           "(t = {:.1f}) cuts the moving rows' torque residual from {:.4g} to {:.4g}",
                           A, P, t_pair(ls, 4), base.residual_rms, ls.residual_rms);
  t.torque = [&rows](std::size_t k, const ParamSet& p, const DriveRefit*) {
    // rg = 1 mm/rad in a machine identified from data.
    return feeddrive::cogging_torque_Nm(param_value(p, EffectParam::cogging_amplitude_Nm),
                                        param_value(p, EffectParam::cogging_cycles_per_rev),
                                        param_value(p, EffectParam::cogging_phase_rad), rows.x[k], 1.0);
  };
  s.attempt(t);
}

namespace {

// screw_pitch_error where no motor speed is logged and the speed is the
// encoder's own (add_speed_from_position), with the velocity law fitted
// from the logged velocity command and torque: the law's integral of the
// speed error is then short by the lead error e(x) and its speed error by
// de/dt, so its residual follows Ki e + Kvp de/dt. The period is found with
// the law (lead_error_in_law, in identify_velocity_loop, so that the gains,
// the dead time and the feedforward are fitted with it); here the law as
// the axis finally has it (dead time, current-loop lag, feedforward) gives
// e's amplitude and phase, its sin/cos coefficients over Ki, replayed
// where the amplitude is half a position step or more.
void screw_pitch_error_from_law(DataSearch& s) {
  const AxisFromData& ax = s.ax;
  if (!(ax.velocity_loop_from_data && ax.law_lead_period_mm > 0.0)) return;
  LawFitOptions o = law_options(ax, {.lag = ax.torque_lag_samples,
                                     .lag_fraction = ax.torque_lag_fraction,
                                     .lag_a = ax.gains.tau_i_s > 0.0 ? std::exp(-s.dt / ax.gains.tau_i_s) : 0.0,
                                     .torque_ff = ax.torque_feedforward});
  o.lead_period_mm = 0.0;
  const VelocityLoopFit without = fit_velocity_loop(s.runs, ax.axis, ax.channel.column, o);
  o.lead_period_mm = ax.law_lead_period_mm;
  LeadInLaw l;
  l.P_mm = ax.law_lead_period_mm;
  l.ls = fit_velocity_loop(s.runs, ax.axis, ax.channel.column, o).ls;
  l.column = lead_column(o);
  if (!(without.ls.ok && l.ls.ok && l.ls.theta[1] > 0.0)) return;
  const double A = l.amplitude_mm();
  if (!(A >= 0.5 * s.q)) return;
  Trial tr;
  tr.kind = EffectKind::kScrewPitchError;
  tr.sets = {{{EffectParam::screw_pitch_error_amplitude_mm, A},
              {EffectParam::screw_pitch_error_period_mm, l.P_mm},
              {EffectParam::screw_pitch_error_phase_rad, l.phase_rad()}}};
  tr.evidence = fmt::format("no motor speed is logged, so the velocity law runs on the encoder's speed, whose "
                            "integral a lead error shifts by the error itself: a lead error of {:.4g} mm with a "
                            "period of {:.4g} mm takes the law's residual from {:.4g} to {:.4g}",
                            A, l.P_mm, without.ls.residual_rms, l.ls.residual_rms);
  s.attempt(tr);
}

}  // namespace

// The motor's travel (the logged speed integrated, trapezoids, from the
// logged position at each segment's start) less the logged position, over
// the run's first `rows` rows: what lies between the motor and the encoder
// (a gap, a lead error, a stretch), with the integration's drift.
std::vector<double> motor_travel_less_position(const RunData& rd, Axis a, double dt, std::size_t rows) {
  const auto& xm = rd.run->trace.at(col(a, "_mm"));
  const auto& vm = rd.run->trace.at(col(a, "_v_mm_s"));
  std::vector<double> d(rows, 0.0);
  for (const Segment& sg : rd.segments) {
    double travel = 0.0;
    for (std::size_t k = sg.begin; k < std::min(sg.end, rows); ++k) {
      travel = k == sg.begin ? xm[k] : travel + 0.5 * (vm[k] + vm[k - 1]) * dt;
      d[k] = travel - xm[k];
    }
  }
  return d;
}

// screw_pitch_error, where a fast log has the motor's speed beside the
// encoder's position: the encoder reads x + A sin(2 pi x / P + phase) while
// the motor moves x, so the motor's travel less the logged position is
// -A sin(2 pi x / P + phase) plus what else lies between them. Regressed on
// that, with as nuisances a constant per second of each segment (the
// integration's drift and the segment's start; taken out as the block's
// mean), the logged speed (a speed logged late), the position (a speed
// scaled off the encoder's), the torque (a stretch under load) and the
// direction the axis last moved (a gap). Integrated, the position's
// rounding stays one quantum where the speed of the differenced position
// would carry it divided by the sample period. The standard errors count
// the residual's correlation from its lag-one autocorrelation. Where the
// speed is the encoder's own, screw_pitch_error_from_law.
void detect_screw_pitch_error_in_data(DataSearch& s) {
  if (s.fast && s.fine && s.logs_position() &&
      has_lowpassed_twin(s.runs.front().run->trace, s.ax.channel.column)) {
    screw_pitch_error_from_law(s);
    return;
  }
  if (!(s.fast && s.fine && s.rows.measured_speed && s.logs_position())) return;
  const AxisRows& rows = s.rows;
  const std::size_t n = rows.all.size();
  // Per run: the travel less the position, the direction last moved, and
  // each row's block (segment and whole seconds from its start).
  std::vector<std::vector<double>> travel(s.runs.size());
  std::vector<std::vector<double>> last_dir(s.runs.size());
  std::vector<std::vector<std::size_t>> block_of(s.runs.size());
  std::size_t blocks = 0;
  const auto rows_per_block = std::max<std::size_t>(1, static_cast<std::size_t>(std::lround(1.0 / s.dt)));
  for (std::size_t run = 0; run < s.runs.size(); ++run) {
    const RunData& rd = s.runs[run];
    travel[run] = motor_travel_less_position(rd, s.axis(), s.dt, rd.n_fit);
    last_dir[run].assign(rd.n_fit, 0.0);
    block_of[run].assign(rd.n_fit, 0);
    const auto& vm = rd.run->trace.at(col(s.axis(), "_v_mm_s"));
    for (const Segment& sg : rd.segments) {
      int last = 0;
      for (std::size_t k = sg.begin; k < std::min(sg.end, rd.n_fit); ++k) {
        if (const int dr = direction(vm[k], rd.v_move[s.ai()]); dr != 0) last = dr;
        last_dir[run][k] = last;
        block_of[run][k] = blocks + (k - sg.begin) / rows_per_block;
      }
      if (sg.begin < std::min(sg.end, rd.n_fit)) blocks += (std::min(sg.end, rd.n_fit) - 1 - sg.begin) / rows_per_block + 1;
    }
  }
  std::vector<std::size_t> block(n);
  std::vector<double> d(n), dir(n);
  for (std::size_t k : rows.all) {
    const auto [run, row] = rows.at[k];
    d[k] = travel[run][row];
    dir[k] = last_dir[run][row];
    block[k] = block_of[run][row];
  }
  // A column less its mean over each block (the block's constant taken out).
  std::vector<double> sum(blocks), count(blocks, 0.0);
  for (std::size_t k : rows.all) count[block[k]] += 1.0;
  auto demeaned = [&](const std::vector<double>& c) {
    std::fill(sum.begin(), sum.end(), 0.0);
    for (std::size_t k : rows.all) sum[block[k]] += c[k];
    std::vector<double> out(n);
    for (std::size_t k : rows.all) out[k] = c[k] - sum[block[k]] / count[block[k]];
    return out;
  };
  const std::vector<double> d_b = demeaned(d), v_b = demeaned(rows.vel_m), x_b = demeaned(rows.x),
                            T_b = demeaned(rows.T), dir_b = demeaned(dir);
  std::vector<double> c1(n), c2(n), c1_b, c2_b;
  double corr = 1.0;
  auto fit = [&](double P) {
    const double w = 2.0 * M_PI / P;
    for (std::size_t k : rows.all) {
      c1[k] = -std::sin(w * rows.x[k]);
      c2[k] = -std::cos(w * rows.x[k]);
    }
    c1_b = demeaned(c1);
    c2_b = demeaned(c2);
    return least_squares({&v_b, &x_b, &T_b, &dir_b, &c1_b, &c2_b}, d_b, rows.all, corr);
  };
  const double P_min = std::max(0.5, 8.0 * s.dt * rows.v_high), P_max = (rows.x_hi - rows.x_lo) / 2.0;
  if (!(P_max > P_min)) return;
  auto [P, ls] = scan_period(P_min, P_max, fit);
  if (!(P > 0.0)) return;
  // The residual's lag-one autocorrelation rho at the best period, within
  // blocks: (1 + rho) / (1 - rho) rows count as one (an AR(1) residual),
  // at most a block's rows.
  ls = fit(P);
  double r0 = 0.0, r1 = 0.0, prev = 0.0;
  std::size_t prev_k = n;
  for (std::size_t k : rows.all) {
    const double e = d_b[k] - ls.theta[0] * v_b[k] - ls.theta[1] * x_b[k] - ls.theta[2] * T_b[k] -
                     ls.theta[3] * dir_b[k] - ls.theta[4] * c1_b[k] - ls.theta[5] * c2_b[k];
    r0 += e * e;
    if (prev_k != n && k == prev_k + 1 && block[k] == block[prev_k]) r1 += e * prev;
    prev = e;
    prev_k = k;
  }
  const double rho = r0 > 0.0 ? std::clamp(r1 / r0, 0.0, 0.999) : 0.0;
  corr = std::min((1.0 + rho) / (1.0 - rho), static_cast<double>(rows_per_block));
  ls = fit(P);
  const double A = std::hypot(ls.theta[4], ls.theta[5]);
  if (!(t_pair(ls, 4) >= kMinT && A >= 0.5 * s.q)) return;
  Trial t;
  t.kind = EffectKind::kScrewPitchError;
  t.sets = {{{EffectParam::screw_pitch_error_amplitude_mm, A},
             {EffectParam::screw_pitch_error_period_mm, P},
             {EffectParam::screw_pitch_error_phase_rad, std::atan2(ls.theta[5], ls.theta[4])}}};
  t.evidence = fmt::format("the motor's travel (the logged speed integrated) less the logged position runs as a "
                           "lead error of {:.4g} mm with a period of {:.4g} mm would make it (t = {:.1f}, "
                           "residual {:.2g} mm)",
                           A, P, t_pair(ls, 4), ls.residual_rms);
  s.attempt(t);
}

namespace {

// The steps, signed by the new direction, of the motor's travel (the logged
// speed integrated) less the logged position across the fitting part's
// reversals of one run: the mean over the 50 ms of motion before the stop
// against the mean 30 to 80 ms into the new move, each over rows whose
// logged speed has the direction of its side.
void travel_steps_at_reversals(const RunData& rd, Axis a, double dt, std::vector<double>& steps) {
  const std::size_t ai = index(a);
  const auto w = std::max<std::size_t>(2, static_cast<std::size_t>(std::lround(0.05 / dt)));
  const auto skip = static_cast<std::size_t>(std::lround(0.03 / dt));
  const auto& vm = rd.run->trace.at(col(a, "_v_mm_s"));
  const std::vector<double> d = motor_travel_less_position(rd, a, dt, rd.n_fit);
  std::vector<std::size_t> seg(rd.n_fit, 0);
  for (std::size_t s = 0; s < rd.segments.size(); ++s)
    for (std::size_t k = rd.segments[s].begin; k < std::min(rd.segments[s].end, rd.n_fit); ++k) seg[k] = s;
  // Mean of d over rows [b, e) whose logged speed has direction `dir`.
  auto mean_d = [&](std::size_t b, std::size_t e, int dir, std::size_t s) {
    double sum = 0.0;
    std::size_t n = 0;
    for (std::size_t k = b; k < e; ++k)
      if (seg[k] == s && rd.interior[k] && direction(vm[k], rd.v_move[ai]) == dir) {
        sum += d[k];
        ++n;
      }
    return n >= w / 2 ? std::optional<double>(sum / static_cast<double>(n)) : std::nullopt;
  };
  int last = 0;
  std::size_t last_end = 0;
  for (std::size_t k = 0; k < rd.n_fit; ++k) {
    const int dr = direction(rd.kin[ai].v_mm_per_s[k], rd.v_move[ai]);
    if (dr == 0) continue;
    if (last != 0 && dr != last && last_end + 1 >= w && k + skip + w <= rd.n_fit && seg[last_end] == seg[k]) {
      const auto before = mean_d(last_end + 1 - w, last_end + 1, last, seg[k]);
      const auto after = mean_d(k + skip, k + skip + w, dr, seg[k]);
      if (before && after) steps.push_back(dr * (*after - *before));
    }
    last = dr;
    last_end = k;
  }
}

// A gap of g mm found by `found`, replayed at each of `multiples` of it.
void attempt_gap(DataSearch& s, double g, const std::string& found, std::initializer_list<double> multiples) {
  Trial t;
  t.kind = EffectKind::kBacklash;
  for (double m : multiples) t.sets.push_back({{EffectParam::backlash_gap_mm, m * g}});
  t.evidence = found + fmt::format(": a gap of that size ({:g} to {:g} times it replayed)", *multiples.begin(),
                                   *(multiples.end() - 1));
  s.attempt(t);
}

// backlash, where a fast log has the motor's speed beside the encoder's
// position (a linear scale on the table, the loop closed across the
// gap): the motor's travel (the logged speed integrated) runs ahead of
// the table by half the gap while it pushes one way and behind by half
// while it pushes the other, so across each reversal of the command
// their difference steps by the gap, signed by the new direction. Read
// over the 50 ms of motion before the stop and 30 to 80 ms into the new
// move (the gap crossed at any acceleration over 100 mm/s^2), where the
// motor's speed has the direction of each; the median over the fitting
// part's reversals is the gap. A run without a gap steps by the
// encoder's rounding and the integration's drift, well under 3 counts
// (and so does a log whose speed is the encoder's own, derived from the
// position: then the lost motion in the position is looked for).
// Returns whether a gap was found this way.
bool backlash_from_speed(DataSearch& s) {
  if (!(s.fast && s.fine && s.rows.measured_speed && s.logs_position())) return false;
  std::vector<double> steps;
  for (const RunData& rd : s.runs) travel_steps_at_reversals(rd, s.axis(), s.dt, steps);
  if (steps.size() < 4) return false;
  std::nth_element(steps.begin(), steps.begin() + static_cast<std::ptrdiff_t>(steps.size() / 2), steps.end());
  const double g = steps[steps.size() / 2];
  // A step beyond 1 mm is no feed drive's gap but a run whose motor
  // and encoder have parted (a diverging loop, a slipping coupling).
  if (!(g >= 3.0 * s.q && g <= 1.0)) return false;
  attempt_gap(s, g,
              fmt::format("across {} reversals of the command the motor's travel (the logged speed integrated) "
                          "and the logged position part by a median {:.4g} mm ({:.1f} position quanta), signed by "
                          "the new direction",
                          steps.size(), g, g / s.q),
              {0.85, 1.0, 1.15});
  return true;
}

// backlash, from the position: after a reversal of the command the measured position lags
// the replay's in the new direction while the motor crosses the gap: the
// median over the fitting part's reversals of the peak of that lag in the
// 50 ms after each sizes the gap; gaps of 0.5 to 2 times it are replayed.
void backlash_from_position(DataSearch& s) {
  if (!s.fine) return;
  const std::size_t ai = s.ai();
  const auto span = std::max<std::size_t>(2, static_cast<std::size_t>(std::lround(0.05 / s.dt)));
  std::vector<double> peaks;
  for (std::size_t run = 0; run < s.runs.size(); ++run) {
    const RunData& rd = s.runs[run];
    const auto* xm = rd.run->trace.find(col(s.axis(), "_mm"));
    if (xm == nullptr || s.current.replays[run].x_mm[ai].empty()) continue;
    const auto& xr = s.current.replays[run].x_mm[ai];
    int last = 0;
    for (std::size_t k = 0; k < rd.n_fit; ++k) {
      const int d = direction(rd.kin[ai].v_mm_per_s[k], rd.v_move[ai]);
      if (d == 0) continue;
      if (last != 0 && d != last && k + span <= rd.n_fit) {
        double peak = -1e300;
        for (std::size_t j = k; j < k + span; ++j)
          if (rd.interior[j]) peak = std::max(peak, d * (xr[j] - (*xm)[j]));
        if (peak > -1e300) peaks.push_back(peak);
      }
      last = d;
    }
  }
  if (peaks.size() < 4) return;
  std::nth_element(peaks.begin(), peaks.begin() + static_cast<std::ptrdiff_t>(peaks.size() / 2), peaks.end());
  const double p = peaks[peaks.size() / 2];
  if (!(p >= 3.0 * s.q)) return;
  Trial t;
  t.kind = EffectKind::kBacklash;
  for (double m : {0.5, 1.0, 1.5, 2.0, 3.0}) t.sets.push_back({{EffectParam::backlash_gap_mm, m * 2.0 * p}});
  t.evidence = fmt::format("after a reversal the position lags the replay's by a median peak of {:.4g} mm "
                           "({} reversals, {:.1f} position quanta): lost motion of a gap of about {:.4g} mm (0.5 to 3 times it replayed)",
                           p, peaks.size(), p / s.q, 2.0 * p);
  s.attempt(t);
}

// backlash where no motor speed is logged and the speed is the encoder's
// own: the gap the velocity law shows (gap_in_law, found with the law in
// identify_velocity_loop), 0.6 to 1.15 times it replayed: under a position
// loop slower than the velocity loop the constants step by more than Ki
// times the gap (2 ms over 1 ms, the cascade sweep's 40 um gap at twice
// the size: 58 um with the law's Ki within 1 % of the truth's; why is not
// found), and the smallest of 0.85 to 1.15 times it, 50 um, tracked the
// other program at 0.018. Returns whether the law shows one.
bool backlash_from_law(DataSearch& s) {
  const double g = s.ax.law_gap_mm;
  if (!(s.fast && s.logs_position() && g > 0.0)) return false;
  attempt_gap(s, g,
              fmt::format("no motor speed is logged, so the velocity law runs on the encoder's speed: its "
                          "constant over each stretch of motion steps with the direction by Ki times {:.4g} mm "
                          "({:.1f} position quanta)",
                          g, g / s.q),
              {0.6, 0.7, 0.85, 1.0, 1.15});
  return true;
}

}  // namespace

void detect_backlash_in_data(DataSearch& s) {
  if (!backlash_from_law(s) && !backlash_from_speed(s)) backlash_from_position(s);
}

namespace {

/// The catalogue effects the log's rate and resolution can show, each
/// detected on the residual of the machine so far (the registry's from-data
/// detectors, in its order), replayed, and kept only where the held-out
/// error falls. Returns the errors of the machine it leaves on the fitting
/// runs (the replay the last judgement made of it).
FitRunErrors search_catalogue_effects(DataCalibration& out, const std::vector<RunData>& runs) {
  const double dt = runs.front().run->sample_period_s;
  const double q = measured_position_step(out, runs);
  FitRunErrors current = errors_on_fit_runs(runs, out.final_machine, out.axes, out.rounding, out.replays);
  if (!current.ok) return current;
  const auto detectors = from_data_search_order();
  for (const AxisFromData& ax : out.axis) {
    if (!ax.identified) continue;
    DataSearch s{out, runs, ax, current, axis_rows(runs, ax), axis_keys(ax), {}};
    if (s.rows.moving.size() < 200) continue;
    s.base_cols = s.rows.drive_columns();
    s.dt = dt;
    s.q = q;
    s.fast = resolves_velocity_loop(dt);
    // The second difference shows the noise only where the torque changes
    // little from row to row: on a log that resolves the loop, not every
    // 100 ms (at 4 ms a smooth torque's own second difference adds to it,
    // which makes the rules that take the noise off stricter, not looser).
    s.noise_rms = s.fast ? channel_noise_rms(s.rows, runs, ax.channel.column) : 0.0;
    // Where the speed is taken from the position the detectors fit the
    // torque low-passed alike (axis_rows), whose noise is correlated over
    // the filter's span as a model error is: the whole residual is counted
    // correlated there.
    const bool filtered = has_lowpassed_twin(runs.front().run->trace, ax.channel.column);
    s.corr = residual_correlation_rows(s.rows, s.base_cols, filtered ? 0.0 : s.noise_rms, dt);
    s.fine = q <= 0.005;
    for (const EffectEntry* e : detectors) e->from_data(s);
  }
  return current;
}

}  // namespace

namespace {

/// The fitting runs' axes (all the same) and notes.
void check_fit_runs(const std::vector<MeasuredRun>& fit, DataCalibration& out) {
  out.axes = fit.front().axes;
  for (const auto& r : fit)
    if (r.axes != out.axes)
      throw ConfigError(fmt::format("{}: the runs calibrated together must log the same axes ({} logs others)",
                                    fit.front().dir.string(), r.dir.string()));
  for (const auto& r : fit)
    for (const auto& n : r.notes) out.notes.push_back(n);
}

/// A position this far from its command on any row: the logged loop ran
/// away (no machine tool's following error reaches a metre).
constexpr double kRunawayError_mm = 1000.0;

/// A run whose axis ran away from its command cannot be calibrated on or
/// validated against: said in one line, with where.
void check_no_runaway(const MeasuredRun& r) {
  const auto* t = r.trace.find("t_s");
  for (Axis a : r.axes) {
    const auto* ref = r.trace.find(col(a, "_ref_mm"));
    const auto* x = r.trace.find(col(a, "_mm"));
    if (ref == nullptr || x == nullptr) continue;
    for (std::size_t k = 0; k < ref->size(); ++k) {
      const double e = std::abs((*ref)[k] - (*x)[k]);
      if (!(e > kRunawayError_mm)) continue;
      throw ConfigError(fmt::format("{}: axis {} is {:.4g} mm from its command at {} (row {}): the logged loop ran "
                                    "away (an unstable loop, or position columns that do not belong together); "
                                    "nothing to calibrate on",
                                    r.dir.string(), axis_name(a), e,
                                    t != nullptr ? fmt::format("t = {:g} s", (*t)[k]) : std::string("the row"), k + 1));
    }
  }
}

/// Rounding: the coarsest all fitting runs agree with. It is the log's, not
/// the encoder's, where it is coarser than 10 um, or coarser than 1 um with
/// the commanded positions rounded alike: an encoder quantises the position
/// it measures, not the command the interpolator computes. (Taken as a 10 um
/// encoder, a 1 kHz cascade log rounded to 0.01 mm was replayed on a loop
/// that hunted by counts of 10 um: the cascade sweep's runs then validated at
/// 0.066 to 0.072 tracking NRMS and a torque error near 1.)
void choose_rounding(const std::vector<MeasuredRun>& fit, DataCalibration& out) {
  out.rounding = detect_rounding(fit.front());
  for (std::size_t i = 1; i < fit.size(); ++i) {
    const PositionRounding ri = detect_rounding(fit[i]);
    if (ri.quantum_mm > out.rounding.quantum_mm) out.rounding = ri;
  }
  bool commands_alike = true;
  for (const auto& r : fit)
    commands_alike = commands_alike && detect_rounding_of(r, {"_ref_mm"}).quantum_mm >= out.rounding.quantum_mm;
  out.display_rounding = out.rounding.kind == PositionRounding::Kind::kSignificant ||
                         out.rounding.quantum_mm > 0.01 + 1e-12 ||
                         (out.rounding.quantum_mm > 0.001 + 1e-12 && commands_alike);
  out.notes.push_back(out.rounding.describe() +
                      (out.display_rounding
                           ? std::string(": the log's rounding, not the servo's encoder (") +
                                 (out.rounding.quantum_mm > 0.01 + 1e-12 ||
                                          out.rounding.kind == PositionRounding::Kind::kSignificant
                                      ? "coarser than an encoder's count"
                                      : "the commanded positions are rounded alike, and an encoder does not round "
                                        "the command") +
                                 "); the twin's loop closes on the encoder (meta.json's, else 1 um) and its "
                                 "logged positions are rounded as the log's"
                           : std::string("")));
}

/// The loop period the twin replays at, said in a note.
double controller_period(const MeasuredRun& r0, const DataCalibrationOptions& options, DataCalibration& out) {
  double Ts = options.default_controller_period_s;
  if (r0.meta.controller_period_s) {
    Ts = *r0.meta.controller_period_s;
    out.notes.push_back(fmt::format("controller period {} s from meta.json", Ts));
  } else if (const std::size_t every = r0.log_rows_per_loop_period; every > 1) {
    // load_run kept the rows of the loop's ticks (its own note says which).
    Ts = r0.sample_period_s;
    out.notes.push_back(fmt::format("controller period {} s: {} changes only every {} row of the {} s log ({:.1f} % "
                                    "of its changes), as a position loop of that period holds its output between its "
                                    "ticks",
                                    Ts, r0.loop_period_seen_in, ordinal(every), Ts / static_cast<double>(every),
                                    100.0 * r0.loop_period_share));
  } else if (r0.sample_period_s <= 1e-3 + 1e-12) {
    Ts = r0.sample_period_s;
    out.notes.push_back(fmt::format("controller period not stated: the log's own period {} s is taken", Ts));
  } else {
    out.notes.push_back(fmt::format("controller period not stated and the log samples every {} s: the twin replays at "
                                    "Ts = {} s, the reference between samples rebuilt by a monotone cubic",
                                    r0.sample_period_s, Ts));
  }
  return Ts;
}

/// What the identification of the machine's axes works on.
struct AxisFit {
  const std::vector<RunData>& runs;
  const Fitter fitter;
  const MeasuredRun& r0;
  double Ts{0.0};
  double position_quantum_mm{0.0};  ///< the rounding of the logged positions (0: none seen)
};

bool all_runs_log(const std::vector<RunData>& runs, const std::string& column) {
  bool all = true;
  for (const auto& rd : runs) all = all && rd.run->trace.find(column) != nullptr;
  return all;
}

/// The reference through a moving average of n periods of Ts, a first-order
/// lag of lag_s and a dead time of `delay` periods, as controller::PositionLoop
/// smooths it, each segment from its own first value (held before it); the
/// log's rows are taken at the loop's period.
std::vector<double> smooth_reference_in_segments(const std::vector<double>& ref, const std::vector<Segment>& segs,
                                                 int n, double lag_s, double Ts, int delay = 0) {
  std::vector<double> out(ref);
  const double a = lag_s > 0.0 ? std::exp(-Ts / lag_s) : 0.0;
  const auto N = static_cast<std::size_t>(std::max(1, n));
  for (const Segment& sg : segs) {
    if (sg.end <= sg.begin) continue;
    const double first = ref[sg.begin];
    double sum = 0.0, y = first;  // sum: of ref - first over the window
    for (std::size_t k = sg.begin; k < sg.end; ++k) {
      sum += ref[k] - (k >= sg.begin + N ? ref[k - N] : first);
      y = a * y + (1.0 - a) * (first + sum / static_cast<double>(N));
      out[k] = y;
    }
    // The dead time, from the segment's end back (each row then reads one not yet moved).
    if (delay > 0) {
      const auto d = static_cast<std::size_t>(delay);
      for (std::size_t k = sg.end; k-- > sg.begin;) out[k] = k >= sg.begin + d ? out[k - d] : first;
    }
  }
  return out;
}

/// The reference's smoothing whose P law fits a logged velocity command best.
struct ReferenceSmoothingFit {
  int n{1};            ///< moving average, loop periods
  double lag_s{0.0};   ///< first-order lag after it
  int delay{0};        ///< dead time after both, loop periods
  bool feedforward_as_given{false};  ///< the feedforward's speed from the reference as logged
  double residual{std::numeric_limits<double>::infinity()};
  /// Whether the reference is smoothed or held back at all.
  bool any() const { return n > 1 || lag_s > 0.0 || delay > 0; }
  /// The delay at constant speed, in loop periods of Ts.
  double delay_periods(double Ts) const { return 0.5 * (n - 1) + lag_s / Ts + delay; }
};

/// The reference a loop follows: the logged one through `sm` (its moving
/// average, lag and dead time; none by default).
std::vector<double> followed_reference(const std::vector<double>& ref, const std::vector<Segment>& segs,
                                       const ReferenceSmoothingFit& sm, double Ts) {
  return sm.any() ? smooth_reference_in_segments(ref, segs, sm.n, sm.lag_s, Ts, sm.delay) : ref;
}

/// The smoothing in words: "a moving average over 8 ms and a dead time of
/// 3 ms (3 loop periods)"; empty where there is none.
std::string smoothing_words(const ReferenceSmoothingFit& sm, double Ts) {
  std::vector<std::string> parts;
  if (sm.n > 1) parts.push_back(fmt::format("a moving average over {:.4g} ms", 1e3 * sm.n * Ts));
  if (sm.lag_s > 0.0) parts.push_back(fmt::format("a first-order lag of {:.4g} ms", 1e3 * sm.lag_s));
  if (sm.delay > 0)
    parts.push_back(fmt::format("a dead time of {:.4g} ms ({} loop periods)", 1e3 * sm.delay * Ts, sm.delay));
  std::string how;
  for (std::size_t i = 0; i < parts.size(); ++i)
    how += (i == 0 ? "" : (i + 1 == parts.size() ? " and " : ", ")) + parts[i];
  return how;
}

/// The P law fitted with the loop's reference smoothed by (n, lag_s) and
/// held back by `delay` periods, its feedforward's speed from the reference
/// as logged (true) or the smoothed one.
using SmoothedLawFit = std::function<LsqResult(int n, double lag_s, int delay, bool feedforward_as_given)>;

/// The step of the grid of periods the smoothing's search tries about k:
/// every period to 16, then 4, 8 and 16 from 16, 32 and 64.
int period_grid_step(int k) { return k < 16 ? 1 : (k < 32 ? 4 : (k < 64 ? 8 : 16)); }

/// That grid from 1 to max_periods.
std::vector<int> period_grid(int max_periods) {
  std::vector<int> grid;
  for (int k = 1; k <= max_periods; k += period_grid_step(k)) grid.push_back(k);
  return grid;
}

/// best_reference_smoothing with the feedforward taken one way, at a given
/// dead time (0: none, and then some smoothing).
ReferenceSmoothingFit best_reference_smoothing_with(const SmoothedLawFit& fit, double Ts, bool ff_given, int delay) {
  ReferenceSmoothingFit best;
  best.feedforward_as_given = ff_given;
  best.delay = delay;
  const auto take = [&](int n, double lag_s) {
    if (!ReferenceSmoothingFit{n, lag_s, delay}.any() || (lag_s > 0.0 && lag_s < Ts))
      return std::numeric_limits<double>::infinity();
    const LsqResult trial = fit(n, lag_s, delay, ff_given);
    const double r = trial.ok && trial.theta[0] > 0.0 ? trial.residual_rms : std::numeric_limits<double>::infinity();
    if (r < best.residual) best = {n, lag_s, delay, ff_given, r};
    return r;
  };
  const std::vector<double> lags_ms{0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 12.0, 16.0, 20.0, 25.0, 32.0, 40.0, 50.0};
  const std::vector<int> ns = period_grid(controller::kMaxCommandAverageTicks);
  for (double lag_ms : lags_ms)
    for (int n : ns) take(n, 1e-3 * lag_ms);
  if (!std::isfinite(best.residual)) return best;
  const int step = period_grid_step(best.n);
  const auto at = std::find(lags_ms.begin(), lags_ms.end(), 1e3 * best.lag_s);
  const std::size_t li = at == lags_ms.end() ? 0 : static_cast<std::size_t>(at - lags_ms.begin());
  const double lag_lo = 1e-3 * lags_ms[li > 0 ? li - 1 : 0], lag_hi = 1e-3 * lags_ms[std::min(li + 1, lags_ms.size() - 1)];
  const double lag0 = best.lag_s;
  for (int n = std::max(1, best.n - step + 1); n <= std::min(controller::kMaxCommandAverageTicks, best.n + step - 1); ++n)
    for (double lag_s : {lag_lo, lag0, lag_hi}) take(n, lag_s);
  // The lag between its grid neighbours at the best average.
  const int n_best = best.n;
  double lo = lag_lo, hi = lag_hi;
  const double g = 0.5 * (std::sqrt(5.0) - 1.0);
  double c = hi - g * (hi - lo), d = lo + g * (hi - lo);
  double fc = take(n_best, c), fd = take(n_best, d);
  for (int it = 0; it < 16 && hi - lo > 1e-5; ++it) {
    if (fc < fd) {
      hi = d;
      d = c;
      fd = fc;
      c = hi - g * (hi - lo);
      fc = take(n_best, c);
    } else {
      lo = c;
      c = d;
      fc = fd;
      d = lo + g * (hi - lo);
      fd = take(n_best, d);
    }
  }
  return best;
}

/// A dead time is a third parameter beside the smoothing's two: it is kept
/// only where it leaves at most this share of the best smoothing's residual
/// without it. On the tests' runs whose truth has no dead time the best one
/// fitted no better than none (1.0 to 6.4 times the residual; with the
/// feedforward from the reference as logged, a dead time of one period spans
/// the same columns as a moving average of two); on those with one, 0.40
/// and 0.54 of it.
constexpr double kDelayResidualShare = 0.8;

/// best_reference_smoothing with the feedforward taken one way: the
/// smoothing without a dead time; then dead times of 1 to
/// controller::kMaxCommandDelayTicks periods (every one to 16, then a grid,
/// refined about the best), each alone, behind that smoothing, and behind
/// the part of it that the dead time leaves of the smoothing's delay at
/// constant speed (as a moving average, and as a lag); where one fits better
/// (leaves under delay_share of the residual without it),
/// the smoothing searched again behind the best dead time and the dead time
/// again about it behind that smoothing, until neither moves (three rounds
/// at most).
ReferenceSmoothingFit best_reference_smoothing_way(const SmoothedLawFit& fit, double Ts, bool ff_given,
                                                   double delay_share = kDelayResidualShare) {
  const ReferenceSmoothingFit plain = best_reference_smoothing_with(fit, Ts, ff_given, 0);
  ReferenceSmoothingFit delayed;
  delayed.feedforward_as_given = ff_given;
  const auto take = [&](int n, double lag_s, int d) {
    if (d < 1 || d > controller::kMaxCommandDelayTicks || n < 1 || n > controller::kMaxCommandAverageTicks ||
        (lag_s > 0.0 && lag_s < Ts))
      return;
    const LsqResult trial = fit(n, lag_s, d, ff_given);
    if (trial.ok && trial.theta[0] > 0.0 && trial.residual_rms < delayed.residual)
      delayed = {n, lag_s, d, ff_given, trial.residual_rms};
  };
  // The smoothing's delay at constant speed, in periods.
  const double total = std::isfinite(plain.residual) ? plain.delay_periods(Ts) : 0.0;
  for (int d : period_grid(controller::kMaxCommandDelayTicks)) {
    take(1, 0.0, d);
    if (!std::isfinite(plain.residual)) continue;
    take(plain.n, plain.lag_s, d);
    const double left = total - d;
    if (left <= 0.0) continue;
    take(static_cast<int>(std::lround(2.0 * left + 1.0)), 0.0, d);
    take(1, left * Ts, d);
  }
  if (!std::isfinite(delayed.residual)) return plain;
  const int step = period_grid_step(delayed.delay);
  for (int d = delayed.delay - step + 1; d < delayed.delay + step; ++d) take(delayed.n, delayed.lag_s, d);
  if (!(delayed.residual < delay_share * plain.residual)) return plain;
  for (int round = 0; round < 3; ++round) {
    const int d0 = delayed.delay;
    const ReferenceSmoothingFit behind = best_reference_smoothing_with(fit, Ts, ff_given, d0);
    if (behind.residual < delayed.residual) delayed = behind;
    for (int d = d0 - 3; d <= d0 + 3; ++d) take(delayed.n, delayed.lag_s, d);
    if (delayed.delay == d0) break;
  }
  return delayed;
}

/// The moving average (1 to controller::kMaxCommandAverageTicks periods of
/// Ts), lag (0 to 50 ms) and dead time (best_reference_smoothing_way) whose
/// `fit(n, lag_s, delay)` leaves the least residual, no smoothing left out:
/// a coarse grid (every n to 16, then steps of 4 to 16; 18 lags), every n
/// about the best, then the lag by golden section between the grid's lags
/// about the best; each with the feedforward from the smoothed reference and
/// from the logged one.
ReferenceSmoothingFit best_reference_smoothing(const SmoothedLawFit& fit, double Ts,
                                               double delay_share = kDelayResidualShare) {
  const ReferenceSmoothingFit both = best_reference_smoothing_way(fit, Ts, false, delay_share);
  const ReferenceSmoothingFit error_only = best_reference_smoothing_way(fit, Ts, true, delay_share);
  return error_only.residual < both.residual ? error_only : both;
}

/// Kv and kff from a logged velocity command against the following error and
/// the command's speed.
void loop_from_vcmd(const AxisFit& f, AxisFromData& ax) {
  const Axis a = ax.axis;
  std::vector<double> e, vr, vc;
  std::vector<std::size_t> rows;
  // The law's own speed: the backward difference of the reference over a
  // period, of the reference as rebuilt from a coarse rounding's staircase
  // (RunData::smooth).
  // Positions rounded to 1 um or coarser, the reference too (prepare_run),
  // on a log at 2 ms or faster: the rounding's steps are noise on the error
  // and on that speed, which a regression takes for signal (Kv 87 and kff
  // 0.23 for 45 and 0.6 at 10 um and 1 kHz; 48.8 and 0.566 at 1 um). The law is linear, so all three columns are low-passed alike
  // (zero phase, at the identification's 50 Hz) and the noise is left out.
  const double dt = f.r0.sample_period_s;
  const bool filter = f.position_quantum_mm >= 0.001 - 1e-12 && dt <= 2e-3 + 1e-12;
  // The law fitted with the reference the loop follows taken as the logged
  // one through a moving average of n loop periods and a lag of `lag_s`
  // (a CNC's smoothing after its interpolator; 1 and 0: none), on each run's
  // reference, position and command (`in`), the columns low-passed after
  // where `lowpass_after`.
  struct LawInputs {
    const std::vector<double>* ref;
    const std::vector<double>* x;
    const std::vector<double>* vcmd;
  };
  const auto fit_on = [&](const std::vector<LawInputs>& in, bool lowpass_after, int n, double lag_s, int delay,
                          bool ff_given) {
    e.clear();
    vr.clear();
    vc.clear();
    rows.clear();
    // On a log slower than 5 ms the reference's speed over the loop's period
    // is read off the cubic between rows, which misses it where the speed
    // changes within a row: the law there came out at Kv 59.8 and kff 0.473
    // for 45 and 0.6 at 50 ms (46.0 and 0.592 at 20 ms). Where the rebuilt
    // reference is a straight line over the rows about a row and the one
    // before (second differences within the position's rounding), the cubic's
    // speed at the row is exact, and the law is fitted on those rows where
    // they are at least a fifth of the fitting rows (the loop still settling
    // after each change of speed parts Kv from kff): 45.00 and 0.600 at 20
    // and 50 ms. Up to the 20 ms the velocity loop is read at, at first: at
    // 50 ms the loop chosen blind and the drive fitted there are further
    // off, and with the exact P law the other program tracked worse (median 0.12
    // against 0.073 on the sweep; the truth's velocity loop on that drive:
    // 0.043): the monotone cubic between rows 50 ms apart left 4 % of the
    // tracking error's RMS in the reference itself. With the reference
    // rebuilt through the speed this law reads off the logged command
    // (law_reference_speed) it is 1.4 %, and the exact law is taken at any
    // rate slower than 5 ms (at 50 ms the other program tracks at a median
    // 0.026 over the sweep).
    const bool straight_only = !resolves_velocity_loop(dt) && !lowpass_after;
    const double straight_tol_mm = 2.5 * std::max(f.position_quantum_mm, 1e-9);
    std::vector<std::vector<char>> line(f.runs.size());
    std::vector<std::array<std::vector<double>, 3>> cols;  // e, v_ref, vcmd per run
    for (std::size_t i = 0; i < f.runs.size(); ++i) {
      const auto& rd = f.runs[i];
      const std::vector<double>& logged_ref = *in[i].ref;
      const std::vector<double> ref = followed_reference(logged_ref, rd.segments, {n, lag_s, delay}, f.Ts);
      if (straight_only) {
        // The cubic over the row before a row takes its slopes from the rows
        // about both ends: straight about the row and the one before it.
        line[i].assign(ref.size(), 0);
        for (std::size_t k = 2; k + 1 < ref.size(); ++k)
          line[i][k] = static_cast<char>(std::abs(ref[k + 1] - 2.0 * ref[k] + ref[k - 1]) <= straight_tol_mm &&
                                         std::abs(ref[k] - 2.0 * ref[k - 1] + ref[k - 2]) <= straight_tol_mm);
      }
      const std::vector<double>& x = *in[i].x;
      std::array<std::vector<double>, 3> c;
      c[0].resize(ref.size());
      for (std::size_t k = 0; k < ref.size(); ++k) c[0][k] = ref[k] - x[k];
      c[1] = loop_reference_speed(ff_given ? logged_ref : ref, rd.segments, rd.run->sample_period_s, f.Ts);
      c[2] = *in[i].vcmd;
      if (lowpass_after)
        for (auto& y : c) y = lowpass_in_segments(y, rd.segments, rd.run->sample_period_s);
      cols.push_back(std::move(c));
    }
    std::size_t straight = 0, all = 0;
    if (straight_only)
      f.fitter.for_fit_rows([&](std::size_t r, std::size_t k) {
        ++all;
        straight += line[r][k] ? 1 : 0;
      });
    const bool on_lines = straight_only && straight >= std::max<std::size_t>(30, all / 5);
    f.fitter.for_fit_rows([&](std::size_t r, std::size_t k) {
      if (on_lines && !line[r][k]) return;
      e.push_back(cols[r][0][k]);
      vr.push_back(cols[r][1][k]);
      vc.push_back(cols[r][2][k]);
      rows.push_back(rows.size());
    });
    return least_squares({&e, &vr}, vc, rows);
  };
  // As logged (the rebuilt reference where the log is not filtered here; it
  // is low-passed already), and all three low-passed alike (zero phase, 50
  // Hz) for the smoothing's search: a reference logged to the encoder's
  // resolution at 1 kHz steps its speed by a count a row, which a moving
  // average of two rows halves, and the search would take that for a
  // smoothing (2 ms on the truth's run with its reference rounded to 1 um,
  // Kv 43.9 and kff 0.631 for 45 and 0.6). A smoothing the loop follows
  // shows below 50 Hz (its delay of milliseconds times the speed); the
  // smoothing is linear, so it is applied to the low-passed reference.
  // The search runs where the log samples at the loop's period and fast
  // enough for the 50 Hz low-pass (5 ms or faster).
  const bool search = std::abs(dt - f.Ts) <= 1e-6 * f.Ts && dt <= 5e-3 + 1e-12;
  std::vector<LawInputs> as_logged;
  std::vector<std::array<std::vector<double>, 3>> lowpassed;
  for (const auto& rd : f.runs) {
    const auto& t = rd.run->trace;
    const auto& ref = (filter ? *rd.run : *rd.smooth).trace.at(col(a, "_ref_mm"));
    const auto& x = t.at(col(a, "_mm"));
    const auto& vcmd = t.at(velocity_command_column(t, a));
    as_logged.push_back({&ref, &x, &vcmd});
    if (search)
      lowpassed.push_back({lowpass_in_segments(ref, rd.segments, rd.run->sample_period_s),
                           lowpass_in_segments(x, rd.segments, rd.run->sample_period_s),
                           lowpass_in_segments(vcmd, rd.segments, rd.run->sample_period_s)});
  }
  std::vector<LawInputs> filtered;
  for (const auto& c : lowpassed) filtered.push_back({&c[0], &c[1], &c[2]});
  const auto fit_with = [&](int n, double lag_s, int delay, bool ff_given) {
    return fit_on(as_logged, filter, n, lag_s, delay, ff_given);
  };
  const auto search_fit = [&](int n, double lag_s, int delay, bool ff_given) {
    return fit_on(filtered, false, n, lag_s, delay, ff_given);
  };
  LsqResult ls = fit_with(1, 0.0, 0, false);
  if (!(ls.ok && ls.theta[0] > 0.0)) return;
  // The smoothing: where the log samples at the loop's period, the one whose
  // law fits best on the low-passed columns (best_reference_smoothing),
  // taken where it halves the residual of the law on the logged reference
  // low-passed alike (the law is exact but for the encoder's steps there,
  // so no smoothing comes near that on a log without one).
  ReferenceSmoothingFit best;  // none unless the search finds one
  if (search) {
    const LsqResult none = search_fit(1, 0.0, 0, false);
    const ReferenceSmoothingFit sm = best_reference_smoothing(search_fit, f.Ts);
    if (none.ok && sm.residual < 0.5 * none.residual_rms) best = sm;
  }
  const double residual_logged = ls.residual_rms;
  const bool smoothed = best.any();
  if (smoothed) ls = fit_with(best.n, best.lag_s, best.delay, best.feedforward_as_given);
  ax.gains.command_average_s = best.n > 1 ? best.n * f.Ts : 0.0;
  ax.gains.command_lag_s = best.lag_s;
  ax.gains.command_delay_s = best.delay * f.Ts;
  ax.gains.feedforward_unsmoothed = best.feedforward_as_given ? 1.0 : 0.0;
  ax.gains.Kv_per_s = ls.theta[0];
  ax.gains.kff = std::clamp(ls.theta[1], 0.0, 1.5);
  // The lag at constant speed: the P loop's plus the smoothing's delay
  // (whichever reference the feedforward takes: its speed is the same there).
  const double delay_s = best.delay_periods(f.Ts) * f.Ts;
  ax.lag_s = (1.0 - ax.gains.kff) / ax.gains.Kv_per_s + delay_s;
  double vrms = 0.0;
  for (double x : vc) vrms += x * x;
  vrms = std::sqrt(vrms / static_cast<double>(std::max<std::size_t>(1, vc.size())));
  const bool logged = f.r0.trace.find(col(a, "_vcmd_mm_s")) != nullptr;
  const std::string how = smoothing_words(best, f.Ts);
  const std::string smoothing =
      smoothed
          ? fmt::format("; the loop follows the logged reference {} {} (a CNC's smoothing after its "
                        "interpolator, {:.4g} ms of delay{}), which fits the command with {:.3g} mm/s of residual "
                        "against {:.3g} mm/s on the reference as logged",
                        best.n > 1 || best.lag_s > 0.0 ? "smoothed by" : "held back by", how, 1e3 * delay_s,
                        best.feedforward_as_given ? "; the feedforward takes the reference as logged, only the error the smoothed one"
                                 : "",
                        ls.residual_rms, residual_logged)
          : std::string();
  ax.loop_source = logged ? fmt::format("the logged velocity command against the following error and the command's "
                                        "speed (residual {:.3g} mm/s against an RMS of {:.3g} mm/s){}",
                                        ls.residual_rms, vrms, smoothing)
                          : std::string("the velocity command rebuilt from the logged torque and speed (see the "
                                        "notes: no velocity command is logged)") +
                                smoothing;
}

/// Kv from the lag of the position behind the command (a P loop without feedforward).
void loop_from_lag(const AxisFit& f, AxisFromData& ax) {
  const Axis a = ax.axis;
  const std::size_t i = index(a);
  double num = 0.0, den = 0.0;
  f.fitter.for_fit_rows([&](std::size_t r, std::size_t k) {
    const double v = f.runs[r].kin[i].v_mm_per_s[k];
    if (direction(v, f.runs[r].v_move[i]) == 0) return;
    const auto& t = f.runs[r].run->trace;
    num += (v > 0 ? 1.0 : -1.0) * (t.at(col(a, "_ref_mm"))[k] - t.at(col(a, "_mm"))[k]);
    den += std::abs(v);
  });
  ax.lag_s = den > 0.0 ? num / den : 0.0;
  if (ax.lag_s > 1e-4) {
    ax.gains.Kv_per_s = 1.0 / ax.lag_s;
    ax.gains.kff = 0.0;
    ax.loop_source = fmt::format("the lag of the position behind the command ({:.4g} ms, the mean of the rounded "
                                 "following error over the speed); a P loop without feedforward assumed",
                                 1e3 * ax.lag_s);
  }
}

/// The position loop: the vcmd regression where logged, else the lag of the position.
void identify_position_loop(const AxisFit& f, AxisFromData& ax, bool have_vcmd, bool have_x) {
  if (have_vcmd && have_x) loop_from_vcmd(f, ax);
  if (ax.loop_source.empty() && have_x) loop_from_lag(f, ax);
  if (ax.loop_source.empty()) {
    ax.gains.Kv_per_s = 1.0 / std::max(10.0 * f.Ts, 0.01);
    ax.loop_source = fmt::format("not seen in the data ({}); Kv = {:.4g} 1/s assumed",
                                 have_x ? "the position does not lag the command measurably" : "no position logged",
                                 ax.gains.Kv_per_s);
  }
}

/// The drive's regressors on the fitting rows: a, v, [v > 0], -[v < 0], 1,
/// and the channel's torque.
struct DriveRows {
  std::vector<double> acc, vel, pos, neg, one, T;
  std::vector<std::size_t> rows;
  double a2{0.0}, T2{0.0};
};

/// The axis's own motion where a fast log has its speed (the torque
/// accelerates the axis, not the command: under a loop whose torque
/// overshoots at every change of acceleration, J fitted on the commanded
/// acceleration comes out 17 % low on the truth runs of the tests), else
/// the commanded kinematics (the logged positions are often too coarse to
/// differentiate).
///
/// The options give the motion as a torque logged ahead of it needs
/// (motion_behind_torque).
struct DriveRowsOptions {
  /// The speed's change over the loop period from the row on (the
  /// acceleration the torque held over that period gives: the forward
  /// difference where the log samples every period, else the speed one
  /// period on from the cubic through the rows about) in place of the
  /// central difference.
  bool forward{false};
  /// Each motion column M taken as (M[k + ahead] - a M[k + ahead - 1]) / (1 - a)
  /// with a = a_lag: the torque a loop commands at row k where the motion
  /// answers to it through a first-order lag of coefficient a (a current
  /// loop) and `ahead` rows of dead time. Rows whose neighbours that needs
  /// lie outside the segment's interior or the fitting rows are left out.
  std::size_t ahead{0};
  double a_lag{0.0};
  /// Rows where the axis moves (and the row before, with a lag) only.
  bool moving_only{false};
};

/// Whether the drive of axis `a` is fitted on its logged speed: a log at
/// 5 ms or faster whose every fitting run has `<a>_v_mm_s`.
bool drive_on_logged_speed(const AxisFit& f, Axis a) {
  return resolves_velocity_loop(f.r0.sample_period_s) && all_runs_log(f.runs, col(a, "_v_mm_s"));
}

/// What the torque applied over the row k to k+1 of a velocity loop that
/// runs n times a row exceeds the logged torque of row k by (the mean of the
/// n ticks' torques less the first's), where the drive applies the law's
/// torque `dead` ticks late and logs what it applies: the applied ticks are
/// the law's ticks -p .. n-1-p about row b = k - dead / n, p = dead % n.
/// Each tick's speed error is on its period's command (row b-1's before row
/// b's tick, row b's from it) and the speed between the rows on the line
/// (behind a dead time off the cubic through the rows about);
/// from one tick to the next the law's torque moves by Kvp times the error's
/// change plus Ki Tv times the new error (Ki_Tv). With no dead time this is
/// -Kvp dv (n-1)/(2n) + Ki Tv (n-1) (e/2 - dv (n+1)/(6n)), e row k's speed
/// error and dv the speed's change over the row. nullopt where row b is not
/// inside its segment.
std::optional<double> law_ticks_mean_offset(const std::vector<double>& vc, const std::vector<double>& v,
                                            const RunData& rd, std::size_t k, int n, int dead, double Kvp,
                                            double Ki_Tv) {
  const auto L = static_cast<std::size_t>(dead / n);
  const int p = dead % n;
  if (k < L || !rd.interior[k - L]) return std::nullopt;  // rows b - 1 to b + 1 in one segment
  const std::size_t b = k - L;
  // Behind a dead time the speed between the rows is read off the cubic
  // through the four about (the line where row b+2 is not in the segment).
  const bool cubic = dead > 0, cubic_after = cubic && b + 1 < rd.interior.size() && rd.interior[b + 1];
  const auto error_at = [&](int m) {
    const double sm = static_cast<double>(m) / n;
    if (m < 0)
      return vc[b - 1] - (cubic ? catmull_rom(v[b - 2], v[b - 1], v[b], v[b + 1], 1.0 + sm)
                                : v[b] + sm * (v[b] - v[b - 1]));
    if (m == 0) return vc[b] - v[b];
    return vc[b] - (cubic_after ? catmull_rom(v[b - 1], v[b], v[b + 1], v[b + 2], sm) : v[b] + sm * (v[b + 1] - v[b]));
  };
  double Tm = 0.0, sum = 0.0, e_prev = error_at(-p);
  for (int m = -p + 1; m <= n - 1 - p; ++m) {
    const double e = error_at(m);
    Tm += Kvp * (e - e_prev) + Ki_Tv * e;
    sum += Tm;
    e_prev = e;
  }
  return sum / n;
}

DriveRows drive_rows(const AxisFit& f, const AxisFromData& ax, const DriveRowsOptions& o = {}) {
  const std::size_t ahead = o.ahead;
  const double a_lag = o.a_lag;
  const Axis a = ax.axis;
  const std::size_t i = index(a);
  const bool own_speed = drive_on_logged_speed(f, a);
  struct Motion {
    double acc{0.0}, vel{0.0}, pos{0.0}, neg{0.0};
  };
  // Each run's logged speed (where the drive is fitted on it) and torque.
  std::vector<const std::vector<double>*> speed(f.runs.size(), nullptr), torque(f.runs.size(), nullptr);
  for (std::size_t r = 0; r < f.runs.size(); ++r) {
    const io::TraceTable& t = f.runs[r].run->trace;
    if (own_speed) speed[r] = t.find(col(a, "_v_mm_s"));
    torque[r] = own_speed ? filtered_alike(t, ax.channel.column) : t.find(ax.channel.column);
  }
  // The motion's columns at row k of run r; nullopt where they cannot be had.
  const auto motion = [&](std::size_t r, std::size_t k) -> std::optional<Motion> {
    const RunData& rd = f.runs[r];
    if (k >= rd.n || !rd.interior[k]) return std::nullopt;
    const auto* vm = speed[r];
    if (vm != nullptr && (k == 0 || k + 1 >= vm->size())) return std::nullopt;
    const double v = vm ? (*vm)[k] : rd.kin[i].v_mm_per_s[k];
    const int dir = direction(v, rd.v_move[i]);
    const double dt = rd.run->sample_period_s;
    const auto held = [&] {
      const std::vector<double>& w = *vm;
      const double u = std::clamp(f.Ts / dt, 0.0, 1.0);
      if (u > 1.0 - 1e-9 || !(k + 2 < rd.n && rd.interior[k + 1])) return (w[k + 1] - w[k]) / dt;
      return (catmull_rom(w[k - 1], w[k], w[k + 1], w[k + 2], u) - w[k]) / (u * dt);
    };
    const double acc = vm == nullptr                            ? rd.kin[i].a_mm_per_s2[k]
                       : o.forward || ax.torque_held_over_row ? held()
                                                              : ((*vm)[k + 1] - (*vm)[k - 1]) / (2.0 * dt);
    return Motion{acc, v, dir > 0 ? 1.0 : 0.0, dir < 0 ? -1.0 : 0.0};
  };
  // A velocity loop that runs n times a row changes the torque at each of
  // its ticks, and the speed's change over the row answers to their mean.
  // With the row's velocity command held and the speed moving linearly to
  // the next row's (dv), the law gives the ticks' torques (the row's at
  // tick 0): their mean is the row's torque less Kvp dv (n - 1) / (2 n),
  // plus Ki Tv (n - 1) (e / 2 - dv (n + 1) / (6 n)) of the integral, e the
  // row's speed error and Tv the loop's period. Paired with the row's own
  // torque (its sawtooth's top), a 125 us loop under a 1 ms one took J 2 %
  // high, and the replay's torque at rest was 0.097 NRMS off the log against
  // 0.022 with the truth's J; with the mean, J within 0.3 %. Behind a dead
  // time the ticks applied over the row are the law's that many ticks
  // earlier (law_ticks_mean_offset), on the law's gains at that lag: a 1 ms
  // one under a 2 ms loop took J 1.3 % high with the ticks taken from the
  // row on and the gains fitted at no lag.
  const int n_inner = ax.law_inner_ticks;
  const bool within = own_speed && n_inner > 1 && ax.torque_held_over_row && ax.velocity_loop_from_data;
  // The loop's dead time in its ticks (the law's lag: whole rows and a part
  // of one), which the torque applied over a row is that many ticks behind.
  const int dead_ticks =
      within ? static_cast<int>(ax.torque_lag_samples) * n_inner +
                   static_cast<int>(std::lround(ax.torque_lag_fraction * n_inner))
             : 0;
  // The law's gains at its dead time where it has one (fitted at lag 0 the
  // law takes the dead time's misfit into its gains).
  const controller::CascadeGains& law = dead_ticks > 0 ? ax.gains_at_lag : ax.gains;
  const double Kvp = law.Kvp_torque_s_per_rad, Ki = law.Tn_s > 0.0 ? Kvp / law.Tn_s : 0.0;
  std::vector<const std::vector<double>*> command(f.runs.size(), nullptr);
  if (within)
    for (std::size_t r = 0; r < f.runs.size(); ++r)
      command[r] = filtered_alike(f.runs[r].run->trace, velocity_command_column(f.runs[r].run->trace, a));
  DriveRows d;
  f.fitter.for_fit_rows([&](std::size_t r, std::size_t k) {
    const auto* ch = torque[r];
    if (ch == nullptr || k + ahead >= f.runs[r].n_fit) return;  // the fitting rows' motion only
    if (within && (command[r] == nullptr || !(k + 1 < f.runs[r].n && f.runs[r].interior[k + 1]))) return;
    const auto still = [&](const std::optional<Motion>& x) { return o.moving_only && x->pos == 0.0 && x->neg == 0.0; };
    std::optional<Motion> m = motion(r, k + ahead);
    if (!m || still(m)) return;
    if (a_lag > 0.0) {
      const std::optional<Motion> before = motion(r, k + ahead - 1);
      if (!before || still(before)) return;
      const auto through = [&](double now, double prev) { return (now - a_lag * prev) / (1.0 - a_lag); };
      *m = Motion{through(m->acc, before->acc), through(m->vel, before->vel), through(m->pos, before->pos),
                  through(m->neg, before->neg)};
    }
    const bool forward = own_speed && (o.forward || ax.torque_held_over_row);
    double T = logged_torque_at(*ch, k, ax.logs_period_mean(), forward);
    if (within && !ax.logs_period_mean()) {
      const std::optional<double> off =
          law_ticks_mean_offset(*command[r], *speed[r], f.runs[r], k, n_inner, dead_ticks, Kvp, Ki * f.Ts / n_inner);
      if (!off) return;
      T += *off;
    }
    d.acc.push_back(m->acc);
    d.vel.push_back(m->vel);
    d.pos.push_back(m->pos);
    d.neg.push_back(m->neg);
    d.one.push_back(1.0);
    d.T.push_back(T);
    d.a2 += d.acc.back() * d.acc.back();
    d.T2 += d.T.back() * d.T.back();
    d.rows.push_back(d.rows.size());
  });
  return d;
}

/// J, B, Tc_pos, Tc_neg, c from the fitted coefficients (a direction the
/// axis never moves in takes the other's level).
void take_drive_fit(const LsqResult& ls, bool moves_pos, bool moves_neg, AxisFromData& ax) {
  std::size_t j = 0;
  ax.J = ls.theta[j];
  ax.J_se = ls.stderr_theta[j++];
  ax.B = ls.theta[j];
  ax.B_se = ls.stderr_theta[j++];
  if (moves_pos) {
    ax.Tc_pos = ls.theta[j];
    ax.Tc_pos_se = ls.stderr_theta[j++];
  }
  if (moves_neg) {
    ax.Tc_neg = ls.theta[j];
    ax.Tc_neg_se = ls.stderr_theta[j++];
  }
  ax.c = ls.theta[j];
  ax.c_se = ls.stderr_theta[j];
  if (!moves_pos) ax.Tc_pos = ax.Tc_neg;
  if (!moves_neg) ax.Tc_neg = ax.Tc_pos;
}

/// Physical floors, each said: an inertia the fixed-step drive integrates
/// (B Ts / J <= 0.5) and that 1 % of the torque RMS accelerates at most at
/// the run's RMS acceleration; B and the Coulomb levels not below zero.
std::vector<std::string> clamp_drive(const DriveRows& d, double Ts, AxisFromData& ax) {
  std::vector<std::string> clamped;
  const double a_rms = std::sqrt(d.a2 / static_cast<double>(d.rows.size()));
  const double T_rms = std::sqrt(d.T2 / static_cast<double>(d.rows.size()));
  const double J_floor = std::max({2.0 * std::max(ax.B, 0.0) * Ts, a_rms > 0.0 ? 0.01 * T_rms / a_rms : 0.0, 1e-9});
  if (ax.J < J_floor) {
    clamped.push_back(fmt::format("J {:.4g} raised to {:.4g} (the log's accelerations do not resolve it)", ax.J, J_floor));
    ax.J = J_floor;
  }
  if (ax.B < 0.0) {
    clamped.push_back(fmt::format("B {:.4g} set to 0", ax.B));
    ax.B = 0.0;
  }
  for (double* tc : {&ax.Tc_pos, &ax.Tc_neg})
    if (*tc < 0.0) {
      clamped.push_back(fmt::format("a Coulomb level {:.4g} set to 0", *tc));
      *tc = 0.0;
    }
  return clamped;
}

/// The direction of motion of each row (+1, -1, 0): one Coulomb column for
/// both directions.
std::vector<double> direction_signs(const DriveRows& d) {
  std::vector<double> sgn(d.pos.size());
  for (std::size_t k = 0; k < sgn.size(); ++k) sgn[k] = d.pos[k] + d.neg[k];
  return sgn;
}

/// The rows' torque less J a: what is left for the other columns where J is
/// held.
std::vector<double> torque_less_inertia(const DriveRows& d, double J) {
  std::vector<double> T = d.T;
  for (std::size_t k = 0; k < T.size(); ++k) T[k] -= J * d.acc[k];
  return T;
}

/// The drive with one Coulomb level for both directions (columns a, v,
/// sgn v, 1) on the same rows, under the same floors; not ok where the axis
/// moves one way only or the fit is rank deficient; with J held at
/// `J_held` where fit_drive took it from the windows.
AxisFromData::OneLevel fit_one_level(const DriveRows& d, double Ts, const AxisFromData& two,
                                     std::optional<double> J_held = std::nullopt) {
  AxisFromData::OneLevel one;
  const std::vector<double> sgn = direction_signs(d);
  LsqResult ls;
  if (J_held) {
    // J held (fit_drive): the torque less J a on the other columns.
    ls = least_squares({&d.vel, &sgn, &d.one}, torque_less_inertia(d, *J_held), d.rows);
    if (ls.ok) {
      ls.theta.insert(ls.theta.begin(), *J_held);
      ls.stderr_theta.insert(ls.stderr_theta.begin(), two.J_se);
    }
  } else {
    ls = least_squares({&d.acc, &d.vel, &sgn, &d.one}, d.T, d.rows);
  }
  if (!ls.ok) return one;
  AxisFromData ax = two;
  ax.J = ls.theta[0];
  ax.B = ls.theta[1];
  ax.Tc_pos = ax.Tc_neg = ls.theta[2];
  ax.c = ls.theta[3];
  one.clamped = clamp_drive(d, Ts, ax);
  one.ok = true;
  one.J = ax.J;
  one.B = ax.B;
  one.Tc = ax.Tc_pos;
  one.c = ax.c;
  one.J_se = ls.stderr_theta[0];
  one.B_se = ls.stderr_theta[1];
  one.Tc_se = ls.stderr_theta[2];
  one.c_se = ls.stderr_theta[3];
  return one;
}

/// The drive's columns on `d`: a, v, [v > 0] and -[v < 0] for the directions
/// the axis moves in, and the constant (left out where `moving` rows move
/// both ways: the two levels hold it then).
struct DriveColumns {
  std::vector<const std::vector<double>*> X;
  bool pos{false}, neg{false};
};
DriveColumns drive_columns(const DriveRows& d, bool moving = false) {
  DriveColumns c;
  c.pos = std::any_of(d.pos.begin(), d.pos.end(), [](double x) { return x != 0.0; });
  c.neg = std::any_of(d.neg.begin(), d.neg.end(), [](double x) { return x != 0.0; });
  c.X = {&d.acc, &d.vel};
  if (c.pos) c.X.push_back(&d.pos);
  if (c.neg) c.X.push_back(&d.neg);
  if (!(moving && c.pos && c.neg)) c.X.push_back(&d.one);
  return c;
}

/// The inertia from the torque's integral between rows where the command
/// holds its speed (a cruise or a rest): over such a window [a, b] the
/// rigid body gives int T dt = J (v_b - v_a) + B (x_b - x_a) + Tc+ t+ -
/// Tc- t- + c (t_b - t_a), t+ and t- the time moving each way. No row's
/// acceleration enters, only the commanded speeds at the window's ends,
/// where they are steady (each the slope of the line it holds to), and the
/// distance travelled. Where the positions are rounded coarser than the
/// motion between rows, the acceleration at a row (of the reference rebuilt
/// from the rounding staircase, or low-passed) is mostly the rebuild's, and
/// a loop that rings after every change of speed puts its torque on rows
/// the command does not accelerate: on a 10 ms log rounded to 0.1 mm of the
/// cascade truth (J 0.01107 A per mm/s^2, a loop ringing at 10 Hz for
/// 0.3 s) the rows gave J 0.001, the windows 0.0107.
/// Steady at row k: the rebuilt reference within a quantum (or 1e-6 mm) of
/// its line through k - S and k + S, S = 0.1 s of rows (at least 2), all
/// those rows interior and fitting rows; windows run from one steady row to
/// the next at least S rows on in the same segment. nullopt where fewer than
/// 20 windows are found or the fit is rank deficient.
struct WindowDrive {
  double J{0.0}, J_se{0.0};
  std::size_t windows{0};
  /// The windows' first and second halves give J within 3 standard errors
  /// of their difference (a few windows that carry the fit disagree).
  bool halves_agree{false};
};
std::optional<WindowDrive> drive_from_windows(const AxisFit& f, const AxisFromData& ax) {
  const std::size_t i = index(ax.axis);
  std::vector<double> dv, dx, tp, tn, tt, y;
  for (const RunData& rd : f.runs) {
    const double dt = rd.run->sample_period_s;
    const auto S = static_cast<std::size_t>(std::max(2L, std::lround(0.1 / dt)));
    const std::vector<double>& ref = rd.smooth->trace.at(col(ax.axis, "_ref_mm"));
    const std::vector<double>* x = rd.run->trace.find(col(ax.axis, "_mm"));
    const std::vector<double>* T = rd.run->trace.find(ax.channel.column);
    if (T == nullptr) continue;
    const double tol_mm = std::max(f.position_quantum_mm, 1e-6);
    const auto steady = [&](std::size_t k) {
      if (k < S || k + S >= rd.n_fit) return false;
      for (std::size_t j = k - S; j <= k + S; ++j)
        if (!rd.interior[j]) return false;
      const double r0 = ref[k - S], slope = (ref[k + S] - ref[k - S]) / static_cast<double>(2 * S);
      for (std::size_t j = k - S; j <= k + S; ++j)
        if (std::abs(ref[j] - r0 - slope * static_cast<double>(j - (k - S))) > tol_mm) return false;
      return true;
    };
    const auto segment_of = [&](std::size_t k) {
      for (std::size_t s = 0; s < rd.segments.size(); ++s)
        if (k >= rd.segments[s].begin && k < rd.segments[s].end) return s;
      return rd.segments.size();
    };
    std::optional<std::size_t> start;
    for (std::size_t k = 0; k < rd.n_fit; ++k) {
      if (!steady(k)) continue;
      if (start && (k < *start + S)) continue;
      if (start && segment_of(*start) == segment_of(k)) {
        const std::size_t a = *start, b = k;
        double Tint = 0.0, pos = 0.0, neg = 0.0;
        for (std::size_t j = a; j <= b; ++j) {
          const double w = (j == a || j == b) ? 0.5 * dt : dt;  // the trapezoid
          Tint += w * (*T)[j];
          const int d = direction(rd.kin[i].v_mm_per_s[j], rd.v_move[i]);
          pos += d > 0 ? w : 0.0;
          neg += d < 0 ? w : 0.0;
        }
        const std::vector<double>& pos_mm = x != nullptr ? *x : ref;
        // Each end's speed from the line it is steady on (a row's own,
        // off a rebuilt or low-passed staircase, carries the rounding).
        const auto line_speed = [&](std::size_t m) {
          return (ref[m + S] - ref[m - S]) / (static_cast<double>(2 * S) * dt);
        };
        dv.push_back(line_speed(b) - line_speed(a));
        dx.push_back(pos_mm[b] - pos_mm[a]);
        tp.push_back(pos);
        tn.push_back(-neg);
        tt.push_back(static_cast<double>(b - a) * dt);
        y.push_back(Tint);
      }
      start = k;
    }
  }
  if (y.size() < 20) return std::nullopt;
  std::vector<const std::vector<double>*> X{&dv, &dx};
  if (std::any_of(tp.begin(), tp.end(), [](double v) { return v != 0.0; })) X.push_back(&tp);
  if (std::any_of(tn.begin(), tn.end(), [](double v) { return v != 0.0; })) X.push_back(&tn);
  X.push_back(&tt);
  std::vector<std::size_t> rows(y.size()), first, second;
  for (std::size_t k = 0; k < rows.size(); ++k) {
    rows[k] = k;
    (2 * k < rows.size() ? first : second).push_back(k);
  }
  const LsqResult ls = least_squares(X, y, rows);
  const LsqResult l1 = least_squares(X, y, first), l2 = least_squares(X, y, second);
  if (!ls.ok || !l1.ok || !l2.ok) return std::nullopt;
  return WindowDrive{ls.theta[0], ls.stderr_theta[0], y.size(),
                     std::abs(l1.theta[0] - l2.theta[0]) <= 3.0 * std::hypot(l1.stderr_theta[0], l2.stderr_theta[0])};
}

/// The drive fitted on drive_rows(f, ax, o): J, B, the Coulomb
/// levels and the constant under clamp_drive's floors, the one-level fit
/// beside it; false where it cannot be (why in `why_not`). The floors applied
/// are in ax.note.
///
/// Where the drive is fitted on the commanded kinematics and the windows
/// between steady rows (drive_from_windows) resolve J (to a tenth, their two
/// halves alike) apart from the rows' J beyond both scatters (3 standard
/// errors of the difference) and by more than half the smaller (a few per
/// cent between two good estimates is the windows' own bias: an axis's lag
/// behind a cruise), J is the windows' and the rest is fitted on the rows
/// with J held (said in ax.note).
bool fit_drive(const AxisFit& f, AxisFromData& ax, const DriveRowsOptions& o, std::string& why_not) {
  const DriveRows d = drive_rows(f, ax, o);
  const DriveColumns c = drive_columns(d);
  const bool moves_pos = c.pos, moves_neg = c.neg;
  LsqResult ls = least_squares(c.X, d.T, d.rows);
  ax.fit_rows = d.rows.size();
  if (!ls.ok || !(moves_pos || moves_neg)) {
    why_not = fmt::format("{} rows, {}", d.rows.size(),
                          moves_pos || moves_neg ? "rank deficient" : "the axis does not move");
    return false;
  }
  std::string from_windows;
  std::optional<double> J_held;
  if (!drive_on_logged_speed(f, ax.axis)) {
    const std::optional<WindowDrive> w = drive_from_windows(f, ax);
    const double J_rows = ls.theta[0], J_rows_se = ls.stderr_theta[0];
    if (w && w->J > 0.0 && w->J >= 10.0 * w->J_se && w->halves_agree &&
        std::abs(w->J - J_rows) > 3.0 * std::hypot(w->J_se, J_rows_se) &&
        !(J_rows > 0.0 && w->J < 1.5 * J_rows && J_rows < 1.5 * w->J)) {
      // The rows' fit again with J held: the torque less J a, on the
      // columns but the acceleration's.
      const std::vector<const std::vector<double>*> others(c.X.begin() + 1, c.X.end());
      const LsqResult hls = least_squares(others, torque_less_inertia(d, w->J), d.rows);
      if (hls.ok) {
        LsqResult with_J = hls;
        with_J.theta.insert(with_J.theta.begin(), w->J);
        with_J.stderr_theta.insert(with_J.stderr_theta.begin(), w->J_se);
        ls = with_J;
        J_held = w->J;
        from_windows = fmt::format(
            "J {:.4g} +- {:.2g} from the torque's integral over {} windows between rows where the command holds its "
            "speed (the rows' accelerations gave {:.4g} +- {:.2g}: they do not resolve it)",
            w->J, w->J_se, w->windows, J_rows, J_rows_se);
      }
    }
  }
  take_drive_fit(ls, moves_pos, moves_neg, ax);
  std::vector<std::string> clamped = clamp_drive(d, f.Ts, ax);
  ax.one_level = moves_pos && moves_neg ? fit_one_level(d, f.Ts, ax, J_held) : AxisFromData::OneLevel{};
  if (!from_windows.empty()) {
    // In the note of whichever drive the Coulomb choice takes.
    clamped.insert(clamped.begin(), from_windows);
    if (ax.one_level.ok) ax.one_level.clamped.insert(ax.one_level.clamped.begin(), from_windows);
  }
  ax.note = clamped.empty() ? "" : fmt::format("axis {}: {}", axis_name(ax.axis), fmt::join(clamped, "; "));
  return true;
}

/// Whether the log samples every loop period (the loop's own rows: a lag of
/// a row is one of the loop's, and the command's acceleration is the loop's).
bool samples_every_loop_period(const AxisFit& f) {
  return std::abs(f.r0.sample_period_s - f.Ts) <= 1e-9 + 1e-6 * f.Ts;
}

/// Whether the logged torque holds over its row (AxisFromData::
/// torque_held_over_row): the drive fitted on the speed's forward difference
/// against the central one, on the same rows with the same columns, where a
/// fast log has the motor's speed (not one taken from the position, whose
/// central difference and low-pass already spread each row over its
/// neighbours: there the central one stays). The forward one is taken where
/// its residual is the smaller by more than the rows' scatter,
/// n (r_c^2 - r_f^2) / (r_f^2 corr) of at least kMinT^2 with the residual
/// counted correlated over 10 ms of rows (the same number of parameters
/// either way; under 0.2 N m of torque noise the two residuals differ by
/// 0.6 % and the choice would follow the noise). A digital drive holds
/// its torque command over the loop period, and the speed's change over the
/// row answers to it alone; the central difference spans two rows' torques.
/// Under a loop that rings (a dead time behind a current loop's lag) the
/// central one misreads the ringing torque as friction: on the truth's 2 ms
/// delay it took B 6 % low and the Coulomb levels 5 % high, and the other
/// program tracked at 0.0125 against 0.0076 with the truth's drive.
void choose_torque_timing(const AxisFit& f, AxisFromData& ax) {
  ax.torque_held_over_row = false;
  ax.torque_timing.clear();
  if (!drive_on_logged_speed(f, ax.axis) || has_lowpassed_twin(f.r0.trace, ax.channel.column)) return;
  std::size_t n = 0;
  const auto residual = [&](bool forward) {
    const DriveRows d = drive_rows(f, ax, {.forward = forward});
    const LsqResult ls = least_squares(drive_columns(d).X, d.T, d.rows);
    n = d.rows.size();
    return ls.ok ? ls.residual_rms : 1e300;
  };
  const double central = residual(false), forward = residual(true);
  if (!(forward < 1e300 && central < 1e300)) return;
  const double corr = std::max(1.0, 0.01 / f.r0.sample_period_s);
  ax.torque_held_over_row =
      forward < central &&
      static_cast<double>(n) * (central * central - forward * forward) >= kMinT * kMinT * corr * forward * forward;
  // Where the log is slower than the loop, the torque holds over the loop's
  // period, not the row: the speed one period on is read off the cubic
  // through the rows (drive_rows).
  const bool every_period = samples_every_loop_period(f);
  const std::string held = every_period ? "forward difference over the row"
                                        : fmt::format("change over the loop's {:g} s from the row on", f.Ts);
  const std::string why = ax.torque_held_over_row
                              ? fmt::format("the logged torque holds over the {} it is logged at",
                                            every_period ? "row" : "loop period")
                          : forward < central ? "the two do not differ beyond the rows' scatter"
                                              : "the logged torque is a sample of a torque that changes within the row";
  const std::string central_name = "central difference over the row";
  ax.torque_timing = fmt::format("the drive fitted on the speed's {} (residual {:.3g}; on the {}, {:.3g}): {}",
                                 ax.torque_held_over_row ? held : central_name,
                                 ax.torque_held_over_row ? forward : central,
                                 ax.torque_held_over_row ? central_name : held,
                                 ax.torque_held_over_row ? central : forward, why);
}

/// The drive in the channel's unit; false (said in the axis's note) where it
/// cannot be identified.
bool identify_drive_in_channel(const AxisFit& f, AxisFromData& ax, DataCalibration& out) {
  const Axis a = ax.axis;
  if (!ax.channel.present()) {
    ax.note = fmt::format("axis {}: no torque, current or command channel: the drive is not identified and the axis is "
                          "not replayed",
                          axis_name(a));
    out.notes.push_back(ax.note);
    return false;
  }
  std::string why_not;
  choose_torque_timing(f, ax);
  if (!fit_drive(f, ax, {}, why_not)) {
    ax.note = fmt::format("axis {}: the drive could not be identified ({}); the axis is not replayed", axis_name(a),
                          why_not);
    out.notes.push_back(ax.note);
    return false;
  }
  ax.identified = true;
  if (!ax.note.empty()) out.notes.push_back(ax.note);
  return true;
}

/// Kvp and Tn from the PI law fitted on the log's rows. The law integrates
/// at the loop's period Ts and the fit at the log's dt, each sum taking its
/// period's last value: over a log interval the loop's sum exceeds the log's
/// by (Ts - dt) / 2 times the speed error's change, which the fit puts into
/// Kvp. So Kvp is the fitted one plus Ki (dt - Ts) / 2 (at a 2 ms log of the
/// 1 ms truth, 11.79 fitted, 12.57 so, for 12.57).
void set_velocity_loop(const VelocityLoopFit& vl, const AxisFit& f, controller::CascadeGains& g) {
  const double Ki = vl.ls.theta[1];
  const double excess_s = std::max(0.0, f.r0.sample_period_s - f.Ts);
  g.Kvp_torque_s_per_rad = vl.ls.theta[0] + 0.5 * Ki * excess_s;
  g.Tn_s = Ki > 0.0 ? g.Kvp_torque_s_per_rad / Ki : 0.0;
  g.Jff_torque_s2_per_rad = vl.torque_ff ? vl.ls.theta.back() : 0.0;
}

/// A dead time of part of a position-loop period is looked for in steps of
/// the velocity loop's ticks where it runs at most this many times a period
/// (the columns at a tick read the speeds between the rows off a cubic, and
/// at 8 or 16 ticks a row a tick's dead time is one a current loop's lag
/// covers).
constexpr int kTickLagMaxInnerTicks = 4;

/// The rows a torque may follow its law late: up to 10 ms, 1 to 10 rows.
std::size_t max_torque_lag_rows(const AxisFit& f) {
  return static_cast<std::size_t>(std::clamp(std::lround(0.01 / f.r0.sample_period_s), 1L, 10L));
}

/// The same law a few samples later: a torque that follows its command late
/// (a delay beyond the loop) fits best at that lag. A lag that lowers the
/// residual by less than a fifth is the law's own noise: the residual less
/// the white noise on the logged torque (which no lag fits), so that noise
/// on the log does not hide a lag the law shows.
///
/// On a log slower than the loop the lags are whole loop periods, a row's
/// part taken between two rows (LawFitOptions::lag_fraction): in whole rows
/// a 2 ms delay of a 1 ms loop logged every 4 ms was not seen (the other
/// program tracked at 0.040 NRMS). At most ten steps a row.
void velocity_loop_lag(const AxisFit& f, const VelocityLoopFit& vl, const TorqueClip* clip, AxisFromData& ax) {
  ax.gains_at_lag = ax.gains;
  ax.torque_lag_samples = 0;
  ax.torque_lag_fraction = 0.0;
  // A velocity loop 2 to 4 times as fast as the position loop logged at its
  // ticks: the lags are its ticks (fit_velocity_loop takes the columns at each).
  const bool by_ticks =
      ax.law_inner_ticks > 1 && ax.law_inner_ticks <= kTickLagMaxInnerTicks && !ax.logs_period_mean();
  const long per_row =
      by_ticks ? ax.law_inner_ticks : std::clamp(std::lround(f.r0.sample_period_s / f.Ts), 1L, 10L);
  double best = vl.ls.residual_rms;
  for (std::size_t step = 1; step <= max_torque_lag_rows(f) * static_cast<std::size_t>(per_row); ++step) {
    const std::size_t lag = step / static_cast<std::size_t>(per_row);
    const double part = static_cast<double>(step % static_cast<std::size_t>(per_row)) / static_cast<double>(per_row);
    const VelocityLoopFit vlag = fit_velocity_loop(
        f.runs, ax.axis, ax.channel.column,
        law_options(ax, {.lag = lag, .lag_fraction = part, .clip = clip, .torque_ff = ax.torque_feedforward}));
    if (!(vlag.gains_physical() && vlag.ls.residual_rms < best)) continue;
    best = vlag.ls.residual_rms;
    ax.torque_lag_samples = lag;
    ax.torque_lag_fraction = part;
    set_velocity_loop(vlag, f, ax.gains_at_lag);
  }
  if (ax.torque_lag_rows() > 0.0 && vl.less_noise(best) > 0.8 * vl.less_noise(vl.ls.residual_rms)) {
    ax.torque_lag_samples = 0;
    ax.torque_lag_fraction = 0.0;
    ax.gains_at_lag = ax.gains;
  }
}

/// The plain law's residual at its best lag (velocity_loop_lag's): what a
/// current loop's lag must improve on.
double plain_law_residual(const AxisFit& f, const VelocityLoopFit& vl, const TorqueClip* clip,
                          const AxisFromData& ax) {
  double plain = vl.ls.residual_rms;
  if (ax.torque_lag_rows() > 0.0) {
    const VelocityLoopFit d = fit_velocity_loop(f.runs, ax.axis, ax.channel.column,
                                                law_options(ax, {.lag = ax.torque_lag_samples,
                                                                 .lag_fraction = ax.torque_lag_fraction,
                                                                 .clip = clip,
                                                                 .torque_ff = ax.torque_feedforward}));
    if (d.ls.ok) plain = std::min(plain, d.ls.residual_rms);
  }
  return plain;
}

/// The current loop as a first-order lag where the logged torque shows one:
/// the law fitted with the previous row's torque (fit_velocity_loop's
/// current_lag) on a log that samples every loop period and logs the speed,
/// with the law's columns at 0 to max_lag rows back as for a pure delay (a
/// drive's dead time and its current loop's lag together: each alone left
/// the other program's tracking at 0.054 on a 2 ms dead time with a 1 ms
/// lag, the dead time read as 3 ms). The lag with the smallest residual whose
/// coefficient a lies within 0.05 to 0.95 (tau_i from a third of a period to
/// 20 periods) with positive gains is taken where it leaves under 0.8 of the
/// plain law's residual at its best lag (velocity_loop_lag; both less the
/// noise). Its gains are the loop's, and its lag the dead time a delay is
/// then proposed at. Without it, on the truth's runs with a current loop of
/// 0.5 to 2 ms and a Stribeck rise, Kvp came out 2 to 22 % low and
/// rising_friction, backlash or delay was named for the lag.
void current_loop_lag(const AxisFit& f, const VelocityLoopFit& vl, const TorqueClip* clip, AxisFromData& ax) {
  const double dt = f.r0.sample_period_s;
  if (!samples_every_loop_period(f)) return;
  std::optional<VelocityLoopFit> best;
  std::size_t best_lag = 0;
  for (std::size_t lag = 0; lag <= max_torque_lag_rows(f); ++lag) {
    VelocityLoopFit arx =
        fit_velocity_loop(f.runs, ax.axis, ax.channel.column,
                          law_options(ax, {.lag = lag,
                                           .clip = clip,
                                           .current_lag = true,
                                           .torque_ff = ax.torque_feedforward}));
    if (!arx.ls.ok) continue;
    const double a = arx.ls.theta[2];
    if (!(a > 0.05 && a < 0.95 && arx.gains_physical())) continue;
    if (!best || arx.ls.residual_rms < best->ls.residual_rms) {
      best = std::move(arx);
      best_lag = lag;
    }
  }
  if (!best) return;
  const double plain = plain_law_residual(f, vl, clip, ax);
  if (!(vl.less_noise(best->ls.residual_rms) < 0.8 * vl.less_noise(plain))) return;
  const double a = best->ls.theta[2];
  const double Kvp = best->ls.theta[0] / (1.0 - a), Ki = best->ls.theta[1] / (1.0 - a);
  ax.gains.Kvp_torque_s_per_rad = Kvp;
  ax.gains.Tn_s = Ki > 0.0 ? Kvp / Ki : 0.0;
  ax.gains.Jff_torque_s2_per_rad = best->torque_ff ? best->ls.theta.back() / (1.0 - a) : 0.0;
  ax.gains.tau_i_s = -dt / std::log(a);
  ax.torque_lag_samples = best_lag;
  ax.gains_at_lag = ax.gains;
  ax.loop_source += fmt::format("; a current loop lagging the law by {:.3g} ms{} (a first order: the law with the "
                                "previous row's torque leaves a residual of {:.3g}, {:.3g} without; Kvp {:.4g}, "
                                "Tn {:.3g} s)",
                                1e3 * ax.gains.tau_i_s,
                                best_lag > 0 ? fmt::format(" behind a dead time of {} samples", best_lag) : "",
                                best->ls.residual_rms, plain, Kvp, ax.gains.Tn_s);
}

/// A first-order lag searched on the residual it leaves: a grid of 0.25 to
/// 5 ms, then a golden-section search in log tau between the best grid
/// point's neighbours; the lag of the smallest residual among the grid's
/// best and the search's last two, with that residual (1e300 where nothing
/// fits on the grid).
struct LagFound {
  double tau_s{0.0};
  double residual{1e300};
};
LagFound search_lag(const std::function<double(double)>& residual) {
  const std::vector<double> grid_ms{0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0};
  std::size_t at = 0;
  double r_at = 1e300;
  for (std::size_t g = 0; g < grid_ms.size(); ++g)
    if (const double r = residual(1e-3 * grid_ms[g]); r < r_at) {
      r_at = r;
      at = g;
    }
  if (r_at >= 1e300) return {};
  const GoldenSection s = golden_section_min([&](double x) { return residual(std::exp(x)); },
                                             std::log(1e-3 * grid_ms[at == 0 ? 0 : at - 1]),
                                             std::log(1e-3 * grid_ms[std::min(at + 1, grid_ms.size() - 1)]), 12);
  LagFound best{1e-3 * grid_ms[at], r_at};
  for (const auto& [r, x] : {std::pair{s.f1, s.x1}, std::pair{s.f2, s.x2}})
    if (r < best.residual) best = {std::exp(x), r};
  return best;
}

/// The current loop's lag where the speed is taken from the position: the
/// law is fitted through the zero-phase low-pass there (filtered_alike), and
/// with the previous row's torque as a column that smooth torque's own
/// neighbour fitted the law's misfit (the sweep without the motor's speed
/// went from 8 named wrong and 4 tracking misses to 12 and 5). So the lag is
/// given, not fitted: the law's columns pass through a first-order lag of
/// 0.25 to 5 ms (fit_velocity_loop's lag_a) and then of a golden-section
/// search between the best grid point's neighbours, at each of 0 to max_lag
/// rows of dead time; the pair with the smallest residual is taken where it
/// leaves under 0.8 of the plain law's residual at its best lag (both less
/// the noise). Without it, a truth with a 1 ms current loop behind a 2 ms
/// dead time and no speed logged tracked the other program at 0.047 NRMS,
/// and a 2 ms lag alone was read as a delay. Through the filter a lag and a
/// dead time of about the same total look alike (a 1.7 ms lag fits no
/// better than a 1 ms dead time, and is left as that delay). The law fitted
/// on the first-order lag alone is kept for place_law_dead_time, which
/// tries that lag as a smoothed torque monitor's.
void current_loop_lag_through_filter(const AxisFit& f, const VelocityLoopFit& vl, const TorqueClip* clip,
                                     AxisFromData& ax) {
  const double dt = f.r0.sample_period_s;
  if (!samples_every_loop_period(f)) return;
  struct Best {
    VelocityLoopFit fit;
    std::size_t lag{0};
    double tau_s{0.0};
  };
  std::optional<Best> best, alone;
  const auto fit_at = [&](std::size_t lag, double tau_s) -> std::optional<VelocityLoopFit> {
    VelocityLoopFit v = fit_velocity_loop(
        f.runs, ax.axis, ax.channel.column,
        law_options(ax, {.lag = lag,
                         .clip = clip,
                         .lag_a = std::exp(-dt / tau_s),
                         .torque_ff = ax.torque_feedforward}));
    if (!v.gains_physical()) return std::nullopt;
    return v;
  };
  // Each dead time's lag (search_lag).
  for (std::size_t lag = 0; lag <= max_torque_lag_rows(f); ++lag) {
    const LagFound l = search_lag([&](double tau_s) {
      const std::optional<VelocityLoopFit> v = fit_at(lag, tau_s);
      return v ? v->ls.residual_rms : 1e300;
    });
    if (l.residual >= 1e300) continue;
    std::optional<VelocityLoopFit> v = fit_at(lag, l.tau_s);
    if (v && lag == 0) alone = Best{*v, lag, l.tau_s};
    if (v && (!best || v->ls.residual_rms < best->fit.ls.residual_rms)) best = Best{std::move(*v), lag, l.tau_s};
  }
  if (!best) return;
  const auto gains_of = [&](const Best& b) {
    controller::CascadeGains g = ax.gains;
    const double Kvp = b.fit.ls.theta[0], Ki = b.fit.ls.theta[1];
    g.Kvp_torque_s_per_rad = Kvp;
    g.Tn_s = Ki > 0.0 ? Kvp / Ki : 0.0;
    g.Jff_torque_s2_per_rad = b.fit.torque_ff ? b.fit.ls.theta.back() : 0.0;
    g.tau_i_s = b.tau_s;
    return g;
  };
  const double plain = plain_law_residual(f, vl, clip, ax);
  if (!(vl.less_noise(best->fit.ls.residual_rms) < 0.8 * vl.less_noise(plain))) {
    if (alone) ax.law_lag_alone = gains_of(*alone);
    return;
  }
  ax.gains = gains_of(*best);
  const double Kvp = ax.gains.Kvp_torque_s_per_rad;
  ax.torque_lag_samples = best->lag;
  ax.gains_at_lag = ax.gains;
  ax.loop_source += fmt::format("; a current loop lagging the law by {:.3g} ms{} (the law's columns through that "
                                "first order leave a residual of {:.3g}, {:.3g} without; Kvp {:.4g}, Tn {:.3g} s)",
                                1e3 * best->tau_s,
                                best->lag > 0 ? fmt::format(" behind a dead time of {} samples", best->lag) : "",
                                best->fit.ls.residual_rms, plain, Kvp, ax.gains.Tn_s);
}

/// The drive's residual on the rows where the axis moves, its motion `ahead`
/// rows on through a lag of coefficient a_lag (drive_rows; 1e300 where it
/// cannot be fitted), and those rows' count.
std::pair<double, std::size_t> drive_residual(const AxisFit& f, const AxisFromData& ax, std::size_t ahead,
                                              double a_lag) {
  const DriveRows d = drive_rows(f, ax, {.forward = true, .ahead = ahead, .a_lag = a_lag, .moving_only = true});
  const LsqResult ls = least_squares(drive_columns(d, true).X, d.T, d.rows);
  return {ls.ok ? ls.residual_rms : 1e300, d.rows.size()};
}

/// Where the log holds the torque the velocity loop commands (many drives
/// trace the current loop's input, not its output), the law fits that
/// torque with no lag, but the motion answers to it through the current
/// loop's lag and any dead time. So the drive is fitted on the rows where
/// the axis moves with its motion columns that far ahead (drive_rows, with
/// the speed's forward difference: the acceleration the torque held from a
/// row on gives), the lag by search_lag at each of 0 to max_lag rows of dead
/// time. The motion is moved, not the torque: a lag put on a noisy torque
/// lowers the residual by smoothing the noise, whatever the drive does.
/// The pair with the smallest residual is the candidate where it lowers the
/// residual at the torque's own rows by kMinT standard errors at least (the
/// fall in the sum of squares against the residual's variance, the rows
/// counted by 10 ms of correlation: under 0.2 N m of noise a lag of 0.39 ms
/// lowered a motor torque's residual by 0.1 %, t = 1.9, and replayed better
/// by chance), and decisive where it leaves under 0.8 of that residual, both
/// less the white noise on the torque the drive is fitted on (on a log of
/// the motor's own torque, 0.94 at the least on the cascade sweep's runs).
AxisFromData::MotionBehindTorque motion_behind_torque(const AxisFit& f, const AxisFromData& ax) {
  AxisFromData::MotionBehindTorque m;
  const double dt = f.r0.sample_period_s;
  std::size_t n = 0;
  std::tie(m.plain, n) = drive_residual(f, ax, 0, 0.0);
  if (!(m.plain < 1e300)) return m;
  const auto residual_at = [&](std::size_t rows, double tau_s) {
    return drive_residual(f, ax, rows, tau_s > 0.0 ? std::exp(-dt / tau_s) : 0.0).first;
  };
  double best = m.plain;
  for (std::size_t rows = 0; rows <= max_torque_lag_rows(f); ++rows) {
    if (rows > 0)
      if (const double r = residual_at(rows, 0.0); r < best) {
        best = r;
        m.rows = rows;
        m.tau_s = 0.0;
      }
    const LagFound l = search_lag([&](double tau_s) { return residual_at(rows, tau_s); });
    if (l.residual < best) {
      best = l.residual;
      m.rows = rows;
      m.tau_s = l.tau_s;
    }
  }
  m.residual = best;
  const double corr = std::max(1.0, 0.01 / dt);
  m.t = best > 0.0 ? std::sqrt(std::max(0.0, static_cast<double>(n) / corr * (m.plain * m.plain - best * best)) /
                               best)
                   : 1e3;
  m.shown = (m.rows > 0 || m.tau_s > 0.0) && m.t >= kMinT;
  const double noise = noise_as_fitted(f.runs, ax.channel.column);
  const auto less_noise = [&](double r) { return std::sqrt(std::max(0.0, r * r - noise * noise)); };
  m.decisive = m.shown && less_noise(best) < 0.8 * less_noise(m.plain);
  return m;
}

/// A velocity loop faster than the position loop (most drives run it at 125
/// to 250 us under a 1 ms position loop): its integral sums the speed error
/// at each of its ticks, which a sum once a row misses by half the speed's
/// change over the row, a drift the law then reads as a lag (a 125 us loop
/// under a 1 ms one: a current loop of 10 ms read, the other program tracked
/// at 0.035). Read where the log samples every loop period: the law (with
/// what `o` holds beyond the axis's options) fitted with 1, 2, 4, 8 and 16
/// ticks a period, each at the whole-row lag it fits best (a dead time: at
/// lag 0 every count of ticks fits badly, and a 2 ms one took 16 ticks for
/// 8); the count of the smallest residual is taken where it leaves under 0.8
/// of the residual of one tick (both less the noise), else one. Where the
/// count changes, ax.law_inner_ticks and `vl` (the law at lag 0 with
/// `refit`) change with it; returns the report's words for a count above
/// one (empty for one). Looked for first, as every later fit sums so, and
/// again where the law gains a lead error, a gap, a feedforward or a limit's
/// rows, which the first look fitted as the law's misfit (a lead error of
/// 8 um hid 8 ticks). Each count is also fitted on the logged torque as the
/// mean of the law's over the period (AxisFromData::law_period_mean), and
/// the way of logging that fits better is taken with its count (below).
/// `best_count` and `best_mean`, where given, receive the best count and
/// way of logging even where one tick is kept.
std::string choose_inner_ticks(const AxisFit& f, AxisFromData& ax, const LawFitOptions& o, VelocityLoopFit& vl,
                               const LawFitOptions& refit, int* best_count = nullptr, bool* best_mean = nullptr) {
  if (!vl.ls.ok || !samples_every_loop_period(f)) return {};
  const auto best_over_lags = [&](int n, bool mean) {
    std::optional<VelocityLoopFit> best;
    const int steps = mean || n > kTickLagMaxInnerTicks ? 1 : n;
    for (std::size_t lag = 0; lag <= max_torque_lag_rows(f); ++lag)
      for (int step = 0; step < steps; ++step) {
        LawFitOptions at = law_options(ax, o);
        at.lag = lag;
        at.lag_fraction = static_cast<double>(step) / steps;
        at.inner_ticks = n;
        at.bend_J = 0.0;
        at.period_mean = mean;
        VelocityLoopFit fit = fit_velocity_loop(f.runs, ax.axis, ax.channel.column, at);
        if (fit.gains_physical() && (!best || fit.ls.residual_rms < best->ls.residual_rms)) best = std::move(fit);
      }
    return best;
  };
  const std::optional<VelocityLoopFit> once = best_over_lags(1, false);
  // A mean over the period is looked for only in a channel as logged: one
  // read a row earlier at loading (a mean, logged with the speed, is) is
  // taken as the tick's, as it fits then (below); as a mean, a row's dead
  // time fitted with the logger's row (a 2 ms delay was read as 3 ms).
  bool as_logged = true;
  for (const RunData& rd : f.runs) as_logged = as_logged && !rd.run->rows_read_earlier.contains(ax.channel.column);
  // The best count of ticks, each at its best lag, with the row's own tick
  // logged and with the period's mean.
  struct Best {
    std::optional<VelocityLoopFit> fit;
    int n{1};
  };
  Best tick, mean_fit;
  for (int n : {2, 4, 8, 16})
    for (const bool mean : {false, true}) {
      if (mean && !as_logged) continue;
      Best& b = mean ? mean_fit : tick;
      if (std::optional<VelocityLoopFit> fn = best_over_lags(n, mean);
          fn && (!b.fit || fn->ls.residual_rms < b.fit->ls.residual_rms))
        b = Best{std::move(fn), n};
    }
  // The two ways of logging fit the law with the same columns, so the one
  // of the smaller residual is taken: the mean over the period where it
  // leaves under 0.95 of the residual of the row's own tick (both less the
  // noise), else the tick's, which logs hold more often. Without the
  // motor's speed (the law fitted through the speed's low-pass) a 125 us
  // loop under a 1 ms one left 0.565 with the mean and 0.634 with the tick
  // (a row late) on a log of the mean, and 0.928 against 0.565 on a log of
  // the tick. Where the speed is logged, a mean is read a row earlier at
  // loading (its row answers to the speed's change over the row before, as
  // a held torque's to the change after it); the tick's law then fits it
  // (0.22 against 0.82).
  const bool mean =
      mean_fit.fit && (!tick.fit || tick.fit->less_noise(mean_fit.fit->ls.residual_rms) <
                                         0.95 * tick.fit->less_noise(tick.fit->ls.residual_rms));
  const Best& chosen = mean ? mean_fit : tick;
  const std::optional<VelocityLoopFit>& best = chosen.fit;
  const int best_n = chosen.n;
  const bool faster =
      once && best && once->less_noise(best->ls.residual_rms) < 0.8 * once->less_noise(once->ls.residual_rms);
  if (best_count != nullptr) *best_count = best ? best_n : 1;
  if (best_mean != nullptr) *best_mean = best && mean;
  const int n = faster ? best_n : 1;
  if (n != ax.law_inner_ticks || (faster && mean) != ax.law_period_mean) {
    ax.law_inner_ticks = n;
    ax.law_period_mean = faster && mean;
    if (VelocityLoopFit at = fit_velocity_loop(f.runs, ax.axis, ax.channel.column, law_options(ax, refit)); at.ls.ok)
      vl = std::move(at);
  }
  if (!faster) return {};
  const std::string logged =
      !mean ? std::string()
            : fmt::format("; the logged torque is the mean of the law's over the period before each row (residual "
                          "{:.3g}, {:.3g} as the row's own tick's)",
                          best->ls.residual_rms, tick.fit ? tick.fit->ls.residual_rms : 0.0);
  return fmt::format("; the law's integral sums the speed error {} times a period: a velocity loop at {:.4g} ms under "
                     "the position loop's {:.4g} ms (residual {:.3g} at its best lag, {:.3g} summed once a period){}",
                     n, 1e3 * f.Ts / n, 1e3 * f.Ts, best->ls.residual_rms, once->ls.residual_rms, logged);
}

/// The velocity loop: from the logged torque against the speed error where
/// both speeds are logged every kLawFitMaxPeriod_s or faster, else well
/// above the position loop.
void identify_velocity_loop(const AxisFit& f, AxisFromData& ax, bool have_vcmd) {
  const double wv = std::min(std::max(5.0 * ax.gains.Kv_per_s, 2.0 * M_PI * 20.0), 0.3 / f.Ts);
  ax.gains.Kvp_torque_s_per_rad = ax.J * wv;
  ax.gains.Tn_s = 4.0 / wv;
  ax.gains.tau_i_s = 0.0;
  ax.gains.T_max = 1e9;
  ax.blind_velocity_loop = ax.gains;
  if (have_vcmd && f.r0.sample_period_s <= kLawFitMaxPeriod_s + 1e-12 &&
      all_runs_log(f.runs, col(ax.axis, "_v_mm_s"))) {
    VelocityLoopFit vl = fit_velocity_loop(f.runs, ax.axis, ax.channel.column);
    // The first look leaves out the rows where the logged torque stands at
    // its largest (a limit's: the law asks for more there), its running sum
    // through them; a 7.2 A limit took 4 ticks for 8 with them in.
    std::string inner;
    int best_count = 1;
    bool best_mean = false;
    {
      std::vector<std::vector<char>> at;
      const bool limit = rows_at_limit(f.runs, ax.channel.column, at).held >= kClippedRows;
      inner = choose_inner_ticks(
          f, ax, limit ? LawFitOptions{.limit_rows = &at, .constant_after_limit = false} : LawFitOptions{}, vl, {},
          &best_count, &best_mean);
    }
    // A limit that holds the integral while it clamps (anti-windup): after
    // each stretch at the limit the law resumes short of its running sum, so
    // the law is fitted with a new constant there from then on. Taken where
    // it leaves under 0.8 of the residual the law leaves without the rows at
    // the limit but with its running sum through them (both less the noise),
    // and where the constants step by what the held integral makes them
    // (VelocityLoopFit::held_share, over kHeldShareOfAntiWindup); where the
    // integral runs on through the limit the constants agree and fit no
    // better. Looked for first: the running sum's misfit was read as a lead
    // error, a gap or a feedforward. Under a velocity loop that ticks twice
    // a row a limit that starts or ends within a row leaves the running sum
    // off by the speed's bend over that part of the row (the law's own
    // proportional action, which the limit stops), and a new constant after
    // each stretch fitted that better (0.084 against 0.19) where the truth's
    // current limit lets the integral run on (the other program tracked at
    // 0.024); its steps carried 0.003 of the held integrals, against 0.42 and
    // 0.43 where the truth's limit holds the integral (test
    // ALimitThatHoldsTheIntegralIsFoundInTheLaw; not 1, as the rows at the
    // limit in the log are not exactly the ticks its command was clamped at).
    std::string held_integral;
    if (vl.ls.ok) {
      std::vector<std::vector<char>> at;
      if (const RowsAtLimit lim = rows_at_limit(f.runs, ax.channel.column, at); lim.held >= kClippedRows) {
        ax.law_limit_rows = std::move(at);
        VelocityLoopFit w = fit_velocity_loop(f.runs, ax.axis, ax.channel.column, law_options(ax, {}));
        const VelocityLoopFit on = fit_velocity_loop(f.runs, ax.axis, ax.channel.column,
                                                     law_options(ax, {.constant_after_limit = false}));
        if (w.gains_physical() && on.ls.ok &&
            w.less_noise(w.ls.residual_rms) < 0.8 * on.less_noise(on.ls.residual_rms) &&
            w.held_share() > kHeldShareOfAntiWindup) {
          held_integral = fmt::format("; the logged torque stands at its largest ({} rows, median {:.4g}) and the law "
                                      "resumes after each stretch there from a new constant (residual {:.3g} against "
                                      "{:.3g}; the constants step by {:.2g} of the integral held over the "
                                      "stretches): a limit that holds the integral while it clamps (anti-windup)",
                                      lim.held, lim.level, w.ls.residual_rms, on.ls.residual_rms, w.held_share());
          ax.law_limit_level = lim.level;
          vl = std::move(w);
        } else {
          ax.law_limit_rows.clear();
        }
      }
    }
    // Where the speed is the encoder's own, what parts the motor from the
    // encoder shows in the law: a gap (its constants step with the
    // direction of motion by Ki times it; three position steps at least,
    // 1 um where the log shows no rounding), then a lead error; each is
    // fitted with the law from then on. A torque fed forward is chosen after
    // them (a gap made the law with the command's acceleration fit better
    // when it had none), so each is looked for without that column and,
    // where the log samples every loop period, with it, and the look with
    // the larger t is taken: left out of the law, a feedforward of Jff
    // 0.01 N m s^2/rad hid both; always in, its column's scatter hid a gap
    // of 10 um under 0.2 N m of noise.
    const bool every_period = samples_every_loop_period(f);
    // Each hides the other: a velocity loop faster than the position loop
    // and a lead error or gap (a lead error of 8 um: the law's misfit summed
    // once a period took the lead error's share, and neither was read, the
    // other program tracked at 0.028). Where the first look at the ticks
    // kept one but fitted best with more, and neither part is shown with
    // one, the parts are looked for with that count, and kept where the
    // count, chosen again with them, stays above one (a count that is not
    // the loop's leaves a drift that steps with the direction as a gap's
    // constants do).
    const auto look_for_parts = [&] {
      std::string lead;
      if (vl.ls.ok && has_lowpassed_twin(f.runs.front().run->trace, ax.channel.column)) {
        const double q = std::max(f.position_quantum_mm, 1e-3);
        GapInLaw gp = gap_in_law(f.runs, ax, law_options(ax, {}));
        if (every_period)
          if (GapInLaw with_ff = gap_in_law(f.runs, ax, law_options(ax, {.torque_ff = true})); with_ff.t > gp.t)
            gp = with_ff;
        if (gp.t >= kMinT && gp.gap_mm >= 3.0 * q && gp.gap_mm <= 1.0) {
          ax.law_gap_mm = gp.gap_mm;
          const double before = vl.ls.residual_rms;
          vl = fit_velocity_loop(f.runs, ax.axis, ax.channel.column, law_options(ax, {}));
          lead = fmt::format("; the law's constant steps with the direction of motion as a gap of {:.4g} mm between "
                             "the motor and the encoder makes it (t = {:.1f} over {} stretches of motion; residual "
                             "{:.3g} against {:.3g}): fitted with a constant per stretch",
                             gp.gap_mm, std::min(gp.t, 1e3), gp.stretches, vl.ls.residual_rms, before);
        }
        LeadInLaw l = lead_error_in_law(f.runs, ax, law_options(ax, {}));
        if (every_period)
          if (LeadInLaw with_ff = lead_error_in_law(f.runs, ax, law_options(ax, {.torque_ff = true}));
              with_ff.P_mm > 0.0 && (l.P_mm == 0.0 || with_ff.t > l.t))
            l = std::move(with_ff);
        if (l.P_mm > 0.0) {
          ax.law_lead_period_mm = l.P_mm;
          vl = fit_velocity_loop(f.runs, ax.axis, ax.channel.column, law_options(ax, {}));
          lead += fmt::format("; the law's residual follows the position with a period of {:.4g} mm (t = {:.1f}, "
                              "residual {:.3g} against {:.3g}): a lead error between the motor and the encoder, "
                              "fitted with the law",
                              l.P_mm, l.t, l.ls.residual_rms, l.base_residual);
        }
      }
      return lead;
    };
    std::string lead = look_for_parts();
    if (lead.empty() && ax.law_inner_ticks == 1 && best_count > 1 && vl.ls.ok &&
        has_lowpassed_twin(f.runs.front().run->trace, ax.channel.column)) {
      ax.law_inner_ticks = best_count;
      ax.law_period_mean = best_mean;
      VelocityLoopFit at_count = fit_velocity_loop(f.runs, ax.axis, ax.channel.column, law_options(ax, {}));
      std::swap(vl, at_count);
      lead = look_for_parts();
      if (!lead.empty()) inner = choose_inner_ticks(f, ax, {}, vl, {});
      if (lead.empty() || ax.law_inner_ticks == 1) {
        ax.law_inner_ticks = 1;
        ax.law_period_mean = false;
        ax.law_gap_mm = ax.law_lead_period_mm = 0.0;
        lead.clear();
        inner.clear();
        vl = std::move(at_count);
      }
    }
    // The count of ticks again with the parts the law shows (a feedforward
    // is then chosen on it: at one tick its column took the count's misfit,
    // and the law with 8 and the lead error fed forward a negative torque).
    if (ax.law_gap_mm > 0.0 || ax.law_lead_period_mm > 0.0 || ax.law_holds_integral_at_limit())
      inner = choose_inner_ticks(f, ax, {}, vl, {});
    // A torque fed forward from the command's acceleration (the spec's
    // acceleration or torque feedforward): the law with that acceleration as
    // a column, taken where its coefficient is positive and it leaves under
    // 0.8 of the plain law's residual (both less the noise). Read where the
    // log samples every loop period, whose acceleration the loop takes.
    std::string fed_forward;
    if (vl.ls.ok && every_period) {
      VelocityLoopFit ff = fit_velocity_loop(f.runs, ax.axis, ax.channel.column,
                                             law_options(ax, {.torque_ff = true}));
      if (ff.ls.ok && ff.ls.theta.back() > 0.0 &&
          ff.less_noise(ff.ls.residual_rms) < 0.8 * vl.less_noise(vl.ls.residual_rms)) {
        fed_forward = fmt::format("; a torque fed forward from the command's acceleration (Jff {:.4g}: the law with "
                                  "it leaves a residual of {:.3g}, {:.3g} without)",
                                  ff.ls.theta.back(), ff.ls.residual_rms, vl.ls.residual_rms);
        ax.torque_feedforward = true;
        vl = std::move(ff);
      }
    }
    if (ax.torque_feedforward)
      inner = choose_inner_ticks(f, ax, {.torque_ff = true}, vl, {.torque_ff = true});
    // A torque limit: the logged torque flattens near its largest value where
    // the law asks for more. Those rows follow the limit, not the law; the
    // law is fitted on the rest.
    std::optional<TorqueClip> clip;
    std::string clipped;
    if (vl.ls.ok && vl.held_by_limit >= clipped_rows(f.r0.sample_period_s) && !ax.law_holds_integral_at_limit()) {
      const std::size_t held = vl.held_by_limit;
      // The rows held are found with the law fitted so far; a fit without
      // them asks for the unlimited torque more nearly, so twice more.
      TorqueClip c{vl.ls.theta, vl.c_seg, vl.T_abs_max, vl.noise_rms};
      for (int pass = 0; pass < 3; ++pass) {
        const VelocityLoopFit inside =
            fit_velocity_loop(f.runs, ax.axis, ax.channel.column,
                              law_options(ax, {.clip = &c, .torque_ff = ax.torque_feedforward}));
        if (!inside.ls.ok) break;
        clip = c;
        vl = inside;
        c.theta = inside.ls.theta;
        c.c_seg = inside.c_seg;
      }
      if (clip) {
        ax.law_clip_level = c.T_abs_max;
        clipped = fmt::format("; the logged torque flattens near {:.4g} where the law asks for more ({} rows): the "
                              "rows a limit holds are left out of the law's fit",
                              c.T_abs_max, held);
        const LawFitOptions o{.clip = &*clip, .torque_ff = ax.torque_feedforward};
        inner = choose_inner_ticks(f, ax, o, vl, o);
      }
    }
    // The law must explain most of the torque: its residual under 0.3 of
    // the torque's RMS, both less the white noise on the log (which no law
    // fits; at 0.2 N m of noise on a torque of 0.75 N m RMS the residual is
    // mostly the noise). On a log slower than 5 ms the law's integral,
    // summed once a row, drifts over a segment (at 20 ms of a 1 ms loop the
    // residual in levels was 0.41 of the torque); there the law is also
    // taken where its misfit from row to row is under 0.3 of the torque's
    // change (0.2 there).
    const bool explains = vl.less_noise(vl.ls.residual_rms) < 0.3 * vl.less_noise(vl.T_rms);
    const bool explains_steps = !resolves_velocity_loop(f.r0.sample_period_s) &&
                                vl.step_less_noise(vl.step_residual_rms) < 0.3 * vl.step_less_noise(vl.step_T_rms);
    if (vl.gains_physical(std::max(0.0, f.r0.sample_period_s - f.Ts)) && (explains || explains_steps)) {
      set_velocity_loop(vl, f, ax.gains);
      ax.gains.Tv_s = ax.law_inner_ticks > 1 ? f.Ts / ax.law_inner_ticks : 0.0;
      ax.velocity_loop_from_data = true;
      const std::string by_steps =
          explains ? std::string()
                   : fmt::format(", {:.3g} of an RMS {:.3g} from row to row: the law's integral, summed between "
                                 "rows {:g} s apart, drifts over a segment",
                                 vl.step_residual_rms, vl.step_T_rms, f.r0.sample_period_s);
      ax.loop_source += fmt::format("; velocity loop from the logged torque against the speed error (residual "
                                    "{:.3g} of an RMS {:.3g}{}){}",
                                    vl.ls.residual_rms, vl.T_rms, by_steps,
                                    inner + held_integral + lead + clipped + fed_forward);
      velocity_loop_lag(f, vl, clip ? &*clip : nullptr, ax);
      // Where the speed is taken from the position the law is fitted through
      // the low-pass, whose own lag the previous row's torque would fit.
      if (has_lowpassed_twin(f.r0.trace, ax.channel.column))
        current_loop_lag_through_filter(f, vl, clip ? &*clip : nullptr, ax);
      else
        current_loop_lag(f, vl, clip ? &*clip : nullptr, ax);
    }
  }
  if (!ax.velocity_loop_from_data) {
    ax.law_inner_ticks = 1;
    ax.loop_source += fmt::format("; the velocity loop is not seen directly in this log: its bandwidth starts at "
                                  "{:.3g} rad/s ({:.3g} times Kv) with Tn = 4 / that",
                                  wv, wv / ax.gains.Kv_per_s);
  }
}

/// A law's lag of `tau_s` placed `share_in_loop` in the loop (the current
/// loop's) and the rest in the logged channel's monitor.
void place_lag(sim::AxisDefinition& def, double tau_s, double share_in_loop) {
  def.loop.cascade.tau_i_s = share_in_loop * tau_s;
  def.logged_torque_filter_s = (1.0 - share_in_loop) * tau_s;
}

/// The axis of the machine: the cascade loop and the drive in the channel's
/// unit (Kt = Ka = 1, rg = 1 mm/rad).
void set_identified_axis(sim::AxisDefinition& def, const AxisFromData& ax) {
  def.present = true;
  def.drive = feeddrive::DriveParams{};
  def.drive.Ka_A_per_V = 1.0;
  def.drive.Kt_Nm_per_A = 1.0;
  def.drive.rg_mm_per_rad = 1.0;
  set_drive(def.drive, DriveRefit{ax.J, ax.B, ax.Tc_pos, ax.Tc_neg, ax.c});
  def.loop.law = controller::LoopLaw::kCascade;
  def.loop.cascade = ax.gains;
  def.torque_command_logged = ax.torque_command_logged ? 1.0 : 0.0;
  def.logged_torque_filter_s = 0.0;
  def.logged_torque_period_mean = ax.logs_period_mean() ? 1.0 : 0.0;
  if (ax.lag_in_monitor) place_lag(def, ax.gains.tau_i_s, ax.lag_share_in_loop);
  def.following_error_limit_mm = 1e3;
}

/// Where the law shows a velocity loop that runs several times a row
/// (AxisFromData::law_inner_ticks) and the drive is fitted on a speed (the
/// motor's, or the one taken from the position): the drive fitted again on the speed's forward difference over the row
/// against the torque's mean over the loop's ticks in it (drive_rows); kept
/// where it fits.
void refit_drive_under_fast_velocity_loop(const AxisFit& f, AxisFromData& ax) {
  if (ax.law_inner_ticks <= 1 || !drive_on_logged_speed(f, ax.axis)) return;
  AxisFromData trial = ax;
  trial.torque_held_over_row = true;
  std::string why_not;
  if (!fit_drive(f, trial, {}, why_not)) return;
  const std::string at_each =
      ax.torque_lag_rows() > 0.0
          ? fmt::format("the law's torque at each, {:.3g} ms earlier behind the dead time the law shows, the speed "
                        "between the rows off the cubic through them",
                        1e3 * ax.torque_lag_rows() * f.r0.sample_period_s)
          : std::string("the law's torque at each, the speed moving linearly from the row to the next");
  trial.torque_timing = fmt::format("the drive fitted on the speed's forward difference over the row against the "
                                    "torque's mean over the velocity loop's {} ticks in it ({}): J {:.4g}, {:.4g} on "
                                    "the row's own torque",
                                    ax.law_inner_ticks, at_each, trial.J, ax.J);
  ax = std::move(trial);
}

/// Loop and drive of one axis, found in the fitting runs.
AxisFromData identify_axis_from_data(const AxisFit& f, Axis a, sim::MachineDefinition& m, DataCalibration& out) {
  AxisFromData ax;
  ax.axis = a;
  ax.channel = torque_channel(f.r0, a);
  // A velocity command logged, or rebuilt from the torque where none is.
  const bool have_vcmd = all_runs_log(f.runs, col(a, "_vcmd_mm_s")) ||
                         all_runs_log(f.runs, for_identification(col(a, "_vcmd_mm_s")));
  const bool have_x = all_runs_log(f.runs, col(a, "_mm"));
  identify_position_loop(f, ax, have_vcmd, have_x);
  if (!identify_drive_in_channel(f, ax, out)) return ax;
  identify_velocity_loop(f, ax, have_vcmd);
  refit_drive_under_fast_velocity_loop(f, ax);
  if (ax.velocity_loop_from_data && ax.gains.tau_i_s == 0.0 && ax.torque_lag_rows() == 0.0 &&
      samples_every_loop_period(f))
    ax.motion_behind_torque = motion_behind_torque(f, ax);
  set_identified_axis(m.axes[index(a)], ax);
  return ax;
}

/// The encoder the twin's loop closes on, said in a note: meta.json's where
/// the first fitting run gives one (as `twin replay` takes it); else the step
/// the measured positions are logged to, where that is not the log's display
/// rounding; else 1 um. The commands' rounding is not the encoder's: the
/// cascade sweep's truth logs its 1 um encoder's positions to 3 decimals and
/// its commands to 4, and the twin closed its loop on 0.1 um, whose stick/slip
/// at rest hunts by other counts (the run without an effect validated at
/// tracking 0.0024 and torque 0.057 NRMS, and at 0.0015 and 0.011 replayed by
/// `twin replay` on the same machine with the meta's 1 um).
double choose_encoder(const AxisFit& f, DataCalibration& out) {
  if (f.r0.meta.encoder_resolution_mm) {
    out.notes.push_back(fmt::format("encoder resolution {:g} mm from meta.json: the twin's loop closes on it",
                                    *f.r0.meta.encoder_resolution_mm));
    return *f.r0.meta.encoder_resolution_mm;
  }
  if (out.display_rounding) return 0.001;  // said with the rounding
  double q = 0.0;
  for (const RunData& rd : f.runs) q = std::max(q, detect_rounding_of(*rd.run, {"_mm"}).quantum_mm);
  if (!(q > 0.0)) q = 0.001;
  out.notes.push_back(fmt::format("encoder resolution {:g} mm, the step the measured positions are logged to: the "
                                  "twin's loop closes on it",
                                  q));
  return q;
}

/// The velocity loop's law and the drive fitted again on the log's own rows,
/// where the log samples faster than the position loop and the law shows a
/// velocity loop that ticks once a row of it (law_inner_ticks the log's rows
/// per loop period) and nothing beside its two gains: no lag, no dead time,
/// no feedforward of torque, no lead error, gap or limit. On the kept rows
/// the speed is the central difference over a loop period, whose gain falls
/// to 0.76 at the 50 Hz the channels are low-passed at under a 4 ms loop
/// (1 ms: 0.98), and the row's torque is one tick's of the several that move
/// the axis over the row; on the truth's cascade under a 4 ms position loop
/// over a 1 ms velocity loop with no speed logged, the law read there had
/// Kvp 2.5 % high and Tn 4 % low, J 2.4 % high, and the other program
/// tracked at 0.0061 against 0.0014 with the truth's values.
///
/// On each fitting segment's span of the log's rows (fitting rows only), the
/// position, the velocity command and the torque are low-passed alike at
/// kSpeedCutoff_Hz without phase, the speed is the position's central
/// difference, and away from the filter's ends (a cut-off period) the law
///   T = Kvp vcmd + b v + Ki (sum of vcmd dt - (x - x0)) + c_span
/// is fitted, its integral the position's change (no sum of a speed to
/// drift), the speed's column free (b = -Kvp plus Ki dt times where in
/// its tick the loop reads the speed); the drive
///   T = J a + B v + Tc+ [v > 0] - Tc- [v < 0] + c
/// on the same rows. Kept where the fitting runs' held-out rows replay
/// better on the axis's channels (the sum of their NRMS), as a structure is;
/// said in a note either way.
void refit_on_log_rows(const AxisFit& f, DataCalibration& out, sim::MachineDefinition& m) {
  if (f.runs.empty() || !resolves_velocity_loop(f.r0.sample_period_s)) return;
  for (const RunData& rd : f.runs)
    if (!rd.run->log_rows || rd.run->log_rows_per_loop_period < 2) return;
  sim::MachineDefinition trial = m;
  std::vector<std::pair<std::size_t, AxisFromData>> changed;  // the axis's place in out.axis, its refit
  std::vector<std::string> said;
  for (std::size_t ai = 0; ai < out.axis.size(); ++ai) {
    const AxisFromData& ax = out.axis[ai];
    const Axis a = ax.axis;
    const std::size_t i = index(a);
    // The dead time the law shows on the kept rows, in the log's rows.
    const double lag_log_rows = ax.torque_lag_rows() * static_cast<double>(f.r0.log_rows_per_loop_period);
    const auto lag0 = static_cast<std::size_t>(std::llround(lag_log_rows));
    const bool plain = ax.identified && ax.velocity_loop_from_data &&
                       std::abs(lag_log_rows - static_cast<double>(lag0)) < 1e-6 && ax.gains.tau_i_s == 0.0 &&
                       !ax.torque_feedforward && ax.law_lead_period_mm == 0.0 && ax.law_gap_mm == 0.0 &&
                       !ax.law_holds_integral_at_limit() && !ax.logs_period_mean() && !ax.torque_command_logged &&
                       !ax.lag_in_monitor && ax.channel.present();
    if (!plain) continue;
    // Each run's spans of the log's rows and its columns there; the largest
    // |torque| and the torque's white noise over them (for a limit).
    struct Span {
      const MeasuredRun::LogRows* lr{nullptr};
      Segment rows;
      std::size_t run{0};
    };
    std::vector<Span> spans;
    bool usable = true;
    double T_max = 0.0;
    std::vector<double> d2;
    for (std::size_t r = 0; r < f.runs.size() && usable; ++r) {
      const RunData& rd = f.runs[r];
      const MeasuredRun::LogRows& lr = *rd.run->log_rows;
      const std::vector<double>*x = lr.trace.find(col(a, "_mm")), *vc = lr.trace.find(col(a, "_vcmd_mm_s")),
      *T = lr.trace.find(ax.channel.column);
      usable = x != nullptr && vc != nullptr && T != nullptr &&
               rd.run->trace.find(for_identification(col(a, "_vcmd_mm_s"))) == nullptr &&
               ax.law_inner_ticks == static_cast<int>(rd.run->log_rows_per_loop_period);
      if (!usable) break;
      const auto margin = static_cast<std::size_t>(std::ceil(1.0 / (kSpeedCutoff_Hz * lr.sample_period_s)));
      for (const Segment& s : rd.segments) {
        const std::size_t end = std::min(s.end, rd.n_fit);
        if (end < s.begin + 2) continue;
        const Segment sp{lr.kept[s.begin], lr.kept[end - 1] + 1};
        if (sp.end - sp.begin < std::max(kSpeedFilterRows, 4 * margin)) continue;
        spans.push_back({&lr, sp, r});
        for (std::size_t k = sp.begin; k < sp.end; ++k) {
          T_max = std::max(T_max, std::abs((*T)[k]));
          if (k >= sp.begin + 2) d2.push_back(std::abs((*T)[k] - 2.0 * (*T)[k - 1] + (*T)[k - 2]));
        }
      }
    }
    if (!usable || spans.empty()) continue;
    // Rows at a limit of the torque (within 2 % of the largest, or four
    // times the noise: rows_at_limit's rule) do not follow the law, and the
    // law's integral resumes after them from a constant its sum need not
    // give (a limit that holds it): they, and the filter's reach about
    // them, are left out of the law, and each stretch between them has a
    // constant of its own. The drive takes every row (the torque at a limit
    // still drives the axis).
    const double at_limit = T_max - std::max(0.02 * T_max, 4.0 * white_noise_rms(std::move(d2)));
    // The drive's columns on every row taken (d.vel and d.T are the law's
    // speed and torque too), the law's own beside them.
    DriveRows d;
    std::vector<double> vc_c, sum_c;
    std::vector<std::size_t> law_rows, group_of, in_span;
    std::size_t groups = 0;
    for (const Span& sp : spans) {
      const MeasuredRun::LogRows& lr = *sp.lr;
      const RunData& rd = f.runs[sp.run];
      const double dt = lr.sample_period_s;
      const auto margin = static_cast<std::size_t>(std::ceil(1.0 / (kSpeedCutoff_Hz * dt)));
      const std::vector<Segment> one{sp.rows};
      const std::vector<double>&x = lr.trace.at(col(a, "_mm")), &vc = lr.trace.at(col(a, "_vcmd_mm_s")),
      &T = lr.trace.at(ax.channel.column);
      const std::vector<double> xf = lowpass_in_segments(x, one, dt), vcf = lowpass_in_segments(vc, one, dt),
                                Tf = lowpass_in_segments(T, one, dt);
      const std::size_t n = sp.rows.end - sp.rows.begin;
      // The motor's speed where the log has it (the law's own feedback,
      // which a gap or a compliance parts from the position), else the
      // position's difference.
      const std::vector<double>* logged_v = lr.trace.find(col(a, "_v_mm_s"));
      const std::vector<double> v =
          logged_v != nullptr
              ? [&] {
                  const std::vector<double> vf = lowpass_in_segments(*logged_v, one, dt);
                  return std::vector<double>(vf.begin() + static_cast<std::ptrdiff_t>(sp.rows.begin),
                                             vf.begin() + static_cast<std::ptrdiff_t>(sp.rows.end));
                }()
              : derivative(std::span<const double>(xf.data() + sp.rows.begin, n), dt);
      const std::vector<double> acc = derivative(v, dt);
      // Rows from the nearest row at the limit, each way.
      std::vector<std::size_t> near(n, n);
      for (std::size_t j = 0, last = n; j < n; ++j) {
        if (std::abs(T[sp.rows.begin + j]) >= at_limit && at_limit > 0.0) last = j;
        if (last < n) near[j] = j - last;
      }
      for (std::size_t j = n, next = n; j-- > 0;) {
        if (std::abs(T[sp.rows.begin + j]) >= at_limit && at_limit > 0.0) next = j;
        if (next < n) near[j] = std::min(near[j], next - j);
      }
      double sum = 0.0;
      bool fresh = true;
      for (std::size_t j = 0; j < n; ++j) {
        const std::size_t k = sp.rows.begin + j;
        if (j > 0) sum += (vcf[k] - (logged_v != nullptr ? v[j] : 0.0)) * dt;
        if (j < margin || j + margin >= n) continue;
        const bool law_row = near[j] > margin + 2;
        if (!law_row) fresh = true;
        if (law_row && fresh) {
          ++groups;
          fresh = false;
        }
        const std::size_t row = d.T.size();
        vc_c.push_back(vcf[k]);
        sum_c.push_back(logged_v != nullptr ? sum : sum - (xf[k] - xf[sp.rows.begin]));
        const int dir = direction(v[j], rd.v_move[i]);
        d.acc.push_back(acc[j]);
        d.vel.push_back(v[j]);
        d.pos.push_back(dir > 0 ? 1.0 : 0.0);
        d.neg.push_back(dir < 0 ? -1.0 : 0.0);
        d.one.push_back(1.0);
        d.T.push_back(Tf[k]);
        d.a2 += acc[j] * acc[j];
        d.T2 += Tf[k] * Tf[k];
        d.rows.push_back(row);
        group_of.push_back(groups - 1);
        in_span.push_back(j - margin);
        if (law_row) law_rows.push_back(row);
      }
    }
    if (law_rows.size() < 1000) continue;
    // The law with its columns `lag` rows before the torque's row (a dead
    // time between the law and the logged torque): each stretch's constant
    // taken out (the columns less their stretch's means over the rows
    // fitted), then its three gains.
    const auto fit_law = [&](std::size_t lag) {
      std::vector<std::size_t> rows;
      for (std::size_t k : law_rows)
        if (in_span[k] >= lag) rows.push_back(k);
      std::vector<double> sum(groups, 0.0), cnt(groups, 0.0);
      for (std::size_t k : rows) cnt[group_of[k]] += 1.0;
      const auto less_group_means = [&](const std::vector<double>& c, std::size_t back) {
        std::fill(sum.begin(), sum.end(), 0.0);
        for (std::size_t k : rows) sum[group_of[k]] += c[k - back];
        std::vector<double> out_c(c.size(), 0.0);
        for (std::size_t k : rows) out_c[k] = c[k - back] - sum[group_of[k]] / cnt[group_of[k]];
        return out_c;
      };
      const std::vector<double> vc_d = less_group_means(vc_c, lag), v_d = less_group_means(d.vel, lag),
                                sum_d = less_group_means(sum_c, lag), T_d = less_group_means(d.T, 0);
      return least_squares({&vc_d, &v_d, &sum_d}, T_d, rows);
    };
    const auto gains_ok = [](const LsqResult& ls) { return ls.ok && ls.theta[0] > 0.0 && ls.theta[2] > 0.0; };
    const LsqResult law = fit_law(0);
    if (!gains_ok(law)) continue;
    const double Kvp = law.theta[0], Ki = law.theta[2];
    // Behind a dead time, the law at the rows about the one the loop's
    // ticks show, the smallest residual's.
    std::size_t lag = 0;
    LsqResult law_lag = law;
    if (lag0 > 0) {
      law_lag = LsqResult{};
      for (std::size_t L = lag0 - 1; L <= lag0 + 1; ++L) {
        if (L == 0) continue;
        LsqResult ls = fit_law(L);
        if (gains_ok(ls) && (!law_lag.ok || ls.residual_rms < law_lag.residual_rms)) {
          law_lag = std::move(ls);
          lag = L;
        }
      }
      if (!law_lag.ok) continue;
    }
    const DriveColumns dc = drive_columns(d);
    const LsqResult drive = least_squares(dc.X, d.T, d.rows);
    if (!drive.ok || !(dc.pos || dc.neg)) continue;
    AxisFromData refit = ax;
    take_drive_fit(drive, dc.pos, dc.neg, refit);
    const std::vector<std::string> clamped = clamp_drive(d, f.Ts, refit);
    if (!clamped.empty()) continue;
    refit.one_level = dc.pos && dc.neg ? fit_one_level(d, f.Ts, refit) : AxisFromData::OneLevel{};
    refit.gains.Kvp_torque_s_per_rad = Kvp;
    refit.gains.Tn_s = Kvp / Ki;
    refit.gains_at_lag = refit.gains;
    const std::size_t per_period = f.r0.log_rows_per_loop_period;
    if (lag > 0) {
      refit.gains_at_lag.Kvp_torque_s_per_rad = law_lag.theta[0];
      refit.gains_at_lag.Tn_s = law_lag.theta[0] / law_lag.theta[2];
      refit.torque_lag_samples = lag / per_period;
      refit.torque_lag_fraction = static_cast<double>(lag % per_period) / static_cast<double>(per_period);
    }
    refit.fit_rows = d.rows.size();
    set_identified_axis(trial.axes[i], refit);
    const std::string left_out =
        law_rows.size() < d.rows.size()
            ? fmt::format(", {} rows at the torque's limit ({:.4g} of the channel's unit) and about them left out of "
                          "the law",
                          d.rows.size() - law_rows.size(), at_limit)
            : std::string();
    const double dt_log = f.runs.front().run->log_rows->sample_period_s;
    refit.torque_timing = fmt::format("the drive fitted on the log's own rows (every {:g} s), the speed the "
                                      "position's difference there",
                                      dt_log);
    const std::string at_lag =
        lag > 0 ? fmt::format(" {:.3g} ms behind its torque (the loop's ticks showed {:.3g} ms)", 1e3 * lag * dt_log,
                              1e3 * lag0 * dt_log)
                : std::string();
    const controller::CascadeGains& was = lag > 0 ? ax.gains_at_lag : ax.gains;
    said.push_back(fmt::format("axis {}: on the log's own rows ({} of them, every {:g} s{}) the velocity law{} has "
                               "Kvp {:.4g} and Tn {:.4g} s (residual {:.3g}), the drive J {:.4g} and B {:.4g}, "
                               "against Kvp {:.4g}, Tn {:.4g} s and J {:.4g} on the loop's ticks",
                               axis_name(a), d.rows.size(), dt_log, left_out, at_lag,
                               refit.gains_at_lag.Kvp_torque_s_per_rad, refit.gains_at_lag.Tn_s, law_lag.residual_rms,
                               refit.J, refit.B, was.Kvp_torque_s_per_rad, was.Tn_s, ax.J));
    changed.emplace_back(ai, std::move(refit));
  }
  if (changed.empty()) return;
  // Behind a dead time the two are compared with it in the loop, each on
  // its law at its lag (as the delay is tried later).
  sim::MachineDefinition base_m = m, trial_m = trial;
  const double dt = f.r0.sample_period_s;
  const auto with_dead_time = [&](sim::MachineDefinition& mm, const AxisFromData& x) {
    if (x.torque_lag_rows() == 0.0) return;
    Trial t;
    t.kind = EffectKind::kDelay;
    t.sets = {{{EffectParam::delay_delay_s, x.torque_lag_rows() * dt}}};
    t.gains = x.gains_at_lag;
    mm = with_trial(mm, x.axis, t, 0);
  };
  for (const auto& [ai, refit] : changed) {
    with_dead_time(base_m, out.axis[ai]);
    with_dead_time(trial_m, refit);
  }
  const FitRunErrors base = errors_on_fit_runs(f.runs, base_m, out.axes, out.rounding, out.replays);
  const FitRunErrors with = errors_on_fit_runs(f.runs, trial_m, out.axes, out.rounding, out.replays);
  for (std::size_t c = 0; c < changed.size(); ++c) {
    auto& [ai, refit] = changed[c];
    const std::vector<std::string> keys = axis_keys(refit);
    const double before = base.ok ? keys_sum(base.held, keys) : 1e300, after = with.ok ? keys_sum(with.held, keys) : 1e300;
    const bool keep = with.ok && after < before;
    out.notes.push_back(fmt::format("{}: {}, the fitting runs' held-out rows replayed to {:.4g} (the axis's channels' "
                                    "NRMS summed) against {:.4g}",
                                    said[c], keep ? "kept" : "not kept", after, before));
    if (!keep) continue;
    set_identified_axis(m.axes[index(refit.axis)], refit);
    out.axis[ai] = std::move(refit);
  }
}

/// The cascade machine found in the fitting runs, no effects.
sim::MachineDefinition identify_machine(const AxisFit& f, DataCalibration& out) {
  sim::MachineDefinition m;
  m.name = "identified";
  m.source = "twin calibrate (from data)";
  m.Ts_s = f.Ts;
  m.encoder_resolution_mm = choose_encoder(f, out);
  sim::set_machine_loop_law(m, controller::LoopLaw::kCascade);
  for (Axis a : out.axes) out.axis.push_back(identify_axis_from_data(f, a, m, out));
  sim::set_machine_loop_law(m, controller::LoopLaw::kCascade);
  for (Axis a : kAllAxes)
    if (!m.axes[index(a)].present) m.axes[index(a)] = sim::AxisDefinition{};
  refit_on_log_rows(f, out, m);
  if (m.present_axes().empty())
    throw ConfigError(fmt::format("{}: no axis could be identified: {}", f.r0.dir.string(),
                                  out.axis.empty() ? std::string("no axis") : out.axis.front().note));
  sim::set_machine_loop_law(m, controller::LoopLaw::kCascade);
  m.validate();
  return m;
}

/// What a log of this rate and resolution cannot show.
void skip_unseen_effects(const std::vector<MeasuredRun>& fit, DataCalibration& out) {
  const double dt = fit.front().sample_period_s;
  const double q = out.rounding.quantum_mm;
  auto skip = [&](EffectKind k, std::string why) {
    out.skipped.emplace_back(feeddrive::effect_name(k), std::move(why));
  };
  if (!resolves_velocity_loop(dt)) {
    skip(EffectKind::kDelay, fmt::format("a delay of a few loop periods is far below the {:g} s sample "
                                         "period: it cannot be told from the loop's lag",
                                         dt));
    skip(EffectKind::kCompliance, fmt::format("a resonance above the Nyquist frequency {:.3g} Hz of the log "
                                              "cannot be seen",
                                              0.5 / dt));
    skip(EffectKind::kCogging, fmt::format("a ripple periodic in motor angle needs several samples per "
                                           "period; at {:g} s per sample it aliases",
                                           dt));
    skip(EffectKind::kLoadDependentFriction,
         fmt::format("the torque of an acceleration lasts a few samples of {:g} s, and the drive's load at a row "
                     "is not resolved to the share of it friction takes",
                     dt));
  }
  else
    skip(EffectKind::kCompliance, "not searched on a machine identified from data: its drive is one inertia "
                                  "in the log's unit, and a two-mass resonance needs the split of that "
                                  "inertia and a stiffness the replay of a cascade loop does not resolve");
  if (resolves_velocity_loop(dt) && q <= 0.005) {
    // Told from the logged motor speed against the position's, or without
    // it from the velocity loop's law (screw_pitch_error_from_law).
    bool seen = true;
    for (const AxisFromData& ax : out.axis) {
      bool speed = true;
      for (const MeasuredRun& r : fit) speed = speed && r.trace.find(col(ax.axis, "_v_mm_s")) != nullptr;
      seen = seen && (speed || ax.velocity_loop_from_data);
    }
    if (!seen)
      skip(EffectKind::kScrewPitchError, "a lead error moves the encoder and not the motor: it is told "
                                         "from the logged motor speed against the speed of the logged "
                                         "position, or from the velocity loop's law fitted on the logged "
                                         "torque, and this log gives neither");
  }
  if (q > 0.005) {
    skip(EffectKind::kScrewPitchError, fmt::format("a lead error of microns is below the log's position "
                                                   "quantum {:g} mm",
                                                   q));
    skip(EffectKind::kBacklash, fmt::format("lost motion at reversals below the log's position quantum "
                                            "{:g} mm is not seen in the position",
                                            q));
  }
}

/// Replays `machine` on `rd` and puts its errors on rows [from, to) in `dst`
/// (the replay kept in `keep`, the pools added to `pooled`, where given).
void errors_on(DataCalibration& out, const sim::MachineDefinition& machine, const RunData& rd, std::size_t from,
               std::size_t to, bool same_unit, ReplayResult* keep, ChannelErrors& dst, PoolSet* pooled,
               std::vector<char>* compared = nullptr) {
  PoolSet pools;
  std::vector<char> cmp;
  try {
    // Where neither the replay nor the rows compared are kept, only the
    // segments that reach into [from, to) are replayed.
    const Segment rows = keep == nullptr && compared == nullptr ? Segment{from, to} : Segment{0, SIZE_MAX};
    ReplayResult rr = replay_segments(*rd.smooth, machine, rd.segments, out.rounding, &cmp, rows);
    ++out.replays;
    for (std::size_t k = 0; k < cmp.size(); ++k) cmp[k] = static_cast<char>(cmp[k] && rd.interior[k]);
    std::map<std::string, std::string> nc;
    add_errors(pools, *rd.run, rr, cmp, out.axes, from, to, same_unit,
               sim::machine_loop_law(machine) == controller::LoopLaw::kCascade, &nc);
    dst = errors_from(pools);
    for (auto& [k, why] : nc) dst.not_computed[k] = why;
    if (keep) *keep = std::move(rr);
    if (compared) *compared = std::move(cmp);
    if (pooled)
      for (const auto& [k, p] : pools) (*pooled)[k].add(p);
  } catch (const Error& e) {
    for (Axis a : out.axes) {
      dst.not_computed[col(a, "_err_mm")] = fmt::format("the replay failed: {}", e.what());
      const TorqueChannel ch = torque_channel(*rd.run, a);
      if (ch.present()) dst.not_computed[ch.column] = fmt::format("the replay failed: {}", e.what());
    }
  }
}

/// The errors of `machine` pooled over the fitting runs: on their fitting
/// rows, or on their held-out rows.
ChannelErrors pooled_on_fit_runs(DataCalibration& out, const std::vector<RunData>& runs,
                                 const sim::MachineDefinition& machine, bool held_out) {
  PoolSet pools;
  for (const RunData& rd : runs) {
    ChannelErrors ignored;
    errors_on(out, machine, rd, held_out ? rd.n_fit : 0, held_out ? rd.n : rd.n_fit, true, nullptr, ignored, &pools);
  }
  return errors_from(pools);
}

/// The NRMS of channel `k` in `e`, 1e300 where there is no figure (a replay
/// that failed, or a channel it does not give).
double nrms_or_none(const ChannelErrors& e, const std::string& k) {
  const auto it = e.nrms.find(k);
  return it == e.nrms.end() ? 1e300 : it->second;
}
double nrms_or_none(const std::optional<ChannelErrors>& e, const std::string& k) {
  return e ? nrms_or_none(*e, k) : 1e300;
}

/// One of the 16 velocity loops with its fitting rows' errors.
struct LoopChoice {
  /// The fitting rows' torque NRMS with it (1e300 where none).
  double score{1e300};
  double Kvp{0.0}, Tn{0.0};
  /// The fitting rows' tracking NRMS with it (1e300 where none).
  double track{1e300};
  /// Chosen on the torque and the tracking error together (best_velocity_loops).
  bool on_tracking_too{false};
};

/// The best of 16 velocity loops per axis where `on`: bandwidths 0.25 to 2
/// times the default's, integral times 0 (none) to 16 over the bandwidth,
/// each replayed on `base` and scored on the fitting rows: on the torque,
/// or on the torque and the tracking error together where the replay
/// rebuilds the reference through the speed the logged command shows.
AxisArray<LoopChoice> best_velocity_loops(DataCalibration& out, const std::vector<RunData>& runs,
                                          const sim::MachineDefinition& base, const AxisArray<bool>& on) {
  AxisArray<LoopChoice> best{};
  if (std::none_of(on.begin(), on.end(), [](bool b) { return b; })) return best;
  // Where the replay rebuilds the reference through the speed the logged
  // velocity command shows (law_reference_speed), the tracking error at the
  // rows is the loop's own, and the loops are chosen on it beside the
  // torque: each NRMS over the least of the 16's, summed. On a 50 ms log the
  // torque at a row is mostly a change of speed the row does not resolve
  // (NRMS 0.55 for every loop), and on it alone a loop of Kvp 0.74 and Tn 9
  // times the truth's was taken, which tracked the other program at 0.14.
  AxisArray<bool> weigh_tracking{};
  for (const AxisFromData& ax : out.axis)
    weigh_tracking[index(ax.axis)] = on[index(ax.axis)] && !runs.empty() &&
                                     shows_reference_speed(*runs.front().smooth, ax.axis, base.axes[index(ax.axis)]);
  AxisArray<std::vector<LoopChoice>> all{};
  for (double fw : {0.25, 0.5, 1.0, 2.0}) {
    for (double ft : {0.0, 2.0, 4.0, 16.0}) {
      sim::MachineDefinition trial = base;
      for (const AxisFromData& ax : out.axis) {
        if (!on[index(ax.axis)]) continue;
        auto& g = trial.axes[index(ax.axis)].loop.cascade;
        const double wv = fw * ax.default_velocity_loop.Kvp_torque_s_per_rad / ax.J;
        g.Kvp_torque_s_per_rad = ax.J * wv;
        g.Tn_s = ft > 0.0 ? ft / wv : 0.0;
      }
      const ChannelErrors e = pooled_on_fit_runs(out, runs, trial, false);
      for (const AxisFromData& ax : out.axis) {
        if (!on[index(ax.axis)]) continue;
        const auto it = e.nrms.find(ax.channel.column);
        if (it == e.nrms.end() || !(it->second < 1e300)) continue;
        const auto& g = trial.axes[index(ax.axis)].loop.cascade;
        all[index(ax.axis)].push_back(
            {it->second, g.Kvp_torque_s_per_rad, g.Tn_s, nrms_or_none(e, col(ax.axis, "_err_mm"))});
      }
    }
  }
  for (const AxisFromData& ax : out.axis) {
    const auto& c = all[index(ax.axis)];
    if (c.empty()) continue;
    double least_torque = 1e300, least_track = 1e300;
    for (const LoopChoice& l : c) {
      least_torque = std::min(least_torque, l.score);
      least_track = std::min(least_track, l.track);
    }
    const bool both = weigh_tracking[index(ax.axis)] && least_track > 0.0 && least_track < 1e300;
    const auto rank = [&](const LoopChoice& l) {
      return both ? l.score / least_torque + l.track / least_track : l.score;
    };
    best[index(ax.axis)] = *std::min_element(
        c.begin(), c.end(), [&](const LoopChoice& a, const LoopChoice& b) { return rank(a) < rank(b); });
    best[index(ax.axis)].on_tracking_too = both;
  }
  return best;
}

/// The law's gains polished on the replay, where they were read from a log
/// slower than 5 ms. There the law is fitted on rows 10 or 20 loop periods
/// apart, and without the motor's speed on a speed differentiated from the
/// position, whose gain falls towards the log's Nyquist rate where the
/// velocity loop rings: the integral's gain Ki = Kvp / Tn comes out right
/// and Kvp high (18.6 for 12.6 at 20 ms). Per axis, a pattern search on
/// Kvp at constant Ki, then Ki at constant Kvp, steps of a quarter halved
/// to 1 %, on the fitting rows' torque and tracking NRMS, each over its
/// value with the law (the two outputs weighed alike: on the torque alone
/// the search trades the tracking for a drive the effects have not yet
/// completed). Kept where that sum (2 before) falls by at least
/// kPolishGain and both outputs fall: gains that trade one for the other stand in for an effect
/// the drive does not have yet (a 10 ms log of a torque limit the law had
/// found took Kvp 6 % and Tn 18 % off the truth's for 6 % less tracking
/// error and 2 % more torque error, and the other program then tracked at
/// 0.010 for 0.0035). A limit the law shows is in the replays, as in
/// choose_torque_command. Returns what it says per axis.
AxisArray<std::string> polish_velocity_loops(DataCalibration& out, const std::vector<RunData>& runs,
                                             const AxisArray<bool>& on, sim::MachineDefinition& machine) {
  // Replayed with the limit the law shows (its level from the log), so that
  // the gains do not stand in for it: on the loop's command where the law
  // holds its integral there, else on the motor's current.
  sim::MachineDefinition base = machine;
  for (const AxisFromData& ax : out.axis) {
    if (!on[index(ax.axis)] || base.axes[index(ax.axis)].drive.effects.current_saturation.enabled) continue;
    if (ax.law_holds_integral_at_limit()) {
      base.axes[index(ax.axis)].loop.cascade.T_max = ax.law_limit_level;
    } else if (ax.law_clip_level > 0.0) {
      // A limit behind the loop (the law's fit left its rows out): the
      // motor's current clamped there.
      Trial limit;
      limit.kind = EffectKind::kCurrentSaturation;
      limit.sets = {{{EffectParam::current_saturation_i_max_A, ax.law_clip_level}}};
      base = with_trial(base, ax.axis, limit, 0);
    }
  }
  const ChannelErrors start = pooled_on_fit_runs(out, runs, base, false);
  constexpr double kFirstStep = 0.25, kLastStep = 0.01, kPolishGain = 0.02;
  constexpr int kMaxReplays = 64;
  struct State {
    double Kvp{0.0}, Ki{0.0}, score{1e300}, torque{1e300}, track{1e300};
    std::array<double, 2> step{kFirstStep, kFirstStep};
  };
  AxisArray<State> st{}, first{};
  AxisArray<std::string> said{};
  auto score_of = [&](const State& s0, double torque, double track) {
    return torque < 1e300 && track < 1e300 ? torque / s0.torque + track / s0.track : 1e300;
  };
  bool any = false;
  for (const AxisFromData& ax : out.axis) {
    if (!on[index(ax.axis)]) continue;
    State& s = st[index(ax.axis)];
    const controller::CascadeGains& g = machine.axes[index(ax.axis)].loop.cascade;
    s.Kvp = g.Kvp_torque_s_per_rad;
    s.Ki = g.Tn_s > 0.0 ? s.Kvp / g.Tn_s : 0.0;
    s.torque = nrms_or_none(start, ax.channel.column);
    s.track = nrms_or_none(start, col(ax.axis, "_err_mm"));
    if (!(s.torque > 0.0 && s.torque < 1e300 && s.track > 0.0 && s.track < 1e300)) continue;
    s.score = 2.0;
    if (s.Ki == 0.0) s.step[1] = 0.0;
    first[index(ax.axis)] = s;
    any = true;
  }
  if (!any) return said;
  auto gains_of = [](const State& s, controller::CascadeGains g) {
    g.Kvp_torque_s_per_rad = s.Kvp;
    g.Tn_s = s.Ki > 0.0 ? s.Kvp / s.Ki : 0.0;
    return g;
  };
  int replays = 0;
  for (bool moved = true; moved && replays < kMaxReplays;) {
    moved = false;
    for (std::size_t p = 0; p < 2; ++p) {
      AxisArray<bool> up{};
      for (double dir : {1.0, -1.0}) {
        sim::MachineDefinition trial = base;
        AxisArray<std::optional<State>> tried{};
        for (const AxisFromData& ax : out.axis) {
          const State& s = st[index(ax.axis)];
          if (!(s.score < 1e300) || s.step[p] < kLastStep || up[index(ax.axis)]) continue;
          State t = s;
          (p == 0 ? t.Kvp : t.Ki) *= std::pow(1.0 + s.step[p], dir);
          sim::AxisDefinition& def = trial.axes[index(ax.axis)];
          def.loop.cascade = gains_of(t, def.loop.cascade);
          tried[index(ax.axis)] = t;
        }
        if (std::none_of(tried.begin(), tried.end(), [](const auto& t) { return t.has_value(); })) continue;
        const ChannelErrors e = pooled_on_fit_runs(out, runs, trial, false);
        ++replays;
        for (const AxisFromData& ax : out.axis) {
          if (!tried[index(ax.axis)]) continue;
          State t = *tried[index(ax.axis)];
          t.torque = nrms_or_none(e, ax.channel.column);
          t.track = nrms_or_none(e, col(ax.axis, "_err_mm"));
          t.score = score_of(first[index(ax.axis)], t.torque, t.track);
          if (!(t.score < st[index(ax.axis)].score)) continue;
          st[index(ax.axis)] = t;
          up[index(ax.axis)] = true;
          moved = true;
        }
      }
    }
    // Once nothing moves, every step halves, down to kLastStep.
    if (!moved)
      for (State& s : st)
        for (double& h : s.step)
          if (h >= kLastStep) {
            h *= 0.5;
            moved = moved || h >= kLastStep;
          }
  }
  for (AxisFromData& ax : out.axis) {
    const State &s = st[index(ax.axis)], &s0 = first[index(ax.axis)];
    if (!(s.score < 2.0 - kPolishGain)) continue;
    const controller::CascadeGains g = gains_of(s, machine.axes[index(ax.axis)].loop.cascade);
    const std::string figures =
        fmt::format("Kvp {:.4g}, Tn {:.4g} s replay the fitting rows' {} to {:.4g} and their tracking error to "
                    "{:.4g}, against {:.4g} and {:.4g} with Kvp {:.4g}, Tn {:.4g} s ({} replays)",
                    g.Kvp_torque_s_per_rad, g.Tn_s, ax.channel.column, s.torque, s.track, s0.torque, s0.track,
                    s0.Kvp, s0.Ki > 0.0 ? s0.Kvp / s0.Ki : 0.0, replays);
    if (!(s.torque < s0.torque && s.track < s0.track)) {
      said[index(ax.axis)] = fmt::format("polished on the replay, not kept: {}, one of them higher", figures);
      continue;
    }
    said[index(ax.axis)] = fmt::format("polished on the replay: {}", figures);
    machine.axes[index(ax.axis)].loop.cascade = g;
    for (controller::CascadeGains* h : {&ax.gains, &ax.gains_at_lag}) {
      h->Kvp_torque_s_per_rad = g.Kvp_torque_s_per_rad;
      h->Tn_s = g.Tn_s;
    }
  }
  return said;
}

/// Whether the law of `ax` is polished on the replay: read from a log
/// slower than 5 ms, kept against the 16, and with no lag, dead time or
/// logged command of its own (their gains are fitted with those).
bool polishes_law(const AxisFromData& ax, double dt_s) {
  return !resolves_velocity_loop(dt_s) && ax.identified && ax.velocity_loop_from_data &&
         ax.torque_lag_rows() == 0.0 && ax.gains.tau_i_s == 0.0 && !ax.torque_command_logged && !ax.lag_in_monitor;
}

/// The law polished again on the machine the effects have completed (the
/// first polish fits the gains to a drive without them, which they can
/// stand in for: a 10 ms log of a torque limit took Kvp 3 % under the
/// truth's and the other program tracked at 0.011 for 0.0066).
void polish_final_velocity_loops(DataCalibration& out, const std::vector<RunData>& runs) {
  if (runs.empty()) return;
  const double dt = runs.front().run->sample_period_s;
  AxisArray<bool> on{};
  for (const AxisFromData& ax : out.axis)
    on[index(ax.axis)] = polishes_law(ax, dt) && out.final_machine.axes[index(ax.axis)].loop.cascade.tau_i_s == 0.0;
  if (std::none_of(on.begin(), on.end(), [](bool b) { return b; })) return;
  const AxisArray<std::string> said = polish_velocity_loops(out, runs, on, out.final_machine);
  for (AxisFromData& ax : out.axis)
    if (!said[index(ax.axis)].empty()) ax.loop_source += "; with the effects kept, " + said[index(ax.axis)];
}

/// The velocity loop where the log cannot show it: its bandwidth and
/// integral time still shape what the current does where the axis stops
/// (the torque the integral holds against friction), which the fitting rows
/// show. A small grid around the default, chosen per axis on the fitting
/// rows of the fitting runs; the held-out rows judge it like everything else.
void choose_velocity_loops(DataCalibration& out, const std::vector<RunData>& runs) {
  // On a log slower than 5 ms the law read from it stands against the 16
  // (a logger that averages its torque over the sample period makes the
  // law's integral time a third of the loop's, and that loop's replay runs
  // away): its fitting rows' error against theirs, around the default.
  const bool contest_law = !resolves_velocity_loop(runs.front().run->sample_period_s);
  AxisArray<bool> on{}, contest{};
  sim::MachineDefinition base = out.identified;
  for (AxisFromData& ax : out.axis) {
    contest[index(ax.axis)] = contest_law && ax.identified && ax.velocity_loop_from_data;
    ax.default_velocity_loop = contest[index(ax.axis)] ? ax.blind_velocity_loop : ax.gains;
    on[index(ax.axis)] = ax.identified && (!ax.velocity_loop_from_data || contest[index(ax.axis)]);
    if (contest[index(ax.axis)]) base.axes[index(ax.axis)].loop.cascade = ax.blind_velocity_loop;
  }
  ChannelErrors with_law;
  AxisArray<std::string> polished{};
  if (std::any_of(contest.begin(), contest.end(), [](bool b) { return b; })) {
    // The law polished on the replay before it stands against the 16.
    AxisArray<bool> polish{};
    for (const AxisFromData& ax : out.axis)
      polish[index(ax.axis)] = contest[index(ax.axis)] && polishes_law(ax, runs.front().run->sample_period_s);
    for (AxisFromData& ax : out.axis)
      if (polish[index(ax.axis)]) ax.law_before_polish = ax.gains;
    if (std::any_of(polish.begin(), polish.end(), [](bool b) { return b; }))
      polished = polish_velocity_loops(out, runs, polish, out.identified);
    with_law = pooled_on_fit_runs(out, runs, out.identified, false);
  }
  const AxisArray<LoopChoice> best = best_velocity_loops(out, runs, base, on);
  for (AxisFromData& ax : out.axis) {
    const LoopChoice& c = best[index(ax.axis)];
    if (!contest[index(ax.axis)]) continue;
    if (!polished[index(ax.axis)].empty()) ax.loop_source += "; " + polished[index(ax.axis)];
    const double law = nrms_or_none(with_law, ax.channel.column);
    const std::string law_text = law < 1e300 ? fmt::format("{:.4g}", law) : std::string("no figure (its replay fails)");
    // The 16 stand against the law on the torque; where the law's replay
    // tracks the fitting rows better, the torque's lower error is not taken
    // as the loop's (a P loop without the integral tracked a Stribeck rise
    // at 0.12).
    const double law_track = nrms_or_none(with_law, col(ax.axis, "_err_mm"));
    const bool tracks = law < 1e300 && law_track < 1e300 && c.track > law_track * (1.0 + kRiseAllowed);
    if (!(c.score < law) || tracks) {
      const std::string why_law =
          tracks && c.score < law
              ? fmt::format(", and their tracking error to {:.4g} against the best's {:.4g}", law_track, c.track)
              : std::string();
      ax.loop_source += fmt::format("; it replays the fitting rows' {} to {} against {:.4g} for the best of 16 "
                                    "velocity loops chosen without it{}",
                                    ax.channel.column, law_text, c.score, why_law);
      continue;
    }
    // The 16's: the loop as where the log does not show it.
    ax.velocity_loop_from_data = false;
    ax.gains = ax.blind_velocity_loop;
    ax.gains_at_lag = ax.gains;
    ax.torque_lag_samples = 0;
    ax.torque_lag_fraction = 0.0;
    ax.torque_feedforward = false;
    ax.law_lead_period_mm = 0.0;
    ax.law_gap_mm = 0.0;
    ax.law_limit_rows.clear();
    ax.law_limit_level = 0.0;
    ax.law_clip_level = 0.0;
    ax.loop_source += fmt::format("; not kept: it replays the fitting rows' {} to {}, the best of 16 velocity "
                                  "loops chosen without it to {:.4g}",
                                  ax.channel.column, law_text, c.score);
    set_identified_axis(out.identified.axes[index(ax.axis)], ax);
  }
  for (AxisFromData& ax : out.axis) {
    const LoopChoice& c = best[index(ax.axis)];
    if (!on[index(ax.axis)] || ax.velocity_loop_from_data || c.score >= 1e300) continue;
    ax.gains.Kvp_torque_s_per_rad = c.Kvp;
    ax.gains.Tn_s = c.Tn;
    out.identified.axes[index(ax.axis)].loop.cascade = ax.gains;
    ax.loop_source += fmt::format("; chosen on the fitting rows among 16 velocity loops: Kvp {:.4g}, Tn {:.4g} s "
                                  "(fitting-row NRMS {:.4g}{})",
                                  c.Kvp, c.Tn, c.score,
                                  c.on_tracking_too ? fmt::format(", tracking {:.4g}: chosen on both, the reference "
                                                                  "rebuilt through the speed the logged command shows",
                                                                  c.track)
                                                    : std::string());
  }
  out.final_machine = out.identified;
}

/// The first velocity loop of `ax` on a drive of inertia J: the same
/// bandwidth (Kvp in proportion to J) where the loop is not fitted from the log.
controller::CascadeGains first_loop_at(const AxisFromData& ax, double J) {
  controller::CascadeGains g = ax.gains;
  if (!ax.velocity_loop_from_data && ax.J > 0.0) g.Kvp_torque_s_per_rad *= J / ax.J;
  return g;
}

/// Whether the tracking error of axis `a` in `after` is at most kRiseAllowed
/// above the one in `before` (true where either has none).
bool tracking_holds(const ChannelErrors& before, const ChannelErrors& after, Axis a) {
  const auto t0 = before.nrms.find(col(a, "_err_mm"));
  const auto t1 = after.nrms.find(col(a, "_err_mm"));
  return t0 == before.nrms.end() || t1 == after.nrms.end() || t1->second <= t0->second * (1.0 + kRiseAllowed);
}

/// The held-out rows' errors of the fitting runs replayed on `machine`, each
/// axis's torque channel low-passed without phase at kSpeedCutoff_Hz, log and
/// replay alike, and its tracking error as it is; nullopt where a replay
/// fails. A loop hunting at standstill or at low speed makes the torque a
/// loop commands chatter at a phase no replay reproduces; the low-pass keeps
/// what the drive and the loop's response put into it.
std::optional<ChannelErrors> held_out_lowpassed(DataCalibration& out, const std::vector<RunData>& runs,
                                                const sim::MachineDefinition& machine) {
  PoolSet pools;
  try {
    for (const RunData& rd : runs) {
      std::vector<char> cmp;
      const ReplayResult rr =
          replay_segments(*rd.smooth, machine, rd.segments, out.rounding, &cmp, Segment{rd.n_fit, rd.n});
      const double dt = rd.run->sample_period_s;
      for (Axis a : out.axes) {
        const std::size_t i = index(a);
        if (rr.x_mm[i].empty()) continue;
        const auto& ref = rd.run->trace.at(col(a, "_ref_mm"));
        const auto* x = rd.run->trace.find(col(a, "_mm"));
        const TorqueChannel ch = torque_channel(*rd.run, a);
        const auto* m = ch.present() ? model_channel(rr, a, ch, true) : nullptr;
        std::vector<double> lp_log, lp_model;
        if (m != nullptr) {
          lp_log = lowpass_in_segments(rd.run->trace.at(ch.column), rd.segments, dt);
          lp_model = lowpass_in_segments(*m, rd.segments, dt);
        }
        for (std::size_t k = rd.n_fit; k < rd.n; ++k) {
          if (!(cmp[k] && rd.interior[k])) continue;
          if (x != nullptr) pools[col(a, "_err_mm")].add(ref[k] - (*x)[k], ref[k] - rr.x_mm[i][k]);
          if (m != nullptr) pools[ch.column].add(lp_log[k], lp_model[k]);
        }
      }
    }
  } catch (const Error&) {
    return std::nullopt;
  }
  return errors_from(pools);
}

/// A logged torque command (AxisFromData::motion_behind_torque): the drive
/// fitted with its motion behind the logged torque by the candidate's lag
/// and dead time, the current loop given that lag, the dead time as a
/// delay, and the twin giving the channel as the command. Taken where the
/// drive's residual decides it (motion_behind_torque), else where it
/// replays the held-out rows of the fitting runs better than the machine as
/// identified (held_out_lowpassed: the torque by more than kKeepMargin),
/// and either way where the tracking error rises by no more than
/// kRiseAllowed. Between those: an effect the drive does not model leaves
/// a residual a small lag lowers by a few per cent on a log of the motor's
/// own torque (0.94 to 1 of the residual at the torque's rows on the
/// cascade sweep's runs), which the replay refuses; a large one (cogging,
/// friction along the travel) hides a current loop's true 1 ms in the
/// residual as well (0.83 to 0.96), which the replay takes. And a Stribeck
/// rise the drive does not have yet makes the replay with the true lag of 1
/// ms worse (the torque 0.315 against 0.276, low-passed, with the drive
/// fitted the same to 1 %), where the residual falls to 0.66. Where it is
/// taken, the dead time is left to the catalogue search to propose as the
/// delay (torque_lag_samples).
void choose_torque_command(DataCalibration& out, const std::vector<RunData>& runs, const AxisFit& f) {
  // Both readings are replayed with the limit a law that holds its integral
  // shows (its level from the log), so that what the limit does is not
  // taken for what the current loop does.
  sim::MachineDefinition limited = out.identified;
  for (const AxisFromData& ax : out.axis)
    if (ax.law_holds_integral_at_limit()) limited.axes[index(ax.axis)].loop.cascade.T_max = ax.law_limit_level;
  sim::MachineDefinition trial = limited;
  AxisArray<std::optional<AxisFromData>> with{};
  AxisArray<std::string> limit_note{};
  const double dt = f.r0.sample_period_s;
  for (const AxisFromData& ax : out.axis) {
    const AxisFromData::MotionBehindTorque& m = ax.motion_behind_torque;
    if (!ax.identified || !m.shown) continue;
    AxisFromData c = ax;
    std::string why_not;
    const double a_lag = m.tau_s > 0.0 ? std::exp(-dt / m.tau_s) : 0.0;
    if (!fit_drive(f, c, {.forward = true, .ahead = m.rows, .a_lag = a_lag}, why_not)) continue;
    c.gains.tau_i_s = m.tau_s;
    c.gains_at_lag = c.gains;
    c.torque_lag_samples = m.rows;
    c.torque_lag_fraction = 0.0;
    c.torque_command_logged = true;
    sim::AxisDefinition& def = trial.axes[index(ax.axis)];
    set_identified_axis(def, c);
    if (c.law_holds_integral_at_limit()) def.loop.cascade.T_max = c.law_limit_level;
    if (m.rows > 0) {
      def.drive.effects.delay.enabled = true;
      def.drive.effects.delay.delay_s = static_cast<double>(m.rows) * dt;
    }
    // Read as the command, the log may run past a limit on the motor's
    // current that the motion shows (limit_in_motion): the command reading
    // is replayed with that limit and the drive fitted under it, so that
    // the limit is not held against the reading. The machine keeps the
    // drive fitted as before; the catalogue search proposes the limit.
    const AxisRows rows = axis_rows(runs, c);
    const double corr = residual_correlation_rows(rows, rows.drive_columns(), 0.0, dt);
    if (const auto lim = limit_in_motion(rows, corr); lim && lim->clipped.theta[0] > 0.0) {
      const std::vector<double>& th = lim->clipped.theta;
      set_drive(def.drive, DriveRefit{th[0], std::max(th[1], 0.0), std::max(th[2], 0.0), std::max(th[3], 0.0), th[4]});
      def.drive.effects.current_saturation.enabled = true;
      def.drive.effects.current_saturation.i_max_A = lim->level;
      limit_note[index(ax.axis)] =
          fmt::format(", with the limit of {:.4g} on the motor's current its motion shows behind it", lim->level);
    }
    with[index(ax.axis)] = std::move(c);
  }
  if (std::none_of(with.begin(), with.end(), [](const auto& c) { return c.has_value(); })) return;
  const std::optional<ChannelErrors> motor_e = held_out_lowpassed(out, runs, limited);
  const std::optional<ChannelErrors> command_e = held_out_lowpassed(out, runs, trial);
  if (!motor_e || !command_e) return;
  const ChannelErrors &motor = *motor_e, &command = *command_e;
  for (AxisFromData& ax : out.axis) {
    if (!with[index(ax.axis)]) continue;
    const AxisFromData::MotionBehindTorque& m = ax.motion_behind_torque;
    const auto e0 = motor.nrms.find(ax.channel.column);
    const auto e1 = command.nrms.find(ax.channel.column);
    if (e0 == motor.nrms.end() || e1 == command.nrms.end()) continue;
    const bool tracking_ok = tracking_holds(motor, command, ax.axis);
    const std::string behind =
        fmt::format("{}{}", m.tau_s > 0.0 ? fmt::format("a first-order lag of {:.3g} ms", 1e3 * m.tau_s) : "",
                    m.rows > 0 ? fmt::format("{}{} sample{} of dead time", m.tau_s > 0.0 ? " and " : "", m.rows,
                                             m.rows == 1 ? "" : "s")
                               : "");
    if (!(tracking_ok && (m.decisive || e1->second < (1.0 - kKeepMargin) * e0->second))) {
      ax.torque_command_choice = fmt::format(
          "the logged torque is taken as the motor's: the drive fits the motion behind it by {} best (residual "
          "{:.3g} against {:.3g} at its own rows), but as the loop's command before a current loop so{}, the held-out "
          "rows replay {} low-passed to {:.4g} against {:.4g}{}",
          behind, m.residual, m.plain, limit_note[index(ax.axis)], ax.channel.column, e1->second, e0->second,
          tracking_ok ? "" : ", and the tracking error rises");
      ax.loop_source += "; " + ax.torque_command_choice;
      continue;
    }
    const std::string before_note = ax.note;
    ax = std::move(*with[index(ax.axis)]);
    if (ax.note != before_note) {
      if (const auto it = std::find(out.notes.begin(), out.notes.end(), before_note);
          !before_note.empty() && it != out.notes.end())
        out.notes.erase(it);
      if (!ax.note.empty()) out.notes.push_back(ax.note);
    }
    ax.torque_command_choice = fmt::format(
        "the logged torque is the loop's command, ahead of the motion: the drive fits the motion behind it by {} "
        "(residual {:.3g} against {:.3g} at its own rows{}); with a current loop so between the two{}, the held-out "
        "rows replay {} low-passed to {:.4g}, {:.4g} without",
        behind, m.residual, m.plain, m.decisive ? ", which decides it" : "", limit_note[index(ax.axis)],
        ax.channel.column, e1->second, e0->second);
    ax.loop_source += "; " + ax.torque_command_choice;
    set_identified_axis(out.identified.axes[index(ax.axis)], ax);
  }
  out.final_machine = out.identified;
}

/// An NRMS of nrms_or_none as a report gives it.
std::string figure_text(double v) { return v < 1e300 ? fmt::format("{:.4g}", v) : std::string("no figure"); }

/// A lag the law shows outside the loop. The law fitted with a first-order
/// lag between its output and the logged torque (fit as a current loop's)
/// holds the same where the log is a drive's smoothed torque monitor and
/// the motor's torque has no lag: the log lags the law alike, and only the
/// motion tells the two apart. Put in the loop, a 2 ms monitor's lag made
/// the twin track the cascade sweep's other program at 0.026 (0.0028
/// without it) and its torque at 0.41. So the machine with the lag in the
/// other place (out of the loop and given to the logged channel, or back)
/// is replayed on the held-out rows of the fitting runs, and taken where
/// the tracking error falls by more than kMotionShowsLag and the low-passed
/// torque rises by no more than kRiseAllowed. The motion decides, by a
/// margin a misplaced lag exceeds many times (the lag of a 1 and a 2 ms
/// monitor, put in the loop, tracked the fitting runs' held-out rows at
/// 0.0071 and 0.020 against 0.0022 and 0.0027), and a model's own error
/// does not reach alone: a current loop's true lag of 0.5 ms beside a
/// Stribeck rise the drive does not have, taken out, lowered it by 2.4 %.
/// A larger effect the drive does not have yet can: with a Stribeck rise
/// of twice the sweep's size behind a 1 ms current loop, taking the lag
/// out lowered the tracking from 0.0142 to 0.0116 before the rise was
/// found, and the other program then tracked at 0.0096 (0.0026 with the
/// lag in the loop). So the choice is made once on the machine as
/// identified, for the catalogue's search to run on the right loop, and
/// again on the final machine with the effects found (`again`), where only
/// a change is said.
constexpr double kMotionShowsLag = 0.1;
void split_monitor_lag(DataCalibration& out, const std::vector<RunData>& runs, const AxisArray<bool>& taken);
void place_law_lag(DataCalibration& out, const std::vector<RunData>& runs, bool again) {
  const sim::MachineDefinition& base = again ? out.final_machine : out.identified;
  sim::MachineDefinition trial = base;
  // The lag moved to the other place on a machine's axis.
  const auto move_lag = [](sim::AxisDefinition& def, bool to_monitor) {
    double& from = to_monitor ? def.loop.cascade.tau_i_s : def.logged_torque_filter_s;
    double& to = to_monitor ? def.logged_torque_filter_s : def.loop.cascade.tau_i_s;
    to = from;
    from = 0.0;
  };
  AxisArray<bool> on{};
  for (const AxisFromData& ax : out.axis) {
    if (!ax.identified || !ax.velocity_loop_from_data || ax.torque_command_logged || !(ax.gains.tau_i_s > 0.0) ||
        ax.lag_share_in_loop > 0.0)
      continue;
    move_lag(trial.axes[index(ax.axis)], !ax.lag_in_monitor);
    on[index(ax.axis)] = true;
  }
  if (std::none_of(on.begin(), on.end(), [](bool b) { return b; })) return;
  const std::optional<ChannelErrors> now_e = held_out_lowpassed(out, runs, base);
  const std::optional<ChannelErrors> moved_e = held_out_lowpassed(out, runs, trial);
  if (!moved_e) return;
  AxisArray<bool> to_monitor{};  // the lags moved into the monitor on the machine as identified
  for (AxisFromData& ax : out.axis) {
    if (!on[index(ax.axis)]) continue;
    const std::string err = col(ax.axis, "_err_mm");
    const double t0 = nrms_or_none(now_e, err), t1 = nrms_or_none(moved_e, err);
    const double q0 = nrms_or_none(now_e, ax.channel.column), q1 = nrms_or_none(moved_e, ax.channel.column);
    if (!(t1 < 1e300 && q1 < 1e300)) continue;
    const bool take = q1 <= q0 * (1.0 + kRiseAllowed) && t1 < (1.0 - kMotionShowsLag) * t0;
    const bool in_monitor = take != ax.lag_in_monitor;
    const std::string figures = fmt::format(
        "the held-out rows of the fitting runs replay the tracking error to {} and {} low-passed to {} with it "
        "outside the loop, {} and {} in it{}",
        figure_text(in_monitor == take ? t1 : t0), ax.channel.column, figure_text(in_monitor == take ? q1 : q0),
        figure_text(in_monitor == take ? t0 : t1), figure_text(in_monitor == take ? q0 : q1),
        again ? ", with the effects found" : "");
    if (again && !take) continue;
    ax.loop_source += in_monitor ? fmt::format("; the lag is outside the loop, in the logged {} (a smoothed torque "
                                               "monitor: the motion does not show it; {})",
                                               ax.channel.column, figures)
                                 : fmt::format("; the lag is the current loop's, in the loop ({})", figures);
    if (!take) continue;
    ax.lag_in_monitor = in_monitor;
    move_lag(out.identified.axes[index(ax.axis)], in_monitor);
    if (again) move_lag(out.final_machine.axes[index(ax.axis)], in_monitor);
    to_monitor[index(ax.axis)] = in_monitor && !again;
  }
  split_monitor_lag(out, runs, to_monitor);
  if (!again) out.final_machine = out.identified;
}

/// The lag place_law_dead_time or place_law_lag put in the monitor, split: a share of it
/// the current loop's, in the loop, the rest the monitor's (a drive that
/// lags its torque and smooths what it traces). Through the speed's
/// low-pass the law shows one first-order lag of about their sum. Shares
/// of 0.2, 0.35 and 0.5 are replayed on the held-out rows of the fitting
/// runs; the best is taken where its tracking error is under (1 -
/// kMotionShowsLag) of the whole lag in the monitor and its low-passed
/// torque rises by no more than kRiseAllowed (AxisFromData::lag_share_in_loop).
void split_monitor_lag(DataCalibration& out, const std::vector<RunData>& runs, const AxisArray<bool>& taken) {
  if (std::none_of(taken.begin(), taken.end(), [](bool b) { return b; })) return;
  const std::optional<ChannelErrors> whole = held_out_lowpassed(out, runs, out.identified);
  if (!whole) return;
  struct Best {
    double share{0.0}, t{1e300};
  };
  AxisArray<Best> best{};
  for (const double share : {0.2, 0.35, 0.5}) {
    sim::MachineDefinition m = out.identified;
    for (const AxisFromData& ax : out.axis) {
      if (!taken[index(ax.axis)]) continue;
      place_lag(m.axes[index(ax.axis)], ax.gains.tau_i_s, share);
    }
    const std::optional<ChannelErrors> e = held_out_lowpassed(out, runs, m);
    if (!e) continue;
    for (const AxisFromData& ax : out.axis) {
      if (!taken[index(ax.axis)]) continue;
      const double t = nrms_or_none(e, col(ax.axis, "_err_mm")), q = nrms_or_none(e, ax.channel.column);
      const double q0 = nrms_or_none(whole, ax.channel.column);
      Best& b = best[index(ax.axis)];
      if (t < b.t && q <= q0 * (1.0 + kRiseAllowed)) b = {share, t};
    }
  }
  for (AxisFromData& ax : out.axis) {
    if (!taken[index(ax.axis)]) continue;
    const Best& b = best[index(ax.axis)];
    const double t0 = nrms_or_none(whole, col(ax.axis, "_err_mm"));
    if (!(b.share > 0.0 && b.t < (1.0 - kMotionShowsLag) * t0)) {
      if (b.share > 0.0)
        ax.loop_source += fmt::format("; split between the loop and the monitor the lag tracks no better ({} at "
                                      "{:g} of it in the loop against {} with none)",
                                      figure_text(b.t), b.share, figure_text(t0));
      continue;
    }
    ax.lag_share_in_loop = b.share;
    sim::AxisDefinition& def = out.identified.axes[index(ax.axis)];
    place_lag(def, ax.gains.tau_i_s, b.share);
    ax.loop_source += fmt::format("; {:g} of it is the current loop's, in the loop ({:.3g} ms), the rest the "
                                  "monitor's ({:.3g} ms): the held-out rows of the fitting runs replay the tracking "
                                  "error to {} so, {} with the whole lag in the monitor",
                                  b.share, 1e3 * def.loop.cascade.tau_i_s, 1e3 * def.logged_torque_filter_s,
                                  figure_text(b.t), figure_text(t0));
  }
}

/// A smoothed monitor's lag the law does not show as a lag. Where the speed
/// is taken from the position, the law is fitted through the speed's
/// low-pass (current_loop_lag_through_filter), and through it a 2 ms
/// monitor's lag fits no better than a 1 ms dead time (proposed as a delay,
/// which the replay refused) and a 1 ms monitor's not beyond the law's noise
/// (the law taken as plain PI, Kvp 8 % and Tn 9 % low). Either way the loop
/// kept the gains fitted without a lag, which the monitor's lag biases: the
/// cascade sweep's runs without the motor's speed tracked the other program
/// at 0.019 to 0.025 behind a 2 ms monitor, and 0.0065 behind a 1 ms one on
/// the run without an effect. So the machine with the law fitted on a
/// first-order lag alone (AxisFromData::law_lag_alone) and that lag in the
/// logged channel is replayed on the held-out rows of the fitting runs beside
/// the machine as identified and, where the law shows a dead time, the one
/// with that dead time in the loop (the delay the catalogue would try, with
/// the gains fitted at it), and taken where its tracking error is under
/// (1 - kMotionShowsLag) of both and its low-passed torque rises by no more
/// than kRiseAllowed on the machine as identified. The lag is then the
/// monitor's (lag_in_monitor) and the catalogue tries no delay for it;
/// place_law_lag may move it into the loop on the final machine.
void place_law_dead_time(DataCalibration& out, const std::vector<RunData>& runs) {
  if (runs.empty()) return;
  const double dt = runs.front().run->sample_period_s;
  sim::MachineDefinition in_loop = out.identified, in_monitor = out.identified;
  AxisArray<bool> on{};
  bool any_dead_time = false;
  for (const AxisFromData& ax : out.axis) {
    if (!ax.identified || !ax.velocity_loop_from_data || ax.torque_command_logged || ax.gains.tau_i_s > 0.0 ||
        !ax.law_lag_alone)
      continue;
    if (ax.torque_lag_rows() > 0.0) {
      Trial delay;
      delay.kind = EffectKind::kDelay;
      delay.sets = {{{EffectParam::delay_delay_s, ax.torque_lag_rows() * dt}}};
      delay.gains = ax.gains_at_lag;
      in_loop = with_trial(in_loop, ax.axis, delay, 0);
      any_dead_time = true;
    }
    sim::AxisDefinition& def = in_monitor.axes[index(ax.axis)];
    def.loop.cascade = *ax.law_lag_alone;
    def.loop.cascade.tau_i_s = 0.0;
    def.logged_torque_filter_s = ax.law_lag_alone->tau_i_s;
    on[index(ax.axis)] = true;
  }
  if (std::none_of(on.begin(), on.end(), [](bool b) { return b; })) return;
  const std::optional<ChannelErrors> now_e = held_out_lowpassed(out, runs, out.identified);
  const std::optional<ChannelErrors> loop_e = any_dead_time ? held_out_lowpassed(out, runs, in_loop) : now_e;
  const std::optional<ChannelErrors> monitor_e = held_out_lowpassed(out, runs, in_monitor);
  if (!monitor_e) return;
  AxisArray<bool> taken{};
  for (AxisFromData& ax : out.axis) {
    if (!on[index(ax.axis)]) continue;
    const std::string err = col(ax.axis, "_err_mm");
    const double t0 = nrms_or_none(now_e, err), tl = nrms_or_none(loop_e, err), tm = nrms_or_none(monitor_e, err);
    const double q0 = nrms_or_none(now_e, ax.channel.column), tq = nrms_or_none(monitor_e, ax.channel.column);
    if (!(tm < 1e300 && tq < 1e300)) continue;
    const bool take = tq <= q0 * (1.0 + kRiseAllowed) && tm < (1.0 - kMotionShowsLag) * std::min(t0, tl);
    const std::string figures = fmt::format(
        "the held-out rows of the fitting runs replay the tracking error to {} with a first-order lag of {:.3g} ms "
        "outside the loop ({} low-passed to {}), {}{} without it ({} to {})",
        figure_text(tm), 1e3 * ax.law_lag_alone->tau_i_s, ax.channel.column, figure_text(tq),
        ax.torque_lag_rows() > 0.0 ? fmt::format("{} with the law's dead time in the loop, ", figure_text(tl)) : "",
        figure_text(t0), ax.channel.column, figure_text(q0));
    if (!take) {
      if (ax.torque_lag_rows() > 0.0)
        ax.loop_source += fmt::format("; the law's lag is not a smoothed torque monitor's ({})", figures);
      continue;
    }
    ax.loop_source += fmt::format("; the law's lag is outside the loop, in the logged {} (a smoothed torque "
                                  "monitor: the motion does not show it; Kvp {:.4g}, Tn {:.3g} s fitted with it; {})",
                                  ax.channel.column, ax.law_lag_alone->Kvp_torque_s_per_rad,
                                  ax.law_lag_alone->Tn_s, figures);
    ax.gains = *ax.law_lag_alone;
    ax.gains_at_lag = ax.gains;
    ax.torque_lag_samples = 0;
    ax.torque_lag_fraction = 0.0;
    ax.lag_in_monitor = true;
    out.identified.axes[index(ax.axis)].loop = in_monitor.axes[index(ax.axis)].loop;
    out.identified.axes[index(ax.axis)].logged_torque_filter_s = ax.gains.tau_i_s;
    taken[index(ax.axis)] = true;
  }
  split_monitor_lag(out, runs, taken);
  out.final_machine = out.identified;
}

/// One Coulomb level or two. The drive's two levels (one per direction) are
/// a parameter more than the rigid-body regression's one: with two, the
/// rest level (the constant) is free of the moving levels; with one, it is
/// their midpoint, and the rest rows inform the moving levels and the
/// viscous slope. On a real log two levels can take up what the fitting
/// part's speeds happen to differ by between the directions (umich07 y:
/// 7.21 and 8.64 A with 0.025 A per mm/s; one level 6.88 A with 0.078 A per
/// mm/s, nearer the slope its held-out rows show). Both drives are replayed
/// with the first velocity loop on the held-out rows of the fitting runs,
/// before the loop is chosen on the drive taken. The one level is a change
/// of the identified structure, so it is taken as an effect is kept: where
/// it lowers the channel's held-out error by more than kKeepMargin and the
/// tracking error rises by no more than kRiseAllowed (a difference within
/// the margin sends the rest of the calibration down another path of loop
/// and effect choices, by as much as 0.62 against 0.67 on umich10 y, but is
/// not evidence). The report says which, with both errors.
void choose_coulomb_levels(DataCalibration& out, const std::vector<RunData>& runs) {
  sim::MachineDefinition trial = out.identified;
  bool any = false;
  for (const AxisFromData& ax : out.axis) {
    if (!ax.identified || !ax.one_level.ok) continue;
    const auto& o = ax.one_level;
    set_drive(trial.axes[index(ax.axis)].drive, DriveRefit{o.J, o.B, o.Tc, o.Tc, o.c});
    trial.axes[index(ax.axis)].loop.cascade = first_loop_at(ax, o.J);
    any = true;
  }
  if (!any) return;
  const ChannelErrors two = pooled_on_fit_runs(out, runs, out.identified, true);
  const ChannelErrors one = pooled_on_fit_runs(out, runs, trial, true);
  for (AxisFromData& ax : out.axis) {
    if (!ax.identified || !ax.one_level.ok) continue;
    const auto e2 = two.nrms.find(ax.channel.column);
    const auto e1 = one.nrms.find(ax.channel.column);
    if (e2 == two.nrms.end() || e1 == one.nrms.end()) continue;
    const bool tracking_ok = tracking_holds(two, one, ax.axis);
    const auto& o = ax.one_level;
    const std::string u = ax.channel.unit == "raw" ? "in the log's unit" : ax.channel.unit;
    if (!(e1->second < (1.0 - kKeepMargin) * e2->second && tracking_ok)) {
      ax.coulomb_choice = fmt::format("a Coulomb level per direction: one level for both ({:.3g} {}, and {:.3g} {} "
                                      "per mm/s) replays the held-out rows' {} to {:.4g} against {:.4g} with two{}",
                                      o.Tc, u, o.B, u, ax.channel.column, e1->second, e2->second,
                                      tracking_ok ? fmt::format(" (one level is taken where it lowers that by "
                                                                "more than {:g} %)",
                                                                100.0 * kKeepMargin)
                                                  : std::string(", and raises the tracking error"));
      continue;
    }
    ax.coulomb_choice = fmt::format("one Coulomb level for both directions: fitted apart ({:.3g} {} in +, {:.3g} in "
                                    "-, and {:.3g} {} per mm/s) the levels replay the held-out rows' {} to {:.4g}, "
                                    "one level to {:.4g}",
                                    ax.Tc_pos, u, ax.Tc_neg, ax.B, u, ax.channel.column, e2->second, e1->second);
    // The run's notes give the floors of the drive taken, not of the two-level fit.
    if (const auto it = std::find(out.notes.begin(), out.notes.end(), ax.note); !ax.note.empty() && it != out.notes.end())
      out.notes.erase(it);
    ax.note = o.clamped.empty() ? "" : fmt::format("axis {}: {}", axis_name(ax.axis), fmt::join(o.clamped, "; "));
    if (!ax.note.empty()) out.notes.push_back(ax.note);
    ax.one_coulomb_level = true;
    ax.gains = first_loop_at(ax, o.J);
    ax.J = o.J;
    ax.B = o.B;
    ax.Tc_pos = ax.Tc_neg = o.Tc;
    ax.c = o.c;
    ax.J_se = o.J_se;
    ax.B_se = o.B_se;
    ax.Tc_pos_se = ax.Tc_neg_se = o.Tc_se;
    ax.c_se = o.c_se;
    set_drive(out.identified.axes[index(ax.axis)].drive, DriveRefit{ax.J, ax.B, ax.Tc_pos, ax.Tc_neg, ax.c});
    out.identified.axes[index(ax.axis)].loop.cascade = ax.gains;
  }
  out.final_machine = out.identified;
}

sim::MachineDefinition with_smooth_friction(const sim::MachineDefinition& base, Axis a, double ws) {
  sim::MachineDefinition trial = base;
  auto& fx = trial.axes[index(a)].drive.effects.smooth_friction;
  fx.enabled = true;
  fx.ws_rad_per_s = ws;
  return trial;
}

/// The smooth_friction trial of an axis (the speed scale its fitting rows
/// chose, kept or not), or null.
DataEffect* smooth_friction_trial(DataCalibration& out, Axis a) {
  const std::string ws_key = param_key(EffectKind::kSmoothFriction, EffectParam::smooth_friction_ws);
  for (DataEffect& e : out.effects)
    if (e.kind == EffectKind::kSmoothFriction && e.axis == a && e.params.count(ws_key)) return &e;
  return nullptr;
}

/// smooth_friction and the velocity loop chosen together where the log does
/// not show the loop. The first choice of the loop was made with stick/slip
/// friction, under which the integral holds what the axis stopped at; with
/// friction that creeps at rest, the loop's gains set how the held torque
/// settles (too soft a loop rings for a second at every stop). With each
/// axis's speed scale (the one its fitting rows chose, or, where none
/// lowered their error under the first loop, the one that raised it least:
/// with another loop it may lower it), the 16 loops are replayed and chosen
/// on the fitting rows; the pair is kept where it lowers the held-out error
/// of the fitting runs against the machine so far (smooth_friction kept or
/// not: the rule of every change to the machine).
void rechoose_velocity_loops(DataCalibration& out, const std::vector<RunData>& runs) {
  const std::string ws_key = param_key(EffectKind::kSmoothFriction, EffectParam::smooth_friction_ws);
  AxisArray<bool> on{};
  AxisArray<DataEffect*> trials{};
  sim::MachineDefinition base = out.final_machine;
  for (const AxisFromData& ax : out.axis) {
    DataEffect* sf = smooth_friction_trial(out, ax.axis);
    on[index(ax.axis)] = ax.identified && !ax.velocity_loop_from_data && sf != nullptr;
    if (!on[index(ax.axis)]) continue;
    trials[index(ax.axis)] = sf;
    base = with_smooth_friction(base, ax.axis, sf->params.at(ws_key));
  }
  if (std::none_of(on.begin(), on.end(), [](bool b) { return b; })) return;
  const ChannelErrors fit_base = pooled_on_fit_runs(out, runs, base, false);
  const AxisArray<LoopChoice> best = best_velocity_loops(out, runs, base, on);
  sim::MachineDefinition trial = base;
  for (const AxisFromData& ax : out.axis) {
    const LoopChoice& c = best[index(ax.axis)];
    if (!on[index(ax.axis)] || c.score >= 1e300) continue;
    auto& g = trial.axes[index(ax.axis)].loop.cascade;
    g.Kvp_torque_s_per_rad = c.Kvp;
    g.Tn_s = c.Tn;
  }
  const ChannelErrors held_now = pooled_on_fit_runs(out, runs, out.final_machine, true);
  const ChannelErrors held_trial = pooled_on_fit_runs(out, runs, trial, true);
  for (AxisFromData& ax : out.axis) {
    if (!on[index(ax.axis)]) continue;
    const std::string& key = ax.channel.column;
    const auto hn = held_now.nrms.find(key);
    const auto ht = held_trial.nrms.find(key);
    const auto fb = fit_base.nrms.find(key);
    if (hn == held_now.nrms.end() || ht == held_trial.nrms.end() || fb == fit_base.nrms.end()) continue;
    const LoopChoice& c = best[index(ax.axis)];
    const bool kept = ht->second < hn->second;
    DataEffect& sf = *trials[index(ax.axis)];
    if (c.Kvp == ax.gains.Kvp_torque_s_per_rad && c.Tn == ax.gains.Tn_s) {
      sf.evidence += fmt::format("; the velocity loop chosen again on the fitting rows with it is the one chosen "
                                 "first (Kvp {:.4g}, Tn {:.4g} s)",
                                 c.Kvp, c.Tn);
      continue;
    }
    sf.evidence += fmt::format("; with the velocity loop chosen again on the fitting rows (Kvp {:.4g}, Tn {:.4g} s: "
                               "fitting rows {:.4g} -> {:.4g}) the held-out error is {:.4g} against {:.4g} without "
                               "{}",
                               c.Kvp, c.Tn, fb->second, c.score, ht->second, hn->second,
                               kept ? "(kept with that loop)" : "(that loop not kept)");
    if (!kept) continue;
    sf.kept = true;
    sf.after = ht->second;
    ax.gains = trial.axes[index(ax.axis)].loop.cascade;
    out.final_machine = with_smooth_friction(out.final_machine, ax.axis, sf.params.at(ws_key));
    out.final_machine.axes[index(ax.axis)].loop.cascade = ax.gains;
    ax.loop_source += fmt::format("; chosen again with smooth friction: Kvp {:.4g}, Tn {:.4g} s", c.Kvp, c.Tn);
  }
}

/// Calls f(r, k, last) on every fitting row k of every run r where the
/// axis's command has stood still for 0.2 s (interior rows only). `last` is
/// the direction the command last moved in within the segment, 0 before it
/// has moved there (a stitched segment starts from an unseen approach).
/// Still is a command at a thousandth of the moving threshold or less, not
/// under the threshold: a contour reverses through zero speed, and on a slow
/// arc its command stays under the threshold for longer than 0.2 s while
/// the axis slides through the reversal.
template <class F>
void for_settled_rest_rows(const std::vector<RunData>& runs, Axis a, F&& f) {
  const std::size_t i = index(a);
  for (std::size_t r = 0; r < runs.size(); ++r) {
    const RunData& rd = runs[r];
    const auto settle = std::max<std::size_t>(2, static_cast<std::size_t>(std::lround(0.2 / rd.run->sample_period_s)));
    std::size_t still = 0;
    int last = 0;
    for (std::size_t k = 0; k < rd.n_fit; ++k) {
      const double v = rd.kin[i].v_mm_per_s[k];
      const int d = direction(v, rd.v_move[i]);
      if (d != 0) last = d;
      if (k > 0 && !rd.interior[k - 1]) last = 0;
      still = std::abs(v) <= 1e-3 * rd.v_move[i] ? still + 1 : 0;
      if (still >= settle && rd.interior[k]) f(r, k, last);
    }
  }
}

/// What a stopped axis holds off the constant load over the fitting rows
/// where the command has stood still for 0.2 s: in the log and in the replay
/// of the identified machine. Each rest period counts with the size of its
/// own mean, weighted by its rows, so a torque channel's noise averages out
/// inside the period instead of adding its mean magnitude (0.8 of its RMS)
/// to what the axis holds.
struct RestHolding {
  double log{0.0}, model{0.0};
  std::size_t rows{0};
};
RestHolding rest_holding(const std::vector<RunData>& runs, const FitRunErrors& id_replay, const AxisFromData& ax) {
  RestHolding h;
  if (!id_replay.ok) return h;
  std::vector<const std::vector<double>*> T, Tm;
  for (std::size_t r = 0; r < runs.size(); ++r) {
    T.push_back(&runs[r].run->trace.at(ax.channel.column));
    Tm.push_back(model_channel(id_replay.replays[r], ax.axis, ax.channel, true));
  }
  double seg_log = 0.0, seg_model = 0.0;
  std::size_t prev_r = 0, prev_k = 0;
  bool open = false;
  auto close = [&] {
    h.log += std::abs(seg_log);
    h.model += std::abs(seg_model);
    seg_log = seg_model = 0.0;
  };
  for_settled_rest_rows(runs, ax.axis, [&](std::size_t r, std::size_t k, int) {
    if (Tm[r] == nullptr) return;
    if (open && (r != prev_r || k != prev_k + 1)) close();
    seg_log += (*T[r])[k] - ax.c;
    seg_model += (*Tm[r])[k] - ax.c;
    open = true;
    prev_r = r;
    prev_k = k;
    ++h.rows;
  });
  if (open) close();
  if (h.rows > 0) {
    h.log /= static_cast<double>(h.rows);
    h.model /= static_cast<double>(h.rows);
  }
  return h;
}

/// smooth_friction tried on one axis: the speed scale chosen on the fitting
/// rows, kept where it lowers the held-out error.
void try_smooth_friction_on_axis(DataCalibration& out, const std::vector<RunData>& runs, const AxisFromData& ax,
                                 const FitRunErrors& id_replay, const ChannelErrors& base_fit,
                                 const ChannelErrors& base_held, sim::MachineDefinition& final_machine) {
  const std::string key = ax.channel.column;
  const auto bf = base_fit.nrms.find(key);
  const auto bh = base_held.nrms.find(key);
  if (bf == base_fit.nrms.end() || bh == base_held.nrms.end()) return;
  const RestHolding h = rest_holding(runs, id_replay, ax);
  DataEffect eff;
  eff.set_kind(EffectKind::kSmoothFriction);
  eff.axis = ax.axis;
  eff.before = eff.after = bh->second;
  const bool rest_resolved = resolves_rest(runs.front().run->sample_period_s);
  if (rest_resolved && !(h.rows >= 10 && h.log < 0.5 * h.model)) {
    eff.evidence = h.rows < 10
                       ? fmt::format("not tried: {} fitting rows at rest, too few to see what the axis holds there",
                                     h.rows)
                       : fmt::format("not tried: at rest the log holds {:.4g} off the constant load on average, "
                                     "the stick/slip model {:.4g}: the held torque does not relax",
                                     h.log, h.model);
    out.effects.push_back(eff);
    return;
  }
  // rg = 1 mm/rad in a machine identified from data: rad/s are mm/s.
  double v_move = 0.0;
  for (const RunData& rd : runs) v_move = std::max(v_move, rd.v_move[index(ax.axis)]);
  double ws_chosen = 0.0, fit_chosen = 1e300;
  for (double f : {0.1, 0.3, 1.0}) {
    const sim::MachineDefinition trial = with_smooth_friction(out.identified, ax.axis, f * v_move);
    const ChannelErrors e = pooled_on_fit_runs(out, runs, trial, false);
    const auto it = e.nrms.find(key);
    if (it != e.nrms.end() && it->second < fit_chosen) {
      fit_chosen = it->second;
      ws_chosen = f * v_move;
    }
  }
  const bool lowers_fit = ws_chosen > 0.0 && fit_chosen < bf->second;
  if (!lowers_fit) {
    eff.evidence = fmt::format("no speed scale lowers the fitting rows' {} error ({:.4g}) with the velocity loop "
                               "chosen under stick/slip friction",
                               key, bf->second);
    // The loop was chosen with stick/slip friction; with friction that
    // relaxes another loop may settle the held torque better. The speed
    // scale that did least harm is left for the joint choice of the two
    // (rechoose_velocity_loops), which keeps it only with a loop that
    // lowers the held-out error.
    if (ws_chosen > 0.0) eff.params[param_key(EffectKind::kSmoothFriction, EffectParam::smooth_friction_ws)] = ws_chosen;
    out.effects.push_back(eff);
    return;
  }
  eff.params[param_key(EffectKind::kSmoothFriction, EffectParam::smooth_friction_ws)] = ws_chosen;
  const ChannelErrors held =
      pooled_on_fit_runs(out, runs, with_smooth_friction(out.identified, ax.axis, ws_chosen), true);
  const auto hh = held.nrms.find(key);
  eff.after = hh != held.nrms.end() ? hh->second : bh->second;
  eff.kept = eff.after < eff.before;
  // Where the rest is not resolved, what the log holds there is said as
  // read, not as the signature: the replay's errors alone decide.
  const std::string rest =
      rest_resolved
          ? fmt::format("a stopped axis holds {:.4g} off the constant load in the log (its rest periods' means, "
                        "weighted by their rows), the stick/slip model {:.4g}",
                        h.log, h.model)
          : fmt::format("a log sampled every {:g} s does not resolve how the held torque settles at rest (the log "
                        "holds {:.4g} off the constant load there, the stick/slip model {:.4g}), so the replay's "
                        "errors alone decide",
                        runs.front().run->sample_period_s, h.log, h.model);
  eff.evidence = fmt::format("{}: friction smoothed below {:.3g} mm/s takes the {} error from {:.4g} to {:.4g} on "
                             "the fitting rows and from {:.4g} to {:.4g} on the held-out rows{}",
                             rest, ws_chosen, key, bf->second, fit_chosen, eff.before, eff.after,
                             eff.kept ? "" : " (not kept)");
  if (eff.kept) final_machine = with_smooth_friction(final_machine, ax.axis, ws_chosen);
  out.effects.push_back(eff);
}

/// Friction that relaxes at rest (smooth_friction). A stopped axis with
/// stick/slip friction holds the Coulomb level of its last direction (the
/// velocity loop winds up to the breakaway torque and the axis creeps until
/// its error is within a count); real drives hold a torque spread about
/// zero. The signature first: on the fitting rows where the command has
/// stood still for 0.2 s, the torque the log holds off the constant load,
/// against what the identified stick/slip model holds there (stick/slip
/// holds whatever it stopped at, up to the Coulomb level; friction that
/// relaxes lets the loop bring it to the load). The speed scale is chosen
/// per axis on the fitting rows among three multiples of the axis's moving
/// threshold; it is kept where it lowers the held-out error of the fitting
/// runs (the rule every added effect follows).
void try_smooth_friction(DataCalibration& out, const std::vector<RunData>& runs) {
  const ChannelErrors base_fit = pooled_on_fit_runs(out, runs, out.identified, false);
  const ChannelErrors base_held = pooled_on_fit_runs(out, runs, out.identified, true);
  sim::MachineDefinition final_machine = out.identified;
  const FitRunErrors id_replay = errors_on_fit_runs(runs, out.identified, out.axes, out.rounding, out.replays);
  for (const AxisFromData& ax : out.axis)
    if (ax.identified) try_smooth_friction_on_axis(out, runs, ax, id_replay, base_fit, base_held, final_machine);
  out.final_machine = final_machine;
}

sim::MachineDefinition with_rising_friction(const sim::MachineDefinition& base, Axis a, double share, double ws) {
  sim::MachineDefinition trial = base;
  auto& fx = trial.axes[index(a)].drive.effects;
  fx.smooth_friction.enabled = false;
  fx.rising_friction.enabled = true;
  fx.rising_friction.share = share;
  fx.rising_friction.ws_rad_per_s = ws;
  return trial;
}

/// What a stopped axis holds off the constant load in the log, by the
/// direction it last moved: mean over the fitting rows where the command has
/// stood still for 0.2 s.
struct DirectionalHold {
  double after_pos{0.0}, after_neg{0.0};
  std::size_t rows_pos{0}, rows_neg{0};
};
DirectionalHold directional_hold(const std::vector<RunData>& runs, const AxisFromData& ax) {
  DirectionalHold h;
  std::vector<const std::vector<double>*> T;
  for (const RunData& rd : runs) T.push_back(&rd.run->trace.at(ax.channel.column));
  for_settled_rest_rows(runs, ax.axis, [&](std::size_t r, std::size_t k, int last) {
    if (last == 0) return;
    (last > 0 ? h.after_pos : h.after_neg) += (*T[r])[k] - ax.c;
    ++(last > 0 ? h.rows_pos : h.rows_neg);
  });
  if (h.rows_pos > 0) h.after_pos /= static_cast<double>(h.rows_pos);
  if (h.rows_neg > 0) h.after_neg /= static_cast<double>(h.rows_neg);
  return h;
}

/// How a trial machine's gain over a base machine on the fitting runs'
/// held-out rows is spread: the fall of the squared error of axis `a`'s
/// channel `ch`, in all and in the second of the log that carries the most
/// of it (kGainBlock_s blocks from each run's start), and where that second
/// starts.
struct HeldGain {
  double total{0.0}, largest{0.0};
  double largest_at_s{0.0};
  std::size_t largest_run{0};
};
constexpr double kGainBlock_s = 1.0;
HeldGain held_gain_by_block(const std::vector<RunData>& runs, const FitRunErrors& base, const FitRunErrors& trial,
                            Axis a, const TorqueChannel& ch) {
  HeldGain g;
  for (std::size_t r = 0; r < runs.size() && r < base.replays.size() && r < trial.replays.size(); ++r) {
    const RunData& rd = runs[r];
    const std::vector<double>* mb = model_channel(base.replays[r], a, ch, true);
    const std::vector<double>* mt = model_channel(trial.replays[r], a, ch, true);
    if (mb == nullptr || mt == nullptr) continue;
    const std::vector<double>& meas = rd.run->trace.at(ch.column);
    const std::vector<char>&cb = base.compared[r], &ct = trial.compared[r];
    const double dt = rd.run->sample_period_s;
    std::map<long, double> blocks;
    for (std::size_t k = rd.n_fit; k < rd.n && k < cb.size() && k < ct.size() && k < mb->size() && k < mt->size(); ++k)
      if (cb[k] && ct[k]) {
        const double eb = meas[k] - (*mb)[k], et = meas[k] - (*mt)[k];
        blocks[static_cast<long>(std::floor(static_cast<double>(k) * dt / kGainBlock_s))] += eb * eb - et * et;
      }
    for (const auto& [b, d] : blocks) {
      g.total += d;
      if (d > g.largest) {
        g.largest = d;
        g.largest_at_s = static_cast<double>(b) * kGainBlock_s;
        g.largest_run = r;
      }
    }
  }
  return g;
}

/// Friction that rises with speed from a breakaway level below Coulomb
/// (rising_friction), tried on every identified axis without stribeck (which
/// describes the same range the other way) against the machine so far, the
/// catalogue's effects included (a gap at reversals, say, also moves what a
/// stopped axis holds, and is looked for first). Stick/slip friction makes a
/// stopped axis hold the Coulomb level of the direction it last moved;
/// smooth_friction lets the hold relax to the constant load; a real axis
/// often holds part of its sliding friction in that direction, which
/// breakaway below Coulomb gives (the loop's torque falls while the axis
/// creeps until it is within the breakaway level). The
/// share and the speed scale are chosen per axis on the fitting rows from
/// four shares and two multiples of the moving threshold (the axes replay
/// independently, so one replay scores a grid point on every axis); kept
/// where the held-out error of the fitting runs falls by more than
/// kKeepMargin without the tracking error rising by more than kRiseAllowed.
/// `now`: the machine so far on the fitting runs.
void try_rising_friction(DataCalibration& out, const std::vector<RunData>& runs, const FitRunErrors& now) {
  std::vector<const AxisFromData*> axes;
  for (const AxisFromData& ax : out.axis)
    if (ax.identified && ax.channel.present() &&
        !out.final_machine.axes[index(ax.axis)].drive.effects.stribeck.enabled)
      axes.push_back(&ax);
  if (axes.empty() || !now.ok) return;
  struct Best {
    double fit{1e300}, share{0.0}, ws{0.0};
    FitRunErrors errors;
  };
  AxisArray<Best> best{};
  AxisArray<double> v_move{};
  for (const AxisFromData* ax : axes) {
    const std::size_t i = index(ax->axis);
    for (const RunData& rd : runs) v_move[i] = std::max(v_move[i], rd.v_move[i]);
  }
  for (double share : {0.1, 0.2, 0.35, 0.6}) {
    for (double fw : {0.3, 1.0}) {
      sim::MachineDefinition trial = out.final_machine;
      for (const AxisFromData* ax : axes)
        trial = with_rising_friction(trial, ax->axis, share, fw * v_move[index(ax->axis)]);
      const FitRunErrors e = errors_on_fit_runs(runs, trial, out.axes, out.rounding, out.replays);
      if (!e.ok) continue;
      for (const AxisFromData* ax : axes) {
        const auto it = e.fit.nrms.find(ax->channel.column);
        Best& b = best[index(ax->axis)];
        if (it == e.fit.nrms.end() || it->second >= b.fit) continue;
        b = {it->second, share, fw * v_move[index(ax->axis)], e};
      }
    }
  }
  for (const AxisFromData* ax : axes) {
    const std::string& key = ax->channel.column;
    const Best& b = best[index(ax->axis)];
    const auto ff = now.fit.nrms.find(key);
    const auto hn = now.held.nrms.find(key);
    if (ff == now.fit.nrms.end() || hn == now.held.nrms.end()) continue;
    DataEffect eff;
    eff.set_kind(EffectKind::kRisingFriction);
    eff.axis = ax->axis;
    eff.before = eff.after = hn->second;
    const DirectionalHold h = directional_hold(runs, *ax);
    auto hold = [](double mean, std::size_t rows) {
      return rows == 0 ? std::string("no settled rest row") : fmt::format("{:+.3g} ({} rows)", mean, rows);
    };
    const std::string holds = fmt::format(
        "after moving + {}, after moving - {}; its Coulomb levels are {:.3g} / {:.3g} {}", hold(h.after_pos, h.rows_pos),
        hold(h.after_neg, h.rows_neg), ax->Tc_pos, ax->Tc_neg, ax->channel.unit);
    // Where the rest is not resolved, what the log holds there is said as
    // read, not as the signature.
    const double dt_s = runs.front().run->sample_period_s;
    const std::string held_in_log =
        resolves_rest(dt_s)
            ? fmt::format("a stopped axis holds, off the constant load in the log: {}", holds)
            : fmt::format("a log sampled every {:g} s does not resolve how the held torque settles at rest (off the "
                          "constant load the log holds there: {}), so the replay's errors alone decide",
                          dt_s, holds);
    if (b.fit >= ff->second) {
      eff.evidence = fmt::format("{}: no breakaway share lowers the fitting rows' {} error ({:.4g})", held_in_log, key,
                                 ff->second);
      out.effects.push_back(eff);
      continue;
    }
    eff.params[param_key(EffectKind::kRisingFriction, EffectParam::rising_friction_share)] = b.share;
    eff.params[param_key(EffectKind::kRisingFriction, EffectParam::rising_friction_ws)] = b.ws;
    const ChannelErrors& b_held = b.errors.held;
    const auto ha = b_held.nrms.find(key);
    eff.after = ha != b_held.nrms.end() ? ha->second : hn->second;
    bool tracking_ok = true;
    const std::string err_key = col(ax->axis, "_err_mm");
    if (const auto en = now.held.nrms.find(err_key), ea = b_held.nrms.find(err_key);
        en != now.held.nrms.end() && ea != b_held.nrms.end() && en->second > 0.0)
      tracking_ok = ea->second <= en->second * (1.0 + kRiseAllowed);
    // A gain on the held-out rows that one second of them carries is one
    // event (an axis that stuck a little elsewhere after one stop), not the
    // friction the rest of the rows show: without that second the error must
    // still fall. On a truth with no rising friction and a 2 ms loop, one
    // second held 1.35 times the whole gain (21691 of 16002 in the squared
    // error), and the other program's torque rose eightfold with the effect.
    const HeldGain gain = held_gain_by_block(runs, now, b.errors, ax->axis, ax->channel);
    const bool one_event = gain.total > 0.0 && gain.total - gain.largest <= 0.0;
    // With smooth_friction kept on the axis the two are alternatives for
    // the same low-speed range, not one added to the other: the one that
    // replays the held-out rows better names it, with no margin for the
    // one tried first.
    const bool replaces_smooth = out.final_machine.axes[index(ax->axis)].drive.effects.smooth_friction.enabled;
    const bool lowers = eff.after < eff.before * (replaces_smooth ? 1.0 : 1.0 - kKeepMargin);
    eff.kept = lowers && tracking_ok && !one_event;
    const std::string why_not =
        eff.kept                 ? std::string()
        : !lowers                ? std::string(" (not kept)")
        : !tracking_ok           ? std::string(" (not kept: the tracking error rises)")
                                 : fmt::format(" (not kept: its gain is one event: the second of the held-out "
                                               "rows from {:.4g} s into the log{} gains {:.2g} times what they "
                                               "all gain together, and without that second the error rises)",
                                               gain.largest_at_s,
                                               runs.size() > 1 ? fmt::format(" of run {}", gain.largest_run + 1)
                                                               : std::string(),
                                               gain.largest / gain.total);
    eff.evidence = fmt::format(
        "{}: breakaway at {:.2g} of the Coulomb level, rising to it over {:.3g} mm/s, takes the {} error from "
        "{:.4g} to {:.4g} on the fitting rows and from {:.4g} to {:.4g} on the held-out rows{}",
        held_in_log, b.share, b.ws, key, ff->second, b.fit, eff.before, eff.after, why_not);
    if (eff.kept) {
      out.final_machine = with_rising_friction(out.final_machine, ax->axis, b.share, b.ws);
      for (DataEffect& other : out.effects)
        if (other.kind == EffectKind::kSmoothFriction && other.axis == ax->axis && other.kept) {
          other.kept = false;
          other.evidence += "; replaced by rising_friction, which lowers the held-out error further";
        }
    }
    out.effects.push_back(eff);
  }
}

/// Baselines fitted on the fitting rows: the rigid-body regression per axis
/// T = m a_cmd + Fc sgn(v_cmd) + b v_cmd + c, and the first-order lag of the
/// tracking error e = lag v.
AxisArray<Regression> fit_regressions(const DataCalibration& out, const std::vector<RunData>& runs) {
  const Fitter fitter{runs};
  AxisArray<Regression> reg{};
  for (const AxisFromData& ax : out.axis) {
    const std::size_t i = index(ax.axis);
    std::vector<double> acc, sg, vel, one, T;
    std::vector<std::size_t> rows;
    double num = 0.0, den = 0.0;
    fitter.for_fit_rows([&](std::size_t r, std::size_t k) {
      const double v = runs[r].kin[i].v_mm_per_s[k];
      const auto& t = runs[r].run->trace;
      if (const auto* x = t.find(col(ax.axis, "_mm"))) {
        num += v * (t.at(col(ax.axis, "_ref_mm"))[k] - (*x)[k]);
        den += v * v;
      }
      const auto* ch = ax.channel.present() ? t.find(ax.channel.column) : nullptr;
      if (ch == nullptr) return;
      acc.push_back(runs[r].kin[i].a_mm_per_s2[k]);
      sg.push_back(direction(v, runs[r].v_move[i]));
      vel.push_back(v);
      one.push_back(1.0);
      T.push_back((*ch)[k]);
      rows.push_back(rows.size());
    });
    reg[i].lag_s = den > 0.0 ? num / den : 0.0;
    const LsqResult ls = least_squares({&acc, &sg, &vel, &one}, T, rows);
    reg[i].ok = ls.ok;
    reg[i].theta = ls.theta;
  }
  return reg;
}

/// The model and the baselines are compared on the same rows: the interior
/// rows of the replayed segments. One pool per model, over runs.
struct ModelPools {
  PoolSet nominal, identified, calibrated, zero, regression;
};

/// The regression's torque at row k of axis i.
double regression_torque(const Regression& reg, const RunData& rd, std::size_t i, std::size_t k) {
  const auto& kin = rd.kin[i];
  const double v = kin.v_mm_per_s[k];
  return reg.theta[0] * kin.a_mm_per_s2[k] + reg.theta[1] * direction(v, rd.v_move[i]) + reg.theta[2] * v +
         reg.theta[3];
}

/// The twin against the regression, per torque channel, on the rows of
/// [from, to) both are compared on (the twin's compared rows; the regression
/// is compared on every interior row): the difference of their NRMS and its
/// interval over blocks of 1 s of rows (10 rows at least).
void versus_regression(const DataCalibration& out, const AxisArray<Regression>& reg, const RunData& rd,
                       const ReplayResult& twin, const std::vector<char>& compared, std::size_t from, std::size_t to,
                       RunErrors& re) {
  const double dt = rd.run->sample_period_s;
  const auto block_rows =
      std::max<std::size_t>(10, dt > 0.0 ? static_cast<std::size_t>(std::llround(1.0 / dt)) : std::size_t{10});
  for (const AxisFromData& ax : out.axis) {
    const std::size_t i = index(ax.axis);
    const TorqueChannel ch = torque_channel(*rd.run, ax.axis);
    if (!ch.present() || !reg[i].ok || twin.x_mm[i].empty()) continue;
    const std::vector<double>* model = model_channel(twin, ax.axis, ch, true);
    if (model == nullptr) continue;
    const auto& meas = rd.run->trace.at(ch.column);
    const auto& t = rd.run->trace.at("t_s");
    std::vector<double> m, a, b, tm;
    for (std::size_t k = from; k < std::min(to, compared.size()); ++k) {
      if (!compared[k]) continue;
      m.push_back(meas[k]);
      a.push_back((*model)[k]);
      b.push_back(regression_torque(reg[i], rd, i, k));
      tm.push_back(t[k]);
    }
    if (m.size() < 2 * block_rows) continue;
    try {
      const PairedDifference p = paired_nrms_difference(m, a, b, block_rows);
      re.twin_minus_regression[ch.column] = p;
      if (p.largest_loss_rows > 0)
        re.largest_loss_s[ch.column] = {tm[p.largest_loss_first_row],
                                        tm[p.largest_loss_first_row + p.largest_loss_rows - 1]};
    } catch (const ConfigError&) {
      // a measured signal of zeros: the NRMS table says so already
    }
  }
}

/// The zero model and the regression baselines of one run on rows [from, to).
void baselines(const DataCalibration& out, const AxisArray<Regression>& reg, const RunData& rd, std::size_t from,
               std::size_t to, RunErrors& re, ModelPools& pools) {
  PoolSet z, g;
  for (const AxisFromData& ax : out.axis) {
    const std::size_t i = index(ax.axis);
    const auto& t = rd.run->trace;
    const auto& ref = t.at(col(ax.axis, "_ref_mm"));
    const auto& kin = rd.kin[i];
    if (const auto* x = t.find(col(ax.axis, "_mm"))) {
      Pool& pz1 = z[col(ax.axis, "_err_mm")];
      Pool& pg1 = g[col(ax.axis, "_err_mm")];
      for (std::size_t k = from; k < to; ++k) {
        if (!rd.interior[k]) continue;
        const double e = ref[k] - (*x)[k];
        pz1.add(e, 0.0);
        const double ref_smooth = rd.smooth->trace.at(col(ax.axis, "_ref_mm"))[k];
        pg1.add(e, ref[k] - out.rounding.round(ref_smooth - reg[i].lag_s * kin.v_mm_per_s[k]));
      }
    }
    if (const auto* vc = t.find(col(ax.axis, "_vcmd_mm_s"))) {
      Pool& pz3 = z[col(ax.axis, "_vcmd_mm_s")];
      for (std::size_t k = from; k < to; ++k)
        if (rd.interior[k]) pz3.add((*vc)[k], 0.0);
    }
    const TorqueChannel ch = torque_channel(*rd.run, ax.axis);
    if (!ch.present()) continue;
    const auto& meas = t.at(ch.column);
    Pool& pz2 = z[ch.column];
    Pool& pg2 = g[ch.column];
    for (std::size_t k = from; k < to; ++k) {
      if (!rd.interior[k]) continue;
      pz2.add(meas[k], 0.0);
      if (reg[i].ok) pg2.add(meas[k], regression_torque(reg[i], rd, i, k));
    }
  }
  re.zero = errors_from(z);
  re.regression = errors_from(g);
  for (const auto& [k, p] : z) pools.zero[k].add(p);
  for (const auto& [k, p] : g) pools.regression[k].add(p);
}

ChannelErrors pooled_errors(const PoolSet& pools, const std::vector<RunErrors>& list, ChannelErrors RunErrors::*which) {
  ChannelErrors e = errors_from(pools);
  for (const RunErrors& re : list)
    for (const auto& [k, why] : (re.*which).not_computed)
      if (!e.nrms.count(k)) e.not_computed[k] = fmt::format("{}: {}", re.run, why);
  return e;
}

void pool_runs(const std::vector<RunErrors>& list, const ModelPools& pools, RunErrors& dst) {
  dst.run = "pooled";
  for (const RunErrors& re : list) {
    dst.rows += re.rows;
    dst.rows_compared += re.rows_compared;
  }
  dst.identified = pooled_errors(pools.identified, list, &RunErrors::identified);
  dst.calibrated = pooled_errors(pools.calibrated, list, &RunErrors::calibrated);
  dst.nominal = pooled_errors(pools.nominal, list, &RunErrors::nominal);
  dst.zero = pooled_errors(pools.zero, list, &RunErrors::zero);
  dst.regression = pooled_errors(pools.regression, list, &RunErrors::regression);
}

/// Every model's errors on the held-out rows of each fitting run, pooled.
void errors_on_fit_part(DataCalibration& out, const std::vector<RunData>& runs, const sim::MachineDefinition& nominal,
                        const AxisArray<Regression>& reg) {
  ModelPools pools;
  for (std::size_t r = 0; r < runs.size(); ++r) {
    RunErrors re;
    re.run = runs[r].run->dir.string();
    re.rows = runs[r].n;
    const std::size_t from = runs[r].n_fit, to = runs[r].n;
    for (std::size_t k = from; k < to; ++k) re.rows_compared += runs[r].interior[k] ? 1 : 0;
    errors_on(out, out.identified, runs[r], from, to, true, r == 0 ? &out.replay_before : nullptr, re.identified,
              &pools.identified);
    ReplayResult twin;
    std::vector<char> compared;
    errors_on(out, out.final_machine, runs[r], from, to, true, &twin, re.calibrated, &pools.calibrated, &compared);
    versus_regression(out, reg, runs[r], twin, compared, from, to, re);
    if (r == 0) out.replay_after = std::move(twin);
    errors_on(out, nominal, runs[r], from, to, false, nullptr, re.nominal, &pools.nominal);
    baselines(out, reg, runs[r], from, to, re, pools);
    out.fit_runs.push_back(std::move(re));
  }
  pool_runs(out.fit_runs, pools, out.pooled_fit);
}

/// Every model's errors on the whole of each validation run, pooled.
void errors_on_validation_runs(DataCalibration& out, const std::vector<MeasuredRun>& validate,
                               const sim::MachineDefinition& nominal, const AxisArray<Regression>& reg) {
  ModelPools pools;
  for (const MeasuredRun& v : validate) {
    std::vector<std::string> vnotes;
    RunData rd = prepare_run(v, out.axes, out.rounding, 0.0, vnotes);
    for (auto& n : vnotes) out.notes.push_back(n);
    RunErrors re;
    re.run = v.dir.string();
    re.rows = rd.n;
    for (std::size_t k = 0; k < rd.n; ++k) re.rows_compared += rd.interior[k] ? 1 : 0;
    ReplayResult twin;
    std::vector<char> compared;
    errors_on(out, out.final_machine, rd, 0, rd.n, true, &twin, re.calibrated, &pools.calibrated, &compared);
    versus_regression(out, reg, rd, twin, compared, 0, rd.n, re);
    errors_on(out, out.identified, rd, 0, rd.n, true, nullptr, re.identified, &pools.identified);
    errors_on(out, nominal, rd, 0, rd.n, false, nullptr, re.nominal, &pools.nominal);
    baselines(out, reg, rd, 0, rd.n, re, pools);
    out.validation_runs.push_back(std::move(re));
  }
  if (!out.validation_runs.empty()) pool_runs(out.validation_runs, pools, out.pooled_validation);
}

}  // namespace

// ---------------------------------------------------------------------------
// Calibration

namespace {


/// A log at kLawFitMaxPeriod_s or faster (at 2 ms or faster only, a 4 ms
/// log missed the cascade sweep's tracking check on all 14 runs; at 5 ms
/// or faster only, a 10 ms log on all 14 too, 0.025 to 0.12; the drive is
/// fitted on this speed at 5 ms or faster) with positions to 5 um or finer but no speed
/// column (a CNC that traces its position loop's command and output, and not
/// the speed it feeds back): the axis's speed is the central difference of
/// its logged position within each segment (one-sided at a segment's ends,
/// never across a jump), added to the run (the calibration's own copy) as
/// `<a>_v_mm_s` with a note. The velocity loop's law and the drive are then fitted on the axis's
/// own motion, as where the speed is logged; without it the drive's inertia
/// came out of the commanded acceleration, which the loop's torque does not
/// follow, and the velocity loop was not seen. At 1 um and 1 ms a count is
/// 1 mm/s of speed and 1000 mm/s^2 of acceleration, so the position is
/// low-passed (zero phase, at the identification's 50 Hz) before it is
/// differentiated, and the velocity command and the torque channels are
/// added low-passed alike (`lowpassed`): the velocity loop's law and the
/// drive are fitted through the same filter, which a linear law passes, so
/// the filter's shape does not bias them. The count's noise does, and more
/// the higher the cut-off, as a derivative raises it with frequency: on the
/// truth runs of the tests the inertia was 0.165, 0.204 and 0.211 raw
/// s^2/mm, for 0.211, at 200, 100 and 50 Hz.
void add_speed_from_position(std::vector<MeasuredRun>& own, const std::vector<RunData>& runs, DataCalibration& out) {
  const double q = out.rounding.kind == PositionRounding::Kind::kNone ? 0.0 : out.rounding.quantum_mm;
  for (std::size_t i = 0; i < own.size(); ++i) {
    MeasuredRun& r = own[i];
    const std::vector<Segment>& segs = runs[i].segments;
    const double dt = r.sample_period_s;
    if (!(dt <= kLawFitMaxPeriod_s + 1e-12 && q <= 0.005)) continue;
    // Slower than 6.7 ms the low-pass would stand near the log's Nyquist
    // rate: the speed is the five-point difference there, whose gain at a
    // fifth of the sample rate is 0.93 (the central difference's 0.76: at
    // 10 ms of the cascade sweep's loop, ringing at 20 Hz, the law read on
    // it came out at Kvp 16.3 for 12.6; on the five-point difference 13.1).
    const bool filter = 0.5 / dt > 1.5 * kSpeedCutoff_Hz;
    std::vector<std::string> derived;
    for (Axis a : out.axes) {
      const auto* x = r.trace.find(col(a, "_mm"));
      if (x == nullptr || r.trace.find(col(a, "_v_mm_s")) != nullptr) continue;
      const auto filtered = [&](const std::vector<double>& c) { return filter ? lowpass_in_segments(c, segs, dt) : c; };
      const std::vector<double> xf = filtered(*x);
      std::vector<double> v(x->size(), 0.0);
      for (const Segment& sg : segs) {
        if (sg.end < sg.begin + 2) continue;
        const std::vector<double> vs =
            filter ? derivative(std::span<const double>(xf.data() + sg.begin, sg.end - sg.begin), dt)
                   : derivative_five_point(std::span<const double>(xf.data() + sg.begin, sg.end - sg.begin), dt);
        std::copy(vs.begin(), vs.end(), v.begin() + static_cast<std::ptrdiff_t>(sg.begin));
      }
      // The channels a law on this speed is fitted with, through the same filter.
      std::vector<std::pair<std::string, std::vector<double>>> alike;
      for (const std::string& c : {col(a, "_vcmd_mm_s"), torque_channel(r, a).column})
        if (const auto* y = c.empty() || !filter ? nullptr : r.trace.find(c)) alike.emplace_back(lowpassed(c), filtered(*y));
      r.trace.names.push_back(col(a, "_v_mm_s"));
      r.trace.columns.push_back(std::move(v));
      for (auto& [name, y] : alike) {
        r.trace.names.push_back(name);
        r.trace.columns.push_back(std::move(y));
      }
      derived.push_back(std::string(axis_name(a)));
    }
    if (!derived.empty() && filter)
      out.notes.push_back(fmt::format("{}: no speed logged for {}: taken as the central difference of the logged "
                                      "position (every {:g} s, to {:g} mm), low-passed at {:g} Hz without phase",
                                      r.dir.string(), fmt::join(derived, ", "), dt, q > 0.0 ? q : 1e-6,
                                      kSpeedCutoff_Hz));
    else if (!derived.empty())
      out.notes.push_back(fmt::format("{}: no speed logged for {}: taken as the five-point difference of the logged "
                                      "position (every {:g} s, to {:g} mm), not low-passed (the log's Nyquist rate "
                                      "is under 1.5 times the {:g} Hz of the low-pass)",
                                      r.dir.string(), fmt::join(derived, ", "), dt, q > 0.0 ? q : 1e-6,
                                      kSpeedCutoff_Hz));
  }
}

/// A column of a run's own copy set (added, or replacing one of that name).
void set_column(io::TraceTable& t, const std::string& name, std::vector<double> values) {
  const auto it = std::find(t.names.begin(), t.names.end(), name);
  if (it == t.names.end()) {
    t.names.push_back(name);
    t.columns.push_back(std::move(values));
  } else {
    t.columns[static_cast<std::size_t>(it - t.names.begin())] = std::move(values);
  }
}

/// Rows a logged channel may sit off the position it is computed from.
constexpr int kMaxSkewRows = 3;

/// A logged velocity command that sits rows off the following error it is
/// computed from (a trace whose channels are sampled at different points of
/// the loop's cycle, or by different loggers): at 1 kHz, one row late put the
/// cascade sweep's validation tracking at 0.026 to 0.11 NRMS, every law fitted
/// on it being fitted across the skew. On logs at 10 ms or faster, the P law
/// vcmd = Kv e + kff v_ref is fitted with the command moved by -3 to 3 rows
/// (fitting rows, within segments); where a move fits with under half the
/// residual of the command as logged, the moved command is what the
/// identification reads (for_identification), said in a note. The errors
/// still compare the log as it is.
void align_velocity_commands(std::vector<MeasuredRun>& own, const std::vector<RunData>& runs, double Ts,
                             DataCalibration& out) {
  if (own.empty() || !(own.front().sample_period_s <= 1e-2 + 1e-12)) return;
  for (Axis a : out.axes) {
    const std::string vcmd = col(a, "_vcmd_mm_s");
    bool usable = true;
    for (const auto& r : own)
      usable = usable && r.trace.find(vcmd) != nullptr && r.trace.find(col(a, "_mm")) != nullptr;
    if (!usable) continue;
    // The fitting rows (away from segment ends by the largest move) with
    // their error and command's speed, once; the P law's residual with the
    // command taken `skew` rows later.
    std::vector<double> e, vr;
    std::vector<std::pair<std::size_t, std::size_t>> at;  // run, row
    for (std::size_t i = 0; i < own.size(); ++i) {
      const auto& ref = runs[i].smooth->trace.at(col(a, "_ref_mm"));
      const auto& x = own[i].trace.at(col(a, "_mm"));
      const std::vector<double> speed = loop_reference_speed(ref, runs[i].segments, own[i].sample_period_s, Ts);
      for (const Segment& sg : runs[i].segments) {
        const std::size_t end = std::min(sg.end, runs[i].n_fit);
        for (std::size_t k = sg.begin + 1 + kMaxSkewRows; k + kMaxSkewRows < end; ++k) {
          e.push_back(ref[k] - x[k]);
          vr.push_back(speed[k]);
          at.emplace_back(i, k);
        }
      }
    }
    std::vector<std::size_t> rows(e.size());
    std::iota(rows.begin(), rows.end(), std::size_t{0});
    std::vector<const std::vector<double>*> logged;
    for (const auto& r : own) logged.push_back(&r.trace.at(vcmd));
    const auto residual = [&](int skew) {
      std::vector<double> vc(at.size());
      for (std::size_t j = 0; j < at.size(); ++j)
        vc[j] = (*logged[at[j].first])[static_cast<std::size_t>(static_cast<std::ptrdiff_t>(at[j].second) + skew)];
      const LsqResult ls = least_squares({&e, &vr}, vc, rows);
      return ls.ok ? ls.residual_rms : std::numeric_limits<double>::infinity();
    };
    const double as_logged = residual(0);
    int best = 0;
    double best_res = as_logged;
    for (int skew = -kMaxSkewRows; skew <= kMaxSkewRows; ++skew) {
      if (skew == 0) continue;
      const double r = residual(skew);
      if (r < best_res) {
        best_res = r;
        best = skew;
      }
    }
    if (best == 0 || !(best_res < 0.5 * as_logged)) continue;
    // A reference the loop follows smoothed (loop_from_vcmd) also looks like
    // a late command: the skew is taken only where it fits better than the
    // best smoothing of the reference with the command as logged. Both on
    // the columns low-passed alike (zero phase, 50 Hz), as loop_from_vcmd
    // searches: a smoothing of two rows halves the steps of a reference
    // logged to the encoder's count at 1 kHz, which is no smoothing.
    if (std::abs(own.front().sample_period_s - Ts) <= 1e-6 * Ts && own.front().sample_period_s <= 5e-3 + 1e-12) {
      std::vector<std::array<std::vector<double>, 3>> lp;  // reference, position, command per run
      for (std::size_t i = 0; i < own.size(); ++i) {
        const double dt = own[i].sample_period_s;
        lp.push_back({lowpass_in_segments(runs[i].smooth->trace.at(col(a, "_ref_mm")), runs[i].segments, dt),
                      lowpass_in_segments(own[i].trace.at(col(a, "_mm")), runs[i].segments, dt),
                      lowpass_in_segments(*logged[i], runs[i].segments, dt)});
      }
      const auto law_fit = [&](int n, double lag_s, int delay, bool ff_given, int skew) {
        std::vector<double> es, vs, vc;
        for (std::size_t i = 0; i < own.size(); ++i) {
          const std::vector<double>& logged_ref = lp[i][0];
          const std::vector<double> ref = followed_reference(logged_ref, runs[i].segments, {n, lag_s, delay}, Ts);
          const std::vector<double> speed =
              loop_reference_speed(ff_given ? logged_ref : ref, runs[i].segments, own[i].sample_period_s, Ts);
          for (const auto& [run, k] : at)
            if (run == i) {
              es.push_back(ref[k] - lp[i][1][k]);
              vs.push_back(speed[k]);
              vc.push_back(lp[i][2][static_cast<std::size_t>(static_cast<std::ptrdiff_t>(k) + skew)]);
            }
        }
        return least_squares({&es, &vs}, vc, rows);
      };
      const LsqResult skewed = law_fit(1, 0.0, 0, false, best);
      const auto smoothed_fit = [&](int n, double lag_s, int delay, bool ff_given) {
        return law_fit(n, lag_s, delay, ff_given, 0);
      };
      if (!skewed.ok || best_reference_smoothing(smoothed_fit, Ts).residual <= skewed.residual_rms) continue;
    }
    for (std::size_t i = 0; i < own.size(); ++i) {
      auto& t = own[i].trace;
      for (const std::string& name : {vcmd, lowpassed(vcmd)}) {
        const auto* c = t.find(name);
        if (c == nullptr) continue;
        std::vector<double> moved(*c);
        for (const Segment& sg : runs[i].segments)
          for (std::size_t k = sg.begin; k < sg.end; ++k) {
            const auto j = std::clamp<std::ptrdiff_t>(static_cast<std::ptrdiff_t>(k) + best,
                                                      static_cast<std::ptrdiff_t>(sg.begin),
                                                      static_cast<std::ptrdiff_t>(sg.end) - 1);
            moved[k] = (*c)[static_cast<std::size_t>(j)];
          }
        set_column(t, name == vcmd ? for_identification(vcmd) : lowpassed(for_identification(vcmd)), std::move(moved));
      }
    }
    out.notes.push_back(fmt::format(
        "axis {}: {} is logged {} {} {} the following error it is computed from (the P law's residual {:.3g} mm/s "
        "there, {:.3g} as logged): identified on it moved back into line; the errors compare it as logged",
        axis_name(a), vcmd, std::abs(best), std::abs(best) == 1 ? "row" : "rows", best > 0 ? "after" : "before",
        best_res, as_logged));
  }
}

/// The law's six columns and a seventh, the lead of the logged reference
/// over the one the loop follows, fitted only where the feedforward takes
/// the reference as logged on a law that is exact (see
/// rebuild_velocity_commands).
constexpr std::size_t kLawColumns = 6;
constexpr std::size_t kLeadColumn = kLawColumns;
using LawColumns = std::vector<std::array<std::vector<double>, kLawColumns + 1>>;

/// The columns of the law that follow the reference (e, v_ref, Ie and the
/// lead) of one run into L[0], L[1], L[3] and L[kLeadColumn].
void reference_law_columns(const RunData& rd, Axis a, double Ts, bool filtered, const ReferenceSmoothingFit& sm,
                           std::array<std::vector<double>, kLawColumns + 1>& L) {
  // Filtered here, the reference as logged (a rebuilt one may be low-passed already).
  const auto& logged_ref = (filtered ? *rd.run : *rd.smooth).trace.at(col(a, "_ref_mm"));
  const std::vector<double> ref = followed_reference(logged_ref, rd.segments, sm, Ts);
  const auto& x = rd.run->trace.at(col(a, "_mm"));
  const double dt = rd.run->sample_period_s;
  L[0].assign(ref.size(), 0.0);
  L[3].assign(ref.size(), 0.0);
  L[kLeadColumn].assign(ref.size(), 0.0);
  L[1] = loop_reference_speed(sm.feedforward_as_given ? logged_ref : ref, rd.segments, dt, Ts);
  for (const Segment& sg : rd.segments) {
    double ie = 0.0;
    for (std::size_t k = sg.begin; k < sg.end; ++k) {
      const double e = ref[k] - x[k];
      ie += dt * e;
      L[0][k] = e;
      L[3][k] = ie;
      L[kLeadColumn][k] = logged_ref[k] - ref[k];
    }
  }
  if (filtered)
    for (std::size_t c : {0UL, 1UL, 3UL, kLeadColumn}) L[c] = lowpass_in_segments(L[c], rd.segments, dt);
}

/// The six columns of the command's law (rebuild_velocity_commands) per run:
/// e, v_ref, v, Ie, Ix, eps, each filtered alike where the speed was taken
/// from the position (e and v_ref so filtered also give the filtered command);
/// e, v_ref and Ie on the reference smoothed by `sm` (the feedforward's speed
/// on the logged one where sm says so).
/// With `unsmoothed` (the columns without a smoothing), v, Ix and eps are
/// taken from it.
LawColumns command_law_columns(const std::vector<RunData>& runs, Axis a, double Ts, bool filtered,
                               const ReferenceSmoothingFit& sm = {}, const LawColumns* unsmoothed = nullptr) {
  LawColumns law(runs.size());
  for (std::size_t i = 0; i < runs.size(); ++i) {
    auto& L = law[i];
    reference_law_columns(runs[i], a, Ts, filtered, sm, L);
    if (unsmoothed != nullptr) {
      // The columns that do not follow the reference, as computed without the smoothing.
      for (std::size_t c : {2UL, 4UL, 5UL}) L[c] = (*unsmoothed)[i][c];
      continue;
    }
    const auto& t = runs[i].run->trace;
    const auto& x = t.at(col(a, "_mm"));
    const auto& v = t.at(col(a, "_v_mm_s"));
    const double dt = runs[i].run->sample_period_s;
    for (std::size_t c : {2UL, 4UL, 5UL}) L[c].assign(x.size(), 0.0);
    for (const Segment& sg : runs[i].segments) {
      double iv = 0.0;
      for (std::size_t k = sg.begin; k < sg.end; ++k) {
        iv += dt * v[k];
        const double ix = x[k] - x[sg.begin];
        L[2][k] = v[k];
        L[4][k] = ix;
        L[5][k] = iv - ix - 0.5 * dt * v[k];
      }
    }
    if (filtered)
      for (std::size_t c : {4UL, 5UL}) L[c] = lowpass_in_segments(L[c], runs[i].segments, dt);
  }
  return law;
}

/// The white noise on a logged torque channel over the fitting rows, and
/// where a torque limit holds it: as TorqueClip, a flat top of over
/// kClippedRows fitting rows within 2 % and three times the noise of the
/// largest |torque| (held_from is the |torque| from which a row is held; +inf
/// where no limit is seen). The limit, not the law, sets those rows.
struct TorqueTop {
  double noise_rms{0.0};
  double held_from{std::numeric_limits<double>::infinity()};
};
TorqueTop torque_top(const std::vector<RunData>& runs, const std::string& channel) {
  TorqueTop top;
  double T_abs_max = 0.0;
  for (std::size_t i = 0; i < runs.size(); ++i) {
    const auto& ch = runs[i].run->trace.at(channel);
    for (const Segment& sg : runs[i].segments)
      for (std::size_t k = sg.begin; k < std::min(sg.end, runs[i].n_fit); ++k)
        T_abs_max = std::max(T_abs_max, std::abs(ch[k]));
  }
  top.noise_rms = fitting_rows_noise_rms(runs, channel);
  const double from = 0.98 * T_abs_max - 3.0 * top.noise_rms;
  std::size_t held = 0;
  for (std::size_t i = 0; i < runs.size(); ++i) {
    const auto& ch = runs[i].run->trace.at(channel);
    for (std::size_t k = 0; k < std::min(ch.size(), runs[i].n_fit); ++k) held += std::abs(ch[k]) >= from ? 1 : 0;
  }
  if (held >= kClippedRows && from > 0.0) top.held_from = from;
  return top;
}

/// The command's law fitted on the fitting rows less their segment's means,
/// the torque `lag` samples behind the columns, rows a limit holds left out.
struct CommandLawFit {
  LsqResult ls;
  std::size_t lag{0};
  double T_rms{0.0};
};
CommandLawFit fit_command_law(const std::vector<RunData>& runs, const LawColumns& law, const std::string& channel,
                              std::size_t lag, double held_from, bool with_lead = false) {
  const std::size_t n_col = with_lead ? kLawColumns + 1 : kLawColumns;
  std::array<std::vector<double>, kLawColumns + 1> X;
  std::vector<double> T;
  std::vector<std::size_t> seg_of_row;
  std::size_t g = 0;
  for (std::size_t i = 0; i < runs.size(); ++i) {
    const auto& t = runs[i].run->trace;
    const auto& ch = *filtered_alike(t, channel);
    const auto& ch_logged = t.at(channel);
    for (const Segment& sg : runs[i].segments) {
      const std::size_t end = std::min(sg.end, runs[i].n_fit);
      if (end < sg.begin + 3 + lag) continue;
      for (std::size_t k = sg.begin + 2 + lag; k < end; ++k) {
        if (std::abs(ch_logged[k]) >= held_from) continue;
        for (std::size_t c = 0; c < n_col; ++c) X[c].push_back(law[i][c][k - lag]);
        T.push_back(ch[k]);
        seg_of_row.push_back(g);
      }
      ++g;
    }
  }
  // Each segment's means taken off: its constant without a column.
  std::vector<double> n_seg(g, 0.0);
  std::vector<std::array<double, kLawColumns + 2>> mean(g, std::array<double, kLawColumns + 2>{});
  for (std::size_t k = 0; k < T.size(); ++k) {
    const std::size_t sg = seg_of_row[k];
    n_seg[sg] += 1.0;
    for (std::size_t c = 0; c < n_col; ++c) mean[sg][c] += X[c][k];
    mean[sg][kLawColumns + 1] += T[k];
  }
  CommandLawFit lf;
  lf.lag = lag;
  double t2 = 0.0;
  for (std::size_t k = 0; k < T.size(); ++k) {
    const std::size_t sg = seg_of_row[k];
    t2 += T[k] * T[k];
    for (std::size_t c = 0; c < n_col; ++c) X[c][k] -= mean[sg][c] / n_seg[sg];
    T[k] -= mean[sg][kLawColumns + 1] / n_seg[sg];
  }
  std::vector<std::size_t> rows(T.size());
  std::iota(rows.begin(), rows.end(), std::size_t{0});
  std::vector<const std::vector<double>*> cols;
  for (std::size_t c = 0; c < n_col; ++c) cols.push_back(&X[c]);
  lf.ls = least_squares(cols, T, rows);
  lf.T_rms = T.empty() ? 0.0 : std::sqrt(t2 / static_cast<double>(T.size()));
  return lf;
}

/// Kv and kff for a rebuilt command.
struct CommandGains {
  double Kv{0.0}, kff{0.0};
};

/// The gains the law's coefficients give, as rebuild_velocity_commands says:
/// the Kv from e first and, with an integral the fit sees, the Kv from Ie
/// second; none where the checks fail. Where the speed is taken from the
/// position, eps holds only what the filter and the difference leave, and
/// its coefficient says nothing of Ki.
std::vector<CommandGains> command_gains(const CommandLawFit& f, double dt, bool speed_logged, double noise_rms) {
  if (!f.ls.ok || f.ls.theta.size() < kLawColumns) return {};
  const auto& th = f.ls.theta;
  const auto& se = f.ls.stderr_theta;
  const auto less_noise = [&](double rms) { return std::sqrt(std::max(rms * rms - noise_rms * noise_rms, 0.0)); };
  if (!(less_noise(f.ls.residual_rms) < 0.3 * less_noise(f.T_rms))) return {};
  // Kvp, kff and Ki together (Kvp's coefficient holds Ki dt / 2).
  const bool integral = std::abs(th[4]) > 3.0 * se[4] || (speed_logged && std::abs(th[5]) > 3.0 * se[5]);
  double Kvp = -th[2], kff = th[1] / Kvp, Ki = 0.0;
  for (int it = 0; integral && it < 50; ++it) {
    if (std::abs(kff - 1.0) <= 0.1 && !speed_logged) return {};
    Ki = std::abs(kff - 1.0) > 0.1 ? th[4] / (kff - 1.0) : -th[5];
    Kvp = -th[2] - 0.5 * Ki * dt;
    kff = th[1] / Kvp;
  }
  if (!(Kvp > 0.0 && kff >= 0.0 && kff <= 1.5 && Ki >= 0.0)) return {};
  std::vector<CommandGains> gains{{(th[0] - Ki * kff) / Kvp, kff}};
  if (!(gains.front().Kv > 0.0)) return {};
  if (integral) {
    // Within 25 %, or within three standard errors of the coefficient the
    // second value comes from (eps's is the noisier: under 0.2 N m of noise
    // on the torque, Ki 2118 +- 224 from it for 1571).
    const auto near = [](double p, double q, double se_q) {
      return std::abs(p - q) <= std::max(0.25 * std::max(std::abs(p), std::abs(q)), 3.0 * se_q);
    };
    const CommandGains from_integral{th[3] / Ki, kff};
    if (!(Ki > 0.0 && (!speed_logged || near(Ki, -th[5], se[5])) && from_integral.Kv > 0.0 &&
          near(gains.front().Kv, from_integral.Kv, se[3] / Ki)))
      return {};
    gains.push_back(from_integral);
  }
  return gains;
}

/// The rebuilt command written into the runs (and filtered alike beside it
/// where the speed was taken from the position), replacing one written before.
void write_rebuilt_command(std::vector<MeasuredRun>& own, const std::vector<RunData>& runs, const LawColumns& law,
                           Axis a, double Ts, bool filtered, const CommandGains& g, const ReferenceSmoothingFit& sm) {
  const std::string name = for_identification(col(a, "_vcmd_mm_s"));
  for (std::size_t i = 0; i < own.size(); ++i) {
    auto& t = own[i].trace;
    std::vector<std::pair<std::string, std::vector<double>>> cols;
    {
      const auto& logged_ref = runs[i].smooth->trace.at(col(a, "_ref_mm"));
      const std::vector<double> ref = followed_reference(logged_ref, runs[i].segments, sm, Ts);
      const auto& x = t.at(col(a, "_mm"));
      const std::vector<double> vr = loop_reference_speed(sm.feedforward_as_given ? logged_ref : ref,
                                                          runs[i].segments, own[i].sample_period_s, Ts);
      std::vector<double> c(ref.size(), 0.0);
      for (const Segment& sg : runs[i].segments)
        for (std::size_t k = sg.begin; k < sg.end; ++k) c[k] = g.Kv * (ref[k] - x[k]) + g.kff * vr[k];
      cols.emplace_back(name, std::move(c));
    }
    if (filtered) {
      std::vector<double> cf(law[i][0].size());
      for (std::size_t k = 0; k < cf.size(); ++k) cf[k] = g.Kv * law[i][0][k] + g.kff * law[i][1][k];
      cols.emplace_back(lowpassed(name), std::move(cf));
    }
    for (auto& [n, values] : cols) set_column(t, n, std::move(values));
  }
}

/// The least part of the command law's residual, as a share of the torque's
/// RMS, that a smoothing of the reference must explain to be taken where the
/// command is rebuilt. Without the velocity command or the speed (the speed
/// from the 1 um encoder) the law leaves about 2 % of the torque; the truth's
/// 8 ms moving average took out 1.9 % of it (0.77 -> 0.54 of 28.4), the
/// best smoothing of the runs without one 0.1 % (0.556 -> 0.555).
constexpr double kSmoothingShareOfTorque = 0.005;

/// Smoothings of one delay whose command laws leave residuals within this
/// factor of the least are told apart by their two Kv: without the speed
/// the law's floor leaves the shape unresolved (the truth's 8 ms average
/// against a 6 ms average and a 1.2 ms lag: residual 0.559 against 0.556,
/// Kv 44.8 and 44.9 against 50.6 and 47.1).
constexpr double kSmoothingResidualTie = 1.02;

/// The coarse look before the smoothing's full search must find a smoothing
/// that leaves under this share of the law's residual: without the speed,
/// on the sweep's runs without a smoothing the best left 0.997 to 0.999 of
/// it; behind the truth's 8 ms average, 4 ms dead time and 5 ms lag, 0.23,
/// 0.49 and 0.90.
constexpr double kSmoothingLook = 0.97;

/// The fitting context of the command's law (rebuild_velocity_commands):
/// the runs and axis, the loop's and the log's periods, whether the columns
/// are low-passed, the torque channel, the level a limit holds it from, and
/// its noise.
struct CommandLaw {
  const std::vector<RunData>& runs;
  Axis a;
  double Ts{0.0}, dt{0.0};
  bool filtered{false};
  std::string channel;
  double held_from{0.0};
  double noise_rms{0.0};
  /// Whether the law of a smoothing `sm` has the lead column: where the
  /// feedforward takes the reference as logged, on a law that is exact (the
  /// speed logged or read from the law; against the low-passed encoder's
  /// speed the column takes up any smoothing).
  bool with_lead(const ReferenceSmoothingFit& sm) const { return sm.feedforward_as_given && !filtered; }
  /// The torque's largest lag behind the law tried, in rows (10 ms, 1 to 10).
  std::size_t max_lag() const { return static_cast<std::size_t>(std::clamp(std::lround(0.01 / dt), 1L, 10L)); }
  /// The law fitted at the torque's lag (0 to max_lag) that leaves the least residual.
  CommandLawFit best_lag(const LawColumns& columns, bool with_lead = false) const {
    CommandLawFit best = fit_command_law(runs, columns, channel, 0, held_from, with_lead);
    for (std::size_t lag = 1; lag <= max_lag(); ++lag) {
      CommandLawFit f = fit_command_law(runs, columns, channel, lag, held_from, with_lead);
      if (f.ls.ok && (!best.ls.ok || f.ls.residual_rms < best.ls.residual_rms)) best = std::move(f);
    }
    return best;
  }
};

/// The reference's smoothing (a CNC's after its interpolator), searched as
/// on a logged command (best_reference_smoothing) where the log samples at
/// the loop's period, with the law's torque lag as found without it, and
/// the lag then found again behind it. Taken where it explains a part of
/// the law's residual (in quadrature) of at least kSmoothingShareOfTorque
/// of the torque's RMS and leaves at most 0.9 of it.
/// `law` and `best` are the columns and fit without a smoothing on entry,
/// and those with the smoothing returned (none: unchanged).
ReferenceSmoothingFit command_law_smoothing(const CommandLaw& cl, LawColumns& law, CommandLawFit& best) {
  ReferenceSmoothingFit smoothing;
  const double residual_unsmoothed = best.ls.residual_rms;
  const auto explained = [&](double residual) {
    return residual < 0.9 * residual_unsmoothed &&
           std::sqrt(residual_unsmoothed * residual_unsmoothed - residual * residual) >=
               kSmoothingShareOfTorque * best.T_rms;
  };
  // Where the law leaves less than that share, there is nothing for it to explain.
  if (std::abs(cl.dt - cl.Ts) <= 1e-6 * cl.Ts && residual_unsmoothed >= kSmoothingShareOfTorque * best.T_rms) {
    // Searched twice on the same fits: with a dead time kept as on a logged
    // command (where it leaves 0.8 of the residual without it) and with
    // one kept wherever it fits better; both go to the choice below.
    std::vector<std::map<std::tuple<int, double, int, bool>, LsqResult>> fitted(cl.max_lag() + 1);
    const auto fit_at = [&](std::size_t lag) -> SmoothedLawFit {
      return [&, lag](int n, double lag_s, int delay, bool ff_given) {
        const auto key = std::make_tuple(n, lag_s, delay, ff_given);
        if (const auto it = fitted[lag].find(key); it != fitted[lag].end()) return it->second;
        LsqResult r = fit_command_law(cl.runs,
                                      command_law_columns(cl.runs, cl.a, cl.Ts, cl.filtered,
                                                          {n, lag_s, delay, ff_given}, &law),
                                      cl.channel, lag, cl.held_from,
                                      cl.with_lead({n, lag_s, delay, ff_given}))
                          .ls;
        fitted[lag].emplace(key, r);
        return r;
      };
    };
    // A coarse look first (plain averages, lags and dead times of about 1 to
    // 30 ms of delay, both ways of taking the feedforward): the full search
    // only where one of them leaves under kSmoothingLook of the residual.
    // The search then runs at every torque lag up to the larger of the
    // unsmoothed law's and the best look's (a dead time in the torque's path
    // behind a smoothing: a law without the smoothing may take up the dead
    // time in its delay, and the search would take the dead time for more
    // smoothing).
    ReferenceSmoothingFit looked;
    double looked_residual = kSmoothingLook * residual_unsmoothed;
    for (std::size_t lag = 0; lag <= best.lag; ++lag) {
      const SmoothedLawFit fit = fit_at(lag);
      for (const bool ff_given : {false, true}) {
        std::vector<ReferenceSmoothingFit> look;
        for (int n : {3, 5, 9, 17, 33, 65}) look.push_back({n, 0.0, 0, ff_given});
        for (double lag_s : {0.002, 0.005, 0.01, 0.02}) look.push_back({1, lag_s, 0, ff_given});
        for (int d : {1, 2, 4, 8, 16, 32}) look.push_back({1, 0.0, d, ff_given});
        for (const ReferenceSmoothingFit& c : look) {
          if (c.n > controller::kMaxCommandAverageTicks || (c.lag_s > 0.0 && c.lag_s < cl.Ts)) continue;
          const LsqResult r = fit(c.n, c.lag_s, c.delay, c.feedforward_as_given);
          if (r.ok && r.residual_rms < looked_residual) {
            looked = c;
            looked_residual = r.residual_rms;
          }
        }
      }
    }
    const bool worth = looked.any();
    std::size_t search_lags = best.lag;
    if (worth)
      search_lags = std::max(search_lags, cl.best_lag(command_law_columns(cl.runs, cl.a, cl.Ts, cl.filtered, looked, &law),
                                                      cl.with_lead(looked))
                                              .lag);
    ReferenceSmoothingFit sm, sm_any_delay;
    for (std::size_t lag = 0; worth && lag <= search_lags; ++lag) {
      const SmoothedLawFit fit = fit_at(lag);
      const ReferenceSmoothingFit at = best_reference_smoothing(fit, cl.Ts);
      if (at.residual < sm.residual) sm = at;
      const ReferenceSmoothingFit any = best_reference_smoothing(fit, cl.Ts, 1.0);
      if (any.residual < sm_any_delay.residual) sm_any_delay = any;
    }
    if (explained(std::min(sm.residual, sm_any_delay.residual))) {
      // The search's best, the plain average, lag and dead time of the same
      // delay at constant speed, and each part of the best alone, each at its
      // best torque lag; of those within kSmoothingResidualTie of the least
      // residual, the one whose law gives the two Kv closest (they agree on
      // the reference the loop follows, see command_gains).
      std::vector<ReferenceSmoothingFit> candidates;
      const auto add = [&](const ReferenceSmoothingFit& c) {
        if (c.n < 1 || c.n > controller::kMaxCommandAverageTicks || c.delay > controller::kMaxCommandDelayTicks ||
            (c.lag_s > 0.0 && c.lag_s < cl.Ts) || !c.any())
          return;
        for (const ReferenceSmoothingFit& o : candidates)
          if (o.n == c.n && o.lag_s == c.lag_s && o.delay == c.delay &&
              o.feedforward_as_given == c.feedforward_as_given)
            return;
        candidates.push_back(c);
      };
      add(sm);
      add(sm_any_delay);
      for (const ReferenceSmoothingFit& found : {sm, sm_any_delay}) {
        const double delay_periods = found.delay_periods(cl.Ts);
        const bool ffg = found.feedforward_as_given;
        add({static_cast<int>(std::lround(2.0 * delay_periods + 1.0)), 0.0, 0, ffg});
        add({1, delay_periods * cl.Ts, 0, ffg});
        add({1, 0.0, static_cast<int>(std::lround(delay_periods)), ffg});
        // Each part of a combination alone (against the floor a combination
        // may carry a part the loop does not have).
        add({found.n, 0.0, 0, ffg});
        add({1, found.lag_s, 0, ffg});
        add({1, 0.0, found.delay, ffg});
      }
      struct Tried {
        LawColumns law;
        CommandLawFit fit;
        double disagreement;
      };
      std::vector<Tried> tried;
      double least = std::numeric_limits<double>::infinity();
      for (const ReferenceSmoothingFit& c : candidates) {
        LawColumns L = command_law_columns(cl.runs, cl.a, cl.Ts, cl.filtered, c, &law);
        CommandLawFit f = cl.best_lag(L, cl.with_lead(c));
        const std::vector<CommandGains> g = command_gains(f, cl.dt, !cl.filtered, cl.noise_rms);
        const double disagreement = g.size() == 2 ? std::abs(g[0].Kv - g[1].Kv) / std::max(g[0].Kv, g[1].Kv)
                                                  : std::numeric_limits<double>::infinity();
        if (f.ls.ok) least = std::min(least, f.ls.residual_rms);
        tried.push_back({std::move(L), std::move(f), disagreement});
      }
      std::size_t chosen = 0;
      for (std::size_t j = 1; j < tried.size(); ++j)
        if (tried[j].fit.ls.ok && tried[j].fit.ls.residual_rms <= kSmoothingResidualTie * least &&
            (tried[j].disagreement < tried[chosen].disagreement ||
             !(tried[chosen].fit.ls.residual_rms <= kSmoothingResidualTie * least)))
          chosen = j;
      if (tried[chosen].fit.ls.ok && explained(tried[chosen].fit.ls.residual_rms)) {
        smoothing = candidates[chosen];
        law = std::move(tried[chosen].law);
        best = std::move(tried[chosen].fit);
      }
    }
  }
  return smoothing;
}

/// The cascade's position loop where a log at 2 ms or faster has the axis's
/// speed (logged, or taken from the position) and a torque channel but no
/// velocity command (a CNC whose trace leaves the position loop's output
/// out, or holds it dead). The velocity loop's PI acts on vcmd - v with
/// vcmd = Kv e + kff v_ref, integrating as the twin's law does
/// (I[k] = I[k-1] + dt (vcmd - v)[k]), so with the torque L samples behind:
///   T = Kvp (Kv e + kff v_ref - v) + Ki (Kv Ie + kff Iv_ref - Iv) + c,
/// I the sums times dt within a segment, c per segment. Iv_ref = Ix + e up
/// to a constant (Ix: the position less its value where the segment starts),
/// and Iv = Ix + (dt / 2) v + eps, where eps is what the logged speed's sum
/// and the position disagree by (backlash or a pitch error between motor and
/// table, the speed's noise; a few counts where they agree). So
///   T = (Kvp Kv + Ki kff) e + Kvp kff v_ref - (Kvp + Ki dt / 2) v
///       + Ki Kv Ie + Ki (kff - 1) Ix - Ki eps + c,
/// linear in six columns that are not near one another (the sums of the
/// reference and of the speed are, by the position, which is why the law is
/// not fitted on them as they stand: the normal equations are then singular
/// to 1e-11). The coefficients give Kvp, kff and Ki (from Ix, or from eps
/// where kff is near 1), and Kv twice: from Ie and from e. Fitted on the
/// fitting rows less their segment's means, at the lag L (0 to 10 ms) that
/// fits best. The command is rebuilt where the law explains most of the
/// torque (as identify_velocity_loop asks), Kvp and Kv are positive, kff is
/// within 0 to 1.5, and, with an integral the fit sees, both Ki (within 25 %)
/// and both Kv (within 25 %) agree; of the two Kv, the one whose command the
/// PI law (fit_velocity_loop) fits better. Where the CNC smooths the
/// reference before its loop (a moving average, a lag, a dead time), e, v_ref
/// and Ie are those of the smoothed reference: the smoothing is searched on
/// the law's columns as on a logged command, and the command rebuilt on it,
/// so that loop_from_vcmd finds it again. Where the feedforward takes the
/// reference as logged and only the error the smoothed one, the sum of the
/// feedforward's speed is the logged reference, not Ix + e: the lead of the
/// logged reference over the followed one is a seventh column (its
/// coefficient Ki kff). Only on an exact law: without the speed the floor
/// the encoder's low-passed speed leaves lets that column take up any
/// smoothing (the truth's 8 ms average was read as such a lag, tracking
/// 0.037 where it was 0.0013). The position alone shows only the
/// lag (1 - kff) / Kv: how the error settles after a change of speed tells
/// Kv from kff, but there the velocity loop's own error is as large (on the
/// position and speed of the truth runs of the tests, Kv came out at 14 to
/// 19 for 45), while the torque carries the command itself.
void rebuild_velocity_commands(std::vector<MeasuredRun>& own, const std::vector<RunData>& runs, double Ts,
                               DataCalibration& out) {
  if (own.empty() || !(own.front().sample_period_s <= 2e-3 + 1e-12)) return;
  for (Axis a : out.axes) {
    const std::string channel = torque_channel(own.front(), a).column;
    bool usable = !channel.empty();
    for (const auto& r : own)
      usable = usable && r.trace.find(col(a, "_vcmd_mm_s")) == nullptr && r.trace.find(channel) != nullptr &&
               r.trace.find(col(a, "_v_mm_s")) != nullptr && r.trace.find(col(a, "_mm")) != nullptr;
    if (!usable) continue;
    const bool filtered = has_lowpassed_twin(own.front().trace, channel);
    const TorqueTop top = torque_top(runs, channel);
    const double dt = own.front().sample_period_s;
    const CommandLaw cl{runs, a, Ts, dt, filtered, channel, top.held_from,
                        filtered ? top.noise_rms * lowpass_noise_gain(dt) : top.noise_rms};
    LawColumns law = command_law_columns(runs, a, Ts, filtered);
    CommandLawFit best = cl.best_lag(law);
    if (!best.ls.ok) continue;
    const double residual_unsmoothed = best.ls.residual_rms;
    const ReferenceSmoothingFit smoothing = command_law_smoothing(cl, law, best);
    const std::vector<CommandGains> gains = command_gains(best, dt, !filtered, cl.noise_rms);
    if (gains.empty()) continue;
    // Of two, the one whose command the PI law fits better.
    std::size_t chosen = 0;
    if (gains.size() == 2) {
      double best_law = 1e300;
      for (std::size_t j = 0; j < 2; ++j) {
        write_rebuilt_command(own, runs, law, a, Ts, filtered, gains[j], smoothing);
        const VelocityLoopFit vl = fit_velocity_loop(runs, a, channel, {.lag = best.lag});
        if (vl.ls.ok && vl.ls.residual_rms < best_law) {
          best_law = vl.ls.residual_rms;
          chosen = j;
        }
      }
    }
    write_rebuilt_command(own, runs, law, a, Ts, filtered, gains[chosen], smoothing);
    out.notes.push_back(fmt::format(
        "axis {}: no velocity command logged: rebuilt from the logged torque, position and speed through the "
        "velocity loop's PI law (residual {:.3g} of a torque RMS {:.3g}, the torque {} samples behind the law): "
        "Kv {:.4g} 1/s from {}{}, velocity feedforward {:.3g}{}",
        axis_name(a), best.ls.residual_rms, best.T_rms, best.lag, gains[chosen].Kv,
        chosen == 0 ? "the proportional part" : "the integral part",
        gains.size() == 2 ? fmt::format(" ({:.4g} from the {})", gains[1 - chosen].Kv,
                                        chosen == 0 ? "integral part" : "proportional part")
                          : std::string(),
        gains[chosen].kff,
        smoothing.any()
            ? fmt::format("; the law holds on the logged reference through {} (a CNC's smoothing after its "
                          "interpolator; residual {:.3g} on the reference as logged)",
                          smoothing_words(smoothing, Ts), residual_unsmoothed)
            : std::string()));
  }
}

/// The axes whose logged torque channel counts against the motion: the
/// inverse dynamics T = J a + B v + Tc sgn(v) + c, fitted on the fitting
/// rows as the drive is, gives both a negative inertia and a negative
/// Coulomb level, each by more than five standard errors (an inertia and a
/// friction are positive in any unit; a channel logged the other way round
/// turns both). Such a channel is negated in the runs calibrated here and
/// the machine carries torque_sign -1, so that its replays give the
/// channel as the log does.
AxisArray<bool> torque_against_motion(const AxisFit& f, const DataCalibration& out) {
  AxisArray<bool> flip{};
  for (Axis a : out.axes) {
    AxisFromData ax;
    ax.axis = a;
    ax.channel = torque_channel(f.r0, a);
    if (!ax.channel.present()) continue;
    const DriveRows d = drive_rows(f, ax);
    const std::vector<double> sgn = direction_signs(d);
    const LsqResult ls = least_squares({&d.acc, &d.vel, &sgn, &d.one}, d.T, d.rows);
    if (!ls.ok) continue;
    flip[index(a)] = ls.theta[0] < -5.0 * ls.stderr_theta[0] && ls.theta[2] < -5.0 * ls.stderr_theta[2];
  }
  return flip;
}

/// The torque channel of `a` the calibration reads (torque_channel), and its
/// low-passed twin, negated in the calibration's own copies of the runs.
void negate_torque_channel(std::vector<MeasuredRun>& runs, Axis a) {
  for (MeasuredRun& r : runs) {
    const std::string c = torque_channel(r, a).column;
    for (std::size_t j = 0; j < r.trace.names.size(); ++j)
      if (!c.empty() && (r.trace.names[j] == c || r.trace.names[j] == lowpassed(c)))
        for (double& v : r.trace.columns[j]) v = -v;
    if (r.log_rows)
      for (std::size_t j = 0; j < r.log_rows->trace.names.size(); ++j)
        if (!c.empty() && r.log_rows->trace.names[j] == c)
          for (double& v : r.log_rows->trace.columns[j]) v = -v;
  }
}

/// The motor's speed read from the velocity law, for an axis whose log has
/// no speed of its own: the law T = Kvp e + Ki (z + Ts e) + Jff a_ref + c,
/// with e the motor's speed error and z its running sum, solved for e row
/// by row on the logged torque and velocity command, the motor's speed then
/// vcmd - e. Each segment starts from z = 0 and c its first row's torque (an
/// axis at rest); an error in c decays in the loop's Tn, since the sum takes
/// it up. The encoder's speed, which the law is fitted on, differs from the
/// motor's wherever a gap or a lead error parts them: on the sweep's 40 um
/// gap the encoder's central difference misses the truth's motor speed by
/// 0.25 mm/s RMS (0.45 where the axis crawls), the law's speed by 0.006.
/// Taken where the law holds as plain PI (no dead time, no current loop's
/// lag, no limit that holds its integral, the torque the motor's own) on a
/// log of every loop period, and the torque's white noise passed into the
/// speed, noise / (Kvp + Ki Ts), is under a tenth of a count of the encoder
/// per row (a noisy torque gives a noisier speed than the low-passed
/// encoder's); nullopt elsewhere, with `why` saying how large that is.
std::optional<std::vector<double>> motor_speed_from_law(const RunData& rd, const AxisFromData& ax, double Ts,
                                                        double q_mm, std::string& why) {
  const controller::CascadeGains& g = ax.gains;
  if (!(ax.velocity_loop_from_data && g.tau_i_s == 0.0 && ax.torque_lag_rows() == 0.0 && ax.law_inner_ticks == 1 &&
        !ax.law_holds_integral_at_limit() && !ax.torque_command_logged && g.Kvp_torque_s_per_rad > 0.0 &&
        g.Tn_s > 0.0))
    return std::nullopt;
  const io::TraceTable& t = rd.run->trace;
  const double dt = rd.run->sample_period_s;
  if (std::abs(dt - Ts) > 1e-9 + 1e-6 * Ts) return std::nullopt;
  const std::vector<double>* T = t.find(ax.channel.column);
  const std::vector<double>* vc = t.find(velocity_command_column(t, ax.axis));
  const std::vector<double>* ref = t.find(col(ax.axis, "_ref_mm"));
  if (T == nullptr || vc == nullptr || ref == nullptr) return std::nullopt;
  // The torque's white noise: the median |second difference| over the
  // segments' rows (6 sigma^2 for white noise; 0.6745 sigma its median).
  std::vector<double> d2;
  for (const Segment& sg : rd.segments)
    for (std::size_t k = sg.begin + 1; k + 1 < sg.end; ++k)
      d2.push_back(std::abs((*T)[k + 1] - 2.0 * (*T)[k] + (*T)[k - 1]));
  if (d2.empty()) return std::nullopt;
  std::nth_element(d2.begin(), d2.begin() + static_cast<std::ptrdiff_t>(d2.size() / 2), d2.end());
  const double noise = d2[d2.size() / 2] / 0.6745 / std::sqrt(6.0);
  const double Kvp = g.Kvp_torque_s_per_rad, Ki = Kvp / g.Tn_s, gain = Kvp + Ki * dt;
  const double speed_noise = noise / gain, count_per_row = std::max(q_mm, 1e-3) / dt;
  why = fmt::format("the torque's noise {:.3g} (the log's unit) is {:.3g} mm/s of the law's speed, against {:.3g} "
                    "mm/s of one encoder count per row",
                    noise, speed_noise, count_per_row);
  if (!(speed_noise < 0.1 * count_per_row)) return std::nullopt;
  const double Jff = g.Jff_torque_s2_per_rad;
  std::vector<double> v(T->size(), 0.0);
  for (const Segment& sg : rd.segments) {
    if (sg.end <= sg.begin) continue;
    double z = 0.0;
    const double c = (*T)[sg.begin];
    for (std::size_t k = sg.begin; k < sg.end; ++k) {
      const double a_ref =
          k >= sg.begin + 2 ? ((*ref)[k] - 2.0 * (*ref)[k - 1] + (*ref)[k - 2]) / (dt * dt) : 0.0;
      const double e = ((*T)[k] - c - Ki * z - Jff * a_ref) / gain;
      z += dt * e;
      v[k] = (*vc)[k] - e;
    }
  }
  return v;
}

/// The replay's torque channels of `a` negated (back to the log's sign).
void negate_replay_torque(ReplayResult& rr, Axis a) {
  const std::size_t i = index(a);
  for (auto* ch : {&rr.u_V, &rr.i_A, &rr.Tm})
    for (double& v : (*ch)[i]) v = -v;
}

}  // namespace

namespace {

DataCalibration calibrate_from_data_pass(const std::vector<MeasuredRun>& fit, const std::vector<MeasuredRun>& validate,
                                         const sim::MachineDefinition& nominal, const DataCalibrationOptions& options,
                                         bool speed_from_law);

}  // namespace

/// A log without the motor's speed is calibrated twice where the velocity
/// law is seen on the encoder's speed and holds as plain PI: the first pass
/// identifies the law, the second calibrates on the runs with the motor's
/// speed read from that law (motor_speed_from_law) as if it were logged.
DataCalibration calibrate_from_data(const std::vector<MeasuredRun>& fit, const std::vector<MeasuredRun>& validate,
                                    const sim::MachineDefinition& nominal, const DataCalibrationOptions& options) {
  return calibrate_from_data_pass(fit, validate, nominal, options, true);
}

namespace {

DataCalibration calibrate_from_data_pass(const std::vector<MeasuredRun>& fit, const std::vector<MeasuredRun>& validate,
                                         const sim::MachineDefinition& nominal, const DataCalibrationOptions& options,
                                         bool speed_from_law) {
  if (fit.empty()) throw ConfigError("calibrate: no run to fit");
  DataCalibration out;
  out.fit_fraction = options.fit_fraction;
  check_fit_runs(fit, out);
  for (const auto& r : fit) check_no_runaway(r);
  for (const auto& r : validate) check_no_runaway(r);
  choose_rounding(fit, out);
  std::vector<MeasuredRun> fit_own = fit;  // the speed taken from the position and the torque's sign go in here
  const MeasuredRun& r0 = fit_own.front();
  const double Ts = controller_period(r0, options, out);
  std::vector<RunData> runs;
  for (const auto& r : fit_own)
    runs.push_back(prepare_run(r, out.axes, out.rounding, options.fit_fraction, out.notes));
  add_speed_from_position(fit_own, runs, out);
  const AxisArray<bool> flip = torque_against_motion(AxisFit{runs, Fitter{runs}, r0, Ts, out.rounding.quantum_mm}, out);
  std::vector<MeasuredRun> validate_flipped;
  for (Axis a : out.axes)
    if (flip[index(a)]) {
      if (validate_flipped.empty()) validate_flipped = validate;
      negate_torque_channel(fit_own, a);
      negate_torque_channel(validate_flipped, a);
      out.notes.push_back(fmt::format("axis {}: {} counts against the motion (the inverse dynamics on it give a "
                                      "negative inertia and a negative friction): calibrated on its negative, "
                                      "and the machine logs it with torque_sign -1",
                                      axis_name(a), torque_channel(fit.front(), a).column));
    }
  align_velocity_commands(fit_own, runs, Ts, out);
  rebuild_velocity_commands(fit_own, runs, Ts, out);
  const std::vector<MeasuredRun>& validate_own = validate_flipped.empty() ? validate : validate_flipped;
  const AxisFit axis_fit{runs, Fitter{runs}, r0, Ts, out.rounding.quantum_mm};
  out.identified = identify_machine(axis_fit, out);
  // The runs with the motor's speed read from the law, where every fitting
  // run gives it (calibrated again on them at the end).
  std::vector<MeasuredRun> with_speed;
  std::vector<std::string> said;
  if (speed_from_law) {
    with_speed = fit;
    for (const AxisFromData& ax : out.axis) {
      const std::string v = col(ax.axis, "_v_mm_s");
      if (!ax.identified || fit.front().trace.find(v) != nullptr) continue;
      std::vector<std::vector<double>> speeds;
      std::string why;
      for (const RunData& rd : runs)
        if (auto s = motor_speed_from_law(rd, ax, Ts, out.rounding.quantum_mm, why)) speeds.push_back(std::move(*s));
      if (speeds.size() != runs.size()) {
        if (!why.empty())
          out.notes.push_back(fmt::format("axis {}: the motor's speed is not read from the velocity law: {}",
                                          axis_name(ax.axis), why));
        continue;
      }
      for (std::size_t r = 0; r < with_speed.size(); ++r) set_column(with_speed[r].trace, v, std::move(speeds[r]));
      said.push_back(fmt::format("axis {}: no speed logged: the motor's speed read from the velocity law (Kvp {:.4g}, "
                                 "Tn {:.3g} s) on the logged torque and velocity command, as the motor's own "
                                 "({})",
                                 axis_name(ax.axis), ax.gains.Kvp_torque_s_per_rad, ax.gains.Tn_s, why));
    }
  }
  out.final_machine = out.identified;
  skip_unseen_effects(fit, out);
  choose_torque_command(out, runs, axis_fit);
  choose_coulomb_levels(out, runs);
  choose_velocity_loops(out, runs);
  place_law_lag(out, runs, false);
  place_law_dead_time(out, runs);
  try_smooth_friction(out, runs);
  rechoose_velocity_loops(out, runs);
  const FitRunErrors after_catalogue = search_catalogue_effects(out, runs);
  try_rising_friction(out, runs, after_catalogue);
  place_law_lag(out, runs, true);
  polish_final_velocity_loops(out, runs);
  const AxisArray<Regression> reg = fit_regressions(out, runs);
  errors_on_fit_part(out, runs, nominal, reg);
  errors_on_validation_runs(out, validate_own, nominal, reg);
  for (Axis a : out.axes)
    if (flip[index(a)]) {
      out.identified.axes[index(a)].logged_torque_sign = -1.0;
      out.final_machine.axes[index(a)].logged_torque_sign = -1.0;
      negate_replay_torque(out.replay_before, a);
      negate_replay_torque(out.replay_after, a);
    }
  if (said.empty()) return out;
  // Kept where it replays the fitting runs' held-out rows better (the sum of
  // the tracking and torque NRMS over the axes), as a structure is: the law
  // read on the encoder's speed can miss a dead time the motion shows, and
  // the speed read from it then carries the loop's command late.
  DataCalibration again = calibrate_from_data_pass(with_speed, validate, nominal, options, false);
  const auto score = [](const DataCalibration& c) {
    double sum = 0.0;
    for (const AxisFromData& ax : c.axis)
      for (const std::string& k : {col(ax.axis, "_err_mm"), ax.channel.column})
        if (const auto it = c.pooled_fit.calibrated.nrms.find(k); it != c.pooled_fit.calibrated.nrms.end())
          sum += it->second;
    return sum;
  };
  const double with_law = score(again), without = score(out);
  const std::string verdict = fmt::format("the fitting runs' held-out rows replayed to {:.4g} (tracking and torque "
                                          "NRMS summed over the axes) against {:.4g} on the encoder's speed",
                                          with_law, without);
  if (!(with_law < without)) {
    for (const std::string& n : said) out.notes.push_back(n + ": not kept, " + verdict);
    return out;
  }
  for (const std::string& n : said) again.notes.push_back(n + ": kept, " + verdict);
  return again;
}

}  // namespace

RunErrors evaluate_machine_on_run(const MeasuredRun& run, const sim::MachineDefinition& machine, ReplayResult* replay,
                                  std::vector<std::string>* notes) {
  std::vector<std::string> local;
  std::vector<std::string>& nt = notes ? *notes : local;
  std::vector<Axis> axes;
  for (Axis a : run.axes)
    if (machine.axes[index(a)].present) axes.push_back(a);
  if (axes.empty()) throw ConfigError(fmt::format("{}: machine {} defines none of the run's axes", run.dir.string(), machine.name));
  const PositionRounding rounding = detect_rounding(run);
  nt.push_back(rounding.describe());
  const RunData rd = prepare_run(run, axes, rounding, 0.0, nt);
  RunErrors re;
  re.run = run.dir.string();
  re.rows = rd.n;
  std::vector<char> cmp;
  ReplayResult rr = replay_segments(*rd.smooth, machine, rd.segments, rounding, &cmp);
  for (std::size_t k = 0; k < cmp.size(); ++k) cmp[k] = static_cast<char>(cmp[k] && rd.interior[k]);
  for (std::size_t k = 0; k < rd.n; ++k) re.rows_compared += rd.interior[k] ? 1 : 0;
  PoolSet pools, zero;
  const bool has_vcmd = sim::machine_loop_law(machine) == controller::LoopLaw::kCascade;
  add_errors(pools, run, rr, cmp, axes, 0, rd.n, true, has_vcmd, nullptr);
  add_errors(zero, run, rr, cmp, axes, 0, rd.n, true, has_vcmd, nullptr);
  for (auto& [k, p] : zero) p.res2 = p.meas2;
  re.calibrated = errors_from(pools);
  re.identified = re.calibrated;
  re.zero = errors_from(zero);
  if (replay) *replay = std::move(rr);
  return re;
}

void write_data_trace(const std::filesystem::path& path, const MeasuredRun& run, const ReplayResult& rr) {
  std::vector<std::string> names{"t_s"};
  std::vector<const std::vector<double>*> cols{&rr.t_s};
  for (Axis a : rr.axes) {
    const std::size_t i = index(a);
    if (rr.x_mm[i].empty()) continue;
    const std::string n(axis_name(a));
    names.insert(names.end(), {n + "_ref_mm", n + "_mm"});
    cols.insert(cols.end(), {&rr.x_ref_mm[i], &rr.x_mm[i]});
    const TorqueChannel ch = torque_channel(run, a);
    if (ch.present()) {
      names.push_back(ch.column);
      cols.push_back(ch.unit == "A" ? &rr.i_A[i] : (ch.unit == "V" ? &rr.u_V[i] : &rr.Tm[i]));
    }
    names.push_back(n + "_vcmd_mm_s");
    cols.push_back(&rr.vcmd_mm_per_s[i]);
  }
  io::TraceWriter w(path, names);
  std::vector<double> row(cols.size());
  for (std::size_t k = 0; k < rr.t_s.size(); ++k) {
    for (std::size_t c = 0; c < cols.size(); ++c) row[c] = (*cols[c])[k];
    w.write_row(row);
  }
  w.commit();
}

// ---------------------------------------------------------------------------
// Reports

namespace {

nlohmann::json run_errors_json(const RunErrors& e) {
  nlohmann::json j;
  j["run"] = e.run;
  j["rows"] = e.rows;
  j["rows_compared"] = e.rows_compared;
  j["error_nominal"] = e.nominal.to_json();
  j["error_calibrated"] = e.calibrated.to_json();
  j["baseline"] = {{"zero", e.zero.to_json()}, {"rigid_body_regression", e.regression.to_json()}};
  if (!e.twin_minus_regression.empty()) {
    nlohmann::json d = nlohmann::json::object();
    for (const auto& [k, p] : e.twin_minus_regression) {
      d[k] = {{"nrms_difference", p.difference}, {"interval_90", {p.lo, p.hi}}, {"blocks", p.blocks}};
      if (const auto it = e.largest_loss_s.find(k); it != e.largest_loss_s.end())
        d[k]["largest_loss"] = {{"from_s", it->second[0]},
                                {"to_s", it->second[1]},
                                {"rows", p.largest_loss_rows},
                                {"nrms_difference_without", p.difference_without_largest_loss}};
    }
    j["twin_minus_regression"] = d;
  }
  nlohmann::json why = nlohmann::json::object();
  for (const auto* ce : {&e.nominal, &e.calibrated, &e.regression})
    for (const auto& [k, w] : ce->not_computed) why[k] = w;
  if (!why.empty()) j["not_computed"] = why;
  return j;
}

/// Pooled over the fitting runs' held-out rows, from the per-run figures and
/// their compared rows (an approximation only where runs differ in level; the
/// per-run figures are exact and listed too).

}  // namespace

nlohmann::json data_calibration_report_json(const DataCalibration& r) {
  nlohmann::json j;
  nlohmann::json params = nlohmann::json::object();
  for (const AxisFromData& ax : r.axis) {
    nlohmann::json p;
    p["controller"] = "cascade";
    p["torque_channel"] = ax.channel.present() ? nlohmann::json(ax.channel.column) : nlohmann::json(nullptr);
    p["torque_unit"] = ax.channel.present() ? nlohmann::json(ax.channel.unit) : nlohmann::json(nullptr);
    p["lag_s"] = ax.lag_s;
    p["Kv"] = ax.gains.Kv_per_s;
    p["kff"] = ax.gains.kff;
    if (ax.gains.command_average_s > 0.0) p["command_average_s"] = ax.gains.command_average_s;
    if (ax.gains.command_lag_s > 0.0) p["command_lag_s"] = ax.gains.command_lag_s;
    if (ax.gains.command_delay_s > 0.0) p["command_delay_s"] = ax.gains.command_delay_s;
    if (ax.gains.feedforward_unsmoothed == 1.0) p["feedforward_unsmoothed"] = true;
    p["loop_source"] = ax.loop_source;
    if (ax.identified) {
      p["Kvp"] = ax.gains.Kvp_torque_s_per_rad;
      p["Tn"] = ax.gains.Tn_s;
      p["J"] = ax.J;
      p["B"] = ax.B;
      p["Tc_pos"] = ax.Tc_pos;
      p["Tc_neg"] = ax.Tc_neg;
      p["constant_load"] = ax.c;
      p["stderr"] = {{"J", ax.J_se}, {"B", ax.B_se}, {"Tc_pos", ax.Tc_pos_se}, {"Tc_neg", ax.Tc_neg_se},
                     {"constant_load", ax.c_se}};
      p["units"] = fmt::format("J {0} s^2/mm, B {0} s/mm, Tc and constant_load {0} (rg = 1 mm/rad, Kt = Ka = 1)",
                               ax.channel.unit);
      p["fit_rows"] = ax.fit_rows;
      p["coulomb_levels"] = ax.one_coulomb_level ? 1 : 2;
      if (!ax.coulomb_choice.empty()) p["coulomb_choice"] = ax.coulomb_choice;
      if (!ax.torque_timing.empty()) p["torque_timing"] = ax.torque_timing;
    } else {
      p["not_identified"] = ax.note;
    }
    params[std::string(axis_name(ax.axis))] = p;
  }
  j["parameters_identified"] = params;
  j["effects_added"] = nlohmann::json::array();
  for (const auto& e : r.effects)
    if (e.kept)
      j["effects_added"].push_back(
          {{"effect", e.effect}, {"axis", axis_name(e.axis)}, {"params", e.params}, {"evidence", e.evidence}});
  j["error_before"] = r.pooled_fit.identified.to_json();
  j["error_after"] = r.pooled_fit.calibrated.to_json();
  j["validation"] = fmt::format(
      "normalised RMS on the last {:.0f} % of the rows of each fitting run (not used for fitting), interior rows of "
      "each stitched segment only; currents and torques unfiltered in their own unit (the log's rate is below 400 Hz "
      "or the channel is not u), positions of the twin rounded as the log's",
      100.0 * (1.0 - r.fit_fraction));
  j["baseline"] = {{"zero", r.pooled_fit.zero.to_json()},
                   {"rigid_body_regression", r.pooled_fit.regression.to_json()}};
  j["fit_runs"] = nlohmann::json::array();
  for (const auto& e : r.fit_runs) j["fit_runs"].push_back(run_errors_json(e));
  j["validation_runs"] = nlohmann::json::array();
  for (const auto& e : r.validation_runs) j["validation_runs"].push_back(run_errors_json(e));
  if (!r.validation_runs.empty()) j["validation_pooled"] = run_errors_json(r.pooled_validation);
  j["effects_skipped"] = nlohmann::json::object();
  for (const auto& [e, why] : r.skipped) j["effects_skipped"][e] = why;
  j["effects_tried"] = nlohmann::json::array();
  for (const auto& e : r.effects) {
    nlohmann::json t = {{"effect", e.effect}, {"axis", axis_name(e.axis)}, {"params", e.params},
                        {"before", e.before}, {"after", e.after}, {"kept", e.kept}, {"evidence", e.evidence}};
    if (!e.before_channels.empty()) {
      t["held_out_before"] = e.before_channels;
      t["held_out_after"] = e.after_channels;
    }
    j["effects_tried"].push_back(t);
  }
  j["notes"] = r.notes;
  j["replays"] = r.replays;
  return j;
}

std::string data_calibration_report_markdown(const DataCalibration& r, const std::string& runs) {
  std::ostringstream o;
  o << "# Calibration of " << runs << "\n\n";
  o << "The runs name no machine the twin ships, so nothing was assumed of the machine: the loop, the drives and "
       "their units were found from the data alone.\n\n";
  o << "## What the data holds\n\n";
  for (const auto& n : r.notes) o << "- " << n << "\n";
  o << "\n## The machine found\n\n";
  for (const AxisFromData& ax : r.axis) {
    o << "### Axis " << axis_name(ax.axis) << "\n\n";
    o << fmt::format("- Position loop: Kv {:.4g} 1/s, velocity feedforward {:.3g}: the axis lags its command by "
                     "{:.3g} ms. Found from {}.\n",
                     ax.gains.Kv_per_s, ax.gains.kff, 1e3 * ax.lag_s, ax.loop_source);
    if (!ax.identified) {
      o << "- Drive: " << ax.note << "\n\n";
      continue;
    }
    const std::string u = ax.channel.unit == "raw" ? "(the log's unit)" : ax.channel.unit;
    o << fmt::format("- Drive, in the unit of {} {}: it takes {:.3g} +- {:.2g} {} to keep moving in +, {:.3g} +- "
                     "{:.2g} in -, and {:.3g} +- {:.2g} at rest (a constant load); {:.3g} {} per mm/s of speed and "
                     "{:.3g} {} per mm/s^2 of acceleration.\n",
                     ax.channel.column, u, ax.Tc_pos + ax.c, std::hypot(ax.Tc_pos_se, ax.c_se), u,
                     -(ax.Tc_neg - ax.c), std::hypot(ax.Tc_neg_se, ax.c_se), ax.c, ax.c_se, ax.B, u, ax.J, u);
    if (!ax.coulomb_choice.empty()) o << "- Coulomb levels: " << ax.coulomb_choice << ".\n";
    if (!ax.torque_timing.empty()) o << "- Torque timing: " << ax.torque_timing << ".\n";
    o << "\n";
  }
  auto table = [&](const char* title, const std::vector<RunErrors>& list) {
    if (list.empty()) return;
    o << "\n## " << title << "\n\n| run | channel | zero model | rigid-body regression | nominal machine | twin |\n"
      << "|---|---|---|---|---|---|\n";
    for (const auto& e : list) {
      std::vector<std::string> keys;
      for (const auto& [k, v] : e.zero.nrms) keys.push_back(k);
      for (const auto& k : keys) {
        auto get = [&](const ChannelErrors& ce) {
          const auto it = ce.nrms.find(k);
          return it == ce.nrms.end() ? std::string("not computed") : fmt::format("{:.4g}", it->second);
        };
        o << "| " << e.run << " | " << k << " | " << get(e.zero) << " | " << get(e.regression) << " | "
          << get(e.nominal) << " | " << get(e.calibrated) << " |\n";
      }
    }
    bool first = true;
    for (const auto& e : list)
      for (const auto& [k, p] : e.twin_minus_regression) {
        if (first) o << "\nThe twin against the regression, with the scatter of the rows (the 90 % interval of the "
                        "difference over blocks of 1 s of them, at least 10 rows, resampled):\n\n";
        first = false;
        const auto side = [](double x) {
          return x <= 0.0 ? fmt::format("{:.3g} below", -x) : fmt::format("{:.3g} above", x);
        };
        const std::string verdict = p.hi < 0.0   ? "the twin is better beyond the scatter of these rows"
                                    : p.lo > 0.0 ? "the regression is better beyond the scatter of these rows"
                                                 : "within the scatter of these rows (they cannot tell the two apart)";
        o << fmt::format("- {} {}: the twin's NRMS is {} the regression's (from {} to {}, {} blocks): {}", e.run, k,
                         side(p.difference), side(p.lo), side(p.hi), p.blocks, verdict);
        // Where the twin loses, the rows that lose most: on a short log one
        // stop can decide the comparison, and a reader looks there first.
        if (const auto it = e.largest_loss_s.find(k); it != e.largest_loss_s.end() && p.difference > 0.0)
          o << fmt::format("; it loses most in the log from {:.1f} s to {:.1f} s ({} rows), the place to look "
                           "first; without those rows its NRMS would be {} the regression's (a pointer, not a "
                           "verdict: any model's worst rows taken out favour it)",
                           it->second[0], it->second[1], p.largest_loss_rows,
                           side(p.difference_without_largest_loss));
        o << "\n";
      }
  };
  if (!r.effects.empty()) {
    // Each candidate once, in the order tried: what was chosen (the values the
    // fitting rows chose, none where nothing lowered them) and why it was kept
    // or not.
    o << "\n## Effects tried (kept where the held-out error falls)\n\n";
    for (const DataEffect& e : r.effects) {
      // A torque or a current of a machine identified from data is in the
      // unit of the axis's logged channel, whatever the parameter's name says.
      std::string channel_unit;
      for (const AxisFromData& ax : r.axis)
        if (ax.axis == e.axis && ax.channel.present())
          channel_unit = ax.channel.unit == "raw" ? "(the log's unit)" : ax.channel.unit;
      std::vector<std::string> values;
      for (const feeddrive::EffectParamDef& d : feeddrive::effect_params()) {
        if (d.effect != e.kind) continue;
        const auto it = e.params.find(param_key(e.kind, d.id));
        if (it == e.params.end()) continue;
        const bool torque_like = d.unit == "N m" || d.unit == "A";
        const std::string unit = torque_like && !channel_unit.empty() ? channel_unit : std::string(d.unit);
        values.push_back(unit == "1" ? fmt::format("{} {:.4g}", d.name, it->second)
                                     : fmt::format("{} {:.4g} {}", d.name, it->second, unit));
      }
      const bool untried = e.evidence.starts_with("not tried");
      o << fmt::format("- {} on {}{}{}: {}\n", e.effect, axis_name(e.axis),
                       e.kept ? ", **kept**" : (untried ? "" : ", not kept"),
                       values.empty() ? "" : fmt::format(" ({})", fmt::join(values, ", ")), e.evidence);
    }
  }
  table("Held-out errors (normalised RMS, lower is better)", r.fit_runs);
  table("Other runs (not used for fitting)", r.validation_runs);
  if (!r.skipped.empty()) {
    o << "\n## Effects this log cannot show\n\n";
    for (const auto& [e, why] : r.skipped) o << "- " << e << ": " << why << "\n";
  }
  return o.str();
}

}  // namespace twin::analysis
