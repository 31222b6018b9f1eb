// correction_floor: the error floor of ANY correction on the monocular-drift simulator (issue 4).
//
// For a simulated sequence, the MAP estimate of the TRUE keyframe path given
//   (a) the drifted keyframe chain T^M_k (it carries no drift information by itself),
//   (b) the anchors' geo-tag positions (σ = SimOptions::geotag_noise_m), each an EXACT function
//       of its keyframe's true pose (the true keyframe -> right-camera offset, an oracle that a
//       real correction does not have: PnP errors are gone),
//   (c) the simulator's own drift process as the prior (detail::draw_drift / chain_drift, with
//       the calibrated amplitudes β, γ the run actually used): log s_k = g + β·w_k + o_k with
//       w a random walk (σ = rw·√Δd per step), o an Ornstein–Uhlenbeck process (stationary SD,
//       correlation length in metres), and per step a rotation error φ_k ~ N(0, γ²(q_i²Δd +
//       c²θ_k²)) per camera axis, the step's translation direction exact:
//           T^M_{k+1} = T^M_k · [exp(φ_k)·R_rel,k | s_{k+1}·t_rel,k].
// Unknowns per keyframe: the true centre c_k, the map->world rotation R_Q,k (true R_k =
// R_Q,k·R^M_k), o_k, w_k; plus the log-scale offset g. The gauge (c_0, R_Q,0, g) has a flat
// prior. Between keyframes the model is
//   c_{k+1} − c_k = R_Q,k (c^M_{k+1} − c^M_k) e^{−λ_{k+1}}        (exact: re-chained each step)
//   R_Q,k^T R_Q,k+1 = exp(−R^M_k φ_k)                              (φ_k has the prior above)
// so the problem is a sparse nonlinear least-squares problem, solved by Levenberg–Marquardt on
// Eigen's sparse LDLT with central-difference Jacobians (a diagnostic; nothing here is used by
// the library). The drift exists only at keyframes in this simulator (frames between keyframes
// are not simulated), so "every frame" is every keyframe.
//
// The estimate is evaluated as the table's Ours cell: eval::horizontal_errors over ALL
// keyframes in W. Optionally (--ours) the Corrector (Mode::kOurs) runs on the same simulation
// and correspondences, so floor and Ours are paired seed by seed.
//
// usage: correction_floor [--sequences 02,08] [--intervals 100,200,300,400,500] [--seeds N]
//   (seeds 1..N, default 20; the table also reports the mean over the first --report-seeds 5)
//   --ours                 also run the Corrector (Ours) on the same simulation
//   --mode full|nodrift|scale|ou   checks: the drift off (and no noise); rotation drift off in
//                          the simulation and the prior; also the scale random walk off
//   --pnp-offsets [--pnp-sigma]    the PnP-localised keyframe->view offsets instead of the oracle
//                          (optionally weighted by the run's RMS localisation error)
//   --prior-rot true|dist|const, --prior-scale true|rw   mis-specified priors (ablations)
//   --observed-variances   prior variances from the drifted chain, not the true steps/turns
//   --straight             the sequence's speed profile on a straight road (1D check)
//   --sigma-t 1e-4         penalty SD linearising the exact translation constraint [m]
//   --data-dir data/kitti
// See docs/RESULTS.md "Error floor with the true drift model".
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "geodrift/correction/corrector.hpp"
#include "geodrift/correction/replay.hpp"
#include "geodrift/eval/errors.hpp"
#include "geodrift/eval/umeyama.hpp"
#include "geodrift/geo/kitti.hpp"
#include "geodrift/lie/so3.hpp"
#include "geodrift/sim/drift_simulator.hpp"
#include "geodrift/sim/kitti_protocol.hpp"

namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;
using Eigen::VectorXd;
namespace sim = geodrift::sim;
namespace eval = geodrift::eval;

Matrix3d expm(const Vector3d& w) { return geodrift::lie::SO3d::exp(w).matrix(); }
Vector3d logm(const Matrix3d& R) { return geodrift::lie::SO3d(R).log(); }

