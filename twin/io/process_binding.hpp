#pragma once
/// Turns the `process:` section of a scenario into a factory of process
/// models (the in-process stock at its initial state, the tool, the material).
#include <filesystem>
#include <functional>
#include <memory>
#include <string>

#include <yaml-cpp/yaml.h>

#include "process/milling_process.hpp"
#include "process/process_model.hpp"

namespace twin::io {

struct ProcessBinding {
  std::string summary;
  std::function<std::unique_ptr<process::ProcessModel>()> make;
  process::ProcessSetup setup;   ///< what `make` builds from
};

ProcessBinding bind_process(const YAML::Node& node, const std::string& where, const std::filesystem::path& dir);

}  // namespace twin::io
