// What the structure costs: evaluating the Simbody model once (what loading a
// machine file with `structure:` does) against stepping it in every 100 us
// co-simulation tick (what the twin does not do). Figures in docs/stability.md.
#include <benchmark/benchmark.h>

#include <cmath>

#include "twin/structure/machine_structure.hpp"

namespace {

// The slides of scenarios/machines/fadal2216_structure.yaml.
twin::structure::StructureSpec fadal_like() {
  return {.table_kg = 160.0, .saddle_kg = 220.0, .head_kg = 300.0, .workpiece_kg = 20.0, .screw_efficiency = 0.9};
}

// The model built and evaluated (mass matrix, gravity) once.
void BM_StructureLoadsAtLoad(benchmark::State& state) {
  const auto sp = fadal_like();
  for (auto _ : state) benchmark::DoNotOptimize(twin::structure::axis_loads(sp, {1.5915, 1.5915, 1.5915}));
}
BENCHMARK(BM_StructureLoadsAtLoad)->Unit(benchmark::kMicrosecond);

// One 100 us tick of the three-slide model with the screw forces changed every
// tick (as a drive's would be), Runge-Kutta-Merson at accuracy 1e-6.
void BM_SimbodyStepPerTick(benchmark::State& state) {
  twin::structure::StructureStepper stepper(fadal_like(), {100.0, 100.0, -100.0}, 1e-6);
  long k = 0;
  for (auto _ : state) {
    const double s = std::sin(1e-4 * 2.0 * 3.141592653589793 * 50.0 * static_cast<double>(k++));
    benchmark::DoNotOptimize(stepper.advance({200.0 * s, -150.0 * s, 2943.0 + 100.0 * s}, 1e-4));
  }
}
BENCHMARK(BM_SimbodyStepPerTick)->Unit(benchmark::kMicrosecond);

}  // namespace
