#pragma once

/// @file
/// Reader for g2o 3D pose-graph files (VERTEX_SE3:QUAT, EDGE_SE3:QUAT, FIX).
///
/// File conventions (g2o, as written by g2o's `VertexSE3`/`EdgeSE3` and the SE-Sync datasets):
///   VERTEX_SE3:QUAT id x y z qx qy qz qw
///       the pose of body i in the world, T_wi (body -> world): p_w = R·p_i + t.
///   EDGE_SE3:QUAT i j x y z qx qy qz qw  I11 I12 I13 I14 I15 I16  I22 ... I66
///       the measurement Z_ij = T_wi⁻¹·T_wj (frame j expressed in frame i) and the upper
///       triangle (row-major, 21 numbers) of its 6x6 information matrix in g2o's tangent order
///       (translation x y z, rotation rx ry rz).
///   FIX id [id ...]
///       vertices held constant.
/// Any other tag (VERTEX_SE2, EDGE_SE3_PRIOR, PARAMS_SE3OFFSET, ...) is skipped and counted in
/// G2oPoseGraph3D::skipped_tags; blank lines and lines starting with '#' are ignored.
///
/// geodrift's convention (DESIGN.md) is the tangent order (omega, nu) and poses stored as
/// world -> body; G2oEdgeSE3::information_omega_nu() gives the information matrix permuted to
/// (omega, nu). Quaternions are normalised on reading (files carry 6-7 significant digits);
/// a quaternion that is far from unit length (|‖q‖ − 1| > 1e-3) is an error.

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <istream>
#include <map>
#include <sstream>
#include <string>
#include <unordered_map>
#include <vector>

#include "geodrift/error.hpp"

namespace geodrift::io {

/// One VERTEX_SE3:QUAT line: the pose T_wi (body i -> world) as rotation + translation.
struct G2oVertexSE3 {
  int id = 0;
  Eigen::Quaterniond q_wi = Eigen::Quaterniond::Identity();  ///< unit quaternion (normalised)
  Eigen::Vector3d t_wi = Eigen::Vector3d::Zero();            ///< position of body i in world [m]
  int line = 0;                                              ///< 1-based line in the file

  /// The 4x4 homogeneous T_wi.
  Eigen::Matrix4d matrix() const {
    Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
    T.topLeftCorner<3, 3>() = q_wi.toRotationMatrix();
    T.topRightCorner<3, 1>() = t_wi;
    return T;
  }
};

/// One EDGE_SE3:QUAT line: the relative pose Z_ij = T_wi⁻¹·T_wj and its information matrix.
struct G2oEdgeSE3 {
  int i = 0;  ///< id of the first vertex (as written in the file, not an index)
  int j = 0;  ///< id of the second vertex
  Eigen::Quaterniond q_ij = Eigen::Quaterniond::Identity();  ///< rotation of Z_ij (normalised)
  Eigen::Vector3d t_ij = Eigen::Vector3d::Zero();            ///< translation of Z_ij [m]
  /// Information matrix in g2o's tangent order (x, y, z, rx, ry, rz), symmetric, as in the file.
  /// It may be indefinite (cubicle.g2o): see sqrt_information_omega_nu().
  Eigen::Matrix<double, 6, 6> information_g2o = Eigen::Matrix<double, 6, 6>::Identity();
  int line = 0;  ///< 1-based line in the file

  /// The 4x4 homogeneous Z_ij.
  Eigen::Matrix4d matrix() const {
    Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
    T.topLeftCorner<3, 3>() = q_ij.toRotationMatrix();
    T.topRightCorner<3, 1>() = t_ij;
    return T;
  }

  /// The information matrix permuted to geodrift's tangent order (omega, nu):
  /// Ω' = P·Ω·Pᵀ with P mapping (x, y, z, rx, ry, rz) to (rx, ry, rz, x, y, z).
  Eigen::Matrix<double, 6, 6> information_omega_nu() const {
    Eigen::Matrix<double, 6, 6> out;
    for (int r = 0; r < 6; ++r) {
      for (int c = 0; c < 6; ++c) out(r, c) = information_g2o((r + 3) % 6, (c + 3) % 6);
    }
    return out;
  }

