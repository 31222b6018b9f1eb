// geodrift geotags build|query: the geo-tagged image database of the paper's Sec. 3.3 (panorama
// cutting, SIFT bag-of-words vocabulary and inverted file, per-view ORB features), built once
// and queried with an image.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <geodrift/error.hpp>
#include <geodrift/geotag/database.hpp>
#include <geodrift/geotag/views.hpp>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "cli_util.hpp"
#include "commands.hpp"

namespace geodrift::cli {
namespace {

constexpr double kPi = 3.14159265358979323846;

const char* kGeotagsHelp =
    R"(usage: geodrift geotags build --geotags DIR|CSV --out FILE [options]
       geodrift geotags query --db FILE --image IMAGE [options]

build: reads geo-tagged images (a geo-tag CSV, a dataset folder holding geotags.csv, e.g. the
output of `geodrift render`, or a folder of geo-tagged JPEG photos), cuts every equirectangular panorama into 8 rectilinear views at
45 deg steps with the video camera's intrinsics, extracts RootSIFT (retrieval) and ORB
(matching) features of every view, trains a hierarchical k-means vocabulary on a subsample,
builds the tf-idf inverted file and writes everything to one database FILE. Images are not
copied: the database refers to them by absolute path.

Geo-tag CSV columns (header row, any order): file, latitude, longitude, height, heading_deg
[, id, kind (panorama|photo), fx, fy, cx, cy, frame]; aliases image, latitude_deg,
longitude_deg, altitude_m, true_heading_deg. A 2:1 image is a panorama unless `kind` says
otherwise; heading_deg is the true heading of the panorama's centre column or of the photo's
optical axis. An empty latitude, longitude, height or heading_deg cell is read from the image's
EXIF (GPSLatitude, GPSLongitude, GPSAltitude as given, true GPSImgDirection); a photo may have
no heading (unknown: not used to localize), a panorama may not. A photo without fx..cy and
without --photo-hfov-deg takes its focal from EXIF FocalLengthIn35mmFilm f35: fx = fy =
f35 * (image diagonal in px) / 43.27 mm, principal point at the centre.

A folder without geotags.csv: every *.jpg/*.jpeg with EXIF GPS latitude, longitude and altitude
is a source (photo; a 2:1 image is a panorama and needs an EXIF true heading), with the focal
as above. Files that cannot be used (no GPS, no focal, ...) are skipped, each named in a warning
on stderr; none usable is an error.

build options
  --geotags DIR|CSV  geo-tag CSV, a folder with geotags.csv (and calib.txt, image_0/), or a
                     folder of geo-tagged JPEGs
  --out FILE         database file to write (refused if it exists, unless --force)
  --calib FILE       KITTI calib.txt (P0 gives fx, fy, cx, cy); default DIR/calib.txt
  --size WxH         video image size; default: the size of DIR/image_0/000000.png
  --camera fx,fy,cx,cy,W,H   video camera given directly instead of --calib/--size
  --photo-hfov-deg D horizontal field of view of photos without fx..cy columns (default: from
                     EXIF FocalLengthIn35mmFilm)
  --sift N           RootSIFT features per view (default 1000)
  --orb N            ORB features per view (default 2000)
  --retrieval-scale S  RootSIFT for retrieval on images resized by at most S in (0, 1]
                     (default 0.5: SIFT's doubled first octave at the image's resolution); a
                     panorama view is resized to half its panorama's own resolution if that
                     is lower (0.23 for 2048 px and KITTI's fx), and queries by the largest
                     factor any view was. Use 1 for photos as sharp as the video
  --branching B      vocabulary tree branching (default 10)
  --depth L          vocabulary tree depth (default 4: up to 10^4 words)
  --train N          descriptors sampled to train the vocabulary (default 200000)
  --seed S           vocabulary seed (default 42)
  --force            overwrite an existing FILE

query: prints the top-k views for an image as CSV on stdout (rank, view, score, source file,
cut direction (-1: photo), view heading (empty: unknown), geo-tag).

query options
  --db FILE          database written by `geodrift geotags build`
  --image IMAGE      query image (converted to grayscale)
  --top-k K          views to print (default 5)
  --near LAT,LON     distance gate centre (degrees); needs --radius
  --radius M         distance gate radius in metres (default 50)
  --help             this text
)";

map::Camera camera_from_list(const std::string& text) {
  const std::vector<double> v = parse_number_list("camera", text);
  if (v.size() != 6) throw UsageError("--camera needs fx,fy,cx,cy,W,H (6 numbers)");
  map::Camera c;
  c.fx = v[0];
  c.fy = v[1];
  c.cx = v[2];
  c.cy = v[3];
  c.width = static_cast<int>(v[4]);
  c.height = static_cast<int>(v[5]);
  if (c.width != v[4] || c.height != v[5]) throw UsageError("--camera: W and H must be integers");
  c.validate();
  return c;
}

/// fx, fy, cx, cy from the P0 line of a KITTI calib.txt.
void read_kitti_p0(const std::string& path, map::Camera* c) {
  std::ifstream in(path);
  if (!in) throw Error("cannot open calibration '" + path + "'");
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.rfind("P0:", 0) != 0) continue;
    std::istringstream ss(line.substr(3));
    double P[12];
    for (double& p : P)
      if (!(ss >> p) || !std::isfinite(p))
        throw InvalidArgument(path + ":" + std::to_string(lineno) + ": P0 needs 12 finite numbers");
    c->fx = P[0];
    c->cx = P[2];
    c->fy = P[5];
    c->cy = P[6];
    return;
  }
  throw InvalidArgument(path + ": no 'P0:' line (KITTI calib.txt expected)");
}

std::string fmt_time(double s) {
  char b[64];
  std::snprintf(b, sizeof b, "%.1f s", s);
  return b;
}

int run_build(int argc, char** argv) {
  const Args args(argc, argv,
                  {"geotags", "out", "calib", "size", "camera", "photo-hfov-deg", "sift", "orb",
                   "retrieval-scale", "branching", "depth", "train", "seed"},
                  {"help", "force"});
  if (args.flag("help")) {
    std::fputs(kGeotagsHelp, stdout);
    return 0;
  }
  namespace fs = std::filesystem;
  const std::string in = args.required("geotags");
  const std::string out = args.required("out");
  std::error_code ec;
  // Checks --out, and stages the database beside it: --out is never a partial file.
  AtomicOutputDir staged(out, args.flag("force"), AtomicOutputDir::Kind::kFile);
  const bool is_dir = fs::is_directory(in, ec);
  if (!fs::exists(in, ec)) throw Error("--geotags '" + in + "' does not exist");

  map::Camera cam;
  if (args.has("camera")) {
    if (args.has("calib") || args.has("size"))
      throw UsageError("--camera replaces --calib and --size; give one or the other");
    cam = camera_from_list(args.get("camera"));
  } else {
    const std::string calib =
        args.has("calib") ? args.get("calib")
                          : (is_dir ? (fs::path(in) / "calib.txt").string() : std::string());
    if (calib.empty() || !fs::exists(calib, ec))
      throw UsageError(
          "the video camera is needed: give --calib FILE (KITTI calib.txt) or "
          "--camera fx,fy,cx,cy,W,H");
    read_kitti_p0(calib, &cam);
    if (args.has("size")) {
      const std::string s = args.get("size");
      const auto x = s.find('x');
      if (x == std::string::npos) throw UsageError("--size '" + s + "' is not WxH");
      const std::vector<double> w = parse_number_list("size", s.substr(0, x));
      const std::vector<double> h = parse_number_list("size", s.substr(x + 1));
      if (w.size() != 1 || h.size() != 1) throw UsageError("--size '" + s + "' is not WxH");
      cam.width = static_cast<int>(w[0]);
      cam.height = static_cast<int>(h[0]);
    } else {
      const fs::path first = fs::path(calib).parent_path() / "image_0" / "000000.png";
      const cv::Mat img = cv::imread(first.string(), cv::IMREAD_UNCHANGED);
      if (img.empty())
        throw UsageError("the video image size is needed: give --size WxH (no readable '" +
                         first.string() + "')");
      cam.width = img.cols;
      cam.height = img.rows;
    }
    cam.validate();
  }

  geotag::GeoSourceOptions so;
  if (args.has("photo-hfov-deg"))
    so.photo_hfov_deg = parse_number_list("photo-hfov-deg", args.get("photo-hfov-deg")).at(0);
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<std::string> skipped;
  const std::vector<geotag::GeoSource> sources = geotag::read_geotag_sources(in, so, &skipped);
  for (const std::string& w : skipped)
    std::fprintf(stderr, "geodrift geotags build: warning: skipped %s\n", w.c_str());

  geotag::Database::BuildOptions o;
  o.video_camera = cam;
  o.sift_features = static_cast<int>(args.get_int("sift", 1000));
  o.orb_features = static_cast<int>(args.get_int("orb", 2000));
  if (args.has("retrieval-scale")) {
    const std::vector<double> rs =
        parse_number_list("retrieval-scale", args.get("retrieval-scale"));
    if (rs.size() != 1 || !(rs[0] > 0 && rs[0] <= 1))
      throw UsageError("--retrieval-scale must be one number in (0, 1]");
    o.retrieval_scale = rs[0];
  }
  o.vocabulary.branching = static_cast<int>(args.get_int("branching", 10));
  o.vocabulary.depth = static_cast<int>(args.get_int("depth", 4));
  o.vocabulary.max_training_descriptors = static_cast<int>(args.get_int("train", 200000));
  const long long seed = args.get_int("seed", 42);
  if (seed < 0) throw UsageError("--seed must be >= 0");
  o.vocabulary.seed = static_cast<std::uint64_t>(seed);
  const bool tty = stderr_is_tty();
  std::string last_stage;
  if (tty)
    o.progress = [&](const char* stage, std::size_t done, std::size_t total) {
      const double el =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      if (last_stage != stage && !last_stage.empty()) std::fputc('\n', stderr);
      last_stage = stage;
      std::fprintf(stderr, "\r  %-10s %zu/%zu  (%s)   ", stage, done, total, fmt_time(el).c_str());
      std::fflush(stderr);
    };
  const geotag::Database db = geotag::Database::build(sources, o);
  if (tty) std::fputc('\n', stderr);
  if (db.views().size() > 1 && db.index().num_informative_words() == 0)
    std::fprintf(stderr,
                 "warning: every one of the %d visual words occurs in all %zu views, so retrieval "
                 "cannot rank them; rebuild with a larger vocabulary (--branching, --depth)\n",
                 db.vocabulary().num_words(), db.views().size());
  db.save(staged.path(staged.out().filename().string()));
  staged.commit();
  const double el = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  int panos = 0;
  for (const auto& s : sources) panos += s.kind == geotag::SourceKind::kPanorama ? 1 : 0;
  std::printf(
      "geotag database %s: %zu sources (%d panoramas, %zu photos), %zu views, %d words, "
      "built in %s%s\n",
      out.c_str(), sources.size(), panos, sources.size() - panos, db.views().size(),
      db.vocabulary().num_words(), fmt_time(el).c_str(),
      skipped.empty() ? "" : ("; " + std::to_string(skipped.size()) + " JPEGs skipped").c_str());
  return 0;
}

int run_query(int argc, char** argv) {
  const Args args(argc, argv, {"db", "image", "top-k", "near", "radius"}, {"help"});
  if (args.flag("help")) {
    std::fputs(kGeotagsHelp, stdout);
    return 0;
  }
  const geotag::Database db = geotag::Database::load(args.required("db"));
  const std::string image = args.required("image");
  const cv::Mat g = cv::imread(image, cv::IMREAD_GRAYSCALE);
  if (g.empty()) throw Error("cannot read image '" + image + "'");
  geotag::QueryOptions q;
  q.top_k = static_cast<int>(args.get_int("top-k", 5));
  if (q.top_k < 1) throw UsageError("--top-k must be >= 1");
  geo::LocalFrame frame;
  if (args.has("near")) {
    const std::vector<double> ll = parse_number_list("near", args.get("near"));
    if (ll.size() != 2) throw UsageError("--near needs LAT,LON");
    frame = geo::LocalFrame::from_geodetic(ll[0], ll[1], 0.0);
    q.frame = &frame;
    q.gate_position_w = Eigen::Vector3d::Zero();
    q.gate_radius_m =
        args.has("radius") ? parse_number_list("radius", args.get("radius")).at(0) : 50.0;
  } else if (args.has("radius")) {
    throw UsageError("--radius needs --near LAT,LON");
  }
  const std::vector<geotag::Retrieved> r = db.query(g, q);
  std::printf("rank,view,score,file,direction,heading_deg,latitude,longitude,height\n");
  for (std::size_t i = 0; i < r.size(); ++i) {
    const geotag::GeoView& v = db.views()[r[i].view];
    char heading[32] = "";  // empty: unknown (a photo without heading)
    if (std::isfinite(v.heading))
      std::snprintf(heading, sizeof heading, "%.3f", v.heading * 180.0 / kPi);
    std::printf("%zu,%d,%.4f,%s,%d,%s,%.8f,%.8f,%.3f\n", i + 1, v.id, r[i].score,
                db.sources()[v.source].path.c_str(), v.direction, heading, v.tag.latitude_deg,
                v.tag.longitude_deg, v.tag.height);
  }
  if (r.empty())
    std::fprintf(stderr, "geodrift geotags query: %s\n",
                 db.index().num_informative_words() == 0
                     ? "no visual word distinguishes the database's views (each occurs in all of "
                       "them): rebuild it with a larger vocabulary (--branching, --depth)"
                     : "no view shares a visual word with the image");
  return 0;
}

}  // namespace

int run_geotags(int argc, char** argv) {
  if (argc < 2) {
    std::fputs(kGeotagsHelp, stderr);
    return 2;
  }
  const std::string sub = argv[1];
  if (sub == "--help" || sub == "-h" || sub == "help") {
    std::fputs(kGeotagsHelp, stdout);
    return 0;
  }
  if (sub == "build") return run_build(argc - 1, argv + 1);
  if (sub == "query") return run_query(argc - 1, argv + 1);
  throw UsageError("unknown geotags action '" + sub + "' (build or query)");
}

}  // namespace geodrift::cli
