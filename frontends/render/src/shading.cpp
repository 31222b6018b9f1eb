// Materials and lighting of the street world: procedural, band-limited by the ray footprint
// (details smaller than a pixel fade to their mean), hashed per facade / storey / window / slab
// so that nothing repeats exactly.
#include <algorithm>
#include <cmath>

#include "world_impl.hpp"

namespace geodrift::render::detail {
namespace {

inline Vec3f mixv(const Vec3f& a, const Vec3f& b, float k) { return a + (b - a) * k; }
inline float fract(double x) { return static_cast<float>(x - std::floor(x)); }
inline Vec3f grey(float g) { return Vec3f(g, g, g); }

/// Distance of `x` to the nearest multiple of `period` (for thin lines), in [0, period/2].
inline double line_dist(double x, double period) {
  const double f = x - period * std::floor(x / period);
  return std::min(f, period - f);
}

/// 3x5 glyph bitmaps for pseudo-text (letters and digits look alike to a feature detector; what
/// matters is that they are distinct and corner-rich).
inline bool glyph_on(std::uint32_t code, int col, int row) {
  // Guarantee a vertical stroke so no glyph is empty.
  const std::uint32_t bits = (code & 0x7fffu) | 0x1249u;
  return (bits >> (row * 3 + col)) & 1u;
}

// ---- walls ---------------------------------------------------------------------------------

Vec3f wall_texture(const FaceStyle& f, double u, double v, double fp) {
  const float dirt = 0.88f + 0.24f * fbm(u, v, 3.0, fp, 3, f.seed + 7u);
  switch (f.wall) {
    case 0: {  // brick
      const double bh = f.brick_h, bw = f.brick_w, mortar = 0.012;
      const int row = ifloor(v / bh);
      const double uo = u + ((row & 1) ? 0.5 * bw : 0.0);
      const int col = ifloor(uo / bw);
      const double fu = uo - col * bw, fv = v - row * bh;
      const Vec3f mortar_rgb(0.68f, 0.66f, 0.6f);
      const float mf = static_cast<float>(mortar / bh + mortar / bw);
      const Vec3f mean = mixv(f.wall_rgb, mortar_rgb, mf);
      const float k = detail_fade(bh, fp);
      Vec3f c = mean;
      if (k > 0) {
        const bool in_mortar = fu < mortar || fv < mortar;
        const float jit = 0.72f + 0.5f * hash2f(col, row, f.seed);
        const Vec3f brick = f.wall_rgb * jit;
        c = mixv(mean, in_mortar ? mortar_rgb : brick, k);
      }
      return c * dirt;
    }
    case 1: {  // plaster with stains and streaks
      const float stains = 0.82f + 0.36f * fbm(u, v, 1.6, fp, 4, f.seed + 3u);
      const float streak = 0.93f + 0.14f * fbm(u * 4.0, v * 0.25, 1.0, fp * 4.0, 2, f.seed + 5u);
      return f.wall_rgb * (stains * streak * dirt);
    }
    case 2: {  // stone blocks
      const double bh = 0.42, bw = 0.85, joint = 0.02;
      const int row = ifloor(v / bh);
      const double uo = u + ((row & 1) ? 0.37 * bw : 0.0);
      const int col = ifloor(uo / bw);
      const double fu = uo - col * bw, fv = v - row * bh;
      const float k = detail_fade(bh * 0.5, fp);
      const Vec3f block = f.wall_rgb * (0.82f + 0.34f * hash2f(col, row, f.seed + 11u));
      const Vec3f joint_rgb = f.wall_rgb * 0.55f;
      const bool in_joint = fu < joint || fv < joint;
      const float grain = 0.9f + 0.2f * fbm(u, v, 0.4, fp, 2, f.seed + 13u);
      return mixv(f.wall_rgb * 0.95f, in_joint ? joint_rgb : block, k) * (grain * dirt);
    }
    default: {  // glass curtain wall: panels with mullions (windows are the panels)
      const int col = ifloor(u / 1.5), row = ifloor(v / f.storey_h);
      const double fu = u - col * 1.5, fv = v - row * f.storey_h;
      if (fu < 0.08 || fv < 0.08) return grey(0.45f);
      if (fv < 0.9) return grey(0.2f + 0.08f * hash2f(col, row, f.seed + 17u));
      const float tone = 0.08f + 0.3f * hash2f(col, row, f.seed + 19u);
      const float refl = static_cast<float>((fv - 0.9) / (f.storey_h - 0.9));
      return Vec3f(0.8f, 0.9f, 1.1f) * (tone + 0.12f * refl);
    }
  }
}

// ---- windows, doors, shop fronts -------------------------------------------------------------

/// Window glass content at (x, y) inside a glass rectangle of size (w, h), x from the left.
Vec3f window_glass(std::uint32_t h, const FaceStyle& f, double x, double y, double w, double hgt,
                   double fp) {
  const float type = hf(h);
  const float refl = static_cast<float>(y / hgt);
  Vec3f glass = Vec3f(0.75f, 0.85f, 1.0f) * (0.06f + 0.22f * refl * hf(h * 31u + 7u));
  // Mullion cross for wide windows.
  const bool cross_v = w > 1.05 && std::abs(x - 0.5 * w) < 0.035;
  const bool cross_h = (h & 16u) && std::abs(y - 0.68 * hgt) < 0.035;
  if ((cross_v || cross_h) && detail_fade(0.07, fp) > 0.3f) return f.frame_rgb;
  if (type < 0.4f) return glass;
  if (type < 0.65f) {  // curtains from both sides, with folds
    const double cov = 0.12 + 0.3 * hf(h * 13u + 1u);
    const bool in = x < cov * w || x > (1.0 - cov * hf(h * 17u + 3u)) * w;
    if (!in) return glass;
    const Vec3f cur = Vec3f(0.75f, 0.7f, 0.6f) * (0.7f + 0.4f * hf(h * 19u + 5u));
    const float folds = detail_fade(0.06, fp) * 0.15f * std::sin(static_cast<float>(x) * 52.0f);
    return cur * (0.9f + folds);
  }
  if (type < 0.85f) {  // blinds lowered to a level, slats
    const double level = hgt * (1.0 - 0.2 - 0.7 * hf(h * 23u + 9u));
    if (y < level) return glass;
    const float slat = detail_fade(0.05, fp) * (line_dist(y, 0.05) < 0.006 ? 0.25f : 0.0f);
    return grey(0.7f) * (1.0f - slat);
  }
  // Lit room: warm light with a dark piece of furniture.
  Vec3f lit(0.55f, 0.45f, 0.3f);
  const double fx0 = 0.15 * w + 0.4 * w * hf(h * 29u), fx1 = fx0 + 0.25 * w;
  if (x > fx0 && x < fx1 && y < 0.4 * hgt) return grey(0.1f);
  return lit;
}

Vec3f facade(const FaceStyle& f, double u, double v, double top, double fp) {
  // Parapet at the top, plinth at the bottom.
  if (v > top - 0.7) {
    if (v < top - 0.64) return f.trim_rgb * 0.55f;
    return f.trim_rgb * (0.9f + 0.1f * fbm(u, v, 1.0, fp, 2, f.seed + 23u));
  }
  if (v < 0.3) return f.wall_rgb * 0.5f * (0.9f + 0.2f * fbm(u, v, 0.5, fp, 2, f.seed + 29u));
  const double vv = v - 0.3;
  const int floor = std::min(ifloor(vv / f.storey_h), f.storeys - 1);
  const double fy = vv - floor * f.storey_h;
  if (f.wall == 3) return wall_texture(f, u, vv, fp);
  // Cornice between storeys.
  if (floor >= 1 && fy < 0.2) {
    if (fy > 0.16) return f.trim_rgb * 0.55f;
    return f.trim_rgb * (0.95f + 0.1f * fbm(u, v, 0.8, fp, 2, f.seed + 31u));
  }
  if (floor == 0 && f.shop) {
    const int unit = ifloor(u / f.shop_unit);
    const double uu = u - unit * f.shop_unit;
    const std::uint32_t uh = hash2i(unit, 77, f.seed);
    const double sh = f.storey_h;
    if (fy > sh - 0.72 && fy < sh - 0.16 && uu > 0.25 && uu < f.shop_unit - 0.25) {
      // Shop sign with pseudo-text.
      const Vec3f sign =
          (uh & 1u) ? f.sign_rgb : Vec3f(f.sign_rgb.y(), f.sign_rgb.z(), f.sign_rgb.x()) * 1.2f;
      const double sx = uu - 0.25, sy = fy - (sh - 0.72);
      if (sx < 0.04 || sy < 0.04 || sx > f.shop_unit - 0.54 || sy > 0.52) return grey(0.85f);
      const int nchar = 3 + static_cast<int>((uh >> 4) % 8);
      const double cw = 0.3, ch = 0.34;
      const double x0 = 0.5 * (f.shop_unit - 0.5 - nchar * cw);
      const double cx = sx - x0, cy = sy - 0.5 * (0.56 - ch);
      if (cx >= 0 && cx < nchar * cw && cy >= 0 && cy < ch) {
        const float k = detail_fade(0.06, fp);
        const int ci = ifloor(cx / cw);
        const double gx = (cx - ci * cw) / cw * 4.0, gy = cy / ch * 5.0;
        const int gc = ifloor(gx), gr = 4 - ifloor(gy);
        const bool on = gc < 3 && glyph_on(hash2i(unit, ci, f.seed + 41u), gc, gr);
        const Vec3f mean = mixv(sign, f.text_rgb, 0.35f);
        return mixv(mean, on ? f.text_rgb : sign, k);
      }
      return sign;
    }
    if (fy > 0.45 && fy < sh - 0.85 && uu > 0.2 && uu < f.shop_unit - 0.2) {
      // Shop window with mullions and a door.
      const double pane = 1.1 + 0.6 * hf(uh * 3u + 1u);
      const double px = uu - 0.2;
      const int pi = ifloor(px / pane);
      const double pu = px - pi * pane;
      const int door = static_cast<int>((uh >> 8) % 3);
      if (pu < 0.07) return f.frame_rgb * 0.6f;
      if (pi == door) {
        if (fy > 2.2) return f.frame_rgb * 0.6f;
        const Vec3f door_rgb = Vec3f(0.25f, 0.18f, 0.12f) * (0.6f + 0.8f * hf(uh * 5u));
        if (pu > pane - 0.16 && pu < pane - 0.1 && std::abs(fy - 1.05) < 0.1) return grey(0.8f);
        return (pu < 0.15 || fy > 2.05 || fy < 0.55) ? door_rgb * 0.6f : door_rgb;
      }
      const std::uint32_t ph = hash2i(unit * 16 + pi, 91, f.seed);
      // Display items: a few boxes in the lower half.
      const double ix0 = 0.15 + 0.4 * hf(ph), iw = 0.2 + 0.3 * hf(ph * 7u);
      if (pu > ix0 && pu < ix0 + iw && fy < 0.45 + 0.3 + 0.6 * hf(ph * 11u))
        return Vec3f(hf(ph * 13u), hf(ph * 17u), hf(ph * 19u)) * 0.7f + grey(0.1f);
      return window_glass(ph | 0x1u, f, pu, fy - 0.45, pane, sh - 1.3, fp) * 0.8f;
    }
    if (fy < 0.45) return f.wall_rgb * 0.6f;
    return f.trim_rgb * 0.85f;
  }
  // Windows.
  const double span = u - f.offset;
  const int col = ifloor(span / f.pitch);
  if (col >= 0 && col < f.n_cols) {
    const double cu = span - col * f.pitch - 0.5 * (f.pitch - f.win_w);
    const double fr = 0.07;
    const std::uint32_t wh = hash2i(floor * 64 + col, 5, f.seed);
    if (floor == 0 && col == f.door_col) {  // entrance door
      const double dw = std::max(1.0, static_cast<double>(f.win_w));
      const double du = cu - 0.5 * (f.win_w - dw);
      if (du > -fr && du < dw + fr && fy < 2.3 + fr) {
        if (du < 0 || du > dw || fy > 2.3) return f.frame_rgb;
        const Vec3f door_rgb = Vec3f(0.28f, 0.2f, 0.13f) * (0.6f + 0.8f * hf(wh));
        const bool panel = line_dist(du, dw * 0.5) < 0.08 || line_dist(fy, 0.7) < 0.06;
        return panel ? door_rgb * 0.7f : door_rgb;
      }
    } else if (hf(wh * 101u + 1u) > 0.07) {
      const double gy = fy - f.sill;
      if (cu > -fr && cu < f.win_w + fr && gy > -fr && gy < f.win_h + fr) {
        if (cu < 0 || cu > f.win_w || gy < 0 || gy > f.win_h) return f.frame_rgb;
        return window_glass(wh, f, cu, gy, f.win_w, f.win_h, fp);
      }
      if (gy < -fr && gy > -fr - 0.09 && cu > -fr - 0.06 && cu < f.win_w + fr + 0.06)
        return f.trim_rgb;  // sill
      if (gy < -fr - 0.09 && gy > -fr - 0.14 && cu > -fr - 0.06 && cu < f.win_w + fr + 0.06)
        return f.wall_rgb * 0.45f;  // its shadow
    }
  }
  return wall_texture(f, u, vv, fp);
}

// ---- ground ------------------------------------------------------------------------------------

Vec3f ground(const RoutePoint& rp, const Eigen::Vector3d& p, double fp, std::uint32_t seed) {
  const double ad = std::abs(rp.d), s = rp.s;
  const float k_fine = detail_fade(0.08, fp);
  if (ad < 5.5) {
    float a = 0.15f + 0.09f * (fbm(p.x(), p.y(), 2.0, fp, 4, seed + 101u) - 0.5f) * 2.0f;
    a += k_fine * 0.05f * (hash2f(ifloor(p.x() * 25.0), ifloor(p.y() * 25.0), seed + 103u) - 0.5f);
    // Repair patches (corner-rich rectangles).
    const int pi = ifloor(s / 7.0), pj = ifloor((rp.d + 20.0) / 2.5);
    const std::uint32_t ph = hash2i(pi, pj, seed + 107u);
    if (hf(ph) < 0.14f) {
      const double ps0 = 7.0 * pi + 1.0 + 3.0 * hf(ph * 3u), ps1 = ps0 + 1.0 + 2.0 * hf(ph * 5u);
      const double pd0 = 2.5 * pj - 20.0 + 0.3, pd1 = pd0 + 0.8 + 1.2 * hf(ph * 7u);
      if (s > ps0 && s < ps1 && rp.d > pd0 && rp.d < pd1) a *= (ph & 2u) ? 0.65f : 1.35f;
    }
    // Manhole covers.
    const int mi = ifloor(s / 23.0);
    const std::uint32_t mh = hash2i(mi, 3, seed + 109u);
    if (hf(mh) < 0.5f) {
      const double ms = 23.0 * mi + 3.0 + 15.0 * hf(mh * 3u), md = (mh & 4u) ? 1.7 : -1.7;
      const double r = std::hypot(s - ms, rp.d - md);
      if (r < 0.36) {
        const bool groove = detail_fade(0.04, fp) > 0.5f && line_dist(s - ms, 0.09) < 0.015;
        return grey(r > 0.31 ? 0.08f : groove ? 0.12f : 0.22f);
      }
    }
    Vec3f c = grey(a);
    const Vec3f paint(0.82f, 0.82f, 0.78f);
    // Zebra crossing on some 120 m blocks.
    const int zi = ifloor(s / 120.0);
    const std::uint32_t zh = hash2i(zi, 9, seed + 113u);
    const double zs = 120.0 * zi + 30.0 + 60.0 * hf(zh);
    if (hf(zh * 3u) < 0.35f && s > zs && s < zs + 4.0 && ad < 5.2 &&
        line_dist(rp.d + 0.25, 1.0) < 0.25)
      return paint * (0.9f + 0.1f * a);
    const bool centre = ad < 0.075 && std::fmod(s + 1000.0, 9.0) < 3.0;
    const bool edge = std::abs(ad - 3.5) < 0.075;
    const bool bay = ad > 3.575 && line_dist(s, 6.0) < 0.06;
    if (centre || edge || bay) return paint * (0.85f + 0.3f * a);
    return c;
  }
  if (ad < 5.7) {  // curb
    if (ad < 5.52) return grey(0.1f);
    const float j = line_dist(s, 1.0) < 0.01 ? 0.6f : 1.0f;
    return grey(0.55f * j * (0.9f + 0.2f * hash2f(ifloor(s), 1, seed + 117u)));
  }
  if (ad < 9.5) {  // sidewalk slabs
    const double sd = ad - 5.7;
    const int i = ifloor(s / 0.5), j = ifloor(sd / 0.5);
    const double fs = s - i * 0.5, fd = sd - j * 0.5;
    const float k = detail_fade(0.12, fp);
    const float tone = 0.42f + 0.14f * hash2f(i, j + (rp.d > 0 ? 100 : 0), seed + 119u);
    const bool joint = fs < 0.015 || fd < 0.015;
    const float mean = 0.45f;
    const float g = mean + k * ((joint ? 0.22f : tone) - mean);
    return Vec3f(g, g * 0.98f, g * 0.94f) * (0.9f + 0.2f * fbm(p.x(), p.y(), 3.0, fp, 2, seed));
  }
  // Beyond the sidewalk: grass and gravel.
  const float m = fbm(p.x(), p.y(), 5.0, fp, 3, seed + 127u);
  const Vec3f grass(0.16f, 0.26f, 0.09f), earth(0.34f, 0.29f, 0.21f);
  const Vec3f base = mixv(grass, earth, std::clamp((m - 0.4f) * 3.0f, 0.0f, 1.0f));
  return base * (0.8f + 0.4f * fbm(p.x(), p.y(), 0.5, fp, 3, seed + 131u));
}

// ---- small objects -----------------------------------------------------------------------------

Vec3f car(const Box& b, int face, double lx, double ly, double lz, double fp, bool cabin) {
  const Vec3f body = b.colour;
  if (cabin) {
    if (face == 5) return body * 0.9f;
    const bool side = face == 2 || face == 3;
    const double along = side ? lx : ly, half = side ? b.hx : b.hy;
    if (lz < 0.05 || lz > (b.z1 - b.z0) - 0.06 || std::abs(along) > half - 0.12)
      return body * 0.85f;
    if (side && std::abs(along) < 0.06) return body * 0.8f;  // B pillar
    const float refl = static_cast<float>(lz / (b.z1 - b.z0));
    return Vec3f(0.7f, 0.8f, 0.9f) * (0.05f + 0.25f * refl);
  }
  if (face == 5) return body;
  if (face == 2 || face == 3) {
    // Wheels (tyre + hub) at the ends, seams, handles.
    for (int e = -1; e <= 1; e += 2) {
      const double wx = e * (b.hx - 0.75), wz = 0.11;
      const double r = std::hypot(lx - wx, lz - wz);
      if (r < 0.36) return r < 0.17 ? grey(0.55f) : grey(0.04f);
      if (r < 0.4) return body * 0.3f;
    }
    if (detail_fade(0.03, fp) > 0.5f) {
      if (line_dist(lx + 0.15, 1.1) < 0.012 && lz > 0.15) return body * 0.4f;
      if (std::abs(lz - 0.55) < 0.03 && line_dist(lx - 0.35, 1.1) < 0.08) return grey(0.25f);
    }
    return lz < 0.12 ? grey(0.1f) : body * (lz > 0.6 ? 1.05f : 0.95f);
  }
  // Front / back: bumper, plate, lights.
  if (lz < 0.18) return grey(0.1f);
  if (std::abs(ly) < 0.26 && lz > 0.22 && lz < 0.34)
    return detail_fade(0.03, fp) > 0.5f && line_dist(ly, 0.07) < 0.015 ? grey(0.1f) : grey(0.9f);
  if (std::abs(ly) > b.hy - 0.35 && lz > 0.4 && lz < 0.58)
    return face == 1 ? Vec3f(0.95f, 0.95f, 0.85f) : Vec3f(0.7f, 0.05f, 0.04f);
  return body * 0.92f;
}

Vec3f sign_panel(const Box& b, int face, double ly, double lz, double fp) {
  if (face != 0 && face != 1) return grey(0.4f);
  const double w = 2.0 * b.hy, h = b.z1 - b.z0;
  const double x = ly + b.hy, y = lz;
  if (face == 0) return grey(0.45f);  // back
  if (x < 0.04 || y < 0.04 || x > w - 0.04 || y > h - 0.04) return grey(0.9f);
  const std::uint32_t code = b.seed;
  const float k = detail_fade(0.05, fp);
  // Symbol: a 4x4 block pattern plus a bar.
  const int gx = ifloor((x - 0.1) / ((w - 0.2) / 4.0)), gy = ifloor((y - 0.1) / ((h - 0.2) / 4.0));
  bool on = false;
  if (gx >= 0 && gx < 4 && gy >= 0 && gy < 4) on = (code >> (gx + 4 * gy)) & 1u;
  const Vec3f fill = b.colour, sym = grey(0.92f);
  return mixv(mixv(fill, sym, 0.4f), on ? sym : fill, k);
}

}  // namespace

Vec3f shade(const World::Impl& w, const Eigen::Vector3d& dir, const Hit& hit, const RayContext& ctx,
            const Appearance& app) {
  const Vec3f wb = app.white_balance.cast<float>();
  const float light_scale =
      static_cast<float>((app.ambient_intensity + 0.6 * app.sun_intensity) / (0.45 + 0.6 * 0.75));
  const Vec3f horizon = Vec3f(0.78f, 0.82f, 0.88f) * light_scale;
  if (hit.kind == SurfaceKind::kSky) {
    const float el = static_cast<float>(std::max(0.0, dir.z()));
    const Vec3f zenith = Vec3f(0.36f, 0.5f, 0.78f) * light_scale;
    return mixv(horizon, zenith, std::sqrt(el)).cwiseProduct(wb);
  }
  const Eigen::Vector3d p = ctx.origin + hit.t * dir;
  Eigen::Vector3d n = Eigen::Vector3d::UnitZ();
  Vec3f albedo(0.5f, 0.5f, 0.5f);
  double fp = hit.t * ctx.pixel_angle;
  float ao = 1.0f;
  switch (hit.kind) {
    case SurfaceKind::kGround: {
      fp /= std::max(0.15, -dir.z());
      albedo = ground(hit.route, p, fp, static_cast<std::uint32_t>(w.options.seed * 2654435761u));
      break;
    }
    case SurfaceKind::kCanopy: {
      const Sphere& s = w.spheres[hit.obj];
      n = (p - Eigen::Vector3d(s.cx, s.cy, s.cz)) / s.r;
      const double a = std::atan2(n.y(), n.x()) * s.r, e = p.z();
      const float clump = fbm(a, e, 0.7, fp, 3, s.seed);
      const float leaf = 0.85f + 0.3f * detail_fade(0.05, fp) *
                                     (hash2f(ifloor(a * 14), ifloor(e * 14), s.seed + 1u) - 0.5f);
      albedo = Vec3f(0.12f, 0.22f, 0.07f) * ((0.55f + 0.9f * clump) * leaf);
      ao = 0.6f + 0.4f * static_cast<float>(0.5 + 0.5 * n.z());
      break;
    }
    default: {
      const Box& b = w.boxes[hit.obj];
      const double sgn = (hit.face % 2 == 0) ? -1.0 : 1.0;
      if (hit.face < 2)
        n = sgn * Eigen::Vector3d(b.ca, b.sa, 0);
      else if (hit.face < 4)
        n = sgn * Eigen::Vector3d(-b.sa, b.ca, 0);
      else
        n = sgn * Eigen::Vector3d::UnitZ();
      fp /= std::max(0.2, std::abs(n.dot(dir)));
      if (hit.kind == SurfaceKind::kBuilding) {
        const Building& bd = w.buildings[b.index];
        if (hit.face >= 4) {
          albedo = grey(0.25f) * (0.8f + 0.4f * fbm(p.x(), p.y(), 2.0, fp, 2, b.seed));
        } else {
          double u = 0, width = 0;
          switch (hit.face) {
            case 0:
              u = b.hy - hit.ly;
              width = 2 * b.hy;
              break;
            case 1:
              u = hit.ly + b.hy;
              width = 2 * b.hy;
              break;
            case 2:
              u = hit.lx + b.hx;
              width = 2 * b.hx;
              break;
            default:
              u = b.hx - hit.lx;
              width = 2 * b.hx;
              break;
          }
          (void)width;
          const FaceStyle& f = w.styles[bd.style_base + 2 * hit.face + (ctx.street_view ? 1 : 0)];
          albedo = facade(f, u, hit.lz, b.z1 - b.z0, fp);
          ao = static_cast<float>(std::min(1.0, 0.7 + 0.3 * hit.lz));
        }
      } else if (hit.kind == SurfaceKind::kCar) {
        albedo = car(b, hit.face, hit.lx, hit.ly, hit.lz, fp, b.part == 1);
      } else if (hit.kind == SurfaceKind::kPole) {
        albedo = b.colour * (0.9f + 0.2f * fbm(hit.lz, 0.0, 0.3, fp, 2, b.seed));
      } else if (hit.kind == SurfaceKind::kSign) {
        albedo = sign_panel(b, hit.face, hit.ly, hit.lz, fp);
      } else if (hit.kind == SurfaceKind::kTrunk) {
        const float bark = fbm(hit.lx * 6.0 + hit.ly * 6.0, hit.lz * 0.8, 0.15, fp, 2, b.seed);
        albedo = Vec3f(0.26f, 0.19f, 0.12f) * (0.6f + 0.8f * bark);
      }
      break;
    }
  }
  const double cos_sun = std::max(0.0, n.dot(app.sun_direction));
  const float sky_light = static_cast<float>(0.75 + 0.25 * n.z());
  const float light = static_cast<float>(app.ambient_intensity) * sky_light * ao +
                      static_cast<float>(app.sun_intensity * cos_sun);
  Vec3f c = albedo.cwiseProduct(wb) * light;
  const float haze = 1.0f - std::exp(-static_cast<float>(hit.t) / 700.0f);
  return mixv(c, horizon.cwiseProduct(wb), haze);
}

}  // namespace geodrift::render::detail
