#include "geodrift/geotag/pipeline.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <limits>
#include <list>

#include "geodrift/error.hpp"
#include "geodrift/geotag/features.hpp"

#if defined(GEODRIFT_GEOTAG_HAVE_KVLD)
#include "geodrift/kvld/kvld.hpp"
#endif

namespace geodrift::geotag {

namespace {
/// Horizontal field of view of a pinhole camera (rad): the wider side of the principal point.
double horizontal_fov(const map::Camera& c) {
  return std::atan(c.cx / c.fx) + std::atan((c.width - c.cx) / c.fx);
}

/// Angle (rad) between the horizontal projections of two directions in W; NaN when either is
/// (nearly) vertical.
double horizontal_angle(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  const Eigen::Vector2d ha = a.head<2>(), hb = b.head<2>();
  if (ha.norm() < 1e-3 * a.norm() || hb.norm() < 1e-3 * b.norm())
    return std::numeric_limits<double>::quiet_NaN();
  return std::acos(std::clamp(ha.normalized().dot(hb.normalized()), -1.0, 1.0));
}

double thread_cpu_s() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}
}  // namespace

struct GeoLocalizer::Cache {
#if defined(GEODRIFT_GEOTAG_HAVE_KVLD)
  // K-VLD scale spaces: the current keyframe's and the last few views' (adjacent keyframes
  // retrieve the same views).
  int keyframe_id = -1;
  std::unique_ptr<kvld::ImageScale> keyframe_scale;
  std::list<std::pair<int, std::shared_ptr<kvld::ImageScale>>> views;
  std::shared_ptr<kvld::ImageScale> view_scale(const Database& db, int v) {
    for (auto it = views.begin(); it != views.end(); ++it)
      if (it->first == v) {
        views.splice(views.begin(), views, it);
        return views.front().second;
      }
    views.push_front({v, std::make_shared<kvld::ImageScale>(db.view_image(v))});
    if (views.size() > 16) views.pop_back();
    return views.front().second;
  }
#endif
};

GeoLocalizer::GeoLocalizer(const Database& db, const geo::LocalFrame& frame,
                           const PipelineOptions& options)
    : db_(db), frame_(frame), options_(options), cache_(std::make_unique<Cache>()) {
  GEODRIFT_CHECK(!db.views().empty(), "GeoLocalizer: the geotag database has no views");
  GEODRIFT_CHECK(options.ratio > 0 && options.ratio <= 1,
                 "GeoLocalizer: ratio " << options.ratio << " outside (0, 1]");
  GEODRIFT_CHECK(options.max_putative >= 0, "GeoLocalizer: max_putative must be >= 0");
  GEODRIFT_CHECK(options.top_k >= 1, "GeoLocalizer: top_k " << options.top_k << " must be >= 1");
  GEODRIFT_CHECK(options.keyframe_stride >= 1,
                 "GeoLocalizer: keyframe_stride " << options.keyframe_stride << " must be >= 1");
  GEODRIFT_CHECK(options.top_k_gated >= 0 && options.max_localized_per_keyframe >= 0,
                 "GeoLocalizer: top_k_gated and max_localized_per_keyframe must be >= 0");
  GEODRIFT_CHECK(options.gate_radius_m > 0,
                 "GeoLocalizer: gate radius " << options.gate_radius_m << " m must be > 0");
}

GeoLocalizer::~GeoLocalizer() = default;

bool GeoLocalizer::have_kvld() const {
#if defined(GEODRIFT_GEOTAG_HAVE_KVLD)
  return true;
#else
  return false;
#endif
}

std::vector<cv::DMatch> GeoLocalizer::putative(const KeyframeFeatures& kf, int view,
                                               ViewAttempt* a) {
  const double c0 = thread_cpu_s();
  std::vector<cv::DMatch> m =
      match_ratio_mutual(kf.descriptors, db_.orb(view).descriptors, options_.ratio);
  stats_.orb_match_cpu_s += thread_cpu_s() - c0;
  if (options_.max_putative > 0 && static_cast<int>(m.size()) > options_.max_putative)
    m.resize(options_.max_putative);  // sorted by distance: the best are kept
  a->putative = static_cast<int>(m.size());
  return m;
}

