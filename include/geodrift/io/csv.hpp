#pragma once

/// @file
/// trajectory.csv (DESIGN.md "Command line and files"): every input frame of a corrected run,
/// keyframes and interpolated frames, in W and in geographic coordinates.
///
/// Columns (header row after one '#' line stating version, frame and units):
///   frame            integer frame index
///   timestamp        seconds (empty when the input had none)
///   kind             "keyframe" or "interpolated"
///   x,y,z            camera centre in W, metres (6 decimals)
///   easting,northing UTM in W's zone, metres (hemisphere of the point itself)
///   zone             W's UTM zone with the point's hemisphere, e.g. "32N"
///   latitude,longitude  WGS84 degrees (10 decimals, ~0.01 mm)
///   height           ellipsoidal height, metres
///   heading_deg      true heading of the optical axis, degrees clockwise from true north in
///                    [0, 360) (empty when the axis is vertical)
///   after_last_anchor  1 for frames after the last anchor (extrapolated), else 0
///   sd_east,sd_north,cov_en  horizontal uncertainty of the camera centre in W (x east, y north):
///                    standard deviations (metres) and the east–north covariance (m²) of the
///                    1-σ ellipse (correction/uncertainty.hpp); empty when not estimated
/// read_trajectory_csv() reads the file back (tests, `geodrift eval`).

#include <Eigen/Core>
#include <cmath>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "geodrift/error.hpp"
#include "geodrift/geo/local_frame.hpp"
#include "geodrift/io/detail/text_io.hpp"
#include "geodrift/lie/se3.hpp"
#include "geodrift/version.hpp"

