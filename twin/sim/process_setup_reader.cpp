#include "twin/sim/process_setup_reader.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <set>

#include <fmt/format.h>

#include "twin/core/error.hpp"

namespace twin::sim {
namespace {

using Node = std::unique_ptr<SetupNode>;

void require_map(const SetupNode* node, const std::string& where, const std::string& what) {
  if (node == nullptr) throw ConfigError(fmt::format("{}: {} must be a map", where, what));
  if (!node->is_map()) throw ConfigError(fmt::format("{}: {} must be a {} map", where, what, node->format()));
}

void check_keys(const SetupNode& node, const std::string& where, const std::string& prefix,
                const std::set<std::string>& allowed) {
  for (const std::string& key : node.keys()) {
    if (!allowed.count(key)) {
      std::string list;
      for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
      throw ConfigError(fmt::format("{}: unknown key (known: {})", node.locate_key(where, key, prefix + key), list));
    }
  }
}

double number(const SetupNode& map, const std::string& key, const std::string& where, const std::string& prefix,
              double fallback, bool required = false) {
  const Node n = map.get(key);
  if (!n) {
    if (required) throw ConfigError(fmt::format("{}: missing key '{}{}'", where, prefix, key));
    return fallback;
  }
  return n->number(n->locate(where, prefix + key));
}

process::Point2 point(const SetupNode& n, const std::string& w) {
  if (!n.is_list() || n.size() != 2) throw ConfigError(fmt::format("{} must be a point [x, y]", w));
  return {n.item(0)->number(w + "[0]"), n.item(1)->number(w + "[1]")};
}

std::vector<process::Point2> points(const SetupNode& n, const std::string& w) {
  if (!n.is_list()) throw ConfigError(fmt::format("{} must be a list of points [[x, y], ...]", w));
  std::vector<process::Point2> out;
  for (std::size_t i = 0; i < n.size(); ++i) out.push_back(point(*n.item(i), fmt::format("{}[{}]", w, i)));
  return out;
}

std::vector<process::Point2> box(const SetupNode& n, const std::string& w) {
  if (!n.is_list() || n.size() != 4) throw ConfigError(fmt::format("{} must be [x0, y0, x1, y1]", w));
  const double x0 = n.item(0)->number(w + "[0]"), y0 = n.item(1)->number(w + "[1]");
  const double x1 = n.item(2)->number(w + "[2]"), y1 = n.item(3)->number(w + "[3]");
  if (!(x1 > x0 && y1 > y0)) throw ConfigError(fmt::format("{} = [{}, {}, {}, {}] needs x1 > x0 and y1 > y0", w, x0, y0, x1, y1));
  return process::StockSpec::rectangle(x0, y0, x1, y1);
}

/// outline_mm (or polygon_mm) as points, or box_mm as a rectangle; empty when neither is given.
std::vector<process::Point2> outline(const SetupNode& n, const std::string& where, const std::string& prefix,
                                     const char* points_key) {
  if (const Node p = n.get(points_key)) return points(*p, p->locate(where, prefix + points_key));
  if (const Node b = n.get("box_mm")) return box(*b, b->locate(where, prefix + "box_mm"));
  return {};
}

process::ExpCoefficient exp_coefficient(const SetupNode& n, const std::string& where, const std::string& key) {
  require_map(&n, n.locate(where, key), key);
  check_keys(n, where, key + ".", {"a_N_per_mm2", "b_N_per_mm2", "c_per_mm"});
  process::ExpCoefficient k;
  k.a_N_per_mm2 = number(n, "a_N_per_mm2", where, key + ".", 0.0, true);
  k.b_N_per_mm2 = number(n, "b_N_per_mm2", where, key + ".", 0.0);
  k.c_per_mm = number(n, "c_per_mm", where, key + ".", 0.0);
  return k;
}

process::PocketFeature read_pocket(const SetupNode& e, const std::string& where, const std::string& pp,
                                   double bottom_z_mm) {
  require_map(&e, e.locate(where, pp), pp);
  check_keys(e, where, pp, {"polygon_mm", "box_mm", "center_mm", "radius_mm", "floor_z_mm"});
  process::PocketFeature f;
  f.polygon_mm = outline(e, where, pp, "polygon_mm");
  if (f.polygon_mm.empty()) {
    const Node c = e.get("center_mm");
    if (!c) throw ConfigError(fmt::format("{}: {} needs polygon_mm, box_mm or center_mm + radius_mm", where, pp));
    f.center_mm = point(*c, c->locate(where, pp + "center_mm"));
    f.radius_mm = number(e, "radius_mm", where, pp, 0.0, true);
  }
  f.floor_z_mm = number(e, "floor_z_mm", where, pp, bottom_z_mm);
  return f;
}

process::StockSpec read_stock(const SetupNode& n, const std::string& where) {
  require_map(&n, where, "process.stock");
  const std::string p = "stock.";
  check_keys(n, where, p, {"outline_mm", "box_mm", "top_z_mm", "bottom_z_mm", "cell_mm", "pockets"});
  process::StockSpec s;
  if (n.get("outline_mm") && n.get("box_mm"))
    throw ConfigError(fmt::format("{}: give stock.outline_mm or stock.box_mm, not both", where));
  s.outline_mm = outline(n, where, p, "outline_mm");
  if (s.outline_mm.empty() && !n.get("outline_mm"))
    throw ConfigError(fmt::format("{}: missing key 'stock.outline_mm' (or stock.box_mm)", where));
  s.top_z_mm = number(n, "top_z_mm", where, p, 0.0);
  s.bottom_z_mm = number(n, "bottom_z_mm", where, p, 0.0, true);
  s.cell_mm = number(n, "cell_mm", where, p, s.cell_mm);
  if (const Node pk = n.get("pockets")) {
    if (!pk->is_list()) throw ConfigError(fmt::format("{} must be a list", pk->locate(where, p + "pockets")));
    for (std::size_t i = 0; i < pk->size(); ++i)
      s.pockets.push_back(read_pocket(*pk->item(i), where, fmt::format("{}pockets[{}].", p, i), s.bottom_z_mm));
  }
  s.validate(where);
  return s;
}

std::string set_name(const std::string& material, double lead_deg, double tilt_deg) {
  return fmt::format("{} (lead {} deg, tilt {} deg)", material, lead_deg, tilt_deg);
}

/// One coefficient set: K(h) = a + b exp(-c h) per direction, or linear Kc.
process::CuttingCoefficients read_set(const SetupNode& s, const std::string& where, const std::string& p) {
  process::CuttingCoefficients k;
  const bool exponential = s.get("Kt") || s.get("Kr") || s.get("Ka");
  const bool linear = s.get("Ktc_N_per_mm2") || s.get("Krc_N_per_mm2") || s.get("Kac_N_per_mm2");
  if (exponential == linear)
    throw ConfigError(fmt::format("{}: {} needs either Kt/Kr/Ka (K(h) = a + b exp(-c h)) or Ktc/Krc/Kac, not both",
                                  s.locate(where, p), p));
  if (exponential) {
    for (const char* key : {"Kt", "Kr", "Ka"})
      if (!s.get(key)) throw ConfigError(fmt::format("{}: missing key '{}{}'", where, p, key));
    k.Kt = exp_coefficient(*s.get("Kt"), where, p + "Kt");
    k.Kr = exp_coefficient(*s.get("Kr"), where, p + "Kr");
    k.Ka = exp_coefficient(*s.get("Ka"), where, p + "Ka");
  } else {
    k.Kt.a_N_per_mm2 = number(s, "Ktc_N_per_mm2", where, p, 0.0, true);
    k.Kr.a_N_per_mm2 = number(s, "Krc_N_per_mm2", where, p, 0.0, true);
    k.Ka.a_N_per_mm2 = number(s, "Kac_N_per_mm2", where, p, 0.0);
  }
  k.Kte_N_per_mm = number(s, "Kte_N_per_mm", where, p, 0.0);
  k.Kre_N_per_mm = number(s, "Kre_N_per_mm", where, p, 0.0);
  k.Kae_N_per_mm = number(s, "Kae_N_per_mm", where, p, 0.0);
  return k;
}

process::ForceModelOptions read_model(const SetupNode* m, const std::string& where) {
  process::ForceModelOptions o;
  if (m != nullptr) {
    require_map(m, m->locate(where, "process.model"), "process.model");
    check_keys(*m, where, "process.model.", {"dz_mm", "angle_step_deg", "engagement_step_deg"});
    o.dz_mm = number(*m, "dz_mm", where, "process.model.", o.dz_mm);
    o.angle_step_deg = number(*m, "angle_step_deg", where, "process.model.", o.angle_step_deg);
    o.engagement_step_deg = number(*m, "engagement_step_deg", where, "process.model.", o.engagement_step_deg);
  }
  o.validate(where);
  return o;
}

void check_angle(double v_deg, const char* key, const std::string& where) {
  if (!std::isfinite(v_deg) || std::abs(v_deg) >= 60.0)
    throw ConfigError(fmt::format("{}: process.{} = {} must be in (-60, 60)", where, key, v_deg));
}

}  // namespace

process::ToolGeometry read_tool(const SetupNode& n, const std::string& where) {
  require_map(&n, where, "tool");
  const std::string p = "tool.";
  check_keys(n, where, p,
             {"name", "type", "diameter_mm", "flutes", "helix_deg", "corner_radius_mm", "flute_length_mm",
              "runout_rho_mm", "runout_lambda_deg", "source"});
  process::ToolGeometry t;
  if (const Node name = n.get("name")) t.name = name->name(name->locate(where, p + "name"));
  const Node type = n.get("type");
  if (!type) throw ConfigError(fmt::format("{}: missing key 'tool.type' (flat, bull_nose, ball)", where));
  const std::string type_where = type->locate(where, p + "type");
  t.shape = process::parse_tool_shape(type->name(type_where), type_where);
  t.diameter_mm = number(n, "diameter_mm", where, p, 0.0, true);
  const double flutes = number(n, "flutes", where, p, 0.0, true);
  if (flutes != std::floor(flutes) || flutes < 1 || flutes > 16)
    throw ConfigError(
        fmt::format("{} = {} must be a whole number in [1, 16]", n.get("flutes")->locate(where, p + "flutes"), flutes));
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

process::ToolGeometry read_tool_document(const SetupNode& root, const std::string& where) {
  require_map(&root, where, "a tool file");
  if (!root.get("tool")) throw ConfigError(fmt::format("{}: missing key 'tool'", where));
  check_keys(root, where, "", {"tool"});
  return read_tool(*root.get("tool"), where);
}

process::CuttingCoefficients read_material(const SetupNode& n, const std::string& where, double lead_deg,
                                           double tilt_deg) {
  require_map(&n, where, "material");
  check_keys(n, where, "material.", {"name", "source", "sets"});
  const Node name_node = n.get("name");
  const std::string name = name_node ? name_node->name(name_node->locate(where, "material.name")) : "material";
  const Node sets = n.get("sets");
  if (!sets || !sets->is_list() || sets->size() == 0)
    throw ConfigError(fmt::format("{}: material.sets must be a non-empty list", where));
  std::string available;
  for (std::size_t i = 0; i < sets->size(); ++i) {
    const Node s = sets->item(i);
    const std::string p = fmt::format("material.sets[{}].", i);
    require_map(s.get(), s->locate(where, p), p);
    check_keys(*s, where, p,
               {"lead_deg", "tilt_deg", "Kt", "Kr", "Ka", "Ktc_N_per_mm2", "Krc_N_per_mm2", "Kac_N_per_mm2",
                "Kte_N_per_mm", "Kre_N_per_mm", "Kae_N_per_mm", "source"});
    const double lead = number(*s, "lead_deg", where, p, 0.0);
    const double tilt = number(*s, "tilt_deg", where, p, 0.0);
    available += fmt::format("{}(lead {}, tilt {})", available.empty() ? "" : ", ", lead, tilt);
    if (std::abs(lead - lead_deg) > 1e-9 || std::abs(tilt - tilt_deg) > 1e-9) continue;
    process::CuttingCoefficients k = read_set(*s, where, p);
    k.name = set_name(name, lead, tilt);
    k.validate(where);
    return k;
  }
  throw ConfigError(fmt::format("{}: material '{}' has no coefficient set for lead {} deg, tilt {} deg (it has: {})",
                                where, name, lead_deg, tilt_deg, available));
}

process::CuttingCoefficients read_material_document(const SetupNode& root, const std::string& where,
                                                    double lead_deg, double tilt_deg) {
  require_map(&root, where, "a material file");
  check_keys(root, where, "", {"material"});
  if (!root.get("material")) throw ConfigError(fmt::format("{}: missing key 'material'", where));
  return read_material(*root.get("material"), where, lead_deg, tilt_deg);
}

std::string material_name(const process::CuttingCoefficients& k, double lead_deg, double tilt_deg) {
  const std::string suffix = set_name("", lead_deg, tilt_deg);
  const std::string& n = k.name;
  if (n.size() > suffix.size() && n.compare(n.size() - suffix.size(), suffix.size(), suffix) == 0)
    return n.substr(0, n.size() - suffix.size());
  return n;
}

process::ToolTipFrf read_tool_tip(const SetupNode& node, const std::string& where, std::string* source) {
  namespace k = setup_keys;
  if (!node.is_map()) throw ConfigError(fmt::format("{} must be a map with x and/or y mode lists", where));
  process::ToolTipFrf frf;
  for (const std::string& key : node.keys()) {
    const Node value = node.get(key);
    if (source != nullptr && key == k::kToolTipSource) {
      *source = value->text(where + "." + key);
      continue;
    }
    if (key != "x" && key != "y")
      throw ConfigError(
          fmt::format("{}: unknown key '{}' ({})", where, key, source != nullptr ? "x, y, source" : "x, y"));
    if (!value->is_list()) throw ConfigError(fmt::format("{}.{} must be a list of modes", where, key));
    auto& modes = key == "x" ? frf.x : frf.y;
    for (std::size_t i = 0; i < value->size(); ++i) {
      const std::string mw = fmt::format("{}.{}[{}]", where, key, i);
      const Node mode = value->item(i);
      if (!mode->is_map()) throw ConfigError(fmt::format("{} must be a map fn_Hz, zeta, k_N_per_m", mw));
      process::ToolTipMode tm;
      struct Field {
        const char* key;
        double* value;
        bool seen;
      };
      std::array<Field, 3> fields{{{k::kModeFn, &tm.fn_Hz, false},
                                   {k::kModeZeta, &tm.zeta, false},
                                   {k::kModeStiffness, &tm.k_N_per_m, false}}};
      for (const std::string& fk : mode->keys()) {
        const auto f = std::find_if(fields.begin(), fields.end(), [&](const Field& x) { return fk == x.key; });
        if (f == fields.end())
          throw ConfigError(fmt::format("{}: unknown key '{}' (fn_Hz, zeta, k_N_per_m)", mw, fk));
        *f->value = mode->get(fk)->number(mw + "." + fk);
        f->seen = true;
      }
      if (!std::all_of(fields.begin(), fields.end(), [](const Field& x) { return x.seen; }))
        throw ConfigError(fmt::format("{}: needs fn_Hz, zeta and k_N_per_m", mw));
      modes.push_back(tm);
    }
  }
  return frf;
}

process::ProcessSetup read_process_setup(const SetupNode& n, const std::string& where) {
  require_map(&n, where, "process");
  check_keys(n, where, "process.", {"tool", "material", "lead_deg", "tilt_deg", "runout", "stock", "model",
                                    "spindle_angle0_deg"});
  process::ProcessSetup s;
  s.lead_deg = number(n, "lead_deg", where, "process.", 0.0);
  s.tilt_deg = number(n, "tilt_deg", where, "process.", 0.0);
  s.spindle_angle0_deg = number(n, "spindle_angle0_deg", where, "process.", 0.0);
  std::string file;
  const Node tool = n.get("tool");
  if (!tool) throw ConfigError(fmt::format("{}: missing key 'process.tool'", where));
  if (tool->is_scalar()) {
    const Node doc = tool->open_file(tool->locate(where, "process.tool"), file);
    s.tool = read_tool_document(*doc, file);
  } else {
    s.tool = read_tool(*tool, where);
  }
  if (const Node r = n.get("runout")) {
    require_map(r.get(), r->locate(where, "process.runout"), "process.runout");
    check_keys(*r, where, "process.runout.", {"rho_mm", "lambda_deg"});
    s.tool.runout_rho_mm = number(*r, "rho_mm", where, "process.runout.", 0.0, true);
    s.tool.runout_lambda_deg = number(*r, "lambda_deg", where, "process.runout.", 0.0);
    s.tool.validate(where);
  }
  const Node mat = n.get("material");
  if (!mat) throw ConfigError(fmt::format("{}: missing key 'process.material'", where));
  if (mat->is_scalar()) {
    const Node doc = mat->open_file(mat->locate(where, "process.material"), file);
    s.coefficients = read_material_document(*doc, file, s.lead_deg, s.tilt_deg);
  } else {
    s.coefficients = read_material(*mat, where, s.lead_deg, s.tilt_deg);
  }
  const Node stock = n.get("stock");
  if (!stock) throw ConfigError(fmt::format("{}: missing key 'process.stock'", where));
  s.stock = read_stock(*stock, where);
  s.options = read_model(n.get("model").get(), where);
  check_angle(s.lead_deg, "lead_deg", where);
  check_angle(s.tilt_deg, "tilt_deg", where);
  return s;
}

}  // namespace twin::sim
