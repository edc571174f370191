#include "truth_sim.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <random>
#include <vector>

namespace twin::truth {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Trapezoidal moves: (distance mm, speed mm/s), dwells between them.
std::vector<double> make_reference(double Ts, int cycles) {
  struct Move {
    double d_mm, v_mm_per_s;
  };
  const std::vector<Move> cycle{{20.0, 20.0}, {-10.0, 60.0}, {6.0, 3.0}, {-16.0, 40.0}};
  const double a = 1000.0, dwell = 0.25;
  std::vector<double> x;
  double pos = 2.0;
  auto hold = [&](double t) {
    for (int k = 0; k < static_cast<int>(t / Ts); ++k) x.push_back(pos);
  };
  hold(0.3);
  for (int c = 0; c < cycles; ++c)
    for (const Move& m : cycle) {
      const double L = std::abs(m.d_mm), s = m.d_mm > 0 ? 1.0 : -1.0;
      double v = m.v_mm_per_s;
      if (v * v / a > L) v = std::sqrt(L * a);
      const double ta = v / a, tc = (L - v * v / a) / v, T = 2 * ta + tc;
      const double x0 = pos;
      for (double t = Ts; t < T; t += Ts) {
        double d;
        if (t < ta)
          d = 0.5 * a * t * t;
        else if (t < ta + tc)
          d = 0.5 * a * ta * ta + v * (t - ta);
        else {
          const double r = T - t;
          d = L - 0.5 * a * r * r;
        }
        x.push_back(x0 + s * d);
      }
      pos = x0 + m.d_mm;
      x.push_back(pos);
      hold(dwell);
    }
  hold(0.2);
  for (double& v : x) v = std::round(v * 1e4) / 1e4;  // 0.1 um grid
  return x;
}

struct State {
  double th_m{0.0}, w_m{0.0}, th_l{0.0}, w_l{0.0};
};

}  // namespace

std::vector<double> moves_program(double Ts_s, const std::vector<double>& speeds, double seconds) {
  std::vector<double> r;
  double x = 50.0, v = 0.0, t_in = 0.0;
  std::size_t seg = 0;
  for (double t = 0.0; t < seconds; t += Ts_s) {
    const double target = std::fmod(t_in, 2.0) < 1.4 ? speeds[seg % speeds.size()] : 0.0;
    v += std::clamp(target - v, -500.0 * Ts_s, 500.0 * Ts_s);
    x += v * Ts_s;
    r.push_back(x);
    t_in += Ts_s;
    if (t_in >= 2.0) {
      t_in = 0.0;
      ++seg;
    }
  }
  return r;
}

std::vector<double> contour_program(double Ts_s, const std::vector<std::pair<double, double>>& arcs, double seconds,
                                    int turns) {
  std::vector<double> r;
  double x = 50.0;
  const auto n = static_cast<std::size_t>(seconds / Ts_s);
  for (std::size_t i = 0; r.size() < n; ++i) {
    const auto [R, F] = arcs[i % arcs.size()];
    const double c = x - R, alpha = 500.0 / R, w_max = F / R, end = 2.0 * kPi * turns;
    double th = 0.0, w = 0.0;
    while (th < end && r.size() < n) {
      const double left = end - th;
      w = left <= 0.5 * w * w / alpha ? std::max(w - alpha * Ts_s, 0.05 * w_max) : std::min(w + alpha * Ts_s, w_max);
      th = std::min(th + w * Ts_s, end);
      r.push_back(c + R * std::cos(th));
    }
    x = c + R;
    for (int k = 0; k < static_cast<int>(0.3 / Ts_s) && r.size() < n; ++k) r.push_back(x);
  }
  return r;
}

