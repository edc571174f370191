#include "twin/report/benchmark.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>

#include "twin/sim/cosimulation.hpp"
#include "twin/sim/reference.hpp"

namespace twin::analysis {

BenchmarkResult benchmark_scenario(const io::Scenario& scenario, bool air_cut, int repeat) {
  const controller::Program program = io::parse_program(scenario);
  auto reference = std::make_shared<sim::ProgramReference>(
      controller::plan_trajectory(program, scenario.machine.motion_limits(), scenario.machine.Ts_s));
  const std::int64_t ticks =
      reference->num_ticks() + static_cast<std::int64_t>(std::ceil(scenario.settle_s / scenario.machine.Ts_s));
  BenchmarkResult best;
  best.ticks = ticks;
  best.simulated_s = static_cast<double>(ticks) * scenario.machine.Ts_s;
  best.wall_s = 1e300;
  for (int r = 0; r < std::max(1, repeat); ++r) {
    sim::CoSimulation cs(scenario.machine, reference,
                         (air_cut || !scenario.make_process) ? nullptr : scenario.make_process(), scenario.start_mm);
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
