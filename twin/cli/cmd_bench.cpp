#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "twin/report/benchmark.hpp"
#include "twin/cli/commands.hpp"
#include "twin/cli/common.hpp"

namespace twin::cli {

void register_bench(CLI::App& app) {
  struct Options {
    std::string scenario;
    std::string machine;
    std::vector<std::string> sets;
    int repeat{3};
  };
  auto opt = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand(
      "bench", "Measure the real-time factor of a scenario (default: the FADAL pocket corner), air cut and coupled");
  cmd->add_option("scenario", opt->scenario, "scenario.yaml, its folder, or a shipped scenario name");
  cmd->add_option("--machine", opt->machine, "machine definition replacing the scenario's");
  cmd->add_option("--set", opt->sets, "override a parameter: <axis>.<name>=<value>")->take_all();
  cmd->add_option("--repeat", opt->repeat, "runs per case; the fastest is reported")->check(CLI::Range(1, 100));
  cmd->callback([opt]() {
    const auto path = opt->scenario.empty() ? io::default_scenario_path() : io::resolve_scenario_path(opt->scenario);
    io::Scenario scenario = io::load_scenario(path, opt->machine);
    apply_sets(scenario.machine, opt->sets);
    std::printf("scenario %s, %s\n", scenario.name.c_str(),
                sim::process_summary(scenario).c_str());
    for (bool air : {true, false}) {
      if (!air && !scenario.process_setup) break;
      const auto r = analysis::benchmark_scenario(scenario, air, opt->repeat);
      std::printf("%-8s %8.3f s simulated (%lld ticks) in %8.4f s: real-time factor %7.1fx, %6.3f us per tick\n",
                  air ? "air cut" : "coupled", r.simulated_s, static_cast<long long>(r.ticks), r.wall_s,
                  r.real_time_factor, r.us_per_tick);
    }
  });
}

}  // namespace twin::cli
