// render::World: route processing, procedural object placement, the acceleration grids and
// ray tracing.
#include "geodrift/render/world.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <unordered_map>

#include "geodrift/error.hpp"
#include "geodrift/geo/kitti.hpp"
#include "world_impl.hpp"

namespace geodrift::render {

using detail::Box;
using detail::Hit;
using detail::Rng;
using detail::Sphere;

// ---- Appearance --------------------------------------------------------------------------------

Eigen::Vector3d Appearance::sun_from_azimuth_elevation(double azimuth_deg, double elevation_deg) {
  const double a = azimuth_deg * M_PI / 180.0, e = elevation_deg * M_PI / 180.0;
  // Azimuth clockwise from grid north (+y): east = +x.
  return Eigen::Vector3d(std::sin(a) * std::cos(e), std::cos(a) * std::cos(e), std::sin(e));
}

Appearance Appearance::video() {
  Appearance a;
  a.sun_direction = sun_from_azimuth_elevation(135.0, 40.0);
  a.sun_intensity = 0.75;
  a.ambient_intensity = 0.45;
  a.white_balance = Eigen::Vector3d(1.0, 1.0, 1.0);
  a.street_view_content = false;
  return a;
}

Appearance Appearance::street_view() {
  Appearance a;
  a.sun_direction = sun_from_azimuth_elevation(235.0, 58.0);
  a.sun_intensity = 0.75 * 1.4;
  a.ambient_intensity = 0.45 * 0.8;
  a.white_balance = Eigen::Vector3d(1.10, 1.00, 0.85);
  a.street_view_content = true;
  return a;
}

// ---- BuildingInfo ------------------------------------------------------------------------------

std::vector<Eigen::Vector3d> BuildingInfo::corners() const {
  const Eigen::Vector2d ax(std::cos(yaw), std::sin(yaw)), ay(-std::sin(yaw), std::cos(yaw));
  std::vector<Eigen::Vector3d> c;
  const double sx[4] = {-1, 1, 1, -1}, sy[4] = {-1, -1, 1, 1};
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector2d p = centre + sx[k] * half_length * ax + sy[k] * half_depth * ay;
    c.emplace_back(p.x(), p.y(), base_z);
  }
  return c;
}

// ---- route queries
// -------------------------------------------------------------------------------

Eigen::Vector3d World::Impl::route_at(double s) const {
  if (s <= ps.front()) return pv.front();
  if (s >= ps.back()) return pv.back();
  const auto it = std::upper_bound(ps.begin(), ps.end(), s);
  const std::size_t j = static_cast<std::size_t>(it - ps.begin()) - 1;
  const double len = ps[j + 1] - ps[j];
  const double a = len > 0 ? (s - ps[j]) / len : 0.0;
  return (1 - a) * pv[j] + a * pv[j + 1];
}

RoutePoint World::Impl::nearest_route(double x, double y, double* dist) const {
  int ix = static_cast<int>(std::floor((x - gx0) / gcell));
  int iy = static_cast<int>(std::floor((y - gy0) / gcell));
  ix = std::clamp(ix, 0, gnx - 1);
  iy = std::clamp(iy, 0, gny - 1);
  const int k = nearest[static_cast<std::size_t>(iy) * gnx + ix];
  const int nseg = static_cast<int>(pv.size()) - 1;
  const int j0 = std::max(0, k - 3), j1 = std::min(nseg - 1, k + 2);
  double best = std::numeric_limits<double>::infinity(), best_a = 0;
  int best_j = j0;
  for (int j = j0; j <= j1; ++j) {
    const double ax = pv[j].x(), ay = pv[j].y();
    const double bx = pv[j + 1].x() - ax, by = pv[j + 1].y() - ay;
    const double l2 = bx * bx + by * by;
    double a = l2 > 0 ? ((x - ax) * bx + (y - ay) * by) / l2 : 0.0;
    a = std::clamp(a, 0.0, 1.0);
    const double qx = ax + a * bx - x, qy = ay + a * by - y;
    const double d2 = qx * qx + qy * qy;
    if (d2 < best) {
      best = d2;
      best_a = a;
      best_j = j;
    }
  }
  RoutePoint rp;
  {
    const int j = best_j;
    const double a = best_a;
    const double bx = pv[j + 1].x() - pv[j].x(), by = pv[j + 1].y() - pv[j].y();
    const double l = std::sqrt(bx * bx + by * by);
    rp.s = ps[j] + a * (ps[j + 1] - ps[j]);
    rp.camera_z = pv[j].z() + a * (pv[j + 1].z() - pv[j].z());
    if (l > 0) rp.tangent = Eigen::Vector2d(bx / l, by / l);
    const double qx = pv[j].x() + a * bx, qy = pv[j].y() + a * by;
    rp.d = (x - qx) * rp.tangent.y() - (y - qy) * rp.tangent.x();
  }
  if (dist) *dist = std::sqrt(best);
  return rp;
}

double World::Impl::ground_z(double x, double y, RoutePoint* rp) const {
  if (rp) *rp = nearest_route(x, y);
  return ground_fast(x, y);
}

// ---- construction ------------------------------------------------------------------------------

