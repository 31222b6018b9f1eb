#include "geodrift/geotag/views.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <optional>
#include <sstream>

#include "geodrift/error.hpp"
#include "geodrift/geotag/exif.hpp"
#include "geodrift/geotag/panorama.hpp"
#include "geodrift/io/detail/text_io.hpp"

namespace geodrift::geotag {

namespace {

/// Width exactly twice the height (an equirectangular panorama), without int overflow.
bool is_two_to_one(int w, int h) { return static_cast<long long>(w) == 2LL * h; }

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;

using io::detail::parse_double;
using io::detail::parse_error;
using io::detail::parse_int;
using io::detail::split_csv;
using io::detail::trim;

std::uint32_t be32(const unsigned char* p) {
  return (std::uint32_t(p[0]) << 24) | (std::uint32_t(p[1]) << 16) | (std::uint32_t(p[2]) << 8) |
         std::uint32_t(p[3]);
}

/// Image size from the PNG or JPEG header without decoding; falls back to decoding.
bool image_size(const std::string& path, int* w, int* h) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  unsigned char hdr[24] = {};
  in.read(reinterpret_cast<char*>(hdr), sizeof hdr);
  if (in.gcount() == 24 && hdr[0] == 0x89 && hdr[1] == 'P' && hdr[2] == 'N' && hdr[3] == 'G') {
    *w = static_cast<int>(be32(hdr + 16));
    *h = static_cast<int>(be32(hdr + 20));
    return *w > 0 && *h > 0;
  }
  if (in.gcount() >= 2 && hdr[0] == 0xFF && hdr[1] == 0xD8) {
    in.clear();
    in.seekg(2);
    for (int guard = 0; guard < 10000 && in; ++guard) {
      unsigned char m[4];
      in.read(reinterpret_cast<char*>(m), 4);
      if (in.gcount() != 4 || m[0] != 0xFF) break;
      const int len = (m[2] << 8) | m[3];
      const unsigned char marker = m[1];
      const bool sof =
          marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
      if (sof) {
        unsigned char s[5];
        in.read(reinterpret_cast<char*>(s), 5);
        if (in.gcount() != 5) break;
        *h = (s[1] << 8) | s[2];
        *w = (s[3] << 8) | s[4];
        return *w > 0 && *h > 0;
      }
      in.seekg(len - 2, std::ios::cur);
    }
  }
  const cv::Mat img = cv::imread(path, cv::IMREAD_UNCHANGED);
  if (img.empty()) return false;
  *w = img.cols;
  *h = img.rows;
  return true;
}

/// Size of the image as OpenCV decodes it: a JPEG whose EXIF orientation is not 1 may be
/// turned upright (5..8 swap width and height), depending on where its Exif block sits (OpenCV
/// reads the first APP1 segment only), so such photos are decoded once to know.
bool decoded_size(const std::string& path, int* w, int* h) {
  const cv::Mat img = cv::imread(path, cv::IMREAD_GRAYSCALE);
  if (img.empty()) return false;
  *w = img.cols;
  *h = img.rows;
  return true;
}

}  // namespace