/// What the estimator is given (everything in the KITTI world frame, metres).
struct Model {
  int n = 0;
  std::vector<Vector3d> d;        ///< c^M_{k+1} − c^M_k (map units), step k
  std::vector<Matrix3d> Rm;       ///< drifted cam -> M rotation of keyframe k
  std::vector<double> sig_o;      ///< o prior: [0] stationary SD, [k] innovation of step k-1
  std::vector<double> a;          ///< OU decay of step k
  std::vector<double> sig_w;      ///< w (λ units) random-walk SD of step k
  std::vector<Vector3d> sig_phi;  ///< φ_k SD per camera axis, step k
  bool rotation_drift = true;     ///< false: one R_Q for all keyframes (no rotation drift)
  bool scale_walk = true;         ///< false: no random walk (w shared, fixed)
  double ou_coef = 1.0;           ///< 0: the OU part is left out of the scale (prior ablations)
  double sigma_t = 1e-4;          ///< penalty SD of the exact translation direction [m]
  struct Anchor {
    int K = 0;
    Vector3d p_off = Vector3d::Zero();  ///< geo-tagged camera centre in K's true camera frame
    /// false: p_off is exact, in metres (the oracle); true: p_off is the PnP-localised view
    /// centre in K's drifted camera frame, in MAP units, turned into metres by K's scale.
    bool map_units = false;
    Vector3d y = Vector3d::Zero();  ///< geo-tag position, KITTI frame
    double sigma = 0.05;
  };
  std::vector<Anchor> anchors;
  int slot_r(int k) const { return rotation_drift ? k : 0; }
  int slot_w(int k) const { return scale_walk ? k : 0; }
  int nr() const { return rotation_drift ? n : 1; }
  int nw() const { return scale_walk ? n : 1; }
  // Parameter layout: c (3n) | θ (3 nr) | o (n) | w (nw) | g.
  int ic(int k) const { return 3 * k; }
  int ith(int k) const { return 3 * n + 3 * slot_r(k); }
  int io(int k) const { return 3 * n + 3 * nr() + k; }
  int iw(int k) const { return 3 * n + 3 * nr() + n + slot_w(k); }
  int ig() const { return 3 * n + 3 * nr() + n + nw(); }
  int dim() const { return ig() + 1; }
};

struct State {
  std::vector<Vector3d> c;
  std::vector<Matrix3d> RQ;  ///< indexed by slot_r
  std::vector<double> o, w;  ///< w indexed by slot_w
  double g = 0;
};

/// One residual block: global parameter indices, residual and Jacobian (filled by evaluate).
struct Block {
  std::vector<int> idx;
  VectorXd r;
  Eigen::MatrixXd J;
};

/// Central-difference Jacobian of f around δ = 0.
void numeric(const std::function<VectorXd(const VectorXd&)>& f, int p, Block* b) {
  b->r = f(VectorXd::Zero(p));
  b->J.resize(b->r.size(), p);
  const double h = 1e-6;
  for (int j = 0; j < p; ++j) {
    VectorXd e = VectorXd::Zero(p);
    e(j) = h;
    b->J.col(j) = (f(e) - f(-e)) / (2 * h);
  }
}

