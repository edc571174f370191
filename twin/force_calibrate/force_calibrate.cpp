#include "twin/force_calibrate/force_calibrate.hpp"

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>
#include <functional>
#include <limits>
#include <numbers>
#include <numeric>

#include <Eigen/Dense>
#include <fmt/format.h>

#include "twin/report/fft.hpp"
#include "twin/report/plots.hpp"
#include "twin/core/error.hpp"
#include "twin/core/golden_section.hpp"
#include "twin/io/atomic_file.hpp"
#include "twin/io/trace_csv.hpp"

namespace twin::analysis::force {

namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kTwoPi = 2.0 * std::numbers::pi;
constexpr const char* kAxisNames[3] = {"fx_N", "fy_N", "fz_N"};

// ---------------------------------------------------------------------------
// Reading

double field(const nlohmann::json& o, const char* key, const std::string& where, const std::string& prefix,
             std::optional<double> fallback = std::nullopt) {
  if (!o.contains(key) || o[key].is_null()) {
    if (fallback) return *fallback;
    throw ConfigError(fmt::format("{}: missing field {}{}", where, prefix, key));
  }
  if (!o[key].is_number())
    throw ConfigError(fmt::format("{}: {}{} = {} must be a number", where, prefix, key, o[key].dump()));
  const double v = o[key].get<double>();
  if (!std::isfinite(v)) throw ConfigError(fmt::format("{}: {}{} is not finite", where, prefix, key));
  return v;
}

[[noreturn]] void bad(const std::string& where, const std::string& name, double v, const std::string& rule) {
  throw ConfigError(fmt::format("{}: {} = {} {}", where, name, v, rule));
}

ForceCut parse_cut(const nlohmann::json& meta, const std::string& where) {
  if (!meta.contains("cut") || !meta["cut"].is_object())
    throw ConfigError(fmt::format("{}: missing field cut (an object: what was cut)", where));
  const nlohmann::json& c = meta["cut"];
  if (!c.contains("tool") || !c["tool"].is_object())
    throw ConfigError(fmt::format("{}: missing field cut.tool (an object)", where));
  const nlohmann::json& t = c["tool"];
  ForceCut cut;
  cut.diameter_mm = field(t, "diameter_mm", where, "cut.tool.");
  if (!(cut.diameter_mm > 0.0 && cut.diameter_mm <= 200.0))
    bad(where, "cut.tool.diameter_mm", cut.diameter_mm, "must be in (0, 200] mm");
  const double flutes = field(t, "flutes", where, "cut.tool.");
  if (flutes != std::floor(flutes) || flutes < 1 || flutes > 16)
    bad(where, "cut.tool.flutes", flutes, "must be a whole number in [1, 16]");
  cut.flutes = static_cast<int>(flutes);
  cut.helix_deg = field(t, "helix_deg", where, "cut.tool.");
  if (!(cut.helix_deg >= 0.0 && cut.helix_deg < 60.0)) bad(where, "cut.tool.helix_deg", cut.helix_deg, "must be in [0, 60) deg");
  cut.corner_radius_mm = field(t, "corner_radius_mm", where, "cut.tool.", 0.0);
  if (!(cut.corner_radius_mm >= 0.0 && cut.corner_radius_mm <= 0.5 * cut.diameter_mm))
    bad(where, "cut.tool.corner_radius_mm", cut.corner_radius_mm, "must be in [0, D/2] mm");
  cut.spindle_rpm = field(c, "spindle_rpm", where, "cut.");
  if (!(cut.spindle_rpm > 0.0 && cut.spindle_rpm <= 100000.0))
    bad(where, "cut.spindle_rpm", cut.spindle_rpm, "must be in (0, 100000] (clockwise, M3)");
  cut.feed_mm_per_min = field(c, "feed_mm_per_min", where, "cut.");
  if (!(cut.feed_mm_per_min > 0.0)) bad(where, "cut.feed_mm_per_min", cut.feed_mm_per_min, "must be > 0");
  if (!(cut.feed_per_tooth_mm() <= 1.0))
    bad(where, "cut.feed_mm_per_min", cut.feed_mm_per_min, "gives a feed per tooth above 1 mm");
  cut.feed_direction_deg = field(c, "feed_direction_deg", where, "cut.", 0.0);
  cut.ap_mm = field(c, "ap_mm", where, "cut.");
  if (!(cut.ap_mm > 0.0 && cut.ap_mm <= 4.0 * cut.diameter_mm))
    bad(where, "cut.ap_mm", cut.ap_mm, "must be in (0, 4 D] mm");
  if (!c.contains("milling") || !c["milling"].is_string())
    throw ConfigError(fmt::format("{}: missing field cut.milling (slot, up or down)", where));
  cut.milling = c["milling"].get<std::string>();
  if (cut.milling != "slot" && cut.milling != "up" && cut.milling != "down")
    throw ConfigError(fmt::format("{}: cut.milling = '{}' must be slot, up or down", where, cut.milling));
  cut.ae_mm = field(c, "ae_mm", where, "cut.", cut.milling == "slot" ? std::optional<double>(cut.diameter_mm)
                                                                      : std::nullopt);
  if (!(cut.ae_mm > 0.0 && cut.ae_mm <= cut.diameter_mm + 1e-9))
    bad(where, "cut.ae_mm", cut.ae_mm, fmt::format("must be in (0, {}] mm (the diameter)", cut.diameter_mm));
  if (cut.milling == "slot" && std::abs(cut.ae_mm - cut.diameter_mm) > 1e-6)
    bad(where, "cut.ae_mm", cut.ae_mm, fmt::format("must equal the diameter {} mm in a slot", cut.diameter_mm));
  if (c.contains("material") && c["material"].is_string()) cut.material = c["material"].get<std::string>();
  return cut;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

// ---------------------------------------------------------------------------
// The cutting model: regressor waveforms over one revolution.

// Regressor index: 0..2 cutting a_q (h db), 3..5 edge (db), 6..8 exponential b_q (h exp(-c h) db); q = t, r, a.
constexpr int kLinearRegressors = 6;
constexpr int kExpRegressors = 9;

struct Element {
  double z_mm, sin_kappa, cos_kappa, db_mm, sin_lag, cos_lag;
};

std::vector<Element> elements(const ForceCut& cut, int slices) {
  std::vector<Element> out;
  const double R = 0.5 * cut.diameter_mm;
  const double r = cut.corner_radius_mm;
  const double tan_helix = std::tan(cut.helix_deg * kPi / 180.0);
  auto add = [&](double z, double kappa, double db) {
    const double lag = z * tan_helix / R;
    out.push_back({z, std::sin(kappa), std::cos(kappa), db, std::sin(lag), std::cos(lag)});
  };
  const double z_corner = std::min(r, cut.ap_mm);
  int n_corner = 0;
  if (z_corner > 0.0) {
    n_corner = std::max(4, static_cast<int>(std::lround(slices * z_corner / cut.ap_mm)));
    const double k_top = std::acos(std::clamp(1.0 - z_corner / r, -1.0, 1.0));
    const double dk = k_top / n_corner;
    for (int i = 0; i < n_corner; ++i) {
      const double k = (i + 0.5) * dk;
      add(r * (1.0 - std::cos(k)), k, r * dk);
    }
  }
  const double flank = cut.ap_mm - z_corner;
  if (flank > 1e-12) {
    const int n = std::max(4, slices - n_corner);
    const double dz = flank / n;
    for (int i = 0; i < n; ++i) add(z_corner + (i + 0.5) * dz, 0.5 * kPi, dz);
  }
  return out;
}

// g[(q * 3 + a) * M + m]: force on the workpiece, machine axes, per unit coefficient q,
// at flute-0 angle phi_m = 2 pi m / M (clockwise from +y).
std::vector<double> regressor_grid(const ForceCut& cut, const Runout& ro, double c_exp, int nq, int slices, int M) {
  const std::vector<Element> el = elements(cut, slices);
  const int N = cut.flutes;
  const double R = 0.5 * cut.diameter_mm;
  const double fz = cut.feed_per_tooth_mm();
  const auto imm = cut.immersion_rad();
  const double psi = cut.feed_direction_deg * kPi / 180.0;
  const double cpsi = std::cos(psi), spsi = std::sin(psi);
  const double tan_helix = std::tan(cut.helix_deg * kPi / 180.0);
  const double lambda = ro.lambda_deg * kPi / 180.0;
  // Runout radius offsets per element and flute.
  std::vector<double> dR(el.size() * static_cast<std::size_t>(N), 0.0);
  for (std::size_t e = 0; e < el.size(); ++e)
    for (int j = 0; j < N; ++j)
      dR[e * N + j] = ro.rho_mm * std::cos(lambda - j * kTwoPi / N + el[e].z_mm * tan_helix / R);
  std::vector<double> g(static_cast<std::size_t>(nq) * 3 * M, 0.0);
  for (int m = 0; m < M; ++m) {
    const double phi = kTwoPi * m / M + psi;   // flute 0 in the feed frame
    double F[9][3] = {};
    for (int j = 0; j < N; ++j) {
      const double pj = phi + j * kTwoPi / N;
      const double s0 = std::sin(pj), c0 = std::cos(pj);
      for (std::size_t e = 0; e < el.size(); ++e) {
        const Element& E = el[e];
        const double s = s0 * E.cos_lag - c0 * E.sin_lag;   // sin(pj - lag)
        const double c = c0 * E.cos_lag + s0 * E.sin_lag;
        double ang = std::atan2(s, c);
        if (ang < 0.0) ang += kTwoPi;
        if (ang < imm[0] || ang > imm[1]) continue;
        double hr = fz * s;
        if (ro.rho_mm > 0.0) {
          const double* d = &dR[e * N];
          hr = 1e300;
          for (int k = 1; k <= N; ++k) hr = std::min(hr, k * fz * s + d[j] - d[((j - k) % N + N) % N]);
        }
        const double h = hr * E.sin_kappa;
        if (!(h > 0.0)) continue;
        const double w[3] = {h * E.db_mm, E.db_mm, nq > kLinearRegressors ? h * std::exp(-c_exp * h) * E.db_mm : 0.0};
        // Projections of unit dFt, dFr, dFa on the tool (feed frame).
        const double P[3][3] = {{-c, s, 0.0},
                                {-E.sin_kappa * s, -E.sin_kappa * c, E.cos_kappa},
                                {E.cos_kappa * s, E.cos_kappa * c, E.sin_kappa}};
        for (int q = 0; q < 3; ++q)
          for (int kind = 0; kind < (nq > kLinearRegressors ? 3 : 2); ++kind) {
            const int idx = kind * 3 + q;
            for (int a = 0; a < 3; ++a) F[idx][a] += w[kind] * P[q][a];
          }
      }
    }
    for (int q = 0; q < nq; ++q) {
      // On the workpiece (minus), rotated from the feed frame to machine axes.
      const double fx = -F[q][0], fy = -F[q][1], fzz = -F[q][2];
      g[(static_cast<std::size_t>(q) * 3 + 0) * M + m] = fx * cpsi - fy * spsi;
      g[(static_cast<std::size_t>(q) * 3 + 1) * M + m] = fx * spsi + fy * cpsi;
      g[(static_cast<std::size_t>(q) * 3 + 2) * M + m] = fzz;
    }
  }
  return g;
}

using cd = std::complex<double>;

// Harmonics 0..K of each regressor waveform: c[(q*3 + a)*(K+1) + k].
std::vector<cd> harmonics(const std::vector<double>& g, int nq, int M, int K) {
  std::vector<cd> out(static_cast<std::size_t>(nq) * 3 * (K + 1));
  std::vector<double> cs(M), sn(M);
  for (int m = 0; m < M; ++m) {
    cs[m] = std::cos(kTwoPi * m / M);
    sn[m] = std::sin(kTwoPi * m / M);
  }
  for (int qa = 0; qa < nq * 3; ++qa) {
    const double* x = &g[static_cast<std::size_t>(qa) * M];
    for (int k = 0; k <= K; ++k) {
      double re = 0.0, im = 0.0;
      int idx = 0;
      for (int m = 0; m < M; ++m) {
        re += x[m] * cs[idx];
        im -= x[m] * sn[idx];
        idx += k;
        if (idx >= M) idx -= M;
      }
      out[static_cast<std::size_t>(qa) * (K + 1) + k] = cd(re / M, im / M);
    }
  }
  return out;
}

// The sensor path at frequency f: delay and, where present, the mode.
cd transfer(double f_hz, double delay_s, const std::optional<SensorMode>& mode, double lowpass_hz) {
  cd H = std::polar(1.0, -kTwoPi * f_hz * delay_s);
  if (lowpass_hz > 0.0) {
    const double r = f_hz / lowpass_hz;   // 2nd-order Butterworth, unit DC gain
    H /= cd(1.0 - r * r, std::sqrt(2.0) * r);
  }
  if (mode) {
    const double r = f_hz / mode->f_hz;
    H /= cd(1.0 - r * r, 2.0 * mode->zeta * r);
  }
  return H;
}

// ---------------------------------------------------------------------------
// Per run preparation.

struct Prep {
  const ForceRun* run{nullptr};
  double f_rev_hz{0.0};
  double fs_hz{0.0};
  int K{0};
  bool has_angle{false};
  bool has_fz{true};
  RunZero zero;
  double t_air_mean_s{0.0};
  std::array<double, 3> air_mean_N{};
  bool air_before{false};
  bool air_after{false};
  std::array<double, 3> air_after_mean_N{};
  double t_air_after_mean_s{0.0};
  std::vector<double> theta;          ///< per sample: measured flute-0 angle (rad), or 2 pi f t without spindle_deg
  std::vector<int> rev;               ///< per sample: steady revolution index, -1 outside
  double v_mm_per_s{0.0};
  double L0_mm{0.0};                  ///< cut length at entry
  double t_cut_mid_fit_s{0.0};
  // Synchronous average of the fit revolutions (depends on the drift).
  std::vector<double> bin_theta;
  std::vector<double> bin_w;
  std::array<std::vector<double>, 3> bin_F;
  std::array<double, 3> mean_fit_N{};
  double L_mean_fit_mm{0.0};
};

double cut_length_at(const Prep& p, double t_s) { return p.L0_mm + p.v_mm_per_s * std::max(0.0, t_s - p.zero.t_entry_s); }

bool is_fit_rev(int r) { return r >= 0 && r % 2 == 0; }
bool is_held_rev(int r) { return r >= 0 && r % 2 == 1; }

/// The force channels a run has: x and y, and z where logged.
int force_axes(const Prep& p) { return p.has_fz ? 3 : 2; }

/// Baseline (median) and noise (1.4826 MAD, at least 1e-3 N) of each force channel
/// over the run's first n_first samples.
struct AirNoise {
  std::array<double, 3> baseline_N{};
  std::array<double, 3> sigma_N{};
};

AirNoise air_noise(const ForceRun& run, int na, std::size_t n_first) {
  AirNoise out;
  const std::size_t n = run.t_s.size();
  for (int a = 0; a < na; ++a) {
    std::vector<double> v(run.F_N[a].begin(), run.F_N[a].begin() + static_cast<std::ptrdiff_t>(std::min(n_first, n)));
    out.baseline_N[a] = median(v);
    for (double& x : v) x = std::abs(x - out.baseline_N[a]);
    out.sigma_N[a] = std::max(1.4826 * median(v), 1e-3);
  }
  return out;
}

/// Where the cut is in a run's samples.
struct CutSpan {
  std::size_t entry{0};  ///< its first sample
  std::size_t exit{0};   ///< the sample after its last one
};

/// The cut: from the first sample beyond 8 sigma of the air's noise followed within a
/// revolution (`look` samples) by at least a quarter more, to the last beyond it.
CutSpan find_cut(const ForceRun& run, int na, const AirNoise& air, std::size_t look) {
  const std::size_t n = run.t_s.size();
  auto dev = [&](std::size_t k) {
    double s = 0.0;
    for (int a = 0; a < na; ++a)
      s += std::pow((run.F_N[static_cast<std::size_t>(a)][k] - air.baseline_N[a]) / air.sigma_N[a], 2);
    return std::sqrt(s);
  };
  const double thr = 8.0;
  std::size_t entry = n;
  for (std::size_t k = 0; k < n; ++k) {
    if (dev(k) <= thr) continue;
    std::size_t hits = 0, tot = 0;
    for (std::size_t i = k; i < std::min(n, k + look); ++i, ++tot) hits += dev(i) > thr;
    if (hits * 4 >= tot) {
      entry = k;
      break;
    }
  }
  if (entry == n) throw ConfigError(fmt::format("{}: no cut found in the force log (nothing above 8 sigma of the first "
                                                "samples' noise)", run.dir.string()));
  std::size_t exit = entry;
  for (std::size_t k = n; k-- > entry;)
    if (dev(k) > thr) {
      exit = k + 1;
      break;
    }
  return CutSpan{entry, exit};
}

/// Mean force and time of the air before the cut (up to 5 samples before its entry)
/// and the noise there; without that air, the noise of the first samples.
void measure_air_before(Prep& p, std::size_t entry, const AirNoise& air, std::vector<std::string>& notes) {
  const ForceRun& run = *p.run;
  const int na = force_axes(p);
  const std::size_t air_end = entry > 5 ? entry - 5 : 0;
  double nz = 0.0;
  if (!p.air_before) {
    notes.push_back(fmt::format("{}: no air before the cut: the zero offset cannot be measured and is taken as 0 N",
                                run.name));
    for (int a = 0; a < na; ++a) nz += air.sigma_N[a] * air.sigma_N[a];
    p.zero.noise_N = std::sqrt(nz / na);
    return;
  }
  double tm = 0.0;
  for (std::size_t k = 0; k < air_end; ++k) {
    tm += run.t_s[k];
    for (int a = 0; a < na; ++a) p.air_mean_N[a] += run.F_N[static_cast<std::size_t>(a)][k];
  }
  tm /= static_cast<double>(air_end);
  for (int a = 0; a < na; ++a) p.air_mean_N[a] /= static_cast<double>(air_end);
  p.t_air_mean_s = tm;
  std::array<double, 3> var{};
  for (std::size_t k = 0; k < air_end; ++k)
    for (int a = 0; a < na; ++a) var[a] += std::pow(run.F_N[static_cast<std::size_t>(a)][k] - p.air_mean_N[a], 2);
  for (int a = 0; a < na; ++a) nz += var[a] / static_cast<double>(air_end);
  p.zero.noise_N = std::sqrt(nz / na);
}

/// Mean force and time of the air after the cut (from `after0`), where there are at
/// least 20 samples of it.
void measure_air_after(Prep& p, std::size_t exit, std::size_t after0) {
  const ForceRun& run = *p.run;
  const std::size_t n = run.t_s.size();
  if (!(exit < n && after0 + 20 <= n)) return;
  p.air_after = true;
  double tm = 0.0;
  for (std::size_t k = after0; k < n; ++k) {
    tm += run.t_s[k];
    for (int a = 0; a < force_axes(p); ++a) p.air_after_mean_N[a] += run.F_N[static_cast<std::size_t>(a)][k];
  }
  const double cnt = static_cast<double>(n - after0);
  p.t_air_after_mean_s = tm / cnt;
  for (int a = 0; a < force_axes(p); ++a) p.air_after_mean_N[a] /= cnt;
}

/// The steady window (past the entry, whose arc grows over one revolution, and its
/// ringing; short of the exit) in whole revolutions, and each sample's angle and
/// steady revolution.
void steady_revolutions(Prep& p, double guard_s) {
  const ForceRun& run = *p.run;
  const std::size_t n = run.t_s.size();
  const double T = 1.0 / p.f_rev_hz;
  p.zero.t_steady_begin_s = p.zero.t_entry_s + 2.0 * T + guard_s;
  p.zero.t_steady_end_s = p.air_after ? p.zero.t_exit_s - T : run.t_s.back() + 0.5 * run.sample_period_s;
  p.zero.revolutions = static_cast<int>(std::floor((p.zero.t_steady_end_s - p.zero.t_steady_begin_s) / T));
  if (p.zero.revolutions < 2)
    throw ConfigError(fmt::format("{}: {} whole revolutions of steady cut (from {:.4f} s to {:.4f} s): at least 2 "
                                  "are needed",
                                  run.dir.string(), std::max(0, p.zero.revolutions), p.zero.t_steady_begin_s,
                                  p.zero.t_steady_end_s));
  p.theta.resize(n);
  p.rev.assign(n, -1);
  for (std::size_t k = 0; k < n; ++k) {
    p.theta[k] = p.has_angle ? run.spindle_deg[k] * kPi / 180.0 : std::fmod(kTwoPi * p.f_rev_hz * run.t_s[k], kTwoPi);
    const double u = (run.t_s[k] - p.zero.t_steady_begin_s) / T;
    if (u >= 0.0 && u < p.zero.revolutions) p.rev[k] = static_cast<int>(std::floor(u));
  }
}

Prep prepare(const ForceRun& run, std::vector<std::string>& notes) {
  Prep p;
  p.run = &run;
  const ForceCut& cut = run.cut;
  p.f_rev_hz = cut.spindle_rpm / 60.0;
  p.fs_hz = 1.0 / run.sample_period_s;
  p.has_angle = !run.spindle_deg.empty();
  p.has_fz = !run.F_N[2].empty();
  p.v_mm_per_s = cut.feed_mm_per_min / 60.0;
  const std::size_t n = run.t_s.size();
  const double spr = p.fs_hz / p.f_rev_hz;   // samples per revolution
  if (spr < 8.0)
    throw ConfigError(fmt::format("{}: {} samples per spindle revolution ({} Hz log, {} rpm): too few to see the tooth "
                                  "pattern (need >= 8)",
                                  run.dir.string(), spr, p.fs_hz, cut.spindle_rpm));
  p.K = std::max(1, std::min(static_cast<int>(std::floor(0.5 * p.fs_hz / p.f_rev_hz - 1e-9)), 60));
  // Air: baseline and noise from the first samples.
  const std::size_t n_first = std::clamp<std::size_t>(static_cast<std::size_t>(0.5 * spr), 20, std::max<std::size_t>(20, n / 10));
  const AirNoise air = air_noise(run, force_axes(p), n_first);
  const CutSpan cut_span = find_cut(run, force_axes(p), air, static_cast<std::size_t>(std::ceil(spr)));
  const std::size_t entry = cut_span.entry, exit = cut_span.exit;
  const double guard_s = std::max(0.25 * (1.0 / p.f_rev_hz), 0.005);
  p.zero.t_entry_s = run.t_s[entry];
  p.zero.t_exit_s = exit < n ? run.t_s[exit] : run.t_s.back();
  p.air_before = entry >= n_first / 2 && entry >= 10;
  measure_air_before(p, entry, air, notes);
  measure_air_after(p, exit, exit + static_cast<std::size_t>(std::ceil(guard_s * p.fs_hz)));
  steady_revolutions(p, guard_s);
  return p;
}

// Offset and drift given the wear law (the wear grows the mean force too).
void set_zero(Prep& p, double wear_per_mm, const std::array<double, 3>& mean_model_N) {
  const ForceRun& run = *p.run;
  const int na = p.has_fz ? 3 : 2;
  if (p.air_before && p.air_after) {
    for (int a = 0; a < na; ++a)
      p.zero.drift_N_per_s[a] = (p.air_after_mean_N[a] - p.air_mean_N[a]) / (p.t_air_after_mean_s - p.t_air_mean_s);
    p.zero.drift_source = "air before and after the cut";
  } else {
    // Slope of the revolution means over the fit revolutions, less what the wear explains.
    const int R = p.zero.revolutions;
    std::vector<double> tr(R, 0.0), cnt(R, 0.0);
    std::array<std::vector<double>, 3> mr;
    for (auto& v : mr) v.assign(R, 0.0);
    for (std::size_t k = 0; k < run.t_s.size(); ++k) {
      const int r = p.rev[k];
      if (!is_fit_rev(r)) continue;
      tr[r] += run.t_s[k];
      cnt[r] += 1.0;
      for (int a = 0; a < na; ++a) mr[a][r] += run.F_N[a][k];
    }
    double st = 0.0, n = 0.0;
    for (int r = 0; r < R; ++r)
      if (cnt[r] > 0) {
        tr[r] /= cnt[r];
        st += tr[r];
        n += 1.0;
      }
    const double tmean = st / n;
    for (int a = 0; a < na; ++a) {
      double sxy = 0.0, sxx = 0.0, sy = 0.0;
      for (int r = 0; r < R; ++r)
        if (cnt[r] > 0) sy += mr[a][r] / cnt[r];
      sy /= n;
      for (int r = 0; r < R; ++r)
        if (cnt[r] > 0) {
          sxy += (tr[r] - tmean) * (mr[a][r] / cnt[r] - sy);
          sxx += (tr[r] - tmean) * (tr[r] - tmean);
        }
      const double slope = sxx > 0.0 ? sxy / sxx : 0.0;
      p.zero.drift_N_per_s[a] = slope - wear_per_mm * p.v_mm_per_s * mean_model_N[a];
    }
    p.zero.drift_source = "fitted over the cut (slope of the revolution means)";
  }
  for (int a = 0; a < na; ++a)
    p.zero.offset_N[a] = p.air_before ? p.air_mean_N[a] - p.zero.drift_N_per_s[a] * p.t_air_mean_s : 0.0;
}

double zeroed(const Prep& p, int a, std::size_t k) {
  return p.run->F_N[a][k] - p.zero.offset_N[a] - p.zero.drift_N_per_s[a] * p.run->t_s[k];
}

// Synchronous average of the fit revolutions in 1-degree bins of the measured angle.
void make_bins(Prep& p) {
  const int B = 360;
  const int na = p.has_fz ? 3 : 2;
  std::vector<double> th(B, 0.0), w(B, 0.0);
  std::array<std::vector<double>, 3> f;
  for (auto& v : f) v.assign(B, 0.0);
  double Lsum = 0.0, tsum = 0.0, cnt = 0.0;
  p.mean_fit_N = {};
  for (std::size_t k = 0; k < p.theta.size(); ++k) {
    if (!is_fit_rev(p.rev[k])) continue;
    double t = std::fmod(p.theta[k], kTwoPi);
    if (t < 0.0) t += kTwoPi;
    const int bi = std::min(B - 1, static_cast<int>(t / kTwoPi * B));
    th[bi] += t - kTwoPi * bi / B;
    w[bi] += 1.0;
    for (int a = 0; a < na; ++a) {
      const double z = zeroed(p, a, k);
      f[a][bi] += z;
      p.mean_fit_N[a] += z;
    }
    Lsum += cut_length_at(p, p.run->t_s[k]);
    tsum += p.run->t_s[k];
    cnt += 1.0;
  }
  for (int a = 0; a < na; ++a) p.mean_fit_N[a] /= cnt;
  p.L_mean_fit_mm = Lsum / cnt;
  p.t_cut_mid_fit_s = tsum / cnt;
  p.bin_theta.clear();
  p.bin_w.clear();
  for (auto& v : p.bin_F) v.clear();
  for (int bi = 0; bi < B; ++bi) {
    if (w[bi] <= 0.0) continue;
    p.bin_theta.push_back(kTwoPi * bi / B + th[bi] / w[bi]);
    p.bin_w.push_back(w[bi]);
    for (int a = 0; a < 3; ++a) p.bin_F[a].push_back(a < na ? f[a][bi] / w[bi] : 0.0);
  }
}

// ---------------------------------------------------------------------------
// The model of the series and its least-squares fit.

struct Config {
  bool runout{false};
  bool mode{false};
  bool exponential{false};
  bool wear{false};
};

struct Fit {
  ForceModel model;
  double ssr{0.0};
  std::vector<double> coef;       ///< the regression vector (6 or 9)
  std::vector<double> stderr_;
};

class SeriesModel {
 public:
  SeriesModel(std::vector<Prep>& preps, const ForceCalibrationOptions& opt) : p_(preps), opt_(opt) {}

  // Regressor harmonics of the runs (all, or only those in `only`) for a runout and decay;
  // cached on the last call for all runs.
  void build(const Runout& ro, double c_exp, int nq, const std::vector<int>* only = nullptr) {
    if (!only && built_ && ro.rho_mm == ro_.rho_mm && ro.lambda_deg == ro_.lambda_deg && c_exp == c_ && nq == nq_)
      return;
    ro_ = ro;
    c_ = c_exp;
    nq_ = nq;
    H_.resize(p_.size());
    for (std::size_t i = 0; i < p_.size(); ++i) {
      if (only && std::find(only->begin(), only->end(), static_cast<int>(i)) == only->end()) continue;
      const auto g = regressor_grid(p_[i].run->cut, ro, c_exp, nq, opt_.slices, opt_.grid);
      H_[i] = harmonics(g, nq, opt_.grid, p_[i].K);
    }
    built_ = only == nullptr;
  }
  int nq() const { return nq_; }
  double c_exp() const { return c_; }
  const Runout& runout() const { return ro_; }
  /// Mean over a revolution of regressor q on axis a of run i.
  double mean_regressor(std::size_t i, int q, int a) const {
    return H_[i][(static_cast<std::size_t>(q) * 3 + a) * (p_[i].K + 1)].real();
  }

  // Value of regressor q, axis a of run i at angle theta through the sensor path.
  // basis: e^{i k theta} for k = 0..K; Hk: transfer per harmonic.
  static double synth(const std::vector<cd>& c, int qa, int K, const std::vector<cd>& basis, const std::vector<cd>& Hk) {
    const cd* ck = &c[static_cast<std::size_t>(qa) * (K + 1)];
    double y = (ck[0] * Hk[0]).real();
    for (int k = 1; k <= K; ++k) y += 2.0 * (ck[k] * Hk[k] * basis[k]).real();
    return y;
  }

  static void fill_basis(double theta, int K, std::vector<cd>& basis) {
    basis.resize(K + 1);
    const cd step = std::polar(1.0, theta);
    basis[0] = 1.0;
    for (int k = 1; k <= K; ++k) basis[k] = basis[k - 1] * step;
  }

  std::vector<cd> transfers(const Prep& p, const ForceModel& m) const {
    std::vector<cd> Hk(p.K + 1);
    for (int k = 0; k <= p.K; ++k) Hk[k] = transfer(k * p.f_rev_hz, p.has_angle ? m.delay_s : 0.0, m.mode, p.has_angle ? m.lowpass_hz : 0.0);
    return Hk;
  }

  double scale(const Prep& p, const ForceModel& m) const { return 1.0 + m.wear_per_mm * (p.L_mean_fit_mm - m.wear_L_ref_mm); }

  double phase0(std::size_t i, const ForceModel& m) const {
    return (!p_[i].has_angle && i < m.phi0_deg.size()) ? m.phi0_deg[i] * kPi / 180.0 : 0.0;
  }

  // Design rows of the bins of the runs in `use`, weighted; solves for the coefficients.
  Fit solve(const ForceModel& m, const std::vector<int>& use) const {
    const int nq = nq_;
    std::size_t rows = 0;
    for (int i : use) rows += p_[i].bin_theta.size() * (p_[i].has_fz ? 3 : 2);
    Eigen::MatrixXd A(rows, nq);
    Eigen::VectorXd y(rows);
    std::size_t r = 0;
    std::vector<cd> basis;
    for (int i : use) {
      const Prep& p = p_[i];
      const auto Hk = transfers(p, m);
      const double s = scale(p, m);
      const int na = p.has_fz ? 3 : 2;
      for (std::size_t b = 0; b < p.bin_theta.size(); ++b) {
        fill_basis(p.bin_theta[b] + phase0(static_cast<std::size_t>(i), m), p.K, basis);
        const double sw = std::sqrt(p.bin_w[b]);
        for (int a = 0; a < na; ++a, ++r) {
          for (int q = 0; q < nq; ++q) A(r, q) = sw * s * synth(H_[i], q * 3 + a, p.K, basis, Hk);
          y(r) = sw * p.bin_F[a][b];
        }
      }
    }
    Fit f;
    f.model = m;
    const Eigen::MatrixXd NtN = A.transpose() * A;
    // A light ridge keeps the exponential set solvable where b h exp(-c h) is nearly h.
    Eigen::MatrixXd Nr = NtN;
    for (int q = 0; q < nq; ++q) Nr(q, q) += 1e-10 * std::max(NtN(q, q), 1e-30);
    const Eigen::LDLT<Eigen::MatrixXd> ldlt(Nr);
    const Eigen::VectorXd x = ldlt.solve(A.transpose() * y);
    const Eigen::VectorXd res = y - A * x;
    f.ssr = res.squaredNorm();
    f.coef.assign(x.data(), x.data() + nq);
    const double dof = std::max<double>(1.0, static_cast<double>(rows) - nq);
    const Eigen::MatrixXd cov = ldlt.solve(Eigen::MatrixXd::Identity(nq, nq)) * (f.ssr / dof);
    f.stderr_.resize(nq);
    for (int q = 0; q < nq; ++q) f.stderr_[q] = std::sqrt(std::max(0.0, cov(q, q)));
    for (int q = 0; q < 3; ++q) {
      f.model.k.a[q] = x(q);
      f.model.k.e[q] = x(3 + q);
      f.model.k.b[q] = nq > kLinearRegressors ? x(6 + q) : 0.0;
    }
    f.model.k.exponential = nq > kLinearRegressors;
    f.model.k.c_per_mm = nq > kLinearRegressors ? c_ : 0.0;
    for (int q = 0; q < 6; ++q) f.model.k_stderr[q] = f.stderr_[q];
    f.model.runout = ro_;
    return f;
  }

  // The model force (zero not included) at every sample of run i, with the scale of its wear law.
  std::array<std::vector<double>, 3> predict(std::size_t i, const ForceModel& m, const std::vector<double>& coef) const {
    const Prep& p = p_[i];
    const auto Hk = transfers(p, m);
    const int K = p.K;
    // Combined harmonics of the model per axis.
    std::array<std::vector<cd>, 3> C;
    for (int a = 0; a < 3; ++a) {
      C[a].assign(K + 1, 0.0);
      for (int q = 0; q < nq_; ++q)
        for (int k = 0; k <= K; ++k) C[a][k] += coef[q] * H_[i][(static_cast<std::size_t>(q) * 3 + a) * (K + 1) + k] * Hk[k];
    }
    const std::size_t n = p.theta.size();
    std::array<std::vector<double>, 3> out;
    for (auto& v : out) v.assign(n, 0.0);
    std::vector<cd> basis;
    for (std::size_t k = 0; k < n; ++k) {
      if (p.rev[k] < 0) continue;
      fill_basis(p.theta[k] + phase0(i, m), K, basis);
      const double s = 1.0 + m.wear_per_mm * (cut_length_at(p, p.run->t_s[k]) - m.wear_L_ref_mm);
      for (int a = 0; a < 3; ++a) {
        double y = C[a][0].real();
        for (int kk = 1; kk <= K; ++kk) y += 2.0 * (C[a][kk] * basis[kk]).real();
        out[a][k] = s * y;
      }
    }
    return out;
  }

 private:
  std::vector<Prep>& p_;
  const ForceCalibrationOptions& opt_;
  bool built_{false};
  Runout ro_{};
  double c_{0.0};
  int nq_{0};
  std::vector<std::vector<cd>> H_;
};

// Nelder-Mead on a small vector (bounded by the caller's cost returning a large value outside).
std::vector<double> nelder_mead(const std::function<double(const std::vector<double>&)>& f, std::vector<double> x0,
                                const std::vector<double>& step, int iters) {
  const std::size_t n = x0.size();
  std::vector<std::vector<double>> s(n + 1, x0);
  std::vector<double> fv(n + 1);
  for (std::size_t i = 0; i < n; ++i) s[i + 1][i] += step[i];
  for (std::size_t i = 0; i <= n; ++i) fv[i] = f(s[i]);
  for (int it = 0; it < iters; ++it) {
    std::vector<std::size_t> idx(n + 1);
    std::iota(idx.begin(), idx.end(), 0);
    std::sort(idx.begin(), idx.end(), [&](std::size_t a, std::size_t b) { return fv[a] < fv[b]; });
    const std::size_t best = idx[0], worst = idx[n], second = idx[n - 1];
    std::vector<double> c(n, 0.0);
    for (std::size_t i = 0; i <= n; ++i)
      if (i != worst)
        for (std::size_t d = 0; d < n; ++d) c[d] += s[i][d] / n;
    auto along = [&](double t) {
      std::vector<double> x(n);
      for (std::size_t d = 0; d < n; ++d) x[d] = c[d] + t * (s[worst][d] - c[d]);
      return x;
    };
    const auto xr = along(-1.0);
    const double fr = f(xr);
    if (fr < fv[best]) {
      const auto xe = along(-2.0);
      const double fe = f(xe);
      if (fe < fr) {
        s[worst] = xe;
        fv[worst] = fe;
      } else {
        s[worst] = xr;
        fv[worst] = fr;
      }
    } else if (fr < fv[second]) {
      s[worst] = xr;
      fv[worst] = fr;
    } else {
      const auto xc = along(0.5);
      const double fc = f(xc);
      if (fc < fv[worst]) {
        s[worst] = xc;
        fv[worst] = fc;
      } else {
        for (std::size_t i = 0; i <= n; ++i)
          if (i != best) {
            for (std::size_t d = 0; d < n; ++d) s[i][d] = s[best][d] + 0.5 * (s[i][d] - s[best][d]);
            fv[i] = f(s[i]);
          }
      }
    }
  }
  std::size_t b = 0;
  for (std::size_t i = 1; i <= n; ++i)
    if (fv[i] < fv[b]) b = i;
  return s[b];
}

double golden(const std::function<double(double)>& f, double lo, double hi, int iters) {
  return golden_section_min(f, lo, hi, iters).mid();
}

}  // namespace

// ---------------------------------------------------------------------------

std::array<double, 2> ForceCut::immersion_rad() const {
  if (milling == "slot") return {0.0, kPi};
  const double D = diameter_mm;
  if (milling == "up") return {0.0, std::acos(std::clamp(1.0 - 2.0 * ae_mm / D, -1.0, 1.0))};
  return {std::acos(std::clamp(2.0 * ae_mm / D - 1.0, -1.0, 1.0)), kPi};
}

bool is_force_data(const std::filesystem::path& path) {
  auto has_cut = [](const std::filesystem::path& dir) {
    const auto meta = dir / "meta.json";
    std::error_code ec;
    if (!std::filesystem::is_regular_file(meta, ec)) return false;
    try {
      const auto j = nlohmann::json::parse(io::read_file(meta));
      return j.is_object() && j.contains("cut");
    } catch (const std::exception&) {
      return false;
    }
  };
  std::error_code ec;
  if (!std::filesystem::is_directory(path, ec)) return false;
  if (std::filesystem::exists(path / "meta.json", ec)) return has_cut(path);
  for (const auto& e : std::filesystem::directory_iterator(path, ec))
    if (e.is_directory() && has_cut(e.path())) return true;
  return false;
}

ForceRun load_force_run(const std::filesystem::path& dir) {
  ForceRun run;
  run.dir = dir;
  run.name = dir.filename().string();
  if (run.name.empty()) run.name = dir.parent_path().filename().string();
  const auto meta_path = dir / "meta.json";
  if (!std::filesystem::exists(meta_path)) throw IoError(fmt::format("{}: no meta.json", dir.string()));
  nlohmann::json meta;
  try {
    meta = nlohmann::json::parse(io::read_file(meta_path));
  } catch (const nlohmann::json::exception& e) {
    throw ConfigError(fmt::format("{}: not valid JSON ({})", meta_path.string(), e.what()));
  }
  if (!meta.is_object()) throw ConfigError(fmt::format("{}: must hold a JSON object", meta_path.string()));
  run.cut = parse_cut(meta, meta_path.string());
  std::filesystem::path trace_path = dir / "trace.csv";
  if (!std::filesystem::exists(trace_path)) trace_path = dir / "trace.csv.gz";
  const io::TraceTable t = io::read_trace_csv(trace_path);
  run.t_s = t.at("t_s");
  run.F_N[0] = t.at("fx_N");
  run.F_N[1] = t.at("fy_N");
  if (const auto* fz = t.find("fz_N")) run.F_N[2] = *fz;
  if (const auto* sd = t.find("spindle_deg")) run.spindle_deg = *sd;
  if (run.t_s.size() < 16) throw ConfigError(fmt::format("{}: {} rows: too short for a force run", trace_path.string(), run.t_s.size()));
  std::vector<double> dt(run.t_s.size() - 1);
  for (std::size_t k = 1; k < run.t_s.size(); ++k) dt[k - 1] = run.t_s[k] - run.t_s[k - 1];
  run.sample_period_s = median(dt);
  for (std::size_t k = 0; k < dt.size(); ++k)
    if (std::abs(dt[k] - run.sample_period_s) > 0.01 * run.sample_period_s)
      throw ConfigError(fmt::format("{}: line {}: t_s step {} s differs from the log's period {} s (a force log must be "
                                    "evenly sampled)",
                                    trace_path.string(), k + 3, dt[k], run.sample_period_s));
  if (meta.contains("sample_period_s") && meta["sample_period_s"].is_number()) {
    const double Ts = meta["sample_period_s"].get<double>();
    if (!(Ts > 0.0) || std::abs(Ts - run.sample_period_s) > 0.01 * run.sample_period_s)
      throw ConfigError(fmt::format("{}: sample_period_s = {} s but t_s steps by {} s", meta_path.string(), Ts,
                                    run.sample_period_s));
  }
  return run;
}

std::vector<ForceRun> load_force_series(const std::filesystem::path& path) {
  std::vector<ForceRun> runs;
  if (!std::filesystem::is_directory(path)) throw IoError(fmt::format("{}: not a folder", path.string()));
  if (std::filesystem::exists(path / "meta.json")) {
    runs.push_back(load_force_run(path));
    return runs;
  }
  std::vector<std::filesystem::path> dirs;
  for (const auto& e : std::filesystem::directory_iterator(path))
    if (e.is_directory() && std::filesystem::exists(e.path() / "meta.json")) dirs.push_back(e.path());
  std::sort(dirs.begin(), dirs.end());
  if (dirs.empty())
    throw ConfigError(fmt::format("{}: neither a run (meta.json) nor a folder of runs", path.string()));
  for (const auto& d : dirs) runs.push_back(load_force_run(d));
  const ForceCut& c0 = runs.front().cut;
  for (const auto& r : runs) {
    const ForceCut& c = r.cut;
    if (c.diameter_mm != c0.diameter_mm || c.flutes != c0.flutes || c.helix_deg != c0.helix_deg ||
        c.corner_radius_mm != c0.corner_radius_mm)
      throw ConfigError(fmt::format("{}: cut.tool differs from that of {} (a series is one tool)",
                                    (r.dir / "meta.json").string(), runs.front().name));
  }
  return runs;
}

namespace {

struct Evaluated {
  Fit fit;
  std::array<double, 3> err{};
  double E{0.0};
};

class Identifier {
 public:
  Identifier(std::vector<Prep>& preps, const ForceCalibrationOptions& opt, std::vector<std::string>& notes)
      : p_(preps), sm_(preps, opt), notes_(notes) {
    for (std::size_t i = 0; i < p_.size(); ++i) all_.push_back(static_cast<int>(i));
    any_angle_ = std::any_of(p_.begin(), p_.end(), [](const Prep& p) { return p.has_angle; });
    all_angle_ = std::all_of(p_.begin(), p_.end(), [](const Prep& p) { return p.has_angle; });
  }

