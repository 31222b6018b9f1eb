// Minimal ORB monocular SfM: tracking + local mapping in a fixed order, mapping overlapped with
// the next frame's ORB extraction (see odometry.hpp).

#include "geodrift/vo/odometry.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstring>
#include <future>
#include <map>
#include <opencv2/calib3d.hpp>
#include <sstream>
#include <unordered_map>
#include <unordered_set>

#include "geodrift/error.hpp"
#include "geodrift/solver/levenberg_marquardt.hpp"
#include "geodrift/solver/problem.hpp"
#include "geodrift/solver/residuals/reprojection.hpp"

namespace geodrift::vo {
namespace {

constexpr double kChi2_2 = 5.991;  // 95 % quantile, 2 dof
constexpr int kThHigh = 100;       // ORB-SLAM's descriptor thresholds (Hamming, 256 bits)
constexpr int kThLow = 50;
constexpr int kGridCell = 32;

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

using Desc = std::array<std::uint8_t, 32>;

/// The smallest and second-smallest descriptor distances offered, with the best candidate.
struct BestTwo {
  int best = 256, second = 256, index = -1;
  void offer(int d, int k) {
    if (d < best) {
      second = best;
      best = d;
      index = k;
    } else if (d < second) {
      second = d;
    }
  }
  /// A candidate exists, is within `max_distance` and passes the ratio test.
  bool accepted(int max_distance, double ratio) const {
    return index >= 0 && best <= max_distance && best <= ratio * second;
  }
};

/// One-to-one matching (ORB-SLAM's rotation-free variant): query i claims candidate k at
/// distance d unless k already holds an owner at a distance <= d; a displaced owner loses its
/// match. match[i] = candidate of query i or -1.
struct OneToOne {
  std::vector<int> match, owner, owner_d;
  OneToOne(std::size_t queries, std::size_t candidates)
      : match(queries, -1), owner(candidates, -1), owner_d(candidates, 256) {}
  void claim(int i, int k, int d) {
    if (owner[k] >= 0) {
      if (d >= owner_d[k]) return;
      match[owner[k]] = -1;
    }
    owner[k] = i;
    owner_d[k] = d;
    match[i] = k;
  }
};

/// Keypoints of one image with a cell index for radius queries.
struct FrameData {
  int index = -1;
  double timestamp = 0;
  std::string name;
  std::vector<cv::KeyPoint> kps;
  cv::Mat desc;
  std::vector<int> pt;  ///< per keypoint: map point id or -1
  std::vector<std::vector<int>> grid;
  int gw = 0, gh = 0;
  cv::Mat image;
  lie::SE3d T_cw;

  void build_grid(int width, int height) {
    gw = width / kGridCell + 1;
    gh = height / kGridCell + 1;
    grid.assign(static_cast<std::size_t>(gw * gh), {});
    for (std::size_t k = 0; k < kps.size(); ++k) {
      const int cx = std::clamp(static_cast<int>(kps[k].pt.x) / kGridCell, 0, gw - 1);
      const int cy = std::clamp(static_cast<int>(kps[k].pt.y) / kGridCell, 0, gh - 1);
      grid[cy * gw + cx].push_back(static_cast<int>(k));
    }
    pt.assign(kps.size(), -1);
  }
  template <class F>
  void for_each_in_radius(double u, double v, double r, int min_level, int max_level, F f) const {
    const int x0 = std::max(0, static_cast<int>((u - r) / kGridCell));
    const int x1 = std::min(gw - 1, static_cast<int>((u + r) / kGridCell));
    const int y0 = std::max(0, static_cast<int>((v - r) / kGridCell));
    const int y1 = std::min(gh - 1, static_cast<int>((v + r) / kGridCell));
    const double r2 = r * r;
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x)
        for (int k : grid[y * gw + x]) {
          const cv::KeyPoint& kp = kps[k];
          if (kp.octave < min_level || kp.octave > max_level) continue;
          const double du = kp.pt.x - u, dv = kp.pt.y - v;
          if (du * du + dv * dv <= r2) f(k);
        }
  }
  template <class F>
  void for_each_in_box(double u0, double v0, double u1, double v1, F f) const {
    const int x0 = std::clamp(static_cast<int>(u0 / kGridCell), 0, gw - 1);
    const int x1 = std::clamp(static_cast<int>(u1 / kGridCell), 0, gw - 1);
    const int y0 = std::clamp(static_cast<int>(v0 / kGridCell), 0, gh - 1);
    const int y1 = std::clamp(static_cast<int>(v1 / kGridCell), 0, gh - 1);
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x)
        for (int k : grid[y * gw + x]) {
          const cv::KeyPoint& kp = kps[k];
          if (kp.pt.x >= u0 && kp.pt.x <= u1 && kp.pt.y >= v0 && kp.pt.y <= v1) f(k);
        }
  }
  /// The keypoints of for_each_in_box(u0, v0, u1, v1) that lie within `reach` pixels of the
  /// segment a-b, and possibly some others; same visiting order as for_each_in_box (grid rows,
  /// then columns, then cell order), so a caller that filters by the segment gets the same result.
  /// Visits only the cells of each grid row that the segment, dilated by `reach`, can touch.
  template <class F>
  void for_each_near_segment(const Eigen::Vector2d& a, const Eigen::Vector2d& b, double reach,
                             double u0, double v0, double u1, double v1, F f) const {
    const int y0 = std::clamp(static_cast<int>(v0 / kGridCell), 0, gh - 1);
    const int y1 = std::clamp(static_cast<int>(v1 / kGridCell), 0, gh - 1);
    const Eigen::Vector2d ab = b - a;
    for (int y = y0; y <= y1; ++y) {
      // Segment parameters t in [0, 1] whose row coordinate lies in the row band +- reach.
      const double lo = y * kGridCell - reach, hi = (y + 1) * kGridCell + reach;
      double t0 = 0, t1 = 1;
      if (std::abs(ab.y()) < 1e-12) {
        if (a.y() < lo || a.y() > hi) continue;
      } else {
        double ta = (lo - a.y()) / ab.y(), tb = (hi - a.y()) / ab.y();
        if (ta > tb) std::swap(ta, tb);
        t0 = std::max(t0, ta);
        t1 = std::min(t1, tb);
        if (t0 > t1) continue;
      }
      const double ua = a.x() + t0 * ab.x(), ub = a.x() + t1 * ab.x();
      const double cu0 = std::max(u0, std::min(ua, ub) - reach);
      const double cu1 = std::min(u1, std::max(ua, ub) + reach);
      if (cu0 > cu1) continue;
      const int x0 = std::clamp(static_cast<int>(cu0 / kGridCell), 0, gw - 1);
      const int x1 = std::clamp(static_cast<int>(cu1 / kGridCell), 0, gw - 1);
      for (int x = x0; x <= x1; ++x)
        for (int k : grid[y * gw + x]) {
          const cv::KeyPoint& kp = kps[k];
          if (kp.pt.x >= u0 && kp.pt.x <= u1 && kp.pt.y >= v0 && kp.pt.y <= v1) f(k);
        }
    }
  }
  const std::uint8_t* d(int k) const { return desc.ptr<std::uint8_t>(k); }
  Eigen::Vector2d uv(int k) const { return {kps[k].pt.x, kps[k].pt.y}; }
};

