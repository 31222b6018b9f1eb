// LocalFrame: lat/lon/height <-> UTM <-> W, known UTM answers, heading <-> grid yaw, bad input.

#include "geodrift/geo/local_frame.hpp"

#include <Eigen/LU>
#include <GeographicLib/Geodesic.hpp>
#include <catch2/catch.hpp>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "geo_test_util.hpp"
#include "geodrift/geo/utm.hpp"

using geodrift::geo::Geodetic;
using geodrift::geo::LocalFrame;
using geodrift::geo::UtmCoordinate;
using geodrift::test::geodesic_distance;
using geodrift::test::require_invalid_argument;

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;
constexpr double kMm = 1e-3;

// Published UTM <-> latitude/longitude pairs on WGS84, to 1 mm or better, from an
// implementation independent of GeographicLib: Chris Veness, "Geodesy functions" (movable-type
// scripts), test suite test/utm-mgrs-tests.js, sections "latitude/longitude -> UTM" and
// "UTM -> latitude/longitude" (https://github.com/chrisveness/geodesy, MIT licence; values
// also at https://www.movable-type.co.uk/scripts/latlong-utm-mgrs.html). The point zone is the
// standard one, including Norway's exception for Bergen (zone 32 at 5.3°E).
struct Reference {
  const char* name;
  double latitude_deg, longitude_deg;
  int zone;
  bool northp;
  double easting, northing;
};
const Reference kReferences[] = {
    {"0,0", 0.0, 0.0, 31, true, 166021.443081, 0.000000},
    {"1,1", 1.0, 1.0, 31, true, 277438.263521, 110597.972524},
    {"-1,-1", -1.0, -1.0, 30, false, 722561.736479, 9889402.027476},
    {"eiffel tower", 48.8583, 2.2945, 31, true, 448251.898, 5411943.794},
    {"sydney opera house", -33.857, 151.215, 56, false, 334873.199, 6252266.092},
    {"white house", 38.8977, -77.0365, 18, true, 323394.296, 4307395.634},
    {"rio christ", -22.9519, -43.2106, 23, false, 683466.254, 7460687.433},
    {"bergen", 60.39135, 5.3249, 32, true, 297508.410, 6700645.296},
};

// A frame whose W equals the zone's UTM grid minus a round origin.
LocalFrame grid_frame(int zone, bool northp) {
  return LocalFrame::from_utm(zone, northp, 500000.0, northp ? 0.0 : 1.0e7, 0.0);
}

// Random geodetic point in a box around (lat0, lon0).
Geodetic random_point_near(std::mt19937& rng, double lat0, double lon0, double dlat, double dlon) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::uniform_real_distribution<double> h(-200.0, 3000.0);
  return {lat0 + dlat * u(rng), lon0 + dlon * u(rng), h(rng)};
}

}  // namespace