  SeriesModel& sm() { return sm_; }
  const std::vector<int>& all() const { return all_; }

  int nq(const ForceModel& m) const { return m.k.exponential ? kExpRegressors : kLinearRegressors; }

  Fit solve(const ForceModel& m, const std::vector<int>& use) {
    sm_.build(m.runout, m.k.c_per_mm, nq(m));
    return sm_.solve(m, use);
  }

  // The delay of the sensor path (runs with spindle_deg) and the phase of runs without it.
  void fit_phase(ForceModel& m, bool lowpass = true) {
    for (std::size_t i = 0; i < p_.size(); ++i) {
      if (p_[i].has_angle) continue;
      const double pitch = 360.0 / p_[i].run->cut.flutes;
      // Each run's phase from its own pattern (its own coefficients): the others' phases do not bias it.
      const std::vector<int> one{static_cast<int>(i)};
      double best = m.phi0_deg[i], best_c = 1e300;
      for (double a = 0.0; a < pitch; a += 2.0) {
        m.phi0_deg[i] = a;
        const double c = solve(m, one).ssr;
        if (c < best_c) {
          best_c = c;
          best = a;
        }
      }
      m.phi0_deg[i] = golden(
          [&](double a) {
            m.phi0_deg[i] = a;
            return solve(m, one).ssr;
          },
          best - 2.0, best + 2.0, 20);
    }
    if (any_angle_) {
      double best = 0.0, best_c = 1e300;
      // A log may lag the trigger (filters) or, where the trigger is late, lead it.
      for (double d = -5e-4; d <= 1e-3 + 1e-12; d += 5e-5) {
        m.delay_s = d;
        const double c = solve(m, all_).ssr;
        if (c < best_c) {
          best_c = c;
          best = d;
        }
      }
      const double keep_lp = m.lowpass_hz;
      m.lowpass_hz = 0.0;
      m.delay_s = golden(
          [&](double d) {
            m.delay_s = d;
            return solve(m, all_).ssr;
          },
          best - 5e-5, best + 5e-5, 20);
      const double c_delay = solve(m, all_).ssr;
      if (!lowpass) return;
      // The log's anti-alias filter: a 2nd-order low-pass in the sensor path (with the delay
      // of the rest), kept where it explains the data better than the delay alone.
      const double fs = p_.front().fs_hz;
      const double d_only = m.delay_s;
      auto cost = [&](const std::vector<double>& v) {
        const double fc = std::exp(v[1]);
        if (fc < 0.1 * fs || fc > 3.0 * fs || v[0] < -5.0 || v[0] > 10.0) return 1e300;
        m.lowpass_hz = fc;
        m.delay_s = v[0] * 1e-4;
        return solve(m, all_).ssr;
      };
      // Several starts: the filter's phase trades with the delay (and with a sensor mode).
      std::vector<double> x;
      double c_lp = 1e300;
      for (double fc0 : {keep_lp, 0.3 * fs, 0.6 * fs}) {
        if (!(fc0 > 0.0)) continue;
        const double d0 = d_only - std::sqrt(2.0) / (kTwoPi * fc0);
        const auto xi = nelder_mead(cost, {d0 * 1e4, std::log(fc0)}, {0.1, 0.2}, 60);
        const double ci = cost(xi);
        if (ci < c_lp) {
          c_lp = ci;
          x = xi;
        }
      }
      if (c_lp < c_delay * (1.0 - 1e-3) && std::exp(x[1]) < 2.5 * fs) {
        m.lowpass_hz = std::exp(x[1]);
        m.delay_s = x[0] * 1e-4;
      } else {
        m.lowpass_hz = 0.0;
        m.delay_s = d_only;
      }
    }
  }

