#pragma once

/// @file
/// Problem: a nonlinear least-squares problem  min ½ Σ_k ρ_k(|W_k·r_k(x)|²)  over parameter
/// blocks on manifolds. It owns the residual blocks; the caller owns the states.
///
/// @code
///   solver::Problem problem;
///   // states: std::vector<lie::Sim3d> S (world→camera); dS_ij frozen from the start poses
///   problem.add_residual_block(RelativePoseResidual<lie::Sim3d>{dS_ij}, RobustLoss(),
///                              1e5 /* information λ */, &S[i], &S[j]);
///   problem.set_constant(&S[0]);                                  // fix the gauge
///   solver::LevenbergMarquardt lm(options);
///   const solver::Summary summary = lm.solve(&problem);           // finalizes if needed
/// @endcode
///
/// Parameters are passed as pointers: `T*` for a type with Manifold<T> (Eigen::Vector3d,
/// lie::SE3d, ...), or `solver::euclidean<N>(double*)` for a raw array of N doubles. The
/// state must stay at the same address while the Problem refers to it.
///
/// Weights (the square-root weight W applied to r before the loss):
///   - `double lambda`: scalar information, W = √λ (cost ½λ|r|² with the trivial loss);
///   - `Eigen::Matrix<double, N, N> information`: W = Lᵀ with Λ = L·Lᵀ (cost ½ rᵀΛr);
///   - `SqrtInformation<N>{W}`: W given directly.
///
/// Rows of the full Jacobian (evaluate_jacobian) follow the order residual blocks were added;
/// columns follow ParameterBlock::col (insertion order of free blocks; with the Schur ordering,
/// the eliminable R^3 blocks come last).

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <limits>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <tuple>
#include <type_traits>
#include <typeindex>
#include <typeinfo>
#include <unordered_map>
#include <utility>
#include <vector>

#include "geodrift/error.hpp"
#include "geodrift/solver/block_sparse_matrix.hpp"
#include "geodrift/solver/block_structure.hpp"
#include "geodrift/solver/large_array_allocator.hpp"
#include "geodrift/solver/loss.hpp"
#include "geodrift/solver/manifold.hpp"
#include "geodrift/solver/parameter_block.hpp"
#include "geodrift/solver/residual_block.hpp"

namespace geodrift::solver {

/// A square-root information matrix W (r is weighted as W·r), given directly.
template <int N>
struct SqrtInformation {
  Eigen::Matrix<double, N, N> matrix;
};

/// Where and why an evaluation failed.
struct EvaluationError {
  int residual_id = -1;  ///< insertion order of the failing residual block
  std::string what;      ///< e.g. "residual block 12 (RelativePoseResidual) returned false"
};

/// Time split of one linearisation (seconds).
/// Evaluation and accumulation are fused (each residual block's J̃ᵀJ̃ and J̃ᵀr̃ are added to H and
/// g right after its evaluation, no Jacobian storage), so `evaluate` covers both; `assemble` is
/// the rest of the assembly: zeroing H and g before the pass.
struct LinearizeTimes {
  double evaluate = 0.0;  ///< residuals + Jacobians (+ weights, loss) + H += J̃ᵀJ̃, g += J̃ᵀr̃
  double assemble = 0.0;  ///< zeroing H and g
};

namespace detail {

template <typename Ptr>
struct ParamOf;
template <typename T>
struct ParamOf<T*> {
  using type = T;
  static T* state(T* p) { return p; }
};
template <int N>
struct ParamOf<EuclideanPtr<N>> {
  using type = Euclidean<N>;
  static double* state(EuclideanPtr<N> p) { return p.ptr; }
};

/// Type-erased group of parameter blocks of one manifold type (one virtual call per group and
/// iteration for plus / save / restore).
class ParameterGroupBase {
 public:
  virtual ~ParameterGroupBase() = default;
  virtual void add(int block) = 0;
  virtual void plus(const std::vector<ParameterBlock>& blocks, const double* delta) = 0;
  virtual void save(const std::vector<ParameterBlock>& blocks) = 0;
  virtual void restore(const std::vector<ParameterBlock>& blocks) = 0;
  virtual double ambient_squared_norm(const std::vector<ParameterBlock>& blocks) const = 0;
};

template <typename P>
class ParameterGroup final : public ParameterGroupBase {
 public:
  using M = Manifold<P>;
  using State = typename M::State;
  void add(int block) override {
    blocks_.push_back(block);
    backup_.emplace_back();
  }
  void plus(const std::vector<ParameterBlock>& blocks, const double* delta) override {
    for (int b : blocks_) {
      const ParameterBlock& pb = blocks[b];
      if (pb.col >= 0) M::plus_in_place(static_cast<State*>(pb.state), delta + pb.col);
    }
  }
  void save(const std::vector<ParameterBlock>& blocks) override {
    for (std::size_t k = 0; k < blocks_.size(); ++k) {
      const ParameterBlock& pb = blocks[blocks_[k]];
      if (pb.col >= 0) M::save(static_cast<const State*>(pb.state), &backup_[k]);
    }
  }
  void restore(const std::vector<ParameterBlock>& blocks) override {
    for (std::size_t k = 0; k < blocks_.size(); ++k) {
      const ParameterBlock& pb = blocks[blocks_[k]];
      if (pb.col >= 0) M::restore(backup_[k], static_cast<State*>(pb.state));
    }
  }
  double ambient_squared_norm(const std::vector<ParameterBlock>& blocks) const override {
    double s = 0.0;
    for (int b : blocks_) {
      const ParameterBlock& pb = blocks[b];
      if (pb.col >= 0) s += M::ambient_squared_norm(*static_cast<const State*>(pb.state));
    }
    return s;
  }

