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
#include <geodrift/correction/replay.hpp>
#include <geodrift/correction/screening.hpp>
#include <geodrift/error.hpp>
#include <geodrift/io/colmap_text.hpp>
#include <geodrift/io/ply.hpp>
#include <geodrift/io/trajectory.hpp>
#include <geodrift/version.hpp>
#include <geodrift/vo/input.hpp>
#include <geodrift/vo/odometry.hpp>
#include <limits>
#include <map>
#if defined(GEODRIFT_CLI_HAS_GEOTAG)
#include <fstream>
#include <geodrift/geotag/pipeline.hpp>
#include <geodrift/io/csv.hpp>
#include <geodrift/lie/sim3.hpp>
#include <limits>
#include <memory>
#include <unordered_map>
#endif
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
  --geotags DIR|FILE  geo-tagged panoramas/photos: a folder with geotags.csv or, without it,
                      of geo-tagged JPEGs (EXIF GPS; the database is built first; see
                      `geodrift geotags build --help` for the CSV, the EXIF fields used and
                      the JPEGs skipped with a warning) or a database FILE written by
                      `geodrift geotags build`. Each keyframe then
                      retrieves its top-5 views (RootSIFT bag of words), matches ORB + K-VLD,
                      localizes them by PnP + LM against its map points, and every localized
                      view is a correspondence for the Corrector (INIT at the 4th, then
                      PGO + BA). W = UTM grid at the first geo-tag's position.
  --geotag-gate M     after INIT, only retrieve views within M metres of the keyframe's
                      corrected position (default 50; 0 = never gate)
  --geotag-every N    run retrieval + matching + localization on every N-th keyframe only
                      (default 1: every keyframe; keyframes are ~1 m apart on a car, geo-tags
                      often 5 m or more)
  --geotag-top-k K    views tried per keyframe once the gate is active (default 5)
  --no-geotag-direction-gate  after INIT, also try retrieved views that look away from the
                      keyframe. By default a view whose heading differs from the keyframe's
                      corrected heading by more than half the sum of the two horizontal
                      fields of view (frusta disjoint at infinity) is not matched
  --no-screen-anchors use every localized view as it comes. By default, once the video is
                      done, each geo-tag is tested against all the others along the VO path
                      (one localization per geo-tag first, then every localization of the
                      geo-tags kept: correction/screening.hpp); if any is left out the
                      correction is run again over the final map without it. A wrong
                      geo-tag (a mis-tagged panorama, a retrieval mistake) is then listed as
                      not used in correspondences.csv and report.json
  --photo-hfov-deg D  horizontal field of view of geo-tagged photos whose CSV row has no
                      fx..cy (default: from EXIF FocalLengthIn35mmFilm); --geotags folder only
  --weights W         pose-graph edge weights of the correction: metric (default) | paper |
                      drift, as in `geodrift correct --help`

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
  with --geotags (frame W): trajectory.csv, trajectory_kitti.txt and trajectory_tum.txt hold the
                      corrected path; correspondences.csv every localized view, whether the
                      correction used it (why not) and its screening statistic; attempts.csv
                      every keyframe x view attempt (counts, inliers, tilt, position error);
                      vo_keyframes_kitti.txt the uncorrected VO keyframes in M after a frame
                      index (for a Sim(3)-aligned baseline with `geodrift eval`)
  model/              COLMAP text model (cameras.txt, images.txt, points3D.txt) of the VO map
  points.ply          map points in M
  report.json         version, command line, parameters, counts, lost frames, timings
)";

}  // namespace

