// calibrate_sweep: runs of the truth simulator (truth_sim.cpp) over every
// catalogue effect at several magnitudes and on two motion programs, each
// passed to calibrate() without being told what is in it. Prints one line per
// run: the effect put in, what calibrate added, and the held-out errors before
// and after. Not a test: a table for docs/calibration.md.
//
//   calibrate_sweep [--example RUN_DIR] [--filter NAME] [--program NAME] [--magnitudes 0.5,1,2]
//                   [--log-every M] [--current-only] [--keep DIR] [--verbose]
//
// With --example, further motion programs are the x and y reference of that
// measured run, each on the truth's X plant, and its y reference on the Y
// plant written as axis y ("Y example y"). --filter and --program
// keep the cases and programs whose names contain the text; --keep writes the
// runs under DIR (one folder each) instead of one temporary folder;
// --magnitudes sets the multiples m of each effect's middle magnitude;
// --log-every M keeps every M-th row of each run (a coarse log) and
// --current-only drops its u column.
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "truth_sim.hpp"
#include "twin/calibrate/calibrate.hpp"
#include "twin/core/error.hpp"

namespace {

using twin::truth::Effects;

struct Case {
  std::string name;
  std::string effect;
  std::function<void(Effects&)> set;
};

// Each catalogue effect at m times its middle magnitude.
struct EffectAt {
  std::string name;
  void (*set)(Effects&, double m);
  std::string variant{};  ///< appended to the case name where one effect has two forms
};

std::vector<EffectAt> catalogue() {
  return {
      {"stribeck", [](Effects& e, double m) { e.stribeck_Ts = 0.2 + 0.35 * m; e.stribeck_ws = 2.0; }},
      {"cogging", [](Effects& e, double m) { e.cogging_A = 0.15 * m; e.cogging_n = 6; e.cogging_phase = 1.0; }},
      {"screw_pitch_error", [](Effects& e, double m) { e.screw_A_mm = 0.01 * m; e.screw_P_mm = 9.0; }},
      {"backlash", [](Effects& e, double m) { e.backlash_mm = 0.01 * m; }},
      {"backlash", [](Effects& e, double m) {
         e.backlash_mm = 0.01 * m;
         e.backlash_in_coupling = true;
       }, "in coupling"},
      {"constant_load", [](Effects& e, double m) { e.load_Nm = -0.3 * m; }},
      {"position_dependent_friction", [](Effects& e, double m) { e.pdf_dTc = 0.3 * m; e.pdf_x0 = 4.0; e.pdf_x1 = 10.0; }},
      {"delay", [](Effects& e, double m) { e.delay_ticks = static_cast<int>(4 * m); }},
      {"compliance", [](Effects& e, double m) { e.compliance_K = 2500.0 / m; e.compliance_C = 0.15; }},
      {"current_saturation", [](Effects& e, double m) { e.i_max_A = 16.0 / m; }},
  };
}

std::vector<Case> cases(const std::vector<double>& magnitudes) {
  const std::vector<EffectAt> effects = catalogue();
  std::vector<Case> c;
  c.push_back({"none", "none", [](Effects&) {}});
  for (double m : magnitudes) {
    char s_buf[32];
    std::snprintf(s_buf, sizeof s_buf, std::abs(m * 10.0 - std::round(m * 10.0)) < 1e-9 ? "x%.1f" : "x%.2f", m);
    const std::string s = s_buf;
    for (const EffectAt& f : effects) c.push_back({f.name + (f.variant.empty() ? "" : " " + f.variant) + " " + s, f.name, [f, m](Effects& e) { f.set(e, m); }});
  }
  // Two effects at once, at the middle magnitudes.
  auto find = [&](const std::string& name) {
    return *std::find_if(effects.begin(), effects.end(), [&](const EffectAt& f) { return f.name == name; });
  };
  for (const auto& [a, b] : {std::pair{"stribeck", "cogging"}, std::pair{"constant_load", "cogging"},
                             std::pair{"position_dependent_friction", "screw_pitch_error"},
                             std::pair{"stribeck", "current_saturation"}}) {
    const std::string both = std::string(a) + "+" + b;
    c.push_back({"pair " + both, both, [fa = find(a), fb = find(b)](Effects& e) {
                   fa.set(e, 1.0);
                   fb.set(e, 1.0);
                 }});
  }
  return c;
}

}  // namespace

