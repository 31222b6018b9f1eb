// BlockCholeskySolver against dense LDLᵀ and CHOLMOD on random SPD block-sparse matrices (chain,
// random graph with fill, every ordering, block sizes 6 and 7), not-positive-definite / NaN as a
// status, unsupported structures rejected.

#include <Eigen/Cholesky>
#include <algorithm>
#include <catch2/catch.hpp>
#include <limits>
#include <random>
#include <set>
#include <utility>
#include <vector>

#include "geodrift/solver/block_cholesky_solver.hpp"
#include "geodrift/solver/block_sparse_matrix.hpp"
#include "geodrift/solver/cholmod_solver.hpp"
#include "geodrift/solver/detail/block_kernels.hpp"
#include "support/numeric_jacobian.hpp"

using namespace geodrift;
using solver::BlockCholeskySolver;
using solver::LinearSolverStatus;

namespace {

/// Pattern + SPD values H = Σ_pairs JᵀJ + 0.01·I (5-row random J per pair and per block).
struct RandomSpd {
  solver::BlockStructure s;
  std::unique_ptr<solver::BlockSparseMatrix> H;

  RandomSpd(int nb, int B, const std::vector<std::pair<int, int>>& pairs, unsigned seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> n(0.0, 1.0);
    s.build(std::vector<int>(nb, B), pairs);
    H = std::make_unique<solver::BlockSparseMatrix>(&s);
    const auto rnd = [&](int r, int c) {
      Eigen::MatrixXd M(r, c);
      for (int i = 0; i < M.size(); ++i) M.data()[i] = n(rng);
      return M;
    };
    for (int b = 0; b < nb; ++b) {
      const Eigen::MatrixXd J = rnd(B + 1, B);
      H->block(b, b) += J.transpose() * J;
    }
    for (const auto& [a0, b0] : pairs) {
      const int a = std::min(a0, b0), b = std::max(a0, b0);
      const Eigen::MatrixXd Ja = rnd(5, B), Jb = rnd(5, B);
      H->block(a, a) += Ja.transpose() * Ja;
      H->block(b, b) += Jb.transpose() * Jb;
      if (a != b) H->block(a, b) += Ja.transpose() * Jb;
    }
    for (int c = 0; c < s.num_cols(); ++c) H->values()[s.diagonal_positions()[c]] += 0.01;
  }
};

std::vector<std::pair<int, int>> chain(int nb, int links) {
  std::vector<std::pair<int, int>> p;
  for (int i = 0; i < nb; ++i)
    for (int k = 1; k <= links && i + k < nb; ++k) p.emplace_back(i, i + k);
  return p;
}

std::vector<std::pair<int, int>> random_graph(int nb, int edges, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> u(0, nb - 1);
  std::vector<std::pair<int, int>> p = chain(nb, 1);
  for (int e = 0; e < edges; ++e) {
    const int a = u(rng), b = u(rng);
    if (a != b) p.emplace_back(b, a);  // any order: BlockStructure sorts
  }
  return p;
}

}  // namespace