TEST_CASE("UTM conversions reproduce published reference pairs to 1 mm", "[geo][utm]") {
  for (const Reference& r : kReferences) {
    INFO("reference " << r.name);
    // Zone selection of the standard rules.
    CHECK(geodrift::geo::standard_utm_zone(r.latitude_deg, r.longitude_deg) == r.zone);

    // lat/lon -> UTM through the free function (standard zone, point's hemisphere).
    const UtmCoordinate u = geodrift::geo::geodetic_to_utm({r.latitude_deg, r.longitude_deg, 0});
    CHECK(u.zone == r.zone);
    CHECK(u.northp == r.northp);
    CHECK(std::abs(u.easting - r.easting) < kMm);
    CHECK(std::abs(u.northing - r.northing) < kMm);

    // lat/lon -> W -> UTM through a LocalFrame of that zone.
    const LocalFrame frame = grid_frame(r.zone, r.northp);
    const Eigen::Vector3d p = frame.to_world(r.latitude_deg, r.longitude_deg, 12.5);
    CHECK(std::abs(p.x() + 500000.0 - r.easting) < kMm);
    CHECK(std::abs(p.y() + (r.northp ? 0.0 : 1.0e7) - r.northing) < kMm);
    CHECK(p.z() == Approx(12.5).margin(1e-12));
    const UtmCoordinate back = frame.utm_of(p);
    CHECK(back.zone == r.zone);
    CHECK(back.northp == r.northp);
    CHECK(std::abs(back.easting - r.easting) < kMm);
    CHECK(std::abs(back.northing - r.northing) < kMm);

    // UTM -> lat/lon: the published UTM (rounded to 1 mm) maps back to within 1 mm on the
    // ellipsoid.
    const Eigen::Vector3d q(r.easting - 500000.0, r.northing - (r.northp ? 0.0 : 1.0e7), 0.0);
    const Geodetic g = frame.to_geodetic(q);
    CHECK(geodesic_distance(g.latitude_deg, g.longitude_deg, r.latitude_deg, r.longitude_deg) <
          kMm);
    const Geodetic g2 = geodrift::geo::utm_to_geodetic({r.easting, r.northing, r.zone, r.northp});
    CHECK(geodesic_distance(g2.latitude_deg, g2.longitude_deg, r.latitude_deg, r.longitude_deg) <
          kMm);
  }
}

TEST_CASE("Meridian convergence and scale match the published Bergen values", "[geo][utm]") {
  // Same source as kReferences: Bergen, 32N, convergence -3.196281440 deg, scale 1.000102473211.
  const LocalFrame frame = grid_frame(32, true);
  const Eigen::Vector3d p = frame.to_world(60.39135, 5.3249, 0.0);
  CHECK(frame.meridian_convergence(p) / kDeg == Approx(-3.196281440).margin(2e-9));
  CHECK(frame.scale_factor(p) == Approx(1.000102473211).margin(2e-12));
  // Central meridian: no convergence, scale 0.9996 on the equator.
  const Eigen::Vector3d c = frame.to_world(0.0, 9.0, 0.0);
  CHECK(std::abs(frame.meridian_convergence(c)) < 1e-15);
  CHECK(frame.scale_factor(c) == Approx(0.9996).margin(1e-15));
}

TEST_CASE("LocalFrame round trips to 1 mm over seeded random points", "[geo][local_frame]") {
  std::mt19937 rng(42);
  struct Origin {
    const char* name;
    double lat, lon, h;
  };
  // Northern mid-latitude (KITTI), southern hemisphere, both sides of the equator, high north.
  const Origin origins[] = {
      {"karlsruhe", 49.0110, 8.4170, 160.0}, {"sydney", -33.857, 151.215, 20.0},
      {"equator north", 0.2, 33.0, 1200.0},  {"equator south", -0.2, 33.0, 1200.0},
      {"tromso", 69.65, 18.95, 10.0},        {"west hemisphere", 38.8977, -77.0365, 50.0}};
  int num_other_zone = 0, num_other_hemisphere = 0;
  for (const Origin& o : origins) {
    const LocalFrame frame = LocalFrame::from_geodetic(o.lat, o.lon, o.h);
    INFO("origin " << o.name << " zone " << frame.zone_string());
    CHECK(frame.zone() == geodrift::geo::standard_utm_zone(o.lat, o.lon));
    CHECK(frame.northp() == (o.lat >= 0.0));
    // The origin maps to W's zero.
    CHECK(frame.to_world(o.lat, o.lon, o.h).norm() < 1e-9);
    const Geodetic og = frame.origin_geodetic();
    CHECK(geodesic_distance(og.latitude_deg, og.longitude_deg, o.lat, o.lon) < 1e-6);

    // Boxes of ±1° latitude and ±3° longitude cross the zone boundary (and the equator for the
    // equatorial origins); 1000 points per origin.
    const double dlon = o.lat > 60.0 ? 5.0 : 3.0;
    for (int i = 0; i < 1000; ++i) {
      const Geodetic g = random_point_near(rng, o.lat, o.lon, 1.0, dlon);
      INFO("point " << i << ": " << g.latitude_deg << ", " << g.longitude_deg);
      const Eigen::Vector3d p = frame.to_world(g);
      const Geodetic g2 = frame.to_geodetic(p);
      CHECK(geodesic_distance(g.latitude_deg, g.longitude_deg, g2.latitude_deg, g2.longitude_deg) <
            kMm);
      CHECK(std::abs(g2.height - g.height) < kMm);

      // W -> UTM stays in W's zone whatever the point's standard zone.
      const UtmCoordinate u = frame.utm_of(p);
      CHECK(u.zone == frame.zone());
      CHECK(u.northp == (g.latitude_deg >= 0.0));
      if (geodrift::geo::standard_utm_zone(g.latitude_deg, g.longitude_deg) != frame.zone())
        ++num_other_zone;
      if (u.northp != frame.northp()) ++num_other_hemisphere;
      // UTM in W's zone -> W, and UTM of the point's standard zone -> W (transfer) agree.
      CHECK((frame.to_world(u) - p).norm() < kMm);
      const UtmCoordinate s = geodrift::geo::geodetic_to_utm(g);
      CHECK((frame.to_world(s) - p).norm() < kMm);

      // W -> geodetic -> W from a random W point.
      std::uniform_real_distribution<double> w(-50000.0, 50000.0);
      const Eigen::Vector3d q(w(rng), w(rng), w(rng) * 0.01);
      CHECK((frame.to_world(frame.to_geodetic(q)) - q).norm() < kMm);
    }
  }
  // The samples really did cross zone boundaries and the equator.
  CHECK(num_other_zone > 500);
  CHECK(num_other_hemisphere > 200);
}

