#include "twin/structure/chatter_check.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <limits>
#include <numbers>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "process/chatter_spectrum.hpp"
#include "process/milling_process.hpp"
#include "twin/core/error.hpp"
#include "twin/core/units.hpp"
#include "twin/sim/cosimulation.hpp"

namespace twin::structure {
namespace {

constexpr double kPi = std::numbers::pi;

/// The reference of the check: along `dir` at speed v from x0, spindle on, from tick 0.
class LineReference final : public sim::ReferenceSource {
 public:
  LineReference(const AxisArray<double>& x0_mm, std::array<double, 2> dir, double v_mm_per_s, double rpm,
                double Ts_s, std::int64_t ticks)
      : x0_(x0_mm), dir_(dir), v_(v_mm_per_s), rpm_(rpm), Ts_(Ts_s), n_(ticks) {}
  controller::ReferenceSample sample(std::int64_t k) const override {
    controller::ReferenceSample r;
    const double s = v_ * Ts_ * static_cast<double>(std::min(k, n_));
    r.x_mm = x0_;
    r.x_mm[0] += s * dir_[0];
    r.x_mm[1] += s * dir_[1];
    r.v_mm_per_s = {v_ * dir_[0], v_ * dir_[1], 0.0};
    r.path_speed_mm_per_s = v_;
    r.feed_programmed_mm_per_s = v_;
    r.block = 0;
    r.spindle_rpm = rpm_;
    r.cutting_move = true;
    r.done = k >= n_;
    return r;
  }
  std::int64_t num_ticks() const override { return n_; }

