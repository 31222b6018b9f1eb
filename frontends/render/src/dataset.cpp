// Dataset folders: calib, times, ground truth, frames, panoramas, geo-tags, metadata.
#include "geodrift/render/dataset.hpp"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <opencv2/imgcodecs.hpp>
#include <sstream>

#include "geodrift/error.hpp"
#include "geodrift/geo/kitti.hpp"
#include "geodrift/io/trajectory.hpp"
#include "geodrift/sim/kitti_protocol.hpp"
#include "geodrift/version.hpp"
#include "world_impl.hpp"

namespace geodrift::render {
namespace {

std::string json_escape(const std::string& s) {
  std::string o;
  for (char c : s) {
    if (c == '"' || c == '\\') {
      o += '\\';
      o += c;
    } else if (static_cast<unsigned char>(c) < 0x20) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\u%04x", c);
      o += buf;
    } else {
      o += c;
    }
  }
  return o;
}

void write_text(const std::string& path, const std::string& text) {
  std::ofstream f(path, std::ios::binary);
  if (!f) throw Error("cannot create " + path);
  f << text;
  f.close();
  if (!f) throw Error("cannot write " + path);
}

void write_png(const std::string& path, const cv::Mat& img) {
  bool ok = false;
  try {
    ok = cv::imwrite(path, img, {cv::IMWRITE_PNG_COMPRESSION, 3});
  } catch (const cv::Exception& e) {
    throw Error("cannot write image " + path + ": " + e.what());
  }
  if (!ok) throw Error("cannot write image " + path);
}

std::string six(int i) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "%06d", i);
  return buf;
}

}  // namespace

std::vector<PanoramaSite> panorama_sites(const World& world, int first, int last, double spacing_m,
                                         double height_m, double lateral_offset_m) {
  GEODRIFT_CHECK(std::isfinite(spacing_m) && spacing_m > 0,
                 "panorama spacing " << spacing_m << " m must be > 0");
  GEODRIFT_CHECK(std::isfinite(height_m) && std::isfinite(lateral_offset_m),
                 "panorama height / lateral offset not finite");
  const int n = world.frame_count();
  GEODRIFT_CHECK(first >= 0 && last >= first && last < n, "panorama frame range ["
                                                              << first << ", " << last
                                                              << "] outside [0, " << n - 1 << "]");
  std::vector<PanoramaSite> sites;
  const double s0 = world.frame_arclength(first), s1 = world.frame_arclength(last);
  int f = first;
  for (double s = s0; s <= s1 + 1e-9; s += spacing_m) {
    PanoramaSite p;
    p.id = static_cast<int>(sites.size());
    p.s = s;
    const Eigen::Vector3d c = world.route_point(s);
    const Eigen::Vector2d t = world.route_tangent(s);
    const Eigen::Vector2d right(t.y(), -t.x());
    p.centre.head<2>() = c.head<2>() + lateral_offset_m * right;
    p.centre.z() = world.ground_height(p.centre.x(), p.centre.y()) + height_m;
    const double yaw = std::atan2(t.y(), t.x());
    p.heading = world.local_frame().heading_from_grid_yaw(yaw, p.centre);
    while (f < last &&
           std::abs(world.frame_arclength(f + 1) - s) <= std::abs(world.frame_arclength(f) - s))
      ++f;
    p.frame = f - first;
    sites.push_back(p);
  }
  return sites;
}

