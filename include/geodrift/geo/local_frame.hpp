#pragma once

/// @file
/// geodrift's world frame W (DESIGN.md "Conventions"): the UTM grid of ONE zone shifted to a
/// per-dataset origin,
///
///     x = easting  - E0      (metres, grid east)
///     y = northing - N0      (metres, grid north)
///     z = height   - h0      (metres, ellipsoidal height, up)
///
/// right-handed with z up. "2D error" is the horizontal distance in W. Distances in W are grid
/// distances: they differ from distances on the ellipsoid by the UTM point scale k (0.9996 on
/// the central meridian, about 1.0004 at ±3° from it); heights are not scaled.
///
/// Heading (DESIGN.md): the clockwise bearing from TRUE north of a view's optical axis, radians
/// in memory ([0, 2π)), degrees in files (`heading_deg`). Grid yaw: the counter-clockwise angle
/// from W's +x axis (grid east) to the horizontal projection of the optical axis, radians in
/// (-π, π]. Grid north is rotated from true north by the meridian convergence γ (GeographicLib:
/// "the bearing of grid north, clockwise from true north"), so
///
///     grid bearing = heading - γ,       yaw = π/2 - grid bearing = π/2 - heading + γ.
///
/// A camera looking at true north has heading 0 and yaw π/2 + γ; one looking at grid north has
/// yaw π/2 and heading -γ (mod 2π). γ ≈ (λ - λ0)·sin φ, a few degrees at most inside a zone.
///
/// GeographicLib (UTMUPS, WGS84, accuracy ~5 nm) does the projection; its exceptions are
/// rethrown as geodrift::InvalidArgument with our context.

#include <Eigen/Core>
#include <GeographicLib/UTMUPS.hpp>
#include <cmath>
#include <iomanip>
#include <sstream>
#include <string>

#include "geodrift/error.hpp"
#include "geodrift/geo/utm.hpp"

namespace geodrift::geo {

namespace detail {

inline constexpr double kPi = 3.14159265358979323846;
inline constexpr double kDegToRad = kPi / 180.0;

/// Wraps an angle (rad) into (-π, π].
inline double wrap_to_pi(double a) {
  double r = std::remainder(a, 2.0 * kPi);  // [-π, π]
  if (r <= -kPi) r += 2.0 * kPi;
  return r;
}

/// Wraps an angle (rad) into [0, 2π).
inline double wrap_to_two_pi(double a) {
  double r = std::fmod(a, 2.0 * kPi);
  if (r < 0.0) r += 2.0 * kPi;
  if (r >= 2.0 * kPi) r = 0.0;  // fmod of a tiny negative value plus 2π can round up to 2π
  return r;
}

inline void check_world_point(const Eigen::Vector3d& p_w, const char* what) {
  GEODRIFT_CHECK(p_w.allFinite(), what << ": world point (" << p_w.x() << ", " << p_w.y() << ", "
                                       << p_w.z() << ") is not finite");
}

}  // namespace detail

/// Grid yaw of a camera's optical axis: the counter-clockwise angle (rad, (-π, π]) from W's +x
/// axis to the horizontal projection of the camera's +z axis (OpenCV camera: x right, y down,
/// z forward).
/// @param R_wc rotation camera -> W (its third column is the optical axis in W).
/// @throws InvalidArgument if R_wc is not finite or the optical axis is vertical (horizontal
///         component below 1e-9), where yaw is undefined.
inline double optical_axis_grid_yaw(const Eigen::Matrix3d& R_wc) {
  GEODRIFT_CHECK(R_wc.allFinite(), "optical_axis_grid_yaw: rotation R_wc is not finite");
  const Eigen::Vector3d axis = R_wc.col(2);
  const double horizontal = std::hypot(axis.x(), axis.y());
  GEODRIFT_CHECK(horizontal > 1e-9 * axis.norm(), "optical_axis_grid_yaw: optical axis ("
                                                      << axis.x() << ", " << axis.y() << ", "
                                                      << axis.z()
                                                      << ") is vertical; yaw is undefined");
  return std::atan2(axis.y(), axis.x());
}

/// Rotation camera -> W of a level camera (optical axis horizontal, image x axis horizontal,
/// image y axis pointing down = -z of W) whose optical axis has the given grid yaw (rad).
///
///     R_wc = [ sin(yaw)   0   cos(yaw) ]      columns: camera x (right), y (down),
///            [ -cos(yaw)  0   sin(yaw) ]               z (forward) in W
///            [ 0         -1   0        ]
///
/// yaw = π/2 (grid north) gives camera x = grid east, the KITTI frame-0 orientation.
/// @throws InvalidArgument if yaw is not finite.
inline Eigen::Matrix3d level_camera_rotation(double grid_yaw) {
  GEODRIFT_CHECK(std::isfinite(grid_yaw),
                 "level_camera_rotation: grid_yaw " << grid_yaw << " is not finite");
  const double c = std::cos(grid_yaw), s = std::sin(grid_yaw);
  Eigen::Matrix3d R;
  R << s, 0.0, c,  //
      -c, 0.0, s,  //
      0.0, -1.0, 0.0;
  return R;
}

/// The world frame W: one UTM zone (zone, hemisphere) shifted to an origin (E0, N0, h0).
///
/// Points anywhere (including across the zone's boundary, into the neighbouring zone) are
/// projected in THIS zone (GeographicLib UTMUPS::Forward with setzone), so W is continuous; the
/// northing is continued across the equator in the origin's hemisphere, so W is continuous there
/// too. A point farther from the central meridian than GeographicLib allows (easting outside
/// [0, 1000] km, roughly 4.5° of longitude at mid-latitudes) or beyond the UTM northing range
/// throws InvalidArgument.
///
/// Cheap to copy (a zone, a flag and 3 doubles plus the cached origin); immutable; all methods
/// are thread-safe.
class LocalFrame {
 public:
  /// Placeholder frame: zone 31N with origin (E0, N0, h0) = (500000, 0, 0), i.e. latitude 0,
  /// longitude 3°E, height 0. Exists so that holders can be default-constructed; real data
  /// should use from_geodetic() or from_utm().
  LocalFrame() : LocalFrame(31, true, 500000.0, 0.0, 0.0, "LocalFrame") {}