TEST_CASE("Block Cholesky solves like dense LDLT and CHOLMOD on any pattern and ordering",
          "[solver][block_cholesky]") {
  using Ord = BlockCholeskySolver::Ordering;
  struct Case {
    const char* name;
    int nb, B;
    std::vector<std::pair<int, int>> pairs;
    bool fill_free;  ///< no fill in the natural order
  };
  // Fill-free but not banded: a chain whose last block is coupled to every block, and a tree
  // whose parents come after their children (block i's parent is 20 + i / 2), so
  // the in-place factor's rows meet in scattered blocks.
  std::vector<std::pair<int, int>> arrow = chain(30, 1), tree;
  for (int i = 0; i < 29; ++i) arrow.emplace_back(i, 29);
  for (int i = 0; i + 1 < 40; ++i) tree.emplace_back(i, 20 + i / 2);
  const std::vector<Case> cases{
      {"chain 6 links, B=7", 60, 7, chain(60, 6), true},
      {"chain 2 links, B=6", 45, 6, chain(45, 2), true},
      {"chain 1 link + arrow, B=7", 30, 7, arrow, true},
      {"tree, B=6", 40, 6, tree, true},
      {"random graph with fill, B=6", 40, 6, random_graph(40, 50, 3), false},
      {"random graph with fill, B=7", 35, 7, random_graph(35, 30, 4), false},
      {"block diagonal, B=7", 5, 7, {}, true},
      {"single block, B=6", 1, 6, {}, true},
  };
  for (const Case& c : cases) {
    RandomSpd m(c.nb, c.B, c.pairs, 11);
    const Eigen::MatrixXd D = m.H->to_dense();
    std::mt19937 rng(5);
    std::normal_distribution<double> n(0.0, 1.0);
    Eigen::VectorXd b(D.rows());
    for (int i = 0; i < b.size(); ++i) b[i] = n(rng);
    const Eigen::VectorXd ref = D.ldlt().solve(b);
    solver::CholmodSolver chol;
    REQUIRE(chol.analyze(m.s) == LinearSolverStatus::kSuccess);
    REQUIRE(chol.factorize(*m.H) == LinearSolverStatus::kSuccess);
    Eigen::VectorXd xc(D.rows());
    REQUIRE(chol.solve(b.data(), xc.data()) == LinearSolverStatus::kSuccess);
    for (const Ord o : {Ord::kBest, Ord::kNatural, Ord::kAmd}) {
      INFO(c.name << ", ordering " << static_cast<int>(o));
      BlockCholeskySolver bc(o);
      CHECK(BlockCholeskySolver::supported_block_size(m.s) == c.B);
      REQUIRE(bc.analyze(m.s) == LinearSolverStatus::kSuccess);
      // the permutation is one
      std::set<int> seen(bc.permutation().begin(), bc.permutation().end());
      CHECK(static_cast<int>(seen.size()) == c.nb);
      Eigen::VectorXd x(D.rows());
      for (int rep = 0; rep < 2; ++rep) {  // refactorisation reuses the analysis
        REQUIRE(bc.factorize(*m.H) == LinearSolverStatus::kSuccess);
        REQUIRE(bc.solve(b.data(), x.data()) == LinearSolverStatus::kSuccess);
        CHECK(test::near(x, ref, 1e-9));
        CHECK(test::near(x, xc, 1e-9));
        CHECK((D * x - b).norm() < 1e-9 * b.norm());
        // The same substitutions folded into the factorisation: the same x.
        Eigen::VectorXd xf = Eigen::VectorXd::Constant(D.rows(), 5.0);
        REQUIRE(bc.factorize_and_solve(*m.H, b.data(), xf.data()) == LinearSolverStatus::kSuccess);
        CHECK((xf - x).norm() <= 1e-14 * x.norm());
        Eigen::VectorXd xs(D.rows());  // and solve() afterwards still uses that factor
        REQUIRE(bc.solve(b.data(), xs.data()) == LinearSolverStatus::kSuccess);
        CHECK((xs - x).norm() <= 1e-14 * x.norm());
      }
      CHECK(bc.factor_nnz() > 0.0);
      CHECK(bc.flops() > 0.0);
      // In place: only when the chosen order has no fill; then H's values hold L (block row i
      // of L in block column i of H) and L·Lᵀ = H; otherwise H is left alone.
      const bool natural = std::is_sorted(bc.permutation().begin(), bc.permutation().end());
      CHECK(bc.in_place() == (c.fill_free && natural));
      solver::BlockSparseMatrix Hc = *m.H;
      for (int rep = 0; rep < 2; ++rep) {
        Hc = *m.H;
        Eigen::VectorXd xi = Eigen::VectorXd::Constant(D.rows(), 5.0);
        bool overwritten = true;
        REQUIRE(bc.factorize_and_solve_in_place(&Hc, b.data(), xi.data(), &overwritten) ==
                LinearSolverStatus::kSuccess);
        CHECK(overwritten == bc.in_place());
        CHECK(test::near(xi, ref, 1e-9));
        CHECK((D * xi - b).norm() < 1e-9 * b.norm());
        Eigen::VectorXd xs(D.rows());
        REQUIRE(bc.solve(b.data(), xs.data()) == LinearSolverStatus::kSuccess);
        CHECK((xs - xi).norm() <= 1e-14 * xi.norm());
      }
      if (bc.in_place()) {
        Eigen::MatrixXd L = Eigen::MatrixXd::Zero(D.rows(), D.cols());
        const auto& bcp = m.s.block_col_ptr();
        for (int i = 0; i < c.nb; ++i)
          for (int k = bcp[i]; k < bcp[i + 1]; ++k) {
            const int j = m.s.block_rows()[k];
            L.block(m.s.block_col(i), m.s.block_col(j), c.B, c.B) = Hc.block(j, i);
          }
        CHECK((L.triangularView<Eigen::StrictlyUpper>().toDenseMatrix()).norm() == 0.0);
        CHECK((L * L.transpose() - D).norm() <= 1e-12 * D.norm());
      } else {
        CHECK((Hc.to_dense() - D).norm() == 0.0);
      }
    }
  }
}