DatasetSummary write_dataset(const DatasetOptions& o, const std::string& dir,
                             const ProgressFn& progress) {
  namespace fs = std::filesystem;
  GEODRIFT_CHECK(!o.poses_path.empty(), "render: no pose file given");
  GEODRIFT_CHECK(!o.calib_path.empty(), "render: no calibration file given");
  if (!fs::exists(o.poses_path)) throw Error("render: pose file " + o.poses_path + " not found");
  if (!fs::exists(o.calib_path))
    throw Error("render: calibration file " + o.calib_path + " not found");
  if (!o.times_path.empty() && !fs::exists(o.times_path))
    throw Error("render: times file " + o.times_path + " not found");
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw Error("render: output folder " + dir + " does not exist");
  GEODRIFT_CHECK(
      o.panorama_width >= 8 && o.panorama_height >= 4,
      "render: panorama size " << o.panorama_width << "x" << o.panorama_height << " below 8x4");

  const sim::KittiSequence seq =
      sim::load_kitti_sequence(o.poses_path, o.calib_path, o.times_path, o.sequence);
  const int n = seq.num_frames();
  const int first = o.first, last = o.last < 0 ? n - 1 : o.last;
  GEODRIFT_CHECK(first >= 0 && first < n, "render: --first " << first << " outside [0, " << n - 1
                                                             << "] (" << o.poses_path << " has "
                                                             << n << " poses)");
  GEODRIFT_CHECK(last >= first && last < n,
                 "render: --last " << last << " outside [" << first << ", " << n - 1 << "] ("
                                   << o.poses_path << " has " << n << " poses)");
  const std::string sequence =
      o.sequence.empty() ? fs::path(o.poses_path).stem().string() : o.sequence;

  WorldOptions wo;
  wo.seed = o.seed;
  wo.first_frame = first;
  wo.last_frame = last;
  const World world = World::from_kitti(seq.T_K_c, wo);
  const map::Camera cam = seq.camera;
  const int threads = o.threads;

  // calib.txt
  {
    std::ostringstream os;
    os << std::scientific << std::setprecision(12);
    const double P0[12] = {cam.fx, 0, cam.cx, 0, 0, cam.fy, cam.cy, 0, 0, 0, 1, 0};
    double P1[12];
    std::copy(P0, P0 + 12, P1);
    P1[3] = -cam.fx * seq.baseline_m;
    os << "P0:";
    for (double v : P0) os << ' ' << v;
    os << "\nP1:";
    for (double v : P1) os << ' ' << v;
    os << '\n';
    write_text(dir + "/calib.txt", os.str());
  }
  // times.txt, poses.txt
  {
    std::ostringstream os;
    os << std::setprecision(17);
    for (int i = first; i <= last; ++i) os << io::detail::fmt(seq.timestamps[i]) << '\n';
    write_text(dir + "/times.txt", os.str());
    io::Trajectory traj;
    traj.format = io::TrajectoryFormat::kKitti;
    for (int i = first; i <= last; ++i) {
      io::TrajectoryPose p;
      p.frame = i - first;
      const Eigen::Isometry3d T_cK = seq.T_K_c[i].inverse(Eigen::Isometry);
      p.T_cw = lie::SE3d(lie::SO3d(Eigen::Matrix3d(T_cK.linear())), T_cK.translation());
      traj.poses.push_back(p);
    }
    io::write_trajectory_kitti(dir + "/poses.txt", traj,
                               "KITTI world of sequence " + sequence +
                                   " (cam0 of its frame 0; x right, y down, z "
                                   "forward); rows = sequence frames " +
                                   std::to_string(first) + ".." + std::to_string(last) +
                                   " (dataset frames 0.." + std::to_string(last - first) + ")");
  }

  DatasetSummary summary;
  summary.world_summary = world.summary();
  // Frames.
  fs::create_directory(dir + "/image_0", ec);
  if (ec) throw Error("cannot create " + dir + "/image_0: " + ec.message());
  const auto t0 = std::chrono::steady_clock::now();
  RenderOptions fro = o.frame_render;
  fro.color = false;
  fro.threads = threads;
  const int nframes = last - first + 1;
  for (int i = first; i <= last; ++i) {
    const cv::Mat img = render_pinhole(world, world.frame_T_cw(i), cam, Appearance::video(), fro);
    write_png(dir + "/image_0/" + six(i - first) + ".png", img);
    ++summary.frames;
    if (progress) progress("frames", summary.frames, nframes);
  }
  const auto t1 = std::chrono::steady_clock::now();
  summary.frame_seconds = std::chrono::duration<double>(t1 - t0).count();

  // Panoramas + geotags.
  std::ostringstream csv;
  csv << "# geodrift " << kVersion << " renderer " << kRendererVersion
      << " geo-tags: panorama centres; x,y,z in W = " << world.local_frame().description()
      << " (E/N/Up of KITTI cam0 at sequence frame 0); latitude/longitude deg WGS84, height m "
         "ellipsoidal; heading_deg = true bearing of the centre column; frame = dataset frame; "
      << geo::kKittiGeoOriginNote << "\n";
  csv << "id,file,latitude,longitude,height,heading_deg,x,y,z,frame\n";
  std::vector<PanoramaSite> sites;
  if (o.panorama_spacing_m > 0) {
    sites = panorama_sites(world, first, last, o.panorama_spacing_m, o.panorama_height_m,
                           o.panorama_lateral_offset_m);
    fs::create_directory(dir + "/panoramas", ec);
    if (ec) throw Error("cannot create " + dir + "/panoramas: " + ec.message());
    PanoramaOptions po;
    po.width = o.panorama_width;
    po.height = o.panorama_height;
    po.render.threads = threads;
    for (const PanoramaSite& p : sites) {
      const std::string file = "panoramas/pano_" + six(p.id) + ".png";
      write_png(dir + "/" + file,
                render_panorama(world, p.centre, p.heading, Appearance::street_view(), po));
      const geo::Geodetic g = world.local_frame().to_geodetic(p.centre);
      csv << p.id << ',' << file << ',' << std::fixed << std::setprecision(9) << g.latitude_deg
          << ',' << g.longitude_deg << ',' << std::setprecision(4) << g.height << ','
          << std::setprecision(6) << p.heading * 180.0 / M_PI << ',' << std::setprecision(4)
          << p.centre.x() << ',' << p.centre.y() << ',' << p.centre.z() << ',' << p.frame << '\n';
      ++summary.panoramas;
      if (progress) progress("panoramas", summary.panoramas, static_cast<int>(sites.size()));
    }
  }
  summary.panorama_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count();
  write_text(dir + "/geotags.csv", csv.str());

  // dataset.json
  {
    const Appearance v = Appearance::video(), sv = Appearance::street_view();
    auto vec = [](const Eigen::Vector3d& x) {
      std::ostringstream os;
      os << std::setprecision(9) << '[' << x.x() << ", " << x.y() << ", " << x.z() << ']';
      return os.str();
    };
    const geo::Geodetic org = world.local_frame().origin_geodetic();
    std::ostringstream js;
    js << std::setprecision(12);
    js << "{\n  \"geodrift_version\": \"" << kVersion << "\",\n  \"renderer_version\": \""
       << kRendererVersion << "\",\n  \"seed\": " << o.seed << ",\n  \"sequence\": \""
       << json_escape(sequence) << "\",\n  \"poses\": \"" << json_escape(o.poses_path)
       << "\",\n  \"calib\": \"" << json_escape(o.calib_path) << "\",\n  \"times\": \""
       << json_escape(o.times_path) << "\",\n  \"first_frame\": " << first
       << ",\n  \"last_frame\": " << last << ",\n  \"frames\": " << nframes
       << ",\n  \"camera\": {\"fx\": " << cam.fx << ", \"fy\": " << cam.fy << ", \"cx\": " << cam.cx
       << ", \"cy\": " << cam.cy << ", \"width\": " << cam.width << ", \"height\": " << cam.height
       << ", \"baseline_m\": " << seq.baseline_m << "},\n"
       << "  \"frame_antialias\": \""
       << (fro.antialias == Antialias::kQuincunx ? "quincunx"
           : fro.antialias == Antialias::kGrid   ? "grid"
                                                 : "none")
       << "\",\n  \"panoramas\": {\"count\": " << sites.size()
       << ", \"spacing_m\": " << o.panorama_spacing_m << ", \"width\": " << o.panorama_width
       << ", \"height\": " << o.panorama_height
       << ", \"height_above_ground_m\": " << o.panorama_height_m
       << ", \"lateral_offset_m\": " << o.panorama_lateral_offset_m
       << ", \"convention\": \"level; column u -> true bearing heading_deg + 360*((u+0.5)/W - "
          "0.5); row v -> elevation 90 - 180*(v+0.5)/H\"},\n"
       << "  \"appearance_video\": {\"sun_direction_w\": " << vec(v.sun_direction)
       << ", \"sun\": " << v.sun_intensity << ", \"ambient\": " << v.ambient_intensity
       << ", \"white_balance\": " << vec(v.white_balance) << "},\n"
       << "  \"appearance_street_view\": {\"sun_direction_w\": " << vec(sv.sun_direction)
       << ", \"sun\": " << sv.sun_intensity << ", \"ambient\": " << sv.ambient_intensity
       << ", \"white_balance\": " << vec(sv.white_balance)
       << ", \"replaced_facades\": 0.2, \"parked_cars\": \"40% kept, 35% moved 1.5-5 m, 25% "
          "removed, new cars in 15% of empty bays\"},\n"
       << "  \"camera_height_m\": " << wo.camera_height_m << ",\n"
       << "  \"world\": \"" << json_escape(summary.world_summary) << "\",\n"
       << "  \"origin\": {\"latitude\": " << org.latitude_deg
       << ", \"longitude\": " << org.longitude_deg << ", \"height\": " << org.height
       << ", \"utm_zone\": \"" << world.local_frame().zone_string() << "\", \"w_frame\": \""
       << json_escape(world.local_frame().description()) << "\", \"note\": \""
       << json_escape(geo::kKittiGeoOriginNote) << "\"}\n}\n";
    write_text(dir + "/dataset.json", js.str());
  }
  return summary;
}

}  // namespace geodrift::render