int run_run(int argc, char** argv) {
  const Args args(
      argc, argv,
      {"images", "video", "calib", "geotags", "geotag-gate", "geotag-every", "geotag-top-k",
       "photo-hfov-deg", "fps", "max-frames", "features", "threads", "weights", "out"},
      {"help", "force", "no-screen-anchors", "no-geotag-direction-gate"});
  if (args.flag("help")) {
    std::fputs(kRunHelp, stdout);
    return 0;
  }
  if (args.has("images") == args.has("video"))
    throw UsageError("give exactly one of --images DIR and --video FILE");
  const std::string out_dir = args.required("out");
#if !defined(GEODRIFT_CLI_HAS_GEOTAG)
  if (args.has("geotags"))
    throw UsageError("--geotags needs geodrift built with the geotag frontend (OpenCV)");
#endif
  const double gate_m = args.has("geotag-gate")
                            ? parse_number_list("geotag-gate", args.get("geotag-gate")).at(0)
                            : 50.0;
  if (gate_m < 0) throw UsageError("--geotag-gate must be >= 0");
  const long long geo_every = args.get_int("geotag-every", 1);
  if (geo_every < 1) throw UsageError("--geotag-every must be >= 1");
  const long long geo_top_k = args.get_int("geotag-top-k", 5);
  if (geo_top_k < 1) throw UsageError("--geotag-top-k must be >= 1");
  double photo_hfov_deg = std::numeric_limits<double>::quiet_NaN();
  if (args.has("photo-hfov-deg")) {
    photo_hfov_deg = parse_number_list("photo-hfov-deg", args.get("photo-hfov-deg")).at(0);
    if (!(photo_hfov_deg > 1 && photo_hfov_deg < 179))
      throw UsageError("--photo-hfov-deg must be in (1, 179) degrees");
    std::error_code ec;
    if (!args.has("geotags") || !std::filesystem::is_directory(args.get("geotags"), ec))
      throw UsageError(
          "--photo-hfov-deg applies to a --geotags folder (a database FILE has its views' "
          "intrinsics already)");
  }
  const double fps = args.has("fps") ? parse_number_list("fps", args.get("fps")).at(0) : 10.0;
  if (!(fps > 0)) throw UsageError("--fps must be > 0");
  const long long max_frames = args.get_int("max-frames", -1);
  vo::OdometryOptions vopt;
  vopt.orb.num_features = static_cast<int>(args.get_int("features", 2000));
  if (vopt.orb.num_features < 100) throw UsageError("--features must be >= 100");
  vopt.num_threads = static_cast<int>(args.get_int("threads", 1));
  if (vopt.num_threads != 1 && vopt.num_threads != 2) throw UsageError("--threads must be 1 or 2");
  correction::CorrectorOptions copt;
  try {
    copt.edge_weights = correction::edge_weights_from_string(args.get("weights", "metric"));
  } catch (const InvalidArgument& e) {
    throw UsageError(std::string("--weights: ") + e.what());
  }
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

#if defined(GEODRIFT_CLI_HAS_GEOTAG)
  // ---- geo-tagged views (paper Sec. 3.3) -----------------------------------------------------
  std::unique_ptr<geotag::Database> geo_db;
  std::unique_ptr<geotag::GeoLocalizer> geo_loc;
  geo::LocalFrame geo_frame;
  double geotag_build_s = 0;
  if (args.has("geotags")) {
    const std::string g = args.get("geotags");
    std::error_code ec;
    const auto tg = std::chrono::steady_clock::now();
    if (std::filesystem::is_directory(g, ec)) {
      std::vector<std::string> skipped;
      geotag::GeoSourceOptions so;
      so.photo_hfov_deg = photo_hfov_deg;
      std::vector<geotag::GeoSource> sources = geotag::read_geotag_sources(g, so, &skipped);
      for (const std::string& w : skipped)
        std::fprintf(stderr, "geodrift run: warning: --geotags: skipped %s\n", w.c_str());
      geotag::Database::BuildOptions bo;
      bo.video_camera = calib.camera;
      if (stderr_is_tty())
        bo.progress = [](const char* stage, std::size_t done, std::size_t total) {
          std::fprintf(stderr, "\rgeodrift run: geo-tag database %-10s %zu/%zu   ", stage, done,
                       total);
        };
      geo_db = std::make_unique<geotag::Database>(geotag::Database::build(sources, bo));
      if (stderr_is_tty()) std::fputc('\n', stderr);
    } else {
      geo_db = std::make_unique<geotag::Database>(geotag::Database::load(g));
      const map::Camera& c = geo_db->video_camera();
      if (std::abs(c.fx - calib.camera.fx) > 1e-6 * c.fx || c.width != calib.camera.width ||
          c.height != calib.camera.height)
        throw Error("--geotags '" + g + "' was built for another camera (fx " +
                    std::to_string(c.fx) + ", " + std::to_string(c.width) + "x" +
                    std::to_string(c.height) + "); rebuild it with this calibration");
    }
    geotag_build_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - tg).count();
    const map::GeoTag& t0 = geo_db->sources().front().tag;
    geo_frame = geo::LocalFrame::from_geodetic(t0.latitude_deg, t0.longitude_deg, t0.height);
    geotag::PipelineOptions po;
    po.gate = gate_m > 0;
    if (gate_m > 0) po.gate_radius_m = gate_m;
    po.keyframe_stride = static_cast<int>(geo_every);
    po.top_k_gated = static_cast<int>(geo_top_k);
    po.gate_view_direction = !args.flag("no-geotag-direction-gate");
    geo_loc = std::make_unique<geotag::GeoLocalizer>(*geo_db, geo_frame, po);
  }
  std::unordered_map<int, Eigen::Vector3d> geo_points;  // final map points, M
  std::vector<map::Correspondence> geo_all;             // every localized view, in order
  int geo_attempts = 0, geo_corrs = 0;
  // Every keyframe x view attempt, for attempts.csv: the view centre in the keyframe's camera
  // frame (M units) is mapped to W through the keyframe's corrected pose at the end.
  struct GeoAttemptRow {
    geotag::ViewAttempt a;
    Eigen::Vector3d center_k = Eigen::Vector3d::Constant(NAN);
  };
  std::vector<GeoAttemptRow> geo_rows;
  double geo_s = 0, screen_s = 0;
  const bool screen = !args.flag("no-screen-anchors");
  correction::AnchorScreening screening;
