#include "twin/calibrate/calibrate.hpp"

#include <algorithm>
#include <cmath>
#include <optional>

#include <fmt/format.h>

#include "twin/calibrate/signal.hpp"
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

// (rank, score) of a parameter set replayed on the fitting rows: rank 1 for a
// hunting candidate's set that does not reproduce the hunt's size, ranked
// after every set that does.
using SetScore = std::pair<int, double>;

// Scores a candidate's parameter sets by their replay on the fitting rows of
// its own axis (the axes are independent without a cut), each error relative
// to the current model's on the same rows (the tracking error sits on an
// encoder-noise floor that no model moves). Other axes keep `machine`'s model.
class FitPartScorer {
 public:
  FitPartScorer(const MeasuredRun& run, const sim::MachineDefinition& machine, const ReplayResult& current,
                const EffectCandidate& c, std::size_t n_fit, double max_hunt_ratio, int& replays)
      : run_(run), machine_(machine), c_(c), n_fit_(n_fit), max_hunt_ratio_(max_hunt_ratio), replays_(replays),
        base_(axis_errors(run, current, c.axis, 0, n_fit)), one_(run) {
    one_.axes = {c.axis};
  }

  // nullopt when the set cannot be replayed.
  std::optional<SetScore> operator()(const ParamSet& params, const DriveIdentification& drive) const {
    sim::MachineDefinition trial = machine_;
    EffectCandidate v = c_;
    v.params = params;
    v.base = drive;
    try {
      apply_candidate(trial.axes[index(c_.axis)], v);
      trial.validate();
      const ReplayResult rep = replay_run(one_, trial, n_fit_);
      ++replays_;
      const AxisErrors e = axis_errors(run_, rep, c_.axis, 0, n_fit_);
      // A hunt: among the sets that reproduce its size (hunting statistic at
      // most max_hunt_ratio of the current model's), the one closest point
      // by point, i.e. most nearly in phase with the run.
      const double hunt_ratio = base_.hunt > 0.0 ? e.hunt / base_.hunt : 1.0;
      const bool off_hunt = c_.judged_by_hunting && hunt_ratio > max_hunt_ratio_;
      return SetScore{off_hunt ? 1 : 0, off_hunt ? hunt_ratio : base_.relative(e)};
    } catch (const Error&) {
      return std::nullopt;
    }
  }

 private:
  const MeasuredRun& run_;
  const sim::MachineDefinition& machine_;
  const EffectCandidate& c_;
  std::size_t n_fit_;
  double max_hunt_ratio_;
  int& replays_;
  AxisErrors base_;
  MeasuredRun one_;
};

// The best of the candidate's own set and its grid (J, B, Tc of a grid set
// its own refit where the grid carries one) goes into `c`; false when none
// can be replayed.
bool choose_from_grid(EffectCandidate& c, const FitPartScorer& score_of, SetScore& best_score) {
  std::vector<ParamSet> sets{c.params};
  sets.insert(sets.end(), c.param_grid.begin(), c.param_grid.end());
  const bool per_set_base = c.grid_base.size() == c.param_grid.size();
  auto base_for = [&](std::size_t j) -> const DriveIdentification& {
    return j > 0 && per_set_base ? c.grid_base[j - 1] : c.base;
  };
  std::size_t best = sets.size();
  for (std::size_t j = 0; j < sets.size(); ++j) {
    const auto score = score_of(sets[j], base_for(j));
    if (score && (best == sets.size() || *score < best_score)) {
      best_score = *score;
      best = j;
    }
  }
  if (best == sets.size()) return false;
  c.params = sets[best];
  c.base = DriveIdentification(base_for(best));
  return true;
}

// A coordinate search on the parameters the candidate names in `refine`:
// each times and divided by its step, the step's square root in a second
// round. Returns the number of sets replayed.
std::size_t refine_on_fit_part(EffectCandidate& c, const FitPartScorer& score_of, SetScore& best_score) {
  std::size_t tried = 0;
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
  return tried;
}

