#pragma once

/// @file
/// Central-difference Jacobians for checking analytic ones (STYLE.md §9), all for LEFT
/// perturbations X ← exp(d)·X of group inputs and, for group-valued outputs, measured through
/// log(f(X')·f(X)⁻¹). Plus `near()`, an elementwise comparison that prints both matrices when it
/// fails. Generic over the group type (anything with kDoF, Tangent, static exp, log, inverse,
/// operator*), so every helper can use it for its own residuals.

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <limits>
#include <type_traits>

namespace geodrift::test {

/// Central-difference Jacobian (rows = size of f, cols = Group::kDoF) of a vector-valued f at
/// group element x, for LEFT perturbations x ← exp(d)·x:
///   col i = (f(exp(h·eᵢ)·x) − f(exp(−h·eᵢ)·x)) / 2h.
template <class Group, class F>
Eigen::MatrixXd numeric_jacobian(const F& f, const Group& x, double h = 1e-6) {
  const Eigen::VectorXd f0 = f(x);
  Eigen::MatrixXd J(f0.size(), Group::kDoF);
  for (int i = 0; i < Group::kDoF; ++i) {
    typename Group::Tangent d = Group::Tangent::Zero();
    d[i] = h;
    const Eigen::VectorXd fp = f(Group::exp(d) * x);
    const Eigen::VectorXd fm = f(Group::exp(-d) * x);
    J.col(i) = (fp - fm) / (2.0 * h);
  }
  return J;
}

/// Central-difference Jacobian of a vector-valued f of a Euclidean vector x (cols = x.size()).
template <class F, class Vec>
Eigen::MatrixXd numeric_jacobian_vector(const F& f, const Vec& x, double h = 1e-6) {
  const Eigen::VectorXd f0 = f(x);
  Eigen::MatrixXd J(f0.size(), x.size());
  for (int i = 0; i < x.size(); ++i) {
    Vec xp = x, xm = x;
    xp[i] += h;
    xm[i] -= h;
    const Eigen::VectorXd fp = f(xp);
    const Eigen::VectorXd fm = f(xm);
    J.col(i) = (fp - fm) / (2.0 * h);
  }
  return J;
}

/// Central-difference Jacobian of a GROUP-valued f at group element x (both sides LEFT):
///   col i = (log(f(exp(h·eᵢ)·x)·f(x)⁻¹) − log(f(exp(−h·eᵢ)·x)·f(x)⁻¹)) / 2h,
/// i.e. d/dd of the left increment of the output. Rows = output group's kDoF.
template <class Group, class F>
Eigen::MatrixXd numeric_group_jacobian(const F& f, const Group& x, double h = 1e-6) {
  const auto y0_inv = f(x).inverse();
  using Out = std::decay_t<decltype(y0_inv)>;
  Eigen::MatrixXd J(Out::kDoF, Group::kDoF);
  for (int i = 0; i < Group::kDoF; ++i) {
    typename Group::Tangent d = Group::Tangent::Zero();
    d[i] = h;
    const typename Out::Tangent lp = (f(Group::exp(d) * x) * y0_inv).log();
    const typename Out::Tangent lm = (f(Group::exp(-d) * x) * y0_inv).log();
    J.col(i) = (lp - lm) / (2.0 * h);
  }
  return J;
}

/// Central-difference Jacobian of a GROUP-valued f of a Euclidean vector x (e.g. exp(ξ)):
///   col i = (log(f(x + h·eᵢ)·f(x)⁻¹) − log(f(x − h·eᵢ)·f(x)⁻¹)) / 2h.
template <class F, class Vec>
Eigen::MatrixXd numeric_group_jacobian_vector(const F& f, const Vec& x, double h = 1e-6) {
  const auto y0_inv = f(x).inverse();
  using Out = std::decay_t<decltype(y0_inv)>;
  Eigen::MatrixXd J(Out::kDoF, x.size());
  for (int i = 0; i < x.size(); ++i) {
    Vec xp = x, xm = x;
    xp[i] += h;
    xm[i] -= h;
    const typename Out::Tangent lp = (f(xp) * y0_inv).log();
    const typename Out::Tangent lm = (f(xm) * y0_inv).log();
    J.col(i) = (lp - lm) / (2.0 * h);
  }
  return J;
}

/// Absolute error that rounding alone puts into a central difference with step h of a
/// function of magnitude f_scale (|f|∞ of the values differenced): ~ c·eps·|f|/h. Add it to
/// near()'s floor so that 1e4 m translations are not mistaken for Jacobian errors; a wrong
/// term is still orders of magnitude above it.
inline double rounding_floor(double f_scale, double h, double c = 64.0) {
  return c * std::numeric_limits<double>::epsilon() * (1.0 + f_scale) / h;
}

/// Elementwise |A − B| ≤ tol·(1 + |B|) + floor (B = the reference, e.g. numeric). On failure
/// prints both matrices, their difference and the worst element to std::cerr (the first 20
/// failures of the process only, to keep logs readable) and returns false.
template <class DA, class DB>
bool near(const Eigen::MatrixBase<DA>& A, const Eigen::MatrixBase<DB>& B, double tol,
          double floor = 0.0) {
  if (A.rows() != B.rows() || A.cols() != B.cols()) {
    std::cerr << "near(): shape mismatch " << A.rows() << "x" << A.cols() << " vs " << B.rows()
              << "x" << B.cols() << "\n";
    return false;
  }
  const Eigen::MatrixXd a = A.template cast<double>(), b = B.template cast<double>();
  double worst = 0.0;
  int wi = 0, wj = 0;
  bool ok = a.allFinite() && b.allFinite();
  for (int j = 0; j < a.cols(); ++j) {
    for (int i = 0; i < a.rows(); ++i) {
      const double err = std::abs(a(i, j) - b(i, j));
      const double lim = tol * (1.0 + std::abs(b(i, j))) + floor;
      if (!(err <= lim)) ok = false;
      const double ratio = err / lim;
      if (ratio > worst) worst = ratio, wi = i, wj = j;
    }
  }
  if (!ok) {
    static int printed = 0;
    if (printed++ < 20) {
      const Eigen::IOFormat fmt(10, 0, " ", "\n", "  [", "]");
      std::cerr << "near() failed (tol " << tol << ", floor " << floor << "): worst (" << wi << ","
                << wj << ") " << a(wi, wj) << " vs " << b(wi, wj) << "\nA =\n"
                << a.format(fmt) << "\nB =\n"
                << b.format(fmt) << "\nA - B =\n"
                << (a - b).format(fmt) << "\n";
    }
  }
  return ok;
}

}  // namespace geodrift::test
