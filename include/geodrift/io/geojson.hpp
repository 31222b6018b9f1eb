#pragma once

/// @file
/// track.geojson: the corrected path as a GeoJSON (RFC 7946) FeatureCollection: one LineString
/// feature for the path and one Point feature per anchor. Positions are [longitude, latitude,
/// height] (RFC 7946 §3.1.1: longitude first, WGS84 degrees; the third element is the
/// ellipsoidal height in metres), 9 decimals (~0.1 mm). RFC 7946 has no CRS member; the
/// version, frame and units are stated in a foreign member "geodrift" of the collection
/// (RFC 7946 §6.1) and in the path feature's properties.

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
inline std::string geojson_position(const geo::Geodetic& g) {
  return "[" + fmt_fixed(g.longitude_deg, 9) + "," + fmt_fixed(g.latitude_deg, 9) + "," +
         fmt_fixed(g.height, 4) + "]";
}
}  // namespace detail

/// Writes track.geojson atomically.
/// @param path     output file.
/// @param track_w  camera centres in W, in path order (at least 2 for a LineString; with fewer,
///                 the path feature is omitted).
/// @param anchors  anchor positions in W (Point features with frame, timestamp, sigma_m).
/// @param frame    W's definition.
/// @param note     extra statement (e.g. geo::kKittiGeoOriginNote), may be "".
/// @throws InvalidArgument if a position is not finite or outside W's zone; Error on I/O failure.
inline void write_geojson(const std::string& path, const std::vector<Eigen::Vector3d>& track_w,
                          const std::vector<Anchor>& anchors, const geo::LocalFrame& frame,
                          const std::string& note = "") {
  std::vector<geo::Geodetic> track, anchor_g;
  track.reserve(track_w.size());
  for (const Eigen::Vector3d& p : track_w) track.push_back(frame.to_geodetic(p));
  for (const Anchor& a : anchors) anchor_g.push_back(frame.to_geodetic(a.y_w));
  const std::string frame_text =
      "WGS84 [longitude, latitude] degrees, ellipsoidal height metres; "
      "computed from " +
      frame.description();
  detail::write_atomically(path, [&](std::ostream& os) {
    os << "{\n  \"type\": \"FeatureCollection\",\n  \"geodrift\": {\"version\": "
       << detail::json_string(kVersion) << ", \"frame\": " << detail::json_string(frame_text)
       << ", \"units\": \"degrees, metres\", \"note\": " << detail::json_string(note)
       << "},\n  \"features\": [";
    bool first = true;
    if (track.size() >= 2) {
      os << "\n    {\"type\": \"Feature\", \"properties\": {\"name\": \"path\", \"generator\": "
         << detail::json_string(std::string("geodrift ") + kVersion)
         << ", \"num_positions\": " << track.size()
         << "},\n     \"geometry\": {\"type\": \"LineString\", \"coordinates\": [";
      for (std::size_t i = 0; i < track.size(); ++i)
        os << (i ? "," : "") << (i % 4 == 0 ? "\n       " : " ")
           << detail::geojson_position(track[i]);
      os << "]}}";
      first = false;
    }
    for (std::size_t i = 0; i < anchors.size(); ++i) {
      const Anchor& a = anchors[i];
      os << (first ? "" : ",") << "\n    {\"type\": \"Feature\", \"properties\": {\"name\": "
         << detail::json_string("anchor " + std::to_string(i))
         << ", \"frame\": " << (a.frame >= 0 ? std::to_string(a.frame) : std::string("null"))
         << ", \"timestamp\": "
         << (std::isfinite(a.timestamp) ? detail::fmt(a.timestamp) : std::string("null"))
         << ", \"sigma_m\": "
         << (std::isfinite(a.sigma_m) ? detail::fmt(a.sigma_m) : std::string("null"))
         << "},\n     \"geometry\": {\"type\": \"Point\", \"coordinates\": "
         << detail::geojson_position(anchor_g[i]) << "}}";
      first = false;
    }
    os << "\n  ]\n}\n";
  });
}

}  // namespace geodrift::io