 private:
  std::vector<int> blocks_;
  std::vector<typename M::Storage> backup_;
};

/// One persistent background thread for the 2-thread evaluation (no thread creation or
/// allocation per iteration). run() hands it a function pointer + context; wait() joins.
class Worker {
 public:
  Worker() : thread_([this] { loop(); }) {}
  ~Worker() {
    {
      std::lock_guard<std::mutex> lk(m_);
      stop_ = true;
    }
    cv_.notify_all();
    thread_.join();
  }
  Worker(const Worker&) = delete;
  Worker& operator=(const Worker&) = delete;

  void run(void (*fn)(void*), void* ctx) {
    {
      std::lock_guard<std::mutex> lk(m_);
      fn_ = fn;
      ctx_ = ctx;
      pending_ = true;
    }
    cv_.notify_all();
  }
  void wait() {
    std::unique_lock<std::mutex> lk(m_);
    done_cv_.wait(lk, [this] { return !pending_; });
  }

 private:
  void loop() {
    std::unique_lock<std::mutex> lk(m_);
    while (true) {
      cv_.wait(lk, [this] { return pending_ || stop_; });
      if (pending_) {
        void (*fn)(void*) = fn_;
        void* ctx = ctx_;
        lk.unlock();
        fn(ctx);
        lk.lock();
        pending_ = false;
        done_cv_.notify_all();
      } else if (stop_) {
        return;
      }
    }
  }

  std::mutex m_;
  std::condition_variable cv_, done_cv_;
  void (*fn_)(void*) = nullptr;
  void* ctx_ = nullptr;
  bool pending_ = false;
  bool stop_ = false;
  std::thread thread_;
};

/// Type-erased container of residual blocks of one type (one virtual call per container).
class ResidualContainerBase {
 public:
  virtual ~ResidualContainerBase() = default;
  virtual int size() const = 0;
  virtual int num_residuals() const = 0;  ///< rows per block
  virtual const char* functor_name() const = 0;
  /// Parameter block ids of residual k (into Problem's block list).
  virtual void parameter_ids(int k, std::vector<int>* ids) const = 0;
  virtual int id(int k) const = 0;
  /// Records columns and H offsets (after the structure is built).
  virtual void finalize(const std::vector<ParameterBlock>& blocks, const BlockStructure& s) = 0;
  /// Cost-only evaluation of the blocks idx[0..count) (idx null: blocks 0..count-1); false +
  /// *failed = k on the first failure.
  virtual bool cost(const int* idx, int count, double* cost, int* failed) const = 0;
  /// Evaluates and accumulates the blocks listed in idx[0..count) into H, g. Thread-safe for
  /// disjoint lists whose H/g entries do not overlap (scratch is on the caller's stack).
  virtual bool linearize(const int* idx, int count, double* H, double* g, double* cost, int* failed,
                         LinearizeTimes* times) const = 0;
  /// For blocks idx[0..count) in linearize() order: each H block whose offset is not yet marked
  /// in *written is assigned (not added) by this residual, and marked.
  virtual void mark_first_writes(const int* idx, int count, std::vector<bool>* written) = 0;
  /// Smallest and largest H block index of residual k's free parameters (-1, -1 if none).
  virtual void block_range(int k, const std::vector<ParameterBlock>& pbs, int* lo,
                           int* hi) const = 0;
  /// Per-thread work lists (Problem::finalize): [0] thread 0, [1] thread 1, [2] shared (run
  /// after both, on the calling thread). The same lists serve 1 and 2 threads.
  std::vector<int> part[3];
  /// Writes the weighted, corrected residual and Jacobian rows of block k (tests).
  virtual bool jacobian(int k, int row, std::vector<Eigen::Triplet<double>>* triplets,
                        Eigen::VectorXd* residuals, double* cost) const = 0;
  /// Whether the Jacobian of block k is finite (slow; diagnostics only).
  virtual bool jacobian_finite(int k) const = 0;
  /// Compares block k's analytic Jacobians (functor output, before weight and loss) with
  /// central differences (step h, left retraction of each free parameter, states restored):
  /// returns the worst elementwise |J − J_num| / (1 + |J_num|), or +inf if unevaluable.
  virtual double jacobian_error(int k, double h) const = 0;
  /// While true, linearize() keeps every block's W·r and corrected J̃, which acceleration()
  /// reads; the stores are sized by reserve_acceleration().
  bool store_acceleration = false;
  virtual void reserve_acceleration() = 0;
  virtual void release_acceleration() = 0;
  /// Geodesic acceleration over the blocks idx[0..count), called with the states at x ⊞ h·v:
  /// rhs += J̃ᵀ·r̃''_v from each block's W·r there and the W·r, J̃ of x kept by linearize()
  /// (ResidualBlock::accumulate_acceleration).
  virtual bool acceleration(const int* idx, int count, const double* v, double h, double* rhs,
                            int* failed) const = 0;
};

/// What the geodesic-acceleration store keeps of a block's J̃: the whole tuple, or for a
/// functor with a LinkGroup (two parameters of the same DoF) one Jacobian J and the link G:
/// both parameters free, J = J̃_0 and J̃_1 = −J̃_0·Ad(G) is only applied through G
/// (ResidualBlock::accumulate_acceleration_linked; 64 instead of 105 doubles per Sim(3) edge
/// with W·r); one free, J is that parameter's J̃ (G unused).
template <typename Block, bool = Block::kHasLink>
struct StoredJacobian {
  using type = typename Block::Jacobians;
};
template <typename Block>
struct StoredJacobian<Block, true> {
  struct type {
    typename Block::FirstJacobian J;
    typename Block::LinkGroup G;
  };
};

template <typename Functor, typename... Params>
class ResidualContainer final : public ResidualContainerBase {
 public:
  using Block = ResidualBlock<Functor, Params...>;
  using Residual = typename Block::Residual;
  using Jacobians = typename Block::Jacobians;
  using SqrtInfo = typename Block::SqrtInformation;
  std::vector<Block> blocks;
  std::vector<SqrtInfo> sqrt_infos;
  std::vector<std::array<int, sizeof...(Params)>> param_ids;

