#include "twin/analysis/linear_analysis.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Eigenvalues>
#include <fmt/format.h>

#include "twin/core/error.hpp"
#include "twin/core/units.hpp"

namespace twin::analysis {

using cd = std::complex<double>;

void LinearPlant::validate(const std::string& where) const {
  auto positive = [&](const char* name, double v) {
    if (!std::isfinite(v) || !(v > 0.0))
      throw ConfigError(fmt::format("{}: {} = {} must be finite and > 0 for the linear analysis", where, name, v));
  };
  positive("Ka", Ka_A_per_V);
  positive("Kt", Kt_Nm_per_A);
  positive("J", J_kg_m2);
  positive("rg", rg_mm_per_rad);
  if (!std::isfinite(B_kg_m2_per_s) || B_kg_m2_per_s < 0.0)
    throw ConfigError(fmt::format("{}: B = {} must be finite and >= 0 for the linear analysis", where, B_kg_m2_per_s));
}

LinearPlant linear_plant(const feeddrive::DriveParams& d) {
  return LinearPlant{d.Ka_A_per_V, d.Kt_Nm_per_A, d.J_kg_m2, d.B_kg_m2_per_s, d.rg_mm_per_rad};
}

FeedforwardGains model_feedforward(const LinearPlant& p) {
  const double g = p.Ka_A_per_V * p.Kt_Nm_per_A * p.rg_mm_per_rad;
  return FeedforwardGains{p.J_kg_m2 / g, p.B_kg_m2_per_s / g};
}

Eigen::MatrixXd matrix_exponential(const Eigen::MatrixXd& M) {
  const double norm = M.cwiseAbs().rowwise().sum().maxCoeff();
  int squarings = 0;
  if (norm > 0.25) squarings = static_cast<int>(std::ceil(std::log2(norm / 0.25)));
  const Eigen::MatrixXd A = M / std::ldexp(1.0, squarings);
  Eigen::MatrixXd result = Eigen::MatrixXd::Identity(M.rows(), M.cols());
  Eigen::MatrixXd term = result;
  // ||A|| <= 1/4: 18 terms bring the truncation below 1e-16 relative.
  for (int n = 1; n <= 18; ++n) {
    term = (term * A) / static_cast<double>(n);
    result += term;
  }
  for (int s = 0; s < squarings; ++s) result = result * result;
  return result;
}

DiscreteLoopModel::DiscreteLoopModel(const LinearPlant& plant, const controller::PositionLoopParams& gains,
                                     const std::string& where)
    : plant_(plant), gains_(gains), Ts_s_(gains.Ts_s) {
  plant_.validate(where);
  gains_.validate(where);
  if (gains_.law != controller::LoopLaw::kFadal)
    throw ConfigError(fmt::format("{}: the linear analysis and tuning cover the FADAL law; this machine closes the {} "
                                  "law (run, replay and calibrate simulate it)",
                                  where, controller::loop_law_name(gains_.law)));
  const double KaKt = plant.Ka_A_per_V * plant.Kt_Nm_per_A;
  Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
  M(0, 0) = -plant.B_kg_m2_per_s / plant.J_kg_m2;
  M(0, 2) = KaKt / plant.J_kg_m2;
  M(1, 0) = plant.rg_mm_per_rad;
  const Eigen::MatrixXd E = matrix_exponential(M * Ts_s_);
  Phi_ = E.topLeftCorner<2, 2>();
  Gamma_ = E.topRightCorner<2, 1>();

  const double Kp = gains.Kp_V_per_mm, Ki = gains.Ki_V_per_s_mm, Kd = gains.Kd_V_s_per_mm, Ts = Ts_s_;
  // u = Ku s for the reference held at 0: e = -x, I = I_prev - Ts x.
  Eigen::RowVector4d Ku(0.0, -(Kp + Ki * Ts + Kd / Ts), Ki, -Kd / Ts);
  A_fb_.setZero();
  A_fb_.topLeftCorner<2, 2>() = Phi_;
  A_fb_.topRows<2>() += Gamma_ * Ku;
  A_fb_(2, 1) = -Ts;
  A_fb_(2, 2) = 1.0;
  A_fb_(3, 1) = -1.0;
}

std::vector<std::complex<double>> DiscreteLoopModel::poles() const {
  std::vector<cd> p;
  if (gains_.Ki_V_per_s_mm == 0.0) {
    // Without Ki the integrator state is disconnected: its pole at z = 1 is not a mode of the loop.
    Eigen::Matrix3d A;
    const int keep[3] = {0, 1, 3};
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) A(i, j) = A_fb_(keep[i], keep[j]);
    Eigen::EigenSolver<Eigen::Matrix3d> es(A, false);
    for (int i = 0; i < 3; ++i) p.push_back(es.eigenvalues()(i));
  } else {
    Eigen::EigenSolver<Eigen::Matrix4d> es(A_fb_, false);
    for (int i = 0; i < 4; ++i) p.push_back(es.eigenvalues()(i));
  }
  std::sort(p.begin(), p.end(), [](cd a, cd b) { return std::abs(a) > std::abs(b); });
  return p;
}