TEST_CASE("W is continuous across a zone boundary and across the equator", "[geo][local_frame]") {
  const GeographicLib::Geodesic& geod = GeographicLib::Geodesic::WGS84();
  SECTION("zone boundary at 12°E") {
    const LocalFrame frame = LocalFrame::from_geodetic(49.0, 11.99, 100.0);
    REQUIRE(frame.zone() == 32);
    const double lon_a = 11.9995, lon_b = 12.0005;  // standard zones 32 and 33
    REQUIRE(geodrift::geo::standard_utm_zone(49.0, lon_b) == 33);
    const Eigen::Vector3d a = frame.to_world(49.0, lon_a, 100.0);
    const Eigen::Vector3d b = frame.to_world(49.0, lon_b, 100.0);
    double s = 0.0;
    geod.Inverse(49.0, lon_a, 49.0, lon_b, s);
    // A short grid segment is the ellipsoid segment times the point scale.
    const double k = frame.scale_factor(0.5 * (a + b));
    CHECK(std::abs((b - a).norm() - k * s) < 1e-4);
    CHECK(frame.utm_of(b).zone == 32);
    // The neighbouring zone's own coordinates transfer to the same W point.
    const UtmCoordinate b33 = geodrift::geo::geodetic_to_utm({49.0, lon_b, 100.0});
    REQUIRE(b33.zone == 33);
    CHECK((frame.to_world(b33) - b).norm() < kMm);
    // Far inside zone 33 (3° beyond the boundary) still works in zone 32.
    const Eigen::Vector3d far = frame.to_world(49.0, 15.0, 0.0);
    const Geodetic gf = frame.to_geodetic(far);
    CHECK(geodesic_distance(gf.latitude_deg, gf.longitude_deg, 49.0, 15.0) < kMm);
  }
  SECTION("equator, northern and southern frames") {
    for (const double lat0 : {0.3, -0.3}) {
      const LocalFrame frame = LocalFrame::from_geodetic(lat0, 33.0, 0.0);
      INFO("frame " << frame.zone_string());
      const Eigen::Vector3d a = frame.to_world(0.0005, 33.0, 0.0);
      const Eigen::Vector3d b = frame.to_world(-0.0005, 33.0, 0.0);
      double s = 0.0;
      geod.Inverse(0.0005, 33.0, -0.0005, 33.0, s);
      CHECK(std::abs((a - b).norm() - 0.9996 * s) < 1e-4);
      CHECK(a.y() > b.y());  // north is +y on both sides
      const UtmCoordinate ub = frame.utm_of(b), ua = frame.utm_of(a);
      CHECK_FALSE(ub.northp);
      CHECK(ua.northp);
      CHECK(ub.northing == Approx(1.0e7 - 0.9996 * s / 2).margin(0.01));
      CHECK(ua.northing == Approx(0.9996 * s / 2).margin(0.01));
    }
  }
}