namespace {

/// Separating-axis overlap test of two rotated rectangles (centre, axis cos/sin, half sizes).
bool rects_overlap(const Box& a, const Box& b, double pad) {
  const double axes[4][2] = {{a.ca, a.sa}, {-a.sa, a.ca}, {b.ca, b.sa}, {-b.sa, b.ca}};
  const double dx = b.cx - a.cx, dy = b.cy - a.cy;
  for (const auto& ax : axes) {
    const double ra = (a.hx + pad) * std::abs(a.ca * ax[0] + a.sa * ax[1]) +
                      (a.hy + pad) * std::abs(-a.sa * ax[0] + a.ca * ax[1]);
    const double rb = (b.hx + pad) * std::abs(b.ca * ax[0] + b.sa * ax[1]) +
                      (b.hy + pad) * std::abs(-b.sa * ax[0] + b.ca * ax[1]);
    if (std::abs(dx * ax[0] + dy * ax[1]) > ra + rb) return false;
  }
  return true;
}

detail::Vec3f rgb(double r, double g, double b) {
  return detail::Vec3f(static_cast<float>(r), static_cast<float>(g), static_cast<float>(b));
}

/// A facade style drawn from `rng` for a face of the given width and storeys.
detail::FaceStyle make_style(Rng& rng, float width, int storeys, float storey_h,
                             bool shop_allowed) {
  detail::FaceStyle f;
  f.seed = static_cast<std::uint32_t>(rng.next() >> 32);
  const double r = rng.uniform();
  f.wall = r < 0.38 ? 0 : r < 0.78 ? 1 : r < 0.92 ? 2 : 3;
  if (f.wall == 0) {  // brick: reds, browns, yellows
    const double k = rng.uniform();
    f.wall_rgb = k < 0.5   ? rgb(rng.uniform(0.35, 0.5), rng.uniform(0.14, 0.22), 0.1)
                 : k < 0.8 ? rgb(0.45, 0.33, 0.22) * static_cast<float>(rng.uniform(0.8, 1.1))
                           : rgb(0.62, 0.52, 0.33);
  } else if (f.wall == 1) {  // plaster: pale colours
    f.wall_rgb = rgb(rng.uniform(0.45, 0.8), rng.uniform(0.45, 0.75), rng.uniform(0.35, 0.7));
  } else if (f.wall == 2) {  // stone
    const float g = static_cast<float>(rng.uniform(0.4, 0.6));
    f.wall_rgb = rgb(g, g * 0.97f, g * 0.9f);
  } else {  // glass curtain wall: dark blue-grey panels
    f.wall_rgb = rgb(0.18, 0.22, 0.28);
  }
  f.trim_rgb = rng.chance(0.5) ? rgb(0.82, 0.8, 0.74) : f.wall_rgb * 0.7f;
  f.frame_rgb = rng.chance(0.6)   ? rgb(0.88, 0.88, 0.86)
                : rng.chance(0.5) ? rgb(0.3, 0.2, 0.12)
                                  : rgb(0.15, 0.16, 0.17);
  f.storey_h = storey_h;
  f.storeys = storeys;
  f.width = width;
  f.win_w = static_cast<float>(rng.uniform(0.9, 1.6));
  f.win_h = static_cast<float>(rng.uniform(1.2, std::min(1.9, storey_h - 1.1)));
  f.sill = static_cast<float>(rng.uniform(0.7, storey_h - f.win_h - 0.35));
  f.pitch = static_cast<float>(f.win_w + rng.uniform(0.8, 2.2));
  f.n_cols = std::max(0, static_cast<int>((width - 1.0f) / f.pitch));
  f.offset = 0.5f * (width - f.n_cols * f.pitch);
  f.shop = shop_allowed && rng.chance(0.55);
  f.shop_unit = static_cast<float>(rng.uniform(4.5, 8.0));
  const double hue = rng.uniform();
  f.sign_rgb = hue < 0.25   ? rgb(0.65, 0.08, 0.06)
               : hue < 0.5  ? rgb(0.06, 0.2, 0.5)
               : hue < 0.75 ? rgb(0.08, 0.35, 0.12)
                            : rgb(0.1, 0.1, 0.1);
  f.text_rgb = rng.chance(0.7) ? rgb(0.95, 0.95, 0.9) : rgb(0.95, 0.8, 0.1);
  f.brick_w = static_cast<float>(rng.uniform(0.22, 0.3));
  f.brick_h = static_cast<float>(rng.uniform(0.065, 0.09));
  f.door_col = f.n_cols > 0 ? rng.integer(0, f.n_cols - 1) : -1;
  return f;
}

}  // namespace

