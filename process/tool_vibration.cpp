#include "process/tool_vibration.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace twin::process {
namespace {

/// Phi (row major) and Gamma of one mode for a step dt (see the header).
std::array<double, 6> zoh(double wn, double zeta, double m_kg, double dt_s) {
  const double s = zeta * wn;
  const double wd = wn * std::sqrt(1.0 - zeta * zeta);
  const double e = std::exp(-s * dt_s);
  const double c = std::cos(wd * dt_s);
  const double sn = std::sin(wd * dt_s);
  const double p11 = e * (c + s / wd * sn);
  const double p12 = e * sn / wd;
  const double p21 = -e * wn * wn / wd * sn;
  const double p22 = e * (c - s / wd * sn);
  // Gamma = A^-1 (Phi - I) [0; 1/m], A^-1 = [-2 zeta / wn, -1 / wn^2; 1, 0].
  const double g1 = (-2.0 * zeta / wn * p12 - (p22 - 1.0) / (wn * wn)) / m_kg;
  const double g2 = p12 / m_kg;
  return {p11, p12, p21, p22, g1, g2};
}

}  // namespace

ToolVibration::ToolVibration(const ToolTipFrf& frf) {
  frf.validate("tool_tip");
  for (int d = 0; d < 2; ++d)
    for (const ToolTipMode& tm : d == 0 ? frf.x : frf.y) {
      const double wn = 2.0 * std::numbers::pi * tm.fn_Hz;
      modes_.push_back(Mode{d, wn, tm.zeta, tm.k_N_per_m / (wn * wn)});
    }
  fn_max_Hz_ = frf.fn_max_Hz();
}

const ToolVibration::Discrete& ToolVibration::discrete(Discrete& d, double dt_s) const {
  if (d.dt_s != dt_s) {
    d.dt_s = dt_s;
    d.phi_gamma.clear();
    for (const Mode& m : modes_) d.phi_gamma.push_back(zoh(m.wn, m.zeta, m.m_kg, dt_s));
  }
  return d;
}

std::array<double, 2> ToolVibration::deflection_mm() const noexcept {
  std::array<double, 2> u{};
  for (const Mode& m : modes_) u[static_cast<std::size_t>(m.direction)] += m.q_m * 1e3;
  return u;
}

std::array<double, 2> ToolVibration::predict_mm(double dt_s, const std::array<double, 2>& F_tool_N) const {
  const Discrete& d = discrete(predict_, dt_s);
  std::array<double, 2> u{};
  for (std::size_t i = 0; i < modes_.size(); ++i) {
    const Mode& m = modes_[i];
    const auto& a = d.phi_gamma[i];
    const auto dir = static_cast<std::size_t>(m.direction);
    u[dir] += (a[0] * m.q_m + a[1] * m.dq_m_per_s + a[4] * F_tool_N[dir]) * 1e3;
  }
  return u;
}

std::array<double, 2> ToolVibration::deflection_at_mm(double t_s) const {
  if (history_.empty() || t_s < history_.front().t_s) return {0.0, 0.0};
  if (t_s >= history_.back().t_s) return {history_.back().x_mm, history_.back().y_mm};
  const auto hi = std::upper_bound(history_.begin(), history_.end(), t_s,
                                   [](double t, const Point& p) { return t < p.t_s; });
  const Point& b = *hi;
  const Point& a = *(hi - 1);
  const double w = (t_s - a.t_s) / (b.t_s - a.t_s);
  return {a.x_mm + w * (b.x_mm - a.x_mm), a.y_mm + w * (b.y_mm - a.y_mm)};
}

void ToolVibration::advance(double t_s, double dt_s, const std::array<double, 2>& F_tool_N, double keep_s) {
  if (history_.empty()) {
    const auto u = deflection_mm();
    history_.push_back({t_s, u[0], u[1]});
  }
  const Discrete& d = discrete(step_, dt_s);
  for (std::size_t i = 0; i < modes_.size(); ++i) {
    Mode& m = modes_[i];
    const auto& a = d.phi_gamma[i];
    const double F = F_tool_N[static_cast<std::size_t>(m.direction)];
    const double q = a[0] * m.q_m + a[1] * m.dq_m_per_s + a[4] * F;
    m.dq_m_per_s = a[2] * m.q_m + a[3] * m.dq_m_per_s + a[5] * F;
    m.q_m = q;
  }
  const double t1 = t_s + dt_s;
  const auto u = deflection_mm();
  history_.push_back({t1, u[0], u[1]});
  while (history_.size() > 2 && history_[1].t_s < t1 - keep_s) history_.pop_front();
}

}  // namespace twin::process
