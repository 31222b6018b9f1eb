// geodrift eval: the paper's metrics (DESIGN.md "Evaluation") of a result against ground truth.
#include <Eigen/Geometry>
#include <climits>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <geodrift/error.hpp>
#include <geodrift/eval/errors.hpp>
#include <geodrift/geo/kitti.hpp>
#include <geodrift/io/csv.hpp>
#include <geodrift/io/trajectory.hpp>
#include <geodrift/version.hpp>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "cli_util.hpp"
#include "commands.hpp"

namespace geodrift::cli {
namespace {

const char* kEvalHelp =
    R"(usage: geodrift eval --result PATH --ground-truth FILE [options]

Compares a trajectory in W with ground truth in W, matched by frame number, and prints the
paper's metrics: 2D (horizontal) error Ave / SD / max over the keyframes (and over those after
the last anchor, when the result says which), the global Sim(3) error (Umeyama Sim3 alignment
of the result to the ground truth, then the 2D error), ATE (no alignment), RPE and the KITTI
segment error (translation % and deg/m over 100..800 m).

  --result PATH       a `geodrift correct` output directory, its trajectory.csv (the poses
                      then come from trajectory_kitti.txt beside it), or a KITTI/TUM file in W
                      (all poses count as keyframes; frames from a leading index or line order)
  --result-format F   auto | kitti | tum, for a KITTI/TUM --result (default auto)
  --ground-truth FILE KITTI or TUM ground truth (frames from a leading index or line order)
  --gt-format F       auto (default) | kitti | tum
  --kitti-to-w        the ground truth is in KITTI's world (cam0 of frame 0, y down, z
                      forward): map it to W (E = x, N = z, U = -y) at the ASSUMED KITTI geo
                      origin (implies --gt-origin kitti)
  --gt-origin O       origin of the ground truth's W: LAT,LON,H or `kitti` (the assumed KITTI
                      origin). A trajectory.csv result is then re-expressed in that W from its
                      UTM columns (same UTM zone required), so results whose W started at
                      their first anchor compare correctly. Without it the result's x,y,z and
                      the ground truth must already share one W.
  --rpe-delta N       RPE pair distance in frames (default 10)
  --json              machine-readable output on stdout
  --help              this text
)";

struct Result {
  bool from_csv = false;
  Eigen::Vector3d origin_utm = Eigen::Vector3d::Zero();  // (E0, N0, h0) of the result's W
  std::string zone;
  std::vector<int> frame;
  std::vector<char> keyframe, after;
  std::vector<Eigen::Vector3d> c;
  std::vector<Eigen::Isometry3d> T_wc;  // empty when orientation is unknown
  bool has_after = false;
};

Eigen::Isometry3d iso(const lie::SE3d& T) {
  Eigen::Isometry3d I = Eigen::Isometry3d::Identity();
  I.matrix() = T.matrix();
  return I;
}

Result read_result(const std::string& path_in, io::TrajectoryFormat fmt) {
  namespace fs = std::filesystem;
  std::string path = path_in;
  std::error_code ec;
  if (fs::is_directory(path, ec)) path = (fs::path(path) / "trajectory.csv").string();
  Result r;
  if (fs::path(path).extension() == ".csv") {
    const auto rec = io::read_trajectory_csv(path);
    for (const auto& x : rec) {
      r.frame.push_back(x.frame);
      r.keyframe.push_back(x.keyframe);
      r.after.push_back(x.after_last_anchor);
      r.c.push_back(x.p_w);
    }
    r.has_after = true;
    r.from_csv = true;
    if (!rec.empty()) {
      r.zone = rec.front().zone;
      r.origin_utm = Eigen::Vector3d(rec.front().easting - rec.front().p_w.x(),
                                     rec.front().northing - rec.front().p_w.y(),
                                     rec.front().height - rec.front().p_w.z());
    }
    const fs::path kitti = fs::path(path).parent_path() / "trajectory_kitti.txt";
    if (fs::exists(kitti, ec)) {
      const io::Trajectory t = io::read_trajectory(kitti.string(), io::TrajectoryFormat::kKitti);
      if (t.poses.size() != rec.size())
        throw InvalidArgument(kitti.string() + ": " + std::to_string(t.poses.size()) +
                              " poses but " + path + " has " + std::to_string(rec.size()) +
                              " rows");
      for (std::size_t i = 0; i < rec.size(); ++i) {
        r.T_wc.push_back(iso(t.poses[i].T_cw.inverse()));
        if ((r.T_wc.back().translation() - r.c[i]).norm() > 1e-3)
          throw InvalidArgument(kitti.string() + ": pose " + std::to_string(i) +
                                " does not match row " + std::to_string(i) + " of " + path);
      }
    }
  } else {
    const io::Trajectory t = io::read_trajectory(path, fmt);
    for (const auto& p : t.poses) {
      r.frame.push_back(p.frame);
      r.keyframe.push_back(1);
      r.after.push_back(0);
      r.T_wc.push_back(iso(p.T_cw.inverse()));
      r.c.push_back(r.T_wc.back().translation());
    }
  }
  return r;
}