TEST_CASE("True heading <-> grid yaw matches a 1 m geodesic step", "[geo][heading]") {
  // Numeric reference independent of the convergence formula: walk 1 m from a point along a true
  // azimuth with GeographicLib::Geodesic, project both ends into W, and take the grid direction.
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> azimuth(0.0, 360.0);
  const GeographicLib::Geodesic& geod = GeographicLib::Geodesic::WGS84();
  const LocalFrame frames[] = {LocalFrame::from_geodetic(49.0110, 8.4170, 160.0),
                               LocalFrame::from_geodetic(-33.857, 151.215, 0.0),
                               LocalFrame::from_geodetic(64.0, -21.9, 0.0)};
  double max_gamma = 0.0;
  for (const LocalFrame& frame : frames) {
    const Geodetic o = frame.origin_geodetic();
    for (int i = 0; i < 300; ++i) {
      const Geodetic g = random_point_near(rng, o.latitude_deg, o.longitude_deg, 1.0, 3.0);
      const double heading_deg = azimuth(rng);
      double lat2 = 0.0, lon2 = 0.0;
      geod.Direct(g.latitude_deg, g.longitude_deg, heading_deg, 1.0, lat2, lon2);
      const Eigen::Vector3d p = frame.to_world(g);
      const Eigen::Vector3d d = frame.to_world(lat2, lon2, g.height) - p;
      const double yaw_numeric = std::atan2(d.y(), d.x());
      const double heading = heading_deg * kDeg;
      const double yaw = frame.grid_yaw_from_heading(heading, p);
      INFO("frame " << frame.zone_string() << " sample " << i << " heading " << heading_deg);
      CHECK(std::abs(geodrift::geo::detail::wrap_to_pi(yaw - yaw_numeric)) < 1e-7);
      CHECK(yaw > -kPi);
      CHECK(yaw <= kPi);
      const double heading_back = frame.heading_from_grid_yaw(yaw, p);
      CHECK(std::abs(geodrift::geo::detail::wrap_to_pi(heading_back - heading)) < 1e-12);
      CHECK(heading_back >= 0.0);
      CHECK(heading_back < 2.0 * kPi);
      // A level camera built from the heading reports the same heading and looks along d.
      const Eigen::Matrix3d R_wc = frame.level_camera_rotation_from_heading(heading, p);
      CHECK((R_wc.transpose() * R_wc - Eigen::Matrix3d::Identity()).norm() < 1e-12);
      CHECK(R_wc.determinant() == Approx(1.0).margin(1e-12));
      CHECK(std::abs(geodrift::geo::detail::wrap_to_pi(frame.camera_heading(R_wc, p) - heading)) <
            1e-12);
      CHECK((R_wc.col(2).head<2>() - d.head<2>() / d.head<2>().norm()).norm() < 1e-7);
      max_gamma = std::max(max_gamma, std::abs(frame.meridian_convergence(p)));
    }
  }
  // The convergence is large enough here that ignoring it would fail the checks above.
  CHECK(max_gamma > 2.0 * kDeg);
}

