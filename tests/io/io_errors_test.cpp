// Bad input for every io/ reader: each error names the file path and line and what is wrong;
// a missing file is an I/O Error naming the path. Nothing crashes.

#include <catch2/catch.hpp>
#include <string>

#include "geodrift/geo/kitti.hpp"
#include "geodrift/io/anchors.hpp"
#include "geodrift/io/colmap_text.hpp"
#include "geodrift/io/csv.hpp"
#include "geodrift/io/ply.hpp"
#include "geodrift/io/trajectory.hpp"
#include "support/test_files.hpp"

namespace io = geodrift::io;
namespace geo = geodrift::geo;
using geodrift::test::require_io_error;
using geodrift::test::require_parse_error;
using geodrift::test::TempDir;
using geodrift::test::write_text;

namespace {

const std::string kKittiLine = "1 0 0 0 0 1 0 0 0 0 1 0\n";
const std::string kTumLine = "0.0 1 2 3 0 0 0 1\n";

// Writes `content` to dir/name and returns the path.
std::string file(const TempDir& dir, const std::string& name, const std::string& content) {
  const std::string p = dir.file(name);
  write_text(p, content);
  return p;
}

}  // namespace

TEST_CASE("Missing files are I/O errors naming the path", "[io][errors]") {
  TempDir dir;
  const std::string missing = dir.file("does_not_exist.txt");
  require_io_error([&] { io::read_trajectory(missing); }, missing);
  require_io_error([&] { io::read_anchors_csv(missing); }, missing);
  require_io_error([&] { io::read_trajectory_csv(missing); }, missing);
  require_io_error([&] { io::read_ply(missing); }, missing);
  require_io_error([&] { io::read_colmap_text(dir.file("no_model")); },
                   dir.file("no_model") + "/cameras.txt");
  // A model with cameras.txt but no images.txt names images.txt.
  write_text(dir.file("cameras.txt"), "1 PINHOLE 640 480 500 500 320 240\n");
  require_io_error([&] { io::read_colmap_text(dir.path().string()); }, dir.file("images.txt"));
  // A directory given as a file.
  require_io_error([&] { io::read_trajectory(dir.path().string()); }, dir.path().string());
}