World::World(const std::vector<Eigen::Isometry3d>& T_W_c, const WorldOptions& opt) {
  auto impl = std::make_shared<Impl>();
  Impl& w = *impl;
  const int n = static_cast<int>(T_W_c.size());
  GEODRIFT_CHECK(n >= 2, "render::World: " << n << " poses, need at least 2");
  for (int i = 0; i < n; ++i)
    GEODRIFT_CHECK(T_W_c[i].matrix().allFinite(), "render::World: pose " << i << " is not finite");
  WorldOptions o = opt;
  if (o.last_frame < 0) o.last_frame = n - 1;
  GEODRIFT_CHECK(o.first_frame >= 0 && o.first_frame < n,
                 "render::World: first frame " << o.first_frame << " outside [0, " << n - 1 << "]");
  GEODRIFT_CHECK(o.last_frame >= o.first_frame && o.last_frame < n,
                 "render::World: last frame " << o.last_frame << " outside [" << o.first_frame
                                              << ", " << n - 1 << "]");
  GEODRIFT_CHECK(std::isfinite(o.margin_m) && o.margin_m >= 0,
                 "render::World: margin " << o.margin_m << " m must be >= 0");
  GEODRIFT_CHECK(std::isfinite(o.camera_height_m) && o.camera_height_m > 0,
                 "render::World: camera height " << o.camera_height_m << " m must be > 0");
  w.options = o;
  w.T_W_c = T_W_c;
  w.frame = geo::kitti_local_frame();

  // Route polyline.
  w.frame_vertex.resize(n);
  w.frame_s.resize(n);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d c = T_W_c[i].translation();
    if (w.pv.empty() || (c - w.pv.back()).norm() > 0.05) {
      w.ps.push_back(w.pv.empty() ? 0.0 : w.ps.back() + (c - w.pv.back()).head<2>().norm());
      w.pv.push_back(c);
    }
    w.frame_vertex[i] = static_cast<int>(w.pv.size()) - 1;
    w.frame_s[i] = w.ps.back();
  }
  if (w.pv.size() < 2) {  // a stationary sequence: add a tiny segment so queries stay defined
    w.pv.push_back(w.pv.back() + Eigen::Vector3d(0, 0.01, 0));
    w.ps.push_back(0.01);
  }
  const double s_first = w.frame_s[o.first_frame], s_last = w.frame_s[o.last_frame];
  GEODRIFT_CHECK(o.first_frame == o.last_frame || s_last - s_first >= 0.0,
                 "render::World: route is degenerate");
  w.s_lo = s_first - o.margin_m;
  w.s_hi = s_last + o.margin_m;

  // Nearest-vertex grid over the generated stretch (+100 m for far ground).
  double xmin = 1e300, xmax = -1e300, ymin = 1e300, ymax = -1e300;
  for (std::size_t k = 0; k < w.pv.size(); ++k) {
    if (w.ps[k] < w.s_lo || w.ps[k] > w.s_hi) continue;
    xmin = std::min(xmin, w.pv[k].x());
    xmax = std::max(xmax, w.pv[k].x());
    ymin = std::min(ymin, w.pv[k].y());
    ymax = std::max(ymax, w.pv[k].y());
  }
  if (xmin > xmax) {  // range between two vertices
    const Eigen::Vector3d c = w.route_at(s_first);
    xmin = xmax = c.x();
    ymin = ymax = c.y();
  }
  const double pad = 100.0;
  w.gx0 = xmin - pad;
  w.gy0 = ymin - pad;
  w.gnx = static_cast<int>(std::ceil((xmax - xmin + 2 * pad) / w.gcell)) + 1;
  w.gny = static_cast<int>(std::ceil((ymax - ymin + 2 * pad) / w.gcell)) + 1;
  const std::size_t ncell = static_cast<std::size_t>(w.gnx) * w.gny;
  w.nearest.assign(ncell, -1);
  std::vector<double> best(ncell, std::numeric_limits<double>::infinity());
  auto centre_of = [&](int ix, int iy) {
    return Eigen::Vector2d(w.gx0 + (ix + 0.5) * w.gcell, w.gy0 + (iy + 0.5) * w.gcell);
  };
  // Seeds: only the route inside the generated stretch, so that a later pass of the sequence
  // near this place (another height, another street) does not cut into this world.
  for (std::size_t k = 0; k < w.pv.size(); ++k) {
    if (w.ps[k] < w.s_lo - 1.0 || w.ps[k] > w.s_hi + 1.0) continue;
    const int ix = static_cast<int>(std::floor((w.pv[k].x() - w.gx0) / w.gcell));
    const int iy = static_cast<int>(std::floor((w.pv[k].y() - w.gy0) / w.gcell));
    if (ix < 0 || iy < 0 || ix >= w.gnx || iy >= w.gny) continue;
    const std::size_t c = static_cast<std::size_t>(iy) * w.gnx + ix;
    const double d = (centre_of(ix, iy) - w.pv[k].head<2>()).squaredNorm();
    if (d < best[c]) {
      best[c] = d;
      w.nearest[c] = static_cast<std::int32_t>(k);
    }
  }
  auto relax = [&](int ix, int iy, int jx, int jy) {
    if (jx < 0 || jy < 0 || jx >= w.gnx || jy >= w.gny) return;
    const std::int32_t k = w.nearest[static_cast<std::size_t>(jy) * w.gnx + jx];
    if (k < 0) return;
    const std::size_t c = static_cast<std::size_t>(iy) * w.gnx + ix;
    const double d = (centre_of(ix, iy) - w.pv[k].head<2>()).squaredNorm();
    if (d < best[c]) {
      best[c] = d;
      w.nearest[c] = k;
    }
  };
  for (int pass = 0; pass < 2; ++pass) {
    for (int iy = 0; iy < w.gny; ++iy)
      for (int ix = 0; ix < w.gnx; ++ix) {
        relax(ix, iy, ix - 1, iy);
        relax(ix, iy, ix - 1, iy - 1);
        relax(ix, iy, ix, iy - 1);
        relax(ix, iy, ix + 1, iy - 1);
      }
    for (int iy = w.gny - 1; iy >= 0; --iy)
      for (int ix = w.gnx - 1; ix >= 0; --ix) {
        relax(ix, iy, ix + 1, iy);
        relax(ix, iy, ix + 1, iy + 1);
        relax(ix, iy, ix, iy + 1);
        relax(ix, iy, ix - 1, iy + 1);
      }
  }
  for (std::int32_t& k : w.nearest)
    if (k < 0) k = 0;  // unreachable in practice (the grid contains vertices)
  // Ground height at the cell corners: camera height of the nearest route point minus the
  // camera's height above the ground.
  w.ground_corner.resize(static_cast<std::size_t>(w.gnx + 1) * (w.gny + 1));
  for (int iy = 0; iy <= w.gny; ++iy)
    for (int ix = 0; ix <= w.gnx; ++ix)
      w.ground_corner[static_cast<std::size_t>(iy) * (w.gnx + 1) + ix] =
          w.nearest_route(w.gx0 + ix * w.gcell, w.gy0 + iy * w.gcell).camera_z - o.camera_height_m;
  w.ground_min = *std::min_element(w.ground_corner.begin(), w.ground_corner.end());
  w.ground_max = *std::max_element(w.ground_corner.begin(), w.ground_corner.end());
  // Steepest ground slope between neighbouring grid corners (+ margin): tracing uses it to
  // skip rays that climb faster than the ground can.
  {
    double g = 0.0;
    const std::size_t stride = static_cast<std::size_t>(w.gnx) + 1;
    for (int iy = 0; iy <= w.gny; ++iy)
      for (int ix = 0; ix <= w.gnx; ++ix) {
        const double z = w.ground_corner[iy * stride + ix];
        if (ix < w.gnx) g = std::max(g, std::abs(w.ground_corner[iy * stride + ix + 1] - z));
        if (iy < w.gny) g = std::max(g, std::abs(w.ground_corner[(iy + 1) * stride + ix] - z));
      }
    w.max_grade = g / w.gcell * 1.5 + 0.01;
  }

  // ---- objects ----
  const std::uint64_t seed = o.seed;
  auto route_dist = [&](double x, double y) {
    if (x < w.gx0 || y < w.gy0 || x > w.gx0 + w.gnx * w.gcell || y > w.gy0 + w.gny * w.gcell)
      return -1.0;
    double d = 0;
    w.nearest_route(x, y, &d);
    return d;
  };
  // Minimum distance of a box footprint (corners, edge midpoints, centre) to the route.
  auto box_clearance = [&](const Box& b) {
    double m = 1e300;
    for (int i = -1; i <= 1; ++i)
      for (int j = -1; j <= 1; ++j) {
        const double lx = i * b.hx, ly = j * b.hy;
        const double d = route_dist(b.cx + lx * b.ca - ly * b.sa, b.cy + lx * b.sa + ly * b.ca);
        if (d < 0) return -1.0;
        m = std::min(m, d);
      }
    return m;
  };
  std::unordered_map<std::int64_t, std::vector<int>> footprint_hash;  // 20 m cells -> buildings
  auto fp_key = [](int ix, int iy) {
    // Shifted as unsigned (a negative signed left operand is undefined before C++20).
    return static_cast<std::int64_t>(
        (static_cast<std::uint64_t>(static_cast<std::uint32_t>(ix)) << 32) |
        static_cast<std::uint32_t>(iy));
  };
  auto overlaps_building = [&](const Box& b) {
    const int ix = static_cast<int>(std::floor(b.cx / 20.0)),
              iy = static_cast<int>(std::floor(b.cy / 20.0));
    for (int dx = -2; dx <= 2; ++dx)
      for (int dy = -2; dy <= 2; ++dy) {
        const auto it = footprint_hash.find(fp_key(ix + dx, iy + dy));
        if (it == footprint_hash.end()) continue;
        for (int bi : it->second)
          if (rects_overlap(w.boxes[w.buildings[bi].box], b, 0.05)) return true;
      }
    return false;
  };
  // A box along the street at arclength [s0, s1] on `side`, front edge at |d| = front.
  auto street_box = [&](double s0, double s1, int side, double front, double depth, Box* b) {
    const Eigen::Vector3d p0 = w.route_at(s0), p1 = w.route_at(s1);
    Eigen::Vector2d t = (p1 - p0).head<2>();
    if (t.norm() < 1e-3) return false;
    t.normalize();
    const Eigen::Vector2d right(t.y(), -t.x());
    const Eigen::Vector2d mid = 0.5 * (p0 + p1).head<2>() + side * (front + 0.5 * depth) * right;
    b->cx = mid.x();
    b->cy = mid.y();
    b->ca = t.x();
    b->sa = t.y();
    b->hx = 0.5 * (s1 - s0);
    b->hy = 0.5 * depth;
    return true;
  };
  auto min_ground = [&](const Box& b) {
    double m = 1e300;
    for (int i = -1; i <= 1; i += 2)
      for (int j = -1; j <= 1; j += 2) {
        const double lx = i * b.hx, ly = j * b.hy;
        m = std::min(m, w.ground_z(b.cx + lx * b.ca - ly * b.sa, b.cy + lx * b.sa + ly * b.ca));
      }
    return m;
  };

  auto add_building = [&](Box b, int storeys, float storey_h, std::uint64_t style_key) {
    b.z0 = min_ground(b) - 0.3;
    b.z1 = b.z0 + 0.3 + storeys * storey_h + 0.7;
    b.kind = SurfaceKind::kBuilding;
    b.index = static_cast<int>(w.buildings.size());
    b.seed = static_cast<std::uint32_t>(style_key);
    detail::Building bd;
    bd.box = static_cast<int>(w.boxes.size());
    bd.style_base = static_cast<int>(w.styles.size());
    bd.storeys = storeys;
    for (int face = 0; face < 4; ++face) {
      const float width = static_cast<float>(face < 2 ? 2 * b.hy : 2 * b.hx);
      for (int variant = 0; variant < 2; ++variant) {
        // variant 1 (street view) = variant 0 except for 20 % of the faces.
        const bool replaced = detail::u01(detail::hash64(seed, 23, style_key, face)) < 0.2;
        Rng srng(detail::hash64(seed, 29, style_key, face + (variant && replaced ? 8 : 0)));
        w.styles.push_back(make_style(srng, width, storeys, storey_h, true));
      }
    }
    w.buildings.push_back(bd);
    w.boxes.push_back(b);
    footprint_hash[fp_key(static_cast<int>(std::floor(b.cx / 20.0)),
                          static_cast<int>(std::floor(b.cy / 20.0)))]
        .push_back(b.index);
  };

  const double kSlot = 40.0;
  const int slot0 = static_cast<int>(std::floor(w.s_lo / kSlot)),
            slot1 = static_cast<int>(std::floor(w.s_hi / kSlot));
  // Pass 0: the street's first row of buildings; pass 1: everything else (it must not take
  // the first row's place).
  for (int pass = 0; pass < 2; ++pass)
    for (int side = -1; side <= 1; side += 2) {
      const std::uint64_t side_key = side > 0 ? 1 : 2;
      for (int slot = slot0; slot <= slot1; ++slot) {
        const double a0 = slot * kSlot, a1 = a0 + kSlot;
        // Buildings.
        if (pass == 0) {
          Rng rng(detail::hash64(seed, 11, side_key, static_cast<std::uint64_t>(slot + 1000000)));
          double u = a0 + rng.uniform(0.0, 3.0);
          while (u < a1) {
            if (rng.chance(0.22)) {
              u += rng.uniform(3.0, 14.0);
              continue;
            }
            const double len = rng.uniform(7.0, 22.0), depth = rng.uniform(8.0, 16.0);
            const double setback = rng.chance(0.35) ? 0.0 : rng.uniform(0.0, 5.0);
            const int storeys = rng.integer(2, 6);
            const float storey_h = static_cast<float>(rng.uniform(2.9, 3.6));
            const std::uint64_t style_key = rng.next();
            Box b;
            const bool ok = street_box(u, u + len, side, 9.5 + setback, depth, &b);
            u += len + (rng.chance(0.5) ? 0.0 : rng.uniform(0.3, 2.0));
            if (!ok || u - len < w.s_lo || u - len > w.s_hi) continue;
            if (box_clearance(b) < 9.3 || overlaps_building(b)) continue;
            add_building(b, storeys, storey_h, style_key);
          }
        }
        if (pass == 0) continue;
        // A second row of taller buildings behind the first (fills gaps and the skyline).
        {
          Rng rng(detail::hash64(seed, 13, side_key, static_cast<std::uint64_t>(slot + 1000000)));
          double u = a0 + rng.uniform(0.0, 6.0);
          while (u < a1) {
            if (rng.chance(0.15)) {
              u += rng.uniform(4.0, 12.0);
              continue;
            }
            const double len = rng.uniform(12.0, 30.0), depth = rng.uniform(10.0, 18.0);
            const double front = 32.0 + rng.uniform(0.0, 10.0);
            const int storeys = rng.integer(3, 9);
            const float storey_h = static_cast<float>(rng.uniform(2.9, 3.5));
            const std::uint64_t style_key = rng.next();
            Box b;
            const bool ok = street_box(u, u + len, side, front, depth, &b);
            u += len + rng.uniform(0.0, 3.0);
            if (!ok || u - len < w.s_lo || u - len > w.s_hi) continue;
            if (box_clearance(b) < 28.0 || overlaps_building(b)) continue;
            add_building(b, storeys, storey_h, style_key);
          }
        }
        // Trees and poles (with signs) on the sidewalk.
        {
          Rng rng(detail::hash64(seed, 31, side_key, static_cast<std::uint64_t>(slot + 1000000)));
          double u = a0 + rng.uniform(0.0, 8.0);
          while (u < a1) {
            const double s = u;
            u += rng.uniform(9.0, 17.0);
            if (!rng.chance(0.65) || s < w.s_lo || s > w.s_hi) continue;
            const double r = rng.uniform(1.4, 2.4), trunk_h = rng.uniform(2.6, 3.4);
            const std::uint32_t tseed = static_cast<std::uint32_t>(rng.next());
            Box b;
            if (!street_box(s - 0.15, s + 0.15, side, 8.3 + rng.uniform(-0.3, 0.3) - 0.15, 0.3, &b))
              continue;
            if (box_clearance(b) < 7.5) continue;
            b.z0 = w.ground_z(b.cx, b.cy) - 0.1;
            b.z1 = b.z0 + 0.1 + trunk_h + 0.5 * r;
            b.kind = SurfaceKind::kTrunk;
            b.index = w.n_trees;
            b.seed = tseed;
            w.boxes.push_back(b);
            Sphere sp;
            sp.cx = b.cx;
            sp.cy = b.cy;
            sp.cz = b.z0 + 0.1 + trunk_h + 0.75 * r;
            sp.r = r;
            sp.index = w.n_trees++;
            sp.seed = tseed * 7u + 1u;
            w.spheres.push_back(sp);
          }
          u = a0 + rng.uniform(0.0, 20.0);
          while (u < a1) {
            const double s = u;
            u += rng.uniform(18.0, 34.0);
            if (s < w.s_lo || s > w.s_hi) continue;
            Box b;
            if (!street_box(s - 0.08, s + 0.08, side, 6.2 - 0.08, 0.16, &b)) continue;
            if (box_clearance(b) < 5.9) continue;
            b.z0 = w.ground_z(b.cx, b.cy) - 0.1;
            b.z1 = b.z0 + rng.uniform(5.5, 7.5);
            b.kind = SurfaceKind::kPole;
            b.index = w.n_poles++;
            b.seed = static_cast<std::uint32_t>(rng.next());
            b.colour = rng.chance(0.5) ? rgb(0.35, 0.36, 0.37) : rgb(0.18, 0.25, 0.2);
            const bool sign = rng.chance(0.55);
            const double sign_z = rng.uniform(2.2, 2.9), sign_w = rng.uniform(0.5, 0.8);
            const std::uint32_t sseed = static_cast<std::uint32_t>(rng.next());
            w.boxes.push_back(b);
            if (sign) {
              Box g = b;  // panel across the pole, facing along the road
              g.hx = 0.025;
              g.hy = 0.5 * sign_w;
              g.z0 = b.z0 + 0.1 + sign_z;
              g.z1 = g.z0 + sign_w;
              g.kind = SurfaceKind::kSign;
              g.index = w.n_signs++;
              g.seed = sseed;
              const double hue = detail::u01(sseed);
              g.colour = hue < 0.4   ? rgb(0.1, 0.2, 0.6)
                         : hue < 0.8 ? rgb(0.7, 0.08, 0.05)
                                     : rgb(0.85, 0.7, 0.05);
              w.boxes.push_back(g);
            }
          }
        }
      }
      if (pass == 0) continue;
      // Parked cars, one bay every 6 m of arclength (bay index from s = 0).
      const int bay0 = static_cast<int>(std::floor(w.s_lo / 6.0)),
                bay1 = static_cast<int>(std::floor(w.s_hi / 6.0));
      for (int bay = bay0; bay <= bay1; ++bay) {
        Rng rng(detail::hash64(seed, 41, side_key, static_cast<std::uint64_t>(bay + 1000000)));
        const bool video_car = rng.chance(0.45);
        const double fate = rng.uniform();
        const double shift = (rng.chance(0.5) ? -1 : 1) * rng.uniform(1.5, 5.0);
        const bool new_sv_car = rng.chance(0.15);
        const double len = rng.uniform(3.9, 4.7), wid = rng.uniform(1.72, 1.9);
        const double jitter = rng.uniform(-0.6, 0.6);
        const std::uint32_t cseed = static_cast<std::uint32_t>(rng.next());
        const double hue = rng.uniform();
        const detail::Vec3f colour = hue < 0.2    ? rgb(0.6, 0.6, 0.62)
                                     : hue < 0.35 ? rgb(0.08, 0.08, 0.09)
                                     : hue < 0.5  ? rgb(0.55, 0.06, 0.05)
                                     : hue < 0.65 ? rgb(0.07, 0.15, 0.42)
                                     : hue < 0.8  ? rgb(0.85, 0.85, 0.83)
                                                  : rgb(0.2, 0.32, 0.22);
        const double cabin_shift = rng.uniform(-0.3, 0.1), cabin_top = rng.uniform(1.38, 1.55);
        auto add_car = [&](double s_mid, std::uint8_t mask) {
          if (s_mid < w.s_lo || s_mid > w.s_hi) return;
          Box body;
          if (!street_box(s_mid - 0.5 * len, s_mid + 0.5 * len, side, 4.55 - 0.5 * wid, wid, &body))
            return;
          if (box_clearance(body) < 3.3) return;
          const double g = w.ground_z(body.cx, body.cy);
          body.z0 = g + 0.22;
          body.z1 = g + 0.95;
          body.kind = SurfaceKind::kCar;
          body.mask = mask;
          body.seed = cseed;
          body.colour = colour;
          body.index = (mask & detail::kMaskVideo) ? w.n_cars_video : w.n_cars_sv;
          if (mask & detail::kMaskVideo) ++w.n_cars_video;
          if (mask & detail::kMaskStreetView) ++w.n_cars_sv;
          Box cabin = body;
          cabin.hx = body.hx * 0.55;
          cabin.hy = body.hy - 0.08;
          cabin.cx += cabin_shift * body.ca;
          cabin.cy += cabin_shift * body.sa;
          cabin.z0 = body.z1;
          cabin.z1 = g + cabin_top;
          cabin.seed = cseed ^ 0x5555u;
          cabin.part = 1;
          w.boxes.push_back(body);
          w.boxes.push_back(cabin);
        };
        const double s_mid = (bay + 0.5) * 6.0 + jitter;
        if (video_car) {
          if (fate < 0.40) {
            add_car(s_mid, detail::kMaskBoth);
          } else if (fate < 0.75) {
            add_car(s_mid, detail::kMaskVideo);
            add_car(s_mid + shift, detail::kMaskStreetView);
          } else {
            add_car(s_mid, detail::kMaskVideo);
          }
        } else if (new_sv_car) {
          add_car(s_mid, detail::kMaskStreetView);
        }
      }
    }

  // ---- object grid (4 m cells over the nearest-vertex grid's extent) ----
  w.onx = static_cast<int>(std::ceil(w.gnx * w.gcell / w.ocell));
  w.ony = static_cast<int>(std::ceil(w.gny * w.gcell / w.ocell));
  const std::size_t ocells = static_cast<std::size_t>(w.onx) * w.ony;
  w.max_top_z = -1e300;
  for (int variant = 0; variant < 2; ++variant) {
    const std::uint8_t mask = variant == 0 ? detail::kMaskVideo : detail::kMaskStreetView;
    std::vector<std::vector<std::uint32_t>> lists(ocells);
    std::vector<float>& top = w.cell_top[variant];
    top.assign(ocells, -1e30f);
    auto add_aabb = [&](double x0, double y0, double x1, double y1, double z1, std::uint32_t item) {
      const int ix0 = std::max(0, static_cast<int>(std::floor((x0 - w.gx0) / w.ocell)));
      const int iy0 = std::max(0, static_cast<int>(std::floor((y0 - w.gy0) / w.ocell)));
      const int ix1 = std::min(w.onx - 1, static_cast<int>(std::floor((x1 - w.gx0) / w.ocell)));
      const int iy1 = std::min(w.ony - 1, static_cast<int>(std::floor((y1 - w.gy0) / w.ocell)));
      for (int iy = iy0; iy <= iy1; ++iy)
        for (int ix = ix0; ix <= ix1; ++ix) {
          const std::size_t c = static_cast<std::size_t>(iy) * w.onx + ix;
          lists[c].push_back(item);
          top[c] = std::max(top[c], static_cast<float>(z1) + 0.01f);
        }
      w.max_top_z = std::max(w.max_top_z, z1);
    };
    for (std::size_t i = 0; i < w.boxes.size(); ++i) {
      const Box& b = w.boxes[i];
      if (!(b.mask & mask)) continue;
      const double ex = b.hx * std::abs(b.ca) + b.hy * std::abs(b.sa);
      const double ey = b.hx * std::abs(b.sa) + b.hy * std::abs(b.ca);
      add_aabb(b.cx - ex, b.cy - ey, b.cx + ex, b.cy + ey, b.z1, static_cast<std::uint32_t>(i));
    }
    for (std::size_t i = 0; i < w.spheres.size(); ++i) {
      const Sphere& s = w.spheres[i];
      if (!(s.mask & mask)) continue;
      add_aabb(s.cx - s.r, s.cy - s.r, s.cx + s.r, s.cy + s.r, s.cz + s.r,
               static_cast<std::uint32_t>(i) | Impl::kSphereBit);
    }
    std::vector<std::uint32_t>& start = w.cell_start[variant];
    start.assign(ocells + 1, 0);
    for (std::size_t c = 0; c < ocells; ++c)
      start[c + 1] = start[c] + static_cast<std::uint32_t>(lists[c].size());
    w.items[variant].reserve(start.back());
    for (const auto& l : lists) w.items[variant].insert(w.items[variant].end(), l.begin(), l.end());
  }
  impl_ = std::move(impl);
}

