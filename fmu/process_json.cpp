#include "fmu/process_json.hpp"

#include <cmath>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "process/milling_process.hpp"
#include "twin/core/error.hpp"
#include "twin/sim/process_setup_reader.hpp"

namespace twin::fmu {
namespace {

using nlohmann::json;

/// A JSON value as the process setup reader sees it (no lines, no files).
class JsonSetupNode final : public sim::SetupNode {
 public:
  explicit JsonSetupNode(const json& j) : j_(j) {}
  const char* format() const override { return "JSON"; }
  bool is_map() const override { return j_.is_object(); }
  bool is_list() const override { return j_.is_array(); }
  bool is_scalar() const override { return j_.is_primitive() && !j_.is_null(); }
  std::vector<std::string> keys() const override {
    std::vector<std::string> out;
    if (j_.is_object())
      for (const auto& [key, v] : j_.items()) out.push_back(key);
    return out;
  }
  std::unique_ptr<sim::SetupNode> get(const std::string& key) const override {
    if (!j_.is_object() || !j_.contains(key)) return nullptr;
    return std::make_unique<JsonSetupNode>(j_.at(key));
  }
  std::size_t size() const override { return j_.is_array() || j_.is_object() ? j_.size() : 0; }
  std::unique_ptr<sim::SetupNode> item(std::size_t i) const override { return std::make_unique<JsonSetupNode>(j_.at(i)); }
  double number(const std::string& where) const override {
    if (!j_.is_number()) throw ConfigError(fmt::format("{} = {} must be a number", where, j_.dump()));
    const double v = j_.get<double>();
    if (!std::isfinite(v)) throw ConfigError(fmt::format("{} = {} must be finite", where, v));
    return v;
  }
  std::string name(const std::string& where) const override {
    if (!j_.is_string() || j_.get<std::string>().empty())
      throw ConfigError(fmt::format("{} = {} must be a non-empty string", where, j_.dump()));
    return j_.get<std::string>();
  }
  std::string text(const std::string& where) const override {
    if (!j_.is_string()) throw ConfigError(fmt::format("{} = {} must be a string", where, j_.dump()));
    return j_.get<std::string>();
  }
  std::string locate(const std::string& where, const std::string& key) const override {
    return fmt::format("{}: {}", where, key);
  }
  std::string locate_key(const std::string& where, const std::string&, const std::string& label) const override {
    return locate(where, label);
  }
  std::unique_ptr<sim::SetupNode> open_file(const std::string& where, std::string&) const override {
    throw ConfigError(fmt::format("{} = {}: an FMU's process setup carries the tool and material, not file names",
                                  where, j_.dump()));
  }

