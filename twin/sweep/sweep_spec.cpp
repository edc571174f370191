#include "twin/sweep/sweep_spec.hpp"

#include <algorithm>
#include <set>

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include "twin/core/error.hpp"
#include "twin/io/yaml_util.hpp"

namespace twin::sweep {

namespace {

std::string at(const std::filesystem::path& file, const YAML::Node& node, const std::string& key) {
  const YAML::Mark m = node.Mark();
  if (m.line < 0) return fmt::format("{}: {}", file.string(), key);
  return fmt::format("{}:{}: {}", file.string(), m.line + 1, key);
}

// A scalar of the file as text (numbers as written, so a value keeps its spelling).
std::string scalar(const YAML::Node& node, const std::string& where) {
  if (!node.IsScalar() || node.Scalar().empty()) throw ConfigError(fmt::format("{} must be a plain value", where));
  return io::yaml_name(node, where);
}

std::vector<std::string> scalar_list(const YAML::Node& node, const std::string& where) {
  std::vector<std::string> out;
  if (node.IsScalar()) {
    out.push_back(scalar(node, where));
    return out;
  }
  if (!node.IsSequence() || node.size() == 0) throw ConfigError(fmt::format("{} must be a value or a non-empty list", where));
  for (std::size_t i = 0; i < node.size(); ++i) out.push_back(scalar(node[i], fmt::format("{}[{}]", where, i)));
  return out;
}

// A relative path that names a file next to SWEEP.yaml is taken from there;
// anything else (a shipped name, an absolute path) is passed on as written.
std::string resolve(const std::filesystem::path& dir, const std::string& ref) {
  const std::filesystem::path p(ref);
  if (p.is_relative()) {
    std::error_code ec;
    if (std::filesystem::exists(dir / p, ec)) return (dir / p).lexically_normal().string();
  }
  return ref;
}

void check_set(const std::string& assignment, const std::string& where) {
  const auto eq = assignment.find('=');
  const auto dot = assignment.find('.');
  if (eq == std::string::npos || dot == std::string::npos || dot > eq || eq + 1 == assignment.size())
    throw ConfigError(fmt::format("{}: '{}' is not <axis>.<name>=<value>", where, io::escaped(assignment)));
}

bool plain_name(const std::string& n) {
  if (n.empty() || n.size() > 100 || n.front() == '.') return false;
  return std::all_of(n.begin(), n.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' || c == '-' ||
           c == '.';
  });
}

struct Axis {
  std::string key;                  ///< "scenario", "machine", "run" or a --set key such as "x.Kp"
  std::vector<std::string> values;
};

/// What SWEEP.yaml gives beside its command, trace format and log rate.
struct SweepFile {
  SweepCase base;                   ///< scenario, machine and set of every case
  std::vector<Axis> grid;
  std::vector<SweepCase> listed;
  std::vector<std::string> runs;
  bool has_grid{false};
  bool has_cases{false};
  bool has_runs{false};
};

/// grid: a map of lists (scenario, machine, run) and of --set keys under set.
std::vector<Axis> read_grid(const std::filesystem::path& path, const YAML::Node& v, const std::string& w) {
  if (!v.IsMap() || v.size() == 0) throw ConfigError(fmt::format("{} must be a map of lists", w));
  std::vector<Axis> grid;
  for (const auto& g : v) {
    const std::string gk = g.first.as<std::string>();
    const std::string gw = at(path, g.first, "grid." + gk);
    if (gk == "scenario" || gk == "machine" || gk == "run") {
      grid.push_back({gk, scalar_list(g.second, gw)});
    } else if (gk == "set") {
      if (!g.second.IsMap() || g.second.size() == 0)
        throw ConfigError(fmt::format("{} must be a map <axis>.<name>: [values]", gw));
      for (const auto& sv : g.second) {
        const std::string sk = sv.first.as<std::string>();
        const std::string sw = at(path, sv.first, "grid.set." + sk);
        Axis a{sk, scalar_list(sv.second, sw)};
        for (const auto& value : a.values) check_set(sk + "=" + value, sw);
        grid.push_back(std::move(a));
      }
    } else {
      throw ConfigError(fmt::format("{}: unknown grid key (scenario, machine, run, set)", gw));
    }
  }
  return grid;
}

/// One entry of cases: name, scenario, machine, run, set.
SweepCase read_case(const std::filesystem::path& path, const YAML::Node& cn, std::size_t i) {
  const std::string cw = at(path, cn, fmt::format("cases[{}]", i));
  if (!cn.IsMap()) throw ConfigError(fmt::format("{} must be a map", cw));
  SweepCase c;
  for (const auto& ckv : cn) {
    const std::string ck = ckv.first.as<std::string>();
    const std::string ckw = cw + "." + ck;
    if (ck == "name") {
      c.name = scalar(ckv.second, ckw);
      if (!plain_name(c.name))
        throw ConfigError(fmt::format("{} = '{}': a case name is letters, digits, '_', '-', '.'", ckw,
                                      io::escaped(c.name)));
    } else if (ck == "scenario") {
      c.scenario = scalar(ckv.second, ckw);
      c.params.emplace_back("scenario", c.scenario);
    } else if (ck == "machine") {
      c.machine = scalar(ckv.second, ckw);
      c.params.emplace_back("machine", c.machine);
    } else if (ck == "run") {
      c.run_dir = scalar(ckv.second, ckw);
      c.params.emplace_back("run", c.run_dir);
    } else if (ck == "set") {
      c.sets = scalar_list(ckv.second, ckw);
      for (const auto& s : c.sets) {
        check_set(s, ckw);
        c.params.emplace_back(s.substr(0, s.find('=')), s.substr(s.find('=') + 1));
      }
    } else {
      throw ConfigError(fmt::format("{}: unknown key '{}' (name, scenario, machine, run, set)", cw, io::escaped(ck)));
    }
  }
  return c;
}

/// The settings of every case: command, scenario, machine, set, trace_format, log_every.
/// False for any other key.
bool read_setting(const std::string& key, const std::string& w, const YAML::Node& v, SweepSpec& spec,
                  SweepCase& base) {
  if (key == "command") {
    spec.command = scalar(v, w);
    if (spec.command != "run" && spec.command != "calibrate")
      throw ConfigError(fmt::format("{} = '{}': a sweep runs 'run' or 'calibrate'", w, io::escaped(spec.command)));
  } else if (key == "scenario") {
    base.scenario = scalar(v, w);
  } else if (key == "machine") {
    base.machine = scalar(v, w);
  } else if (key == "set") {
    base.sets = scalar_list(v, w);
    for (const auto& s : base.sets) check_set(s, w);
  } else if (key == "trace_format") {
    spec.trace_format = scalar(v, w);
    if (spec.trace_format != "csv" && spec.trace_format != "csv.gz")
      throw ConfigError(fmt::format("{} = '{}' is not csv or csv.gz", w, io::escaped(spec.trace_format)));
  } else if (key == "log_every") {
    const double n = io::yaml_number(v, w);
    if (!(n >= 1.0 && n <= 1e9) || n != static_cast<double>(static_cast<std::int64_t>(n)))
      throw ConfigError(fmt::format("{} = {} must be a whole number of ticks >= 1", w, v.Scalar()));
    spec.log_every = static_cast<std::int64_t>(n);
  } else {
    return false;
  }
  return true;
}

/// The top-level keys of SWEEP.yaml.
SweepFile read_sweep_file(const std::filesystem::path& path, const YAML::Node& root, SweepSpec& spec) {
  SweepFile f;
  for (const auto& kv : root) {
    const std::string key = kv.first.as<std::string>();
    const std::string w = at(path, kv.first, key);
    const YAML::Node& v = kv.second;
    if (read_setting(key, w, v, spec, f.base)) continue;
    if (key == "runs") {
      f.has_runs = true;
      f.runs = scalar_list(v, w);
    } else if (key == "grid") {
      f.has_grid = true;
      f.grid = read_grid(path, v, w);
    } else if (key == "cases") {
      f.has_cases = true;
      if (!v.IsSequence() || v.size() == 0) throw ConfigError(fmt::format("{} must be a non-empty list", w));
      for (std::size_t i = 0; i < v.size(); ++i) f.listed.push_back(read_case(path, v[i], i));
    } else {
      throw ConfigError(fmt::format("{}: unknown key (command, scenario, machine, set, trace_format, log_every, "
                                    "grid, cases, runs)",
                                    w));
    }
  }
  return f;
}

/// The grid's cases: every combination, the first key varying slowest.
std::vector<SweepCase> grid_cases(const std::string& file, const std::vector<Axis>& grid) {
  std::vector<SweepCase> cases;
  std::size_t total = 1;
  for (const auto& a : grid) {
    total *= a.values.size();
    if (total > kMaxCases) throw ConfigError(fmt::format("{}: the grid has more than {} cases", file, kMaxCases));
  }
  for (std::size_t n = 0; n < total; ++n) {
    SweepCase c;
    std::size_t rest = n;
    std::vector<std::size_t> pick(grid.size());
    for (std::size_t a = grid.size(); a-- > 0;) {
      pick[a] = rest % grid[a].values.size();
      rest /= grid[a].values.size();
    }
    for (std::size_t a = 0; a < grid.size(); ++a) {
      const std::string& value = grid[a].values[pick[a]];
      const std::string& k = grid[a].key;
      if (k == "scenario") c.scenario = value;
      else if (k == "machine") c.machine = value;
      else if (k == "run") c.run_dir = value;
      else c.sets.push_back(k + "=" + value);
      c.params.emplace_back(k, value);
    }
    cases.push_back(std::move(c));
  }
  return cases;
}

/// The grid's cases, then the listed ones, then one per measured run (the defaults
/// alone when there is none of them).
std::vector<SweepCase> all_cases(const std::string& file, SweepFile& f) {
  std::vector<SweepCase> cases;
  if (f.has_grid) cases = grid_cases(file, f.grid);
  for (auto& c : f.listed) cases.push_back(std::move(c));
  if (f.has_runs)
    for (const auto& r : f.runs) {
      SweepCase c;
      c.run_dir = r;
      c.params.emplace_back("run", r);
      cases.push_back(std::move(c));
    }
  if (!f.has_grid && !f.has_cases && !f.has_runs) cases.emplace_back();  // the defaults alone: one case
  if (cases.size() > kMaxCases) throw ConfigError(fmt::format("{}: more than {} cases", file, kMaxCases));
  return cases;
}

/// A named case with the sweep's defaults, checked against its command, its paths
/// taken from next to SWEEP.yaml (in `dir`) where they name a file there.
void complete_case(const std::string& file, const std::filesystem::path& dir, const SweepSpec& spec,
                   const SweepCase& base, SweepCase& c) {
  if (c.scenario.empty()) c.scenario = base.scenario;
  if (c.machine.empty()) c.machine = base.machine;
  std::vector<std::string> sets = base.sets;
  sets.insert(sets.end(), c.sets.begin(), c.sets.end());  // the case's own come last and win
  c.sets = std::move(sets);
  if (spec.command == "calibrate" && c.run_dir.empty())
    throw ConfigError(fmt::format("{}: case '{}' of a calibrate sweep names no measured run (runs, or run: in a "
                                  "case or the grid)",
                                  file, c.name));
  if (spec.command == "run" && !c.run_dir.empty())
    throw ConfigError(fmt::format("{}: case '{}' names a measured run but the sweep's command is run (say "
                                  "command: calibrate)",
                                  file, c.name));
  if (!c.scenario.empty()) c.scenario = resolve(dir, c.scenario);
  if (!c.machine.empty()) c.machine = resolve(dir, c.machine);
  if (!c.run_dir.empty()) c.run_dir = resolve(dir, c.run_dir);
}

}  // namespace

