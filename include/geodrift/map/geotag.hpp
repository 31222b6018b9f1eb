#pragma once

/// @file
/// map::GeoTag: where a geo-tagged image was taken. Latitude and longitude in WGS84 degrees,
/// ellipsoidal height in metres, heading in RADIANS clockwise from true north (NaN when
/// unknown; files carry it in degrees as `heading_deg`). geo::LocalFrame maps it into W.

#include <limits>

namespace geodrift::map {

/// The geo-tag of an image (a panorama, a photo or a GNSS fix). Latitude and longitude are in
/// degrees (named `_deg`, as GeographicLib takes them); height is ellipsoidal, in metres;
/// `heading` is the clockwise bearing from true north of the view's optical axis in radians,
/// NaN when unknown.
struct GeoTag {
  int id = 0;
  double latitude_deg = 0.0;
  double longitude_deg = 0.0;
  double height = 0.0;
  double heading = std::numeric_limits<double>::quiet_NaN();
};

}  // namespace geodrift::map
