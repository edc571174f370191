#pragma once
/// Options shared by several subcommands.
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "twin/sim/machine.hpp"

namespace twin::cli {

/// Applies every `--set` assignment and validates the machine.
void apply_sets(sim::MachineDefinition& machine, const std::vector<std::string>& sets);

/// Refuses (ConfigError, one line, before anything is written) an output folder
/// that would write over a command's input: OUT is the measured run folder RUN
/// or a folder inside it (OUT/trace.csv would replace RUN/trace.csv or hide
/// RUN/trace.csv.gz), or OUT holds a file the command reads (a file of RUN
/// reached through a link, or the --machine file). Paths are compared after
/// resolving links, `..` and `.`.
void refuse_output_over_input(std::string_view command, const std::filesystem::path& out,
                              const std::filesystem::path& run_dir, const std::string& machine_option);

}  // namespace twin::cli