std::vector<GeoSource> read_geotag_csv(const std::string& csv_path,
                                       const GeoSourceOptions& options) {
  namespace fs = std::filesystem;
  // LineReader: names the path in open errors, drops a CR and a UTF-8 byte-order mark
  // (spreadsheet exports), refuses a binary file's endless line.
  io::detail::LineReader in(csv_path);
  const fs::path folder = fs::absolute(fs::path(csv_path)).parent_path();
  std::string line;
  int lineno = 0;
  std::vector<std::string> header;
  while (in.next(&line)) {
    lineno = in.line();
    const std::string t = trim(line);
    if (t.empty() || t[0] == '#') continue;
    header = split_csv(t);
    break;
  }
  if (header.empty()) throw Error("geo-tag CSV '" + csv_path + "' is empty (no header row)");
  std::map<std::string, int> col;
  for (std::size_t i = 0; i < header.size(); ++i) col[header[i]] = static_cast<int>(i);
  const auto find = [&](std::initializer_list<const char*> names, bool required) {
    for (const char* n : names)
      if (col.count(n)) return col[n];
    if (required) {
      std::string list;
      for (const char* n : names) list += (list.empty() ? "" : " or ") + std::string(n);
      parse_error(csv_path, lineno, "header has no column " + list);
    }
    return -1;
  };
  const int c_file = find({"file", "image"}, true);
  const int c_lat = find({"latitude", "latitude_deg"}, true);
  const int c_lon = find({"longitude", "longitude_deg"}, true);
  const int c_h = find({"height", "altitude_m"}, true);
  const int c_head = find({"heading_deg", "true_heading_deg"}, true);
  const int c_id = find({"id"}, false), c_kind = find({"kind"}, false);
  const int c_frame = find({"frame"}, false);
  const int c_fx = find({"fx"}, false), c_fy = find({"fy"}, false), c_cx = find({"cx"}, false),
            c_cy = find({"cy"}, false);
  const int n_intr = (c_fx >= 0) + (c_fy >= 0) + (c_cx >= 0) + (c_cy >= 0);
  if (n_intr != 0 && n_intr != 4)
    parse_error(csv_path, lineno, "photo intrinsics need all four columns fx, fy, cx, cy");

  std::vector<GeoSource> out;
  while (in.next(&line)) {
    lineno = in.line();
    const std::string t = trim(line);
    if (t.empty() || t[0] == '#') continue;
    const std::vector<std::string> f = split_csv(t);
    if (f.size() < header.size())
      parse_error(
          csv_path, lineno,
          std::to_string(f.size()) + " fields, header has " + std::to_string(header.size()));
    GeoSource s;
    s.tag.id = c_id >= 0 ? static_cast<int>(parse_int(f[c_id], csv_path, lineno, "id"))
                         : static_cast<int>(out.size());
    if (f[c_file].empty()) parse_error(csv_path, lineno, "empty file name");
    fs::path p(f[c_file]);
    if (p.is_relative()) {
      fs::path a = folder / p;
      for (const char* sub : {"panoramas", "images"})
        if (!fs::exists(a) && fs::exists(folder / sub / p)) a = folder / sub / p;
      p = a;
    }
    s.path = p.lexically_normal().string();
    // An empty latitude/longitude/height/heading_deg cell is taken from the image's EXIF.
    std::optional<ExifGeotag> exif;
    const auto exif_of = [&]() -> const ExifGeotag& {
      if (!exif) {
        if (!fs::is_regular_file(p))
          parse_error(csv_path, lineno, "image '" + s.path + "' does not exist");
        try {
          exif = read_exif(s.path);
        } catch (const Error& e) {
          parse_error(csv_path, lineno, e.what());
        }
      }
      return *exif;
    };
    const auto value = [&](int c, double ExifGeotag::*field, const char* name,
                           const char* exif_name) {
      if (!f[c].empty()) return parse_double(f[c], csv_path, lineno, name);
      const double v = exif_of().*field;
      if (!std::isfinite(v))
        parse_error(csv_path, lineno,
                    std::string(name) + " is empty and image '" + s.path + "' has no EXIF GPS " +
                        exif_name);
      return v;
    };
    s.tag.latitude_deg = value(c_lat, &ExifGeotag::latitude_deg, "latitude", "latitude");
    s.tag.longitude_deg = value(c_lon, &ExifGeotag::longitude_deg, "longitude", "longitude");
    s.tag.height = value(c_h, &ExifGeotag::altitude_m, "height", "altitude");
    const double heading_deg = f[c_head].empty()
                                   ? exif_of().true_heading_deg
                                   : parse_double(f[c_head], csv_path, lineno, "heading_deg");
    if (std::abs(s.tag.latitude_deg) > 90)
      parse_error(csv_path, lineno, "latitude " + f[c_lat] + " outside [-90, 90]");
    if (std::abs(s.tag.longitude_deg) > 180)
      parse_error(csv_path, lineno, "longitude " + f[c_lon] + " outside [-180, 180]");
    // NaN (unknown) only for a photo without a heading cell or EXIF true heading; checked below.
    s.tag.heading = std::isfinite(heading_deg)
                        ? std::fmod(std::fmod(heading_deg, 360.0) + 360.0, 360.0) * kDeg
                        : std::numeric_limits<double>::quiet_NaN();
    if (c_frame >= 0 && !f[c_frame].empty())
      s.frame = static_cast<int>(parse_int(f[c_frame], csv_path, lineno, "frame"));
    int w = 0, h = 0;
    if (!fs::is_regular_file(p))
      parse_error(csv_path, lineno, "image '" + s.path + "' does not exist");
    if (!image_size(s.path, &w, &h))
      parse_error(csv_path, lineno, "image '" + s.path + "' cannot be read");
    if (c_kind >= 0 && !f[c_kind].empty()) {
      if (f[c_kind] == "panorama")
        s.kind = SourceKind::kPanorama;
      else if (f[c_kind] == "photo")
        s.kind = SourceKind::kPhoto;
      else
        parse_error(csv_path, lineno, "kind '" + f[c_kind] + "' is neither panorama nor photo");
    } else {
      s.kind = is_two_to_one(w, h) ? SourceKind::kPanorama : SourceKind::kPhoto;
    }
    if (s.kind == SourceKind::kPanorama && !is_two_to_one(w, h))
      parse_error(csv_path, lineno,
                  "panorama '" + s.path + "' is " + std::to_string(w) + "x" + std::to_string(h) +
                      ", not 2:1 equirectangular");
    if (s.kind == SourceKind::kPanorama && !std::isfinite(s.tag.heading))
      parse_error(
          csv_path, lineno,
          "panorama '" + s.path +
              "' needs a heading: heading_deg is empty and the image has no EXIF true "
              "GPSImgDirection" +
              (std::isfinite(exif_of().magnetic_heading_deg) ? " (only a magnetic one)" : ""));
    if (s.kind == SourceKind::kPhoto && exif_of().orientation > 1 && !decoded_size(s.path, &w, &h))
      parse_error(csv_path, lineno, "image '" + s.path + "' cannot be read");
    if (s.kind == SourceKind::kPhoto) {
      map::Camera& c = s.photo_camera;
      c.id = -1;
      c.width = w;
      c.height = h;
      if (n_intr == 4) {
        c.fx = parse_double(f[c_fx], csv_path, lineno, "fx");
        c.fy = parse_double(f[c_fy], csv_path, lineno, "fy");
        c.cx = parse_double(f[c_cx], csv_path, lineno, "cx");
        c.cy = parse_double(f[c_cy], csv_path, lineno, "cy");
      } else if (std::isfinite(options.photo_hfov_deg)) {
        if (!(options.photo_hfov_deg > 1 && options.photo_hfov_deg < 179))
          throw InvalidArgument("photo horizontal field of view " +
                                std::to_string(options.photo_hfov_deg) + " deg outside (1, 179)");
        c.fx = c.fy = 0.5 * w / std::tan(0.5 * options.photo_hfov_deg * kDeg);
        c.cx = 0.5 * w - 0.5;
        c.cy = 0.5 * h - 0.5;
      } else if (std::isfinite(exif_of().focal_length_35mm)) {
        c.fx = c.fy = focal_px_from_35mm(exif_of().focal_length_35mm, w, h);
        c.cx = 0.5 * w - 0.5;
        c.cy = 0.5 * h - 0.5;
      } else {
        parse_error(
            csv_path, lineno,
            "photo '" + s.path +
                "' has no intrinsics (give columns fx, fy, cx, cy or a field of view; its EXIF "
                "has no FocalLengthIn35mmFilm)");
      }
      try {
        c.validate();
      } catch (const InvalidArgument& e) {
        parse_error(csv_path, lineno, e.what());
      }
    }
    out.push_back(std::move(s));
  }
  if (out.empty()) throw Error("geo-tag CSV '" + csv_path + "' has a header but no rows");
  return out;
}