  /// Frame whose origin is the given geodetic point.
  /// @param latitude_deg  origin latitude, degrees in [-90, 90] (in practice within the UTM
  ///                      range [-80, 84] or the projection throws).
  /// @param longitude_deg origin longitude, degrees in [-180, 180].
  /// @param height        origin ellipsoidal height h0, metres.
  /// @param zone          UTM zone 1..60 of W, or 0 (default) for the origin's standard zone
  ///                      (with the Norway/Svalbard exceptions). The hemisphere is the origin's
  ///                      (north for latitude >= 0).
  /// @throws InvalidArgument naming the argument for non-finite or out-of-range values, or if
  ///         the origin cannot be projected into the requested zone.
  static LocalFrame from_geodetic(double latitude_deg, double longitude_deg, double height,
                                  int zone = 0) {
    const std::string what = "LocalFrame::from_geodetic";
    detail::check_geodetic(latitude_deg, longitude_deg, height, what);
    if (zone != 0) detail::check_zone(zone, what);
    const int z = zone != 0 ? zone : standard_utm_zone(latitude_deg, longitude_deg);
    const UtmCoordinate u = geodetic_to_utm({latitude_deg, longitude_deg, height}, z);
    // W's hemisphere is the origin's own, as GeographicLib reports it.
    return LocalFrame(z, u.northp, u.easting, u.northing, height, what);
  }

  /// Frame from an explicit UTM origin.
  /// @param zone     UTM zone 1..60.
  /// @param northp   hemisphere of the grid: true = north (false northing 0), false = south.
  /// @param easting0 E0, metres (with the 500 km false easting).
  /// @param northing0 N0, metres (with the hemisphere's false northing).
  /// @param height0  h0, ellipsoidal height in metres.
  /// @throws InvalidArgument for a zone outside [1, 60], non-finite values, or an origin outside
  ///         GeographicLib's UTM range.
  static LocalFrame from_utm(int zone, bool northp, double easting0, double northing0,
                             double height0) {
    return LocalFrame(zone, northp, easting0, northing0, height0, "LocalFrame::from_utm");
  }

  /// UTM zone of W (1..60).
  int zone() const { return zone_; }
  /// Hemisphere of W's grid (true = north).
  bool northp() const { return northp_; }
  /// Zone string such as "32N".
  std::string zone_string() const { return format_utm_zone(zone_, northp_); }
  /// Origin easting E0 (m).
  double easting0() const { return easting0_; }
  /// Origin northing N0 (m), in W's hemisphere.
  double northing0() const { return northing0_; }
  /// Origin ellipsoidal height h0 (m).
  double height0() const { return height0_; }
  /// The origin as latitude/longitude/height.
  const Geodetic& origin_geodetic() const { return origin_geodetic_; }

