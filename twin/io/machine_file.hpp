#pragma once
/// Machine definitions as YAML (scenarios/machines/<name>.yaml). Keys are the
/// parameter names of spec/interfaces.md; unknown keys, non-numbers,
/// non-finite or non-physical values are errors naming file, key and value.
#include <filesystem>
#include <string>

#include "twin/sim/machine.hpp"

namespace twin::io {

/// The machine a run that names none (or one not shipped) is taken to be from.
inline constexpr const char* kDefaultMachineName = "fadal2216";

/// The folder holding the shipped scenarios and machines.
std::filesystem::path scenarios_dir();
/// A name of a shipped machine ("fadal2216") or a path to a YAML file.
std::filesystem::path resolve_machine_path(const std::string& name_or_path,
                                           const std::filesystem::path& relative_to = {});
sim::MachineDefinition load_machine(const std::filesystem::path& path);
/// YAML text of a machine, loadable by load_machine (every parameter, with units
/// as comments; a header comment says where it came from).
std::string machine_to_yaml(const sim::MachineDefinition& machine, const std::string& header_comment);

}  // namespace twin::io