  int size() const override { return static_cast<int>(blocks.size()); }
  int num_residuals() const override { return Block::kNumResiduals; }
  const char* functor_name() const override { return typeid(Functor).name(); }
  void parameter_ids(int k, std::vector<int>* ids) const override {
    ids->assign(param_ids[k].begin(), param_ids[k].end());
  }
  int id(int k) const override { return blocks[k].id(); }

  void finalize(const std::vector<ParameterBlock>& pbs, const BlockStructure& s) override {
    for (std::size_t k = 0; k < blocks.size(); ++k) {
      Block& b = blocks[k];
      const auto& ids = param_ids[k];
      for (int i = 0; i < Block::kNumParams; ++i) b.col_[i] = pbs[ids[i]].col;
      for (int i = 0; i < Block::kNumParams; ++i) {
        for (int j = i; j < Block::kNumParams; ++j) {
          const int p = Block::pair_index(i, j);
          const int bi = pbs[ids[i]].index, bj = pbs[ids[j]].index;
          if (bi < 0 || bj < 0) {
            b.off_[p] = -1;
            continue;
          }
          const int lo = std::min(bi, bj), hi = std::max(bi, bj);
          b.off_[p] = s.block_offset(lo, hi);
          b.stride_[p] = s.column_height(hi);
          GEODRIFT_ASSERT(b.off_[p] >= 0);
        }
      }
    }
  }

  bool cost(const int* idx, int count, double* cost, int* failed) const override {
    double c = 0.0;
    Residual r;
    for (int i = 0; i < count; ++i) {
      const int k = idx ? idx[i] : i;
      double ck;
      if (!blocks[k].evaluate(sqrt_infos.data(), &ck, &r, nullptr)) {
        *failed = k;
        return false;
      }
      c += ck;
    }
    *cost += c;
    return true;
  }

  bool linearize(const int* idx, int count, double* H, double* g, double* cost, int* failed,
                 LinearizeTimes* times) const override {
    using Clock = std::chrono::steady_clock;
    // Fused: each block's weighted, corrected Jacobians go straight into its H blocks and g
    // (one block's J̃ lives on the stack while it is accumulated; no batch of Jacobians).
    Residual r;
    Jacobians J;
    double c = 0.0;
    const auto t0 = Clock::now();
    bool ok = true;
    for (int k = 0; k < count; ++k) {
      const Block& b = blocks[idx[k]];
      double ck;
      // Geodesic acceleration: keep W·r and J̃ of this point.
      Residual* const e_out = store_acceleration ? &stored_e_[idx[k]] : nullptr;
      if constexpr (Block::kHasLink) {
        if (b.linked()) {  // both parameters free: H_ij, H_jj, g_j from J̃_i and the link
          // J̃_i and G are written straight into the acceleration store when it is kept (no
          // copy of the 7×7 afterwards), else into locals.
          typename Block::LinkGroup local_link;
          auto* const st = e_out ? &stored_J_[idx[k]] : nullptr;
          auto* const J0 = st ? &st->J : &std::get<0>(J);
          auto* const link = st ? &st->G : &local_link;
          if (!b.evaluate_linked(sqrt_infos.data(), &ck, &r, J0, link, e_out)) {
            *failed = idx[k];
            ok = false;
            break;
          }
          c += ck;
          b.accumulate_linked(r, *J0, *link, H, g);
          continue;
        }
      }
      if (!b.evaluate(sqrt_infos.data(), &ck, &r, &J, e_out)) {
        *failed = idx[k];
        ok = false;
        break;
      }
      if (e_out) {
        if constexpr (Block::kHasLink)  // at most one parameter free here: keep its J̃
          stored_J_[idx[k]].J = b.col_[0] >= 0 ? std::get<0>(J) : std::get<1>(J);
        else
          stored_J_[idx[k]] = J;
      }
      c += ck;
      b.accumulate(r, J, H, g);
    }
    times->evaluate += std::chrono::duration<double>(Clock::now() - t0).count();
    if (ok) *cost += c;
    return ok;
  }

  bool acceleration(const int* idx, int count, const double* v, double h, double* rhs,
                    int* failed) const override {
    Residual e_h;
    [[maybe_unused]] Jacobians J;
    for (int k = 0; k < count; ++k) {
      const std::size_t i = static_cast<std::size_t>(idx[k]);
      const Block& b = blocks[i];
      bool ok = b.weighted_residual(sqrt_infos.data(), &e_h);
      const Residual& e = stored_e_[i];
      if constexpr (Block::kHasLink) {  // J and G (see StoredJacobian)
        const auto& st = stored_J_[i];
        if (ok && b.linked()) {  // both free: J̃_1 = −J̃_0·Ad(G) stays implicit
          ok = b.accumulate_acceleration_linked(e, st.J, st.G, e_h, v, h, rhs);
        } else if (ok) {  // one free: its J̃ into the tuple
          if (b.col_[0] >= 0)
            std::get<0>(J) = st.J;
          else
            std::get<1>(J) = st.J;
          ok = b.accumulate_acceleration(e, J, e_h, v, h, rhs);
        }
      } else {
        ok = ok && b.accumulate_acceleration(e, stored_J_[i], e_h, v, h, rhs);
      }
      if (!ok) {
        *failed = idx[k];
        return false;
      }
    }
    return true;
  }
  /// Sizes the acceleration stores (W·r and J̃ per block).
  void reserve_acceleration() override {
    stored_e_.resize(blocks.size());
    stored_J_.resize(blocks.size());
  }
  void release_acceleration() override {
    decltype(stored_e_)().swap(stored_e_);
    decltype(stored_J_)().swap(stored_J_);
  }

