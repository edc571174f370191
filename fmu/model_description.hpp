#pragma once
/// modelDescription.xml of the FMU (FMI 2.0 or 3.0), generated from the
/// variable table (fmu/variables.hpp) and the model (fmu/model.hpp), and its
/// GUID (FMI 2.0) or instantiationToken (FMI 3.0): a hash of the generated
/// text and of resources/model.json, so that it changes when either does.
/// The FMU regenerates both when it is instantiated and refuses one that
/// differs.
#include <cstddef>
#include <string>

#include "fmu/model.hpp"

namespace twin::fmu {

/// modelIdentifier: the name of the shared library in binaries/<platform>/.
inline constexpr const char* kModelIdentifier = "MachineTwin";

enum class FmiVersion { k2, k3 };

/// FMI 2.0 guid: "{xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxxxx}" from the model and its table.
std::string model_guid(const FmuModel& model);
/// FMI 3.0 instantiationToken, in the same form, from the FMI 3.0 text.
std::string instantiation_token(const FmuModel& model);
/// The whole modelDescription.xml (Co-Simulation), GUID or token included.
std::string model_description_xml(const FmuModel& model, FmiVersion version = FmiVersion::k2);
/// FMI 3.0: the value reference of the independent variable `time` (after
/// every row of the variable table).
std::size_t time_value_reference(const FmuModel& model);

}  // namespace twin::fmu
