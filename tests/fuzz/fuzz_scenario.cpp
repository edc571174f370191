// libFuzzer harness: the scenario reader (twin/io/scenario_file) with the
// shipped machines, tools and materials, and the program it names parsed
// against the machine's travel. A file program.nc next to the scenario
// holds a short valid program.
#include <cstdint>

#include "fuzz_util.hpp"
#include "twin/io/scenario_file.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const bool program_written = [] {
    const std::string prog = "G21 G90\nG1 X10 Y5 F1000\nM30\n";
    twin::fuzz::put("scenario/program.nc", reinterpret_cast<const std::uint8_t*>(prog.data()), prog.size());
    return true;
  }();
  static_cast<void>(program_written);
  const auto path = twin::fuzz::put("scenario/scenario.yaml", data, size);
  twin::fuzz::expect_contract([&] {
    const twin::io::Scenario s = twin::io::load_scenario(path);
    static_cast<void>(twin::io::parse_program(s));
  });
  return 0;
}
