#include "twin/cli/common.hpp"

#include <iterator>
#include <system_error>

#include <fmt/format.h>

#include "twin/core/error.hpp"

namespace twin::cli {

void apply_sets(sim::MachineDefinition& machine, const std::vector<std::string>& sets) {
  for (const auto& s : sets) sim::apply_set(machine, s);
  if (!sets.empty()) machine.source += " (with --set)";
  machine.validate();
}

namespace {

// The absolute path with links, "." and ".." resolved as far as it exists.
std::filesystem::path resolved(const std::filesystem::path& p) {
  std::error_code ec;
  std::filesystem::path r = std::filesystem::weakly_canonical(std::filesystem::absolute(p, ec), ec);
  if (ec) r = std::filesystem::absolute(p, ec).lexically_normal();
  return r;
}

// Whether `inner` is `outer` or a path below it (both resolved).
bool is_within(const std::filesystem::path& inner, const std::filesystem::path& outer) {
  auto i = inner.begin();
  for (auto o = outer.begin(); o != outer.end(); ++o, ++i) {
    if (o->empty() && std::next(o) == outer.end()) break;  // a trailing separator
    if (i == inner.end() || *i != *o) return false;
  }
  return true;
}

}  // namespace

void refuse_output_over_input(std::string_view command, const std::filesystem::path& out,
                              const std::filesystem::path& run_dir, const std::string& machine_option) {
  const auto out_r = resolved(out);
  const auto run_r = resolved(run_dir);
  if (is_within(out_r, run_r))
    throw ConfigError(fmt::format("{}: output folder {} {} the measured run {}: its files would be overwritten or "
                                  "hidden; choose an OUT outside the run folder",
                                  command, out.string(), out_r == run_r ? "is" : "is inside", run_dir.string()));
  std::vector<std::filesystem::path> inputs;
  for (const char* name : {"trace.csv", "trace.csv.gz", "meta.json"}) inputs.push_back(run_dir / name);
  std::error_code ec;
  if (!machine_option.empty() && std::filesystem::is_regular_file(machine_option, ec)) inputs.emplace_back(machine_option);
  for (const auto& in : inputs) {
    if (!std::filesystem::exists(in, ec)) continue;
    const auto in_r = resolved(in);
    if (in_r.parent_path() == out_r)
      throw ConfigError(fmt::format("{}: output folder {} holds the input {} ({}): it would be overwritten; choose "
                                    "another OUT",
                                    command, out.string(), in.string(), in_r.string()));
  }
}

}  // namespace twin::cli
