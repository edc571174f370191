#include "process/steady_cut.hpp"

#include <cmath>

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
}

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
  setup.coefficients = spec.coefficients;
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
    for (std::size_t a = 0; a < 3; ++a) {
      res.mean_F_N[a] += out.F_N[a] / ticks;
      if (std::abs(out.F_N[a]) > std::abs(res.peak_F_N[a])) res.peak_F_N[a] = out.F_N[a];
    }
    res.mean_torque_Nm += out.spindle_torque_Nm / ticks;
    engagement_sum += out.engagement_deg;
  }
  res.mean_power_W = res.mean_torque_Nm * spec.spindle_rpm * kRadPerSPerRpm;
  res.engagement_deg = engagement_sum / ticks;
  return res;
}

}  // namespace twin::process
