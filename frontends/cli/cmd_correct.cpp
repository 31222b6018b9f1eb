// geodrift correct: geo-localize a SLAM trajectory (and optionally its COLMAP map) with an
// anchors CSV, through the same streaming Corrector the live pipeline uses (DESIGN.md "The
// Corrector: who owns what", "Command line and files").
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <geodrift/correction/corrector.hpp>
#include <geodrift/correction/input_checks.hpp>
#include <geodrift/correction/local_scale.hpp>
#include <geodrift/correction/replay.hpp>
#include <geodrift/correction/screening.hpp>
#include <geodrift/correction/time_offset.hpp>
#include <geodrift/correction/uncertainty.hpp>
#include <geodrift/error.hpp>
#include <geodrift/geo/local_frame.hpp>
#include <geodrift/io/anchors.hpp>
#include <geodrift/io/colmap_text.hpp>
#include <geodrift/io/csv.hpp>
#include <geodrift/io/geojson.hpp>
#include <geodrift/io/kml.hpp>
#include <geodrift/io/ply.hpp>
#include <geodrift/io/svg.hpp>
#include <geodrift/io/trajectory.hpp>
#include <geodrift/io/trajectory_jumps.hpp>
#include <geodrift/version.hpp>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "cli_util.hpp"
#include "commands.hpp"

