#include "twin/cli/common.hpp"

namespace twin::cli {

void apply_sets(sim::MachineDefinition& machine, const std::vector<std::string>& sets) {
  for (const auto& s : sets) sim::apply_set(machine, s);
  if (!sets.empty()) machine.source += " (with --set)";
  machine.validate();
}

}  // namespace twin::cli
