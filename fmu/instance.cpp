#include "fmu/instance.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

#include <fmt/format.h>

#include "controller/encoder.hpp"
#include "controller/gcode.hpp"
#include "controller/interpolator.hpp"
#include "fmu/model_description.hpp"
#include "twin/core/error.hpp"

namespace twin::fmu {

const char* mode_name(FmuMode m) {
  switch (m) {
    case FmuMode::kInstantiated: return "instantiated";
    case FmuMode::kInitialization: return "initialization mode";
    case FmuMode::kStepMode: return "step mode";
    case FmuMode::kTerminated: return "terminated";
    case FmuMode::kError: return "error";
  }
  return "?";
}

FmuInstance::FmuInstance(std::string instance_name, FmuModel model, std::string guid)
    : name_(std::move(instance_name)), model_(std::move(model)), guid_(std::move(guid)) {
  if (guid_.empty()) guid_ = model_guid(model_);
  vars_ = make_variables(model_.machine);
  reset();
}

void FmuInstance::reset() {
  machine_ = model_.machine;
  mode_ = FmuMode::kInstantiated;
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
}

std::int64_t FmuInstance::ticks() const noexcept { return cosim_ ? cosim_->tick() : 0; }

void FmuInstance::require(std::initializer_list<FmuMode> allowed) const {
  for (FmuMode m : allowed)
    if (m == mode_) return;
  throw ConfigError(fmt::format("not allowed in state '{}'", mode_name(mode_)));
}

void FmuInstance::setup_experiment(double start_s, bool stop_defined, double stop_s) {
  require({FmuMode::kInstantiated});
  if (!std::isfinite(start_s)) throw ConfigError(fmt::format("startTime = {} must be finite", start_s));
  if (stop_defined && !(std::isfinite(stop_s) && stop_s >= start_s))
    throw ConfigError(fmt::format("stopTime = {} must be finite and >= startTime = {}", stop_s, start_s));
  t_start_s_ = start_s;
  t_comm_s_ = start_s;
  stop_defined_ = stop_defined;
  stop_s_ = stop_defined ? stop_s : 0.0;
}

void FmuInstance::enter_initialization() {
  require({FmuMode::kInstantiated});
  mode_ = FmuMode::kInitialization;
}

void FmuInstance::build_cosim() {
  for (Axis a : machine_.present_axes()) machine_.axes[index(a)].loop.Ts_s = machine_.Ts_s;
  machine_.validate();
  std::shared_ptr<const sim::ReferenceSource> reference;
  if (reference_mode_ == kModeProgram) {
    if (!model_.has_program())
      throw ConfigError(fmt::format("mode = {}: scenario '{}' has no part program; use mode = {} (x_ref_mm inputs)",
                                    kModeProgram, model_.scenario_name, kModeExternal));
    // With the parameters as set now (travel, limits, Ts): checked again.
    reference = std::make_shared<sim::ProgramReference>(model_.plan_program(machine_));
    external_.reset();
  } else {
    external_ = std::make_shared<sim::ExternalReference>(inputs_.x_ref_mm);
    reference = external_;
  }
  cosim_ = std::make_unique<sim::CoSimulation>(machine_, reference, model_.make_process(), model_.start_mm);
  machine_changed_ = false;
}

void FmuInstance::exit_initialization() {
  require({FmuMode::kInitialization});
  build_cosim();
  t_comm_s_ = t_start_s_;
  mode_ = FmuMode::kStepMode;
  warn_ignored_reference("at the end of initialization");
}

void FmuInstance::warn_ignored_reference(const char* when) {
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

std::int64_t FmuInstance::do_step(double t_s, double h_s) {
  require({FmuMode::kStepMode});
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
                                  "given to fmi2SetupExperiment",
                                  t_s, h_s, stop_s_));
  // Ticks j with t_start + j Ts < t_end (a tick starting within tol_s of
  // t_end belongs to the next step).
  const double x = (t_end - t_start_s_) / Ts;
  const double x_round = std::round(x);
  const double n_end_real = std::abs(x - x_round) * Ts <= tol_s ? x_round : std::ceil(x);
  const auto k_now = cosim_->tick();
  const double n_real = std::max(0.0, n_end_real - static_cast<double>(k_now));
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

void FmuInstance::terminate() {
  require({FmuMode::kStepMode});
  mode_ = FmuMode::kTerminated;
}

sim::Snapshot FmuInstance::current_row() const {
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

const Variable& FmuInstance::variable(std::size_t vr, VarType type) const {
  if (vr >= vars_.size())
    throw ConfigError(fmt::format("unknown valueReference {} (the FMU has 0..{})", vr, vars_.size() - 1));
  const Variable& v = vars_[vr];
  if (v.type != type) throw ConfigError(fmt::format("valueReference {} ('{}') is not of this type", vr, v.name));
  return v;
}

double FmuInstance::get_real(std::size_t vr) const {
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

int FmuInstance::get_integer(std::size_t vr) const {
  const Variable& v = variable(vr, VarType::kInteger);
  if (v.kind == VarKind::kMode) return reference_mode_;
  return current_row().block;
}

bool FmuInstance::get_boolean(std::size_t vr) const {
  const Variable& v = variable(vr, VarType::kBoolean);
  if (v.kind == VarKind::kSpindleOverride) return inputs_.spindle_override;
  return current_row().reference_done;
}

void FmuInstance::set_real(std::size_t vr, double value) {
  const Variable& v = variable(vr, VarType::kReal);
  if (!std::isfinite(value)) throw ConfigError(fmt::format("{} = {} must be finite", v.name, value));
  const bool before_run = mode_ == FmuMode::kInstantiated || mode_ == FmuMode::kInitialization;
  switch (v.kind) {
    case VarKind::kMachineParam:
    case VarKind::kAxisParam: {
      if (!before_run && !(mode_ == FmuMode::kStepMode && v.variability == Variability::kTunable))
        throw ConfigError(fmt::format("parameter {} cannot be set in state '{}'{}", v.name, mode_name(mode_),
                                      v.variability == Variability::kFixed ? " (it is fixed)" : ""));
      // Setting a value it already has changes nothing (an effect's parameter
      // would otherwise switch its effect on).
      if (get_parameter(v, machine_) == value) return;
      if (v.kind == VarKind::kMachineParam) v.machine_param->ref(machine_) = value;
      else sim::set_axis_param(machine_.axes[v.axis], *v.axis_param, value);
      if (mode_ == FmuMode::kStepMode) {
        sim::MachineDefinition check = machine_;
        check.validate();
        machine_changed_ = true;
      }
      return;
    }
    case VarKind::kRefInput:
    case VarKind::kSpindleInput:
    case VarKind::kForceInput:
      if (!before_run && mode_ != FmuMode::kStepMode)
        throw ConfigError(fmt::format("input {} cannot be set in state '{}'", v.name, mode_name(mode_)));
      if (v.kind == VarKind::kRefInput) {
        const bool changed = inputs_.x_ref_mm[v.axis] != value;
        inputs_.x_ref_mm[v.axis] = value;
        // Before initialization the mode may still change: checked at its end.
        if (changed && mode_ == FmuMode::kStepMode) warn_ignored_reference(fmt::format("at t = {} s", t_comm_s_).c_str());
      } else if (v.kind == VarKind::kSpindleInput) inputs_.spindle_rpm = value;
      else inputs_.F_ext_N[v.axis] = value;
      return;
    default:
      throw ConfigError(fmt::format("{} (valueReference {}) is an output and cannot be set", v.name, vr));
  }
}

void FmuInstance::set_integer(std::size_t vr, int value) {
  const Variable& v = variable(vr, VarType::kInteger);
  if (v.kind != VarKind::kMode)
    throw ConfigError(fmt::format("{} (valueReference {}) is an output and cannot be set", v.name, vr));
  if (mode_ != FmuMode::kInstantiated && mode_ != FmuMode::kInitialization)
    throw ConfigError(fmt::format("mode is fixed and cannot be set in state '{}'", mode_name(mode_)));
  if (value != kModeExternal && value != kModeProgram)
    throw ConfigError(fmt::format("mode = {} must be {} (x_ref_mm inputs) or {} (part program)", value,
                                  kModeExternal, kModeProgram));
  if (value == kModeProgram && !model_.has_program())
    throw ConfigError(fmt::format("mode = {}: scenario '{}' has no part program", value, model_.scenario_name));
  reference_mode_ = value;
}

void FmuInstance::set_boolean(std::size_t vr, bool value) {
  const Variable& v = variable(vr, VarType::kBoolean);
  if (v.kind != VarKind::kSpindleOverride)
    throw ConfigError(fmt::format("{} (valueReference {}) is an output and cannot be set", v.name, vr));
  if (mode_ == FmuMode::kTerminated || mode_ == FmuMode::kError)
    throw ConfigError(fmt::format("input {} cannot be set in state '{}'", v.name, mode_name(mode_)));
  inputs_.spindle_override = value;
}

std::vector<double> FmuInstance::parameter_values() const {
  std::vector<double> out;
  for (const auto& v : vars_)
    if (v.kind == VarKind::kMachineParam || v.kind == VarKind::kAxisParam) out.push_back(get_parameter(v, machine_));
  return out;
}

void FmuInstance::apply_parameter_values(const std::vector<double>& values) {
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

SavedState FmuInstance::save() const {
  require({FmuMode::kInstantiated, FmuMode::kInitialization, FmuMode::kStepMode, FmuMode::kTerminated});
  SavedState s;
  s.guid = guid_;
  s.mode = mode_;
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

void FmuInstance::check_state(const SavedState& s) const {
  auto refuse = [](const std::string& why) { throw ConfigError(fmt::format("the FMU state is refused: {}", why)); };
  if (s.magic != kStateMagic) refuse("it was not made by this FMU");
  if (s.guid != guid_)
    refuse(fmt::format("it was made by the FMU with GUID {} (another scenario, machine or parameter set); this FMU is {}",
                       s.guid.empty() ? "?" : s.guid, guid_));
  if (s.mode == FmuMode::kError || static_cast<int>(s.mode) < 0 || static_cast<int>(s.mode) > static_cast<int>(FmuMode::kError))
    refuse(fmt::format("call state {} cannot be restored", static_cast<int>(s.mode)));
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
  for (Axis a : machine.present_axes()) machine.axes[index(a)].loop.Ts_s = machine.Ts_s;
  try {
    machine.validate();
  } catch (const Error& e) {
    refuse(fmt::format("its parameters are not valid: {}", e.what()));
  }
  if (!finite_all({s.inputs.x_ref_mm[0], s.inputs.x_ref_mm[1], s.inputs.x_ref_mm[2], s.inputs.F_ext_N[0],
                   s.inputs.F_ext_N[1], s.inputs.F_ext_N[2], s.inputs.spindle_rpm, s.t_start_s, s.t_comm_s, s.stop_s}))
    refuse("a non-finite input or time");
  const bool running = s.mode == FmuMode::kStepMode || s.mode == FmuMode::kTerminated;
  if (s.has_cosim != running)
    refuse(fmt::format("call state '{}' {} a running co-simulation", mode_name(s.mode), s.has_cosim ? "with" : "without"));
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
    if (!finite_all({l.I_mm_s, l.e_prev_mm, l.x_ref_prev_mm, l.v_ref_prev_mm_per_s, l.Iv_rad, l.T_filtered, l.x_meas_prev_mm}))
      refuse("a non-finite position-loop state");
    if (l.last_k >= c.k || l.last_k < -1) refuse(fmt::format("position-loop tick {} with tick counter {}", l.last_k, c.k));
  }
  if (c.k > 0 && c.last.k != c.k - 1) refuse(fmt::format("last row of tick {} with tick counter {}", c.last.k, c.k));
}

void FmuInstance::restore(const SavedState& s) {
  require({FmuMode::kInstantiated, FmuMode::kInitialization, FmuMode::kStepMode, FmuMode::kTerminated,
           FmuMode::kError});
  check_state(s);
  const bool mode_changed = s.reference_mode != reference_mode_;
  const bool from_error = mode_ == FmuMode::kError;
  apply_parameter_values(s.parameters);
  reference_mode_ = s.reference_mode;
  inputs_ = s.inputs;
  t_start_s_ = s.t_start_s;
  t_comm_s_ = s.t_comm_s;
  stop_defined_ = s.stop_defined;
  stop_s_ = s.stop_s;
  if (s.has_cosim) {
    if (!cosim_ || machine_changed_ || mode_changed || from_error) build_cosim();
    cosim_->set_state(s.cosim);
  } else {
    cosim_.reset();
    external_.reset();
  }
  mode_ = s.mode;
}

// ---- serialisation -------------------------------------------------------

namespace {

constexpr char kMagic[8] = {'T', 'W', 'I', 'N', 'F', 'M', 'U', '2'};

class Writer {
 public:
  template <class T>
  void put(const T& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    const char* p = reinterpret_cast<const char*>(&v);
    bytes_.insert(bytes_.end(), p, p + sizeof(T));
  }
  void put_doubles(const std::vector<double>& v) {
    put<std::uint64_t>(v.size());
    for (double d : v) put(d);
  }
  void put_string(const std::string& v) {
    put<std::uint64_t>(v.size());
    bytes_.insert(bytes_.end(), v.begin(), v.end());
  }
  std::vector<char> take() { return std::move(bytes_); }

 private:
  std::vector<char> bytes_;
};

class Reader {
 public:
  Reader(const char* data, std::size_t size) : p_(data), end_(data + size) {}
  template <class T>
  T get() {
    static_assert(std::is_trivially_copyable_v<T>);
    if (static_cast<std::size_t>(end_ - p_) < sizeof(T))
      throw ConfigError("the serialized state is truncated");
    T v;
    std::memcpy(&v, p_, sizeof(T));
    p_ += sizeof(T);
    return v;
  }
  std::vector<double> get_doubles() {
    const auto n = get<std::uint64_t>();
    if (n > static_cast<std::uint64_t>(end_ - p_) / sizeof(double))
      throw ConfigError(fmt::format("a list of {} numbers overruns the state", n));
    std::vector<double> v(n);
    for (auto& d : v) d = get<double>();
    return v;
  }
  std::string get_string() {
    const auto n = get<std::uint64_t>();
    if (n > static_cast<std::uint64_t>(end_ - p_))
      throw ConfigError(fmt::format("a text of {} bytes overruns the state", n));
    std::string v(p_, p_ + n);
    p_ += n;
    return v;
  }
  bool at_end() const noexcept { return p_ == end_; }

 private:
  const char* p_;
  const char* end_;
};

void put_snapshot(Writer& w, const sim::Snapshot& s) {
  w.put(s.k);
  w.put(s.t_s);
  for (const auto& a : s.axes) {
    for (double d : {a.x_ref_mm, a.x_mm, a.x_true_mm, a.e_mm, a.u_V, a.i_A, a.Tm_Nm, a.Td_Nm, a.v_mm_per_s}) w.put(d);
    w.put<std::uint8_t>(a.saturated ? 1 : 0);
  }
  for (double d : s.F_N) w.put(d);
  for (double d : s.F_avg_N) w.put(d);
  for (double d : {s.spindle_rpm, s.engagement_deg, s.chip_mm, s.spindle_torque_Nm, s.cutting_power_W,
                   s.feed_programmed_mm_per_min, s.feed_ref_mm_per_min, s.feed_real_mm_per_min, s.contour_error_mm})
    w.put(d);
  w.put(s.block);
  w.put<std::uint8_t>(s.reference_done ? 1 : 0);
}

sim::Snapshot get_snapshot(Reader& r) {
  sim::Snapshot s;
  s.k = r.get<std::int64_t>();
  s.t_s = r.get<double>();
  for (auto& a : s.axes) {
    for (double* d : {&a.x_ref_mm, &a.x_mm, &a.x_true_mm, &a.e_mm, &a.u_V, &a.i_A, &a.Tm_Nm, &a.Td_Nm, &a.v_mm_per_s})
      *d = r.get<double>();
    a.saturated = r.get<std::uint8_t>() != 0;
  }
  for (double& d : s.F_N) d = r.get<double>();
  for (double& d : s.F_avg_N) d = r.get<double>();
  for (double* d : {&s.spindle_rpm, &s.engagement_deg, &s.chip_mm, &s.spindle_torque_Nm, &s.cutting_power_W,
                    &s.feed_programmed_mm_per_min, &s.feed_ref_mm_per_min, &s.feed_real_mm_per_min,
                    &s.contour_error_mm})
    *d = r.get<double>();
  s.block = r.get<int>();
  s.reference_done = r.get<std::uint8_t>() != 0;
  return s;
}

}  // namespace

std::vector<char> serialize_state(const SavedState& s) {
  if (s.has_cosim && s.cosim.process)
    throw ConfigError("the cutting process cannot be serialized (canSerializeFMUstate=false)");
  Writer w;
  for (char c : kMagic) w.put(c);
  w.put_string(s.guid);
  w.put(static_cast<std::int32_t>(s.mode));
  w.put(static_cast<std::int32_t>(s.reference_mode));
  w.put_doubles(s.parameters);
  for (double d : s.inputs.x_ref_mm) w.put(d);
  for (double d : s.inputs.F_ext_N) w.put(d);
  w.put(s.inputs.spindle_rpm);
  w.put<std::uint8_t>(s.inputs.spindle_override ? 1 : 0);
  w.put(s.t_start_s);
  w.put(s.t_comm_s);
  w.put<std::uint8_t>(s.stop_defined ? 1 : 0);
  w.put(s.stop_s);
  w.put<std::uint8_t>(s.has_cosim ? 1 : 0);
  if (s.has_cosim) {
    const sim::CoSimState& c = s.cosim;
    w.put(c.k);
    w.put<std::uint64_t>(c.drives.size());
    for (const auto& d : c.drives) {
      for (double v : {d.x_mm, d.w_rad_per_s, d.x_load_mm, d.w_load_rad_per_s, d.x_table_mm, d.work_electrical_J,
                       d.work_friction_J, d.work_damping_J, d.work_load_J})
        w.put(v);
      w.put<std::uint8_t>(d.stuck ? 1 : 0);
      w.put<std::uint8_t>(d.load_stuck ? 1 : 0);
      w.put_doubles(d.u_delay_V);
      w.put<std::uint64_t>(d.u_delay_head);
    }
    w.put<std::uint64_t>(c.loops.size());
    for (const auto& l : c.loops) {
      for (double v : {l.I_mm_s, l.e_prev_mm, l.x_ref_prev_mm, l.v_ref_prev_mm_per_s, l.Iv_rad, l.T_filtered,
                       l.x_meas_prev_mm})
        w.put(v);
      w.put(l.last_k);
    }
    put_snapshot(w, c.last);
    w.put<std::uint64_t>(c.clamp_watch.size());
    for (const auto& cw : c.clamp_watch)
      for (int v : {cw.ticks_in_block, cw.saturated_ticks, cw.flips, cw.bad_blocks}) w.put<std::int32_t>(v);
  }
  return w.take();
}

SavedState deserialize_state(const char* data, std::size_t size) {
  Reader r(data, size);
  for (char c : kMagic)
    if (r.get<char>() != c) throw ConfigError("not a state serialized by this FMU");
  SavedState s;
  s.guid = r.get_string();
  const auto mode = r.get<std::int32_t>();
  if (mode < 0 || mode > static_cast<std::int32_t>(FmuMode::kError))
    throw ConfigError(fmt::format("state {} is not a state of the FMU", mode));
  s.mode = static_cast<FmuMode>(mode);
  s.reference_mode = r.get<std::int32_t>();
  s.parameters = r.get_doubles();
  for (double& d : s.inputs.x_ref_mm) d = r.get<double>();
  for (double& d : s.inputs.F_ext_N) d = r.get<double>();
  s.inputs.spindle_rpm = r.get<double>();
  s.inputs.spindle_override = r.get<std::uint8_t>() != 0;
  s.t_start_s = r.get<double>();
  s.t_comm_s = r.get<double>();
  s.stop_defined = r.get<std::uint8_t>() != 0;
  s.stop_s = r.get<double>();
  s.has_cosim = r.get<std::uint8_t>() != 0;
  if (s.has_cosim) {
    sim::CoSimState& c = s.cosim;
    c.k = r.get<std::int64_t>();
    const auto nd = r.get<std::uint64_t>();
    if (nd > kNumAxes) throw ConfigError(fmt::format("{} drives", nd));
    c.drives.resize(nd);
    for (auto& d : c.drives) {
      for (double* v : {&d.x_mm, &d.w_rad_per_s, &d.x_load_mm, &d.w_load_rad_per_s, &d.x_table_mm, &d.work_electrical_J,
                        &d.work_friction_J, &d.work_damping_J, &d.work_load_J})
        *v = r.get<double>();
      d.stuck = r.get<std::uint8_t>() != 0;
      d.load_stuck = r.get<std::uint8_t>() != 0;
      d.u_delay_V = r.get_doubles();
      d.u_delay_head = r.get<std::uint64_t>();
    }
    const auto nl = r.get<std::uint64_t>();
    if (nl > kNumAxes) throw ConfigError(fmt::format("{} position loops", nl));
    c.loops.resize(nl);
    for (auto& l : c.loops) {
      for (double* v : {&l.I_mm_s, &l.e_prev_mm, &l.x_ref_prev_mm, &l.v_ref_prev_mm_per_s, &l.Iv_rad, &l.T_filtered,
                        &l.x_meas_prev_mm})
        *v = r.get<double>();
      l.last_k = r.get<std::int64_t>();
    }
    c.last = get_snapshot(r);
    const auto nw = r.get<std::uint64_t>();
    if (nw > kNumAxes) throw ConfigError(fmt::format("{} clamp watches", nw));
    c.clamp_watch.resize(nw);
    for (auto& cw : c.clamp_watch)
      for (int* v : {&cw.ticks_in_block, &cw.saturated_ticks, &cw.flips, &cw.bad_blocks}) *v = r.get<std::int32_t>();
  }
  if (!r.at_end()) throw ConfigError("trailing bytes after the state");
  return s;
}

}  // namespace twin::fmu
