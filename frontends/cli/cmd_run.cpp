// geodrift run: images or a video + calibration -> our monocular VO (geodrift::vo) -> the
// streaming Corrector (keyframes handed over as they become final) -> outputs. With --geotags
// the geo-tag pipeline (retrieval, matching, localization: issue 6) will turn keyframes into
// correspondences; until it lands, --geotags is refused with a clear message.
#if __has_include(<geodrift/vo/odometry.hpp>)  // built only with geodrift::vo (OpenCV)
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <geodrift/correction/corrector.hpp>
#include <geodrift/error.hpp>
#include <geodrift/io/colmap_text.hpp>
#include <geodrift/io/ply.hpp>
#include <geodrift/io/trajectory.hpp>
#include <geodrift/version.hpp>
#include <geodrift/vo/input.hpp>
#include <geodrift/vo/odometry.hpp>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "cli_util.hpp"
#include "commands.hpp"

namespace geodrift::cli {
namespace {

const char* kRunHelp =
    R"(usage: geodrift run (--images DIR | --video FILE) [--calib FILE] [--geotags DIR] --out DIR

Runs geodrift's monocular ORB visual odometry (two-view initialisation, tracking, keyframes,
local bundle adjustment) on a video, streams its keyframes to the Corrector, and writes the
reconstruction. The VO sees images and the calibration only.

inputs
  --images DIR        image folder sorted by name: DIR/image_0/*.png (KITTI layout) or DIR/*.png
                      (also jpg, pgm, ppm, bmp, tif); DIR/times.txt gives timestamps if present
  --video FILE        any video OpenCV can decode (timestamps from the container)
  --calib FILE        calibration: KITTI calib.txt ("P0:" line), a text file with
                      "K: fx 0 cx 0 fy cy 0 0 1" [+ "D: k1 k2 p1 p2 [k3]"], or an OpenCV YAML
                      with camera_matrix/K and distortion_coefficients/D. Default with --images:
                      DIR/calib.txt. Frames are undistorted when the calibration has distortion.
  --geotags DIR       geo-tagged panoramas/photos: not available yet (the geo-tag pipeline is
                      a separate issue); the VO output below is written without it

options
  --fps F             frame rate for timestamps of an image folder without times.txt (default 10)
  --max-frames N      process at most N frames
  --features N        ORB features per frame (default 2000)
  --threads T         solver threads for local BA, 1 or 2 (default 1)
  --out DIR           output directory (created; must not exist or be empty unless --force)
  --force             write into an existing non-empty --out (replaces geodrift's own files)
  --help              this text

outputs in DIR (map frame M: the VO's own frame and arbitrary scale; geodrift version in headers)
  trajectory_kitti.txt, trajectory_tum.txt   every tracked frame (camera-to-world, for evo); a
                      frame's pose is its raw relative pose to its keyframe composed with the
                      keyframe's final (bundle-adjusted) pose
  keyframes_kitti.txt keyframes only, with their frame index
  model/              COLMAP text model (cameras.txt, images.txt, points3D.txt) of the VO map
  points.ply          map points in M
  report.json         version, command line, parameters, counts, lost frames, timings
)";

std::string json_num(double v) {
  return std::isfinite(v) ? io::detail::fmt(v) : std::string("null");
}

}  // namespace

int run_run(int argc, char** argv) {
  const Args args(
      argc, argv,
      {"images", "video", "calib", "geotags", "fps", "max-frames", "features", "threads", "out"},
      {"help", "force"});
  if (args.flag("help")) {
    std::fputs(kRunHelp, stdout);
    return 0;
  }
  if (args.has("images") == args.has("video"))
    throw UsageError("give exactly one of --images DIR and --video FILE");
  const std::string out_dir = args.required("out");
  if (args.has("geotags"))
    throw UsageError(
        "--geotags is not available yet: the geo-tag pipeline (retrieval, matching, "
        "localization) has not landed; run without --geotags for the VO reconstruction");
  const double fps = args.has("fps") ? parse_number_list("fps", args.get("fps")).at(0) : 10.0;
  if (!(fps > 0)) throw UsageError("--fps must be > 0");
  const long long max_frames = args.get_int("max-frames", -1);
  vo::OdometryOptions vopt;
  vopt.orb.num_features = static_cast<int>(args.get_int("features", 2000));
  if (vopt.orb.num_features < 100) throw UsageError("--features must be >= 100");
  vopt.num_threads = static_cast<int>(args.get_int("threads", 1));
  if (vopt.num_threads != 1 && vopt.num_threads != 2) throw UsageError("--threads must be 1 or 2");
  {
    std::error_code ec;
    const std::filesystem::path p(out_dir);
    if (std::filesystem::exists(p, ec) && !std::filesystem::is_directory(p, ec))
      throw Error("--out '" + out_dir +
                  "' exists and is not a directory (refusing to replace a file)");
    if (std::filesystem::exists(p, ec) && !std::filesystem::is_empty(p, ec) && !args.flag("force"))
      throw Error("--out '" + out_dir + "' exists and is not empty (use --force)");
  }

  // ---- inputs -------------------------------------------------------------------------------
  std::string calib_path = args.get("calib", "");
  if (calib_path.empty() && args.has("images"))
    calib_path = vo::default_calibration_path(args.get("images"));
  if (calib_path.empty())
    throw InvalidArgument(
        "no calibration: pass --calib FILE (KITTI calib.txt, K/D text or OpenCV YAML)" +
        std::string(args.has("images") ? "; " + args.get("images") + "/calib.txt does not exist"
                                       : ""));
  vo::Calibration calib = vo::load_calibration(calib_path);
  std::unique_ptr<vo::FrameSource> source = args.has("images")
                                                ? vo::open_image_folder(args.get("images"), fps)
                                                : vo::open_video(args.get("video"));
  vo::Frame frame;
  if (!source->next(&frame)) throw Error(source->description() + ": no frames");
  if (calib.camera.width == 0) {
    calib.camera.width = frame.gray.cols;
    calib.camera.height = frame.gray.rows;
  }
  if (calib.camera.width != frame.gray.cols || calib.camera.height != frame.gray.rows)
    throw InvalidArgument(
        calib_path + ": calibration is for " + std::to_string(calib.camera.width) + "x" +
        std::to_string(calib.camera.height) + " images, " + source->description() + " has " +
        std::to_string(frame.gray.cols) + "x" + std::to_string(frame.gray.rows));
  vo::Undistorter undistort(calib);

  // ---- VO -> Corrector ----------------------------------------------------------------------
  vo::Odometry odo(calib.camera, vopt);
  correction::Corrector corrector;
  corrector.add_camera(calib.camera);
  int streamed = 0;
  odo.set_keyframe_callback([&](const vo::KeyframeBatch& b) {
    corrector.add_keyframe(b.keyframe);
    for (const auto& p : b.new_points) corrector.add_point(p);
    for (const auto& o : b.observations) corrector.add_observation(o);
    ++streamed;
    // Hook for --geotags (issue 6): retrieve geo views for b.view, match its ORB keypoints,
    // localize against b.view.point_ids' map points, corrector.add_correspondence(...).
  });
  const bool tty = stderr_is_tty();
  std::map<int, double> stamps;
  std::vector<std::pair<int, int>> lost;  // [first, last] frame ranges
  int frames = 0, tracked = 0, last_matches = 0;
  std::string last_message, first_pose_message;
  const auto t0 = std::chrono::steady_clock::now();
  do {
    if (max_frames >= 0 && frames >= max_frames) break;
    frame.gray = undistort.apply(frame.gray);
    stamps[frame.index] = frame.timestamp;
    const vo::FrameResult r = odo.process(frame);
    ++frames;
    if (r.has_pose()) {
      ++tracked;
      last_matches = r.matches;
      if (first_pose_message.empty()) first_pose_message = r.message;
    } else if (odo.initialized()) {
      if (!lost.empty() && lost.back().second == frame.index - 1)
        lost.back().second = frame.index;
      else
        lost.push_back({frame.index, frame.index});
    }
    if (!r.message.empty()) last_message = r.message;
    if (tty && (frames % 10 == 0)) {
      const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      std::fprintf(stderr,
                   "\rgeodrift run: frame %d%s, %.1f frames/s, %d keyframes, %d map points, %d "
                   "correspondences   ",
                   frames, source->size() > 0 ? ("/" + std::to_string(source->size())).c_str() : "",
                   frames / std::max(s, 1e-9), odo.num_keyframes(), odo.num_points(), last_matches);
    }
  } while (source->next(&frame));
  odo.finish();
  const double vo_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (tty) std::fputc('\n', stderr);
  if (!odo.initialized())
    throw Error("the VO could not initialise over " + std::to_string(frames) + " frames of " +
                source->description() + ": " +
                (odo.last_init_failure().empty() ? last_message : odo.last_init_failure()));
  const map::Map m = odo.map();
  if (m.keyframes.size() < 2) throw Error("the VO map has fewer than 2 keyframes");

  // ---- every tracked frame: raw relative pose to its keyframe, composed with the final pose
  std::map<int, lie::SE3d> raw(odo.frame_poses().begin(), odo.frame_poses().end());
  std::map<int, lie::SE3d> kf_final;
  for (const auto& k : m.keyframes) kf_final[k.frame_index] = k.T_cw;
  io::Trajectory traj, kf_traj;
  traj.has_timestamps = kf_traj.has_timestamps = true;
  kf_traj.has_frame_index = true;
  for (const auto& [fi, T_raw] : raw) {
    auto it = kf_final.upper_bound(fi);
    if (it == kf_final.begin()) continue;  // before the first keyframe (cannot happen)
    --it;
    const lie::SE3d T = T_raw * raw.at(it->first).inverse() * it->second;
    io::TrajectoryPose p;
    p.frame = fi;
    p.timestamp = stamps.count(fi) ? stamps.at(fi) : NAN;
    p.T_cw = T;
    traj.poses.push_back(p);
  }
  for (const auto& k : m.keyframes) {
    io::TrajectoryPose p;
    p.frame = k.frame_index;
    p.timestamp = k.timestamp;
    p.T_cw = k.T_cw;
    kf_traj.poses.push_back(p);
  }

  // ---- outputs ------------------------------------------------------------------------------
  StagedOutput out(out_dir, args.flag("force"));
  const std::string note =
      "M = geodrift VO map frame (first keyframe = origin, arbitrary scale); no geo-tags";
  io::write_trajectory_kitti(out.path("trajectory_kitti.txt"), traj, note);
  io::write_trajectory_tum(out.path("trajectory_tum.txt"), traj, note);
  io::write_trajectory_kitti(out.path("keyframes_kitti.txt"), kf_traj, note);
  std::filesystem::create_directory(out.path("model"));
  io::write_colmap_text(out.path("model"), m, note);
  {
    io::PointCloud cloud;
    for (const auto& p : m.points) cloud.points.push_back(p.position);
    io::write_ply(out.path("points.ply"), cloud, note);
  }
  {
    const vo::OdometryTimings& t = odo.timings();
    std::ostringstream j;
    j << "{\n  \"geodrift_version\": " << io::detail::json_string(kVersion)
      << ",\n  \"command_line\": " << io::detail::json_string(command_line(argc, argv))
      << ",\n  \"frame\": " << io::detail::json_string(note)
      << ",\n  \"units\": \"map units of M (arbitrary scale), seconds\""
      << ",\n  \"input\": " << io::detail::json_string(source->description())
      << ",\n  \"calibration\": {\"file\": " << io::detail::json_string(calib_path)
      << ", \"fx\": " << json_num(calib.camera.fx) << ", \"fy\": " << json_num(calib.camera.fy)
      << ", \"cx\": " << json_num(calib.camera.cx) << ", \"cy\": " << json_num(calib.camera.cy)
      << ", \"width\": " << calib.camera.width << ", \"height\": " << calib.camera.height
      << ", \"undistorted\": " << (calib.has_distortion() ? "true" : "false") << "}"
      << ",\n  \"parameters\": {\"features\": " << vopt.orb.num_features
      << ", \"local_window\": " << vopt.local_window << ", \"finalize_lag\": " << vopt.finalize_lag
      << ", \"threads\": " << vopt.num_threads << "}"
      << ",\n  \"counts\": {\"frames\": " << frames << ", \"tracked_frames\": " << tracked
      << ", \"keyframes\": " << m.keyframes.size() << ", \"points\": " << m.points.size()
      << ", \"observations\": " << m.observations.size()
      << ", \"keyframes_streamed_to_corrector\": " << streamed
      << ", \"init_attempts\": " << odo.init_attempts() << "}"
      << ",\n  \"initialisation\": " << io::detail::json_string(first_pose_message)
      << ",\n  \"lost_frame_ranges\": [";
    for (std::size_t i = 0; i < lost.size(); ++i)
      j << (i ? ", " : "") << "[" << lost[i].first << ", " << lost[i].second << "]";
    j << "],\n  \"geotags\": null"
      << ",\n  \"timings_s\": {\"total\": " << json_num(vo_s)
      << ", \"frames_per_second\": " << json_num(frames / std::max(vo_s, 1e-9))
      << ", \"features\": " << json_num(t.features) << ", \"init\": " << json_num(t.init)
      << ", \"tracking\": " << json_num(t.tracking) << ", \"keyframe\": " << json_num(t.keyframe)
      << ", \"triangulation\": " << json_num(t.triangulation)
      << ", \"local_ba\": " << json_num(t.local_ba) << ", \"local_ba_runs\": " << t.local_ba_runs
      << ", \"culling\": " << json_num(t.culling) << "}\n}\n";
    io::detail::write_atomically(out.path("report.json"), [&](std::ostream& os) { os << j.str(); });
  }
  out.commit();
  std::printf(
      "geodrift run: %d frames, %d tracked (%.1f %%), %zu keyframes, %zu map points, %.1f "
      "frames/s -> %s\n",
      frames, tracked, 100.0 * tracked / std::max(frames, 1), m.keyframes.size(), m.points.size(),
      frames / std::max(vo_s, 1e-9), out.out().string().c_str());
  return 0;
}

}  // namespace geodrift::cli
#endif
