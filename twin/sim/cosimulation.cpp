#include "twin/sim/cosimulation.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>

#include <fmt/format.h>

#include "controller/law.hpp"
#include "twin/core/check.hpp"
#include "twin/core/error.hpp"
#include "twin/core/units.hpp"

namespace twin::sim {
namespace {

std::vector<feeddrive::DriveParams> drive_params_of(const MachineDefinition& m, const std::vector<Axis>& axes) {
  std::vector<feeddrive::DriveParams> out;
  for (Axis a : axes) out.push_back(m.axes[index(a)].drive);
  return out;
}

/// The least common multiple of the present axes' inner ticks per period, as each
/// axis's law sets up its step.
int inner_ticks_of(const MachineDefinition& m, const std::vector<Axis>& axes) {
  int l = 1;
  for (Axis a : axes) {
    const AxisDefinition& def = m.axes[index(a)];
    const controller::DriveScale drive{def.drive.rg_mm_per_rad, def.drive.Ka_A_per_V, def.drive.Kt_Nm_per_A};
    l = std::lcm(l, controller::law_of(def.loop.law).setup(def.loop, m.Ts_s, drive).inner_ticks);
    if (l > controller::kMaxInnerTicks)
      throw ConfigError(fmt::format("machine {}: the axes' velocity-loop periods Tv share no period of at least "
                                    "Ts / {} (the least common multiple of their ticks is {})",
                                    m.name, controller::kMaxInnerTicks, l));
  }
  return l;
}

}  // namespace

CoSimulation::CoSimulation(MachineDefinition machine, std::shared_ptr<const ReferenceSource> reference,
                           std::unique_ptr<process::ProcessModel> process, const AxisArray<double>& x0_mm,
                           feeddrive::IntegratorOptions options)
    : machine_(std::move(machine)),
      axes_((machine_.validate(), machine_.present_axes())),
      reference_(std::move(reference)),
      process_(std::move(process)),
      inner_ticks_(inner_ticks_of(machine_, axes_)),
      drives_(drive_params_of(machine_, axes_), machine_.Ts_s / inner_ticks_, options),
      encoder_{machine_.encoder_resolution_mm} {
  TWIN_DEMAND(reference_ != nullptr);
  std::vector<double> x0;
  for (Axis a : axes_) {
    x0.push_back(x0_mm[index(a)]);
    const feeddrive::DriveParams& d = machine_.axes[index(a)].drive;
    loops_.emplace_back(machine_.axes[index(a)].loop, machine_.Ts_s, controller::DriveScale{d.rg_mm_per_rad, d.Ka_A_per_V, d.Kt_Nm_per_A});
  }
  drives_.reset(x0);
  inputs_.assign(axes_.size(), feeddrive::DriveInput{});
  clamp_watch_.assign(axes_.size(), ClampWatch{});
  period_mean_.assign(axes_.size(), PeriodMean{});
}

CoSimulation::~CoSimulation() = default;
CoSimulation::CoSimulation(CoSimulation&&) noexcept = default;
CoSimulation& CoSimulation::operator=(CoSimulation&&) noexcept = default;

void CoSimulation::set_reference(std::shared_ptr<const ReferenceSource> reference) {
  TWIN_DEMAND(reference != nullptr);
  reference_ = std::move(reference);
}

const Snapshot& CoSimulation::step() {
  const double Ts = machine_.Ts_s;
  const double t = time_s();
  Snapshot row;
  row.k = k_;
  row.t_s = t;

  // 1. Drives at t_k.
  std::array<double, 3> p_mm{};
  std::array<double, 3> v_mm_per_s{};
  std::array<double, 3> v_motor_mm_per_s{};  // the speed the loop feeds back: the motor's
  for (std::size_t i = 0; i < axes_.size(); ++i) {
    const std::size_t a = index(axes_[i]);
    const feeddrive::DriveOutput out = drives_.output(i);
    p_mm[a] = out.x_mm;
    v_mm_per_s[a] = out.v_mm_per_s;
    v_motor_mm_per_s[i] = motor_speed_mm_per_s(i, out);
    row.axes[a].x_true_mm = out.x_mm;
    row.axes[a].x_mm = encoder_.measure_mm(out.x_meas_mm);
    row.axes[a].v_mm_per_s = out.v_mm_per_s;
  }

  // 2. Reference.
  const controller::ReferenceSample ref = reference_->sample(k_);
  row.block = ref.block;
  row.reference_done = ref.done;
  row.feed_programmed_mm_per_min = ref.feed_programmed_mm_per_s * kSPerMin;
  row.feed_ref_mm_per_min = ref.path_speed_mm_per_s * kSPerMin;
  row.spindle_rpm = spindle_override_rpm_ ? *spindle_override_rpm_ : ref.spindle_rpm;

  // 3. Process over [t_k, t_k+1).
  const std::array<double, 3> F_avg_N = run_process(row, p_mm, v_mm_per_s);

  // 4. Position loops; 5. drive inputs.
  std::array<controller::PositionLoopOutput, 3> lo{};
  for (std::size_t i = 0; i < axes_.size(); ++i) {
    const std::size_t a = index(axes_[i]);
    AxisSnapshot& s = row.axes[a];
    s.x_ref_mm = ref.x_mm[a];
    lo[i] = loops_[i].step(k_, s.x_ref_mm, s.x_mm, v_motor_mm_per_s[i]);
    s.e_mm = s.x_ref_mm - s.x_mm;  // against the reference given (the loop's own may be smoothed)
    s.vcmd_mm_per_s = lo[i].vcmd_mm_per_s;
    s.u_V = lo[i].u_V;
    s.Tcmd_Nm = lo[i].torque_demand;
    s.saturated = lo[i].saturated;
    s.Td_Nm = F_avg_N[a] * drives_.params(i).rg_mm_per_rad * kMPerMm;
    inputs_[i] = feeddrive::DriveInput{lo[i].u_V, s.Td_Nm};
  }
  // The drives over the period in inner_ticks_ steps; a loop whose velocity
  // loop runs n times a period acts again every inner_ticks_ / n of them, on
  // the motor's speed of that instant. The row's current and torque are those
  // the period starts with (a log samples them at the tick).
  // The period's means (AxisSnapshot::period_mean) are over the same ticks,
  // each weighing Ts / inner_ticks_.
  const double t_end = t0_s_ + static_cast<double>(k_ + 1) * Ts;
  std::array<double, 3> i_first_A{}, Tm_first_Nm{};
  std::array<PeriodMean, 3> sum{};  // per axis of axes_ (at most three): no allocation a tick
  for (int q = 0; q < inner_ticks_; ++q) {
    for (std::size_t i = 0; q > 0 && i < axes_.size(); ++i) {
      const int every = inner_ticks_ / loops_[i].inner_ticks();
      if (q % every != 0) continue;
      loops_[i].inner_step(q / every, motor_speed_mm_per_s(i, drives_.output(i)), lo[i]);
      inputs_[i].u_V = lo[i].u_V;
    }
    const double t_from = t + Ts * q / inner_ticks_;
    drives_.advance(t_from, q + 1 == inner_ticks_ ? t_end : t + Ts * (q + 1) / inner_ticks_, inputs_);
    for (std::size_t i = 0; i < axes_.size(); ++i) {
      const feeddrive::DriveOutput out = drives_.output(i);
      sum[i].i_A += out.i_A;
      sum[i].Tm_Nm += out.Tm_Nm;
      sum[i].Tcmd_Nm += lo[i].torque_demand;
      if (q > 0) continue;
      i_first_A[i] = out.i_A;
      Tm_first_Nm[i] = out.Tm_Nm;
    }
  }

  // 6. Row k: currents and torques held over the tick; health checks.
  double v_real2 = 0.0;
  std::array<double, 3> dev{};
  for (std::size_t i = 0; i < axes_.size(); ++i) {
    const std::size_t a = index(axes_[i]);
    AxisSnapshot& s = row.axes[a];
    const feeddrive::DriveOutput out = drives_.output(i);
    s.i_A = i_first_A[i];
    s.Tm_Nm = Tm_first_Nm[i];
    s.period_mean = period_mean_valid_ ? period_mean_[i] : PeriodMean{s.i_A, s.Tm_Nm, s.Tcmd_Nm};
    check_axis(i, s, out, t);
    v_real2 += s.v_mm_per_s * s.v_mm_per_s;
    dev[a] = s.x_true_mm - s.x_ref_mm;
  }
  period_mean_valid_ = true;
  for (std::size_t i = 0; i < axes_.size(); ++i)
    period_mean_[i] = PeriodMean{sum[i].i_A / inner_ticks_, sum[i].Tm_Nm / inner_ticks_, sum[i].Tcmd_Nm / inner_ticks_};
  row.feed_real_mm_per_min = std::sqrt(v_real2) * kSPerMin;
  // Contour error: the part of the deviation normal to the reference direction.
  const double vr = ref.path_speed_mm_per_s;
  double d2 = dev[0] * dev[0] + dev[1] * dev[1] + dev[2] * dev[2];
  if (vr > 1e-6) {
    double along = 0.0;
    for (std::size_t c = 0; c < 3; ++c) along += dev[c] * ref.v_mm_per_s[c] / vr;
    d2 = std::max(0.0, d2 - along * along);
  }
  row.contour_error_mm = std::sqrt(d2);

  last_ = row;
  ++k_;
  return last_;
}

std::array<double, 3> CoSimulation::run_process(Snapshot& row, const std::array<double, 3>& p_mm,
                                                const std::array<double, 3>& v_mm_per_s) {
  std::array<double, 3> F_avg_N = F_ext_N_;
  row.F_N = F_ext_N_;
  if (process_) {
    process::ProcessInput pin;
    pin.k = k_;
    pin.t_s = row.t_s;
    pin.Ts_s = machine_.Ts_s;
    pin.p_mm = p_mm;
    pin.v_mm_per_s = v_mm_per_s;
    pin.spindle_rpm = row.spindle_rpm;
    const process::ProcessOutput pout = process_->step(pin);
    for (std::size_t c = 0; c < 3; ++c) {
      F_avg_N[c] += pout.F_avg_N[c];
      row.F_N[c] += pout.F_N[c];
    }
    row.engagement_deg = pout.engagement_deg;
    row.chip_mm = pout.chip_mm;
    row.spindle_torque_Nm = pout.spindle_torque_Nm;
    row.cutting_power_W = pout.power_W;
    row.tool_modes = pout.tool_modes;
    row.tool_deflection_um = {pout.deflection_mm[0] * 1e3, pout.deflection_mm[1] * 1e3};
    row.sle_um = pout.sle_mm * 1e3;
  }
  row.F_avg_N = F_avg_N;
  return F_avg_N;
}

void CoSimulation::check_axis(std::size_t i, const AxisSnapshot& s, const feeddrive::DriveOutput& out, double t) {
  const std::size_t a = index(axes_[i]);
  const double Ts = machine_.Ts_s;
  const double limit = machine_.axes[a].following_error_limit_mm;
  if (!std::isfinite(out.x_mm) || !std::isfinite(out.w_rad_per_s) || !std::isfinite(s.u_V))
    throw ModelError(fmt::format("axis {} became non-finite at t = {:.4f} s (tick {}): check the gains and the model",
                                 axis_name(axes_[i]), t, k_));
  if (std::abs(s.e_mm) > limit)
    throw ModelError(fmt::format(
        "axis {} unstable or overloaded at t = {:.4f} s (tick {}): tracking error {:.4g} mm exceeds the following-error "
        "limit {:g} mm (u = {:.3g} V{}); check the gains",
        axis_name(axes_[i]), t, k_, s.e_mm, limit, s.u_V, s.saturated ? ", at the clamp" : ""));
  // An unstable loop whose growth the clamp bounds rings at +-u_max with
  // the sign of u flipping: judged over blocks of 20 ms, a block is bad when
  // u sits at the clamp for half of it and changes sign at least 4 times;
  // three bad blocks in a row (60 ms) are not a transient.
  ClampWatch& w = clamp_watch_[i];
  const double u_prev = last_.k == k_ - 1 ? last_.axes[a].u_V : 0.0;
  w.saturated_ticks += s.saturated ? 1 : 0;
  w.flips += (s.saturated && u_prev * s.u_V < 0.0) ? 1 : 0;
  if (++w.ticks_in_block * Ts >= 0.02 - 1e-12) {
    const bool bad = 2 * w.saturated_ticks >= w.ticks_in_block && w.flips >= 4;
    w.bad_blocks = bad ? w.bad_blocks + 1 : 0;
    w.ticks_in_block = w.saturated_ticks = w.flips = 0;
    if (w.bad_blocks >= 3)
      throw ModelError(fmt::format(
          "axis {} unstable at t = {:.4f} s (tick {}): the command oscillates between its limits ({}) for 60 ms "
          "(tracking error {:.3g} mm); check the gains",
          axis_name(axes_[i]), t, k_,
          machine_.axes[a].loop.law == controller::LoopLaw::kCascade
              ? fmt::format("torque +-{:g}", machine_.axes[a].loop.cascade.T_max)
              : fmt::format("+-{:g} V", machine_.axes[a].loop.u_max_V),
          s.e_mm));
  }
}

const feeddrive::DriveState& CoSimulation::drive_state(Axis a) const {
  for (std::size_t i = 0; i < axes_.size(); ++i)
    if (axes_[i] == a) return drives_.state(i);
  throw ConfigError(fmt::format("axis {} is not present in machine {}", axis_name(a), machine_.name));
}
const feeddrive::DriveParams& CoSimulation::drive_params(Axis a) const {
  for (std::size_t i = 0; i < axes_.size(); ++i)
    if (axes_[i] == a) return drives_.params(i);
  throw ConfigError(fmt::format("axis {} is not present in machine {}", axis_name(a), machine_.name));
}

CoSimState CoSimulation::get_state() const {
  CoSimState s;
  s.k = k_;
  s.drives = drives_.states();
  for (const auto& l : loops_) s.loops.push_back(l.state());
  if (process_) s.process = std::shared_ptr<const process::ProcessModel>(process_->clone());
  s.last = last_;
  s.clamp_watch = clamp_watch_;
  if (period_mean_valid_) s.period_mean = period_mean_;
  return s;
}

void CoSimulation::set_state(const CoSimState& s) {
  TWIN_DEMAND(s.drives.size() == axes_.size() && s.loops.size() == loops_.size());
  k_ = s.k;
  drives_.set_states(s.drives);
  for (std::size_t i = 0; i < loops_.size(); ++i) loops_[i].set_state(s.loops[i]);
  if (s.process) process_ = s.process->clone();
  last_ = s.last;
  clamp_watch_ = s.clamp_watch.size() == axes_.size() ? s.clamp_watch : std::vector<ClampWatch>(axes_.size());
  period_mean_valid_ = s.period_mean.size() == axes_.size();
  if (period_mean_valid_) std::copy(s.period_mean.begin(), s.period_mean.end(), period_mean_.begin());
}

void start_in_steady_motion(CoSimulation& cosim, const AxisArray<std::optional<ReferenceAtStart>>& reference,
                            std::int64_t k0) {
  CoSimState st = cosim.get_state();
  const double Ts = cosim.Ts_s();
  const auto& axes = cosim.axes();
  for (std::size_t i = 0; i < axes.size(); ++i) {
    const auto& r = reference[index(axes[i])];
    if (!r) continue;
    const AxisDefinition& def = cosim.machine().axes[index(axes[i])];
    const auto& d = def.drive;
    const double v = (r->x_prev_mm - r->x_prev2_mm) / Ts;
    const double w = r->v_mm_per_s / d.rg_mm_per_rad;
    const double Tc = w > 0.0 ? d.Tc_pos_Nm : (w < 0.0 ? -d.Tc_neg_Nm : 0.0);
    const double load = d.effects.constant_load.enabled ? d.effects.constant_load.torque_Nm : 0.0;
    // Tm = A + sign(w) f |Tm| with load-dependent friction: A / (1 - f) where
    // Tm takes the direction of motion, A / (1 + f) where it opposes it.
    double Tm = d.B_kg_m2_per_s * w + Tc + load;
    if (d.effects.load_dependent_friction.enabled && w != 0.0) {
      const double f = d.effects.load_dependent_friction.fraction;
      Tm = Tm * w > 0.0 ? Tm / (1.0 - f) : Tm / (1.0 + f);
    }
    const controller::SteadyMotion motion{Ts, v, w, Tm,
                                          controller::DriveScale{d.rg_mm_per_rad, d.Ka_A_per_V, d.Kt_Nm_per_A}};
    controller::PositionLoopState& ls = st.loops[i];
    ls = controller::PositionLoopState{};
    // The reference the loop follows (behind the given one where the law smooths it), up to the tick before k0.
    const double x_prev_loop = controller::prime_reference_smoothing(cosim.loop_setup(i), r->x_prev_mm, v, ls);
    const double x_loop = x_prev_loop + (r->x_mm - r->x_prev_mm);
    const double e = controller::law_of(def.loop.law).steady_state(def.loop, motion, x_loop, ls);
    feeddrive::DriveState& ds = st.drives[i];
    ds.x_mm = x_loop - e;
    ds.w_rad_per_s = w;
    ds.stuck = w == 0.0;
    ds.x_load_mm = ds.x_mm;
    ds.w_load_rad_per_s = w;
    ds.x_table_mm = ds.x_mm;
    ds.load_stuck = ds.stuck;
    ls.x_ref_prev_mm = cosim.loop_setup(i).feedforward_unsmoothed ? r->x_prev_mm : x_prev_loop;
    ls.v_ref_prev_mm_per_s = v;
    ls.last_k = k0 - 1;
  }
  st.k = k0;
  st.last.k = k0 - 1;
  st.period_mean.clear();  // the first row gives its own tick's
  cosim.set_state(st);
}

}  // namespace twin::sim