  ForceModel fit_runout(ForceModel m) {
    // Searched with the delay alone (a low-pass fitted to a model without runout takes part of
    // its pattern), the low-pass found again after, then all refined together.
    m.lowpass_hz = 0.0;
    fit_phase(m, false);
    const double R = 0.5 * p_.front().run->cut.diameter_mm;
    auto cost = [&](double x, double y) {
      const double rho = std::hypot(x, y);
      if (rho >= 0.1 * R) return 1e300;
      m.runout = {rho, std::atan2(y, x) * 180.0 / kPi};
      return solve(m, all_).ssr;
    };
    double bx = 0.0, by = 0.0, bc = cost(0.0, 0.0);
    for (double rho : {0.002, 0.005, 0.01, 0.02})
      for (double lam = 0.0; lam < 360.0; lam += 30.0) {
        const double x = rho * std::cos(lam * kPi / 180.0), y = rho * std::sin(lam * kPi / 180.0);
        const double c = cost(x, y);
        if (c < bc) {
          bc = c;
          bx = x;
          by = y;
        }
      }
    const double step = std::max(0.3 * std::hypot(bx, by), 0.001);
    const auto x = nelder_mead([&](const std::vector<double>& v) { return cost(v[0], v[1]); }, {bx, by}, {step, step}, 60);
    double lam = std::atan2(x[1], x[0]) * 180.0 / kPi;
    if (lam < 0.0) lam += 360.0;
    m.runout = {std::hypot(x[0], x[1]), lam};
    fit_phase(m);
    if (m.lowpass_hz > 0.0 && any_angle_) {
      const double fs = p_.front().fs_hz;
      auto cost4 = [&](const std::vector<double>& v) {
        const double fc = std::exp(v[3]);
        if (fc < 0.1 * fs || fc > 3.0 * fs || v[2] < -5.0 || v[2] > 10.0) return 1e300;
        m.lowpass_hz = fc;
        m.delay_s = v[2] * 1e-4;
        return cost(v[0], v[1]);
      };
      const double lr = m.runout.lambda_deg * kPi / 180.0;
      const double st = std::max(0.1 * m.runout.rho_mm, 2e-4);
      const auto y = nelder_mead(cost4,
                                 {m.runout.rho_mm * std::cos(lr), m.runout.rho_mm * std::sin(lr), m.delay_s * 1e4,
                                  std::log(m.lowpass_hz)},
                                 {st, st, 0.05, 0.1}, 80);
      double l2 = std::atan2(y[1], y[0]) * 180.0 / kPi;
      if (l2 < 0.0) l2 += 360.0;
      m.runout = {std::hypot(y[0], y[1]), l2};
      m.delay_s = y[2] * 1e-4;
      m.lowpass_hz = std::exp(y[3]);
    }
    return m;
  }

