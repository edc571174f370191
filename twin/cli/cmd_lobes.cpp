#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "twin/cli/commands.hpp"
#include "twin/cli/common.hpp"
#include "twin/io/atomic_file.hpp"
#include "twin/structure/chatter_check.hpp"
#include "twin/structure/lobe_study.hpp"

namespace twin::cli {

void register_lobes(CLI::App& app) {
  struct Options {
    std::string scenario;
    std::string out;
    std::string machine;
    std::vector<std::string> sets;
    std::vector<std::string> checks;
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
  cmd->add_option("--check", opt->checks,
                  "RPM:DEPTH_mm, repeatable: run the coupled twin (drives, process, the tool's modes, regenerative "
                  "chip) on a straight cut at the scenario's immersion, feed per tooth and direction at this speed "
                  "and axial depth, and report chatter or not from the force spectrum beside the lobes' verdict "
                  "(OUT/check.csv, report.json \"check\")")
      ->take_all();
  cmd->callback([opt]() {
    const auto path = opt->scenario.empty() ? io::default_scenario_path() : io::resolve_scenario_path(opt->scenario);
    io::Scenario scenario = io::load_scenario(path, opt->machine);
    apply_sets(scenario.machine, opt->sets);
    structure::LobeStudy study = structure::study_lobes(scenario, opt->study);
    std::vector<structure::ChatterCheckPoint> points;
    for (const std::string& c : opt->checks) points.push_back(structure::ChatterCheckPoint::parse(c));
    for (const auto& p : points) study.checks.push_back(structure::check_chatter(scenario, study, p));
    io::ResultSet results(opt->out, "lobes");
    structure::write_lobe_study(results, study);
    results.commit();
    std::printf("%s; wrote %s\n", structure::lobe_summary(study).c_str(),
                results.final_path("lobes.png").c_str());
    for (const auto& c : study.checks) std::printf("%s\n", structure::chatter_check_summary(c).c_str());
  });
}

}  // namespace twin::cli
