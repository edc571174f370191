#pragma once
/// The .fmu archive: modelDescription.xml at the root, the binary at
/// binaries/<platform>/<modelIdentifier>.so and the resources under
/// resources/. The platform folder is the one each standard names for
/// 64-bit Linux: "linux64" in FMI 2.0, "x86_64-linux" in FMI 3.0.
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "fmu/model_description.hpp"

namespace twin::fmu {

/// The folder under binaries/ for 64-bit Linux.
const char* binary_platform(FmiVersion version);

struct FmuArchive {
  FmiVersion version{FmiVersion::k2};
  std::string model_description;   ///< modelDescription.xml
  std::string binary;              ///< the shared library's bytes
  /// (name under resources/, contents); resources/model.json first.
  std::vector<std::pair<std::string, std::string>> resources;
};

/// Writes the archive at `path` through a temporary name in the same folder
/// (renamed at the end: never a half-written file at `path`).
/// @throws ConfigError, before writing anything, when the binary is not one
/// of `archive.version` (no fmi2Instantiate, or no fmi3InstantiateCoSimulation);
/// IoError naming the file and libzip's reason.
void write_fmu_archive(const std::filesystem::path& path, const FmuArchive& archive);

/// The bytes of a file (the FMU binary); throws IoError naming it.
std::string read_binary_file(const std::filesystem::path& path);

}  // namespace twin::fmu