  ForceModel fit_mode(ForceModel m) {
    // The mode is searched with the delay alone (a low-pass would take part of its phase), the
    // low-pass found again after, then all refined together.
    m.lowpass_hz = 0.0;
    fit_phase(m, false);
    const Prep& p0 = p_.front();
    const double f_lo = std::max(100.0, 1.5 * p0.f_rev_hz * p0.run->cut.flutes);
    const double f_hi = 0.45 * p0.fs_hz;
    auto cost = [&](double f, double z) {
      if (!(f > f_lo * 0.9 && f < f_hi * 1.05 && z > 0.003 && z < 0.3)) return 1e300;
      m.mode = SensorMode{f, z};
      return solve(m, all_).ssr;
    };
    double bf = f_lo, bz = 0.05, bc = 1e300;
    for (double f = f_lo; f <= f_hi; f *= 1.03)
      for (double z : {0.02, 0.05, 0.12}) {
        const double c = cost(f, z);
        if (c < bc) {
          bc = c;
          bf = f;
          bz = z;
        }
      }
    // The mode's phase and the delay trade against each other: refine them together.
    const double d0 = m.delay_s;
    auto cost3 = [&](const std::vector<double>& v) {
      if (any_angle_) {
        if (v[2] < -5.0 || v[2] > 10.0) return 1e300;
        m.delay_s = v[2] * 1e-4;
      }
      return cost(std::exp(v[0]), std::exp(v[1]));
    };
    auto x = nelder_mead(cost3, {std::log(bf), std::log(bz), d0 * 1e4}, {0.02, 0.3, 0.2}, 80);
    x = nelder_mead(cost3, x, {0.005, 0.1, 0.05}, 60);
    m.mode = SensorMode{std::exp(x[0]), std::exp(x[1])};
    if (any_angle_) m.delay_s = x[2] * 1e-4;
    fit_phase(m);
    if (m.lowpass_hz > 0.0) {
      auto cost4 = [&](const std::vector<double>& v) {
        const double fc = std::exp(v[3]);
        if (fc < 0.1 * p0.fs_hz || fc > 3.0 * p0.fs_hz) return 1e300;
        m.lowpass_hz = fc;
        return cost3(v);
      };
      const auto y = nelder_mead(cost4,
                                 {std::log(m.mode->f_hz), std::log(m.mode->zeta), m.delay_s * 1e4, std::log(m.lowpass_hz)},
                                 {0.005, 0.1, 0.05, 0.1}, 80);
      m.mode = SensorMode{std::exp(y[0]), std::exp(y[1])};
      m.delay_s = y[2] * 1e-4;
      m.lowpass_hz = std::exp(y[3]);
    }
    return m;
  }

