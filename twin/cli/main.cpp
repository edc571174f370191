// twin: the command-line program of the machine-tool twin.
#include <cstdio>
#include <exception>
#include <string>

#include <CLI/CLI.hpp>

#include "twin/cli/commands.hpp"
#include "twin/core/error.hpp"
#include "twin/io/atomic_file.hpp"

int main(int argc, char** argv) {
  CLI::App app{"twin: a digital twin of a 3-axis milling machine (feed drives, CNC, cutting process)", "twin"};
  // Temporary files and partial result sets are removed when the program is ended by a signal.
  twin::io::install_signal_cleanup();
  app.require_subcommand(1);
  twin::cli::register_run(app);
  twin::cli::register_replay(app);
  twin::cli::register_bench(app);
  twin::cli::register_cut(app);
  twin::cli::register_tune(app);
  twin::cli::register_calibrate(app);
  twin::cli::register_export_fmu(app);
  twin::cli::register_sweep(app);
  twin::cli::register_lobes(app);
  if (argc > 1 && argv[1][0] != '-') {
    bool known = false;
    std::string names;
    for (const CLI::App* sub : app.get_subcommands({})) {
      known = known || sub->get_name() == argv[1];
      names += (names.empty() ? "" : ", ") + sub->get_name();
    }
    if (!known) {
      std::fprintf(stderr, "twin: unknown command '%s' (commands: %s)\n", argv[1], names.c_str());
      return 2;
    }
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    // One line: what is wrong with the command line.
    std::fprintf(stderr, "twin: %s (see --help)\n", e.what());
    return 2;
  } catch (const twin::Error& e) {
    std::fprintf(stderr, "twin: %s\n", e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "twin: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