TEST_CASE("Trajectory readers report the path, line and problem", "[io][errors][trajectory]") {
  TempDir dir;
  // Short line (11 fields) after two good ones and a comment.
  std::string p =
      file(dir, "short.txt", kKittiLine + "# c\n" + kKittiLine + "1 0 0 0 0 1 0 0 0 0 1\n");
  require_parse_error([&] { io::read_trajectory(p); }, p, 4, "11 fields");
  // NaN / inf.
  p = file(dir, "nan.txt", kKittiLine + "1 0 0 nan 0 1 0 0 0 0 1 0\n");
  require_parse_error([&] { io::read_trajectory(p); }, p, 2, "tx 'nan' is not finite");
  p = file(dir, "inf.txt", kTumLine + "0.1 1 2 inf 0 0 0 1\n");
  require_parse_error([&] { io::read_trajectory(p); }, p, 2, "tz 'inf' is not finite");
  // Unparsable number.
  p = file(dir, "bad.txt", "1 0 0 0 0 1 0 0 0 0 1 1.2.3\n");
  require_parse_error([&] { io::read_trajectory(p); }, p, 1, "tz '1.2.3' is not a number");
  p = file(dir, "word.txt", "0.0 x 2 3 0 0 0 1\n");
  require_parse_error([&] { io::read_trajectory(p); }, p, 1, "tx 'x' is not a number");
  // Undetectable format / forced format mismatch.
  p = file(dir, "five.txt", "1 2 3 4 5\n");
  require_parse_error([&] { io::read_trajectory(p); }, p, 1, "cannot detect");
  p = file(dir, "tum_as_kitti.txt", kTumLine);
  require_parse_error([&] { io::read_trajectory(p, io::TrajectoryFormat::kKitti); }, p, 1,
                      "KITTI line has 8 fields");
  p = file(dir, "kitti_as_tum.txt", kKittiLine);
  require_parse_error([&] { io::read_trajectory(p, io::TrajectoryFormat::kTum); }, p, 1,
                      "TUM line has 12 fields");
  // Mixed line lengths.
  p = file(dir, "mixed.txt", kKittiLine + "7 " + kKittiLine);
  require_parse_error([&] { io::read_trajectory(p); }, p, 2, "13 fields, expected 12");
  // Not a rotation; quaternion far from unit norm.
  p = file(dir, "scaled.txt", "2 0 0 0 0 2 0 0 0 0 2 0\n");
  require_parse_error([&] { io::read_trajectory(p); }, p, 1, "not a rotation");
  p = file(dir, "reflect.txt", "-1 0 0 0 0 1 0 0 0 0 1 0\n");
  require_parse_error([&] { io::read_trajectory(p); }, p, 1, "det = -1");
  p = file(dir, "quat.txt", "0.0 1 2 3 0 0 0 1.1\n");
  require_parse_error([&] { io::read_trajectory(p); }, p, 1, "norm 1.1");
  // Order.
  p = file(dir, "time.txt", "1.0 1 2 3 0 0 0 1\n1.0 1 2 3 0 0 0 1\n");
  require_parse_error([&] { io::read_trajectory(p); }, p, 2, "timestamp 1 does not increase");
  p = file(dir, "index.txt", "5 " + kKittiLine + "3 " + kKittiLine);
  require_parse_error([&] { io::read_trajectory(p); }, p, 2, "frame index 3 does not increase");
  p = file(dir, "negindex.txt", "-5 " + kKittiLine);
  require_parse_error([&] { io::read_trajectory(p); }, p, 1, "frame index -5 outside");
  // Empty.
  p = file(dir, "empty.txt", "# nothing\n\n");
  require_parse_error([&] { io::read_trajectory(p); }, p, 2, "no poses");
}

