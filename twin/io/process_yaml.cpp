#include "twin/io/process_yaml.hpp"

#include <cmath>
#include <set>

#include <fmt/format.h>

#include "twin/core/error.hpp"
#include "twin/io/yaml_util.hpp"

namespace twin::io {
namespace {

std::string at(const std::string& where, const YAML::Node& node, const std::string& key) {
  const auto m = node.Mark();
  if (m.line >= 0) return fmt::format("{}:{}: {}", where, m.line + 1, key);
  return fmt::format("{}: {}", where, key);
}

void require_map(const YAML::Node& node, const std::string& where, const std::string& what) {
  if (!node || !node.IsMap()) throw ConfigError(fmt::format("{}: {} must be a YAML map", where, what));
}

void check_keys(const YAML::Node& node, const std::string& where, const std::string& prefix,
                const std::set<std::string>& allowed) {
  for (const auto& kv : node) {
    const std::string key = kv.first.as<std::string>();
    if (!allowed.count(key)) {
      std::string list;
      for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
      throw ConfigError(fmt::format("{}: unknown key (known: {})", at(where, kv.first, prefix + key), list));
    }
  }
}

double number(const YAML::Node& map, const std::string& key, const std::string& where, const std::string& prefix,
              double fallback, bool required = false) {
  const YAML::Node n = map[key];
  if (!n) {
    if (required) throw ConfigError(fmt::format("{}: missing key '{}{}'", where, prefix, key));
    return fallback;
  }
  return yaml_number(n, at(where, n, prefix + key));
}

process::Point2 point(const YAML::Node& n, const std::string& w) {
  if (!n.IsSequence() || n.size() != 2) throw ConfigError(fmt::format("{} must be a point [x, y]", w));
  return {yaml_number(n[0], w + "[0]"), yaml_number(n[1], w + "[1]")};
}

std::vector<process::Point2> points(const YAML::Node& n, const std::string& w) {
  if (!n.IsSequence()) throw ConfigError(fmt::format("{} must be a list of points [[x, y], ...]", w));
  std::vector<process::Point2> out;
  for (std::size_t i = 0; i < n.size(); ++i) out.push_back(point(n[i], fmt::format("{}[{}]", w, i)));
  return out;
}

std::vector<process::Point2> box(const YAML::Node& n, const std::string& w) {
  if (!n.IsSequence() || n.size() != 4) throw ConfigError(fmt::format("{} must be [x0, y0, x1, y1]", w));
  const double x0 = yaml_number(n[0], w + "[0]"), y0 = yaml_number(n[1], w + "[1]");
  const double x1 = yaml_number(n[2], w + "[2]"), y1 = yaml_number(n[3], w + "[3]");
  if (!(x1 > x0 && y1 > y0)) throw ConfigError(fmt::format("{} = [{}, {}, {}, {}] needs x1 > x0 and y1 > y0", w, x0, y0, x1, y1));
  return process::StockSpec::rectangle(x0, y0, x1, y1);
}

process::ExpCoefficient exp_coefficient(const YAML::Node& n, const std::string& where, const std::string& key) {
  require_map(n, at(where, n, key), key);
  check_keys(n, where, key + ".", {"a_N_per_mm2", "b_N_per_mm2", "c_per_mm"});
  process::ExpCoefficient k;
  k.a_N_per_mm2 = number(n, "a_N_per_mm2", where, key + ".", 0.0, true);
  k.b_N_per_mm2 = number(n, "b_N_per_mm2", where, key + ".", 0.0);
  k.c_per_mm = number(n, "c_per_mm", where, key + ".", 0.0);
  return k;
}

process::StockSpec parse_stock(const YAML::Node& n, const std::string& where) {
  require_map(n, where, "process.stock");
  const std::string p = "stock.";
  check_keys(n, where, p, {"outline_mm", "box_mm", "top_z_mm", "bottom_z_mm", "cell_mm", "pockets"});
  process::StockSpec s;
  if (n["outline_mm"] && n["box_mm"]) throw ConfigError(fmt::format("{}: give stock.outline_mm or stock.box_mm, not both", where));
  if (n["outline_mm"]) s.outline_mm = points(n["outline_mm"], at(where, n["outline_mm"], p + "outline_mm"));
  else if (n["box_mm"]) s.outline_mm = box(n["box_mm"], at(where, n["box_mm"], p + "box_mm"));
  else throw ConfigError(fmt::format("{}: missing key 'stock.outline_mm' (or stock.box_mm)", where));
  s.top_z_mm = number(n, "top_z_mm", where, p, 0.0);
  s.bottom_z_mm = number(n, "bottom_z_mm", where, p, 0.0, true);
  s.cell_mm = number(n, "cell_mm", where, p, s.cell_mm);
  if (const YAML::Node pk = n["pockets"]) {
    if (!pk.IsSequence()) throw ConfigError(fmt::format("{} must be a list", at(where, pk, p + "pockets")));
    for (std::size_t i = 0; i < pk.size(); ++i) {
      const std::string pp = fmt::format("{}pockets[{}].", p, i);
      const YAML::Node e = pk[i];
      require_map(e, at(where, e, pp), pp);
      check_keys(e, where, pp, {"polygon_mm", "box_mm", "center_mm", "radius_mm", "floor_z_mm"});
      process::PocketFeature f;
      if (e["polygon_mm"]) f.polygon_mm = points(e["polygon_mm"], at(where, e["polygon_mm"], pp + "polygon_mm"));
      else if (e["box_mm"]) f.polygon_mm = box(e["box_mm"], at(where, e["box_mm"], pp + "box_mm"));
      else if (e["center_mm"]) {
        f.center_mm = point(e["center_mm"], at(where, e["center_mm"], pp + "center_mm"));
        f.radius_mm = number(e, "radius_mm", where, pp, 0.0, true);
      } else {
        throw ConfigError(fmt::format("{}: {} needs polygon_mm, box_mm or center_mm + radius_mm", where, pp));
      }
      f.floor_z_mm = number(e, "floor_z_mm", where, pp, s.bottom_z_mm);
      s.pockets.push_back(std::move(f));
    }
  }
  s.validate(where);
  return s;
}

}  // namespace

process::ToolGeometry parse_tool(const YAML::Node& n, const std::string& where) {
  require_map(n, where, "tool");
  const std::string p = "tool.";
  check_keys(n, where, p,
             {"name", "type", "diameter_mm", "flutes", "helix_deg", "corner_radius_mm", "flute_length_mm",
              "runout_rho_mm", "runout_lambda_deg", "source"});
  process::ToolGeometry t;
  if (n["name"]) t.name = yaml_name(n["name"], at(where, n["name"], p + "name"));
  if (!n["type"]) throw ConfigError(fmt::format("{}: missing key 'tool.type' (flat, bull_nose, ball)", where));
  t.shape = process::parse_tool_shape(yaml_name(n["type"], at(where, n["type"], p + "type")), at(where, n["type"], p + "type"));
  t.diameter_mm = number(n, "diameter_mm", where, p, 0.0, true);
  const double flutes = number(n, "flutes", where, p, 0.0, true);
  if (flutes != std::floor(flutes) || flutes < 1 || flutes > 16)
    throw ConfigError(fmt::format("{} = {} must be a whole number in [1, 16]", at(where, n["flutes"], p + "flutes"), flutes));
  t.flutes = static_cast<int>(flutes);
  t.helix_deg = number(n, "helix_deg", where, p, 0.0, true);
  t.corner_radius_mm = number(n, "corner_radius_mm", where, p,
                              t.shape == process::ToolShape::kBall ? 0.5 * t.diameter_mm : 0.0);
  t.flute_length_mm = number(n, "flute_length_mm", where, p, 0.0, true);
  t.runout_rho_mm = number(n, "runout_rho_mm", where, p, 0.0);
  t.runout_lambda_deg = number(n, "runout_lambda_deg", where, p, 0.0);
  t.validate(where);
  return t;
}

process::ToolGeometry load_tool_file(const std::filesystem::path& path) {
  const YAML::Node root = load_yaml_file(path);
  require_map(root, path.string(), "a tool file");
  if (!root["tool"]) throw ConfigError(fmt::format("{}: missing key 'tool'", path.string()));
  check_keys(root, path.string(), "", {"tool"});
  return parse_tool(root["tool"], path.string());
}

process::CuttingCoefficients parse_material(const YAML::Node& n, const std::string& where, double lead_deg,
                                            double tilt_deg) {
  require_map(n, where, "material");
  check_keys(n, where, "material.", {"name", "source", "sets"});
  std::string name = n["name"] ? yaml_name(n["name"], at(where, n["name"], "material.name")) : "material";
  const YAML::Node sets = n["sets"];
  if (!sets || !sets.IsSequence() || sets.size() == 0)
    throw ConfigError(fmt::format("{}: material.sets must be a non-empty list", where));
  std::string available;
  for (std::size_t i = 0; i < sets.size(); ++i) {
    const YAML::Node s = sets[i];
    const std::string p = fmt::format("material.sets[{}].", i);
    require_map(s, at(where, s, p), p);
    check_keys(s, where, p,
               {"lead_deg", "tilt_deg", "Kt", "Kr", "Ka", "Ktc_N_per_mm2", "Krc_N_per_mm2", "Kac_N_per_mm2",
                "Kte_N_per_mm", "Kre_N_per_mm", "Kae_N_per_mm", "source"});
    const double lead = number(s, "lead_deg", where, p, 0.0);
    const double tilt = number(s, "tilt_deg", where, p, 0.0);
    available += fmt::format("{}(lead {}, tilt {})", available.empty() ? "" : ", ", lead, tilt);
    if (std::abs(lead - lead_deg) > 1e-9 || std::abs(tilt - tilt_deg) > 1e-9) continue;
    process::CuttingCoefficients k;
    const bool exponential = s["Kt"] || s["Kr"] || s["Ka"];
    const bool linear = s["Ktc_N_per_mm2"] || s["Krc_N_per_mm2"] || s["Kac_N_per_mm2"];
    if (exponential == linear)
      throw ConfigError(fmt::format("{}: {} needs either Kt/Kr/Ka (K(h) = a + b exp(-c h)) or Ktc/Krc/Kac, not both",
                                    at(where, s, p), p));
    if (exponential) {
      for (const char* key : {"Kt", "Kr", "Ka"})
        if (!s[key]) throw ConfigError(fmt::format("{}: missing key '{}{}'", where, p, key));
      k.Kt = exp_coefficient(s["Kt"], where, p + "Kt");
      k.Kr = exp_coefficient(s["Kr"], where, p + "Kr");
      k.Ka = exp_coefficient(s["Ka"], where, p + "Ka");
    } else {
      k.Kt.a_N_per_mm2 = number(s, "Ktc_N_per_mm2", where, p, 0.0, true);
      k.Kr.a_N_per_mm2 = number(s, "Krc_N_per_mm2", where, p, 0.0, true);
      k.Ka.a_N_per_mm2 = number(s, "Kac_N_per_mm2", where, p, 0.0);
    }
    k.Kte_N_per_mm = number(s, "Kte_N_per_mm", where, p, 0.0);
    k.Kre_N_per_mm = number(s, "Kre_N_per_mm", where, p, 0.0);
    k.Kae_N_per_mm = number(s, "Kae_N_per_mm", where, p, 0.0);
    k.name = fmt::format("{} (lead {} deg, tilt {} deg)", name, lead, tilt);
    k.validate(where);
    return k;
  }
  throw ConfigError(fmt::format("{}: material '{}' has no coefficient set for lead {} deg, tilt {} deg (it has: {})",
                                where, name, lead_deg, tilt_deg, available));
}

process::CuttingCoefficients load_material_file(const std::filesystem::path& path, double lead_deg, double tilt_deg) {
  const YAML::Node root = load_yaml_file(path);
  require_map(root, path.string(), "a material file");
  check_keys(root, path.string(), "", {"material"});
  if (!root["material"]) throw ConfigError(fmt::format("{}: missing key 'material'", path.string()));
  return parse_material(root["material"], path.string(), lead_deg, tilt_deg);
}

process::ProcessSetup parse_process_setup(const YAML::Node& n, const std::string& where,
                                          const std::filesystem::path& dir) {
  require_map(n, where, "process");
  check_keys(n, where, "process.", {"tool", "material", "lead_deg", "tilt_deg", "runout", "stock", "model",
                                    "spindle_angle0_deg"});
  process::ProcessSetup s;
  s.lead_deg = number(n, "lead_deg", where, "process.", 0.0);
  s.tilt_deg = number(n, "tilt_deg", where, "process.", 0.0);
  s.spindle_angle0_deg = number(n, "spindle_angle0_deg", where, "process.", 0.0);
  const YAML::Node tool = n["tool"];
  if (!tool) throw ConfigError(fmt::format("{}: missing key 'process.tool'", where));
  if (tool.IsScalar()) s.tool = load_tool_file(dir / yaml_name(tool, at(where, tool, "process.tool")));
  else s.tool = parse_tool(tool, where);
  if (const YAML::Node r = n["runout"]) {
    require_map(r, at(where, r, "process.runout"), "process.runout");
    check_keys(r, where, "process.runout.", {"rho_mm", "lambda_deg"});
    s.tool.runout_rho_mm = number(r, "rho_mm", where, "process.runout.", 0.0, true);
    s.tool.runout_lambda_deg = number(r, "lambda_deg", where, "process.runout.", 0.0);
    s.tool.validate(where);
  }
  const YAML::Node mat = n["material"];
  if (!mat) throw ConfigError(fmt::format("{}: missing key 'process.material'", where));
  if (mat.IsScalar())
    s.coefficients = load_material_file(dir / yaml_name(mat, at(where, mat, "process.material")), s.lead_deg, s.tilt_deg);
  else
    s.coefficients = parse_material(mat, where, s.lead_deg, s.tilt_deg);
  if (!n["stock"]) throw ConfigError(fmt::format("{}: missing key 'process.stock'", where));
  s.stock = parse_stock(n["stock"], where);
  if (const YAML::Node m = n["model"]) {
    require_map(m, at(where, m, "process.model"), "process.model");
    check_keys(m, where, "process.model.", {"dz_mm", "angle_step_deg", "engagement_step_deg"});
    s.options.dz_mm = number(m, "dz_mm", where, "process.model.", s.options.dz_mm);
    s.options.angle_step_deg = number(m, "angle_step_deg", where, "process.model.", s.options.angle_step_deg);
    s.options.engagement_step_deg =
        number(m, "engagement_step_deg", where, "process.model.", s.options.engagement_step_deg);
  }
  s.options.validate(where);
  if (!std::isfinite(s.lead_deg) || std::abs(s.lead_deg) >= 60.0)
    throw ConfigError(fmt::format("{}: process.lead_deg = {} must be in (-60, 60)", where, s.lead_deg));
  if (!std::isfinite(s.tilt_deg) || std::abs(s.tilt_deg) >= 60.0)
    throw ConfigError(fmt::format("{}: process.tilt_deg = {} must be in (-60, 60)", where, s.tilt_deg));
  return s;
}

}  // namespace twin::io