  /// Square-root weight L with Lᵀ·L = Ω⁺, the information matrix in (omega, nu) order made
  /// positive semidefinite, so that ½‖L·r‖² = ½ rᵀ·Ω⁺·r for r in (omega, nu) order:
  ///  - Ω positive definite (every edge of sphere2500, parking-garage, torus3D): Ω⁺ = Ω and L
  ///    is the upper Cholesky factor;
  ///  - Ω indefinite (5021 of cubicle's 16869 edges carry indefinite matrices, e.g. eigenvalues
  ///    -1.6e5 ... 1.7e7, for which ½ rᵀΩr is unbounded below): Ω⁺ = V·max(Λ, 0)·Vᵀ, the
  ///    nearest positive semidefinite matrix in the Frobenius norm (Higham 1988), and
  ///    L = max(Λ, 0)^½·Vᵀ. Every solver fed from this function (ours and the Ceres twin)
  ///    minimises the same cost.
  Eigen::Matrix<double, 6, 6> sqrt_information_omega_nu() const {
    const Eigen::Matrix<double, 6, 6> I = information_omega_nu();
    const Eigen::LLT<Eigen::Matrix<double, 6, 6>> llt(I);
    if (llt.info() == Eigen::Success) return llt.matrixU();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> es(I);
    const Eigen::Matrix<double, 6, 1> s = es.eigenvalues().cwiseMax(0.0).cwiseSqrt();
    return s.asDiagonal() * es.eigenvectors().transpose();
  }

  /// True if the information matrix as written in the file is positive definite.
  bool information_is_positive_definite() const {
    return Eigen::LLT<Eigen::Matrix<double, 6, 6>>(information_g2o).info() == Eigen::Success;
  }
};

/// A 3D pose graph as read from a g2o file, in file order.
struct G2oPoseGraph3D {
  std::vector<G2oVertexSE3> vertices;
  std::vector<G2oEdgeSE3> edges;
  std::vector<int> fixed_ids;                ///< ids named on FIX lines, in file order
  std::map<std::string, int> skipped_tags;   ///< unknown tag -> number of lines skipped
  std::unordered_map<int, int> index_of_id;  ///< vertex id -> index into `vertices`
  /// Edges whose information matrix is not positive definite (see
  /// G2oEdgeSE3::sqrt_information_omega_nu() for how they are used).
  int num_indefinite_information = 0;

  /// Index into `vertices` of the vertex with this id. @throws InvalidArgument if absent.
  int index(int id) const {
    const auto it = index_of_id.find(id);
    GEODRIFT_CHECK(it != index_of_id.end(), "g2o vertex id " << id << " does not exist");
    return it->second;
  }
  /// Total number of skipped lines (all unknown tags).
  int num_skipped_lines() const {
    int n = 0;
    for (const auto& kv : skipped_tags) n += kv.second;
    return n;
  }
};

namespace detail_g2o {

/// Throws InvalidArgument "<name>:<line>: <what>".
[[noreturn]] inline void fail(const std::string& name, int line, const std::string& what) {
  std::ostringstream os;
  os << name << ":" << line << ": " << what;
  throw InvalidArgument(os.str());
}

/// Parses field `k` of `tokens` as a finite double.
inline double to_double(const std::vector<std::string>& tokens, std::size_t k,
                        const std::string& name, int line, const char* field) {
  const std::string& s = tokens[k];
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  if (end == s.c_str() || *end != '\0' || !std::isfinite(v)) {
    fail(name, line,
         std::string(tokens[0]) + " field " + std::to_string(k) + " (" + field + "): '" + s +
             "' is not a finite number");
  }
  return v;
}

/// Parses field `k` of `tokens` as a non-negative integer id.
inline int to_id(const std::vector<std::string>& tokens, std::size_t k, const std::string& name,
                 int line, const char* field) {
  const std::string& s = tokens[k];
  char* end = nullptr;
  const long v = std::strtol(s.c_str(), &end, 10);
  if (end == s.c_str() || *end != '\0' || v < 0 || v > 2147483647L) {
    fail(name, line,
         std::string(tokens[0]) + " field " + std::to_string(k) + " (" + field + "): '" + s +
             "' is not a non-negative integer id");
  }
  return static_cast<int>(v);
}

/// Reads fields k..k+6 (x y z qx qy qz qw) into t and a normalised q.
inline void read_pose(const std::vector<std::string>& tok, std::size_t k, const std::string& name,
                      int line, Eigen::Vector3d* t, Eigen::Quaterniond* q) {
  static const char* kFields[7] = {"x", "y", "z", "qx", "qy", "qz", "qw"};
  double v[7];
  for (int m = 0; m < 7; ++m) v[m] = to_double(tok, k + m, name, line, kFields[m]);
  *t = Eigen::Vector3d(v[0], v[1], v[2]);
  *q = Eigen::Quaterniond(v[6], v[3], v[4], v[5]);
  const double norm = q->norm();
  if (!(std::abs(norm - 1.0) <= 1e-3)) {
    std::ostringstream os;
    os << tok[0] << ": quaternion norm " << norm << " is not 1 (tolerance 1e-3)";
    fail(name, line, os.str());
  }
  q->normalize();
}

inline std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  std::istringstream is(s);
  std::string w;
  while (is >> w) out.push_back(w);
  return out;
}

}  // namespace detail_g2o