TEST_CASE("Anchors CSV reader reports the path, line and problem", "[io][errors][anchors]") {
  TempDir dir;
  const geo::LocalFrame frame = geo::kitti_local_frame();
  const std::string head = "frame,latitude,longitude,height\n";
  // Short row.
  std::string p = file(dir, "short.csv", head + "1,49.0,8.4,100\n2,49.0,8.4\n");
  require_parse_error([&] { io::read_anchors_csv(p); }, p, 3, "row has 3 fields, the header has 4");
  // NaN / inf.
  p = file(dir, "nan.csv", head + "1,nan,8.4,100\n");
  require_parse_error([&] { io::read_anchors_csv(p); }, p, 2, "latitude 'nan' is not finite");
  p = file(dir, "inf.csv", "# c\n" + head + "1,49,8.4,-inf\n");
  require_parse_error([&] { io::read_anchors_csv(p); }, p, 3, "height '-inf' is not finite");
  // Unparsable number.
  p = file(dir, "word.csv", head + "1,49.0,eight,100\n");
  require_parse_error([&] { io::read_anchors_csv(p); }, p, 2, "longitude 'eight' is not a number");
  p = file(dir, "frame.csv", head + "1.5,49.0,8.4,100\n");
  require_parse_error([&] { io::read_anchors_csv(p); }, p, 2, "frame '1.5' is not an integer");
  // Unknown column; height_msl; duplicated column.
  p = file(dir, "unknown.csv", "frame,latitude,longitude,height,speed\n");
  require_parse_error([&] { io::read_anchors_csv(p); }, p, 1, "unknown column 'speed'");
  p = file(dir, "msl.csv", "frame,latitude,longitude,height_msl\n");
  require_parse_error([&] { io::read_anchors_csv(p); }, p, 1, "height_msl");
  p = file(dir, "dup.csv", "frame,latitude,longitude,height,frame\n");
  require_parse_error([&] { io::read_anchors_csv(p); }, p, 1, "column 'frame' appears twice");
  // Mixed / incomplete position columns, no time column, no position.
  p = file(dir, "mixed.csv", "frame,latitude,longitude,height,x\n");
  require_parse_error([&] { io::read_anchors_csv(p); }, p, 1, "mixed position columns");
  p = file(dir, "mixed2.csv", "\nframe,easting,northing,zone,height,latitude\n");
  require_parse_error([&] { io::read_anchors_csv(p); }, p, 2, "mixed position columns");
  p = file(dir, "incomplete.csv", "frame,latitude,height\n");
  require_parse_error([&] { io::read_anchors_csv(p); }, p, 1, "missing column 'longitude'");
  p = file(dir, "xyzheight.csv", "frame,x,y,z,height\n");
  require_parse_error([&] { io::read_anchors_csv(p); }, p, 1, "'height' does not go with x,y,z");
  p = file(dir, "notime.csv", "latitude,longitude,height\n");
  require_parse_error([&] { io::read_anchors_csv(p); }, p, 1, "no 'frame' or 'timestamp'");
  p = file(dir, "nopos.csv", "frame,sigma_m\n");
  require_parse_error([&] { io::read_anchors_csv(p); }, p, 1, "no position columns");
  // Bad zone strings.
  const std::string uhead = "frame,easting,northing,zone,height\n";
  p = file(dir, "zone_band.csv", uhead + "1,500000,5400000,32U,100\n");
  require_parse_error([&] { io::read_anchors_csv(p); }, p, 2, "zone '32U'");
  p = file(dir, "zone_range.csv", uhead + "1,500000,5400000,32N,100\n2,500000,5400000,61N,100\n");
  require_parse_error([&] { io::read_anchors_csv(p); }, p, 3, "zone number 61 outside [1, 60]");
  // Out-of-range values and sigma.
  p = file(dir, "lat.csv", head + "1,91.5,8.4,100\n");
  require_parse_error([&] { io::read_anchors_csv(p); }, p, 2, "latitude 91.5 deg outside");
  p = file(dir, "lon.csv", head + "1,49,-180.5,100\n");
  require_parse_error([&] { io::read_anchors_csv(p); }, p, 2, "longitude -180.5 deg outside");
  p = file(dir, "sigma.csv", "frame,x,y,z,sigma_m\n1,0,0,0,0\n");
  require_parse_error([&] { io::read_anchors_csv(p); }, p, 2, "sigma_m 0 must be > 0");
  p = file(dir, "neither.csv", "frame,timestamp,x,y,z\n,,0,0,0\n");
  require_parse_error([&] { io::read_anchors_csv(p); }, p, 2, "neither a frame nor a timestamp");
  // Valid file, but a position W's zone cannot hold (90° of longitude away): named by line.
  p = file(dir, "far.csv", head + "1,49,8.4,100\n2,49,98.4,100\n");
  const io::AnchorTable far = io::read_anchors_csv(p);
  require_parse_error([&] { io::anchors_in_world(far, frame); }, p, 3, "outside the range");
  // No rows / no header.
  p = file(dir, "norows.csv", head);
  require_parse_error([&] { io::read_anchors_csv(p); }, p, 1, "no anchor rows");
  p = file(dir, "nothing.csv", "# only a comment\n");
  require_parse_error([&] { io::read_anchors_csv(p); }, p, 1, "no header row");
}