 private:
  AxisArray<double> x0_;
  std::array<double, 2> dir_;
  double v_, rpm_, Ts_;
  std::int64_t n_;
};

/// Point (along, across) of the feed frame in the machine's xy.
process::Point2 machine_point(const std::array<double, 2>& dir, const std::array<double, 2>& at, double along,
                              double across) {
  return {at[0] + along * dir[0] - across * dir[1], at[1] + along * dir[1] + across * dir[0]};
}

/// The straight cut's process: the scenario's tool, coefficients and model
/// with the machine's tool modes, a block at the immersion, cut up to `at`.
std::unique_ptr<process::MillingProcess> straight_cut(const io::Scenario& sc, const process::Immersion& im,
                                                      const std::array<double, 2>& dir,
                                                      const std::array<double, 2>& at, double ap_mm,
                                                      double length_mm) {
  process::ProcessSetup setup = *sc.process_setup;
  setup.tool_tip = sc.machine.tool_tip;
  const double R = setup.tool.radius_mm();
  // Across the feed, y_f (left of the feed) is phi = 0: material up to R cos(phi_st) ... R cos(phi_ex).
  const double y_hi = im.phi_st_rad < 1e-6 ? R + 2.0 : R * std::cos(im.phi_st_rad);
  const double y_lo = im.phi_ex_rad > kPi - 1e-6 ? -R - 2.0 : R * std::cos(im.phi_ex_rad);
  const double a0 = -2.0 * R - 2.0, a1 = length_mm + R + 2.0;
  setup.stock.outline_mm = {machine_point(dir, at, a0, y_lo), machine_point(dir, at, a1, y_lo),
                            machine_point(dir, at, a1, y_hi), machine_point(dir, at, a0, y_hi)};
  setup.stock.pockets.clear();
  setup.stock.top_z_mm = 0.0;
  setup.stock.bottom_z_mm = -ap_mm - 2.0;
  auto p = std::make_unique<process::MillingProcess>(setup);
  const auto start = machine_point(dir, at, a0 - R - 1.0, 0.0);
  p->remove_swept({start.x_mm, start.y_mm, -ap_mm}, {at[0], at[1], -ap_mm});
  return p;
}

double lobe_depth(const LobeStudy& study, double rpm) {
  const double a = study.lobes.critical_depth_mm(rpm);
  if (std::isfinite(a)) return a;
  process::LobeSettings s = study.settings;
  const double k_needed = 60.0 * 1.5 * study.tool_tip.fn_max_Hz() / (s.teeth * 0.9 * rpm);
  if (!(k_needed <= 2000.0)) return a;
  s.lobes = std::max(s.lobes, static_cast<int>(std::ceil(k_needed)));
  return process::zero_order_lobes(study.tool_tip, s).critical_depth_mm(rpm);
}

}  // namespace

ChatterCheckPoint ChatterCheckPoint::parse(const std::string& text) {
  const auto colon = text.find(':');
  ChatterCheckPoint p;
  const auto number = [&](std::string_view v, double& out) {
    const auto r = std::from_chars(v.data(), v.data() + v.size(), out);
    return r.ec == std::errc() && r.ptr == v.data() + v.size() && std::isfinite(out);
  };
  const std::string_view t(text);
  if (colon == std::string::npos || !number(t.substr(0, colon), p.spindle_rpm) ||
      !number(t.substr(colon + 1), p.ap_mm))
    throw ConfigError(fmt::format("--check '{}': expected RPM:DEPTH_mm, e.g. 9000:2.5", text));
  if (!(p.spindle_rpm > 0.0 && p.spindle_rpm <= 100000.0))
    throw ConfigError(fmt::format("--check '{}': spindle speed must be in (0, 100000] rev/min", text));
  if (!(p.ap_mm > 0.0 && p.ap_mm <= 100.0))
    throw ConfigError(fmt::format("--check '{}': depth must be in (0, 100] mm", text));
  return p;
}

ChatterCheckResult check_chatter(const io::Scenario& sc, const LobeStudy& study, const ChatterCheckPoint& point) {
  if (!sc.process_setup) throw ConfigError(fmt::format("{}: the scenario has no process to check", sc.name));
  if (sc.machine.tool_tip.empty()) throw ConfigError(fmt::format("{}: machine has no tool_tip modes", sc.name));
  if (point.ap_mm > sc.process_setup->tool.flute_length_mm)
    throw ConfigError(fmt::format("--check: depth {} mm exceeds the flute length {} mm", point.ap_mm,
                                  sc.process_setup->tool.flute_length_mm));
  ChatterCheckResult res;
  res.point = point;
  res.a_crit_mm = lobe_depth(study, point.spindle_rpm);
  res.lobe_chatter = point.ap_mm >= res.a_crit_mm;
  const int N = sc.process_setup->tool.flutes;
  res.tooth_Hz = point.spindle_rpm / 60.0 * N;
  const double Ts = sc.machine.Ts_s;
  const double L = std::max(0.1, 16.0 / res.tooth_Hz);
  const auto window = static_cast<std::int64_t>(std::ceil(L / Ts));
  const double v = study.cut.fz_mm * res.tooth_Hz;
  const double th = study.cut.feed_angle_deg * kRadPerDeg;
  const std::array<double, 2> dir{std::cos(th), std::sin(th)};
  const std::array<double, 2> at{sc.start_mm[0], sc.start_mm[1]};
  AxisArray<double> x0 = sc.start_mm;
  x0[2] = -point.ap_mm;
  auto reference = std::make_shared<LineReference>(x0, dir, v, point.spindle_rpm, Ts, 3 * window);
  sim::CoSimulation cosim(sc.machine, reference,
                          straight_cut(sc, study.cut.immersion, dir, at, point.ap_mm, v * 3.0 * L + 1.0), x0);
  std::vector<std::array<double, 2>> F;
  for (std::int64_t k = 0; k < 3 * window; ++k) {
    const sim::Snapshot& s = cosim.step();
    F.push_back({s.F_avg_N[0], s.F_avg_N[1]});
    if (k >= 2 * window)
      res.max_deflection_um = std::max(res.max_deflection_um, std::hypot(s.tool_deflection_um[0], s.tool_deflection_um[1]));
  }
  res.simulated_s = 3.0 * static_cast<double>(window) * Ts;
  const double f_lo = 0.5 * study.tool_tip.fn_min_Hz(), f_hi = 1.5 * study.tool_tip.fn_max_Hz();
  const auto w = static_cast<std::size_t>(window);
  res.ratio_early = process::chatter_spectrum(F, w, 2 * w, Ts, res.tooth_Hz, f_lo, f_hi).ratio;
  const process::ChatterSpectrum last = process::chatter_spectrum(F, 2 * w, 3 * w, Ts, res.tooth_Hz, f_lo, f_hi);
  res.ratio = last.ratio;
  res.chatter_Hz = last.chatter_Hz;
  res.chatter = process::chatter_verdict(res.ratio_early, res.ratio);
  return res;
}

std::string chatter_checks_csv(const std::vector<ChatterCheckResult>& checks) {
  std::string o = "spindle_rpm,ap_mm,a_crit_mm,lobes_verdict,twin_verdict,ratio_window2,ratio_window3,chatter_Hz,"
                  "tooth_Hz,max_deflection_um,simulated_s\n";
  for (const auto& r : checks)
    o += fmt::format("{},{},{},{},{},{:.6g},{:.6g},{:.6g},{:.6g},{:.6g},{:.6g}\n", r.point.spindle_rpm, r.point.ap_mm,
                     std::isfinite(r.a_crit_mm) ? fmt::format("{:.6g}", r.a_crit_mm) : std::string(),
                     r.lobe_chatter ? "chatter" : "stable", r.chatter ? "chatter" : "stable", r.ratio_early, r.ratio,
                     r.chatter_Hz, r.tooth_Hz, r.max_deflection_um, r.simulated_s);
  return o;
}

nlohmann::json chatter_checks_json(const std::vector<ChatterCheckResult>& checks) {
  nlohmann::json a = nlohmann::json::array();
  for (const auto& r : checks)
    a.push_back({{"spindle_rpm", r.point.spindle_rpm},
                 {"ap_mm", r.point.ap_mm},
                 {"a_crit_mm", std::isfinite(r.a_crit_mm) ? nlohmann::json(r.a_crit_mm) : nlohmann::json(nullptr)},
                 {"lobes_verdict", r.lobe_chatter ? "chatter" : "stable"},
                 {"twin_verdict", r.chatter ? "chatter" : "stable"},
                 {"agree", r.lobe_chatter == r.chatter},
                 {"nonharmonic_ratio_window2", r.ratio_early},
                 {"nonharmonic_ratio_window3", r.ratio},
                 {"chatter_Hz", r.chatter_Hz},
                 {"tooth_Hz", r.tooth_Hz},
                 {"max_deflection_um", r.max_deflection_um},
                 {"simulated_s", r.simulated_s}});
  return a;
}

std::string chatter_check_summary(const ChatterCheckResult& r) {
  return fmt::format("check {:.0f} rpm, ap {:.3g} mm: lobes {} (critical {:.3g} mm), twin {} (non-harmonic/harmonic "
                     "{:.3g} -> {:.3g}{})",
                     r.point.spindle_rpm, r.point.ap_mm, r.lobe_chatter ? "chatter" : "stable", r.a_crit_mm,
                     r.chatter ? "chatter" : "stable", r.ratio_early, r.ratio,
                     r.chatter ? fmt::format(", {:.0f} Hz", r.chatter_Hz) : std::string());
}

}  // namespace twin::structure