World World::from_kitti(const std::vector<Eigen::Isometry3d>& T_K_c, const WorldOptions& options) {
  std::vector<Eigen::Isometry3d> T_W_c;
  T_W_c.reserve(T_K_c.size());
  for (const auto& T : T_K_c) T_W_c.push_back(geo::kitti_pose_to_world(T));
  return World(T_W_c, options);
}

// ---- accessors -------------------------------------------------------------------------------

const WorldOptions& World::options() const { return impl_->options; }
int World::frame_count() const { return static_cast<int>(impl_->T_W_c.size()); }

lie::SE3d World::frame_T_cw(int i) const {
  GEODRIFT_CHECK(i >= 0 && i < frame_count(),
                 "World::frame_T_cw: frame " << i << " outside [0, " << frame_count() - 1 << "]");
  const Eigen::Isometry3d T_cw = impl_->T_W_c[i].inverse(Eigen::Isometry);
  return lie::SE3d(lie::SO3d(Eigen::Matrix3d(T_cw.linear())), T_cw.translation());
}

double World::frame_arclength(int i) const {
  GEODRIFT_CHECK(i >= 0 && i < frame_count(), "World::frame_arclength: frame "
                                                  << i << " outside [0, " << frame_count() - 1
                                                  << "]");
  return impl_->frame_s[i];
}