  ForceModel fit_exponential(ForceModel m, const std::vector<int>& use) {
    auto cost = [&](double lc) {
      m.k.exponential = true;
      m.k.c_per_mm = std::exp(lc);
      sm_.build(m.runout, m.k.c_per_mm, kExpRegressors, use.size() == all_.size() ? nullptr : &use);
      const Fit f = sm_.solve(m, use);
      // A size effect raises K as the chip thins (b_t > 0, Duan 2025); the other sign is not one.
      return f.model.k.b[0] > 0.0 ? f.ssr : 1e300;
    };
    double best = std::log(2.0), bc = 1e300;
    for (double lc = std::log(2.0); lc <= std::log(2000.0); lc += 0.35) {
      const double c = cost(lc);
      if (c < bc) {
        bc = c;
        best = lc;
      }
    }
    const double lc = golden(cost, best - 0.35, best + 0.35, 12);
    m.k.exponential = true;
    m.k.c_per_mm = std::exp(lc);
    return m;
  }

  // Wear: the de-meaned revolutions' scale against the model, regressed on the cut length.
  ForceModel fit_wear(ForceModel m) {
    for (int it = 0; it < 2; ++it) {
      const Fit f = solve(m, all_);
      double sl = 0.0, ss = 0.0, sll = 0.0, sls = 0.0, n = 0.0;
      ForceModel unscaled = f.model;
      unscaled.wear_per_mm = 0.0;
      for (std::size_t i = 0; i < p_.size(); ++i) {
        const Prep& p = p_[i];
        const auto pred = sm_.predict(i, unscaled, f.coef);
        const int R = p.zero.revolutions;
        const int na = p.has_fz ? 3 : 2;
        std::vector<double> cnt(R, 0.0), L(R, 0.0);
        std::array<std::vector<double>, 3> gm, mm;
        for (int a = 0; a < 3; ++a) {
          gm[a].assign(R, 0.0);
          mm[a].assign(R, 0.0);
        }
        for (std::size_t k = 0; k < p.theta.size(); ++k) {
          const int r = p.rev[k];
          if (!is_fit_rev(r)) continue;
          cnt[r] += 1.0;
          L[r] += cut_length_at(p, p.run->t_s[k]);
          for (int a = 0; a < na; ++a) {
            gm[a][r] += zeroed(p, a, k);
            mm[a][r] += pred[a][k];
          }
        }
        std::vector<double> num(R, 0.0), den(R, 0.0);
        for (std::size_t k = 0; k < p.theta.size(); ++k) {
          const int r = p.rev[k];
          if (!is_fit_rev(r)) continue;
          for (int a = 0; a < na; ++a) {
            const double dm = pred[a][k] - mm[a][r] / cnt[r];
            num[r] += (zeroed(p, a, k) - gm[a][r] / cnt[r]) * dm;
            den[r] += dm * dm;
          }
        }
        for (int r = 0; r < R; ++r) {
          if (cnt[r] <= 0.0 || den[r] <= 0.0) continue;
          const double s = num[r] / den[r], Lr = L[r] / cnt[r];
          sl += Lr;
          ss += s;
          sll += Lr * Lr;
          sls += Lr * s;
          n += 1.0;
        }
      }
      const double Lm = sl / n, sm = ss / n;
      const double beta = (sls - n * Lm * sm) / std::max(sll - n * Lm * Lm, 1e-30);
      const double s_ref = sm;   // the scale at the mean cut length
      m.wear_L_ref_mm = Lm;
      m.wear_per_mm = beta / s_ref;   // the scale is measured against the unscaled template: the whole law
      for (Prep& p : p_) {
        set_zero(p, m.wear_per_mm, p.mean_fit_N);
        make_bins(p);
      }
    }
    return m;
  }

  void reset_zero(double wear_per_mm) {
    for (Prep& p : p_) {
      set_zero(p, wear_per_mm, p.mean_fit_N);
      make_bins(p);
    }
  }

  // Held-out revolutions: rms(F - model)/rms(F) per axis, F the zero-corrected log.
  Evaluated evaluate(const ForceModel& m) {
    Evaluated ev;
    ev.fit = solve(m, all_);
    std::array<double, 3> num{}, den{};
    for (std::size_t i = 0; i < p_.size(); ++i) {
      const Prep& p = p_[i];
      const auto pred = sm_.predict(i, ev.fit.model, ev.fit.coef);
      const int na = p.has_fz ? 3 : 2;
      for (std::size_t k = 0; k < p.theta.size(); ++k) {
        if (!is_held_rev(p.rev[k])) continue;
        for (int a = 0; a < na; ++a) {
          const double g = zeroed(p, a, k);
          num[a] += std::pow(g - pred[a][k], 2);
          den[a] += std::pow(g, 2);
        }
      }
    }
    int na = 0;
    for (int a = 0; a < 3; ++a) {
      ev.err[a] = den[a] > 0.0 ? std::sqrt(num[a] / den[a]) : 0.0;
      if (den[a] > 0.0) {
        ev.E += ev.err[a];
        ++na;
      }
    }
    ev.E /= std::max(1, na);
    return ev;
  }

  std::array<double, 3> noise_floor() const {
    std::array<double, 3> den{}, num{};
    for (const Prep& p : p_) {
      const int na = p.has_fz ? 3 : 2;
      for (std::size_t k = 0; k < p.theta.size(); ++k) {
        if (!is_held_rev(p.rev[k])) continue;
        for (int a = 0; a < na; ++a) {
          den[a] += std::pow(zeroed(p, a, k), 2);
          num[a] += p.zero.noise_N * p.zero.noise_N;
        }
      }
    }
    std::array<double, 3> out{};
    for (int a = 0; a < 3; ++a) out[a] = den[a] > 0.0 ? std::sqrt(num[a] / den[a]) : 0.0;
    return out;
  }

