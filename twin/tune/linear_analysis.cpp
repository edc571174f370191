#include "twin/tune/linear_analysis.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <tuple>
#include <vector>

#include <Eigen/Eigenvalues>
#include <fmt/format.h>

#include "twin/core/error.hpp"
#include "twin/core/golden_section.hpp"
#include "twin/core/units.hpp"

namespace twin::analysis {

using cd = std::complex<double>;

LinearPlant linear_plant(const feeddrive::DriveParams& d) {
  LinearPlant p{d.Ka_A_per_V, d.Kt_Nm_per_A, d.J_kg_m2, d.B_kg_m2_per_s, d.rg_mm_per_rad};
  if (d.effects.delay.enabled) p.command_delay_s = d.effects.delay.delay_s;
  if (const auto& c = d.effects.compliance; c.enabled) {
    p.load_fraction = c.load_fraction;
    p.K_Nm_per_rad = c.K_Nm_per_rad;
    p.C_Nm_s_per_rad = c.C_Nm_s_per_rad;
  }
  return p;
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
  const auto nl = static_cast<Eigen::Index>(K_.Ac.rows() - K_.reference_states);

  // The drive's step: the inner tick where the law has them, else Ts; a dead time on
  // the command is whole steps of it, rounded as the drive rounds it.
  const double h = Ts_s_ / K_.inner_ticks;
  delay_ticks_ = static_cast<int>(std::llround(plant_.command_delay_s / h));
  const bool compliant = plant_.load_fraction > 0.0;
  if (K_.inner_ticks > 1 || delay_ticks_ > 0 || compliant) {
    // The plant over one drive step: [w, x] of the motor, [w, x] of the load behind
    // a compliant coupling, and the commands in flight; the loop lifted over the
    // period; its loop states are the plant's and the controller's, less those no
    // period reads (the velocity command held over the period, set anew at its first tick).
    const Eigen::Index nphys = compliant ? 4 : 2;
    Eigen::MatrixXd Mc = Eigen::MatrixXd::Zero(nphys + 1, nphys + 1);
    if (compliant) {
      const double Jl = plant_.J_kg_m2 * plant_.load_fraction, Jm = plant_.J_kg_m2 - Jl, rg = plant_.rg_mm_per_rad;
      const double K = plant_.K_Nm_per_rad, C = plant_.C_Nm_s_per_rad;
      // Jm dwm = g m - B wm - K (xm - xl)/rg - C (wm - wl);  Jl dwl = K (xm - xl)/rg + C (wm - wl)
      Mc(0, 0) = -(plant_.B_kg_m2_per_s + C) / Jm;
      Mc(0, 1) = -K / rg / Jm;
      Mc(0, 2) = C / Jm;
      Mc(0, 3) = K / rg / Jm;
      Mc(0, 4) = g / Jm;
      Mc(1, 0) = rg;
      Mc(2, 0) = C / Jl;
      Mc(2, 1) = K / rg / Jl;
      Mc(2, 2) = -C / Jl;
      Mc(2, 3) = -K / rg / Jl;
      Mc(3, 2) = rg;
    } else {
      Mc = M;
    }
    const Eigen::MatrixXd Ev = compliant || K_.inner_ticks > 1 ? matrix_exponential(Mc * h) : E;  // E: over Ts
    const auto np = static_cast<Eigen::Index>(nphys + delay_ticks_);
    Phi_a_ = Eigen::MatrixXd::Zero(np, np);
    Gamma_a_ = Eigen::VectorXd::Zero(np);
    Phi_a_.topLeftCorner(nphys, nphys) = Ev.topLeftCorner(nphys, nphys);
    if (delay_ticks_ == 0) {
      Gamma_a_.head(nphys) = Ev.topRightCorner(nphys, 1);
    } else {
      // [plant, m[k-1], ..., m[k-d]]: the oldest acts, each moves one place on.
      Phi_a_.block(0, np - 1, nphys, 1) = Ev.topRightCorner(nphys, 1);
      for (Eigen::Index i = nphys + 1; i < np; ++i) Phi_a_(i, i - 1) = 1.0;
      Gamma_a_(nphys) = 1.0;
    }
    lifted_ = lift(K_, Phi_a_, Gamma_a_);
    if (K_.inner_ticks > 1) lifted_fb_ = lift(K_fb_, Phi_a_, Gamma_a_);  // only responses() reads it
    std::vector<Eigen::Index> keep;
    for (Eigen::Index i = 0; i < np + nl; ++i)
      if (i < 2 || !lifted_.A.col(i).isZero(0.0)) keep.push_back(i);
    const auto nk = static_cast<Eigen::Index>(keep.size());
    A_fb_.resize(nk, nk);
    for (std::size_t i = 0; i < keep.size(); ++i)
      for (std::size_t j = 0; j < keep.size(); ++j)
        A_fb_(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) = lifted_.A(keep[i], keep[j]);
    return;
  }

  // The loop states of the controller with the plant, the reference held at 0.
  A_fb_.setZero(2 + nl, 2 + nl);
  A_fb_.topLeftCorner(2, 2) = Phi_ + Gamma_ * K_.Dy;
  A_fb_.topRightCorner(2, nl) = Gamma_ * K_.Cc.head(nl);
  A_fb_.bottomLeftCorner(nl, 2) = K_.By.topRows(nl);
  A_fb_.bottomRightCorner(nl, nl) = K_.Ac.topLeftCorner(nl, nl);
}

DiscreteLoopModel::Lifted DiscreteLoopModel::lift(const ControllerRealisation& K, const Eigen::MatrixXd& Phi,
                                                   const Eigen::VectorXd& Gamma) {
  const auto np = Phi.rows(), nc = K.Ac.rows(), N = np + nc;
  // One step of plant and controller, state [plant, c]; the controller reads the
  // plant's first two states [w, x].
  auto tick = [&](const Eigen::MatrixXd& Ac, const Eigen::MatrixXd& By, const Eigen::RowVectorXd& Cc,
                  const Eigen::RowVector2d& Dy) {
    Eigen::MatrixXd T = Eigen::MatrixXd::Zero(N, N);
    T.topLeftCorner(np, np) = Phi;
    T.topLeftCorner(np, 2) += Gamma * Dy;
    T.topRightCorner(np, nc) = Gamma * Cc;
    T.bottomLeftCorner(nc, 2) = By;
    T.bottomRightCorner(nc, nc) = Ac;
    return T;
  };
  Eigen::MatrixXd later = Eigen::MatrixXd::Identity(N, N);
  if (K.inner_ticks > 1) {
    // The position feedback is cut at the period's first tick only.
    if (!K.inner.By.col(1).isZero(0.0) || K.inner.Dy(1) != 0.0)
      throw InternalError("linear analysis: a law's inner ticks read the position");
    const Eigen::MatrixXd inner = tick(K.inner.Ac, K.inner.By, K.inner.Cc, K.inner.Dy);
    for (int q = 1; q < K.inner_ticks; ++q) later = inner * later;
  }
  Eigen::VectorXd Nr(N);
  Nr << Gamma * K.Dr, K.Br;
  Lifted L;
  L.A = later * tick(K.Ac, K.By, K.Cc, K.Dy);
  L.Br = later * Nr;
  if (K.inner_ticks == 1) return L;  // the responses of one tick a period are not lifted
  Eigen::MatrixXd By_open = K.By;
  By_open.col(1).setZero();
  Eigen::RowVector2d Dy_open = K.Dy;
  Dy_open(1) = 0.0;
  Eigen::VectorXd Nd(N);
  Nd << Gamma * K.Dy(1), K.By.col(1);
  L.A_open = later * tick(K.Ac, By_open, K.Cc, Dy_open);
  L.Bd = later * Nd;
  return L;
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
  // P = (zI - Phi)^-1 Gamma: with the 2x2 adjugate for the rigid plant held over Ts,
  // else the plant with its load side and commands in flight over one drive step.
  cd Pw, Px;
  if (Phi_a_.size() > 0) {
    const std::array<cd, 2> P = plant_step_response(f_Hz);
    Pw = P[0];
    Px = P[1];
  } else {
    const cd a = z - Phi_(0, 0), b = -Phi_(0, 1), c = -Phi_(1, 0), d = z - Phi_(1, 1);
    const cd det = a * d - b * c;
    Pw = (d * Gamma_(0) - b * Gamma_(1)) / det;
    Px = (-c * Gamma_(0) + a * Gamma_(1)) / det;
  }
  if (K_.inner_ticks > 1) {
    // The lifted loop: X/R from the reference, L from a disturbance on the measured position.
    const auto N = lifted_.A.rows();
    const Eigen::MatrixXcd zI = z * Eigen::MatrixXcd::Identity(N, N);
    auto x_of = [&](const Eigen::MatrixXd& A, const Eigen::VectorXd& B) {
      return (zI - A.cast<cd>()).partialPivLu().solve(B.cast<cd>().eval())(1);
    };
    Responses r;
    r.Px = Px;
    r.L = -x_of(lifted_.A_open, lifted_.Bd);
    r.X = x_of(lifted_.A, lifted_.Br);
    r.X_fb = x_of(lifted_fb_.A, lifted_fb_.Br);
    return r;
  }
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
  r.X = Px * (KY(2) + K_.Dr) / (1.0 + r.L);
  r.X_fb = Px * Kr_fb / (1.0 + r.L);
  return r;
}

FrequencyPoint DiscreteLoopModel::at(double f_Hz) const {
  const Responses r = responses(f_Hz);
  FrequencyPoint p;
  p.f_Hz = f_Hz;
  p.L = r.L;
  p.S = 1.0 / (1.0 + r.L);
  p.T = r.L * p.S;
  p.X_over_R = r.X;
  p.X_over_R_feedback = r.X_fb;
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
cd DiscreteLoopModel::position_response(double f_Hz) const { return responses(f_Hz).X; }
cd DiscreteLoopModel::feedback_position_response(double f_Hz) const { return responses(f_Hz).X_fb; }
cd DiscreteLoopModel::error_response(double f_Hz) const { return 1.0 - position_response(f_Hz); }

cd DiscreteLoopModel::velocity_loop_response(double f_Hz) const {
  if (K_.inner_ticks <= 1) return {std::numeric_limits<double>::quiet_NaN(), 0.0};
  const cd z = std::polar(1.0, 2.0 * kPi * f_Hz * Ts_s_ / K_.inner_ticks);
  // The inner ticks' controller from [w, x]; its held states (the velocity command and
  // the reference's) are not driven by the plant, so with the position loop open they stay 0.
  const auto& I = K_.inner;
  const auto n = I.Ac.rows();
  const Eigen::MatrixXcd Y =
      (z * Eigen::MatrixXcd::Identity(n, n) - I.Ac.cast<cd>()).partialPivLu().solve(I.By.cast<cd>().eval());
  const Eigen::RowVectorXcd K = I.Cc.cast<cd>() * Y + I.Dy.cast<cd>();
  const std::array<cd, 2> P = plant_step_response(f_Hz);
  return -(K(0) * P[0] + K(1) * P[1]);
}

std::array<cd, 2> DiscreteLoopModel::plant_step_response(double f_Hz) const {
  const cd z = std::polar(1.0, 2.0 * kPi * f_Hz * Ts_s_ / K_.inner_ticks);
  const auto n = Phi_a_.rows();
  const Eigen::VectorXcd y =
      (z * Eigen::MatrixXcd::Identity(n, n) - Phi_a_.cast<cd>()).partialPivLu().solve(Gamma_a_.cast<cd>().eval());
  return {y(0), y(1)};
}

std::vector<double> DiscreteLoopModel::simulate(const std::vector<double>& x_ref_mm) const {
  Eigen::Vector2d p = Eigen::Vector2d::Zero();
  Eigen::VectorXd c = K_.start * (x_ref_mm.empty() ? 0.0 : x_ref_mm.front());
  std::vector<double> x(x_ref_mm.size());
  if (Phi_a_.size() > 0) {
    Eigen::VectorXd s = Eigen::VectorXd::Zero(lifted_.A.rows());
    s.tail(c.size()) = c;
    for (std::size_t k = 0; k < x_ref_mm.size(); ++k) {
      x[k] = s(1);
      s = lifted_.A * s + lifted_.Br * x_ref_mm[k];
    }
    return x;
  }
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

/// A loop's response L(f) on a log grid up to its Nyquist frequency.
struct LoopGrid {
  std::vector<double> f_Hz;
  std::vector<cd> L;
};
template <class LoopFn>
LoopGrid loop_grid(LoopFn&& loop, double f_min_Hz, double f_nyquist_Hz, int points) {
  LoopGrid g;
  const int n = std::max(points, 2);
  for (int i = 0; i < n; ++i) {
    const double f =
        f_min_Hz * std::pow(f_nyquist_Hz / f_min_Hz, static_cast<double>(i) / static_cast<double>(n - 1));
    g.f_Hz.push_back(f);
    g.L.push_back(loop(f));
  }
  return g;
}

/// Gain crossovers (|L| = 1): the smallest phase margin (+inf when none) and its frequency.
template <class LoopFn>
std::pair<double, double> gain_crossovers(LoopFn&& loop, const LoopGrid& grid) {
  double pm_min = std::numeric_limits<double>::infinity(), f_at = 0.0;
  auto gain_fn = [&](double f) { return std::abs(loop(f)) - 1.0; };
  for (std::size_t i = 1; i < grid.f_Hz.size(); ++i) {
    const double g0 = std::abs(grid.L[i - 1]) - 1.0, g1 = std::abs(grid.L[i]) - 1.0;
    if ((g0 < 0.0) == (g1 < 0.0)) continue;
    const double fc = bisect_log(gain_fn, grid.f_Hz[i - 1], grid.f_Hz[i]);
    const double pm = phase_margin_at(loop(fc));
    if (pm < pm_min) {
      pm_min = pm;
      f_at = fc;
    }
  }
  return {pm_min, f_at};
}

/// Phase crossovers (Im L = 0 with Re L < 0, counted where |L| < 1, and Nyquist,
/// where L is real): the smallest gain margin (+inf when none) and its frequency.
template <class LoopFn>
std::pair<double, double> phase_crossovers(LoopFn&& loop, const LoopGrid& grid, double f_nyquist_Hz) {
  double gm_min = std::numeric_limits<double>::infinity(), f_at = 0.0;
  auto consider_gm = [&](double f) {
    const cd L = loop(f);
    if (L.real() < 0.0 && std::abs(L) < 1.0) {
      const double gm = -20.0 * std::log10(std::abs(L));
      if (gm < gm_min) {
        gm_min = gm;
        f_at = f;
      }
    }
  };
  auto imag_fn = [&](double f) { return loop(f).imag(); };
  for (std::size_t i = 1; i < grid.f_Hz.size(); ++i) {
    const double i0 = grid.L[i - 1].imag(), i1 = grid.L[i].imag();
    if ((i0 < 0.0) == (i1 < 0.0) || i == grid.f_Hz.size() - 1) continue;
    if (grid.L[i - 1].real() >= 0.0 && grid.L[i].real() >= 0.0) continue;
    consider_gm(bisect_log(imag_fn, grid.f_Hz[i - 1], grid.f_Hz[i]));
  }
  consider_gm(f_nyquist_Hz);  // at Nyquist L is real
  return {gm_min, f_at};
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
  LoopGrid loop_points;
  for (const FrequencyPoint& p : grid) {
    loop_points.f_Hz.push_back(p.f_Hz);
    loop_points.L.push_back(p.L);
  }
  auto loop = [&m](double f) { return m.loop_response(f); };
  std::tie(a.phase_margin_deg, a.gain_crossover_Hz) = gain_crossovers(loop, loop_points);
  std::tie(a.gain_margin_dB, a.phase_crossover_Hz) = phase_crossovers(loop, loop_points, m.nyquist_Hz());
  if (m.inner_ticks() > 1) {
    auto velocity_loop = [&m](double f) { return m.velocity_loop_response(f); };
    const double f_nyquist_v = m.nyquist_Hz() * m.inner_ticks();
    const LoopGrid v = loop_grid(velocity_loop, f_min_Hz, f_nyquist_v, points);
    a.velocity_loop = true;
    std::tie(a.velocity_loop_phase_margin_deg, a.velocity_loop_gain_crossover_Hz) = gain_crossovers(velocity_loop, v);
    std::tie(a.velocity_loop_gain_margin_dB, a.velocity_loop_phase_crossover_Hz) =
        phase_crossovers(velocity_loop, v, f_nyquist_v);
  }
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
  if (m.delay_ticks() > 0)
    s += fmt::format("  a dead time of {} drive steps ({:g} s) on the command, in the loop\n", m.delay_ticks(),
                     m.delay_ticks() * m.Ts_s() / m.inner_ticks());
  if (m.inner_ticks() > 1)
    s += fmt::format("  loop broken at the position feedback, the velocity loop closed (it runs {} times a period, "
                     "Tv {:g} s); poles of the whole loop over a period\n",
                     m.inner_ticks(), m.Ts_s() / m.inner_ticks());
  else
    s += fmt::format("  loop broken at the command ({} in {})\n", m.law().command_name(), m.law().command_unit());
  s += fmt::format("  closed loop {} (largest pole |z| = {:.6f}); poles:", a.stable ? "stable" : "UNSTABLE",
                   a.max_pole_magnitude);
  for (const auto& p : a.poles) s += fmt::format(" {:.6f}{:+.6f}j", p.real(), p.imag());
  s += "\n";
  s += fmt::format("  phase margin {:.2f} deg at {:.2f} Hz, gain margin {:.2f} dB at {:.2f} Hz\n", a.phase_margin_deg,
                   a.gain_crossover_Hz, a.gain_margin_dB, a.phase_crossover_Hz);
  if (a.velocity_loop)
    s += fmt::format("  velocity loop alone (at Tv, position loop open): phase margin {:.2f} deg at {:.2f} Hz, gain "
                     "margin {:.2f} dB at {:.2f} Hz\n",
                     a.velocity_loop_phase_margin_deg, a.velocity_loop_gain_crossover_Hz,
                     a.velocity_loop_gain_margin_dB, a.velocity_loop_phase_crossover_Hz);
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
