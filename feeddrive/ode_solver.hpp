#pragma once
/// Internal to feeddrive: one SUNDIALS integrator (CVODE Adams or BDF, or
/// ARKODE ERK) with root finding, owned RAII-style. SUNDIALS types stay in
/// ode_solver.cpp; this header speaks plain doubles.
#include <cstddef>
#include <memory>
#include <span>
#include <vector>

#include "feeddrive/drive_bank.hpp"

namespace twin::feeddrive {

/// The right-hand side y' = f(t, y) and the root functions g(t, y) of one
/// integrator. Implementations may throw; the solver rethrows after SUNDIALS
/// returns (no exception crosses the C callback boundary).
class OdeSystem {
 public:
  virtual ~OdeSystem() = default;
  virtual void rhs(double t_s, const double* y, double* ydot) = 0;
  virtual void roots(double t_s, const double* y, double* g) = 0;
};

class OdeSolver {
 public:
  enum class Stop { kReachedEnd, kRoot };

  /// size states, num_roots root functions, absolute tolerance per state.
  /// fixed_step_s > 0 selects fixed steps (ARKODE ERK only).
  /// @throws SolverError if SUNDIALS cannot be set up.
  OdeSolver(OdeSystem& system, std::size_t size, std::size_t num_roots,
            const IntegratorOptions& options, std::span<const double> atol,
            double fixed_step_s);
  ~OdeSolver();
  OdeSolver(const OdeSolver&) = delete;
  OdeSolver& operator=(const OdeSolver&) = delete;

  /// ARKODE ERK with fixed steps only: the step from the next advance on
  /// (call restart() before it).
  /// @throws SolverError on any other method or a step that is not > 0.
  void set_fixed_step(double step_s);
  /// Drops all history and restarts from (t0_s, y0) (CVodeReInit / ERKStepReset).
  void restart(double t0_s, std::span<const double> y0);
  /// Integrates towards t_stop_s, never past it; writes the state at the
  /// returned time into y and the time into t_reached_s. On kRoot,
  /// roots_found()[j] != 0 for each root function j that crossed zero.
  /// @throws SolverError (flag, time) or the exception the system threw.
  Stop advance(double t_stop_s, std::span<double> y, double& t_reached_s);
  const std::vector<int>& roots_found() const noexcept { return roots_found_; }

  long num_steps() const noexcept;
  long num_rhs_evals() const noexcept { return rhs_evals_; }

  struct Handles;

 private:
  void harvest_steps() noexcept;

  OdeSystem* system_;
  IntegratorOptions options_;
  std::size_t size_;
  std::vector<int> roots_found_;
  std::unique_ptr<Handles> h_;
  long rhs_evals_{0};
  long steps_done_{0};       // steps of earlier runs (counters restart with ReInit)
  long steps_last_seen_{0};
  friend struct Trampolines;
};

}  // namespace twin::feeddrive