Eigen::Vector3d World::route_point(double s) const { return impl_->route_at(s); }

Eigen::Vector2d World::route_tangent(double s) const {
  Eigen::Vector2d t = (impl_->route_at(s + 2.0) - impl_->route_at(s - 2.0)).head<2>();
  if (t.norm() < 1e-9) return impl_->nearest_route(route_point(s).x(), route_point(s).y()).tangent;
  return t.normalized();
}

RoutePoint World::nearest_route_point(double x, double y) const {
  return impl_->nearest_route(x, y);
}

double World::ground_height(double x, double y) const { return impl_->ground_z(x, y); }

const geo::LocalFrame& World::local_frame() const { return impl_->frame; }

std::vector<BuildingInfo> World::buildings() const {
  std::vector<BuildingInfo> out;
  for (const detail::Building& bd : impl_->buildings) {
    const Box& b = impl_->boxes[bd.box];
    BuildingInfo bi;
    bi.centre = Eigen::Vector2d(b.cx, b.cy);
    bi.yaw = std::atan2(b.sa, b.ca);
    bi.half_length = b.hx;
    bi.half_depth = b.hy;
    bi.base_z = b.z0;
    bi.top_z = b.z1;
    out.push_back(bi);
  }
  return out;
}

std::string World::summary() const {
  std::ostringstream os;
  os << impl_->buildings.size() << " buildings, " << impl_->n_cars_video << " parked cars (video), "
     << impl_->n_cars_sv << " (street view), " << impl_->n_trees << " trees, " << impl_->n_poles
     << " poles, " << impl_->n_signs << " signs";
  return os.str();
}

