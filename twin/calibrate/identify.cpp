#include "twin/calibrate/identify.hpp"

#include <algorithm>
#include <cmath>
#include <functional>
#include <map>
#include <numeric>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "twin/calibrate/signal.hpp"

namespace twin::analysis {

AxisSignals prepare_axis_signals(const MeasuredRun& run, Axis axis, const feeddrive::DriveParams& nominal,
                                 double encoder_resolution_mm, double controller_period_s, double fit_fraction,
                                 std::string* note) {
  AxisSignals s;
  s.axis = axis;
  const std::string a(axis_name(axis));
  const auto* ref = run.trace.find(a + "_ref_mm");
  const auto* x = run.trace.find(a + "_mm");
  const auto* u = run.trace.find(a + "_u_V");
  const auto* i = run.trace.find(a + "_i_A");
  if (!ref || !x) {
    if (note) *note = fmt::format("axis {}: no {}_mm column: the drive cannot be identified", a, a);
    return s;
  }
  if (!u && !i) {
    if (note) *note = fmt::format("axis {}: neither {}_u_V nor {}_i_A: no torque, the drive cannot be identified", a, a, a);
    return s;
  }
  const std::size_t n = x->size();
  s.dt_s = run.sample_period_s;
  s.controller_period_s = controller_period_s > 0.0 ? controller_period_s : s.dt_s;
  const double fs = 1.0 / s.dt_s;
  // 50 Hz keeps the drive's rigid-body motion (S-curves of a few Hz to tens of Hz)
  // and removes the encoder-count chatter; coarse logs get a fifth of their rate.
  s.fc_Hz = std::min(50.0, 0.2 * fs);
  if (n < 50) {
    if (note) *note = fmt::format("axis {}: {} rows are too few to identify a drive", a, n);
    return s;
  }
  s.n = n;
  s.n_fit = static_cast<std::size_t>(std::floor(fit_fraction * static_cast<double>(n)));
  s.rg_mm_per_rad = nominal.rg_mm_per_rad;
  s.has_u = u != nullptr;
  s.has_current = i != nullptr;
  s.encoder_resolution_mm = encoder_resolution_mm;
  s.x_ref_mm = *ref;
  s.x_mm = *x;
  if (u) s.u_raw_V = *u;
  if (i) s.i_raw_A = *i;
  s.x_lp_mm = lowpass(s.x_mm, s.fc_Hz, fs);
  const auto v = derivative(s.x_lp_mm, s.dt_s);
  s.w_rad_per_s.resize(n);
  for (std::size_t k = 0; k < n; ++k) s.w_rad_per_s[k] = v[k] / s.rg_mm_per_rad;
  s.a_rad_per_s2 = derivative(s.w_rad_per_s, s.dt_s);
  std::vector<double> vr(n, 0.0);
  for (std::size_t k = 1; k < n; ++k) vr[k] = (s.x_ref_mm[k] - s.x_ref_mm[k - 1]) / s.dt_s;
  s.v_ref_mm_per_s = lowpass(vr, s.fc_Hz, fs);
  // The measured current is the torque itself (Tm = Kt i): it carries what
  // happens between the command and the motor (a delay, a current limit),
  // which the command does not. u makes the torque only where no current is logged.
  set_torque_source(s, u != nullptr && i == nullptr, nominal);
  // Moving: faster than 2 mm/s or than 20 encoder counts over the filter's time scale.
  const double v_min = std::max(2.0, 20.0 * encoder_resolution_mm * s.fc_Hz);
  s.w_moving_rad_per_s = v_min / s.rg_mm_per_rad;
  std::string pattern;
  s.phase_locked = phase_locked_rows(s.v_ref_mm_per_s, s.dt_s, s.controller_period_s, encoder_resolution_mm, &pattern);
  const auto locked = static_cast<std::size_t>(std::count(s.phase_locked.begin(), s.phase_locked.end(), 1));
  if (locked == 0) {
    s.phase_locked.clear();
  } else if (note) {
    *note = fmt::format("axis {}: {} of {} rows left out of the fits: at their steady speed the log samples the "
                        "encoder-count chatter at a few of its phases only ({})",
                        a, locked, n, pattern);
  }
  return s;
}

std::vector<char> phase_locked_rows(const std::vector<double>& v_ref_mm_per_s, double dt_s, double Ts_s,
                                    double resolution_mm, std::string* pattern) {
  std::vector<char> locked(v_ref_mm_per_s.size(), 0);
  if (!(resolution_mm > 0.0) || !(Ts_s > 0.0) || !(dt_s > 0.0)) return locked;
  const double ratio = dt_s / Ts_s;
  const long M = std::lround(ratio);
  if (M < 2 || std::abs(ratio - static_cast<double>(M)) > 1e-6 * ratio) return locked;
  constexpr long kMaxPattern = 12;
  // Counts per tick within this of p / L: the pattern's phase drifts by less
  // than one count in half a second, so a steady move keeps it locked.
  const double tol = Ts_s / 0.5;
  // The most frequent locked pattern (speed to 0.01 mm/s, L), for the note.
  std::map<std::pair<long, long>, std::size_t> seen;
  for (std::size_t k = 0; k < locked.size(); ++k) {
    const double r = std::abs(v_ref_mm_per_s[k]) * Ts_s / resolution_mm;
    if (r < tol) continue;
    for (long L = 1; L <= kMaxPattern; ++L) {
      const double p = std::round(r * static_cast<double>(L));
      if (std::abs(r - p / static_cast<double>(L)) >= tol) continue;
      if (std::gcd(M, L) > 1) {
        locked[k] = 1;
        ++seen[{std::lround(100.0 * std::abs(v_ref_mm_per_s[k])), L}];
      }
      break;
    }
  }
  if (pattern && !seen.empty()) {
    const auto top = std::max_element(seen.begin(), seen.end(),
                                      [](const auto& a, const auto& b) { return a.second < b.second; });
    const long L = top->first.second;
    *pattern = fmt::format("most at {:.2f} mm/s: a pattern of {} ticks, sampled every {} ticks at {} of its phases",
                           0.01 * static_cast<double>(top->first.first), L, M, L / std::gcd(M, L));
  }
  return locked;
}

std::vector<std::size_t> moving_rows(const AxisSignals& s, std::size_t from, std::size_t to, double w_min) {
  std::vector<std::size_t> rows;
  to = std::min(to, s.n);
  // Stay away from the ends, where the filter's padding shapes the signals.
  const std::size_t guard = static_cast<std::size_t>(std::ceil(0.05 / s.dt_s));
  to = std::min(to, s.n > guard ? s.n - guard : 0);
  for (std::size_t k = std::max(from, guard); k < to; ++k)
    if (std::abs(s.w_rad_per_s[k]) > w_min && (s.phase_locked.empty() || !s.phase_locked[k])) rows.push_back(k);
  return rows;
}

BaseRegressors base_regressors(const AxisSignals& s) {
  BaseRegressors r;
  r.acc = s.a_rad_per_s2;
  r.vel = s.w_rad_per_s;
  r.pos.resize(s.n);
  r.neg.resize(s.n);
  for (std::size_t k = 0; k < s.n; ++k) {
    r.pos[k] = s.w_rad_per_s[k] > 0.0 ? 1.0 : 0.0;
    r.neg[k] = s.w_rad_per_s[k] < 0.0 ? -1.0 : 0.0;
  }
  return r;
}

namespace {

// Where the data pins a parameter down less tightly than the machine
// definition does (a coarse log, a short run), the estimate is the
// inverse-variance weighted mean of both (each treated as Gaussian, the
// cross-correlations of the fit left aside). At the controller's rate the
// standard errors are hundreds of times smaller than the prior's and the
// fit stands alone.
void lean_on_nominal(DriveIdentification& id, const feeddrive::DriveParams& nominal, std::vector<std::string>& notes) {
  struct Param {
    double* value;
    double* stderr_value;
    double nominal;
    const char* name;
  };
  const Param params[] = {{&id.J_kg_m2, &id.J_stderr, nominal.J_kg_m2, "J"},
                          {&id.B_kg_m2_per_s, &id.B_stderr, nominal.B_kg_m2_per_s, "B"},
                          {&id.Tc_pos_Nm, &id.Tc_pos_stderr, nominal.Tc_pos_Nm, "Tc_pos"},
                          {&id.Tc_neg_Nm, &id.Tc_neg_stderr, nominal.Tc_neg_Nm, "Tc_neg"}};
  std::vector<std::string> leaned;
  for (const Param& p : params) {
    const double sp = kNominalRelativeSpread * std::abs(p.nominal);
    const double se = *p.stderr_value;
    if (!(sp > 0.0) || !(se > 0.0) || !std::isfinite(se)) continue;
    const double w_fit = 1.0 / (se * se), w_nom = 1.0 / (sp * sp);
    const double share = w_nom / (w_fit + w_nom);
    if (share < 0.01) continue;
    const double fitted = *p.value;
    *p.value = (w_fit * fitted + w_nom * p.nominal) / (w_fit + w_nom);
    *p.stderr_value = 1.0 / std::sqrt(w_fit + w_nom);
    leaned.push_back(fmt::format("{} {:.4g} (+-{:.2g}) -> {:.4g}", p.name, fitted, se, *p.value));
  }
  if (!leaned.empty())
    notes.push_back(fmt::format("the data pins down some parameters less tightly than the machine definition "
                                "(+-{:.0f} %): weighted with its values: {}",
                                100.0 * kNominalRelativeSpread, fmt::join(leaned, ", ")));
}

// J above a twentieth of the machine's, B and the Coulomb levels not below zero, each clamp said.
void clamp_identified(DriveIdentification& id, const feeddrive::DriveParams& nominal, std::vector<std::string>& notes) {
  auto clamp_min = [&](double& v, double lo, const char* name) {
    if (v < lo) {
      notes.push_back(fmt::format("{} = {:.4g} came out below {:.3g} and was clamped to {:.3g}", name, v, lo, lo));
      v = lo;
    }
  };
  clamp_min(id.J_kg_m2, 0.05 * nominal.J_kg_m2, "J");
  clamp_min(id.B_kg_m2_per_s, 0.0, "B");
  clamp_min(id.Tc_pos_Nm, 0.0, "Tc_pos");
  clamp_min(id.Tc_neg_Nm, 0.0, "Tc_neg");
}

// The columns of the FADAL law (spec/measured-data.md) at the controller's
// rate: e, its integral, its backward difference, the reference's
// acceleration and speed, and a constant.
struct LawColumns {
  std::vector<double> e, I, D, acc, vel, one;
};
LawColumns law_columns(const AxisSignals& s, double Ts) {
  const std::size_t n = s.n;
  LawColumns c{std::vector<double>(n), std::vector<double>(n), std::vector<double>(n, 0.0),
               std::vector<double>(n, 0.0), std::vector<double>(n, 0.0), std::vector<double>(n, 1.0)};
  double integral = 0.0;
  for (std::size_t k = 0; k < n; ++k) {
    c.e[k] = s.x_ref_mm[k] - s.x_mm[k];
    integral += Ts * c.e[k];
    c.I[k] = integral;
    if (k >= 1) {
      c.D[k] = (c.e[k] - c.e[k - 1]) / Ts;
      c.vel[k] = (s.x_ref_mm[k] - s.x_ref_mm[k - 1]) / Ts;
    }
    if (k >= 2) c.acc[k] = (c.vel[k] - c.vel[k - 1]) / Ts;
  }
  return c;
}

using GainField = double controller::PositionLoopParams::*;
struct LawTerm {
  const std::vector<double>* column;
  GainField field;  ///< nullptr for the constant
  const char* name;
};

// The fitted gains against the machine's: a term that moves u by more than
// 0.5 % of its RMS differs; where any gain differs the fit's are all taken
// (it is exact to the log's rounding). A constant is said, not taken.
void compare_gains(const std::vector<const LawTerm*>& terms, const LsqResult& fit, double u_rms,
                   const std::function<double(const std::vector<double>&)>& rms_on_rows,
                   const controller::PositionLoopParams& machine_gains, const std::string& a, LoopIdentification& out) {
  std::vector<std::string> moved;
  std::string start;
  for (std::size_t j = 0; j < terms.size(); ++j) {
    const LawTerm& t = *terms[j];
    const double fitted = fit.theta[j];
    const double machine = t.field ? machine_gains.*t.field : 0.0;
    if (std::abs(fitted - machine) * rms_on_rows(*t.column) / u_rms <= 0.005) continue;
    if (!t.field) {
      start = fmt::format("; u holds a constant {:.3g} V (an integrator that did not start at zero; the replay "
                          "starts it at zero)",
                          fitted);
      continue;
    }
    out.differs = true;
    moved.push_back(fmt::format("{} {:.4g} (machine {:.4g})", t.name, fitted, machine));
  }
  if (out.differs)
    for (std::size_t j = 0; j < terms.size(); ++j)
      if (terms[j]->field) out.gains.*(terms[j]->field) = fit.theta[j];
  if (out.differs)
    out.note = fmt::format("axis {}: {}_u_V follows the FADAL loop law (to {:.2g} % of its RMS) with gains other than "
                           "the machine's: {}; the replay uses them{}",
                           a, a, 100.0 * out.residual_rel, fmt::join(moved, ", "), start);
  else if (!start.empty())
    out.note = fmt::format("axis {}: {}_u_V follows the FADAL loop law with the machine's gains{}", a, a, start);
}

}  // namespace

DriveIdentification identify_drive(const AxisSignals& s, const std::vector<double>& T_Nm,
                                   const feeddrive::DriveParams& nominal) {
  DriveIdentification id;
  id.J_kg_m2 = nominal.J_kg_m2;
  id.B_kg_m2_per_s = nominal.B_kg_m2_per_s;
  id.Tc_pos_Nm = nominal.Tc_pos_Nm;
  id.Tc_neg_Nm = nominal.Tc_neg_Nm;
  if (s.n == 0) {
    id.note = "no signals";
    return id;
  }
  const auto rows = moving_rows(s, 0, s.n_fit, s.w_moving_rad_per_s);
  std::size_t n_pos = 0, n_neg = 0;
  for (std::size_t k : rows) (s.w_rad_per_s[k] > 0.0 ? n_pos : n_neg)++;
  const auto reg = base_regressors(s);
  const double corr = 1.0 / (2.0 * s.fc_Hz * s.dt_s);
  std::vector<std::string> notes;
  if (n_pos < 200 || n_neg < 200) {
    id.note = fmt::format("axis {}: the fitting part moves too little in both directions ({} samples in +, {} in -): "
                          "nominal J, B, Tc kept",
                          axis_name(s.axis), n_pos, n_neg);
    return id;
  }
  const LsqResult r = least_squares({&reg.acc, &reg.vel, &reg.pos, &reg.neg}, T_Nm, rows, corr);
  if (!r.ok) {
    id.note = fmt::format("axis {}: the motion does not separate inertia, damping and friction (rank-deficient): "
                          "nominal J, B, Tc kept",
                          axis_name(s.axis));
    return id;
  }
  id.ok = true;
  id.samples = r.n;
  id.residual_rms_Nm = r.residual_rms;
  id.J_kg_m2 = r.theta[0];
  id.B_kg_m2_per_s = r.theta[1];
  id.Tc_pos_Nm = r.theta[2];
  id.Tc_neg_Nm = r.theta[3];
  id.J_stderr = r.stderr_theta[0];
  id.B_stderr = r.stderr_theta[1];
  id.Tc_pos_stderr = r.stderr_theta[2];
  id.Tc_neg_stderr = r.stderr_theta[3];
  lean_on_nominal(id, nominal, notes);
  clamp_identified(id, nominal, notes);
  for (const auto& n : notes) id.note += (id.note.empty() ? "" : "; ") + fmt::format("axis {}: {}", axis_name(s.axis), n);
  return id;
}

LoopIdentification identify_loop_gains(const AxisSignals& s, const controller::PositionLoopParams& machine_gains) {
  LoopIdentification out;
  out.gains = machine_gains;
  const double Ts = s.controller_period_s;
  const std::string a(axis_name(s.axis));
  if (s.u_raw_V.size() != s.n || s.n < 1000 || !(Ts > 0.0) || std::abs(s.dt_s - Ts) > 1e-6 * Ts) return out;
  const LawColumns c = law_columns(s, Ts);
  std::vector<std::size_t> rows;
  const double u_lim = 0.999 * machine_gains.u_max_V;
  for (std::size_t k = 2; k < s.n; ++k)
    if (std::abs(s.u_raw_V[k]) < u_lim) rows.push_back(k);
  const LawTerm all[] = {{&c.e, &controller::PositionLoopParams::Kp_V_per_mm, "Kp"},
                         {&c.I, &controller::PositionLoopParams::Ki_V_per_s_mm, "Ki"},
                         {&c.D, &controller::PositionLoopParams::Kd_V_s_per_mm, "Kd"},
                         {&c.acc, &controller::PositionLoopParams::K1_V_s2_per_mm, "K1"},
                         {&c.vel, &controller::PositionLoopParams::K2_V_s_per_mm, "K2"},
                         {&c.one, nullptr, "constant"}};
  auto rms_on_rows = [&](const std::vector<double>& col) {
    double ss = 0.0;
    for (std::size_t k : rows) ss += col[k] * col[k];
    return rows.empty() ? 0.0 : std::sqrt(ss / static_cast<double>(rows.size()));
  };
  // A column the run never excites (no motion: no speed, no acceleration) is
  // left out; its gain stays the machine's.
  std::vector<const LawTerm*> terms;
  std::vector<const std::vector<double>*> columns;
  for (const LawTerm& t : all)
    if (rms_on_rows(*t.column) > 0.0) {
      terms.push_back(&t);
      columns.push_back(t.column);
    }
  const double u_rms = rms_on_rows(s.u_raw_V);
  const LsqResult fit = least_squares(columns, s.u_raw_V, rows);
  if (!fit.ok || !(u_rms > 0.0)) return out;
  out.checked = true;
  out.residual_rel = fit.residual_rms / u_rms;
  if (!(out.residual_rel < kLoopLawTolerance)) {
    out.note = fmt::format("axis {}: {}_u_V does not follow the FADAL loop law with any gains (the best fit leaves "
                           "{:.1f} % of its RMS): the machine's gains are kept",
                           a, a, 100.0 * out.residual_rel);
    return out;
  }
  out.law_holds = true;
  compare_gains(terms, fit, u_rms, rms_on_rows, machine_gains, a, out);
  return out;
}

AmplifierCheck check_amplifier(const AxisSignals& s, double Ka_A_per_V) {
  AmplifierCheck out;
  if (s.u_raw_V.size() != s.n || s.i_raw_A.size() != s.n || s.n < 200 || !(Ka_A_per_V > 0.0)) return out;
  const std::string a(axis_name(s.axis));
  double i_max = 0.0;
  for (double v : s.i_raw_A) i_max = std::max(i_max, std::abs(v));
  if (!(i_max > 0.0)) return out;
  const auto max_lag = static_cast<std::size_t>(std::min(60.0, std::floor(0.01 / s.dt_s)));
  double best = 0.0;
  for (std::size_t L = 0; L <= max_lag && L + 100 < s.n; ++L) {
    double iu = 0.0, uu = 0.0, ii = 0.0;
    for (std::size_t k = L; k < s.n; ++k) {
      const double i = s.i_raw_A[k], u = s.u_raw_V[k - L];
      if (std::abs(i) >= 0.9 * i_max) continue;
      iu += i * u;
      uu += u * u;
      ii += i * i;
    }
    if (!(uu > 0.0) || !(ii > 0.0)) continue;
    const double r = iu / std::sqrt(uu * ii);
    if (std::abs(r) > std::abs(best)) {
      best = r;
      out.lag_samples = L;
      out.gain_A_per_V = iu / uu;
    }
  }
  out.correlation = best;
  if (std::abs(best) < 0.9) return out;
  out.checked = true;
  if (out.gain_A_per_V < 0.0) {
    out.sign_flipped = true;
    out.note = fmt::format("axis {}: {}_i_A is {:.3g} times {}_u_V (correlation {:.3f}): the current is logged with the "
                           "opposite sign of u; the torque is taken from u",
                           a, a, out.gain_A_per_V, a, best);
  } else if (std::abs(out.gain_A_per_V / Ka_A_per_V - 1.0) > 0.02) {
    out.gain_differs = true;
    out.note = fmt::format("axis {}: {}_i_A is {:.4g} times {}_u_V {} samples later (correlation {:.3f}), not the "
                           "machine's Ka = {:.4g} A/V: the amplifier's gain is taken from the run",
                           a, a, out.gain_A_per_V, a, out.lag_samples, best, Ka_A_per_V);
  }
  return out;
}

void set_torque_source(AxisSignals& s, bool from_u, const feeddrive::DriveParams& drive) {
  const auto& src = from_u ? s.u_raw_V : s.i_raw_A;
  if (src.size() != s.n || s.n == 0) return;
  s.torque_from_u = from_u;
  s.torque_per_unit = from_u ? drive.Kt_Nm_per_A * drive.Ka_A_per_V : drive.Kt_Nm_per_A;
  s.cmd_raw = src;
  std::vector<double> T(s.n);
  for (std::size_t k = 0; k < s.n; ++k) T[k] = s.torque_per_unit * s.cmd_raw[k];
  s.T_Nm = lowpass(T, s.fc_Hz, 1.0 / s.dt_s);
}

}  // namespace twin::analysis
