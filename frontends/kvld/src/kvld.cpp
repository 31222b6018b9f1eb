// K-VLD main loop and retry driver (kvld.md §3.5).
#include "geodrift/kvld/kvld.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <sstream>
#include <unordered_map>

#include "geodrift/error.hpp"

namespace geodrift::kvld {
namespace {

constexpr double kPi = 3.14159265358979323846264338327950;

/// Sparse consistency cache (the reference's dense N×N matrix E): absent = untested,
/// kRejected = tested and inconsistent, ≥ 0 = VLD difference D of a consistent pair. Float
/// storage: D only matters against the 0.35 threshold and in tie-breaking sums.
class ConsistencyCache {
 public:
  static constexpr float kRejected = -2.0f;
  explicit ConsistencyCache(std::size_t reserve) { map_.reserve(reserve); }
  /// Returns nullptr if (i, j), i < j, was never tested.
  const float* find(int i, int j) const {
    const auto it = map_.find(key(i, j));
    return it == map_.end() ? nullptr : &it->second;
  }
  void set(int i, int j, float v) { map_[key(i, j)] = v; }
  std::size_t size() const { return map_.size(); }

 private:
  static std::uint64_t key(int i, int j) {
    return (static_cast<std::uint64_t>(static_cast<std::uint32_t>(i)) << 32) |
           static_cast<std::uint32_t>(j);
  }
  std::unordered_map<std::uint64_t, float> map_;
};

/// Neighbour pairs of one run (fixed for the run: the range and min_dist tests depend only on
/// positions). CSR adjacency, each row sorted ascending, with the geometric consistency of the
/// pair (symmetric) cached next to it.
struct Neighbourhood {
  std::vector<int> begin;  // size N+1
  std::vector<int> nbr;
  std::vector<float> geo;  // geometric_consistency of (row, nbr), +inf when geometry is off
};

struct Problem {
  const ImageScale& s1;
  const ImageScale& s2;
  const std::vector<Keypoint>& F1;
  const std::vector<Keypoint>& F2;
  const std::vector<Match>& M;
  const Options& opt;
};

double neighbourhood_range(const ImageScale& s, std::size_t num_features, std::size_t num_matches,
                           double inlier_rate, double range_ratio) {
  const double n = static_cast<double>(std::min(num_features, num_matches));
  return range_ratio * std::sqrt(3.0 * s.width() * s.height() / (kPi * inlier_rate * n));
}

Neighbourhood build_neighbourhood(const Problem& p, double range1, double range2) {
  const int n = static_cast<int>(p.M.size());
  Neighbourhood nb;
  nb.begin.assign(static_cast<std::size_t>(n) + 1, 0);
  std::vector<std::vector<int>> rows(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) {
    const Keypoint& a1 = p.F1[static_cast<std::size_t>(p.M[static_cast<std::size_t>(i)].i1)];
    const Keypoint& b1 = p.F2[static_cast<std::size_t>(p.M[static_cast<std::size_t>(i)].i2)];
    for (int j = i + 1; j < n; ++j) {
      const Keypoint& a2 = p.F1[static_cast<std::size_t>(p.M[static_cast<std::size_t>(j)].i1)];
      const Keypoint& b2 = p.F2[static_cast<std::size_t>(p.M[static_cast<std::size_t>(j)].i2)];
      const double d1 = std::hypot(a1.x - a2.x, a1.y - a2.y);
      const double d2 = std::hypot(b1.x - b2.x, b1.y - b2.y);
      if (d1 > p.opt.min_dist && d2 > p.opt.min_dist && (d1 < range1 || d2 < range2)) {
        rows[static_cast<std::size_t>(i)].push_back(j);
        rows[static_cast<std::size_t>(j)].push_back(i);
      }
    }
  }
  std::size_t total = 0;
  for (const auto& r : rows) total += r.size();
  nb.nbr.reserve(total);
  nb.geo.reserve(total);
  for (int i = 0; i < n; ++i) {
    const Match& mi = p.M[static_cast<std::size_t>(i)];
    for (int j : rows[static_cast<std::size_t>(i)]) {  // ascending: j < i first, then j > i
      nb.nbr.push_back(j);
      float g = std::numeric_limits<float>::infinity();
      if (p.opt.geometry) {
        const Match& mj = p.M[static_cast<std::size_t>(j)];
        g = static_cast<float>(geometric_consistency(
            p.F1[static_cast<std::size_t>(mi.i1)], p.F1[static_cast<std::size_t>(mj.i1)],
            p.F2[static_cast<std::size_t>(mi.i2)], p.F2[static_cast<std::size_t>(mj.i2)]));
      }
      nb.geo.push_back(g);
    }
    nb.begin[static_cast<std::size_t>(i) + 1] = static_cast<int>(nb.nbr.size());
  }
  return nb;
}

struct RunOutput {
  std::vector<char> valid;
  std::vector<double> score;
  std::vector<int> result;
};

/// One K-VLD run (the reference's KVLD()) with the given inlier rate and K.
RunOutput run_once(const Problem& p, double inlier_rate, int K, ConsistencyCache* E,
                   std::size_t* vld_pairs) {
  const int n = static_cast<int>(p.M.size());
  const Options& opt = p.opt;
  const double range1 =
      neighbourhood_range(p.s1, p.F1.size(), p.M.size(), inlier_rate, opt.range_ratio);
  const double range2 =
      neighbourhood_range(p.s2, p.F2.size(), p.M.size(), inlier_rate, opt.range_ratio);
  const Neighbourhood nb = build_neighbourhood(p, range1, range2);

  RunOutput out;
  out.valid.assign(static_cast<std::size_t>(n), 1);
  out.score.assign(static_cast<std::size_t>(n), 0.0);
  out.result.assign(static_cast<std::size_t>(n), 0);
  std::vector<char>& valid = out.valid;
  std::vector<double>& score = out.score;
  std::vector<int>& result = out.result;
  const auto kp1 = [&](int m) -> const Keypoint& {
    return p.F1[static_cast<std::size_t>(p.M[static_cast<std::size_t>(m)].i1)];
  };
  const auto kp2 = [&](int m) -> const Keypoint& {
    return p.F2[static_cast<std::size_t>(p.M[static_cast<std::size_t>(m)].i2)];
  };

  bool change = true;
  while (change) {
    change = false;
    std::fill(score.begin(), score.end(), 0.0);
    std::fill(result.begin(), result.end(), 0);

    // 1. Score: VLD-test (and geometry-gate) every untested neighbour pair, count consistent
    //    neighbours; a match's forward scan stops at max_connection.
    for (int i = 0; i < n; ++i) {
      if (!valid[static_cast<std::size_t>(i)]) continue;
      const int row_end = nb.begin[static_cast<std::size_t>(i) + 1];
      // Forward neighbours (j > i) start after the backward ones in the sorted row.
      int k =
          static_cast<int>(std::upper_bound(nb.nbr.begin() + nb.begin[static_cast<std::size_t>(i)],
                                            nb.nbr.begin() + row_end, i) -
                           nb.nbr.begin());
      for (; k < row_end; ++k) {
        const int j = nb.nbr[static_cast<std::size_t>(k)];
        if (!valid[static_cast<std::size_t>(j)]) continue;
        const float* cached = E->find(i, j);
        float e;
        if (cached) {
          e = *cached;
        } else {
          e = ConsistencyCache::kRejected;
          if (!opt.geometry || nb.geo[static_cast<std::size_t>(k)] < opt.distance_thres) {
            const Keypoint& a1 = kp1(i);
            const Keypoint& a2 = kp1(j);
            const Keypoint& b1 = kp2(i);
            const Keypoint& b2 = kp2(j);
            const Vld v1 = compute_vld(p.s1, a1.x, a1.y, a2.x, a2.y);
            const Vld v2 = compute_vld(p.s2, b1.x, b1.y, b2.x, b2.y);
            ++*vld_pairs;
            const double d = vld_difference(v1, v2, opt.max_contrast);
            if (d < opt.juge) e = static_cast<float>(d);
          }
          E->set(i, j, e);
        }
        if (e >= 0.0f) {
          ++result[static_cast<std::size_t>(i)];
          ++result[static_cast<std::size_t>(j)];
          score[static_cast<std::size_t>(i)] += e;
          score[static_cast<std::size_t>(j)] += e;
          if (result[static_cast<std::size_t>(i)] >= opt.max_connection) break;
        }
      }
    }

    // 2. K rule.
    for (int i = 0; i < n; ++i) {
      if (valid[static_cast<std::size_t>(i)] && result[static_cast<std::size_t>(i)] < K) {
        valid[static_cast<std::size_t>(i)] = 0;
        change = true;
      }
    }

    // 3. Uniqueness: of two valid matches sharing an endpoint (or a position on one side but
    //    not the other) keep the one with more consistent neighbours, then the lower summed D.
    //    As in the reference, the scan over j continues after i itself has been removed.
    if (opt.unique_match) {
      for (int i = 0; i + 1 < n; ++i) {
        if (!valid[static_cast<std::size_t>(i)]) continue;
        const Match& mi = p.M[static_cast<std::size_t>(i)];
        const Keypoint& a1 = kp1(i);
        const Keypoint& b1 = kp2(i);
        for (int j = i + 1; j < n; ++j) {
          if (!valid[static_cast<std::size_t>(j)]) continue;
          const Match& mj = p.M[static_cast<std::size_t>(j)];
          const Keypoint& a2 = kp1(j);
          const Keypoint& b2 = kp2(j);
          const bool same1 = a1.x == a2.x && a1.y == a2.y;
          const bool same2 = b1.x == b2.x && b1.y == b2.y;
          if (!(mi.i1 == mj.i1 || mi.i2 == mj.i2 || same1 != same2)) continue;
          const int ri = result[static_cast<std::size_t>(i)];
          const int rj = result[static_cast<std::size_t>(j)];
          const double si = score[static_cast<std::size_t>(i)];
          const double sj = score[static_cast<std::size_t>(j)];
          if (ri > rj || (ri == rj && si < sj)) {
            valid[static_cast<std::size_t>(j)] = 0;
            change = true;
          } else if (ri < rj || (ri == rj && si > sj)) {
            valid[static_cast<std::size_t>(i)] = 0;
            change = true;
          }
        }
      }
    }

    // 4. Geometric re-scoring: mean consistency error over all valid neighbours; remove a
    //    match when fewer than 30 % are below distance_thres and the mean exceeds 1.2.
    if (opt.unique_match && opt.geometry) {
      std::vector<int> remove;
      for (int i = 0; i < n; ++i) {
        if (!valid[static_cast<std::size_t>(i)]) {
          score[static_cast<std::size_t>(i)] = 0.0;
          continue;
        }
        double sum = 0.0;
        int count = 0, good = 0;
        for (int k = nb.begin[static_cast<std::size_t>(i)];
             k < nb.begin[static_cast<std::size_t>(i) + 1]; ++k) {
          if (!valid[static_cast<std::size_t>(nb.nbr[static_cast<std::size_t>(k)])]) continue;
          const double g = nb.geo[static_cast<std::size_t>(k)];
          sum += g;
          ++count;
          if (g < opt.distance_thres) ++good;
        }
        if (count == 0) {
          // The reference divides 0 by 0 here and keeps the match; we keep it with +inf.
          score[static_cast<std::size_t>(i)] = std::numeric_limits<double>::infinity();
          continue;
        }
        const double mean = sum / count;
        score[static_cast<std::size_t>(i)] = mean;
        if (good < 0.3 * count && mean > 1.2) remove.push_back(i);
      }
      for (int i : remove) valid[static_cast<std::size_t>(i)] = 0;
      if (!remove.empty()) change = true;
    }
  }
  return out;
}

void check_inputs(const ImageScale& s1, const ImageScale& s2, const std::vector<Keypoint>& F1,
                  const std::vector<Keypoint>& F2, const std::vector<Match>& M,
                  const Options& opt) {
  std::string why;
  GEODRIFT_CHECK(opt.validate(&why), "kvld::filter: invalid options: " << why);
  const auto check_set = [&](const std::vector<Keypoint>& F, const ImageScale& s, int which) {
    for (std::size_t k = 0; k < F.size(); ++k) {
      const Keypoint& q = F[k];
      GEODRIFT_CHECK(std::isfinite(q.x) && std::isfinite(q.y), "kvld::filter: keypoint "
                                                                   << k << " of image " << which
                                                                   << " has a non-finite position ("
                                                                   << q.x << ", " << q.y << ")");
      GEODRIFT_CHECK(q.x >= 0 && q.y >= 0 && q.x <= s.width() - 1 && q.y <= s.height() - 1,
                     "kvld::filter: keypoint " << k << " of image " << which << " at (" << q.x
                                               << ", " << q.y << ") is outside the " << s.width()
                                               << "x" << s.height() << " image");
      if (opt.geometry) {
        GEODRIFT_CHECK(std::isfinite(q.scale) && q.scale > 0,
                       "kvld::filter: keypoint " << k << " of image " << which << " has scale "
                                                 << q.scale << " (must be > 0 with geometry on)");
        GEODRIFT_CHECK(std::isfinite(q.angle),
                       "kvld::filter: keypoint "
                           << k << " of image " << which << " has a non-finite angle " << q.angle
                           << " (geometry on needs orientations; was KeyPoint::angle -1?)");
      }
    }
  };
  check_set(F1, s1, 1);
  check_set(F2, s2, 2);
  GEODRIFT_CHECK(M.size() < static_cast<std::size_t>(std::numeric_limits<int>::max()),
                 "kvld::filter: too many matches (" << M.size() << ")");
  for (std::size_t k = 0; k < M.size(); ++k) {
    GEODRIFT_CHECK(M[k].i1 >= 0 && static_cast<std::size_t>(M[k].i1) < F1.size(),
                   "kvld::filter: match " << k << " refers to keypoint " << M[k].i1
                                          << " of image 1, which has " << F1.size());
    GEODRIFT_CHECK(M[k].i2 >= 0 && static_cast<std::size_t>(M[k].i2) < F2.size(),
                   "kvld::filter: match " << k << " refers to keypoint " << M[k].i2
                                          << " of image 2, which has " << F2.size());
  }
}

}  // namespace

bool Options::validate(std::string* why) const {
  std::ostringstream os;
  if (!(std::isfinite(inlier_rate) && inlier_rate > 0 && inlier_rate <= 1)) {
    os << "inlier_rate " << inlier_rate << " outside (0, 1]";
  } else if (K < 1) {
    os << "K " << K << " must be >= 1";
  } else if (retry_K < 1) {
    os << "retry_K " << retry_K << " must be >= 1";
  } else if (!(std::isfinite(juge) && juge > 0)) {
    os << "juge " << juge << " must be > 0";
  } else if (!(std::isfinite(distance_thres) && distance_thres > 0)) {
    os << "distance_thres " << distance_thres << " must be > 0";
  } else if (!(std::isfinite(min_dist) && min_dist >= 0)) {
    os << "min_dist " << min_dist << " must be >= 0";
  } else if (max_connection < 1) {
    os << "max_connection " << max_connection << " must be >= 1";
  } else if (!(std::isfinite(max_contrast) && max_contrast > 0)) {
    os << "max_contrast " << max_contrast << " must be > 0";
  } else if (!(std::isfinite(range_ratio) && range_ratio > 0)) {
    os << "range_ratio " << range_ratio << " must be > 0";
  } else if (max_runs < 1) {
    os << "max_runs " << max_runs << " must be >= 1";
  }
  const std::string msg = os.str();
  if (why) *why = msg;
  return msg.empty();
}

std::vector<Keypoint> keypoints_from_cv(const std::vector<cv::KeyPoint>& keypoints) {
  std::vector<Keypoint> out;
  out.reserve(keypoints.size());
  for (const cv::KeyPoint& k : keypoints) {
    Keypoint q;
    q.x = k.pt.x;
    q.y = k.pt.y;
    q.scale = k.size;
    q.angle = k.angle < 0 ? std::numeric_limits<double>::quiet_NaN() : k.angle * (kPi / 180.0);
    out.push_back(q);
  }
  return out;
}

Result filter(const ImageScale& scale1, const ImageScale& scale2, const std::vector<Keypoint>& F1,
              const std::vector<Keypoint>& F2, const std::vector<Match>& putative,
              const Options& options) {
  check_inputs(scale1, scale2, F1, F2, putative, options);
  Result res;
  if (putative.empty()) return res;
  const Problem prob{scale1, scale2, F1, F2, putative, options};
  ConsistencyCache E(putative.size() * 64);
  double p = options.inlier_rate;
  int K = options.K;
  RunOutput run;
  std::size_t kept = 0;
  // Driver schedule (kvld_filter.cpp): retry with half the inlier rate and K = 2 while the
  // survival ratio stays below the inlier rate, at most max_runs runs in all.
  while (true) {
    run = run_once(prob, p, K, &E, &res.vld_pairs);
    ++res.runs;
    kept = static_cast<std::size_t>(std::count(run.valid.begin(), run.valid.end(), 1));
    const double ratio = static_cast<double>(kept) / static_cast<double>(putative.size());
    res.final_inlier_rate = p;
    res.final_K = K;
    res.survival_ratio = ratio;
    if (!(ratio < p) || res.runs >= options.max_runs) break;
    p *= 0.5;
    K = options.retry_K;
  }
  res.tested_pairs = E.size();
  for (std::size_t i = 0; i < putative.size(); ++i) {
    if (!run.valid[i]) continue;
    res.matches.push_back(putative[i]);
    res.kept_indices.push_back(static_cast<int>(i));
    res.scores.push_back(run.score[i]);
    res.num_consistent.push_back(run.result[i]);
  }
  if (options.collect_edges) {
    for (std::size_t a = 0; a < res.kept_indices.size(); ++a) {
      for (std::size_t b = a + 1; b < res.kept_indices.size(); ++b) {
        const float* e = E.find(res.kept_indices[a], res.kept_indices[b]);
        if (e && *e >= 0.0f) res.edges.push_back({res.kept_indices[a], res.kept_indices[b], *e});
      }
    }
  }
  return res;
}

}  // namespace geodrift::kvld