struct Kf : FrameData {
  int id = -1;
  bool bad = false, final = false;
  Eigen::Vector3d center() const { return T_cw.inverse().translation(); }
};

struct Pt {
  int id = -1;
  Eigen::Vector3d X = Eigen::Vector3d::Zero();
  Desc desc{};
  std::vector<std::pair<int, int>> obs;  ///< (keyframe id, keypoint index)
  int first_kf = -1;
  int visible = 1, found = 1;
  int last_frame = -1;  ///< frame that last matched/considered it (dedupe in searches)
  bool bad = false, emitted = false;
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  double min_d = 0, max_d = 1e30;
};

}  // namespace

struct Odometry::Impl {
  map::Camera cam;
  OdometryOptions opt;
  OrbExtractor orb;
  std::vector<double> scale, inv_sigma2;
  std::function<void(const KeyframeBatch&)> callback;

  std::vector<std::unique_ptr<Kf>> kfs;  // index = id
  std::vector<Pt> pts;                   // index = id
  std::vector<int> recent_points;
  std::vector<std::pair<int, lie::SE3d>> frame_poses;
  OdometryTimings timings;

  bool initialized = false;
  int init_attempts = 0;
  std::string last_init_failure;
  std::unique_ptr<FrameData> init_ref;

  FrameData last;
  bool last_valid = false;
  lie::SE3d velocity;
  int ref_kf = -1;
  int last_kf_frame = -1;
  int lost_frames = 0;
  int pending_mapping = -1;  ///< keyframe whose local mapping has not run yet

  Impl(const map::Camera& c, const OdometryOptions& o) : cam(c), opt(o), orb(o.orb) {
    for (int l = 0; l < o.orb.num_levels; ++l) {
      scale.push_back(orb.level_scale(l));
      inv_sigma2.push_back(1.0 / (scale.back() * scale.back()));
    }
  }

  // ---------------------------------------------------------------- helpers
  Kf& kf(int id) { return *kfs[static_cast<std::size_t>(id)]; }
  Pt& pt(int id) { return pts[static_cast<std::size_t>(id)]; }
  int octave(const cv::KeyPoint& k) const {
    return std::clamp(k.octave, 0, static_cast<int>(scale.size()) - 1);
  }

  std::vector<int> live_kfs() const {
    std::vector<int> v;
    for (const auto& k : kfs)
      if (!k->bad) v.push_back(k->id);
    return v;
  }

  void update_point_geometry(Pt& p) {
    if (p.obs.empty()) return;
    Eigen::Vector3d n = Eigen::Vector3d::Zero();
    for (const auto& [k, i] : p.obs) {
      (void)i;
      n += (p.X - kf(k).center()).normalized();
    }
    p.normal = n.normalized();
    // Scale-invariance range from the first observation (ORB-SLAM UpdateNormalAndDepth).
    const auto& [k0, i0] = p.obs.front();
    const double d = (p.X - kf(k0).center()).norm();
    const int o = octave(kf(k0).kps[i0]);
    p.max_d = d * scale[o];
    p.min_d = p.max_d / scale.back();
  }

  void add_observation(int pid, int kid, int k) {
    Pt& p = pt(pid);
    p.obs.emplace_back(kid, k);
    kf(kid).pt[k] = pid;
    std::memcpy(p.desc.data(), kf(kid).d(k), 32);
  }

  void erase_observation(int pid, int kid) {
    Pt& p = pt(pid);
    for (std::size_t j = 0; j < p.obs.size(); ++j)
      if (p.obs[j].first == kid) {
        kf(kid).pt[p.obs[j].second] = -1;
        p.obs.erase(p.obs.begin() + static_cast<long>(j));
        break;
      }
  }

  void set_bad(int pid) {
    Pt& p = pt(pid);
    for (const auto& [k, i] : p.obs)
      if (kf(k).pt[i] == pid) kf(k).pt[i] = -1;
    p.obs.clear();
    p.bad = true;
  }

  int new_point(const Eigen::Vector3d& X, int first_kf) {
    Pt p;
    p.id = static_cast<int>(pts.size());
    p.X = X;
    p.first_kf = first_kf;
    pts.push_back(p);
    recent_points.push_back(p.id);
    return p.id;
  }

  /// Covisible keyframes of `kid` with their shared point counts, most shared first.
  std::vector<std::pair<int, int>> covisible(int kid) {
    std::unordered_map<int, int> count;
    for (int pid : kf(kid).pt) {
      if (pid < 0 || pt(pid).bad) continue;
      for (const auto& o : pt(pid).obs)
        if (o.first != kid) ++count[o.first];
    }
    std::vector<std::pair<int, int>> v(count.begin(), count.end());
    std::sort(v.begin(), v.end(), [](auto& a, auto& b) {
      return a.second != b.second ? a.second > b.second : a.first > b.first;
    });
    return v;
  }

  // ---------------------------------------------------------------- features / matching
  /// Features of a frame. Touches no map state (safe on a second thread while mapping runs).
  FrameData make_frame(const Frame& f, double* seconds) const {
    const auto t0 = Clock::now();
    FrameData fd;
    fd.index = f.index;
    fd.timestamp = f.timestamp;
    fd.name = f.name;
    Features feats = orb.extract(f.gray);
    fd.kps = std::move(feats.keypoints);
    fd.desc = feats.descriptors;
    fd.image = f.gray;
    fd.build_grid(cam.width, cam.height);
    *seconds = since(t0);
    return fd;
  }

