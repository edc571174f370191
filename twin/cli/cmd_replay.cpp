#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "twin/calibrate/machine_from_data.hpp"
#include "twin/report/replay.hpp"
#include "twin/cli/commands.hpp"
#include "twin/cli/common.hpp"
#include "twin/io/atomic_file.hpp"

namespace twin::cli {

void register_replay(CLI::App& app) {
  struct Options {
    std::string run;
    std::string out;
    std::string machine;
    std::vector<std::string> sets;
  };
  auto opt = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand(
      "replay", "Replay a measured run folder (trace.csv + meta.json) from its <a>_ref_mm columns; writes OUT/trace.csv");
  cmd->add_option("run", opt->run, "measured run folder")->required();
  cmd->add_option("-o,--out", opt->out, "output folder (created if missing)")->required();
  cmd->add_option("--machine", opt->machine, "machine definition (name or YAML file) replacing the run's meta.machine");
  cmd->add_option("--set", opt->sets, "override a parameter: <axis>.<name>=<value>, e.g. x.J=0.008")->take_all();
  cmd->callback([opt]() {
    refuse_output_over_input("replay", opt->out, opt->run, opt->machine);
    const analysis::MeasuredRun run = analysis::load_run(opt->run);
    std::vector<std::string> notes = run.notes;
    sim::MachineDefinition machine = analysis::machine_for_run(run, opt->machine, &notes);
    apply_sets(machine, opt->sets);
    if (sim::machine_loop_law(machine) == controller::LoopLaw::kCascade || !analysis::names_shipped_machine(run)) {
      // A machine identified from data (twin calibrate's machine.yaml), or a
      // log from a machine the twin does not ship (a user's data, whichever
      // machine stands in): replayed as calibrate validates it, segment by
      // segment with the log's rounding, never across a stitch, and its
      // errors written beside the trace.
      analysis::ReplayResult rr;
      const analysis::RunErrors e = analysis::evaluate_machine_on_run(run, machine, &rr, &notes);
      notes.insert(notes.end(), rr.notes.begin(), rr.notes.end());
      io::ResultSet results(opt->out, "replay");
      analysis::write_data_trace(results.path("trace.csv"), run, rr);
      nlohmann::json j;
      j["run"] = e.run;
      j["rows_compared"] = e.rows_compared;
      j["error"] = e.calibrated.to_json();
      j["baseline"] = {{"zero", e.zero.to_json()}};
      io::write_file_atomic(results.path("errors.json"), j.dump(2) + "\n");
      results.commit();
      const auto path = results.final_path("trace.csv");
      for (const auto& n : notes) std::fprintf(stderr, "twin replay: note: %s\n", n.c_str());
      std::string figs;
      for (const auto& [k, v] : e.calibrated.nrms) figs += fmt::format("{}{} {:.4g}", figs.empty() ? "" : ", ", k, v);
      std::printf("replayed %zu samples of %s on machine %s (NRMS: %s); wrote %s\n", rr.t_s.size(), opt->run.c_str(),
                  machine.name.c_str(), figs.c_str(), path.c_str());
      return;
    }
    analysis::ReplayResult r = analysis::replay_run(run, machine);
    io::ResultSet results(opt->out, "replay");
    analysis::write_replay_trace(results.path("trace.csv"), r);
    results.commit();
    const auto path = results.final_path("trace.csv");
    notes.insert(notes.end(), r.notes.begin(), r.notes.end());
    for (const auto& n : notes) std::fprintf(stderr, "twin replay: note: %s\n", n.c_str());
    std::printf("replayed %zu samples of %s on machine %s; wrote %s\n", r.t_s.size(), opt->run.c_str(),
                machine.name.c_str(), path.c_str());
  });
}

}  // namespace twin::cli