bool DiscreteLoopModel::stable() const {
  for (const cd& p : poles())
    if (!(std::abs(p) < 1.0)) return false;
  return true;
}

cd DiscreteLoopModel::z_of(double f_Hz) const { return std::polar(1.0, 2.0 * kPi * f_Hz * Ts_s_); }

cd DiscreteLoopModel::plant_response(double f_Hz) const {
  const cd z = z_of(f_Hz);
  // [0 1] (zI - Phi)^-1 Gamma with the 2x2 adjugate.
  const cd a = z - Phi_(0, 0), b = -Phi_(0, 1), c = -Phi_(1, 0), d = z - Phi_(1, 1);
  const cd det = a * d - b * c;
  return (-c * Gamma_(0) + a * Gamma_(1)) / det;
}

cd DiscreteLoopModel::controller_response(double f_Hz) const {
  const cd z = z_of(f_Hz);
  const double Ts = Ts_s_;
  return gains_.Kp_V_per_mm + gains_.Ki_V_per_s_mm * Ts * z / (z - 1.0) +
         gains_.Kd_V_s_per_mm * (1.0 - 1.0 / z) / Ts;
}

cd DiscreteLoopModel::feedforward_response(double f_Hz) const {
  const cd z = z_of(f_Hz);
  const cd D = (1.0 - 1.0 / z) / Ts_s_;
  return gains_.K2_V_s_per_mm * D + gains_.K1_V_s2_per_mm * D * D;
}

cd DiscreteLoopModel::loop_response(double f_Hz) const { return controller_response(f_Hz) * plant_response(f_Hz); }
cd DiscreteLoopModel::sensitivity(double f_Hz) const { return 1.0 / (1.0 + loop_response(f_Hz)); }
cd DiscreteLoopModel::complementary(double f_Hz) const {
  const cd L = loop_response(f_Hz);
  return L / (1.0 + L);
}
cd DiscreteLoopModel::position_response(double f_Hz) const {
  const cd P = plant_response(f_Hz);
  const cd C = controller_response(f_Hz);
  return (C + feedforward_response(f_Hz)) * P / (1.0 + C * P);
}
cd DiscreteLoopModel::error_response(double f_Hz) const {
  const cd P = plant_response(f_Hz);
  return (1.0 - feedforward_response(f_Hz) * P) / (1.0 + controller_response(f_Hz) * P);
}

std::vector<double> DiscreteLoopModel::simulate(const std::vector<double>& x_ref_mm) const {
  const double Ts = Ts_s_;
  const auto& g = gains_;
  Eigen::Vector2d p = Eigen::Vector2d::Zero();
  double I = 0.0, e_prev = 0.0, r_prev = 0.0, v_prev = 0.0;
  std::vector<double> x(x_ref_mm.size());
  for (std::size_t k = 0; k < x_ref_mm.size(); ++k) {
    const double r = x_ref_mm[k];
    x[k] = p(1);
    const double e = r - p(1);
    if (k == 0) {
      r_prev = r;
      e_prev = e;
    }
    const double v = (r - r_prev) / Ts;
    const double a = (v - v_prev) / Ts;
    I += Ts * e;
    const double u = g.Kp_V_per_mm * e + g.Ki_V_per_s_mm * I + g.Kd_V_s_per_mm * (e - e_prev) / Ts +
                     g.K1_V_s2_per_mm * a + g.K2_V_s_per_mm * v;
    p = Phi_ * p + Gamma_ * u;
    e_prev = e;
    r_prev = r;
    v_prev = v;
  }
  return x;
}

