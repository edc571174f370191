#pragma once
/// The process setup in an FMU's resources/model.json: the scenario's
/// `process:` section in JSON, with the keys of the YAML (docs/process.md),
/// read by the same reader (twin/sim/process_setup_reader.hpp) with the same
/// checks. The setup is written resolved: the tool and the one coefficient
/// set it uses inline (the FMU carries numbers, not file references), every
/// number to the last bit.
#include <memory>

#include <nlohmann/json_fwd.hpp>

#include "process/milling_process.hpp"
#include "process/process_model.hpp"

namespace twin::fmu {

/// The setup `process` describes (not null).
/// @throws ConfigError naming the key and the value for an unknown key, a
/// value of the wrong type, or a setup the reader rejects.
process::ProcessSetup process_setup_from_json(const nlohmann::json& process);

/// Builds the milling process (process::make_process) from `process`.
/// A null `process` gives nullptr (an air cut).
std::unique_ptr<process::ProcessModel> make_process_from_json(const nlohmann::json& process);

/// The JSON form of a complete setup, which process_setup_from_json reads
/// back into the same setup. `twin export-fmu` writes it from the
/// scenario's setup (tool and material files read).
nlohmann::json process_setup_to_json(const process::ProcessSetup& setup);

}  // namespace twin::fmu
