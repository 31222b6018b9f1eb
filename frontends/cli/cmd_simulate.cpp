// geodrift simulate: what a user's monocular SLAM would hand to `geodrift correct` on a KITTI
// sequence (the drift simulator of sim/), plus ground truth for `geodrift eval`.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <geodrift/error.hpp>
#include <geodrift/geo/kitti.hpp>
#include <geodrift/io/anchors.hpp>
#include <geodrift/io/colmap_text.hpp>
#include <geodrift/io/trajectory.hpp>
#include <geodrift/sim/drift_simulator.hpp>
#include <geodrift/sim/kitti_protocol.hpp>
#include <geodrift/version.hpp>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "cli_util.hpp"
#include "commands.hpp"

namespace geodrift::cli {
namespace {

const char* kSimulateHelp =
    R"(usage: geodrift simulate --sequence 02|08 --out DIR [options]

Simulates monocular SLAM on a KITTI ground-truth path (drifting scale and rotation, keyframes
about one frame in three, map points with 1 px observations) and writes what the SLAM would
give, plus GNSS-style anchors and ground truth:

  trajectory_kitti.txt   drifted keyframe trajectory, KITTI with a leading frame index,
                         camera-to-map (frame M, arbitrary drifting units)
  colmap/                COLMAP text model of the drifted map (cameras, images, points3D with
                         tracks); image names are the frame indices
  anchors.csv            frame,latitude,longitude,height,sigma_m for the protocol's anchor
                         frames (50, 100, 150, 200, then every --interval): the true left-camera
                         centre of the keyframe nearest each anchor frame + 5 cm noise, converted
                         with the ASSUMED KITTI geo origin (stated in the header)
  ground_truth_kitti.txt ground truth of every simulated frame, KITTI world (cam0 of frame 0)
  ground_truth_w.txt     the same in W (E = x, N = z, U = -y of KITTI), for `geodrift eval`

then:  geodrift correct --trajectory DIR/trajectory_kitti.txt --map DIR/colmap \
           --anchors DIR/anchors.csv --out RESULT
       geodrift eval --result RESULT --ground-truth DIR/ground_truth_kitti.txt --kitti-to-w
   (or --ground-truth DIR/ground_truth_w.txt --gt-origin kitti)

options
  --sequence S     02 or 08 (shipped data)
  --data-dir DIR   folder with poses/SS.txt, times/SS.txt, calib_seq00-02.txt,
                   calib_seq04-12.txt (default data/kitti)
  --interval N     anchor interval in frames after the 4 INIT anchors (default 100)
  --seed S         simulator and anchor-noise seed (default 1)
  --frames A:B     simulate frames [A, B) only (anchor frames then count from A)
  --out DIR        output directory (must not exist or be empty unless --force)
  --force          write into an existing non-empty --out
  --help           this text
)";

std::string kitti_note() { return geo::kKittiGeoOriginNote; }

}  // namespace

