#include "twin/sim/machine.hpp"

#include <charconv>
#include <cmath>
#include <string>

#include <fmt/format.h>

#include "feeddrive/effect_catalogue.hpp"
#include "twin/core/error.hpp"

namespace twin::sim {
namespace {

#define TWIN_AXIS_PARAM(NAME, UNIT, DOC, EXPR) \
  AxisParamSpec { NAME, UNIT, DOC, [](AxisDefinition& a) -> double& { return EXPR; }, nullptr }
#define TWIN_LAW_PARAM(NAME, UNIT, DOC, EXPR, LAW)                                        \
  AxisParamSpec { NAME, UNIT, DOC, [](AxisDefinition& a) -> double& { return EXPR; }, nullptr, LAW }
#define TWIN_EFFECT_PARAM(NAME, UNIT, DOC, EFFECT, FIELD)                                   \
  AxisParamSpec {                                                                          \
    NAME, UNIT, DOC, [](AxisDefinition& a) -> double& { return a.drive.effects.EFFECT.FIELD; }, \
        [](AxisDefinition& a) -> bool* { return &a.drive.effects.EFFECT.enabled; }         \
  }

std::vector<AxisParamSpec> make_axis_specs() {
  return {
      TWIN_AXIS_PARAM("Ka", "A/V", "current amplifier gain", a.drive.Ka_A_per_V),
      TWIN_AXIS_PARAM("Kt", "N m/A", "motor torque constant", a.drive.Kt_Nm_per_A),
      TWIN_AXIS_PARAM("J", "kg m^2", "inertia reflected to the motor shaft", a.drive.J_kg_m2),
      TWIN_AXIS_PARAM("B", "kg m^2/s", "viscous damping", a.drive.B_kg_m2_per_s),
      TWIN_AXIS_PARAM("rg", "mm/rad", "transmission (ballscrew lead / 2 pi)", a.drive.rg_mm_per_rad),
      TWIN_LAW_PARAM("Kp", "V/mm", "proportional gain", a.loop.Kp_V_per_mm, controller::LoopLaw::kFadal),
      TWIN_LAW_PARAM("Ki", "V/(s mm)", "integral gain", a.loop.Ki_V_per_s_mm, controller::LoopLaw::kFadal),
      TWIN_LAW_PARAM("Kd", "V s/mm", "derivative gain", a.loop.Kd_V_s_per_mm, controller::LoopLaw::kFadal),
      TWIN_LAW_PARAM("K1", "V s^2/mm", "acceleration feedforward", a.loop.K1_V_s2_per_mm, controller::LoopLaw::kFadal),
      TWIN_LAW_PARAM("K2", "V s/mm", "velocity feedforward", a.loop.K2_V_s_per_mm, controller::LoopLaw::kFadal),
      TWIN_AXIS_PARAM("Tc_pos", "N m", "Coulomb friction torque moving in +", a.drive.Tc_pos_Nm),
      TWIN_AXIS_PARAM("Tc_neg", "N m", "Coulomb friction torque moving in - (positive)", a.drive.Tc_neg_Nm),
      TWIN_LAW_PARAM("u_max", "V", "amplifier command limit (symmetric)", a.loop.u_max_V, controller::LoopLaw::kFadal),
      TWIN_LAW_PARAM("Kv", "1/s", "cascade: position-loop gain", a.loop.cascade.Kv_per_s, controller::LoopLaw::kCascade),
      TWIN_LAW_PARAM("kff", "1", "cascade: velocity feedforward fraction", a.loop.cascade.kff, controller::LoopLaw::kCascade),
      TWIN_LAW_PARAM("Kvp", "torque unit s/rad", "cascade: velocity-loop proportional gain", a.loop.cascade.Kvp_torque_s_per_rad, controller::LoopLaw::kCascade),
      TWIN_LAW_PARAM("Tn", "s", "cascade: velocity-loop integral time (0: none)", a.loop.cascade.Tn_s, controller::LoopLaw::kCascade),
      TWIN_LAW_PARAM("tau_i", "s", "cascade: current-loop lag (0: ideal)", a.loop.cascade.tau_i_s, controller::LoopLaw::kCascade),
      TWIN_LAW_PARAM("T_max", "torque unit", "cascade: torque limit", a.loop.cascade.T_max, controller::LoopLaw::kCascade),
      TWIN_LAW_PARAM("Jff", "torque unit s^2/rad", "cascade: acceleration (torque) feedforward", a.loop.cascade.Jff_torque_s2_per_rad, controller::LoopLaw::kCascade),
      TWIN_LAW_PARAM("Tv", "s",
                     "cascade: the velocity and current loops' period where they run faster than the position "
                     "loop, Ts a whole multiple of it (0: Ts)",
                     a.loop.cascade.Tv_s, controller::LoopLaw::kCascade),
      TWIN_LAW_PARAM("command_average", "s",
                     "cascade: the reference's moving average over this window before the position loop (a CNC's "
                     "smoothing after its interpolator, which a logged reference does not show), a whole multiple "
                     "of Ts; 0: none",
                     a.loop.cascade.command_average_s, controller::LoopLaw::kCascade),
      TWIN_LAW_PARAM("command_lag", "s",
                     "cascade: first-order lag of the reference after its moving average, before the position "
                     "loop; 0: none",
                     a.loop.cascade.command_lag_s, controller::LoopLaw::kCascade),
      TWIN_LAW_PARAM("command_delay", "s",
                     "cascade: dead time of the reference after its smoothing, before the position loop (a CNC "
                     "that holds an axis's setpoint back to match a slower axis), a whole multiple of Ts; 0: none",
                     a.loop.cascade.command_delay_s, controller::LoopLaw::kCascade),
      TWIN_LAW_PARAM("feedforward_unsmoothed", "1",
                     "cascade: 1 where the velocity and torque feedforward take the reference as given and only the "
                     "position loop's error the smoothed one (command_average, command_lag, command_delay); 0: both the smoothed one",
                     a.loop.cascade.feedforward_unsmoothed, controller::LoopLaw::kCascade),
      TWIN_LAW_PARAM("torque_command_logged", "1",
                     "cascade: 1 where the log's torque or current is the velocity loop's command, before the "
                     "current loop and any delay; 0: the motor's",
                     a.torque_command_logged, controller::LoopLaw::kCascade),
      TWIN_LAW_PARAM("torque_log_filter", "s",
                     "cascade: first-order lag of the log's torque or current behind the torque it shows, outside "
                     "the loop (a drive's smoothed monitor); 0: none",
                     a.logged_torque_filter_s, controller::LoopLaw::kCascade),
      TWIN_LAW_PARAM("torque_log_mean", "1",
                     "cascade: 1 where the log's torque or current at a row is its mean over the position-loop "
                     "period before the row (over the velocity loop's ticks in it); 0: the value at the row's tick",
                     a.logged_torque_period_mean, controller::LoopLaw::kCascade),
      TWIN_AXIS_PARAM("v_max", "mm/s", "interpolator speed limit", a.v_max_mm_per_s),
      TWIN_AXIS_PARAM("a_max", "mm/s^2", "interpolator acceleration limit", a.a_max_mm_per_s2),
      TWIN_AXIS_PARAM("j_max", "mm/s^3", "interpolator jerk limit", a.j_max_mm_per_s3),
      TWIN_AXIS_PARAM("travel_min", "mm", "lower end of travel", a.travel_min_mm),
      TWIN_AXIS_PARAM("travel_max", "mm", "upper end of travel", a.travel_max_mm),
      TWIN_AXIS_PARAM("following_error_limit", "mm", "following-error alarm", a.following_error_limit_mm),
      TWIN_AXIS_PARAM("torque_sign", "1",
                      "sign of the logged torque, current or command against the axis's motion (1 or -1)",
                      a.logged_torque_sign),
      // The drive effects' parameters (feeddrive/effect_catalogue.hpp), as "<effect>.<name>".
#define TWIN_EFFECT_ROW(EFFECT, NAME, FIELD, UNIT, DOC) TWIN_EFFECT_PARAM(#EFFECT "." #NAME, UNIT, DOC, EFFECT, FIELD),
      TWIN_DRIVE_EFFECT_PARAMS(TWIN_EFFECT_ROW)
#undef TWIN_EFFECT_ROW
  };
}
#undef TWIN_AXIS_PARAM
#undef TWIN_LAW_PARAM
#undef TWIN_EFFECT_PARAM

std::vector<MachineParamSpec> make_machine_specs() {
  return {
      {"Ts", "s", "position-loop sample period", [](MachineDefinition& m) -> double& { return m.Ts_s; }},
      {"encoder_resolution", "mm", "encoder resolution at the table (0: ideal)",
       [](MachineDefinition& m) -> double& { return m.encoder_resolution_mm; }},
      {"rapid", "mm/min", "rapid traverse rate", [](MachineDefinition& m) -> double& { return m.rapid_mm_per_min; }},
      {"blend_tolerance", "mm", "G64 corner tolerance when P is not given",
       [](MachineDefinition& m) -> double& { return m.blend_tolerance_mm; }},
  };
}

}  // namespace

const std::vector<AxisParamSpec>& axis_param_specs() {
  static const std::vector<AxisParamSpec> specs = make_axis_specs();
  return specs;
}
const std::vector<MachineParamSpec>& machine_param_specs() {
  static const std::vector<MachineParamSpec> specs = make_machine_specs();
  return specs;
}
const AxisParamSpec* find_axis_param(std::string_view name) {
  for (const auto& s : axis_param_specs())
    if (s.name == name) return &s;
  return nullptr;
}
const MachineParamSpec* find_machine_param(std::string_view name) {
  for (const auto& s : machine_param_specs())
    if (s.name == name) return &s;
  return nullptr;
}

double get_axis_param(const AxisDefinition& axis, const AxisParamSpec& spec) {
  return spec.ref(const_cast<AxisDefinition&>(axis));
}
void set_axis_param(AxisDefinition& axis, const AxisParamSpec& spec, double value) {
  spec.ref(axis) = value;
  if (spec.enables != nullptr) *spec.enables(axis) = true;
}

controller::LoopLaw machine_loop_law(const MachineDefinition& m) {
  for (Axis a : kAllAxes)
    if (m.axes[index(a)].present) return m.axes[index(a)].loop.law;
  return controller::LoopLaw::kFadal;
}
void set_machine_loop_law(MachineDefinition& m, controller::LoopLaw law) {
  for (auto& ax : m.axes) ax.loop.law = law;
}

void MachineDefinition::validate() const {
  const std::string where = source.empty() ? std::string("machine ") + name : source;
  auto positive = [&](const char* key, double v) {
    if (!std::isfinite(v) || !(v > 0.0))
      throw ConfigError(fmt::format("{}: {} = {} must be a finite number > 0", where, key, v));
  };
  positive("Ts", Ts_s);
  if (Ts_s > 0.1) throw ConfigError(fmt::format("{}: Ts = {} s is beyond 0.1 s", where, Ts_s));
  if (!std::isfinite(encoder_resolution_mm) || encoder_resolution_mm < 0.0)
    throw ConfigError(fmt::format("{}: encoder_resolution = {} must be a finite number >= 0", where,
                                  encoder_resolution_mm));
  positive("rapid", rapid_mm_per_min);
  positive("blend_tolerance", blend_tolerance_mm);
  if (!tool_tip.empty()) tool_tip.validate(where + ": tool_tip");
  bool any = false;
  for (Axis a : kAllAxes) {
    const AxisDefinition& ax = axes[index(a)];
    if (!ax.present) continue;
    any = true;
    const std::string w = fmt::format("{}: axis {}", where, axis_name(a));
    ax.drive.validate(w);
    ax.loop.validate(w);
    auto pos = [&](const char* key, double v) {
      if (!std::isfinite(v) || !(v > 0.0))
        throw ConfigError(fmt::format("{}: {} = {} must be a finite number > 0", w, key, v));
    };
    pos("v_max", ax.v_max_mm_per_s);
    pos("a_max", ax.a_max_mm_per_s2);
    pos("j_max", ax.j_max_mm_per_s3);
    pos("following_error_limit", ax.following_error_limit_mm);
    if (ax.logged_torque_sign != 1.0 && ax.logged_torque_sign != -1.0)
      throw ConfigError(fmt::format("{}: torque_sign = {} must be 1 or -1", w, ax.logged_torque_sign));
    if (ax.torque_command_logged != 0.0 && ax.torque_command_logged != 1.0)
      throw ConfigError(fmt::format("{}: torque_command_logged = {} must be 0 or 1", w, ax.torque_command_logged));
    if (ax.logged_torque_period_mean != 0.0 && ax.logged_torque_period_mean != 1.0)
      throw ConfigError(
          fmt::format("{}: torque_log_mean = {} must be 0 or 1", w, ax.logged_torque_period_mean));
    if (!std::isfinite(ax.logged_torque_filter_s) || ax.logged_torque_filter_s < 0.0)
      throw ConfigError(
          fmt::format("{}: torque_log_filter = {} s must be a finite number >= 0", w, ax.logged_torque_filter_s));
    if (!std::isfinite(ax.travel_min_mm) || !std::isfinite(ax.travel_max_mm) ||
        !(ax.travel_min_mm < ax.travel_max_mm))
      throw ConfigError(fmt::format("{}: travel [{}, {}] mm must be finite with min < max", w,
                                    ax.travel_min_mm, ax.travel_max_mm));
    if (ax.loop.law != machine_loop_law(*this))
      throw ConfigError(fmt::format("{}: the axes close different loop laws; a machine has one `controller`", w));
  }
  if (!any) throw ConfigError(fmt::format("{}: no axis defined", where));
}

controller::MotionLimits MachineDefinition::motion_limits() const {
  controller::MotionLimits lim;
  for (Axis a : kAllAxes) {
    const AxisDefinition& ax = axes[index(a)];
    lim.v_max_mm_per_s[index(a)] = std::min(ax.v_max_mm_per_s, rapid_mm_per_min / 60.0);
    lim.a_max_mm_per_s2[index(a)] = ax.a_max_mm_per_s2;
    lim.j_max_mm_per_s3[index(a)] = ax.j_max_mm_per_s3;
  }
  lim.default_blend_tolerance_mm = blend_tolerance_mm;
  return lim;
}

std::vector<Axis> MachineDefinition::present_axes() const {
  std::vector<Axis> out;
  for (Axis a : kAllAxes)
    if (axes[index(a)].present) out.push_back(a);
  return out;
}

namespace {
double parse_number(std::string_view text, std::string_view context) {
  double v = 0.0;
  const auto* b = text.data();
  const auto* e = text.data() + text.size();
  auto [p, ec] = std::from_chars(b, e, v);
  if (ec != std::errc() || p != e || text.empty())
    throw ConfigError(fmt::format("--set {}: '{}' is not a number", context, text));
  if (!std::isfinite(v)) throw ConfigError(fmt::format("--set {}: value {} is not finite", context, text));
  return v;
}
}  // namespace

void apply_set(MachineDefinition& machine, std::string_view assignment) {
  const auto eq = assignment.find('=');
  if (eq == std::string_view::npos)
    throw ConfigError(fmt::format("--set '{}': expected <axis>.<name>=<value>", assignment));
  const std::string_view lhs = assignment.substr(0, eq);
  const double value = parse_number(assignment.substr(eq + 1), assignment);
  if (const auto* ms = find_machine_param(lhs)) {
    ms->ref(machine) = value;
    return;
  }
  const auto dot = lhs.find('.');
  if (dot == std::string_view::npos)
    throw ConfigError(fmt::format("--set '{}': unknown machine parameter '{}' (axis parameters are <axis>.<name>)",
                                  assignment, lhs));
  const auto axis = parse_axis(lhs.substr(0, dot));
  if (!axis) throw ConfigError(fmt::format("--set '{}': unknown axis '{}'", assignment, lhs.substr(0, dot)));
  const auto* spec = find_axis_param(lhs.substr(dot + 1));
  if (spec == nullptr)
    throw ConfigError(fmt::format("--set '{}': unknown parameter '{}'", assignment, lhs.substr(dot + 1)));
  AxisDefinition& ax = machine.axes[index(*axis)];
  if (!ax.present)
    throw ConfigError(fmt::format("--set '{}': axis {} is not defined in {}", assignment, axis_name(*axis),
                                  machine.source));
  if (spec->law && *spec->law != ax.loop.law)
    throw ConfigError(fmt::format("--set '{}': {} is a gain of the {} law; this machine's controller is {}", assignment,
                                  spec->name, controller::loop_law_name(*spec->law),
                                  controller::loop_law_name(ax.loop.law)));
  set_axis_param(ax, *spec, value);
}

}  // namespace twin::sim
