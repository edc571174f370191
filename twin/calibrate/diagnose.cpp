#include "twin/calibrate/diagnose.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <optional>

#include <fmt/format.h>

#include "feeddrive/effect_torques.hpp"
#include "twin/calibrate/effect_detectors.hpp"
#include "twin/calibrate/signal.hpp"
#include "twin/core/error.hpp"

namespace twin::analysis {
namespace {

constexpr double kPi = std::numbers::pi;

struct Fit {
  bool ok{false};
  LsqResult with, without;
  double gain{0.0};
  double t_stat{0.0};
  std::vector<double> extra_Nm;  ///< fitted effect torque at every row
};

double corr_len(const AxisSignals& s) { return 1.0 / (2.0 * s.fc_Hz * s.dt_s); }

// The element at half the size in sorted order (the upper median); v non-empty.
double median_of(std::vector<double> v) {
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

double residual_rms(const std::vector<const std::vector<double>*>& cols, const std::vector<double>& theta,
                    const std::vector<double>& y, const std::vector<std::size_t>& rows) {
  if (rows.empty()) return 0.0;
  double sse = 0.0;
  for (std::size_t k : rows) {
    double p = 0.0;
    for (std::size_t j = 0; j < cols.size(); ++j) p += (*cols[j])[k] * theta[j];
    sse += (y[k] - p) * (y[k] - p);
  }
  return std::sqrt(sse / static_cast<double>(rows.size()));
}

// Base regressors plus `extra`, fitted on `fit_rows`; gain judged on `held_rows`.
Fit fit_additive(const AxisSignals& s, const std::vector<double>& T, const BaseRegressors& reg,
                 const std::vector<const std::vector<double>*>& extra, const std::vector<std::size_t>& fit_rows,
                 const std::vector<std::size_t>& held_rows) {
  Fit f;
  std::vector<const std::vector<double>*> base{&reg.acc, &reg.vel, &reg.pos, &reg.neg};
  std::vector<const std::vector<double>*> all = base;
  all.insert(all.end(), extra.begin(), extra.end());
  f.with = least_squares(all, T, fit_rows, corr_len(s));
  f.without = least_squares(base, T, fit_rows, corr_len(s));
  if (!f.with.ok || !f.without.ok || held_rows.size() < 50) return f;
  const double r0 = residual_rms(base, f.without.theta, T, held_rows);
  const double r1 = residual_rms(all, f.with.theta, T, held_rows);
  f.gain = r0 > 0.0 ? 1.0 - r1 / r0 : 0.0;
  double t2 = 0.0;
  for (std::size_t j = 0; j < extra.size(); ++j) {
    const double se = f.with.stderr_theta[4 + j];
    if (se > 0.0) t2 += std::pow(f.with.theta[4 + j] / se, 2);
  }
  f.t_stat = std::sqrt(t2 / static_cast<double>(extra.size()));
  f.extra_Nm.assign(s.n, 0.0);
  for (std::size_t k = 0; k < s.n; ++k)
    for (std::size_t j = 0; j < extra.size(); ++j) f.extra_Nm[k] += (*extra[j])[k] * f.with.theta[4 + j];
  f.ok = true;
  return f;
}

DriveIdentification base_of(const Fit& f, const feeddrive::DriveParams& d) {
  DriveIdentification id;
  id.ok = true;
  id.J_kg_m2 = std::max(0.05 * d.J_kg_m2, f.with.theta[0]);
  id.B_kg_m2_per_s = std::max(0.0, f.with.theta[1]);
  id.Tc_pos_Nm = std::max(0.0, f.with.theta[2]);
  id.Tc_neg_Nm = std::max(0.0, f.with.theta[3]);
  id.J_stderr = f.with.stderr_theta[0];
  id.B_stderr = f.with.stderr_theta[1];
  id.Tc_pos_stderr = f.with.stderr_theta[2];
  id.Tc_neg_stderr = f.with.stderr_theta[3];
  id.residual_rms_Nm = f.with.residual_rms;
  id.samples = f.with.n;
  return id;
}

std::vector<double> minus(const std::vector<double>& a, const std::vector<double>& b) {
  std::vector<double> r(a.size());
  for (std::size_t k = 0; k < a.size(); ++k) r[k] = a[k] - b[k];
  return r;
}

template <class Pred>
std::vector<std::size_t> filter_rows(const std::vector<std::size_t>& rows, Pred p) {
  std::vector<std::size_t> r;
  for (std::size_t k : rows)
    if (p(k)) r.push_back(k);
  return r;
}

// Second-order kinematic regressor: the torque that moving the motor by
// q(x) (mm) beyond the measured position takes, (J D^2 + B D) lp(q) / rg.
std::vector<double> kinematic_torque(const AxisSignals& s, const std::vector<double>& q_mm, double J, double B) {
  const auto ql = lowpass(q_mm, s.fc_Hz, 1.0 / s.dt_s);
  const auto d1 = derivative(ql, s.dt_s);
  const auto d2 = derivative(d1, s.dt_s);
  std::vector<double> r(s.n);
  for (std::size_t k = 0; k < s.n; ++k) r[k] = (J * d2[k] + B * d1[k]) / s.rg_mm_per_rad;
  return r;
}

// Rows where the reference reverses (its speed, above 0.05 mm/s, changes
// sign), each with the new direction.
std::vector<std::pair<std::size_t, double>> reversals(const AxisSignals& s) {
  std::vector<std::pair<std::size_t, double>> r;
  double last = 0.0;
  for (std::size_t k = 0; k < s.n; ++k) {
    const double v = s.v_ref_mm_per_s[k];
    if (std::abs(v) <= 0.05) continue;
    const double sg = v > 0.0 ? 1.0 : -1.0;
    if (last != 0.0 && sg != last) r.emplace_back(k, sg);
    last = sg;
  }
  return r;
}

}  // namespace

/// A detector's view of one axis: the signals, the torque the base model
/// explains, the drive, the replay's tracking residual, the effects already
/// on the axis, and the fits every detector starts from.
struct DiagnoseContext {
  const AxisSignals& s;
  const std::vector<double>& T;
  const feeddrive::DriveParams& d;
  const std::vector<double>& e_residual;  ///< measured minus replayed tracking error (may be empty)
  const std::vector<EffectKind>& present;
  BaseRegressors reg;
  std::vector<std::size_t> fit_moving{}, held_moving{}, fit_slow{}, held_slow{};
  DriveIdentification base{};
  double travel_mm{0.0};  ///< range of x over the fitting rows
  std::size_t current_lag{0};  ///< samples the logged current lags Ka u (measure_current_lag)
  std::vector<std::pair<std::size_t, double>> reversals{};  ///< reversals(s)
  /// Whether the effect is still to be looked for (not on the axis yet).
  bool wants(EffectKind k) const { return std::find(present.begin(), present.end(), k) == present.end(); }
};

namespace {

/// A candidate of `kind` found by the fit `f`, with the torque it leaves to the next detectors.
void add(std::vector<EffectCandidate>& out, const DiagnoseContext& c, EffectKind kind, const Fit& f, ParamSet params,
         std::string evidence, std::vector<double> T_after_Nm) {
  EffectCandidate e;
  e.set_kind(kind);
  e.axis = c.s.axis;
  e.params = std::move(params);
  e.signal_gain = f.gain;
  e.t_stat = f.t_stat;
  e.evidence = std::move(evidence);
  e.base = base_of(f, c.d);
  e.T_after_Nm = std::move(T_after_Nm);
  out.push_back(std::move(e));
}

/// A candidate whose fit added columns to the base model: the torque less what they explain is left.
void add(std::vector<EffectCandidate>& out, const DiagnoseContext& c, EffectKind kind, const Fit& f, ParamSet params,
         std::string evidence) {
  add(out, c, kind, f, std::move(params), std::move(evidence), minus(c.T, f.extra_Nm));
}

/// The fit of an effect that changes the torque itself (shifted, clipped) rather
/// than adding columns: `with` on the changed torque against `without`, its gain
/// from the held-out residuals before (h0) and after (h1).
Fit changed_torque_fit(const LsqResult& with, const LsqResult& without, double h0, double h1, double t_stat) {
  Fit g;
  g.ok = true;
  g.with = with;
  g.without = without;
  g.gain = h0 > 0.0 ? 1.0 - h1 / h0 : 0.0;
  g.t_stat = t_stat;
  return g;
}

/// sn[k], cs[k] := the sine and cosine of angle_rad(x_mm[k]) over the samples.
template <class Angle>
void sin_cos_of_position(const AxisSignals& s, Angle angle_rad, std::vector<double>& sn, std::vector<double>& cs) {
  for (std::size_t k = 0; k < s.n; ++k) {
    const double th = angle_rad(s.x_mm[k]);
    sn[k] = std::sin(th);
    cs[k] = std::cos(th);
  }
}

/// Takes `f` as `best` when it fitted with a smaller residual than best_rms.
bool keep_better_fit(Fit& f, Fit& best, double& best_rms) {
  if (!(f.ok && f.with.residual_rms < best_rms)) return false;
  best_rms = f.with.residual_rms;
  best = std::move(f);
  return true;
}

/// The amplitude and phase of the sine-cosine pair a fit added (its columns 4 and 5).
struct Harmonic {
  double amplitude;
  double phase_rad;
};
Harmonic added_harmonic(const Fit& f) {
  return {std::hypot(f.with.theta[4], f.with.theta[5]), std::atan2(f.with.theta[5], f.with.theta[4])};
}

}  // namespace

void detect_stribeck(const DiagnoseContext& c, std::vector<EffectCandidate>& out) {
  // Scan the Stribeck speed; the torque residual alone places it only roughly
  // (few samples at the lowest speeds, the filter smears reversals), so the
  // best fit and two slower ones go to the replay.
  struct Entry {
    double ws;
    Fit fit;
  };
  std::vector<Entry> fits;
  std::vector<double> psi(c.s.n);
  for (double ws = 0.3; ws < 40.0; ws *= 1.35) {
    for (std::size_t k = 0; k < c.s.n; ++k) {
      const double w = c.s.w_rad_per_s[k];
      psi[k] = (w > 0.0 ? 1.0 : w < 0.0 ? -1.0 : 0.0) * feeddrive::stribeck_shape(w, ws);
    }
    const auto held = filter_rows(c.held_slow, [&](std::size_t k) { return std::abs(c.s.w_rad_per_s[k]) < 2.0 * ws; });
    Fit f = fit_additive(c.s, c.T, c.reg, {&psi}, c.fit_slow, held);
    if (!f.ok || f.with.theta[4] <= 0.0) continue;
    fits.push_back({ws, std::move(f)});
  }
  if (fits.empty()) return;
  std::size_t best = 0;
  for (std::size_t i = 1; i < fits.size(); ++i)
    if (fits[i].fit.with.residual_rms < fits[best].fit.with.residual_rms) best = i;
  const double ws_best = fits[best].ws;
  const Fit& f = fits[best].fit;
  const double excess = f.with.theta[4];
  const double Tc_mean = 0.5 * (std::max(0.0, f.with.theta[2]) + std::max(0.0, f.with.theta[3]));
  add(out, c, EffectKind::kStribeck, f,
      {{EffectParam::stribeck_Ts_static, Tc_mean + excess}, {EffectParam::stribeck_ws, ws_best}},
      fmt::format("friction excess {:.3f} N m (t = {:.1f}) below ws = {:.2g} rad/s cuts the held-out low-speed "
                  "torque residual by {:.0f} %",
                  excess, f.t_stat, ws_best, 100.0 * f.gain));
  // The low-pass smears reversals: a rise at a few rad/s reads as a smaller
  // one at a higher speed. The replay on the fitting part chooses among
  // slower and stronger versions of it.
  // Each set's J, B and Coulomb levels are refitted with its own Stribeck
  // curve (friction Tc (1 - g) + Ts g, g = exp(-(w/ws)^2), as the drive
  // has it): levels fitted beside a fast curve are too low for a slow one.
  std::vector<double> pos(c.s.n), neg(c.s.n), y(c.s.n);
  auto refit = [&](double Ts, double ws) {
    for (std::size_t k = 0; k < c.s.n; ++k) {
      const double w = c.s.w_rad_per_s[k];
      const double g = feeddrive::stribeck_shape(w, ws);
      pos[k] = c.reg.pos[k] * (1.0 - g);
      neg[k] = c.reg.neg[k] * (1.0 - g);
      y[k] = c.T[k] - Ts * (w > 0.0 ? 1.0 : w < 0.0 ? -1.0 : 0.0) * g;
    }
    Fit g;
    g.with = least_squares({&c.reg.acc, &c.reg.vel, &pos, &neg}, y, c.fit_slow, corr_len(c.s));
    if (!g.with.ok) return out.back().base;
    return base_of(g, c.d);
  };
  auto& cand = out.back();
  for (double ws : {0.125, 0.18, 0.25, 0.37, 0.5, 0.75, 1.0})
    for (double m : {1.25, 1.75, 2.25}) {
      if (ws >= 0.75 && m > 2.0) continue;
      const double Ts = Tc_mean + m * excess;
      cand.param_grid.push_back({{EffectParam::stribeck_Ts_static, Ts}, {EffectParam::stribeck_ws, ws * ws_best}});
      cand.grid_base.push_back(refit(Ts, ws * ws_best));
    }
}

namespace {

}  // namespace

void detect_cogging(const DiagnoseContext& c, std::vector<EffectCandidate>& out) {
  const double fs = 1.0 / c.s.dt_s;
  double best_rms = 1e300;
  int best_n = 0;
  Fit best;
  std::vector<double> sn(c.s.n), cs(c.s.n);
  for (int n = 1; n <= 48; ++n) {
    if (2.0 * kPi * c.s.rg_mm_per_rad / n > 0.5 * c.travel_mm) continue;  // two periods at least
    sin_cos_of_position(
        c.s, [&](double x_mm) { return feeddrive::cogging_angle_rad(n, x_mm, c.s.rg_mm_per_rad); }, sn, cs);
    const auto sl = lowpass(sn, c.s.fc_Hz, fs);
    const auto cl = lowpass(cs, c.s.fc_Hz, fs);
    Fit f = fit_additive(c.s, c.T, c.reg, {&sl, &cl}, c.fit_moving, c.held_moving);
    if (keep_better_fit(f, best, best_rms)) best_n = n;
  }
  if (!best.ok) return;
  const Harmonic h = added_harmonic(best);
  add(out, c, EffectKind::kCogging, best,
      {{EffectParam::cogging_amplitude_Nm, h.amplitude}, {EffectParam::cogging_cycles_per_rev, best_n},
       {EffectParam::cogging_phase_rad, h.phase_rad}},
      fmt::format("torque ripple {:.3f} N m at {} cycles per motor revolution (period {:.3g} mm, t = {:.1f}) cuts the "
                  "held-out torque residual by {:.0f} %",
                  h.amplitude, best_n, 2.0 * kPi * c.s.rg_mm_per_rad / best_n, best.t_stat, 100.0 * best.gain));
}

void detect_screw_pitch_error(const DiagnoseContext& c, std::vector<EffectCandidate>& out) {
  double best_rms = 1e300, best_P = 0.0;
  Fit best;
  std::vector<double> sn(c.s.n), cs(c.s.n);
  // A periodic error is told from a slow drift only if the travel holds two periods.
  const double P_max = 0.5 * c.travel_mm;
  auto try_period = [&](double P) {
    sin_cos_of_position(c.s, [P](double x_mm) { return feeddrive::screw_pitch_angle_rad(x_mm, P); }, sn, cs);
    // The motor sits at x - A sin(...): its torque lacks (J D^2 + B D) of that.
    auto ks = kinematic_torque(c.s, sn, c.base.J_kg_m2, c.base.B_kg_m2_per_s);
    auto kc = kinematic_torque(c.s, cs, c.base.J_kg_m2, c.base.B_kg_m2_per_s);
    for (auto& v : ks) v = -v;
    for (auto& v : kc) v = -v;
    Fit f = fit_additive(c.s, c.T, c.reg, {&ks, &kc}, c.fit_moving, c.held_moving);
    if (keep_better_fit(f, best, best_rms)) best_P = P;
  };
  for (double P = 1.0; P <= P_max; P *= 1.06) try_period(P);
  // The coarse scan places the period to 6 %; over a travel of many periods
  // that is a phase error the replay sees (0.3 % over 100 mm of a 7 mm
  // period is 0.9 rad at the ends). Refine to 0.4 %, then to 0.05 %.
  for (const auto& [span, step] : {std::pair{1.06, 1.004}, std::pair{1.005, 1.0005}}) {
    if (!best.ok) break;
    const double P0 = best_P;
    for (double P = P0 / span; P <= std::min(P_max, P0 * span); P *= step) try_period(P);
  }
  if (!best.ok) return;
  const Harmonic h = added_harmonic(best);
  // A lead error under half an encoder count is not resolved by the data;
  // replayed, it only moves the quantisation boundaries.
  if (c.s.encoder_resolution_mm > 0.0 && h.amplitude < 0.5 * c.s.encoder_resolution_mm) return;
  add(out, c, EffectKind::kScrewPitchError, best,
      {{EffectParam::screw_pitch_error_amplitude_mm, h.amplitude}, {EffectParam::screw_pitch_error_period_mm, best_P},
       {EffectParam::screw_pitch_error_phase_rad, h.phase_rad}},
      fmt::format("lead error {:.4f} mm with period {:.3g} mm (t = {:.1f}): the torque to follow it cuts the held-out "
                  "torque residual by {:.0f} %",
                  h.amplitude, best_P, best.t_stat, 100.0 * best.gain));
}

namespace {

// Backlash seen at reversals: with the encoder on the table, the motor turns
// back through the gap while the table stands, so the measured position lags
// the model's by up to about half the gap just after every reversal of the
// reference, in the new direction. The median over reversals of the peak of
// that signed residual (measured minus model tracking error) in the 50 ms
// after each reversal sizes the gap; a grid around it goes to the replay.
void try_backlash_reversals(const DiagnoseContext& c, const std::vector<double>& e_res, std::vector<EffectCandidate>& out) {
  if (e_res.size() != c.s.n) return;
  const double q = c.s.encoder_resolution_mm > 0.0 ? c.s.encoder_resolution_mm : 0.001;
  const auto span = static_cast<std::size_t>(std::lround(0.05 / c.s.dt_s));
  std::vector<double> fit_peaks, held_peaks;
  for (const auto& [k, sg] : c.reversals) {
    if (k + span > c.s.n) continue;
    // e_res is model minus measured position: positive where the table lags.
    double peak = -1e300;
    for (std::size_t j = k; j < k + span; ++j) peak = std::max(peak, sg * e_res[j]);
    (k + span <= c.s.n_fit ? fit_peaks : held_peaks).push_back(peak);
  }
  if (fit_peaks.size() < 4 || held_peaks.size() < 2) return;
  const double p_fit = median_of(fit_peaks), p_held = median_of(held_peaks);
  // A model without the gap leaves about one encoder count of such peaks.
  if (p_fit < 2.5 * q || p_held < 2.0 * q) return;
  const double gap = 2.0 * p_fit;
  EffectCandidate e;
  e.set_kind(EffectKind::kBacklash);
  e.axis = c.s.axis;
  e.params = {{EffectParam::backlash_gap_mm, gap}};
  for (double m : {0.6, 0.8, 1.2, 1.5, 2.0}) e.param_grid.push_back({{EffectParam::backlash_gap_mm, m * gap}});
  e.signal_gain = 1.0 - q / p_held;
  e.t_stat = p_held / (0.5 * q);
  e.evidence = fmt::format(
      "after a reversal the table lags the model by a median peak of {:.4f} mm ({} reversals fitted) and {:.4f} mm "
      "({} held out), {:.1f} encoder counts: lost motion of a gap of about {:.4f} mm",
      p_fit, fit_peaks.size(), p_held, held_peaks.size(), p_held / q, gap);
  e.base = c.base;
  e.T_after_Nm = c.T;
  out.push_back(std::move(e));
}

// Backlash with the loop closed on the table: across the gap the motor moves
// and the table does not, the integral winds up and the loop hunts from one
// flank of the gap to the other. At standstill, where the nominal plant only
// chatters by an encoder count, the tracking error then spreads over several
// counts. The spread at standstill sizes the gap; the candidates are judged by
// the hunting statistic, since a replay hunts out of phase with the run.
bool try_backlash_hunting(const DiagnoseContext& c, std::vector<EffectCandidate>& out) {
  const double q = c.s.encoder_resolution_mm;
  if (!(q > 0.0)) return false;
  const auto window = std::max<std::size_t>(8, static_cast<std::size_t>(std::lround(0.02 / c.s.dt_s)));
  const auto settle = static_cast<std::size_t>(std::lround(0.1 / c.s.dt_s));
  std::vector<double> e(c.s.n);
  for (std::size_t k = 0; k < c.s.n; ++k) e[k] = c.s.x_ref_mm[k] - c.s.x_mm[k];
  // Standstill windows: the reference has not changed for `settle` rows, and
  // is unchanged to the window's end. The stop before the first motion is left out.
  std::vector<double> fit_sp, held_sp;
  std::size_t still_since = 0;
  bool moved = false;
  std::size_t k = 1;
  while (k + window <= c.s.n) {
    if (c.s.x_ref_mm[k] != c.s.x_ref_mm[k - 1]) {
      still_since = k;
      moved = true;
      ++k;
      continue;
    }
    if (!moved || k - still_since < settle) {
      ++k;
      continue;
    }
    bool still = true;
    for (std::size_t j = k; j < k + window && still; ++j) still = c.s.x_ref_mm[j] == c.s.x_ref_mm[k - 1];
    if (!still) {
      ++k;
      continue;
    }
    const double sp = window_spread(e, k, k + window, window).front();
    (k + window <= c.s.n_fit ? fit_sp : held_sp).push_back(sp);
    k += window;
  }
  if (fit_sp.size() < 5 || held_sp.size() < 5) return false;
  const double s_fit = median_of(fit_sp), s_held = median_of(held_sp);
  // Quantisation alone spreads by q / sqrt(12); chatter by one count about q / 2.
  // A hunt is a spread of two counts and more, in both parts of the run.
  if (s_fit < 2.0 * q || s_held < 2.0 * q) return false;
  const double q_spread = q / std::sqrt(12.0);
  EffectCandidate e_c;
  e_c.set_kind(EffectKind::kBacklash);
  e_c.axis = c.s.axis;
  e_c.params = {{EffectParam::backlash_gap_mm, s_fit}};
  // Gaps from 0.6 to 1.6 times the spread. (A finer grid finds sets closer
  // on the fitting part whose hunt is no more in phase on the held-out part:
  // the phase of a limit cycle is not a smooth function of the gap.)
  for (double m : {0.6, 0.7, 0.8, 0.9, 1.1, 1.25, 1.4, 1.6})
    e_c.param_grid.push_back({{EffectParam::backlash_gap_mm, m * s_fit}});
  e_c.signal_gain = 1.0 - q_spread / s_held;
  e_c.t_stat = s_held / q_spread;
  e_c.judged_by_hunting = true;
  e_c.evidence = fmt::format(
      "at standstill the tracking error hunts with a spread of {:.4f} mm (fitting part, {} windows of {:.0f} ms) and "
      "{:.4f} mm (held out, {} windows), {:.1f} encoder counts where quantisation leaves {:.2f}: a limit cycle across "
      "a gap in the loop",
      s_fit, fit_sp.size(), 1e3 * static_cast<double>(window) * c.s.dt_s, s_held, held_sp.size(), s_held / q,
      q_spread / q);
  e_c.base = c.base;
  e_c.T_after_Nm = c.T;
  out.push_back(std::move(e_c));
  return true;
}

}  // namespace

void detect_backlash(const DiagnoseContext& c, std::vector<EffectCandidate>& out) {
  try_backlash_hunting(c, out);
  try_backlash_reversals(c, c.e_residual, out);
}

namespace {

}  // namespace

void detect_position_dependent_friction(const DiagnoseContext& c, std::vector<EffectCandidate>& out) {
  const auto& rows = c.fit_moving;
  if (rows.size() < 500) return;
  // Residual of the base fit, signed by the direction of motion, binned over x.
  const LsqResult b = least_squares({&c.reg.acc, &c.reg.vel, &c.reg.pos, &c.reg.neg}, c.T, rows, corr_len(c.s));
  if (!b.ok) return;
  std::vector<double> rho(c.s.n, 0.0);
  double lo = 1e300, hi = -1e300;
  for (std::size_t k : rows) {
    const double pred = c.reg.acc[k] * b.theta[0] + c.reg.vel[k] * b.theta[1] + c.reg.pos[k] * b.theta[2] +
                        c.reg.neg[k] * b.theta[3];
    rho[k] = (c.T[k] - pred) * (c.s.w_rad_per_s[k] > 0.0 ? 1.0 : -1.0);
    lo = std::min(lo, c.s.x_mm[k]);
    hi = std::max(hi, c.s.x_mm[k]);
  }
  constexpr std::size_t kBins = 60;
  const Bins bins = bin_means(c.s.x_mm, rho, rows, lo, hi, kBins);
  double best = 0.0;
  std::size_t bi = 0, bj = 0;
  for (std::size_t i = 0; i < kBins; ++i) {
    double sum = 0.0;
    double cnt = 0.0;
    for (std::size_t j = i; j < kBins; ++j) {
      sum += bins.mean[j] * static_cast<double>(bins.count[j]);
      cnt += static_cast<double>(bins.count[j]);
      if (cnt < 200 || j - i + 1 == kBins) continue;
      const double score = sum > 0.0 ? sum * sum / cnt : 0.0;
      if (score > best) {
        best = score;
        bi = i;
        bj = j;
      }
    }
  }
  if (best <= 0.0) return;
  const double w = (hi - lo) / static_cast<double>(kBins);
  const double x0 = lo + w * static_cast<double>(bi), x1 = lo + w * static_cast<double>(bj + 1);
  std::vector<double> psi(c.s.n, 0.0);
  for (std::size_t k = 0; k < c.s.n; ++k)
    if (feeddrive::in_friction_band(c.s.x_mm[k], x0, x1))
      psi[k] = c.s.w_rad_per_s[k] > 0.0 ? 1.0 : c.s.w_rad_per_s[k] < 0.0 ? -1.0 : 0.0;
  const auto held = filter_rows(c.held_moving, [&](std::size_t k) { return psi[k] != 0.0; });
  Fit f = fit_additive(c.s, c.T, c.reg, {&psi}, c.fit_moving, held);
  if (!f.ok || f.with.theta[4] <= 0.0) return;
  add(out, c, EffectKind::kPositionDependentFriction, f,
      {{EffectParam::position_dependent_friction_dTc_Nm, f.with.theta[4]},
       {EffectParam::position_dependent_friction_x_start_mm, x0},
       {EffectParam::position_dependent_friction_x_end_mm, x1}},
      fmt::format("friction {:+.3f} N m (t = {:.1f}) between x = {:.1f} and {:.1f} mm cuts the held-out torque "
                  "residual there by {:.0f} % ({} held-out samples in the band)",
                  f.with.theta[4], f.t_stat, x0, x1, 100.0 * f.gain, held.size()));
}

// load_dependent_friction: friction that grows with the motor's torque,
// fitted with the drive as a column load sgn(w). Where u is logged (the
// loop's own command: exact, not measured) the load is |Kt Ka u|, low-passed
// as the torque is. The FADAL law's u chatters with the encoder's counts,
// and the friction follows the chatter's magnitude, which the low-passed
// torque averages away: the drive's own torque put the truth's 5 % at 1.2 %.
// From a measured current, whose noise would then sit on both sides of the
// fit, the load is |T^|, the drive's own torque on the row (the base fit's,
// with the friction found so far, refined twice). Proposed where its share
// is positive (at most 0.5), with the base drive refitted beside it.
void detect_load_dependent_friction(const DiagnoseContext& c, std::vector<EffectCandidate>& out) {
  const auto& rows = c.fit_moving;
  if (rows.size() < 500) return;
  std::vector<double> dir(c.s.n, 0.0);
  for (std::size_t k = 0; k < c.s.n; ++k)
    dir[k] = c.s.w_rad_per_s[k] > 0.0 ? 1.0 : (c.s.w_rad_per_s[k] < 0.0 ? -1.0 : 0.0);
  std::vector<double> psi(c.s.n, 0.0);
  if (c.s.has_u && c.s.u_raw_V.size() == c.s.n) {
    std::vector<double> load(c.s.n);
    for (std::size_t k = 0; k < c.s.n; ++k) load[k] = std::abs(c.d.Ka_A_per_V * c.d.Kt_Nm_per_A * c.s.u_raw_V[k]);
    load = lowpass(load, c.s.fc_Hz, 1.0 / c.s.dt_s);
    for (std::size_t k = 0; k < c.s.n; ++k) psi[k] = dir[k] * load[k];
  } else if (!fit_with_own_torque_load({&c.reg.acc, &c.reg.vel, &c.reg.pos, &c.reg.neg}, c.T, rows, dir,
                                       corr_len(c.s), 3, psi)
                  .ok) {
    return;
  }
  const Fit fa = fit_additive(c.s, c.T, c.reg, {&psi}, c.fit_moving, c.held_moving);
  if (!fa.ok || !(fa.with.theta[4] > 0.0 && fa.with.theta[4] <= 0.5)) return;
  add(out, c, EffectKind::kLoadDependentFriction, fa,
      {{EffectParam::load_dependent_friction_fraction, fa.with.theta[4]}},
      fmt::format("friction that grows with the drive's load, {:.3g} % of the motor's torque (t = {:.1f}), as a "
                  "screw loses under load, cuts the held-out torque residual by {:.0f} %",
                  100.0 * fa.with.theta[4], fa.t_stat, 100.0 * fa.gain));
}

namespace {

std::vector<double> shift_by(const std::vector<double>& T, double d_samples) {
  std::vector<double> r(T.size());
  const auto n = static_cast<std::ptrdiff_t>(T.size());
  for (std::ptrdiff_t k = 0; k < n; ++k) {
    const double pos = static_cast<double>(k) - d_samples;
    const auto i0 = static_cast<std::ptrdiff_t>(std::floor(pos));
    const double f = pos - static_cast<double>(i0);
    const auto a = std::clamp<std::ptrdiff_t>(i0, 0, n - 1);
    const auto b = std::clamp<std::ptrdiff_t>(i0 + 1, 0, n - 1);
    r[static_cast<std::size_t>(k)] = (1.0 - f) * T[static_cast<std::size_t>(a)] + f * T[static_cast<std::size_t>(b)];
  }
  return r;
}

// Mean square of i - Ka u(t - lag) over rows [from, to) for lags 0..max_lag
// samples: where the current is logged, a delay in the command path shows
// as the lag that lines the current up with the command (the derivative
// term's encoder-count chatter makes the match sharp).
std::vector<double> current_lag_mse(const DiagnoseContext& c, std::size_t from, std::size_t to, std::size_t max_lag) {
  std::vector<double> mse(max_lag + 1, 0.0);
  const double Ka = c.d.Ka_A_per_V;
  to = std::min(to, c.s.n);
  if (to <= from + max_lag + 10) return {};
  for (std::size_t L = 0; L <= max_lag; ++L) {
    double sum = 0.0;
    for (std::size_t k = from + max_lag; k < to; ++k) {
      const double d = c.s.i_raw_A[k] - Ka * c.s.u_raw_V[k - L];
      sum += d * d;
    }
    mse[L] = sum / static_cast<double>(to - from - max_lag);
  }
  return mse;
}

std::size_t max_delay_samples(const DiagnoseContext& c) {
  return static_cast<std::size_t>(std::floor(0.01 / c.s.dt_s));  // 10 ms
}

// Lag (samples) of the current behind the command on the fitting rows; 0 when
// no lag fits the current better than half the mismatch at lag 0.
std::size_t measure_current_lag(const DiagnoseContext& c) {
  if (!c.s.has_u || !c.s.has_current) return 0;
  const auto mse = current_lag_mse(c, 0, c.s.n_fit, max_delay_samples(c));
  if (mse.empty()) return 0;
  const auto best = static_cast<std::size_t>(std::min_element(mse.begin(), mse.end()) - mse.begin());
  return mse[best] < 0.5 * mse[0] ? best : 0;
}

void try_delay_from_current(const DiagnoseContext& c, std::vector<EffectCandidate>& out) {
  const std::size_t lag = c.current_lag;
  const auto held = current_lag_mse(c, c.s.n_fit, c.s.n, max_delay_samples(c));
  if (held.empty() || !(held[0] > 0.0)) return;
  const double gain = 1.0 - std::sqrt(held[lag] / held[0]);
  const double delay_s = static_cast<double>(lag) * c.s.dt_s;
  EffectCandidate e;
  e.set_kind(EffectKind::kDelay);
  e.axis = c.s.axis;
  e.params = {{EffectParam::delay_delay_s, delay_s}};
  e.signal_gain = gain;
  e.t_stat = 100.0 * gain;
  e.evidence = fmt::format("the current follows Ka u {:.2f} ms late ({} samples): lined up, the held-out mismatch of "
                           "current and command falls from {:.3f} A to {:.3f} A rms",
                           1e3 * delay_s, lag, std::sqrt(held[0]), std::sqrt(held[lag]));
  e.base = c.base;
  e.T_after_Nm = c.T;
  out.push_back(std::move(e));
}

}  // namespace

void detect_delay(const DiagnoseContext& c, std::vector<EffectCandidate>& out) {
  if (!c.s.has_u) return;  // a command delay needs the command
  // Where the current is logged and lags the command, that lag is the delay.
  // Otherwise (no current, or a delay after the current's sensor) the motion
  // lags the torque: shift the torque.
  if (c.current_lag > 0) {
    try_delay_from_current(c, out);
    return;
  }
  // u is held over a controller period: the torque follows it by half a period
  // on average. That is the model's own lag; a delay is what comes on top.
  const double tick = c.s.controller_period_s / c.s.dt_s;  // controller periods in samples
  const double base_shift = 0.5 * tick;
  const auto cols = std::vector<const std::vector<double>*>{&c.reg.acc, &c.reg.vel, &c.reg.pos, &c.reg.neg};
  const auto T0 = shift_by(c.T, base_shift);
  const auto r0 = least_squares(cols, T0, c.fit_moving, corr_len(c.s));
  if (!r0.ok) return;
  const double max_ticks = std::min(60.0, std::floor(0.01 / c.s.controller_period_s));
  const double step_ticks = std::max(1.0, std::floor(max_ticks / 60.0));
  double best_rms = r0.residual_rms, best_ticks = 0.0;
  for (double d = 1.0; d <= max_ticks; d += step_ticks) {
    const auto Td = shift_by(c.T, base_shift + d * tick);
    const auto r = least_squares(cols, Td, c.fit_moving, corr_len(c.s));
    if (r.ok && r.residual_rms < best_rms) {
      best_rms = r.residual_rms;
      best_ticks = d;
    }
  }
  if (best_ticks == 0.0) return;
  auto Td = shift_by(c.T, base_shift + best_ticks * tick);
  const LsqResult rs = least_squares(cols, Td, c.fit_moving, corr_len(c.s));
  if (!rs.ok) return;
  const double h0 = residual_rms(cols, r0.theta, T0, c.held_moving);
  const double h1 = residual_rms(cols, rs.theta, Td, c.held_moving);
  const Fit g = changed_torque_fit(rs, r0, h0, h1,
                                   r0.residual_rms > 0.0 ? 100.0 * (1.0 - rs.residual_rms / r0.residual_rms) : 0.0);
  const double delay_s = best_ticks * c.s.controller_period_s;
  add(out, c, EffectKind::kDelay, g, {{EffectParam::delay_delay_s, delay_s}},
      fmt::format("torque lags the command by {:.2f} ms beyond the hold: shifting it cuts the held-out torque "
                  "residual by {:.0f} %",
                  1e3 * delay_s, 100.0 * g.gain),
      std::move(Td));
}

namespace {

// A current limit read from the logged current at i_max in `samples` rows.
// The torque is the measured current: the base model fitted on it already
// holds the limit's consequences; the limit itself goes to the replay.
void add_limit(std::vector<EffectCandidate>& out, const DiagnoseContext& c, double i_max, std::size_t samples, double t_stat,
               std::string evidence) {
  EffectCandidate e;
  e.set_kind(EffectKind::kCurrentSaturation);
  e.axis = c.s.axis;
  e.params = {{EffectParam::current_saturation_i_max_A, i_max}};
  e.signal_gain =
      std::max(0.1, std::min(1.0, static_cast<double>(samples) / std::max(1.0, 0.01 * static_cast<double>(c.s.n))));
  e.t_stat = t_stat;
  e.evidence = std::move(evidence);
  e.base = c.base;
  e.T_after_Nm = c.T;
  out.push_back(std::move(e));
}

// Without u, a current limit shows in the logged current alone: samples pile
// up at one magnitude in both directions, where a current that is not
// limited thins out into a tail (the count chatter's 20 A spikes make a
// smooth one). A pile is at least 20 samples, each direction holding a fifth
// of them, within 0.5 % (+ 0.02 A) of the largest magnitude, and 5 times as
// dense as the band of three such widths just below it.
void try_saturation_from_current(const DiagnoseContext& c, std::vector<EffectCandidate>& out) {
  double hi = 0.0;
  for (double i : c.s.i_raw_A) hi = std::max(hi, std::abs(i));
  if (!(hi > 0.0)) return;
  const double tol = 0.005 * hi + 0.02;
  if (hi - 4.0 * tol < 0.5 * hi) return;  // a current of a few tenths of an ampere at most: no limit to read
  std::size_t n_pos = 0, n_neg = 0, n_below = 0;
  std::vector<double> top;
  for (double i : c.s.i_raw_A) {
    const double a = std::abs(i);
    if (a >= hi - tol) {
      top.push_back(a);
      (i > 0.0 ? n_pos : n_neg)++;
    } else if (a >= hi - 4.0 * tol) {
      ++n_below;
    }
  }
  const double density_ratio = static_cast<double>(top.size()) / std::max(1.0, static_cast<double>(n_below) / 3.0);
  if (top.size() < 20 || 5 * std::min(n_pos, n_neg) < top.size() || density_ratio < 5.0) return;
  const double i_max = median_of(top);
  add_limit(out, c, i_max, top.size(), density_ratio,
            fmt::format("with no u logged, the current piles up at +-{:.2f} A: {} samples ({} in +, {} in -) within "
                        "{:.2f} A of it, {:.0f} times as dense as just below: a limit",
                        i_max, top.size(), n_pos, n_neg, tol, density_ratio));
}

}  // namespace

void detect_current_saturation(const DiagnoseContext& c, std::vector<EffectCandidate>& out) {
  if (!c.s.has_u) {
    if (c.s.has_current) try_saturation_from_current(c, out);
    return;
  }
  const double Ka = c.d.Ka_A_per_V;
  const double Kt = c.d.Kt_Nm_per_A;
  const double fs = 1.0 / c.s.dt_s;
  // Ka u as it reaches the amplifier: behind the logged command by the lag
  // the current shows (a delay is a separate effect, not a limit).
  const std::size_t lag = c.current_lag;
  std::vector<double> iu(c.s.n);
  for (std::size_t k = 0; k < c.s.n; ++k) iu[k] = Ka * c.s.u_raw_V[k >= lag ? k - lag : 0];
  if (c.s.has_current) {
    // Direct: the current stops short of Ka u (flat tops).
    std::vector<double> small;
    for (std::size_t k = 0; k < c.s.n; ++k)
      if (std::abs(iu[k]) < 2.0) small.push_back(std::abs(c.s.i_raw_A[k] - iu[k]));
    const double noise = small.empty() ? 0.01 : 1.4826 * median_of(small);
    std::vector<double> tops;
    for (std::size_t k = 0; k < c.s.n; ++k) {
      const double i = c.s.i_raw_A[k];
      if (std::abs(iu[k]) - std::abs(i) > std::max(0.5, 8.0 * noise) && i * iu[k] > 0.0) tops.push_back(std::abs(i));
    }
    if (tops.size() < 20) return;
    const double i_max = median_of(tops);
    add_limit(out, c, i_max, tops.size(), static_cast<double>(tops.size()),
              fmt::format("the current is flat at {:.2f} A in {} samples where Ka u{} asks for more (noise {:.3f} A)",
                          i_max, tops.size(), lag > 0 ? fmt::format(" ({} samples earlier)", lag) : "", noise));
    return;
  }
  std::vector<double> a = iu;
  for (auto& v : a) v = std::abs(v);
  std::sort(a.begin(), a.end());
  const auto base_cols = std::vector<const std::vector<double>*>{&c.reg.acc, &c.reg.vel, &c.reg.pos, &c.reg.neg};
  const auto r0 = least_squares(base_cols, c.T, c.fit_moving, corr_len(c.s));
  if (!r0.ok) return;
  double best_rms = r0.residual_rms;
  double best_i = 0.0;
  std::vector<double> best_T;
  LsqResult best_r;
  for (double q : {0.999, 0.995, 0.99, 0.98, 0.97, 0.95, 0.92, 0.9, 0.85, 0.8}) {
    const double i_max = a[static_cast<std::size_t>(q * static_cast<double>(a.size() - 1))];
    if (!(i_max > 0.0)) continue;
    std::vector<double> Ti(c.s.n);
    for (std::size_t k = 0; k < c.s.n; ++k) Ti[k] = Kt * feeddrive::saturated_current_A(iu[k], i_max);
    Ti = lowpass(Ti, c.s.fc_Hz, fs);
    const auto r = least_squares(base_cols, Ti, c.fit_moving, corr_len(c.s));
    if (r.ok && r.residual_rms < best_rms) {
      best_rms = r.residual_rms;
      best_i = i_max;
      best_T = std::move(Ti);
      best_r = r;
    }
  }
  if (best_i == 0.0) return;
  const double h0 = residual_rms(base_cols, r0.theta, c.T, c.held_moving);
  const double h1 = residual_rms(base_cols, best_r.theta, best_T, c.held_moving);
  const Fit g = changed_torque_fit(best_r, r0, h0, h1, 100.0 * (1.0 - best_rms / r0.residual_rms));
  add(out, c, EffectKind::kCurrentSaturation, g, {{EffectParam::current_saturation_i_max_A, best_i}},
      fmt::format("clipping Ka u at {:.2f} A cuts the held-out torque residual by {:.0f} %", best_i, 100.0 * g.gain),
      std::move(best_T));
}

namespace {

}  // namespace

void detect_constant_load(const DiagnoseContext& c, std::vector<EffectCandidate>& out) {
  // Moving, a load shifts both Coulomb levels the same way: the base fit reads
  // it as an asymmetry, and friction alone explains an asymmetry only up to a
  // point (a level below half the other, or below zero, is more than ballscrew
  // and guide friction differ by direction). Hypothesis: symmetric friction
  // plus a load of half the asymmetry. The replay cannot tell the two apart
  // (stuck, the drive holds while Tm - load is within the friction band, which
  // is the asymmetric band), so this candidate rests on the size of the
  // asymmetry alone; the stops' mean holding torque is reported, not used
  // (it lies anywhere in that band).
  const LsqResult b = least_squares({&c.reg.acc, &c.reg.vel, &c.reg.pos, &c.reg.neg}, c.T, c.fit_moving, corr_len(c.s));
  if (!b.ok) return;
  const double lo = std::min(b.theta[2], b.theta[3]), hi = std::max(b.theta[2], b.theta[3]);
  if (!(hi > 0.0) || lo >= 0.5 * hi) return;
  const double load = 0.5 * (b.theta[2] - b.theta[3]);
  const double Tc_sym = 0.5 * (b.theta[2] + b.theta[3]);
  const double se = 0.5 * std::hypot(b.stderr_theta[2], b.stderr_theta[3]);
  // Mean torque over the settled second half of every stop of at least 0.2 s.
  std::vector<double> stops;
  const auto min_len = static_cast<std::size_t>(0.2 / c.s.dt_s);
  const std::size_t guard = static_cast<std::size_t>(0.05 / c.s.dt_s);
  std::size_t start = 0;
  bool first = true;
  for (std::size_t k = 1; k <= c.s.n; ++k) {
    const bool still = k < c.s.n && std::abs(c.s.x_ref_mm[k] - c.s.x_ref_mm[k - 1]) < 1e-9;
    if (still) continue;
    if (k - start >= min_len) {
      const std::size_t a = start + (k - start) / 2, e = k > guard ? k - guard : k;
      // The first stop precedes any motion: it tells nothing.
      if (e > a + 10 && a > guard && !first) {
        double sum = 0.0;
        for (std::size_t j = a; j < e; ++j) sum += c.T[j];
        stops.push_back(sum / static_cast<double>(e - a));
      }
      first = false;
    }
    start = k;
  }
  double mean = 0.0;
  for (double m : stops) mean += m;
  if (!stops.empty()) mean /= static_cast<double>(stops.size());
  Fit g;
  g.ok = true;
  g.with = b;
  g.with.theta[2] = g.with.theta[3] = std::max(0.0, Tc_sym);
  g.gain = std::min(1.0, std::abs(load) / std::max(std::abs(Tc_sym), 1e-9));
  g.t_stat = se > 0.0 ? std::abs(load) / se : 0.0;
  g.extra_Nm.assign(c.s.n, 0.0);
  const std::string stop_note =
      stops.empty() ? std::string("no stops to check it against")
                    : fmt::format("the {} stops hold {:+.3f} N m on average", stops.size(), mean);
  add(out, c, EffectKind::kConstantLoad, g, {{EffectParam::constant_load_torque_Nm, load}},
      fmt::format("moving, friction reads {:.3f} N m in + and {:.3f} N m in -, more asymmetric than friction alone "
                  "(one level under half the other): a load of {:+.3f} N m (t = {:.1f}) with symmetric friction {:.3f} "
                  "N m; {}",
                  b.theta[2], b.theta[3], load, g.t_stat, g.with.theta[2], stop_note));
  out.back().signal_gain = g.gain;
  out.back().replay_blind = true;
  // The same hypothesis on the current model's own Coulomb levels: symmetric
  // friction of their mean and a load of half their difference move and hold
  // the drive exactly as the asymmetric levels do. Its replay is the current
  // one; where the identification clamped a level at zero, the candidate above
  // differs from it and may replay better.
  const double L_eq = 0.5 * (c.d.Tc_pos_Nm - c.d.Tc_neg_Nm);
  if (L_eq * load <= 0.0) return;
  EffectCandidate eq = out.back();
  eq.params = {{EffectParam::constant_load_torque_Nm, L_eq}};
  eq.base.J_kg_m2 = c.d.J_kg_m2;
  eq.base.B_kg_m2_per_s = c.d.B_kg_m2_per_s;
  eq.base.Tc_pos_Nm = eq.base.Tc_neg_Nm = 0.5 * (c.d.Tc_pos_Nm + c.d.Tc_neg_Nm);
  eq.param_grid.clear();
  eq.signal_gain = std::min(1.0, std::abs(L_eq) / std::max(eq.base.Tc_pos_Nm, 1e-9));
  eq.evidence = fmt::format(
      "the identified Coulomb levels {:.3f} N m in + and {:.3f} N m in - are more asymmetric than friction alone: "
      "symmetric friction {:.3f} N m and a load of {:+.3f} N m (t = {:.1f}), the same motion; {}",
      c.d.Tc_pos_Nm, c.d.Tc_neg_Nm, eq.base.Tc_pos_Nm, L_eq, g.t_stat, stop_note);
  out.push_back(std::move(eq));
}

namespace {

// The replay decides: a peak 2.5 times the median level is enough to try
// the two-mass model (a run without one shows about 1.6; the S-curves of a
// real program excite a 170 Hz resonance to only 3 to 4 times the median).
constexpr double kMinProminence = 2.5;

// The strongest band of the tracking-error residual's spectrum between
// 20 Hz and 1 kHz on the fitting part, and its prominence over the median level.
struct ResidualPeak {
  double f_Hz{0.0};
  double prominence{0.0};
};
std::optional<ResidualPeak> residual_peak(const DiagnoseContext& c) {
  const std::vector<double>& e_res = c.e_residual;
  if (e_res.size() != c.s.n) return std::nullopt;
  const double fs = 1.0 / c.s.dt_s;
  double df = 0.0;
  // The fitting part only: the held-out part judges the replay.
  const auto spec = amplitude_spectrum(std::span<const double>(e_res).subspan(0, c.s.n_fit), fs, &df);
  if (spec.size() < 64 || !(df > 0.0)) return std::nullopt;
  const auto k_lo = static_cast<std::size_t>(std::ceil(20.0 / df));
  // Up to 1 kHz: the ballscrew and coupling resonances of such drives lie in
  // the tens to hundreds of Hz; above, the residual holds the encoder-count chatter.
  const auto k_hi = std::min(spec.size() - 1, static_cast<std::size_t>(std::min(0.4 * fs, 1000.0) / df));
  if (k_hi <= k_lo + 8) return std::nullopt;
  const double median = median_of(
      std::vector<double>(spec.begin() + static_cast<std::ptrdiff_t>(k_lo), spec.begin() + static_cast<std::ptrdiff_t>(k_hi)));
  // Smooth over a few bins so a peak is a band, not one bin of noise.
  const std::size_t hw = std::max<std::size_t>(2, static_cast<std::size_t>(2.0 / df));
  double best = 0.0;
  std::size_t kb = 0;
  for (std::size_t k = k_lo + hw; k + hw < k_hi; ++k) {
    double s2 = 0.0;
    for (std::size_t j = k - hw; j <= k + hw; ++j) s2 += spec[j] * spec[j];
    if (s2 > best) {
      best = s2;
      kb = k;
    }
  }
  const double peak = std::sqrt(best / static_cast<double>(2 * hw + 1));
  const double prominence = median > 0.0 ? peak / median : 0.0;
  if (prominence < kMinProminence) return std::nullopt;
  return ResidualPeak{static_cast<double>(kb) * df, prominence};
}

void add_coupling_gap(const DiagnoseContext& c, const ResidualPeak& pk, double mu, double frac,
                      std::vector<EffectCandidate>& out) {
  const double f_Hz = pk.f_Hz, prominence = pk.prominence;
  // The same peak from a gap in the coupling: with the encoder on the motor
  // the gap never shows as lost motion in the position; the motor crosses it
  // free of the table's inertia and friction at each reversal and strikes the
  // table's flank, and at standstill it rests in the gap. Tried where the run
  // reverses often enough to judge it (4 reversals fitted, 2 held out): gaps
  // of 3 to 24 um against contact stiffnesses of 5000 and 20000 N m/rad
  // (damping ratio 0.1), then gap, stiffness and damping refined.
  std::size_t rev_fit = 0, rev_held = 0;
  for (const auto& [k, sg] : c.reversals) ++(k < c.s.n_fit ? rev_fit : rev_held);
  if (rev_fit < 4 || rev_held < 2) return;
  auto gap_set = [&](double gap_mm, double K) {
    return ParamSet{{EffectParam::backlash_gap_mm, gap_mm},
                    {EffectParam::compliance_K_Nm_per_rad, K},
                    {EffectParam::compliance_C_Nm_s_per_rad, 2.0 * 0.1 * std::sqrt(K * mu)},
                    {EffectParam::compliance_load_fraction, frac}};
  };
  EffectCandidate gap = out.back();
  gap.set_kind(EffectKind::kBacklash);
  gap.params = gap_set(0.006, 20000.0);
  gap.param_grid.clear();
  for (double K : {20000.0, 5000.0})
    for (double g_mm : {0.003, 0.006, 0.012, 0.024})
      if (!(K == 20000.0 && g_mm == 0.006)) gap.param_grid.push_back(gap_set(g_mm, K));
  gap.refine = {{EffectParam::backlash_gap_mm, 1.4},
                {EffectParam::compliance_K_Nm_per_rad, 2.0},
                {EffectParam::compliance_C_Nm_s_per_rad, 2.5}};
  gap.evidence = fmt::format(
      "the tracking-error residual of the fitting part has a peak at {:.0f} Hz, {:.1f} times the median level of its "
      "spectrum, and the run reverses {} times ({} held out): a gap in the coupling, the encoder on the motor",
      f_Hz, prominence, rev_fit + rev_held, rev_held);
  out.push_back(std::move(gap));
}

}  // namespace

void detect_compliance(const DiagnoseContext& c, std::vector<EffectCandidate>& out) {
  const auto pk = residual_peak(c);
  if (!pk) return;
  const double f_Hz = pk->f_Hz, prominence = pk->prominence;
  Fit g;
  g.ok = true;
  g.with = least_squares({&c.reg.acc, &c.reg.vel, &c.reg.pos, &c.reg.neg}, c.T, c.fit_moving, corr_len(c.s));
  if (!g.with.ok) return;
  g.gain = std::min(0.9, 1.0 - 1.0 / prominence);
  g.t_stat = prominence;
  g.extra_Nm.assign(c.s.n, 0.0);
  // Inside the position loop the peak of the residual sits below the
  // two-mass resonance sqrt(K / (J f (1 - f))), or is the loop's own mode
  // that the resonance shifts; the replay on the fitting part picks among
  // resonances 1, 1.8 and 2.6 times the peak and stiffnesses of 1200, 2500
  // and 5000 N m/rad (ballscrew drives of this size).
  const double J = c.base.J_kg_m2;
  const double frac = 0.5;
  const double mu = J * frac * (1.0 - frac);
  const double zeta = 0.05;
  auto set_for = [&](double K) {
    const double C = 2.0 * zeta * std::sqrt(K * mu);
    return ParamSet{{EffectParam::compliance_K_Nm_per_rad, K},
                    {EffectParam::compliance_C_Nm_s_per_rad, C},
                    {EffectParam::compliance_load_fraction, frac}};
  };
  const double w_peak = 2.0 * kPi * f_Hz;
  add(out, c, EffectKind::kCompliance, g, set_for(w_peak * w_peak * mu),
      fmt::format("the tracking-error residual of the fitting part has a peak at {:.0f} Hz, {:.1f} times the median level of its "
                  "spectrum: a two-mass resonance tried at and above it",
                  f_Hz, prominence));
  out.back().min_t = kMinProminence;
  for (double ratio : {1.8, 2.6}) out.back().param_grid.push_back(set_for(std::pow(ratio * w_peak, 2) * mu));
  for (double K : {1200.0, 2500.0, 5000.0}) out.back().param_grid.push_back(set_for(K));
  // Then the stiffness and the damping of the best set, finer, on the same rows.
  out.back().refine = {{EffectParam::compliance_K_Nm_per_rad, 1.3}, {EffectParam::compliance_C_Nm_s_per_rad, 2.5}};

  // The same peak from a gap in the coupling, while backlash is still to be looked for.
  if (c.wants(EffectKind::kBacklash)) add_coupling_gap(c, *pk, mu, frac, out);
}

namespace {

}  // namespace

std::vector<EffectCandidate> diagnose_axis(const AxisSignals& s, const std::vector<double>& T_Nm,
                                           const feeddrive::DriveParams& drive, const std::vector<EffectKind>& present,
                                           const std::vector<double>& e_residual_mm) {
  std::vector<EffectCandidate> out;
  if (s.n == 0) return out;
  DiagnoseContext c{s, T_Nm, drive, e_residual_mm, present, base_regressors(s)};
  c.fit_moving = moving_rows(s, 0, s.n_fit, s.w_moving_rad_per_s);
  c.held_moving = moving_rows(s, s.n_fit, s.n, s.w_moving_rad_per_s);
  const double w_slow = 0.15 * s.w_moving_rad_per_s;
  c.fit_slow = moving_rows(s, 0, s.n_fit, w_slow);
  c.held_slow = moving_rows(s, s.n_fit, s.n, w_slow);
  c.base = identify_drive(s, T_Nm, drive);
  if (!c.fit_moving.empty()) {
    double lo = s.x_mm[c.fit_moving.front()], hi = lo;
    for (std::size_t k : c.fit_moving) {
      lo = std::min(lo, s.x_mm[k]);
      hi = std::max(hi, s.x_mm[k]);
    }
    c.travel_mm = hi - lo;
  }
  if (!c.base.ok) return out;
  c.current_lag = measure_current_lag(c);
  c.reversals = reversals(s);
  for (const EffectEntry& e : effect_registry())
    if (e.diagnose != nullptr && c.wants(e.kind)) e.diagnose(c, out);
  std::sort(out.begin(), out.end(),
            [](const EffectCandidate& a, const EffectCandidate& b) { return a.signal_gain > b.signal_gain; });
  return out;
}

std::vector<double> window_spread(const std::vector<double>& e, std::size_t from, std::size_t to, std::size_t window) {
  std::vector<double> r;
  to = std::min(to, e.size());
  if (window == 0) return r;
  for (std::size_t a = from; a + window <= to; a += window) {
    double m = 0.0;
    for (std::size_t k = a; k < a + window; ++k) m += e[k];
    m /= static_cast<double>(window);
    double v = 0.0;
    for (std::size_t k = a; k < a + window; ++k) v += (e[k] - m) * (e[k] - m);
    r.push_back(std::sqrt(v / static_cast<double>(window)));
  }
  return r;
}

void update_torque_after(const AxisSignals& s, const std::vector<double>& T_Nm, EffectCandidate& c) {
  if (const auto recompute = registry_entry(c.kind).torque_after) recompute(s, T_Nm, c);
}

void stribeck_torque_after(const AxisSignals& s, const std::vector<double>& T_Nm, EffectCandidate& c) {
  if (T_Nm.size() != s.n) return;
  const double Ts = param_value(c.params, EffectParam::stribeck_Ts_static);
  const double ws = param_value(c.params, EffectParam::stribeck_ws);
  if (!(ws > 0.0)) return;
  c.T_after_Nm.resize(s.n);
  for (std::size_t k = 0; k < s.n; ++k) {
    const double w = s.w_rad_per_s[k];
    const double sg = w > 0.0 ? 1.0 : w < 0.0 ? -1.0 : 0.0;
    const double Tc = w > 0.0 ? c.base.Tc_pos_Nm : c.base.Tc_neg_Nm;
    c.T_after_Nm[k] = T_Nm[k] - sg * feeddrive::stribeck_excess_Nm(Ts, Tc, w, ws);
  }
}

void apply_candidate(sim::AxisDefinition& axis, const EffectCandidate& c) {
  axis.drive.J_kg_m2 = c.base.J_kg_m2;
  axis.drive.B_kg_m2_per_s = c.base.B_kg_m2_per_s;
  axis.drive.Tc_pos_Nm = c.base.Tc_pos_Nm;
  axis.drive.Tc_neg_Nm = c.base.Tc_neg_Nm;
  for (const auto& [param, value] : c.params) {
    // A parameter may belong to another effect the candidate carries (a gap
    // in the coupling carries the coupling's stiffness).
    const std::string_view full = feeddrive::effect_param_def(param).qualified;
    const sim::AxisParamSpec* spec = sim::find_axis_param(full);
    if (!spec) throw InternalError(fmt::format("calibrate: no machine parameter {}", full));
    sim::set_axis_param(axis, *spec, value);
  }
}

}  // namespace twin::analysis