int run_simulate(int argc, char** argv) {
  const Args args(argc, argv, {"sequence", "data-dir", "interval", "seed", "frames", "out"},
                  {"help", "force"});
  if (args.flag("help")) {
    std::fputs(kSimulateHelp, stdout);
    return 0;
  }
  const std::string seq = args.required("sequence");
  if (seq != "02" && seq != "08")
    throw UsageError("--sequence '" + seq + "': the shipped sequences are 02 and 08");
  const std::string data = args.get("data-dir", "data/kitti");
  const long long interval = args.get_int("interval", 100);
  if (interval < 1) throw UsageError("--interval must be >= 1");
  const long long seed = args.get_int("seed", 1);
  if (seed < 0) throw UsageError("--seed must be >= 0");
  const std::string out_dir = args.required("out");
  int first = 0, last = std::numeric_limits<int>::max();
  if (args.has("frames")) {
    const std::string f = args.get("frames");
    const auto colon = f.find(':');
    if (colon == std::string::npos) throw UsageError("--frames needs A:B, got '" + f + "'");
    const auto a = parse_number_list("frames", f.substr(0, colon));
    const auto b = parse_number_list("frames", f.substr(colon + 1));
    if (a.size() != 1 || b.size() != 1 || a[0] < 0 || b[0] <= a[0] || a[0] != std::floor(a[0]) ||
        b[0] != std::floor(b[0]))
      throw UsageError("--frames '" + f + "': need integers 0 <= A < B");
    first = static_cast<int>(a[0]);
    last = static_cast<int>(b[0]);
  }

  const std::string calib = data + (seq == "02" ? "/calib_seq00-02.txt" : "/calib_seq04-12.txt");
  const sim::KittiSequence ks = sim::load_kitti_sequence(data + "/poses/" + seq + ".txt", calib,
                                                         data + "/times/" + seq + ".txt", seq);
  if (first >= ks.num_frames())
    throw UsageError("--frames: sequence " + seq + " has " + std::to_string(ks.num_frames()) +
                     " frames");
  last = std::min(last, ks.num_frames());
  sim::SimOptions so = sim::SimOptions::kitti(seq, static_cast<unsigned>(seed));
  so.first_frame = first;
  so.last_frame = last;

  AtomicOutputDir out(out_dir, args.flag("force"));
  if (stderr_is_tty())
    std::fprintf(stderr, "geodrift simulate: simulating %s [%d, %d) ...\n", seq.c_str(), first,
                 last);
  const sim::SimulatedSequence s = sim::simulate(ks, so);
  GEODRIFT_CHECK(s.map.keyframes.size() >= 2,
                 "the simulation produced " << s.map.keyframes.size() << " keyframes");
  const geo::LocalFrame frame = geo::kitti_local_frame();
  const std::string m_note =
      "M = simulated monocular SLAM map of KITTI " + seq + " (arbitrary, drifting scale)";

  // Drifted keyframe trajectory, camera-to-map, with the frame index.
  io::Trajectory traj;
  traj.has_frame_index = true;
  for (const auto& k : s.map.keyframes) {
    io::TrajectoryPose p;
    p.frame = k.frame_index;
    p.T_cw = k.T_cw;
    traj.poses.push_back(p);
  }
  io::write_trajectory_kitti(out.path("trajectory_kitti.txt"), traj, m_note, true, io::kMapUnits);
  std::filesystem::create_directory(out.path("colmap"));
  io::write_colmap_text(out.path("colmap"), s.map, m_note, {}, {}, {}, io::kMapUnits);

  // Anchors: GNSS-style fixes at the keyframe nearest each protocol anchor frame.
  std::vector<int> frames = sim::kitti_anchor_frames(last - first, static_cast<int>(interval));
  std::mt19937 rng(static_cast<unsigned>(seed) * 7919u + 17u);
  std::normal_distribution<double> noise(0.0, so.geotag_noise_m);
  std::vector<io::Anchor> anchors;
  int prev_k = -1;
  for (int f : frames) {
    const int k = s.nearest_keyframe(first + f);
    if (k == prev_k) continue;
    prev_k = k;
    io::Anchor a;
    a.frame = s.map.keyframes[k].frame_index;
    a.y_w = s.gt_center_w[k] + Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
    a.sigma_m = so.geotag_noise_m;
    anchors.push_back(a);
  }
  {
    const std::string tmp = out.path(".anchors.part");
    io::write_anchors_csv(tmp, anchors, frame);
    std::ifstream in(tmp);
    std::stringstream body;
    body << in.rdbuf();
    in.close();
    std::filesystem::remove(tmp);
    io::detail::write_atomically(out.path("anchors.csv"), [&](std::ostream& os) {
      os << "# geodrift " << kVersion << " simulated GNSS fixes (5 cm noise) at keyframes of KITTI "
         << seq << ", protocol interval " << interval << "; " << kitti_note() << "\n"
         << body.str();
    });
  }

  // Ground truth of every simulated frame.
  io::Trajectory gt_k, gt_w;
  gt_k.has_frame_index = gt_w.has_frame_index = true;
  for (int f = first; f < last; ++f) {
    io::TrajectoryPose p;
    p.frame = f;
    p.timestamp = ks.timestamps[f];
    const Eigen::Isometry3d& T = ks.T_K_c[f];
    p.T_cw = sim::detail::to_se3(T).inverse();
    gt_k.poses.push_back(p);
    p.T_cw = sim::detail::to_se3(geo::kitti_pose_to_world(T)).inverse();
    gt_w.poses.push_back(p);
  }
  io::write_trajectory_kitti(out.path("ground_truth_kitti.txt"), gt_k,
                             "KITTI world = cam0 of frame 0 (x right, y down, z forward)", true);
  io::write_trajectory_kitti(out.path("ground_truth_w.txt"), gt_w,
                             frame.description() + "; " + kitti_note(), true);
  out.commit();
  std::printf(
      "geodrift simulate: KITTI %s frames [%d, %d): %zu keyframes, %zu points, %zu "
      "observations, %zu anchors (interval %lld, seed %lld)%s -> %s\n",
      seq.c_str(), first, last, s.map.keyframes.size(), s.map.points.size(),
      s.map.observations.size(), anchors.size(), interval, seed,
      s.calibrated ? "" : (" [" + s.message + "]").c_str(), out.out().string().c_str());
  return 0;
}

}  // namespace geodrift::cli