#endif

  // ---- VO -> Corrector ----------------------------------------------------------------------
  vo::Odometry odo(calib.camera, vopt);
  correction::Corrector corrector(copt);
  corrector.add_camera(calib.camera);
  int streamed = 0;
  odo.set_keyframe_callback([&](const vo::KeyframeBatch& b) {
    corrector.add_keyframe(b.keyframe);
    for (const auto& p : b.new_points) corrector.add_point(p);
    for (const auto& o : b.observations) corrector.add_observation(o);
    ++streamed;
#if defined(GEODRIFT_CLI_HAS_GEOTAG)
    if (geo_loc) {
      const auto tg = std::chrono::steady_clock::now();
      for (const auto& p : b.new_points) geo_points[p.id] = p.position;
      geotag::KeyframeFeatures kf;
      kf.keyframe = b.keyframe;
      kf.gray = b.view.image;
      kf.keypoints = b.view.keypoints;
      kf.descriptors = b.view.descriptors;
      kf.point_ids = b.view.point_ids;
      if (!kf.gray.empty() && kf.keypoints.size() == kf.point_ids.size()) {
        Eigen::Vector3d estimate;
        const Eigen::Vector3d* est = nullptr;
        if (corrector.initialized()) {
          const int ki = corrector.keyframe_index(b.keyframe.id);
          estimate = corrector.keyframe_center_w(ki);
          est = &estimate;
          kf.optical_axis_w =
              corrector.keyframe_pose_w(ki).rotation().inverse().act(Eigen::Vector3d::UnitZ());
        }
        std::vector<geotag::ViewAttempt> attempts;
        const std::vector<map::Correspondence> cs = geo_loc->process(
            kf,
            [&](int id) -> const Eigen::Vector3d* {
              const auto it = geo_points.find(id);
              return it == geo_points.end() ? nullptr : &it->second;
            },
            est, &attempts);
        geo_attempts += static_cast<int>(attempts.size());
        for (geotag::ViewAttempt& a : attempts) {
          GeoAttemptRow row;
          if (a.result.inliers > 0)
            row.center_k = b.keyframe.T_cw.act(a.result.T_vm.inverse().translation());
          a.result.inlier_indices.clear();
          row.a = std::move(a);
          geo_rows.push_back(std::move(row));
        }
        for (const map::Correspondence& c : cs) corrector.add_correspondence(c);
        geo_all.insert(geo_all.end(), cs.begin(), cs.end());
        geo_corrs += static_cast<int>(cs.size());
      }
      geo_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - tg).count();
    }
#endif
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
                   "2D-3D matches, %d geo correspondences   ",
                   frames, source->size() > 0 ? ("/" + std::to_string(source->size())).c_str() : "",
                   frames / std::max(s, 1e-9), odo.num_keyframes(), odo.num_points(), last_matches,
                   static_cast<int>(corrector.correspondences().size()));
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
  AtomicOutputDir out(out_dir, args.flag("force"));
  const std::string note =
      "M = geodrift VO map frame (first keyframe = origin, arbitrary scale; not geo-referenced)";
  bool geo_written = false;
