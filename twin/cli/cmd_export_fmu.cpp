// `twin export-fmu`: the twin as an FMI 2.0 Co-Simulation FMU (docs/fmu.md).
#include <cstdio>
#include <deque>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <yaml-cpp/yaml.h>
#include <unistd.h>
#include <zip.h>

#include "fmu/model.hpp"
#include "fmu/model_description.hpp"
#include "fmu/process_json.hpp"
#include "twin/cli/commands.hpp"
#include "twin/cli/common.hpp"
#include "twin/core/error.hpp"
#include "twin/io/atomic_file.hpp"
#include "twin/io/machine_file.hpp"
#include "twin/io/process_yaml.hpp"
#include "twin/io/scenario_file.hpp"
#include "twin/io/yaml_util.hpp"

namespace twin::cli {
namespace {

std::string read_binary(const std::filesystem::path& p) {
  std::FILE* f = std::fopen(p.c_str(), "rb");
  if (f == nullptr) throw IoError(fmt::format("cannot read the FMU binary {} (build the MachineTwin target, or pass --binary)", p.string()));
  std::string data;
  char buf[65536];
  std::size_t n = 0;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) data.append(buf, n);
  std::fclose(f);
  return data;
}

/// Writes the entries into a zip at `path` (via a temporary name).
void write_zip(const std::filesystem::path& path, const std::vector<std::pair<std::string, std::string>>& entries) {
  const std::string tmp = path.string() + fmt::format(".tmp{}", static_cast<long>(::getpid()));
  int err = 0;
  zip_t* z = zip_open(tmp.c_str(), ZIP_CREATE | ZIP_TRUNCATE, &err);
  if (z == nullptr) throw IoError(fmt::format("{}: cannot create the zip (libzip error {})", tmp, err));
  for (const auto& [name, data] : entries) {
    zip_source_t* src = zip_source_buffer(z, data.data(), data.size(), 0);
    if (src == nullptr || zip_file_add(z, name.c_str(), src, ZIP_FL_ENC_UTF_8 | ZIP_FL_OVERWRITE) < 0) {
      if (src != nullptr) zip_source_free(src);
      const std::string msg = zip_strerror(z);
      zip_discard(z);
      throw IoError(fmt::format("{}: cannot add {}: {}", tmp, name, msg));
    }
  }
  if (zip_close(z) != 0) {
    const std::string msg = zip_strerror(z);
    zip_discard(z);
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
    throw IoError(fmt::format("{}: cannot write the zip: {}", tmp, msg));
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
    throw IoError(fmt::format("cannot rename {} to {}: {}", tmp, path.string(), ec.message()));
  }
}

}  // namespace

void register_export_fmu(CLI::App& app) {
  struct Options {
    std::string scenario;
    std::string machine;
    std::string out;
    std::string binary{TWIN_FMU_BINARY};
    std::vector<std::string> sets;
  };
  auto opt = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand("export-fmu", "Write the twin of a scenario as an FMI 2.0 Co-Simulation FMU (docs/fmu.md)");
  cmd->add_option("--scenario", opt->scenario, "scenario.yaml, its folder, or a shipped scenario name (default: the FADAL 2216 pocket corner)");
  cmd->add_option("--machine", opt->machine, "machine definition (name or YAML file) replacing the scenario's");
  cmd->add_option("-o,--out", opt->out, "the .fmu file to write")->required();
  cmd->add_option("--set", opt->sets, "override a parameter: <axis>.<name>=<value>, e.g. x.Kp=600")->take_all();
  cmd->add_option("--binary", opt->binary, "the FMU shared library to pack (default: the one built with this twin)");
  cmd->callback([opt]() {
    const auto path = opt->scenario.empty() ? io::default_scenario_path() : io::resolve_scenario_path(opt->scenario);
    io::Scenario scenario = io::load_scenario(path, opt->machine);
    apply_sets(scenario.machine, opt->sets);
    const YAML::Node root = io::load_yaml_file(path);
    // The process section resolved (tool and material files read) into a
    // complete setup: the FMU carries numbers, not file references.
    nlohmann::json process = nullptr;
    if (root.IsMap() && root["process"])
      process = fmu::process_setup_to_json(io::parse_process_setup(root["process"], path.string(), path.parent_path()));

    const std::string model_text =
        fmu::model_to_json(scenario.name, scenario.machine, scenario.program_path.filename().string(),
                           scenario.program_text, scenario.start_mm, scenario.settle_s, process);
    fmu::FmuModel model;
    try {
      model = fmu::model_from_json(model_text, "resources/model.json");
    } catch (const Error& e) {
      throw ConfigError(fmt::format("{}: cannot be carried into the FMU: {}", path.string(), e.what()));
    }
    const std::string xml = fmu::model_description_xml(model);
    const std::string binary = read_binary(opt->binary);

    std::vector<std::pair<std::string, std::string>> entries;
    entries.emplace_back("modelDescription.xml", xml);
    entries.emplace_back(fmt::format("binaries/linux64/{}.so", fmu::kModelIdentifier), binary);
    entries.emplace_back("resources/model.json", model_text);
    entries.emplace_back("resources/machine.yaml",
                         io::machine_to_yaml(scenario.machine, fmt::format("machine of the FMU exported from {}", path.string())));
    entries.emplace_back("resources/scenario.yaml", io::read_file(path));
    if (!scenario.program_path.empty())
      entries.emplace_back("resources/" + scenario.program_path.filename().string(), scenario.program_text);
    const std::filesystem::path out(opt->out);
    if (out.has_parent_path()) io::ensure_directory(out.parent_path());
    write_zip(out, entries);
    std::printf("%s\n", fmt::format("wrote {} (scenario {}, {} axes, GUID {}{})", out.string(), scenario.name,
                                    scenario.machine.present_axes().size(), fmu::model_guid(model),
                                    model.has_process() ? ", with the cutting process" : ", air cut")
                            .c_str());
  });
}

}  // namespace twin::cli
