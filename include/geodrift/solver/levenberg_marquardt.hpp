#pragma once

/// @file
/// LevenbergMarquardt: the damped Gauss-Newton loop over a Problem. It owns the loop and the
/// linear solver, nothing else.
///
/// Each iteration solves (H + λ·D)·δ = −g with H = J̃ᵀJ̃, g = J̃ᵀr̃ (weighted, Triggs-corrected
/// Jacobian and residual, see residual_block.hpp), then tries x ← x ⊞ δ.
///
/// Scaling and damping. Columns are Jacobi-scaled, s_c = 1/(1 + √H_cc) (as Ceres), and the
/// damping is λ times the scaled diagonal clamped to [min_diagonal, max_diagonal]; written back
/// in unscaled variables this is D_c = clamp(s_c²·H_cc, min, max)/s_c², which we add to H's
/// diagonal directly (identical step, no rescaling pass over H).
///
/// λ update (gain ratio). ρ = (F(x) − F(x ⊞ δ)) / (L(0) − L(δ)) with the model decrease
/// L(0) − L(δ) = ½·δᵀ(λ·D·δ − g). A step is accepted only if F decreases (ρ > 0); then
/// λ ← λ·max(f, 1 − (2ρ − 1)³), ν ← 2 (f = Options::lambda_decrease_limit: by default
/// Nielsen's 1/3, optionally Marquardt's 1/10, see there); otherwise the states are restored and λ
/// ← λ·ν, ν ← 2ν. Source: H.B. Nielsen, "Damping parameter in Marquardt's method", IMM-REP-1999-05,
/// and K. Madsen, H.B. Nielsen, O. Tingleff, "Methods for non-linear least squares problems",
/// 2nd ed., IMM DTU 2004, §3.2 (eq. 3.15 and Algorithm 3.16).
///
/// A step that raises the cost is never accepted. A factorisation that is not positive
/// definite, a non-finite step, or a trial point where a residual cannot be evaluated is a
/// rejected step (λ grows), never an exception. The loop allocates nothing per iteration (all
/// buffers are sized before the first iteration; CHOLMOD's internal workspace is its own).

#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <limits>
#include <memory>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "geodrift/solver/block_cholesky_solver.hpp"
#include "geodrift/solver/block_sparse_matrix.hpp"
#include "geodrift/solver/cholmod_solver.hpp"
#include "geodrift/solver/dense_solver.hpp"
#include "geodrift/solver/linear_solver.hpp"
#include "geodrift/solver/problem.hpp"
#include "geodrift/solver/schur.hpp"