std::size_t write_truth_run(const std::filesystem::path& out_dir, const RunSpec& sp, TruthRunStats* stats) {
  TruthRunStats st;
  const Plant& p = sp.plant;
  const Effects& e = sp.effects;
  const double Ts = sp.Ts_s;
  const std::vector<double> ref = sp.reference_mm.empty() ? make_reference(Ts, sp.cycles) : sp.reference_mm;
  // What the cascade's position loop follows: the reference, or its moving
  // average (command_average_ticks), which the log does not show.
  std::vector<double> ref_loop = ref;
  if (sp.cascade.on && sp.cascade.command_average_ticks > 1) {
    const std::size_t n = static_cast<std::size_t>(sp.cascade.command_average_ticks);
    double sum = 0.0;
    // sum: of ref - ref[0] over the window; before the first period the window holds ref[0].
    for (std::size_t k = 0; k < ref.size(); ++k) {
      sum += ref[k] - ref[k >= n ? k - n : 0];
      ref_loop[k] = ref[0] + sum / static_cast<double>(n);
    }
  }
  if (sp.cascade.on && sp.cascade.command_lag_s > 0.0) {
    const double a = std::exp(-Ts / sp.cascade.command_lag_s);
    double y = ref_loop[0];
    for (double& r : ref_loop) r = y = a * y + (1.0 - a) * r;
  }
  if (sp.cascade.on && sp.cascade.command_delay_ticks > 0) {
    const std::size_t d = static_cast<std::size_t>(sp.cascade.command_delay_ticks);
    const std::vector<double> undelayed = ref_loop;
    for (std::size_t k = 0; k < ref_loop.size(); ++k) ref_loop[k] = undelayed[k >= d ? k - d : 0];
  }
  const bool coupling_gap = e.backlash_in_coupling && e.backlash_mm > 0.0;
  const bool two_mass = e.compliance_K > 0.0 || coupling_gap;
  const double K_c = e.compliance_K > 0.0 ? e.compliance_K : 20000.0;
  const double half_gap_rad = coupling_gap ? 0.5 * e.backlash_mm / p.rg : 0.0;
  const double Jm = two_mass ? p.J * (1.0 - e.compliance_frac) : p.J;
  const double Jl = two_mass ? p.J * e.compliance_frac : 0.0;
  std::mt19937 rng(sp.seed);
  std::normal_distribution<double> noise(0.0, sp.current_noise_A);

  State s;
  s.th_m = s.th_l = ref[0] / p.rg;
  double table_mm = ref[0];           // backlash: table behind the play
  bool stuck = true;                  // friction side held (Karnopp)
  double I = 0.0, e_prev = 0.0, vref_prev = 0.0;
  // The cascade's position loop every pe periods: its output and the
  // command's acceleration held between its ticks.
  const std::size_t pe = static_cast<std::size_t>(sp.cascade.on ? std::max(1, sp.cascade.position_every) : 1);
  double vcmd = 0.0, aref_p = 0.0, vref_p_prev = 0.0;
  // The velocity loop's ticks per period (cascade only) and their period.
  const int nv = sp.cascade.on ? std::max(1, sp.cascade.velocity_ticks) : 1;
  const double Tv = Ts / nv;
  std::vector<double> ring(static_cast<std::size_t>(std::max(1, e.delay_ticks * nv)), 0.0);
  std::size_t head = 0;

  // Friction on the friction side (load side when two-mass) at speed w and position x.
  auto coulomb = [&](int dir, double x_mm) {
    double T = dir > 0 ? p.Tc_pos : p.Tc_neg;
    if (e.pdf_dTc != 0.0 && x_mm >= e.pdf_x0 && x_mm <= e.pdf_x1) T += e.pdf_dTc;
    return T;
  };
  double Tm_now = 0.0;  // the motor's torque over the current tick (load_friction)
  auto sliding = [&](double w, double x_mm) {
    const int dir = w > 0 ? 1 : -1;
    double T = coulomb(dir, x_mm) + e.load_friction * std::abs(Tm_now) + e.sqrt_friction * std::sqrt(std::abs(w));
    if (e.stribeck_Ts > 0.0) T += (e.stribeck_Ts - (dir > 0 ? p.Tc_pos : p.Tc_neg)) * std::exp(-std::pow(w / e.stribeck_ws, 2));
    return dir * T;
  };
  auto breakaway = [&](int dir, double x_mm) {
    const double T = coulomb(dir, x_mm) + e.load_friction * std::abs(Tm_now);
    return e.stribeck_Ts > 0.0 ? e.stribeck_Ts + T - (dir > 0 ? p.Tc_pos : p.Tc_neg) : T;
  };
  double F_dahl = 0.0;  // Dahl's friction state (dahl_sigma)

  std::filesystem::create_directories(out_dir);
  std::FILE* f = std::fopen((out_dir / "trace.csv").c_str(), "w");
  const char* a = sp.axis.c_str();
  const auto every = static_cast<std::size_t>(std::max(1, sp.log_every));
  const CascadeLaw& cl = sp.cascade;
  double Iv = 0.0, Tf = 0.0, Tcmd = 0.0;
  const double lag_a = cl.tau_i > 0.0 ? std::exp(-Tv / cl.tau_i) : 0.0;
  const double monitor_a = cl.log_torque_filter_s > 0.0 ? std::exp(-Tv / cl.log_torque_filter_s) : 0.0;
  double T_monitor = 0.0;
  bool monitor_started = false;
  double T_period_sum = 0.0, T_period_mean = 0.0;  // log_torque_mean: over the ticks of the period
  auto pos = [&](double x) {
    if (sp.log_significant_figures <= 0 || x == 0.0) return x;
    const double q = std::pow(10.0, std::floor(std::log10(std::abs(x))) - sp.log_significant_figures + 1);
    return std::round(x / q) * q;
  };
  if (cl.on) {
    std::fprintf(f, "t_s,%s_ref_mm,%s_mm", a, a);
    if (cl.log_velocities && cl.log_velocity_command) std::fprintf(f, ",%s_vcmd_mm_s", a);
    if (cl.log_velocities && cl.log_motor_speed) std::fprintf(f, ",%s_v_mm_s", a);
    std::fprintf(f, cl.raw_per_Nm > 0.0 ? ",%s_torque_raw\n" : ",%s_i_A\n", a);
  } else if (sp.log_current_only)
    std::fprintf(f, "t_s,%s_ref_mm,%s_mm,%s_i_A\n", a, a, a);
  else
    std::fprintf(f, "t_s,%s_ref_mm,%s_mm,%s_u_V,%s_i_A\n", a, a, a, a);
  // The RK4 steps per velocity tick: 20 a period or the next multiple of the ticks.
  const int steps_per_tick = (20 + nv - 1) / nv;
  const double h = Tv / steps_per_tick;
  const double dv = 1e-4;  // Karnopp band, rad/s
  // One integration step of h under the motor's torque Tm.
  auto substep = [&](double Tm) {
    // Friction side: the load (two-mass) or the motor.
    const double x_f = (two_mass ? s.th_l : s.th_m) * p.rg;
    const double cog_th = s.th_m;
    const double T_cog = e.cogging_A * std::sin(e.cogging_n * cog_th + e.cogging_phase);
    if (!two_mass && e.dahl_sigma > 0.0) {
      // Dahl: RK4 on (w, th, F); the level g at w is the sliding law's
      // (at w = 0 its limit in the direction F points).
      struct D {
        double w, th, F;
      };
      auto rate = [&](const D& z) {
        const double tc = e.cogging_A * std::sin(e.cogging_n * z.th + e.cogging_phase);
        const double w_dir = z.w != 0.0 ? z.w : (z.F >= 0.0 ? dv : -dv);
        const double g = std::abs(sliding(w_dir, z.th * p.rg));
        return D{(Tm - p.B * z.w - e.load_Nm - tc - z.F) / p.J, z.w,
                 e.dahl_sigma * (z.w - std::abs(z.w) * z.F / g)};
      };
      const D z0{s.w_m, s.th_m, F_dahl};
      auto step = [](const D& z, const D& r, double hh) { return D{z.w + hh * r.w, z.th + hh * r.th, z.F + hh * r.F}; };
      const D k1 = rate(z0), k2 = rate(step(z0, k1, 0.5 * h)), k3 = rate(step(z0, k2, 0.5 * h)), k4 = rate(step(z0, k3, h));
      s.w_m += h / 6 * (k1.w + 2 * k2.w + 2 * k3.w + k4.w);
      s.th_m += h / 6 * (k1.th + 2 * k2.th + 2 * k3.th + k4.th);
      F_dahl += h / 6 * (k1.F + 2 * k2.F + 2 * k3.F + k4.F);
      s.th_l = s.th_m;
      s.w_l = s.w_m;
    } else if (!two_mass && e.creep_w > 0.0) {
      // Creep below creep_w: friction linear in speed up to the Coulomb
      // level, never sticking; RK4 on (w, th).
      auto acc = [&](double w, double th) {
        const double tc = e.cogging_A * std::sin(e.cogging_n * th + e.cogging_phase);
        const double level = std::abs(sliding(w >= 0.0 ? std::max(w, dv) : std::min(w, -dv), th * p.rg));
        const double Tfr = level * std::clamp(w / e.creep_w, -1.0, 1.0);
        return (Tm - p.B * w - e.load_Nm - tc - Tfr) / p.J;
      };
      const double k1w = acc(s.w_m, s.th_m), k1t = s.w_m;
      const double k2w = acc(s.w_m + 0.5 * h * k1w, s.th_m + 0.5 * h * k1t), k2t = s.w_m + 0.5 * h * k1w;
      const double k3w = acc(s.w_m + 0.5 * h * k2w, s.th_m + 0.5 * h * k2t), k3t = s.w_m + 0.5 * h * k2w;
      const double k4w = acc(s.w_m + h * k3w, s.th_m + h * k3t), k4t = s.w_m + h * k3w;
      s.w_m += h / 6 * (k1w + 2 * k2w + 2 * k3w + k4w);
      s.th_m += h / 6 * (k1t + 2 * k2t + 2 * k3t + k4t);
      s.th_l = s.th_m;
      s.w_l = s.w_m;
    } else if (!two_mass) {
      const double F = Tm - p.B * s.w_m - e.load_Nm - T_cog;
      if (stuck) {
        const int dir = F > 0 ? 1 : -1;
        if (std::abs(F) <= breakaway(dir, x_f)) return;
        stuck = false;
        s.w_m = dir * 2 * dv;
      }
      // RK4 on w with the sliding friction of the current direction.
      const int dir = s.w_m > 0 ? 1 : -1;
      auto acc = [&](double w, double th) {
        const double tc = e.cogging_A * std::sin(e.cogging_n * th + e.cogging_phase);
        const double ww = dir * std::max(dir * w, 0.0);
        return (Tm - p.B * w - e.load_Nm - tc - sliding(ww == 0 ? dir * dv : ww, th * p.rg)) / p.J;
      };
      const double k1w = acc(s.w_m, s.th_m), k1t = s.w_m;
      const double k2w = acc(s.w_m + 0.5 * h * k1w, s.th_m + 0.5 * h * k1t), k2t = s.w_m + 0.5 * h * k1w;
      const double k3w = acc(s.w_m + 0.5 * h * k2w, s.th_m + 0.5 * h * k2t), k3t = s.w_m + 0.5 * h * k2w;
      const double k4w = acc(s.w_m + h * k3w, s.th_m + h * k3t), k4t = s.w_m + h * k3w;
      const double w_new = s.w_m + h / 6 * (k1w + 2 * k2w + 2 * k3w + k4w);
      s.th_m += h / 6 * (k1t + 2 * k2t + 2 * k3t + k4t);
      s.w_m = w_new;
      if (w_new * dir <= 0.0) {  // came to rest: Karnopp sticks it
        s.w_m = 0.0;
        stuck = true;
      }
      s.th_l = s.th_m;
      s.w_l = s.w_m;
    } else {
      // Two-mass: semi-implicit Euler with the small step (spring at a few hundred Hz, h = 5 us).
      // Spring (and its damping) only in contact: the deflection beyond the gap.
      const double d = s.th_m - s.th_l;
      const double defl = d > half_gap_rad ? d - half_gap_rad : (d < -half_gap_rad ? d + half_gap_rad : 0.0);
      const double C_c = e.compliance_K > 0.0 ? e.compliance_C : 1.3;
      const double Tsp = K_c * defl + (defl != 0.0 ? C_c * (s.w_m - s.w_l) : 0.0);
      s.w_m += h * (Tm - p.B * s.w_m - Tsp - T_cog) / Jm;
      s.th_m += h * s.w_m;
      const double Fl = Tsp - e.load_Nm;
      if (stuck) {
        const int dir = Fl > 0 ? 1 : -1;
        if (std::abs(Fl) <= breakaway(dir, x_f)) {
          s.w_l = 0.0;
          return;
        }
        stuck = false;
        s.w_l = dir * 2 * dv;
      }
      const int dir = s.w_l > 0 ? 1 : -1;
      const double wl = s.w_l + h * (Fl - sliding(s.w_l, x_f)) / Jl;
      if (wl * dir <= 0.0) {
        s.w_l = 0.0;
        stuck = true;
      } else {
        s.w_l = wl;
      }
      s.th_l += h * s.w_l;
    }
  };
  for (std::size_t k = 0; k < ref.size(); ++k) {
    // Sensor: the encoder on the motor (two-mass) or the table (backlash), screw error, quantiser.
    const double x_mot = s.th_m * p.rg;
    double x_sense = e.backlash_mm > 0.0 && !coupling_gap ? table_mm : x_mot;
    if (e.screw_A_mm != 0.0) x_sense += e.screw_A_mm * std::sin(2 * kPi * x_sense / e.screw_P_mm);
    const double x_meas = sp.resolution_mm > 0 ? std::round(x_sense / sp.resolution_mm) * sp.resolution_mm : x_sense;
    // FADAL law.
    const double err = ref[k] - x_meas;
    const double vref = k > 0 ? (ref[k] - ref[k - 1]) / Ts : 0.0;
    const double aref = (vref - vref_prev) / Ts;
    I += Ts * err;
    double u = p.Kp * err + p.Ki * I + p.Kd * (err - e_prev) / Ts + p.K1 * aref + p.K2 * vref;
    u = std::clamp(u, -p.u_max, p.u_max);
    // The cascade's position loop: on its own ticks only (position_every).
    const double vcmd_before = vcmd;
    if (k % pe == 0) {
      const std::vector<double>& ref_ff = cl.smooth_position_path_only ? ref : ref_loop;
      const double vref_p = k >= pe ? (ref_ff[k] - ref_ff[k - pe]) / (pe * Ts) : 0.0;
      aref_p = (vref_p - vref_p_prev) / (pe * Ts);
      vref_p_prev = vref_p;
      vcmd = cl.Kv * (ref_loop[k] - x_meas) + cl.kff * vref_p;
    }
    e_prev = err;
    vref_prev = vref;
    for (int q = 0; q < nv; ++q) {
      const double v_motor = s.w_m * p.rg;
      if (cl.on) {
        const double ev = (vcmd - v_motor) / p.rg;
        const double Iv_next = Iv + Tv * ev;
        Tcmd = cl.Kvp * (ev + (cl.Tn > 0.0 ? Iv_next / cl.Tn : 0.0)) + cl.Jff * aref_p / p.rg;
        const bool clamped = cl.T_max_Nm > 0.0 && std::abs(Tcmd) > cl.T_max_Nm;
        if (clamped) {
          Tcmd = std::clamp(Tcmd, -cl.T_max_Nm, cl.T_max_Nm);
          ++st.ticks_at_limit;
        }
        if (!(clamped && cl.anti_windup)) Iv = Iv_next;
        Tf = lag_a * Tf + (1.0 - lag_a) * Tcmd;
        u = Tf / (p.Ka * p.Kt);
      }
      double u_app = u;
      if (e.delay_ticks > 0) {
        u_app = ring[head];
        ring[head] = u;
        head = (head + 1) % ring.size();
      }
      double i = p.Ka * u_app;
      if (e.i_max_A > 0.0 && std::abs(i) > e.i_max_A) {
        i = std::clamp(i, -e.i_max_A, e.i_max_A);
        ++st.ticks_at_limit;
      }
      const double Tm = p.Kt * i;
      Tm_now = Tm;
      const double T_seen = cl.log_torque_command ? Tcmd : Tm;
      T_monitor = monitor_started ? monitor_a * T_monitor + (1.0 - monitor_a) * T_seen : T_seen;
      monitor_started = true;
      if (q == 0) {
        const double i_logged = e.delay_after_current ? p.Ka * u : i;
        const double i_measured = i_logged + noise(rng);
        if (k % every == 0 && cl.on) {
          const double ref_logged = sp.log_reference_quantum_mm > 0.0
                                        ? std::round(ref[k] / sp.log_reference_quantum_mm) * sp.log_reference_quantum_mm
                                        : pos(ref[k]);
          std::fprintf(f, "%.4f,%.10g,%.10g", static_cast<double>(k) * Ts, ref_logged, pos(x_meas));
          if (cl.log_velocities && cl.log_velocity_command)
            std::fprintf(f, ",%.6f", cl.log_vcmd_before_update ? vcmd_before : vcmd);
          if (cl.log_velocities && cl.log_motor_speed) std::fprintf(f, ",%.6f", v_motor);
          const double T_logged = cl.log_torque_mean ? T_period_mean : T_monitor;
          double raw = cl.raw_per_Nm * (T_logged + noise(rng));
          if (cl.raw_step > 0.0) raw = cl.raw_step * std::round(raw / cl.raw_step);
          std::fprintf(f, ",%.6f\n", cl.raw_per_Nm > 0.0 ? raw : i_measured);
        } else if (k % every == 0) {
          if (sp.log_current_only)
            std::fprintf(f, "%.4f,%.4f,%.3f,%.4f\n", static_cast<double>(k) * Ts, ref[k], x_meas, i_measured);
          else
            std::fprintf(f, "%.4f,%.4f,%.3f,%.5f,%.4f\n", static_cast<double>(k) * Ts, ref[k], x_meas, u, i_measured);
        }
      }
      for (int j = 0; j < steps_per_tick; ++j) substep(Tm);
      T_period_sum += T_seen;
      if (q + 1 == nv) {
        T_period_mean = T_period_sum / nv;
        T_period_sum = 0.0;
      }
    }
    if (e.backlash_mm > 0.0 && !coupling_gap) {
      const double xm = s.th_m * p.rg, half = 0.5 * e.backlash_mm;
      if (xm - table_mm > half) table_mm = xm - half;
      if (table_mm - xm > half) table_mm = xm + half;
    }
  }
  std::fclose(f);
  std::ofstream meta(out_dir / "meta.json");
  meta << "{\"machine\": " << (cl.on ? "null" : "\"fadal2216\"") << ", \"axes\": [\"" << sp.axis
       << "\"], \"controller_period_s\": ";
  if (sp.period_in_meta == RunSpec::PeriodInMeta::kLoop)
    meta << Ts * static_cast<double>(pe);
  else if (sp.period_in_meta == RunSpec::PeriodInMeta::kLog)
    meta << Ts;
  else
    meta << "null";
  meta << ", \"sample_period_s\": " << Ts * static_cast<double>(every)
       << ", \"encoder_resolution_mm\": " << sp.resolution_mm
       << ", \"description\": \"truth simulator of the calibration tests\"}\n";
  if (stats != nullptr) *stats = st;
  return ref.size();
}

}  // namespace twin::truth
