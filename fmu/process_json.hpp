#pragma once
/// The process section of a scenario, in its JSON form (resources/model.json
/// of an FMU), turned into a process model at its initial state.
///
/// Accepted keys (units in the names, as in process/*.hpp):
///   tool: {name, shape: flat|bull_nose|ball, diameter_mm, flutes, helix_deg,
///          corner_radius_mm, flute_length_mm, runout_rho_mm, runout_lambda_deg}
///   coefficients: {name, Kt|Kr|Ka: {a_N_per_mm2, b_N_per_mm2, c_per_mm},
///                  Kte_N_per_mm, Kre_N_per_mm, Kae_N_per_mm}
///                 or {name, linear: {Ktc_N_per_mm2, Krc_N_per_mm2, Kac_N_per_mm2,
///                  Kte_N_per_mm, Kre_N_per_mm, Kae_N_per_mm}}
///   stock: {outline_mm: [[x, y], ...] | rectangle_mm: [x0, y0, x1, y1],
///           top_z_mm, bottom_z_mm, cell_mm,
///           pockets: [{polygon_mm: [[x, y], ...] | center_mm: [x, y], radius_mm, floor_z_mm}]}
///   options: {dz_mm, angle_step_deg, engagement_step_deg}
///   lead_deg, tilt_deg, spindle_angle0_deg
/// Keys left out keep the defaults of process::ProcessSetup.
#include <memory>

#include <nlohmann/json_fwd.hpp>

#include "process/milling_process.hpp"
#include "process/process_model.hpp"

namespace twin::fmu {

/// Builds the milling process (process::make_process) from `process`.
/// A null `process` gives nullptr (an air cut).
/// @throws ConfigError naming the key and the value for an unknown key, a
/// value of the wrong type, or a setup that process::ProcessSetup rejects.
std::unique_ptr<process::ProcessModel> make_process_from_json(const nlohmann::json& process);
/// The setup make_process_from_json builds from (`process` not null).
process::ProcessSetup process_setup_from_json(const nlohmann::json& process);

/// The JSON form of a complete setup (every field, numbers to the last
/// bit), which make_process_from_json turns back into the same process.
/// `twin export-fmu` writes it from the scenario's resolved process section
/// (tool and material files read), so the FMU needs no other file.
nlohmann::json process_setup_to_json(const process::ProcessSetup& setup);

}  // namespace twin::fmu