namespace geodrift::solver {

/// Which linear solver LM uses for the damped normal equations.
enum class LinearSolverType {
  kCholmod,  ///< CHOLMOD Cholesky on the full H (general; supernodal or simplicial by its rule)
  /// Eliminate R^3 point blocks (BA); the reduced camera system goes to the block Cholesky
  /// when its cameras are 6/7 wide and its factor is thin (≤ kAutoMaxBlocksPerColumn blocks per
  /// column), otherwise to CHOLMOD (SchurSolver::ReducedSolver::kAuto, schur.hpp).
  kSchur,
  kDense,       ///< dense LLᵀ of H (tests, tiny problems)
  kSchurDense,  ///< Schur elimination, dense LLᵀ of the reduced camera system (tiny BA)
  /// Block sparse Cholesky with fixed-size 6×6 / 7×7 kernels (block_cholesky_solver.hpp);
  /// needs every free block of size 6 or 7 (SE(3) / Sim(3) pose graphs), else the solve stops
  /// with kInvalidProblem.
  kBlockCholesky,
  /// kSchur with CHOLMOD on the reduced camera system, whatever its shape.
  kSchurCholmod,
  /// kSchur with the block Cholesky on the reduced camera system (cameras of size 6 or 7,
  /// else the solve stops with kLinearSolverFailure).
  kSchurBlockCholesky,
  /// kBlockCholesky when every free block has size 6 or 7 and its factor is thin (chain-like
  /// graphs: at most kAutoMaxBlocksPerColumn blocks per column of L on average), otherwise
  /// kCholmod. Decided at each symbolic analysis.
  kAuto,
};

/// LM options; every member has a default.
struct Options {
  /// Maximum number of LM iterations (each linear solve, accepted or rejected, counts one).
  int max_iterations = 100;
  /// Stop after an accepted step when (F_old − F_new) ≤ function_tolerance · F_old.
  double function_tolerance = 1e-6;
  /// Stop when max_c |g_c| ≤ gradient_tolerance, g = J̃ᵀr̃ (gradient of the cost).
  double gradient_tolerance = 1e-10;
  /// Stop when |δ| ≤ parameter_tolerance · (|x| + parameter_tolerance), |x| in ambient
  /// coordinates over the free blocks (Problem::state_norm()).
  double parameter_tolerance = 1e-8;
  /// Initial damping λ (relative to the scaled diagonal; 1e-4 = Ceres' initial radius 1e4).
  double initial_lambda = 1e-4;
  /// Smallest factor an accepted step multiplies λ by: λ ← λ·max(lambda_decrease_limit,
  /// 1 − (2ρ − 1)³). Default 1/3: Nielsen's rule (as Ceres and g2o). 1/10 is Marquardt's
  /// original decrease factor (D. W. Marquardt, "An algorithm for least-squares estimation of
  /// nonlinear parameters", SIAM J. Appl. Math. 11(2), 1963: λ/ν with ν = 10; also GTSAM's
  /// lambdaFactor) as the limit for very good steps (ρ → 1), Nielsen's smooth rule otherwise.
  /// Measured from the same starts with 1/10 (bench_solver sets it, BENCHMARKS.md): Sim3 drift
  /// 10k 14 → 10 iterations, sphere2500 10 → 7, parking-garage 14 → 9, cubicle 47 → 46,
  /// torus3D 99 = 99. Not the default: on the ill-conditioned 3-camera BAL subset (cond(H) ≈
  /// 3e7) it stops (parameter tolerance) where |g|/λ_min(H) = 2.3e-5, above the 1e-5 that the
  /// solver_data test asks of every linear solver.
  double lambda_decrease_limit = 1.0 / 3.0;
  /// Stop (no step can decrease the cost) when λ exceeds this.
  double max_lambda = 1e32;
  /// λ never drops below this (as Ceres' max trust-region radius 1e16), so that a rejected
  /// step after a long run of very successful ones recovers damping in a few iterations.
  double min_lambda = 1e-16;
  /// Clamp of the Jacobi-scaled diagonal used for damping (as Ceres' min/max_lm_diagonal).
  double min_diagonal = 1e-6;
  double max_diagonal = 1e32;
  /// kAuto: the block Cholesky for thin 6/7-block pose graphs, CHOLMOD otherwise; BA wants
  /// kSchur (set it explicitly).
  LinearSolverType linear_solver = LinearSolverType::kAuto;
  /// After an accepted step, evaluate the next trial point with Jacobians, into H (already
  /// factorised and solved with) and a second g; its cost decides the step as usual. When the
  /// step is accepted again, which is the common case, the separate cost-only evaluation is
  /// saved; when it is rejected, x is linearised again (one linearisation more than without
  /// speculation). The first trial (nothing is known yet about how well λ0 fits the problem) and
  /// trials after a rejection are evaluated cost-only. Same steps either way. (On the 50k drift
  /// graph, whose first trial at λ0 = 1e-8 is rejected, a cost-only first trial took the time to
  /// reach Ceres' cost from 6.81 to 6.44 s CPU, medians of 6; on the 10k graph, whose first trial
  /// is accepted, no change beyond noise: round 8 of BENCHMARKS.md's history,
  /// `git show 3d5878d:BENCHMARKS.md`.)
  bool speculative_linearization = true;
  /// Geodesic acceleration (M. K. Transtrum, J. P. Sethna, "Improvements to the
  /// Levenberg-Marquardt algorithm for nonlinear least-squares minimization", arXiv:1201.5885,
  /// 2012, Sec. 4; also GSL's multifit_nlinear "lmaccel"): after the damped Gauss–Newton step v
  /// ("velocity"), a second-order correction a solves (H + λD)·a = −J̃ᵀ·r̃''_v with the same
  /// factorisation, r̃''_v being the residuals' second directional derivative along v (one
  /// finite difference of the residuals at x ⊞ h·v, acceleration_step = h). The step is
  /// v + a/2 if 2|a|_D / |v|_D ≤ max_acceleration_ratio, else the plain step v (their paper
  /// rejects the iteration instead; measured here, that costs sphere2500 15 instead of 7
  /// iterations and KITTI 00 BA 41 instead of 32, the fallback neither). ρ uses v's quadratic
  /// model; a step that raises the cost is still never accepted. Costs per iteration one
  /// residual-only evaluation at x ⊞ h·v, two small products per block and one more solve; the
  /// Jacobians of the current point are kept for it (Problem::reserve_acceleration: 49 + 8 + 7
  /// doubles per Sim(3) edge, about the memory of H on a pose graph). Pays off where the cost
  /// valley is curved (large corrections along long chains, e.g. the Sim(3) drift graph:
  /// BENCHMARKS.md).
  bool geodesic_acceleration = false;
  double acceleration_step = 0.1;        ///< h of the finite difference (their choice 0.1)
  double max_acceleration_ratio = 0.75;  ///< α: largest accepted 2|a|/|v| (their 0.75)
  /// Backtracking along a rejected step (J. Nocedal, Y. Yuan, "Combining trust region and line
  /// search techniques", in Advances in Nonlinear Programming, Kluwer 1998): when the trial
  /// point x ⊞ δ does not lower the cost, one cost-only evaluation at the shorter step
  /// δ(t) = t·v + (t²/2)·a (the step's own curve: a = 0 without geodesic acceleration) is tried
  /// before a new factorisation, t the minimiser of the quadratic through F(0), F'(0) = gᵀv and
  /// F(1), kept in [0.1, 0.5]. If F(x ⊞ δ(t)) < F(x) that point is accepted and λ grows as after
  /// a rejection (the full step was too long); otherwise the iteration is rejected as without
  /// backtracking. Costs one cost-only evaluation per rejected step and saves a factorisation
  /// and solve where the short step succeeds.
  bool backtracking = false;
  /// Let the linear solver write its factor over H where it can
  /// (LinearSolver::factorize_and_solve_in_place: the block Cholesky when its order has no fill,
  /// chains of keyframes linked to their next few). Saves the factor's memory (137 MB at 50k
  /// Sim(3) keyframes, whose first touch costs 0.2-0.4 s on the project's VMs) and the copy of H
  /// into it; a rejected step then linearises x again to get H back (one linearisation more per
  /// rejection, as after a rejected speculative trial). Same steps up to rounding either way.
  bool in_place_factor = true;
  /// Threads for evaluation and assembly: 1 or 2 (2 splits the residual blocks whose H blocks
  /// fall in disjoint column halves; the rest run on one thread).
  int num_threads = 1;
  /// Print one line per iteration to stdout.
  bool verbose = false;
  /// Debug: before iterating, compare every residual block's analytic Jacobians (functor
  /// output) with central differences (step 1e-6, left retraction); stop with
  /// kJacobianCheckFailed if any element differs by more than jacobian_check_tolerance·(1+|J|).
  bool check_jacobians = false;
  double jacobian_check_tolerance = 1e-5;