// Chooses among the candidate's parameter sets (its own and its grid) the one
// whose replay has the lowest error on the fitting rows; the held-out rows
// play no part. Then refines the parameters it names in `refine` on the same
// rows.
// Returns false when no set improves the fitting part (a candidate judged by
// the hunting statistic excepted): it is not tried on the held-out part.
bool choose_on_fit_part(const MeasuredRun& run, const sim::MachineDefinition& machine, const ReplayResult& current,
                        EffectCandidate& c, std::size_t n_fit, double max_hunt_ratio, int& replays) {
  if ((c.param_grid.empty() && c.refine.empty()) || n_fit < 2) return true;
  const FitPartScorer score_of(run, machine, current, c, n_fit, max_hunt_ratio, replays);
  SetScore best_score{0, 0.0};
  if (!choose_from_grid(c, score_of, best_score)) return true;
  const std::size_t tried = 1 + c.param_grid.size() + refine_on_fit_part(c, score_of, best_score);
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

namespace {

// The state of one calibration as it adds effects: the machine so far, per
// axis the signals, the torque left to explain, the effects present, and the
// replay of the machine so far with its held-out errors.
struct EffectSearch {
  const MeasuredRun& run;
  const CalibrateOptions& opt;
  CalibrationResult& r;
  sim::MachineDefinition machine;
  AxisArray<AxisSignals> sig{};
  AxisArray<std::vector<double>> T_cur{};
  AxisArray<std::vector<EffectKind>> present{};
  AxisArray<bool> hunting_on{};
  ReplayResult current{};
  AxisArray<AxisErrors> cur_err{};
};

// The best replay slot of each axis in one round.
struct RoundBest {
  AxisArray<int> k{-1, -1, -1};
  AxisArray<AxisErrors> err{};
  AxisArray<double> ratio{1.0, 1.0, 1.0};
  AxisArray<ReplayResult> replay{};
};

using AxisCandidates = AxisArray<std::vector<EffectCandidate>>;

// Signals, loop gains, amplifier and J, B, Tc of one axis; false where the
// drive could not be identified.
bool identify_axis(EffectSearch& st, Axis a) {
  CalibrationResult& r = st.r;
  std::string note;
  auto& ax = st.machine.axes[index(a)];
  AxisSignals& sig = st.sig[index(a)];
  sig = prepare_axis_signals(st.run, a, ax.drive, st.machine.encoder_resolution_mm, st.machine.Ts_s,
                             st.opt.fit_fraction, &note);
  if (!note.empty()) r.notes.push_back(note);
  if (sig.n == 0) return false;
  r.loop[index(a)] = identify_loop_gains(sig, ax.loop);
  if (!r.loop[index(a)].note.empty()) r.notes.push_back(r.loop[index(a)].note);
  if (r.loop[index(a)].differs) ax.loop = r.loop[index(a)].gains;
  r.amplifier[index(a)] = check_amplifier(sig, ax.drive.Ka_A_per_V);
  const AmplifierCheck& amp = r.amplifier[index(a)];
  if (!amp.note.empty()) r.notes.push_back(amp.note);
  if (amp.gain_differs) ax.drive.Ka_A_per_V = amp.gain_A_per_V;
  if (amp.sign_flipped) set_torque_source(sig, true, ax.drive);
  if (!sig.has_u)
    r.notes.push_back(fmt::format("axis {}: no {}_u_V: torque from the current (Tm = Kt i); the u error is measured "
                                  "on the current",
                                  axis_name(a), axis_name(a)));
  const DriveIdentification id = identify_drive(sig, sig.T_Nm, ax.drive);
  r.identification[index(a)] = id;
  if (!id.note.empty()) r.notes.push_back(id.note);
  st.T_cur[index(a)] = sig.T_Nm;
  if (!id.ok) return false;
  ax.drive.J_kg_m2 = id.J_kg_m2;
  ax.drive.B_kg_m2_per_s = id.B_kg_m2_per_s;
  ax.drive.Tc_pos_Nm = id.Tc_pos_Nm;
  ax.drive.Tc_neg_Nm = id.Tc_neg_Nm;
  return true;
}

// The identified machine replayed (the nominal one where it cannot be), and
// its held-out errors: the starting point of the effect search.
void replay_identified(EffectSearch& st, const sim::MachineDefinition& start) {
  CalibrationResult& r = st.r;
  try {
    st.machine.validate();
    r.replay_before = replay_run(st.run, st.machine);
  } catch (const Error& e) {
    r.notes.push_back(fmt::format("the identified model could not be replayed ({}): the nominal parameters are kept",
                                  e.what()));
    st.machine = start;
    r.identified_axis = {};
    r.replay_before = replay_run(st.run, st.machine);
  }
  ++r.replays;
  r.notes.insert(r.notes.end(), r.replay_before.notes.begin(), r.replay_before.notes.end());
  r.identified = st.machine;
  for (Axis a : st.run.axes) r.error_before[index(a)] = axis_errors(st.run, r.replay_before, a, r.n_fit);
  st.current = r.replay_before;
  st.cur_err = r.error_before;
}

// The candidates of every identified axis that pass their signal figures, up
// to replays_per_round per axis: distinct effects first, then further
// variants. False when no axis has one.
bool gather_candidates(EffectSearch& st, AxisCandidates& cands) {
  bool any = false;
  for (Axis a : st.run.axes) {
    const std::size_t i = index(a);
    if (!st.r.identified_axis[i]) continue;
    auto all = diagnose_axis(st.sig[i], st.T_cur[i], st.machine.axes[i].drive, st.present[i],
                             tracking_residual(st.run, st.current, a));
    const auto slots = static_cast<std::size_t>(st.opt.replays_per_round);
    std::vector<EffectCandidate> variants;
    for (auto& c : all) {
      st.r.considered.push_back(c);
      st.r.considered.back().T_after_Nm.clear();
      if (c.signal_gain < st.opt.min_signal_gain || c.t_stat < c.min_t) continue;
      const bool seen = std::any_of(cands[i].begin(), cands[i].end(),
                                    [&](const EffectCandidate& o) { return o.kind == c.kind; });
      if (seen)
        variants.push_back(std::move(c));
      else if (cands[i].size() < slots)
        cands[i].push_back(std::move(c));
    }
    for (auto& c : variants)
      if (cands[i].size() < slots) cands[i].push_back(std::move(c));
    any = any || !cands[i].empty();
  }
  return any;
}

// Each candidate's parameter set chosen on the fitting part; a candidate no
// set of which improves it is rejected there.
void choose_parameter_sets(EffectSearch& st, AxisCandidates& cands) {
  for (Axis a : st.run.axes) {
    std::vector<EffectCandidate> kept;
    for (auto& c : cands[index(a)]) {
      if (!choose_on_fit_part(st.run, st.machine, st.current, c, st.r.n_fit, st.opt.max_hunt_ratio, st.r.replays)) {
        c.evidence += "; no parameter set improves the fitting part: not tried on the held-out part";
        st.r.rejected.push_back(std::move(c));
        continue;
      }
      update_torque_after(st.sig[index(a)], st.T_cur[index(a)], c);
      kept.push_back(std::move(c));
    }
    cands[index(a)] = std::move(kept);
  }
}

// Judges candidate `c` of axis `a`, replayed in slot `k` with errors `e`, and
// makes it the axis's best of the round where it is.
void judge_slot(EffectSearch& st, Axis a, int k, EffectCandidate& c, const ReplayResult& rep, RoundBest& best) {
  const std::size_t i = index(a);
  const CalibrateOptions& opt = st.opt;
  const AxisErrors& before = st.cur_err[i];
  const AxisErrors e = axis_errors(st.run, rep, a, st.r.n_fit);
  c.evidence += fmt::format("; replayed held-out error: tracking {:.4g} -> {:.4g}, u {:.4g} -> {:.4g}",
                            before.err_mm, e.err_mm, before.u, e.u);
  // Each error relative to its own value before: the tracking error of a
  // quantised run sits on a floor of encoder noise that no model moves.
  double ratio = before.relative(e);
  // Once a hunt is modelled on the axis, no later effect may give it up.
  const bool hunt_kept = !st.hunting_on[i] || e.hunt <= before.hunt * (1.0 + opt.min_improvement) + 0.02;
  // Never above before, in any of the contract's errors.
  const bool no_worse = e.err_mm <= before.err_mm && e.u <= before.u && hunt_kept;
  const double needed = st.present[i].empty() ? opt.min_improvement : opt.min_improvement_second;
  bool better = ratio < 1.0 - needed && no_worse;
  if (c.judged_by_hunting) {
    const double hr = before.hunt > 0.0 ? e.hunt / before.hunt : 1.0;
    c.evidence += fmt::format("; hunting statistic {:.4f} -> {:.4f} ({:.2f} of before)", before.hunt, e.hunt, hr);
    better = hr <= opt.max_hunt_ratio && no_worse;
    ratio = hr;
  }
  // As a second effect on an axis only where the replay is the same
  // (the exact reparametrisation of the levels fitted with the first
  // effect): a variant that changes the replay must earn its place there.
  const bool same_replay = e.err_mm == before.err_mm && e.u == before.u;
  const bool tie_strong = (st.present[i].empty() || same_replay) && c.replay_blind &&
                          c.signal_gain >= opt.strong_signal_gain && c.t_stat >= opt.strong_t &&
                          before.err_mm < opt.tie_max_err_nrms && no_worse;
  if (tie_strong && !better) c.evidence += "; the replayed errors are not above before and the signature decides";
  const bool first_choice = best.k[i] < 0;
  if ((better || tie_strong) && (first_choice || ratio < best.ratio[i])) {
    best.k[i] = k;
    best.ratio[i] = ratio;
    best.err[i] = e;
    best.replay[i] = rep;
  }
}

// Replay slot k: the k-th candidate of every axis together (the axes are
// independent), each judged on its own axis. False when no axis has a k-th.
bool replay_slot(EffectSearch& st, AxisCandidates& cands, int k, RoundBest& best) {
  const auto slot = static_cast<std::size_t>(k);
  sim::MachineDefinition trial = st.machine;
  bool used = false;
  for (Axis a : st.run.axes)
    if (cands[index(a)].size() > slot) {
      apply_candidate(trial.axes[index(a)], cands[index(a)][slot]);
      used = true;
    }
  if (!used) return false;
  ReplayResult rep;
  try {
    trial.validate();
    rep = replay_run(st.run, trial);
    ++st.r.replays;
  } catch (const Error& e) {
    for (Axis a : st.run.axes)
      if (cands[index(a)].size() > slot)
        cands[index(a)][slot].evidence += fmt::format("; its model could not be replayed: {}", e.what());
    return true;
  }
  for (Axis a : st.run.axes)
    if (cands[index(a)].size() > slot) judge_slot(st, a, k, cands[index(a)][slot], rep, best);
  return true;
}

// The round's best candidate of each axis goes into the machine; the others
// are rejected. False when no axis took one.
bool accept_best(EffectSearch& st, AxisCandidates& cands, const RoundBest& best) {
  bool accepted = false;
  for (Axis a : st.run.axes) {
    const std::size_t i = index(a);
    for (std::size_t k = 0; k < cands[i].size(); ++k) {
      if (static_cast<int>(k) != best.k[i]) {
        st.r.rejected.push_back(cands[i][k]);
        continue;
      }
      AddedEffect ad;
      ad.candidate = cands[i][k];
      ad.before = st.cur_err[i];
      ad.after = best.err[i];
      apply_candidate(st.machine.axes[i], ad.candidate);
      st.present[i].push_back(ad.candidate.kind);
      st.hunting_on[i] = st.hunting_on[i] || ad.candidate.judged_by_hunting;
      st.T_cur[i] = ad.candidate.T_after_Nm;
      copy_axis(st.current, best.replay[i], a);
      st.cur_err[i] = best.err[i];
      st.r.added.push_back(std::move(ad));
      accepted = true;
    }
  }
  return accepted;
}

// One round of the search: candidates, their sets, the replays, the choice.
// False when nothing was added.
bool search_round(EffectSearch& st) {
  AxisCandidates cands;
  if (!gather_candidates(st, cands)) return false;
  choose_parameter_sets(st, cands);
  RoundBest best;
  best.err = st.cur_err;
  for (int k = 0; k < st.opt.replays_per_round; ++k)
    if (!replay_slot(st, cands, k, best)) break;
  return accept_best(st, cands, best);
}

}  // namespace

CalibrationResult calibrate(const MeasuredRun& run, const sim::MachineDefinition& start,
                            const CalibrateOptions& opt) {
  if (!run.time_breaks.empty()) {
    const std::size_t k = run.time_breaks.front();
    const auto& t = run.trace.at("t_s");
    throw IoError(fmt::format("{}: t_s has a gap before t = {:.6g} s (line {} of the trace): a named machine's drives "
                              "are identified on one uninterrupted log (a run that names no machine is calibrated "
                              "part by part)",
                              run.trace.source, t[k], k + 2));
  }
  CalibrationResult r;
  r.axes = run.axes;
  r.n = run.trace.num_rows();
  r.n_fit = static_cast<std::size_t>(std::floor(opt.fit_fraction * static_cast<double>(r.n)));
  const auto& t = run.trace.at("t_s");
  r.t_split_s = t[std::min(r.n_fit, r.n - 1)];
  r.t_end_s = t.back();
  r.notes = run.notes;
  EffectSearch st{run, opt, r, start};
  for (Axis a : run.axes) r.identified_axis[index(a)] = identify_axis(st, a);
  replay_identified(st, start);
  for (int round = 0; round < opt.max_effects_per_axis; ++round)
    if (!search_round(st)) break;
  r.final_machine = st.machine;
  r.replay_after = st.current;
  r.error_after = st.cur_err;
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