int main(int argc, char** argv) {
  std::string example, filter, program, keep;
  std::vector<double> magnitudes{0.5, 1.0, 2.0};
  long log_every = 1;
  bool verbose = false, current_only = false;
  for (int i = 1; i < argc; ++i) {
    const bool has_value = i + 1 < argc;
    if (!std::strcmp(argv[i], "--verbose")) {
      verbose = true;
    } else if (!std::strcmp(argv[i], "--example") && has_value) {
      example = argv[++i];
    } else if (!std::strcmp(argv[i], "--filter") && has_value) {
      filter = argv[++i];
    } else if (!std::strcmp(argv[i], "--program") && has_value) {
      program = argv[++i];
    } else if (!std::strcmp(argv[i], "--magnitudes") && has_value) {
      magnitudes.clear();
      for (char* t = std::strtok(argv[++i], ","); t; t = std::strtok(nullptr, ",")) {
        char* end = nullptr;
        const double m = std::strtod(t, &end);
        if (end == t || *end != '\0' || !(m > 0.0)) {
          std::fprintf(stderr, "calibrate_sweep: --magnitudes takes positive numbers separated by commas, not '%s'\n", t);
          return 2;
        }
        magnitudes.push_back(m);
      }
    } else if (!std::strcmp(argv[i], "--log-every") && has_value) {
      log_every = std::strtol(argv[++i], nullptr, 10);
      if (log_every < 1) {
        std::fprintf(stderr, "calibrate_sweep: --log-every takes a whole number of controller periods >= 1\n");
        return 2;
      }
    } else if (!std::strcmp(argv[i], "--current-only")) {
      current_only = true;
    } else if (!std::strcmp(argv[i], "--keep") && has_value) {
      keep = argv[++i];
    } else {
      std::fprintf(stderr, "calibrate_sweep: unknown or incomplete argument '%s'\n", argv[i]);
      return 2;
    }
  }
  // A program: a reference and the drive that follows it (the X plant, or
  // the Y plant written as axis y).
  struct Program {
    std::string name;
    std::vector<double> ref_mm;
    bool y_plant{false};
  };
  std::vector<Program> programs{{"trapezoids", {}, false}};
  if (!example.empty()) {
    const auto run = twin::analysis::load_run(example);
    for (const char* a : {"x", "y"})
      if (const auto* r = run.trace.find(std::string(a) + "_ref_mm")) programs.push_back({std::string("example ") + a, *r, false});
    if (const auto* r = run.trace.find("y_ref_mm")) programs.push_back({"Y example y", *r, true});
  }
  const auto tmp = std::filesystem::temp_directory_path() / ("calibrate_sweep_" + std::to_string(::getpid()));
  int wrong = 0, rose = 0, total = 0;
  for (const auto& [prog, ref, y_plant] : programs)
    for (const Case& c : cases(magnitudes)) {
      if (!filter.empty() && c.name.find(filter) == std::string::npos) continue;
      if (!program.empty() && prog.find(program) == std::string::npos) continue;
      std::string folder = prog + " " + c.name;
      std::replace(folder.begin(), folder.end(), ' ', '_');
      const auto dir = keep.empty() ? tmp : std::filesystem::path(keep) / folder;
      twin::truth::RunSpec spec;
      spec.plant = y_plant ? twin::truth::perturbed_y_plant() : twin::truth::perturbed_x_plant();
      if (y_plant) spec.axis = "y";
      spec.reference_mm = ref;
      c.set(spec.effects);
      try {
        spec.log_every = static_cast<int>(log_every);
        spec.log_current_only = current_only;
        twin::truth::write_truth_run(dir, spec);
        const auto run = twin::analysis::load_run(dir);
        std::vector<std::string> notes;
        const auto machine = twin::analysis::machine_for_run(run, "", &notes);
        const auto t0 = std::chrono::steady_clock::now();
        const auto r = twin::analysis::calibrate(run, machine);
        const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        std::string added;
        for (const auto& a : r.added) added += (added.empty() ? "" : "+") + a.candidate.effect;
        if (added.empty()) added = "none";
        const std::size_t ax = twin::index(run.axes.front());
        const auto& b = r.error_before[ax];
        const auto& a = r.error_after[ax];
        // One effect: the first added must be it. Two ("a+b"): exactly those two, in any order.
        std::vector<std::string> want, got;
        for (std::size_t p = 0, q; p <= c.effect.size(); p = q + 1) {
          q = c.effect.find('+', p);
          if (q == std::string::npos) q = c.effect.size();
          want.push_back(c.effect.substr(p, q - p));
        }
        for (const auto& ad : r.added) got.push_back(ad.candidate.effect);
        std::sort(want.begin(), want.end());
        std::sort(got.begin(), got.end());
        const bool ok = want.size() > 1 ? got == want
                                        : (r.added.empty() ? std::string("none") : r.added[0].candidate.effect) == c.effect;
        const bool up = a.err_mm > b.err_mm || a.u > b.u;
        wrong += !ok;
        rose += up;
        ++total;
        std::printf("%-12s %-34s %-40s err %.4f -> %.4f  u %.4f -> %.4f  hunt %.3f -> %.3f  %.1f s%s%s\n", prog.c_str(),
                    c.name.c_str(), added.c_str(), b.err_mm, a.err_mm, b.u, a.u, b.hunt, a.hunt, wall_s, ok ? "" : " WRONG",
                    up ? " ROSE" : "");
        if (verbose) {
          for (const auto& k : r.considered)
            std::printf("    considered %s: gain %.3f t %.1f: %s\n", k.effect.c_str(), k.signal_gain, k.t_stat,
                        k.evidence.c_str());
          for (const auto& k : r.rejected) std::printf("    rejected %s: %s\n", k.effect.c_str(), k.evidence.c_str());
          for (const auto& k : r.added)
            std::printf("    added %s: %s\n", k.candidate.effect.c_str(), k.candidate.evidence.c_str());
        }
        std::fflush(stdout);
      } catch (const twin::Error& e) {
        std::printf("%-12s %-34s error: %s\n", prog.c_str(), c.name.c_str(), e.what());
        ++wrong;
        ++total;
      }
    }
  if (keep.empty()) std::filesystem::remove_all(tmp);
  std::printf("%d runs: %d named wrong, %d with a held-out error above before\n", total, wrong, rose);
  return 0;
}