TEST_CASE(
    "Meridian convergence has GeographicLib's sign: grid north east of true north east of "
    "the central meridian in the north",
    "[geo][heading]") {
  const LocalFrame frame = LocalFrame::from_geodetic(49.0, 9.0, 0.0);  // zone 32, CM 9°E
  const Eigen::Vector3d east = frame.to_world(49.0, 11.0, 0.0);
  const Eigen::Vector3d west = frame.to_world(49.0, 7.0, 0.0);
  // γ ≈ (λ - λ0) sin φ.
  CHECK(frame.meridian_convergence(east) / kDeg ==
        Approx(2.0 * std::sin(49.0 * kDeg)).epsilon(0.01));
  CHECK(frame.meridian_convergence(west) / kDeg ==
        Approx(-2.0 * std::sin(49.0 * kDeg)).epsilon(0.01));
  // A camera looking at grid north east of the CM looks a little east of true north.
  CHECK(frame.heading_from_grid_yaw(kPi / 2, east) / kDeg ==
        Approx(2.0 * std::sin(49.0 * kDeg)).epsilon(0.01));
}

TEST_CASE("Zone strings parse and format", "[geo][utm]") {
  int zone = 0;
  bool northp = false;
  geodrift::geo::parse_utm_zone("32N", &zone, &northp);
  CHECK(zone == 32);
  CHECK(northp);
  geodrift::geo::parse_utm_zone(" 7 s ", &zone, &northp);
  CHECK(zone == 7);
  CHECK_FALSE(northp);
  geodrift::geo::parse_utm_zone("60n", &zone, &northp);
  CHECK(zone == 60);
  CHECK(northp);
  CHECK(geodrift::geo::format_utm_zone(56, false) == "56S");
  CHECK(LocalFrame::from_geodetic(49.0110, 8.4170, 160.0).zone_string() == "32N");
  for (const char* bad : {"32U", "61N", "0N", "", "N", "abc", "032N", "32NN", "32 N x", "-3N"}) {
    INFO("zone string '" << bad << "'");
    require_invalid_argument([&] { geodrift::geo::parse_utm_zone(bad, &zone, &northp); },
                             {"zone '" + std::string(bad) + "'"});
  }
}