  void mark_first_writes(const int* idx, int count, std::vector<bool>* written) override {
    for (int k = 0; k < count; ++k) {
      Block& b = blocks[idx[k]];
      for (int p = 0; p < Block::kNumPairs; ++p) {
        b.assign_[p] = false;
        if (b.off_[p] < 0) continue;
        const std::size_t o = static_cast<std::size_t>(b.off_[p]);
        b.assign_[p] = !(*written)[o];
        (*written)[o] = true;
      }
    }
  }

  void block_range(int k, const std::vector<ParameterBlock>& pbs, int* lo, int* hi) const override {
    *lo = *hi = -1;
    for (int id : param_ids[k]) {
      const int b = pbs[id].index;
      if (b < 0) continue;
      if (*lo < 0 || b < *lo) *lo = b;
      if (b > *hi) *hi = b;
    }
  }

  bool jacobian(int k, int row, std::vector<Eigen::Triplet<double>>* triplets,
                Eigen::VectorXd* residuals, double* cost) const override {
    Residual r;
    Jacobians J;
    double ck;
    if (!blocks[k].evaluate(sqrt_infos.data(), &ck, &r, &J)) return false;
    *cost += ck;
    residuals->segment<Block::kNumResiduals>(row) = r;
    detail::static_for<sizeof...(Params)>([&](auto i) {
      const int col = blocks[k].col_[i];
      if (col < 0) return;
      const auto& Ji = std::get<i>(J);
      for (int cc = 0; cc < Ji.cols(); ++cc)
        for (int rr = 0; rr < Ji.rows(); ++rr)
          triplets->emplace_back(row + rr, col + cc, Ji(rr, cc));
    });
    return true;
  }

  bool jacobian_finite(int k) const override {
    Residual r;
    Jacobians J;
    double ck;
    if (!blocks[k].evaluate(sqrt_infos.data(), &ck, &r, &J)) return false;
    bool ok = true;
    detail::static_for<sizeof...(Params)>([&](auto i) {
      if (blocks[k].col_[i] >= 0) ok = ok && std::get<i>(J).allFinite();
    });
    return ok;
  }

  double jacobian_error(int k, double h) const override {
    const Block& b = blocks[k];
    Residual r0, rp, rm;
    Jacobians J;
    double worst = 0.0;
    const auto call = [&](Residual* r, Jacobians* jac) {
      return call_functor(b, r, jac, std::index_sequence_for<Params...>{});
    };
    if (!call(&r0, &J)) return std::numeric_limits<double>::infinity();
    bool ok = true;
    detail::static_for<sizeof...(Params)>([&](auto i) {
      constexpr std::size_t I = decltype(i)::value;
      using M = Manifold<typename Block::template Param<I>>;
      if (!ok || b.col_[I] < 0) return;
      auto* state = std::get<I>(b.states());
      typename M::Storage saved;
      M::save(state, &saved);
      for (int c = 0; c < M::kDoF; ++c) {
        typename M::Tangent d = M::Tangent::Zero();
        d[c] = h;
        M::plus_in_place(state, d.data());
        const bool okp = call(&rp, nullptr);
        M::restore(saved, state);
        d[c] = -h;
        M::plus_in_place(state, d.data());
        const bool okm = call(&rm, nullptr);
        M::restore(saved, state);
        if (!okp || !okm) {
          ok = false;
          return;
        }
        const Residual num = (rp - rm) / (2.0 * h);
        const auto col = std::get<I>(J).col(c);
        for (int row = 0; row < Block::kNumResiduals; ++row)
          worst = std::max(worst, std::abs(col[row] - num[row]) / (1.0 + std::abs(num[row])));
      }
    });
    return ok ? worst : std::numeric_limits<double>::infinity();
  }

 private:
  /// Geodesic acceleration stores: W·r and J̃ per block at the last point linearised with
  /// store_acceleration.
  mutable std::vector<Residual, LargeArrayAllocator<Residual>> stored_e_;
  using Stored = typename StoredJacobian<Block>::type;
  mutable std::vector<Stored, LargeArrayAllocator<Stored>> stored_J_;

  template <std::size_t... I>
  static bool call_functor(const Block& b, Residual* r, Jacobians* jac, std::index_sequence<I...>) {
    return b.functor()(
        Manifold<typename Block::template Param<I>>::view(std::get<I>(b.states()))..., r,
        (jac && b.col_[I] >= 0 ? &std::get<I>(*jac) : nullptr)...);
  }
};

}  // namespace detail

class Problem {
 public:
  Problem() = default;
  Problem(const Problem&) = delete;
  Problem& operator=(const Problem&) = delete;
  Problem(Problem&&) = default;
  Problem& operator=(Problem&&) = default;

