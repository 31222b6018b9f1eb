#pragma once

/// @file
/// track.kml: the corrected path as KML 2.2 (OGC 07-147r2) for Google Earth and GIS tools: a
/// Placemark with a LineString for the path and one Point Placemark per anchor. Coordinates are
/// "longitude,latitude,height" (WGS84 degrees, 9 decimals). KML altitudes are relative to mean
/// sea level while geodrift's heights are ellipsoidal, so geometry is clamped to the ground
/// (altitudeMode clampToGround) and the ellipsoidal height is kept only as the third coordinate
/// for reference. The Document's description states version, frame and units.

#include <Eigen/Core>
#include <cmath>
#include <string>
#include <vector>

#include "geodrift/error.hpp"
#include "geodrift/geo/local_frame.hpp"
#include "geodrift/io/anchors.hpp"
#include "geodrift/io/detail/text_io.hpp"
#include "geodrift/version.hpp"

namespace geodrift::io {

namespace detail {
inline std::string kml_position(const geo::Geodetic& g) {
  return fmt_fixed(g.longitude_deg, 9) + "," + fmt_fixed(g.latitude_deg, 9) + "," +
         fmt_fixed(g.height, 4);
}
}  // namespace detail

/// Writes track.kml atomically.
/// @param path     output file.
/// @param track_w  camera centres in W, in path order (the path Placemark needs at least 2).
/// @param anchors  anchors in W (one Point Placemark each).
/// @param frame    W's definition.
/// @param note     extra statement (e.g. geo::kKittiGeoOriginNote), may be "".
/// @param name     document name.
/// @throws InvalidArgument if a position is not finite or outside W's zone; Error on I/O failure.
inline void write_kml(const std::string& path, const std::vector<Eigen::Vector3d>& track_w,
                      const std::vector<Anchor>& anchors, const geo::LocalFrame& frame,
                      const std::string& note = "", const std::string& name = "geodrift track") {
  std::vector<geo::Geodetic> track, anchor_g;
  track.reserve(track_w.size());
  for (const Eigen::Vector3d& p : track_w) track.push_back(frame.to_geodetic(p));
  for (const Anchor& a : anchors) anchor_g.push_back(frame.to_geodetic(a.y_w));
  const std::string description =
      std::string("geodrift ") + kVersion +
      ". Coordinates: WGS84 longitude,latitude (degrees), ellipsoidal height (metres, shown "
      "clamped to ground); computed from " +
      frame.description() + "." + (note.empty() ? "" : " ") + note;
  detail::write_atomically(path, [&](std::ostream& os) {
    os << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
       << "<kml xmlns=\"http://www.opengis.net/kml/2.2\">\n<Document>\n"
       << "  <name>" << detail::xml_escape(name) << "</name>\n"
       << "  <description>" << detail::xml_escape(description) << "</description>\n"
       << "  <Style id=\"path\"><LineStyle><color>ff0000ff</color><width>3</width></LineStyle>"
          "</Style>\n"
       << "  <Style id=\"anchor\"><IconStyle><color>ff00ffff</color></IconStyle></Style>\n";
    if (track.size() >= 2) {
      os << "  <Placemark>\n    <name>path</name>\n    <styleUrl>#path</styleUrl>\n"
         << "    <LineString>\n      <tessellate>1</tessellate>\n"
         << "      <altitudeMode>clampToGround</altitudeMode>\n      <coordinates>\n";
      for (const geo::Geodetic& g : track) os << "        " << detail::kml_position(g) << "\n";
      os << "      </coordinates>\n    </LineString>\n  </Placemark>\n";
    }
    for (std::size_t i = 0; i < anchors.size(); ++i) {
      const Anchor& a = anchors[i];
      os << "  <Placemark>\n    <name>anchor " << i << "</name>\n    <description>"
         << detail::xml_escape(
                (a.frame >= 0 ? "frame " + std::to_string(a.frame) : std::string("frame ?")) +
                (std::isfinite(a.timestamp) ? ", timestamp " + detail::fmt(a.timestamp) : "") +
                (std::isfinite(a.sigma_m) ? ", sigma " + detail::fmt(a.sigma_m) + " m" : ""))
         << "</description>\n    <styleUrl>#anchor</styleUrl>\n    <Point>\n"
         << "      <altitudeMode>clampToGround</altitudeMode>\n      <coordinates>"
         << detail::kml_position(anchor_g[i]) << "</coordinates>\n    </Point>\n  </Placemark>\n";
    }
    os << "</Document>\n</kml>\n";
  });
}

}  // namespace geodrift::io