 private:
  const json& j_;
};

json exp_to_json(const process::ExpCoefficient& k) {
  return {{"a_N_per_mm2", k.a_N_per_mm2}, {"b_N_per_mm2", k.b_N_per_mm2}, {"c_per_mm", k.c_per_mm}};
}

json polygon_to_json(const std::vector<process::Point2>& p) {
  json a = json::array();
  for (const auto& q : p) a.push_back({q.x_mm, q.y_mm});
  return a;
}

json tool_to_json(const process::ToolGeometry& t) {
  json j = {{sim::setup_keys::kToolType, process::tool_shape_name(t.shape)},
            {"diameter_mm", t.diameter_mm},
            {"flutes", t.flutes},
            {"helix_deg", t.helix_deg},
            {"corner_radius_mm", t.corner_radius_mm},
            {"flute_length_mm", t.flute_length_mm},
            {"runout_rho_mm", t.runout_rho_mm},
            {"runout_lambda_deg", t.runout_lambda_deg}};
  if (!t.name.empty()) j["name"] = t.name;
  return j;
}

/// The material with the one set the setup uses, keyed by its lead and tilt.
json material_to_json(const process::ProcessSetup& s) {
  const process::CuttingCoefficients& c = s.coefficients;
  const json set = {{"lead_deg", s.lead_deg},          {"tilt_deg", s.tilt_deg},
                    {"Kt", exp_to_json(c.Kt)},         {"Kr", exp_to_json(c.Kr)},
                    {"Ka", exp_to_json(c.Ka)},         {"Kte_N_per_mm", c.Kte_N_per_mm},
                    {"Kre_N_per_mm", c.Kre_N_per_mm}, {"Kae_N_per_mm", c.Kae_N_per_mm}};
  json m = {{sim::setup_keys::kSets, json::array({set})}};
  const std::string name = sim::material_name(c, s.lead_deg, s.tilt_deg);
  if (!name.empty()) m["name"] = name;
  return m;
}

json stock_to_json(const process::StockSpec& stock) {
  json pockets = json::array();
  for (const auto& p : stock.pockets) {
    json q = {{"floor_z_mm", p.floor_z_mm}};
    if (p.polygon_mm.size() >= 3) {
      q["polygon_mm"] = polygon_to_json(p.polygon_mm);
    } else {
      q["center_mm"] = {p.center_mm.x_mm, p.center_mm.y_mm};
      q["radius_mm"] = p.radius_mm;
    }
    pockets.push_back(q);
  }
  return {{"outline_mm", polygon_to_json(stock.outline_mm)},
          {"top_z_mm", stock.top_z_mm},
          {"bottom_z_mm", stock.bottom_z_mm},
          {"cell_mm", stock.cell_mm},
          {"pockets", pockets}};
}

/// The tool's modes when it vibrates in the cut (a machine with `structure:`
/// and `tool_tip:`): set by the scenario from its machine, not by the process
/// section of a scenario file, so they are kept out of what read_process_setup
/// reads and read by sim::read_tool_tip, as a machine file's are.
constexpr const char* kToolTip = sim::setup_keys::kToolTip;
constexpr const char* kSubsteps = "substeps_per_mode_period";

json modes_to_json(const std::vector<process::ToolTipMode>& modes) {
  namespace k = sim::setup_keys;
  json out = json::array();
  for (const auto& m : modes)
    out.push_back({{k::kModeFn, m.fn_Hz}, {k::kModeZeta, m.zeta}, {k::kModeStiffness, m.k_N_per_m}});
  return out;
}

/// Reads the tool's modes (the one reader, sim::read_tool_tip) and the
/// substeps from `j`'s tool_tip and substeps entries into `setup`.
void read_tool_modes(const json& j, process::ProcessSetup& setup) {
  if (j.contains(kToolTip)) {
    setup.tool_tip = sim::read_tool_tip(JsonSetupNode(j.at(kToolTip)), std::string("process: ") + kToolTip);
    setup.tool_tip.validate(std::string("process: ") + kToolTip);
  }
  if (j.contains(kSubsteps))
    setup.substeps_per_mode_period = JsonSetupNode(j.at(kSubsteps)).number(std::string("process: ") + kSubsteps);
}

}  // namespace

json process_setup_to_json(const process::ProcessSetup& s) {
  json j;
  j[sim::setup_keys::kTool] = tool_to_json(s.tool);
  j[sim::setup_keys::kMaterial] = material_to_json(s);
  j[sim::setup_keys::kStock] = stock_to_json(s.stock);
  j[sim::setup_keys::kModel] = {{"dz_mm", s.options.dz_mm},
                                {"angle_step_deg", s.options.angle_step_deg},
                                {"engagement_step_deg", s.options.engagement_step_deg}};
  j["lead_deg"] = s.lead_deg;
  j["tilt_deg"] = s.tilt_deg;
  j["spindle_angle0_deg"] = s.spindle_angle0_deg;
  if (!s.tool_tip.empty()) {
    j[kToolTip] = {{"x", modes_to_json(s.tool_tip.x)}, {"y", modes_to_json(s.tool_tip.y)}};
    j[kSubsteps] = s.substeps_per_mode_period;
  }
  return j;
}

process::ProcessSetup process_setup_from_json(const nlohmann::json& j) {
  if (!j.is_object() || (!j.contains(kToolTip) && !j.contains(kSubsteps)))
    return sim::read_process_setup(JsonSetupNode(j), "process");
  json rest = j;
  rest.erase(kToolTip);
  rest.erase(kSubsteps);
  process::ProcessSetup setup = sim::read_process_setup(JsonSetupNode(rest), "process");
  read_tool_modes(j, setup);
  return setup;
}

std::unique_ptr<process::ProcessModel> make_process_from_json(const nlohmann::json& j) {
  if (j.is_null()) return nullptr;
  return process::make_process(process_setup_from_json(j));
}

}  // namespace twin::fmu
