#pragma once
/// The one reader of a process setup (the `process:` section of a scenario,
/// docs/process.md), over any tree of maps, lists and scalars: the scenario's
/// YAML (twin/io/process_yaml) and the FMU's resources/model.json
/// (fmu/process_json) are read by the same keys with the same checks. Every
/// problem is a ConfigError "where[:line]: process.key ...".
#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include "process/milling_process.hpp"

namespace twin::sim {

/// A node of a parsed document (YAML, JSON), as the reader sees it.
class SetupNode {
 public:
  virtual ~SetupNode() = default;
  /// The document's format, for messages ("YAML", "JSON").
  virtual const char* format() const = 0;
  virtual bool is_map() const = 0;
  virtual bool is_list() const = 0;
  virtual bool is_scalar() const = 0;
  /// A map's keys, in order.
  virtual std::vector<std::string> keys() const = 0;
  /// A map's entry; null when absent.
  virtual std::unique_ptr<SetupNode> get(const std::string& key) const = 0;
  virtual std::size_t size() const = 0;
  virtual std::unique_ptr<SetupNode> item(std::size_t i) const = 0;
  /// The scalar as a finite number; ConfigError naming `where` otherwise.
  virtual double number(const std::string& where) const = 0;
  /// The scalar as a name: non-empty, one line, no control characters.
  virtual std::string name(const std::string& where) const = 0;
  /// The scalar as free text (may be empty).
  virtual std::string text(const std::string& where) const = 0;
  /// "where:line: key" when the document knows the node's line, else "where: key".
  virtual std::string locate(const std::string& where, const std::string& key) const = 0;
  /// As locate, at the line of this map's key `key`; `label` names it.
  virtual std::string locate_key(const std::string& where, const std::string& key, const std::string& label) const = 0;
  /// The document of a file a scalar names (a tool or material file next to
  /// the scenario); `file_where` gets its name for messages. ConfigError
  /// where the document cannot refer to files (an FMU carries numbers).
  virtual std::unique_ptr<SetupNode> open_file(const std::string& where, std::string& file_where) const = 0;
};

/// The keys of a process setup, shared by the reader and every writer.
namespace setup_keys {
inline constexpr const char* kTool = "tool";
inline constexpr const char* kToolType = "type";
inline constexpr const char* kMaterial = "material";
inline constexpr const char* kSets = "sets";
inline constexpr const char* kStock = "stock";
inline constexpr const char* kModel = "model";
inline constexpr const char* kRunout = "runout";
/// The tool tip's modes (read_tool_tip).
inline constexpr const char* kToolTip = "tool_tip";
inline constexpr const char* kToolTipSource = "source";
inline constexpr const char* kModeFn = "fn_Hz";
inline constexpr const char* kModeZeta = "zeta";
inline constexpr const char* kModeStiffness = "k_N_per_m";
}  // namespace setup_keys

/// A tool map (keys of process::ToolGeometry, `type` flat|bull_nose|ball).
process::ToolGeometry read_tool(const SetupNode& node, const std::string& where);
/// A document holding `tool:` (a tool file).
process::ToolGeometry read_tool_document(const SetupNode& root, const std::string& where);
/// A material map with `sets:`; picks the set measured at (lead, tilt).
process::CuttingCoefficients read_material(const SetupNode& node, const std::string& where, double lead_deg,
                                           double tilt_deg);
/// A document holding `material:` (a material file).
process::CuttingCoefficients read_material_document(const SetupNode& root, const std::string& where,
                                                    double lead_deg, double tilt_deg);
/// The tool tip's modes: a map of `x` and `y`, each a list of modes
/// {fn_Hz, zeta, k_N_per_m} (`tool_tip:` of a machine file, `process.tool_tip`
/// of the FMU's resources). With `source` (a machine file) the map may also hold
/// `source:`, the text saying where the modes come from. `where` names the map
/// ("machine.yaml: tool_tip"). The modes' values are checked by
/// process::ToolTipFrf::validate, which the caller runs.
process::ToolTipFrf read_tool_tip(const SetupNode& node, const std::string& where, std::string* source = nullptr);
/// The whole `process:` section.
process::ProcessSetup read_process_setup(const SetupNode& node, const std::string& where);
/// The material's own name, as read_material was given it (it names the
/// coefficients "name (lead L deg, tilt T deg)").
std::string material_name(const process::CuttingCoefficients& coefficients, double lead_deg, double tilt_deg);

}  // namespace twin::sim