  /// @return true if the options are usable; otherwise false and *why names the member.
  bool validate(std::string* why) const {
    std::ostringstream os;
    if (max_iterations < 0)
      os << "max_iterations " << max_iterations << " < 0";
    else if (!(function_tolerance >= 0.0))
      os << "function_tolerance " << function_tolerance << " not >= 0";
    else if (!(gradient_tolerance >= 0.0))
      os << "gradient_tolerance " << gradient_tolerance << " not >= 0";
    else if (!(parameter_tolerance >= 0.0))
      os << "parameter_tolerance " << parameter_tolerance << " not >= 0";
    else if (!(initial_lambda > 0.0) || !std::isfinite(initial_lambda))
      os << "initial_lambda " << initial_lambda << " not finite and > 0";
    else if (!(max_lambda >= initial_lambda))
      os << "max_lambda " << max_lambda << " < initial_lambda " << initial_lambda;
    else if (!(acceleration_step > 0.0) || !std::isfinite(acceleration_step))
      os << "acceleration_step " << acceleration_step << " not finite and > 0";
    else if (!(max_acceleration_ratio > 0.0) || !std::isfinite(max_acceleration_ratio))
      os << "max_acceleration_ratio " << max_acceleration_ratio << " not finite and > 0";
    else if (!(min_lambda >= 0.0) || !(min_lambda <= initial_lambda))
      os << "min_lambda " << min_lambda << " not in [0, initial_lambda " << initial_lambda << "]";
    else if (!(lambda_decrease_limit > 0.0) || !(lambda_decrease_limit < 1.0))
      os << "lambda_decrease_limit " << lambda_decrease_limit << " not in (0, 1)";
    else if (!(min_diagonal > 0.0) || !(max_diagonal >= min_diagonal))
      os << "diagonal clamp [" << min_diagonal << ", " << max_diagonal << "] is not 0 < min <= max";
    else if (num_threads != 1 && num_threads != 2)
      os << "num_threads " << num_threads << " not 1 or 2";
    const std::string msg = os.str();
    if (why) *why = msg;
    return msg.empty();
  }
};

/// Why LM stopped.
enum class Termination {
  kFunctionTolerance,    ///< converged: relative cost decrease ≤ function_tolerance
  kGradientTolerance,    ///< converged: max |g| ≤ gradient_tolerance
  kParameterTolerance,   ///< converged: |δ| ≤ parameter_tolerance·(|x| + parameter_tolerance)
  kZeroCost,             ///< converged: the cost is exactly 0
  kMaxIterations,        ///< iteration limit reached (not converged)
  kNoDecrease,           ///< λ > max_lambda: no step decreases the cost (a local minimum or
                         ///< a failing residual around x)
  kLinearSolverFailure,  ///< the linear solver reported a fatal error
  kNonFiniteResidual,    ///< a residual cannot be evaluated / is NaN at the start
  kNonFiniteJacobian,    ///< a Jacobian is NaN / inf at an accepted point
  kInvalidOptions,       ///< Options::validate failed; nothing was done
  kInvalidProblem,       ///< empty problem or a structure the linear solver cannot handle
  kJacobianCheckFailed,  ///< Options::check_jacobians found a wrong analytic Jacobian
};

inline const char* to_string(Termination t) {
  switch (t) {
    case Termination::kFunctionTolerance:
      return "converged (function tolerance)";
    case Termination::kGradientTolerance:
      return "converged (gradient tolerance)";
    case Termination::kParameterTolerance:
      return "converged (parameter tolerance)";
    case Termination::kZeroCost:
      return "converged (zero cost)";
    case Termination::kMaxIterations:
      return "maximum iterations";
    case Termination::kNoDecrease:
      return "no decrease (lambda too large)";
    case Termination::kLinearSolverFailure:
      return "linear solver failure";
    case Termination::kNonFiniteResidual:
      return "non-finite or unevaluable residual";
    case Termination::kNonFiniteJacobian:
      return "non-finite Jacobian";
    case Termination::kInvalidOptions:
      return "invalid options";
    case Termination::kInvalidProblem:
      return "invalid problem";
    case Termination::kJacobianCheckFailed:
      return "Jacobian check failed";
  }
  return "?";
}

/// State after one LM iteration (Summary::trace).
struct IterationRecord {
  int iteration = 0;       ///< 0 = the start, then 1, 2, ... (linear solves)
  double cost = 0.0;       ///< cost at the current (best accepted) point after the iteration
  bool accepted = false;   ///< whether this iteration's step was accepted
  double lambda = 0.0;     ///< damping used by this iteration's step
  double time_wall = 0.0;  ///< seconds since solve() started (steady clock)
  double time_cpu = 0.0;   ///< process CPU seconds since solve() started (std::clock)
};

/// What happened in one solve.
struct Summary {
  Termination termination = Termination::kInvalidOptions;
  std::string message;  ///< human-readable reason, names the culprit when one exists
  int iterations = 0;   ///< linear solves (accepted + rejected)
  int successful_steps = 0;
  int unsuccessful_steps = 0;
  /// Steps that included the geodesic acceleration (Options::geodesic_acceleration), and
  /// steps taken without it because it was too large relative to the velocity.
  int accelerated_steps = 0;
  int acceleration_fallbacks = 0;
  /// Accepted steps that were shortened by backtracking (Options::backtracking).
  int backtracked_steps = 0;
  double initial_cost = 0.0;  ///< ½Σρ at the start
  double final_cost = 0.0;    ///< ½Σρ at the returned states
  double final_lambda = 0.0;
  int num_parameters = 0;  ///< free tangent columns
  int num_residuals = 0;
  double factor_nnz = 0.0;
  std::string linear_solver;
  /// Residuals + Jacobians + their accumulation H += J̃ᵀJ̃, g += J̃ᵀr̃ (fused per residual block,
  /// see LinearizeTimes), incl. cost-only trial evaluations [s].
  double time_evaluate = 0.0;
  double time_assemble = 0.0;  ///< zeroing H and g before each linearisation [s]
  double time_analyze = 0.0;   ///< symbolic analysis (0 when reused) [s]
  /// True when this solve() reused the symbolic analysis kept by the LevenbergMarquardt object
  /// from an earlier solve() of the same pattern (the same Problem or another one).
  bool analysis_reused = false;
  /// numeric factorisation (incl. Schur elimination) and the step's solve with it
  /// (LinearSolver::factorize_and_solve) [s]
  double time_factorize = 0.0;
  double time_solve = 0.0;      ///< further solves: the geodesic acceleration's [s]
  double time_total = 0.0;      ///< whole solve() [s]
  double time_total_cpu = 0.0;  ///< whole solve(), process CPU time (std::clock) [s]
  /// One record for the start and one per iteration (first iteration reaching a given cost,
  /// convergence profiles). Reserved before the loop for up to 1000 iterations.
  std::vector<IterationRecord> trace;