namespace geodrift::io {

/// One frame to write: its pose in W and bookkeeping.
struct TrajectoryCsvRow {
  int frame = 0;
  double timestamp = std::numeric_limits<double>::quiet_NaN();  ///< seconds, NaN if unknown
  bool keyframe = true;            ///< false: interpolated between keyframes
  lie::SE3d T_cw;                  ///< W -> camera (metres)
  bool after_last_anchor = false;  ///< extrapolated beyond the last anchor
  /// Horizontal covariance of the camera centre in W (x east, y north; m²), written as
  /// sd_east, sd_north, cov_en; NaN (empty fields) when not estimated.
  Eigen::Matrix2d cov_en = Eigen::Matrix2d::Constant(std::numeric_limits<double>::quiet_NaN());
};

/// One row as read back from trajectory.csv.
struct TrajectoryCsvRecord {
  int line = 0;
  int frame = 0;
  double timestamp = std::numeric_limits<double>::quiet_NaN();
  bool keyframe = true;
  Eigen::Vector3d p_w = Eigen::Vector3d::Zero();
  double easting = 0, northing = 0;
  std::string zone;
  double latitude_deg = 0, longitude_deg = 0, height = 0;
  double heading_deg = std::numeric_limits<double>::quiet_NaN();
  bool after_last_anchor = false;
  /// NaN when the file has no uncertainty (empty fields, or a file from before geodrift wrote
  /// these columns).
  double sd_east = std::numeric_limits<double>::quiet_NaN();
  double sd_north = std::numeric_limits<double>::quiet_NaN();
  double cov_en = std::numeric_limits<double>::quiet_NaN();
};

/// The trajectory.csv column names, in order.
inline const std::vector<std::string>& trajectory_csv_columns() {
  static const std::vector<std::string> kCols = {
      "frame",       "timestamp",         "kind",    "x",        "y",         "z",
      "easting",     "northing",          "zone",    "latitude", "longitude", "height",
      "heading_deg", "after_last_anchor", "sd_east", "sd_north", "cov_en"};
  return kCols;
}
/// Columns of trajectory.csv before the uncertainty columns (still read).
constexpr std::size_t kTrajectoryCsvColumnsWithoutUncertainty = 14;

/// Writes trajectory.csv atomically (see the file comment).
/// @param path   output file.
/// @param rows   frames in output order.
/// @param frame  W's definition (UTM zone + origin), used for UTM / latitude / longitude / heading.
/// @param note   extra statement for the header line (e.g. geo::kKittiGeoOriginNote), may be "".
/// @throws InvalidArgument if a pose is not finite or lies outside W's zone; Error on I/O failure.
inline void write_trajectory_csv(const std::string& path, const std::vector<TrajectoryCsvRow>& rows,
                                 const geo::LocalFrame& frame, const std::string& note = "") {
  // Convert everything first so that a bad row throws before any file is touched.
  struct Out {
    Eigen::Vector3d c;
    geo::UtmCoordinate u;
    geo::Geodetic g;
    double heading_deg;
  };
  std::vector<Out> out;
  out.reserve(rows.size());
  for (std::size_t i = 0; i < rows.size(); ++i) {
    GEODRIFT_CHECK(rows[i].T_cw.matrix().allFinite(),
                   "write_trajectory_csv: pose of frame " << rows[i].frame << " is not finite");
    const lie::SE3d T_wc = rows[i].T_cw.inverse();
    Out o;
    o.c = T_wc.translation();
    o.u = frame.utm_of(o.c);
    o.g = frame.to_geodetic(o.c);
    const Eigen::Matrix3d R_wc = T_wc.rotation().matrix();
    const Eigen::Vector3d axis = R_wc.col(2);
    o.heading_deg = std::hypot(axis.x(), axis.y()) > 1e-9
                        ? frame.camera_heading(R_wc, o.c) / geo::detail::kDegToRad
                        : std::numeric_limits<double>::quiet_NaN();
    out.push_back(o);
  }
  detail::write_atomically(path, [&](std::ostream& os) {
    os << "# geodrift " << kVersion << " trajectory: x,y,z camera centre in " << frame.description()
       << "; latitude/longitude WGS84 degrees; heights ellipsoidal metres; heading_deg "
          "clockwise from true north"
       << (note.empty() ? "" : "; ") << note << "\n";
    const auto& cols = trajectory_csv_columns();
    for (std::size_t i = 0; i < cols.size(); ++i) os << (i ? "," : "") << cols[i];
    os << '\n';
    for (std::size_t i = 0; i < rows.size(); ++i) {
      const TrajectoryCsvRow& r = rows[i];
      const Out& o = out[i];
      os << r.frame << ',' << (std::isfinite(r.timestamp) ? detail::fmt(r.timestamp) : "") << ','
         << (r.keyframe ? "keyframe" : "interpolated") << ',' << detail::fmt_fixed(o.c.x(), 6)
         << ',' << detail::fmt_fixed(o.c.y(), 6) << ',' << detail::fmt_fixed(o.c.z(), 6) << ','
         << detail::fmt_fixed(o.u.easting, 6) << ',' << detail::fmt_fixed(o.u.northing, 6) << ','
         << geo::format_utm_zone(o.u.zone, o.u.northp) << ','
         << detail::fmt_fixed(o.g.latitude_deg, 10) << ','
         << detail::fmt_fixed(o.g.longitude_deg, 10) << ',' << detail::fmt_fixed(o.g.height, 6)
         << ',' << (std::isfinite(o.heading_deg) ? detail::fmt_fixed(o.heading_deg, 6) : "") << ','
         << (r.after_last_anchor ? 1 : 0);
      const bool has_cov = r.cov_en.allFinite() && r.cov_en(0, 0) >= 0 && r.cov_en(1, 1) >= 0;
      if (has_cov)
        os << ',' << detail::fmt_fixed(std::sqrt(r.cov_en(0, 0)), 4) << ','
           << detail::fmt_fixed(std::sqrt(r.cov_en(1, 1)), 4) << ','
           << detail::fmt(0.5 * (r.cov_en(0, 1) + r.cov_en(1, 0)), 4);
      else
        os << ",,,";
      os << '\n';
    }
  });
}

/// Reads a trajectory.csv written by write_trajectory_csv().
/// @throws Error if the file cannot be opened; InvalidArgument "<path>:<line>: <what>" for a
///         header that is not trajectory.csv's, a short row, a bad number or kind.
inline std::vector<TrajectoryCsvRecord> read_trajectory_csv(const std::string& path) {
  detail::LineReader reader(path);
  std::vector<TrajectoryCsvRecord> out;
  const auto& cols = trajectory_csv_columns();
  bool header = false;
  std::size_t ncols = cols.size();
  std::string raw;
  while (reader.next(&raw)) {
    const std::string text = detail::trim(raw);
    if (text.empty() || text[0] == '#') continue;
    const int line = reader.line();
    const std::vector<std::string> f = detail::split_csv(text);
    if (!header) {
      const std::vector<std::string> old(cols.begin(),
                                         cols.begin() + kTrajectoryCsvColumnsWithoutUncertainty);
      if (f == old) ncols = old.size();
      if (f != cols && f != old) {
        std::string expected;
        for (std::size_t i = 0; i < cols.size(); ++i) expected += (i ? "," : "") + cols[i];
        detail::parse_error(path, line, "header is not trajectory.csv's: expected " + expected);
      }
      header = true;
      continue;
    }
    if (f.size() != ncols)
      detail::parse_error(
          path, line,
          "row has " + std::to_string(f.size()) + " fields, expected " + std::to_string(ncols));
    TrajectoryCsvRecord r;
    r.line = line;
    r.frame = static_cast<int>(detail::parse_int(f[0], path, line, "frame", 0));
    if (!f[1].empty()) r.timestamp = detail::parse_double(f[1], path, line, "timestamp");
    if (f[2] != "keyframe" && f[2] != "interpolated")
      detail::parse_error(path, line, "kind '" + f[2] + "' is not keyframe or interpolated");
    r.keyframe = f[2] == "keyframe";
    r.p_w = Eigen::Vector3d(detail::parse_double(f[3], path, line, "x"),
                            detail::parse_double(f[4], path, line, "y"),
                            detail::parse_double(f[5], path, line, "z"));
    r.easting = detail::parse_double(f[6], path, line, "easting");
    r.northing = detail::parse_double(f[7], path, line, "northing");
    r.zone = f[8];
    int zone = 0;
    bool northp = true;
    try {
      geo::parse_utm_zone(r.zone, &zone, &northp);
    } catch (const InvalidArgument& e) {
      detail::parse_error(path, line, e.what());
    }
    r.latitude_deg = detail::parse_double(f[9], path, line, "latitude");
    r.longitude_deg = detail::parse_double(f[10], path, line, "longitude");
    r.height = detail::parse_double(f[11], path, line, "height");
    if (!f[12].empty()) r.heading_deg = detail::parse_double(f[12], path, line, "heading_deg");
    r.after_last_anchor = detail::parse_int(f[13], path, line, "after_last_anchor", 0, 1) == 1;
    if (ncols > kTrajectoryCsvColumnsWithoutUncertainty) {
      if (!f[14].empty()) r.sd_east = detail::parse_double(f[14], path, line, "sd_east");
      if (!f[15].empty()) r.sd_north = detail::parse_double(f[15], path, line, "sd_north");
      if (!f[16].empty()) r.cov_en = detail::parse_double(f[16], path, line, "cov_en");
      if (r.sd_east < 0 || r.sd_north < 0)
        detail::parse_error(path, line, "sd_east/sd_north is negative");
    }
    out.push_back(r);
  }
  if (!header) detail::parse_error(path, reader.line(), "no header row");
  return out;
}

}  // namespace geodrift::io