#if defined(GEODRIFT_CLI_HAS_GEOTAG)
  if (geo_loc) {
    corrector.finish();
    if (!corrector.initialized())
      throw Error(std::to_string(geo_corrs) + " geo views localized in " +
                  std::to_string(geo_attempts) + " attempts; INIT needs 4 (" +
                  corrector.init_message() + ")");
    // Wrong geo-tags: every one tested against all the others along the final VO path; the
    // streamed correction used them as they came, so with any left out it is run again over
    // the final map (the same stream `geodrift correct` replays) without them.
    std::unique_ptr<correction::Corrector> rescreened;
    const auto ts = std::chrono::steady_clock::now();
    if (screen) {
      screening = correction::screen_anchors_by_geotag(m.keyframes, geo_all);
      if (!screening.ok) {
        std::fprintf(stderr, "geodrift run: warning: geo-tags not screened: %s\n",
                     screening.message.c_str());
      } else if (2 * screening.num_left_out() > static_cast<int>(geo_all.size())) {
        throw Error(std::to_string(screening.num_left_out()) + " of the " +
                    std::to_string(geo_all.size()) +
                    " localized geo views disagree with the others beyond what the VO can have "
                    "drifted (geo-tags of another place, or a broken VO path): no trustworthy "
                    "result, nothing written (--no-screen-anchors uses them all)");
      } else if (screening.num_left_out() > 0) {
        rescreened = std::make_unique<correction::Corrector>(copt);
        correction::apply_screening(screening, geo_all, rescreened.get());
        correction::replay(m, geo_all, rescreened.get());
        if (!rescreened->initialized())
          throw Error("INIT failed over the geo views the screening kept (" +
                      rescreened->init_message() + "); nothing written");
        for (const correction::ScreenedAnchor& a : screening.anchors)
          if (!a.used) std::fprintf(stderr, "geodrift run: geo view not used: %s\n", a.why.c_str());
      }
    }
    screen_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - ts).count();
    const correction::Corrector& fin = rescreened ? *rescreened : corrector;
    // Every tracked frame in W: its raw pose relative to its keyframe composed with the
    // keyframe's corrected Sim(3) pose.
    std::map<int, int> ci_of_frame;
    for (int i = 0; i < fin.num_keyframes(); ++i) ci_of_frame[fin.keyframes()[i].frame_index] = i;
    int last_anchor_frame = -1;
    for (const map::Correspondence& c : fin.correspondences())
      last_anchor_frame =
          std::max(last_anchor_frame, fin.keyframes()[fin.keyframe_index(c.keyframe)].frame_index);
    std::vector<io::TrajectoryCsvRow> rows;
    io::Trajectory w_traj;
    w_traj.has_timestamps = true;
    std::vector<Eigen::Vector3d> track;
    for (const auto& [fi, T_raw] : raw) {
      auto it = ci_of_frame.upper_bound(fi);
      if (it == ci_of_frame.begin() || !raw.count(std::prev(it)->first)) continue;
      --it;
      const lie::SE3d dT = T_raw * raw.at(it->first).inverse();
      const lie::SE3d T = (lie::Sim3d(dT) * fin.keyframe_sim3(it->second)).to_se3();
      io::TrajectoryCsvRow r;
      r.frame = fi;
      r.timestamp = stamps.count(fi) ? stamps.at(fi) : NAN;
      r.keyframe = it->first == fi;
      r.T_cw = T;
      r.after_last_anchor = fi > last_anchor_frame;
      rows.push_back(r);
      io::TrajectoryPose p;
      p.frame = fi;
      p.timestamp = r.timestamp;
      p.T_cw = T;
      w_traj.poses.push_back(p);
      track.push_back(T.inverse().translation());
    }
    const std::string wnote = geo_frame.description();
    io::write_trajectory_csv(out.path("trajectory.csv"), rows, geo_frame,
                             "geodrift run with geo-tagged views");
    io::write_trajectory_kitti(out.path("trajectory_kitti.txt"), w_traj, wnote);
    io::write_trajectory_tum(out.path("trajectory_tum.txt"), w_traj, wnote);
    std::ofstream cs(out.path("correspondences.csv"));
    cs << "# geodrift " << kVersion << " localized geo views; y in " << wnote << "\n"
       << "id,keyframe,frame,geotag,x,y,z,inliers,reprojection_rms_px,used,"
          "screening_statistic,screening_innovation_m,screening_sd_m,why_not\n";
    std::unordered_map<int, const correction::AnchorDecision*> decision_of;
    for (const correction::AnchorDecision& d : fin.anchor_decisions()) decision_of[d.id] = &d;
    for (std::size_t q = 0; q < geo_all.size(); ++q) {
      const map::Correspondence& c = geo_all[q];
      const auto d = decision_of.find(c.id);
      const bool used = d != decision_of.end() && d->second->used;
      std::string why = d == decision_of.end() ? "not received by the correction" : d->second->why;
      for (char& ch : why)
        if (ch == ',' || ch == '\n') ch = ';';
      const bool tested = screening.ok && q < screening.anchors.size();
      cs << c.id << "," << c.keyframe << ","
         << fin.keyframes()[fin.keyframe_index(c.keyframe)].frame_index << "," << c.geotag_id << ","
         << io::detail::fmt(c.y_w.x()) << "," << io::detail::fmt(c.y_w.y()) << ","
         << io::detail::fmt(c.y_w.z()) << "," << c.inliers << ","
         << io::detail::fmt(c.reprojection_rms) << "," << (used ? 1 : 0) << ","
         << (tested ? csv_num(screening.anchors[q].statistic) : "") << ","
         << (tested ? csv_num(screening.anchors[q].innovation_m) : "") << ","
         << (tested ? csv_num(screening.anchors[q].sd_m) : "") << "," << why << "\n";
    }
    close_checked(cs, out.path("correspondences.csv"));
    std::ofstream as(out.path("attempts.csv"));
    as << "# geodrift " << kVersion << " every keyframe x retrieved view attempt; x,y,z = the "
       << "view's PnP centre mapped to W through the keyframe's corrected pose (empty without "
       << "an estimate); dx = its horizontal distance to the geo-tag; " << wnote << "\n"
       << "keyframe,frame,view,geotag,score,putative,kvld_kept,pairs_3d,inliers,rms_px,tilt_deg,"
          "accepted,x,y,z,dx_m,reason\n";
    for (const GeoAttemptRow& g : geo_rows) {
      const geotag::ViewAttempt& a = g.a;
      const int ki = fin.keyframe_index(a.keyframe);
      const geotag::GeoView& v = geo_db->views()[a.view];
      const map::GeoTag& tag = geo_db->sources()[v.source].tag;
      const Eigen::Vector3d y = geo_frame.to_world(tag.latitude_deg, tag.longitude_deg, tag.height);
      as << a.keyframe << "," << (ki >= 0 ? fin.keyframes()[ki].frame_index : -1) << "," << a.view
         << "," << tag.id << "," << io::detail::fmt(a.score) << "," << a.putative << "," << a.kept
         << "," << a.pairs_3d << "," << a.result.inliers << "," << io::detail::fmt(a.result.rms_px)
         << "," << csv_num(a.tilt_deg) << "," << (a.result.ok ? 1 : 0) << ",";
      if (ki >= 0 && g.center_k.allFinite()) {
        const Eigen::Vector3d c = fin.keyframe_sim3(ki).inverse().act(g.center_k);
        as << io::detail::fmt(c.x()) << "," << io::detail::fmt(c.y()) << ","
           << io::detail::fmt(c.z()) << ","
           << io::detail::fmt(std::hypot(c.x() - y.x(), c.y() - y.y()));
      } else {
        as << ",,,";
      }
      std::string reason = a.result.reason;
      for (char& ch : reason)
        if (ch == ',' || ch == '\n') ch = ';';
      as << "," << reason << "\n";
    }
    close_checked(as, out.path("attempts.csv"));
    // The uncorrected VO keyframes (M) with their frame index, for a Sim(3)-aligned baseline.
    io::write_trajectory_kitti(out.path("vo_keyframes_kitti.txt"), kf_traj, note, true,
                               io::kMapUnits);
    geo_written = true;
  }
