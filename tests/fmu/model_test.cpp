// resources/model.json and the GUID (fmu/model.hpp, fmu/model_description.hpp).
// Oracle for the round trip: the machine definition loaded from the YAML
// scenario itself, parameter by parameter through the table of
// twin/sim/machine.hpp (exact equality: JSON keeps doubles to the last bit).
#include <gtest/gtest.h>

#include <regex>

#include <nlohmann/json.hpp>

#include "fmu/model.hpp"
#include "fmu/model_description.hpp"
#include "twin/core/error.hpp"
#include "twin/io/scenario_file.hpp"

namespace twin::fmu {
namespace {

io::Scenario aircut() { return io::load_scenario(TWIN_SOURCE_DIR "/tests/fmu/aircut/scenario.yaml"); }

std::string to_json(const io::Scenario& s, const nlohmann::json& process = nullptr) {
  return model_to_json(s.name, s.machine, "aircut.nc", s.program_text, s.start_mm, s.settle_s, process);
}

void expect_same_machine(const sim::MachineDefinition& a, const sim::MachineDefinition& b) {
  sim::MachineDefinition ca = a, cb = b;
  for (const auto& spec : sim::machine_param_specs()) EXPECT_EQ(spec.ref(ca), spec.ref(cb)) << spec.name;
  for (Axis ax : kAllAxes) {
    EXPECT_EQ(a.axes[index(ax)].present, b.axes[index(ax)].present);
    if (!a.axes[index(ax)].present) continue;
    sim::AxisDefinition da = a.axes[index(ax)], db = b.axes[index(ax)];
    for (const auto& spec : sim::axis_param_specs()) {
      if (spec.enables != nullptr) {
        EXPECT_EQ(*spec.enables(da), *spec.enables(db)) << axis_name(ax) << "." << spec.name << " enabled";
        if (!*spec.enables(da)) continue;
      }
      EXPECT_EQ(sim::get_axis_param(da, spec), sim::get_axis_param(db, spec)) << axis_name(ax) << "." << spec.name;
    }
  }
}

TEST(FmuModel, JsonRoundTripKeepsEveryParameterExactly) {
  io::Scenario s = aircut();
  sim::apply_set(s.machine, "y.stribeck.Ts_static=0.35");
  sim::apply_set(s.machine, "y.stribeck.ws=2.5");
  sim::apply_set(s.machine, "x.Kp=512.25");
  const FmuModel m = model_from_json(to_json(s), "model.json");
  expect_same_machine(s.machine, m.machine);
  EXPECT_EQ(m.program_text, s.program_text);
  EXPECT_EQ(m.start_mm, s.start_mm);
  EXPECT_EQ(m.settle_s, s.settle_s);
  EXPECT_FALSE(m.has_process());
  EXPECT_TRUE(m.has_program());
}

TEST(FmuModel, GuidIsStableAndFollowsTheModel) {
  io::Scenario s = aircut();
  const FmuModel a = model_from_json(to_json(s), "a");
  const FmuModel a2 = model_from_json(to_json(s), "a2");
  EXPECT_EQ(model_guid(a), model_guid(a2));
  EXPECT_NE(model_description_xml(a).find(model_guid(a)), std::string::npos);
  io::Scenario t = s;
  sim::apply_set(t.machine, "x.Kp=501");
  EXPECT_NE(model_guid(model_from_json(to_json(t), "b")), model_guid(a));
  io::Scenario u = s;
  u.program_text += "\n";
  EXPECT_NE(model_guid(model_from_json(to_json(u), "c")), model_guid(a));
  EXPECT_TRUE(std::regex_match(model_guid(a), std::regex(R"(\{[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}\})")));
}

TEST(FmuModel, BadModelFilesNameTheProblem) {
  io::Scenario s = aircut();
  nlohmann::json j = nlohmann::json::parse(to_json(s));
  j["machine"]["axes"]["x"]["Kq"] = 1.0;
  try {
    model_from_json(j.dump(), "resources/model.json");
    FAIL() << "an unknown parameter was accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("'Kq'"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("resources/model.json"), std::string::npos) << e.what();
  }
  EXPECT_THROW(model_from_json("{", "m"), ConfigError);
  EXPECT_THROW(model_from_json(R"({"format": "other"})", "m"), ConfigError);
  j = nlohmann::json::parse(to_json(s));
  j["machine"]["axes"]["x"]["J"] = -1.0;
  EXPECT_THROW(model_from_json(j.dump(), "m"), ConfigError);
}

}  // namespace
}  // namespace twin::fmu