  /// Adds the residual functor(x_1, ..., x_n) with a robust loss and a weight (see the file
  /// comment for the weight forms).
  /// @return the residual block id (insertion order, 0-based).
  /// @throws InvalidArgument if a state pointer is null, the same state appears twice in the
  ///         block, a state was registered before with a different type, or the weight is not
  ///         finite / positive (definite).
  template <typename Functor, typename Weight, typename... Ptrs>
  int add_residual_block(Functor functor, const RobustLoss& loss, const Weight& weight,
                         Ptrs... ptrs) {
    using Container = detail::ResidualContainer<Functor, typename detail::ParamOf<Ptrs>::type...>;
    using Block = typename Container::Block;
    constexpr int kN = Functor::kNumResiduals;
    Container* c = container<Container>();

    std::array<int, sizeof...(Ptrs)> ids{
        parameter_id<typename detail::ParamOf<Ptrs>::type>(detail::ParamOf<Ptrs>::state(ptrs))...};
    for (std::size_t a = 0; a < ids.size(); ++a)
      for (std::size_t b = a + 1; b < ids.size(); ++b)
        GEODRIFT_CHECK(ids[a] != ids[b], "add_residual_block: parameters "
                                             << a << " and " << b << " are the same state");
    double sqrt_w = 1.0;
    int info_index = -1;
    if constexpr (std::is_arithmetic_v<Weight>) {
      GEODRIFT_CHECK(
          std::isfinite(double(weight)) && weight > 0,
          "add_residual_block: scalar information " << weight << " is not finite and > 0");
      sqrt_w = std::sqrt(double(weight));
    } else if constexpr (std::is_same_v<Weight, SqrtInformation<kN>>) {
      GEODRIFT_CHECK(weight.matrix.allFinite(),
                     "add_residual_block: square-root information is not finite");
      info_index = static_cast<int>(c->sqrt_infos.size());
      c->sqrt_infos.push_back(weight.matrix);
    } else {
      static_assert(std::is_same_v<Weight, Eigen::Matrix<double, kN, kN>>,
                    "weight must be a double (information), an NxN information matrix, or "
                    "SqrtInformation<N>, N = Functor::kNumResiduals");
      GEODRIFT_CHECK(weight.allFinite(), "add_residual_block: information matrix not finite");
      const Eigen::Matrix<double, kN, kN> sym = 0.5 * (weight + weight.transpose());
      const Eigen::LLT<Eigen::Matrix<double, kN, kN>> llt(sym);
      GEODRIFT_CHECK(llt.info() == Eigen::Success,
                     "add_residual_block: information matrix is not positive definite");
      info_index = static_cast<int>(c->sqrt_infos.size());
      c->sqrt_infos.push_back(llt.matrixU());  // W = Lᵀ: |W·r|² = rᵀΛr
    }
    const int id = static_cast<int>(order_.size());
    c->blocks.emplace_back(std::move(functor), loss, sqrt_w, info_index,
                           typename Block::States{detail::ParamOf<Ptrs>::state(ptrs)...}, id);
    c->param_ids.push_back(ids);
    order_.emplace_back(container_index_[std::type_index(typeid(Container))], c->size() - 1);
    for (int b : ids) ++params_[b].num_residuals;
    finalized_ = false;
    return id;
  }

  /// Holds a state fixed (no columns). Gauge fixing: set the first pose constant.
  /// @throws InvalidArgument if the state was never added to a residual block.
  void set_constant(const void* state) {
    params_.at(lookup(state)).constant = true;
    finalized_ = false;
  }
  /// Frees a constant state again.
  void set_variable(const void* state) {
    params_.at(lookup(state)).constant = false;
    finalized_ = false;
  }
  bool is_constant(const void* state) const { return params_.at(lookup(state)).constant; }
  bool has_parameter(const void* state) const { return index_.count(state) > 0; }

  /// Builds the column layout and the pattern of H (once; again only after a change).
  /// @param schur_ordering put R^3 blocks that are never coupled to another R^3 block (BA
  ///        points) last and mark them eliminable (BlockStructure::num_eliminated()).
  void finalize(bool schur_ordering = false) {
    // Eliminable: free, R^3, and no residual touches two of them.
    for (auto& p : params_)
      p.eliminable = schur_ordering && !p.constant && p.dof == 3 && p.ambient == 3;
    std::vector<int> ids;
    if (schur_ordering) {
      for (const auto& c : containers_) {
        for (int k = 0; k < c->size(); ++k) {
          c->parameter_ids(k, &ids);
          int n = 0;
          for (int b : ids) n += params_[b].eliminable ? 1 : 0;
          if (n > 1)
            for (int b : ids) params_[b].eliminable = false;
        }
      }
    }
    std::vector<int> sizes;
    int index = 0, col = 0, num_elim = 0;
    for (int pass = 0; pass < 2; ++pass) {
      for (auto& p : params_) {
        if (p.constant) {
          p.index = p.col = -1;
          continue;
        }
        if (p.eliminable != (pass == 1)) continue;
        p.index = index++;
        p.col = col;
        col += p.dof;
        sizes.push_back(p.dof);
        if (pass == 1) ++num_elim;
      }
    }
    std::vector<std::pair<int, int>> couplings;
    for (const auto& c : containers_) {
      for (int k = 0; k < c->size(); ++k) {
        c->parameter_ids(k, &ids);
        for (std::size_t a = 0; a < ids.size(); ++a)
          for (std::size_t b = a + 1; b < ids.size(); ++b)
            if (params_[ids[a]].index >= 0 && params_[ids[b]].index >= 0)
              couplings.emplace_back(params_[ids[a]].index, params_[ids[b]].index);
      }
    }
    structure_ = std::make_unique<BlockStructure>();
    structure_->build(sizes, std::move(couplings), num_elim);
    for (auto& c : containers_) {
      c->finalize(params_, *structure_);
      c->release_acceleration();
    }
    acceleration_reserved_ = false;
    partition();
    row_.assign(order_.size() + 1, 0);
    for (std::size_t i = 0; i < order_.size(); ++i)
      row_[i + 1] = row_[i] + containers_[order_[i].first]->num_residuals();
    finalized_ = true;
    schur_ordering_ = schur_ordering;
    ++generation_;
  }

  /// Threads used by linearize() and evaluate_cost(): 1 or 2. Residual blocks whose H blocks
  /// all lie in the first (second) half of the block columns form list 0 (1); the few that
  /// straddle the split form list 2. With 2 threads lists 0 and 1 run at once (calling and
  /// background thread), with 1 one after the other; list 2 runs last on the calling thread.
  /// Every sum (H, g, cost) is therefore taken in the same order with 1 and 2 threads, and the
  /// results are bit-identical.
  /// @throws InvalidArgument unless n is 1 or 2.
  void set_num_threads(int n) {
    GEODRIFT_CHECK(n == 1 || n == 2, "num_threads " << n << " not 1 or 2");
    if (n == num_threads_) return;
    num_threads_ = n;
    worker_ = n == 2 ? std::make_unique<detail::Worker>() : nullptr;
  }
  int num_threads() const { return num_threads_; }

  bool is_finalized() const { return finalized_; }
  bool has_schur_ordering() const { return schur_ordering_; }
  /// Increments on every finalize(): a solver may keep its symbolic analysis while it is equal.
  std::uint64_t generation() const { return generation_; }
  const BlockStructure& structure() const {
    GEODRIFT_CHECK(finalized_, "Problem::structure() before finalize()");
    return *structure_;
  }