// ---- tracing ---------------------------------------------------------------------------------

namespace {

/// Ray / vertical box. Returns the entry distance (> tmin) or +inf; sets face and local point.
inline double intersect_box(const Box& b, const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                            double tmin, double tmax, int* face) {
  const double px = o.x() - b.cx, py = o.y() - b.cy;
  const double lox = px * b.ca + py * b.sa, loy = -px * b.sa + py * b.ca;
  const double ldx = d.x() * b.ca + d.y() * b.sa, ldy = -d.x() * b.sa + d.y() * b.ca;
  double t0 = tmin, t1 = tmax;
  int f = -1;
  auto slab = [&](double oo, double dd, double lo, double hi, int fneg) {
    if (std::abs(dd) < 1e-12) return oo >= lo && oo <= hi;
    const double inv = 1.0 / dd;
    double ta = (lo - oo) * inv, tb = (hi - oo) * inv;
    int fa = fneg;
    if (ta > tb) {
      std::swap(ta, tb);
      fa = fneg + 1;
    }
    if (ta > t0) {
      t0 = ta;
      f = fa;
    }
    t1 = std::min(t1, tb);
    return t0 <= t1;
  };
  if (!slab(lox, ldx, -b.hx, b.hx, 0)) return std::numeric_limits<double>::infinity();
  if (!slab(loy, ldy, -b.hy, b.hy, 2)) return std::numeric_limits<double>::infinity();
  if (!slab(o.z(), d.z(), b.z0, b.z1, 4)) return std::numeric_limits<double>::infinity();
  if (f < 0) return std::numeric_limits<double>::infinity();  // origin inside the box
  *face = f;
  return t0;
}

inline double intersect_sphere(const Sphere& s, const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                               double tmin) {
  const double ox = o.x() - s.cx, oy = o.y() - s.cy, oz = o.z() - s.cz;
  const double b = ox * d.x() + oy * d.y() + oz * d.z();
  const double c = ox * ox + oy * oy + oz * oz - s.r * s.r;
  const double disc = b * b - c;
  if (disc < 0) return std::numeric_limits<double>::infinity();
  const double t = -b - std::sqrt(disc);
  return t > tmin ? t : std::numeric_limits<double>::infinity();
}

}  // namespace

