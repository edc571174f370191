// calibrate_probe: replays a run on the model calibrate identified (no effect
// added) with parameter overrides, and prints the errors on the fitting and
// the held-out part. A tool for studying a run, not a test.
//
//   calibrate_probe RUN_DIR [axis.param=value ...] [-- axis.param=value ...]
//
// Each group of overrides (separated by "--") is one replay.
#include <cstdio>
#include <string>
#include <vector>

#include "twin/calibrate/calibrate.hpp"
#include "twin/core/error.hpp"

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: calibrate_probe RUN_DIR [axis.param=value ...] [-- ...]\n");
    return 2;
  }
  try {
    const auto run = twin::analysis::load_run(argv[1]);
    std::vector<std::string> notes;
    const auto start = twin::analysis::machine_for_run(run, "", &notes);
    twin::analysis::CalibrateOptions none;
    none.max_effects_per_axis = 0;
    const auto base = twin::analysis::calibrate(run, start, none);
    std::vector<std::vector<std::string>> groups{{}};
    for (int i = 2; i < argc; ++i) {
      if (std::string(argv[i]) == "--")
        groups.emplace_back();
      else
        groups.back().push_back(argv[i]);
    }
    for (const auto& g : groups) {
      auto m = base.identified;
      std::string label;
      for (const auto& s : g) {
        const auto dot = s.find('.'), eq = s.find('=');
        if (dot == std::string::npos || eq == std::string::npos) throw twin::ConfigError("override " + s);
        const auto axis = twin::parse_axis(s.substr(0, dot));
        if (!axis) throw twin::ConfigError("no axis in " + s);
        const auto* spec = twin::sim::find_axis_param(s.substr(dot + 1, eq - dot - 1));
        if (!spec) throw twin::ConfigError("no parameter " + s);
        twin::sim::set_axis_param(m.axes[twin::index(*axis)], *spec, std::stod(s.substr(eq + 1)));
        label += s + " ";
      }
      m.validate();
      const auto rep = twin::analysis::replay_run(run, m);
      for (auto a : run.axes) {
        const auto f = twin::analysis::axis_errors(run, rep, a, 0, base.n_fit);
        const auto h = twin::analysis::axis_errors(run, rep, a, base.n_fit);
        std::printf("%-50s %s fit err %.5f u %.5f hunt %.4f | held err %.5f u %.5f hunt %.4f\n",
                    label.empty() ? "(identified)" : label.c_str(), std::string(twin::axis_name(a)).c_str(), f.err_mm,
                    f.u, f.hunt, h.err_mm, h.u, h.hunt);
      }
    }
  } catch (const twin::Error& e) {
    std::fprintf(stderr, "calibrate_probe: %s\n", e.what());
    return 1;
  }
  return 0;
}
