// libFuzzer harness: the machine-definition reader (twin/io/machine_file).
#include <cstdint>

#include "fuzz_util.hpp"
#include "twin/io/machine_file.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = twin::fuzz::put("machine.yaml", data, size);
  twin::fuzz::expect_contract([&] { static_cast<void>(twin::io::load_machine(path)); });
  return 0;
}
