// Engagement plus force per control tick (MillingProcess::step), and its
// independence of how much material has been removed before.
//   build/bin/process_bench --benchmark_min_time=0.5
#include <benchmark/benchmark.h>

#include "process/milling_process.hpp"

namespace {

using twin::process::MillingProcess;
using twin::process::ProcessInput;
using twin::process::ProcessSetup;
using twin::process::StockSpec;
using twin::process::ToolShape;

// Duan 2025 tool and Al 2024-T6 set 4 coefficients, wall cut ae 2 mm, ap 1 mm.
ProcessSetup duan_setup() {
  ProcessSetup s;
  s.tool = {.name = "duan",
            .shape = ToolShape::kBullNose,
            .diameter_mm = 10,
            .flutes = 2,
            .helix_deg = 30,
            .corner_radius_mm = 1.5,
            .flute_length_mm = 22};
  s.coefficients.Kt = {816.935, 1913.93, 41.7956};
  s.coefficients.Kr = {166.518, 686.391, 25.2867};
  s.coefficients.Ka = {868.228, -884.065, 0.17887};
  s.stock.outline_mm = StockSpec::rectangle(0, -60, 200, 2);
  s.stock.top_z_mm = 0;
  s.stock.bottom_z_mm = -10;
  s.stock.cell_mm = 0.025;
  return s;
}

ProcessSetup hsm_setup() {
  ProcessSetup s = duan_setup();
  s.tool = {.name = "duan", .shape = ToolShape::kFlat, .diameter_mm = 12, .flutes = 3, .helix_deg = 40,
            .corner_radius_mm = 0, .flute_length_mm = 26};
  s.coefficients = twin::process::CuttingCoefficients::linear(796.1, 168.8, 222.0, 27.7, 30.8, 1.8);
  s.stock.cell_mm = 0.03;
  s.options.dz_mm = 0.2;
  return s;
}

// range(0): number of earlier 200 mm passes already removed below this one
// (the removed region grows; the cost per tick must not).
void run(benchmark::State& state, const ProcessSetup& setup, double rpm, double v_mm_per_s, double ap_mm,
         double R_mm, double ae_mm) {
  MillingProcess proc(setup);
  const double y = 2.0 - R_mm - (2.0 - ae_mm);   // edge at y = 2 - ae ... tool centre cuts ae into y < 2
  for (int pass = 1; pass <= state.range(0); ++pass) {
    const double yp = y - 2.0 * pass;
    proc.remove_swept({-10, yp, -ap_mm}, {210, yp, -ap_mm});
  }
  proc.remove_swept({-10, y, -ap_mm}, {0, y, -ap_mm});
  ProcessInput in;
  in.Ts_s = 1e-4;
  in.spindle_rpm = rpm;
  in.v_mm_per_s = {v_mm_per_s, 0, 0};
  std::int64_t k = 0;
  for (auto _ : state) {
    in.k = k;
    in.t_s = k * in.Ts_s;
    in.p_mm = {v_mm_per_s * in.t_s, y, -ap_mm};
    benchmark::DoNotOptimize(proc.step(in));
    ++k;
    if (in.p_mm[0] > 190.0) k = 0;
  }
  state.SetItemsProcessed(state.iterations());
}

void BM_StepDuanWallCut(benchmark::State& state) { run(state, duan_setup(), 1200, 500.0 / 60.0, 1.0, 5.0, 2.0); }
void BM_StepHsmSideCut(benchmark::State& state) { run(state, hsm_setup(), 12000, 3600.0 / 60.0, 6.0, 6.0, 3.0); }

BENCHMARK(BM_StepDuanWallCut)->Arg(0)->Arg(25);
BENCHMARK(BM_StepHsmSideCut)->Arg(0)->Arg(25);

}  // namespace
