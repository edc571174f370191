// The process section of the shipped scenarios parses into what the files
// say (values read back against the numbers in the YAML, Duan 2025 eq. (22)),
// and bad input is a one-line ConfigError naming the file and the key.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "process/milling_process.hpp"
#include "twin/core/error.hpp"
#include "twin/io/process_yaml.hpp"
#include "twin/io/yaml_util.hpp"

namespace twin::io {
namespace {

const std::filesystem::path kScenarios = std::filesystem::path(TWIN_SOURCE_DIR) / "scenarios";

TEST(ProcessYaml, ShippedScenariosBuildProcesses) {
  for (const char* name : {"fadal_pocket_corner", "pocket_rectangle", "slot", "aluminium_hsm"}) {
    const auto file = kScenarios / name / "scenario.yaml";
    const YAML::Node root = load_yaml_file(file);
    const process::ProcessSetup setup =
        parse_process_setup(root["process"], file.string() + ": process", file.parent_path());
    auto model = process::make_process(setup);
    ASSERT_NE(model, nullptr) << name;
    EXPECT_FALSE(setup.summary().empty());
  }
}

TEST(ProcessYaml, DuanSet4IsReadAsWritten) {
  const auto tool = load_tool_file(kScenarios / "tools/duan2025_bullnose_d10.yaml");
  EXPECT_EQ(tool.shape, process::ToolShape::kBullNose);
  EXPECT_EQ(tool.diameter_mm, 10.0);
  EXPECT_EQ(tool.flutes, 2);
  EXPECT_EQ(tool.helix_deg, 30.0);
  EXPECT_EQ(tool.corner_radius_mm, 1.5);
  const auto k = load_material_file(kScenarios / "materials/al2024_t6_duan2025.yaml", 0.0, 0.0);
  // K_t(h) = 816.935 + 1913.93 exp(-41.7956 h) (Duan 2025 eq. (22)).
  EXPECT_NEAR(k.Kt.at(0.02), 816.935 + 1913.93 * std::exp(-41.7956 * 0.02), 1e-9);
  EXPECT_NEAR(k.Kr.at(0.02), 166.518 + 686.391 * std::exp(-25.2867 * 0.02), 1e-9);
  EXPECT_NEAR(k.Ka.at(0.02), 868.228 - 884.065 * std::exp(-0.17887 * 0.02), 1e-9);
  const auto k2 = load_material_file(kScenarios / "materials/al2024_t6_duan2025.yaml", 10.0, 0.0);
  EXPECT_NEAR(k2.Kt.a_N_per_mm2, 743.408, 1e-12);
  try {
    load_material_file(kScenarios / "materials/al2024_t6_duan2025.yaml", 5.0, 0.0);
    FAIL() << "no set for lead 5";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("lead 5"), std::string::npos) << e.what();
  }
}

/// `message` := what the ConfigError says that loading `file`, written with
/// `text`, throws (a fatal failure when it throws none).
void tool_file_error(const std::filesystem::path& file, const std::string& text, std::string& message) {
  std::ofstream(file) << text;
  try {
    load_tool_file(file);
    FAIL();
  } catch (const ConfigError& e) {
    message = e.what();
  }
}

TEST(ProcessYaml, ErrorsNameFileAndKey) {
  const auto dir = std::filesystem::path(TWIN_BINARY_DIR) / "process_yaml_test";
  std::filesystem::create_directories(dir);
  const auto file = dir / "tool.yaml";
  // A bull-nose corner larger than the tool's radius; then a key no tool has, on line 7.
  const std::string corner = "tool:\n  type: bull_nose\n  diameter_mm: 10\n  flutes: 2\n  helix_deg: 30\n"
                             "  corner_radius_mm: 7\n  flute_length_mm: 20\n";
  const std::string colour = "tool:\n  type: flat\n  diameter_mm: 10\n  flutes: 2\n  helix_deg: 30\n"
                             "  flute_length_mm: 20\n  colour: red\n";
  std::string m;
  ASSERT_NO_FATAL_FAILURE(tool_file_error(file, corner, m));
  EXPECT_NE(m.find("tool.yaml"), std::string::npos) << m;
  EXPECT_NE(m.find("corner_radius_mm"), std::string::npos) << m;
  EXPECT_EQ(m.find('\n'), std::string::npos) << m;
  ASSERT_NO_FATAL_FAILURE(tool_file_error(file, colour, m));
  EXPECT_NE(m.find("colour"), std::string::npos) << m;
  EXPECT_NE(m.find(":7:"), std::string::npos) << m;
}

}  // namespace
}  // namespace twin::io