#endif
  if (!geo_written) {
    io::write_trajectory_kitti(out.path("trajectory_kitti.txt"), traj, note, false, io::kMapUnits);
    io::write_trajectory_tum(out.path("trajectory_tum.txt"), traj, note, io::kMapUnits);
  }
  io::write_trajectory_kitti(out.path("keyframes_kitti.txt"), kf_traj, note,
                             /*write_frame_index=*/true, io::kMapUnits);
  std::filesystem::create_directory(out.path("model"));
  io::write_colmap_text(out.path("model"), m, note, {}, {}, {}, io::kMapUnits);
  {
    io::PointCloud cloud;
    for (const auto& p : m.points) cloud.points.push_back(p.position);
    io::write_ply(out.path("points.ply"), cloud, note, io::kMapUnits);
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
    j << "],\n  \"geotags\": ";
#if defined(GEODRIFT_CLI_HAS_GEOTAG)
    if (geo_loc)
      j << "{\"source\": " << io::detail::json_string(args.get("geotags"))
        << ", \"views\": " << geo_db->views().size() << ", \"attempts\": " << geo_attempts
        << ", \"correspondences\": " << geo_corrs
        << ", \"database_seconds\": " << json_num(geotag_build_s)
        << ", \"localization_seconds\": " << json_num(geo_s) << ", \"every\": " << geo_every
        << ", \"top_k_gated\": " << geo_top_k
        << ", \"keyframes_queried\": " << geo_loc->stats().keyframes_queried
        << ", \"views_skipped_direction\": " << geo_loc->stats().views_skipped_direction
        << ", \"cpu_seconds\": {\"retrieval\": " << json_num(geo_loc->stats().retrieval_cpu_s)
        << ", \"orb_matching\": " << json_num(geo_loc->stats().orb_match_cpu_s)
        << ", \"kvld\": " << json_num(geo_loc->stats().kvld_cpu_s)
        << ", \"pnp\": " << json_num(geo_loc->stats().pnp_cpu_s)
        << ", \"total\": " << json_num(geo_loc->stats().total_cpu_s) << "}"
        << ", \"frame\": " << io::detail::json_string(geo_frame.description())
        << ", \"screening\": {\"enabled\": " << (screen ? "true" : "false")
        << ", \"ok\": " << (screening.ok ? "true" : "false")
        << ", \"message\": " << io::detail::json_string(screening.message)
        << ", \"left_out\": " << screening.num_left_out()
        << ", \"drift_variance_factor\": " << json_num(screening.ok ? screening.drift_factor : NAN)
        << ", \"threshold_chi2\": " << json_num(screening.ok ? screening.threshold : NAN)
        << ", \"rounds\": " << screening.rounds << ", \"seconds\": " << json_num(screen_s) << "}}";
    else
#endif
      j << "null";
    j << ",\n  \"timings_s\": {\"total\": " << json_num(vo_s)
      << ", \"frames_per_second\": " << json_num(frames / std::max(vo_s, 1e-9))
      << ", \"features\": " << json_num(t.features) << ", \"init\": " << json_num(t.init)
      << ", \"tracking\": " << json_num(t.tracking) << ", \"keyframe\": " << json_num(t.keyframe)
      << ", \"triangulation\": " << json_num(t.triangulation)
      << ", \"local_ba\": " << json_num(t.local_ba) << ", \"local_ba_runs\": " << t.local_ba_runs
      << ", \"culling\": " << json_num(t.culling)
      << ", \"keyframe_handover\": " << json_num(t.handover) << "}\n}\n";
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
