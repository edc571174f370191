#include "twin/structure/lobe_study.hpp"

#include "twin/structure/chatter_check.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <sstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "twin/report/plots.hpp"
#include "twin/core/error.hpp"

namespace twin::structure {
namespace {

constexpr double kPi = std::numbers::pi;

double finite_or_null(double v) { return std::isfinite(v) ? v : std::numeric_limits<double>::quiet_NaN(); }

nlohmann::json number_or_null(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }

nlohmann::json modes_json(const std::vector<process::ToolTipMode>& modes) {
  nlohmann::json a = nlohmann::json::array();
  for (const auto& m : modes) a.push_back({{"fn_Hz", m.fn_Hz}, {"zeta", m.zeta}, {"k_N_per_m", m.k_N_per_m}});
  return a;
}

}  // namespace

void LobeStudyOptions::validate() const {
  if (lobes < 1 || lobes > 100) throw ConfigError(fmt::format("lobes: --lobes must be in [1, 100], got {}", lobes));
  if (!std::isfinite(rpm_min) || !std::isfinite(rpm_max) || rpm_min < 0.0 || rpm_max < 0.0 ||
      (rpm_max > 0.0 && rpm_max <= rpm_min) || rpm_max > 1e6)
    throw ConfigError(fmt::format("lobes: speed range must satisfy 0 <= rpm-min < rpm-max <= 1e6, got {} to {}",
                                  rpm_min, rpm_max));
  if (boundary_points < 10 || boundary_points > 100000)
    throw ConfigError(fmt::format("lobes: boundary points must be in [10, 100000], got {}", boundary_points));
}

LobeStudy study_lobes(const io::Scenario& scenario, const LobeStudyOptions& options) {
  options.validate();
  if (!scenario.process_setup)
    throw ConfigError(fmt::format("{}: the scenario has no process: stability lobes need a cut", scenario.name));
  if (scenario.machine.tool_tip.empty())
    throw ConfigError(fmt::format("{}: machine {} has no tool_tip modes (add tool_tip: x/y modes with fn_Hz, zeta, "
                                  "k_N_per_m to its machine file)",
                                  scenario.name, scenario.machine.name));
  const process::ProcessSetup& setup = *scenario.process_setup;
  const controller::Program program = io::parse_program(scenario);
  const std::vector<CutCondition> cuts = study_cuts(program, setup);
  if (cuts.empty()) throw ConfigError(fmt::format("{}: the program never engages the stock", scenario.name));

  LobeStudy st;
  st.scenario = scenario.name;
  st.machine = scenario.machine.name;
  st.tool_tip_source = scenario.machine.tool_tip_source;
  st.tool_tip = scenario.machine.tool_tip;
  st.cut = cuts.front();
  st.cut_conditions = cuts.size();
  st.coefficients = linearise_coefficients(setup.coefficients, st.cut);
  st.settings.teeth = setup.tool.flutes;
  st.settings.Ktc_N_per_mm2 = st.coefficients.Ktc_N_per_mm2;
  st.settings.Kr_ratio = st.coefficients.Kr_ratio;
  st.settings.immersion = st.cut.immersion;
  st.settings.feed_angle_deg = st.cut.feed_angle_deg;
  // Enough lobes to reach half the scenario's speed: lobe k's speeds are about
  // 60 fc / (N (k + 1)), fc up to 1.5 times the highest mode.
  const double rpm_abs = std::abs(st.cut.spindle_rpm);
  const double k_needed = rpm_abs > 0.0 ? 60.0 * 1.5 * scenario.machine.tool_tip.fn_max_Hz() /
                                              (st.settings.teeth * 0.5 * rpm_abs)
                                        : 0.0;
  st.settings.lobes = std::clamp(static_cast<int>(std::ceil(k_needed)), options.lobes, 400);
  st.settings.frequencies = 1500;
  st.lobes = process::zero_order_lobes(scenario.machine.tool_tip, st.settings);
  st.rpm = std::abs(st.cut.spindle_rpm);
  const process::LobePoint b = st.lobes.boundary_at(st.rpm);
  st.a_crit_mm = b.a_lim_mm;
  st.chatter_Hz = b.chatter_Hz;
  st.stable = st.cut.ap_mm < st.a_crit_mm;

  // The table's speed range: the lobes' own (lobe 0 reaches the highest
  // speed, the last lobe the lowest), widened to hold the scenario's speed.
  // (log-spaced) from half the scenario's speed to where lobe 0's deepest
  // point lies times 1.5, or the range asked for.
  double lo = options.rpm_min, hi = options.rpm_max;
  if (hi <= 0.0) {
    double top = 0.0;
    for (const process::Lobe& l : st.lobes.lobes)
      for (const process::LobePoint& p : l.points)
        if (l.number == 0) top = std::max(top, p.spindle_rpm);
    lo = 0.5 * st.rpm;
    hi = std::max(std::min(top, 60.0 * 1.5 * scenario.machine.tool_tip.fn_max_Hz() / st.settings.teeth * 1.5),
                  2.0 * st.rpm);
  }
  if (!(lo > 0.0)) lo = hi / 100.0;
  st.rpm_min = lo;
  st.rpm_max = hi;
  for (int i = 0; i < options.boundary_points; ++i) {
    const double n = lo * std::pow(hi / lo, static_cast<double>(i) / (options.boundary_points - 1));
    const process::LobePoint p = st.lobes.boundary_at(n);
    st.boundary.push_back({n, p.a_lim_mm, p.chatter_Hz});
  }
  return st;
}

std::string lobe_summary(const LobeStudy& s) {
  if (!std::isfinite(s.a_crit_mm))
    return fmt::format("{}: {:.0f} rpm, ap {:.3g} mm: no lobe of the {} computed covers this speed", s.scenario,
                       s.rpm, s.cut.ap_mm, s.settings.lobes);
  return fmt::format("{}: {:.0f} rpm, ap {:.3g} mm, critical depth {:.3g} mm (chatter near {:.0f} Hz): {}",
                     s.scenario, s.rpm, s.cut.ap_mm, s.a_crit_mm, s.chatter_Hz,
                     s.stable ? "stable" : "chatter expected");
}

namespace {

/// report.json of the study (without the checks).
nlohmann::json report_json(const LobeStudy& s) {
  nlohmann::json j;
  j["command"] = "lobes";
  j["scenario"] = s.scenario;
  j["machine"] = s.machine;
  j["method"] = "zero-order (Altintas and Budak 1995)";
  j["tool_tip"] = {{"source", s.tool_tip_source}, {"x", modes_json(s.tool_tip.x)}, {"y", modes_json(s.tool_tip.y)}};
  j["cut"] = {{"spindle_rpm", s.rpm},
              {"ap_mm", s.cut.ap_mm},
              {"phi_st_deg", s.cut.immersion.phi_st_rad * 180.0 / kPi},
              {"phi_ex_deg", s.cut.immersion.phi_ex_rad * 180.0 / kPi},
              {"feed_angle_deg", s.cut.feed_angle_deg},
              {"fz_mm", s.cut.fz_mm},
              {"length_mm", s.cut.length_mm},
              {"first_line", s.cut.first_line},
              {"distinct_cuts_in_program", s.cut_conditions}};
  j["coefficients"] = {{"teeth", s.settings.teeth},
                       {"h_mean_mm", s.coefficients.h_mean_mm},
                       {"Ktc_N_per_mm2", s.coefficients.Ktc_N_per_mm2},
                       {"Kr_ratio", s.coefficients.Kr_ratio}};
  j["a_lim_min_mm"] = s.lobes.a_lim_min_mm;
  j["a_lim_min_chatter_Hz"] = s.lobes.a_lim_min_chatter_Hz;
  j["a_crit_mm"] = number_or_null(s.a_crit_mm);
  j["chatter_Hz"] = number_or_null(finite_or_null(s.chatter_Hz));
  j["stable"] = s.stable;
  j["verdict"] = !std::isfinite(s.a_crit_mm) ? "no lobe covers the speed" : (s.stable ? "stable" : "chatter");
  return j;
}

}  // namespace

std::vector<std::filesystem::path> write_lobe_study(io::ResultSet& results, const LobeStudy& s) {
  std::vector<std::filesystem::path> written;
  if (!s.checks.empty()) {
    io::write_file_atomic(results.path("check.csv"), chatter_checks_csv(s.checks));
    written.push_back(results.path("check.csv"));
  }
  {
    std::ostringstream o;
    o.precision(10);
    o << "lobe,branch,chatter_Hz,spindle_rpm,a_lim_mm\n";
    for (const process::Lobe& l : s.lobes.lobes)
      for (const process::LobePoint& p : l.points)
        o << l.number << ',' << l.branch << ',' << p.chatter_Hz << ',' << p.spindle_rpm << ',' << p.a_lim_mm << '\n';
    io::write_file_atomic(results.path("lobes.csv"), o.str());
    written.push_back(results.path("lobes.csv"));
  }
  {
    std::ostringstream o;
    o.precision(10);
    o << "spindle_rpm,a_crit_mm,chatter_Hz\n";
    for (const auto& [n, a, f] : s.boundary) {
      if (std::isfinite(a))
        o << n << ',' << a << ',' << f << '\n';
      else
        o << n << ",,\n";
    }
    io::write_file_atomic(results.path("boundary.csv"), o.str());
    written.push_back(results.path("boundary.csv"));
  }
  {
    nlohmann::json j = report_json(s);
    if (!s.checks.empty()) j["check"] = chatter_checks_json(s.checks);
    io::write_file_atomic(results.path("report.json"), j.dump(2) + "\n");
    written.push_back(results.path("report.json"));
  }
  {
    analysis::LobesPlot plot;
    plot.scenario = s.scenario;
    plot.teeth = s.settings.teeth;
    plot.entry_deg = s.cut.immersion.phi_st_rad * 180.0 / kPi;
    plot.exit_deg = s.cut.immersion.phi_ex_rad * 180.0 / kPi;
    plot.rpm_min = s.rpm_min;
    plot.rpm_max = s.rpm_max;
    for (const auto& [n, a, f] : s.boundary)
      if (std::isfinite(a)) plot.boundary_max_mm = std::max(plot.boundary_max_mm, a);
    plot.lobe_min_mm = s.lobes.a_lim_min_mm;
    plot.rpm = s.rpm;
    plot.ap_mm = s.cut.ap_mm;
    plot.stable = s.stable;
    for (const auto& p : analysis::plot_lobes(results, plot)) written.push_back(p);
  }
  return written;
}

}  // namespace twin::structure