std::string num(double v) { return std::isfinite(v) ? io::detail::fmt(v, 6) : "null"; }

std::string stats_json(const eval::ErrorStats& s) {
  std::ostringstream o;
  o << "{\"mean\": " << num(s.mean) << ", \"sd\": " << num(s.sd) << ", \"max\": " << num(s.max)
    << ", \"rmse\": " << num(s.rmse) << ", \"count\": " << s.count << "}";
  return o.str();
}

}  // namespace

int run_eval(int argc, char** argv) {
  const Args args(
      argc, argv,
      {"result", "result-format", "ground-truth", "gt-format", "rpe-delta", "gt-origin"},
      {"help", "json", "kitti-to-w"});
  if (args.flag("help")) {
    std::fputs(kEvalHelp, stdout);
    return 0;
  }
  const std::string result_path = args.required("result");
  const std::string gt_path = args.required("ground-truth");
  io::TrajectoryFormat rfmt, gfmt;
  try {
    rfmt = io::parse_trajectory_format(args.get("result-format", "auto"));
    gfmt = io::parse_trajectory_format(args.get("gt-format", "auto"));
  } catch (const InvalidArgument& e) {
    throw UsageError(e.what());
  }
  const long long delta = args.get_int("rpe-delta", 10);
  if (delta < 1) throw UsageError("--rpe-delta must be >= 1");

  Result r = read_result(result_path, rfmt);
  if (args.has("gt-origin") || args.flag("kitti-to-w")) {
    const std::string o = args.get("gt-origin", "kitti");
    geo::LocalFrame gf;
    if (o == "kitti") {
      gf = geo::kitti_local_frame();
    } else {
      const std::vector<double> v = parse_number_list("gt-origin", o);
      if (v.size() != 3) throw UsageError("--gt-origin needs LAT,LON,H or kitti");
      gf = geo::LocalFrame::from_geodetic(v[0], v[1], v[2]);
    }
    if (!r.from_csv)
      throw UsageError(
          "--gt-origin/--kitti-to-w re-express a trajectory.csv result only; a "
          "KITTI/TUM result must already be in the ground truth's W");
    const std::string gz = geo::format_utm_zone(gf.zone(), gf.northp());
    if (r.zone != gz)
      throw InvalidArgument(result_path + ": result is in UTM zone " + r.zone +
                            ", the ground truth's W in zone " + gz);
    const geo::UtmCoordinate u0 = gf.utm_of(Eigen::Vector3d::Zero());
    const double h0 = gf.to_geodetic(Eigen::Vector3d::Zero()).height;
    const Eigen::Vector3d shift = r.origin_utm - Eigen::Vector3d(u0.easting, u0.northing, h0);
    for (auto& c : r.c) c += shift;
    for (auto& T : r.T_wc) T.translation() += shift;
  }
  const io::Trajectory gt = io::read_trajectory(gt_path, gfmt);
  std::map<int, Eigen::Isometry3d> gt_by_frame;
  for (const auto& p : gt.poses) {
    Eigen::Isometry3d T = iso(p.T_cw.inverse());
    if (args.flag("kitti-to-w")) T = geo::kitti_pose_to_world(T);
    gt_by_frame[p.frame] = T;
  }

  // Keyframes with ground truth (2D error); all poses with ground truth (ATE, RPE, segments).
  std::vector<Eigen::Vector3d> est_k, gt_k, est_all, gt_all;
  std::vector<int> frame_k;
  std::vector<Eigen::Isometry3d> est_T, gt_T;
  int last_anchor_frame = INT_MIN;
  int missing = 0;
  for (std::size_t i = 0; i < r.frame.size(); ++i) {
    if (r.has_after && !r.after[i]) last_anchor_frame = std::max(last_anchor_frame, r.frame[i]);
    const auto it = gt_by_frame.find(r.frame[i]);
    if (it == gt_by_frame.end()) {
      ++missing;
      continue;
    }
    est_all.push_back(r.c[i]);
    gt_all.push_back(it->second.translation());
    if (!r.T_wc.empty()) {
      est_T.push_back(r.T_wc[i]);
      gt_T.push_back(it->second);
    }
    if (r.keyframe[i]) {
      est_k.push_back(r.c[i]);
      gt_k.push_back(it->second.translation());
      frame_k.push_back(r.frame[i]);
    }
  }
  if (est_k.size() < 3)
    throw InvalidArgument("only " + std::to_string(est_k.size()) + " keyframes of " + result_path +
                          " have ground truth in " + gt_path + " (frames must match)");
  const bool split = r.has_after && last_anchor_frame != INT_MIN;
  const eval::HorizontalErrorReport e2d = eval::horizontal_errors(
      est_k, gt_k, frame_k, split ? last_anchor_frame : std::numeric_limits<int>::max());
  const eval::GlobalSim3Error g = eval::global_sim3_error(est_k, gt_k);
  const double ate = eval::ate_rmse(est_all, gt_all, eval::AteAlignment::kNone);
  const bool poses = est_T.size() > static_cast<std::size_t>(delta);
  eval::RpeResult rpe;
  eval::KittiSegmentError seg;
  if (poses) {
    rpe = eval::relative_pose_error(est_T, gt_T, static_cast<double>(delta));
    seg = eval::kitti_segment_error(est_T, gt_T, {100, 200, 300, 400, 500, 600, 700, 800}, 10);
  }

  if (args.flag("json")) {
    std::printf("{\"geodrift_version\": \"%s\", \"result\": %s, \"ground_truth\": %s,\n", kVersion,
                io::detail::json_string(result_path).c_str(),
                io::detail::json_string(gt_path).c_str());
    std::printf(
        " \"units\": \"metres, radians\", \"keyframes_evaluated\": %zu, "
        "\"poses_without_ground_truth\": %d,\n",
        est_k.size(), missing);
    std::printf(" \"error_2d\": %s,\n", stats_json(e2d.all).c_str());
    std::printf(" \"error_2d_after_last_anchor\": %s,\n",
                split ? stats_json(e2d.after_last_anchor).c_str() : "null");
    std::printf(" \"global_sim3_error_2d\": %s,\n",
                g.alignment.ok() ? stats_json(g.errors.all).c_str() : "null");
    std::printf(" \"ate_rmse\": %s,\n", num(ate).c_str());
    if (poses) {
      std::printf(" \"rpe_delta_frames\": %lld, \"rpe_translation\": %s, \"rpe_rotation\": %s,\n",
                  delta, stats_json(rpe.translation).c_str(), stats_json(rpe.rotation).c_str());
      std::printf(
          " \"kitti_segment\": {\"translation_percent\": %s, \"rotation_deg_per_m\": %s, "
          "\"segments\": %d}\n}\n",
          num(seg.translation_percent).c_str(), num(seg.rotation_deg_per_m).c_str(), seg.segments);
    } else {
      std::printf(
          " \"rpe_translation\": null, \"rpe_rotation\": null, \"kitti_segment\": null\n}\n");
    }
    return 0;
  }
  std::printf("geodrift %s eval: %s vs %s\n", kVersion, result_path.c_str(), gt_path.c_str());
  std::printf("  keyframes evaluated        %zu (poses without ground truth: %d)\n", est_k.size(),
              missing);
  std::printf("  2D error [m]               Ave %.3f  SD %.3f  max %.3f\n", e2d.all.mean,
              e2d.all.sd, e2d.all.max);
  if (split)
    std::printf(
        "  2D error after last anchor Ave %.3f  SD %.3f  max %.3f  (%d keyframes after "
        "frame %d)\n",
        e2d.after_last_anchor.mean, e2d.after_last_anchor.sd, e2d.after_last_anchor.max,
        e2d.after_last_anchor.count, last_anchor_frame);
  if (g.alignment.ok())
    std::printf("  global Sim3 error [m]      Ave %.3f  SD %.3f  max %.3f  (Umeyama scale %.6g)\n",
                g.errors.all.mean, g.errors.all.sd, g.errors.all.max, g.alignment.s);
  else
    std::printf("  global Sim3 error          n/a (%s)\n", g.alignment.message.c_str());
  std::printf("  ATE RMSE [m]               %.3f (no alignment)\n", ate);
  if (poses) {
    std::printf("  RPE (%lld frames)           trans %.3f m  rot %.4f deg (mean)\n", delta,
                rpe.translation.mean, rpe.rotation.mean * 180.0 / M_PI);
    std::printf("  KITTI segment error        %.3f %%  %.5f deg/m  (%d segments)\n",
                seg.translation_percent, seg.rotation_deg_per_m, seg.segments);
  } else {
    std::printf("  RPE, KITTI segment error   n/a (the result has no orientations)\n");
  }
  return 0;
}

}  // namespace geodrift::cli
