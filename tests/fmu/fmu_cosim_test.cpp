// The FMU as a co-simulation master drives it: steps that end between the
// controller's ticks (a shortened last step, an input event), runs to the
// default stop time at the output intervals fmusim users pick, the status
// calls, FMU states from elsewhere, huge steps and the stop time, inputs the
// mode ignores, and logging. Every test goes through dlopen (LoadedFmu).
//
// Oracle: a native twin::sim::CoSimulation built here from the same scenario
// file. A step from t to t + h runs every tick that starts in [t, t + h),
// each with the inputs set at the last communication point at or before its
// start, and the outputs are the row of the last tick started; so after
// every step the FMU's outputs must EQUAL the native run's last row after
// that many ticks (same code, same numbers, no tolerance).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "controller/interpolator.hpp"
#include "fmu_importer.hpp"
#include "twin/io/scenario_file.hpp"
#include "twin/sim/cosimulation.hpp"
#include "twin/sim/reference.hpp"

namespace twin::fmu_test {
namespace {

/// Ticks a step ending at t_end (from 0) has run: those starting before
/// t_end, a start within 1e-9 of t_end counting as t_end.
std::int64_t ticks_before(double t_end, double Ts) {
  const double x = t_end / Ts;
  const double r = std::round(x);
  return static_cast<std::int64_t>(std::abs(x - r) * Ts <= 1e-9 * std::max(1.0, t_end) ? r : std::ceil(x));
}

std::size_t count(const std::string& text, const std::string& what) {
  std::size_t n = 0;
  for (auto p = text.find(what); p != std::string::npos; p = text.find(what, p + 1)) ++n;
  return n;
}

class FmuCosim : public ::testing::Test {
 protected:
  void SetUp() override {
    REQUIRE_EXPORTED(TWIN_FMU_AIRCUT);
    fmu_ = std::make_unique<LoadedFmu>(TWIN_FMU_AIRCUT);
    sc_ = io::load_scenario(TWIN_FMU_AIRCUT_SCENARIO);
    Ts_ = sc_.machine.Ts_s;
    for (Axis a : sc_.machine.present_axes()) {
      const std::string n(axis_name(a));
      for (const char* suffix : {"_mm", "_true_mm", "_ref_out_mm", "_u_V", "_i_A", "_Td_Nm", "_v_mm_per_s"}) {
        names_.push_back(n + suffix);
        fields_.push_back([a, s = std::string(suffix)](const sim::Snapshot& r) {
          const sim::AxisSnapshot& x = r.axes[index(a)];
          if (s == "_mm") return x.x_mm;
          if (s == "_true_mm") return x.x_true_mm;
          if (s == "_ref_out_mm") return x.x_ref_mm;
          if (s == "_u_V") return x.u_V;
          if (s == "_i_A") return x.i_A;
          if (s == "_Td_Nm") return x.Td_Nm;
          return x.v_mm_per_s;
        });
      }
    }
    names_.push_back("fx_N");
    fields_.push_back([](const sim::Snapshot& r) { return r.F_N[0]; });
    for (const auto& n : names_) vrs_.push_back(fmu_->var(n).vr);
  }
  void TearDown() override {
    for (fmi2Component c : instances_) fmu_->fn().fmi2FreeInstance(c);
  }

