#include "process/stability_lobes.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>

#include <fmt/format.h>

#include "twin/core/error.hpp"

namespace twin::process {
namespace {

using cd = std::complex<double>;
constexpr double kPi = std::numbers::pi;

bool finite_positive(double v) { return std::isfinite(v) && v > 0.0; }

void validate_modes(const std::vector<ToolTipMode>& modes, const std::string& where) {
  for (std::size_t i = 0; i < modes.size(); ++i) modes[i].validate(fmt::format("{} mode {}", where, i + 1));
}

double fn_extreme(const ToolTipFrf& frf, bool lowest) {
  double v = lowest ? std::numeric_limits<double>::infinity() : 0.0;
  for (const auto* modes : {&frf.x, &frf.y})
    for (const ToolTipMode& m : *modes) v = lowest ? std::min(v, m.fn_Hz) : std::max(v, m.fn_Hz);
  return v;
}

/// The two eigenvalues of a complex 2x2 matrix [[a, b], [c, d]].
std::array<cd, 2> eigenvalues(cd a, cd b, cd c, cd d) {
  const cd half_tr = 0.5 * (a + d);
  const cd disc = std::sqrt(0.25 * (a - d) * (a - d) + b * c);
  return {half_tr + disc, half_tr - disc};
}

}  // namespace

void ToolTipMode::validate(const std::string& where) const {
  if (!finite_positive(fn_Hz) || fn_Hz > 1e5)
    throw ConfigError(fmt::format("{}: fn_Hz must be in (0, 1e5], got {}", where, fn_Hz));
  if (!std::isfinite(zeta) || zeta <= 0.0 || zeta >= 1.0)
    throw ConfigError(fmt::format("{}: zeta must be in (0, 1), got {}", where, zeta));
  if (!finite_positive(k_N_per_m) || k_N_per_m > 1e12)
    throw ConfigError(fmt::format("{}: k_N_per_m must be in (0, 1e12], got {}", where, k_N_per_m));
}

void ToolTipFrf::validate(const std::string& where) const {
  if (empty()) throw ConfigError(fmt::format("{}: the tool tip has no mode in x or y", where));
  if (x.size() > 32 || y.size() > 32)
    throw ConfigError(fmt::format("{}: at most 32 modes per direction, got {} and {}", where, x.size(), y.size()));
  validate_modes(x, where + " x");
  validate_modes(y, where + " y");
}

cd ToolTipFrf::direct_mm_per_N(const std::vector<ToolTipMode>& modes, double w_rad_per_s) {
  cd G{0.0, 0.0};
  for (const ToolTipMode& m : modes) {
    const double r = w_rad_per_s / (2.0 * kPi * m.fn_Hz);
    G += 1e3 / (m.k_N_per_m * cd(1.0 - r * r, 2.0 * m.zeta * r));
  }
  return G;
}

double ToolTipFrf::fn_min_Hz() const { return fn_extreme(*this, true); }
double ToolTipFrf::fn_max_Hz() const { return fn_extreme(*this, false); }

Immersion Immersion::of_cut(double ae_mm, double D_mm, MillingMode mode, const std::string& where) {
  if (!finite_positive(D_mm)) throw ConfigError(fmt::format("{}: tool diameter must be > 0, got {}", where, D_mm));
  if (!finite_positive(ae_mm) || ae_mm > D_mm * (1.0 + 1e-12))
    throw ConfigError(fmt::format("{}: radial depth must be in (0, D = {} mm], got {} mm", where, D_mm, ae_mm));
  const double c = std::clamp(1.0 - 2.0 * ae_mm / D_mm, -1.0, 1.0);
  Immersion im;
  if (mode == MillingMode::kUp) {
    im.phi_st_rad = 0.0;
    im.phi_ex_rad = std::acos(c);
  } else {
    im.phi_st_rad = std::acos(-c);
    im.phi_ex_rad = kPi;
  }
  return im;
}

DirectionalCoefficients DirectionalCoefficients::of(const Immersion& im, double Kr) {
  auto xx = [Kr](double p) { return std::cos(2 * p) - 2 * Kr * p + Kr * std::sin(2 * p); };
  auto xy = [Kr](double p) { return -std::sin(2 * p) - 2 * p + Kr * std::cos(2 * p); };
  auto yx = [Kr](double p) { return -std::sin(2 * p) + 2 * p + Kr * std::cos(2 * p); };
  auto yy = [Kr](double p) { return -std::cos(2 * p) - 2 * Kr * p - Kr * std::sin(2 * p); };
  const double a = im.phi_st_rad, b = im.phi_ex_rad;
  DirectionalCoefficients d;
  d.xx = 0.5 * (xx(b) - xx(a));
  d.xy = 0.5 * (xy(b) - xy(a));
  d.yx = 0.5 * (yx(b) - yx(a));
  d.yy = 0.5 * (yy(b) - yy(a));
  return d;
}

void LobeSettings::validate(const std::string& where) const {
  if (teeth < 1 || teeth > 16) throw ConfigError(fmt::format("{}: teeth must be in [1, 16], got {}", where, teeth));
  if (!finite_positive(Ktc_N_per_mm2) || Ktc_N_per_mm2 > 1e5)
    throw ConfigError(fmt::format("{}: Ktc must be in (0, 1e5] N/mm^2, got {}", where, Ktc_N_per_mm2));
  if (!std::isfinite(Kr_ratio) || Kr_ratio < 0.0 || Kr_ratio > 10.0)
    throw ConfigError(fmt::format("{}: Kr/Kt must be in [0, 10], got {}", where, Kr_ratio));
  const double a = immersion.phi_st_rad, b = immersion.phi_ex_rad;
  if (!std::isfinite(a) || !std::isfinite(b) || a < 0.0 || b > kPi + 1e-12 || b <= a)
    throw ConfigError(fmt::format("{}: immersion must satisfy 0 <= phi_st < phi_ex <= pi, got {} to {} rad", where,
                                  a, b));
  if (!std::isfinite(feed_angle_deg))
    throw ConfigError(fmt::format("{}: feed angle must be finite", where));
  if (lobes < 1 || lobes > 1000) throw ConfigError(fmt::format("{}: lobes must be in [1, 1000], got {}", where, lobes));
  if (frequencies < 10 || frequencies > 200000)
    throw ConfigError(fmt::format("{}: frequencies must be in [10, 200000], got {}", where, frequencies));
}

double StabilityLobes::critical_depth_mm(double spindle_rpm) const { return boundary_at(spindle_rpm).a_lim_mm; }

LobePoint StabilityLobes::boundary_at(double n) const {
  LobePoint best{n, std::numeric_limits<double>::infinity(), 0.0};
  for (const Lobe& lobe : lobes) {
    for (std::size_t i = 1; i < lobe.points.size(); ++i) {
      const LobePoint& p = lobe.points[i - 1];
      const LobePoint& q = lobe.points[i];
      const double lo = std::min(p.spindle_rpm, q.spindle_rpm), hi = std::max(p.spindle_rpm, q.spindle_rpm);
      if (n < lo || n > hi) continue;
      const double s = hi > lo ? (n - p.spindle_rpm) / (q.spindle_rpm - p.spindle_rpm) : 0.0;
      const double a = p.a_lim_mm + s * (q.a_lim_mm - p.a_lim_mm);
      if (a < best.a_lim_mm) best = {n, a, p.chatter_Hz + s * (q.chatter_Hz - p.chatter_Hz)};
    }
  }
  return best;
}

StabilityLobes zero_order_lobes(const ToolTipFrf& frf, const LobeSettings& s) {
  frf.validate("tool tip");
  s.validate("stability lobes");
  const DirectionalCoefficients al = DirectionalCoefficients::of(s.immersion, s.Kr_ratio);
  const double th = s.feed_angle_deg * kPi / 180.0;
  const double c = std::cos(th), sn = std::sin(th);
  const double N = s.teeth;

  // Chatter frequencies: log-spaced over the modes' neighbourhood.
  const double f_lo = 0.5 * frf.fn_min_Hz(), f_hi = 2.0 * frf.fn_max_Hz();
  const int nf = s.frequencies;

  StabilityLobes out;
  out.a_lim_min_mm = std::numeric_limits<double>::infinity();
  // Per branch: the run of consecutive valid points (Lambda_R < 0), per lobe number.
  std::array<std::vector<std::vector<LobePoint>>, 2> open;
  for (auto& b : open) b.assign(static_cast<std::size_t>(s.lobes), {});
  auto close = [&](int branch) {
    for (int k = 0; k < s.lobes; ++k) {
      auto& pts = open[branch][static_cast<std::size_t>(k)];
      if (pts.size() >= 2) out.lobes.push_back(Lobe{k, branch, std::move(pts)});
      pts.clear();
    }
  };
  std::array<cd, 2> prev{};
  bool have_prev = false;
  for (int i = 0; i < nf; ++i) {
    const double f_Hz = f_lo * std::pow(f_hi / f_lo, static_cast<double>(i) / (nf - 1));
    const double w = 2.0 * kPi * f_Hz;
    // The FRF matrix in the feed frame: G_f = R^T diag(Gx, Gy) R, R the feed rotation.
    const cd Gx = ToolTipFrf::direct_mm_per_N(frf.x, w), Gy = ToolTipFrf::direct_mm_per_N(frf.y, w);
    const cd gxx = c * c * Gx + sn * sn * Gy, gyy = sn * sn * Gx + c * c * Gy, gxy = c * sn * (Gy - Gx);
    // [alpha][G_f]
    const cd a11 = al.xx * gxx + al.xy * gxy, a12 = al.xx * gxy + al.xy * gyy;
    const cd a21 = al.yx * gxx + al.yy * gxy, a22 = al.yx * gxy + al.yy * gyy;
    std::array<cd, 2> ev = eigenvalues(a11, a12, a21, a22);
    // Follow each branch by continuity (the two eigenvalues may swap order).
    if (have_prev && std::abs(ev[0] - prev[1]) + std::abs(ev[1] - prev[0]) <
                         std::abs(ev[0] - prev[0]) + std::abs(ev[1] - prev[1]))
      std::swap(ev[0], ev[1]);
    prev = ev;
    have_prev = true;
    for (int b = 0; b < 2; ++b) {
      const cd lam = ev[static_cast<std::size_t>(b)];
      // An eigenvalue at round-off of the matrix (a direction without a mode) has no lobe.
      const double scale = std::abs(a11) + std::abs(a12) + std::abs(a21) + std::abs(a22);
      if (!(std::abs(lam) > 1e-12 * scale)) {
        close(b);
        continue;
      }
      const cd L = -1.0 / lam;
      if (!(L.real() < 0.0)) {
        close(b);
        continue;
      }
      const double kap = L.imag() / L.real();
      const double a_lim = -2.0 * kPi * L.real() * (1.0 + kap * kap) / (N * s.Ktc_N_per_mm2);
      if (!std::isfinite(a_lim) || a_lim <= 0.0) {
        close(b);
        continue;
      }
      if (a_lim < out.a_lim_min_mm) {
        out.a_lim_min_mm = a_lim;
        out.a_lim_min_chatter_Hz = f_Hz;
      }
      const double eps = kPi - 2.0 * std::atan(kap);
      for (int k = 0; k < s.lobes; ++k) {
        const double T_s = (eps + 2.0 * kPi * k) / w;
        open[static_cast<std::size_t>(b)][static_cast<std::size_t>(k)].push_back({60.0 / (N * T_s), a_lim, f_Hz});
      }
    }
  }
  close(0);
  close(1);
  if (out.lobes.empty())
    throw ConfigError("stability lobes: no chatter frequency gives a positive critical depth for this cut and tool tip");
  return out;
}

}  // namespace twin::process