  /// Projects map points into `f` at pose T and matches them to free keypoints within
  /// radius_px x level scale. `predict_level` uses the points' scale-invariance range and viewing
  /// direction (local map); otherwise every octave is searched (last frame).
  int search_by_projection(FrameData& f, const lie::SE3d& T, const std::vector<int>& pids,
                           double radius_px, bool predict_level, double ratio) {
    int n = 0;
    const Eigen::Vector3d O = T.inverse().translation();
    const double log_s = std::log(static_cast<double>(opt.orb.scale_factor));
    const int nl = static_cast<int>(scale.size());
    for (int pid : pids) {
      Pt& p = pt(pid);
      if (p.bad || p.last_frame == f.index) continue;
      const Eigen::Vector3d Xc = T.act(p.X);
      if (Xc.z() <= 0) continue;
      const Eigen::Vector2d uv = cam.project(Xc);
      if (!cam.in_image(uv)) continue;
      int lo = 0, hi = nl - 1;
      double r = radius_px;
      if (predict_level) {
        const Eigen::Vector3d PO = p.X - O;
        const double dist = PO.norm();
        if (dist < 0.8 * p.min_d || dist > 1.2 * p.max_d) continue;
        if (PO.dot(p.normal) < 0.5 * dist) continue;
        const int level =
            std::clamp(static_cast<int>(std::ceil(std::log(p.max_d / dist) / log_s)), 0, nl - 1);
        lo = std::max(0, level - 1);
        hi = std::min(nl - 1, level + 1);
        r *= scale[level];
        ++p.visible;
      }
      int best = 256, second = 256, best_k = -1, best_o = -1, second_o = -1;
      f.for_each_in_radius(uv.x(), uv.y(), r, lo, hi, [&](int k) {
        if (f.pt[k] >= 0) return;
        const int d = hamming(p.desc.data(), f.d(k));
        if (d < best) {
          second = best;
          second_o = best_o;
          best = d;
          best_k = k;
          best_o = f.kps[k].octave;
        } else if (d < second) {
          second = d;
          second_o = f.kps[k].octave;
        }
      });
      if (best_k < 0 || best > kThHigh) continue;
      if (ratio < 1.0 && best_o == second_o && best > ratio * second) continue;
      f.pt[best_k] = pid;
      p.last_frame = f.index;
      ++n;
    }
    return n;
  }

  /// Robust pose-only refinement (ORB-SLAM PoseOptimization): Gauss-Newton on SE(3) with left
  /// perturbation and a Huber kernel, four rounds re-classifying outliers at chi2(2) = 5.991.
  /// Outlier matches are removed from f.pt. Returns the inlier count.
  int refine_pose(FrameData& f, lie::SE3d* T) {
    std::vector<int> idx;
    for (std::size_t k = 0; k < f.pt.size(); ++k)
      if (f.pt[k] >= 0) idx.push_back(static_cast<int>(k));
    if (idx.size() < 6) {
      for (int k : idx) f.pt[k] = -1;
      return 0;
    }
    std::vector<char> outlier(idx.size(), 0);
    solver::ReprojectionResidual res;
    res.fx = cam.fx;
    res.fy = cam.fy;
    res.cx = cam.cx;
    res.cy = cam.cy;
    const double delta = std::sqrt(kChi2_2);
    lie::SE3d Tc = *T;
    int inliers = 0;
    for (int round = 0; round < 4; ++round) {
      for (int it = 0; it < 10; ++it) {
        Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Zero();
        Eigen::Matrix<double, 6, 1> b = Eigen::Matrix<double, 6, 1>::Zero();
        int used = 0;
        for (std::size_t j = 0; j < idx.size(); ++j) {
          if (outlier[j]) continue;
          const int k = idx[j];
          res.uv = f.uv(k);
          solver::ReprojectionResidual::Vec r;
          solver::ReprojectionResidual::MatT J;
          if (!res(Tc, pt(f.pt[k]).X, &r, &J)) continue;
          const double is2 = inv_sigma2[octave(f.kps[k])];
          const double e = std::sqrt(r.squaredNorm() * is2);
          const double w = is2 * ((round < 3 && e > delta) ? delta / e : 1.0);
          H.noalias() += w * J.transpose() * J;
          b.noalias() += w * J.transpose() * r;
          ++used;
        }
        if (used < 6) break;
        const Eigen::Matrix<double, 6, 1> dx = H.ldlt().solve(-b);
        if (!dx.allFinite()) break;
        Tc = lie::SE3d::exp(dx) * Tc;
        if (dx.norm() < 1e-8) break;
      }
      inliers = 0;
      for (std::size_t j = 0; j < idx.size(); ++j) {
        const int k = idx[j];
        res.uv = f.uv(k);
        solver::ReprojectionResidual::Vec r;
        const bool ok = res(Tc, pt(f.pt[k]).X, &r);
        outlier[j] = !ok || r.squaredNorm() * inv_sigma2[octave(f.kps[k])] > kChi2_2;
        if (!outlier[j]) ++inliers;
      }
      if (inliers < 6) break;
    }
    for (std::size_t j = 0; j < idx.size(); ++j)
      if (outlier[j]) f.pt[idx[j]] = -1;
    if (inliers >= 6 && Tc.matrix().allFinite()) *T = Tc;
    return inliers;
  }

