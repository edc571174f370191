#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "twin/cli/commands.hpp"
#include "twin/cli/common.hpp"
#include "twin/io/atomic_file.hpp"
#include "twin/structure/lobe_study.hpp"

namespace twin::cli {

void register_lobes(CLI::App& app) {
  struct Options {
    std::string scenario;
    std::string out;
    std::string machine;
    std::vector<std::string> sets;
    structure::LobeStudyOptions study;
  };
  auto opt = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand(
      "lobes", "Zero-order stability lobes of a scenario's cut (default: the FADAL 2216 pocket corner) from the "
               "machine's tool-tip modes; writes OUT/lobes.csv, boundary.csv, report.json, lobes.png");
  cmd->add_option("scenario", opt->scenario, "scenario.yaml, its folder, or a shipped scenario name");
  cmd->add_option("-o,--out", opt->out, "output folder (created if missing)")->required();
  cmd->add_option("--machine", opt->machine, "machine definition (name or YAML file) replacing the scenario's");
  cmd->add_option("--set", opt->sets, "override a parameter: <axis>.<name>=<value>")->take_all();
  cmd->add_option("--lobes", opt->study.lobes, "number of lobes")->capture_default_str();
  cmd->add_option("--rpm-min", opt->study.rpm_min, "lowest speed of the boundary table, rev/min (0: from the lobes)");
  cmd->add_option("--rpm-max", opt->study.rpm_max, "highest speed of the boundary table, rev/min (0: from the lobes)");
  cmd->callback([opt]() {
    const auto path = opt->scenario.empty() ? io::default_scenario_path() : io::resolve_scenario_path(opt->scenario);
    io::Scenario scenario = io::load_scenario(path, opt->machine);
    apply_sets(scenario.machine, opt->sets);
    const structure::LobeStudy study = structure::study_lobes(scenario, opt->study);
    io::ResultSet results(opt->out, "lobes");
    structure::write_lobe_study(results, study);
    results.commit();
    std::printf("%s; wrote %s\n", structure::lobe_summary(study).c_str(),
                results.final_path("lobes.png").c_str());
  });
}

}  // namespace twin::cli
