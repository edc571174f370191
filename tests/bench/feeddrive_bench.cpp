// Cost per simulated second of the FADAL X and Y drives (plus a Z copy of Y
// for the 3-axis figure) under the hand-written FADAL PID, for each
// integrator arrangement, and their accuracy against the exact ZOH solution
// (matrix exponential, friction off). Time is per simulated second of all
// three axes (divide by 1e4 for a tick). Counters: steps_per_tick and
// rhs_per_tick (summed over instances), max_err_mm (friction-off run of the
// same loop without quantisation against the exact discrete loop, 1 s).
#include <benchmark/benchmark.h>

#include <cmath>
#include <vector>

#include "../feeddrive/exact_loop.hpp"
#include "../feeddrive/fadal_fixture.hpp"
#include "feeddrive/drive_bank.hpp"

namespace twin::feeddrive {
namespace {

constexpr double kTs_s = 1e-4;
constexpr double kCount_mm = 1e-3;

IntegratorOptions variant(int id) {
  IntegratorOptions o;
  o.one_instance_for_all_axes = id == 1 || id == 6 || id == 7 || id == 8;
  o.atol_rad_per_s = 1e-7;
  if (id == 8) o = IntegratorOptions{};
  // Variants 0-8 measure SUNDIALS arrangements on every tick; 9 is the
  // default with the closed-form ordinary ticks (8 is the same without them).
  o.exact_linear_ticks = false;
  if (id == 9) o = IntegratorOptions{};
  switch (id) {
    case 0:  // CVODE Adams, reinit per tick, one instance per axis
      o.method = IntegratorOptions::Method::kCvodeAdams;
      break;
    case 1:  // CVODE Adams, reinit per tick, one instance for all axes
      o.method = IntegratorOptions::Method::kCvodeAdams;
      o.one_instance_for_all_axes = true;
      break;
    case 2:  // CVODE Adams without reinit (history across ZOH jumps)
      o.method = IntegratorOptions::Method::kCvodeAdams;
      o.reinit_every_tick = false;
      break;
    case 3:  // CVODE BDF, reinit per tick
      o.method = IntegratorOptions::Method::kCvodeBdf;
      break;
    case 4:  // ARKODE ERK, adaptive
      o.method = IntegratorOptions::Method::kArkodeErk;
      o.erk_fixed_steps_per_tick = 0;
      break;
    case 5:  // ARKODE ERK, fixed step Ts, one instance per axis
      o.method = IntegratorOptions::Method::kArkodeErk;
      o.erk_fixed_steps_per_tick = 1;
      break;
    case 6:  // ARKODE ERK, fixed step Ts, one instance for all axes
      o.method = IntegratorOptions::Method::kArkodeErk;
      o.erk_fixed_steps_per_tick = 1;
      o.one_instance_for_all_axes = true;
      break;
    case 7:  // ARKODE ERK, fixed step Ts, shared, no reset per tick (one-step: nothing to forget)
      o.method = IntegratorOptions::Method::kArkodeErk;
      o.erk_fixed_steps_per_tick = 1;
      o.one_instance_for_all_axes = true;
      o.reinit_every_tick = false;
      break;
    default:  // the default options
      break;
  }
  return o;
}

const char* variant_name(int id) {
  static const char* names[] = {"cvode_adams_reinit_per_axis", "cvode_adams_reinit_shared",
                                "cvode_adams_no_reinit",       "cvode_bdf_reinit",
                                "arkode_erk_adaptive",         "arkode_erk_fixed_Ts_per_axis",
                                "arkode_erk_fixed_Ts_shared",  "arkode_erk_fixed_Ts_shared_no_reset",
                                "default_sundials_every_tick", "default"};
  return names[id];
}

std::vector<DriveParams> axes3(bool friction) {
  std::vector<DriveParams> p{testing::fadal_x(), testing::fadal_y(), testing::fadal_y()};
  if (!friction)
    for (auto& a : p) a.Tc_pos_Nm = a.Tc_neg_Nm = 0.0;
  return p;
}

// Reference: 50 mm/s ramps with 2000 mm/s^2 accelerations, a reversal every
// 0.5 s, and a 0.2 s dwell (stuck axes) per cycle; X, Y and Z phase-shifted.
double reference_mm(int axis, long k) {
  const double t = std::fmod(k * kTs_s + 0.1 * axis, 1.2);
  const double v = 50.0, a = 2000.0, ta = v / a;
  auto leg = [&](double s) {  // 0.5 s trapezoid of 0..~24 mm
    if (s < ta) return 0.5 * a * s * s;
    if (s < 0.5 - ta) return 0.5 * a * ta * ta + v * (s - ta);
    const double r = 0.5 - s;
    return v * (0.5 - ta) - 0.5 * a * r * r;
  };
  const double L = v * (0.5 - ta);
  if (t < 0.5) return 100.0 + leg(t);
  if (t < 0.6) return 100.0 + L;
  if (t < 1.1) return 100.0 + L - leg(t - 0.6);
  return 100.0;
}

void BM_Drives3Axes(benchmark::State& st) {
  const int id = static_cast<int>(st.range(0));
  const auto params = axes3(true);
  const long ticks = 10000;  // one simulated second
  long steps = 0, rhs = 0, closed = 0, integrated = 0;
  for (auto _ : st) {
    st.PauseTiming();
    DriveBank bank(params, kTs_s, variant(id));
    bank.reset({100.0, 100.0, 100.0});
    std::vector<testing::HandPid> pid{testing::HandPid(testing::fadal_x_gains(), kTs_s),
                                      testing::HandPid(testing::fadal_y_gains(), kTs_s),
                                      testing::HandPid(testing::fadal_y_gains(), kTs_s)};
    std::vector<DriveInput> in(3);
    st.ResumeTiming();
    for (long k = 0; k < ticks; ++k) {
      for (int a = 0; a < 3; ++a)
        in[a].u_V = pid[a].step(reference_mm(a, k), testing::quantize_mm(bank.output(a).x_meas_mm, kCount_mm));
      bank.advance(k * kTs_s, (k + 1) * kTs_s, in);
    }
    benchmark::DoNotOptimize(bank.state(0).x_mm);
    steps = bank.num_steps();
    rhs = bank.num_rhs_evals();
    closed = bank.num_closed_form_ticks();
    integrated = bank.num_sundials_ticks();
  }
  st.SetLabel(variant_name(id));
  // Wall time per tick for all three axes = Time / 10000 (one simulated second per iteration).
  st.counters["steps_per_tick"] = static_cast<double>(steps) / ticks;
  st.counters["rhs_per_tick"] = static_cast<double>(rhs) / ticks;
  // Share of the moving axis-ticks advanced in closed form.
  st.counters["closed_form_share"] = closed + integrated > 0 ? static_cast<double>(closed) / (closed + integrated) : 0.0;

  // Accuracy: friction off, same loop without quantisation, against the exact ZOH solution.
  const auto lin = axes3(false);
  DriveBank bank(lin, kTs_s, variant(id));
  bank.reset({100.0, 100.0, 100.0});
  const double worst = testing::max_deviation_from_exact(
      bank, lin, {testing::fadal_x_gains(), testing::fadal_y_gains(), testing::fadal_y_gains()}, reference_mm, ticks,
      100.0);
  st.counters["max_err_mm"] = worst;
}
BENCHMARK(BM_Drives3Axes)->DenseRange(0, 9)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace twin::feeddrive
