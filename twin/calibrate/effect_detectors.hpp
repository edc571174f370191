#pragma once
/// The detectors the effect registry names (effect_registry.cpp): each looks
/// for one effect's signature and proposes candidates with their parameter
/// sets.
#include <vector>

#include "twin/calibrate/effect_registry.hpp"

namespace twin::analysis {

// On the inverse-dynamics residual of a machine the twin ships (diagnose.cpp).
void detect_stribeck(const DiagnoseContext& c, std::vector<EffectCandidate>& out);
void detect_cogging(const DiagnoseContext& c, std::vector<EffectCandidate>& out);
void detect_screw_pitch_error(const DiagnoseContext& c, std::vector<EffectCandidate>& out);
void detect_backlash(const DiagnoseContext& c, std::vector<EffectCandidate>& out);
void detect_constant_load(const DiagnoseContext& c, std::vector<EffectCandidate>& out);
void detect_position_dependent_friction(const DiagnoseContext& c, std::vector<EffectCandidate>& out);
void detect_delay(const DiagnoseContext& c, std::vector<EffectCandidate>& out);
void detect_compliance(const DiagnoseContext& c, std::vector<EffectCandidate>& out);
void detect_current_saturation(const DiagnoseContext& c, std::vector<EffectCandidate>& out);
void detect_load_dependent_friction(const DiagnoseContext& c, std::vector<EffectCandidate>& out);
/// stribeck's torque taken out of the residual for the chosen Ts_static and ws.
void stribeck_torque_after(const AxisSignals& s, const std::vector<double>& T_Nm, EffectCandidate& c);

// On an axis of a machine identified from data (machine_from_data.cpp).
void detect_delay_in_data(DataSearch& s);
void detect_current_saturation_in_data(DataSearch& s);
void detect_stribeck_in_data(DataSearch& s);
void detect_position_dependent_friction_in_data(DataSearch& s);
void detect_load_dependent_friction_in_data(DataSearch& s);
void detect_cogging_in_data(DataSearch& s);
void detect_screw_pitch_error_in_data(DataSearch& s);
void detect_backlash_in_data(DataSearch& s);

}  // namespace twin::analysis
