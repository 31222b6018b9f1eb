#pragma once

/// @file
/// UTM coordinates, zone strings and the input validation shared by geo/ (WGS84 ellipsoid,
/// GeographicLib's UTMUPS conventions: false easting 500 km, false northing 0 m in the northern
/// and 10,000 km in the southern hemisphere, scale 0.9996 on the central meridian).
///
/// geodrift's world frame W is built on ONE UTM zone (DESIGN.md), so only UTM zones 1..60 are
/// supported; the polar UPS grids are not (a point whose UTM coordinates fall outside
/// GeographicLib's allowed range throws InvalidArgument).

#include <GeographicLib/UTMUPS.hpp>
#include <cctype>
#include <cmath>
#include <iomanip>
#include <sstream>
#include <string>

#include "geodrift/error.hpp"

namespace geodrift::geo {

/// Smallest and largest UTM zone number.
inline constexpr int kMinUtmZone = 1;
inline constexpr int kMaxUtmZone = 60;
/// Northing offset (m) between the northern and southern halves of a UTM zone (10,000 km):
/// a southern northing N_s and a northern northing N_n of the same point satisfy
/// N_s = N_n + kUtmSouthShift (with N_n negative south of the equator).
inline constexpr double kUtmSouthShift = 1.0e7;

/// A UTM grid position with its zone and hemisphere stated explicitly.
/// Units: metres. `northp` is true for the northern hemisphere (false northing 0 m), false for
/// the southern one (false northing 10,000 km). `height` is the ellipsoidal height (WGS84).
struct UtmCoordinate {
  double easting = 0.0;   ///< m, including the 500 km false easting
  double northing = 0.0;  ///< m, including the hemisphere's false northing
  int zone = 0;           ///< 1..60
  bool northp = true;     ///< hemisphere: true = north ("32N"), false = south ("32S")
  double height = 0.0;    ///< ellipsoidal height, m
};

/// Geodetic position on WGS84: latitude and longitude in degrees (the universal file and
/// display unit, hence the `_deg` names), ellipsoidal height in metres.
struct Geodetic {
  double latitude_deg = 0.0;   ///< [-90, 90], positive north
  double longitude_deg = 0.0;  ///< [-180, 180], positive east
  double height = 0.0;         ///< ellipsoidal height, m
};

namespace detail {

/// Throws InvalidArgument "<what> <name> <value> is not finite" unless v is finite.
inline void check_finite(double v, const char* name, const std::string& what) {
  GEODRIFT_CHECK(std::isfinite(v),
                 what << (what.empty() ? "" : ": ") << name << " " << v << " is not finite");
}

/// Validates a latitude/longitude/height triple (degrees, degrees, metres).
/// @throws InvalidArgument naming the argument and value: non-finite, latitude outside
///         [-90, 90], longitude outside [-180, 180].
inline void check_geodetic(double latitude_deg, double longitude_deg, double height,
                           const std::string& what) {
  const std::string pre = what.empty() ? std::string() : what + ": ";
  check_finite(latitude_deg, "latitude", what);
  check_finite(longitude_deg, "longitude", what);
  check_finite(height, "height", what);
  GEODRIFT_CHECK(latitude_deg >= -90.0 && latitude_deg <= 90.0,
                 pre << "latitude " << latitude_deg << " deg outside [-90, 90]");
  GEODRIFT_CHECK(longitude_deg >= -180.0 && longitude_deg <= 180.0,
                 pre << "longitude " << longitude_deg << " deg outside [-180, 180]");
}

/// Validates a UTM zone number.
inline void check_zone(int zone, const std::string& what) {
  GEODRIFT_CHECK(zone >= kMinUtmZone && zone <= kMaxUtmZone,
                 what << (what.empty() ? "" : ": ") << "zone " << zone << " outside ["
                      << kMinUtmZone << ", " << kMaxUtmZone << "] (UPS is not supported)");
}

}  // namespace detail

/// The standard UTM zone (1..60) of a point, with the Norway and Svalbard exceptions
/// (GeographicLib UTMUPS::StandardZone with the UTM pseudo-zone, so latitudes outside
/// [-80, 84) get the UTM zone of their longitude instead of UPS).
/// @throws InvalidArgument for non-finite or out-of-range latitude/longitude.
inline int standard_utm_zone(double latitude_deg, double longitude_deg) {
  detail::check_geodetic(latitude_deg, longitude_deg, 0.0, "standard_utm_zone");
  return GeographicLib::UTMUPS::StandardZone(latitude_deg, longitude_deg,
                                             GeographicLib::UTMUPS::UTM);
}

/// Formats a zone as "<number><N|S>", e.g. "32N", "56S".
/// @throws InvalidArgument if zone is outside [1, 60].
inline std::string format_utm_zone(int zone, bool northp) {
  detail::check_zone(zone, "format_utm_zone");
  return std::to_string(zone) + (northp ? "N" : "S");
}

/// Parses a zone string: a zone number 1..60 followed by a hemisphere letter N or S (either
/// case, optional spaces in between), e.g. "32N", "32 n", "56S". Latitude-band letters
/// ("32U") are rejected because "S" would be ambiguous (band S is in the northern hemisphere).
/// @param text the zone string.
/// @param zone receives the zone number.
/// @param northp receives true for N, false for S.
/// @throws InvalidArgument naming the string when it is malformed or the zone is out of range.
inline void parse_utm_zone(const std::string& text, int* zone, bool* northp) {
  GEODRIFT_CHECK(zone != nullptr && northp != nullptr, "parse_utm_zone: null output pointer");
  std::size_t i = 0;
  const std::size_t n = text.size();
  while (i < n && std::isspace(static_cast<unsigned char>(text[i]))) ++i;
  const std::size_t digits_begin = i;
  while (i < n && std::isdigit(static_cast<unsigned char>(text[i]))) ++i;
  const std::size_t num_digits = i - digits_begin;
  while (i < n && std::isspace(static_cast<unsigned char>(text[i]))) ++i;
  const char hemi =
      i < n ? static_cast<char>(std::toupper(static_cast<unsigned char>(text[i]))) : '\0';
  std::size_t end = i + 1;
  while (end < n && std::isspace(static_cast<unsigned char>(text[end]))) ++end;
  const bool well_formed =
      num_digits >= 1 && num_digits <= 2 && (hemi == 'N' || hemi == 'S') && end >= n;
  GEODRIFT_CHECK(well_formed, "zone '" << text
                                       << "' is not a UTM zone: expected a number 1..60 followed "
                                          "by N or S, e.g. 32N (latitude bands are not accepted)");
  const int z = std::stoi(text.substr(digits_begin, num_digits));
  GEODRIFT_CHECK(z >= kMinUtmZone && z <= kMaxUtmZone,
                 "zone '" << text << "': zone number " << z << " outside [1, 60]");
  *zone = z;
  *northp = hemi == 'N';
}

/// Converts a UTM position to latitude/longitude (degrees) on WGS84, whatever its zone
/// (GeographicLib UTMUPS::Reverse, accuracy about 5 nm).
/// @throws InvalidArgument for non-finite values, a zone outside [1, 60], or a position outside
///         GeographicLib's allowed UTM range (easting [0, 1000] km, northing [-9100, 9600] km
///         north / [900, 19600] km south).
inline Geodetic utm_to_geodetic(const UtmCoordinate& u) {
  detail::check_finite(u.easting, "easting", "utm_to_geodetic");
  detail::check_finite(u.northing, "northing", "utm_to_geodetic");
  detail::check_finite(u.height, "height", "utm_to_geodetic");
  detail::check_zone(u.zone, "utm_to_geodetic");
  Geodetic g;
  g.height = u.height;
  try {
    GeographicLib::UTMUPS::Reverse(u.zone, u.northp, u.easting, u.northing, g.latitude_deg,
                                   g.longitude_deg);
  } catch (const std::exception& e) {
    std::ostringstream os;
    os << std::setprecision(12) << "utm_to_geodetic: UTM position (easting " << u.easting
       << " m, northing " << u.northing << " m, zone " << format_utm_zone(u.zone, u.northp)
       << ") is outside the UTM range: " << e.what();
    ::geodrift::detail::throw_invalid_argument(os.str());
  }
  return g;
}

/// Converts latitude/longitude (degrees) to UTM in the point's standard zone and hemisphere,
/// or in `zone` when it is given (1..60; 0 = standard zone).
/// @throws InvalidArgument for bad inputs or a point outside the chosen zone's allowed range.
inline UtmCoordinate geodetic_to_utm(const Geodetic& g, int zone = 0) {
  detail::check_geodetic(g.latitude_deg, g.longitude_deg, g.height, "geodetic_to_utm");
  if (zone != 0) detail::check_zone(zone, "geodetic_to_utm");
  UtmCoordinate u;
  u.height = g.height;
  try {
    GeographicLib::UTMUPS::Forward(g.latitude_deg, g.longitude_deg, u.zone, u.northp, u.easting,
                                   u.northing,
                                   zone == 0 ? static_cast<int>(GeographicLib::UTMUPS::UTM) : zone);
  } catch (const std::exception& e) {
    std::ostringstream os;
    os << std::setprecision(12) << "geodetic_to_utm: latitude " << g.latitude_deg
       << " deg, longitude " << g.longitude_deg << " deg cannot be projected to UTM zone "
       << (zone == 0 ? std::string("(standard)") : std::to_string(zone)) << ": " << e.what();
    ::geodrift::detail::throw_invalid_argument(os.str());
  }
  return u;
}

}  // namespace geodrift::geo