TEST_CASE("LocalFrame rejects bad input with InvalidArgument naming the argument",
          "[geo][local_frame][errors]") {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  const LocalFrame frame = LocalFrame::from_geodetic(49.0110, 8.4170, 160.0);

  // Geodetic inputs.
  require_invalid_argument([&] { frame.to_world(nan, 8.4, 0.0); }, {"latitude", "nan"});
  require_invalid_argument([&] { frame.to_world(49.0, inf, 0.0); }, {"longitude", "inf"});
  require_invalid_argument([&] { frame.to_world(49.0, 8.4, -inf); }, {"height", "inf"});
  require_invalid_argument([&] { frame.to_world(91.2, 8.4, 0.0); },
                           {"latitude", "91.2", "[-90, 90]"});
  require_invalid_argument([&] { frame.to_world(-90.5, 8.4, 0.0); }, {"latitude", "-90.5"});
  require_invalid_argument([&] { frame.to_world(49.0, 180.5, 0.0); },
                           {"longitude", "180.5", "[-180, 180]"});
  require_invalid_argument([&] { frame.to_world(49.0, -181.0, 0.0); }, {"longitude", "-181"});
  // Valid geodetic input that W's zone cannot hold: far outside the zone, or polar.
  require_invalid_argument([&] { frame.to_world(49.0, 40.0, 0.0); },
                           {"LocalFrame::to_world", "longitude 40", "32N"});
  require_invalid_argument([&] { frame.to_world(89.5, 8.4, 0.0); },
                           {"LocalFrame::to_world", "latitude 89.5"});

  // Constructors.
  require_invalid_argument([&] { LocalFrame::from_geodetic(nan, 8.0, 0.0); }, {"latitude", "nan"});
  require_invalid_argument([&] { LocalFrame::from_geodetic(95.0, 8.0, 0.0); }, {"latitude", "95"});
  require_invalid_argument([&] { LocalFrame::from_geodetic(49.0, 200.0, 0.0); },
                           {"longitude", "200"});
  require_invalid_argument([&] { LocalFrame::from_geodetic(49.0, 8.0, nan); }, {"height", "nan"});
  require_invalid_argument([&] { LocalFrame::from_geodetic(49.0, 8.0, 0.0, 61); }, {"zone", "61"});
  require_invalid_argument([&] { LocalFrame::from_geodetic(49.0, 8.0, 0.0, -1); }, {"zone", "-1"});
  require_invalid_argument([&] { LocalFrame::from_geodetic(49.0, 8.0, 0.0, 45); },
                           {"latitude 49", "45"});
  require_invalid_argument([&] { LocalFrame::from_utm(0, true, 500000.0, 0.0, 0.0); },
                           {"zone", "0"});
  require_invalid_argument([&] { LocalFrame::from_utm(32, true, nan, 0.0, 0.0); },
                           {"easting0", "nan"});
  require_invalid_argument([&] { LocalFrame::from_utm(32, true, 500000.0, inf, 0.0); },
                           {"northing0", "inf"});
  require_invalid_argument([&] { LocalFrame::from_utm(32, true, 500000.0, 0.0, nan); },
                           {"height0", "nan"});
  require_invalid_argument([&] { LocalFrame::from_utm(32, true, -2.0e6, 0.0, 0.0); },
                           {"easting", "outside the UTM range"});

  // W points, headings, UTM coordinates.
  require_invalid_argument([&] { frame.to_geodetic(Eigen::Vector3d(nan, 0, 0)); },
                           {"world point", "nan"});
  require_invalid_argument([&] { frame.to_geodetic(Eigen::Vector3d(2.0e6, 0, 0)); },
                           {"world point", "outside the UTM range"});
  require_invalid_argument([&] { frame.utm_of(Eigen::Vector3d(0, inf, 0)); },
                           {"world point", "inf"});
  require_invalid_argument([&] { frame.meridian_convergence(Eigen::Vector3d(0, 0, nan)); },
                           {"world point"});
  require_invalid_argument([&] { frame.grid_yaw_from_heading(nan, Eigen::Vector3d::Zero()); },
                           {"heading", "nan"});
  require_invalid_argument([&] { frame.heading_from_grid_yaw(inf, Eigen::Vector3d::Zero()); },
                           {"yaw", "inf"});
  require_invalid_argument(
      [&] {
        frame.to_world(UtmCoordinate{nan, 5.4e6, 32, true, 0.0});
      },
      {"easting", "nan"});
  require_invalid_argument(
      [&] {
        frame.to_world(UtmCoordinate{500000.0, 5.4e6, 61, true, 0.0});
      },
      {"zone", "61"});
  require_invalid_argument([&] { geodrift::geo::standard_utm_zone(100.0, 0.0); },
                           {"latitude", "100"});
  require_invalid_argument(
      [&] { geodrift::geo::optical_axis_grid_yaw(Eigen::Matrix3d::Identity() * nan); },
      {"R_wc", "not finite"});
  Eigen::Matrix3d looking_down;
  looking_down << 1, 0, 0, 0, -1, 0, 0, 0, -1;  // optical axis = -z of W
  require_invalid_argument([&] { geodrift::geo::optical_axis_grid_yaw(looking_down); },
                           {"vertical"});
  require_invalid_argument([&] { geodrift::geo::level_camera_rotation(nan); }, {"grid_yaw", "nan"});
}

TEST_CASE("Angle wrapping stays in its documented ranges", "[geo][heading]") {
  using geodrift::geo::detail::wrap_to_pi;
  using geodrift::geo::detail::wrap_to_two_pi;
  CHECK(wrap_to_pi(kPi) == Approx(kPi));
  CHECK(wrap_to_pi(-kPi) == Approx(kPi));
  CHECK(wrap_to_pi(3.0 * kPi / 2) == Approx(-kPi / 2));
  CHECK(wrap_to_two_pi(-1e-18) < 2.0 * kPi);
  CHECK(wrap_to_two_pi(-kPi / 2) == Approx(3.0 * kPi / 2));
  CHECK(wrap_to_two_pi(5.0 * kPi) == Approx(kPi));
}