  /// Instantiated, set up (stop time when stop_s > 0) and initialised, in mode 2.
  fmi2Component start(double stop_s = 0.0, bool logging_on = false) {
    const auto& f = fmu_->fn();
    fmi2Component c = fmu_->instantiate("cosim", nullptr, logging_on);
    EXPECT_NE(c, nullptr);
    if (c == nullptr) return c;
    instances_.push_back(c);
    EXPECT_EQ(f.fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, stop_s > 0.0 ? fmi2True : fmi2False, stop_s), fmi2OK);
    EXPECT_EQ(f.fmi2EnterInitializationMode(c), fmi2OK);
    EXPECT_EQ(f.fmi2ExitInitializationMode(c), fmi2OK);
    return c;
  }
  /// An instance started and stepped `ticks` ticks, its state then and that state's bytes.
  void state_after_ticks(int ticks, fmi2Component& c, fmi2FMUstate& st, std::vector<fmi2Byte>& bytes) {
    const auto& f = fmu_->fn();
    c = start();
    ASSERT_NE(c, nullptr);
    ASSERT_EQ(f.fmi2DoStep(c, 0.0, ticks * Ts_, fmi2True), fmi2OK);
    ASSERT_EQ(f.fmi2GetFMUstate(c, &st), fmi2OK);
    ASSERT_NO_FATAL_FAILURE(serialize_state(f, c, st, bytes));
  }
  std::unique_ptr<sim::CoSimulation> native() const {
    auto ref = std::make_shared<sim::ProgramReference>(
        controller::plan_trajectory(io::parse_program(sc_), sc_.machine.motion_limits(), sc_.machine.Ts_s));
    return std::make_unique<sim::CoSimulation>(sc_.machine, ref, nullptr, sc_.start_mm);
  }
  std::vector<double> outputs(fmi2Component c) const {
    std::vector<double> row(vrs_.size());
    EXPECT_EQ(fmu_->fn().fmi2GetReal(c, vrs_.data(), vrs_.size(), row.data()), fmi2OK);
    return row;
  }
  std::vector<double> expected(const sim::Snapshot& s) const {
    std::vector<double> row;
    for (const auto& f : fields_) row.push_back(f(s));
    return row;
  }
  void set_real(fmi2Component c, const std::string& name, double v, fmi2Status want = fmi2OK) {
    const fmi2ValueReference vr = fmu_->var(name).vr;
    EXPECT_EQ(fmu_->fn().fmi2SetReal(c, &vr, 1, &v), want) << name;
  }
  double last_successful_time(fmi2Component c) const {
    fmi2Real t = -1.0;
    EXPECT_EQ(fmu_->fn().fmi2GetRealStatus(c, fmi2LastSuccessfulTime, &t), fmi2OK);
    return t;
  }
  bool logged(const std::string& what) const {
    for (const auto& l : fmu_->log())
      if (l.find(what) != std::string::npos) return true;
    return false;
  }

