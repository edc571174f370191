// make_process_from_json (fmu/process_json.hpp). Oracle: the same
// process::ProcessSetup written out field by field in this test and built
// with process::make_process; both models stepped through the same tool path
// must give identical outputs (the reader only transports numbers).
#include <gtest/gtest.h>

#include <array>
#include <cstdint>
#include <filesystem>

#include <nlohmann/json.hpp>
#include <yaml-cpp/yaml.h>

#include "fmu/process_json.hpp"
#include "process/milling_process.hpp"
#include "twin/core/error.hpp"
#include "twin/io/process_yaml.hpp"
#include "twin/io/scenario_file.hpp"

namespace twin::fmu {
namespace {

// The keys of a scenario's `process:` section (docs/process.md), in JSON.
const char* kProcess = R"({
  "tool": {"name": "em10", "type": "bull_nose", "diameter_mm": 10, "flutes": 2, "helix_deg": 30,
           "corner_radius_mm": 1.5, "flute_length_mm": 22},
  "material": {"name": "lin", "sets": [{"Ktc_N_per_mm2": 800, "Krc_N_per_mm2": 250, "Kac_N_per_mm2": 100,
                                        "Kte_N_per_mm": 25, "Kre_N_per_mm": 30, "Kae_N_per_mm": 5}]},
  "stock": {"box_mm": [0, 0, 40, 40], "top_z_mm": 0, "bottom_z_mm": -20, "cell_mm": 0.05},
  "model": {"dz_mm": 0.2, "angle_step_deg": 2.0},
  "spindle_angle0_deg": 10
})";

process::ProcessSetup direct_setup() {
  process::ProcessSetup s;
  s.tool.name = "em10";
  s.tool.shape = process::ToolShape::kBullNose;
  s.tool.diameter_mm = 10;
  s.tool.flutes = 2;
  s.tool.helix_deg = 30;
  s.tool.corner_radius_mm = 1.5;
  s.tool.flute_length_mm = 22;
  s.coefficients = process::CuttingCoefficients::linear(800, 250, 100, 25, 30, 5);
  s.coefficients.name = "lin";
  s.stock.outline_mm = process::StockSpec::rectangle(0, 0, 40, 40);
  s.stock.top_z_mm = 0;
  s.stock.bottom_z_mm = -20;
  s.stock.cell_mm = 0.05;
  s.options.dz_mm = 0.2;
  s.options.angle_step_deg = 2.0;
  s.spindle_angle0_deg = 10;
  return s;
}

/// Tick k (of 1e-4 s) of a straight move from p0 at v (mm/s) with the spindle at `rpm`.
process::ProcessInput straight_move_tick(std::int64_t k, const std::array<double, 3>& p0,
                                         const std::array<double, 3>& v, double rpm) {
  process::ProcessInput in;
  in.k = k;
  in.Ts_s = 1e-4;
  in.t_s = static_cast<double>(k) * in.Ts_s;
  in.p_mm = {p0[0] + v[0] * in.t_s, p0[1] + v[1] * in.t_s, p0[2] + v[2] * in.t_s};
  in.v_mm_per_s = v;
  in.spindle_rpm = rpm;
  return in;
}

TEST(ProcessJson, BuildsTheSameProcessAsTheSetupItDescribes) {
  auto from_json = make_process_from_json(nlohmann::json::parse(kProcess));
  auto direct = process::make_process(direct_setup());
  ASSERT_NE(from_json, nullptr);
  double peak_N = 0.0;
  for (std::int64_t k = 0; k < 300; ++k) {
    // Entering the stock along +x at 50 mm/s, 2 mm deep.
    const process::ProcessInput in = straight_move_tick(k, {-4.0, 20.0, -2.0}, {50.0, 0.0, 0.0}, 6000.0);
    const process::ProcessOutput a = from_json->step(in);
    const process::ProcessOutput b = direct->step(in);
    for (std::size_t i = 0; i < 3; ++i) {
      ASSERT_EQ(a.F_N[i], b.F_N[i]) << "tick " << k;
      ASSERT_EQ(a.F_avg_N[i], b.F_avg_N[i]) << "tick " << k;
    }
    ASSERT_EQ(a.engagement_deg, b.engagement_deg);
    ASSERT_EQ(a.removed_mm3, b.removed_mm3);
    peak_N = std::max(peak_N, std::abs(a.F_N[1]));
  }
  EXPECT_GT(peak_N, 1.0) << "the path must cut, or the comparison proves nothing";
}

TEST(ProcessJson, SetupWrittenAndReadBackGivesTheSameProcess) {
  // The path export-fmu takes: the resolved setup of the default scenario
  // (tool and material files read) -> JSON text -> process.
  const std::filesystem::path path = io::default_scenario_path();
  const YAML::Node root = YAML::LoadFile(path.string());
  ASSERT_TRUE(root["process"]) << "the default scenario cuts";
  const process::ProcessSetup setup = io::parse_process_setup(root["process"], path.string(), path.parent_path());
  const std::string text = process_setup_to_json(setup).dump();
  auto from_json = make_process_from_json(nlohmann::json::parse(text));
  auto direct = process::make_process(setup);
  const auto& outline = setup.stock.outline_mm;
  ASSERT_FALSE(outline.empty());
  double x_max = -1e9, y_min = 1e9, y_max = -1e9;
  for (const auto& q : outline) {
    x_max = std::max(x_max, q.x_mm);
    y_min = std::min(y_min, q.y_mm);
    y_max = std::max(y_max, q.y_mm);
  }
  // Along the stock's outer wall x = x_max (half immersion), 1 mm deep, in +y.
  const double x0 = x_max, y0 = 0.5 * (y_min + y_max), z = setup.stock.top_z_mm - 1.0;
  double peak_N = 0.0;
  for (std::int64_t k = 0; k < 300; ++k) {
    const process::ProcessInput in = straight_move_tick(k, {x0, y0, z}, {0.0, 40.0, 0.0}, 8000.0);
    const process::ProcessOutput a = from_json->step(in);
    const process::ProcessOutput b = direct->step(in);
    for (std::size_t i = 0; i < 3; ++i) ASSERT_EQ(a.F_N[i], b.F_N[i]) << "tick " << k;
    ASSERT_EQ(a.removed_mm3, b.removed_mm3) << "tick " << k;
    peak_N = std::max(peak_N, std::abs(a.F_N[0]) + std::abs(a.F_N[1]));
  }
  EXPECT_GT(peak_N, 0.0) << "the path must cut, or the comparison proves nothing";
}

TEST(ProcessJson, NullIsAnAirCut) { EXPECT_EQ(make_process_from_json(nullptr), nullptr); }

TEST(ProcessJson, UnknownKeysAndBadValuesAreNamed) {
  nlohmann::json j = nlohmann::json::parse(kProcess);
  j["tool"]["diamter_mm"] = 10;
  try {
    make_process_from_json(j);
    FAIL() << "a misspelt key was accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("diamter_mm"), std::string::npos) << e.what();
  }
  j = nlohmann::json::parse(kProcess);
  j["tool"]["diameter_mm"] = "ten";
  EXPECT_THROW(make_process_from_json(j), ConfigError);
  j = nlohmann::json::parse(kProcess);
  j["tool"]["diameter_mm"] = -10;
  EXPECT_THROW(make_process_from_json(j), ConfigError);
}

}  // namespace
}  // namespace twin::fmu
