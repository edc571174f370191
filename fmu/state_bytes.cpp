// Bytes of a slave's saved state (fmu/slave.hpp): serialize_state and
// deserialize_state, the format of the FMI Serialize/DeSerialize FMU state
// calls of both adapters.
#include <cstring>
#include <type_traits>

#include <fmt/format.h>

#include "fmu/slave.hpp"
#include "twin/core/error.hpp"

namespace twin::fmu {

namespace {

constexpr char kMagic[8] = {'T', 'W', 'I', 'N', 'F', 'M', 'U', '4'};

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
    for (double d : {a.x_ref_mm, a.x_mm, a.x_true_mm, a.e_mm, a.u_V, a.i_A, a.Tm_Nm, a.Tcmd_Nm, a.Td_Nm, a.v_mm_per_s,
                     a.vcmd_mm_per_s, a.period_mean.i_A, a.period_mean.Tm_Nm, a.period_mean.Tcmd_Nm})
      w.put(d);
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
    for (double* d : {&a.x_ref_mm, &a.x_mm, &a.x_true_mm, &a.e_mm, &a.u_V, &a.i_A, &a.Tm_Nm, &a.Tcmd_Nm, &a.Td_Nm,
                      &a.v_mm_per_s, &a.vcmd_mm_per_s, &a.period_mean.i_A, &a.period_mean.Tm_Nm,
                      &a.period_mean.Tcmd_Nm})
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
  w.put_string(s.identity);
  w.put(s.host_state);
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
                       l.x_meas_prev_mm, l.ref_lagged_mm})
        w.put(v);
      for (double v : l.ref_window) w.put(v);
      w.put<std::int32_t>(l.ref_window_head);
      for (double v : l.ref_delay_line) w.put(v);
      w.put<std::int32_t>(l.ref_delay_head);
      w.put(l.last_k);
    }
    put_snapshot(w, c.last);
    w.put<std::uint64_t>(c.clamp_watch.size());
    for (const auto& cw : c.clamp_watch)
      for (int v : {cw.ticks_in_block, cw.saturated_ticks, cw.flips, cw.bad_blocks}) w.put<std::int32_t>(v);
    w.put<std::uint64_t>(c.period_mean.size());
    for (const auto& pm : c.period_mean)
      for (double v : {pm.i_A, pm.Tm_Nm, pm.Tcmd_Nm}) w.put(v);
  }
  return w.take();
}

SavedState deserialize_state(const char* data, std::size_t size) {
  Reader r(data, size);
  for (char c : kMagic)
    if (r.get<char>() != c) throw ConfigError("not a state serialized by this FMU");
  SavedState s;
  s.identity = r.get_string();
  s.host_state = r.get<std::int32_t>();
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
                        &l.x_meas_prev_mm, &l.ref_lagged_mm})
        *v = r.get<double>();
      for (double& v : l.ref_window) v = r.get<double>();
      l.ref_window_head = r.get<std::int32_t>();
      if (l.ref_window_head < 0 || l.ref_window_head >= controller::kMaxCommandAverageTicks)
        throw ConfigError(fmt::format("reference window at {}", l.ref_window_head));
      for (double& v : l.ref_delay_line) v = r.get<double>();
      l.ref_delay_head = r.get<std::int32_t>();
      if (l.ref_delay_head < 0 || l.ref_delay_head > controller::kMaxCommandDelayTicks)
        throw ConfigError(fmt::format("reference delay line at {}", l.ref_delay_head));
      l.last_k = r.get<std::int64_t>();
    }
    c.last = get_snapshot(r);
    const auto nw = r.get<std::uint64_t>();
    if (nw > kNumAxes) throw ConfigError(fmt::format("{} clamp watches", nw));
    c.clamp_watch.resize(nw);
    for (auto& cw : c.clamp_watch)
      for (int* v : {&cw.ticks_in_block, &cw.saturated_ticks, &cw.flips, &cw.bad_blocks}) *v = r.get<std::int32_t>();
    const auto nm = r.get<std::uint64_t>();
    if (nm > kNumAxes) throw ConfigError(fmt::format("{} period means", nm));
    c.period_mean.resize(nm);
    for (auto& pm : c.period_mean)
      for (double* v : {&pm.i_A, &pm.Tm_Nm, &pm.Tcmd_Nm}) *v = r.get<double>();
  }
  if (!r.at_end()) throw ConfigError("trailing bytes after the state");
  return s;
}

}  // namespace twin::fmu