std::vector<GeoSource> read_geotag_jpeg_folder(const std::string& dir,
                                               const GeoSourceOptions& options,
                                               std::vector<std::string>* skipped) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw Error("geo-tag folder '" + dir + "' is not a directory");
  const bool hfov = std::isfinite(options.photo_hfov_deg);
  if (hfov && !(options.photo_hfov_deg > 1 && options.photo_hfov_deg < 179))
    throw InvalidArgument("photo horizontal field of view " +
                          std::to_string(options.photo_hfov_deg) + " deg outside (1, 179)");
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    std::string ext = e.path().extension().string();
    for (char& ch : ext) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    if ((ext == ".jpg" || ext == ".jpeg") && e.is_regular_file(ec)) files.push_back(e.path());
  }
  if (ec) throw Error("cannot list geo-tag folder '" + dir + "': " + ec.message());
  if (files.empty())
    throw Error("geo-tag folder '" + dir + "' has neither geotags.csv nor JPEG files");
  std::sort(files.begin(), files.end());
  std::vector<GeoSource> out;
  std::vector<std::string> why;
  for (const fs::path& file : files) {
    const std::string path = fs::absolute(file).lexically_normal().string();
    const auto skip = [&](const std::string& reason) { why.push_back(path + ": " + reason); };
    ExifGeotag x;
    int w = 0, h = 0;
    try {
      x = read_exif(path);
    } catch (const Error& e) {
      skip(e.what());
      continue;
    }
    if (!image_size(path, &w, &h)) {
      skip("cannot be read as an image");
      continue;
    }
    if (!x.has_gps_position()) {
      skip(x.has_exif ? "no EXIF GPS position (GPSLatitude/GPSLongitude with their refs)"
                      : "no EXIF block");
      continue;
    }
    if (!std::isfinite(x.altitude_m)) {
      skip("no EXIF GPS altitude");
      continue;
    }
    GeoSource s;
    s.tag.id = static_cast<int>(out.size());
    s.tag.latitude_deg = x.latitude_deg;
    s.tag.longitude_deg = x.longitude_deg;
    s.tag.height = x.altitude_m;
    if (std::isfinite(x.true_heading_deg)) s.tag.heading = x.true_heading_deg * kDeg;
    s.path = path;
    s.kind = is_two_to_one(w, h) ? SourceKind::kPanorama : SourceKind::kPhoto;
    if (s.kind == SourceKind::kPanorama) {
      if (!std::isfinite(s.tag.heading)) {
        skip(std::string("2:1 panorama without an EXIF true GPSImgDirection") +
             (std::isfinite(x.magnetic_heading_deg) ? " (only a magnetic one)" : ""));
        continue;
      }
    } else {
      if (x.orientation > 1 && !decoded_size(path, &w, &h)) {
        skip("cannot be read as an image");
        continue;
      }
      map::Camera& c = s.photo_camera;
      c.id = -1;
      c.width = w;
      c.height = h;
      if (hfov) {
        c.fx = c.fy = 0.5 * w / std::tan(0.5 * options.photo_hfov_deg * kDeg);
      } else if (std::isfinite(x.focal_length_35mm)) {
        c.fx = c.fy = focal_px_from_35mm(x.focal_length_35mm, w, h);
      } else {
        skip("no focal length (no EXIF FocalLengthIn35mmFilm; give a photo field of view)");
        continue;
      }
      c.cx = 0.5 * w - 0.5;
      c.cy = 0.5 * h - 0.5;
      try {
        c.validate();
      } catch (const InvalidArgument& e) {
        skip(e.what());
        continue;
      }
    }
    out.push_back(std::move(s));
  }
  if (out.empty()) {
    std::string list;
    for (const std::string& r : why) list += "\n  " + r;
    throw InvalidArgument("geo-tag folder '" + dir + "': none of its " +
                          std::to_string(files.size()) + " JPEG files is usable:" + list);
  }
  if (skipped) *skipped = std::move(why);
  return out;
}

