#pragma once
// Internal state of render::World, shared by world.cpp (construction, tracing), shading.cpp
// (materials and lighting) and render.cpp (cameras, anti-aliasing, threads). Not installed.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "geodrift/geo/local_frame.hpp"
#include "geodrift/render/world.hpp"

namespace geodrift::render::detail {

// ---- hashing and noise (integer hashes: bit-identical on every platform) --------------------

inline std::uint64_t mix64(std::uint64_t x) {
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ULL;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebULL;
  x ^= x >> 31;
  return x;
}
inline std::uint64_t hash64(std::uint64_t a, std::uint64_t b = 0, std::uint64_t c = 0,
                            std::uint64_t d = 0) {
  std::uint64_t h = mix64(a + 0x9e3779b97f4a7c15ULL);
  h = mix64(h ^ (b + 0x632be59bd9b4e019ULL));
  h = mix64(h ^ (c + 0x85157af5a4b2c1d3ULL));
  h = mix64(h ^ (d + 0x2545f4914f6cdd1dULL));
  return h;
}
/// Uniform in [0, 1) from a 64-bit hash.
inline double u01(std::uint64_t h) { return static_cast<double>(h >> 11) * 0x1.0p-53; }

/// Fast 32-bit hash of two integers and a seed (per-sample textures).
inline std::uint32_t hash2i(std::int32_t x, std::int32_t y, std::uint32_t seed) {
  std::uint32_t h = seed ^ 0x9e3779b9u;
  h ^= static_cast<std::uint32_t>(x) * 0x85ebca6bu;
  h = (h << 13) | (h >> 19);
  h *= 5u;
  h += 0xe6546b64u;
  h ^= static_cast<std::uint32_t>(y) * 0xc2b2ae35u;
  h ^= h >> 16;
  h *= 0x85ebca6bu;
  h ^= h >> 13;
  h *= 0xc2b2ae35u;
  h ^= h >> 16;
  return h;
}
inline float hf(std::uint32_t h) { return static_cast<float>(h >> 8) * (1.0f / 16777216.0f); }
inline float hash2f(std::int32_t x, std::int32_t y, std::uint32_t seed) {
  return hf(hash2i(x, y, seed));
}

/// Deterministic RNG for world generation (splitmix64 stream).
class Rng {
 public:
  explicit Rng(std::uint64_t seed) : state_(seed) {}
  std::uint64_t next() {
    state_ += 0x9e3779b97f4a7c15ULL;
    return mix64(state_);
  }
  double uniform() { return u01(next()); }
  double uniform(double a, double b) { return a + (b - a) * uniform(); }
  int integer(int lo, int hi) {  // inclusive
    return lo + static_cast<int>(uniform() * (hi - lo + 1) * 0.999999999);
  }
  bool chance(double p) { return uniform() < p; }

