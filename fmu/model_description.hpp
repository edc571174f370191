#pragma once
/// modelDescription.xml of the FMU, generated from the variable table
/// (fmu/variables.hpp) and the model (fmu/model.hpp), and its GUID: a hash of
/// the generated text and of resources/model.json, so that it changes when
/// either does. The FMU regenerates both at fmi2Instantiate and refuses a
/// GUID that differs.
#include <string>

#include "fmu/model.hpp"

namespace twin::fmu {

/// modelIdentifier: the name of the shared library in binaries/linux64/.
inline constexpr const char* kModelIdentifier = "MachineTwin";

/// "{xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxxxx}" from the model and its table.
std::string model_guid(const FmuModel& model);
/// The whole modelDescription.xml (FMI 2.0, Co-Simulation), GUID included.
std::string model_description_xml(const FmuModel& model);

}  // namespace twin::fmu