 private:
  std::vector<Prep>& p_;
  SeriesModel sm_;
  [[maybe_unused]] std::vector<std::string>& notes_;
  std::vector<int> all_;
  bool any_angle_{false};
  bool all_angle_{false};
};

nlohmann::json coefficients_json(const ForceCoefficients& k) {
  nlohmann::json j;
  if (!k.exponential) {
    j = {{"Ktc", k.a[0]}, {"Krc", k.a[1]}, {"Kac", k.a[2]}, {"Kte", k.e[0]}, {"Kre", k.e[1]}, {"Kae", k.e[2]}};
  } else {
    const char* q[3] = {"Kt", "Kr", "Ka"};
    for (int i = 0; i < 3; ++i) {
      j[std::string(q[i]) + "_a"] = k.a[i];
      j[std::string(q[i]) + "_b"] = k.b[i];
      j[std::string(q[i]) + "_c"] = k.c_per_mm;
    }
    j["Kte"] = k.e[0];
    j["Kre"] = k.e[1];
    j["Kae"] = k.e[2];
  }
  return j;
}

nlohmann::json axes_json(const std::array<double, 3>& v) {
  return {{"fx_N", v[0]}, {"fy_N", v[1]}, {"fz_N", v[2]}};
}

std::string percent(double v) { return fmt::format("{:.2f} %", 100.0 * v); }


}  // namespace

namespace {

using Prediction = std::array<std::vector<double>, 3>;

/// Each run prepared, its cut length at entry the sum of the runs before, with a
/// zero offset and drift without wear and its synchronous average.
std::vector<Prep> prepare_runs(const std::vector<ForceRun>& runs, ForceCalibration& R) {
  std::vector<Prep> preps;
  for (const auto& r : runs) {
    preps.push_back(prepare(r, R.notes));
    R.runs.push_back(r.name);
  }
  double L = 0.0;
  for (Prep& p : preps) {
    p.L0_mm = L;
    L += p.v_mm_per_s * (p.zero.t_exit_s - p.zero.t_entry_s);
    set_zero(p, 0.0, {});
    make_bins(p);
  }
  return preps;
}

/// Altintas' average-force regression: revolution means against the model's means (runout 0).
void average_force_regression(Identifier& id, const std::vector<Prep>& preps, ForceCalibration& R) {
  id.sm().build({}, 0.0, kLinearRegressors);
  std::vector<std::array<double, 7>> rows;
  for (std::size_t i = 0; i < preps.size(); ++i)
    for (int a = 0; a < force_axes(preps[i]); ++a) {
      std::array<double, 7> r{};
      for (int q = 0; q < 6; ++q) r[q] = id.sm().mean_regressor(i, q, a);
      r[6] = preps[i].mean_fit_N[a];
      rows.push_back(r);
    }
  Eigen::MatrixXd A(rows.size(), 6);
  Eigen::VectorXd y(rows.size());
  for (std::size_t r = 0; r < rows.size(); ++r) {
    for (int q = 0; q < 6; ++q) A(r, q) = rows[r][q];
    y(r) = rows[r][6];
  }
  // Columns without information (e.g. one feed only) are left at 0 with an infinite error.
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(A);
  const Eigen::VectorXd x = qr.solve(y);
  for (int q = 0; q < 3; ++q) {
    R.average_force.a[q] = x(q);
    R.average_force.e[q] = x(3 + q);
  }
  const double dof = static_cast<double>(rows.size()) - 6.0;
  if (dof > 0.0 && qr.rank() == 6) {
    const double s2 = (y - A * x).squaredNorm() / dof;
    const Eigen::MatrixXd cov = (A.transpose() * A).inverse() * s2;
    for (int q = 0; q < 6; ++q) R.average_force_stderr[q] = std::sqrt(std::max(0.0, cov(q, q)));
  } else {
    R.average_force_stderr.fill(std::numeric_limits<double>::infinity());
    R.notes.push_back(fmt::format("average-force regression: {} equations for 6 coefficients (rank {}): standard "
                                  "errors not available; use more feeds",
                                  rows.size(), qr.rank()));
  }
}

/// The mean of the axes' noise floors (those logged).
double mean_noise_floor(const std::array<double, 3>& floor) {
  double floor_E = 0.0;
  int na = 0;
  for (int a = 0; a < 3; ++a)
    if (floor[a] > 0.0) {
      floor_E += floor[a];
      ++na;
    }
  return floor_E / std::max(1, na);
}

/// The catalogue's effects tried one after the other on the current model `cur`:
/// each is recorded with its held-out errors and kept only where it lowers them.
class EffectSearch {
 public:
  EffectSearch(ForceCalibration& R, Evaluated cur, double floor_E) : R_(R), cur_(std::move(cur)), floor_E_(floor_E) {}
  const Evaluated& current() const { return cur_; }

  /// No axis's held-out error rises, and the mean falls by 2 % of it or a tenth of its
  /// excess over the noise floor, whichever is more.
  bool accept(const Evaluated& cand, std::string& why) const {
    const Evaluated& old = cur_;
    for (int a = 0; a < 3; ++a)
      if (cand.err[a] > old.err[a] * (1.0 + 1e-3) + 1e-6) {
        why = fmt::format("{} held-out error would rise {} -> {}", kAxisNames[a], percent(old.err[a]), percent(cand.err[a]));
        return false;
      }
    const double need = std::max(0.02 * old.E, 0.1 * (old.E - floor_E_));
    if (old.E - cand.E < need) {
      why = fmt::format("mean held-out error {} -> {}: less than the {} needed (2 % of it, or a tenth of its excess over "
                        "the noise floor {})",
                        percent(old.E), percent(cand.E), percent(need), percent(floor_E_));
      return false;
    }
    why = fmt::format("mean held-out error {} -> {} (noise floor {})", percent(old.E), percent(cand.E), percent(floor_E_));
    return true;
  }

  /// Records candidate `effect`; when `ok`, adds it (evidence: `evidence` then why) and
  /// makes it the current model.
  void decide(const std::string& effect, const Evaluated& cand, bool ok, const std::string& why,
              const nlohmann::json& params, const std::string& evidence) {
    R_.candidates.push_back({{"effect", effect}, {"accepted", ok}, {"params", params},
                             {"error_held_out", axes_json(cand.err)}, {"reason", why}});
    if (!ok) return;
    R_.added.push_back({effect, params, evidence + "; " + why});
    cur_ = cand;
  }

  /// Tries `effect` fitted as `cm` on the current model.
  template <typename Params, typename Evidence>
  bool consider(Identifier& id, const std::string& effect, const ForceModel& cm, Params&& params,
                Evidence&& evidence) {
    const Evaluated cand = id.evaluate(cm);
    std::string why;
    const bool ok = accept(cand, why);
    decide(effect, cand, ok, why, params(cand.fit.model), evidence(cand.fit.model));
    return ok;
  }

  /// tool_wear (last: it changes the drift); kept only when the coefficients grow with
  /// cut length, else the zero goes back to no wear.
  void consider_wear(Identifier& id) {
    const Evaluated cand = id.evaluate(id.fit_wear(cur_.fit.model));
    std::string why;
    bool ok = accept(cand, why);
    if (ok && cand.fit.model.wear_per_mm <= 0.0) {
      ok = false;
      why += "; but the coefficients fall with cut length (not wear)";
    }
    const ForceModel& m = cand.fit.model;
    const nlohmann::json params = {{"wear_per_mm", m.wear_per_mm},
                                   {"L_ref_mm", m.wear_L_ref_mm},
                                   {"law", "K(L) = K(L_ref) (1 + w (L - L_ref)), L the cut length along the feed"}};
    decide("tool_wear", cand, ok, why, params,
           fmt::format("coefficients grow {:.3f} % per mm of cut", 100.0 * m.wear_per_mm));
    if (!ok) id.reset_zero(0.0);
  }

 private:
  ForceCalibration& R_;
  Evaluated cur_;
  double floor_E_;
};

/// runout, sensor_resonance, size_effect and tool_wear, in that order, from `base`.
Evaluated search_effects(Identifier& id, const std::vector<Prep>& preps, ForceCalibration& R, const Evaluated& base) {
  EffectSearch search(R, base, mean_noise_floor(R.noise_floor));
  const char* pattern = preps.front().has_angle ? "spindle_deg" : "tooth pattern";
  search.consider(
      id, "runout", id.fit_runout(search.current().fit.model),
      [](const ForceModel& m) {
        return nlohmann::json{{"rho_mm", m.runout.rho_mm}, {"lambda_deg", m.runout.lambda_deg}};
      },
      [&](const ForceModel& m) {
        return fmt::format("rho {:.4f} mm at lambda {:.1f} deg from the per-revolution pattern ({})", m.runout.rho_mm,
                           m.runout.lambda_deg, pattern);
      });
  search.consider(
      id, "sensor_resonance", id.fit_mode(search.current().fit.model),
      [](const ForceModel& m) {
        return nlohmann::json{{"f_hz", m.mode->f_hz}, {"zeta", m.mode->zeta},
                              {"model", "H(s) = wn^2/(s^2 + 2 zeta wn s + wn^2) on fx, fy, fz"}};
      },
      [](const ForceModel& m) {
        return fmt::format("a sensor mode at {:.0f} Hz, zeta {:.3f}, in the force output", m.mode->f_hz, m.mode->zeta);
      });
  search.consider(
      id, "size_effect", id.fit_exponential(search.current().fit.model, id.all()),
      [](const ForceModel& m) { return coefficients_json(m.k); },
      [](const ForceModel& m) {
        return fmt::format("K(h) = a + b exp(-c h), c = {:.1f} 1/mm (Duan 2025 eq. 1)", m.k.c_per_mm);
      });
  search.consider_wear(id);
  return search.current();
}

/// Duan's exponential K(h) over all feeds and per feed (runout and sensor path as identified).
void exponential_per_feed(Identifier& id, const std::vector<Prep>& preps, ForceCalibration& R) {
  ForceModel e = id.fit_exponential(R.after, id.all());
  R.exponential_joint = id.solve(e, id.all()).model.k;
  for (std::size_t i = 0; i < preps.size(); ++i) {
    FeedResult fr;
    fr.run = preps[i].run->name;
    fr.fz_mm = preps[i].run->cut.feed_per_tooth_mm();
    const std::vector<int> one{static_cast<int>(i)};
    ForceModel ei = id.fit_exponential(R.after, one);
    id.sm().build(ei.runout, ei.k.c_per_mm, kExpRegressors, &one);
    fr.exponential = id.sm().solve(ei, one).model.k;
    R.feeds.push_back(fr);
  }
}

/// Measured and model forces of a run's steady revolutions in 360 bins of the
/// spindle angle (sums and counts), and their means.
struct RevolutionBins {
  static constexpr int B = 360;
  std::vector<double> w = std::vector<double>(B, 0.0), th = std::vector<double>(B, 0.0);
  std::array<std::vector<double>, 3> bm, bp;