namespace geodrift::cli {
namespace {

const char* kCorrectHelp =
    R"(usage: geodrift correct --trajectory FILE --anchors FILE --out DIR [options]

Geo-localizes a monocular SLAM/SfM result: INIT (similarity from the first 4 anchors), then
sliding-window Sim(3) pose-graph optimisation and bundle adjustment at each further anchor.

inputs
  --trajectory FILE   camera trajectory in the map frame M: KITTI (12 fields, or 13 with a
                      leading frame index or time) or TUM (timestamp tx ty tz qx qy qz qw)
  --format F          auto (default; by field count) | kitti | tum
  --times FILE        one timestamp per pose (seconds; KITTI times.txt), optional
  --map DIR           COLMAP text model (cameras.txt, images.txt, points3D.txt) in the same M:
                      its images are the keyframes (matched to trajectory poses by the frame
                      number or timestamp in the image name); without --map the correction is
                      trajectory-only (pose graph over links to the next few keyframes)
  --anchors FILE      anchors CSV: header row; frame and/or timestamp; latitude,longitude,height
                      | easting,northing,zone,height | x,y,z (W, needs --origin); optional
                      sigma_m, heading_deg. At least 4 anchors, inside the trajectory's range.

options
  --mode M            ours (default: INIT + PGO + BA) | init+pgo | init+ba | init | batch |
                      piecewise | piecewise3d (the naive baseline: one similarity per segment
                      between consecutive anchors, 2D in the levelled frame or Sim(3), the last
                      carried on after the last anchor)
  --origin LAT,LON,H  origin of W (degrees, degrees, ellipsoidal metres); default: first anchor
  --keyframe-step K   without --map: every K-th pose is a keyframe (default 1; the last pose is
                      always one); the others are carried along by their raw relative pose
  --weights W         pose-graph edge weights: metric (default) | paper | drift.
                      metric: the paper's lambda1 = lambda2 = 1e5 on rotation and scale, a
                      keyframe pair's translation to 1 % of its length (the VO's direction
                      error; metres at INIT's scale), each anchor weighted by its
                      sigma_m (1/sigma^2; lambda3 = 1 for views localized by `run`): the
                      result does not depend on the map's unit.
                      paper: the same in map units (Iwami et al. verbatim): the result changes
                      with the map's unit. drift: each edge carries the monocular VO's
                      relative-pose uncertainty over its distance and turn, anchors their
                      sigma_m (docs/correction_model.md): unit-free too; experimental (better
                      at anchors every 100-200 frames, worse at 300-500: docs/RESULTS.md)
  --local-scale auto|SD
                      metric weights: SD of the VO's local, mean-reverting log-scale error
                      (a scale error that comes and goes over ~25 m, on top of the slow
                      drift). auto (default): chosen from 0, 0.01, 0.02, 0.04, 0.08 by
                      two-fold cross-validation over the anchors after INIT's (each half
                      predicted by a run on the other; with fewer than 14 anchors, or
                      more than 2,000 anchors or 20,000 keyframes, 0 is kept); report.json
                      lists each candidate's held-out error.
                      0: the paper's chain alone
  --no-screen-anchors use every anchor as given. By default each anchor is first tested
                      against all the others along the raw path (leave-one-out, under the VO
                      drift model, its level estimated from the anchors): one that disagrees
                      beyond what the VO can have drifted is left out, named on stderr and in
                      report.json, and marked in topview.svg (docs/correction_model.md)
  --gate-anchors      test each anchor after INIT against the path the previous ones give
                      and leave out those that do not fit (named on stderr and in report.json;
                      INIT's RANSAC outliers too); experimental, off by default: it catches
                      anchors hundreds of metres off, but at anchor intervals of ~300 m it can
                      reject correct anchors (docs/correction_model.md)
  --links N           link each keyframe to its N predecessors by relative-pose edges
                      (default 1, the consecutive chain; the edges of one keyframe overlap, so
                      more links count the same VO motion several times and stiffen the path
                      against its anchors)
  --first-window W    from-start (default) | paper: the first window after INIT reaches back to
                      the first keyframe and holds INIT's anchors too (from-start), or spans
                      only the keyframes of its newest 3 anchors (paper; measured on simulated
                      KITTI 08 it let the first windows roll about nearly collinear anchors)
  --min-window-keyframes N
                      the sliding window is lengthened to older anchors until it spans at
                      least N keyframes (default 30: about 90 frames; it matters when anchors
                      are denser than every ~10 keyframes, e.g. street-view panoramas every
                      few metres; 0 keeps exactly the paper's window of the newest 3 anchors);
                      an integer in [0, 1000000]
  --fixed-windows     keep every window as above. By default a window whose solution leaves
                      one of its own anchors outside its sigma_m (chi-square, 99.9 %) is run
                      again over twice as many keyframes (up to 4 times): the keyframes before
                      a window are held fixed, and with metre-level anchors (GNSS) and a map
                      they hold it to a heading its anchors cannot turn
                      (docs/correction_model.md)
  --ba-min-parallax DEG
                      bundle adjustment leaves out map points whose rays from the window's
                      keyframes span less than DEG degrees (they move with their reference
                      keyframe); default 1.146 (ORB-SLAM's triangulation limit), 0 keeps all,
                      must be in [0, 90)
  --ba-cost-tolerance-sd X
                      bundle adjustment stops when a step lowers the cost by less than X
                      standard deviations of the cost at the noise level (sqrt(m/2) for m
                      scalar residuals); default 1, must be >= 0 (0: the solver's own limits)
  --allow-jumps       correct a trajectory that jumps (a step faster than 10x the path's
                      speed around it: a new SLAM map after lost tracking, or a corrupt pose;
                      refused by default, as a pose graph across it bends the whole path);
                      each jump is then named on stderr and in report.json (as is, always,
                      a suspect step: faster than 4x)
  --allow-upside-down correct a path whose corrected cameras come out upside down although it
                      moves forwards along their +z axis: refused by default, as that is what
                      anchors mirrored against the path give (latitude/longitude, easting/
                      northing or x/y swapped); pass it for a camera mounted upside down
  --anchor-time-offset S
                      seconds to add to the anchors' timestamps to get the trajectory's clock
                      (anchors placed by a timestamp only; a 'frame' column is exact), or auto:
                      the offset estimated from the path's turns, applied when significant.
                      Without it the offset is estimated and a significant one is warned about
                      (a logging latency, GPS time against UTC: 18 s); report.json
                      "anchor_time_offset" (correction/time_offset.hpp)
  --out DIR           output directory (created; must not exist or be empty unless --force)
  --force             write into an existing non-empty --out (replaces geodrift's own files)
  --no-uncertainty    skip the per-keyframe uncertainty (sd_east/sd_north/cov_en left empty):
                      it costs one more factorisation of the whole path per iteration of its
                      variance estimate (correction/uncertainty.hpp)
  --help              this text

outputs in DIR (every file states frame, units and the geodrift version)
  trajectory.csv      every input pose: frame, timestamp, kind (keyframe|interpolated), x,y,z in
                      W, UTM, latitude/longitude/height, heading_deg, after_last_anchor,
                      sd_east, sd_north, cov_en (horizontal uncertainty, metres / m²; an
                      interpolated pose carries its keyframe's)
  trajectory_kitti.txt, trajectory_tum.txt   corrected path in W (camera-to-world, for evo)
  track.geojson, track.kml                   path + anchors (WGS84)
  points.ply          corrected map points in W (with --map)
  topview.svg         corrected path, anchors and 95 % uncertainty ellipses, top view
                      (and where the input path jumps or takes a suspect step)
  scale.svg           local scale of the corrected keyframes (no ground truth here)
  report.json         version, command line, parameters, INIT result, per-step timings
)";

/// Checks the anchors' geometry before anything runs: at least INIT's count, and the first ones
/// (those INIT uses) not coincident horizontally (a vertical line or a point leaves yaw and scale
/// unobservable).
void check_anchor_geometry(const std::vector<io::Anchor>& a, const std::string& path,
                           const correction::InitOptions& init) {
  const int need = init.num_correspondences;
  if (static_cast<int>(a.size()) < need)
    throw InvalidArgument(path + ": " + std::to_string(a.size()) +
                          " anchor(s); INIT needs at least " + std::to_string(need) +
                          " anchors (fewer than " + std::to_string(need) + " anchors)");
  double spread = 0;
  for (int i = 0; i < need; ++i)
    for (int j = i + 1; j < need; ++j)
      spread = std::max(spread, (a[i].y_w - a[j].y_w).head<2>().norm());
  std::ostringstream lines;
  for (int i = 0; i < need; ++i) lines << (i ? ", " : "") << a[i].line;
  if (spread < init.min_anchor_spread_m) {
    double spread3 = 0;
    for (int i = 0; i < need; ++i)
      for (int j = i + 1; j < need; ++j) spread3 = std::max(spread3, (a[i].y_w - a[j].y_w).norm());
    std::ostringstream os;
    os << path << ": the first " << need << " anchors (lines " << lines.str() << ") ";
    if (spread3 < init.min_anchor_spread_m)
      os << "are coincident (all within " << spread3 << " m)";
    else
      os << "are collinear on one vertical line (horizontal spread " << spread << " m)";
    os << ": scale and yaw are unobservable (degenerate anchors; need a horizontal spread of at "
          "least "
       << init.min_anchor_spread_m << " m)";
    throw InvalidArgument(os.str());
  }
}

/// A finite number given to --`key`, or `def` when absent. @throws UsageError otherwise.
double number_option(const Args& args, const std::string& key, double def) {
  if (!args.has(key)) return def;
  const std::string v = args.get(key);
  std::size_t pos = 0;
  double x = 0;
  try {
    x = std::stod(v, &pos);
  } catch (const std::exception&) {
    pos = 0;
  }
  if (pos == 0 || pos != v.size() || !std::isfinite(x))
    throw UsageError("option --" + key + ": '" + v + "' is not a finite number");
  return x;
}

/// report.json's fields of a cross-validated local scale choice, after "chosen_by".
std::string local_scale_json(const correction::LocalScaleChoice& c) {
  std::string s;
  if (!c.rms_m.empty()) {
    s += ", \"candidates\": [";
    for (std::size_t i = 0; i < c.candidates.size(); ++i)
      s += (i ? ", " : "") + json_num(c.candidates[i]);
    s += "], \"held_out_rms_m\": [";
    for (std::size_t i = 0; i < c.rms_m.size(); ++i) s += (i ? ", " : "") + json_num(c.rms_m[i]);
    s += "], \"held_out_anchors\": " + std::to_string(c.held_out);
  }
  if (!c.message.empty()) s += ", \"note\": " + io::detail::json_string(c.message);
  return s;
}

}  // namespace

int run_correct(int argc, char** argv) {
  const Args args(
      argc, argv,
      {"trajectory", "format", "times", "map", "anchors", "mode", "origin", "keyframe-step",
       "links", "weights", "local-scale", "first-window", "min-window-keyframes", "ba-min-parallax",
       "ba-cost-tolerance-sd", "anchor-time-offset", "out"},
      {"help", "force", "gate-anchors", "no-screen-anchors", "no-uncertainty", "allow-jumps",
       "allow-upside-down", "fixed-windows"});
  if (args.flag("help")) {
    std::fputs(kCorrectHelp, stdout);
    return 0;
  }
  const std::string traj_path = args.required("trajectory");
  const std::string anchors_path = args.required("anchors");
  const std::string out_dir = args.required("out");
  const bool with_map = args.has("map");
  correction::CorrectorOptions opt;
  io::TrajectoryFormat format;
  try {
    opt.mode = correction::mode_from_string(args.get("mode", "ours"));
    format = io::parse_trajectory_format(args.get("format", "auto"));
    // Both ways explicitly: the Corrector's default is the paper's, so setting only kPaper
    // left --weights drift without effect.
    opt.edge_weights = correction::edge_weights_from_string(args.get("weights", "metric"));
  } catch (const InvalidArgument& e) {
    throw UsageError(e.what());
  }
  const long long step = args.get_int("keyframe-step", 1);
  if (step < 1) throw UsageError("--keyframe-step must be >= 1");
  if (with_map && args.has("keyframe-step"))
    throw UsageError(
        "--keyframe-step applies without --map only (the map's images are the "
        "keyframes)");
  const long long links = args.get_int("links", 1);
  if (links < 1 || links > 100) throw UsageError("--links must be in [1, 100]");
  if (!with_map && opt.mode == correction::Mode::kInitBa)
    throw UsageError("--mode init+ba needs --map (bundle adjustment needs map points)");
  bool local_auto = true;
  if (args.has("local-scale") && args.get("local-scale") != "auto") {
    const std::vector<double> v = parse_number_list("local-scale", args.get("local-scale"));
    if (v.size() != 1 || !(v[0] >= 0)) throw UsageError("--local-scale takes auto or one SD >= 0");
    opt.local_scale_sd = v[0];
    local_auto = false;
    if (opt.local_scale_sd > 0 &&
        opt.edge_weights != correction::CorrectorOptions::EdgeWeights::kPaperMetric)
      throw UsageError("--local-scale applies to --weights metric only");
  }
  opt.gate_anchors = args.flag("gate-anchors");
  opt.link_consecutive = true;
  opt.consecutive_links = static_cast<int>(links);
  const std::string first_window = args.get("first-window", "from-start");
  if (first_window != "from-start" && first_window != "paper")
    throw UsageError("--first-window: '" + first_window + "' is not from-start or paper");
  opt.first_window_from_start = first_window == "from-start";
  const long long min_window = args.get_int("min-window-keyframes", opt.min_window_keyframes);
  if (min_window < 0 || min_window > 1000000)
    throw UsageError("--min-window-keyframes must be an integer in [0, 1000000], not " +
                     args.get("min-window-keyframes"));
  opt.min_window_keyframes = static_cast<int>(min_window);
  opt.adaptive_windows = !args.flag("fixed-windows");
  opt.ba_min_parallax_deg = number_option(args, "ba-min-parallax", opt.ba_min_parallax_deg);
  opt.ba_cost_tolerance_sd = number_option(args, "ba-cost-tolerance-sd", opt.ba_cost_tolerance_sd);
  if (!(opt.ba_min_parallax_deg >= 0 && opt.ba_min_parallax_deg < 90))
    throw UsageError("--ba-min-parallax must be in [0, 90) degrees");
  if (!(opt.ba_cost_tolerance_sd >= 0)) throw UsageError("--ba-cost-tolerance-sd must be >= 0");
  const bool time_offset_auto = args.get("anchor-time-offset", "") == "auto";
  double time_offset = 0.0;  // applied to the anchors placed by timestamp
  if (args.has("anchor-time-offset") && !time_offset_auto) {
    time_offset = number_option(args, "anchor-time-offset", 0.0);
    // Up to 1e10 s: GPS time against Unix time is 315,964,782 s apart.
    if (!(std::abs(time_offset) <= 1e10))
      throw UsageError("--anchor-time-offset takes auto or seconds in [-1e10, 1e10], not " +
                       args.get("anchor-time-offset"));
  }
  {
    std::string why;
    if (!opt.validate(&why)) throw UsageError("invalid correction options: " + why);
  }
  // Check --out before the work (AtomicOutputDir below re-checks and stages).
  {
    std::error_code ec;
    const std::filesystem::path p(out_dir);
    if (std::filesystem::exists(p, ec) && !std::filesystem::is_directory(p, ec))
      throw Error("--out '" + out_dir +
                  "' exists and is not a directory (refusing to replace "
                  "a file)");
  }

  // ---- inputs -------------------------------------------------------------------------------
  io::Trajectory traj = io::read_trajectory(traj_path, format);
  if (args.has("times")) {
    const std::vector<double> t = read_times_file(args.get("times"), traj.poses.size(), traj_path);
    for (std::size_t i = 0; i < t.size(); ++i) traj.poses[i].timestamp = t[i];
    traj.has_timestamps = true;
  }
  const std::size_t np = traj.poses.size();
  if (np < 2)
    throw InvalidArgument(traj_path + ": needs at least 2 poses, has " + std::to_string(np));
  // A path that jumps (io/trajectory_jumps.hpp): refused unless --allow-jumps; a suspect step
  // (between kSuspectJumpRatio and the jump ratio) is a warning.
  const io::TrajectoryJumpOptions jump_options;
  io::TrajectoryJumpOptions suspect_options = jump_options;
  suspect_options.max_ratio = io::kSuspectJumpRatio;
  const std::vector<io::TrajectoryJump> steps_flagged =
      io::find_trajectory_jumps(traj, suspect_options);
  std::vector<io::TrajectoryJump> jumps;
  for (const io::TrajectoryJump& jp : steps_flagged)
    if (jp.ratio > jump_options.max_ratio) jumps.push_back(jp);
  if (!jumps.empty() && !args.flag("allow-jumps")) {
    std::string others;
    for (std::size_t i = 1; i < jumps.size(); ++i)
      others += (i > 1 ? ", " : "") + std::to_string(traj.poses[jumps[i].index + 1].line);
    throw InvalidArgument(
        traj_path + ": the camera jumps " + io::describe_jump(traj, jumps[0]) +
        (others.empty() ? "" : " (and before line(s) " + others + ")") +
        ": a new SLAM map after lost tracking (another origin and unit) or a corrupt pose. A pose "
        "graph across it bends the whole path: no trustworthy result, nothing written. Split the "
        "trajectory there and correct each part with its own anchors, or pass --allow-jumps if "
        "the motion is real");
  }
  constexpr std::size_t kMaxNamed = 10;  // on stderr; report.json lists them all
  for (std::size_t i = 0; i < std::min(steps_flagged.size(), kMaxNamed); ++i) {
    const io::TrajectoryJump& jp = steps_flagged[i];
    if (jp.ratio > jump_options.max_ratio)
      std::fprintf(stderr, "geodrift correct: warning: %s: the camera jumps %s (--allow-jumps)\n",
                   traj_path.c_str(), io::describe_jump(traj, jp).c_str());
    else
      std::fprintf(stderr,
                   "geodrift correct: warning: %s: a suspect step %s: if the SLAM started a new "
                   "map there, the correction across it is wrong (split the trajectory there)\n",
                   traj_path.c_str(), io::describe_jump(traj, jp).c_str());
  }
  if (steps_flagged.size() > kMaxNamed)
    std::fprintf(stderr, "geodrift correct: warning: %s: %zu more such steps (report.json)\n",
                 traj_path.c_str(), steps_flagged.size() - kMaxNamed);

  const io::AnchorTable table = io::read_anchors_csv(anchors_path);
  geo::LocalFrame frame;
  if (args.has("origin")) {
    const std::vector<double> o = parse_number_list("origin", args.get("origin"));
    if (o.size() != 3) throw UsageError("--origin needs LAT,LON,H (3 numbers)");
    frame = geo::LocalFrame::from_geodetic(o[0], o[1], o[2]);
  } else {
    if (table.kind == io::AnchorPositionKind::kWorld)
      throw UsageError(anchors_path + ": anchors given as x,y,z in W need --origin LAT,LON,H");
    frame = io::local_frame_at_first_anchor(table);
  }
  std::vector<io::Anchor> anchors = io::anchors_in_world(table, frame);
  // The anchors' clock against the trajectory's (correction/time_offset.hpp): the given offset
  // applied, then the remaining one estimated from the path's turns.
  std::vector<std::size_t> timed;  // anchors placed by their timestamp
  for (std::size_t i = 0; i < anchors.size(); ++i)
    if (anchors[i].frame < 0 && std::isfinite(anchors[i].timestamp)) timed.push_back(i);
  if (args.has("anchor-time-offset") && timed.empty())
    throw UsageError("--anchor-time-offset: no anchor of " + anchors_path +
                     " is placed by its timestamp (anchors with a 'frame' are placed by it)");
  for (std::size_t i : timed) anchors[i].timestamp += time_offset;
  correction::TimeOffsetEstimate clock;
  if (timed.empty()) {
    clock.reason = "no anchor is placed by its timestamp";
  } else if (!traj.has_timestamps) {
    clock.reason = "the trajectory has no timestamps";
  } else {
    std::vector<double> times, anchor_times;
    std::vector<Eigen::Vector3d> centres, anchor_positions;
    for (const io::TrajectoryPose& p : traj.poses) {
      times.push_back(p.timestamp);
      centres.push_back(p.T_cw.inverse().translation());
    }
    for (std::size_t i : timed) {
      anchor_times.push_back(anchors[i].timestamp);
      anchor_positions.push_back(anchors[i].y_w);
    }
    clock = correction::estimate_anchor_time_offset(times, centres, anchor_times, anchor_positions);
  }
  // The offset to add to the file's timestamps: the given one plus the estimate on top of it.
  const double clock_total = time_offset + clock.offset;
  if (clock.significant) {
    char buf[512];
    std::snprintf(buf, sizeof buf,
                  "%s: the anchors fit the path best with %+.3f s (sd %.3f s) added to their "
                  "timestamps (windowed RMS %.2f m -> %.2f m over %d windows of %d anchors)%s",
                  anchors_path.c_str(), clock_total, clock.sd, clock.rms_at_zero,
                  clock.rms_at_estimate, clock.windows, correction::kTimeOffsetWindow,
                  clock.at_edge ? ", at the edge of the search: the offset may be larger" : "");
    if (time_offset_auto && !clock.at_edge) {
      std::fprintf(stderr, "geodrift correct: %s; applied (--anchor-time-offset auto)\n", buf);
      time_offset = clock.offset;
      for (std::size_t i : timed) anchors[i].timestamp += time_offset;
    } else {
      std::fprintf(stderr,
                   "geodrift correct: warning: %s: the anchors' clock and the trajectory's may "
                   "differ; check them, or pass --anchor-time-offset %.3f%s\n",
                   buf, clock_total, clock.at_edge ? "" : " (or auto)");  // auto stops at the edge
    }
  }
  std::vector<io::AnchorLocation> locs = io::locate_anchors(anchors, traj, anchors_path);
  {  // time order
    std::vector<std::size_t> order(anchors.size());
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
      return locs[a].index + locs[a].fraction < locs[b].index + locs[b].fraction;
    });
    std::vector<io::Anchor> a2;
    std::vector<io::AnchorLocation> l2;
    for (std::size_t i : order) a2.push_back(anchors[i]), l2.push_back(locs[i]);
    anchors.swap(a2);
    locs.swap(l2);
  }
  check_anchor_geometry(anchors, anchors_path, opt.init);

  // ---- keyframes: trajectory index of each -------------------------------------------------
  map::Map m;
  io::ColmapModel model;
  std::vector<std::size_t> kf_pose;  // trajectory index of each keyframe
  auto ts_of = [&](std::size_t p) {
    const double t = traj.poses[p].timestamp;
    return std::isfinite(t) ? t : static_cast<double>(traj.poses[p].frame);
  };
  if (with_map) {
    model = io::read_colmap_text(args.get("map"));
    m = model.map;
    GEODRIFT_CHECK(!m.keyframes.empty(), args.get("map") << ": the model has no images");
    for (std::size_t i = 0; i < m.keyframes.size(); ++i) {
      map::Keyframe& k = m.keyframes[i];
      std::size_t best = np;
      for (std::size_t p = 0; p < np; ++p) {
        const bool hit = std::isfinite(k.timestamp)
                             ? std::abs(traj.poses[p].timestamp - k.timestamp) < 1e-4
                             : traj.poses[p].frame == k.frame_index;
        if (hit) {
          best = p;
          break;
        }
      }
      if (best == np)
        throw InvalidArgument(args.get("map") + "/images.txt: image '" + model.image_names[i] +
                              "' (frame " + std::to_string(k.frame_index) +
                              ") matches no pose of " + traj_path);
      if (!kf_pose.empty() && best <= kf_pose.back())
        throw InvalidArgument(args.get("map") + "/images.txt: image '" + model.image_names[i] +
                              "' is not after the previous image in time");
      kf_pose.push_back(best);
      k.timestamp = ts_of(best);
    }
  } else {
    for (std::size_t p = 0; p < np; p += static_cast<std::size_t>(step)) kf_pose.push_back(p);
    if (kf_pose.back() != np - 1) kf_pose.push_back(np - 1);
    for (std::size_t i = 0; i < kf_pose.size(); ++i) {
      map::Keyframe k;
      k.id = static_cast<int>(i);
      k.frame_index = traj.poses[kf_pose[i]].frame;
      k.timestamp = ts_of(kf_pose[i]);
      k.T_cw = traj.poses[kf_pose[i]].T_cw;
      m.keyframes.push_back(k);
    }
  }
  const std::size_t nk = kf_pose.size();
  // Keyframe governing each pose: the last at or before it (the first for poses before it).
  std::vector<int> gov(np, 0);
  std::vector<int> kf_at(np, -1);
  for (std::size_t i = 0; i < nk; ++i) kf_at[kf_pose[i]] = static_cast<int>(i);
  {
    int g = 0;
    for (std::size_t p = 0; p < np; ++p) {
      if (kf_at[p] >= 0) g = kf_at[p];
      gov[p] = g;
    }
  }

  // ---- anchors -> correspondences ----------------------------------------------------------
  std::vector<map::Correspondence> corr;
  for (std::size_t j = 0; j < anchors.size(); ++j) {
    const io::AnchorLocation& L = locs[j];
    const lie::SE3d T_a = io::anchor_pose_cw(traj, L);
    const int k = gov[L.index];
    map::Correspondence c;
    c.id = static_cast<int>(j);
    c.keyframe = m.keyframes[k].id;
    c.T_vk = T_a * traj.poses[kf_pose[k]].T_cw.inverse();
    c.y_w = anchors[j].y_w;
    c.sigma_m = std::isfinite(anchors[j].sigma_m) ? anchors[j].sigma_m : 0.0;
    c.geotag_id = static_cast<int>(j);
    corr.push_back(c);
  }

  AtomicOutputDir out(out_dir, args.flag("force"));

  // ---- wrong anchors: each tested against all the others (correction/screening.hpp) --------
  correction::AnchorScreening screening;
  const bool screen = !args.flag("no-screen-anchors");
  if (screen) {
    screening = correction::screen_anchors(m.keyframes, corr);
    if (!screening.ok)
      std::fprintf(stderr, "geodrift correct: warning: anchors not screened: %s\n",
                   screening.message.c_str());
    else if (2 * screening.num_left_out() > static_cast<int>(corr.size()))
      // The drift level is estimated from the median anchor: with most anchors disagreeing
      // there is no telling which ones are right.
      throw Error(std::to_string(screening.num_left_out()) + " of the " +
                  std::to_string(corr.size()) + " anchors of " + anchors_path +
                  " disagree with the others beyond what the path can have drifted (anchors of "
                  "another place or time, a wrong --origin, or a broken trajectory): no "
                  "trustworthy result, nothing written (--no-screen-anchors uses them all)");
  }
  const bool screened = screen && screening.ok;

  // ---- the VO's local scale error: given, or chosen by cross-validation (local_scale.hpp) ---
  correction::LocalScaleChoice local_choice;
  if (local_auto) {
    std::vector<map::Correspondence> in_use;
    for (std::size_t j = 0; j < corr.size(); ++j)
      if (!screened || screening.anchors[j].used) in_use.push_back(corr[j]);
    if (stderr_is_tty())
      std::fprintf(stderr,
                   "geodrift correct: choosing the local scale SD (10 cross-validation runs)\r");
    local_choice = correction::choose_local_scale(m, in_use, opt);
    opt.local_scale_sd = local_choice.sd;
  }
  correction::Corrector corrector(opt);
  if (screened) correction::apply_screening(screening, corr, &corrector);

  // ---- correction --------------------------------------------------------------------------
  const bool tty = stderr_is_tty();
  const auto t0 = std::chrono::steady_clock::now();
  correction::replay(m, corr, &corrector, [&](int i) {
    if (tty && (i % 50 == 0 || i + 1 == static_cast<int>(nk)))
      std::fprintf(stderr, "\rgeodrift correct: keyframe %d / %zu", i + 1, nk);
  });
  const double total_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (tty) std::fputc('\n', stderr);
  if (!corrector.initialized()) {
    std::string why = corrector.init_message();
    if (why.empty()) {
      // Name what the screening took away: the user sees which anchors to check.
      // With this few anchors the leave-one-out test has little redundancy: the one it singles
      // out is not always the wrong one (a simulated 02 with 4 anchors, the second 470 m off:
      // it left out the third), so every line is named.
      std::string out_lines, all_lines;
      int kept = 0;
      for (std::size_t j = 0; j < corr.size(); ++j) {
        const std::string l = std::to_string(anchors[j].line);
        all_lines += (all_lines.empty() ? "" : ", ") + l;
        if (!screened || screening.anchors[j].used)
          ++kept;
        else
          out_lines += (out_lines.empty() ? "" : ", ") + l;
      }
      why = "too few usable anchors";
      if (!out_lines.empty())
        why += " (" + std::to_string(kept) + " of " + std::to_string(corr.size()) +
               " left after the screening left out line(s) " + out_lines +
               " as inconsistent with the others; with this few anchors it cannot always tell "
               "which one is wrong: check lines " +
               all_lines + "; INIT needs 4 consistent anchors)";
    }
    throw Error("INIT did not succeed with the anchors of " + anchors_path + ": " + why);
  }

  // ---- what became of each anchor ----------------------------------------------------------
  const auto& decisions = corrector.anchor_decisions();
  std::vector<char> used(anchors.size(), 0);
  int after_init = 0, after_init_used = 0;
  for (const auto& d : decisions) {
    used[d.id] = d.used;
    const bool screened_out = screening.ok && !screening.anchors[d.id].used;
    if (!std::isnan(d.innovation_m) && !screened_out) {  // tested by the gate
      ++after_init;
      after_init_used += d.used;
    }
    if (!d.used)
      std::fprintf(stderr, "geodrift correct: %s line %d not used: %s\n", anchors_path.c_str(),
                   anchors[d.id].line, d.why.c_str());
  }
  if (after_init >= 2 && after_init_used == 0)
    throw Error("all " + std::to_string(after_init) + " anchors of " + anchors_path +
                " after INIT were rejected as inconsistent with the path INIT's anchors give "
                "(wrong INIT anchors, a broken trajectory, or anchors of another place): no "
                "trustworthy result, nothing written");
  {  // anchors mirrored against the path turn it over (correction/input_checks.hpp)
    std::vector<lie::SE3d> T_cw(nk);
    for (std::size_t i = 0; i < nk; ++i) T_cw[i] = corrector.keyframe_pose_w(static_cast<int>(i));
    const correction::CameraAttitude att = correction::camera_attitude(T_cw);
    if (att.turned_over() && !args.flag("allow-upside-down"))
      throw Error(strprintf(
          "the anchors of %s fit the path only turned over: the corrected cameras are upside "
          "down at %d of %d keyframes while they move forwards. The anchors are a mirror image "
          "of the path: latitude and longitude swapped (GeoJSON's order is longitude, "
          "latitude), or easting and northing, or x and y. No trustworthy result, nothing "
          "written (--allow-upside-down if the camera is mounted upside down)",
          anchors_path.c_str(), att.upside_down, att.keyframes));
  }
  if (corrector.rejected_window_updates() > 0)
    std::fprintf(stderr,
                 "geodrift correct: warning: %d pose-graph window(s) diverged and were not "
                 "applied (a keyframe rescaled by more than %gx; report.json steps say which): "
                 "check the anchors near them\n",
                 corrector.rejected_window_updates(), opt.max_window_rescale);
  // ---- uncertainty of the corrected path (correction/uncertainty.hpp) ---------------------
  correction::PathUncertainty unc;
  if (!args.flag("no-uncertainty")) {
    unc = correction::estimate_path_uncertainty(corrector);
    if (!unc.ok)
      std::fprintf(stderr, "geodrift correct: warning: no uncertainty estimate: %s\n",
                   unc.message.c_str());
    else if (!unc.message.empty())
      std::fprintf(stderr, "geodrift correct: uncertainty: %s\n", unc.message.c_str());
  } else {
    unc.message = "skipped (--no-uncertainty)";
  }
  // How much more the correction stretched the path in one place than in another.
  double scale_spread = NAN;
  {
    std::vector<double> scales(nk);
    for (std::size_t i = 0; i < nk; ++i)
      scales[i] = corrector.keyframe_sim3(static_cast<int>(i)).scale();
    scale_spread = correction::scale_spread(scales);
  }
  if (screen) {  // a path and anchors that do not belong together (correction/input_checks.hpp)
    // The screening's drift factor; where it could not run, the uncertainty's (estimated from
    // the anchors' prediction by the others, as the screening's is).
    const auto drift_factor = [&](const correction::PathUncertainty& u) {
      return screening.ok ? screening.drift_factor
             : u.ok && u.predicted_anchors >=
                           correction::PathUncertaintyOptions{}.min_predicted_anchors
                 ? u.drift_factor
                 : NAN;
    };
    double k = drift_factor(unc), spread = scale_spread;
    // The limits were set on the paper's fixed windows. Windows adapted to the anchors bend a
    // path more evenly onto anchors it does not fit (a T_cw path, in cli_test, then passed), so
    // where the test could flip, it is made on the fixed windows' correction: its stretch, and
    // the uncertainty's drift factor where the screening has none.
    if (opt.adaptive_windows && !correction::implausible_drift(k, spread) &&
        (!screening.ok || k > correction::kMaxPlausibleDriftFactor)) {
      correction::CorrectorOptions fixed = opt;
      fixed.adaptive_windows = false;
      correction::Corrector paper(fixed);
      if (screened) correction::apply_screening(screening, corr, &paper);
      correction::replay(m, corr, &paper);
      if (paper.initialized()) {
        std::vector<double> scales(nk);
        for (std::size_t i = 0; i < nk; ++i)
          scales[i] = paper.keyframe_sim3(static_cast<int>(i)).scale();
        spread = correction::scale_spread(scales);
        if (!screening.ok && unc.ok) k = drift_factor(correction::estimate_path_uncertainty(paper));
      }
    }
    if (correction::implausible_drift(k, spread))
      throw Error(strprintf(
          "the path of %s does not have the anchors' shape: between the anchors of %s it would "
          "have to drift %.0fx more (SD) than a monocular VO does (drift variance factor %.3g > "
          "%g), and the correction stretched it by %.3gx more in one place than in another "
          "(> %g). World-to-camera poses where camera-to-world are expected (TUM and KITTI "
          "files hold T_wc), anchors of another run or place, poses out of order, or anchors "
          "far worse than their sigma_m: no trustworthy result, nothing written "
          "(--no-screen-anchors skips this check)",
          traj_path.c_str(), anchors_path.c_str(), std::sqrt(k), k,
          correction::kMaxPlausibleDriftFactor, spread, correction::kMaxPlausibleScaleSpread));
  }
  std::size_t last_anchor_index = 0;
  for (std::size_t j = 0; j < anchors.size(); ++j)
    if (used[j]) last_anchor_index = std::max(last_anchor_index, locs[j].index);

  // ---- every pose in W -----------------------------------------------------------------------
  std::vector<io::TrajectoryCsvRow> rows(np);
  io::Trajectory out_traj;
  out_traj.has_timestamps = traj.has_timestamps;
  std::vector<Eigen::Vector3d> track;
  for (std::size_t p = 0; p < np; ++p) {
    const int k = gov[p];
    lie::SE3d T;
    if (kf_at[p] >= 0) {
      T = corrector.keyframe_pose_w(kf_at[p]);
    } else {
      const lie::SE3d dT = traj.poses[p].T_cw * traj.poses[kf_pose[k]].T_cw.inverse();
      T = (lie::Sim3d(dT) * corrector.keyframe_sim3(k)).to_se3();
    }
    rows[p].frame = traj.poses[p].frame;
    rows[p].timestamp = traj.poses[p].timestamp;
    rows[p].keyframe = kf_at[p] >= 0;
    rows[p].T_cw = T;
    rows[p].after_last_anchor = p > last_anchor_index;
    if (unc.ok) rows[p].cov_en = unc.cov_en[k];
    io::TrajectoryPose tp = traj.poses[p];
    tp.T_cw = T;
    out_traj.poses.push_back(tp);
    track.push_back(T.inverse().translation());
  }
  const std::string note = frame.description();
  io::write_trajectory_csv(out.path("trajectory.csv"), rows, frame,
                           "mode " + std::string(correction::to_string(opt.mode)));
  io::write_trajectory_kitti(out.path("trajectory_kitti.txt"), out_traj, note);
  io::write_trajectory_tum(out.path("trajectory_tum.txt"), out_traj, note);
  io::write_geojson(out.path("track.geojson"), track, anchors, frame);
  io::write_kml(out.path("track.kml"), track, anchors, frame);
  if (with_map) {
    io::PointCloud cloud;
    for (int i = 0; i < corrector.num_points(); ++i) cloud.points.push_back(corrector.point_w(i));
    if (model.point_colors.size() == cloud.points.size()) cloud.colors = model.point_colors;
    io::write_ply(out.path("points.ply"), cloud, note);
  }
  {
    io::SvgSeries path{"corrected path", "#1f77b4", 1.5, {}, false};
    for (const auto& c : track) path.points.push_back(c.head<2>());
    std::vector<io::SvgMarker> markers;
    for (std::size_t j = 0; j < anchors.size(); ++j)
      markers.push_back(
          used[j] ? io::SvgMarker{"anchor line " + std::to_string(anchors[j].line),
                                  anchors[j].y_w.head<2>(), "#d62728"}
                  : io::SvgMarker{"REJECTED anchor line " + std::to_string(anchors[j].line),
                                  anchors[j].y_w.head<2>(), "#7f7f7f"});
    for (const io::TrajectoryJump& jp : steps_flagged) {  // where the path jumps or may
      char label[96];
      std::snprintf(label, sizeof label, "%s line %d (%.3g x)",
                    jp.ratio > jump_options.max_ratio ? "JUMP before" : "SUSPECT STEP before",
                    traj.poses[jp.index + 1].line, jp.ratio);
      markers.push_back({label, track[jp.index + 1].head<2>(), "#ff7f0e"});
    }
    // At most about 150 ellipses: every n-th keyframe and the last one.
    std::vector<io::SvgEllipse> ellipses;
    if (unc.ok) {
      const std::size_t every = std::max<std::size_t>(1, (nk + 149) / 150);
      for (std::size_t i = 0; i < nk; ++i)
        if (i % every == 0 || i + 1 == nk)
          ellipses.push_back(
              {corrector.keyframe_center_w(static_cast<int>(i)).head<2>(), unc.cov_en[i]});
    }
    io::write_svg_topview(out.path("topview.svg"), {path}, markers,
                          "geodrift correct: corrected path (top view)", note, "anchors", ellipses);
  }
  {
    // Without ground truth: the local scale s_i of the corrected Sim3 keyframe poses (M units
    // per metre), normalised by its median, along the corrected path.
    std::vector<double> s(nk);
    for (std::size_t i = 0; i < nk; ++i)
      s[i] = corrector.keyframe_sim3(static_cast<int>(i)).scale();
    std::vector<double> sorted = s;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    const double med = sorted[sorted.size() / 2];
    io::SvgSeries ser{"s_i / median", "#2ca02c", 1.5, {}, false};
    double dist = 0;
    for (std::size_t i = 0; i < nk; ++i) {
      if (i > 0)
        dist += (corrector.keyframe_center_w(static_cast<int>(i)) -
                 corrector.keyframe_center_w(static_cast<int>(i) - 1))
                    .norm();
      ser.points.push_back({dist, s[i] / med});
    }
    io::write_svg_line_plot(out.path("scale.svg"), {ser},
                            "local map scale of the corrected keyframes (M units per metre / "
                            "median; no ground truth, not the scale factor vs GT)",
                            "distance along the corrected path [m]", "s_i / median s",
                            "frame: " + note + "; units: metres (x), ratio (y)", 1.0);
  }
  {
    // Metrics without ground truth: distance of each used anchor's corrected view centre from
    // its geo-tag (3D and horizontal).
    std::string residuals;
    {
      double sum = 0, sum_h = 0, mx = 0;
      const int nc = static_cast<int>(corrector.correspondences().size());
      for (int c = 0; c < nc; ++c) {
        const Eigen::Vector3d d = corrector.view_center_w(c) - corrector.correspondences()[c].y_w;
        sum += d.norm();
        sum_h += d.head<2>().norm();
        mx = std::max(mx, d.norm());
      }
      std::ostringstream r;
      r << "{\"count\": " << nc << ", \"mean_3d\": " << json_num(nc ? sum / nc : NAN)
        << ", \"mean_2d\": " << json_num(nc ? sum_h / nc : NAN) << ", \"max_3d\": " << json_num(mx)
        << "}";
      residuals = r.str();
    }
    std::ostringstream j;
    const auto& ir = corrector.init_result();
    const bool paper_w = opt.edge_weights != correction::CorrectorOptions::EdgeWeights::kDriftModel;
    j << "{\n  \"geodrift_version\": " << io::detail::json_string(kVersion)
      << ",\n  \"command_line\": " << io::detail::json_string(command_line(argc, argv))
      << ",\n  \"frame\": " << io::detail::json_string(note)
      << ",\n  \"units\": \"metres, seconds\""
      << ",\n  \"parameters\": {\"mode\": "
      << io::detail::json_string(correction::to_string(opt.mode))
      << ", \"trajectory\": " << io::detail::json_string(traj_path)
      << ", \"trajectory_format\": " << io::detail::json_string(io::to_string(traj.format))
      << ", \"map\": " << (with_map ? io::detail::json_string(args.get("map")) : "null")
      << ", \"anchors\": " << io::detail::json_string(anchors_path)
      << ", \"trajectory_only\": " << (with_map ? "false" : "true")
      << ", \"keyframe_step\": " << (with_map ? 0 : step) << ", \"consecutive_links\": " << links
      << ", \"window_correspondences\": " << opt.window_correspondences << ", \"edge_weights\": \""
      << correction::to_string(opt.edge_weights) << "\""
      << ", \"local_scale\": {\"sd\": " << json_num(opt.local_scale_sd)
      << ", \"length_m\": " << json_num(opt.local_scale_length_m) << ", \"chosen_by\": \""
      << (!local_auto                    ? "--local-scale"
          : local_choice.cross_validated ? "cross-validation"
                                         : "default")
      << "\"" << local_scale_json(local_choice) << "}"
      << (paper_w
              ? ", \"lambda1\": " + json_num(opt.lambda1) + ", \"lambda2\": " +
                    json_num(opt.lambda2) + ", \"lambda3\": " + json_num(opt.lambda3)
              : ", \"drift_model\": {\"scale_walk_per_sqrt_m\": " +
                    json_num(opt.drift.scale_walk_per_sqrt_m) + ", \"rotation_walk_per_sqrt_m\": " +
                    json_num(opt.drift.rotation_walk_per_sqrt_m) +
                    ", \"turn_rotation_fraction\": " + json_num(opt.drift.turn_rotation_fraction) +
                    ", \"turn_scale_per_rad\": " + json_num(opt.drift.turn_scale_per_rad) +
                    ", \"direction_sd_rad\": " + json_num(opt.drift.direction_sd_rad) +
                    ", \"min_distance_m\": " + json_num(opt.drift.min_distance_m) + "}")
      << ", \"min_shared_points\": " << opt.min_shared_points
      << ", \"ba_huber_px\": " << json_num(opt.ba_huber_px)
      << ", \"first_window\": " << io::detail::json_string(first_window)
      << ", \"min_window_keyframes\": " << opt.min_window_keyframes
      << ", \"adaptive_windows\": " << (opt.adaptive_windows ? "true" : "false")
      << ", \"ba_min_parallax_deg\": " << json_num(opt.ba_min_parallax_deg)
      << ", \"ba_cost_tolerance_sd\": " << json_num(opt.ba_cost_tolerance_sd) << "}"
      << ",\n  \"counts\": {\"poses\": " << np << ", \"keyframes\": " << nk
      << ", \"points\": " << corrector.num_points() << ", \"anchors\": " << anchors.size()
      << ", \"correspondences_used\": " << corrector.correspondences().size() << "}";
    j << ",\n  \"trajectory_jumps\": {\"time_unit\": "
      << io::detail::json_string(io::trajectory_time_unit(traj))
      << ", \"jump_ratio\": " << json_num(jump_options.max_ratio)
      << ", \"suspect_ratio\": " << json_num(suspect_options.max_ratio) << ", \"steps\": [";
    for (std::size_t i = 0; i < steps_flagged.size(); ++i) {
      const io::TrajectoryJump& jp = steps_flagged[i];
      j << (i ? ", " : "") << "{\"line_from\": " << traj.poses[jp.index].line
        << ", \"line_to\": " << traj.poses[jp.index + 1].line
        << ", \"frame_from\": " << traj.poses[jp.index].frame
        << ", \"frame_to\": " << traj.poses[jp.index + 1].frame
        << ", \"step\": " << json_num(jp.step) << ", \"dt\": " << json_num(jp.dt)
        << ", \"typical_speed\": " << json_num(jp.typical_speed)
        << ", \"ratio\": " << json_num(jp.ratio)
        << ", \"jump\": " << (jp.ratio > jump_options.max_ratio ? "true" : "false") << "}";
    }
    j << "]}";
    j << ",\n  \"anchor_time_offset\": {\"applied\": " << json_num(time_offset)
      << ", \"auto\": " << (time_offset_auto ? "true" : "false")
      << ", \"estimated\": " << (clock.estimated ? "true" : "false");
    if (clock.estimated)
      j << ", \"estimate\": " << json_num(clock_total) << ", \"sd\": " << json_num(clock.sd)
        << ", \"searched\": " << json_num(clock.searched) << ", \"windows\": " << clock.windows
        << ", \"windows_left_out\": " << clock.windows_left_out
        << ", \"anchors\": " << clock.anchors
        << ", \"rms_at_zero\": " << json_num(clock.rms_at_zero)
        << ", \"rms_at_estimate\": " << json_num(clock.rms_at_estimate)
        << ", \"statistic\": " << json_num(clock.statistic)
        << ", \"significant\": " << (clock.significant ? "true" : "false")
        << ", \"at_edge\": " << (clock.at_edge ? "true" : "false");
    else
      j << ", \"reason\": " << io::detail::json_string(clock.reason);
    j << "}"
      << ",\n  \"init\": {\"ok\": " << (ir.ok ? "true" : "false")
      << ", \"message\": " << io::detail::json_string(ir.message)
      << ", \"scale_m_units_per_metre\": " << json_num(1.0 / ir.S_wm.scale())
      << ", \"rms_m\": " << json_num(ir.rms_m) << ", \"inliers\": " << ir.inliers.size()
      << ", \"plane_from_camera_up\": " << (ir.plane_from_camera_up ? "true" : "false") << "}"
      << ",\n  \"anchor_residuals_m\": " << residuals
      << ",\n  \"drift_factor\": " << json_num(corrector.drift_factor())
      << ",\n  \"rejected_window_updates\": " << corrector.rejected_window_updates()
      << ",\n  \"grown_windows\": " << corrector.grown_windows()
      << ",\n  \"scale_spread\": " << json_num(scale_spread)
      << ",\n  \"screening\": {\"enabled\": " << (screen ? "true" : "false")
      << ", \"ok\": " << (screening.ok ? "true" : "false")
      << ", \"message\": " << io::detail::json_string(screening.message)
      << ", \"left_out\": " << screening.num_left_out()
      << ", \"drift_variance_factor\": " << json_num(screening.ok ? screening.drift_factor : NAN)
      << ", \"threshold_chi2\": " << json_num(screening.ok ? screening.threshold : NAN)
      << ", \"rounds\": " << screening.rounds << ", \"seconds\": " << json_num(screening.seconds)
      << "}";
    {
      std::vector<double> sd;
      for (const auto& C : unc.cov_en) sd.push_back(std::sqrt(C.trace()));
      std::sort(sd.begin(), sd.end());
      j << ",\n  \"uncertainty\": {\"ok\": " << (unc.ok ? "true" : "false")
        << ", \"message\": " << io::detail::json_string(unc.message)
        << ", \"drift_variance_factor\": " << json_num(unc.ok ? unc.drift_factor : NAN)
        << ", \"anchor_variance_factor\": " << json_num(unc.ok ? unc.anchor_factor : NAN)
        << ", \"fit_drift_variance_factor\": " << json_num(unc.ok ? unc.fit_drift_factor : NAN)
        << ", \"prediction_factor\": " << json_num(unc.ok ? unc.prediction_factor : NAN)
        << ", \"predicted_anchors\": " << unc.predicted_anchors
        << ", \"variance_dof\": " << json_num(unc.ok ? unc.variance_dof : NAN)
        << ", \"region_factor\": " << json_num(unc.ok ? unc.region_factor : NAN)
        << ", \"redundancy\": " << json_num(unc.ok ? unc.redundancy : NAN)
        << ", \"median_horizontal_sd_m\": " << json_num(sd.empty() ? NAN : sd[sd.size() / 2])
        << ", \"max_horizontal_sd_m\": " << json_num(sd.empty() ? NAN : sd.back())
        << ", \"seconds\": " << json_num(unc.ok ? unc.seconds : NAN) << "}";
    }
    // Each anchor in use: its leave-one-out prediction χ² (PathUncertainty), by anchor id.
    std::map<int, double> prediction_chi2;
    if (unc.ok)
      for (std::size_t c = 0; c < corrector.correspondences().size(); ++c)
        prediction_chi2[corrector.correspondences()[c].id] = unc.anchor_prediction_chi2[c];
    j << ",\n  \"anchors\": [";
    for (std::size_t d = 0; d < decisions.size(); ++d) {
      const auto& x = decisions[d];
      const io::Anchor& a = anchors[x.id];
      const Eigen::Vector3d r = corrector.received_view_center_w(static_cast<int>(d)) - a.y_w;
      j << (d ? "," : "") << "\n    {\"line\": " << a.line
        << ", \"frame\": " << traj.poses[locs[x.id].index].frame
        << ", \"used\": " << (x.used ? "true" : "false")
        << ", \"why_not\": " << io::detail::json_string(x.why)
        << ", \"readmitted\": " << (x.readmitted ? "true" : "false")
        << ", \"sigma_m\": " << json_num(a.sigma_m)
        << ", \"innovation_m\": " << json_num(x.innovation_m)
        << ", \"gate_m\": " << json_num(x.gate_m) << ", \"screening_statistic\": "
        << json_num(screening.ok ? screening.anchors[x.id].statistic : NAN)
        << ", \"screening_innovation_m\": "
        << json_num(screening.ok ? screening.anchors[x.id].innovation_m : NAN)
        << ", \"screening_sd_m\": " << json_num(screening.ok ? screening.anchors[x.id].sd_m : NAN)
        << ", \"screening_run_length\": " << (screening.ok ? screening.anchors[x.id].run_length : 0)
        << ", \"screening_run_offset_m\": "
        << json_num(screening.ok ? screening.anchors[x.id].run_offset_m : NAN)
        << ", \"residual_2d_m\": " << json_num(r.head<2>().norm())
        << ", \"residual_3d_m\": " << json_num(r.norm()) << ", \"prediction_chi2\": "
        << json_num(prediction_chi2.count(x.id) ? prediction_chi2.at(x.id) : NAN) << "}";
    }
    j << "\n  ]"
      << ",\n  \"last_anchor_frame\": " << traj.poses[last_anchor_index].frame
      << ",\n  \"steps\": [";
    const auto& reps = corrector.reports();
    for (std::size_t i = 0; i < reps.size(); ++i) {
      const auto& r = reps[i];
      j << (i ? "," : "") << "\n    {\"kind\": " << io::detail::json_string(r.kind)
        << ", \"correspondence\": " << r.correspondence << ", \"window_keyframes\": ["
        << r.window_first_keyframe << ", " << r.window_last_keyframe << "], \"nodes\": " << r.nodes
        << ", \"edges\": " << r.edges << ", \"initial_cost\": " << json_num(r.initial_cost)
        << ", \"final_cost\": " << json_num(r.final_cost) << ", \"iterations\": " << r.iterations
        << ", \"skipped_points\": " << r.skipped_points
        << ", \"termination\": " << io::detail::json_string(r.termination)
        << ", \"seconds\": " << json_num(r.seconds) << "}";
    }
    j << "\n  ],\n  \"correction_seconds_total\": " << json_num(total_s) << "\n}\n";
    io::detail::write_atomically(out.path("report.json"), [&](std::ostream& os) { os << j.str(); });
  }
  out.commit();
  std::printf(
      "geodrift correct: %zu poses (%zu keyframes), %zu anchors, mode %s, correction "
      "%.3f s -> %s\n",
      np, nk, anchors.size(), correction::to_string(opt.mode), total_s, out.out().string().c_str());
  return 0;
}

}  // namespace geodrift::cli
