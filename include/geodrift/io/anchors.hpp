#pragma once

/// @file
/// Anchors CSV (`--anchors`, DESIGN.md "Command line and files"): the world positions of a few
/// frames of the trajectory (geo-tags, GNSS fixes, surveyed points).
///
/// Format: comma-separated, one header row naming the columns (any order, case-sensitive),
/// then one anchor per row. Blank lines and lines starting with '#' are skipped. Columns:
///   time      `frame` (integer frame index) and/or `timestamp` (seconds); at least one;
///   position  exactly ONE of these groups, complete:
///               `latitude,longitude,height`   degrees, degrees, ellipsoidal metres (WGS84)
///               `easting,northing,zone,height` UTM metres, zone like "32N", ellipsoidal metres
///               `x,y,z`                        W itself, metres (geo::LocalFrame)
///   optional  `sigma_m` (standard deviation of the position, metres, > 0) and `heading_deg`
///             (true heading of the view, degrees clockwise from true north).
/// Heights are ellipsoidal (DESIGN.md); a `height_msl` column is rejected with a message saying
/// so, as geodrift does not ship a geoid model. An empty `frame` or `timestamp` field means
/// "unknown" (each row needs one of them); an empty `sigma_m` or `heading_deg` means "not
/// given". A literal nan/inf is always an error.
///
/// Errors: InvalidArgument "<path>:<line>: <what>" for an unknown or duplicated column, mixed or
/// incomplete position columns, no time column, a short or long row, a field that is not a
/// number or not finite, a bad zone string, latitude/longitude out of range, sigma_m ≤ 0, a
/// position outside W's UTM zone; Error for a missing file.

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <iomanip>
#include <limits>
#include <map>
#include <ostream>
#include <sstream>
#include <string>
#include <vector>

#include "geodrift/error.hpp"
#include "geodrift/geo/local_frame.hpp"
#include "geodrift/geo/utm.hpp"
#include "geodrift/io/detail/text_io.hpp"
#include "geodrift/io/trajectory.hpp"
#include "geodrift/version.hpp"

