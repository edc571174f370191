// `twin export-fmu`: the twin as an FMI 2.0 or FMI 3.0 Co-Simulation FMU
// (docs/fmu.md).
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "fmu/archive.hpp"
#include "fmu/model.hpp"
#include "fmu/model_description.hpp"
#include "fmu/process_json.hpp"
#include "twin/cli/commands.hpp"
#include "twin/cli/common.hpp"
#include "twin/core/error.hpp"
#include "twin/io/atomic_file.hpp"
#include "twin/io/machine_file.hpp"
#include "twin/io/scenario_file.hpp"

namespace twin::cli {
void register_export_fmu(CLI::App& app) {
  struct Options {
    std::string scenario;
    std::string machine;
    std::string out;
    std::string binary;
    int fmi{2};
    std::vector<std::string> sets;
  };
  auto opt = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand(
      "export-fmu", "Write the twin of a scenario as an FMI 2.0 or FMI 3.0 Co-Simulation FMU (docs/fmu.md)");
  cmd->add_option("--scenario", opt->scenario, "scenario.yaml, its folder, or a shipped scenario name (default: the FADAL 2216 pocket corner)");
  cmd->add_option("--machine", opt->machine, "machine definition (name or YAML file) replacing the scenario's");
  cmd->add_option("-o,--out", opt->out, "the .fmu file to write")->required();
  cmd->add_option("--set", opt->sets, "override a parameter: <axis>.<name>=<value>, e.g. x.Kp=600")->take_all();
  cmd->add_option("--fmi", opt->fmi, "FMI version of the FMU: 2 (FMI 2.0, the default) or 3 (FMI 3.0)")
      ->check(CLI::IsMember({2, 3}));
  cmd->add_option("--binary", opt->binary,
                  "the FMU shared library to pack (default: the one of that FMI version built with this twin)");
  cmd->callback([opt]() {
    const auto path = opt->scenario.empty() ? io::default_scenario_path() : io::resolve_scenario_path(opt->scenario);
    io::Scenario scenario = io::load_scenario(path, opt->machine);
    apply_sets(scenario.machine, opt->sets);
    // The scenario's process setup, resolved when it was read (tool and
    // material files included): the FMU carries numbers, not file references.
    nlohmann::json process = nullptr;
    if (scenario.process_setup) process = fmu::process_setup_to_json(*scenario.process_setup);

    const std::string model_text =
        fmu::model_to_json(scenario.name, scenario.machine, scenario.program_path.filename().string(),
                           scenario.program_text, scenario.start_mm, scenario.settle_s, process);
    fmu::FmuModel model;
    try {
      model = fmu::model_from_json(model_text, "resources/model.json");
    } catch (const Error& e) {
      throw ConfigError(fmt::format("{}: cannot be carried into the FMU: {}", path.string(), e.what()));
    }
    const fmu::FmiVersion version = opt->fmi == 3 ? fmu::FmiVersion::k3 : fmu::FmiVersion::k2;
    fmu::FmuArchive archive;
    archive.version = version;
    archive.model_description = fmu::model_description_xml(model, version);
    const std::string binary_path = !opt->binary.empty()                 ? opt->binary
                                    : version == fmu::FmiVersion::k3 ? TWIN_FMU3_BINARY
                                                                     : TWIN_FMU_BINARY;
    archive.binary = fmu::read_binary_file(binary_path);
    archive.resources.emplace_back("model.json", model_text);
    archive.resources.emplace_back(
        "machine.yaml",
        io::machine_to_yaml(scenario.machine, fmt::format("machine of the FMU exported from {}", path.string())));
    archive.resources.emplace_back("scenario.yaml", io::read_file(path));
    if (!scenario.program_path.empty())
      archive.resources.emplace_back(scenario.program_path.filename().string(), scenario.program_text);
    const std::filesystem::path out(opt->out);
    if (out.has_parent_path()) io::ensure_directory(out.parent_path());
    try {
      fmu::write_fmu_archive(out, archive);
    } catch (const ConfigError& e) {
      throw ConfigError(fmt::format("{}: {} (--fmi {})", binary_path, e.what(), opt->fmi));
    }
    const std::string id = version == fmu::FmiVersion::k3 ? fmu::instantiation_token(model) : fmu::model_guid(model);
    std::printf("%s\n", fmt::format("wrote {} (FMI {}.0, scenario {}, {} axes, {} {}{})", out.string(), opt->fmi,
                                    scenario.name, scenario.machine.present_axes().size(),
                                    version == fmu::FmiVersion::k3 ? "instantiationToken" : "GUID", id,
                                    model.has_process() ? ", with the cutting process" : ", air cut")
                            .c_str());
  });
}

}  // namespace twin::cli