std::vector<std::pair<int, int>> GeoLocalizer::match(const KeyframeFeatures& kf, int view,
                                                     ViewAttempt* a) {
  return filter(kf, view, putative(kf, view, a), a);
}

std::vector<std::pair<int, int>> GeoLocalizer::filter(const KeyframeFeatures& kf, int view,
                                                      const std::vector<cv::DMatch>& m,
                                                      ViewAttempt* a) {
  const OrbFeatures vf = db_.orb(view);
  const double c1 = thread_cpu_s();
  std::vector<std::pair<int, int>> out;
#if defined(GEODRIFT_GEOTAG_HAVE_KVLD)
  if (options_.use_kvld && !m.empty()) {
    if (cache_->keyframe_id != kf.keyframe.id || !cache_->keyframe_scale) {
      cache_->keyframe_scale = std::make_unique<kvld::ImageScale>(kf.gray);
      cache_->keyframe_id = kf.keyframe.id;
    }
    const std::shared_ptr<kvld::ImageScale> vs = cache_->view_scale(db_, view);
    std::vector<kvld::Match> put;
    put.reserve(m.size());
    for (const cv::DMatch& d : m) put.push_back({d.queryIdx, d.trainIdx});
    const kvld::Result r =
        kvld::filter(*cache_->keyframe_scale, *vs, kvld::keypoints_from_cv(kf.keypoints),
                     kvld::keypoints_from_cv(vf.cv_keypoints()), put);
    for (const kvld::Match& k : r.matches) out.push_back({k.i1, k.i2});
    a->kept = static_cast<int>(out.size());
    stats_.kvld_cpu_s += thread_cpu_s() - c1;
    return out;
  }
#endif
  for (const cv::DMatch& d : m) out.push_back({d.queryIdx, d.trainIdx});
  a->kept = static_cast<int>(out.size());
  return out;
}