/// Residuals (whitened) and, if `blocks` is given, their Jacobians. Returns the cost Σ r².
/// `cost_parts`: [0] translation penalty, [1] rotation prior, [2] o, [3] w, [4] anchors.
double evaluate(const Model& m, const State& s, std::vector<Block>* blocks,
                std::vector<double>* cost_parts = nullptr) {
  double parts[5] = {0, 0, 0, 0, 0};
  const bool jac = blocks != nullptr;
  if (jac) blocks->clear();
  const auto add = [&](int part, Block&& b) {
    parts[part] += b.r.squaredNorm();
    if (jac) blocks->push_back(std::move(b));
  };
  for (int k = 0; k + 1 < m.n; ++k) {
    // Translation direction (exact in the model): c_{k+1} − c_k = R_Q,k d_k e^{−λ_{k+1}}.
    {
      Block b;
      b.idx = {m.ic(k),  m.ic(k) + 1,  m.ic(k) + 2,  m.ic(k + 1), m.ic(k + 1) + 1, m.ic(k + 1) + 2,
               m.ith(k), m.ith(k) + 1, m.ith(k) + 2, m.io(k + 1), m.iw(k + 1),     m.ig()};
      const Vector3d c0 = s.c[k], c1 = s.c[k + 1];
      const Matrix3d R = s.RQ[m.slot_r(k)];
      const double o1 = s.o[k + 1], w1 = s.w[m.slot_w(k + 1)], g = s.g;
      const Vector3d dk = m.d[k];
      const double st = m.sigma_t;
      const auto f = [&](const VectorXd& x) -> VectorXd {
        const double lam = g + x(11) + w1 + x(10) + m.ou_coef * (o1 + x(9));
        return ((c1 + x.segment<3>(3)) - (c0 + x.segment<3>(0)) -
                expm(x.segment<3>(6)) * R * dk * std::exp(-lam)) /
               st;
      };
      if (jac) {
        numeric(f, 12, &b);
      } else {
        b.r = f(VectorXd::Zero(12));
      }
      add(0, std::move(b));
    }
    // Rotation drift prior: φ_k = −R^M_k^T log(R_Q,k^T R_Q,k+1).
    if (m.rotation_drift) {
      Block b;
      b.idx = {m.ith(k),     m.ith(k) + 1,     m.ith(k) + 2,
               m.ith(k + 1), m.ith(k + 1) + 1, m.ith(k + 1) + 2};
      const Matrix3d Ra = s.RQ[k], Rb = s.RQ[k + 1], Rmk = m.Rm[k];
      const Vector3d sig = m.sig_phi[k];
      const auto f = [&](const VectorXd& x) -> VectorXd {
        const Matrix3d A = expm(x.segment<3>(0)) * Ra, B = expm(x.segment<3>(3)) * Rb;
        const Vector3d phi = -Rmk.transpose() * logm(A.transpose() * B);
        return phi.cwiseQuotient(sig);
      };
      if (jac) {
        numeric(f, 6, &b);
      } else {
        b.r = f(VectorXd::Zero(6));
      }
      add(1, std::move(b));
    }
    // OU: o_{k+1} − a o_k ~ N(0, sd²(1 − a²)).
    {
      Block b;
      b.idx = {m.io(k), m.io(k + 1)};
      b.r.resize(1);
      b.r(0) = (s.o[k + 1] - m.a[k] * s.o[k]) / m.sig_o[k + 1];
      b.J.resize(1, 2);
      b.J << -m.a[k] / m.sig_o[k + 1], 1.0 / m.sig_o[k + 1];
      add(2, std::move(b));
    }
    if (m.scale_walk) {
      Block b;
      b.idx = {m.iw(k), m.iw(k + 1)};
      b.r.resize(1);
      b.r(0) = (s.w[k + 1] - s.w[k]) / m.sig_w[k];
      b.J.resize(1, 2);
      b.J << -1.0 / m.sig_w[k], 1.0 / m.sig_w[k];
      add(3, std::move(b));
    }
  }
  {
    Block b;  // o_0 ~ N(0, sd²)
    b.idx = {m.io(0)};
    b.r.resize(1);
    b.r(0) = s.o[0] / m.sig_o[0];
    b.J.resize(1, 1);
    b.J << 1.0 / m.sig_o[0];
    add(2, std::move(b));
  }
  {
    Block b;  // w_0 = 0 fixes the exact symmetry (g, w) -> (g + ε, w − ε); zero at the optimum
    b.idx = {m.iw(0)};
    b.r.resize(1);
    b.r(0) = s.w[0];
    b.J.resize(1, 1);
    b.J << 1.0;
    add(3, std::move(b));
  }
  for (const auto& an : m.anchors) {
    Block b;
    const int K = an.K;
    b.idx = {m.ic(K),      m.ic(K) + 1, m.ic(K) + 2, m.ith(K), m.ith(K) + 1,
             m.ith(K) + 2, m.io(K),     m.iw(K),     m.ig()};
    const Vector3d cK = s.c[K];
    const Matrix3d R = s.RQ[m.slot_r(K)] * m.Rm[K];
    const double lamK = s.g + s.w[m.slot_w(K)] + m.ou_coef * s.o[K];
    const auto f = [&](const VectorXd& x) -> VectorXd {
      const double to_m = an.map_units ? std::exp(-(lamK + x(8) + x(7) + m.ou_coef * x(6))) : 1.0;
      return ((cK + x.segment<3>(0)) + expm(x.segment<3>(3)) * R * an.p_off * to_m - an.y) /
             an.sigma;
    };
    if (jac) {
      numeric(f, 9, &b);
    } else {
      b.r = f(VectorXd::Zero(9));
    }
    add(4, std::move(b));
  }
  if (cost_parts) cost_parts->assign(parts, parts + 5);
  return parts[0] + parts[1] + parts[2] + parts[3] + parts[4];
}

State retract(const Model& m, const State& s, const VectorXd& dx) {
  State t = s;
  for (int k = 0; k < m.n; ++k) t.c[k] += dx.segment<3>(m.ic(k));
  for (int k = 0; k < m.nr(); ++k) t.RQ[k] = expm(dx.segment<3>(m.ith(k))) * s.RQ[k];
  for (int k = 0; k < m.n; ++k) t.o[k] += dx(m.io(k));
  for (int k = 0; k < m.nw(); ++k) t.w[k] += dx(m.iw(k));
  t.g += dx(m.ig());
  // Back onto the constraint manifold: the exact translation directions chain the centres from
  // c_0, so the step is Gauss–Newton in the reduced coordinates (c_0, R_Q, o, w, g); the penalty
  // σ_t only linearises the constraint in the normal equations.
  for (int k = 0; k + 1 < m.n; ++k)
    t.c[k + 1] = t.c[k] + t.RQ[m.slot_r(k)] * m.d[k] *
                              std::exp(-(t.g + t.w[m.slot_w(k + 1)] + m.ou_coef * t.o[k + 1]));
  return t;
}

