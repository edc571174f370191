#include "feeddrive/ode_solver.hpp"

#include <exception>
#include <string>

#include <arkode/arkode_erkstep.h>
#include <cvode/cvode.h>
#include <fmt/format.h>
#include <nvector/nvector_serial.h>
#include <sundials/sundials_context.h>
#include <sunlinsol/sunlinsol_dense.h>
#include <sunmatrix/sunmatrix_dense.h>
#include <sunnonlinsol/sunnonlinsol_fixedpoint.h>

#include "twin/core/error.hpp"

namespace twin::feeddrive {

struct OdeSolver::Handles {
  SUNContext ctx{nullptr};
  N_Vector y{nullptr};
  N_Vector atol{nullptr};
  SUNNonlinearSolver nls{nullptr};
  SUNMatrix A{nullptr};
  SUNLinearSolver ls{nullptr};
  void* mem{nullptr};
  bool is_cvode{true};
  std::exception_ptr pending;

  ~Handles() {
    if (mem != nullptr) {
      if (is_cvode) {
        CVodeFree(&mem);
      } else {
        ERKStepFree(&mem);
      }
    }
    if (ls != nullptr) SUNLinSolFree(ls);
    if (A != nullptr) SUNMatDestroy(A);
    if (nls != nullptr) SUNNonlinSolFree(nls);
    if (atol != nullptr) N_VDestroy(atol);
    if (y != nullptr) N_VDestroy(y);
    if (ctx != nullptr) SUNContext_Free(&ctx);
  }
};

struct Trampolines {
  static int rhs(sunrealtype t, N_Vector y, N_Vector ydot, void* user) noexcept {
    auto* self = static_cast<OdeSolver*>(user);
    ++self->rhs_evals_;
    try {
      self->system_->rhs(t, N_VGetArrayPointer(y), N_VGetArrayPointer(ydot));
      return 0;
    } catch (...) {
      self->h_->pending = std::current_exception();
      return -1;
    }
  }
  static int roots(sunrealtype t, N_Vector y, sunrealtype* g, void* user) noexcept {
    auto* self = static_cast<OdeSolver*>(user);
    try {
      self->system_->roots(t, N_VGetArrayPointer(y), g);
      return 0;
    } catch (...) {
      self->h_->pending = std::current_exception();
      return -1;
    }
  }
  static void silent_cvode(int, const char*, const char*, char*, void*) noexcept {}
  static void silent_arkode(int, const char*, const char*, char*, void*) noexcept {}
};

namespace {
void check(int flag, const char* what) {
  if (flag < 0) throw SolverError(fmt::format("feeddrive: {} failed with flag {}", what, flag));
}
}  // namespace

OdeSolver::OdeSolver(OdeSystem& system, std::size_t size, std::size_t num_roots,
                     const IntegratorOptions& options, std::span<const double> atol,
                     double fixed_step_s)
    : system_(&system), options_(options), size_(size), roots_found_(num_roots, 0),
      h_(std::make_unique<Handles>()) {
  Handles& h = *h_;
  check(SUNContext_Create(nullptr, &h.ctx), "SUNContext_Create");
  const auto n = static_cast<sunindextype>(size);
  h.y = N_VNew_Serial(n, h.ctx);
  h.atol = N_VNew_Serial(n, h.ctx);
  if (h.y == nullptr || h.atol == nullptr) throw SolverError("feeddrive: N_VNew_Serial failed");
  N_VConst(0.0, h.y);
  double* a = N_VGetArrayPointer(h.atol);
  for (std::size_t j = 0; j < size; ++j) a[j] = atol[j];
  const int nr = static_cast<int>(num_roots);

  if (options.method == IntegratorOptions::Method::kArkodeErk) {
    h.is_cvode = false;
    h.mem = ERKStepCreate(&Trampolines::rhs, 0.0, h.y, h.ctx);
    if (h.mem == nullptr) throw SolverError("feeddrive: ERKStepCreate failed");
    check(ERKStepSetUserData(h.mem, this), "ERKStepSetUserData");
    check(ERKStepSetErrHandlerFn(h.mem, &Trampolines::silent_arkode, nullptr), "ERKStepSetErrHandlerFn");
    check(ERKStepSVtolerances(h.mem, options.rtol, h.atol), "ERKStepSVtolerances");
    check(ERKStepSetMaxNumSteps(h.mem, 200000), "ERKStepSetMaxNumSteps");
    if (fixed_step_s > 0.0) check(ERKStepSetFixedStep(h.mem, fixed_step_s), "ERKStepSetFixedStep");
    if (nr > 0) {
      check(ERKStepRootInit(h.mem, nr, &Trampolines::roots), "ERKStepRootInit");
      check(ERKStepSetNoInactiveRootWarn(h.mem), "ERKStepSetNoInactiveRootWarn");
    }
    return;
  }
  const bool adams = options.method == IntegratorOptions::Method::kCvodeAdams;
  h.mem = CVodeCreate(adams ? CV_ADAMS : CV_BDF, h.ctx);
  if (h.mem == nullptr) throw SolverError("feeddrive: CVodeCreate failed");
  check(CVodeInit(h.mem, &Trampolines::rhs, 0.0, h.y), "CVodeInit");
  check(CVodeSetUserData(h.mem, this), "CVodeSetUserData");
  check(CVodeSetErrHandlerFn(h.mem, &Trampolines::silent_cvode, nullptr), "CVodeSetErrHandlerFn");
  check(CVodeSVtolerances(h.mem, options.rtol, h.atol), "CVodeSVtolerances");
  check(CVodeSetMaxNumSteps(h.mem, 200000), "CVodeSetMaxNumSteps");
  if (adams) {
    h.nls = SUNNonlinSol_FixedPoint(h.y, 0, h.ctx);
    if (h.nls == nullptr) throw SolverError("feeddrive: SUNNonlinSol_FixedPoint failed");
    check(CVodeSetNonlinearSolver(h.mem, h.nls), "CVodeSetNonlinearSolver");
  } else {
    h.A = SUNDenseMatrix(n, n, h.ctx);
    h.ls = SUNLinSol_Dense(h.y, h.A, h.ctx);
    if (h.A == nullptr || h.ls == nullptr) throw SolverError("feeddrive: dense linear solver failed");
    check(CVodeSetLinearSolver(h.mem, h.ls, h.A), "CVodeSetLinearSolver");
  }
  if (nr > 0) {
    check(CVodeRootInit(h.mem, nr, &Trampolines::roots), "CVodeRootInit");
    check(CVodeSetNoInactiveRootWarn(h.mem), "CVodeSetNoInactiveRootWarn");
  }
}

OdeSolver::~OdeSolver() = default;

void OdeSolver::harvest_steps() noexcept {
  long n = 0;
  if (h_->is_cvode) {
    CVodeGetNumSteps(h_->mem, &n);
  } else {
    ERKStepGetNumSteps(h_->mem, &n);
  }
  // ReInit zeroes the counters, ERKStepReset may not: count only growth.
  if (n >= steps_last_seen_) {
    steps_done_ += n - steps_last_seen_;
  } else {
    steps_done_ += n;
  }
  steps_last_seen_ = n;
}

long OdeSolver::num_steps() const noexcept {
  long n = 0;
  if (h_->is_cvode) {
    CVodeGetNumSteps(h_->mem, &n);
  } else {
    ERKStepGetNumSteps(h_->mem, &n);
  }
  return steps_done_ + (n >= steps_last_seen_ ? n - steps_last_seen_ : n);
}

void OdeSolver::set_fixed_step(double step_s) {
  if (h_->is_cvode || !(step_s > 0.0))
    throw SolverError(fmt::format("feeddrive: a fixed step of {} s asked of an integrator without fixed steps", step_s));
  check(ERKStepSetFixedStep(h_->mem, step_s), "ERKStepSetFixedStep");
}

void OdeSolver::restart(double t0_s, std::span<const double> y0) {
  harvest_steps();
  double* y = N_VGetArrayPointer(h_->y);
  for (std::size_t j = 0; j < size_; ++j) y[j] = y0[j];
  if (h_->is_cvode) {
    check(CVodeReInit(h_->mem, t0_s, h_->y), "CVodeReInit");
  } else {
    check(ERKStepReset(h_->mem, t0_s, h_->y), "ERKStepReset");
  }
  long n = 0;
  if (h_->is_cvode) {
    CVodeGetNumSteps(h_->mem, &n);
  } else {
    ERKStepGetNumSteps(h_->mem, &n);
  }
  steps_last_seen_ = n;
}

OdeSolver::Stop OdeSolver::advance(double t_stop_s, std::span<double> y, double& t_reached_s) {
  Handles& h = *h_;
  int flag = 0;
  sunrealtype t_ret = 0.0;
  if (h.is_cvode) {
    check(CVodeSetStopTime(h.mem, t_stop_s), "CVodeSetStopTime");
    flag = CVode(h.mem, t_stop_s, h.y, &t_ret, CV_NORMAL);
  } else {
    check(ERKStepSetStopTime(h.mem, t_stop_s), "ERKStepSetStopTime");
    flag = ERKStepEvolve(h.mem, t_stop_s, h.y, &t_ret, ARK_NORMAL);
  }
  if (h.pending) {
    std::exception_ptr e = h.pending;
    h.pending = nullptr;
    std::rethrow_exception(e);
  }
  if (flag < 0) {
    // Flags -1..-4 mean the same in CVODE and ARKODE.
    const char* why = flag == -1   ? "too many steps: a time constant of a drive is far shorter than the tick"
                      : flag == -2 ? "the tolerances cannot be met"
                      : flag == -3 ? "error test failed repeatedly: the state moves faster than the step can follow"
                      : flag == -4 ? "convergence failed repeatedly"
                                   : "see the SUNDIALS return flags";
    throw SolverError(fmt::format("feeddrive: {} failed with flag {} ({}) at t = {} s (target {} s)",
                                  h.is_cvode ? "CVode" : "ERKStepEvolve", flag, why, t_ret, t_stop_s));
  }
  const double* yv = N_VGetArrayPointer(h.y);
  for (std::size_t j = 0; j < size_; ++j) y[j] = yv[j];
  t_reached_s = t_ret;
  const bool root = h.is_cvode ? flag == CV_ROOT_RETURN : flag == ARK_ROOT_RETURN;
  if (!root) return Stop::kReachedEnd;
  if (h.is_cvode) {
    check(CVodeGetRootInfo(h.mem, roots_found_.data()), "CVodeGetRootInfo");
  } else {
    check(ERKStepGetRootInfo(h.mem, roots_found_.data()), "ERKStepGetRootInfo");
  }
  return Stop::kRoot;
}

}  // namespace twin::feeddrive
