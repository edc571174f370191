#include "twin/analysis/calibrate.hpp"

#include <algorithm>
#include <cmath>
#include <optional>

#include <fmt/format.h>

#include "twin/analysis/signal.hpp"
#include "twin/core/error.hpp"

namespace twin::analysis {
namespace {


void copy_axis(ReplayResult& dst, const ReplayResult& src, Axis a) {
  dst.x_ref_mm[index(a)] = src.x_ref_mm[index(a)];
  dst.x_mm[index(a)] = src.x_mm[index(a)];
  dst.u_V[index(a)] = src.u_V[index(a)];
  dst.i_A[index(a)] = src.i_A[index(a)];
}

std::vector<double> tracking_residual(const MeasuredRun& run, const ReplayResult& m, Axis a) {
  const auto& x = run.trace.at(std::string(axis_name(a)) + "_mm");
  const auto& xm = m.x_mm[index(a)];
  std::vector<double> r(std::min(x.size(), xm.size()));
  for (std::size_t k = 0; k < r.size(); ++k) r[k] = xm[k] - x[k];
  return r;
}

// Chooses among the candidate's parameter sets (its own and its grid) the one
// whose replay has the lowest error on the fitting rows; the held-out rows
// play no part. Then, for the parameters the candidate names in `refine`, a
// coordinate search on the fitting rows: each parameter times and divided by
// its step, the step's square root in a second round. Other axes keep
// `machine`'s model.
// Returns false when no set improves the fitting part (a candidate judged by
// the hunting statistic excepted): it is not tried on the held-out part.
bool choose_on_fit_part(const MeasuredRun& run, const sim::MachineDefinition& machine, const ReplayResult& current,
                        EffectCandidate& c, std::size_t n_fit, double max_hunt_ratio, int& replays) {
  if ((c.param_grid.empty() && c.refine.empty()) || n_fit < 2) return true;
  std::vector<ParamSet> sets{c.params};
  sets.insert(sets.end(), c.param_grid.begin(), c.param_grid.end());
  // Each error relative to the current model's on the same rows (the
  // tracking error sits on an encoder-noise floor that no model moves).
  const AxisErrors base = axis_errors(run, current, c.axis, 0, n_fit);
  // Only the fitting rows and the candidate's axis are replayed (the axes are
  // independent without a cut).
  MeasuredRun one = run;
  one.axes = {c.axis};
  // (rank, score): rank 1 for a hunting candidate's set that does not
  // reproduce the hunt's size, ranked after every set that does; nullopt
  // when the set cannot be replayed.
  auto score_of = [&](const ParamSet& params, const DriveIdentification& drive) -> std::optional<std::pair<int, double>> {
    sim::MachineDefinition trial = machine;
    EffectCandidate v = c;
    v.params = params;
    v.base = drive;
    try {
      apply_candidate(trial.axes[index(c.axis)], v);
      trial.validate();
      const ReplayResult rep = replay_run(one, trial, n_fit);
      ++replays;
      const AxisErrors e = axis_errors(run, rep, c.axis, 0, n_fit);
      // A hunt: among the sets that reproduce its size (hunting statistic at
      // most max_hunt_ratio of the current model's), the one closest point
      // by point, i.e. most nearly in phase with the run.
      const double hunt_ratio = base.hunt > 0.0 ? e.hunt / base.hunt : 1.0;
      const bool off_hunt = c.judged_by_hunting && hunt_ratio > max_hunt_ratio;
      return std::pair<int, double>{off_hunt ? 1 : 0, off_hunt ? hunt_ratio : base.relative(e)};
    } catch (const Error&) {
      return std::nullopt;
    }
  };
  // J, B, Tc of set j: its own refit where the grid carries one.
  const bool per_set_base = c.grid_base.size() == c.param_grid.size();
  auto base_for = [&](std::size_t j) -> const DriveIdentification& {
    return j > 0 && per_set_base ? c.grid_base[j - 1] : c.base;
  };
  std::pair<int, double> best_score{0, 0.0};
  std::size_t best = sets.size();
  for (std::size_t j = 0; j < sets.size(); ++j) {
    const auto score = score_of(sets[j], base_for(j));
    if (score && (best == sets.size() || *score < best_score)) {
      best_score = *score;
      best = j;
    }
  }
  if (best == sets.size()) return true;
  c.params = sets[best];
  c.base = DriveIdentification(base_for(best));
  std::size_t tried = sets.size();
  for (int round = 0; round < 2; ++round)
    for (const auto& [name, step0] : c.refine) {
      const double step = round == 0 ? step0 : std::sqrt(step0);
      const EffectParam key = name;  // a structured binding cannot be captured before clang 16
      const auto it = std::find_if(c.params.begin(), c.params.end(), [&](const auto& p) { return p.first == key; });
      if (it == c.params.end() || !(step > 1.0)) continue;
      const auto i = static_cast<std::size_t>(it - c.params.begin());
      for (double f : {step, 1.0 / step}) {
        ParamSet trial = c.params;
        trial[i].second *= f;
        const auto score = score_of(trial, c.base);
        ++tried;
        if (score && *score < best_score) {
          best_score = *score;
          c.params = trial;
          break;
        }
      }
    }
  c.evidence += fmt::format("; of {} parameter sets replayed on the fitting part, the best:", tried);
  for (const auto& [k, v] : c.params) c.evidence += fmt::format(" {} = {:.4g}", param_key(c.kind, k), v);
  c.evidence += fmt::format(" (fitting-part {} {:.3f} of the current model's)",
                            best_score.first == 0 ? "errors" : "hunting statistic", best_score.second);
  c.param_grid.clear();
  c.grid_base.clear();
  c.refine.clear();
  return c.judged_by_hunting || best_score.second < 1.0;
}

// The errors are kept to 4 significant digits, the precision the replay
// supports: the tracking error of a quantised run sits on an encoder-noise
// floor, and any change of the model (a parameter moved by a part in a
// thousand, a friction band where the tracking error is noise) moves where
// the replay crosses the encoder counts and so the 5th digit of its NRMS.
// The held-out rule compares these reported numbers themselves.
double reported_digits(double v) {
  constexpr int kDigits = 4;
  if (!(v > 0.0) || !std::isfinite(v)) return v;
  const double scale = std::pow(10.0, kDigits - 1 - static_cast<int>(std::floor(std::log10(v))));
  return std::round(v * scale) / scale;
}

}  // namespace

AxisErrors axis_errors(const MeasuredRun& run, const ReplayResult& model, Axis a, std::size_t from, std::size_t to) {
  AxisErrors e;
  const std::string n(axis_name(a));
  const auto& ref = run.trace.at(n + "_ref_mm");
  const auto* x = run.trace.find(n + "_mm");
  const std::size_t rows = std::min({ref.size(), model.x_mm[index(a)].size(), to});
  const std::size_t held = rows > from ? rows - from : 0;
  if (held < 3) {
    e.err_not_computed = e.u_not_computed = fmt::format("{} held-out rows: too few to compare", held);
  } else if (!x) {
    e.err_not_computed = fmt::format("no {}_mm column: the tracking error is not measured", n);
  }
  if (x && held >= 3) {
    std::vector<double> em(rows), es(rows);
    for (std::size_t k = 0; k < rows; ++k) {
      em[k] = ref[k] - (*x)[k];
      es[k] = model.x_ref_mm[index(a)][k] - model.x_mm[index(a)][k];
    }
    e.err_mm = nrms(em, es, from, rows);
    if (!(rms(em, from, rows) > 0.0))
      e.err_not_computed = "the measured tracking error is zero on the held-out rows (the axis does not move there)";
    const auto window = std::max<std::size_t>(8, static_cast<std::size_t>(std::lround(0.02 / run.sample_period_s)));
    e.hunt = nrms(window_spread(em, from, rows, window), window_spread(es, from, rows, window), 0,
                  static_cast<std::size_t>(-1));
  }
  const double fs = 1.0 / run.sample_period_s;
  const double fc = std::min(200.0, 0.4 * fs);
  const auto* u = run.trace.find(n + "_u_V");
  const auto* i = run.trace.find(n + "_i_A");
  const std::vector<double>* meas = u ? u : i;
  const std::vector<double>& mod = u ? model.u_V[index(a)] : model.i_A[index(a)];
  if (meas) {
    e.has_u = u != nullptr;
    e.has_current = u == nullptr;
  }
  if (meas && held >= 3) {
    const auto lm = lowpass(std::span<const double>(meas->data(), rows), fc, fs);
    const auto ls = lowpass(std::span<const double>(mod.data(), rows), fc, fs);
    e.u = nrms(lm, ls, from, rows);
    if (!(rms(lm, from, rows) > 0.0))
      e.u_not_computed = fmt::format("the measured {} is zero on the held-out rows", u ? n + "_u_V" : n + "_i_A");
  }
  e.err_mm = reported_digits(e.err_mm);
  e.u = reported_digits(e.u);
  e.hunt = reported_digits(e.hunt);
  return e;
}

CalibrationResult calibrate(const MeasuredRun& run, const sim::MachineDefinition& start,
                            const CalibrateOptions& opt) {
  CalibrationResult r;
  r.axes = run.axes;
  r.n = run.trace.num_rows();
  r.n_fit = static_cast<std::size_t>(std::floor(opt.fit_fraction * static_cast<double>(r.n)));
  const auto& t = run.trace.at("t_s");
  r.t_split_s = t[std::min(r.n_fit, r.n - 1)];
  r.t_end_s = t.back();
  sim::MachineDefinition machine = start;
  r.notes = run.notes;

  AxisArray<AxisSignals> sig;
  AxisArray<std::vector<double>> T_cur;
  AxisArray<std::vector<EffectKind>> present;
  AxisArray<bool> hunting_on{};
  for (Axis a : run.axes) {
    std::string note;
    auto& ax = machine.axes[index(a)];
    sig[index(a)] = prepare_axis_signals(run, a, ax.drive, machine.encoder_resolution_mm, machine.Ts_s,
                                         opt.fit_fraction, &note);
    if (!note.empty()) r.notes.push_back(note);
    if (sig[index(a)].n == 0) continue;
    r.loop[index(a)] = identify_loop_gains(sig[index(a)], ax.loop);
    if (!r.loop[index(a)].note.empty()) r.notes.push_back(r.loop[index(a)].note);
    if (r.loop[index(a)].differs) ax.loop = r.loop[index(a)].gains;
    r.amplifier[index(a)] = check_amplifier(sig[index(a)], ax.drive.Ka_A_per_V);
    const AmplifierCheck& amp = r.amplifier[index(a)];
    if (!amp.note.empty()) r.notes.push_back(amp.note);
    if (amp.gain_differs) ax.drive.Ka_A_per_V = amp.gain_A_per_V;
    if (amp.sign_flipped) set_torque_source(sig[index(a)], true, ax.drive);
    if (!sig[index(a)].has_u)
      r.notes.push_back(fmt::format("axis {}: no {}_u_V: torque from the current (Tm = Kt i); the u error is measured "
                                    "on the current",
                                    axis_name(a), axis_name(a)));
    const DriveIdentification id = identify_drive(sig[index(a)], sig[index(a)].T_Nm, ax.drive);
    r.identification[index(a)] = id;
    if (!id.note.empty()) r.notes.push_back(id.note);
    T_cur[index(a)] = sig[index(a)].T_Nm;
    if (!id.ok) continue;
    r.identified_axis[index(a)] = true;
    ax.drive.J_kg_m2 = id.J_kg_m2;
    ax.drive.B_kg_m2_per_s = id.B_kg_m2_per_s;
    ax.drive.Tc_pos_Nm = id.Tc_pos_Nm;
    ax.drive.Tc_neg_Nm = id.Tc_neg_Nm;
  }
  try {
    machine.validate();
    r.replay_before = replay_run(run, machine);
  } catch (const Error& e) {
    r.notes.push_back(fmt::format("the identified model could not be replayed ({}): the nominal parameters are kept",
                                  e.what()));
    machine = start;
    r.identified_axis = {};
    r.replay_before = replay_run(run, machine);
  }
  ++r.replays;
  r.notes.insert(r.notes.end(), r.replay_before.notes.begin(), r.replay_before.notes.end());
  r.identified = machine;
  for (Axis a : run.axes) r.error_before[index(a)] = axis_errors(run, r.replay_before, a, r.n_fit);
  ReplayResult current = r.replay_before;
  AxisArray<AxisErrors> cur_err = r.error_before;

  for (int round = 0; round < opt.max_effects_per_axis; ++round) {
    AxisArray<std::vector<EffectCandidate>> cands;
    bool any = false;
    for (Axis a : run.axes) {
      const std::size_t i = index(a);
      if (!r.identified_axis[i]) continue;
      auto all = diagnose_axis(sig[i], T_cur[i], machine.axes[i].drive, present[i], tracking_residual(run, current, a));
      // Replay slots go to distinct effects first, then to further variants.
      std::vector<EffectCandidate> variants;
      for (auto& c : all) {
        r.considered.push_back(c);
        r.considered.back().T_after_Nm.clear();
        if (c.signal_gain < opt.min_signal_gain || c.t_stat < c.min_t) continue;
        const bool seen = std::any_of(cands[i].begin(), cands[i].end(),
                                      [&](const EffectCandidate& o) { return o.kind == c.kind; });
        if (seen)
          variants.push_back(std::move(c));
        else if (cands[i].size() < static_cast<std::size_t>(opt.replays_per_round))
          cands[i].push_back(std::move(c));
      }
      for (auto& c : variants)
        if (cands[i].size() < static_cast<std::size_t>(opt.replays_per_round)) cands[i].push_back(std::move(c));
      any = any || !cands[i].empty();
    }
    if (!any) break;
    for (Axis a : run.axes) {
      std::vector<EffectCandidate> kept;
      for (auto& c : cands[index(a)]) {
        if (!choose_on_fit_part(run, machine, current, c, r.n_fit, opt.max_hunt_ratio, r.replays)) {
          c.evidence += "; no parameter set improves the fitting part: not tried on the held-out part";
          r.rejected.push_back(std::move(c));
          continue;
        }
        update_torque_after(sig[index(a)], T_cur[index(a)], c);
        kept.push_back(std::move(c));
      }
      cands[index(a)] = std::move(kept);
    }
    AxisArray<int> best_k{-1, -1, -1};
    AxisArray<AxisErrors> best_err = cur_err;
    AxisArray<double> best_ratio{1.0, 1.0, 1.0};
    AxisArray<ReplayResult> best_replay;
    for (int k = 0; k < opt.replays_per_round; ++k) {
      sim::MachineDefinition trial = machine;
      bool used = false;
      for (Axis a : run.axes)
        if (cands[index(a)].size() > static_cast<std::size_t>(k)) {
          apply_candidate(trial.axes[index(a)], cands[index(a)][static_cast<std::size_t>(k)]);
          used = true;
        }
      if (!used) break;
      ReplayResult rep;
      try {
        trial.validate();
        rep = replay_run(run, trial);
        ++r.replays;
      } catch (const Error& e) {
        for (Axis a : run.axes)
          if (cands[index(a)].size() > static_cast<std::size_t>(k)) {
            auto& c = cands[index(a)][static_cast<std::size_t>(k)];
            c.evidence += fmt::format("; its model could not be replayed: {}", e.what());
          }
        continue;
      }
      for (Axis a : run.axes) {
        const std::size_t i = index(a);
        if (cands[i].size() <= static_cast<std::size_t>(k)) continue;
        const AxisErrors e = axis_errors(run, rep, a, r.n_fit);
        auto& c = cands[i][static_cast<std::size_t>(k)];
        c.evidence += fmt::format("; replayed held-out error: tracking {:.4g} -> {:.4g}, u {:.4g} -> {:.4g}",
                                  cur_err[i].err_mm, e.err_mm, cur_err[i].u, e.u);
        // Each error relative to its own value before: the tracking error of a
        // quantised run sits on a floor of encoder noise that no model moves.
        double ratio = cur_err[i].relative(e);
        // Once a hunt is modelled on the axis, no later effect may give it up.
        const bool hunt_kept = !hunting_on[i] || e.hunt <= cur_err[i].hunt * (1.0 + opt.min_improvement) + 0.02;
        // Never above before, in any of the contract's errors.
        const bool no_worse = e.err_mm <= cur_err[i].err_mm && e.u <= cur_err[i].u && hunt_kept;
        const double needed = present[i].empty() ? opt.min_improvement : opt.min_improvement_second;
        bool better = ratio < 1.0 - needed && no_worse;
        if (c.judged_by_hunting) {
          const double hr = cur_err[i].hunt > 0.0 ? e.hunt / cur_err[i].hunt : 1.0;
          c.evidence += fmt::format("; hunting statistic {:.4f} -> {:.4f} ({:.2f} of before)", cur_err[i].hunt,
                                    e.hunt, hr);
          better = hr <= opt.max_hunt_ratio && no_worse;
          ratio = hr;
        }
        // As a second effect on an axis only where the replay is the same
        // (the exact reparametrisation of the levels fitted with the first
        // effect): a variant that changes the replay must earn its place there.
        const bool same_replay = e.err_mm == cur_err[i].err_mm && e.u == cur_err[i].u;
        const bool tie_strong = (present[i].empty() || same_replay) && c.replay_blind &&
                                c.signal_gain >= opt.strong_signal_gain && c.t_stat >= opt.strong_t &&
                                cur_err[i].err_mm < opt.tie_max_err_nrms && no_worse;
        if (tie_strong && !better)
          c.evidence += "; the replayed errors are not above before and the signature decides";
        const bool first_choice = best_k[i] < 0;
        if ((better || tie_strong) && (first_choice || ratio < best_ratio[i])) {
          best_k[i] = k;
          best_ratio[i] = ratio;
          best_err[i] = e;
          best_replay[i] = rep;
        }
      }
    }
    bool accepted = false;
    for (Axis a : run.axes) {
      const std::size_t i = index(a);
      for (std::size_t k = 0; k < cands[i].size(); ++k) {
        if (static_cast<int>(k) != best_k[i]) {
          r.rejected.push_back(cands[i][k]);
          continue;
        }
        AddedEffect ad;
        ad.candidate = cands[i][k];
        ad.before = cur_err[i];
        ad.after = best_err[i];
        apply_candidate(machine.axes[i], ad.candidate);
        present[i].push_back(ad.candidate.kind);
        hunting_on[i] = hunting_on[i] || ad.candidate.judged_by_hunting;
        T_cur[i] = ad.candidate.T_after_Nm;
        copy_axis(current, best_replay[i], a);
        cur_err[i] = best_err[i];
        r.added.push_back(std::move(ad));
        accepted = true;
      }
    }
    if (!accepted) break;
  }
  r.final_machine = machine;
  r.replay_after = current;
  r.error_after = cur_err;
  for (Axis a : run.axes)
    if (!r.identified_axis[index(a)])
      r.notes.push_back(fmt::format("axis {}: not identified; replayed with the machine's own parameters and no "
                                    "effect search",
                                    axis_name(a)));
  return r;
}

nlohmann::json calibration_report_json(const CalibrationResult& r) {
  nlohmann::json j;
  j["parameters_identified"] = nlohmann::json::object();
  for (Axis a : r.axes) {
    if (!r.identified_axis[index(a)]) continue;
    const auto& d = r.final_machine.axes[index(a)].drive;
    auto& p = j["parameters_identified"][std::string(axis_name(a))];
    p = {{"J", d.J_kg_m2}, {"B", d.B_kg_m2_per_s}, {"Tc_pos", d.Tc_pos_Nm}, {"Tc_neg", d.Tc_neg_Nm}};
    if (r.amplifier[index(a)].gain_differs) p["Ka"] = d.Ka_A_per_V;
    // Loop gains only where the run's u shows other gains than the machine's.
    if (r.loop[index(a)].differs) {
      const auto& g = r.loop[index(a)].gains;
      p["Kp"] = g.Kp_V_per_mm;
      p["Ki"] = g.Ki_V_per_s_mm;
      p["Kd"] = g.Kd_V_s_per_mm;
      p["K1"] = g.K1_V_s2_per_mm;
      p["K2"] = g.K2_V_s_per_mm;
    }
  }
  j["effects_added"] = nlohmann::json::array();
  for (const auto& ad : r.added) {
    nlohmann::json p = nlohmann::json::object();
    for (const auto& [k, v] : ad.candidate.params) p[param_key(ad.candidate.kind, k)] = v;
    j["effects_added"].push_back({{"effect", ad.candidate.effect},
                                  {"axis", std::string(axis_name(ad.candidate.axis))},
                                  {"params", p},
                                  {"evidence", ad.candidate.evidence}});
  }
  // An error that could not be computed is null, and the reason is said.
  nlohmann::json why = nlohmann::json::object();
  auto errs = [&](const AxisArray<AxisErrors>& e) {
    nlohmann::json o = nlohmann::json::object();
    auto put = [&](const std::string& key, double v, const std::string& reason) {
      o[key] = reason.empty() ? nlohmann::json(v) : nlohmann::json(nullptr);
      if (!reason.empty()) why[key] = reason;
    };
    for (Axis a : r.axes) {
      const std::string n(axis_name(a));
      const AxisErrors& ae = e[index(a)];
      put(n + "_err_mm", ae.err_mm, ae.err_not_computed);
      if (ae.has_u) put(n + "_u_V", ae.u, ae.u_not_computed);
      if (ae.has_current) put(n + "_i_A", ae.u, ae.u_not_computed);
    }
    return o;
  };
  j["error_before"] = errs(r.error_before);
  j["error_after"] = errs(r.error_after);
  if (!why.empty()) j["not_computed"] = why;
  j["validation"] = fmt::format(
      "held-out rows {} to {} (t = {:.3f} to {:.3f} s), the last {:.0f} % of the run; J, B, Tc and effect parameters "
      "were fitted on the rows before; u compared after a zero-phase 4th-order Butterworth low-pass at 200 Hz",
      r.n_fit, r.n - 1, r.t_split_s, r.t_end_s, 100.0 * static_cast<double>(r.n - r.n_fit) / static_cast<double>(r.n));
  return j;
}

std::string calibration_report_markdown(const CalibrationResult& r, const std::string& run_dir) {
  std::string s = fmt::format("# Calibration of {}\n\n", run_dir);
  s += fmt::format("Fitted on t < {:.3f} s, judged on t = {:.3f} to {:.3f} s ({} replays).\n\n", r.t_split_s,
                   r.t_split_s, r.t_end_s, r.replays);
  s += "## Identified parameters (inverse-dynamics least squares, standard errors in brackets)\n\n";
  s += "| axis | J kg m^2 | B kg m^2/s | Tc_pos N m | Tc_neg N m | residual N m | samples |\n|---|---|---|---|---|---|---|\n";
  for (Axis a : r.axes) {
    const auto& id = r.identification[index(a)];
    if (!r.identified_axis[index(a)]) {
      s += fmt::format("| {} | not identified | | | | | |\n", axis_name(a));
      continue;
    }
    s += fmt::format("| {} | {:.5g} ({:.2g}) | {:.4g} ({:.2g}) | {:.4g} ({:.2g}) | {:.4g} ({:.2g}) | {:.3g} | {} |\n",
                     axis_name(a), id.J_kg_m2, id.J_stderr, id.B_kg_m2_per_s, id.B_stderr, id.Tc_pos_Nm,
                     id.Tc_pos_stderr, id.Tc_neg_Nm, id.Tc_neg_stderr, id.residual_rms_Nm, id.samples);
  }
  s += "\n## Effects added\n\n";
  if (r.added.empty()) s += "none: no candidate improved the held-out error by more than the threshold.\n";
  for (const auto& ad : r.added) {
    s += fmt::format("- **{}** on {}:", ad.candidate.effect, axis_name(ad.candidate.axis));
    for (const auto& [k, v] : ad.candidate.params) s += fmt::format(" {} = {:.5g}", param_key(ad.candidate.kind, k), v);
    s += fmt::format(". {}\n", ad.candidate.evidence);
  }
  s += "\n## Candidates replayed and rejected\n\n";
  if (r.rejected.empty()) s += "none\n";
  for (const auto& c : r.rejected)
    s += fmt::format("- {} on {} (signal gain {:.1f} %): {}\n", c.effect, axis_name(c.axis), 100.0 * c.signal_gain,
                     c.evidence);
  s += "\n## Every candidate (signal gain: held-out torque-residual reduction where the effect acts)\n\n";
  for (const auto& c : r.considered)
    s += fmt::format("- {} on {}: gain {:.1f} %, t = {:.1f}: {}\n", c.effect, axis_name(c.axis), 100.0 * c.signal_gain,
                     c.t_stat, c.evidence);
  s += "\n## Held-out errors (normalised RMS; hunting: of the 20 ms spreads of the tracking error)\n\n"
       "| axis | tracking before | tracking after | u before | u after | hunting before | hunting after |\n"
       "|---|---|---|---|---|---|---|\n";
  for (Axis a : r.axes)
    s += fmt::format("| {} | {:.4f} | {:.4f} | {:.4f} | {:.4f} | {:.4f} | {:.4f} |\n", axis_name(a),
                     r.error_before[index(a)].err_mm, r.error_after[index(a)].err_mm, r.error_before[index(a)].u,
                     r.error_after[index(a)].u, r.error_before[index(a)].hunt, r.error_after[index(a)].hunt);
  s += "\n## Notes\n\n";
  if (r.notes.empty()) s += "none\n";
  for (const auto& n : r.notes) s += "- " + n + "\n";
  s += "\nPlots: residual_before.png, residual_after.png (measured minus model tracking error and low-passed u, "
       "for the axes whose position is logged)";
  s += r.added.empty() ? ".\n" : ", evidence.png (the first added effect's signature).\n";
  return s;
}

}  // namespace twin::analysis