struct SolveReport {
  double cost = 0;
  int iterations = 0;
  bool converged = false;
};

/// Levenberg–Marquardt (Marquardt scaling) on the sparse normal equations.
SolveReport solve(const Model& m, State* s) {
  SolveReport rep;
  std::vector<Block> blocks;
  double cost = evaluate(m, *s, &blocks);
  double mu = 0.0;  // start as Gauss–Newton
  const int N = m.dim();
  for (int it = 0; it < 100; ++it) {
    rep.iterations = it + 1;
    std::vector<Eigen::Triplet<double>> trip;
    VectorXd b = VectorXd::Zero(N);
    for (const auto& bl : blocks) {
      const Eigen::MatrixXd JtJ = bl.J.transpose() * bl.J;
      const VectorXd Jtr = bl.J.transpose() * bl.r;
      const int p = static_cast<int>(bl.idx.size());
      for (int i = 0; i < p; ++i) {
        b(bl.idx[i]) += Jtr(i);
        for (int j = 0; j < p; ++j)
          if (JtJ(i, j) != 0.0) trip.emplace_back(bl.idx[i], bl.idx[j], JtJ(i, j));
      }
    }
    Eigen::SparseMatrix<double> H(N, N);
    H.setFromTriplets(trip.begin(), trip.end());
    const VectorXd diag = H.diagonal();
    bool accepted = false;
    for (int tries = 0; tries < 20 && !accepted; ++tries) {
      Eigen::SparseMatrix<double> A = H;
      if (mu > 0)
        for (int i = 0; i < N; ++i) A.coeffRef(i, i) += mu * std::max(diag(i), 1e-12);
      Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(A);
      if (ldlt.info() != Eigen::Success) {
        mu = mu > 0 ? mu * 10 : 1e-6;
        continue;
      }
      const VectorXd dx = -ldlt.solve(b);
      const State t = retract(m, *s, dx);
      const double c = evaluate(m, t, nullptr);
      if (std::isfinite(c) && c <= cost) {
        const double rel = (cost - c) / std::max(cost, 1e-300);
        *s = t;
        cost = evaluate(m, *s, &blocks);
        accepted = true;
        mu = mu > 0 ? mu / 10 : 0.0;
        if (mu < 1e-9) mu = 0.0;
        if (rel < 1e-12 || dx.lpNorm<Eigen::Infinity>() < 1e-10) {
          rep.converged = true;
          rep.cost = cost;
          return rep;
        }
      } else {
        mu = mu > 0 ? mu * 10 : 1e-6;
      }
    }
    if (!accepted) {  // no decrease possible: at the minimum to rounding
      rep.converged = true;
      break;
    }
  }
  rep.cost = cost;
  return rep;
}

/// Which variant of the model (sanity checks) is simulated and assumed.
enum class Variant { kFull, kNoDrift, kScaleOnly, kOuOnly };

/// --prior-rot true|dist|const: rotation-drift SD per step as simulated, or the same total
/// variance spread by distance / evenly over keyframe steps (no turn weighting).
/// --prior-scale true|rw: the log-scale as simulated (random walk + OU), or a pure random walk
/// with the same one-step variance (no correlation of the fluctuation).
struct PriorAblation {
  std::string rot = "true";
  std::string scale = "true";
};

struct Run {
  std::vector<double> floor_err;  ///< per interval
  std::vector<double> ours_err;   ///< per interval (NaN without --ours)
  std::vector<double> cost, cost_truth, expected_min, expected_truth;
  std::vector<int> iters;
  double beta = 0, gamma = 0;
  double max_trans_truth = 0;  ///< max |translation residual| at the true state [σ_t]
  double max_rot_truth = 0;    ///< max |φ(true) − γδω| [rad]
};