SweepSpec load_sweep(const std::filesystem::path& path) {
  const YAML::Node root = io::load_yaml_file(path);
  const std::string file = path.string();
  if (!root.IsMap()) throw ConfigError(fmt::format("{}: a sweep must be a YAML map", file));
  SweepSpec spec;
  spec.source = path;
  SweepFile f = read_sweep_file(path, root, spec);
  std::vector<SweepCase> cases = all_cases(file, f);
  std::set<std::string> names;
  for (std::size_t i = 0; i < cases.size(); ++i) {
    SweepCase& c = cases[i];
    c.index = i;
    c.command = spec.command;
    if (c.name.empty()) c.name = fmt::format("case{:04d}", i);
    if (!names.insert(c.name).second)
      throw ConfigError(fmt::format("{}: case name '{}' is given twice", file, c.name));
    complete_case(file, path.parent_path(), spec, f.base, c);
  }
  spec.cases = std::move(cases);
  return spec;
}

std::vector<std::string> case_arguments(const SweepSpec& spec, const SweepCase& c,
                                        const std::filesystem::path& case_dir) {
  std::vector<std::string> a;
  if (c.command == "calibrate") {
    a = {"calibrate", c.run_dir, "-o", case_dir.string(), "--no-plots"};
  } else {
    a = {"run"};
    if (!c.scenario.empty()) a.push_back(c.scenario);
    a.insert(a.end(), {"-o", case_dir.string(), "--no-plots", "--trace-format", spec.trace_format, "--log-every",
                       std::to_string(spec.log_every)});
  }
  if (!c.machine.empty()) a.insert(a.end(), {"--machine", c.machine});
  if (!c.sets.empty()) {
    a.push_back("--set");
    a.insert(a.end(), c.sets.begin(), c.sets.end());
  }
  return a;
}

}  // namespace twin::sweep