  int num_residual_blocks() const { return static_cast<int>(order_.size()); }
  int num_parameter_blocks() const { return static_cast<int>(params_.size()); }
  /// Total residual rows.
  int num_residuals() const { return row_.empty() ? 0 : row_.back(); }
  /// Free tangent columns (after finalize()).
  int num_effective_parameters() const { return finalized_ ? structure_->num_cols() : 0; }
  const std::vector<ParameterBlock>& parameter_blocks() const { return params_; }
  /// The block record of a state (col/index are valid after finalize()).
  const ParameterBlock& parameter_block(const void* state) const {
    return params_.at(lookup(state));
  }

  /// Cost ½Σρ(|W·r|²) at the current states. @return false (and *error) if a block fails.
  bool evaluate_cost(double* cost, EvaluationError* error = nullptr) const {
    *cost = 0.0;
    if (!finalized_) {  // no work lists yet: every block on the calling thread
      for (const auto& c : containers_) {
        int failed = -1;
        if (!c->cost(nullptr, c->size(), cost, &failed)) {
          set_error(*c, failed, kFailed, error);
          return false;
        }
      }
      return true;
    }
    // The same work lists (and summation order) as linearize(): equal costs at equal states.
    double cost1 = 0.0;
    PartFailure fail;
    const bool ok = for_parts(
        [](const detail::ResidualContainerBase& c, const std::vector<int>& l, double* acc,
           int* failed) { return c.cost(l.data(), static_cast<int>(l.size()), acc, failed); },
        cost, &cost1, &fail);
    if (!ok) set_error(*containers_[fail.container], fail.block, kFailed, error);
    *cost += cost1;
    return ok;
  }

  /// Evaluates residuals and Jacobians at the current states and writes H = J̃ᵀJ̃ (values on
  /// structure()) and g = J̃ᵀr̃ (J̃, r̃: weighted, Triggs-corrected). H and g are overwritten.
  /// @param g num_effective_parameters() doubles.
  /// @param times accumulates the calling thread's evaluation and assembly time.
  /// @param keep_acceleration (after reserve_acceleration(true)): also keep every block's W·r
  ///        and J̃ for acceleration_rhs(), replacing those of the previous such call.
  bool linearize(BlockSparseMatrix* H, double* g, double* cost, LinearizeTimes* times,
                 EvaluationError* error = nullptr, bool keep_acceleration = false) const {
    GEODRIFT_CHECK(finalized_, "Problem::linearize() before finalize()");
    GEODRIFT_CHECK(!keep_acceleration || acceleration_reserved_,
                   "Problem::linearize(): keep_acceleration without reserve_acceleration(true)");
    struct StoreGuard {
      const std::vector<std::unique_ptr<detail::ResidualContainerBase>>& cs;
      StoreGuard(const std::vector<std::unique_ptr<detail::ResidualContainerBase>>& c, bool on)
          : cs(c) {
        for (auto& x : cs) x->store_acceleration = on;
      }
      ~StoreGuard() {
        for (auto& x : cs) x->store_acceleration = false;
      }
    } guard(containers_, keep_acceleration);
    const auto tz = std::chrono::steady_clock::now();
    // No zeroing pass over H: every block's first writer assigns (mark_first_writes); only
    // blocks no residual writes are zeroed here.
    GEODRIFT_CHECK(&H->structure() == structure_.get(),
                   "Problem::linearize(): H is not on this problem's structure()");
    for (const auto& z : unwritten_) {
      double* d = H->values() + z[0];
      for (int c = 0; c < z[2]; ++c) std::fill(d + c * z[3], d + c * z[3] + z[1], 0.0);
    }
    std::fill(g, g + structure_->num_cols(), 0.0);
    times->assemble += std::chrono::duration<double>(std::chrono::steady_clock::now() - tz).count();
    struct Acc {
      double* H;
      double* g;
      double cost = 0.0;
      LinearizeTimes times;
    } acc0{H->values(), g, 0.0, LinearizeTimes{}}, acc1{H->values(), g, 0.0, LinearizeTimes{}};
    PartFailure fail;
    const bool ok = for_parts(
        [](const detail::ResidualContainerBase& c, const std::vector<int>& l, Acc* a, int* failed) {
          return c.linearize(l.data(), static_cast<int>(l.size()), a->H, a->g, &a->cost, failed,
                             &a->times);
        },
        &acc0, &acc1, &fail);
    if (!ok) set_error(*containers_[fail.container], fail.block, kFailed, error);
    *cost = acc0.cost + acc1.cost;
    times->evaluate += acc0.times.evaluate;  // the calling thread's
    times->assemble += acc0.times.assemble;
    return ok;
  }

  /// Finds the first residual block with a non-finite Jacobian (diagnostics, slow).
  bool find_non_finite_jacobian(EvaluationError* error) const {
    for (const auto& c : containers_)
      for (int k = 0; k < c->size(); ++k)
        if (!c->jacobian_finite(k)) {
          set_error(*c, k, "has a non-finite Jacobian", error);
          return true;
        }
    return false;
  }

  /// Checks every residual block's analytic Jacobians against central differences (step h,
  /// left retraction) at the current states; states are left unchanged.
  /// @return true if all agree within tol (elementwise |J − J_num| ≤ tol·(1 + |J_num|));
  ///         otherwise false and *error names the worst block and its error.
  bool check_jacobians(double tol, double h, EvaluationError* error) const {
    double worst = 0.0;
    int worst_c = -1, worst_k = -1;
    for (std::size_t ci = 0; ci < containers_.size(); ++ci) {
      const auto& c = *containers_[ci];
      for (int k = 0; k < c.size(); ++k) {
        const double e = c.jacobian_error(k, h);
        if (!(e <= worst)) {
          worst = e;
          worst_c = static_cast<int>(ci);
          worst_k = k;
        }
      }
    }
    if (worst <= tol) return true;
    std::ostringstream os;
    os << "has an analytic Jacobian off by " << worst << " (relative) from central differences";
    set_error(*containers_[worst_c], worst_k, os.str().c_str(), error);
    return false;
  }

