// The VO tracker on rendered sequences: tracked fraction and KITTI-style drift of the keyframe
// path after Sim3 alignment; clean failures on pure rotation and black frames.

#include <catch2/catch.hpp>
#include <cstdlib>
#include <map>

#include "corridor.hpp"
#include "geodrift/eval/errors.hpp"
#include "geodrift/eval/umeyama.hpp"
#include "geodrift/vo/odometry.hpp"

using namespace geodrift;

namespace {

bool reduced() {
  const char* ci = std::getenv("CI");
  const char* red = std::getenv("GEODRIFT_REDUCED");
  return (ci && std::string(ci) == "true") || (red && std::string(red) == "1");
}

struct RunResult {
  int frames = 0, tracked = 0, keyframes = 0;
  double segment_error_percent = -1;
  int segments = 0;
  double ate_rmse_m = -1;
  std::string messages;
};

/// Runs the VO over ground-truth poses T_wc rendered by `render(i)` and evaluates the keyframes.
template <class Render>
RunResult run_sequence(const map::Camera& cam, const std::vector<Eigen::Isometry3d>& gt,
                       Render render, const vo::OdometryOptions& opt = {}, double seg_len = 100) {
  vo::Odometry odo(cam, opt);
  int batches = 0, last_id = -1;
  bool ordered = true;
  odo.set_keyframe_callback([&](const vo::KeyframeBatch& b) {
    ++batches;
    ordered = ordered && b.keyframe.id > last_id;
    last_id = b.keyframe.id;
  });
  RunResult r;
  for (std::size_t i = 0; i < gt.size(); ++i) {
    vo::Frame f;
    f.index = static_cast<int>(i);
    f.timestamp = 0.1 * i;
    f.gray = render(static_cast<int>(i));
    const vo::FrameResult fr = odo.process(f);
    ++r.frames;
    if (fr.has_pose()) ++r.tracked;
    if (!fr.message.empty() && fr.state != vo::FrameResult::State::kTracked)
      r.messages += fr.message + "\n";
  }
  odo.finish();
  CHECK(ordered);
  const map::Map m = odo.map();
  r.keyframes = static_cast<int>(m.keyframes.size());
  CHECK(batches == r.keyframes);
  if (m.keyframes.size() < 3) return r;
  std::vector<Eigen::Vector3d> est, ref;
  std::vector<Eigen::Isometry3d> est_T, gt_T;
  for (const auto& k : m.keyframes) {
    est.push_back(k.center());
    ref.push_back(gt[static_cast<std::size_t>(k.frame_index)].translation());
  }
  const eval::Alignment a = eval::umeyama(est, ref, true);
  REQUIRE(a.ok());
  r.ate_rmse_m = a.rmse;
  for (const auto& k : m.keyframes) {
    const lie::SE3d T_wc = k.T_cw.inverse();
    Eigen::Isometry3d E = Eigen::Isometry3d::Identity();
    E.linear() = a.R * T_wc.rotation().matrix();
    E.translation() = a.apply(T_wc.translation());
    est_T.push_back(E);
    gt_T.push_back(gt[static_cast<std::size_t>(k.frame_index)]);
  }
  const eval::KittiSegmentError e = eval::kitti_segment_error(est_T, gt_T, {seg_len}, 1);
  r.segment_error_percent = e.translation_percent;
  r.segments = e.segments;
  return r;
}

}  // namespace

TEST_CASE("VO tracks a rendered corridor drive with low drift", "[vo]") {
  const map::Camera cam = test::corridor_camera();
  const test::Corridor world;
  const int n = reduced() ? 120 : 200;
  std::vector<Eigen::Isometry3d> gt;
  for (int i = 0; i < n; ++i) gt.push_back(test::Corridor::pose(i));
  const RunResult r = run_sequence(
      cam, gt, [&](int i) { return world.render(cam, gt[static_cast<std::size_t>(i)]); }, {}, 50.0);
  INFO(r.messages << "tracked " << r.tracked << "/" << r.frames << ", keyframes " << r.keyframes
                  << ", ATE " << r.ate_rmse_m << " m, segment error " << r.segment_error_percent
                  << " % over " << r.segments << " 50 m segments");
  CHECK(r.tracked >= 0.95 * r.frames);
  CHECK(r.segments > 0);
  CHECK(r.segment_error_percent < 1.0);
}
