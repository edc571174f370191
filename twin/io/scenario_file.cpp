#include "twin/io/scenario_file.hpp"

#include <cmath>

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include "twin/core/error.hpp"
#include "twin/io/atomic_file.hpp"
#include "twin/io/machine_file.hpp"
#include "twin/io/process_yaml.hpp"
#include "twin/io/yaml_util.hpp"

namespace twin::io {
namespace {
/// No machine tool reaches 100 m from its origin.
constexpr double kMaxStart_mm = 1e5;
}  // namespace

std::filesystem::path default_scenario_path() { return scenarios_dir() / "fadal_pocket_corner" / "scenario.yaml"; }

std::filesystem::path resolve_scenario_path(const std::string& name_or_path) {
  std::filesystem::path p(name_or_path);
  if (std::filesystem::is_directory(p)) return p / "scenario.yaml";
  if (std::filesystem::exists(p)) return p;
  const auto shipped = scenarios_dir() / name_or_path / "scenario.yaml";
  if (name_or_path.find('/') == std::string::npos && std::filesystem::exists(shipped)) return shipped;
  throw ConfigError(fmt::format("scenario '{}': no such file, folder or shipped scenario", name_or_path));
}

Scenario load_scenario(const std::filesystem::path& path, const std::string& machine_override) {
  const std::string where = path.string();
  YAML::Node root = load_yaml_file(path);
  if (!root.IsMap()) throw ConfigError(fmt::format("{}: a scenario must be a YAML map", where));
  Scenario s;
  s.path = path;
  s.name = path.parent_path().filename().string();
  const auto dir = path.parent_path();
  std::string machine_name;
  YAML::Node process_node;
  for (const auto& kv : root) {
    const std::string key = kv.first.as<std::string>();
    const std::string w = where + ": " + key;
    if (key == "name") {
      s.name = yaml_name(kv.second, w);
    } else if (key == "description") {
      s.description = yaml_string(kv.second, w);
    } else if (key == "machine") {
      machine_name = yaml_name(kv.second, w);
    } else if (key == "program") {
      s.program_path = dir / yaml_name(kv.second, w);
    } else if (key == "start_mm") {
      if (!kv.second.IsSequence() || kv.second.size() != 3)
        throw ConfigError(fmt::format("{} must be a list [x, y, z]", w));
      for (std::size_t i = 0; i < 3; ++i) {
        s.start_mm[i] = yaml_number(kv.second[i], fmt::format("{}[{}]", w, i));
        if (!(std::abs(s.start_mm[i]) <= kMaxStart_mm))
          throw ConfigError(fmt::format("{}[{}] = {:g} mm is beyond +-{:g} mm, the reach of any machine", w, i,
                                        s.start_mm[i], kMaxStart_mm));
      }
    } else if (key == "settle_s") {
      s.settle_s = yaml_number(kv.second, w);
      if (s.settle_s < 0.0 || s.settle_s > 60.0) throw ConfigError(fmt::format("{} = {} must be in [0, 60] s", w, s.settle_s));
    } else if (key == "process") {
      process_node = kv.second;
    } else {
      throw ConfigError(fmt::format("{}: unknown key '{}'", where, escaped(key)));
    }
  }
  if (machine_name.empty() && machine_override.empty())
    throw ConfigError(fmt::format("{}: missing key 'machine'", where));
  if (s.program_path.empty()) throw ConfigError(fmt::format("{}: missing key 'program'", where));
  const std::string& machine_ref = machine_override.empty() ? machine_name : machine_override;
  try {
    s.machine = load_machine(resolve_machine_path(machine_ref, dir));
  } catch (const std::filesystem::filesystem_error& e) {
    // A name the file system cannot look up (too long, a bad path).
    throw IoError(fmt::format("{}: machine '{}': {}", where, escaped(machine_ref), e.code().message()));
  }
  s.program_text = read_file(s.program_path, controller::kMaxProgramBytes);
  if (process_node && !process_node.IsNull()) {
    s.process_setup = parse_process_setup(process_node, where + ": process", dir);
    // A machine with a structure cuts with its tool-tip modes (the tool
    // vibrates, the chip regenerates); without `structure:` the tool is rigid.
    if (s.machine.structure) s.process_setup->tool_tip = s.machine.tool_tip;
  }
  return s;
}

}  // namespace twin::io