 private:
  std::uint64_t state_;
};

inline int ifloor(double x) { return static_cast<int>(std::floor(x)); }

/// Value noise in [0, 1], C1 (smoothstep) interpolation of hashed lattice values.
inline float value_noise(double x, double y, std::uint32_t seed) {
  const int xi = ifloor(x), yi = ifloor(y);
  const float fx = static_cast<float>(x - xi), fy = static_cast<float>(y - yi);
  const float sx = fx * fx * (3 - 2 * fx), sy = fy * fy * (3 - 2 * fy);
  const float a = hash2f(xi, yi, seed), b = hash2f(xi + 1, yi, seed);
  const float c = hash2f(xi, yi + 1, seed), d = hash2f(xi + 1, yi + 1, seed);
  return (a + (b - a) * sx) + ((c + (d - c) * sx) - (a + (b - a) * sx)) * sy;
}

/// Band-limited fBm: octaves whose period is below ~2 footprints are faded out (their mean 0.5
/// remains), so the noise does not alias.
inline float fbm(double x, double y, double base_period, double footprint, int octaves,
                 std::uint32_t seed) {
  float sum = 0, norm = 0, amp = 1;
  double period = base_period;
  for (int o = 0; o < octaves; ++o) {
    const double fade = std::clamp(2.0 - 2.0 * footprint / period, 0.0, 1.0);
    float n = 0.5f;
    if (fade > 0)
      n = 0.5f +
          static_cast<float>(fade) * (value_noise(x / period, y / period, seed + 131u * o) - 0.5f);
    sum += amp * n;
    norm += amp;
    amp *= 0.55f;
    period *= 0.5;
  }
  return sum / norm;
}

/// Fade factor in [0, 1] for a detail of size `size` seen with pixel footprint `footprint`
/// (1 = fully visible, 0 = below the pixel: replace by its mean).
inline float detail_fade(double size, double footprint) {
  return static_cast<float>(std::clamp(1.5 - footprint / size, 0.0, 1.0));
}

using Vec3f = Eigen::Vector3f;

// ---- objects --------------------------------------------------------------------------------

inline constexpr std::uint8_t kMaskVideo = 1, kMaskStreetView = 2, kMaskBoth = 3;

/// Box standing along z, rotated by yaw about z: local x = (ca, sa), local y = (-sa, ca).
struct Box {
  double cx = 0, cy = 0, ca = 1, sa = 0, hx = 0, hy = 0, z0 = 0, z1 = 0;
  SurfaceKind kind = SurfaceKind::kBuilding;
  int index = 0;  // building / car / pole / sign / trunk index of its kind
  std::uint8_t mask = kMaskBoth;
  std::uint8_t part = 0;  // cars: 0 body, 1 cabin
  std::uint32_t seed = 0;
  Vec3f colour = Vec3f(0.5f, 0.5f, 0.5f);
};

struct Sphere {
  double cx = 0, cy = 0, cz = 0, r = 1;
  int index = 0;
  std::uint8_t mask = kMaskBoth;
  std::uint32_t seed = 0;
};

/// One facade (box side face) style.
struct FaceStyle {
  std::uint32_t seed = 0;
  int wall = 0;  // 0 brick, 1 plaster, 2 stone blocks, 3 glass curtain wall
  Vec3f wall_rgb{0.5f, 0.4f, 0.3f}, trim_rgb{0.8f, 0.8f, 0.75f}, frame_rgb{0.9f, 0.9f, 0.9f};
  float storey_h = 3.2f, win_w = 1.2f, win_h = 1.5f, sill = 0.9f, pitch = 2.6f, offset = 0.5f;
  int n_cols = 0;
  bool shop = false;
  float shop_unit = 6.0f;
  Vec3f sign_rgb{0.7f, 0.1f, 0.1f}, text_rgb{0.95f, 0.95f, 0.9f};
  float brick_w = 0.24f, brick_h = 0.075f;
  float width = 10.0f;  // face width (m)
  int storeys = 3;
  int door_col = -1;  // column of the entrance door (non-shop ground floors)
};

struct Building {
  int box = 0;
  int style_base = 0;  // styles[style_base + 2*face + variant], faces 0..3
  int storeys = 3;
};

/// Internal hit record: the public RayHit plus the object's local hit point.
struct Hit {
  double t = std::numeric_limits<double>::infinity();
  SurfaceKind kind = SurfaceKind::kSky;
  int obj = -1;                   // box or sphere index (internal arrays)
  int face = -1;                  // box face 0..5
  double lx = 0, ly = 0, lz = 0;  // hit point in the box frame (box centre at 0, z from z0)
  RoutePoint route;               // ground hits: the route point of the hit
};

/// Ray context shared by the rays of one image (same origin).
struct RayContext {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  double origin_above_ground = 1.65;  // origin z minus ground height under it
  bool street_view = false;
  double pixel_angle = 1.0 / 718.856;  // radians per pixel (texture band limit)
};

}  // namespace geodrift::render::detail

namespace geodrift::render {

struct World::Impl {
  WorldOptions options;
  std::vector<Eigen::Isometry3d> T_W_c;
  std::vector<double> frame_s;
  std::vector<int> frame_vertex;
  // Route polyline (camera centres with near-duplicates removed).
  std::vector<Eigen::Vector3d> pv;
  std::vector<double> ps;
  double s_lo = 0, s_hi = 0;  // generated arclength range

  // Nearest-vertex grid.
  double gx0 = 0, gy0 = 0, gcell = 2.0;
  int gnx = 0, gny = 0;
  std::vector<std::int32_t> nearest;

  // Objects and their grid (items: box index, or sphere index | kSphereBit).
  std::vector<detail::Box> boxes;
  std::vector<detail::Sphere> spheres;
  std::vector<detail::Building> buildings;
  std::vector<detail::FaceStyle> styles;
  double ocell = 4.0;
  int onx = 0, ony = 0;
  std::vector<std::uint32_t> cell_start, items;
  double max_top_z = 0;
  int n_cars_video = 0, n_cars_sv = 0, n_trees = 0, n_poles = 0, n_signs = 0;
  static constexpr std::uint32_t kSphereBit = 0x80000000u;

  geo::LocalFrame frame = geo::LocalFrame();

  RoutePoint nearest_route(double x, double y, double* dist = nullptr) const;
  double ground_z(double x, double y, RoutePoint* rp = nullptr) const;
  Eigen::Vector3d route_at(double s) const;
  detail::Hit trace(const Eigen::Vector3d& dir, const detail::RayContext& ctx) const;
};

namespace detail {
/// Linear RGB radiance seen along a ray (sky, haze and lighting included), before tone mapping.
Vec3f shade(const World::Impl& w, const Eigen::Vector3d& dir, const Hit& hit, const RayContext& ctx,
            const Appearance& app);
/// Tone map + white balance already applied: linear radiance -> display value in [0, 1].
inline float tone(float x) {
  x = std::max(x, 0.0f);
  return std::min(1.25f * x / (x + 0.25f), 1.0f);
}
}  // namespace detail

}  // namespace geodrift::render
