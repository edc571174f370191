// The FMU as a co-simulation master drives it: its default experiment and
// the outputs' dependencies on the inputs. Every test goes through dlopen
// (LoadedFmu).
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

std::string export_error(const std::string& fmu) {
  std::ifstream e(fmu + ".error");
  if (!e) return {};
  std::stringstream s;
  s << e.rdbuf();
  return s.str();
}

#define REQUIRE_EXPORTED(path)                                                 \
  do {                                                                         \
    const std::string err = export_error(path);                                \
    ASSERT_TRUE(err.empty()) << err;                                           \
    ASSERT_TRUE(std::filesystem::exists(path)) << path << " was not exported"; \
  } while (false)

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

TEST_F(FmuCosim, DefaultStopTimeIsTheProgramEndOnTheTickGrid) {
  // Oracle: the twin's own plan of the program (duration) plus settle_s,
  // rounded up to a whole tick.
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

}  // namespace
}  // namespace twin::fmu_test