  std::unique_ptr<LoadedFmu> fmu_;
  io::Scenario sc_;
  double Ts_{1e-4};
  std::vector<std::string> names_;
  std::vector<std::function<double(const sim::Snapshot&)>> fields_;
  std::vector<fmi2ValueReference> vrs_;
  std::vector<fmi2Component> instances_;
};

// ---- steps that end between ticks -------------------------------------------

TEST_F(FmuCosim, StepsEndingBetweenTicksAndAShortenedLastStepFollowTheNativeRun) {
  // Sub-tick steps (0.35 Ts), whole steps, steps of 2.5 Ts, then a last step
  // shortened to a stop time between ticks (0.01234 s = 123.4 ticks).
  const double stop_s = 0.01234;
  const auto& f = fmu_->fn();
  fmi2Component c = start(stop_s);
  ASSERT_NE(c, nullptr);
  auto cosim = native();
  std::vector<double> steps;
  for (int i = 0; i < 10; ++i) steps.push_back(0.35 * Ts_);
  for (int i = 0; i < 5; ++i) steps.push_back(10 * Ts_);
  for (int i = 0; i < 7; ++i) steps.push_back(2.5 * Ts_);
  double t = 0.0;
  for (double h : steps) {
    ASSERT_EQ(f.fmi2DoStep(c, t, h, fmi2True), fmi2OK) << "t = " << t << ", h = " << h;
    t += h;
    while (cosim->tick() < ticks_before(t, Ts_)) cosim->step();
    if (cosim->tick() > 0) {
      ASSERT_EQ(outputs(c), expected(cosim->last())) << "after the step to t = " << t;
    }
    EXPECT_EQ(last_successful_time(c), t);
  }
  // Whole steps of 1 ms (from a point between ticks), then the shortened last one.
  while (t + 1e-3 < stop_s) {
    ASSERT_EQ(f.fmi2DoStep(c, t, 1e-3, fmi2True), fmi2OK) << "t = " << t;
    t += 1e-3;
  }
  const double h_last = stop_s - t;
  ASSERT_GT(h_last, 0.0);
  ASSERT_EQ(f.fmi2DoStep(c, t, h_last, fmi2True), fmi2OK) << "the last step, shortened to " << h_last << " s";
  while (cosim->tick() < 124) cosim->step();  // ticks 0..123 start before 0.01234 s
  EXPECT_EQ(outputs(c), expected(cosim->last()));
  EXPECT_EQ(last_successful_time(c), stop_s);
  EXPECT_EQ(f.fmi2Terminate(c), fmi2OK);
}

TEST_F(FmuCosim, AnInputEventBetweenTicksActsFromTheNextTick) {
  // The master shortens a step to hit an input change at 0.00505 s (tick 50.5):
  // the force set there is sampled by tick 51 (t = 0.0051 s), the first tick
  // starting after it, like the cutting force it is added to.
  const auto& f = fmu_->fn();
  fmi2Component c = start();
  ASSERT_NE(c, nullptr);
  auto cosim = native();
  auto quiet = native();  // no force at all: the event must change something
  const double t_event = 0.00505;
  double t = 0.0;
  for (int i = 0; i < 5; ++i, t += 1e-3) ASSERT_EQ(f.fmi2DoStep(c, t, 1e-3, fmi2True), fmi2OK);
  ASSERT_EQ(f.fmi2DoStep(c, t, t_event - t, fmi2True), fmi2OK) << "step shortened to the event";
  t = t_event;
  for (int k = 0; k < 51; ++k) cosim->step();
  EXPECT_EQ(outputs(c), expected(cosim->last()));
  set_real(c, "fx_ext_N", 300.0);
  set_real(c, "fy_ext_N", -200.0);
  cosim->set_external_force_N({300.0, -200.0, 0.0});
  ASSERT_EQ(f.fmi2DoStep(c, t, 0.006 - t_event, fmi2True), fmi2OK) << "step from the event to the next output point";
  t = 0.006;
  for (int k = 51; k < 60; ++k) cosim->step();
  EXPECT_EQ(outputs(c), expected(cosim->last()));
  for (int i = 0; i < 4; ++i, t += 1e-3) ASSERT_EQ(f.fmi2DoStep(c, t, 1e-3, fmi2True), fmi2OK);
  for (int k = 60; k < 100; ++k) cosim->step();
  for (int k = 0; k < 100; ++k) quiet->step();
  EXPECT_EQ(outputs(c), expected(cosim->last()));
  EXPECT_NE(cosim->last().axes[0].Td_Nm, 0.0);
  EXPECT_NE(cosim->last().axes[0].x_true_mm, quiet->last().axes[0].x_true_mm) << "the force must act";
}

TEST_F(FmuCosim, DefaultStopTimeIsTheProgramEndOnTheTickGrid) {
  // Oracle: the twin's own plan of the program (duration) plus settle_s,
  // rounded up to a whole tick. Tolerances: the stop time is decimal text,
  // so stop / Ts reads back within a few ulps of a whole number (1e-6 ticks
  // is far above that and far below the 0.19 ticks the old default stop
  // time 8.801919244755586 s was off the grid);
  // 1e-9 s covers the rounding of duration + settle_s.
  for (const std::string& path : {std::string(TWIN_FMU_AIRCUT), std::string(TWIN_FMU_DEFAULT)}) {
    REQUIRE_EXPORTED(path);
    LoadedFmu fmu(path);
    const io::Scenario sc = io::load_scenario(path == TWIN_FMU_AIRCUT ? std::string(TWIN_FMU_AIRCUT_SCENARIO)
                                                                       : io::default_scenario_path().string());
    const double Ts = sc.machine.Ts_s;
    const double end_s =
        controller::plan_trajectory(io::parse_program(sc), sc.machine.motion_limits(), Ts).duration_s() + sc.settle_s;
    const double stop = std::stod(fmu.default_experiment("stopTime"));
    const double n = stop / Ts;
    EXPECT_NEAR(n, std::round(n), 1e-6) << path << ": stopTime " << stop << " is not on the tick grid";
    EXPECT_GE(stop, end_s - 1e-9) << path;
    EXPECT_LT(stop, end_s + Ts) << path;
    EXPECT_NEAR(std::stod(fmu.default_experiment("stepSize")) / Ts, 10.0, 1e-9) << path;
  }
}

TEST_F(FmuCosim, FmusimStyleRunsReachTheDefaultStopTimeAtEveryOutputInterval) {
  // As fmusim runs an FMU: stop time defined, communication points k * dt,
  // the last step shortened to the stop time. The run must reach it with
  // every step OK and end on the native run's row of the last tick.
  const double stop = std::stod(fmu_->default_experiment("stopTime"));
  const auto n_ticks = ticks_before(stop, Ts_);
  auto cosim = native();
  while (cosim->tick() < n_ticks) cosim->step();
  for (double dt : {1e-4, 1e-3, 1e-2}) {
    const auto& f = fmu_->fn();
    fmi2Component c = start(stop);
    ASSERT_NE(c, nullptr);
    double t = 0.0;
    int steps = 0;
    for (std::int64_t k = 1; t < stop && std::abs(t - stop) > 1e-9 * stop; ++k) {
      double t_next = static_cast<double>(k) * dt;
      if (t_next > stop || std::abs(t_next - stop) <= 1e-9 * stop) t_next = stop;
      ASSERT_EQ(f.fmi2DoStep(c, t, t_next - t, fmi2True), fmi2OK) << "dt = " << dt << ", t = " << t;
      t = t_next;
      ++steps;
    }
    EXPECT_EQ(last_successful_time(c), stop) << "dt = " << dt;
    EXPECT_EQ(outputs(c), expected(cosim->last())) << "dt = " << dt;
    EXPECT_EQ(f.fmi2Terminate(c), fmi2OK);
    EXPECT_EQ(steps, static_cast<int>(std::ceil(stop / dt - 1e-9))) << "dt = " << dt;
  }
}

TEST_F(FmuCosim, NoOutputChangesWhenAnInputIsSetOnlyTheNextStepSeesIt) {
  // The behaviour behind dependencies="" in ModelStructure/Outputs: setting
  // any input (mode 1, where the reference inputs act) changes no output
  // until the next fmi2DoStep, in initialization mode and after a step.
  const auto& f = fmu_->fn();
  std::vector<fmi2ValueReference> reals, ints, bools;
  for (const auto& v : fmu_->variables()) {
    if (v.causality != "output") continue;
    (v.type == "Real" ? reals : v.type == "Integer" ? ints : bools).push_back(v.vr);
  }
  auto all_outputs = [&](fmi2Component c) {
    std::vector<double> r(reals.size());
    std::vector<fmi2Integer> i(ints.size());
    std::vector<fmi2Boolean> b(bools.size());
    EXPECT_EQ(f.fmi2GetReal(c, reals.data(), reals.size(), r.data()), fmi2OK);
    EXPECT_EQ(f.fmi2GetInteger(c, ints.data(), ints.size(), i.data()), fmi2OK);
    EXPECT_EQ(f.fmi2GetBoolean(c, bools.data(), bools.size(), b.data()), fmi2OK);
    for (auto v : i) r.push_back(v);
    for (auto v : b) r.push_back(v);
    return r;
  };
  auto set_every_input = [&](fmi2Component c, double offset) {
    for (const auto& v : fmu_->variables()) {
      if (v.causality != "input") continue;
      if (v.type == "Boolean") {
        const fmi2Boolean on = fmi2True;
        EXPECT_EQ(f.fmi2SetBoolean(c, &v.vr, 1, &on), fmi2OK) << v.name;
      } else {
        const fmi2Real x = std::stod(v.start) + offset;
        EXPECT_EQ(f.fmi2SetReal(c, &v.vr, 1, &x), fmi2OK) << v.name;
      }
    }
  };
  fmi2Component c = fmu_->instantiate("feedthrough");
  ASSERT_NE(c, nullptr);
  instances_.push_back(c);
  const fmi2ValueReference mode = fmu_->var("mode").vr;
  const fmi2Integer one = 1;
  ASSERT_EQ(f.fmi2SetInteger(c, &mode, 1, &one), fmi2OK);
  ASSERT_EQ(f.fmi2EnterInitializationMode(c), fmi2OK);
  const auto at_init = all_outputs(c);
  set_every_input(c, 0.05);
  EXPECT_EQ(all_outputs(c), at_init) << "in initialization mode";
  ASSERT_EQ(f.fmi2ExitInitializationMode(c), fmi2OK);
  EXPECT_EQ(all_outputs(c), at_init) << "after initialization, before the first step";
  ASSERT_EQ(f.fmi2DoStep(c, 0.0, 10 * Ts_, fmi2True), fmi2OK);
  const auto after_step = all_outputs(c);
  EXPECT_NE(after_step, at_init) << "the step must see the inputs";
  set_every_input(c, 0.1);
  EXPECT_EQ(all_outputs(c), after_step) << "at a communication point";
}

// ---- status, stop time, huge steps ------------------------------------------

TEST_F(FmuCosim, AStatusKindNotProvidedIsDiscardAndTheInstanceGoesOn) {
  // FMI 2.0.2, section 4.2.3: a status the slave cannot give -> fmi2Discard.
  const auto& f = fmu_->fn();
  fmi2Component c = start();
  ASSERT_NE(c, nullptr);
  ASSERT_EQ(f.fmi2DoStep(c, 0.0, 10 * Ts_, fmi2True), fmi2OK);
  fmi2Status st = fmi2OK;
  fmi2Real r = -1.0;
  fmi2Integer i = -1;
  fmi2Boolean b = fmi2True;
  fmi2String s = nullptr;
  EXPECT_EQ(f.fmi2GetRealStatus(c, fmi2DoStepStatus, &r), fmi2Discard);
  EXPECT_EQ(f.fmi2GetBooleanStatus(c, fmi2LastSuccessfulTime, &b), fmi2Discard);
  EXPECT_EQ(f.fmi2GetStatus(c, fmi2DoStepStatus, &st), fmi2Discard);
  EXPECT_EQ(f.fmi2GetIntegerStatus(c, fmi2DoStepStatus, &i), fmi2Discard);
  EXPECT_EQ(f.fmi2GetStringStatus(c, fmi2PendingStatus, &s), fmi2Discard);
  EXPECT_EQ(r, -1.0) << "nothing written";
  // The kinds provided still answer, and the instance still steps.
  EXPECT_EQ(f.fmi2GetBooleanStatus(c, fmi2Terminated, &b), fmi2OK);
  EXPECT_EQ(b, fmi2False);
  EXPECT_EQ(f.fmi2DoStep(c, 10 * Ts_, 10 * Ts_, fmi2True), fmi2OK);
  EXPECT_DOUBLE_EQ(last_successful_time(c), 20 * Ts_);
}

TEST_F(FmuCosim, AHugeStepIsRefusedAtOnceAndTheInstanceGoesOn) {
  // 1e5 s is 1e9 ticks of 1e-4 s: refused before anything runs (fmi2Discard,
  // state unchanged), with the reason in the log.
  const auto& f = fmu_->fn();
  fmi2Component c = start(0.0, true);
  ASSERT_NE(c, nullptr);
  EXPECT_EQ(f.fmi2DoStep(c, 0.0, 1e5, fmi2True), fmi2Discard);
  ASSERT_FALSE(fmu_->log().empty());
  EXPECT_NE(fmu_->log().back().find("at most"), std::string::npos) << fmu_->log().back();
  EXPECT_NE(fmu_->log().back().find("logStatusDiscard"), std::string::npos) << fmu_->log().back();
  EXPECT_EQ(last_successful_time(c), 0.0);
  ASSERT_EQ(f.fmi2DoStep(c, 0.0, 10 * Ts_, fmi2True), fmi2OK);
  auto cosim = native();
  for (int k = 0; k < 10; ++k) cosim->step();
  EXPECT_EQ(outputs(c), expected(cosim->last())) << "the refused step changed nothing";
}

TEST_F(FmuCosim, StepsPastTheStopTimeAreErrors) {
  // FMI 2.0, fmi2SetupExperiment: with stopTimeDefined the FMU is not stepped
  // past stopTime; a step that would is an error.
  const auto& f = fmu_->fn();
  fmi2Component c = start(0.01);
  ASSERT_NE(c, nullptr);
  double t = 0.0;
  for (int i = 0; i < 10; ++i, t += 0.001) ASSERT_EQ(f.fmi2DoStep(c, t, 0.001, fmi2True), fmi2OK) << t;
  EXPECT_EQ(f.fmi2DoStep(c, t, 0.001, fmi2True), fmi2Error);
  ASSERT_FALSE(fmu_->log().empty());
  EXPECT_NE(fmu_->log().back().find("stop time"), std::string::npos) << fmu_->log().back();
  fmi2Component d = start(0.01);
  EXPECT_EQ(f.fmi2DoStep(d, 0.0, 1e5, fmi2True), fmi2Error) << "past the stop time comes first";
  fmi2Component e = fmu_->instantiate("bad stop");
  instances_.push_back(e);
  EXPECT_EQ(f.fmi2SetupExperiment(e, fmi2False, 0.0, 1.0, fmi2True, 0.5), fmi2Error) << "stop before start";
}

// ---- FMU states ---------------------------------------------------------------

TEST_F(FmuCosim, AStateOfAnotherFmuIsRefusedWithItsReason) {
  // The default scenario's FMU (another machine setup and program) must not
  // take the air cut's state, in memory or as bytes; its own state restores
  // it even from the error state the refusal left.
  REQUIRE_EXPORTED(TWIN_FMU_DEFAULT);
  LoadedFmu other(TWIN_FMU_DEFAULT);
  const auto& f = fmu_->fn();
  const auto& g = other.fn();
  fmi2Component c = nullptr;
  fmi2FMUstate foreign = nullptr;
  std::vector<fmi2Byte> bytes;
  ASSERT_NO_FATAL_FAILURE(state_after_ticks(50, c, foreign, bytes));

  fmi2Component d = other.instantiate("other");
  ASSERT_NE(d, nullptr);
  ASSERT_EQ(g.fmi2SetupExperiment(d, fmi2False, 0.0, 0.0, fmi2False, 0.0), fmi2OK);
  ASSERT_EQ(g.fmi2EnterInitializationMode(d), fmi2OK);
  ASSERT_EQ(g.fmi2ExitInitializationMode(d), fmi2OK);
  ASSERT_EQ(g.fmi2DoStep(d, 0.0, 20 * Ts_, fmi2True), fmi2OK);
  fmi2FMUstate own = nullptr;
  ASSERT_EQ(g.fmi2GetFMUstate(d, &own), fmi2OK);
  EXPECT_EQ(g.fmi2SetFMUstate(d, foreign), fmi2Error);
  ASSERT_FALSE(other.log().empty());
  EXPECT_NE(other.log().back().find("GUID"), std::string::npos) << other.log().back();
  fmi2FMUstate from_bytes = nullptr;
  EXPECT_EQ(g.fmi2DeSerializeFMUstate(d, bytes.data(), bytes.size(), &from_bytes), fmi2Error);
  EXPECT_EQ(from_bytes, nullptr);
  EXPECT_NE(other.log().back().find("GUID"), std::string::npos) << other.log().back();
  // Recovery: the FMU's own state, then steps go on from t = 20 Ts.
  EXPECT_EQ(g.fmi2SetFMUstate(d, own), fmi2OK);
  EXPECT_EQ(g.fmi2DoStep(d, 20 * Ts_, 10 * Ts_, fmi2True), fmi2OK);
  g.fmi2FreeFMUstate(d, &own);
  g.fmi2FreeInstance(d);
  f.fmi2FreeFMUstate(c, &foreign);
}

TEST_F(FmuCosim, AStateWithANegativeTickCounterIsRefused) {
  // The serialized state after 1237 ticks holds the tick counter as the only
  // 8-byte integer equal to 1237 (the rows and loops hold 1236); a state
  // edited to -5 ticks must be refused on deserialize, with a log line.
  const auto& f = fmu_->fn();
  fmi2Component c = nullptr;
  fmi2FMUstate st = nullptr;
  std::vector<fmi2Byte> bytes;
  ASSERT_NO_FATAL_FAILURE(state_after_ticks(1237, c, st, bytes));
  std::vector<std::size_t> at;
  for (std::size_t i = 0; i + 8 <= bytes.size(); ++i) {
    std::int64_t v = 0;
    std::memcpy(&v, bytes.data() + i, 8);
    if (v == 1237) at.push_back(i);
  }
  ASSERT_EQ(at.size(), 1u);
  // Unedited, the bytes restore (the check itself is not what refuses).
  fmi2FMUstate good = nullptr;
  ASSERT_EQ(f.fmi2DeSerializeFMUstate(c, bytes.data(), bytes.size(), &good), fmi2OK);
  const std::int64_t negative = -5;
  std::memcpy(bytes.data() + at[0], &negative, 8);
  fmi2FMUstate bad = nullptr;
  EXPECT_EQ(f.fmi2DeSerializeFMUstate(c, bytes.data(), bytes.size(), &bad), fmi2Error);
  EXPECT_EQ(bad, nullptr);
  ASSERT_FALSE(fmu_->log().empty());
  EXPECT_NE(fmu_->log().back().find("tick counter -5"), std::string::npos) << fmu_->log().back();
  f.fmi2FreeFMUstate(c, &st);
  f.fmi2FreeFMUstate(c, &good);
}

// ---- inputs the mode ignores, logging ------------------------------------------

TEST_F(FmuCosim, ReferenceInputsSetInMode2AreReportedAsIgnored) {
  const auto& f = fmu_->fn();
  fmi2Component c = start(0.0, true);
  ASSERT_NE(c, nullptr);
  ASSERT_EQ(f.fmi2DoStep(c, 0.0, 10 * Ts_, fmi2True), fmi2OK);
  set_real(c, "x_ref_mm", sc_.start_mm[0] + 1.0, fmi2Warning);
  ASSERT_FALSE(fmu_->log().empty());
  EXPECT_NE(fmu_->log().back().find("logStatusWarning"), std::string::npos) << fmu_->log().back();
  EXPECT_NE(fmu_->log().back().find("ignores"), std::string::npos) << fmu_->log().back();
  // And it is ignored: the run equals the native program run.
  ASSERT_EQ(f.fmi2DoStep(c, 10 * Ts_, 10 * Ts_, fmi2True), fmi2OK);
  auto cosim = native();
  for (int k = 0; k < 20; ++k) cosim->step();
  EXPECT_EQ(outputs(c), expected(cosim->last()));
  // Set before initialization: reported when initialization ends.
  fmi2Component d = fmu_->instantiate("early", nullptr, true);
  instances_.push_back(d);
  ASSERT_EQ(f.fmi2EnterInitializationMode(d), fmi2OK);
  set_real(d, "x_ref_mm", sc_.start_mm[0] + 1.0);
  EXPECT_EQ(f.fmi2ExitInitializationMode(d), fmi2Warning);
  // Mode 1 follows them: no warning.
  fmi2Component e = fmu_->instantiate("mode1", nullptr, true);
  instances_.push_back(e);
  const fmi2ValueReference mode = fmu_->var("mode").vr;
  const fmi2Integer one = 1;
  ASSERT_EQ(f.fmi2SetInteger(e, &mode, 1, &one), fmi2OK);
  ASSERT_EQ(f.fmi2EnterInitializationMode(e), fmi2OK);
  ASSERT_EQ(f.fmi2ExitInitializationMode(e), fmi2OK);
  set_real(e, "x_ref_mm", sc_.start_mm[0] + 0.01);
}

TEST_F(FmuCosim, LoggingFollowsLoggingOnAndTheCategories) {
  const auto& f = fmu_->fn();
  fmi2Component c = start();  // loggingOn = false
  ASSERT_NE(c, nullptr);
  fmu_->clear_log();
  ASSERT_EQ(f.fmi2DoStep(c, 0.0, 10 * Ts_, fmi2True), fmi2OK);
  set_real(c, "x_ref_mm", sc_.start_mm[0] + 1.0, fmi2Warning);
  EXPECT_TRUE(fmu_->log().empty()) << fmu_->log().front();

  const fmi2String calls[] = {"logCalls"};
  ASSERT_EQ(f.fmi2SetDebugLogging(c, fmi2True, 1, calls), fmi2OK);
  fmu_->clear_log();
  ASSERT_EQ(f.fmi2DoStep(c, 10 * Ts_, 10 * Ts_, fmi2True), fmi2OK);
  ASSERT_EQ(fmu_->log().size(), 1u);
  EXPECT_NE(fmu_->log()[0].find("logCalls: fmi2DoStep: "), std::string::npos) << fmu_->log()[0];
  EXPECT_EQ(count(fmu_->log()[0], "fmi2DoStep"), 1u) << fmu_->log()[0];
  fmu_->clear_log();
  set_real(c, "x_ref_mm", sc_.start_mm[0] + 2.0, fmi2Warning);
  EXPECT_FALSE(logged("logStatusWarning")) << "logStatusWarning is off";

  const fmi2String warnings[] = {"logStatusWarning"};
  ASSERT_EQ(f.fmi2SetDebugLogging(c, fmi2True, 1, warnings), fmi2OK);
  fmu_->clear_log();
  set_real(c, "x_ref_mm", sc_.start_mm[0] + 3.0, fmi2Warning);
  EXPECT_TRUE(logged("logStatusWarning: fmi2SetReal: x_ref_mm = "));

  ASSERT_EQ(f.fmi2SetDebugLogging(c, fmi2False, 0, nullptr), fmi2OK);
  fmu_->clear_log();
  ASSERT_EQ(f.fmi2DoStep(c, 20 * Ts_, 10 * Ts_, fmi2True), fmi2OK);
  EXPECT_TRUE(fmu_->log().empty()) << fmu_->log().front();

  // Errors are always logged, naming the function once.
  EXPECT_EQ(f.fmi2DoStep(c, 30 * Ts_, -1.0, fmi2True), fmi2Error);
  ASSERT_EQ(fmu_->log().size(), 1u);
  EXPECT_NE(fmu_->log()[0].find("logStatusError: fmi2DoStep: "), std::string::npos) << fmu_->log()[0];
  EXPECT_EQ(count(fmu_->log()[0], "fmi2DoStep"), 1u) << fmu_->log()[0];
  fmu_->clear_log();
  EXPECT_EQ(f.fmi2DoStep(c, 30 * Ts_, 10 * Ts_, fmi2True), fmi2Error) << "error state";
  ASSERT_EQ(fmu_->log().size(), 1u);
  EXPECT_EQ(count(fmu_->log()[0], "fmi2DoStep"), 1u) << fmu_->log()[0];

  // loggingOn = true at instantiation: every category.
  fmu_->clear_log();
  fmi2Component d = start(0.0, true);
  EXPECT_TRUE(logged("logCalls: fmi2Instantiate: "));
  EXPECT_TRUE(logged("logCalls: fmi2ExitInitializationMode: "));
  const fmi2String unknown[] = {"logEverything"};
  EXPECT_EQ(f.fmi2SetDebugLogging(d, fmi2True, 1, unknown), fmi2Error);
  EXPECT_TRUE(logged("logEverything"));
}

}  // namespace
}  // namespace twin::fmu_test