TEST_CASE("COLMAP reader reports the path, line and problem", "[io][errors][colmap]") {
  TempDir dir;
  const std::string d = dir.path().string();
  const std::string cams = dir.file("cameras.txt"), imgs = dir.file("images.txt"),
                    pts = dir.file("points3D.txt");
  const auto model = [&](const std::string& c, const std::string& i, const std::string& p) {
    write_text(cams, c);
    write_text(imgs, i);
    write_text(pts, p);
  };
  const std::string good_cam = "# c\n1 PINHOLE 640 480 500 500 320 240\n";
  const std::string good_img = "1 1 0 0 0 0 0 0 1 000001.png\n10 20 7\n";
  const std::string good_pt = "7 1 2 3 0 0 0 0.1 1 0\n";
  model(good_cam, good_img, good_pt);
  REQUIRE_NOTHROW(io::read_colmap_text(d));

  model("1 RADIAL 640 480 500 320 240 0.1 0\n", good_img, good_pt);
  require_parse_error([&] { io::read_colmap_text(d); }, cams, 1, "non-zero distortion");
  model("1 FISHEYE 640 480 500 320 240 0.1\n", good_img, good_pt);
  require_parse_error([&] { io::read_colmap_text(d); }, cams, 1, "camera model 'FISHEYE'");
  model(good_cam + "2 PINHOLE 640 480 500 500 320\n", good_img, good_pt);
  require_parse_error([&] { io::read_colmap_text(d); }, cams, 3, "3 parameters, expected 4");
  model("1 PINHOLE 640 480 -500 500 320 240\n", good_img, good_pt);
  require_parse_error([&] { io::read_colmap_text(d); }, cams, 1, "fx -500");
  model(good_cam, "1 1 0 0 0 0 0 0 1\n\n", good_pt);
  require_parse_error([&] { io::read_colmap_text(d); }, imgs, 1, "9 fields");
  model(good_cam, "1 1 0 0 0 nan 0 0 1 a.png\n\n", good_pt);
  require_parse_error([&] { io::read_colmap_text(d); }, imgs, 1, "TX 'nan' is not finite");
  model(good_cam, "1 2 0 0 0 0 0 0 1 a.png\n\n", good_pt);
  require_parse_error([&] { io::read_colmap_text(d); }, imgs, 1, "norm 2");
  model(good_cam, "1 1 0 0 0 0 0 0 3 a.png\n\n", good_pt);
  require_parse_error([&] { io::read_colmap_text(d); }, imgs, 1, "unknown CAMERA_ID 3");
  model(good_cam, "1 1 0 0 0 0 0 0 1 a.png\n10 20\n", good_pt);
  require_parse_error([&] { io::read_colmap_text(d); }, imgs, 2, "not a multiple of 3");
  model(good_cam, "1 1 0 0 0 0 0 0 1 a.png\n", good_pt);
  require_parse_error([&] { io::read_colmap_text(d); }, imgs, 1, "no POINTS2D line");
  model(good_cam, "1 1 0 0 0 0 0 0 1 000001.png\n10 20 8\n", good_pt);
  require_parse_error([&] { io::read_colmap_text(d); }, pts, 1, "does not point back");
  model(good_cam, good_img, "7 1 2 inf 0 0 0 0.1 1 0\n");
  require_parse_error([&] { io::read_colmap_text(d); }, pts, 1, "Z 'inf' is not finite");
  model(good_cam, good_img, "7 1 2 3 0 0 0 0.1 1\n");
  require_parse_error([&] { io::read_colmap_text(d); }, pts, 1, "9 fields");
  model(good_cam, good_img, "7 1 2 3 0 0 0 0.1 5 0\n");
  require_parse_error([&] { io::read_colmap_text(d); }, pts, 1, "unknown IMAGE_ID 5");
  model(good_cam, "1 1 0 0 0 0 0 0 1 000001.png\n10 20 7 11 21 9\n", good_pt);
  require_parse_error([&] { io::read_colmap_text(d); }, imgs, 2, "unknown POINT3D_ID 9");
  model(good_cam, good_img + "2 1 0 0 0 0 0 0 1 x/000001.png\n\n", good_pt);
  require_parse_error([&] { io::read_colmap_text(d); }, imgs, 3, "frame index 1, already used");
}

