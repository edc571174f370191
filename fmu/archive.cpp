#include "fmu/archive.hpp"

#include <cstdio>

#include <fmt/format.h>
#include <unistd.h>
#include <zip.h>

#include "twin/core/error.hpp"

namespace twin::fmu {

const char* binary_platform(FmiVersion version) { return version == FmiVersion::k3 ? "x86_64-linux" : "linux64"; }

std::string read_binary_file(const std::filesystem::path& p) {
  std::FILE* f = std::fopen(p.c_str(), "rb");
  if (f == nullptr) throw IoError(fmt::format("cannot read the FMU binary {} (build the MachineTwin target, or pass --binary)", p.string()));
  std::string data;
  char buf[65536];
  std::size_t n = 0;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) data.append(buf, n);
  std::fclose(f);
  return data;
}

namespace {

/// Writes the entries into a zip at `path` (via a temporary name).
void write_zip(const std::filesystem::path& path, const std::vector<std::pair<std::string, const std::string*>>& entries) {
  const std::string tmp = path.string() + fmt::format(".tmp{}", static_cast<long>(::getpid()));
  int err = 0;
  zip_t* z = zip_open(tmp.c_str(), ZIP_CREATE | ZIP_TRUNCATE, &err);
  if (z == nullptr) throw IoError(fmt::format("{}: cannot create the zip (libzip error {})", tmp, err));
  for (const auto& [name, data] : entries) {
    zip_source_t* src = zip_source_buffer(z, data->data(), data->size(), 0);
    if (src == nullptr || zip_file_add(z, name.c_str(), src, ZIP_FL_ENC_UTF_8 | ZIP_FL_OVERWRITE) < 0) {
      if (src != nullptr) zip_source_free(src);
      const std::string msg = zip_strerror(z);
      zip_discard(z);
      throw IoError(fmt::format("{}: cannot add {}: {}", tmp, name, msg));
    }
  }
  if (zip_close(z) != 0) {
    const std::string msg = zip_strerror(z);
    zip_discard(z);
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
    throw IoError(fmt::format("{}: cannot write the zip: {}", tmp, msg));
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
    throw IoError(fmt::format("cannot rename {} to {}: {}", tmp, path.string(), ec.message()));
  }
}

}  // namespace

void write_fmu_archive(const std::filesystem::path& path, const FmuArchive& a) {
  // The binary must be one of this version: it holds the name of the
  // version's instantiate function (which it exports); the other's does not.
  const char* entry = a.version == FmiVersion::k3 ? "fmi3InstantiateCoSimulation" : "fmi2Instantiate";
  if (a.binary.find(entry) == std::string::npos)
    throw ConfigError(fmt::format("the FMU binary has no {}: not an FMI {} binary", entry,
                                  a.version == FmiVersion::k3 ? "3.0" : "2.0"));
  std::vector<std::pair<std::string, const std::string*>> entries;
  entries.emplace_back("modelDescription.xml", &a.model_description);
  entries.emplace_back(fmt::format("binaries/{}/{}.so", binary_platform(a.version), kModelIdentifier), &a.binary);
  for (const auto& [name, data] : a.resources) entries.emplace_back("resources/" + name, &data);
  write_zip(path, entries);
}

}  // namespace twin::fmu