namespace {

/// Bisection on log f for a sign change of fn between f0 and f1.
template <class Fn>
double bisect_log(Fn&& fn, double f0, double f1) {
  double v0 = fn(f0);
  for (int it = 0; it < 60; ++it) {
    const double fm = std::sqrt(f0 * f1);
    const double vm = fn(fm);
    if ((vm < 0.0) == (v0 < 0.0)) {
      f0 = fm;
      v0 = vm;
    } else {
      f1 = fm;
    }
  }
  return std::sqrt(f0 * f1);
}

/// Golden-section search for the maximum of fn on [a, b] in log f.
template <class Fn>
std::pair<double, double> maximise_log(Fn&& fn, double a, double b) {
  const double gr = (std::sqrt(5.0) - 1.0) / 2.0;
  double la = std::log(a), lb = std::log(b);
  double lc = lb - gr * (lb - la), ld = la + gr * (lb - la);
  double fc = fn(std::exp(lc)), fd = fn(std::exp(ld));
  for (int it = 0; it < 60; ++it) {
    if (fc > fd) {
      lb = ld;
      ld = lc;
      fd = fc;
      lc = lb - gr * (lb - la);
      fc = fn(std::exp(lc));
    } else {
      la = lc;
      lc = ld;
      fc = fd;
      ld = la + gr * (lb - la);
      fd = fn(std::exp(ld));
    }
  }
  const double f = std::exp(0.5 * (la + lb));
  return {f, fn(f)};
}

double phase_margin_at(cd L) {
  double phi = std::arg(L);
  if (phi > 0.0) phi -= 2.0 * kPi;
  return 180.0 + phi * kDegPerRad;
}

}  // namespace

std::vector<FrequencyPoint> frequency_response(const DiscreteLoopModel& m, double f_min_Hz, int points) {
  std::vector<FrequencyPoint> out;
  const double fN = m.nyquist_Hz();
  const int n = std::max(points, 2);
  for (int i = 0; i < n; ++i) {
    const double f = f_min_Hz * std::pow(fN / f_min_Hz, static_cast<double>(i) / static_cast<double>(n - 1));
    FrequencyPoint p;
    p.f_Hz = f;
    p.L = m.loop_response(f);
    p.S = 1.0 / (1.0 + p.L);
    p.T = p.L * p.S;
    p.X_over_R = m.position_response(f);
    p.E_over_R = m.error_response(f);
    out.push_back(p);
  }
  return out;
}

LoopAnalysis analyse_loop(const DiscreteLoopModel& m, double f_min_Hz, int points) {
  LoopAnalysis a;
  a.poles = m.poles();
  a.max_pole_magnitude = std::abs(a.poles.front());
  a.stable = m.stable();
  const double inf = std::numeric_limits<double>::infinity();
  const double fN = m.nyquist_Hz();
  const auto grid = frequency_response(m, f_min_Hz, points);

  // Gain crossovers: |L| = 1.
  a.phase_margin_deg = inf;
  auto gain_fn = [&](double f) { return std::abs(m.loop_response(f)) - 1.0; };
  for (std::size_t i = 1; i < grid.size(); ++i) {
    const double g0 = std::abs(grid[i - 1].L) - 1.0, g1 = std::abs(grid[i].L) - 1.0;
    if ((g0 < 0.0) == (g1 < 0.0)) continue;
    const double fc = bisect_log(gain_fn, grid[i - 1].f_Hz, grid[i].f_Hz);
    const double pm = phase_margin_at(m.loop_response(fc));
    if (pm < a.phase_margin_deg) {
      a.phase_margin_deg = pm;
      a.gain_crossover_Hz = fc;
    }
  }
  // Phase crossovers: Im L = 0 with Re L < 0, counted where |L| < 1.
  a.gain_margin_dB = inf;
  auto consider_gm = [&](double f) {
    const cd L = m.loop_response(f);
    if (L.real() < 0.0 && std::abs(L) < 1.0) {
      const double gm = -20.0 * std::log10(std::abs(L));
      if (gm < a.gain_margin_dB) {
        a.gain_margin_dB = gm;
        a.phase_crossover_Hz = f;
      }
    }
  };
  auto imag_fn = [&](double f) { return m.loop_response(f).imag(); };
  for (std::size_t i = 1; i < grid.size(); ++i) {
    const double i0 = grid[i - 1].L.imag(), i1 = grid[i].L.imag();
    if ((i0 < 0.0) == (i1 < 0.0) || i == grid.size() - 1) continue;
    if (grid[i - 1].L.real() >= 0.0 && grid[i].L.real() >= 0.0) continue;
    consider_gm(bisect_log(imag_fn, grid[i - 1].f_Hz, grid[i].f_Hz));
  }
  consider_gm(fN);  // at Nyquist L is real

  // Sensitivity and complementary peaks.
  std::size_t imax = 0;
  for (std::size_t i = 0; i < grid.size(); ++i) {
    if (std::abs(grid[i].S) > std::abs(grid[imax].S)) imax = i;
    a.complementary_peak = std::max(a.complementary_peak, std::abs(grid[i].T));
  }
  const double lo = grid[imax > 0 ? imax - 1 : 0].f_Hz, hi = grid[std::min(imax + 1, grid.size() - 1)].f_Hz;
  const auto [fs, ms] = maximise_log([&](double f) { return std::abs(m.sensitivity(f)); }, lo, hi);
  a.sensitivity_peak = std::max(ms, std::abs(grid[imax].S));
  a.sensitivity_peak_Hz = ms >= std::abs(grid[imax].S) ? fs : grid[imax].f_Hz;
  a.sensitivity_peak_dB = 20.0 * std::log10(a.sensitivity_peak);

  // -3 dB bandwidths.
  const double half_power = 1.0 / std::sqrt(2.0);
  auto bandwidth = [&](auto&& mag) {
    for (std::size_t i = 1; i < grid.size(); ++i) {
      if (mag(grid[i].f_Hz) < half_power && mag(grid[i - 1].f_Hz) >= half_power)
        return bisect_log([&](double f) { return mag(f) - half_power; }, grid[i - 1].f_Hz, grid[i].f_Hz);
    }
    return fN;
  };
  a.bandwidth_Hz = bandwidth([&](double f) { return std::abs(m.complementary(f)); });
  a.bandwidth_with_feedforward_Hz = bandwidth([&](double f) { return std::abs(m.position_response(f)); });
  a.error_gain_1Hz = std::abs(m.error_response(1.0));
  a.error_gain_10Hz = std::abs(m.error_response(10.0));

  // Step response of the feedback loop.
  if (a.stable) {
    controller::PositionLoopParams fb = m.gains();
    fb.K1_V_s2_per_mm = 0.0;
    fb.K2_V_s_per_mm = 0.0;
    const DiscreteLoopModel feedback(m.plant(), fb);
    const double pmax = std::max(a.max_pole_magnitude, 1e-12);
    const double tau_ticks = pmax < 1.0 ? -1.0 / std::log(pmax) : 1e9;
    const auto n = static_cast<std::size_t>(std::clamp(8.0 * tau_ticks + 2000.0, 2000.0, 300000.0));
    const std::vector<double> x = feedback.simulate(std::vector<double>(n, 1.0));
    double peak = 0.0;
    std::size_t last_out = 0;
    for (std::size_t k = 0; k < n; ++k) {
      peak = std::max(peak, x[k]);
      if (std::abs(x[k] - 1.0) > 0.02) last_out = k;
    }
    a.step_overshoot = std::max(0.0, peak - 1.0);
    a.step_settling_time_s = static_cast<double>(last_out + 1) * m.Ts_s();
  } else {
    a.step_overshoot = inf;
    a.step_settling_time_s = inf;
  }
  return a;
}

