#include "fmu/slave.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

#include <fmt/format.h>

#include "controller/encoder.hpp"
#include "controller/gcode.hpp"
#include "controller/interpolator.hpp"
#include "twin/core/error.hpp"

namespace twin::fmu {

Slave::Slave(FmuModel model, std::string identity) : model_(std::move(model)), identity_(std::move(identity)) {
  vars_ = make_variables(model_.machine, sim::vibrating_tool(model_));
  reset();
}

void Slave::reset() {
  machine_ = model_.machine;
  reference_mode_ = model_.has_program() ? kModeProgram : kModeExternal;
  inputs_ = InputValues{};
  inputs_.x_ref_mm = model_.start_mm;
  t_start_s_ = 0.0;
  t_comm_s_ = 0.0;
  stop_defined_ = false;
  stop_s_ = 0.0;
  machine_changed_ = false;
  warnings_.clear();
  external_.reset();
  cosim_.reset();
  failed_ = false;
}

std::int64_t Slave::ticks() const noexcept { return cosim_ ? cosim_->tick() : 0; }

void Slave::set_experiment(double start_s, std::optional<double> stop_s) {
  if (running()) throw ConfigError("the experiment cannot change while the co-simulation runs");
  if (!std::isfinite(start_s)) throw ConfigError(fmt::format("startTime = {} must be finite", start_s));
  if (stop_s && !(std::isfinite(*stop_s) && *stop_s >= start_s))
    throw ConfigError(fmt::format("stopTime = {} must be finite and >= startTime = {}", *stop_s, start_s));
  t_start_s_ = start_s;
  t_comm_s_ = start_s;
  stop_defined_ = stop_s.has_value();
  stop_s_ = stop_s.value_or(0.0);
}

void Slave::build_cosim() {
  machine_.validate();
  std::shared_ptr<const sim::ReferenceSource> reference;
  if (reference_mode_ == kModeProgram) {
    if (!model_.has_program())
      throw ConfigError(fmt::format("mode = {}: scenario '{}' has no part program; use mode = {} (x_ref_mm inputs)",
                                    kModeProgram, model_.name, kModeExternal));
    // With the parameters as set now (travel, limits, Ts): checked again.
    reference = model_.plan_program(machine_).reference;
    external_.reset();
  } else {
    external_ = std::make_shared<sim::ExternalReference>(inputs_.x_ref_mm);
    reference = external_;
  }
  cosim_ = std::make_unique<sim::CoSimulation>(
      sim::build_cosimulation(model_, {.machine = &machine_, .reference = std::move(reference)}));
  machine_changed_ = false;
}

void Slave::start() {
  if (running()) throw ConfigError("the co-simulation runs already");
  build_cosim();
  t_comm_s_ = t_start_s_;
  warn_ignored_reference("at the end of initialization");
}

void Slave::warn_ignored_reference(const char* when) {
  if (reference_mode_ != kModeProgram) return;
  std::string changed;
  for (const auto& v : vars_)
    if (v.kind == VarKind::kRefInput && inputs_.x_ref_mm[v.axis] != model_.start_mm[v.axis])
      changed += fmt::format("{}{} = {}", changed.empty() ? "" : ", ", v.name, inputs_.x_ref_mm[v.axis]);
  if (!changed.empty())
    warnings_.push_back(fmt::format("{} {}: mode = {} follows the part program and ignores the reference inputs; "
                                    "set mode = {} before initialization to follow them",
                                    changed, when, kModeProgram, kModeExternal));
}

double Slave::ticks_to(double t_end_s) const {
  // Ticks j with t_start + j Ts < t_end (a tick starting within the
  // tolerance of t_end belongs to the next step).
  const double Ts = machine_.Ts_s;
  const double tol_s = 1e-9 * std::max(1.0, std::abs(t_end_s));
  const double x = (t_end_s - t_start_s_) / Ts;
  const double x_round = std::round(x);
  const double n_end_real = std::abs(x - x_round) * Ts <= tol_s ? x_round : std::ceil(x);
  return std::max(0.0, n_end_real - static_cast<double>(ticks()));
}

bool Slave::whole_ticks(double t_s, double h_s) const {
  const double Ts = machine_.Ts_s;
  const double n = std::round(h_s / Ts);
  return n >= 1.0 && std::abs(h_s - n * Ts) <= 1e-9 * std::max(1.0, std::abs(t_s + h_s));
}

std::int64_t Slave::step(double t_s, double h_s) {
  if (!running()) throw ConfigError("the co-simulation has not started");
  const double Ts = machine_.Ts_s;
  if (!std::isfinite(h_s) || !(h_s > 0.0))
    throw ConfigError(fmt::format("communicationStepSize = {} s must be > 0", h_s));
  const double expected = t_comm_s_;
  if (!std::isfinite(t_s) || std::abs(t_s - expected) > 1e-9 * std::max(1.0, std::abs(expected)))
    throw ConfigError(fmt::format(
        "currentCommunicationPoint = {:.17g} s, expected {:.17g} s (the end of the last step; start {} s, {} ticks of "
        "{} s run)",
        t_s, expected, t_start_s_, cosim_->tick(), Ts));
  const double t_end = t_s + h_s;
  const double tol_s = 1e-9 * std::max(1.0, std::abs(t_end));
  if (stop_defined_ && t_end > stop_s_ + tol_s)
    throw ConfigError(fmt::format("the step from t = {:.17g} s by h = {:.17g} s ends past the stop time {:.17g} s "
                                  "of the experiment",
                                  t_s, h_s, stop_s_));
  const double n_real = ticks_to(t_end);
  if (n_real > static_cast<double>(kMaxTicksPerStep))
    throw Discard(fmt::format(
        "a step of h = {:.6g} s is {:.6g} controller ticks of Ts = {} s; one step runs at most {} ticks ({:g} s), so "
        "that it returns in reasonable time: nothing was computed, use a smaller communicationStepSize",
        h_s, n_real, Ts, kMaxTicksPerStep, static_cast<double>(kMaxTicksPerStep) * Ts));
  const auto n = static_cast<std::int64_t>(n_real);
  if (n == 0) {
    // The step ends inside the tick already run (its plant interval reaches
    // past t_end with the inputs it sampled): nothing new to compute.
    t_comm_s_ = t_end;
    return 0;
  }
  if (machine_changed_) {
    const sim::CoSimState state = cosim_->get_state();
    build_cosim();
    cosim_->set_state(state);
  }
  if (external_) external_->set(inputs_.x_ref_mm);
  cosim_->set_external_force_N(inputs_.F_ext_N);
  cosim_->set_spindle_override_rpm(inputs_.spindle_override ? std::optional<double>(inputs_.spindle_rpm)
                                                            : std::optional<double>());
  for (std::int64_t i = 0; i < n; ++i) cosim_->step();
  t_comm_s_ = t_end;
  return n;
}

sim::Snapshot Slave::current_row() const {
  if (cosim_ && cosim_->tick() > 0) return cosim_->last();
  // Before the first step: the axes at rest at their start positions.
  sim::Snapshot s;
  const controller::Encoder encoder{machine_.encoder_resolution_mm};
  for (Axis a : machine_.present_axes()) {
    sim::AxisSnapshot& x = s.axes[index(a)];
    x.x_true_mm = model_.start_mm[index(a)];
    x.x_mm = encoder.measure_mm(x.x_true_mm);
    // No loop has run: the reference is where the axis rests, in both modes
    // (so no output depends on an input at the same communication point).
    x.x_ref_mm = model_.start_mm[index(a)];
    x.e_mm = x.x_ref_mm - x.x_mm;
  }
  return s;
}

const Variable& Slave::variable(std::size_t vr, VarType type) const {
  if (vr >= vars_.size())
    throw ConfigError(fmt::format("unknown valueReference {} (the FMU has 0..{})", vr, vars_.size() - 1));
  const Variable& v = vars_[vr];
  if (v.type != type) throw ConfigError(fmt::format("valueReference {} ('{}') is not of this type", vr, v.name));
  return v;
}

double Slave::get_real(std::size_t vr) const {
  const Variable& v = variable(vr, VarType::kReal);
  switch (v.kind) {
    case VarKind::kMachineParam:
    case VarKind::kAxisParam: return get_parameter(v, machine_);
    case VarKind::kRefInput: return inputs_.x_ref_mm[v.axis];
    case VarKind::kSpindleInput: return inputs_.spindle_rpm;
    case VarKind::kForceInput: return inputs_.F_ext_N[v.axis];
    case VarKind::kAxisOutput: return v.axis_output(current_row().axes[v.axis]);
    case VarKind::kOutput: return v.output(current_row());
    default: break;
  }
  throw InternalError(fmt::format("variable '{}' has no Real value", v.name));
}

int Slave::get_integer(std::size_t vr) const {
  const Variable& v = variable(vr, VarType::kInteger);
  if (v.kind == VarKind::kMode) return reference_mode_;
  return current_row().block;
}

bool Slave::get_boolean(std::size_t vr) const {
  const Variable& v = variable(vr, VarType::kBoolean);
  if (v.kind == VarKind::kSpindleOverride) return inputs_.spindle_override;
  return current_row().reference_done;
}

void Slave::set_real(std::size_t vr, double value) {
  const Variable& v = variable(vr, VarType::kReal);
  if (!std::isfinite(value)) throw ConfigError(fmt::format("{} = {} must be finite", v.name, value));
  const bool before_run = !running();
  switch (v.kind) {
    case VarKind::kMachineParam:
    case VarKind::kAxisParam: {
      if (!before_run && v.variability != Variability::kTunable)
        throw ConfigError(fmt::format("parameter {} is fixed and cannot be set while the co-simulation runs", v.name));
      // Setting a value it already has changes nothing (an effect's parameter
      // would otherwise switch its effect on).
      if (get_parameter(v, machine_) == value) return;
      if (v.kind == VarKind::kMachineParam) v.machine_param->ref(machine_) = value;
      else sim::set_axis_param(machine_.axes[v.axis], *v.axis_param, value);
      if (running()) {
        sim::MachineDefinition check = machine_;
        check.validate();
        machine_changed_ = true;
      }
      return;
    }
    case VarKind::kRefInput:
    case VarKind::kSpindleInput:
    case VarKind::kForceInput:
      if (v.kind == VarKind::kRefInput) {
        const bool changed = inputs_.x_ref_mm[v.axis] != value;
        inputs_.x_ref_mm[v.axis] = value;
        // Before initialization the mode may still change: checked at its end.
        if (changed && running()) warn_ignored_reference(fmt::format("at t = {} s", t_comm_s_).c_str());
      } else if (v.kind == VarKind::kSpindleInput) inputs_.spindle_rpm = value;
      else inputs_.F_ext_N[v.axis] = value;
      return;
    default:
      throw ConfigError(fmt::format("{} (valueReference {}) is an output and cannot be set", v.name, vr));
  }
}

void Slave::set_integer(std::size_t vr, int value) {
  const Variable& v = variable(vr, VarType::kInteger);
  if (v.kind != VarKind::kMode)
    throw ConfigError(fmt::format("{} (valueReference {}) is an output and cannot be set", v.name, vr));
  if (running()) throw ConfigError("mode is fixed and cannot be set while the co-simulation runs");
  if (value != kModeExternal && value != kModeProgram)
    throw ConfigError(fmt::format("mode = {} must be {} (x_ref_mm inputs) or {} (part program)", value,
                                  kModeExternal, kModeProgram));
  if (value == kModeProgram && !model_.has_program())
    throw ConfigError(fmt::format("mode = {}: scenario '{}' has no part program", value, model_.name));
  reference_mode_ = value;
}

void Slave::set_boolean(std::size_t vr, bool value) {
  const Variable& v = variable(vr, VarType::kBoolean);
  if (v.kind != VarKind::kSpindleOverride)
    throw ConfigError(fmt::format("{} (valueReference {}) is an output and cannot be set", v.name, vr));
  inputs_.spindle_override = value;
}

std::vector<double> Slave::parameter_values() const {
  std::vector<double> out;
  for (const auto& v : vars_)
    if (v.kind == VarKind::kMachineParam || v.kind == VarKind::kAxisParam) out.push_back(get_parameter(v, machine_));
  return out;
}

void Slave::apply_parameter_values(const std::vector<double>& values) {
  std::size_t i = 0;
  for (const auto& v : vars_) {
    if (v.kind != VarKind::kMachineParam && v.kind != VarKind::kAxisParam) continue;
    if (i >= values.size()) throw ConfigError(fmt::format("FMU state: {} parameter values, the table has more", values.size()));
    const double value = values[i++];
    if (get_parameter(v, machine_) == value) continue;
    if (v.kind == VarKind::kMachineParam) v.machine_param->ref(machine_) = value;
    else sim::set_axis_param(machine_.axes[v.axis], *v.axis_param, value);
    machine_changed_ = true;
  }
  if (i != values.size()) throw ConfigError(fmt::format("FMU state: {} parameter values, the table has {}", values.size(), i));
}

SavedState Slave::save(std::int32_t host_state) const {
  SavedState s;
  s.identity = identity_;
  s.host_state = host_state;
  s.reference_mode = reference_mode_;
  s.parameters = parameter_values();
  s.inputs = inputs_;
  s.t_start_s = t_start_s_;
  s.t_comm_s = t_comm_s_;
  s.stop_defined = stop_defined_;
  s.stop_s = stop_s_;
  s.has_cosim = cosim_ != nullptr;
  if (cosim_) s.cosim = cosim_->get_state();
  return s;
}

namespace {

bool finite_all(std::initializer_list<double> values) {
  for (double v : values)
    if (!std::isfinite(v)) return false;
  return true;
}

}  // namespace

void Slave::check_state(const SavedState& s) const {
  auto refuse = [](const std::string& why) { throw ConfigError(fmt::format("the FMU state is refused: {}", why)); };
  if (s.magic != kStateMagic) refuse("it was not made by this FMU");
  if (s.identity != identity_)
    refuse(fmt::format("it was made by the FMU with GUID {} (another scenario, machine or parameter set); this FMU is {}",
                       s.identity.empty() ? "?" : s.identity, identity_));
  if (s.reference_mode != kModeExternal && s.reference_mode != kModeProgram)
    refuse(fmt::format("mode = {} (must be {} or {})", s.reference_mode, kModeExternal, kModeProgram));
  if (s.reference_mode == kModeProgram && !model_.has_program()) refuse("mode 2 without a part program");
  const std::size_t n_params = parameter_values().size();
  if (s.parameters.size() != n_params)
    refuse(fmt::format("it has {} parameter values, this FMU {}", s.parameters.size(), n_params));
  // The parameters must make a machine this FMU accepts.
  sim::MachineDefinition machine = model_.machine;
  std::size_t i = 0;
  for (const auto& v : vars_) {
    if (v.kind != VarKind::kMachineParam && v.kind != VarKind::kAxisParam) continue;
    const double value = s.parameters[i++];
    if (!std::isfinite(value)) refuse(fmt::format("parameter {} = {}", v.name, value));
    if (get_parameter(v, machine) == value) continue;
    if (v.kind == VarKind::kMachineParam) v.machine_param->ref(machine) = value;
    else sim::set_axis_param(machine.axes[v.axis], *v.axis_param, value);
  }
  try {
    machine.validate();
  } catch (const Error& e) {
    refuse(fmt::format("its parameters are not valid: {}", e.what()));
  }
  if (!finite_all({s.inputs.x_ref_mm[0], s.inputs.x_ref_mm[1], s.inputs.x_ref_mm[2], s.inputs.F_ext_N[0],
                   s.inputs.F_ext_N[1], s.inputs.F_ext_N[2], s.inputs.spindle_rpm, s.t_start_s, s.t_comm_s, s.stop_s}))
    refuse("a non-finite input or time");
  if (s.stop_defined && s.stop_s < s.t_start_s) refuse(fmt::format("stop time {} s before its start time {} s", s.stop_s, s.t_start_s));
  if (!s.has_cosim) {
    if (s.t_comm_s != s.t_start_s) refuse("a communication point without a co-simulation");
    return;
  }
  const sim::CoSimState& c = s.cosim;
  const double Ts = machine.Ts_s;
  if (c.k < 0) refuse(fmt::format("tick counter {} < 0", c.k));
  const double tol = 1e-9 * std::max(1.0, std::abs(s.t_comm_s));
  const double t_k = s.t_start_s + static_cast<double>(c.k) * Ts;
  // The communication point lies in the last tick run: (t_k - Ts, t_k].
  if (s.t_comm_s > t_k + tol || (c.k > 0 && s.t_comm_s <= t_k - Ts + tol) || (c.k == 0 && s.t_comm_s < t_k - tol))
    refuse(fmt::format("communication point {} s does not match {} ticks of {} s from {} s", s.t_comm_s, c.k, Ts,
                       s.t_start_s));
  if (s.stop_defined && s.t_comm_s > s.stop_s + tol) refuse("communication point past its stop time");
  const std::size_t n_axes = machine.present_axes().size();
  if (c.drives.size() != n_axes || c.loops.size() != n_axes)
    refuse(fmt::format("{} drive and {} loop states for {} axes", c.drives.size(), c.loops.size(), n_axes));
  for (std::size_t j = 0; j < n_axes; ++j) {
    const feeddrive::DriveState& d = c.drives[j];
    const feeddrive::DriveParams& p = machine.axes[index(machine.present_axes()[j])].drive;
    const std::size_t delay_ticks =
        p.effects.delay.enabled ? static_cast<std::size_t>(std::llround(p.effects.delay.delay_s / Ts)) : 0;
    if (d.u_delay_V.size() != delay_ticks || (delay_ticks > 0 && d.u_delay_head >= delay_ticks))
      refuse(fmt::format("a command delay of {} ticks (head {}) where the machine has {}", d.u_delay_V.size(),
                         d.u_delay_head, delay_ticks));
    if (!finite_all({d.x_mm, d.w_rad_per_s, d.x_load_mm, d.w_load_rad_per_s, d.x_table_mm, d.work_electrical_J,
                     d.work_friction_J, d.work_damping_J, d.work_load_J}))
      refuse("a non-finite drive state");
    for (double u : d.u_delay_V)
      if (!std::isfinite(u)) refuse("a non-finite delayed command");
  }
  for (const auto& l : c.loops) {
    if (!finite_all({l.I_mm_s, l.e_prev_mm, l.x_ref_prev_mm, l.v_ref_prev_mm_per_s, l.Iv_rad, l.T_filtered, l.x_meas_prev_mm,
                     l.ref_lagged_mm}))
      refuse("a non-finite position-loop state");
    for (double x : l.ref_window)
      if (!std::isfinite(x)) refuse("a non-finite reference in the position loop's smoothing");
    for (double x : l.ref_delay_line)
      if (!std::isfinite(x)) refuse("a non-finite reference in the position loop's dead time");
    if (l.last_k >= c.k || l.last_k < -1) refuse(fmt::format("position-loop tick {} with tick counter {}", l.last_k, c.k));
  }
  if (c.k > 0 && c.last.k != c.k - 1) refuse(fmt::format("last row of tick {} with tick counter {}", c.last.k, c.k));
}

void Slave::restore(const SavedState& s) {
  check_state(s);
  const bool mode_changed = s.reference_mode != reference_mode_;
  const bool from_failure = std::exchange(failed_, false);
  apply_parameter_values(s.parameters);
  reference_mode_ = s.reference_mode;
  inputs_ = s.inputs;
  t_start_s_ = s.t_start_s;
  t_comm_s_ = s.t_comm_s;
  stop_defined_ = s.stop_defined;
  stop_s_ = s.stop_s;
  if (s.has_cosim) {
    if (!cosim_ || machine_changed_ || mode_changed || from_failure) build_cosim();
    cosim_->set_state(s.cosim);
  } else {
    cosim_.reset();
    external_.reset();
  }
}

}  // namespace twin::fmu