  /// Descriptor matching of f against the points of keyframe `kid` (nearest neighbour with
  /// ratio test), then PnP RANSAC and refinement. Returns inliers (0 on failure).
  int match_keyframe_pnp(FrameData& f, int kid, lie::SE3d* T) {
    Kf& K = kf(kid);
    std::vector<int> kidx;
    for (std::size_t i = 0; i < K.pt.size(); ++i)
      if (K.pt[i] >= 0 && !pt(K.pt[i]).bad) kidx.push_back(static_cast<int>(i));
    std::vector<int> owner(f.kps.size(), -1), owner_d(f.kps.size(), 256);
    for (int i : kidx) {
      BestTwo b;
      for (std::size_t k = 0; k < f.kps.size(); ++k)
        b.offer(hamming(K.d(i), f.d(static_cast<int>(k))), static_cast<int>(k));
      if (!b.accepted(kThLow, 0.75)) continue;
      if (b.best < owner_d[b.index]) {
        owner[b.index] = K.pt[i];
        owner_d[b.index] = b.best;
      }
    }
    std::vector<cv::Point3d> obj;
    std::vector<cv::Point2d> img;
    std::vector<int> fk;
    for (std::size_t k = 0; k < owner.size(); ++k)
      if (owner[k] >= 0) {
        const Eigen::Vector3d& X = pt(owner[k]).X;
        obj.emplace_back(X.x(), X.y(), X.z());
        img.emplace_back(f.kps[k].pt.x, f.kps[k].pt.y);
        fk.push_back(static_cast<int>(k));
      }
    if (obj.size() < 15) return 0;
    const cv::Matx33d Kc(cam.fx, 0, cam.cx, 0, cam.fy, cam.cy, 0, 0, 1);
    cv::Mat rvec, tvec;
    std::vector<int> inl;
    bool ok = false;
    try {
      ok = cv::solvePnPRansac(obj, img, Kc, cv::noArray(), rvec, tvec, false, 200, 4.0f, 0.99, inl,
                              cv::SOLVEPNP_EPNP);
    } catch (const cv::Exception&) {
      ok = false;
    }
    if (!ok || inl.size() < 10) return 0;
    cv::Mat Rm;
    cv::Rodrigues(rvec, Rm);
    Eigen::Matrix3d R;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) R(r, c) = Rm.at<double>(r, c);
    lie::SE3d Tp(lie::SO3d(R),
                 Eigen::Vector3d(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2)));
    std::fill(f.pt.begin(), f.pt.end(), -1);
    for (int i : inl) f.pt[fk[i]] = owner[fk[i]];
    const int n = refine_pose(f, &Tp);
    if (n < 10) {
      std::fill(f.pt.begin(), f.pt.end(), -1);
      return 0;
    }
    *T = Tp;
    return n;
  }

  /// Keyframes whose points form the local map of a frame: those observing its matched points
  /// (most shared first, up to local_window + 2), plus the newest keyframes.
  std::vector<int> local_keyframes(const FrameData& f) {
    std::unordered_map<int, int> count;
    for (int pid : f.pt)
      if (pid >= 0)
        for (const auto& o : pt(pid).obs) ++count[o.first];
    std::vector<std::pair<int, int>> v(count.begin(), count.end());
    std::sort(v.begin(), v.end(), [](auto& a, auto& b) {
      return a.second != b.second ? a.second > b.second : a.first > b.first;
    });
    std::vector<int> out;
    for (const auto& [k, c] : v) {
      (void)c;
      if (kf(k).bad) continue;
      out.push_back(k);
      if (static_cast<int>(out.size()) >= opt.local_window + 2) break;
    }
    if (!v.empty()) ref_kf = v.front().first;
    int added = 0;
    for (int k = static_cast<int>(kfs.size()) - 1; k >= 0 && added < 3; --k)
      if (!kf(k).bad && std::find(out.begin(), out.end(), k) == out.end()) {
        out.push_back(k);
        ++added;
      }
    return out;
  }

  int track_local_map(FrameData& f, lie::SE3d* T, double radius) {
    for (int pid : f.pt)
      if (pid >= 0) pt(pid).last_frame = f.index;
    std::vector<int> pids;
    std::unordered_set<int> queued;
    for (int k : local_keyframes(f))
      for (int pid : kf(k).pt)
        if (pid >= 0 && !pt(pid).bad && pt(pid).last_frame != f.index && queued.insert(pid).second)
          pids.push_back(pid);
    search_by_projection(f, *T, pids, radius, true, 0.8);
    const int n = refine_pose(f, T);
    for (int pid : f.pt)
      if (pid >= 0) ++pt(pid).found;
    return n;
  }

  // ---------------------------------------------------------------- initialisation
  FrameResult try_initialize(FrameData&& f) {
    const auto t0 = Clock::now();
    FrameResult out;
    out.features = static_cast<int>(f.kps.size());
    const int min_feat = opt.init.min_matches;
    if (static_cast<int>(f.kps.size()) < min_feat) {
      out.message = "frame " + std::to_string(f.index) + ": only " + std::to_string(f.kps.size()) +
                    " features (black or textureless frame?)";
      last_init_failure = out.message;
      init_ref.reset();
      timings.init += since(t0);
      return out;
    }
    if (!init_ref) {
      init_ref = std::make_unique<FrameData>(std::move(f));
      out.message = "initialisation reference frame " + std::to_string(init_ref->index);
      timings.init += since(t0);
      return out;
    }
    ++init_attempts;
    FrameData& r = *init_ref;
    // Matching for initialisation (ORB-SLAM SearchForInitialization): same octave, 100 px
    // window, Hamming < 50, ratio 0.9, one-to-one.
    OneToOne m11(r.kps.size(), f.kps.size());
    for (std::size_t i = 0; i < r.kps.size(); ++i) {
      const int oc = r.kps[i].octave;
      BestTwo b;
      f.for_each_in_radius(r.kps[i].pt.x, r.kps[i].pt.y, 100.0, oc, oc,
                           [&](int k) { b.offer(hamming(r.d(static_cast<int>(i)), f.d(k)), k); });
      if (b.accepted(kThLow, 0.9)) m11.claim(static_cast<int>(i), b.index, b.best);
    }
    const std::vector<int>& match = m11.match;
    std::vector<Eigen::Vector2d> x1, x2;
    std::vector<std::pair<int, int>> pairs;
    for (std::size_t i = 0; i < match.size(); ++i)
      if (match[i] >= 0) {
        x1.push_back(r.uv(static_cast<int>(i)));
        x2.push_back(f.uv(match[i]));
        pairs.emplace_back(static_cast<int>(i), match[i]);
      }
    const TwoViewResult tv = initialize_two_view(x1, x2, cam, opt.init);
    if (!tv.ok) {
      out.message = "frames " + std::to_string(r.index) + "-" + std::to_string(f.index) +
                    ": initialisation failed: " + tv.reason;
      last_init_failure = out.message;
      if (static_cast<int>(x1.size()) < opt.init.min_matches ||
          f.index - r.index >= opt.init_max_reference_age)
        init_ref = std::make_unique<FrameData>(std::move(f));
      timings.init += since(t0);
      return out;
    }
    // Two keyframes, points in the frame of the first (= M), scaled to median depth 1.
    std::vector<double> depths;
    for (std::size_t m = 0; m < pairs.size(); ++m)
      if (tv.good[m]) depths.push_back(tv.points[m].z());
    std::nth_element(depths.begin(), depths.begin() + depths.size() / 2, depths.end());
    const double s = 1.0 / depths[depths.size() / 2];
    auto k0 = std::make_unique<Kf>();
    static_cast<FrameData&>(*k0) = std::move(r);
    k0->id = 0;
    k0->T_cw = lie::SE3d();
    auto k1 = std::make_unique<Kf>();
    static_cast<FrameData&>(*k1) = f;  // keep f as the last frame too
    k1->id = 1;
    k1->T_cw = lie::SE3d(tv.T_21.rotation(), tv.T_21.translation() * s);
    kfs.push_back(std::move(k0));
    kfs.push_back(std::move(k1));
    for (std::size_t m = 0; m < pairs.size(); ++m) {
      if (!tv.good[m]) continue;
      const int pid = new_point(tv.points[m] * s, 0);
      add_observation(pid, 0, pairs[m].first);
      add_observation(pid, 1, pairs[m].second);
      update_point_geometry(pt(pid));
    }
    init_ref.reset();
    local_bundle_adjustment(1, /*global=*/true);
    // Renormalise: median depth of the first keyframe = 1.
    depths.clear();
    for (int pid : kf(0).pt)
      if (pid >= 0 && !pt(pid).bad) depths.push_back(pt(pid).X.z());
    int tracked = 0;
    for (int pid : kf(1).pt) tracked += pid >= 0 && !pt(pid).bad;
    if (depths.size() < 30 || tracked < 30) {
      out.message =
          "initialisation rejected after BA: only " + std::to_string(tracked) + " points survive";
      last_init_failure = out.message;
      kfs.clear();
      pts.clear();
      recent_points.clear();
      timings.init += since(t0);
      return out;
    }
    std::nth_element(depths.begin(), depths.begin() + depths.size() / 2, depths.end());
    const double s2 = 1.0 / depths[depths.size() / 2];
    for (Pt& p : pts) p.X *= s2;
    kf(1).T_cw = lie::SE3d(kf(1).T_cw.rotation(), kf(1).T_cw.translation() * s2);
    for (Pt& p : pts) update_point_geometry(p);
    initialized = true;
    last = kf(1);
    last_valid = true;
    velocity = kf(1).T_cw * kf(0).T_cw.inverse();
    ref_kf = 1;
    last_kf_frame = kf(1).index;
    frame_poses.emplace_back(kf(0).index, kf(0).T_cw);
    frame_poses.emplace_back(kf(1).index, kf(1).T_cw);
    out.state = FrameResult::State::kInitialized;
    out.keyframe = true;
    out.T_cw = kf(1).T_cw;
    out.matches = tracked;
    std::ostringstream os;
    os << "initialised from frames " << kf(0).index << "-" << kf(1).index << " ("
       << (tv.model == TwoViewResult::Model::kHomography ? "homography" : "essential") << ", "
       << tv.num_good << " points, parallax " << tv.parallax_deg << " deg)";
    out.message = os.str();
    timings.init += since(t0);
    return out;
  }

  // ---------------------------------------------------------------- tracking
  FrameResult track(FrameData&& f) {
    const auto t0 = Clock::now();
    FrameResult out;
    out.features = static_cast<int>(f.kps.size());
    lie::SE3d T;
    int n = 0;
    bool reloc = false;
    if (static_cast<int>(f.kps.size()) < opt.min_tracked_inliers) {
      out.message = "frame " + std::to_string(f.index) + ": only " + std::to_string(f.kps.size()) +
                    " features (black or textureless frame?)";
    } else if (last_valid) {
      T = velocity * last.T_cw;
      std::vector<int> lp;
      for (int pid : last.pt)
        if (pid >= 0) lp.push_back(pid);
      int m = search_by_projection(f, T, lp, 2 * opt.search_radius_px, false, 1.0);
      if (m < 20) {
        std::fill(f.pt.begin(), f.pt.end(), -1);
        for (int pid : lp) pt(pid).last_frame = -1;
        m = search_by_projection(f, T, lp, 4 * opt.search_radius_px, false, 1.0);
      }
      n = m >= 20 ? refine_pose(f, &T) : 0;
      if (n < 10) {
        std::fill(f.pt.begin(), f.pt.end(), -1);
        n = ref_kf >= 0 && !kf(ref_kf).bad ? match_keyframe_pnp(f, ref_kf, &T) : 0;
      }
      if (n >= 10) n = track_local_map(f, &T, opt.search_radius_px);
      if (n < opt.min_tracked_inliers)
        out.message = "frame " + std::to_string(f.index) + ": tracking lost (" + std::to_string(n) +
                      " inliers < " + std::to_string(opt.min_tracked_inliers) + ")";
    } else {
      // Relocalisation against the newest keyframes.
      const std::vector<int> live = live_kfs();
      int tried = 0;
      for (auto it = live.rbegin(); it != live.rend() && tried < opt.reloc_keyframes;
           ++it, ++tried) {
        std::fill(f.pt.begin(), f.pt.end(), -1);
        lie::SE3d Tr;
        if (match_keyframe_pnp(f, *it, &Tr) < 10) continue;
        ref_kf = *it;
        const int m = track_local_map(f, &Tr, 2 * opt.search_radius_px);
        if (m >= opt.reloc_min_inliers) {
          T = Tr;
          n = m;
          reloc = true;
          break;
        }
      }
      if (!reloc) {
        std::fill(f.pt.begin(), f.pt.end(), -1);
        out.message = "frame " + std::to_string(f.index) + ": lost, relocalisation failed";
      }
    }
    timings.tracking += since(t0);
    if (n < opt.min_tracked_inliers) {
      out.state = FrameResult::State::kLost;
      last_valid = false;
      velocity = lie::SE3d();
      ++lost_frames;
      return out;
    }
    out.state = reloc ? FrameResult::State::kRelocalized : FrameResult::State::kTracked;
    if (reloc) {
      out.message = "frame " + std::to_string(f.index) + ": relocalised against keyframe " +
                    std::to_string(ref_kf) + " after " + std::to_string(lost_frames) +
                    " lost frames";
      lost_frames = 0;
      velocity = lie::SE3d();
    } else {
      velocity = T * last.T_cw.inverse();
    }
    f.T_cw = T;
    out.T_cw = T;
    out.matches = n;
    frame_poses.emplace_back(f.index, T);

    // Keyframe decision (ORB-SLAM NeedNewKeyFrame, monocular, local mapping always idle).
    int ref_tracked = 0;
    if (ref_kf >= 0)
      for (int pid : kf(ref_kf).pt)
        ref_tracked += pid >= 0 && !pt(pid).bad && pt(pid).obs.size() >= 2;
    const int since_kf = f.index - last_kf_frame;
    const bool need =
        since_kf >= opt.keyframe_min_frames &&
        (since_kf >= opt.keyframe_max_frames || n < opt.keyframe_track_ratio * ref_tracked) &&
        n > 15;
    last = f;
    last_valid = true;
    if (need) {
      create_keyframe(std::move(f));
      out.keyframe = true;
    }
    return out;
  }

  // ---------------------------------------------------------------- local mapping
  void create_keyframe(FrameData&& f) {
    auto t0 = Clock::now();
    auto k = std::make_unique<Kf>();
    const int kid = static_cast<int>(kfs.size());
    k->id = kid;
    static_cast<FrameData&>(*k) = std::move(f);
    std::vector<int> matched = k->pt;
    std::fill(k->pt.begin(), k->pt.end(), -1);
    kfs.push_back(std::move(k));
    for (std::size_t i = 0; i < matched.size(); ++i)
      if (matched[i] >= 0 && !pt(matched[i]).bad) {
        add_observation(matched[i], kid, static_cast<int>(i));
        update_point_geometry(pt(matched[i]));
      }
    last_kf_frame = kf(kid).index;
    ref_kf = kid;
    cull_recent_points(kid);
    timings.keyframe += since(t0);
    pending_mapping = kid;
    if (!opt.pipeline_mapping) run_pending_mapping();
  }

  /// Local mapping of the newest keyframe: triangulation, local BA, keyframe culling, handing out
  /// final keyframes. With pipeline_mapping it runs at the start of the next process() call (or
  /// in finish()/map()), while that frame's ORB features are extracted on a second thread: it
  /// still completes before that frame is tracked, so the results are those of the synchronous
  /// order, bit for bit.
  void run_pending_mapping() {
    if (pending_mapping < 0) return;
    const int kid = pending_mapping;
    pending_mapping = -1;
    auto t0 = Clock::now();
    triangulate(kid);
    timings.triangulation += since(t0);
    t0 = Clock::now();
    local_bundle_adjustment(kid, false);
    timings.local_ba += since(t0);
    ++timings.local_ba_runs;
    t0 = Clock::now();
    cull_keyframes(kid);
    timings.culling += since(t0);
    t0 = Clock::now();
    finalize_old();
    timings.handover += since(t0);
    // The last frame's matches are the new keyframe's (live) observations.
    for (std::size_t i = 0; i < last.pt.size(); ++i) last.pt[i] = kf(kid).pt[i];
  }

  void cull_recent_points(int kid) {
    std::vector<int> keep;
    for (int pid : recent_points) {
      Pt& p = pt(pid);
      if (p.bad) continue;
      const int age = kid - p.first_kf;
      if (static_cast<double>(p.found) / p.visible < 0.25 || (age >= 2 && p.obs.size() <= 2)) {
        set_bad(pid);
      } else if (age < 3) {
        keep.push_back(pid);
      }
    }
    recent_points.swap(keep);
  }

  void triangulate(int kid) {
    Kf& k1 = kf(kid);
    const auto cov = covisible(kid);
    const Eigen::Vector3d O1 = k1.center();
    const Eigen::Matrix3d R1 = k1.T_cw.rotation().matrix();
    const Eigen::Vector3d t1 = k1.T_cw.translation();
    Eigen::Matrix3d Kinv;
    Kinv << 1 / cam.fx, 0, -cam.cx / cam.fx, 0, 1 / cam.fy, -cam.cy / cam.fy, 0, 0, 1;
    const double ratio_factor = 1.5 * opt.orb.scale_factor;
    int used = 0;
    for (const auto& [k2id, shared] : cov) {
      (void)shared;
      if (used >= opt.triangulation_neighbors) break;
      Kf& k2 = kf(k2id);
      if (k2.bad) continue;
      ++used;
      const Eigen::Vector3d O2 = k2.center();
      // Baseline vs scene depth of k2 (ORB-SLAM: skip when baseline/median depth < 0.01).
      std::vector<double> dz;
      for (int pid : k2.pt)
        if (pid >= 0 && !pt(pid).bad) dz.push_back(k2.T_cw.act(pt(pid).X).z());
      if (dz.empty()) continue;
      std::nth_element(dz.begin(), dz.begin() + dz.size() / 2, dz.end());
      if ((O2 - O1).norm() / dz[dz.size() / 2] < 0.01) continue;
      const Eigen::Matrix3d R2 = k2.T_cw.rotation().matrix();
      const Eigen::Vector3d t2 = k2.T_cw.translation();
      // Fundamental matrix 1 -> 2: x2^T F21 x1 = 0.
      const Eigen::Matrix3d R21 = R2 * R1.transpose();
      const Eigen::Vector3d t21 = t2 - R21 * t1;
      Eigen::Matrix3d tx;
      tx << 0, -t21.z(), t21.y(), t21.z(), 0, -t21.x(), -t21.y(), t21.x(), 0;
      const Eigen::Matrix3d F21 = Kinv.transpose() * tx * R21 * Kinv;
      // Depth range of k1's scene: a match must lie on the epipolar segment between the
      // projections of the ray at the nearest depth and at infinity (a box query on the grid).
      std::vector<double> z1;
      for (int pid : k1.pt)
        if (pid >= 0 && !pt(pid).bad) z1.push_back(k1.T_cw.act(pt(pid).X).z());
      if (z1.empty()) continue;
      const double zmin = 0.5 * *std::min_element(z1.begin(), z1.end());
      // A keypoint of the box that passes the epipolar-line test below (distance <= 1.96 sigma,
      // at most w px) lies within `reach` of the segment: along the line it can pass a segment
      // end by at most sqrt(2) (margin + w) inside the box. So the strip query visits every
      // candidate the box query would, in the same order.
      const double w = 1.96 * scale.back();
      const double reach = std::sqrt(2.0) * (6.0 + w) + w + 1.0;
      OneToOne m11(k1.kps.size(), k2.kps.size());
      for (std::size_t i = 0; i < k1.kps.size(); ++i) {
        if (k1.pt[i] >= 0) continue;
        const Eigen::Vector3d n1 = Kinv * Eigen::Vector3d(k1.kps[i].pt.x, k1.kps[i].pt.y, 1.0);
        const Eigen::Vector3d a = R21 * n1 * zmin + t21, b = R21 * n1;
        if (a.z() <= 0 || b.z() <= 0) continue;
        const Eigen::Vector2d pa = cam.project(a), pb = cam.project(b);
        const double margin = 6.0;
        const Eigen::Vector3d l = F21 * Eigen::Vector3d(k1.kps[i].pt.x, k1.kps[i].pt.y, 1.0);
        const double ln2 = l.head<2>().squaredNorm();
        BestTwo bt;
        k2.for_each_near_segment(
            pa, pb, reach, std::min(pa.x(), pb.x()) - margin, std::min(pa.y(), pb.y()) - margin,
            std::max(pa.x(), pb.x()) + margin, std::max(pa.y(), pb.y()) + margin, [&](int j) {
              if (k2.pt[j] >= 0) return;
              const double e = l.x() * k2.kps[j].pt.x + l.y() * k2.kps[j].pt.y + l.z();
              const double s2 = scale[octave(k2.kps[j])];
              if (e * e > 3.84 * ln2 * s2 * s2) return;
              bt.offer(hamming(k1.d(static_cast<int>(i)), k2.d(j)), j);
            });
        if (bt.accepted(kThLow, 0.8)) m11.claim(static_cast<int>(i), bt.index, bt.best);
      }
      const std::vector<int>& match = m11.match;
      Eigen::Matrix<double, 3, 4> P1, P2;
      P1 << R1, t1;
      P2 << R2, t2;
      for (std::size_t i = 0; i < match.size(); ++i) {
        const int j = match[i];
        if (j < 0 || k1.pt[i] >= 0 || k2.pt[j] >= 0) continue;
        const Eigen::Vector2d u1 = k1.uv(static_cast<int>(i)), u2 = k2.uv(j);
        const Eigen::Vector3d n1 = Kinv * u1.homogeneous(), n2 = Kinv * u2.homogeneous();
        const Eigen::Vector3d r1 = R1.transpose() * n1, r2 = R2.transpose() * n2;
        const double cosr = r1.dot(r2) / (r1.norm() * r2.norm());
        if (!(cosr > 0 && cosr < 0.9998)) continue;
        const Eigen::Vector3d X = triangulate_dlt(P1, P2, n1.head<2>(), n2.head<2>());
        if (!X.allFinite()) continue;
        const Eigen::Vector3d c1 = k1.T_cw.act(X), c2 = k2.T_cw.act(X);
        if (c1.z() <= 0 || c2.z() <= 0) continue;
        const int o1 = octave(k1.kps[i]), o2 = octave(k2.kps[j]);
        if ((cam.project(c1) - u1).squaredNorm() * inv_sigma2[o1] > kChi2_2) continue;
        if ((cam.project(c2) - u2).squaredNorm() * inv_sigma2[o2] > kChi2_2) continue;
        const double d1 = (X - O1).norm(), d2 = (X - O2).norm();
        const double ratio_dist = d2 / d1, ratio_oct = scale[o1] / scale[o2];
        if (ratio_dist * ratio_factor < ratio_oct || ratio_dist > ratio_oct * ratio_factor)
          continue;
        const int pid = new_point(X, kid);
        add_observation(pid, k2id, j);
        add_observation(pid, kid, static_cast<int>(i));
        update_point_geometry(pt(pid));
      }
    }
  }

  /// Local BA (ORB-SLAM LocalBundleAdjustment) through the core solver: the keyframe and its
  /// covisible keyframes free, other keyframes observing their points fixed, Huber on
  /// chi2(2) = 5.991, two rounds with outlier observations dropped in between, Schur on points.
  void local_bundle_adjustment(int kid, bool global) {
    std::vector<int> window{kid};
    if (global) {
      window = live_kfs();
    } else {
      for (const auto& [k, c] : covisible(kid)) {
        (void)c;
        if (static_cast<int>(window.size()) >= opt.local_window) break;
        if (!kf(k).bad && !kf(k).final) window.push_back(k);
      }
    }
    std::unordered_map<int, int> in_window;
    for (int k : window) in_window[k] = 1;
    std::vector<int> pids;
    std::unordered_map<int, int> pindex;
    for (int k : window)
      for (int pid : kf(k).pt)
        if (pid >= 0 && !pt(pid).bad && !pindex.count(pid)) {
          pindex[pid] = static_cast<int>(pids.size());
          pids.push_back(pid);
        }
    std::unordered_map<int, int> kindex;
    std::vector<int> kids;
    for (int k : window) {
      kindex[k] = static_cast<int>(kids.size());
      kids.push_back(k);
    }
    for (int pid : pids)
      for (const auto& o : pt(pid).obs)
        if (!kindex.count(o.first)) {
          kindex[o.first] = static_cast<int>(kids.size());
          kids.push_back(o.first);
        }
    std::vector<lie::SE3d> poses(kids.size());
    for (std::size_t i = 0; i < kids.size(); ++i) poses[i] = kf(kids[i]).T_cw;
    std::vector<Eigen::Vector3d> X(pids.size());
    for (std::size_t i = 0; i < pids.size(); ++i) X[i] = pt(pids[i]).X;
    struct Ob {
      int k, p, kp;
    };
    std::vector<Ob> obs;
    for (std::size_t i = 0; i < pids.size(); ++i)
      for (const auto& o : pt(pids[i]).obs)
        obs.push_back({kindex[o.first], static_cast<int>(i), o.second});
    std::vector<char> outlier(obs.size(), 0);
    solver::ReprojectionResidual base;
    base.fx = cam.fx;
    base.fy = cam.fy;
    base.cx = cam.cx;
    base.cy = cam.cy;
    const auto chi2 = [&](const Ob& o) {
      solver::ReprojectionResidual r = base;
      const Kf& K = kf(kids[o.k]);
      r.uv = K.uv(o.kp);
      solver::ReprojectionResidual::Vec e;
      if (!r(poses[o.k], X[o.p], &e)) return 1e30;
      return e.squaredNorm() * inv_sigma2[octave(K.kps[o.kp])];
    };
    const int rounds = 2;
    for (int round = 0; round < rounds; ++round) {
      solver::Problem problem;
      int used = 0;
      std::vector<char> pose_used(kids.size(), 0);
      for (std::size_t j = 0; j < obs.size(); ++j) {
        if (outlier[j]) continue;
        pose_used[static_cast<std::size_t>(obs[j].k)] = 1;
        const Ob& o = obs[j];
        solver::ReprojectionResidual r = base;
        const Kf& K = kf(kids[o.k]);
        r.uv = K.uv(o.kp);
        problem.add_residual_block(r, solver::RobustLoss::huber(std::sqrt(kChi2_2)),
                                   inv_sigma2[octave(K.kps[o.kp])], &poses[o.k], &X[o.p]);
        ++used;
      }
      if (used == 0) return;
      std::vector<char> constant(kids.size(), 0);
      for (std::size_t i = 0; i < kids.size(); ++i)
        if (!in_window.count(kids[i]) || kids[i] == 0 || kf(kids[i]).final) constant[i] = 1;
      for (std::size_t i = 0; i < kids.size(); ++i)
        if (constant[i] && pose_used[i]) problem.set_constant(&poses[i]);
      solver::Options so;
      so.linear_solver = solver::LinearSolverType::kSchur;
      so.max_iterations = std::max(1, opt.ba_iterations / rounds);
      so.num_threads = opt.num_threads;
      so.function_tolerance = 1e-5;
      solver::LevenbergMarquardt lm(so);
      const solver::Summary s = lm.solve(&problem);
      (void)s;
      for (std::size_t j = 0; j < obs.size(); ++j) outlier[j] = chi2(obs[j]) > kChi2_2;
    }
    for (std::size_t i = 0; i < kids.size(); ++i)
      if (poses[i].matrix().allFinite()) kf(kids[i]).T_cw = poses[i];
    for (std::size_t i = 0; i < pids.size(); ++i)
      if (X[i].allFinite()) pt(pids[i]).X = X[i];
    for (std::size_t j = 0; j < obs.size(); ++j)
      if (outlier[j]) erase_observation(pids[obs[j].p], kids[obs[j].k]);
    for (int pid : pids) {
      if (pt(pid).obs.size() < 2)
        set_bad(pid);
      else
        update_point_geometry(pt(pid));
    }
  }

  /// Redundant keyframes (ORB-SLAM KeyFrameCulling): 90 % of their points seen by >= 3 other
  /// keyframes at the same or a finer scale.
  void cull_keyframes(int kid) {
    for (const auto& [k, c] : covisible(kid)) {
      (void)c;
      Kf& K = kf(k);
      if (k <= 1 || K.bad || K.final || k == kid) continue;
      int total = 0, redundant = 0;
      for (std::size_t i = 0; i < K.pt.size(); ++i) {
        const int pid = K.pt[i];
        if (pid < 0 || pt(pid).bad) continue;
        ++total;
        if (pt(pid).obs.size() <= 3) continue;
        int others = 0;
        for (const auto& [k2, i2] : pt(pid).obs)
          if (k2 != k && kf(k2).kps[i2].octave <= K.kps[i].octave + 1) ++others;
        if (others >= 3) ++redundant;
      }
      if (total > 0 && redundant > 0.9 * total) {
        for (int pid : std::vector<int>(K.pt)) {
          if (pid < 0) continue;
          erase_observation(pid, k);
          if (pt(pid).obs.size() < 2) set_bad(pid);
        }
        K.bad = true;
        K.image.release();
        if (ref_kf == k) ref_kf = kid;
      }
    }
  }

  KeyframeView view_of(const Kf& k) const {
    KeyframeView v;
    v.keyframe_id = k.id;
    v.frame_index = k.index;
    v.T_cw = k.T_cw;
    v.camera = cam;
    v.image = k.image;
    v.keypoints = k.kps;
    v.descriptors = k.desc;
    v.point_ids = k.pt;
    for (int& p : v.point_ids)
      if (p >= 0 && pts[static_cast<std::size_t>(p)].bad) p = -1;
    return v;
  }

  void finalize_keyframe(Kf& k) {
    k.final = true;
    KeyframeBatch b;
    b.keyframe.id = k.id;
    b.keyframe.frame_index = k.index;
    b.keyframe.timestamp = k.timestamp;
    b.keyframe.T_cw = k.T_cw;
    b.keyframe.camera_id = cam.id;
    for (std::size_t i = 0; i < k.pt.size(); ++i) {
      const int pid = k.pt[i];
      if (pid < 0 || pt(pid).bad) continue;
      Pt& p = pt(pid);
      if (!p.emitted) {
        p.emitted = true;
        b.new_points.push_back({p.id, p.X, k.id});
      }
      b.observations.push_back({k.id, p.id, k.uv(static_cast<int>(i))});
    }
    b.view = view_of(k);
    if (callback) callback(b);
    if (!opt.keep_final_images) k.image.release();
  }

  void finalize_old() {
    std::vector<int> pending;
    for (const auto& k : kfs)
      if (!k->bad && !k->final) pending.push_back(k->id);
    const int excess = static_cast<int>(pending.size()) - opt.finalize_lag;
    for (int i = 0; i < excess; ++i) finalize_keyframe(kf(pending[i]));
  }
};

