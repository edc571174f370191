#include "twin/tune/linear_analysis.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Eigenvalues>
#include <fmt/format.h>

#include "twin/core/error.hpp"
#include "twin/core/golden_section.hpp"
#include "twin/core/units.hpp"

namespace twin::analysis {

using cd = std::complex<double>;

LinearPlant linear_plant(const feeddrive::DriveParams& d) {
  return LinearPlant{d.Ka_A_per_V, d.Kt_Nm_per_A, d.J_kg_m2, d.B_kg_m2_per_s, d.rg_mm_per_rad};
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
                                     double Ts_s, const std::string& where)
    : plant_(plant), gains_(gains), law_(&controller::law_of(gains.law)), Ts_s_(Ts_s) {
  plant_.validate(where);
  controller::validate_sample_period(where, Ts_s_);
  gains_.validate(where);
  const double g = law_->torque_per_command(plant_);
  Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
  M(0, 0) = -plant.B_kg_m2_per_s / plant.J_kg_m2;
  M(0, 2) = g / plant.J_kg_m2;
  M(1, 0) = plant.rg_mm_per_rad;
  const Eigen::MatrixXd E = matrix_exponential(M * Ts_s_);
  Phi_ = E.topLeftCorner<2, 2>();
  Gamma_ = E.topRightCorner<2, 1>();
  K_ = law_->realise(gains_, Ts_s_, plant_);
  K_fb_ = law_->realise(law_->feedback_only(gains_), Ts_s_, plant_);
  same_states_ = K_fb_.Ac == K_.Ac;

  // The loop states of the controller with the plant, the reference held at 0.
  const auto nl = static_cast<Eigen::Index>(K_.Ac.rows() - K_.reference_states);
  A_fb_.setZero(2 + nl, 2 + nl);
  A_fb_.topLeftCorner(2, 2) = Phi_ + Gamma_ * K_.Dy;
  A_fb_.topRightCorner(2, nl) = Gamma_ * K_.Cc.head(nl);
  A_fb_.bottomLeftCorner(nl, 2) = K_.By.topRows(nl);
  A_fb_.bottomRightCorner(nl, nl) = K_.Ac.topLeftCorner(nl, nl);
}

std::vector<std::complex<double>> DiscreteLoopModel::poles() const {
  Eigen::EigenSolver<Eigen::MatrixXd> es(A_fb_, false);
  std::vector<cd> p(es.eigenvalues().begin(), es.eigenvalues().end());
  std::sort(p.begin(), p.end(), [](cd a, cd b) { return std::abs(a) > std::abs(b); });
  return p;
}

bool DiscreteLoopModel::stable() const {
  for (const cd& p : poles())
    if (!(std::abs(p) < 1.0)) return false;
  return true;
}

DiscreteLoopModel::Responses DiscreteLoopModel::responses(double f_Hz) const {
  const cd z = std::polar(1.0, 2.0 * kPi * f_Hz * Ts_s_);
  // P = (zI - Phi)^-1 Gamma with the 2x2 adjugate.
  const cd a = z - Phi_(0, 0), b = -Phi_(0, 1), c = -Phi_(1, 0), d = z - Phi_(1, 1);
  const cd det = a * d - b * c;
  const cd Pw = (d * Gamma_(0) - b * Gamma_(1)) / det;
  const cd Px = (-c * Gamma_(0) + a * Gamma_(1)) / det;
  // The controller's responses from w, x and r share one factorisation; the law without
  // its feedforward shares it too where the feedforward changes only the command (FADAL),
  // not the states (the cascade's kff enters the speed integral).
  const auto n = K_.Ac.rows();
  const Eigen::MatrixXcd I = Eigen::MatrixXcd::Identity(n, n);
  Eigen::MatrixXd B(n, 4);
  B << K_.By, K_.Br, K_fb_.Br;
  const auto lu = (z * I - K_.Ac.cast<cd>()).eval().partialPivLu();
  const Eigen::MatrixXcd Y = lu.solve(B.cast<cd>());
  const Eigen::RowVectorXcd KY = K_.Cc.cast<cd>() * Y;
  const Eigen::VectorXcd y_fb =
      same_states_ ? Eigen::VectorXcd(Y.col(3))
                   : Eigen::VectorXcd((z * I - K_fb_.Ac.cast<cd>()).partialPivLu().solve(K_fb_.Br.cast<cd>()));
  const cd Kr_fb = (K_fb_.Cc.cast<cd>() * y_fb)(0) + K_fb_.Dr;
  Responses r;
  r.Px = Px;
  r.L = -((KY(0) + K_.Dy(0)) * Pw + (KY(1) + K_.Dy(1)) * Px);
  r.Kr = KY(2) + K_.Dr;
  r.Kr_fb = Kr_fb;
  return r;
}

FrequencyPoint DiscreteLoopModel::at(double f_Hz) const {
  const Responses r = responses(f_Hz);
  FrequencyPoint p;
  p.f_Hz = f_Hz;
  p.L = r.L;
  p.S = 1.0 / (1.0 + r.L);
  p.T = r.L * p.S;
  p.X_over_R = r.Px * r.Kr * p.S;
  p.X_over_R_feedback = r.Px * r.Kr_fb * p.S;
  p.E_over_R = 1.0 - p.X_over_R;
  return p;
}

cd DiscreteLoopModel::plant_response(double f_Hz) const { return responses(f_Hz).Px; }
cd DiscreteLoopModel::loop_response(double f_Hz) const { return responses(f_Hz).L; }
cd DiscreteLoopModel::sensitivity(double f_Hz) const { return 1.0 / (1.0 + loop_response(f_Hz)); }
cd DiscreteLoopModel::complementary(double f_Hz) const {
  const cd L = loop_response(f_Hz);
  return L / (1.0 + L);
}
cd DiscreteLoopModel::position_response(double f_Hz) const {
  const Responses r = responses(f_Hz);
  return r.Px * r.Kr / (1.0 + r.L);
}
cd DiscreteLoopModel::feedback_position_response(double f_Hz) const {
  const Responses r = responses(f_Hz);
  return r.Px * r.Kr_fb / (1.0 + r.L);
}
cd DiscreteLoopModel::error_response(double f_Hz) const { return 1.0 - position_response(f_Hz); }

std::vector<double> DiscreteLoopModel::simulate(const std::vector<double>& x_ref_mm) const {
  Eigen::Vector2d p = Eigen::Vector2d::Zero();
  Eigen::VectorXd c = K_.start * (x_ref_mm.empty() ? 0.0 : x_ref_mm.front());
  std::vector<double> x(x_ref_mm.size());
  for (std::size_t k = 0; k < x_ref_mm.size(); ++k) {
    const double r = x_ref_mm[k];
    x[k] = p(1);
    const double m = K_.Cc.dot(c) + K_.Dy.dot(p) + K_.Dr * r;
    c = K_.Ac * c + K_.By * p + K_.Br * r;
    p = Phi_ * p + Gamma_ * m;
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
  const GoldenSection s =
      golden_section_min([&](double lf) { return -fn(std::exp(lf)); }, std::log(a), std::log(b), 60);
  const double f = std::exp(s.mid());
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
    out.push_back(m.at(f));
  }
  return out;
}

namespace {

using Grid = std::vector<FrequencyPoint>;

/// Gain crossovers (|L| = 1): the smallest phase margin and its frequency.
void gain_crossovers(const DiscreteLoopModel& m, const Grid& grid, LoopAnalysis& a) {
  a.phase_margin_deg = std::numeric_limits<double>::infinity();
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
}

/// Phase crossovers (Im L = 0 with Re L < 0, counted where |L| < 1, and Nyquist,
/// where L is real): the smallest gain margin and its frequency.
void phase_crossovers(const DiscreteLoopModel& m, const Grid& grid, LoopAnalysis& a) {
  a.gain_margin_dB = std::numeric_limits<double>::infinity();
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
  consider_gm(m.nyquist_Hz());  // at Nyquist L is real
}

/// Sensitivity peak (refined around the grid's largest |S|) and complementary peak.
void sensitivity_peaks(const DiscreteLoopModel& m, const Grid& grid, LoopAnalysis& a) {
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
}

/// The first frequency where |response `of`| falls below -3 dB (Nyquist if none).
double bandwidth_Hz(const DiscreteLoopModel& m, const Grid& grid, std::complex<double> FrequencyPoint::*of) {
  const double half_power = 1.0 / std::sqrt(2.0);
  auto mag = [&](double f) { return std::abs(m.at(f).*of); };
  for (std::size_t i = 1; i < grid.size(); ++i) {
    if (std::abs(grid[i].*of) < half_power && std::abs(grid[i - 1].*of) >= half_power)
      return bisect_log([&](double f) { return mag(f) - half_power; }, grid[i - 1].f_Hz, grid[i].f_Hz);
  }
  return m.nyquist_Hz();
}

/// Overshoot and 2 % settling time of the feedback loop's unit step (infinite when unstable).
void step_response(const DiscreteLoopModel& m, LoopAnalysis& a) {
  if (!a.stable) {
    a.step_overshoot = std::numeric_limits<double>::infinity();
    a.step_settling_time_s = std::numeric_limits<double>::infinity();
    return;
  }
  const DiscreteLoopModel feedback(m.plant(), m.law().feedback_only(m.gains()), m.Ts_s());
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
}

}  // namespace

LoopAnalysis analyse_loop(const DiscreteLoopModel& m, double f_min_Hz, int points) {
  LoopAnalysis a;
  a.poles = m.poles();
  a.max_pole_magnitude = std::abs(a.poles.front());
  a.stable = m.stable();
  const auto grid = frequency_response(m, f_min_Hz, points);
  gain_crossovers(m, grid, a);
  phase_crossovers(m, grid, a);
  sensitivity_peaks(m, grid, a);
  a.bandwidth_Hz = bandwidth_Hz(m, grid, &FrequencyPoint::X_over_R_feedback);
  a.bandwidth_with_feedforward_Hz = bandwidth_Hz(m, grid, &FrequencyPoint::X_over_R);
  a.error_gain_1Hz = std::abs(m.error_response(1.0));
  a.error_gain_10Hz = std::abs(m.error_response(10.0));
  step_response(m, a);
  return a;
}

std::string format_analysis(const std::string& title, const DiscreteLoopModel& m, const LoopAnalysis& a) {
  std::string s = fmt::format("{}\n", title);
  s += fmt::format("  {} law, gains: {}\n", controller::loop_law_name(m.law().id()),
                   m.law().gains_text(m.gains(), true));
  s += fmt::format("  loop broken at the command ({} in {})\n", m.law().command_name(), m.law().command_unit());
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
