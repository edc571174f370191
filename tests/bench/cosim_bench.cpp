// Real-time factor of the co-simulation loop: the default FADAL pocket
// corner as an air cut and coupled with the cutting process, and the cost
// per tick of an air-cut program repeated 1x and 10x (it must stay flat);
// the structured default (fadal2216_structure) coupled, in CPU time.
//   build/bin/cosim_bench --benchmark_min_time=2
#include <memory>
#include <string>

#include <benchmark/benchmark.h>

#include "twin/io/scenario_file.hpp"
#include "twin/sim/cosimulation.hpp"

namespace {

using namespace twin;

void run_ticks(benchmark::State& state, const sim::MachineDefinition& m,
               const std::shared_ptr<sim::ProgramReference>& ref, const io::Scenario* cutting,
               const AxisArray<double>& start) {
  const std::int64_t ticks = ref->num_ticks();
  for (auto _ : state) {
    sim::CoSimulation cs(m, ref, cutting ? process::make_process(*cutting->process_setup) : nullptr, start);
    double sink = 0.0;
    for (std::int64_t k = 0; k < ticks; ++k) sink += cs.step().contour_error_mm;
    benchmark::DoNotOptimize(sink);
  }
  const double sim_s = static_cast<double>(ticks) * m.Ts_s * static_cast<double>(state.iterations());
  state.SetItemsProcessed(ticks * state.iterations());
  state.counters["real_time_factor"] = benchmark::Counter(sim_s, benchmark::Counter::kIsRate);
  state.counters["us_per_tick"] =
      benchmark::Counter(static_cast<double>(ticks * state.iterations()) * 1e-6,
                         benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

void BM_DefaultScenario(benchmark::State& state) {
  const io::Scenario sc = io::load_scenario(io::default_scenario_path());
  const auto program = io::parse_program(sc);
  auto ref = std::make_shared<sim::ProgramReference>(
      controller::plan_trajectory(program, sc.machine.motion_limits(), sc.machine.Ts_s));
  run_ticks(state, sc.machine, ref, state.range(0) ? &sc : nullptr, sc.start_mm);
}
BENCHMARK(BM_DefaultScenario)->Arg(0)->Arg(1)->ArgName("coupled")->Unit(benchmark::kMillisecond)->UseRealTime();

// The structured default: the default scenario on fadal2216_structure (the
// slides' masses, gravity on Z, the tool's modes in the cut with the
// regenerative chip), coupled, against the rigid default in the same run.
// Thread CPU time: the honest single-core figure on a shared machine.
void BM_StructuredDefaultCpu(benchmark::State& state) {
  const io::Scenario sc =
      io::load_scenario(io::default_scenario_path(), state.range(0) ? "fadal2216_structure" : std::string());
  const auto program = io::parse_program(sc);
  auto ref = std::make_shared<sim::ProgramReference>(
      controller::plan_trajectory(program, sc.machine.motion_limits(), sc.machine.Ts_s));
  run_ticks(state, sc.machine, ref, &sc, sc.start_mm);
}
BENCHMARK(BM_StructuredDefaultCpu)->Arg(0)->Arg(1)->ArgName("structure")->Unit(benchmark::kMillisecond);

void BM_AirCutProgramLength(benchmark::State& state) {
  const io::Scenario sc = io::load_scenario(io::default_scenario_path());
  std::string text = "G21 G90 G64 P0.01\n";
  for (int r = 0; r < state.range(0); ++r) text += "G1 X40 Y0 F3000\nX40 Y30\nX0 Y30\nX0 Y0\n";
  text += "M30\n";
  const auto program = controller::parse_gcode(text, "square.nc", {0, 0, 0}, sc.machine.rapid_mm_per_min);
  auto ref = std::make_shared<sim::ProgramReference>(
      controller::plan_trajectory(program, sc.machine.motion_limits(), sc.machine.Ts_s));
  run_ticks(state, sc.machine, ref, nullptr, {0, 0, 0});
}
BENCHMARK(BM_AirCutProgramLength)->Arg(1)->Arg(10)->ArgName("repeats")->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