std::string format_analysis(const std::string& title, const controller::PositionLoopParams& g, const LoopAnalysis& a) {
  std::string s = fmt::format("{}\n", title);
  s += fmt::format("  gains: Kp {:.6g} V/mm, Ki {:.6g} V/(s mm), Kd {:.6g} V s/mm, K1 {:.6g} V s^2/mm, K2 {:.6g} V s/mm\n",
                   g.Kp_V_per_mm, g.Ki_V_per_s_mm, g.Kd_V_s_per_mm, g.K1_V_s2_per_mm, g.K2_V_s_per_mm);
  s += fmt::format("  closed loop {} (largest pole |z| = {:.6f}); poles:", a.stable ? "stable" : "UNSTABLE",
                   a.max_pole_magnitude);
  for (const auto& p : a.poles) s += fmt::format(" {:.6f}{:+.6f}j", p.real(), p.imag());
  s += "\n";
  s += fmt::format("  phase margin {:.2f} deg at {:.2f} Hz, gain margin {:.2f} dB at {:.2f} Hz\n", a.phase_margin_deg,
                   a.gain_crossover_Hz, a.gain_margin_dB, a.phase_crossover_Hz);
  s += fmt::format("  sensitivity peak Ms {:.3f} ({:.2f} dB) at {:.2f} Hz, complementary peak Mt {:.3f}\n",
                   a.sensitivity_peak, a.sensitivity_peak_dB, a.sensitivity_peak_Hz, a.complementary_peak);
  s += fmt::format("  bandwidth (-3 dB) {:.2f} Hz feedback only, {:.2f} Hz with feedforward\n", a.bandwidth_Hz,
                   a.bandwidth_with_feedforward_Hz);
  s += fmt::format("  step (feedback only): overshoot {:.1f} %, 2 % settling {:.4f} s\n", 100.0 * a.step_overshoot,
                   a.step_settling_time_s);
  s += fmt::format("  tracking error |E/R|: {:.3e} at 1 Hz, {:.3e} at 10 Hz\n", a.error_gain_1Hz, a.error_gain_10Hz);
  return s;
}

}  // namespace twin::analysis
