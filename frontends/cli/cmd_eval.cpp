// geodrift eval: the paper's metrics (DESIGN.md "Evaluation") of a result against ground truth.
#include <Eigen/Geometry>
#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <geodrift/error.hpp>
#include <geodrift/eval/associate.hpp>
#include <geodrift/eval/errors.hpp>
#include <geodrift/geo/kitti.hpp>
#include <geodrift/io/csv.hpp>
#include <geodrift/io/trajectory.hpp>
#include <geodrift/version.hpp>
#include <iomanip>
#include <sstream>
#include <string>
#include <vector>

#include "cli_util.hpp"
#include "commands.hpp"

namespace geodrift::cli {
namespace {

const char* kEvalHelp =
    R"(usage: geodrift eval --result PATH --ground-truth FILE [options]

Compares a trajectory in W with ground truth in W and prints the paper's metrics: 2D
(horizontal) error Ave / SD / max over the keyframes (and over those after the last anchor,
when the result says which), the global Sim(3) error (Umeyama Sim3 alignment of the result to
the ground truth, then the 2D error), ATE (no alignment), RPE and the KITTI segment error
(translation % and deg/m over 100..800 m). Result poses without ground truth are left out of
the metrics and counted.

  --result PATH       a `geodrift correct` output directory, its trajectory.csv (the poses
                      then come from trajectory_kitti.txt beside it; timestamps from its
                      timestamp column), or a KITTI/TUM file in W (all poses count as
                      keyframes; frames from a leading index or line order)
  --result-format F   auto | kitti | tum, for a KITTI/TUM --result (default auto)
  --result-times FILE timestamps (s) of a KITTI --result without a time column, one per pose
  --ground-truth FILE KITTI or TUM ground truth (frames from a leading index or line order)
  --gt-format F       auto (default) | kitti | tum
  --gt-times FILE     timestamps (s) of a KITTI ground truth, one per pose (KITTI's times.txt)
  --associate A       how result poses find their ground truth (default auto):
                        time   by timestamp, as evo does: each result pose takes the ground-
                               truth pose nearest to (its time + --time-offset), if within
                               --max-time-diff; each ground-truth pose is used at most once
                               (when several result poses share the nearest one, the nearest
                               in time keeps it, the others are unmatched, not re-paired)
                        frame  by equal frame number
                        auto   time when both sides have timestamps (TUM files, KITTI with a
                               time column or --*-times, a trajectory.csv with timestamps),
                               else frame
  --max-time-diff S   time association tolerance in seconds, finite and >= 0 (default 0.01,
                      evo's default)
  --time-offset S     seconds added to the result's timestamps before matching (default 0,
                      evo's --t_offset)
  --kitti-to-w        the ground truth is in KITTI's world (cam0 of frame 0, y down, z
                      forward): map it to W (E = x, N = z, U = -y) at the ASSUMED KITTI geo
                      origin (implies --gt-origin kitti)
  --gt-origin O       origin of the ground truth's W: LAT,LON,H or `kitti` (the assumed KITTI
                      origin). A trajectory.csv result is then re-expressed in that W from its
                      UTM columns (same UTM zone required), so results whose W started at
                      their first anchor compare correctly. Without it the result's x,y,z and
                      the ground truth must already share one W.
  --rpe-delta N       RPE pair distance (default 10): pairs of MATCHED result poses N apart in
                      the result's order (the KITTI segment error also steps over matched
                      poses). With frame association and every frame matched that is N frames;
                      with time association of a keyframe result it is N keyframes, whatever
                      time lies between them.
  --json              machine-readable output on stdout
  --help              this text

The association used and how many result poses were matched / unmatched are printed (and in
--json under "association"). At least 3 keyframes must match (the Sim3 alignment needs 3),
else eval fails naming the files and the tolerance.
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
  std::string path;        // the file the rows came from (trajectory.csv for a directory)
  std::vector<int> line;   // 1-based line of each row in `path`
  std::vector<double> t;   // timestamps, seconds (NaN where unknown)
  bool has_times = false;  // every row has a timestamp
  int untimed_line = 0;    // trajectory.csv: first row without a timestamp (0: none)
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
  r.path = path;
  if (fs::path(path).extension() == ".csv") {
    const auto rec = io::read_trajectory_csv(path);
    // The CSV reader checks each row alone; eval needs frames and timestamps in order.
    std::size_t timed = 0;
    for (std::size_t i = 0; i < rec.size(); ++i) {
      const auto& x = rec[i];
      if (i > 0 && !(x.frame > rec[i - 1].frame))
        io::detail::parse_error(path, x.line,
                                "frame " + std::to_string(x.frame) + " does not increase (line " +
                                    std::to_string(rec[i - 1].line) + " has " +
                                    std::to_string(rec[i - 1].frame) + ")");
      if (std::isfinite(x.timestamp))
        ++timed;
      else if (r.untimed_line == 0)
        r.untimed_line = x.line;
    }
    r.has_times = !rec.empty() && timed == rec.size();
    for (std::size_t i = 1; r.has_times && i < rec.size(); ++i) {
      if (!(rec[i].timestamp > rec[i - 1].timestamp)) {
        std::ostringstream os;
        os << std::setprecision(17) << "timestamp " << rec[i].timestamp
           << " does not increase (previous " << rec[i - 1].timestamp << " on line "
           << rec[i - 1].line << ")";
        io::detail::parse_error(path, rec[i].line, os.str());
      }
    }
    for (const auto& x : rec) {
      r.line.push_back(x.line);
      r.t.push_back(x.timestamp);
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
    r.has_times = t.has_timestamps;  // the reader checked they are finite and increase
    for (const auto& p : t.poses) {
      r.line.push_back(p.line);
      r.t.push_back(p.timestamp);
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
      {"result", "result-format", "result-times", "ground-truth", "gt-format", "gt-times",
       "rpe-delta", "gt-origin", "associate", "max-time-diff", "time-offset"},
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
  const std::string assoc_mode = args.get("associate", "auto");
  if (assoc_mode != "auto" && assoc_mode != "time" && assoc_mode != "frame")
    throw UsageError("--associate '" + assoc_mode + "' is not one of auto, time, frame");
  const auto one_number = [&](const std::string& option, double def) {
    if (!args.has(option)) return def;
    const std::vector<double> v = parse_number_list(option, args.get(option));
    if (v.size() != 1) throw UsageError("option --" + option + " takes one number of seconds");
    return v[0];
  };
  eval::TimeAssociationOptions topt;
  topt.max_time_diff_s = one_number("max-time-diff", topt.max_time_diff_s);
  topt.time_offset_s = one_number("time-offset", topt.time_offset_s);
  if (!(topt.max_time_diff_s >= 0.0))
    throw UsageError("--max-time-diff " + args.get("max-time-diff") + " must be >= 0 seconds");

  Result r = read_result(result_path, rfmt);
  if (args.has("result-times")) {
    if (std::any_of(r.t.begin(), r.t.end(), [](double v) { return std::isfinite(v); }))
      throw UsageError("--result-times: " + r.path + " already has timestamps");
    r.t = read_times_file(args.get("result-times"), r.frame.size(), r.path);
    r.has_times = true;
    r.untimed_line = 0;
  }
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
  std::vector<int> gt_frame;
  std::vector<double> gt_t;
  std::vector<Eigen::Isometry3d> gt_pose;
  for (const auto& p : gt.poses) {
    Eigen::Isometry3d T = iso(p.T_cw.inverse());
    if (args.flag("kitti-to-w")) T = geo::kitti_pose_to_world(T);
    gt_pose.push_back(T);
    gt_frame.push_back(p.frame);
    gt_t.push_back(p.timestamp);
  }
  bool gt_has_times = gt.has_timestamps;  // the reader checked they are finite and increase
  if (args.has("gt-times")) {
    if (gt_has_times) throw UsageError("--gt-times: " + gt_path + " already has timestamps");
    gt_t = read_times_file(args.get("gt-times"), gt.poses.size(), gt_path);
    gt_has_times = true;
  }

  // Which association: time needs timestamps on both sides.
  const auto no_times = [](const std::string& path, int untimed_line, const char* option) {
    if (untimed_line != 0)
      return path + ":" + std::to_string(untimed_line) +
             ": row has no timestamp (time association needs one on every row)";
    return path + " has no timestamps (give " + option + " FILE, or --associate frame)";
  };
  const bool by_time = assoc_mode == "time" ||
                       (assoc_mode == "auto" && r.has_times && gt_has_times && r.untimed_line == 0);
  if (by_time) {
    if (!r.has_times) throw InvalidArgument(no_times(r.path, r.untimed_line, "--result-times"));
    if (!gt_has_times) throw InvalidArgument(no_times(gt_path, 0, "--gt-times"));
  } else if (args.has("max-time-diff") || args.has("time-offset")) {
    throw UsageError(
        "--max-time-diff and --time-offset apply to time association only; this run "
        "associates by frame (" +
        std::string(assoc_mode == "frame" ? "--associate frame"
                    : !r.has_times        ? r.path + " has no timestamps"
                                          : gt_path + " has no timestamps") +
        ")");
  }
  const eval::Association assoc = by_time ? eval::associate_by_time(r.t, gt_t, topt)
                                          : eval::associate_by_frame(r.frame, gt_frame);

  // Keyframes with ground truth (2D error); all poses with ground truth (ATE, RPE, segments).
  std::vector<Eigen::Vector3d> est_k, gt_k, est_all, gt_all;
  std::vector<int> frame_k;
  std::vector<Eigen::Isometry3d> est_T, gt_T;
  int last_anchor_frame = INT_MIN;
  for (std::size_t i = 0; i < r.frame.size(); ++i)
    if (r.has_after && !r.after[i]) last_anchor_frame = std::max(last_anchor_frame, r.frame[i]);
  for (std::size_t k = 0; k < assoc.matched(); ++k) {
    const std::size_t i = assoc.result_index[k];
    const Eigen::Isometry3d& g = gt_pose[assoc.gt_index[k]];
    est_all.push_back(r.c[i]);
    gt_all.push_back(g.translation());
    if (!r.T_wc.empty()) {
      est_T.push_back(r.T_wc[i]);
      gt_T.push_back(g);
    }
    if (r.keyframe[i]) {
      est_k.push_back(r.c[i]);
      gt_k.push_back(g.translation());
      frame_k.push_back(r.frame[i]);
    }
  }
  const int missing = static_cast<int>(assoc.unmatched());
  std::ostringstream how;  // the association, in words, for the output and errors
  if (by_time)
    how << "by time: nearest ground-truth pose within " << topt.max_time_diff_s
        << " s of (result time + " << topt.time_offset_s << " s), each used at most once";
  else
    how << "by frame number";
  if (est_k.size() < 3)
    throw InvalidArgument("only " + std::to_string(est_k.size()) + " keyframes of " + r.path +
                          " (" + std::to_string(assoc.matched()) + " of " +
                          std::to_string(r.frame.size()) + " poses) have ground truth in " +
                          gt_path + " (association " + how.str() +
                          "); the metrics need at least 3");
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
    std::printf(
        " \"association\": {\"method\": \"%s\", \"max_time_diff_s\": %s, "
        "\"time_offset_s\": %s, \"result_poses\": %zu, \"ground_truth_poses\": %zu, "
        "\"matched\": %zu, \"unmatched\": %zu, \"unmatched_lost_to_closer\": %zu, "
        "\"max_abs_time_diff_s\": %s},\n",
        by_time ? "time" : "frame", by_time ? num(topt.max_time_diff_s).c_str() : "null",
        by_time ? num(topt.time_offset_s).c_str() : "null", r.frame.size(), gt.poses.size(),
        assoc.matched(), assoc.unmatched(), assoc.lost_to_closer,
        by_time ? num(assoc.max_abs_time_diff_s()).c_str() : "null");
    std::printf(" \"error_2d\": %s,\n", stats_json(e2d.all).c_str());
    std::printf(" \"error_2d_after_last_anchor\": %s,\n",
                split && e2d.after_last_anchor.count > 0 ? stats_json(e2d.after_last_anchor).c_str()
                                                         : "null");
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
  std::printf("  association                %s\n", how.str().c_str());
  std::printf("  matched poses              %zu of %zu (%zu unmatched", assoc.matched(),
              r.frame.size(), assoc.unmatched());
  if (assoc.lost_to_closer > 0)
    std::printf(", %zu of them because a closer result pose took their ground truth",
                assoc.lost_to_closer);
  if (by_time) std::printf("; max |dt| %.6g s", assoc.max_abs_time_diff_s());
  std::printf(")\n");
  std::printf("  keyframes evaluated        %zu (poses without ground truth: %d)\n", est_k.size(),
              missing);
  std::printf("  2D error [m]               Ave %.3f  SD %.3f  max %.3f\n", e2d.all.mean,
              e2d.all.sd, e2d.all.max);
  if (split && e2d.after_last_anchor.count > 0)
    std::printf(
        "  2D error after last anchor Ave %.3f  SD %.3f  max %.3f  (%d keyframes after "
        "frame %d)\n",
        e2d.after_last_anchor.mean, e2d.after_last_anchor.sd, e2d.after_last_anchor.max,
        e2d.after_last_anchor.count, last_anchor_frame);
  else if (split)
    std::printf("  2D error after last anchor n/a (no keyframe after frame %d has ground truth)\n",
                last_anchor_frame);
  if (g.alignment.ok())
    std::printf("  global Sim3 error [m]      Ave %.3f  SD %.3f  max %.3f  (Umeyama scale %.6g)\n",
                g.errors.all.mean, g.errors.all.sd, g.errors.all.max, g.alignment.s);
  else
    std::printf("  global Sim3 error          n/a (%s)\n", g.alignment.message.c_str());
  std::printf("  ATE RMSE [m]               %.3f (no alignment)\n", ate);
  if (poses) {
    std::printf("  RPE (pairs %lld apart)      trans %.3f m  rot %.4f deg (mean)\n", delta,
                rpe.translation.mean, rpe.rotation.mean * 180.0 / M_PI);
    std::printf("  KITTI segment error        %.3f %%  %.5f deg/m  (%d segments)\n",
                seg.translation_percent, seg.rotation_deg_per_m, seg.segments);
  } else {
    if (r.T_wc.empty())
      std::printf("  RPE, KITTI segment error   n/a (the result has no orientations)\n");
    else
      std::printf(
          "  RPE, KITTI segment error   n/a (%zu matched poses; pairs %lld apart need more)\n",
          est_T.size(), delta);
  }
  return 0;
}

}  // namespace geodrift::cli
