// The FMI 3.0 Co-Simulation FMU (`twin export-fmu --fmi 3`) as an outside
// tool sees it and as a master drives it, through dlopen (LoadedFmu3).
//
// Oracles: the FMI 3.0 XSD of the standard (xmllint); the standard's rules
// for ModelStructure and the independent variable, re-stated here; and the
// FMI 2.0 FMU of the same scenario, loaded in the same process. Both
// binaries run the same slave over the same machine, so every output after
// every step, and after a state save/restore, must be the same double, bit
// for bit (no tolerance). The FMI 2.0 FMU is itself checked against the
// native co-simulation in fmu_import_test and fmu_cosim_test.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "fmu3_importer.hpp"
#include "fmu_importer.hpp"

namespace twin::fmu_test {
namespace {

// ---- the archive and its modelDescription.xml -----------------------------------

struct Pair {
  const char* fmi3;
  const char* fmi2;
};

class Fmi3Archive : public ::testing::TestWithParam<Pair> {
 protected:
  void SetUp() override {
    REQUIRE_EXPORTED(GetParam().fmi3);
    fmu_ = std::make_unique<LoadedFmu3>(GetParam().fmi3);
  }
  std::unique_ptr<LoadedFmu3> fmu_;
};

TEST_P(Fmi3Archive, LayoutHasDescriptionBinaryForX86_64LinuxAndResources) {
  // FMI 3.0, 2.5.1: binaries/<arch>-<sys>/ ("x86_64-linux"), not FMI 2.0's linux64.
  EXPECT_EQ(fmu_->model_identifier(), "MachineTwin");
  EXPECT_TRUE(std::filesystem::exists(fmu_->dir() + "/binaries/x86_64-linux/MachineTwin.so"));
  EXPECT_FALSE(std::filesystem::exists(fmu_->dir() + "/binaries/linux64"));
  expect_scenario_resources(*fmu_);
}

TEST_P(Fmi3Archive, ModelDescriptionValidatesAgainstTheFmi3Schema) {
  expect_valid_model_description(*fmu_, TWIN_SHARED_DIR "/fmi/schema/fmi3/fmi3ModelDescription.xsd");
}

TEST_P(Fmi3Archive, ModelStructureFollowsTheStandard) {
  // FMI 3.0, 2.4.7 and 2.4.8: exactly one independent variable (no start, no
  // initial); value references unique; ModelStructure lists one Output per
  // causality="output" variable, in order, by value reference; the
  // InitialUnknowns are the outputs (initial="calculated"), depending only on
  // exact parameters or inputs.
  const std::string& x = fmu_->xml();
  EXPECT_NE(x.find("fmiVersion=\"3.0\""), std::string::npos);
  std::set<std::string> names;
  std::set<unsigned> vrs;
  std::vector<std::string> outputs;
  int independent = 0;
  for (const VarInfo& v : fmu_->variables()) {
    EXPECT_TRUE(names.insert(v.name).second) << "duplicate name " << v.name;
    EXPECT_TRUE(vrs.insert(v.vr).second) << "duplicate valueReference " << v.vr;
    if (v.causality == "independent") {
      ++independent;
      EXPECT_EQ(v.type, "Float64");
      EXPECT_TRUE(v.start.empty() && v.initial.empty()) << v.name;
    }
    if (v.causality == "output") {
      outputs.push_back(std::to_string(v.vr));
      EXPECT_EQ(v.initial, "calculated") << v.name;
      EXPECT_TRUE(v.start.empty()) << v.name;
    }
    if (v.causality == "input" || v.initial == "exact") {
      EXPECT_FALSE(v.start.empty()) << v.name << " needs a start";
    }
    if (v.type != "Float64") {
      EXPECT_NE(v.variability, "continuous") << v.name;
    }
  }
  EXPECT_EQ(independent, 1);
  auto listed = [&](const char* element) {
    std::vector<std::string> out;
    const std::regex re(std::string("<") + element + "\\s+valueReference=\"(\\d+)\"\\s+dependencies=\"([^\"]*)\"");
    for (auto it = std::sregex_iterator(x.begin(), x.end(), re); it != std::sregex_iterator(); ++it) {
      out.push_back((*it)[1]);
      std::istringstream deps((*it)[2].str());
      for (unsigned d = 0; deps >> d;) {
        bool ok = false;
        for (const VarInfo& v : fmu_->variables())
          if (v.vr == d) ok = v.causality == "input" || v.initial == "exact";
        EXPECT_TRUE(ok) << element << " " << (*it)[1] << " depends on valueReference " << d;
      }
    }
    return out;
  };
  ASSERT_FALSE(outputs.empty());
  EXPECT_EQ(listed("Output"), outputs);
  EXPECT_EQ(listed("InitialUnknown"), outputs);
  // A fixed-step FMU says so (FMI 3.0 adds fixedInternalStepSize for it).
  std::smatch m;
  ASSERT_TRUE(std::regex_search(x, m, std::regex("fixedInternalStepSize=\"([^\"]+)\"")));
  EXPECT_EQ(std::stod(m[1]), std::stod(fmu_->var("Ts").start));
}

TEST_P(Fmi3Archive, HasTheVariablesOfTheFmi2FmuOfTheSameScenario) {
  // The same table behind both: every FMI 2.0 variable with the same value
  // reference, causality, variability, unit and start; Real is Float64,
  // Integer Int32. FMI 3.0 adds only `time`.
  REQUIRE_EXPORTED(GetParam().fmi2);
  const LoadedFmu fmi2(GetParam().fmi2);
  ASSERT_EQ(fmu_->variables().size(), fmi2.variables().size() + 1);
  for (const VarInfo& v2 : fmi2.variables()) {
    ASSERT_TRUE(fmu_->has(v2.name)) << v2.name;
    const VarInfo& v3 = fmu_->var(v2.name);
    EXPECT_EQ(v3.vr, v2.vr) << v2.name;
    EXPECT_EQ(v3.type, v2.type == "Real" ? "Float64" : (v2.type == "Integer" ? "Int32" : v2.type)) << v2.name;
    EXPECT_EQ(v3.causality, v2.causality) << v2.name;
    EXPECT_EQ(v3.variability, v2.variability) << v2.name;
    EXPECT_EQ(v3.unit, v2.unit) << v2.name;
    EXPECT_EQ(v3.start, v2.start) << v2.name;
  }
  EXPECT_EQ(fmu_->var("time").causality, "independent");
  EXPECT_EQ(fmu_->default_experiment("stopTime"), fmi2.default_experiment("stopTime"));
  EXPECT_NE(fmu_->token(), fmi2.guid()) << "the two FMUs are told apart";
}

TEST_P(Fmi3Archive, BinaryExportsExactlyTheFmi3FunctionsAndNeedsOnlyTheCRuntime) {
  std::string out;
  ASSERT_EQ(run("nm -D --defined-only " + fmu_->so_path(), out), 0) << out;
  std::set<std::string> exported;
  std::istringstream syms(out);
  for (std::string line; std::getline(syms, line);) exported.insert(line.substr(line.rfind(' ') + 1));
  const auto& names = fmi3_function_names();
  EXPECT_EQ(exported, std::set<std::string>(names.begin(), names.end()));
  ASSERT_NO_FATAL_FAILURE(expect_only_the_c_runtime_needed(fmu_->so_path()));
}

INSTANTIATE_TEST_SUITE_P(Exported, Fmi3Archive,
                         ::testing::Values(Pair{TWIN_FMU3_AIRCUT, TWIN_FMU_AIRCUT},
                                           Pair{TWIN_FMU3_DEFAULT, TWIN_FMU_DEFAULT}),
                         [](const auto& p) { return std::string(p.index == 0 ? "AirCut" : "Default"); });

// ---- FMI 3.0 against FMI 2.0, output for output ------------------------------------

/// Both FMUs of one scenario, initialised, driven in lockstep.
class Fmi3AgainstFmi2 : public ::testing::Test {
 protected:
  void open(const char* fmi3_path, const char* fmi2_path) {
    REQUIRE_EXPORTED(fmi3_path);
    REQUIRE_EXPORTED(fmi2_path);
    f3_ = std::make_unique<LoadedFmu3>(fmi3_path);
    f2_ = std::make_unique<LoadedFmu>(fmi2_path);
    for (const VarInfo& v : f2_->variables()) {
      if (v.causality != "output") continue;
      (v.type == "Real" ? reals_ : (v.type == "Integer" ? ints_ : bools_)).push_back(v.vr);
    }
    Ts_ = std::stod(f3_->var("Ts").start);
    c3_ = f3_->instantiate("fmi3");
    c2_ = f2_->instantiate("fmi2");
    ASSERT_NE(c3_, nullptr) << (f3_->log().empty() ? "" : f3_->log().back());
    ASSERT_NE(c2_, nullptr);
    ASSERT_EQ(f3_->fn().fmi3EnterInitializationMode(c3_, fmi3False, 0.0, 0.0, fmi3False, 0.0), fmi3OK);
    ASSERT_EQ(f3_->fn().fmi3ExitInitializationMode(c3_), fmi3OK);
    ASSERT_EQ(f2_->fn().fmi2SetupExperiment(c2_, fmi2False, 0.0, 0.0, fmi2False, 0.0), fmi2OK);
    ASSERT_EQ(f2_->fn().fmi2EnterInitializationMode(c2_), fmi2OK);
    ASSERT_EQ(f2_->fn().fmi2ExitInitializationMode(c2_), fmi2OK);
  }
  void TearDown() override {
    if (c3_ != nullptr) f3_->fn().fmi3FreeInstance(c3_);
    if (c2_ != nullptr) f2_->fn().fmi2FreeInstance(c2_);
  }
  /// One step of n ticks in both, from tick k; checks the FMI 3.0 times.
  void step(std::int64_t k, std::int64_t n) {
    const double t = static_cast<double>(k) * Ts_;
    const double h = static_cast<double>(n) * Ts_;
    fmi3Boolean event = fmi3True, terminate = fmi3True, early = fmi3True;
    fmi3Float64 last = -1.0;
    ASSERT_EQ(f3_->fn().fmi3DoStep(c3_, t, h, fmi3True, &event, &terminate, &early, &last), fmi3OK)
        << "t = " << t << (f3_->log().empty() ? "" : ": " + f3_->log().back());
    ASSERT_EQ(f2_->fn().fmi2DoStep(c2_, t, h, fmi2True), fmi2OK) << "t = " << t;
    EXPECT_FALSE(event || terminate || early);
    EXPECT_EQ(last, t + h);
    const fmi3ValueReference time_vr = f3_->var("time").vr;
    fmi3Float64 time = -1.0;
    ASSERT_EQ(f3_->fn().fmi3GetFloat64(c3_, &time_vr, 1, &time, 1), fmi3OK);
    EXPECT_EQ(time, t + h);
  }
  /// Every output of both, as bits (Real/Float64, Integer/Int32, Boolean).
  std::pair<std::vector<std::uint64_t>, std::vector<std::uint64_t>> outputs() {
    std::vector<double> r3(reals_.size()), r2(reals_.size());
    std::vector<fmi3Int32> i3(ints_.size());
    std::vector<fmi2Integer> i2(ints_.size());
    std::vector<fmi2Boolean> b2(bools_.size());
    std::unique_ptr<fmi3Boolean[]> b3(new fmi3Boolean[bools_.size()]);
    EXPECT_EQ(f3_->fn().fmi3GetFloat64(c3_, reals_.data(), reals_.size(), r3.data(), r3.size()), fmi3OK);
    EXPECT_EQ(f3_->fn().fmi3GetInt32(c3_, ints_.data(), ints_.size(), i3.data(), i3.size()), fmi3OK);
    EXPECT_EQ(f3_->fn().fmi3GetBoolean(c3_, bools_.data(), bools_.size(), b3.get(), bools_.size()), fmi3OK);
    EXPECT_EQ(f2_->fn().fmi2GetReal(c2_, reals_.data(), reals_.size(), r2.data()), fmi2OK);
    EXPECT_EQ(f2_->fn().fmi2GetInteger(c2_, ints_.data(), ints_.size(), i2.data()), fmi2OK);
    EXPECT_EQ(f2_->fn().fmi2GetBoolean(c2_, bools_.data(), bools_.size(), b2.data()), fmi2OK);
    std::pair<std::vector<std::uint64_t>, std::vector<std::uint64_t>> out;
    for (std::size_t i = 0; i < reals_.size(); ++i) {
      out.first.push_back(std::bit_cast<std::uint64_t>(r3[i]));
      out.second.push_back(std::bit_cast<std::uint64_t>(r2[i]));
    }
    for (std::size_t i = 0; i < ints_.size(); ++i) {
      out.first.push_back(static_cast<std::uint64_t>(i3[i]));
      out.second.push_back(static_cast<std::uint64_t>(i2[i]));
    }
    for (std::size_t i = 0; i < bools_.size(); ++i) {
      out.first.push_back(b3[i] ? 1u : 0u);
      out.second.push_back(b2[i] != fmi2False ? 1u : 0u);
    }
    return out;
  }
  void expect_equal_outputs(const std::string& when) {
    const auto [a, b] = outputs();
    ASSERT_EQ(a.size(), b.size());
    for (std::size_t i = 0; i < a.size(); ++i) ASSERT_EQ(a[i], b[i]) << "output " << i << " " << when;
  }
  double real(const std::string& name) {
    const fmi3ValueReference vr = f3_->var(name).vr;
    double v = 0.0;
    EXPECT_EQ(f3_->fn().fmi3GetFloat64(c3_, &vr, 1, &v, 1), fmi3OK);
    return v;
  }

