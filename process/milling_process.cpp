#include "process/milling_process.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "twin/core/check.hpp"
#include "twin/core/error.hpp"
#include "twin/core/units.hpp"

namespace twin::process {
namespace {
/// At the default 1.5 deg step this is 4.2 revolutions per tick: 250000 rpm
/// at Ts = 1e-4 s, beyond the G-code reader's 200000 rpm and twenty times the
/// shipped scenarios' fastest spindle (12000 rpm).
constexpr int kMaxForceSamplesPerTick = 1000;
/// The smallest descent that updates the stock by itself (see update_stock).
constexpr double kDescent_mm = 1e-4;
}  // namespace

std::string ProcessSetup::summary() const {
  return fmt::format("{} ({} D{} mm, {} flutes, helix {} deg, r {} mm), {}, lead {} deg, tilt {} deg",
                     tool.name, tool_shape_name(tool.shape), tool.diameter_mm, tool.flutes, tool.helix_deg,
                     tool.corner_radius_mm, coefficients.name, lead_deg, tilt_deg);
}

MillingProcess::MillingProcess(const ProcessSetup& setup)
    : model_(setup.tool, setup.coefficients, setup.lead_deg, setup.options),
      stock_(setup.stock),
      phi_rad_(setup.spindle_angle0_deg * kRadPerDeg),
      vibration_(setup.tool_tip.empty() ? ToolVibration() : ToolVibration(setup.tool_tip)),
      substeps_per_mode_period_(setup.substeps_per_mode_period) {
  if (!(substeps_per_mode_period_ >= 1.0 && substeps_per_mode_period_ <= 100.0))
    throw ConfigError(fmt::format("process: substeps_per_mode_period = {} must be in [1, 100]",
                                  substeps_per_mode_period_));
  if (!std::isfinite(setup.tilt_deg) || std::abs(setup.tilt_deg) >= 60.0)
    throw ConfigError(fmt::format("process: tilt_deg = {} must be in (-60, 60) deg", setup.tilt_deg));
  if (!std::isfinite(phi_rad_)) throw ConfigError("process: spindle_angle0_deg is not finite");
}

std::unique_ptr<ProcessModel> MillingProcess::clone() const { return std::make_unique<MillingProcess>(*this); }

double MillingProcess::remove_swept(const std::array<double, 3>& p0_mm, const std::array<double, 3>& p1_mm) {
  const double v = stock_.remove_sweep(model_.tool(), p0_mm, p1_mm, true);
  swept_once_ = true;
  last_removed_mm_ = p1_mm;
  last_sweep_level_ = p1_mm[2] >= p0_mm[2] - 1e-9;
  return v;
}

void MillingProcess::check_stopped_spindle(const ProcessInput& in, const std::array<double, 2>& v_dir,
                                           double z_top_mm) const {
  const auto& p = in.p_mm;
  if (!(v_dir[0] != 0.0 || v_dir[1] != 0.0) || !(p[2] < z_top_mm)) return;
  const auto material = [this](double x, double y, double z) { return stock_.has_material(x, y, z); };
  for (int q = 0; q < 8; ++q) {
    const ForceSample probe_cut = model_.sample(phi_rad_ + q * kPi / 4.0, p, v_dir, z_top_mm, probe_mm(), material);
    if (probe_cut.cutting_elements > 0)
      throw ModelError(fmt::format("process: the tool feeds into material with the spindle stopped at t = {} s, "
                                   "p = ({:.4f}, {:.4f}, {:.4f}) mm",
                                   in.t_s, p[0], p[1], p[2]));
  }
}

int MillingProcess::substeps(const ProcessInput& in, double omega_rad_per_s) const {
  const double dphi_tick = omega_rad_per_s * in.Ts_s;
  const double angle_step_rad = model_.options().angle_step_deg * kRadPerDeg;
  double n_sub_wanted = std::ceil(dphi_tick / angle_step_rad - 1e-9);
  if (!vibration_.empty())
    n_sub_wanted = std::max(n_sub_wanted, std::ceil(substeps_per_mode_period_ * vibration_.fn_max_Hz() * in.Ts_s - 1e-9));
  if (!(n_sub_wanted <= kMaxForceSamplesPerTick))
    throw ModelError(fmt::format(
        "process: spindle {} rpm turns {:.4g} deg per tick of {} s: {:.4g} force samples of {} deg, more than the {} a "
        "tick may take (lower S, or raise process.model.angle_step_deg)",
        in.spindle_rpm, dphi_tick / kRadPerDeg, in.Ts_s, n_sub_wanted, model_.options().angle_step_deg,
        kMaxForceSamplesPerTick));
  return std::max(1, static_cast<int>(n_sub_wanted));
}

void MillingProcess::sample_rigid(const ProcessInput& in, const TickCut& cut, ProcessOutput& out) const {
  const auto& p = in.p_mm;
  const auto& v = in.v_mm_per_s;
  const auto material = [this](double x, double y, double z) { return stock_.has_material(x, y, z); };
  const double dt = in.Ts_s / cut.n_sub;
  std::array<double, 3> F_sum{};
  double T_sum = 0.0;
  for (int s = 0; s < cut.n_sub; ++s) {
    const std::array<double, 3> ps{p[0] + v[0] * s * dt, p[1] + v[1] * s * dt, p[2] + v[2] * s * dt};
    const ForceSample fs =
        model_.sample(phi_rad_ + cut.omega_rad_per_s * s * dt, ps, cut.f_mm, cut.z_top_mm, probe_mm(), material);
    for (std::size_t a = 0; a < 3; ++a) F_sum[a] += fs.F_tool_N[a];
    T_sum += fs.torque_Nm;
    out.chip_mm = std::max(out.chip_mm, fs.chip_max_mm);
    if (s == 0)
      for (std::size_t a = 0; a < 3; ++a) out.F_N[a] = -fs.F_tool_N[a];
  }
  for (std::size_t a = 0; a < 3; ++a) out.F_avg_N[a] = -F_sum[a] / cut.n_sub;
  out.spindle_torque_Nm = T_sum / cut.n_sub;
}

int MillingProcess::finished_walls(const ProcessInput& in, const TickCut& cut,
                                   std::array<std::array<double, 2>, 2>& n) const {
  // phi = 0 and pi in the feed frame: +-(the feed direction turned +90 deg).
  const double r = model_.tool().radius_mm() + probe_mm();
  const double z = in.p_mm[2] + 0.5 * std::min(cut.z_top_mm - in.p_mm[2], model_.tool().flute_length_mm);
  int walls = 0;
  for (double sign : {1.0, -1.0}) {
    const std::array<double, 2> w{-sign * cut.v_dir[1], sign * cut.v_dir[0]};
    if (stock_.has_material(in.p_mm[0] + r * w[0], in.p_mm[1] + r * w[1], z)) n[static_cast<std::size_t>(walls++)] = w;
  }
  return walls;
}

void MillingProcess::sample_vibrating(const ProcessInput& in, const TickCut& cut, ProcessOutput& out) {
  const auto& p = in.p_mm;
  const auto& v = in.v_mm_per_s;
  const auto material = [this](double x, double y, double z) { return stock_.has_material(x, y, z); };
  const int N = model_.tool().flutes;
  const double T_tooth = kRadPerRev / (N * cut.omega_rad_per_s);
  const double keep_s = N * T_tooth + in.Ts_s;
  const double dt = in.Ts_s / cut.n_sub;
  std::array<std::array<double, 2>, 2> walls{};
  const int n_walls = cut.v_dir[0] != 0.0 || cut.v_dir[1] != 0.0 ? finished_walls(in, cut, walls) : 0;
  const double depth = std::min(cut.z_top_mm - p[2], model_.tool().flute_length_mm);
  const double lag = 0.5 * depth * std::tan(model_.tool().helix_deg * kRadPerDeg) / model_.tool().radius_mm();
  Regeneration regen;
  std::array<double, 3> F_sum{};
  double T_sum = 0.0;
  for (int s = 0; s < cut.n_sub; ++s) {
    const double t0 = in.t_s + s * dt;
    const double tm = t0 + 0.5 * dt;
    const std::array<double, 2> u = vibration_.predict_mm(0.5 * dt, F_tool_prev_N_);
    for (int m = 1; m <= N; ++m) {
      const std::array<double, 2> u_then = vibration_.deflection_at_mm(tm - m * T_tooth);
      regen.du_mm[static_cast<std::size_t>(m - 1)] = {u[0] - u_then[0], u[1] - u_then[1]};
    }
    const double w = (s + 0.5) * dt;
    const std::array<double, 3> ps{p[0] + v[0] * w, p[1] + v[1] * w, p[2] + v[2] * w};
    const double phi0 = phi_rad_ + cut.omega_rad_per_s * s * dt;
    const ForceSample fs =
        model_.sample(phi0 + cut.omega_rad_per_s * 0.5 * dt, ps, cut.f_mm, cut.z_top_mm, probe_mm(), material, &regen);
    for (std::size_t a = 0; a < 3; ++a) F_sum[a] += fs.F_tool_N[a];
    T_sum += fs.torque_Nm;
    out.chip_mm = std::max(out.chip_mm, fs.chip_max_mm);
    if (s == 0)
      for (std::size_t a = 0; a < 3; ++a) out.F_N[a] = -fs.F_tool_N[a];
    // A flute at mid depth passing a finished wall's angle in this substep.
    for (int k = 0; k < n_walls; ++k) {
      const auto& nw = walls[static_cast<std::size_t>(k)];
      const double angle_wall = std::atan2(nw[0], nw[1]);
      for (int j = 0; j < N; ++j) {
        const double ahead = std::fmod(angle_wall - (phi0 + j * kRadPerRev / N - lag), kRadPerRev);
        const double d = ahead < 0.0 ? ahead + kRadPerRev : ahead;
        if (d < cut.omega_rad_per_s * dt) sle_mm_ = u[0] * nw[0] + u[1] * nw[1];
      }
    }
    F_tool_prev_N_ = {fs.F_tool_N[0], fs.F_tool_N[1]};
    vibration_.advance(t0, dt, F_tool_prev_N_, keep_s);
  }
  for (std::size_t a = 0; a < 3; ++a) out.F_avg_N[a] = -F_sum[a] / cut.n_sub;
  out.spindle_torque_Nm = T_sum / cut.n_sub;
}

double MillingProcess::update_stock(const ProcessInput& in) {
  const auto& p = in.p_mm;
  const auto& v = in.v_mm_per_s;
  double removed = 0.0;
  const std::array<double, 3> p_next{p[0] + v[0] * in.Ts_s, p[1] + v[1] * in.Ts_s, p[2] + v[2] * in.Ts_s};
  if (!swept_once_) {
    removed += stock_.remove_sweep(model_.tool(), p, p, true);
    swept_once_ = true;
    last_removed_mm_ = p;
  }
  const double moved = std::hypot(p_next[0] - last_removed_mm_[0], p_next[1] - last_removed_mm_[1]);
  // A descent of less than kDescent_mm waits for the next update (the cells
  // over the tip then lag by that much at most, far below anything the force
  // or the engagement read): a Z axis held against gravity moves by a few nm
  // from tick to tick, and a whole sweep every tick would cost more than the cut.
  if (moved >= 2.0 * stock_.cell_mm() || p_next[2] < last_removed_mm_[2] - kDescent_mm) {
    // An update may visit only the cells this move can still lower when the
    // one before it was level or rising (the cells over its end's flat core
    // are then at the tip height); after a descent it visits every cell.
    removed += stock_.remove_sweep(model_.tool(), last_removed_mm_, p_next, !last_sweep_level_);
    last_sweep_level_ = p_next[2] >= last_removed_mm_[2] - 1e-9;
    last_removed_mm_ = p_next;
  }
  return removed;
}

ProcessOutput MillingProcess::step(const ProcessInput& in) {
  const auto& p = in.p_mm;
  const auto& v = in.v_mm_per_s;
  if (!all_finite(p[0], p[1], p[2], v[0], v[1], v[2], in.spindle_rpm, in.Ts_s) || !(in.Ts_s > 0.0))
    throw ModelError(fmt::format("process: non-finite or invalid input at t = {} s (tick {}): p = ({}, {}, {}) mm, "
                                 "v = ({}, {}, {}) mm/s, spindle {} rpm, Ts {} s",
                                 in.t_s, in.k, p[0], p[1], p[2], v[0], v[1], v[2], in.spindle_rpm, in.Ts_s));
  if (in.spindle_rpm < 0.0)
    throw ModelError(fmt::format("process: counter-clockwise spindle (M4, {} rpm) at t = {} s is not modelled",
                                 in.spindle_rpm, in.t_s));
  const ToolGeometry& tool = model_.tool();
  TickCut cut;
  cut.z_top_mm = stock_.top_z_mm();
  const double speed_xy = std::hypot(v[0], v[1]);
  if (speed_xy > 0.0) cut.v_dir = {v[0] / speed_xy, v[1] / speed_xy};
  ProcessOutput out;
  out.tool_modes = !vibration_.empty();
  out.deflection_mm = out.tool_modes ? vibration_.deflection_mm() : std::array<double, 2>{};
  cut.omega_rad_per_s = in.spindle_rpm * kRadPerSPerRpm;
  const bool cutting = in.spindle_rpm != 0.0 && p[2] < cut.z_top_mm;
  if (in.spindle_rpm == 0.0) {
    check_stopped_spindle(in, cut.v_dir, cut.z_top_mm);
  } else if (cutting) {
    const double n_rev_per_s = in.spindle_rpm / kSPerMin;
    cut.f_mm = {v[0] / (tool.flutes * n_rev_per_s), v[1] / (tool.flutes * n_rev_per_s)};
    cut.n_sub = substeps(in, cut.omega_rad_per_s);
    if (vibration_.empty())
      sample_rigid(in, cut, out);
    else
      sample_vibrating(in, cut, out);
    out.power_W = out.spindle_torque_Nm * cut.omega_rad_per_s;
    if (speed_xy > 0.0) {
      const double depth_mm = std::min(cut.z_top_mm - p[2], tool.flute_length_mm);
      out.engagement_deg =
          model_.engaged_arc_deg(p, cut.v_dir, model_.disk_height_nearest_mm(0.5 * depth_mm), probe_mm(), stock_);
    }
  }
  if (!cutting && !vibration_.empty()) {
    // Out of the cut the tool rings down freely.
    F_tool_prev_N_ = {0.0, 0.0};
    const double rev_s = in.spindle_rpm > 0.0 ? kSPerMin / in.spindle_rpm : 0.0;
    vibration_.advance(in.t_s, in.Ts_s, F_tool_prev_N_, rev_s + in.Ts_s);
  }
  out.sle_mm = sle_mm_;
  phi_rad_ = std::fmod(phi_rad_ + cut.omega_rad_per_s * in.Ts_s, kRadPerRev);
  out.removed_mm3 = update_stock(in);
  for (double f : {out.F_avg_N[0], out.F_avg_N[1], out.F_avg_N[2], out.F_N[0], out.F_N[1], out.F_N[2], out.power_W})
    if (!std::isfinite(f)) throw ModelError(fmt::format("process: non-finite force at t = {} s", in.t_s));
  return out;
}

std::unique_ptr<ProcessModel> make_process(const ProcessSetup& setup) {
  return std::make_unique<MillingProcess>(setup);
}

}  // namespace twin::process