Odometry::Odometry(const map::Camera& camera, const OdometryOptions& options) {
  camera.validate();
  GEODRIFT_CHECK(options.local_window >= 2, "local_window " << options.local_window << " < 2");
  GEODRIFT_CHECK(
      options.finalize_lag >= options.local_window,
      "finalize_lag " << options.finalize_lag << " < local_window " << options.local_window);
  GEODRIFT_CHECK(options.num_threads == 1 || options.num_threads == 2,
                 "num_threads " << options.num_threads << " not 1 or 2");
  GEODRIFT_CHECK(options.keyframe_max_frames >= 1,
                 "keyframe_max_frames " << options.keyframe_max_frames << " < 1");
  impl_ = std::make_unique<Impl>(camera, options);
}

Odometry::~Odometry() = default;

void Odometry::set_keyframe_callback(std::function<void(const KeyframeBatch&)> cb) {
  impl_->callback = std::move(cb);
}

FrameResult Odometry::process(const Frame& frame) {
  Impl& m = *impl_;
  GEODRIFT_CHECK(frame.gray.type() == CV_8UC1, "frame " << frame.index << " is not 8-bit gray");
  GEODRIFT_CHECK(frame.gray.cols == m.cam.width && frame.gray.rows == m.cam.height,
                 "frame " << frame.index << " is " << frame.gray.cols << "x" << frame.gray.rows
                          << ", the camera is " << m.cam.width << "x" << m.cam.height);
  FrameData f;
  double feature_s = 0;
  if (m.pending_mapping >= 0) {
    // ORB of this frame on a second thread while the previous keyframe's local mapping runs
    // here (the callback stays on the caller's thread); both finish before tracking.
    std::future<FrameData> next = std::async(
        std::launch::async, [&m, &frame, &feature_s] { return m.make_frame(frame, &feature_s); });
    try {
      m.run_pending_mapping();
    } catch (...) {
      next.wait();
      throw;
    }
    f = next.get();
  } else {
    f = m.make_frame(frame, &feature_s);
  }
  m.timings.features += feature_s;
  const int nf = static_cast<int>(f.kps.size());
  FrameResult r = m.initialized ? m.track(std::move(f)) : m.try_initialize(std::move(f));
  r.features = nf;
  return r;
}