namespace geodrift::io {

/// Which position columns an anchors file uses.
enum class AnchorPositionKind { kGeodetic, kUtm, kWorld };

/// One anchor row as written in the file (before conversion to W).
struct AnchorRecord {
  int line = 0;    ///< 1-based line in the file
  int frame = -1;  ///< frame index, -1 when the file has no `frame` column
  double timestamp = std::numeric_limits<double>::quiet_NaN();  ///< NaN without `timestamp`
  /// (latitude_deg, longitude_deg, height) | (easting, northing, height) | (x, y, z).
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  int zone = 0;                                                   ///< UTM zone (kUtm only)
  bool northp = true;                                             ///< UTM hemisphere (kUtm only)
  double sigma_m = std::numeric_limits<double>::quiet_NaN();      ///< NaN when not given
  double heading_deg = std::numeric_limits<double>::quiet_NaN();  ///< NaN when not given
};

/// An anchors file as read.
struct AnchorTable {
  std::string path;
  AnchorPositionKind kind = AnchorPositionKind::kGeodetic;
  bool has_frame = false;
  bool has_timestamp = false;
  bool has_sigma = false;
  bool has_heading = false;
  std::vector<AnchorRecord> records;
};

/// An anchor converted to W.
struct Anchor {
  int line = 0;    ///< line in the source file (0 when built in memory)
  int frame = -1;  ///< frame index, -1 when unknown
  double timestamp = std::numeric_limits<double>::quiet_NaN();  ///< seconds, NaN when unknown
  Eigen::Vector3d y_w = Eigen::Vector3d::Zero();                ///< position in W, metres
  double sigma_m = std::numeric_limits<double>::quiet_NaN();    ///< metres, NaN when not given
  /// True heading of the view (rad, clockwise from true north, [0, 2π)), NaN when not given.
  double heading = std::numeric_limits<double>::quiet_NaN();
};

/// Reads an anchors CSV (see the file comment for the format and every error).
/// @throws Error if the file cannot be opened; InvalidArgument "<path>:<line>: <what>".
inline AnchorTable read_anchors_csv(const std::string& path) {
  detail::LineReader reader(path);
  AnchorTable table;
  table.path = path;
  std::map<std::string, std::size_t> col;  // column name -> index
  std::size_t num_cols = 0;
  int header_line = 0;
  std::string raw;
  static const char* kKnown[] = {"frame",   "timestamp", "latitude",   "longitude", "height",
                                 "easting", "northing",  "zone",       "x",         "y",
                                 "z",       "sigma_m",   "heading_deg"};
  while (reader.next(&raw)) {
    const std::string text = detail::trim(raw);
    if (text.empty() || text[0] == '#') continue;
    const int line = reader.line();
    const std::vector<std::string> fields = detail::split_csv(text);
    if (header_line == 0) {
      header_line = line;
      num_cols = fields.size();
      for (std::size_t i = 0; i < fields.size(); ++i) {
        const std::string& name = fields[i];
        if (name == "height_msl") {
          detail::parse_error(path, line,
                              "column 'height_msl' (height above mean sea level) is not "
                              "supported: give the ellipsoidal height in a 'height' column");
        }
        bool known = false;
        for (const char* k : kKnown) known = known || name == k;
        if (!known) {
          detail::parse_error(
              path, line,
              "unknown column '" + name +
                  "' (expected frame/timestamp; latitude,longitude,height or "
                  "easting,northing,zone,height or x,y,z; optional sigma_m, heading_deg)");
        }
        if (!col.emplace(name, i).second)
          detail::parse_error(path, line, "column '" + name + "' appears twice");
      }
      const auto has = [&](const char* c) { return col.count(c) != 0; };
      table.has_frame = has("frame");
      table.has_timestamp = has("timestamp");
      table.has_sigma = has("sigma_m");
      table.has_heading = has("heading_deg");
      if (!table.has_frame && !table.has_timestamp)
        detail::parse_error(path, line, "no 'frame' or 'timestamp' column");
      const bool geod = has("latitude") || has("longitude");
      const bool utm = has("easting") || has("northing") || has("zone");
      const bool world = has("x") || has("y") || has("z");
      if (int(geod) + int(utm) + int(world) > 1) {
        detail::parse_error(path, line,
                            "mixed position columns: use exactly one of latitude,longitude,height "
                            "or easting,northing,zone,height or x,y,z");
      }
      if (geod) {
        table.kind = AnchorPositionKind::kGeodetic;
        for (const char* c : {"latitude", "longitude", "height"})
          if (!has(c))
            detail::parse_error(
                path, line,
                std::string("missing column '") + c + "' (latitude,longitude,height go together)");
      } else if (utm) {
        table.kind = AnchorPositionKind::kUtm;
        for (const char* c : {"easting", "northing", "zone", "height"})
          if (!has(c))
            detail::parse_error(path, line,
                                std::string("missing column '") + c +
                                    "' (easting,northing,zone,height go together)");
      } else if (world) {
        table.kind = AnchorPositionKind::kWorld;
        if (has("height"))
          detail::parse_error(path, line, "column 'height' does not go with x,y,z (use z)");
        for (const char* c : {"x", "y", "z"})
          if (!has(c))
            detail::parse_error(path, line,
                                std::string("missing column '") + c + "' (x,y,z go together)");
      } else {
        detail::parse_error(path, line,
                            "no position columns (latitude,longitude,height or "
                            "easting,northing,zone,height or x,y,z)");
      }
      continue;
    }

    if (fields.size() != num_cols) {
      detail::parse_error(path, line,
                          "row has " + std::to_string(fields.size()) + " fields, the header has " +
                              std::to_string(num_cols));
    }
    const auto num = [&](const char* c) {
      return detail::parse_double(fields[col.at(c)], path, line, c);
    };
    AnchorRecord r;
    r.line = line;
    // An empty frame or timestamp field means "unknown" (one of the two must be given); an
    // empty sigma_m or heading_deg means "not given". NaN written out is never accepted.
    const auto empty = [&](const char* c) { return col.count(c) && fields[col.at(c)].empty(); };
    if (table.has_frame && !empty("frame"))
      r.frame =
          static_cast<int>(detail::parse_int(fields[col.at("frame")], path, line, "frame", 0));
    if (table.has_timestamp && !empty("timestamp")) r.timestamp = num("timestamp");
    if (r.frame < 0 && !std::isfinite(r.timestamp))
      detail::parse_error(path, line, "row gives neither a frame nor a timestamp");
    switch (table.kind) {
      case AnchorPositionKind::kGeodetic: {
        r.position = Eigen::Vector3d(num("latitude"), num("longitude"), num("height"));
        if (!(r.position.x() >= -90.0 && r.position.x() <= 90.0))
          detail::parse_error(path, line,
                              "latitude " + detail::fmt(r.position.x()) + " deg outside [-90, 90]");
        if (!(r.position.y() >= -180.0 && r.position.y() <= 180.0))
          detail::parse_error(
              path, line, "longitude " + detail::fmt(r.position.y()) + " deg outside [-180, 180]");
        break;
      }
      case AnchorPositionKind::kUtm: {
        r.position = Eigen::Vector3d(num("easting"), num("northing"), num("height"));
        try {
          geo::parse_utm_zone(fields[col.at("zone")], &r.zone, &r.northp);
        } catch (const InvalidArgument& e) {
          detail::parse_error(path, line, e.what());
        }
        break;
      }
      case AnchorPositionKind::kWorld:
        r.position = Eigen::Vector3d(num("x"), num("y"), num("z"));
        break;
    }
    if (table.has_sigma && !empty("sigma_m")) {
      r.sigma_m = num("sigma_m");
      if (!(r.sigma_m > 0.0))
        detail::parse_error(path, line, "sigma_m " + detail::fmt(r.sigma_m) + " must be > 0");
    }
    if (table.has_heading && !empty("heading_deg")) r.heading_deg = num("heading_deg");
    table.records.push_back(r);
  }
  if (header_line == 0) detail::parse_error(path, reader.line(), "no header row");
  if (table.records.empty()) detail::parse_error(path, reader.line(), "no anchor rows");
  return table;
}

/// A LocalFrame for anchors given as latitude/longitude or UTM: the origin is the first anchor
/// (its standard zone for latitude/longitude, its own zone for UTM).
/// @throws InvalidArgument for x,y,z anchors (W must then be given by the caller).
inline geo::LocalFrame local_frame_at_first_anchor(const AnchorTable& table) {
  GEODRIFT_CHECK(!table.records.empty(), table.path << ": no anchors");
  const AnchorRecord& r = table.records.front();
  try {
    switch (table.kind) {
      case AnchorPositionKind::kGeodetic:
        return geo::LocalFrame::from_geodetic(r.position.x(), r.position.y(), r.position.z());
      case AnchorPositionKind::kUtm:
        return geo::LocalFrame::from_utm(r.zone, r.northp, r.position.x(), r.position.y(),
                                         r.position.z());
      case AnchorPositionKind::kWorld:
        break;
    }
  } catch (const InvalidArgument& e) {
    detail::parse_error(table.path, r.line, e.what());
  }
  detail::parse_error(table.path, r.line,
                      "anchors are given as x,y,z in W: the world frame (UTM zone and origin) "
                      "must be given separately");
}

/// Converts the anchors to W through `frame`; heading_deg becomes radians in [0, 2π).
/// @throws InvalidArgument "<path>:<line>: <what>" when a position cannot be expressed in W
///         (outside the zone's range, UTM outside its range).
inline std::vector<Anchor> anchors_in_world(const AnchorTable& table,
                                            const geo::LocalFrame& frame) {
  std::vector<Anchor> out;
  out.reserve(table.records.size());
  for (const AnchorRecord& r : table.records) {
    Anchor a;
    a.line = r.line;
    a.frame = r.frame;
    a.timestamp = r.timestamp;
    a.sigma_m = r.sigma_m;
    if (std::isfinite(r.heading_deg))
      a.heading = geo::detail::wrap_to_two_pi(r.heading_deg * geo::detail::kDegToRad);
    try {
      switch (table.kind) {
        case AnchorPositionKind::kGeodetic:
          a.y_w = frame.to_world(r.position.x(), r.position.y(), r.position.z());
          break;
        case AnchorPositionKind::kUtm:
          a.y_w = frame.to_world(
              geo::UtmCoordinate{r.position.x(), r.position.y(), r.zone, r.northp, r.position.z()});
          break;
        case AnchorPositionKind::kWorld:
          a.y_w = r.position;
          break;
      }
    } catch (const InvalidArgument& e) {
      detail::parse_error(table.path, r.line, e.what());
    }
    out.push_back(a);
  }
  return out;
}

/// Reads an anchors CSV and converts it to W in one call.
inline std::vector<Anchor> read_anchors(const std::string& path, const geo::LocalFrame& frame) {
  return anchors_in_world(read_anchors_csv(path), frame);
}

namespace detail {

/// GPS time (from 1980-01-06) runs 315,964,800 s behind Unix time (from 1970-01-01) less the
/// leap seconds since 1980: 18 since 2017, 10–17 from 1996 on.
constexpr double kGpsEpochUnixSeconds = 315964800.0;

/// Why the anchors' timestamps `a` (ascending) may not be in the trajectory's clock
/// [t0, t1]: a unit factor (seconds against milli-, micro- or nanoseconds) or the GPS/Unix
/// epochs that put every one of them inside the trajectory's range, said in words; empty when
/// none does. A hint only: nothing is converted.
inline std::string time_unit_hint(const std::vector<double>& a, double t0, double t1) {
  if (a.empty() || !(t1 > t0)) return {};
  const double span = t1 - t0;
  const auto inside = [&](double scale, double shift) {
    const double lo = a.front() * scale + shift, hi = a.back() * scale + shift;
    return lo >= t0 - 1e-3 * span && hi <= t1 + 1e-3 * span;
  };
  static const struct {
    double factor;
    const char* anchors;
    const char* trajectory;
  } kUnits[] = {{1e9, "seconds", "nanoseconds"},   {1e6, "seconds", "microseconds"},
                {1e3, "seconds", "milliseconds"},  {1e-3, "milliseconds", "seconds"},
                {1e-6, "microseconds", "seconds"}, {1e-9, "nanoseconds", "seconds"}};
  std::ostringstream os;
  os << std::setprecision(6);
  for (const auto& u : kUnits)
    if (inside(u.factor, 0.0)) {
      os << "the anchors' timestamps look like " << u.anchors << " and the trajectory's like "
         << u.trajectory << " (x" << u.factor
         << " puts every anchor inside the trajectory's range): give both in seconds";
      return os.str();
    }
  // Today's 18 leap seconds first: a range fits a few seconds either way, and the clock check
  // of the correction (correction/time_offset.hpp) finds the rest.
  for (int i = 0; i <= 20; ++i) {
    const int leap = i <= 18 ? 18 - i : i;
    const double d = kGpsEpochUnixSeconds - leap;
    if (inside(1.0, d) || inside(1.0, -d)) {
      os << std::setprecision(10) << "the anchors' and the trajectory's timestamps differ by " << d
         << " s, the GPS epoch against Unix time less " << leap
         << " leap seconds: one is GPS time, the other Unix (UTC) time (--anchor-time-offset "
         << (inside(1.0, d) ? d : -d) << ")";
      return os.str();
    }
  }
  if (a.front() >= 0 && a.back() <= 604800.0 && t0 > 1e8)
    return "the anchors' timestamps look like seconds of the GPS week and the trajectory's like "
           "an absolute time: give the anchors as GPS or Unix time";
  return {};
}

}  // namespace detail

/// Where an anchor falls on a trajectory: at pose `index` + `fraction` of the way to pose
/// `index + 1` (fraction in [0, 1); the last pose is index n-1 with fraction 0).
struct AnchorLocation {
  std::size_t index = 0;
  double fraction = 0.0;
  bool by_time = false;  ///< placed by TrajectoryPose::timestamp (else by frame)
};

/// Locates each anchor on a trajectory (DESIGN.md: "an anchor between frames is interpolated in
/// time; one outside the trajectory's time range is an error"). An anchor with a frame is placed
/// by TrajectoryPose::frame (the KITTI leading index, or the 0-based pose order); one with only a
/// timestamp by TrajectoryPose::timestamp (linear in time between the two neighbouring poses).
/// @param anchors_path the anchors file, for messages.
/// @throws InvalidArgument "<anchors_path>:<line>: <what>" for an anchor outside the
///         trajectory's frame or time range, or with only a timestamp when the trajectory has
///         none, or anchors' timestamps bunched into a thousandth of the trajectory's time
///         range when another unit would spread them over it (seconds against nanoseconds);
///         a timestamp out of range says which unit or epoch would fit
///         (detail::time_unit_hint).
inline std::vector<AnchorLocation> locate_anchors(const std::vector<Anchor>& anchors,
                                                  const Trajectory& traj,
                                                  const std::string& anchors_path) {
  GEODRIFT_CHECK(!traj.poses.empty(), "locate_anchors: empty trajectory");
  std::vector<double> frames, times;
  for (const TrajectoryPose& p : traj.poses) {
    frames.push_back(p.frame);
    times.push_back(p.timestamp);
  }
  // The timestamps of the anchors placed by one, for a hint when they are in another clock.
  std::vector<double> anchor_times;
  const Anchor* first_timed = nullptr;
  for (const Anchor& a : anchors)
    if (a.frame < 0 && std::isfinite(a.timestamp)) {
      anchor_times.push_back(a.timestamp);
      if (!first_timed) first_timed = &a;
    }
  std::sort(anchor_times.begin(), anchor_times.end());
  const std::string time_hint =
      traj.has_timestamps ? detail::time_unit_hint(anchor_times, times.front(), times.back())
                          : std::string();
  const auto locate = [&](const std::vector<double>& keys, double v, const Anchor& a,
                          const char* what) {
    if (!(v >= keys.front() && v <= keys.back())) {
      std::ostringstream os;
      os << std::setprecision(15) << "anchor " << what << " " << v
         << " is outside the trajectory's " << what << " range [" << keys.front() << ", "
         << keys.back() << "]";
      if (&keys == &times && !time_hint.empty()) os << ": " << time_hint;
      detail::parse_error(anchors_path, a.line, os.str());
    }
    AnchorLocation loc;
    const std::size_t hi = static_cast<std::size_t>(std::upper_bound(keys.begin(), keys.end(), v) -
                                                    keys.begin());  // first key > v
    if (hi >= keys.size()) {
      loc.index = keys.size() - 1;  // v == last key
    } else {
      loc.index = hi - 1;
      loc.fraction = (v - keys[loc.index]) / (keys[hi] - keys[loc.index]);
    }
    return loc;
  };
  std::vector<AnchorLocation> out;
  for (const Anchor& a : anchors) {
    if (a.frame >= 0) {
      out.push_back(locate(frames, a.frame, a, "frame"));
    } else {
      if (!traj.has_timestamps)
        detail::parse_error(anchors_path, a.line,
                            "anchor has a timestamp but no frame, and the trajectory has no "
                            "timestamps (KITTI): give a 'frame' column");
      out.push_back(locate(times, a.timestamp, a, "timestamp"));
      out.back().by_time = true;
    }
  }
  // Inside the range but bunched into a sliver of it, as seconds read against nanoseconds
  // are: every such anchor would land on the first poses.
  if (anchor_times.size() >= 2 && !time_hint.empty() &&
      anchor_times.back() - anchor_times.front() < 1e-3 * (times.back() - times.front())) {
    std::ostringstream os;
    os << std::setprecision(6) << "the anchors' timestamps span "
       << anchor_times.back() - anchor_times.front() << ", a fraction "
       << (anchor_times.back() - anchor_times.front()) / (times.back() - times.front())
       << " of the trajectory's " << times.back() - times.front() << ": " << time_hint;
    detail::parse_error(anchors_path, first_timed->line, os.str());
  }
  return out;
}

/// The camera pose T_cw at an anchor's location on a trajectory (locate_anchors). Rotation:
/// the geodesic between the two neighbouring poses. Centre: the cubic Hermite curve between
/// them with finite-difference tangents over the next poses out, (c_{i+1} − c_{i−1}) /
/// (k_{i+1} − k_{i−1}) at pose i in the location's key k (frame or time): a vehicle's path is
/// smooth, and a chord cuts its turns. On KITTI 02's ground truth thinned to poses every 3–12
/// frames (an ORB-SLAM keyframe trajectory), the chord misses the 4,036 frames between them by
/// 0.096 m on average (at worst 0.76 m), the cubic by 0.043 m (0.46 m). The chord is kept for a
/// tangent that is not there (the first and last poses) or that a step more than 4× faster than
/// the anchor's own would pull (a jump, or setting off from a stop).
inline lie::SE3d anchor_pose_cw(const Trajectory& traj, const AnchorLocation& loc) {
  const std::size_t n = traj.poses.size();
  GEODRIFT_CHECK(loc.index < n, "anchor_pose_cw: index " << loc.index << " of " << n << " poses");
  const std::size_t i = loc.index;
  if (loc.fraction <= 0 || i + 1 >= n) return traj.poses[i].T_cw;
  const auto key = [&](std::size_t k) {
    return loc.by_time ? traj.poses[k].timestamp : static_cast<double>(traj.poses[k].frame);
  };
  const auto centre = [&](std::size_t k) -> Eigen::Vector3d {
    return traj.poses[k].T_cw.inverse().translation();
  };
  const lie::SE3d a = traj.poses[i].T_cw.inverse(), b = traj.poses[i + 1].T_cw.inverse();
  const double f = loc.fraction;
  const lie::SO3d R =
      a.rotation() * lie::SO3d::exp(f * (a.rotation().inverse() * b.rotation()).log());
  const Eigen::Vector3d c1 = a.translation(), c2 = b.translation();
  const double h = key(i + 1) - key(i);
  const Eigen::Vector3d chord = c2 - c1;
  // Tangent at pose j (i or i + 1), per key interval h, from its neighbours j − 1 and j + 1; the
  // chord where there is no neighbour or the step to the outer one is a jump.
  const auto tangent = [&](std::size_t j) -> Eigen::Vector3d {
    if (j == 0 || j + 1 >= n) return chord;
    const std::size_t outer = j == i ? i - 1 : i + 2;
    const double dk = key(j + 1) - key(j - 1);
    const double dk_outer = std::abs(key(outer) - key(j));
    const double speed_outer = (centre(outer) - centre(j)).norm() / dk_outer;
    if (!(dk > 0 && dk_outer > 0 && h > 0 && speed_outer <= 4.0 * chord.norm() / h)) return chord;
    return (centre(j + 1) - centre(j - 1)) * (h / dk);
  };
  const Eigen::Vector3d m1 = tangent(i), m2 = tangent(i + 1);
  const double f2 = f * f, f3 = f2 * f;
  const Eigen::Vector3d c = (2 * f3 - 3 * f2 + 1) * c1 + (f3 - 2 * f2 + f) * m1 +
                            (-2 * f3 + 3 * f2) * c2 + (f3 - f2) * m2;
  return lie::SE3d(R, c).inverse();
}

/// Writes anchors as CSV with columns
/// frame,timestamp,latitude,longitude,height,sigma_m,heading_deg (readable by
/// read_anchors_csv; the frame/timestamp columns only when some anchor has one), positions
/// converted from W through `frame`, after a '#' line stating frame, units and version. Unknown
/// values (frame -1, NaN timestamp/sigma/heading) are written as empty fields.
/// @throws InvalidArgument for an anchor without frame and timestamp or outside W's zone; Error
///         on I/O failure.
inline void write_anchors_csv(const std::string& path, const std::vector<Anchor>& anchors,
                              const geo::LocalFrame& frame) {
  std::vector<geo::Geodetic> g;
  g.reserve(anchors.size());
  bool any_time = false;
  for (const Anchor& a : anchors) {
    g.push_back(frame.to_geodetic(a.y_w));
    any_time = any_time || std::isfinite(a.timestamp);
  }
  for (std::size_t i = 0; i < anchors.size(); ++i) {
    GEODRIFT_CHECK(anchors[i].frame >= 0 || std::isfinite(anchors[i].timestamp),
                   "write_anchors_csv: anchor " << i << " has neither frame nor timestamp");
  }
  bool any_frame = false;
  for (const Anchor& a : anchors) any_frame = any_frame || a.frame >= 0;
  detail::write_atomically(path, [&](std::ostream& os) {
    os << "# geodrift " << kVersion << " anchors: WGS84 latitude/longitude (deg), ellipsoidal "
       << "height (m), sigma_m (m), heading_deg (deg clockwise from true north); converted "
       << "from " << frame.description() << "\n";
    std::string header;
    if (any_frame) header += "frame,";
    if (any_time) header += "timestamp,";
    os << header << "latitude,longitude,height,sigma_m,heading_deg\n";
    for (std::size_t i = 0; i < anchors.size(); ++i) {
      const Anchor& a = anchors[i];
      const auto opt = [](double v) { return std::isfinite(v) ? detail::fmt(v) : std::string(); };
      if (any_frame) os << (a.frame >= 0 ? std::to_string(a.frame) : std::string()) << ',';
      if (any_time) os << opt(a.timestamp) << ',';
      os << detail::fmt(g[i].latitude_deg) << ',' << detail::fmt(g[i].longitude_deg) << ','
         << detail::fmt(g[i].height) << ',' << opt(a.sigma_m) << ','
         << opt(a.heading / geo::detail::kDegToRad) << '\n';
    }
  });
}

}  // namespace geodrift::io
