#include "fmu/process_json.hpp"

#include <cmath>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "process/milling_process.hpp"
#include "twin/core/error.hpp"

namespace twin::fmu {
namespace {

using nlohmann::json;

double number(const json& j, const std::string& where) {
  if (!j.is_number()) throw ConfigError(fmt::format("{} = {} must be a number", where, j.dump()));
  const double v = j.get<double>();
  if (!std::isfinite(v)) throw ConfigError(fmt::format("{} = {} must be finite", where, v));
  return v;
}

std::string text(const json& j, const std::string& where) {
  if (!j.is_string()) throw ConfigError(fmt::format("{} = {} must be a string", where, j.dump()));
  return j.get<std::string>();
}

void require_object(const json& j, const std::string& where) {
  if (!j.is_object()) throw ConfigError(fmt::format("{} must be a map, got {}", where, j.dump()));
}

[[noreturn]] void unknown_key(const std::string& where, const std::string& key) {
  throw ConfigError(fmt::format("{}: unknown key '{}' (the FMU's process reader knows the keys of fmu/process_json.hpp)",
                                where, key));
}

process::Point2 point(const json& j, const std::string& where) {
  if (!j.is_array() || j.size() != 2) throw ConfigError(fmt::format("{} = {} must be [x, y]", where, j.dump()));
  return {number(j[0], where + "[0]"), number(j[1], where + "[1]")};
}

std::vector<process::Point2> polygon(const json& j, const std::string& where) {
  if (!j.is_array()) throw ConfigError(fmt::format("{} must be a list of [x, y]", where));
  std::vector<process::Point2> out;
  for (std::size_t i = 0; i < j.size(); ++i) out.push_back(point(j[i], fmt::format("{}[{}]", where, i)));
  return out;
}

process::ToolGeometry read_tool(const json& j, const std::string& where) {
  require_object(j, where);
  process::ToolGeometry t;
  for (const auto& [key, v] : j.items()) {
    const std::string w = where + "." + key;
    if (key == "name") t.name = text(v, w);
    else if (key == "shape") t.shape = process::parse_tool_shape(text(v, w), w);
    else if (key == "diameter_mm") t.diameter_mm = number(v, w);
    else if (key == "flutes") {
      const double n = number(v, w);
      if (n != std::floor(n) || n < 1.0 || n > 64.0) throw ConfigError(fmt::format("{} = {} must be a whole number", w, n));
      t.flutes = static_cast<int>(n);
    } else if (key == "helix_deg") t.helix_deg = number(v, w);
    else if (key == "corner_radius_mm") t.corner_radius_mm = number(v, w);
    else if (key == "flute_length_mm") t.flute_length_mm = number(v, w);
    else if (key == "runout_rho_mm") t.runout_rho_mm = number(v, w);
    else if (key == "runout_lambda_deg") t.runout_lambda_deg = number(v, w);
    else unknown_key(where, key);
  }
  return t;
}

process::ExpCoefficient read_exp(const json& j, const std::string& where) {
  require_object(j, where);
  process::ExpCoefficient k;
  for (const auto& [key, v] : j.items()) {
    const std::string w = where + "." + key;
    if (key == "a_N_per_mm2") k.a_N_per_mm2 = number(v, w);
    else if (key == "b_N_per_mm2") k.b_N_per_mm2 = number(v, w);
    else if (key == "c_per_mm") k.c_per_mm = number(v, w);
    else unknown_key(where, key);
  }
  return k;
}

process::CuttingCoefficients read_coefficients(const json& j, const std::string& where) {
  require_object(j, where);
  process::CuttingCoefficients c;
  if (j.contains("linear")) {
    const json& l = j["linear"];
    const std::string wl = where + ".linear";
    require_object(l, wl);
    for (const auto& [key, v] : l.items())
      if (key != "Ktc_N_per_mm2" && key != "Krc_N_per_mm2" && key != "Kac_N_per_mm2" && key != "Kte_N_per_mm" &&
          key != "Kre_N_per_mm" && key != "Kae_N_per_mm")
        unknown_key(wl, key);
    auto get = [&](const char* key) { return l.contains(key) ? number(l[key], wl + "." + key) : 0.0; };
    c = process::CuttingCoefficients::linear(get("Ktc_N_per_mm2"), get("Krc_N_per_mm2"), get("Kac_N_per_mm2"),
                                             get("Kte_N_per_mm"), get("Kre_N_per_mm"), get("Kae_N_per_mm"));
  }
  for (const auto& [key, v] : j.items()) {
    const std::string w = where + "." + key;
    if (key == "linear") continue;
    if (key == "name") c.name = text(v, w);
    else if (key == "Kt") c.Kt = read_exp(v, w);
    else if (key == "Kr") c.Kr = read_exp(v, w);
    else if (key == "Ka") c.Ka = read_exp(v, w);
    else if (key == "Kte_N_per_mm") c.Kte_N_per_mm = number(v, w);
    else if (key == "Kre_N_per_mm") c.Kre_N_per_mm = number(v, w);
    else if (key == "Kae_N_per_mm") c.Kae_N_per_mm = number(v, w);
    else unknown_key(where, key);
  }
  return c;
}

process::PocketFeature read_pocket(const json& j, const std::string& where) {
  require_object(j, where);
  process::PocketFeature p;
  for (const auto& [key, v] : j.items()) {
    const std::string w = where + "." + key;
    if (key == "polygon_mm") p.polygon_mm = polygon(v, w);
    else if (key == "center_mm") p.center_mm = point(v, w);
    else if (key == "radius_mm") p.radius_mm = number(v, w);
    else if (key == "floor_z_mm") p.floor_z_mm = number(v, w);
    else unknown_key(where, key);
  }
  return p;
}

process::StockSpec read_stock(const json& j, const std::string& where) {
  require_object(j, where);
  process::StockSpec s;
  for (const auto& [key, v] : j.items()) {
    const std::string w = where + "." + key;
    if (key == "outline_mm") s.outline_mm = polygon(v, w);
    else if (key == "rectangle_mm") {
      if (!v.is_array() || v.size() != 4) throw ConfigError(fmt::format("{} = {} must be [x0, y0, x1, y1]", w, v.dump()));
      s.outline_mm = process::StockSpec::rectangle(number(v[0], w + "[0]"), number(v[1], w + "[1]"),
                                                   number(v[2], w + "[2]"), number(v[3], w + "[3]"));
    } else if (key == "top_z_mm") s.top_z_mm = number(v, w);
    else if (key == "bottom_z_mm") s.bottom_z_mm = number(v, w);
    else if (key == "cell_mm") s.cell_mm = number(v, w);
    else if (key == "pockets") {
      if (!v.is_array()) throw ConfigError(fmt::format("{} must be a list", w));
      for (std::size_t i = 0; i < v.size(); ++i) s.pockets.push_back(read_pocket(v[i], fmt::format("{}[{}]", w, i)));
    } else unknown_key(where, key);
  }
  return s;
}

process::ForceModelOptions read_options(const json& j, const std::string& where) {
  require_object(j, where);
  process::ForceModelOptions o;
  for (const auto& [key, v] : j.items()) {
    const std::string w = where + "." + key;
    if (key == "dz_mm") o.dz_mm = number(v, w);
    else if (key == "angle_step_deg") o.angle_step_deg = number(v, w);
    else if (key == "engagement_step_deg") o.engagement_step_deg = number(v, w);
    else unknown_key(where, key);
  }
  return o;
}

json exp_to_json(const process::ExpCoefficient& k) {
  return {{"a_N_per_mm2", k.a_N_per_mm2}, {"b_N_per_mm2", k.b_N_per_mm2}, {"c_per_mm", k.c_per_mm}};
}

json polygon_to_json(const std::vector<process::Point2>& p) {
  json a = json::array();
  for (const auto& q : p) a.push_back({q.x_mm, q.y_mm});
  return a;
}

}  // namespace

json process_setup_to_json(const process::ProcessSetup& s) {
  json j;
  const process::ToolGeometry& t = s.tool;
  j["tool"] = {{"name", t.name},
               {"shape", process::tool_shape_name(t.shape)},
               {"diameter_mm", t.diameter_mm},
               {"flutes", t.flutes},
               {"helix_deg", t.helix_deg},
               {"corner_radius_mm", t.corner_radius_mm},
               {"flute_length_mm", t.flute_length_mm},
               {"runout_rho_mm", t.runout_rho_mm},
               {"runout_lambda_deg", t.runout_lambda_deg}};
  const process::CuttingCoefficients& c = s.coefficients;
  j["coefficients"] = {{"name", c.name},
                       {"Kt", exp_to_json(c.Kt)},
                       {"Kr", exp_to_json(c.Kr)},
                       {"Ka", exp_to_json(c.Ka)},
                       {"Kte_N_per_mm", c.Kte_N_per_mm},
                       {"Kre_N_per_mm", c.Kre_N_per_mm},
                       {"Kae_N_per_mm", c.Kae_N_per_mm}};
  json pockets = json::array();
  for (const auto& p : s.stock.pockets) {
    json q = {{"floor_z_mm", p.floor_z_mm}};
    if (p.polygon_mm.size() >= 3) {
      q["polygon_mm"] = polygon_to_json(p.polygon_mm);
    } else {
      q["center_mm"] = {p.center_mm.x_mm, p.center_mm.y_mm};
      q["radius_mm"] = p.radius_mm;
    }
    pockets.push_back(q);
  }
  j["stock"] = {{"outline_mm", polygon_to_json(s.stock.outline_mm)},
                {"top_z_mm", s.stock.top_z_mm},
                {"bottom_z_mm", s.stock.bottom_z_mm},
                {"cell_mm", s.stock.cell_mm},
                {"pockets", pockets}};
  j["options"] = {{"dz_mm", s.options.dz_mm},
                  {"angle_step_deg", s.options.angle_step_deg},
                  {"engagement_step_deg", s.options.engagement_step_deg}};
  j["lead_deg"] = s.lead_deg;
  j["tilt_deg"] = s.tilt_deg;
  j["spindle_angle0_deg"] = s.spindle_angle0_deg;
  return j;
}

std::unique_ptr<process::ProcessModel> make_process_from_json(const nlohmann::json& j) {
  if (j.is_null()) return nullptr;
  return process::make_process(process_setup_from_json(j));
}

process::ProcessSetup process_setup_from_json(const nlohmann::json& j) {
  const std::string where = "process";
  require_object(j, where);
  process::ProcessSetup setup;
  for (const auto& [key, v] : j.items()) {
    const std::string w = where + "." + key;
    if (key == "tool") setup.tool = read_tool(v, w);
    else if (key == "coefficients") setup.coefficients = read_coefficients(v, w);
    else if (key == "stock") setup.stock = read_stock(v, w);
    else if (key == "options") setup.options = read_options(v, w);
    else if (key == "lead_deg") setup.lead_deg = number(v, w);
    else if (key == "tilt_deg") setup.tilt_deg = number(v, w);
    else if (key == "spindle_angle0_deg") setup.spindle_angle0_deg = number(v, w);
    else unknown_key(where, key);
  }
  return setup;
}

}  // namespace twin::fmu
