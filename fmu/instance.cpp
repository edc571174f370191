#include "fmu/instance.hpp"

#include <cmath>
#include <cstring>

#include <fmt/format.h>

#include "controller/encoder.hpp"
#include "controller/gcode.hpp"
#include "controller/interpolator.hpp"
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

FmuInstance::FmuInstance(std::string instance_name, FmuModel model)
    : name_(std::move(instance_name)), model_(std::move(model)) {
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
  machine_changed_ = false;
  external_.reset();
  cosim_.reset();
}

double FmuInstance::time_s() const noexcept {
  const std::int64_t k = cosim_ ? cosim_->tick() : 0;
  return t_start_s_ + static_cast<double>(k) * machine_.Ts_s;
}

void FmuInstance::require(const char* function, std::initializer_list<FmuMode> allowed) const {
  for (FmuMode m : allowed)
    if (m == mode_) return;
  throw ConfigError(fmt::format("{} is not allowed in state '{}'", function, mode_name(mode_)));
}

void FmuInstance::setup_experiment(double start_s) {
  require("fmi2SetupExperiment", {FmuMode::kInstantiated});
  if (!std::isfinite(start_s)) throw ConfigError(fmt::format("fmi2SetupExperiment: startTime = {} must be finite", start_s));
  t_start_s_ = start_s;
}

void FmuInstance::enter_initialization() {
  require("fmi2EnterInitializationMode", {FmuMode::kInstantiated});
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
    const controller::Program program =
        controller::parse_gcode(model_.program_text, model_.program_name, model_.start_mm, machine_.rapid_mm_per_min);
    reference = std::make_shared<sim::ProgramReference>(
        controller::plan_trajectory(program, machine_.motion_limits(), machine_.Ts_s));
    external_.reset();
  } else {
    external_ = std::make_shared<sim::ExternalReference>(inputs_.x_ref_mm);
    reference = external_;
  }
  cosim_ = std::make_unique<sim::CoSimulation>(machine_, reference, model_.make_process(), model_.start_mm);
  machine_changed_ = false;
}

void FmuInstance::exit_initialization() {
  require("fmi2ExitInitializationMode", {FmuMode::kInitialization});
  build_cosim();
  mode_ = FmuMode::kStepMode;
}

void FmuInstance::do_step(double t_s, double h_s) {
  require("fmi2DoStep", {FmuMode::kStepMode});
  const double Ts = machine_.Ts_s;
  if (!std::isfinite(h_s) || !(h_s > 0.0))
    throw ConfigError(fmt::format("fmi2DoStep: communicationStepSize = {} s must be > 0 (a multiple of Ts = {} s)", h_s, Ts));
  const double n_real = std::round(h_s / Ts);
  if (n_real < 1.0 || n_real > 1e12 || std::abs(n_real * Ts - h_s) > 1e-9 * std::max(1.0, h_s))
    throw ConfigError(fmt::format(
        "fmi2DoStep: communicationStepSize = {:.17g} s is not a whole number of controller ticks Ts = {} s ({:.9g} ticks)",
        h_s, Ts, h_s / Ts));
  const double expected = time_s();
  if (!std::isfinite(t_s) || std::abs(t_s - expected) > 1e-9 * std::max(1.0, std::abs(expected)))
    throw ConfigError(fmt::format(
        "fmi2DoStep: currentCommunicationPoint = {:.17g} s, expected {:.17g} s (start {} s + {} ticks of {} s)", t_s,
        expected, t_start_s_, cosim_->tick(), Ts));
  if (machine_changed_) {
    const sim::CoSimState state = cosim_->get_state();
    build_cosim();
    cosim_->set_state(state);
  }
  if (external_) external_->set(inputs_.x_ref_mm);
  cosim_->set_external_force_N(inputs_.F_ext_N);
  cosim_->set_spindle_override_rpm(inputs_.spindle_override ? std::optional<double>(inputs_.spindle_rpm)
                                                            : std::optional<double>());
  const auto n = static_cast<std::int64_t>(n_real);
  for (std::int64_t i = 0; i < n; ++i) cosim_->step();
}