Hit World::Impl::trace(const Eigen::Vector3d& d, const detail::RayContext& ctx) const {
  const Eigen::Vector3d& o = ctx.origin;
  constexpr double kMaxT = 300.0;
  Hit hit;
  hit.t = kMaxT;
  const int variant = ctx.street_view ? 1 : 0;
  const std::vector<std::uint32_t>& cstart = cell_start[variant];
  const std::vector<std::uint32_t>& citems = items[variant];
  const std::vector<float>& ctop = cell_top[variant];

  // Ground first (it bounds the object search): first crossing of the ray below the height
  // field, found by stepping with the local plane estimate, then Illinois false position.
  // The ray can meet the ground only below ground_max; it has crossed it by ground_min.
  double tground = kMaxT;
  if (d.z() > 0) tground = o.z() >= ground_max ? 0.0 : (ground_max - o.z()) / d.z();
  if (d.z() < 0) tground = std::min(tground, (o.z() - ground_min) / -d.z() + 1e-3);
  tground = std::min(tground, kMaxT);
  // A ray climbing faster than the steepest ground never meets it.
  const bool may_hit_ground = d.z() < max_grade * std::sqrt(d.x() * d.x() + d.y() * d.y());
  if (may_hit_ground && tground > 0 && ctx.origin_above_ground > 0) {
    auto f = [&](double t) {
      return o.z() + t * d.z() - ground_fast(o.x() + t * d.x(), o.y() + t * d.y());
    };
    double ta = 0, fa = ctx.origin_above_ground, tb = 0, fb = 0;
    bool bracket = false;
    double t = 0, ft = fa, slope = d.z();  // slope: df/dt estimate (plane under the origin)
    bool done = false;
    for (int it = 0; it < 32 && t < tground; ++it) {
      double step = slope < -1e-3 ? ft / -slope : 4.0 + 0.5 * t;
      step = std::max(step, 0.02 + 0.01 * t);
      const double tn = std::min(t + step, tground);
      const double fn = f(tn);
      if (std::abs(fn) < 1e-4) {
        hit.t = tn;
        hit.kind = SurfaceKind::kGround;
        done = true;
        break;
      }
      if (fn < 0) {
        ta = t;
        fa = ft;
        tb = tn;
        fb = fn;
        bracket = true;
        break;
      }
      // Secant slope for the next step, when it is a usable (descending) one.
      const double sl = (fn - ft) / (tn - t);
      slope = sl < -1e-3 ? sl : d.z();
      t = tn;
      ft = fn;
    }
    if (bracket && !done) {
      int side = 0;
      double tm = tb;
      for (int it = 0; it < 16; ++it) {
        tm = (ta * fb - tb * fa) / (fb - fa);
        const double fm = f(tm);
        if (std::abs(fm) < 1e-4 || tb - ta < 1e-4) break;
        if (fm < 0) {
          tb = tm;
          fb = fm;
          if (side == -1) fa *= 0.5;
          side = -1;
        } else {
          ta = tm;
          fa = fm;
          if (side == 1) fb *= 0.5;
          side = 1;
        }
      }
      hit.t = tm;
      hit.kind = SurfaceKind::kGround;
    }
  }

  // Objects: 2D DDA over the object grid up to the ground hit.
  const double gx1 = gx0 + onx * ocell, gy1 = gy0 + ony * ocell;
  double tin = 0, tout = hit.t;
  auto clip = [&](double oo, double dd, double lo, double hi) {
    if (std::abs(dd) < 1e-12) return oo >= lo && oo <= hi;
    double ta = (lo - oo) / dd, tb = (hi - oo) / dd;
    if (ta > tb) std::swap(ta, tb);
    tin = std::max(tin, ta);
    tout = std::min(tout, tb);
    return tin <= tout;
  };
  if (d.z() > 0 && o.z() < max_top_z) tout = std::min(tout, (max_top_z - o.z()) / d.z());
  const bool objects_possible = !(d.z() >= 0 && o.z() >= max_top_z) &&
                                clip(o.x(), d.x(), gx0, gx1) && clip(o.y(), d.y(), gy0, gy1) &&
                                tin <= tout;
  bool object_hit = false;
  if (objects_possible) {
    const double sx = o.x() + tin * d.x(), sy = o.y() + tin * d.y();
    int ix = std::clamp(static_cast<int>(std::floor((sx - gx0) / ocell)), 0, onx - 1);
    int iy = std::clamp(static_cast<int>(std::floor((sy - gy0) / ocell)), 0, ony - 1);
    const int stepx = d.x() > 0 ? 1 : -1, stepy = d.y() > 0 ? 1 : -1;
    const double inf = std::numeric_limits<double>::infinity();
    const double tdx = std::abs(d.x()) > 1e-12 ? ocell / std::abs(d.x()) : inf;
    const double tdy = std::abs(d.y()) > 1e-12 ? ocell / std::abs(d.y()) : inf;
    double tmx =
        std::abs(d.x()) > 1e-12 ? (gx0 + (ix + (stepx > 0 ? 1 : 0)) * ocell - o.x()) / d.x() : inf;
    double tmy =
        std::abs(d.y()) > 1e-12 ? (gy0 + (iy + (stepy > 0 ? 1 : 0)) * ocell - o.y()) / d.y() : inf;
    double tcur = tin;
    std::uint32_t recent[8] = {~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u};
    int rpos = 0;
    while (true) {
      const double texit = std::min({tmx, tmy, tout});
      const std::size_t c = static_cast<std::size_t>(iy) * onx + ix;
      // Skip cells whose objects are all below the ray over this cell.
      const double zlow = o.z() + (d.z() >= 0 ? tcur : texit) * d.z();
      if (zlow <= ctop[c]) {
        for (std::uint32_t k = cstart[c]; k < cstart[c + 1]; ++k) {
          const std::uint32_t item = citems[k];
          bool seen = false;
          for (std::uint32_t r : recent) seen = seen || r == item;
          if (seen) continue;
          recent[rpos] = item;
          rpos = (rpos + 1) & 7;
          if (item & kSphereBit) {
            const detail::Sphere& s = spheres[item & ~kSphereBit];
            const double t = intersect_sphere(s, o, d, 1e-4);
            if (t < hit.t) {
              hit.t = t;
              hit.kind = SurfaceKind::kCanopy;
              hit.obj = static_cast<int>(item & ~kSphereBit);
              hit.face = -1;
              object_hit = true;
            }
          } else {
            const detail::Box& b = boxes[item];
            int face = -1;
            const double t = intersect_box(b, o, d, 1e-4, hit.t, &face);
            if (t < hit.t) {
              hit.t = t;
              hit.kind = b.kind;
              hit.obj = static_cast<int>(item);
              hit.face = face;
              object_hit = true;
            }
          }
        }
      }
      if ((object_hit && hit.t <= texit) || texit >= tout) break;
      tcur = texit;
      if (tmx < tmy) {
        ix += stepx;
        tmx += tdx;
        if (ix < 0 || ix >= onx) break;
      } else {
        iy += stepy;
        tmy += tdy;
        if (iy < 0 || iy >= ony) break;
      }
    }
  }
  if (hit.kind == SurfaceKind::kGround && !object_hit) {
    const Eigen::Vector3d p = o + hit.t * d;
    hit.route = nearest_route(p.x(), p.y());
  } else if (!object_hit) {
    hit.kind = SurfaceKind::kSky;
    hit.t = std::numeric_limits<double>::infinity();
    hit.obj = -1;
  }
  if (object_hit && hit.kind != SurfaceKind::kCanopy) {
    const detail::Box& b = boxes[hit.obj];
    const Eigen::Vector3d p = o + hit.t * d;
    const double px = p.x() - b.cx, py = p.y() - b.cy;
    hit.lx = px * b.ca + py * b.sa;
    hit.ly = -px * b.sa + py * b.ca;
    hit.lz = p.z() - b.z0;
  }
  return hit;
}

