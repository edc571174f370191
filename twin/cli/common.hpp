#pragma once
/// Options shared by several subcommands.
#include <string>
#include <vector>

#include "twin/sim/machine.hpp"

namespace twin::cli {

/// Applies every `--set` assignment and validates the machine.
void apply_sets(sim::MachineDefinition& machine, const std::vector<std::string>& sets);

}  // namespace twin::cli
