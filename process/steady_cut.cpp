#include "process/steady_cut.hpp"

#include <cmath>
#include <complex>
#include <vector>

#include <fmt/format.h>

#include "process/milling_process.hpp"
#include "twin/core/error.hpp"
#include "twin/core/units.hpp"

namespace twin::process {

void SteadyCutSpec::validate() const {
  tool.validate("cut");
  coefficients.validate("cut: material " + coefficients.name);
  const double D = tool.diameter_mm;
  if (!(spindle_rpm > 0.0 && spindle_rpm <= 100000.0))
    throw ConfigError(fmt::format("cut: --rpm = {} must be in (0, 100000]", spindle_rpm));
  if (!(feed_per_tooth_mm > 0.0 && feed_per_tooth_mm <= 1.0))
    throw ConfigError(fmt::format("cut: --fz = {} mm must be in (0, 1]", feed_per_tooth_mm));
  if (!(ae_mm > 0.0 && ae_mm <= D)) throw ConfigError(fmt::format("cut: --ae = {} mm must be in (0, {}]", ae_mm, D));
  if (!(ap_mm > 0.0 && ap_mm <= tool.flute_length_mm))
    throw ConfigError(fmt::format("cut: --ap = {} mm must be in (0, {}] (flute length)", ap_mm, tool.flute_length_mm));
  if (!(angle_step_deg >= 0.1 && angle_step_deg <= 10.0))
    throw ConfigError(fmt::format("cut: angle step {} deg must be in [0.1, 10]", angle_step_deg));
  if (!(coefficient_scale > 0.0 && coefficient_scale <= 10.0))
    throw ConfigError(fmt::format("cut: --wear-scale = {} must be in (0, 10]", coefficient_scale));
  if (!(sensor_f_hz >= 0.0 && std::isfinite(sensor_f_hz)))
    throw ConfigError(fmt::format("cut: --sensor-f = {} Hz must be >= 0", sensor_f_hz));
  if (sensor_f_hz > 0.0 && !(sensor_zeta > 0.0 && sensor_zeta <= 1.0))
    throw ConfigError(fmt::format("cut: --sensor-zeta = {} must be in (0, 1] with a sensor mode", sensor_zeta));
}

namespace {

CuttingCoefficients scaled(CuttingCoefficients k, double f) {
  for (ExpCoefficient* e : {&k.Kt, &k.Kr, &k.Ka}) {
    e->a_N_per_mm2 *= f;
    e->b_N_per_mm2 *= f;
  }
  k.Kte_N_per_mm *= f;
  k.Kre_N_per_mm *= f;
  k.Kae_N_per_mm *= f;
  return k;
}

// The steady response of the sensor mode to one revolution sampled uniformly:
// harmonic k of the revolution (frequency k n_rev) times H(k n_rev).
void apply_sensor_mode(std::vector<SteadyCutRow>& rows, double n_rev_hz, double f_hz, double zeta) {
  const std::size_t M = rows.size();
  for (std::size_t a = 0; a < 3; ++a) {
    std::vector<std::complex<double>> c(M / 2 + 1);
    for (std::size_t k = 0; k <= M / 2; ++k) {
      std::complex<double> sum = 0.0;
      for (std::size_t m = 0; m < M; ++m) sum += rows[m].F_N[a] * std::polar(1.0, -kRadPerRev * double(k * m % M) / M);
      const double r = k * n_rev_hz / f_hz;
      c[k] = sum / double(M) / std::complex<double>(1.0 - r * r, 2.0 * zeta * r);
    }
    for (std::size_t m = 0; m < M; ++m) {
      double y = c[0].real();
      for (std::size_t k = 1; k <= M / 2; ++k) {
        const double w = (2 * k == M) ? 1.0 : 2.0;
        y += w * (c[k] * std::polar(1.0, kRadPerRev * double(k * m % M) / M)).real();
      }
      rows[m].F_N[a] = y;
    }
  }
}

}  // namespace

SteadyCutResult run_steady_cut(const SteadyCutSpec& spec) {
  spec.validate();
  const double R = spec.tool.radius_mm();
  const double D = spec.tool.diameter_mm;
  const double n_rev_per_s = spec.spindle_rpm / kSPerMin;
  const double v_mm_per_s = spec.feed_per_tooth_mm * spec.tool.flutes * n_rev_per_s;
  const double Ts_s = spec.angle_step_deg / 360.0 / n_rev_per_s;
  const int ticks = static_cast<int>(std::lround(360.0 / spec.angle_step_deg));
  const double travel = v_mm_per_s * Ts_s * ticks;
  const double x_lo = -(D + 2.0);
  const double x_hi = travel + R + 2.0;
  ProcessSetup setup;
  setup.tool = spec.tool;
  setup.coefficients = scaled(spec.coefficients, spec.coefficient_scale);
  setup.lead_deg = spec.lead_deg;
  setup.tilt_deg = spec.tilt_deg;
  setup.options.dz_mm = spec.dz_mm;
  setup.options.angle_step_deg = spec.angle_step_deg;
  setup.stock.cell_mm = spec.cell_mm;
  setup.stock.top_z_mm = 0.0;
  setup.stock.bottom_z_mm = -spec.ap_mm - 2.0;
  if (spec.ae_mm >= D - 1e-12)
    setup.stock.outline_mm = StockSpec::rectangle(x_lo, -R - 2.0, x_hi, R + 2.0);
  else if (spec.up_milling)
    setup.stock.outline_mm = StockSpec::rectangle(x_lo, R - spec.ae_mm, x_hi, R + 2.0);
  else
    setup.stock.outline_mm = StockSpec::rectangle(x_lo, -R - 2.0, x_hi, -(R - spec.ae_mm));
  MillingProcess process(setup);
  process.remove_swept({x_lo - R - 1.0, 0.0, -spec.ap_mm}, {0.0, 0.0, -spec.ap_mm});
  SteadyCutResult res;
  res.feed_mm_per_min = v_mm_per_s * kSPerMin;
  double engagement_sum = 0.0;
  for (int k = 0; k < ticks; ++k) {
    ProcessInput in;
    in.k = k;
    in.t_s = k * Ts_s;
    in.Ts_s = Ts_s;
    in.p_mm = {v_mm_per_s * k * Ts_s, 0.0, -spec.ap_mm};
    in.v_mm_per_s = {v_mm_per_s, 0.0, 0.0};
    in.spindle_rpm = spec.spindle_rpm;
    const double angle_deg = process.spindle_angle_rad() * kDegPerRad;
    const ProcessOutput out = process.step(in);
    res.rows.push_back({angle_deg, out.F_N, out.spindle_torque_Nm, out.chip_mm});
    res.mean_torque_Nm += out.spindle_torque_Nm / ticks;
    engagement_sum += out.engagement_deg;
  }
  if (spec.sensor_f_hz > 0.0) apply_sensor_mode(res.rows, n_rev_per_s, spec.sensor_f_hz, spec.sensor_zeta);
  for (const auto& row : res.rows)
    for (std::size_t a = 0; a < 3; ++a) {
      res.mean_F_N[a] += row.F_N[a] / ticks;
      if (std::abs(row.F_N[a]) > std::abs(res.peak_F_N[a])) res.peak_F_N[a] = row.F_N[a];
    }
  res.mean_power_W = res.mean_torque_Nm * spec.spindle_rpm * kRadPerSPerRpm;
  res.engagement_deg = engagement_sum / ticks;
  return res;
}

}  // namespace twin::process
