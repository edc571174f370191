#pragma once
/// Each subcommand registers itself on the CLI11 app. Its callback does the
/// work and throws twin::Error (or a subclass) on failure; main() prints the
/// one-line message on stderr and exits non-zero.
namespace CLI {
class App;
}

namespace twin::cli {
void register_run(CLI::App& app);
void register_replay(CLI::App& app);
void register_bench(CLI::App& app);
void register_cut(CLI::App& app);
void register_export_fmu(CLI::App& app);
void register_sweep(CLI::App& app);
void register_tune(CLI::App& app);
void register_calibrate(CLI::App& app);
void register_lobes(CLI::App& app);
}  // namespace twin::cli