std::vector<map::Correspondence> GeoLocalizer::process(
    const KeyframeFeatures& kf,
    const std::function<const Eigen::Vector3d*(int point_id)>& point_position,
    const Eigen::Vector3d* position_w, std::vector<ViewAttempt>* attempts) {
  GEODRIFT_CHECK(!kf.gray.empty() && kf.gray.type() == CV_8UC1,
                 "keyframe " << kf.keyframe.id << ": an 8-bit grayscale image is needed");
  GEODRIFT_CHECK(kf.keypoints.size() == kf.point_ids.size() &&
                     static_cast<int>(kf.keypoints.size()) == kf.descriptors.rows,
                 "keyframe " << kf.keyframe.id << ": " << kf.keypoints.size() << " keypoints, "
                             << kf.descriptors.rows << " descriptors, " << kf.point_ids.size()
                             << " point ids");
  const auto w0 = std::chrono::steady_clock::now();
  const double c0 = thread_cpu_s();
  std::vector<map::Correspondence> out;
  if (stats_.keyframes_seen++ % options_.keyframe_stride != 0) return out;
  ++stats_.keyframes_queried;
  QueryOptions q;
  q.top_k = options_.top_k;
  q.frame = &frame_;
  q.gate_radius_m = options_.gate_radius_m;
  if (options_.gate && position_w) {
    q.gate_position_w = *position_w;
    if (options_.top_k_gated > 0) q.top_k = options_.top_k_gated;
  }
  const std::vector<Retrieved> top = db_.query(kf.gray, q);
  stats_.retrieval_cpu_s += thread_cpu_s() - c0;
  for (const Retrieved& r : top) {
    if (options_.max_localized_per_keyframe > 0 &&
        static_cast<int>(out.size()) >= options_.max_localized_per_keyframe)
      break;
    if (r.score < options_.min_retrieval_score) continue;
    if (options_.localize_each_view_once && localized_.count(r.view)) continue;
    const GeoView& view = db_.views()[r.view];
    if (options_.gate_view_direction && kf.optical_axis_w && std::isfinite(view.heading)) {
      const Eigen::Vector3d axis_v =
          view_pose_world(view, frame_).rotation().inverse().act(Eigen::Vector3d::UnitZ());
      const double limit = 0.5 * (horizontal_fov(view.camera) + horizontal_fov(db_.video_camera()));
      if (horizontal_angle(axis_v, *kf.optical_axis_w) > limit) {
        ++stats_.views_skipped_direction;
        continue;
      }
    }
    ViewAttempt a;
    a.keyframe = kf.keyframe.id;
    a.view = r.view;
    a.score = r.score;
    ++stats_.views_tried;
    const std::vector<cv::DMatch> put = putative(kf, r.view, &a);
    // K-VLD only removes matches, and a view is accepted only with at least
    // max(min_correspondences, min_inliers) 2D-3D pairs: when fewer putative matches observe a
    // map point, the outcome is known without K-VLD (most tried views end here).
    const int needed =
        std::max(options_.localize.min_correspondences, options_.localize.min_inliers);
    int putative_3d = 0;
    for (const cv::DMatch& d : put) {
      const int pid = kf.point_ids[d.queryIdx];
      putative_3d += pid >= 0 && point_position(pid) != nullptr ? 1 : 0;
    }
    if (putative_3d < needed) {
      a.result.correspondences = putative_3d;
      a.result.reason = std::to_string(putative_3d) +
                        " putative matches observe a map point, need " + std::to_string(needed) +
                        " (K-VLD and PnP skipped)";
      if (attempts) attempts->push_back(std::move(a));
      continue;
    }
    const std::vector<std::pair<int, int>> m = filter(kf, r.view, put, &a);
    std::vector<Eigen::Vector3d> X;
    std::vector<Eigen::Vector2d> uv;
    const OrbFeatures vf = db_.orb(r.view);
    for (const auto& [ik, iv] : m) {
      const int pid = kf.point_ids[ik];
      if (pid < 0) continue;
      const Eigen::Vector3d* p = point_position(pid);
      if (!p) continue;
      X.push_back(*p);
      uv.push_back({vf.keypoints[iv].x, vf.keypoints[iv].y});
    }
    a.pairs_3d = static_cast<int>(X.size());
    const double cp = thread_cpu_s();
    a.result = localize_view(X, uv, db_.views()[r.view].camera, options_.localize);
    if (a.result.inliers > 0 && db_.views()[r.view].direction >= 0) {
      // Angle between the view's and the keyframe's "down" axes, both expressed in M.
      const Eigen::Vector3d down_v =
          a.result.T_vm.rotation().inverse().act(Eigen::Vector3d::UnitY());
      const Eigen::Vector3d down_k =
          kf.keyframe.T_cw.rotation().inverse().act(Eigen::Vector3d::UnitY());
      const double tilt =
          std::acos(std::clamp(down_v.dot(down_k), -1.0, 1.0)) * 180.0 / 3.14159265358979323846;
      a.tilt_deg = tilt;
      if (a.result.ok && options_.max_view_tilt_deg > 0 && tilt > options_.max_view_tilt_deg) {
        a.result.ok = false;
        a.result.reason = "view tilted " + std::to_string(tilt) +
                          " deg from the keyframe (panorama views are level)";
      }
    }
    stats_.pnp_cpu_s += thread_cpu_s() - cp;
    if (a.result.ok) {
      a.correspondence = next_id_;
      out.push_back(make_correspondence(next_id_++, db_.views()[r.view], kf.keyframe, a.result,
                                        frame_, options_.sigma_m));
      localized_.insert(r.view);
    }
    if (attempts) attempts->push_back(std::move(a));
  }
  stats_.total_cpu_s += thread_cpu_s() - c0;
  stats_.total_wall_s +=
      std::chrono::duration<double>(std::chrono::steady_clock::now() - w0).count();
  return out;
}

}  // namespace geodrift::geotag