std::vector<GeoSource> read_geotag_sources(const std::string& path, const GeoSourceOptions& options,
                                           std::vector<std::string>* skipped) {
  namespace fs = std::filesystem;
  if (skipped) skipped->clear();
  std::error_code ec;
  if (!fs::exists(path, ec)) throw Error("geo-tags '" + path + "' do not exist");
  if (!fs::is_directory(path, ec)) return read_geotag_csv(path, options);
  const fs::path csv = fs::path(path) / "geotags.csv";
  if (fs::exists(csv, ec)) return read_geotag_csv(csv.string(), options);
  return read_geotag_jpeg_folder(path, options, skipped);
}

std::vector<GeoView> make_views(const std::vector<GeoSource>& sources, const map::Camera& video) {
  std::vector<GeoView> views;
  const bool any_pano = [&] {
    for (const GeoSource& s : sources)
      if (s.kind == SourceKind::kPanorama) return true;
    return false;
  }();
  if (any_pano) video.validate();
  for (std::size_t i = 0; i < sources.size(); ++i) {
    const GeoSource& s = sources[i];
    if (s.kind == SourceKind::kPanorama) {
      for (int k = 0; k < kViewsPerPanorama; ++k) {
        GeoView v;
        v.id = static_cast<int>(views.size());
        v.source = static_cast<int>(i);
        v.tag = s.tag;
        v.heading = std::fmod(s.tag.heading + k * kViewStepDeg * kDeg, 2.0 * kPi);
        v.direction = k;
        v.camera = video;
        v.frame = s.frame;
        views.push_back(v);
      }
    } else {
      GeoView v;
      v.id = static_cast<int>(views.size());
      v.source = static_cast<int>(i);
      v.tag = s.tag;
      v.heading = s.tag.heading;
      v.direction = -1;
      v.camera = s.photo_camera;
      v.frame = s.frame;
      views.push_back(v);
    }
  }
  return views;
}

Eigen::Vector3d view_position_world(const GeoView& view, const geo::LocalFrame& frame) {
  return frame.to_world(view.tag.latitude_deg, view.tag.longitude_deg, view.tag.height);
}

lie::SE3d view_pose_world(const GeoView& view, const geo::LocalFrame& frame) {
  const Eigen::Vector3d c = view_position_world(view, frame);
  const Eigen::Matrix3d R_wc = frame.level_camera_rotation_from_heading(view.heading, c);
  const Eigen::Matrix3d R_cw = R_wc.transpose();
  return lie::SE3d(lie::SO3d(R_cw), -R_cw * c);
}

}  // namespace geodrift::geotag