  /// The full weighted, loss-corrected Jacobian J̃ (num_residuals() x num_effective_parameters())
  /// and residual r̃ at the current states (tests; allocates). Finalizes if needed.
  /// @return false if a block cannot be evaluated.
  bool evaluate_jacobian(Eigen::SparseMatrix<double>* J, Eigen::VectorXd* residuals,
                         double* cost = nullptr) {
    if (!finalized_) finalize(schur_ordering_);
    std::vector<Eigen::Triplet<double>> t;
    residuals->setZero(num_residuals());
    double c = 0.0;
    for (std::size_t i = 0; i < order_.size(); ++i) {
      const auto& [ci, k] = order_[i];
      if (!containers_[ci]->jacobian(k, row_[i], &t, residuals, &c)) return false;
    }
    J->resize(num_residuals(), structure_->num_cols());
    J->setFromTriplets(t.begin(), t.end());
    if (cost) *cost = c;
    return true;
  }

  /// Allocates (true) or frees (false) the geodesic-acceleration stores: per residual block
  /// W·r and J̃ of one linearisation point (m·n_J + m doubles for m residual rows and n_J
  /// Jacobian columns per block; a functor with a LinkGroup keeps J̃_0 and the link instead,
  /// see StoredJacobian: 49 + 8 + 7 for a Sim(3) edge). Dropped by finalize().
  void reserve_acceleration(bool on) {
    GEODRIFT_CHECK(finalized_, "Problem::reserve_acceleration() before finalize()");
    for (auto& c : containers_) {
      if (on)
        c->reserve_acceleration();
      else
        c->release_acceleration();
    }
    acceleration_reserved_ = on;
  }

  /// Geodesic acceleration right-hand side rhs = J̃ᵀ·r̃''_v at the point last linearised with
  /// keep_acceleration (the current states; see ResidualBlock::accumulate_acceleration). The
  /// states are moved to x ⊞ h·v for one residual-only pass and restored (through the
  /// save_state() buffers; bit for bit). rhs: num_effective_parameters() doubles, overwritten. With
  /// 2 threads the blocks are split as in linearize(). @return false if a block cannot be evaluated
  /// at x ⊞ h·v or a value is not finite.
  bool acceleration_rhs(const double* v, double h, double* rhs) {
    GEODRIFT_CHECK(finalized_ && acceleration_reserved_,
                   "Problem::acceleration_rhs() needs reserve_acceleration(true)");
    const int n = structure_->num_cols();
    accel_step_.resize(static_cast<std::size_t>(n));
    for (int c = 0; c < n; ++c) accel_step_[static_cast<std::size_t>(c)] = h * v[c];
    std::fill(rhs, rhs + n, 0.0);
    accel_buffer_.assign(static_cast<std::size_t>(n), 0.0);  // list 1's half (see for_parts)
    save_state();
    plus(accel_step_.data());
    PartFailure fail;
    const bool ok = for_parts(
        [v, h](const detail::ResidualContainerBase& c, const std::vector<int>& l, double* out,
               int* failed) {
          return c.acceleration(l.data(), static_cast<int>(l.size()), v, h, out, failed);
        },
        rhs, accel_buffer_.data(), &fail);
    restore_state();
    if (!ok) return false;
    for (int c = 0; c < n; ++c) rhs[c] += accel_buffer_[static_cast<std::size_t>(c)];
    return true;
  }

  /// x ← x ⊞ delta for every free block (delta: num_effective_parameters() doubles, in column
  /// order).
  void plus(const double* delta) {
    for (auto& g : groups_) g->plus(params_, delta);
  }
  /// Copies / restores every free state (LM's rollback of a rejected step; no allocation).
  void save_state() {
    for (auto& g : groups_) g->save(params_);
  }
  void restore_state() {
    for (auto& g : groups_) g->restore(params_);
  }
  /// |x| over free blocks in ambient coordinates (Manifold::ambient_squared_norm).
  double state_norm() const {
    double s = 0.0;
    for (const auto& g : groups_) s += g->ambient_squared_norm(params_);
    return std::sqrt(s);
  }

 private:
  template <typename Container>
  Container* container() {
    const std::type_index key(typeid(Container));
    auto it = container_index_.find(key);
    if (it != container_index_.end()) return static_cast<Container*>(containers_[it->second].get());
    container_index_.emplace(key, static_cast<int>(containers_.size()));
    containers_.push_back(std::make_unique<Container>());
    return static_cast<Container*>(containers_.back().get());
  }

  template <typename P>
  int parameter_id(typename Manifold<P>::State* state) {
    GEODRIFT_CHECK(state != nullptr, "add_residual_block: null parameter pointer");
    const std::type_index type(typeid(P));
    auto it = index_.find(state);
    if (it != index_.end()) {
      GEODRIFT_CHECK(params_[it->second].type == type, "add_residual_block: state at "
                                                           << static_cast<const void*>(state)
                                                           << " was added before as another type");
      return it->second;
    }
    ParameterBlock pb;
    pb.state = state;
    pb.type = type;
    pb.dof = Manifold<P>::kDoF;
    pb.ambient = Manifold<P>::kAmbient;
    const int id = static_cast<int>(params_.size());
    params_.push_back(pb);
    index_.emplace(state, id);
    auto g = group_index_.find(type);
    if (g == group_index_.end()) {
      g = group_index_.emplace(type, static_cast<int>(groups_.size())).first;
      groups_.push_back(std::make_unique<detail::ParameterGroup<P>>());
    }
    groups_[g->second]->add(id);
    return id;
  }

