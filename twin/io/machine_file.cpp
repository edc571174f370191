#include "twin/io/machine_file.hpp"

#include <cmath>
#include <cstdlib>
#include <sstream>

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include "twin/core/error.hpp"
#include "twin/io/atomic_file.hpp"
#include "twin/io/process_yaml.hpp"
#include "twin/io/yaml_util.hpp"
#include "twin/structure/machine_structure.hpp"

#ifndef TWIN_SCENARIOS_DIR
#error "TWIN_SCENARIOS_DIR must be defined by the build"
#endif

namespace twin::io {

namespace {
/// A YAML single-quoted scalar: a quote is doubled, nothing else is special (a newline becomes a space).
std::string single_quoted(const std::string& text) {
  std::string quoted;
  for (char ch : text) quoted += ch == '\'' ? std::string("''") : std::string(1, ch == '\n' ? ' ' : ch);
  return "'" + quoted + "'";
}
}  // namespace

std::filesystem::path scenarios_dir() {
  if (const char* env = std::getenv("TWIN_SCENARIOS_DIR"); env != nullptr && *env != '\0') return env;
  return TWIN_SCENARIOS_DIR;
}

std::filesystem::path resolve_machine_path(const std::string& name_or_path, const std::filesystem::path& relative_to) {
  std::filesystem::path p(name_or_path);
  if (p.has_extension() || name_or_path.find('/') != std::string::npos) {
    if (p.is_relative() && !relative_to.empty() && !std::filesystem::exists(p)) p = relative_to / p;
    return p;
  }
  return scenarios_dir() / "machines" / (name_or_path + ".yaml");
}

namespace {

void parse_effects(const YAML::Node& node, sim::AxisDefinition& axis, const std::string& where) {
  if (!node.IsMap()) throw ConfigError(fmt::format("{}: effects must be a map of effect names", where));
  for (const auto& kv : node) {
    const std::string effect = kv.first.as<std::string>();
    const std::string w = where + ".effects." + effect;
    if (!kv.second.IsMap()) throw ConfigError(fmt::format("{}: must be a map of parameters", w));
    bool known_effect = false;
    for (const auto& spec : sim::axis_param_specs())
      if (spec.name.starts_with(effect + ".")) known_effect = true;
    if (!known_effect) throw ConfigError(fmt::format("{}: unknown effect '{}'", where, effect));
    bool any = false;
    for (const auto& p : kv.second) {
      const std::string key = p.first.as<std::string>();
      if (key == "enabled") {
        const bool on = yaml_bool(p.second, w + ".enabled");
        for (const auto& spec : sim::axis_param_specs())
          if (spec.name.starts_with(effect + ".") && spec.enables) *spec.enables(axis) = on;
        any = true;
        continue;
      }
      const auto* spec = sim::find_axis_param(effect + "." + key);
      if (spec == nullptr) throw ConfigError(fmt::format("{}: unknown key '{}'", w, key));
      sim::set_axis_param(axis, *spec, yaml_number(p.second, w + "." + key));
      any = true;
    }
    if (!any) throw ConfigError(fmt::format("{}: no parameters", w));
  }
}

/// `structure:` {stacking, table_kg, saddle_kg, head_kg, workpiece_kg,
/// counterbalance_N, screw_efficiency, screw_stiffness_N_per_um: {x, y, z}, source}.
void parse_structure(const YAML::Node& node, sim::MachineDefinition& m, const std::string& where) {
  const std::string w = where + ": structure";
  if (!node.IsMap()) throw ConfigError(fmt::format("{} must be a map (stacking, table_kg, saddle_kg, head_kg ...)", w));
  sim::StructureDefinition s;
  bool table = false, saddle = false, head = false;
  for (const auto& kv : node) {
    const std::string key = kv.first.as<std::string>();
    const std::string kw = w + "." + key;
    if (key == "stacking") s.stacking = yaml_string(kv.second, kw);
    else if (key == "source") s.source = yaml_string(kv.second, kw);
    else if (key == "table_kg") s.table_kg = yaml_number(kv.second, kw), table = true;
    else if (key == "saddle_kg") s.saddle_kg = yaml_number(kv.second, kw), saddle = true;
    else if (key == "head_kg") s.head_kg = yaml_number(kv.second, kw), head = true;
    else if (key == "workpiece_kg") s.workpiece_kg = yaml_number(kv.second, kw);
    else if (key == "counterbalance_N") s.counterbalance_N = yaml_number(kv.second, kw);
    else if (key == "screw_efficiency") s.screw_efficiency = yaml_number(kv.second, kw);
    else if (key == "screw_stiffness_N_per_um") {
      if (!kv.second.IsMap()) throw ConfigError(fmt::format("{} must be a map of axes x/y/z", kw));
      for (const auto& ax : kv.second) {
        const std::string an = ax.first.as<std::string>();
        const auto axis = parse_axis(an);
        if (!axis) throw ConfigError(fmt::format("{}: unknown axis '{}'", kw, an));
        s.screw_stiffness_N_per_um[index(*axis)] = yaml_number(ax.second, kw + "." + an);
      }
    } else {
      throw ConfigError(fmt::format("{}: unknown key '{}' (stacking, table_kg, saddle_kg, head_kg, workpiece_kg, "
                                    "counterbalance_N, screw_efficiency, screw_stiffness_N_per_um, source)",
                                    w, key));
    }
  }
  if (!table || !saddle || !head) throw ConfigError(fmt::format("{}: needs table_kg, saddle_kg and head_kg", w));
  m.structure = s;
}

structure::StructureSpec structure_spec(const sim::StructureDefinition& s, const std::string& where) {
  structure::StructureSpec sp;
  const auto st = structure::parse_stacking(s.stacking);
  if (!st) throw ConfigError(fmt::format("{}: structure.stacking: unknown '{}' (x_on_y or y_on_x)", where, s.stacking));
  sp.stacking = *st;
  sp.table_kg = s.table_kg;
  sp.saddle_kg = s.saddle_kg;
  sp.head_kg = s.head_kg;
  sp.workpiece_kg = s.workpiece_kg;
  sp.counterbalance_N = s.counterbalance_N;
  sp.screw_efficiency = s.screw_efficiency;
  sp.screw_stiffness_N_per_um = s.screw_stiffness_N_per_um;
  return sp;
}

/// Evaluates the structure model (Simbody) and folds its loads into the drives.
void fold_structure(sim::MachineDefinition& m, const std::string& where) {
  sim::StructureDefinition& s = *m.structure;
  std::array<double, 3> rg{};
  for (Axis a : kAllAxes) {
    if (!m.axes[index(a)].present)
      throw ConfigError(fmt::format("{}: structure: needs all three axes (axis {} is missing)", where, axis_name(a)));
    rg[index(a)] = m.axes[index(a)].drive.rg_mm_per_rad;
  }
  const structure::StructureSpec spec = structure_spec(s, where);
  spec.validate(where);
  const auto loads = structure::axis_loads(spec, rg);
  for (Axis a : kAllAxes) {
    const std::size_t i = index(a);
    feeddrive::DriveParams& d = m.axes[i].drive;
    s.carried_kg[i] = loads[i].carried_kg;
    s.reflected_J_kg_m2[i] = loads[i].reflected_J_kg_m2;
    s.gravity_torque_Nm[i] = loads[i].gravity_torque_Nm;
    const double J_motor = d.J_kg_m2;
    d.J_kg_m2 += loads[i].reflected_J_kg_m2;
    s.enabled_constant_load[i] = false;
    if (loads[i].gravity_torque_Nm != 0.0) {
      s.enabled_constant_load[i] = !d.effects.constant_load.enabled;
      d.effects.constant_load.enabled = true;
      d.effects.constant_load.torque_Nm += loads[i].gravity_torque_Nm;
    }
    s.enabled_compliance[i] = false;
    if (loads[i].screw_K_Nm_per_rad > 0.0) {
      if (d.effects.compliance.enabled)
        throw ConfigError(fmt::format("{}: axes.{}: effects.compliance and structure.screw_stiffness_N_per_um.{} "
                                      "both set the screw's compliance; give one",
                                      where, axis_name(a), axis_name(a)));
      // Two masses: the motor and screw (the file's J) against the carried mass.
      s.enabled_compliance[i] = true;
      d.effects.compliance.enabled = true;
      d.effects.compliance.K_Nm_per_rad = loads[i].screw_K_Nm_per_rad;
      d.effects.compliance.load_fraction = loads[i].reflected_J_kg_m2 / (J_motor + loads[i].reflected_J_kg_m2);
    }
  }
}

/// The machine as its file gives it: the structure's loads taken back out of the drives.
sim::MachineDefinition unfold_structure(const sim::MachineDefinition& folded) {
  sim::MachineDefinition m = folded;
  if (!m.structure) return m;
  const sim::StructureDefinition& s = *m.structure;
  for (Axis a : kAllAxes) {
    const std::size_t i = index(a);
    feeddrive::DriveParams& d = m.axes[i].drive;
    d.J_kg_m2 -= s.reflected_J_kg_m2[i];
    if (s.gravity_torque_Nm[i] != 0.0) {
      d.effects.constant_load.torque_Nm -= s.gravity_torque_Nm[i];
      if (s.enabled_constant_load[i]) d.effects.constant_load = {};
    }
    if (s.enabled_compliance[i]) d.effects.compliance = {};
  }
  return m;
}

}  // namespace

sim::MachineDefinition load_machine(const std::filesystem::path& path) {
  const std::string where = path.string();
  YAML::Node root = load_yaml_file(path);
  if (!root.IsMap()) throw ConfigError(fmt::format("{}: a machine definition must be a YAML map", where));
  sim::MachineDefinition m;
  m.source = where;
  m.name = path.stem().string();
  // The loop law first: it decides which gains the axes may hold.
  controller::LoopLaw law = controller::LoopLaw::kFadal;
  if (const YAML::Node c = root["controller"]; c) {
    const std::string name = yaml_string(c, where + ": controller");
    const auto parsed = controller::parse_loop_law(name);
    if (!parsed) throw ConfigError(fmt::format("{}: controller: unknown law '{}' (fadal or cascade)", where, name));
    law = *parsed;
  }
  bool have_axes = false;
  for (const auto& kv : root) {
    const std::string key = kv.first.as<std::string>();
    if (key == "controller") continue;
    if (key == "name") {
      m.name = yaml_string(kv.second, where + ": name");
    } else if (key == "tool_tip") {
      m.tool_tip = parse_tool_tip(kv.second, where + ": tool_tip", m.tool_tip_source);
    } else if (key == "structure") {
      parse_structure(kv.second, m, where);
    } else if (key == "description") {
      static_cast<void>(yaml_string(kv.second, where + ": description"));
    } else if (key == "axes") {
      have_axes = true;
      if (!kv.second.IsMap()) throw ConfigError(fmt::format("{}: axes must be a map x/y/z", where));
      for (const auto& ax : kv.second) {
        const std::string an = ax.first.as<std::string>();
        const auto axis = parse_axis(an);
        if (!axis) throw ConfigError(fmt::format("{}: axes: unknown axis '{}'", where, an));
        sim::AxisDefinition& def = m.axes[index(*axis)];
        def.present = true;
        if (!ax.second.IsMap()) throw ConfigError(fmt::format("{}: axes.{} must be a map", where, an));
        for (const auto& p : ax.second) {
          const std::string pk = p.first.as<std::string>();
          const std::string w = fmt::format("{}: axes.{}", where, an);
          if (pk == "effects") {
            parse_effects(p.second, def, w);
            continue;
          }
          const auto* spec = sim::find_axis_param(pk);
          if (spec == nullptr || spec->enables != nullptr)
            throw ConfigError(fmt::format("{}: unknown key '{}'", w, pk));
          if (spec->law && *spec->law != law)
            throw ConfigError(fmt::format("{}: {} is a gain of the {} law; this machine's controller is {}", w, pk,
                                          controller::loop_law_name(*spec->law), controller::loop_law_name(law)));
          sim::set_axis_param(def, *spec, yaml_number(p.second, w + "." + pk));
        }
      }
    } else if (const auto* ms = sim::find_machine_param(key)) {
      ms->ref(m) = yaml_number(kv.second, where + ": " + key);
    } else {
      throw ConfigError(fmt::format("{}: unknown key '{}'", where, key));
    }
  }
  if (!have_axes) throw ConfigError(fmt::format("{}: missing key 'axes'", where));
  sim::set_machine_loop_law(m, law);
  if (m.structure) fold_structure(m, where);
  m.validate();
  return m;
}

std::string machine_to_yaml(const sim::MachineDefinition& folded, const std::string& header_comment) {
  const sim::MachineDefinition m = unfold_structure(folded);
  std::ostringstream o;
  o.precision(12);
  std::istringstream hc(header_comment);
  for (std::string line; std::getline(hc, line);) o << "# " << line << "\n";
  o << "name: " << m.name << "\n";
  const controller::LoopLaw law = sim::machine_loop_law(m);
  if (law != controller::LoopLaw::kFadal)
    o << "controller: " << controller::loop_law_name(law) << "    # position-loop law (spec/measured-data.md)\n";
  for (const auto& s : sim::machine_param_specs())
    o << s.name << ": " << s.ref(const_cast<sim::MachineDefinition&>(m)) << "    # " << s.unit << ", " << s.doc << "\n";
  o << "axes:\n";
  for (Axis a : m.present_axes()) {
    const sim::AxisDefinition& ax = m.axes[index(a)];
    o << "  " << axis_name(a) << ":\n";
    std::ostringstream eff;
    eff.precision(12);
    std::string current_effect;
    for (const auto& s : sim::axis_param_specs()) {
      const double v = sim::get_axis_param(ax, s);
      if (s.law && *s.law != law) continue;
      if (s.enables == nullptr) {
        o << "    " << s.name << ": " << v << "    # " << s.unit << ", " << s.doc << "\n";
        continue;
      }
      if (!*s.enables(const_cast<sim::AxisDefinition&>(ax))) continue;
      const auto dot = s.name.find('.');
      const std::string effect(s.name.substr(0, dot));
      if (effect != current_effect) {
        eff << "      " << effect << ":\n";
        current_effect = effect;
      }
      eff << "        " << s.name.substr(dot + 1) << ": " << v << "    # " << s.unit << ", " << s.doc << "\n";
    }
    if (!eff.str().empty()) o << "    effects:\n" << eff.str();
  }
  if (!m.tool_tip.empty()) {
    o << "tool_tip:    # tool-tip modes (stability lobes)\n";
    if (!m.tool_tip_source.empty()) {
      o << "  source: " << single_quoted(m.tool_tip_source) << "\n";
    }
    for (const auto* dir : {"x", "y"}) {
      const auto& modes = dir[0] == 'x' ? m.tool_tip.x : m.tool_tip.y;
      if (modes.empty()) continue;
      o << "  " << dir << ":\n";
      for (const auto& md : modes)
        o << "    - {fn_Hz: " << md.fn_Hz << ", zeta: " << md.zeta << ", k_N_per_m: " << md.k_N_per_m << "}\n";
    }
  }
  if (m.structure) {
    const sim::StructureDefinition& s = *m.structure;
    o << "structure:    # masses on the slides (J above is the motor and screw alone)\n";
    if (!s.source.empty()) o << "  source: " << single_quoted(s.source) << "\n";
    o << "  stacking: " << s.stacking << "\n  table_kg: " << s.table_kg << "\n  saddle_kg: " << s.saddle_kg
      << "\n  head_kg: " << s.head_kg << "\n  workpiece_kg: " << s.workpiece_kg
      << "\n  counterbalance_N: " << s.counterbalance_N << "\n  screw_efficiency: " << s.screw_efficiency << "\n";
    o << "  screw_stiffness_N_per_um: {x: " << s.screw_stiffness_N_per_um[0]
      << ", y: " << s.screw_stiffness_N_per_um[1] << ", z: " << s.screw_stiffness_N_per_um[2] << "}\n";
  }
  return o.str();
}

}  // namespace twin::io