  std::unique_ptr<LoadedFmu3> f3_;
  std::unique_ptr<LoadedFmu> f2_;
  fmi3Instance c3_{nullptr};
  fmi2Component c2_{nullptr};
  std::vector<unsigned> reals_, ints_, bools_;
  double Ts_{1e-4};
};

TEST_F(Fmi3AgainstFmi2, AirCutWholeRunEqualsTheFmi2FmuBitForBit) {
  // The whole default experiment (the program's end plus settle_s) in steps of
  // the default step size (10 ticks), every output compared after every step.
  open(TWIN_FMU3_AIRCUT, TWIN_FMU_AIRCUT);
  const auto n_end = std::llround(std::stod(f3_->default_experiment("stopTime")) / Ts_);
  const auto n_step = std::llround(std::stod(f3_->default_experiment("stepSize")) / Ts_);
  ASSERT_GT(n_end, 1000);
  expect_equal_outputs("at initialization");
  const double x0 = real("x_mm");
  double travel_mm = 0.0;
  for (std::int64_t k = 0; k < n_end; k += n_step) {
    step(k, std::min<std::int64_t>(n_step, n_end - k));
    expect_equal_outputs("after the step from tick " + std::to_string(k));
    travel_mm = std::max(travel_mm, std::abs(real("x_mm") - x0));
  }
  EXPECT_GT(travel_mm, 1.0) << "the program must move the axis";
  EXPECT_EQ(f3_->fn().fmi3Terminate(c3_), fmi3OK);
}

TEST_F(Fmi3AgainstFmi2, CuttingRunAndAStateRestoreEqualTheFmi2FmuBitForBit) {
  // 1.2 s of the pocket corner (the tool enters the stock after ~0.9 s), then
  // both FMUs save their state, run 5 steps, restore and run the same 5
  // steps again: four runs, one result.
  open(TWIN_FMU3_DEFAULT, TWIN_FMU_DEFAULT);
  double peak_N = 0.0;
  std::int64_t k = 0;
  for (; k < 12000; k += 100) {
    step(k, 100);
    expect_equal_outputs("after the step from tick " + std::to_string(k));
    peak_N = std::max(peak_N, std::abs(real("fx_N")) + std::abs(real("fy_N")));
  }
  EXPECT_GT(peak_N, 1.0) << "the run must reach the cut";
  fmi3FMUState s3 = nullptr;
  fmi2FMUstate s2 = nullptr;
  ASSERT_EQ(f3_->fn().fmi3GetFMUState(c3_, &s3), fmi3OK);
  ASSERT_EQ(f2_->fn().fmi2GetFMUstate(c2_, &s2), fmi2OK);
  auto run_on = [&]() {
    std::vector<std::uint64_t> all;
    for (std::int64_t j = k; j < k + 500; j += 100) {
      step(j, 100);
      expect_equal_outputs("after the restore, step from tick " + std::to_string(j));
      const auto row = outputs().first;
      all.insert(all.end(), row.begin(), row.end());
    }
    return all;
  };
  const auto first = run_on();
  ASSERT_EQ(f3_->fn().fmi3SetFMUState(c3_, s3), fmi3OK);
  ASSERT_EQ(f2_->fn().fmi2SetFMUstate(c2_, s2), fmi2OK);
  EXPECT_EQ(run_on(), first);
  // With the cutting process the state cannot be serialized (declared so).
  std::size_t size = 0;
  EXPECT_EQ(f3_->fn().fmi3SerializedFMUStateSize(c3_, s3, &size), fmi3Error);
  EXPECT_NE(f3_->xml().find("canSerializeFMUState=\"false\""), std::string::npos);
  f3_->fn().fmi3FreeFMUState(c3_, &s3);
  f2_->fn().fmi2FreeFMUstate(c2_, &s2);
}

TEST_F(Fmi3AgainstFmi2, ASerializedStateRestoresTheSameRunAsTheFmi2Fmu) {
  // Air cut: the FMI 3.0 state goes through bytes and back, then both FMUs
  // go back to tick 2000 and run on with a force input set in both.
  open(TWIN_FMU3_AIRCUT, TWIN_FMU_AIRCUT);
  for (std::int64_t k = 0; k < 2000; k += 250) step(k, 250);
  fmi3FMUState s3 = nullptr;
  fmi2FMUstate s2 = nullptr;
  ASSERT_EQ(f3_->fn().fmi3GetFMUState(c3_, &s3), fmi3OK);
  ASSERT_EQ(f2_->fn().fmi2GetFMUstate(c2_, &s2), fmi2OK);
  std::size_t size = 0;
  ASSERT_EQ(f3_->fn().fmi3SerializedFMUStateSize(c3_, s3, &size), fmi3OK);
  std::vector<fmi3Byte> bytes(size);
  ASSERT_EQ(f3_->fn().fmi3SerializeFMUState(c3_, s3, bytes.data(), size), fmi3OK);
  fmi3FMUState back = nullptr;
  ASSERT_EQ(f3_->fn().fmi3DeserializeFMUState(c3_, bytes.data(), bytes.size(), &back), fmi3OK);
  for (std::int64_t k = 2000; k < 3000; k += 250) step(k, 250);
  ASSERT_EQ(f3_->fn().fmi3SetFMUState(c3_, back), fmi3OK);
  ASSERT_EQ(f2_->fn().fmi2SetFMUstate(c2_, s2), fmi2OK);
  expect_equal_outputs("after the restore");
  const fmi3ValueReference fx = f3_->var("fx_ext_N").vr;
  const double force_N = 250.0;
  ASSERT_EQ(f3_->fn().fmi3SetFloat64(c3_, &fx, 1, &force_N, 1), fmi3OK);
  ASSERT_EQ(f2_->fn().fmi2SetReal(c2_, &fx, 1, &force_N), fmi2OK);
  for (std::int64_t k = 2000; k < 3000; k += 250) {
    step(k, 250);
    expect_equal_outputs("after the restore, step from tick " + std::to_string(k));
  }
  for (fmi3FMUState* s : {&s3, &back}) f3_->fn().fmi3FreeFMUState(c3_, s);
  f2_->fn().fmi2FreeFMUstate(c2_, &s2);
}

// ---- bad input: fmi3Error with one clear log line, never a crash -----------------------

class Fmi3Calls : public ::testing::Test {
 protected:
  void SetUp() override {
    REQUIRE_EXPORTED(TWIN_FMU3_AIRCUT);
    fmu_ = std::make_unique<LoadedFmu3>(TWIN_FMU3_AIRCUT);
    Ts_ = std::stod(fmu_->var("Ts").start);
  }
  void TearDown() override {
    for (fmi3Instance c : instances_) fmu_->fn().fmi3FreeInstance(c);
  }
  fmi3Instance initialised() {
    fmi3Instance c = fmu_->instantiate("calls");
    EXPECT_NE(c, nullptr);
    if (c == nullptr) return c;
    instances_.push_back(c);
    EXPECT_EQ(fmu_->fn().fmi3EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0), fmi3OK);
    EXPECT_EQ(fmu_->fn().fmi3ExitInitializationMode(c), fmi3OK);
    return c;
  }
  fmi3Status do_step(fmi3Instance c, double t, double h) {
    fmi3Boolean event = fmi3False, terminate = fmi3False, early = fmi3False;
    fmi3Float64 last = 0.0;
    return fmu_->fn().fmi3DoStep(c, t, h, fmi3False, &event, &terminate, &early, &last);
  }
  const std::string& last_log() const {
    static const std::string none = "(no log line)";
    return fmu_->log().empty() ? none : fmu_->log().back();
  }
  std::unique_ptr<LoadedFmu3> fmu_;
  std::vector<fmi3Instance> instances_;
  double Ts_{1e-4};
};

TEST_F(Fmi3Calls, VersionIs30) { EXPECT_STREQ(fmu_->fn().fmi3GetVersion(), "3.0"); }

TEST_F(Fmi3Calls, AWrongInstantiationTokenGivesNoInstanceAndALogLine) {
  EXPECT_EQ(fmu_->instantiate("bad", "{00000000-0000-0000-0000-000000000000}"), nullptr);
  ASSERT_EQ(fmu_->log().size(), 1u);
  EXPECT_NE(last_log().find("instantiationToken {00000000-0000-0000-0000-000000000000} does not match"),
            std::string::npos)
      << last_log();
  EXPECT_NE(last_log().find("[3] logStatusError"), std::string::npos) << last_log();
}

TEST_F(Fmi3Calls, InterfacesAndModesTheFmuDoesNotHaveGiveNoInstance) {
  EXPECT_EQ(fmu_->fn().fmi3InstantiateModelExchange("me", fmu_->token().c_str(), fmu_->resource_path().c_str(),
                                                    fmi3False, fmi3False, nullptr, nullptr),
            nullptr);
  EXPECT_EQ(fmu_->fn().fmi3InstantiateCoSimulation("ev", fmu_->token().c_str(), fmu_->resource_path().c_str(),
                                                   fmi3False, fmi3False, fmi3True, fmi3False, nullptr, 0, nullptr,
                                                   nullptr, nullptr),
            nullptr)
      << "eventModeUsed with hasEventMode=false";
}

TEST_F(Fmi3Calls, AnUnknownValueReferenceIsAnErrorNamingIt) {
  fmi3Instance c = initialised();
  const fmi3ValueReference bad = 99999;
  fmi3Float64 v = 0.0;
  EXPECT_EQ(fmu_->fn().fmi3GetFloat64(c, &bad, 1, &v, 1), fmi3Error);
  EXPECT_NE(last_log().find("unknown valueReference 99999"), std::string::npos) << last_log();
  EXPECT_NE(last_log().find("fmi3GetFloat64"), std::string::npos) << last_log();
  // Another instance: the wrong type, a Float32 read, a count that does not
  // match, and the independent variable set.
  fmi3Instance d = initialised();
  const fmi3ValueReference block = fmu_->var("block").vr;
  EXPECT_EQ(fmu_->fn().fmi3GetFloat64(d, &block, 1, &v, 1), fmi3Error);
  EXPECT_NE(last_log().find("is not of this type"), std::string::npos) << last_log();
  fmi3Instance e = initialised();
  const fmi3ValueReference x_mm = fmu_->var("x_mm").vr;
  fmi3Float32 f32 = 0.0f;
  EXPECT_EQ(fmu_->fn().fmi3GetFloat32(e, &x_mm, 1, &f32, 1), fmi3Error);
  EXPECT_NE(last_log().find("is not a Float32 variable"), std::string::npos) << last_log();
  fmi3Instance g = initialised();
  double two[2] = {0.0, 0.0};
  EXPECT_EQ(fmu_->fn().fmi3GetFloat64(g, &x_mm, 1, two, 2), fmi3Error);
  EXPECT_NE(last_log().find("nValues = 2 for 1 value references"), std::string::npos) << last_log();
  fmi3Instance h = initialised();
  const fmi3ValueReference time_vr = fmu_->var("time").vr;
  const double t = 1.0;
  EXPECT_EQ(fmu_->fn().fmi3SetFloat64(h, &time_vr, 1, &t, 1), fmi3Error);
  EXPECT_NE(last_log().find("independent variable"), std::string::npos) << last_log();
}

TEST_F(Fmi3Calls, AStepThatIsNotAWholeNumberOfTicksIsAnErrorUntilReset) {
  // FMI 3.0 declares fixedInternalStepSize = Ts: 1.5 ticks is refused with
  // the numbers; the instance is then in the error state (further steps are
  // errors) until fmi3Reset, after which the run repeats the first exactly.
  fmi3Instance c = initialised();
  ASSERT_EQ(do_step(c, 0.0, 10 * Ts_), fmi3OK);
  const fmi3ValueReference x_mm = fmu_->var("x_true_mm").vr;
  EXPECT_EQ(do_step(c, 10 * Ts_, 1.5 * Ts_), fmi3Error);
  EXPECT_NE(last_log().find("is not a whole number of controller ticks"), std::string::npos) << last_log();
  EXPECT_NE(last_log().find("1.5 ticks"), std::string::npos) << last_log();
  EXPECT_EQ(do_step(c, 10 * Ts_, 10 * Ts_), fmi3Error) << "no step in the error state";
  EXPECT_EQ(do_step(c, 10 * Ts_, -Ts_), fmi3Error);
  EXPECT_NE(last_log().find("not allowed in state 'error'"), std::string::npos) << last_log();
  ASSERT_EQ(fmu_->fn().fmi3Reset(c), fmi3OK);
  EXPECT_EQ(fmu_->fn().fmi3EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0), fmi3OK);
  EXPECT_EQ(fmu_->fn().fmi3ExitInitializationMode(c), fmi3OK);
  EXPECT_EQ(do_step(c, 0.0, -Ts_), fmi3Error);
  EXPECT_NE(last_log().find("communicationStepSize = -0.0001 s must be > 0"), std::string::npos) << last_log();
  // A fresh instance: 2000 ticks in steps of 10 and in one step give one row.
  fmi3Instance a = initialised();
  fmi3Instance b = initialised();
  for (int k = 0; k < 2000; k += 10) ASSERT_EQ(do_step(a, k * Ts_, 10 * Ts_), fmi3OK) << k;
  ASSERT_EQ(do_step(b, 0.0, 2000 * Ts_), fmi3OK);
  double xa = 0.0, xb = 1.0;
  ASSERT_EQ(fmu_->fn().fmi3GetFloat64(a, &x_mm, 1, &xa, 1), fmi3OK);
  ASSERT_EQ(fmu_->fn().fmi3GetFloat64(b, &x_mm, 1, &xb, 1), fmi3OK);
  EXPECT_EQ(xa, xb);
}

