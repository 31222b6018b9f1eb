#pragma once

/// @file
/// points.ply: map points as an ASCII PLY point cloud (Greg Turk's format, as MeshLab,
/// CloudCompare and Open3D read it):
///
///     ply
///     format ascii 1.0
///     comment geodrift <version> ...          version, frame and units
///     element vertex N
///     property double x | y | z                metres
///     property uchar red | green | blue        optional colour
///     end_header
///     x y z [r g b]                            one vertex per line
///
/// read_ply() reads ASCII PLY vertex elements with float/double x, y, z (and optional uchar
/// red/green/blue); other elements/properties are rejected with a line-numbered message.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "geodrift/error.hpp"
#include "geodrift/io/detail/text_io.hpp"
#include "geodrift/version.hpp"

namespace geodrift::io {

/// A point cloud: positions and optional colours (empty or one per point).
struct PointCloud {
  std::vector<Eigen::Vector3d> points;
  std::vector<std::array<std::uint8_t, 3>> colors;
  std::vector<std::string> comments;  ///< header comments (read only)
};

/// Writes an ASCII PLY atomically, stating the version, `frame_note` and `units` ("metres" in W,
/// kMapUnits in a monocular map frame M) in comments.
/// @throws InvalidArgument if a point is not finite or the colours do not match the points;
///         Error on I/O failure.
inline void write_ply(const std::string& path, const PointCloud& cloud,
                      const std::string& frame_note, const std::string& units = "metres") {
  GEODRIFT_CHECK(
      cloud.colors.empty() || cloud.colors.size() == cloud.points.size(),
      "write_ply: " << cloud.colors.size() << " colours for " << cloud.points.size() << " points");
  for (std::size_t i = 0; i < cloud.points.size(); ++i)
    GEODRIFT_CHECK(cloud.points[i].allFinite(), "write_ply: point " << i << " is not finite");
  const bool rgb = !cloud.colors.empty();
  detail::write_atomically(path, [&](std::ostream& os) {
    os << "ply\nformat ascii 1.0\ncomment geodrift " << kVersion << " map points\n"
       << "comment frame: " << frame_note << "\ncomment units: " << units << "\n"
       << "element vertex " << cloud.points.size() << "\n"
       << "property double x\nproperty double y\nproperty double z\n";
    if (rgb) os << "property uchar red\nproperty uchar green\nproperty uchar blue\n";
    os << "end_header\n";
    for (std::size_t i = 0; i < cloud.points.size(); ++i) {
      const Eigen::Vector3d& p = cloud.points[i];
      os << detail::fmt(p.x()) << ' ' << detail::fmt(p.y()) << ' ' << detail::fmt(p.z());
      if (rgb)
        os << ' ' << int(cloud.colors[i][0]) << ' ' << int(cloud.colors[i][1]) << ' '
           << int(cloud.colors[i][2]);
      os << '\n';
    }
  });
}

/// Reads an ASCII PLY point cloud (see the file comment).
/// @throws Error if the file cannot be opened; InvalidArgument "<path>:<line>: <what>" for a
///         non-PLY or binary file, an unsupported element/property, a short vertex line, a
///         non-number or non-finite value, or fewer vertices than declared.
inline PointCloud read_ply(const std::string& path) {
  detail::LineReader r(path);
  PointCloud cloud;
  std::string raw;
  if (!r.next(&raw) || detail::trim(raw) != "ply")
    detail::parse_error(path, r.line(), "not a PLY file (first line is not 'ply')");
  long long n = -1;
  std::vector<std::string> props;
  bool in_vertex = false, header_done = false;
  while (r.next(&raw)) {
    const int line = r.line();
    const std::vector<std::string> t = detail::split_ws(raw);
    if (t.empty()) continue;
    if (t[0] == "format") {
      if (t.size() < 2 || t[1] != "ascii")
        detail::parse_error(path, line, "only 'format ascii 1.0' PLY is supported");
    } else if (t[0] == "comment" || t[0] == "obj_info") {
      const std::size_t p = raw.find(t[0]) + t[0].size();
      cloud.comments.push_back(detail::trim(raw.substr(p)));
    } else if (t[0] == "element") {
      if (t.size() != 3 || t[1] != "vertex")
        detail::parse_error(
            path, line,
            "unsupported element '" + detail::trim(raw) + "' (only 'element vertex N')");
      if (n >= 0) detail::parse_error(path, line, "second 'element vertex'");
      n = detail::parse_int(t[2], path, line, "vertex count", 0);
      in_vertex = true;
    } else if (t[0] == "property") {
      if (!in_vertex) detail::parse_error(path, line, "property before 'element vertex'");
      if (t.size() != 3) detail::parse_error(path, line, "unsupported property '" + raw + "'");
      const std::string& type = t[1];
      const std::string& name = t[2];
      const bool coord = name == "x" || name == "y" || name == "z";
      const bool colour = name == "red" || name == "green" || name == "blue";
      if (!(coord &&
            (type == "double" || type == "float" || type == "float64" || type == "float32")) &&
          !(colour && (type == "uchar" || type == "uint8")))
        detail::parse_error(path, line,
                            "unsupported property '" + detail::trim(raw) +
                                "' (x y z float/double, red green blue uchar)");
      props.push_back(name);
    } else if (t[0] == "end_header") {
      header_done = true;
      break;
    } else {
      detail::parse_error(path, line, "unknown PLY header line '" + detail::trim(raw) + "'");
    }
  }
  if (!header_done) detail::parse_error(path, r.line(), "no 'end_header'");
  if (n < 0) detail::parse_error(path, r.line(), "no 'element vertex'");
  int ix = -1, iy = -1, iz = -1, ir = -1, ig = -1, ib = -1;
  for (int i = 0; i < static_cast<int>(props.size()); ++i) {
    const std::string& p = props[i];
    (p == "x" ? ix : p == "y" ? iy : p == "z" ? iz : p == "red" ? ir : p == "green" ? ig : ib) = i;
  }
  if (ix < 0 || iy < 0 || iz < 0)
    detail::parse_error(path, r.line(), "vertex element lacks x, y or z");
  const bool rgb = ir >= 0 && ig >= 0 && ib >= 0;
  while (static_cast<long long>(cloud.points.size()) < n) {
    if (!r.next(&raw))
      detail::parse_error(path, r.line(),
                          "file ends after " + std::to_string(cloud.points.size()) + " of " +
                              std::to_string(n) + " vertices");
    const int line = r.line();
    const std::vector<std::string> t = detail::split_ws(raw);
    if (t.size() != props.size())
      detail::parse_error(path, line,
                          "vertex line has " + std::to_string(t.size()) + " fields, expected " +
                              std::to_string(props.size()));
    cloud.points.emplace_back(detail::parse_double(t[ix], path, line, "x"),
                              detail::parse_double(t[iy], path, line, "y"),
                              detail::parse_double(t[iz], path, line, "z"));
    if (rgb)
      cloud.colors.push_back(
          {static_cast<std::uint8_t>(detail::parse_int(t[ir], path, line, "red", 0, 255)),
           static_cast<std::uint8_t>(detail::parse_int(t[ig], path, line, "green", 0, 255)),
           static_cast<std::uint8_t>(detail::parse_int(t[ib], path, line, "blue", 0, 255))});
  }
  return cloud;
}

}  // namespace geodrift::io
