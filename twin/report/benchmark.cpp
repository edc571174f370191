#include "twin/report/benchmark.hpp"

#include <algorithm>
#include <chrono>
#include <memory>

#include "twin/sim/scenario.hpp"

namespace twin::analysis {

BenchmarkResult benchmark_scenario(const io::Scenario& scenario, bool air_cut, int repeat) {
  // Planned once: every repeat follows the same reference.
  const sim::PlannedProgram planned = sim::plan_program(scenario, scenario.machine);
  const std::int64_t ticks = sim::run_ticks(scenario, planned.trajectory());
  BenchmarkResult best;
  best.ticks = ticks;
  best.simulated_s = static_cast<double>(ticks) * scenario.machine.Ts_s;
  best.wall_s = 1e300;
  for (int r = 0; r < std::max(1, repeat); ++r) {
    sim::CoSimulation cs = sim::build_cosimulation(scenario, {.reference = planned.reference, .air_cut = air_cut});
    const auto t0 = std::chrono::steady_clock::now();
    double sink = 0.0;
    for (std::int64_t k = 0; k < ticks; ++k) sink += cs.step().contour_error_mm;
    const auto t1 = std::chrono::steady_clock::now();
    const double wall = std::chrono::duration<double>(t1 - t0).count() + (sink < 0.0 ? 1.0 : 0.0);
    best.wall_s = std::min(best.wall_s, wall);
  }
  best.real_time_factor = best.simulated_s / best.wall_s;
  best.us_per_tick = best.wall_s / static_cast<double>(ticks) * 1e6;
  return best;
}

}  // namespace twin::analysis
