#include "fmu/model.hpp"

#include <cmath>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "controller/gcode.hpp"
#include "controller/interpolator.hpp"
#include "fmu/process_json.hpp"
#include "twin/core/error.hpp"

namespace twin::fmu {
namespace {

using nlohmann::json;
constexpr const char* kFormat = "twin-fmu-model";
constexpr int kVersion = 1;

double number(const json& j, const std::string& where) {
  if (!j.is_number()) throw ConfigError(fmt::format("{} = {} must be a number", where, j.dump()));
  const double v = j.get<double>();
  if (!std::isfinite(v)) throw ConfigError(fmt::format("{} = {} must be finite", where, v));
  return v;
}

const json& member(const json& j, const char* key, const std::string& where) {
  if (!j.is_object() || !j.contains(key)) throw ConfigError(fmt::format("{}: missing key '{}'", where, key));
  return j[key];
}

std::string text(const json& j, const std::string& where) {
  if (!j.is_string()) throw ConfigError(fmt::format("{} = {} must be a string", where, j.dump()));
  return j.get<std::string>();
}

}  // namespace

std::string model_to_json(const std::string& scenario_name, const sim::MachineDefinition& machine,
                          const std::string& program_name, const std::string& program_text,
                          const AxisArray<double>& start_mm, double settle_s, const nlohmann::json& process) {
  json m;
  m["name"] = machine.name;
  json mp = json::object();
  sim::MachineDefinition copy = machine;
  for (const auto& spec : sim::machine_param_specs()) mp[std::string(spec.name)] = spec.ref(copy);
  m["params"] = mp;
  json axes = json::object();
  for (Axis a : kAllAxes) {
    const sim::AxisDefinition& ax = machine.axes[index(a)];
    if (!ax.present) continue;
    json p = json::object();
    sim::AxisDefinition c = ax;
    for (const auto& spec : sim::axis_param_specs()) {
      // An effect's parameters are written only when the effect is on:
      // setting one switches its effect on; the other loop law's gains never.
      if (spec.enables != nullptr && !*spec.enables(c)) continue;
      if (spec.law && *spec.law != ax.loop.law) continue;
      p[std::string(spec.name)] = sim::get_axis_param(ax, spec);
    }
    axes[std::string(axis_name(a))] = p;
  }
  m["axes"] = axes;
  if (sim::machine_loop_law(machine) != controller::LoopLaw::kFadal)
    m["controller"] = std::string(controller::loop_law_name(sim::machine_loop_law(machine)));

  json j;
  j["format"] = kFormat;
  j["version"] = kVersion;
  j["scenario"] = scenario_name;
  j["machine"] = m;
  j["program_name"] = program_name;
  j["program"] = program_text;
  j["start_mm"] = json::array({start_mm[0], start_mm[1], start_mm[2]});
  j["settle_s"] = settle_s;
  j["process"] = process;
  return j.dump(1) + "\n";
}

FmuModel model_from_json(const std::string& text_in, const std::string& where) {
  json j;
  try {
    j = json::parse(text_in);
  } catch (const json::exception& e) {
    throw ConfigError(fmt::format("{}: not valid JSON: {}", where, e.what()));
  }
  if (!j.is_object() || j.value("format", std::string()) != kFormat)
    throw ConfigError(fmt::format("{}: not a twin FMU model (key 'format' must be \"{}\")", where, kFormat));
  if (number(member(j, "version", where), where + ": version") != kVersion)
    throw ConfigError(fmt::format("{}: version {} is not {}", where, j["version"].dump(), kVersion));
  FmuModel model;
  model.model_json = text_in;
  model.name = text(member(j, "scenario", where), where + ": scenario");
  const json& m = member(j, "machine", where);
  sim::MachineDefinition& machine = model.machine;
  machine.name = text(member(m, "name", where + ": machine"), where + ": machine.name");
  machine.source = where;
  const json& mp = member(m, "params", where + ": machine");
  for (const auto& [key, v] : mp.items()) {
    const sim::MachineParamSpec* spec = sim::find_machine_param(key);
    if (spec == nullptr) throw ConfigError(fmt::format("{}: machine.params: unknown parameter '{}'", where, key));
    spec->ref(machine) = number(v, fmt::format("{}: machine.params.{}", where, key));
  }
  controller::LoopLaw law = controller::LoopLaw::kFadal;
  if (m.contains("controller")) {
    const std::string name = text(m["controller"], where + ": machine.controller");
    const auto parsed = controller::parse_loop_law(name);
    if (!parsed) throw ConfigError(fmt::format("{}: machine.controller: unknown law '{}'", where, name));
    law = *parsed;
  }
  const json& axes = member(m, "axes", where + ": machine");
  if (!axes.is_object()) throw ConfigError(fmt::format("{}: machine.axes must be a map", where));
  for (const auto& [axis_key, p] : axes.items()) {
    const auto a = parse_axis(axis_key);
    if (!a) throw ConfigError(fmt::format("{}: machine.axes: unknown axis '{}'", where, axis_key));
    sim::AxisDefinition& ax = machine.axes[index(*a)];
    ax.present = true;
    ax.loop.law = law;
    if (!p.is_object()) throw ConfigError(fmt::format("{}: machine.axes.{} must be a map", where, axis_key));
    for (const auto& [key, v] : p.items()) {
      const sim::AxisParamSpec* spec = sim::find_axis_param(key);
      if (spec == nullptr)
        throw ConfigError(fmt::format("{}: machine.axes.{}: unknown parameter '{}'", where, axis_key, key));
      sim::set_axis_param(ax, *spec, number(v, fmt::format("{}: machine.axes.{}.{}", where, axis_key, key)));
    }
  }
  machine.validate();
  model.program_path = text(member(j, "program_name", where), where + ": program_name");
  model.program_text = text(member(j, "program", where), where + ": program");
  const json& s = member(j, "start_mm", where);
  if (!s.is_array() || s.size() != 3) throw ConfigError(fmt::format("{}: start_mm must be [x, y, z]", where));
  for (std::size_t i = 0; i < 3; ++i) model.start_mm[i] = number(s[i], fmt::format("{}: start_mm[{}]", where, i));
  model.settle_s = number(member(j, "settle_s", where), where + ": settle_s");
  if (model.settle_s < 0.0 || model.settle_s > 60.0)
    throw ConfigError(fmt::format("{}: settle_s = {} must be in [0, 60] s", where, model.settle_s));
  const json& proc = member(j, "process", where);
  if (!proc.is_null()) {
    model.process_setup = process_setup_from_json(proc);
    process::make_process(*model.process_setup);  // fails here, with the key, rather than at the first step
  }
  // A program out of the machine's travel, or one no run could finish, is
  // refused here (at export and at fmi2Instantiate), not at the first step.
  if (model.has_program()) {
    try {
      static_cast<void>(model.plan_program(machine));
    } catch (const ConfigError& e) {
      throw ConfigError(fmt::format("{}: program: {}", where, e.what()));
    }
  }
  return model;
}

sim::PlannedProgram FmuModel::plan_program(const sim::MachineDefinition& m) const {
  sim::PlannedProgram planned = sim::plan_program(*this, m);
  const double duration_s = planned.trajectory().duration_s() + settle_s;
  const double ticks = std::ceil(duration_s / m.Ts_s);
  if (!(duration_s <= kMaxProgramDuration_s) || !(ticks <= kMaxProgramTicks))
    throw ConfigError(fmt::format(
        "{}: the program is planned to run {:.6g} s ({:.6g} ticks of Ts = {} s, settle_s included); an FMU runs at "
        "most {:g} s and {:g} ticks of a program",
        program_path.string(), duration_s, ticks, m.Ts_s, kMaxProgramDuration_s, kMaxProgramTicks));
  return planned;
}

double FmuModel::program_duration_s() const {
  if (!has_program()) return 0.0;
  return plan_program(machine).trajectory().duration_s() + settle_s;
}

}  // namespace twin::fmu
