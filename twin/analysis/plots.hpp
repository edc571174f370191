#pragma once
/// Plots a person looks at, drawn by gnuplot (Debian's gnuplot-nox) from the
/// trace the run wrote: PNG files in the output folder.
#include <filesystem>
#include <string>
#include <vector>

#include "twin/analysis/run_report.hpp"

namespace twin::analysis {

/// Runs a gnuplot script; each output named in `outputs` must appear. The
/// script writes to temporary names that are renamed when gnuplot succeeds.
/// Throws IoError with gnuplot's first error line otherwise.
void run_gnuplot(const std::filesystem::path& work_dir, const std::string& script,
                 const std::vector<std::filesystem::path>& outputs);

/// feedrate.png (programmed, reference and real feed over time, corners
/// marked), errors.png (tracking per axis and contour error), and with a cut
/// forces.png (fx fy fz and engagement).
std::vector<std::filesystem::path> plot_run(const std::filesystem::path& out_dir,
                                            const std::filesystem::path& trace,
                                            const std::vector<Axis>& axes,
                                            const std::vector<CornerWindow>& corners, bool cutting);

/// Quotes a path for a gnuplot string literal.
std::string gnuplot_quote(const std::filesystem::path& p);

}  // namespace twin::analysis