  int lookup(const void* state) const {
    auto it = index_.find(state);
    GEODRIFT_CHECK(it != index_.end(),
                   "state at " << state << " is not a parameter of this problem");
    return it->second;
  }

  /// Work lists (see set_num_threads), the same for 1 and 2 threads: split at the block column
  /// m where half of the residual blocks have all their H blocks left of m.
  void partition() {
    std::vector<int> his;
    int lo, hi;
    for (const auto& c : containers_)
      for (int k = 0; k < c->size(); ++k) {
        c->block_range(k, params_, &lo, &hi);
        his.push_back(hi);
      }
    int m = 0;
    if (!his.empty()) {
      std::nth_element(his.begin(), his.begin() + his.size() / 2, his.end());
      m = his[his.size() / 2];
    }
    for (auto& c : containers_) {
      for (auto& l : c->part) l.clear();
      for (int k = 0; k < c->size(); ++k) {
        c->block_range(k, params_, &lo, &hi);
        if (hi < 0) {  // all parameters constant: cost only, no H or g entries
          c->part[0].push_back(k);
          continue;
        }
        c->part[hi < m ? 0 : lo >= m ? 1 : 2].push_back(k);
      }
    }
    // First writer of every H block in linearize()'s order (thread 0's lists, thread 1's —
    // disjoint H blocks —, then the shared ones), and the blocks nobody writes.
    std::vector<bool> written(static_cast<std::size_t>(structure_->num_values()), false);
    for (int q = 0; q < 3; ++q)
      for (auto& c : containers_)
        c->mark_first_writes(c->part[q].data(), static_cast<int>(c->part[q].size()), &written);
    unwritten_.clear();
    const BlockStructure& s = *structure_;
    for (int b = 0; b < s.num_blocks(); ++b)
      for (int k = s.block_col_ptr()[b]; k < s.block_col_ptr()[b + 1]; ++k)
        if (!written[static_cast<std::size_t>(s.block_offsets()[k])])
          unwritten_.push_back({s.block_offsets()[k], s.block_size(s.block_rows()[k]),
                                s.block_size(b), s.column_height(b)});
  }

  /// The first failure for_parts() met: container index and block within it (-1: none).
  struct PartFailure {
    int container = -1, block = -1;
  };
  static constexpr const char* kFailed = "returned false or a non-finite residual";

  /// The threading of linearize(), evaluate_cost() and acceleration_rhs() (see
  /// set_num_threads): f(container, work list, ctx, &failed_block) over every container's
  /// list 0 on the calling thread with ctx0 and list 1 with ctx1 (with 2 threads on the worker
  /// meanwhile, with 1 afterwards on the calling thread); then list 2 (blocks straddling the
  /// split) on the calling thread with ctx0. Lists 0 and 1 touch disjoint H blocks and g
  /// entries, so each sum is taken in the same order either way. Each list stops at its first
  /// false; list 2 runs only if nothing failed. @return false with *fail = list 0's failure,
  /// else list 1's.
  template <typename F, typename Ctx>
  bool for_parts(F f, Ctx* ctx0, Ctx* ctx1, PartFailure* fail) const {
    struct Job {
      const Problem* p;
      F* f;
      Ctx* ctx;
      PartFailure fail;
    };
    const bool two = num_threads_ == 2 && worker_;
    Job job{this, &f, ctx1, PartFailure{}};
    if (two) {
      worker_->run(
          [](void* vp) {
            Job& j = *static_cast<Job*>(vp);
            run_list(*j.p, *j.f, 1, j.ctx, &j.fail);
          },
          &job);
    }
    bool ok = run_list(*this, f, 0, ctx0, fail);
    if (two)
      worker_->wait();
    else if (ok)
      run_list(*this, f, 1, ctx1, &job.fail);
    if (ok && job.fail.container >= 0) {
      *fail = job.fail;
      ok = false;
    }
    return ok && run_list(*this, f, 2, ctx0, fail);
  }
  template <typename F, typename Ctx>
  static bool run_list(const Problem& p, F& f, int list, Ctx* ctx, PartFailure* fail) {
    for (std::size_t i = 0; i < p.containers_.size(); ++i) {
      const detail::ResidualContainerBase& c = *p.containers_[i];
      int failed = -1;
      if (!f(c, c.part[list], ctx, &failed)) {
        *fail = {static_cast<int>(i), failed};
        return false;
      }
    }
    return true;
  }

  static void set_error(const detail::ResidualContainerBase& c, int k, const char* what,
                        EvaluationError* error) {
    if (!error) return;
    error->residual_id = c.id(k);
    std::ostringstream os;
    os << "residual block " << c.id(k) << " (functor " << c.functor_name() << ") " << what;
    error->what = os.str();
  }

  std::vector<ParameterBlock> params_;
  std::unordered_map<const void*, int> index_;
  std::vector<std::unique_ptr<detail::ParameterGroupBase>> groups_;
  std::unordered_map<std::type_index, int> group_index_;
  std::vector<std::unique_ptr<detail::ResidualContainerBase>> containers_;
  std::unordered_map<std::type_index, int> container_index_;
  std::vector<std::pair<int, int>> order_;  ///< residual id -> (container, index)
  std::vector<int> row_;                    ///< residual id -> first row
  std::unique_ptr<BlockStructure> structure_;
  /// H blocks no residual writes: {offset, rows, cols, stride}, zeroed by linearize().
  std::vector<std::array<int, 4>> unwritten_;
  bool finalized_ = false;
  bool schur_ordering_ = false;
  std::uint64_t generation_ = 0;
  int num_threads_ = 1;
  std::unique_ptr<detail::Worker> worker_;
  std::vector<double> accel_buffer_;  ///< second thread's half of acceleration_rhs()
  std::vector<double> accel_step_;    ///< h·v of acceleration_rhs()
  bool acceleration_reserved_ = false;
};

}  // namespace geodrift::solver