TEST_CASE("Block Cholesky: chain ordering keeps the band, AMD limits fill on a random graph",
          "[solver][block_cholesky]") {
  // The drift-graph shape: block j coupled to j+1..j+6. In the natural order L has exactly the
  // band (no fill): 7 blocks per column except at the end.
  RandomSpd m(100, 7, chain(100, 6), 2);
  BlockCholeskySolver bc;
  REQUIRE(bc.analyze(m.s) == LinearSolverStatus::kSuccess);
  const double off_blocks = 94 * 6 + 15;  // off-diagonal blocks of the band = those of H
  CHECK(bc.factor_nnz() == Approx(off_blocks * 49 + 100.0 * 28).epsilon(1e-15));
  CHECK(BlockCholeskySolver::thin_factor(m.s, 7.0));
  // kBest keeps the fill-free natural order (no AMD run).
  for (int q = 0; q < 100; ++q) CHECK(bc.permutation()[static_cast<std::size_t>(q)] == q);
  // The same chain with its blocks interleaved (2k, 2k+1 swapped halves): the natural order
  // fills, and kBest finds an order with fewer flops.
  std::vector<std::pair<int, int>> shuffled;
  const auto pos = [](int i) { return i % 2 == 0 ? i / 2 : 50 + i / 2; };
  for (const auto& [a, b] : chain(100, 6)) shuffled.emplace_back(pos(a), pos(b));
  RandomSpd sh(100, 7, shuffled, 3);
  BlockCholeskySolver sh_nat(BlockCholeskySolver::Ordering::kNatural), sh_best;
  REQUIRE(sh_nat.analyze(sh.s) == LinearSolverStatus::kSuccess);
  REQUIRE(sh_best.analyze(sh.s) == LinearSolverStatus::kSuccess);
  CHECK(sh_best.flops() < 0.5 * sh_nat.flops());
  // A dense-ish random graph is not thin.
  RandomSpd r(60, 6, random_graph(60, 400, 9), 2);
  CHECK_FALSE(BlockCholeskySolver::thin_factor(r.s, 16.0));
  BlockCholeskySolver nat(BlockCholeskySolver::Ordering::kNatural),
      best(BlockCholeskySolver::Ordering::kBest);
  REQUIRE(nat.analyze(r.s) == LinearSolverStatus::kSuccess);
  REQUIRE(best.analyze(r.s) == LinearSolverStatus::kSuccess);
  CHECK(best.flops() <= nat.flops());
}