void Odometry::finish() {
  impl_->run_pending_mapping();
  for (auto& k : impl_->kfs)
    if (!k->bad && !k->final) impl_->finalize_keyframe(*k);
}

bool Odometry::initialized() const { return impl_->initialized; }

map::Map Odometry::map() const {
  impl_->run_pending_mapping();
  const Impl& m = *impl_;
  map::Map out;
  out.cameras.push_back(m.cam);
  for (const auto& k : m.kfs) {
    if (k->bad) continue;
    map::Keyframe K;
    K.id = k->id;
    K.frame_index = k->index;
    K.timestamp = k->timestamp;
    K.T_cw = k->T_cw;
    K.camera_id = m.cam.id;
    out.keyframes.push_back(K);
  }
  for (const Pt& p : m.pts) {
    if (p.bad || p.obs.size() < 2) continue;
    int ref = p.obs.front().first;
    out.points.push_back({p.id, p.X, ref});
    for (const auto& [k, i] : p.obs)
      out.observations.push_back({k, p.id, m.kfs[static_cast<std::size_t>(k)]->uv(i)});
  }
  return out;
}

KeyframeView Odometry::keyframe_view(int id) const {
  GEODRIFT_CHECK(id >= 0 && id < static_cast<int>(impl_->kfs.size()) &&
                     !impl_->kfs[static_cast<std::size_t>(id)]->bad,
                 "keyframe " << id << " does not exist or was culled");
  impl_->run_pending_mapping();
  GEODRIFT_CHECK(!impl_->kfs[static_cast<std::size_t>(id)]->bad,
                 "keyframe " << id << " was culled");
  return impl_->view_of(*impl_->kfs[static_cast<std::size_t>(id)]);
}

const std::vector<std::pair<int, lie::SE3d>>& Odometry::frame_poses() const {
  return impl_->frame_poses;
}
int Odometry::num_keyframes() const { return static_cast<int>(impl_->live_kfs().size()); }
int Odometry::num_points() const {
  int n = 0;
  for (const Pt& p : impl_->pts) n += !p.bad;
  return n;
}
const OdometryTimings& Odometry::timings() const { return impl_->timings; }
const map::Camera& Odometry::camera() const { return impl_->cam; }
int Odometry::init_attempts() const { return impl_->init_attempts; }
const std::string& Odometry::last_init_failure() const { return impl_->last_init_failure; }

}  // namespace geodrift::vo
