#pragma once

// Helpers shared by the geo tests.

#include <GeographicLib/Geodesic.hpp>
#include <catch2/catch.hpp>
#include <cmath>
#include <string>

#include "geodrift/error.hpp"

namespace geodrift::test {

/// Runs f and checks that it throws geodrift::InvalidArgument whose message contains every
/// given fragment (e.g. the argument name and its value).
template <class F>
void require_invalid_argument(const F& f, std::initializer_list<std::string> fragments) {
  bool thrown = false;
  try {
    f();
  } catch (const geodrift::InvalidArgument& e) {
    thrown = true;
    const std::string msg = e.what();
    INFO("message: " << msg);
    for (const std::string& frag : fragments) {
      INFO("expected fragment: " << frag);
      CHECK(msg.find(frag) != std::string::npos);
    }
  } catch (const std::exception& e) {
    FAIL("threw a non-InvalidArgument exception: " << e.what());
  }
  CHECK(thrown);
}

/// Geodesic distance (m) on WGS84 between two lat/lon pairs (degrees).
inline double geodesic_distance(double lat1, double lon1, double lat2, double lon2) {
  double s12 = 0.0;
  GeographicLib::Geodesic::WGS84().Inverse(lat1, lon1, lat2, lon2, s12);
  return s12;
}

}  // namespace geodrift::test
