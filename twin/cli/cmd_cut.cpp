#include <cmath>
#include <cstdio>
#include <memory>
#include <string>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "process/steady_cut.hpp"
#include "twin/cli/commands.hpp"
#include "twin/core/error.hpp"
#include "twin/io/atomic_file.hpp"
#include "twin/io/process_yaml.hpp"

namespace twin::cli {

namespace {

struct CutCliOptions {
  std::string tool;
  std::string material;
  double rpm{1200.0};
  double fz_mm{0.05};
  double ae_mm{10.0};
  double ap_mm{1.0};
  std::string mode{"up"};
  double lead_deg{0.0};
  double tilt_deg{0.0};
  double rho_mm{0.0};
  double lambda_deg{0.0};
  double step_deg{1.0};
  double sensor_f_hz{0.0};
  double sensor_zeta{0.03};
  double wear_scale{1.0};
  std::string out;
};

void add_cut_options(CLI::App* cmd, CutCliOptions& opt) {
  cmd->add_option("--tool", opt.tool, "tool YAML file (e.g. scenarios/tools/duan2025_bullnose_d10.yaml)")->required();
  cmd->add_option("--material", opt.material, "material YAML file (e.g. scenarios/materials/al2024_t6_duan2025.yaml)")
      ->required();
  cmd->add_option("--rpm", opt.rpm, "spindle speed, rev/min (clockwise, M3)")->capture_default_str();
  cmd->add_option("--fz", opt.fz_mm, "feed per tooth, mm")->capture_default_str();
  cmd->add_option("--ae", opt.ae_mm, "radial depth of cut, mm (= diameter: slot)")->capture_default_str();
  cmd->add_option("--ap", opt.ap_mm, "axial depth of cut, mm")->capture_default_str();
  cmd->add_option("--mode", opt.mode, "up or down milling")->capture_default_str();
  cmd->add_option("--lead", opt.lead_deg, "lead angle thetaL, deg (Duan 2025 eq. 4; picks the material set)")
      ->capture_default_str();
  cmd->add_option("--tilt", opt.tilt_deg, "tilt angle thetaT, deg (picks the material set)")->capture_default_str();
  cmd->add_option("--runout-rho", opt.rho_mm, "radial runout offset, mm (default: the tool file's)");
  cmd->add_option("--runout-lambda", opt.lambda_deg, "runout direction from flute 0, deg (default: the tool file's)");
  cmd->add_option("--step", opt.step_deg, "spindle angle step, deg")->capture_default_str();
  cmd->add_option("--sensor-f", opt.sensor_f_hz, "a sensor mode in the force output, Hz (0: none; twin calibrate's "
                                                  "sensor_f_hz)")->capture_default_str();
  cmd->add_option("--sensor-zeta", opt.sensor_zeta, "damping ratio of that mode")->capture_default_str();
  cmd->add_option("--wear-scale", opt.wear_scale, "wear state: factor on every coefficient, 1 + w (L - L_ref) of "
                                                  "twin calibrate's tool_wear")->capture_default_str();
  cmd->add_option("-o,--out", opt.out, "CSV file for the revolution (angle_deg, fx_N, fy_N, fz_N, torque_Nm, chip_mm)");
}

/// The cut the options describe; the tool file's runout unless given on the command line.
process::SteadyCutSpec cut_spec(const CutCliOptions& opt, const CLI::App& cmd) {
  if (opt.mode != "up" && opt.mode != "down")
    throw ConfigError(fmt::format("cut: --mode = '{}' must be up or down", opt.mode));
  process::SteadyCutSpec spec;
  spec.tool = io::load_tool_file(opt.tool);
  // The tool file's runout (e.g. identified by twin calibrate) unless given here.
  if (cmd.count("--runout-rho") > 0) spec.tool.runout_rho_mm = opt.rho_mm;
  if (cmd.count("--runout-lambda") > 0) spec.tool.runout_lambda_deg = opt.lambda_deg;
  spec.coefficients = io::load_material_file(opt.material, opt.lead_deg, opt.tilt_deg);
  spec.lead_deg = opt.lead_deg;
  spec.tilt_deg = opt.tilt_deg;
  spec.spindle_rpm = opt.rpm;
  spec.feed_per_tooth_mm = opt.fz_mm;
  spec.ae_mm = opt.ae_mm;
  spec.ap_mm = opt.ap_mm;
  spec.up_milling = opt.mode == "up";
  spec.angle_step_deg = opt.step_deg;
  spec.sensor_f_hz = opt.sensor_f_hz;
  spec.sensor_zeta = opt.sensor_zeta;
  spec.coefficient_scale = opt.wear_scale;
  return spec;
}

void run_cut(const CutCliOptions& opt, const CLI::App& cmd) {
  const process::SteadyCutSpec spec = cut_spec(opt, cmd);
  const process::SteadyCutResult r = process::run_steady_cut(spec);
  if (!opt.out.empty()) {
    std::string csv = "angle_deg,fx_N,fy_N,fz_N,torque_Nm,chip_mm\n";
    for (const auto& row : r.rows)
      csv += fmt::format("{:.4f},{:.6g},{:.6g},{:.6g},{:.6g},{:.6g}\n", row.angle_deg, row.F_N[0], row.F_N[1],
                         row.F_N[2], row.torque_Nm, row.chip_mm);
    io::write_file_atomic(opt.out, csv);
  }
  std::printf("%s", fmt::format("steady cut: {} | {} | {:.0f} rpm, fz {} mm ({:.1f} mm/min), ae {} mm, ap {} mm, "
                                "{} milling, engaged arc {:.1f} deg\n",
                                spec.tool.name, spec.coefficients.name, spec.spindle_rpm, spec.feed_per_tooth_mm,
                                r.feed_mm_per_min, spec.ae_mm, spec.ap_mm, opt.mode, r.engagement_deg)
                        .c_str());
  std::printf("force on the workpiece, N:   mean      peak\n");
  const char* names[] = {"fx", "fy", "fz"};
  for (std::size_t a = 0; a < 3; ++a)
    std::printf("  %s                      %9.3f %9.3f\n", names[a], r.mean_F_N[a], r.peak_F_N[a]);
  std::printf("spindle torque %.4f N m, cutting power %.1f W\n", r.mean_torque_Nm, r.mean_power_W);
  if (!opt.out.empty()) std::printf("wrote %s (%zu rows, one revolution)\n", opt.out.c_str(), r.rows.size());
}

}  // namespace

void register_cut(CLI::App& app) {
  auto opt = std::make_shared<CutCliOptions>();
  CLI::App* cmd = app.add_subcommand(
      "cut", "Forces of a steady straight cut over one tool revolution (forces on the workpiece, machine axes)");
  add_cut_options(cmd, *opt);
  cmd->callback([opt, cmd]() { run_cut(*opt, *cmd); });
}

}  // namespace twin::cli