Run run_one(const sim::KittiSequence& seq, const std::string& name, unsigned seed,
            const std::vector<int>& intervals, Variant variant, double sigma_t, bool ours,
            const PriorAblation& prior, bool pnp_offsets, bool pnp_sigma, bool observed_variances) {
  Run out;
  // The simulation exactly as `geodrift experiment` makes it (or a sanity-check variant).
  const sim::SimOptions kitti = sim::SimOptions::kitti(name, seed);
  sim::SimulatedSequence s = sim::simulate(seq, kitti);
  const double beta_cal = s.scale_drift_amplitude, gamma_cal = s.rotation_drift_amplitude;
  if (variant != Variant::kFull) {
    sim::SimOptions o = kitti;
    if (variant == Variant::kNoDrift) {
      o = sim::SimOptions::noise_free(seed);
    } else {
      // Same draws (draw_drift consumes the same stream whatever the amplitudes), rotation
      // drift off, the calibrated scale-walk amplitude folded into the parameter (β = 1).
      o.drift.rotation_random_walk.setZero();
      o.drift.turn_rotation_error = 0.0;
      o.drift.target_global_sim3_error_m = 0.0;
      o.drift.target_window_scale_sd = 0.0;
      o.drift.scale_random_walk =
          variant == Variant::kOuOnly ? 0.0 : beta_cal * kitti.drift.scale_random_walk;
    }
    s = sim::simulate(seq, o);
  }
  const sim::DriftParams& P = kitti.drift;  // the prior: the calibrated default process
  const double beta = variant == Variant::kFull || variant == Variant::kNoDrift
                          ? beta_cal
                          : (variant == Variant::kScaleOnly ? beta_cal : 0.0);
  const double gamma =
      variant == Variant::kScaleOnly || variant == Variant::kOuOnly ? 0.0 : gamma_cal;
  out.beta = beta;
  out.gamma = gamma;

  const int n = static_cast<int>(s.map.keyframes.size());
  const auto& T = s.gt_T_K_c;
  Model m;
  m.n = n;
  m.sigma_t = sigma_t;
  m.rotation_drift = gamma > 0;
  m.scale_walk = beta > 0;
  std::vector<Vector3d> cm(n);
  m.Rm.resize(n);
  for (int k = 0; k < n; ++k) {
    const auto Twc = s.map.keyframes[k].T_cw.inverse();
    cm[k] = Twc.translation();
    m.Rm[k] = Twc.rotation().matrix();
  }
  m.d.resize(n);
  m.a.assign(n, 0.0);
  m.sig_o.assign(n, P.scale_fluctuation_sd);
  m.sig_w.assign(n, 1.0);
  m.sig_phi.assign(n, Vector3d::Ones());
  double len_true = 0, len_map = 0;
  for (int k = 0; k + 1 < n; ++k) {
    len_true += (T[k + 1].translation() - T[k].translation()).norm();
    len_map += (cm[k + 1] - cm[k]).norm();
  }
  for (int k = 0; k + 1 < n; ++k) {
    m.d[k] = cm[k + 1] - cm[k];
    // Step length and turn of the TRUE path (the process' variances; the estimator is not
    // given them as measurements), or (--observed-variances) of the drifted chain, its length
    // scaled by one global ratio.
    double dd = (T[k + 1].translation() - T[k].translation()).norm();
    double turn = Eigen::AngleAxisd(T[k].linear().transpose() * T[k + 1].linear()).angle();
    if (observed_variances) {
      dd = m.d[k].norm() * len_true / len_map;
      turn = Eigen::AngleAxisd(m.Rm[k].transpose() * m.Rm[k + 1]).angle();
    }
    m.a[k] = std::exp(-dd / P.scale_fluctuation_length_m);
    m.sig_o[k + 1] = P.scale_fluctuation_sd * std::sqrt(1.0 - m.a[k] * m.a[k]);
    m.sig_w[k] = beta * P.scale_random_walk * std::sqrt(dd);
    for (int i = 0; i < 3; ++i)
      m.sig_phi[k](i) =
          gamma * std::sqrt(P.rotation_random_walk(i) * P.rotation_random_walk(i) * dd +
                            P.turn_rotation_error * P.turn_rotation_error * turn * turn);
  }
  // Prior ablations (a mis-specified prior, the simulation unchanged): what the Bayes estimator
  // gains from each part of the true model. The total prior variance over the path is kept.
  if (prior.rot != "true" && m.rotation_drift) {
    Vector3d total = Vector3d::Zero();
    double dist = 0;
    for (int k = 0; k + 1 < n; ++k) {
      total += m.sig_phi[k].cwiseAbs2();
      dist += (T[k + 1].translation() - T[k].translation()).norm();
    }
    for (int k = 0; k + 1 < n; ++k) {
      const double dd = (T[k + 1].translation() - T[k].translation()).norm();
      const double share = prior.rot == "dist" ? dd / dist : 1.0 / (n - 1);
      m.sig_phi[k] = (total * share).cwiseSqrt();
    }
  }
  if (prior.scale == "rw") {  // λ a pure random walk with the true one-step variance of Δλ
    m.scale_walk = true;
    m.ou_coef = 0.0;
    for (int k = 0; k + 1 < n; ++k) {
      const double dd = (T[k + 1].translation() - T[k].translation()).norm();
      m.sig_w[k] =
          std::sqrt(beta * beta * P.scale_random_walk * P.scale_random_walk * dd +
                    2.0 * P.scale_fluctuation_sd * P.scale_fluctuation_sd * (1.0 - m.a[k]));
    }
  }
  const Matrix3d R_WK = geodrift::geo::kitti_to_world_rotation();
  const auto truth_state = [&]() {
    const sim::detail::DriftDraws dr = sim::detail::draw_drift(T, s.options.drift, s.options.seed);
    State t;
    t.c.resize(n);
    t.RQ.resize(m.nr());
    t.o.assign(n, 0.0);
    t.w.assign(m.nw(), 0.0);
    for (int k = 0; k < n; ++k) {
      t.c[k] = T[k].translation();
      if (k < m.nr()) t.RQ[k] = T[k].linear() * m.Rm[k].transpose();
      t.o[k] = dr.ou[k];
      if (k < m.nw()) t.w[k] = s.scale_drift_amplitude * dr.rw[k];
    }
    t.g = std::log(s.options.drift.initial_map_scale);
    // Rotation check: the drift φ_k recovered from the true state vs the simulator's γδω_k.
    for (int k = 0; k + 1 < n && m.rotation_drift; ++k) {
      const Vector3d phi = -m.Rm[k].transpose() * logm(t.RQ[k].transpose() * t.RQ[k + 1]);
      out.max_rot_truth =
          std::max(out.max_rot_truth, (phi - s.rotation_drift_amplitude * dr.domega[k]).norm());
    }
    return t;
  };

  for (int interval : intervals) {
    std::vector<sim::GeoView> views;
    const auto corr = sim::kitti_correspondences(s, interval, &views);
    // --pnp-offsets with --pnp-sigma: the geo-tag SD widened by the RMS localisation error of
    // this run's views (one weight for all views: a calibration of the weight, not per view).
    double loc_rms = 0;
    {
      int cnt = 0;
      for (const auto& v : views)
        if (v.localized) {
          loc_rms += v.position_error_m * v.position_error_m;
          ++cnt;
        }
      loc_rms = cnt ? std::sqrt(loc_rms / cnt) : 0.0;
    }
    m.anchors.clear();
    for (const auto& c : corr) {
      Model::Anchor an;
      an.K = c.keyframe;
      const int f = c.geotag_id;  // the frame of the geo-tagged (right-camera) image
      Eigen::Isometry3d T_K_r = s.sequence.T_K_c[f];
      T_K_r.translation() += T_K_r.linear().col(0) * s.sequence.baseline_m;
      an.p_off = T[an.K].inverse() * T_K_r.translation();
      if (pnp_offsets) {  // what a real correction has: the view localised in the drifted map
        an.map_units = true;
        an.p_off = c.T_vk.inverse().translation();  // view centre in K's camera frame, map units
      }
      an.y = R_WK.transpose() * c.y_w;
      an.sigma = c.sigma_m;
      if (pnp_offsets && pnp_sigma) an.sigma = std::hypot(c.sigma_m, loc_rms);
      if (s.options.geotag_noise_m == 0.0) an.sigma = 0.05;  // noise-free check: any weight
      m.anchors.push_back(an);
    }
    // Start: the drifted chain under the Sim(3) that best fits the anchors, no drift.
    std::vector<Vector3d> src, dst;
    for (const auto& an : m.anchors) {
      src.push_back(cm[an.K]);
      dst.push_back(an.y);
    }
    const eval::Alignment al = eval::umeyama(src, dst);
    State st;
    st.c.resize(n);
    for (int k = 0; k < n; ++k) st.c[k] = al.apply(cm[k]);
    st.RQ.assign(m.nr(), al.R);
    st.o.assign(n, 0.0);
    st.w.assign(m.nw(), 0.0);
    st.g = -std::log(al.s);
    const SolveReport rep = solve(m, &st);
    std::vector<Vector3d> est(n);
    for (int k = 0; k < n; ++k) est[k] = R_WK * st.c[k];
    out.floor_err.push_back(eval::horizontal_errors(est, s.gt_center_w).all.mean);
    out.cost.push_back(rep.cost);
    out.iters.push_back(rep.iterations);
    // χ²: at the true state the cost ~ χ²(stochastic residuals); at the MAP optimum ~ χ²(3A − 7)
    // (linear-Gaussian: free dof = 5n+3 after the exact constraints and the w_0 gauge).
    const int A = static_cast<int>(m.anchors.size());
    const int stochastic =
        n /*o*/ + (m.scale_walk ? n - 1 : 0) + (m.rotation_drift ? 3 * (n - 1) : 0) + 3 * A;
    const int free_dof = 3 * m.nr() + n + (m.scale_walk ? n - 1 : 0) + 1 /*g*/ + 3 /*c_0*/;
    out.expected_truth.push_back(stochastic);
    out.expected_min.push_back(stochastic - free_dof);
    {
      const State t = truth_state();
      std::vector<double> parts;
      out.cost_truth.push_back(evaluate(m, t, nullptr, &parts));
      out.max_trans_truth = std::max(out.max_trans_truth, std::sqrt(parts[0]));
    }
    double ours_err = NAN;
    if (ours) {
      geodrift::correction::CorrectorOptions opt;
      opt.mode = geodrift::correction::Mode::kOurs;
      geodrift::correction::Corrector c(opt);
      geodrift::correction::replay(s.map, corr, &c);
      if (c.initialized()) {
        std::vector<Vector3d> e;
        for (int i = 0; i < c.num_keyframes(); ++i) e.push_back(c.keyframe_center_w(i));
        ours_err = eval::horizontal_errors(e, s.gt_center_w).all.mean;
      }
    }
    out.ours_err.push_back(ours_err);
  }
  return out;
}

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> v;
  std::stringstream ss(s);
  std::string t;
  while (std::getline(ss, t, ',')) v.push_back(t);
  return v;
}