  /// Converged by one of the tolerance criteria (or zero cost).
  bool converged() const {
    return termination == Termination::kFunctionTolerance ||
           termination == Termination::kGradientTolerance ||
           termination == Termination::kParameterTolerance || termination == Termination::kZeroCost;
  }
  /// One paragraph: termination, iterations, costs, times.
  std::string brief_report() const {
    char buf[512];
    std::snprintf(buf, sizeof buf,
                  "LM (%s): %s after %d iterations (%d accepted); cost %.9g -> %.9g; "
                  "time %.4f s (evaluate %.4f, assemble %.4f, analyze %.4f, factorize %.4f, "
                  "solve %.4f)",
                  linear_solver.c_str(), to_string(termination), iterations, successful_steps,
                  initial_cost, final_cost, time_total, time_evaluate, time_assemble, time_analyze,
                  time_factorize, time_solve);
    std::string s(buf);
    if (!message.empty()) s += ": " + message;
    return s;
  }
};

/// LM over a Problem. Keeps its linear solver (and symbolic analysis) between solve() calls
/// while the problem's pattern is unchanged.
///
/// Reusing the symbolic analysis across repeated solves. The analysis (fill-reducing ordering,
/// CHOLMOD's supernodal symbolic factor or the block Cholesky's column structures, the Schur
/// complement's pattern) belongs to this object, not to the Problem, and is keyed by the block
/// pattern (BlockStructure::pattern(): block sizes, which blocks couple, the number of
/// Schur-eliminated blocks). So a caller that solves many problems of the SAME structure (sliding
/// windows of equal length and connectivity, a user re-solving after new measurements or new
/// start values) keeps ONE LevenbergMarquardt alive and calls solve() on each Problem:
///
///   solver::LevenbergMarquardt lm(options);         // once
///   for (each window) {
///     solver::Problem p;                             // new values, same pattern
///     ... add the same kinds of blocks in the same order, same constant blocks ...
///     const solver::Summary s = lm.solve(&p);        // s.analysis_reused, s.time_analyze == 0
///   }
///
/// The pattern is compared on every solve() (O(number of blocks)); a different pattern is
/// analysed again automatically (and, with kAuto, the solver type chosen again), so reuse is
/// never wrong, only sometimes not possible. Reuse needs an equal block pattern, which holds when
/// the problems have the same parameter blocks (sizes) in the same order of first use
/// (add_residual_block order), the same constant blocks and the same couplings; residual values,
/// weights, losses and states may all differ. Changing Options::linear_solver through
/// set_options() drops the analysis. Tested in tests/solver/solver_problems_test.cpp ("One
/// LevenbergMarquardt reuses its symbolic analysis across problems of the same pattern").
class LevenbergMarquardt {
 public:
  explicit LevenbergMarquardt(Options options = {}) : options_(options) {}
  const Options& options() const { return options_; }
  /// Changing the linear solver type drops the cached analysis.
  void set_options(const Options& o) {
    if (o.linear_solver != options_.linear_solver) solver_.reset();
    options_ = o;
  }