  RevolutionBins(const Prep& p, const Prediction& pred, FeedResult& fr) {
    for (int a = 0; a < 3; ++a) {
      bm[a].assign(B, 0.0);
      bp[a].assign(B, 0.0);
    }
    std::array<double, 3> sm{}, smod{};
    double cnt = 0.0;
    for (std::size_t k = 0; k < p.theta.size(); ++k) {
      if (p.rev[k] < 0) continue;
      double t = std::fmod(p.theta[k], kTwoPi);
      if (t < 0.0) t += kTwoPi;
      const int bi = std::min(B - 1, static_cast<int>(t / kTwoPi * B));
      w[bi] += 1.0;
      th[bi] += t;
      cnt += 1.0;
      for (int a = 0; a < force_axes(p); ++a) {
        const double g = zeroed(p, a, k);
        bm[a][bi] += g;
        bp[a][bi] += pred[a][k];
        sm[a] += g;
        smod[a] += pred[a][k];
      }
    }
    for (int a = 0; a < 3; ++a) {
      fr.mean_measured_N[a] = sm[a] / cnt;
      fr.mean_model_N[a] = smod[a] / cnt;
    }
  }
};

/// One revolution of measured and model (bin means), its peak-to-peak and its
/// spindle-frequency line.
void revolution_shape(const RevolutionBins& bins, FeedResult& fr) {
  std::array<cd, 3> h1m{}, h1p{};
  std::array<double, 3> lo, hi, lop, hip;
  lo.fill(1e300);
  hi.fill(-1e300);
  lop.fill(1e300);
  hip.fill(-1e300);
  double wsum = 0.0;
  for (int bi = 0; bi < RevolutionBins::B; ++bi) {
    if (bins.w[bi] <= 0.0) continue;
    const double t = bins.th[bi] / bins.w[bi];
    fr.rev_theta_deg.push_back(t * 180.0 / kPi);
    wsum += 1.0;
    for (int a = 0; a < 3; ++a) {
      const double vm = bins.bm[a][bi] / bins.w[bi], vp = bins.bp[a][bi] / bins.w[bi];
      fr.rev_measured_N[a].push_back(vm);
      fr.rev_model_N[a].push_back(vp);
      h1m[a] += vm * std::polar(1.0, -t);
      h1p[a] += vp * std::polar(1.0, -t);
      lo[a] = std::min(lo[a], vm);
      hi[a] = std::max(hi[a], vm);
      lop[a] = std::min(lop[a], vp);
      hip[a] = std::max(hip[a], vp);
    }
  }
  for (int a = 0; a < 3; ++a) {
    fr.p2p_measured_N[a] = hi[a] - lo[a];
    fr.p2p_model_N[a] = hip[a] - lop[a];
    fr.spindle_line_measured_N[a] = 2.0 * std::abs(h1m[a]) / wsum;
    fr.spindle_line_model_N[a] = 2.0 * std::abs(h1p[a]) / wsum;
  }
}

/// Shapes of measured and model per feed: means, one revolution, peak-to-peak, spindle-frequency line.
void feed_shapes(Identifier& id, const std::vector<Prep>& preps, ForceCalibration& R) {
  const Fit f = id.solve(R.after, id.all());
  for (std::size_t i = 0; i < preps.size(); ++i) {
    const Prediction pred = id.sm().predict(i, f.model, f.coef);
    const RevolutionBins bins(preps[i], pred, R.feeds[i]);
    revolution_shape(bins, R.feeds[i]);
  }
}

/// The largest power of two of steady samples every run has.
std::size_t spectrum_length(const std::vector<Prep>& preps) {
  std::size_t nfft = 0;
  for (const Prep& p : preps) {
    std::size_t c = 0;
    for (int r : p.rev) c += r >= 0;
    std::size_t m2 = 1;
    while (m2 * 2 <= c) m2 *= 2;
    nfft = nfft == 0 ? m2 : std::min(nfft, m2);
  }
  return nfft;
}

/// Hann-windowed amplitude spectrum of the residual of `model`, averaged over the runs
/// logged at rate fs, from each run's first steady sample.
void residual_spectrum(Identifier& id, const std::vector<Prep>& preps, const ForceModel& model, double fs,
                       std::size_t nfft, std::array<std::vector<double>, 3>& out) {
  for (auto& v : out) v.assign(nfft / 2, 0.0);
  const Fit f = id.solve(model, id.all());
  int used = 0;
  for (std::size_t i = 0; i < preps.size(); ++i) {
    const Prep& p = preps[i];
    if (std::abs(p.fs_hz - fs) > 1e-6 * fs) continue;
    const Prediction pred = id.sm().predict(i, f.model, f.coef);
    std::size_t k0 = 0;
    while (k0 < p.rev.size() && p.rev[k0] < 0) ++k0;
    ++used;
    for (int a = 0; a < force_axes(p); ++a) {
      std::vector<cd> x(nfft);
      double wsum = 0.0;
      for (std::size_t k = 0; k < nfft; ++k) {
        const double win = 0.5 - 0.5 * std::cos(kTwoPi * k / nfft);
        x[k] = win * (zeroed(p, a, k0 + k) - pred[a][k0 + k]);
        wsum += win;
      }
      fft_in_place(x);
      for (std::size_t k = 0; k < nfft / 2; ++k) out[a][k] += 2.0 * std::abs(x[k]) / wsum;
    }
  }
  for (auto& v : out)
    for (double& y : v) y /= std::max(1, used);
}

/// Residual spectra, before and after, averaged over the runs logged at the first run's rate.
void residual_spectra(Identifier& id, const std::vector<Prep>& preps, ForceCalibration& R) {
  R.spindle_hz = preps.front().f_rev_hz;
  R.tooth_hz = R.spindle_hz * preps.front().run->cut.flutes;
  const double fs = preps.front().fs_hz;
  const std::size_t nfft = spectrum_length(preps);
  if (nfft < 64) return;
  R.spectrum_f_hz.resize(nfft / 2);
  for (std::size_t k = 0; k < nfft / 2; ++k) R.spectrum_f_hz[k] = k * fs / nfft;
  residual_spectrum(id, preps, R.before, fs, nfft, R.spectrum_before_N);
  residual_spectrum(id, preps, R.after, fs, nfft, R.spectrum_after_N);
}

/// Feed h's mean-force error and normalised RMS error predicted by `model` fitted on `use`.
nlohmann::json held_out_errors(Identifier& id, const Prep& p, int h, const ForceModel& model,
                               const std::vector<int>& use) {
  const Fit f = id.solve(model, use);
  const Prediction pred = id.sm().predict(static_cast<std::size_t>(h), f.model, f.coef);
  std::array<double, 3> mm{}, mp{}, num{}, den{};
  for (std::size_t k = 0; k < p.theta.size(); ++k) {
    if (p.rev[k] < 0) continue;
    for (int a = 0; a < force_axes(p); ++a) {
      const double g = zeroed(p, a, k);
      mm[a] += g;
      mp[a] += pred[a][k];
      num[a] += std::pow(g - pred[a][k], 2);
      den[a] += g * g;
    }
  }
  std::array<double, 3> mean_err{}, err{};
  for (int a = 0; a < 3; ++a) {
    mean_err[a] = mm[a] != 0.0 ? (mp[a] - mm[a]) / std::abs(mm[a]) : 0.0;
    err[a] = den[a] > 0.0 ? std::sqrt(num[a] / den[a]) : 0.0;
  }
  return {{"mean_force_error", axes_json(mean_err)}, {"error", axes_json(err)}};
}

/// A held-out feed: the middle one, predicted by a fit on the others.
nlohmann::json held_out_feed(Identifier& id, const std::vector<Prep>& preps, const ForceCalibration& R) {
  const std::size_t n = preps.size();
  const int h = static_cast<int>(n / 2);
  std::vector<int> use;
  for (int i = 0; i < static_cast<int>(n); ++i)
    if (i != h) use.push_back(i);
  nlohmann::json hf = {{"run", preps[h].run->name}, {"fz_mm", preps[h].run->cut.feed_per_tooth_mm()}};
  hf["before"] = held_out_errors(id, preps[h], h, R.before, use);
  hf["after"] = held_out_errors(id, preps[h], h, R.after, use);
  return hf;
}

}  // namespace

ForceCalibration calibrate_forces(const std::vector<ForceRun>& runs, const ForceCalibrationOptions& opt) {
  if (runs.empty()) throw ConfigError("calibrate: no force run");
  ForceCalibration R;
  std::vector<Prep> preps = prepare_runs(runs, R);
  R.material = runs.front().cut.material;
  Identifier id(preps, opt, R.notes);
  const std::size_t n = preps.size();
  average_force_regression(id, preps, R);

  // Base model: linear coefficients, sensor delay (or the phase of runs without spindle_deg).
  ForceModel m;
  m.phi0_deg.assign(n, 0.0);
  id.fit_phase(m);
  const Evaluated base = id.evaluate(m);
  R.before = base.fit.model;
  R.error_before = base.err;
  R.noise_floor = id.noise_floor();
  const Evaluated found = search_effects(id, preps, R, base);
  // Refit the final model on the zero it uses.
  const Evaluated cur = id.evaluate(found.fit.model);
  R.after = cur.fit.model;
  R.error_after = cur.err;
  for (const Prep& p : preps) R.zero.push_back(p.zero);

  exponential_per_feed(id, preps, R);
  feed_shapes(id, preps, R);
  residual_spectra(id, preps, R);
  if (opt.held_out_feed && n >= 3) R.held_out_feed = held_out_feed(id, preps, R);
  int held_out_revolutions = 0;
  for (const Prep& p : preps) held_out_revolutions += p.zero.revolutions / 2;
  R.validation = fmt::format(
      "normalised RMS rms(F - model)/rms(F) on held-out revolutions (every second whole revolution of the steady cut "
      "of each run; the fit uses the others), F the log less the identified zero offset and drift; {} run(s), {} "
      "held-out revolutions",
      n, held_out_revolutions);
  return R;
}

nlohmann::json force_report_json(const ForceCalibration& r) {
  nlohmann::json cut = coefficients_json(r.after.k);
  cut["runout_rho_mm"] = r.after.runout.rho_mm;
  cut["runout_lambda_deg"] = r.after.runout.lambda_deg;
  if (r.after.mode) {
    cut["sensor_f_hz"] = r.after.mode->f_hz;
    cut["sensor_zeta"] = r.after.mode->zeta;
  }
  if (r.after.wear_per_mm != 0.0) {
    cut["wear_per_mm"] = r.after.wear_per_mm;
    cut["wear_L_ref_mm"] = r.after.wear_L_ref_mm;
  }
  cut["delay_s"] = r.after.delay_s;
  if (r.after.lowpass_hz > 0.0) cut["sensor_lowpass_hz"] = r.after.lowpass_hz;
  nlohmann::json j;
  j["parameters_identified"] = {{"cut", cut}};
  const char* se_names[6] = {"Ktc", "Krc", "Kac", "Kte", "Kre", "Kae"};
  nlohmann::json se, se_avg;
  for (int q = 0; q < 6; ++q) {
    se[se_names[q]] = r.after.k_stderr[q];
    se_avg[se_names[q]] = std::isfinite(r.average_force_stderr[q]) ? nlohmann::json(r.average_force_stderr[q])
                                                                    : nlohmann::json(nullptr);
  }
  j["standard_errors"] = {{"cut", se}};
  j["effects_added"] = nlohmann::json::array();
  for (const auto& e : r.added)
    j["effects_added"].push_back({{"effect", e.effect}, {"axis", nullptr}, {"params", e.params}, {"evidence", e.evidence}});
  j["error_before"] = axes_json(r.error_before);
  j["error_after"] = axes_json(r.error_after);
  j["validation"] = r.validation;
  nlohmann::json ident;
  ident["runs"] = r.runs;
  ident["average_force"] = {{"coefficients", coefficients_json(r.average_force)}, {"standard_errors", se_avg},
                            {"method", "Altintas: revolution-mean forces over the feeds, least squares (runout 0)"}};
  nlohmann::json before = coefficients_json(r.before.k);
  before["delay_s"] = r.before.delay_s;
  ident["model_before"] = before;
  ident["exponential_joint"] = coefficients_json(r.exponential_joint);
  ident["noise_floor"] = axes_json(r.noise_floor);
  ident["candidates"] = r.candidates;
  ident["zero"] = nlohmann::json::array();
  for (std::size_t i = 0; i < r.zero.size(); ++i) {
    const RunZero& z = r.zero[i];
    ident["zero"].push_back({{"run", r.runs[i]},
                             {"offset_N", axes_json(z.offset_N)},
                             {"drift_N_per_s", axes_json(z.drift_N_per_s)},
                             {"drift_source", z.drift_source},
                             {"noise_N", z.noise_N},
                             {"t_entry_s", z.t_entry_s},
                             {"t_exit_s", z.t_exit_s},
                             {"steady_s", {z.t_steady_begin_s, z.t_steady_end_s}},
                             {"revolutions", z.revolutions}});
  }
  ident["feeds"] = nlohmann::json::array();
  for (const auto& f : r.feeds)
    ident["feeds"].push_back({{"run", f.run},
                              {"fz_mm", f.fz_mm},
                              {"mean_measured_N", axes_json(f.mean_measured_N)},
                              {"mean_model_N", axes_json(f.mean_model_N)},
                              {"peak_to_peak_measured_N", axes_json(f.p2p_measured_N)},
                              {"peak_to_peak_model_N", axes_json(f.p2p_model_N)},
                              {"spindle_line_measured_N", axes_json(f.spindle_line_measured_N)},
                              {"spindle_line_model_N", axes_json(f.spindle_line_model_N)},
                              {"exponential", coefficients_json(f.exponential)}});
  if (!r.held_out_feed.is_null()) ident["held_out_feed"] = r.held_out_feed;
  ident["notes"] = r.notes;
  j["identification"] = ident;
  return j;
}

std::string force_report_markdown(const ForceCalibration& r, const std::string& source) {
  std::string s = fmt::format("# Force calibration of {}\n\n{} run(s): {}.\n\n", source, r.runs.size(), [&] {
    std::string l;
    for (const auto& n : r.runs) l += (l.empty() ? "" : ", ") + n;
    return l;
  }());
  const auto& k = r.after.k;
  s += "## Identified\n\n| coefficient | value | standard error | average-force method |\n|---|---|---|---|\n";
  const char* names[6] = {"Ktc N/mm^2", "Krc N/mm^2", "Kac N/mm^2", "Kte N/mm", "Kre N/mm", "Kae N/mm"};
  for (int q = 0; q < 6; ++q) {
    const double v = q < 3 ? k.a[q] : k.e[q - 3];
    const double va = q < 3 ? r.average_force.a[q] : r.average_force.e[q - 3];
    s += fmt::format("| {} | {:.2f} | {:.2f} | {:.2f} +- {:.2f} |\n", names[q], v, r.after.k_stderr[q], va,
                     r.average_force_stderr[q]);
  }
  if (k.exponential)
    s += fmt::format("\nSize effect (Duan 2025 eq. 1): Kt = {:.1f} + {:.1f} exp(-{:.1f} h), Kr = {:.1f} + {:.1f} "
                     "exp(-c h), Ka = {:.1f} + {:.1f} exp(-c h) N/mm^2.\n",
                     k.a[0], k.b[0], k.c_per_mm, k.a[1], k.b[1], k.a[2], k.b[2]);
  s += fmt::format("\nRunout rho {:.4f} mm at lambda {:.1f} deg; sensor delay {:.1f} us{}{}.\n", r.after.runout.rho_mm,
                   r.after.runout.lambda_deg, r.after.delay_s * 1e6,
                   r.after.mode ? fmt::format("; sensor mode {:.0f} Hz, zeta {:.3f}", r.after.mode->f_hz, r.after.mode->zeta)
                                : std::string(),
                   r.after.wear_per_mm != 0.0 ? fmt::format("; wear {:.4f} %/mm", 100 * r.after.wear_per_mm) : std::string());
  s += "\n## Effects\n\n";
  if (r.added.empty()) s += "none: the data resolves nothing beyond the model.\n\n";
  for (const auto& e : r.added) s += fmt::format("- **{}**: {}\n", e.effect, e.evidence);
  s += "\nCandidates tried:\n\n";
  for (const auto& c : r.candidates)
    s += fmt::format("- {} ({}): {}\n", c["effect"].get<std::string>(), c["accepted"].get<bool>() ? "added" : "not added",
                     c["reason"].get<std::string>());
  s += "\n## Held-out error\n\n| axis | before | after | noise floor |\n|---|---|---|---|\n";
  for (int a = 0; a < 3; ++a)
    s += fmt::format("| {} | {} | {} | {} |\n", kAxisNames[a], percent(r.error_before[a]), percent(r.error_after[a]),
                     percent(r.noise_floor[a]));
  s += "\n" + r.validation + ".\n";
  s += "\n## Per feed\n\n| run | fz mm | mean fx meas/model N | mean fy | mean fz | p2p fy meas/model N | spindle line fy "
       "meas/model N |\n|---|---|---|---|---|---|---|\n";
  for (const auto& f : r.feeds)
    s += fmt::format("| {} | {:.4f} | {:.2f} / {:.2f} | {:.2f} / {:.2f} | {:.2f} / {:.2f} | {:.2f} / {:.2f} | {:.2f} / "
                     "{:.2f} |\n",
                     f.run, f.fz_mm, f.mean_measured_N[0], f.mean_model_N[0], f.mean_measured_N[1], f.mean_model_N[1],
                     f.mean_measured_N[2], f.mean_model_N[2], f.p2p_measured_N[1], f.p2p_model_N[1],
                     f.spindle_line_measured_N[1], f.spindle_line_model_N[1]);
  if (!r.held_out_feed.is_null())
    s += fmt::format("\nHeld-out feed {} (fit on the others): mean-force error {} (after), waveform error {}.\n",
                     r.held_out_feed["run"].get<std::string>(), r.held_out_feed["after"]["mean_force_error"].dump(),
                     r.held_out_feed["after"]["error"].dump());
  s += "\n## Zero offset and drift\n\n";
  for (std::size_t i = 0; i < r.zero.size(); ++i)
    s += fmt::format("- {}: offset ({:.2f}, {:.2f}, {:.2f}) N, drift ({:.3f}, {:.3f}, {:.3f}) N/s ({}), noise {:.2f} N, "
                     "entry {:.4f} s, {} steady revolutions\n",
                     r.runs[i], r.zero[i].offset_N[0], r.zero[i].offset_N[1], r.zero[i].offset_N[2],
                     r.zero[i].drift_N_per_s[0], r.zero[i].drift_N_per_s[1], r.zero[i].drift_N_per_s[2],
                     r.zero[i].drift_source, r.zero[i].noise_N, r.zero[i].t_entry_s, r.zero[i].revolutions);
  s += "\n## Reproduce a cut\n\n```\ntwin cut --tool OUT/tool.yaml --material OUT/material.yaml --rpm RPM --fz FZ "
       "--ae AE --ap AP";
  if (r.after.mode) s += fmt::format(" --sensor-f {:.1f} --sensor-zeta {:.4f}", r.after.mode->f_hz, r.after.mode->zeta);
  if (r.after.wear_per_mm != 0.0)
    s += fmt::format(" --wear-scale S   # S = 1 + {:.5g} (L - {:.1f}), L mm of cut", r.after.wear_per_mm,
                     r.after.wear_L_ref_mm);
  s += "\n```\n";
  if (!r.notes.empty()) {
    s += "\n## Notes\n\n";
    for (const auto& n : r.notes) s += "- " + n + "\n";
  }
  return s;
}

namespace {

// A YAML double-quoted scalar: every character that is not plain printable ASCII is escaped.
std::string yaml_quote(const std::string& in) {
  std::string q = "\"";
  for (unsigned char c : in) {
    if (c == '"' || c == '\\') {
      q += '\\';
      q += static_cast<char>(c);
    } else if (c < 0x20 || c >= 0x7f) {
      q += fmt::format("\\x{:02x}", c);
    } else {
      q += static_cast<char>(c);
    }
  }
  return q + "\"";
}

// A comment line: no line break can end it early.
std::string comment(const std::string& in) {
  std::string c;
  for (char ch : in) c += (ch == '\n' || ch == '\r') ? ' ' : ch;
  return "# " + c + "\n";
}

}  // namespace

std::string material_yaml(const ForceCalibration& r, const std::string& source) {
  const auto& k = r.after.k;
  std::string s = comment("identified by twin calibrate from " + source);
  if (r.after.wear_per_mm != 0.0)
    s += comment(fmt::format("coefficients at cut length {:.1f} mm; they grow by {:.4f} % per mm of cut (tool_wear)",
                             r.after.wear_L_ref_mm, 100 * r.after.wear_per_mm));
  const std::string name = r.material.empty() ? std::string("calibrated") : r.material + " (calibrated)";
  s += fmt::format("material:\n  name: {}\n  sets:\n    - lead_deg: 0\n      tilt_deg: 0\n", yaml_quote(name));
  if (k.exponential) {
    const char* q[3] = {"Kt", "Kr", "Ka"};
    for (int i = 0; i < 3; ++i)
      s += fmt::format("      {}: {{a_N_per_mm2: {:.6g}, b_N_per_mm2: {:.6g}, c_per_mm: {:.6g}}}\n", q[i], k.a[i], k.b[i],
                       k.c_per_mm);
  } else {
    s += fmt::format("      Ktc_N_per_mm2: {:.6g}\n      Krc_N_per_mm2: {:.6g}\n      Kac_N_per_mm2: {:.6g}\n", k.a[0],
                     k.a[1], k.a[2]);
  }
  s += fmt::format("      Kte_N_per_mm: {:.6g}\n      Kre_N_per_mm: {:.6g}\n      Kae_N_per_mm: {:.6g}\n", k.e[0], k.e[1],
                   k.e[2]);
  return s;
}

std::string tool_yaml(const ForceCalibration& r, const ForceCut& cut, const std::string& source) {
  std::string s = comment("tool of " + source + " with the runout identified by twin calibrate");
  const char* type = cut.corner_radius_mm == 0.0 ? "flat"
                     : std::abs(cut.corner_radius_mm - 0.5 * cut.diameter_mm) < 1e-12 ? "ball"
                                                                                       : "bull_nose";
  const double flute_length = std::max({2.0 * cut.diameter_mm, 2.0 * cut.ap_mm, cut.corner_radius_mm});
  s += fmt::format(
      "tool:\n  name: calibrated\n  type: {}\n  diameter_mm: {}\n  flutes: {}\n  helix_deg: {}\n  corner_radius_mm: {}\n"
      "  flute_length_mm: {}   # not in the log: twice the diameter\n  runout_rho_mm: {:.6g}\n  runout_lambda_deg: {:.6g}\n",
      type, cut.diameter_mm, cut.flutes, cut.helix_deg, cut.corner_radius_mm, flute_length, r.after.runout.rho_mm,
      r.after.runout.lambda_deg);
  return s;
}

namespace {

// The figures' data files in `out`, drawn by analysis::plot_force_calibration.
void force_plots(const std::filesystem::path& out, const ForceCalibration& r) {
  ForceCalibrationPlots plots;
  // One revolution per feed.
  {
    std::string csv = "feed,theta_deg,fx_meas_N,fx_model_N,fy_meas_N,fy_model_N,fz_meas_N,fz_model_N\n";
    for (std::size_t i = 0; i < r.feeds.size(); ++i) {
      const auto& f = r.feeds[i];
      for (std::size_t b = 0; b < f.rev_theta_deg.size(); ++b)
        csv += fmt::format("{},{:.4f},{:.4f},{:.4f},{:.4f},{:.4f},{:.4f},{:.4f}\n", i, f.rev_theta_deg[b],
                           f.rev_measured_N[0][b], f.rev_model_N[0][b], f.rev_measured_N[1][b], f.rev_model_N[1][b],
                           f.rev_measured_N[2][b], f.rev_model_N[2][b]);
      csv += "\n\n";   // gnuplot data blocks, one per feed (index i)
      plots.feed_fz_mm.push_back(f.fz_mm);
    }
    io::write_file_atomic(out / plots.revolution_name, csv);
  }
  {
    std::string csv = "f_hz,fx_before_N,fy_before_N,fz_before_N,fx_after_N,fy_after_N,fz_after_N\n";
    for (std::size_t k = 0; k < r.spectrum_f_hz.size(); ++k)
      csv += fmt::format("{:.4f},{:.5g},{:.5g},{:.5g},{:.5g},{:.5g},{:.5g}\n", r.spectrum_f_hz[k], r.spectrum_before_N[0][k],
                         r.spectrum_before_N[1][k], r.spectrum_before_N[2][k], r.spectrum_after_N[0][k],
                         r.spectrum_after_N[1][k], r.spectrum_after_N[2][k]);
    io::write_file_atomic(out / plots.spectrum_name, csv);
  }
  plots.spectrum = !r.spectrum_f_hz.empty();
  if (plots.spectrum) plots.spectrum_max_Hz = r.spectrum_f_hz.back();
  plots.spindle_Hz = r.spindle_hz;
  plots.tooth_Hz = r.tooth_hz;
  plot_force_calibration(out, plots);
}

}  // namespace

void run_force_calibration(const std::filesystem::path& series, const std::filesystem::path& out, bool no_plots) {
  const std::vector<ForceRun> runs = load_force_series(series);
  ForceCalibration r = calibrate_forces(runs);
  io::ensure_directory(out);
  if (!no_plots) {
    try {
      force_plots(out, r);
    } catch (const Error& e) {
      r.notes.push_back(fmt::format("plots not drawn: {}", e.what()));
    }
  }
  io::write_file_atomic(out / "material.yaml", material_yaml(r, series.string()));
  io::write_file_atomic(out / "tool.yaml", tool_yaml(r, runs.front().cut, series.string()));
  io::write_file_atomic(out / "report.md", force_report_markdown(r, series.string()));
  io::write_file_atomic(out / "report.json", force_report_json(r).dump(2) + "\n");
  for (const auto& n : r.notes) std::fprintf(stderr, "twin calibrate: note: %s\n", n.c_str());
  std::string added;
  for (const auto& a : r.added) added += (added.empty() ? "" : ", ") + a.effect;
  std::printf("%s\n", fmt::format("calibrated forces of {} ({} runs): Ktc {:.1f} Krc {:.1f} Kac {:.1f} N/mm^2, Kte {:.2f} "
                                  "Kre {:.2f} Kae {:.2f} N/mm, runout {:.4f} mm at {:.1f} deg; effects added: {}; wrote {}",
                                  series.string(), runs.size(), r.after.k.a[0], r.after.k.a[1], r.after.k.a[2],
                                  r.after.k.e[0], r.after.k.e[1], r.after.k.e[2], r.after.runout.rho_mm,
                                  r.after.runout.lambda_deg, added.empty() ? "none" : added, out.string())
                          .c_str());
}

}  // namespace twin::analysis::force