void FmuInstance::terminate() {
  require("fmi2Terminate", {FmuMode::kStepMode});
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

const Variable& FmuInstance::variable(std::size_t vr, VarType type, const char* function) const {
  if (vr >= vars_.size())
    throw ConfigError(fmt::format("{}: unknown valueReference {} (the FMU has 0..{})", function, vr, vars_.size() - 1));
  const Variable& v = vars_[vr];
  if (v.type != type) throw ConfigError(fmt::format("{}: valueReference {} ('{}') has another type", function, vr, v.name));
  return v;
}

double FmuInstance::get_real(std::size_t vr) const {
  const Variable& v = variable(vr, VarType::kReal, "fmi2GetReal");
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
  throw InternalError(fmt::format("fmi2GetReal: variable '{}' has no Real value", v.name));
}

int FmuInstance::get_integer(std::size_t vr) const {
  const Variable& v = variable(vr, VarType::kInteger, "fmi2GetInteger");
  if (v.kind == VarKind::kMode) return reference_mode_;
  return current_row().block;
}

bool FmuInstance::get_boolean(std::size_t vr) const {
  const Variable& v = variable(vr, VarType::kBoolean, "fmi2GetBoolean");
  if (v.kind == VarKind::kSpindleOverride) return inputs_.spindle_override;
  return current_row().reference_done;
}

void FmuInstance::set_real(std::size_t vr, double value) {
  const Variable& v = variable(vr, VarType::kReal, "fmi2SetReal");
  if (!std::isfinite(value)) throw ConfigError(fmt::format("fmi2SetReal: {} = {} must be finite", v.name, value));
  const bool before_run = mode_ == FmuMode::kInstantiated || mode_ == FmuMode::kInitialization;
  switch (v.kind) {
    case VarKind::kMachineParam:
    case VarKind::kAxisParam: {
      if (!before_run && !(mode_ == FmuMode::kStepMode && v.variability == Variability::kTunable))
        throw ConfigError(fmt::format("fmi2SetReal: parameter {} cannot be set in state '{}'{}", v.name, mode_name(mode_),
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
        throw ConfigError(fmt::format("fmi2SetReal: input {} cannot be set in state '{}'", v.name, mode_name(mode_)));
      if (v.kind == VarKind::kRefInput) inputs_.x_ref_mm[v.axis] = value;
      else if (v.kind == VarKind::kSpindleInput) inputs_.spindle_rpm = value;
      else inputs_.F_ext_N[v.axis] = value;
      return;
    default:
      throw ConfigError(fmt::format("fmi2SetReal: {} (valueReference {}) is an output and cannot be set", v.name, vr));
  }
}

void FmuInstance::set_integer(std::size_t vr, int value) {
  const Variable& v = variable(vr, VarType::kInteger, "fmi2SetInteger");
  if (v.kind != VarKind::kMode)
    throw ConfigError(fmt::format("fmi2SetInteger: {} (valueReference {}) is an output and cannot be set", v.name, vr));
  if (mode_ != FmuMode::kInstantiated && mode_ != FmuMode::kInitialization)
    throw ConfigError(fmt::format("fmi2SetInteger: mode is fixed and cannot be set in state '{}'", mode_name(mode_)));
  if (value != kModeExternal && value != kModeProgram)
    throw ConfigError(fmt::format("fmi2SetInteger: mode = {} must be {} (x_ref_mm inputs) or {} (part program)", value,
                                  kModeExternal, kModeProgram));
  if (value == kModeProgram && !model_.has_program())
    throw ConfigError(fmt::format("fmi2SetInteger: mode = {}: scenario '{}' has no part program", value, model_.scenario_name));
  reference_mode_ = value;
}

void FmuInstance::set_boolean(std::size_t vr, bool value) {
  const Variable& v = variable(vr, VarType::kBoolean, "fmi2SetBoolean");
  if (v.kind != VarKind::kSpindleOverride)
    throw ConfigError(fmt::format("fmi2SetBoolean: {} (valueReference {}) is an output and cannot be set", v.name, vr));
  if (mode_ == FmuMode::kTerminated || mode_ == FmuMode::kError)
    throw ConfigError(fmt::format("fmi2SetBoolean: input {} cannot be set in state '{}'", v.name, mode_name(mode_)));
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
  require("fmi2GetFMUstate", {FmuMode::kInstantiated, FmuMode::kInitialization, FmuMode::kStepMode, FmuMode::kTerminated});
  SavedState s;
  s.mode = mode_;
  s.reference_mode = reference_mode_;
  s.parameters = parameter_values();
  s.inputs = inputs_;
  s.t_start_s = t_start_s_;
  s.has_cosim = cosim_ != nullptr;
  if (cosim_) s.cosim = cosim_->get_state();
  return s;
}

void FmuInstance::restore(const SavedState& s) {
  require("fmi2SetFMUstate", {FmuMode::kInstantiated, FmuMode::kInitialization, FmuMode::kStepMode, FmuMode::kTerminated});
  const bool mode_changed = s.reference_mode != reference_mode_;
  apply_parameter_values(s.parameters);
  reference_mode_ = s.reference_mode;
  inputs_ = s.inputs;
  t_start_s_ = s.t_start_s;
  if (s.has_cosim) {
    if (!cosim_ || machine_changed_ || mode_changed) build_cosim();
    cosim_->set_state(s.cosim);
  } else {
    cosim_.reset();
    external_.reset();
  }
  mode_ = s.mode;
}

// ---- serialisation -------------------------------------------------------

namespace {

constexpr char kMagic[8] = {'T', 'W', 'I', 'N', 'F', 'M', 'U', '1'};

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
      throw ConfigError("fmi2DeSerializeFMUstate: the serialized state is truncated");
    T v;
    std::memcpy(&v, p_, sizeof(T));
    p_ += sizeof(T);
    return v;
  }
  std::vector<double> get_doubles() {
    const auto n = get<std::uint64_t>();
    if (n > static_cast<std::uint64_t>(end_ - p_) / sizeof(double))
      throw ConfigError(fmt::format("fmi2DeSerializeFMUstate: a list of {} numbers overruns the state", n));
    std::vector<double> v(n);
    for (auto& d : v) d = get<double>();
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
    throw ConfigError("fmi2SerializeFMUstate: the cutting process cannot be serialized (canSerializeFMUstate=false)");
  Writer w;
  for (char c : kMagic) w.put(c);
  w.put(static_cast<std::int32_t>(s.mode));
  w.put(static_cast<std::int32_t>(s.reference_mode));
  w.put_doubles(s.parameters);
  for (double d : s.inputs.x_ref_mm) w.put(d);
  for (double d : s.inputs.F_ext_N) w.put(d);
  w.put(s.inputs.spindle_rpm);
  w.put<std::uint8_t>(s.inputs.spindle_override ? 1 : 0);
  w.put(s.t_start_s);
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
      for (double v : {l.I_mm_s, l.e_prev_mm, l.x_ref_prev_mm, l.v_ref_prev_mm_per_s}) w.put(v);
      w.put(l.last_k);
    }
    put_snapshot(w, c.last);
  }
  return w.take();
}

SavedState deserialize_state(const char* data, std::size_t size) {
  Reader r(data, size);
  for (char c : kMagic)
    if (r.get<char>() != c) throw ConfigError("fmi2DeSerializeFMUstate: not a state serialized by this FMU");
  SavedState s;
  const auto mode = r.get<std::int32_t>();
  if (mode < 0 || mode > static_cast<std::int32_t>(FmuMode::kError))
    throw ConfigError(fmt::format("fmi2DeSerializeFMUstate: state {} is not a state of the FMU", mode));
  s.mode = static_cast<FmuMode>(mode);
  s.reference_mode = r.get<std::int32_t>();
  s.parameters = r.get_doubles();
  for (double& d : s.inputs.x_ref_mm) d = r.get<double>();
  for (double& d : s.inputs.F_ext_N) d = r.get<double>();
  s.inputs.spindle_rpm = r.get<double>();
  s.inputs.spindle_override = r.get<std::uint8_t>() != 0;
  s.t_start_s = r.get<double>();
  s.has_cosim = r.get<std::uint8_t>() != 0;
  if (s.has_cosim) {
    sim::CoSimState& c = s.cosim;
    c.k = r.get<std::int64_t>();
    const auto nd = r.get<std::uint64_t>();
    if (nd > kNumAxes) throw ConfigError(fmt::format("fmi2DeSerializeFMUstate: {} drives", nd));
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
    if (nl > kNumAxes) throw ConfigError(fmt::format("fmi2DeSerializeFMUstate: {} position loops", nl));
    c.loops.resize(nl);
    for (auto& l : c.loops) {
      for (double* v : {&l.I_mm_s, &l.e_prev_mm, &l.x_ref_prev_mm, &l.v_ref_prev_mm_per_s}) *v = r.get<double>();
      l.last_k = r.get<std::int64_t>();
    }
    c.last = get_snapshot(r);
  }
  if (!r.at_end()) throw ConfigError("fmi2DeSerializeFMUstate: trailing bytes after the state");
  return s;
}

}  // namespace twin::fmu