  /// Minimises the problem's cost from the current states, which hold the result on return
  /// (the best accepted point). Never throws for numerical outcomes (see Summary::termination).
  Summary solve(Problem* problem) {
    using Clock = std::chrono::steady_clock;
    const auto t_start = Clock::now();
    const std::clock_t c_start = std::clock();
    Summary sum;
    sum.trace.reserve(static_cast<std::size_t>(std::min(options_.max_iterations, 1000) + 1));
    const auto finish = [&](Termination t, std::string msg) {
      if (options_.geodesic_acceleration && problem->is_finalized())
        problem->reserve_acceleration(false);  // the stores are per solve
      sum.termination = t;
      sum.message = std::move(msg);
      sum.time_total = std::chrono::duration<double>(Clock::now() - t_start).count();
      sum.time_total_cpu = static_cast<double>(std::clock() - c_start) / CLOCKS_PER_SEC;
      return sum;
    };
    const auto record = [&](double cost, bool accepted, double lambda) {
      IterationRecord r;
      r.iteration = sum.iterations;
      r.cost = cost;
      r.accepted = accepted;
      r.lambda = lambda;
      r.time_wall = std::chrono::duration<double>(Clock::now() - t_start).count();
      r.time_cpu = static_cast<double>(std::clock() - c_start) / CLOCKS_PER_SEC;
      sum.trace.push_back(r);
    };
    std::string why;
    if (!options_.validate(&why)) return finish(Termination::kInvalidOptions, why);

    const bool schur = options_.linear_solver == LinearSolverType::kSchur ||
                       options_.linear_solver == LinearSolverType::kSchurDense ||
                       options_.linear_solver == LinearSolverType::kSchurCholmod ||
                       options_.linear_solver == LinearSolverType::kSchurBlockCholesky;
    problem->set_num_threads(options_.num_threads);
    if (!problem->is_finalized() || problem->has_schur_ordering() != schur)
      problem->finalize(schur);
    const BlockStructure& s = problem->structure();
    const int n = s.num_cols();
    sum.num_parameters = n;
    sum.num_residuals = problem->num_residuals();

    // Linear solver + symbolic analysis (reused while the pattern is the same).
    if (options_.linear_solver == LinearSolverType::kAuto && analyzed_ && !s.same_pattern(pattern_))
      solver_.reset();  // kAuto decides again for a new pattern
    if (!solver_) analyzed_ = false;
    sum.analysis_reused = analyzed_ && s.same_pattern(pattern_);
    if (!sum.analysis_reused) {
      const auto t0 = Clock::now();
      LinearSolverStatus st = LinearSolverStatus::kSuccess;
      if (!solver_ && options_.linear_solver == LinearSolverType::kAuto) {
        // kAuto decides on the block Cholesky's own ordering and symbolic factor, kept when
        // the factor is thin (one analysis, not one to decide and one to use).
        auto block = std::make_unique<BlockCholeskySolver>();
        if (block->analyze_if_thin(s, kAutoMaxBlocksPerColumn)) {
          solver_ = std::move(block);
        } else {
          solver_ = std::make_unique<CholmodSolver>();
          st = solver_->analyze(s);
        }
      } else {
        if (!solver_) solver_ = make_solver(options_.linear_solver);
        st = solver_->analyze(s);
      }
      sum.time_analyze = std::chrono::duration<double>(Clock::now() - t0).count();
      if (st != LinearSolverStatus::kSuccess) {
        analyzed_ = false;
        const std::string m = solver_->message();
        const bool structural = options_.linear_solver == LinearSolverType::kBlockCholesky &&
                                BlockCholeskySolver::supported_block_size(s) == 0;
        solver_.reset();
        return finish(structural ? Termination::kInvalidProblem : Termination::kLinearSolverFailure,
                      m);
      }
      pattern_ = s.pattern();
      analyzed_ = true;
    }
    sum.linear_solver = solver_->name();  // after analyze(): kSchur picks its reduced solver there

    // Buffers (sized once).
    H_.reset(&s);
    g_.resize(n);
    g2_.resize(n);  // the speculative trial's g, or x's again after an in-place factor
    diag_.resize(n);
    damp_.resize(n);
    rhs_.resize(n);
    delta_.resize(n);
    // Geodesic acceleration: the problem keeps the J̃ of the point last linearised.
    const bool accel = options_.geodesic_acceleration;
    if (accel) {
      accel_.resize(n);
      problem->reserve_acceleration(true);
    }
    const std::vector<int>& dpos = s.diagonal_positions();

    LinearizeTimes lt;
    EvaluationError err;
    if (options_.check_jacobians &&
        !problem->check_jacobians(options_.jacobian_check_tolerance, 1e-6, &err)) {
      return finish(Termination::kJacobianCheckFailed, err.what);
    }
    double cost = 0.0;
    bool ok = problem->linearize(&H_, g_.data(), &cost, &lt, &err, accel);
    sum.time_evaluate += lt.evaluate;
    sum.time_assemble += lt.assemble;
    if (!ok) {
      sum.initial_cost = sum.final_cost = std::numeric_limits<double>::quiet_NaN();
      return finish(Termination::kNonFiniteResidual, "at the initial point: " + err.what);
    }
    sum.initial_cost = sum.final_cost = cost;
    record(cost, true, 0.0);
    if (!g_.allFinite()) {
      problem->find_non_finite_jacobian(&err);
      return finish(Termination::kNonFiniteJacobian, "at the initial point: " + err.what);
    }
    if (n == 0) return finish(Termination::kGradientTolerance, "no free parameters");

    double lambda = options_.initial_lambda, nu = 2.0;
    // Speculate on the next trial only after an accepted step: the first trial and those after a
    // rejection are evaluated cost-only (Options::speculative_linearization).
    bool relinearized = true, speculate_next = false, speculated = false;
    while (true) {
      if (cost == 0.0) return done(sum, cost, lambda, Termination::kZeroCost, "", finish);
      if (relinearized) {
        const double gmax = g_.lpNorm<Eigen::Infinity>();
        if (gmax <= options_.gradient_tolerance) {
          return done(sum, cost, lambda, Termination::kGradientTolerance, "max |g| = " + num(gmax),
                      finish);
        }
        double* hv = H_.values();
        for (int c = 0; c < n; ++c) {
          const double d = std::max(hv[dpos[c]], 0.0);
          diag_[c] = hv[dpos[c]];
          const double sc = 1.0 / (1.0 + std::sqrt(d));
          damp_[c] =
              std::clamp(sc * sc * d, options_.min_diagonal, options_.max_diagonal) / (sc * sc);
        }
        relinearized = false;
      }
      if (sum.iterations >= options_.max_iterations)
        return done(sum, cost, lambda, Termination::kMaxIterations, "", finish);
      ++sum.iterations;

      // Damped system.
      double* hv = H_.values();
      for (int c = 0; c < n; ++c) hv[dpos[c]] = diag_[c] + lambda * damp_[c];
      // Factorisation and the step v = −(H + λD)⁻¹·g in one call, timed as factorisation (the
      // block Cholesky does the forward substitution inside it; LinearSolver).
      rhs_ = -g_;
      const auto t0 = Clock::now();
      bool h_overwritten = false;  // H_ holds the factor: a rejected step linearises x again
      LinearSolverStatus st = options_.in_place_factor
                                  ? solver_->factorize_and_solve_in_place(
                                        &H_, rhs_.data(), delta_.data(), &h_overwritten)
                                  : solver_->factorize_and_solve(H_, rhs_.data(), delta_.data());
      sum.time_factorize += std::chrono::duration<double>(Clock::now() - t0).count();
      if (st == LinearSolverStatus::kFatal)
        return done(sum, cost, lambda, Termination::kLinearSolverFailure, solver_->message(),
                    finish);
      // x = −(H + λD)⁻¹·b with the current factorisation (timed as a solve): the acceleration.
      const auto solve_neg = [&](const Eigen::VectorXd& b, Eigen::VectorXd* x) {
        const auto ts = Clock::now();
        rhs_ = -b;
        const LinearSolverStatus s2 = solver_->solve(rhs_.data(), x->data());
        sum.time_solve += std::chrono::duration<double>(Clock::now() - ts).count();
        return s2;
      };
      // The cost at x ⊞ delta_, cost-only (timed as evaluation); the states stay there (saved).
      const auto cost_at_step = [&](double* c) {
        problem->save_state();
        problem->plus(delta_.data());
        const auto te = Clock::now();
        const bool ok_c = problem->evaluate_cost(c);
        sum.time_evaluate += std::chrono::duration<double>(Clock::now() - te).count();
        return ok_c;
      };
      bool step_ok = st == LinearSolverStatus::kSuccess && delta_.allFinite();
      // L(0) − L(v) = ½ vᵀ(λDv − g), v the damped Gauss–Newton step (the velocity).
      double model = 0.0, gv = 0.0;
      if (step_ok) {
        for (int c = 0; c < n; ++c) {
          model += delta_[c] * (lambda * damp_[c] * delta_[c] - g_[c]);
          gv += g_[c] * delta_[c];
        }
        model *= 0.5;
      }
      bool accelerated = false;  // delta_ = v + a/2 with a in accel_
      if (step_ok && accel) {
        const auto ta = Clock::now();
        const bool aok =
            problem->acceleration_rhs(delta_.data(), options_.acceleration_step, accel_.data());
        sum.time_evaluate += std::chrono::duration<double>(Clock::now() - ta).count();
        if (aok) {  // otherwise (not evaluable at x ⊞ h·v) the plain step v is tried
          st = solve_neg(accel_, &accel_);
          if (st == LinearSolverStatus::kFatal)
            return done(sum, cost, lambda, Termination::kLinearSolverFailure, solver_->message(),
                        finish);
          if (st == LinearSolverStatus::kSuccess && accel_.allFinite()) {
            double aa = 0.0, vv = 0.0;
            for (int c = 0; c < n; ++c) {
              aa += damp_[c] * accel_[c] * accel_[c];
              vv += damp_[c] * delta_[c] * delta_[c];
            }
            if (4.0 * aa <=
                options_.max_acceleration_ratio * options_.max_acceleration_ratio * vv) {
              delta_ += 0.5 * accel_;
              accelerated = true;
              ++sum.accelerated_steps;
            } else {
              ++sum.acceleration_fallbacks;  // too large to trust: the plain step v
            }
          }
        }
      }
      double new_cost = std::numeric_limits<double>::infinity();
      double rho = -1.0;
      bool backtracked = false;
      if (step_ok) {
        const double dnorm = delta_.norm();
        const double xnorm = problem->state_norm();
        if (dnorm <= options_.parameter_tolerance * (xnorm + options_.parameter_tolerance)) {
          return done(sum, cost, lambda, Termination::kParameterTolerance,
                      "|delta| = " + num(dnorm), finish);
        }
        bool eval_ok;
        speculated = options_.speculative_linearization && speculate_next;
        if (speculated) {
          // Linearise the trial point into H and the spare gradient: its cost decides the step,
          // and if it is accepted H, g are ready (no second evaluation). H (factorised and
          // solved with already) and the acceleration store of x are overwritten; a rejected
          // trial linearises x again (below).
          problem->save_state();
          problem->plus(delta_.data());
          LinearizeTimes lt2;
          eval_ok = problem->linearize(&H_, g2_.data(), &new_cost, &lt2, &err, accel);
          sum.time_evaluate += lt2.evaluate;
          sum.time_assemble += lt2.assemble;
        } else {
          eval_ok = cost_at_step(&new_cost);
        }
        if (eval_ok && std::isfinite(new_cost) && new_cost < cost && model > 0.0) {
          rho = (cost - new_cost) / model;
        } else {
          problem->restore_state();
          rho = -1.0;
          if (options_.backtracking && model > 0.0 && gv < 0.0) {
            // F(t) ≈ F(0) + t·gᵀv + t²·(F(1) − F(0) − gᵀv); a failed or non-finite trial: t = ½.
            double t = 0.5;
            const double curv = eval_ok && std::isfinite(new_cost) ? new_cost - cost - gv : 0.0;
            if (curv > 0.0) t = std::clamp(-gv / (2.0 * curv), 0.1, 0.5);
            // δ(t) = t·v + (t²/2)·a from delta_ = v + a/2.
            delta_ *= t;
            if (accelerated) delta_ += (0.5 * t * t - 0.5 * t) * accel_;
            double bt_cost = std::numeric_limits<double>::infinity();
            const bool bt_ok = cost_at_step(&bt_cost);
            if (options_.verbose)
              std::printf("LM it %3d backtrack t %.3g cost %.12g\n", sum.iterations, t, bt_cost);
            if (bt_ok && std::isfinite(bt_cost) && bt_cost < cost) {
              new_cost = bt_cost;
              backtracked = true;
              speculated = false;  // H, g2_ (if written) belong to the rejected full step
            } else {
              problem->restore_state();
            }
          }
        }
      }
      if (options_.verbose) {
        std::printf("LM it %3d cost %.12g new %.12g rho %.3g lambda %.3g\n", sum.iterations, cost,
                    new_cost, rho, lambda);
      }
      const bool accept = rho > 0.0 || backtracked;
      record(accept ? new_cost : cost, accept, lambda);
      speculate_next = rho > 0.0;  // not after a backtracked step: the full step was too long
      if (accept) {
        ++sum.successful_steps;
        const double old_cost = cost;
        cost = new_cost;
        if (backtracked) {
          ++sum.backtracked_steps;
          lambda *= nu;  // as after a rejection, ν back to 2 as after an acceptance
        } else {
          const double t = 2.0 * rho - 1.0;
          lambda = std::max(options_.min_lambda,
                            lambda * std::max(options_.lambda_decrease_limit, 1.0 - t * t * t));
        }
        nu = 2.0;
        if (old_cost - new_cost <= options_.function_tolerance * old_cost) {
          return done(sum, cost, lambda, Termination::kFunctionTolerance,
                      "relative decrease " + num((old_cost - new_cost) / old_cost), finish);
        }
        if (speculated) {
          g_.swap(g2_);
        } else {
          LinearizeTimes lt2;
          double c2 = 0.0;
          ok = problem->linearize(&H_, g_.data(), &c2, &lt2, &err, accel);
          sum.time_evaluate += lt2.evaluate;
          sum.time_assemble += lt2.assemble;
          if (!ok)  // evaluated fine a moment ago: only a Jacobian-side failure can land here
            return done(sum, cost, lambda, Termination::kNonFiniteResidual, err.what, finish);
        }
        if (!g_.allFinite()) {
          problem->find_non_finite_jacobian(&err);
          return done(sum, cost, lambda, Termination::kNonFiniteJacobian, err.what, finish);
        }
        relinearized = true;
      } else {
        ++sum.unsuccessful_steps;
        lambda *= nu;
        nu *= 2.0;
        if (lambda > options_.max_lambda) {
          return done(sum, cost, lambda, Termination::kNoDecrease,
                      "lambda " + num(lambda) + " > max_lambda; " +
                          (step_ok ? std::string("no step decreases the cost")
                                   : std::string("last step: ") + solver_->message()),
                      finish);
        }
        // H and the acceleration store hold the rejected trial, or H holds the factor: H at x
        // again (the same values as before).
        if (speculated || h_overwritten) {
          LinearizeTimes lt2;
          double c2 = 0.0;
          ok = problem->linearize(&H_, g2_.data(), &c2, &lt2, &err, accel);
          sum.time_evaluate += lt2.evaluate;
          sum.time_assemble += lt2.assemble;
          if (!ok)  // linearised fine before: only a non-deterministic functor can land here
            return done(sum, cost, lambda, Termination::kNonFiniteResidual, err.what, finish);
        }
      }
    }
  }

