// The twin against a hand-fused loop of the same equations, side by side in
// one run, on the default scenario (the FADAL pocket corner, as `twin bench`).
//
// The fused loop is the per-tick work of the co-simulation written as one
// flat loop, without the twin's machinery (no SUNDIALS, no DriveBank, no
// PositionLoop objects, no health checks, no snapshot rows):
//   - the same reference samples (ProgramReference::sample),
//   - 1 um encoder quantisation and the FADAL PID (Kp, Ki, Kd, K1, K2, clamp)
//     of each axis, written out by hand,
//   - 3 rigid drives J dw/dt = Ka Kt u - B w - Tc_dir - Td, dx/dt = rg w with
//     Karnopp stick at rest (|net| <= Tc sticks) and a stop when w changes
//     sign inside a substep (w set to 0 at the substep's end: no root finding),
//     integrated by classical RK4 with `substeps` fixed substeps per tick,
//   - coupled: the same process model (process::make_process of the scenario's setup, the same
//     ProcessModel::step call per tick) loading the drives with Td = F rg.
// Each benchmark iteration times the twin's tick loop and then the fused
// loop's (construction excluded from both, as `twin bench` does; thread CPU
// time, so a busy neighbour's share of the core is not counted), so both see
// the same machine state; the counters give each one's time per tick and the
// ratio twin / fused (the bound: <= 5), and fused_dev_um the largest
// difference of the fused loop's axis positions from the twin's (a check that
// the two loops do the same job: microns, from the stop treatment).
// closed_form:0 runs the twin with IntegratorOptions::exact_linear_ticks off,
// SUNDIALS on every tick, which is the drives' arrangement before the closed
// form (the before/after figures of docs/performance.md in one run).
//   build/bin/fused_loop_bench --benchmark_min_time=2
#include <algorithm>
#include <array>
#include <ctime>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "twin/io/scenario_file.hpp"
#include "twin/sim/scenario.hpp"
#include "twin/sim/cosimulation.hpp"

namespace {

using namespace twin;

struct Setup {
  io::Scenario sc;
  std::shared_ptr<sim::ProgramReference> ref;
  std::int64_t ticks{0};
};

const Setup& setup() {
  static const Setup s = [] {
    Setup x;
    x.sc = io::load_scenario(io::default_scenario_path());
    const auto program = io::parse_program(x.sc);
    x.ref = std::make_shared<sim::ProgramReference>(
        controller::plan_trajectory(program, x.sc.machine.motion_limits(), x.sc.machine.Ts_s));
    x.ticks = x.ref->num_ticks() + static_cast<std::int64_t>(std::ceil(x.sc.settle_s / x.sc.machine.Ts_s));
    return x;
  }();
  return s;
}

// Everything the fused loop carries per axis.
struct FusedAxis {
  // constants
  double Ka_Kt{0.0}, B{0.0}, J{0.0}, rg{0.0}, Tc_pos{0.0}, Tc_neg{0.0};
  double Kp{0.0}, Ki{0.0}, Kd{0.0}, K1{0.0}, K2{0.0}, u_max{0.0};
  // state
  double x_mm{0.0}, w{0.0};
  double I{0.0}, e_prev{0.0}, r_prev{0.0}, v_ref_prev{0.0};
  bool primed{false};
};

struct FusedLoop {
  std::array<FusedAxis, 3> ax{};
  std::size_t n{0};
  std::array<std::size_t, 3> index{};  // machine axis index of each present axis
  double Ts{1e-4}, res{1e-3};
  int substeps{1};

  FusedLoop(const sim::MachineDefinition& m, const AxisArray<double>& start, int sub) : substeps(sub) {
    Ts = m.Ts_s;
    res = m.encoder_resolution_mm;
    for (Axis a : m.present_axes()) {
      const std::size_t i = twin::index(a);
      const auto& d = m.axes[i].drive;
      const auto& l = m.axes[i].loop;
      FusedAxis f;
      f.Ka_Kt = d.Ka_A_per_V * d.Kt_Nm_per_A;
      f.B = d.B_kg_m2_per_s;
      f.J = d.J_kg_m2;
      f.rg = d.rg_mm_per_rad;
      f.Tc_pos = d.Tc_pos_Nm;
      f.Tc_neg = d.Tc_neg_Nm;
      f.Kp = l.Kp_V_per_mm;
      f.Ki = l.Ki_V_per_s_mm;
      f.Kd = l.Kd_V_s_per_mm;
      f.K1 = l.K1_V_s2_per_mm;
      f.K2 = l.K2_V_s_per_mm;
      f.u_max = l.u_max_V;
      f.x_mm = start[i];
      index[n] = i;
      ax[n++] = f;
    }
  }

