#pragma once
// Shared by the fuzz harnesses. The contract under test: a reader given any
// bytes either returns or throws a twin::Error (one line, no crash, no
// hang, no other exception). Anything else escaping is a finding: abort().
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>

#include "twin/core/error.hpp"

namespace twin::fuzz {

/// A folder of this process's own under the temporary directory.
inline const std::filesystem::path& scratch() {
  static const std::filesystem::path dir = [] {
    auto d = std::filesystem::temp_directory_path() / ("twin_fuzz_" + std::to_string(::getpid()));
    std::filesystem::create_directories(d);
    return d;
  }();
  return dir;
}

/// Writes the input to `name` in scratch() and returns its path.
inline std::filesystem::path put(const std::string& name, const std::uint8_t* data, std::size_t size) {
  const auto p = scratch() / name;
  std::filesystem::create_directories(p.parent_path());
  std::ofstream f(p, std::ios::binary | std::ios::trunc);
  f.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  return p;
}

/// Runs `body`; twin::Error is an accepted outcome, any other exception aborts.
template <class F>
void expect_contract(F&& body) {
  try {
    body();
  } catch (const twin::Error& e) {
    const std::string_view msg = e.what();
    if (msg.find('\n') != std::string_view::npos) {
      std::fprintf(stderr, "message of more than one line: %.200s\n", e.what());
      std::abort();
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "exception outside the contract: %s\n", e.what());
    std::abort();
  }
}

}  // namespace twin::fuzz