TEST_CASE("PLY and trajectory.csv readers report the path, line and problem",
          "[io][errors][ply][csv]") {
  TempDir dir;
  const std::string head =
      "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\nproperty double y\n"
      "property double z\nend_header\n";
  std::string p = file(dir, "short.ply", head + "1 2 3\n4 5\n");
  require_parse_error([&] { io::read_ply(p); }, p, 9, "2 fields, expected 3");
  p = file(dir, "nan.ply", head + "1 2 3\n4 nan 6\n");
  require_parse_error([&] { io::read_ply(p); }, p, 9, "y 'nan' is not finite");
  p = file(dir, "few.ply", head + "1 2 3\n");
  require_parse_error([&] { io::read_ply(p); }, p, 8, "1 of 2 vertices");
  p = file(dir, "binary.ply", "ply\nformat binary_little_endian 1.0\n");
  require_parse_error([&] { io::read_ply(p); }, p, 2, "ascii");
  p = file(dir, "face.ply", "ply\nformat ascii 1.0\nelement face 2\n");
  require_parse_error([&] { io::read_ply(p); }, p, 3, "unsupported element");
  p = file(dir, "notply.ply", "hello\n");
  require_parse_error([&] { io::read_ply(p); }, p, 1, "not a PLY file");

  std::string cols;
  for (const std::string& c : io::trajectory_csv_columns()) cols += (cols.empty() ? "" : ",") + c;
  p = file(dir, "bad_header.csv", "# x\nframe,x,y\n");
  require_parse_error([&] { io::read_trajectory_csv(p); }, p, 2, "header is not trajectory.csv's");
  p = file(dir, "short.csv", cols + "\n0,0.1,keyframe,1,2,3\n");
  require_parse_error([&] { io::read_trajectory_csv(p); }, p, 2, "6 fields, expected 17");
  p = file(dir, "kind.csv", cols + "\n0,0.1,frame,1,2,3,500001,5400002,32N,49,8.4,100,10,0,,,\n");
  require_parse_error([&] { io::read_trajectory_csv(p); }, p, 2, "kind 'frame'");
  p = file(dir, "zone.csv",
           cols + "\n0,0.1,keyframe,1,2,3,500001,5400002,32X,49,8.4,100,10,0,,,\n");
  require_parse_error([&] { io::read_trajectory_csv(p); }, p, 2, "zone '32X'");
  p = file(dir, "nan.csv",
           cols + "\n0,0.1,keyframe,1,nan,3,500001,5400002,32N,49,8.4,100,10,0,,,\n");
  require_parse_error([&] { io::read_trajectory_csv(p); }, p, 2, "y 'nan' is not finite");
  p = file(dir, "sd.csv",
           cols + "\n0,0.1,keyframe,1,2,3,500001,5400002,32N,49,8.4,100,10,0,-1,2,0\n");
  require_parse_error([&] { io::read_trajectory_csv(p); }, p, 2, "sd_east/sd_north is negative");
  p = file(dir, "sdnan.csv",
           cols + "\n0,0.1,keyframe,1,2,3,500001,5400002,32N,49,8.4,100,10,0,1,x,0\n");
  require_parse_error([&] { io::read_trajectory_csv(p); }, p, 2, "sd_north");
  // A file written before the uncertainty columns existed (14 columns) is still read; a row
  // of the new width under the old header is not.
  std::string old_cols;
  for (std::size_t i = 0; i < io::kTrajectoryCsvColumnsWithoutUncertainty; ++i)
    old_cols += (i ? "," : "") + io::trajectory_csv_columns()[i];
  p = file(dir, "old.csv",
           old_cols + "\n0,0.1,keyframe,1,2,3,500001,5400002,32N,49,8.4,100,10,0\n");
  const auto old = io::read_trajectory_csv(p);
  REQUIRE(old.size() == 1);
  CHECK(std::isnan(old[0].sd_east));
  p = file(dir, "oldwide.csv",
           old_cols + "\n0,0.1,keyframe,1,2,3,500001,5400002,32N,49,8.4,100,10,0,1,1,0\n");
  require_parse_error([&] { io::read_trajectory_csv(p); }, p, 2, "17 fields, expected 14");
}