double mean(const std::vector<double>& v, std::size_t count) {
  double s = 0;
  std::size_t k = 0;
  for (std::size_t i = 0; i < v.size() && i < count; ++i, ++k) s += v[i];
  return k ? s / static_cast<double>(k) : NAN;
}
double sdev(const std::vector<double>& v) {
  if (v.size() < 2) return 0;
  const double mu = mean(v, v.size());
  double s = 0;
  for (double x : v) s += (x - mu) * (x - mu);
  return std::sqrt(s / static_cast<double>(v.size() - 1));
}

}  // namespace

int main(int argc, char** argv) {
  std::map<std::string, std::string> a{{"sequences", "02,08"},
                                       {"intervals", "100,200,300,400,500"},
                                       {"seeds", "20"},
                                       {"report-seeds", "5"},
                                       {"mode", "full"},
                                       {"sigma-t", "1e-4"},
                                       {"data-dir", "data/kitti"},
                                       {"prior-rot", "true"},
                                       {"prior-scale", "true"}};
  bool ours = false, pnp_offsets = false, pnp_sigma = false, straight = false;
  bool observed_variances = false;
  for (int i = 1; i < argc; ++i) {
    const std::string k = argv[i];
    if (k == "--ours") {
      ours = true;
    } else if (k == "--pnp-offsets") {
      pnp_offsets = true;
    } else if (k == "--pnp-sigma") {
      pnp_sigma = true;
    } else if (k == "--observed-variances") {
      observed_variances = true;
    } else if (k == "--straight") {
      straight = true;
    } else if (k.rfind("--", 0) == 0 && i + 1 < argc && a.count(k.substr(2))) {
      a[k.substr(2)] = argv[++i];
    } else {
      std::fprintf(stderr,
                   "usage: correction_floor [--sequences 02,08] [--intervals 100,...] "
                   "[--seeds N (1..N)] [--report-seeds 5] [--ours] [--pnp-offsets [--pnp-sigma]] "
                   "[--observed-variances] [--straight] [--mode "
                   "full|nodrift|scale|ou] [--prior-rot true|dist|const] [--prior-scale "
                   "true|rw] [--sigma-t 1e-4] [--data-dir data/kitti]\n");
      return 2;
    }
  }
  const std::map<std::string, Variant> modes{{"full", Variant::kFull},
                                             {"nodrift", Variant::kNoDrift},
                                             {"scale", Variant::kScaleOnly},
                                             {"ou", Variant::kOuOnly}};
  if (!modes.count(a["mode"])) {
    std::fprintf(stderr, "correction_floor: --mode %s is not full, nodrift, scale or ou\n",
                 a["mode"].c_str());
    return 2;
  }
  const Variant variant = modes.at(a["mode"]);
  PriorAblation prior;
  prior.rot = a["prior-rot"];
  prior.scale = a["prior-scale"];
  if ((prior.rot != "true" && prior.rot != "dist" && prior.rot != "const") ||
      (prior.scale != "true" && prior.scale != "rw")) {
    std::fprintf(stderr, "correction_floor: --prior-rot true|dist|const, --prior-scale true|rw\n");
    return 2;
  }
  std::vector<int> intervals;
  for (const auto& t : split(a["intervals"])) intervals.push_back(std::stoi(t));
  const int nseeds = std::stoi(a["seeds"]);
  const std::size_t report = static_cast<std::size_t>(std::stoi(a["report-seeds"]));
  const double sigma_t = std::stod(a["sigma-t"]);
  const auto t0 = std::chrono::steady_clock::now();
  std::printf(
      "correction_floor: mode %s, prior rotation %s, prior scale %s, seeds 1..%d, "
      "sigma_t %g m%s%s%s\n",
      a["mode"].c_str(), prior.rot.c_str(), prior.scale.c_str(), nseeds, sigma_t,
      ours ? ", with Ours" : "", pnp_offsets ? ", PnP keyframe->view offsets (not the oracle)" : "",
      straight ? ", STRAIGHT path with the sequence's speed profile" : "");
  struct Row {
    std::string seq;
    int interval;
    std::vector<double> floor, ours;
  };
  std::vector<Row> rows;
  for (const auto& name : split(a["sequences"])) {
    const std::string dir = a["data-dir"];
    const std::string calib = dir + (name == "02" ? "/calib_seq00-02.txt" : "/calib_seq04-12.txt");
    sim::KittiSequence seq = sim::load_kitti_sequence(dir + "/poses/" + name + ".txt", calib,
                                                      dir + "/times/" + name + ".txt");
    if (straight) {
      // The same speed profile on a straight road (a 2 m, 1 km height undulation keeps the
      // anchors off one line, so the gauge stays observable): the 1D case of round 4's estimate.
      double arc = 0;
      std::vector<Eigen::Isometry3d> T(seq.T_K_c.size(), Eigen::Isometry3d::Identity());
      for (std::size_t f = 0; f < T.size(); ++f) {
        if (f > 0) arc += (seq.T_K_c[f].translation() - seq.T_K_c[f - 1].translation()).norm();
        T[f].translation() = Vector3d(0.0, 2.0 * std::sin(2.0 * M_PI * arc / 1000.0), arc);
      }
      seq.T_K_c = T;
    }
    std::vector<Row> r(intervals.size());
    for (std::size_t i = 0; i < intervals.size(); ++i) r[i] = {name, intervals[i], {}, {}};
    for (int seed = 1; seed <= nseeds; ++seed) {
      const Run run = run_one(seq, name, static_cast<unsigned>(seed), intervals, variant, sigma_t,
                              ours, prior, pnp_offsets, pnp_sigma, observed_variances);
      for (std::size_t i = 0; i < intervals.size(); ++i) {
        r[i].floor.push_back(run.floor_err[i]);
        r[i].ours.push_back(run.ours_err[i]);
        std::printf(
            "  %s seed %2d @%d: floor %.3g m, Ours %.3f m | beta %.3f gamma %.3f | cost %.1f "
            "(E %.0f) at truth %.1f (E %.0f) | %d it | truth check: trans %.2e, rot %.2e\n",
            name.c_str(), seed, intervals[i], run.floor_err[i], run.ours_err[i], run.beta,
            run.gamma, run.cost[i], run.expected_min[i], run.cost_truth[i], run.expected_truth[i],
            run.iters[i], run.max_trans_truth, run.max_rot_truth);
      }
      std::fflush(stdout);
    }
    rows.insert(rows.end(), r.begin(), r.end());
  }
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf(
      "\n| seq | interval | floor, seeds 1-%zu | floor, seeds 1-%d (mean ± sd) |%s paper |\n",
      report, nseeds, ours ? " Ours, seeds 1-5 | Ours, all seeds | Ours − floor (paired) |" : "");
  std::printf("|---|---|---|---|%s---|\n", ours ? "---|---|---|" : "");
  for (const auto& r : rows) {
    const auto paper = sim::paper_ours_2d_error_m(r.seq);
    const int col = (r.interval / 100) - 1;
    const double p = r.interval % 100 == 0 && col >= 0 && col < static_cast<int>(paper.size())
                         ? paper[col]
                         : NAN;
    std::printf("| %s | %d | %.2f | %.2f ± %.2f |", r.seq.c_str(), r.interval,
                mean(r.floor, report), mean(r.floor, r.floor.size()), sdev(r.floor));
    if (ours) {
      std::vector<double> diff;
      for (std::size_t i = 0; i < r.floor.size(); ++i) diff.push_back(r.ours[i] - r.floor[i]);
      std::printf(" %.2f | %.2f ± %.2f | %+.2f ± %.2f |", mean(r.ours, report),
                  mean(r.ours, r.ours.size()), sdev(r.ours), mean(diff, diff.size()), sdev(diff));
    }
    std::printf(" %.2f |\n", p);
  }
  std::printf("\nwall time %.1f s\n", wall);
  return 0;
}