  /// One-line statement of W for file headers, e.g. "W = UTM 32N grid shifted to E0 457367.401
  /// N0 5428842.326 h0 160 (x east, y north, z up ellipsoidal; metres)". Millimetre precision.
  std::string description() const {
    std::ostringstream os;
    os << std::fixed << std::setprecision(3) << "W = UTM " << zone_string()
       << " grid shifted to E0 " << easting0_ << " N0 " << northing0_ << " h0 " << height0_
       << " (x east, y north, z up ellipsoidal; metres)";
    return os.str();
  }

  /// Geodetic point -> W (metres), projected in W's zone even when the point's standard zone
  /// differs.
  /// @throws InvalidArgument for non-finite inputs, latitude outside [-90, 90], longitude
  ///         outside [-180, 180], or a point outside the zone's projectable range.
  Eigen::Vector3d to_world(double latitude_deg, double longitude_deg, double height) const {
    double gamma_deg = 0.0, k = 0.0;
    return to_world_impl(latitude_deg, longitude_deg, height, &gamma_deg, &k);
  }
  /// Geodetic point -> W (see the overload on three doubles).
  Eigen::Vector3d to_world(const Geodetic& g) const {
    return to_world(g.latitude_deg, g.longitude_deg, g.height);
  }
  /// UTM position in ANY zone/hemisphere -> W (transferred into W's zone through the geodetic
  /// position; exact to GeographicLib's ~5 nm).
  /// @throws InvalidArgument for non-finite values, a zone outside [1, 60], or a position
  ///         outside the UTM range of its own zone or of W's zone.
  Eigen::Vector3d to_world(const UtmCoordinate& u) const {
    const Geodetic g = utm_to_geodetic(u);
    return to_world(g);
  }

  /// W point -> geodetic (latitude/longitude in degrees, ellipsoidal height in metres).
  /// Longitude is in [-180, 180].
  /// @throws InvalidArgument for a non-finite point or one outside the zone's UTM range.
  Geodetic to_geodetic(const Eigen::Vector3d& p_w) const {
    double gamma_deg = 0.0, k = 0.0;
    return to_geodetic_impl(p_w, "LocalFrame::to_geodetic", &gamma_deg, &k);
  }

  /// W point -> UTM coordinates in W's zone, with the hemisphere of the point itself
  /// (a point south of the equator in a northern frame is reported with northp = false and the
  /// 10,000 km false northing, as UTM requires), so the result is a valid UTM coordinate.
  /// @throws InvalidArgument for a non-finite point.
  UtmCoordinate utm_of(const Eigen::Vector3d& p_w) const {
    detail::check_world_point(p_w, "LocalFrame::utm_of");
    UtmCoordinate u;
    u.zone = zone_;
    u.easting = easting0_ + p_w.x();
    u.height = height0_ + p_w.z();
    const double n = northing0_ + p_w.y();  // continued in W's hemisphere
    if (northp_) {
      u.northp = n >= 0.0;
      u.northing = u.northp ? n : n + kUtmSouthShift;
    } else {
      u.northp = n >= kUtmSouthShift;
      u.northing = u.northp ? n - kUtmSouthShift : n;
    }
    return u;
  }

  /// Meridian convergence γ at a W point (rad): the bearing of grid north measured clockwise
  /// from true north (GeographicLib's convention; negative west of the central meridian in the
  /// northern hemisphere).
  /// @throws InvalidArgument as to_geodetic().
  double meridian_convergence(const Eigen::Vector3d& p_w) const {
    double gamma_deg = 0.0, k = 0.0;
    to_geodetic_impl(p_w, "LocalFrame::meridian_convergence", &gamma_deg, &k);
    return gamma_deg * detail::kDegToRad;
  }

  /// UTM point scale k at a W point (grid distance / ellipsoid distance; 0.9996 on the central
  /// meridian).
  /// @throws InvalidArgument as to_geodetic().
  double scale_factor(const Eigen::Vector3d& p_w) const {
    double gamma_deg = 0.0, k = 0.0;
    to_geodetic_impl(p_w, "LocalFrame::scale_factor", &gamma_deg, &k);
    return k;
  }

  /// True heading (rad, clockwise from true north) -> grid yaw (rad, counter-clockwise from W's
  /// +x axis, in (-π, π]) at W point p_w: yaw = π/2 - heading + γ(p_w).
  /// @throws InvalidArgument if heading is not finite, or as to_geodetic().
  double grid_yaw_from_heading(double heading, const Eigen::Vector3d& p_w) const {
    GEODRIFT_CHECK(std::isfinite(heading),
                   "LocalFrame::grid_yaw_from_heading: heading " << heading << " is not finite");
    return detail::wrap_to_pi(0.5 * detail::kPi - heading + meridian_convergence(p_w));
  }

