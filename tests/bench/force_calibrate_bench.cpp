// Identification time of `twin calibrate` on one force run: 1 s at 10 kHz,
// 3 channels (fx, fy, fz), a slot with runout, made by the tests' independent
// generator. Target of issue 14: under 5 s.
#include <benchmark/benchmark.h>

#include <filesystem>

#include "../process/force_truth_generator.hpp"
#include "twin/force_calibrate/force_calibrate.hpp"

namespace {

std::filesystem::path one_second_run() {
  const auto dir = std::filesystem::temp_directory_path() / "twin_force_calibrate_bench";
  std::filesystem::remove_all(dir);
  twin::process::truth::TruthSeries s;
  s.fz_mm = {0.08};
  s.duration_s = 1.0;
  s.rho_mm = 0.008;
  s.lambda_deg = 40.0;
  twin::process::truth::write_truth_series(dir, s);
  return dir;
}

void BM_IdentifyOneSecondRun(benchmark::State& state) {
  const auto runs = twin::analysis::force::load_force_series(one_second_run());
  for (auto _ : state) {
    const auto r = twin::analysis::force::calibrate_forces(runs);
    benchmark::DoNotOptimize(r.after.k.a[0]);
  }
  state.counters["samples"] = static_cast<double>(runs.front().t_s.size());
}
BENCHMARK(BM_IdentifyOneSecondRun)->Unit(benchmark::kMillisecond)->Iterations(3);

void BM_ReadOneSecondRun(benchmark::State& state) {
  const auto dir = one_second_run();
  for (auto _ : state) benchmark::DoNotOptimize(twin::analysis::force::load_force_series(dir).size());
}
BENCHMARK(BM_ReadOneSecondRun)->Unit(benchmark::kMillisecond)->Iterations(3);

}  // namespace