TEST_CASE("Block Cholesky: not positive definite or NaN is a status, and it recovers",
          "[solver][block_cholesky]") {
  RandomSpd m(20, 7, chain(20, 3), 4);
  BlockCholeskySolver bc;
  REQUIRE(bc.analyze(m.s) == LinearSolverStatus::kSuccess);
  {  // L is not initialised before the first factorisation: solve() refuses
    Eigen::VectorXd b = Eigen::VectorXd::Ones(m.s.num_cols()), x(m.s.num_cols());
    CHECK(bc.solve(b.data(), x.data()) == LinearSolverStatus::kFatal);
    CHECK_THAT(bc.message(), Catch::Contains("without a successful factorize"));
  }
  REQUIRE(bc.factorize(*m.H) == LinearSolverStatus::kSuccess);
  double* v = m.H->values();
  const int pos = m.s.diagonal_positions()[7 * 12 + 3];
  const double keep = v[pos];
  v[pos] = -50.0;
  CHECK(bc.factorize(*m.H) == LinearSolverStatus::kNotPositiveDefinite);
  CHECK_THAT(bc.message(), Catch::Contains("not positive definite"));
  v[pos] = std::numeric_limits<double>::quiet_NaN();
  CHECK(bc.factorize(*m.H) == LinearSolverStatus::kNotPositiveDefinite);
  {
    Eigen::VectorXd b = Eigen::VectorXd::Ones(m.s.num_cols()), x(m.s.num_cols());
    CHECK(bc.factorize_and_solve(*m.H, b.data(), x.data()) ==
          LinearSolverStatus::kNotPositiveDefinite);
    CHECK(bc.solve(b.data(), x.data()) == LinearSolverStatus::kFatal);  // after a failed one
  }
  {  // in place: the same status, and solve() refuses after it
    REQUIRE(bc.in_place());
    solver::BlockSparseMatrix Hc = *m.H;
    Eigen::VectorXd b = Eigen::VectorXd::Ones(m.s.num_cols()), x(m.s.num_cols());
    bool overwritten = false;
    CHECK(bc.factorize_and_solve_in_place(&Hc, b.data(), x.data(), &overwritten) ==
          LinearSolverStatus::kNotPositiveDefinite);
    CHECK(overwritten);
    CHECK_THAT(bc.message(), Catch::Contains("block 12"));
    CHECK(bc.solve(b.data(), x.data()) == LinearSolverStatus::kFatal);
  }
  v[pos] = keep;
  REQUIRE(bc.factorize(*m.H) == LinearSolverStatus::kSuccess);
  Eigen::VectorXd b = Eigen::VectorXd::Ones(m.s.num_cols()), x(m.s.num_cols());
  REQUIRE(bc.solve(b.data(), x.data()) == LinearSolverStatus::kSuccess);
  CHECK((m.H->to_dense() * x - b).norm() < 1e-9 * b.norm());
}

TEST_CASE("Block Cholesky refuses a matrix of another pattern than the analysed one",
          "[solver][block_cholesky]") {
  // Same size, one more coupling: the factor (in place or not) would read H's blocks at the
  // analysed offsets, so it is a fatal status, not a factorisation of the wrong values.
  RandomSpd m(20, 7, chain(20, 2), 4), other(20, 7, chain(20, 3), 4);
  BlockCholeskySolver bc;
  REQUIRE(bc.analyze(m.s) == LinearSolverStatus::kSuccess);
  REQUIRE(bc.in_place());
  Eigen::VectorXd b = Eigen::VectorXd::Ones(m.s.num_cols()), x(m.s.num_cols());
  CHECK(bc.factorize(*other.H) == LinearSolverStatus::kFatal);
  CHECK_THAT(bc.message(), Catch::Contains("pattern differs"));
  bool overwritten = true;
  CHECK(bc.factorize_and_solve_in_place(other.H.get(), b.data(), x.data(), &overwritten) ==
        LinearSolverStatus::kFatal);
  CHECK_FALSE(overwritten);
  CHECK(bc.solve(b.data(), x.data()) == LinearSolverStatus::kFatal);
  REQUIRE(bc.factorize_and_solve_in_place(m.H.get(), b.data(), x.data(), &overwritten) ==
          LinearSolverStatus::kSuccess);
  CHECK(overwritten);
}