 private:
  template <typename Finish>
  Summary done(Summary& sum, double cost, double lambda, Termination t, const std::string& msg,
               const Finish& finish) const {
    sum.final_cost = cost;
    sum.final_lambda = lambda;
    sum.factor_nnz = solver_->factor_nnz();
    return finish(t, msg);
  }

  static std::string num(double v) {
    char b[32];
    std::snprintf(b, sizeof b, "%.3g", v);
    return b;
  }

  static std::unique_ptr<LinearSolver> make_solver(LinearSolverType t) {
    switch (t) {
      case LinearSolverType::kCholmod:
        return std::make_unique<CholmodSolver>();
      case LinearSolverType::kSchur:
        return std::make_unique<SchurSolver>(SchurSolver::ReducedSolver::kAuto);
      case LinearSolverType::kSchurCholmod:
        return std::make_unique<SchurSolver>(SchurSolver::ReducedSolver::kCholmod);
      case LinearSolverType::kSchurBlockCholesky:
        return std::make_unique<SchurSolver>(SchurSolver::ReducedSolver::kBlockCholesky);
      case LinearSolverType::kDense:
        return std::make_unique<DenseSolver>();
      case LinearSolverType::kSchurDense:
        return std::make_unique<SchurSolver>(std::make_unique<DenseSolver>());
      case LinearSolverType::kBlockCholesky:
        return std::make_unique<BlockCholeskySolver>();
      case LinearSolverType::kAuto:
        break;
    }
    return std::make_unique<CholmodSolver>();
  }

  Options options_;
  std::unique_ptr<LinearSolver> solver_;
  bool analyzed_ = false;
  BlockStructure::Pattern pattern_;
  BlockSparseMatrix H_;
  Eigen::VectorXd g_, g2_, diag_, damp_, rhs_, delta_, accel_;
};

}  // namespace geodrift::solver