/// Parses a g2o 3D pose graph from a stream. `name` is used in error messages (a path).
/// @throws InvalidArgument "<name>:<line>: <what>" on a malformed line (wrong field count,
///         non-numeric or non-finite field, non-unit quaternion, information matrix without
///         any positive eigenvalue, duplicate vertex id, edge or FIX naming an unknown vertex,
///         self-loop edge), or if the graph has no vertex.
inline G2oPoseGraph3D parse_g2o_se3(std::istream& in, const std::string& name) {
  using detail_g2o::fail;
  G2oPoseGraph3D g;
  std::vector<int> fix_lines;
  std::string text;
  int line = 0;
  while (std::getline(in, text)) {
    ++line;
    const std::vector<std::string> tok = detail_g2o::split(text);
    if (tok.empty() || tok[0][0] == '#') continue;
    const std::string& tag = tok[0];
    if (tag == "VERTEX_SE3:QUAT") {
      if (tok.size() != 9) {
        fail(name, line,
             "VERTEX_SE3:QUAT needs 8 fields (id x y z qx qy qz qw), got " +
                 std::to_string(tok.size() - 1));
      }
      G2oVertexSE3 v;
      v.id = detail_g2o::to_id(tok, 1, name, line, "id");
      detail_g2o::read_pose(tok, 2, name, line, &v.t_wi, &v.q_wi);
      v.line = line;
      if (!g.index_of_id.emplace(v.id, static_cast<int>(g.vertices.size())).second) {
        fail(name, line,
             "duplicate vertex id " + std::to_string(v.id) + " (first defined on line " +
                 std::to_string(g.vertices[static_cast<std::size_t>(g.index_of_id[v.id])].line) +
                 ")");
      }
      g.vertices.push_back(v);
    } else if (tag == "EDGE_SE3:QUAT") {
      if (tok.size() != 31) {
        fail(name, line,
             "EDGE_SE3:QUAT needs 30 fields (i j x y z qx qy qz qw + 21 information entries), "
             "got " +
                 std::to_string(tok.size() - 1));
      }
      G2oEdgeSE3 e;
      e.i = detail_g2o::to_id(tok, 1, name, line, "i");
      e.j = detail_g2o::to_id(tok, 2, name, line, "j");
      if (e.i == e.j)
        fail(name, line, "edge connects vertex " + std::to_string(e.i) + " to itself");
      detail_g2o::read_pose(tok, 3, name, line, &e.t_ij, &e.q_ij);
      std::size_t k = 10;
      for (int r = 0; r < 6; ++r) {
        for (int c = r; c < 6; ++c) {
          const double v = detail_g2o::to_double(tok, k++, name, line, "information");
          e.information_g2o(r, c) = v;
          e.information_g2o(c, r) = v;
        }
      }
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> es(e.information_g2o,
                                                                          Eigen::EigenvaluesOnly);
      if (!(es.eigenvalues()(5) > 0.0)) {
        fail(name, line,
             "EDGE_SE3:QUAT information matrix has no positive eigenvalue (carries no "
             "information)");
      }
      if (!(es.eigenvalues()(0) > 0.0)) ++g.num_indefinite_information;
      e.line = line;
      g.edges.push_back(e);
    } else if (tag == "FIX") {
      if (tok.size() < 2) fail(name, line, "FIX needs at least one vertex id");
      for (std::size_t k = 1; k < tok.size(); ++k) {
        g.fixed_ids.push_back(detail_g2o::to_id(tok, k, name, line, "id"));
        fix_lines.push_back(line);
      }
    } else {
      ++g.skipped_tags[tag];
    }
  }
  GEODRIFT_CHECK(!in.bad(), name << ": read error after line " << line);
  // References are checked after the whole file is read: g2o allows edges before vertices.
  for (const G2oEdgeSE3& e : g.edges) {
    for (const int id : {e.i, e.j}) {
      if (!g.index_of_id.count(id)) {
        fail(name, e.line,
             "EDGE_SE3:QUAT references vertex id " + std::to_string(id) +
                 " that no VERTEX_SE3:QUAT line defines");
      }
    }
  }
  for (std::size_t k = 0; k < g.fixed_ids.size(); ++k) {
    if (!g.index_of_id.count(g.fixed_ids[k])) {
      fail(name, fix_lines[k],
           "FIX references vertex id " + std::to_string(g.fixed_ids[k]) + " that does not exist");
    }
  }
  GEODRIFT_CHECK(!g.vertices.empty(), name << ": no VERTEX_SE3:QUAT line (is this a 3D graph?)");
  return g;
}

/// Reads a g2o 3D pose graph file. @throws InvalidArgument naming the path if it cannot be
/// opened, and "<path>:<line>: <what>" on malformed content (see parse_g2o_se3).
inline G2oPoseGraph3D read_g2o_se3(const std::string& path) {
  std::ifstream in(path);
  GEODRIFT_CHECK(in.is_open(), "cannot open g2o file '" << path << "'");
  return parse_g2o_se3(in, path);
}

}  // namespace geodrift::io