TEST_F(Fmi3Calls, CallsOutOfTurnAreErrorsAndWhatTheFmuLacksIsRefusedWithItsReason) {
  fmi3Instance c = fmu_->instantiate("early");
  ASSERT_NE(c, nullptr);
  instances_.push_back(c);
  EXPECT_EQ(do_step(c, 0.0, 10 * Ts_), fmi3Error) << "DoStep before initialization";
  EXPECT_NE(last_log().find("not allowed in state 'instantiated'"), std::string::npos) << last_log();
  fmi3Instance d = initialised();
  EXPECT_EQ(fmu_->fn().fmi3EnterEventMode(d), fmi3Error);
  EXPECT_NE(last_log().find("hasEventMode=false"), std::string::npos) << last_log();
  EXPECT_EQ(fmu_->fn().fmi3EnterStepMode(d), fmi3Error);
  // Refusing what the FMU lacks leaves the instance usable.
  EXPECT_EQ(do_step(d, 0.0, 10 * Ts_), fmi3OK);
  fmi3Instance e = initialised();
  EXPECT_EQ(do_step(e, 0.0, 1e5), fmi3Discard) << "more ticks than one step runs";
  EXPECT_EQ(do_step(e, 0.0, 10 * Ts_), fmi3OK) << "a Discard changes nothing";
}

TEST(Fmi3Export, TheFmi2BinaryIsNotPackedAsAnFmi3Fmu) {
  // `--fmi 3 --binary` with the FMI 2.0 binary: one line, exit 1, no file.
  REQUIRE_EXPORTED(TWIN_FMU_AIRCUT);
  const LoadedFmu fmi2(TWIN_FMU_AIRCUT);
  const std::string out_path = fmi2.dir() + "/wrong.fmu";
  std::string out;
  const int rc = run(std::string(TWIN_BINARY_DIR) + "/bin/twin export-fmu --fmi 3 --binary " + fmi2.so_path() +
                         " -o " + out_path,
                     out);
  EXPECT_EQ(rc, 1) << out;
  EXPECT_NE(out.find("not an FMI 3.0 binary"), std::string::npos) << out;
  EXPECT_EQ(std::count(out.begin(), out.end(), '\n'), 1) << out;
  EXPECT_FALSE(std::filesystem::exists(out_path));
}

}  // namespace
}  // namespace twin::fmu_test
