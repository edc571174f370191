#pragma once
/// Real-time factor of a scenario: the co-simulation loop alone (no files),
/// as `twin bench` reports it.
#include <cstdint>

#include "twin/io/scenario_file.hpp"

namespace twin::analysis {

struct BenchmarkResult {
  double simulated_s{0.0};
  double wall_s{0.0};
  std::int64_t ticks{0};
  double real_time_factor{0.0};  ///< simulated time / wall time
  double us_per_tick{0.0};
};

/// Plans the program once, then runs the whole scenario `repeat` times and
/// keeps the fastest run. `air_cut` drops the process model.
BenchmarkResult benchmark_scenario(const io::Scenario& scenario, bool air_cut, int repeat);

}  // namespace twin::analysis
