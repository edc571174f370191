// libFuzzer harness: the `process:` section reader (twin/io/process_yaml)
// on a YAML document, with the shipped tools and materials next to it.
#include <cstdint>
#include <string>

#include "fuzz_util.hpp"
#include "twin/io/machine_file.hpp"
#include "twin/io/process_yaml.hpp"
#include "twin/io/yaml_util.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  twin::fuzz::expect_contract([&] {
    const std::string text(reinterpret_cast<const char*>(data), size);
    const YAML::Node doc = twin::io::parse_yaml_text(text, "fuzz.yaml");
    // A scenario's `process:` section, or the section's content alone.
    const YAML::Node node = doc.IsMap() && doc["process"] ? doc["process"] : doc;
    static_cast<void>(
        twin::io::parse_process_setup(node, "fuzz.yaml: process", twin::io::scenarios_dir() / "fadal_pocket_corner"));
  });
  return 0;
}