RayHit World::trace(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir,
                    const Appearance& appearance) const {
  GEODRIFT_CHECK(origin.allFinite() && dir.allFinite() && dir.norm() > 0,
                 "World::trace: origin/direction not finite or zero");
  detail::RayContext ctx;
  ctx.origin = origin;
  ctx.origin_above_ground = origin.z() - impl_->ground_z(origin.x(), origin.y());
  ctx.street_view = appearance.street_view_content;
  const Eigen::Vector3d d = dir.normalized();
  const Hit h = impl_->trace(d, ctx);
  RayHit r;
  r.t = h.t;
  r.kind = h.kind;
  r.face = h.face;
  if (h.kind == SurfaceKind::kBuilding) {
    r.object = impl_->boxes[h.obj].index;
  } else if (h.kind != SurfaceKind::kSky && h.kind != SurfaceKind::kGround) {
    r.object =
        h.kind == SurfaceKind::kCanopy ? impl_->spheres[h.obj].index : impl_->boxes[h.obj].index;
  }
  if (h.kind == SurfaceKind::kGround) {
    r.normal = Eigen::Vector3d::UnitZ();
  } else if (h.kind == SurfaceKind::kCanopy) {
    const detail::Sphere& s = impl_->spheres[h.obj];
    r.normal = (origin + h.t * d - Eigen::Vector3d(s.cx, s.cy, s.cz)).normalized();
  } else if (h.kind != SurfaceKind::kSky) {
    const detail::Box& b = impl_->boxes[h.obj];
    const double sgn = (h.face % 2 == 0) ? -1.0 : 1.0;
    if (h.face < 2)
      r.normal = sgn * Eigen::Vector3d(b.ca, b.sa, 0);
    else if (h.face < 4)
      r.normal = sgn * Eigen::Vector3d(-b.sa, b.ca, 0);
    else
      r.normal = sgn * Eigen::Vector3d::UnitZ();
  }
  return r;
}

}  // namespace geodrift::render