TEST_CASE("Block Cholesky rejects structures it cannot factor", "[solver][block_cholesky]") {
  solver::BlockStructure mixed;
  mixed.build({7, 7, 3}, {{0, 1}, {1, 2}});
  BlockCholeskySolver bc;
  CHECK(BlockCholeskySolver::supported_block_size(mixed) == 0);
  CHECK(bc.analyze(mixed) == LinearSolverStatus::kFatal);
  CHECK_THAT(bc.message(), Catch::Contains("size 6 or 7"));
  solver::BlockStructure eliminated;
  eliminated.build({6, 6, 6}, {{0, 1}, {1, 2}}, 1);
  CHECK(BlockCholeskySolver::supported_block_size(eliminated) == 0);
  solver::BlockStructure threes;
  threes.build({3, 3}, {{0, 1}});
  CHECK(BlockCholeskySolver::supported_block_size(threes) == 0);
}

namespace {

template <int B>
void check_block_kernels(std::mt19937* rng) {
  using Mat = Eigen::Matrix<double, B, B>;
  std::normal_distribution<double> n(0.0, 1.0);
  const auto rnd = [&] {
    Mat M;
    for (int i = 0; i < B * B; ++i) M.data()[i] = n(*rng);
    return M;
  };
  // Cholesky + inverse of a random SPD block against Eigen's LLT.
  const Mat J = rnd();
  const Mat D = J.transpose() * J + 0.1 * Mat::Identity();
  Mat L = D, Li;
  L.template triangularView<Eigen::StrictlyUpper>().setConstant(7.0);  // never read
  REQUIRE(solver::detail::cholesky_inverse<B>(L.data(), Li.data()));
  const Mat L_ref = D.llt().matrixL();
  CHECK((L - L_ref).norm() <= 1e-13 * L_ref.norm());
  CHECK((L * Li - Mat::Identity()).norm() <= 1e-12);
  // Substitution with the triangle: L·y = b and Lᵀ·y = b.
  using Vec = Eigen::Matrix<double, B, 1>;
  const Vec rhs = rnd().col(0);
  Vec sol = rhs;
  solver::detail::lower_solve<B>(L.data(), Li.data(), sol.data());
  CHECK((L_ref * sol - rhs).norm() <= 1e-12 * rhs.norm());
  sol = rhs;
  solver::detail::lower_transpose_solve<B>(L.data(), Li.data(), sol.data());
  CHECK((L_ref.transpose() * sol - rhs).norm() <= 1e-12 * rhs.norm());
  Mat bad = D;
  bad(B - 1, B - 1) = -1.0;
  CHECK_FALSE(solver::detail::cholesky_inverse<B>(bad.data(), Li.data()));
  bad = D;
  bad(B - 1, 0) = std::numeric_limits<double>::quiet_NaN();
  CHECK_FALSE(solver::detail::cholesky_inverse<B>(bad.data(), Li.data()));
  bad = D;
  bad(2, 2) = std::numeric_limits<double>::infinity();
  CHECK_FALSE(solver::detail::cholesky_inverse<B>(bad.data(), Li.data()));

  // update(): C_slot(q) -= L_q·L_pᵀ over a column of 4 blocks landing in slots 4..7 (reversed);
  // scale(): L_q <- L_q·Mᵀ. Both kernels against the Eigen expressions.
  std::vector<Mat, Eigen::aligned_allocator<Mat>> blocks(8);
  for (Mat& m : blocks) m = rnd();
  const Mat M = rnd();
  const std::vector<int> row = {3, 2, 1, 0};
  const std::vector<int> slot_of_row = {7, 6, 5, 4};
  std::vector<Mat, Eigen::aligned_allocator<Mat>> ref = blocks;
  for (int q = 0; q < 4; ++q) ref[4 + q] -= blocks[q] * blocks[0].transpose();
  for (int q = 1; q < 4; ++q) ref[q] = ref[q] * M.transpose();
  const auto run = [&](auto kernels) {
    auto b = blocks;
    double* base = b.data()->data();
    decltype(kernels)::update(base, 0, 4, row.data(), slot_of_row.data());
    decltype(kernels)::scale(base, 1, 4, M.data());
    double err = 0.0;
    for (int q = 0; q < 8; ++q) err = std::max(err, (b[q] - ref[q]).norm() / ref[q].norm());
    return err;
  };
  // The substitutions: y_row(q) -= L_q·x, t -= Σ L_qᵀ·y_row(q), on 5 block rows
  // with a block column of 3 (rows 4, 0, 2).
  std::vector<Vec, Eigen::aligned_allocator<Vec>> y(5);
  for (Vec& v : y) v = rnd().col(0);
  const Vec xv = rnd().col(1), t0 = rnd().col(2);
  const std::vector<int> srow = {4, 0, 2};
  auto y_ref = y;
  Vec t_ref = t0;
  for (int q = 0; q < 3; ++q) {
    y_ref[srow[q]] -= blocks[q] * xv;
    t_ref -= blocks[q].transpose() * y[srow[q]];
  }
  const auto subst = [&](auto kernels) {
    using K = decltype(kernels);
    auto yk = y;
    Vec t = t0;
    K::lower_update(blocks.data()->data(), 0, 3, srow.data(), xv.data(), yk.data()->data());
    K::transpose_update(blocks.data()->data(), 0, 3, srow.data(), y.data()->data(), t.data());
    K::transpose_update(blocks.data()->data(), 3, 3, srow.data(), y.data()->data(), t.data());
    // load_transposed() of block 1 seen as the top of a column-major array with stride B + 3.
    Eigen::Matrix<double, B + 3, B> tall = Eigen::Matrix<double, B + 3, B>::Constant(9.0);
    tall.template topRows<B>() = blocks[1];
    Mat tr;
    K::load_transposed(tall.data(), B + 3, tr.data());
    double err = std::max((t - t_ref).norm() / t_ref.norm(), (tr - blocks[1].transpose()).norm());
    for (int r = 0; r < 5; ++r) err = std::max(err, (yk[r] - y_ref[r]).norm() / y_ref[r].norm());
    return err;
  };
  // The in-place factor's kernels on blocks inside column-major panels (stride B + 5, the block
  // at row offset 2): C -= Σ A_q·Bq_qᵀ over 3 pairs, out = C·Mᵀ, t -= Σ L_q·y_q, t -= Σ L_qᵀ·y_q;
  // the panel rows around the blocks must not change.
  constexpr int kStride = B + 5;
  using Panel = Eigen::Matrix<double, kStride, B>;
  std::vector<Panel, Eigen::aligned_allocator<Panel>> panels(6);
  for (Panel& pnl : panels)
    for (int i = 0; i < pnl.size(); ++i) pnl.data()[i] = n(*rng);
  const auto blk = [&](int k) -> Mat { return panels[k].template middleRows<B>(2); };
  const Mat C0 = rnd();
  Mat C_ref = C0;
  for (int q = 0; q < 3; ++q) C_ref -= blk(q) * blk(3 + q).transpose();
  Panel out_ref = panels[0];
  out_ref.template middleRows<B>(2) = C_ref * M.transpose();
  const Vec tv0 = rnd().col(3);
  const Vec mv_ref = tv0 - blk(4) * xv - blk(2) * rhs,
            mtv_ref = tv0 - blk(5).transpose() * rhs - blk(1).transpose() * xv;
  const auto in_place = [&](auto kernels) {
    using K = decltype(kernels);
    const double* A[3] = {panels[0].data() + 2, panels[1].data() + 2, panels[2].data() + 2};
    const double* Bq[3] = {panels[3].data() + 2, panels[4].data() + 2, panels[5].data() + 2};
    Mat C = C0;
    K::nt_sum(C.data(), 3, A, kStride, Bq, kStride);
    double err = (C - C_ref).norm() / C_ref.norm();
    Mat C1 = C0;
    K::nt_sum(C1.data(), 0, A, kStride, Bq, kStride);  // no pairs: C unchanged
    err = std::max(err, (C1 - C0).norm());
    Panel out = panels[0];
    K::scale_store(C.data(), M.data(), out.data() + 2, kStride);
    err = std::max(err, (out - out_ref).norm() / out_ref.norm());
    Vec t = tv0;
    // row_mat_vec_sub over the blocks of panels 4 and 2 with the y blocks 0 and 1.
    const int row_off[2] = {static_cast<int>(panels[4].data() - panels[0].data()) + 2,
                            static_cast<int>(panels[2].data() - panels[0].data()) + 2},
              row_blk[2] = {0, 1};
    Eigen::Matrix<double, 2 * B, 1> yx;
    yx << xv, rhs;
    K::row_mat_vec_sub(panels[0].data(), row_off, kStride, row_blk, 2, yx.data(), t.data());
    err = std::max(err, (t - mv_ref).norm() / mv_ref.norm());
    // transpose_gather over the blocks of panels 5 and 1 (offsets from panel 0's data) with
    // the y blocks 1 and 0.
    t = tv0;
    const int off[2] = {static_cast<int>(panels[5].data() - panels[0].data()) + 2,
                        static_cast<int>(panels[1].data() - panels[0].data()) + 2},
              stride[2] = {kStride, kStride}, yblk[2] = {1, 0};
    Eigen::Matrix<double, 2 * B, 1> yy;
    yy << xv, rhs;
    K::transpose_gather(panels[0].data(), off, stride, yblk, 2, yy.data(), t.data());
    err = std::max(err, (t - mtv_ref).norm() / mtv_ref.norm());
    t = tv0;
    K::transpose_gather(panels[0].data(), off, stride, yblk, 0, yy.data(), t.data());
    err = std::max(err, (t - tv0).norm());
    // The strided substitutions read the triangle through the stride.
    Eigen::Matrix<double, kStride, B> tri = Eigen::Matrix<double, kStride, B>::Constant(3.0);
    tri.template topRows<B>() = L;
    Vec y1 = rhs;
    solver::detail::lower_solve<B>(tri.data(), Li.data(), y1.data(), kStride);
    err = std::max(err, (L_ref * y1 - rhs).norm() / rhs.norm());
    y1 = rhs;
    solver::detail::lower_transpose_solve<B>(tri.data(), Li.data(), y1.data(), kStride);
    return std::max(err, (L_ref.transpose() * y1 - rhs).norm() / rhs.norm());
  };
  CHECK(run(solver::detail::BlockKernelsEigen<B>()) <= 1e-14);
  CHECK(subst(solver::detail::BlockKernelsEigen<B>()) <= 1e-14);
  CHECK(in_place(solver::detail::BlockKernelsEigen<B>()) <= 1e-12);
#ifdef GEODRIFT_AVX2_KERNELS
  if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) {
    CHECK(run(solver::detail::BlockKernelsAvx2<B>()) <= 1e-14);
    CHECK(subst(solver::detail::BlockKernelsAvx2<B>()) <= 1e-14);
    CHECK(in_place(solver::detail::BlockKernelsAvx2<B>()) <= 1e-12);
    // gram(): JᵀJ of a residual block's Jacobian, symmetric to the bit.
    const Mat J = blocks[2];
    const Mat G_ref = J.transpose() * J;
    Mat G;
    solver::detail::BlockKernelsAvx2<B>::gram(J.data(), G.data());
    CHECK((G - G_ref).norm() <= 1e-14 * G_ref.norm());
    CHECK((G - G.transpose()).norm() == 0.0);
  } else {
    WARN("no AVX2/FMA on this CPU: the AVX2 block kernels are not exercised");
  }
#endif
}

}  // namespace

TEST_CASE("Block kernels: Cholesky inverse, Eigen and AVX2 products and substitutions agree",
          "[solver][block_cholesky]") {
  std::mt19937 rng(11);
  for (int rep = 0; rep < 20; ++rep) {
    check_block_kernels<6>(&rng);
    check_block_kernels<7>(&rng);
  }
}