  /// Grid yaw (rad, counter-clockwise from W's +x) -> true heading (rad, clockwise from true
  /// north, in [0, 2π)) at W point p_w: heading = π/2 - yaw + γ(p_w).
  /// @throws InvalidArgument if yaw is not finite, or as to_geodetic().
  double heading_from_grid_yaw(double yaw, const Eigen::Vector3d& p_w) const {
    GEODRIFT_CHECK(std::isfinite(yaw),
                   "LocalFrame::heading_from_grid_yaw: yaw " << yaw << " is not finite");
    return detail::wrap_to_two_pi(0.5 * detail::kPi - yaw + meridian_convergence(p_w));
  }

  /// True heading (rad, [0, 2π)) of a camera's optical axis, camera at W point p_w with
  /// rotation R_wc (camera -> W; OpenCV camera axes).
  /// @throws InvalidArgument as optical_axis_grid_yaw() and to_geodetic().
  double camera_heading(const Eigen::Matrix3d& R_wc, const Eigen::Vector3d& p_w) const {
    return heading_from_grid_yaw(optical_axis_grid_yaw(R_wc), p_w);
  }

  /// Rotation camera -> W of a level camera at W point p_w whose optical axis has the given
  /// true heading (rad). See level_camera_rotation().
  Eigen::Matrix3d level_camera_rotation_from_heading(double heading,
                                                     const Eigen::Vector3d& p_w) const {
    return level_camera_rotation(grid_yaw_from_heading(heading, p_w));
  }

 private:
  LocalFrame(int zone, bool northp, double easting0, double northing0, double height0,
             const std::string& what)
      : zone_(zone),
        northp_(northp),
        easting0_(easting0),
        northing0_(northing0),
        height0_(height0) {
    detail::check_zone(zone, what);
    detail::check_finite(easting0, "easting0", what);
    detail::check_finite(northing0, "northing0", what);
    detail::check_finite(height0, "height0", what);
    double gamma_deg = 0.0, k = 0.0;
    origin_geodetic_ = to_geodetic_impl(Eigen::Vector3d::Zero(), what, &gamma_deg, &k);
  }

  Eigen::Vector3d to_world_impl(double latitude_deg, double longitude_deg, double height,
                                double* gamma_deg, double* k) const {
    detail::check_geodetic(latitude_deg, longitude_deg, height, "LocalFrame::to_world");
    int zone_out = 0;
    bool northp_out = true;
    double easting = 0.0, northing = 0.0;
    try {
      GeographicLib::UTMUPS::Forward(latitude_deg, longitude_deg, zone_out, northp_out, easting,
                                     northing, *gamma_deg, *k, zone_);
    } catch (const std::exception& e) {
      std::ostringstream os;
      os << std::setprecision(12) << "LocalFrame::to_world: latitude " << latitude_deg
         << " deg, longitude " << longitude_deg << " deg is outside the range of W's UTM zone "
         << zone_string() << ": " << e.what();
      ::geodrift::detail::throw_invalid_argument(os.str());
    }
    GEODRIFT_ASSERT(zone_out == zone_);
    // Continue the northing across the equator in W's hemisphere.
    if (northp_out != northp_) northing += northp_ ? -kUtmSouthShift : kUtmSouthShift;
    return Eigen::Vector3d(easting - easting0_, northing - northing0_, height - height0_);
  }

  Geodetic to_geodetic_impl(const Eigen::Vector3d& p_w, const std::string& what, double* gamma_deg,
                            double* k) const {
    detail::check_world_point(p_w, what.c_str());
    Geodetic g;
    const double easting = easting0_ + p_w.x(), northing = northing0_ + p_w.y();
    try {
      // Reverse accepts northings continued across the equator ([-9100, 9600] km north,
      // [900, 19600] km south), matching to_world's continuation.
      GeographicLib::UTMUPS::Reverse(zone_, northp_, easting, northing, g.latitude_deg,
                                     g.longitude_deg, *gamma_deg, *k);
    } catch (const std::exception& e) {
      std::ostringstream os;
      os << std::setprecision(12) << what << ": world point (" << p_w.x() << ", " << p_w.y() << ", "
         << p_w.z() << ") = UTM " << zone_string() << " easting " << easting << " m, northing "
         << northing << " m is outside the UTM range: " << e.what();
      ::geodrift::detail::throw_invalid_argument(os.str());
    }
    g.height = height0_ + p_w.z();
    return g;
  }

  int zone_;
  bool northp_;
  double easting0_;
  double northing0_;
  double height0_;
  Geodetic origin_geodetic_;
};

}  // namespace geodrift::geo