  // One tick; returns the sum of the positions (kept by the caller).
  double tick(std::int64_t k, const sim::ProgramReference& ref, process::ProcessModel* proc) {
    const controller::ReferenceSample r = ref.sample(k);
    std::array<double, 3> F_N{};
    if (proc != nullptr) {
      process::ProcessInput pin;
      pin.k = k;
      pin.t_s = static_cast<double>(k) * Ts;
      pin.Ts_s = Ts;
      for (std::size_t j = 0; j < n; ++j) {
        pin.p_mm[index[j]] = ax[j].x_mm;
        pin.v_mm_per_s[index[j]] = ax[j].rg * ax[j].w;
      }
      pin.spindle_rpm = r.spindle_rpm;
      F_N = proc->step(pin).F_avg_N;
    }
    double sum = 0.0;
    for (std::size_t j = 0; j < n; ++j) {
      FusedAxis& a = ax[j];
      // Encoder and FADAL PID.
      const double xr = r.x_mm[index[j]];
      const double xm = std::nearbyint(a.x_mm / res) * res;
      const double e = xr - xm;
      if (!a.primed) {
        a.r_prev = xr;
        a.e_prev = e;
        a.primed = true;
      }
      const double v_ref = (xr - a.r_prev) / Ts;
      const double a_ref = (v_ref - a.v_ref_prev) / Ts;
      a.I += Ts * e;
      const double u = std::clamp(a.Kp * e + a.Ki * a.I + a.Kd * (e - a.e_prev) / Ts + a.K1 * a_ref + a.K2 * v_ref,
                                  -a.u_max, a.u_max);
      a.e_prev = e;
      a.r_prev = xr;
      a.v_ref_prev = v_ref;
      // Drive over the tick, u and Td held.
      const double Td = F_N[index[j]] * a.rg * 1e-3;
      const double net = a.Ka_Kt * u - Td;
      int dir = a.w > 0.0 ? 1 : (a.w < 0.0 ? -1 : 0);
      if (dir == 0) dir = net > a.Tc_pos ? 1 : (net < -a.Tc_neg ? -1 : 0);
      if (dir != 0) {
        const double F = net - (dir > 0 ? a.Tc_pos : -a.Tc_neg);
        const double h = Ts / substeps;
        const auto dw = [&](double w) { return (F - a.B * w) / a.J; };
        for (int s = 0; s < substeps; ++s) {
          const double k1w = dw(a.w), k1x = a.rg * a.w;
          const double w2 = a.w + 0.5 * h * k1w;
          const double k2w = dw(w2), k2x = a.rg * w2;
          const double w3 = a.w + 0.5 * h * k2w;
          const double k3w = dw(w3), k3x = a.rg * w3;
          const double w4 = a.w + h * k3w;
          const double k4w = dw(w4), k4x = a.rg * w4;
          a.x_mm += h / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x);
          a.w += h / 6.0 * (k1w + 2.0 * k2w + 2.0 * k3w + k4w);
          if (dir * a.w <= 0.0) {  // stopped inside the substep: stick there
            a.w = 0.0;
            break;
          }
        }
      }
      sum += a.x_mm;
    }
    return sum;
  }
};

// Largest difference of the fused loop's axis positions from the twin's over
// the whole run (untimed).
double fused_deviation_mm(bool coupled, int substeps) {
  const Setup& s = setup();
  sim::CoSimulation cs = sim::build_cosimulation(s.sc, {.reference = s.ref, .air_cut = !coupled});
  FusedLoop f(s.sc.machine, s.sc.start_mm, substeps);
  auto proc = coupled ? process::make_process(*s.sc.process_setup) : nullptr;
  double worst = 0.0;
  for (std::int64_t k = 0; k < s.ticks; ++k) {
    const sim::Snapshot& row = cs.step();
    f.tick(k, *s.ref, proc.get());
    (void)row;
    for (std::size_t j = 0; j < f.n; ++j) {
      // The twin's row k holds x at t_k; compare after its drives advanced: drive_state.
      const double x_twin = cs.drive_state(static_cast<Axis>(f.index[j])).x_mm;
      worst = std::max(worst, std::abs(x_twin - f.ax[j].x_mm));
    }
  }
  return worst;
}

// CPU time of this thread: on a machine shared with other jobs, wall time
// counts the time the loop waits for a core; CPU time does not.
double thread_cpu_s() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

void BM_TwinVsFusedLoop(benchmark::State& state) {
  const bool coupled = state.range(0) != 0;
  const int substeps = static_cast<int>(state.range(1));
  feeddrive::IntegratorOptions options;
  options.exact_linear_ticks = state.range(2) != 0;
  const Setup& s = setup();
  double twin_s = 0.0, fused_s = 0.0;
  for (auto _ : state) {
    sim::CoSimulation cs =
        sim::build_cosimulation(s.sc, {.reference = s.ref, .air_cut = !coupled, .integrator = options});
    double sink = 0.0;
    const double t0 = thread_cpu_s();
    for (std::int64_t k = 0; k < s.ticks; ++k) sink += cs.step().contour_error_mm;
    const double t1 = thread_cpu_s();
    FusedLoop f(s.sc.machine, s.sc.start_mm, substeps);
    auto proc = coupled ? process::make_process(*s.sc.process_setup) : nullptr;
    const double t2 = thread_cpu_s();
    for (std::int64_t k = 0; k < s.ticks; ++k) sink += f.tick(k, *s.ref, proc.get());
    const double t3 = thread_cpu_s();
    benchmark::DoNotOptimize(sink);
    const double tw = t1 - t0;
    twin_s += tw;
    fused_s += t3 - t2;
    state.SetIterationTime(tw);
  }
  const double n = static_cast<double>(s.ticks) * static_cast<double>(state.iterations());
  state.counters["twin_us_per_tick"] = twin_s / n * 1e6;
  state.counters["fused_us_per_tick"] = fused_s / n * 1e6;
  state.counters["ratio_twin_to_fused"] = twin_s / fused_s;
  state.counters["twin_real_time_x"] = n * s.sc.machine.Ts_s / twin_s;
  state.counters["fused_real_time_x"] = n * s.sc.machine.Ts_s / fused_s;
  state.counters["fused_dev_um"] = 1e3 * fused_deviation_mm(coupled, substeps);
  state.SetLabel(std::string(coupled ? "coupled" : "air cut") +
                 (options.exact_linear_ticks ? "" : ", twin with SUNDIALS on every tick (before)"));
}
BENCHMARK(BM_TwinVsFusedLoop)
    ->ArgsProduct({{0, 1}, {1, 4}, {1, 0}})
    ->ArgNames({"coupled", "rk4_substeps", "closed_form"})
    ->UseManualTime()
    ->Unit(benchmark::kMillisecond);

}  // namespace
