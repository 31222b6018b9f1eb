// Pinhole frames and equirectangular panoramas: ray generation, anti-aliasing, threads.
#include "geodrift/render/render.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <thread>
#include <vector>

#include "geodrift/error.hpp"
#include "world_impl.hpp"

namespace geodrift::render {
namespace {

using detail::Vec3f;

int thread_count(int requested) {
  if (requested > 0) return requested;
  const unsigned hw = std::thread::hardware_concurrency();
  return hw == 0 ? 1 : static_cast<int>(hw);
}

/// Runs body(row_begin, row_end) over [0, rows) in chunks on `threads` threads.
template <typename Body>
void parallel_rows(int rows, int threads, int chunk, const Body& body) {
  std::atomic<int> next{0};
  auto worker = [&]() {
    while (true) {
      const int r0 = next.fetch_add(chunk);
      if (r0 >= rows) break;
      body(r0, std::min(rows, r0 + chunk));
    }
  };
  const int n = std::max(1, std::min(threads, (rows + chunk - 1) / chunk));
  std::vector<std::thread> pool;
  for (int i = 1; i < n; ++i) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();
}

void check_options(const RenderOptions& o) {
  GEODRIFT_CHECK(o.grid_n >= 1 && o.grid_n <= 8,
                 "RenderOptions: grid_n " << o.grid_n << " outside [1, 8]");
  GEODRIFT_CHECK(o.threads >= 0, "RenderOptions: threads " << o.threads << " must be >= 0");
}

/// Renders an image whose pixel (col, row) is centred at sample coordinates (col, row):
/// dir_at(x, y) gives the unit W ray direction of sample coordinates (x, y).
template <typename DirFn>
cv::Mat render_image(const World::Impl& w, const detail::RayContext& ctx, const Appearance& app,
                     int width, int height, const RenderOptions& opt, const DirFn& dir_at) {
  check_options(opt);
  const Vec3f wb(1, 1, 1);
  auto sample = [&](double x, double y) -> Vec3f {
    const Eigen::Vector3d d = dir_at(x, y);
    const detail::Hit h = w.trace(d, ctx);
    const Vec3f c = detail::shade(w, d, h, ctx, app);
    return Vec3f(detail::tone(c.x()), detail::tone(c.y()), detail::tone(c.z()));
  };
  cv::Mat out(height, width, opt.color ? CV_8UC3 : CV_8UC1);
  auto store = [&](int row, int col, const Vec3f& c) {
    auto q = [](float v) {
      return static_cast<std::uint8_t>(std::clamp(std::lround(v * 255.0f), 0L, 255L));
    };
    if (opt.color) {
      out.at<cv::Vec3b>(row, col) = cv::Vec3b(q(c.z()), q(c.y()), q(c.x()));
    } else {
      out.at<std::uint8_t>(row, col) = q(0.299f * c.x() + 0.587f * c.y() + 0.114f * c.z());
    }
  };
  const int threads = thread_count(opt.threads);
  constexpr int kChunk = 8;
  parallel_rows(height, threads, kChunk, [&](int r0, int r1) {
    if (opt.antialias == Antialias::kQuincunx) {
      // Corner rows r0 .. r1 (corner (i, j) at (i - 0.5, j - 0.5)), shared between pixels.
      std::vector<Vec3f> corners(static_cast<std::size_t>(width + 1) * (r1 - r0 + 1));
      for (int j = r0; j <= r1; ++j)
        for (int i = 0; i <= width; ++i)
          corners[static_cast<std::size_t>(j - r0) * (width + 1) + i] = sample(i - 0.5, j - 0.5);
      for (int r = r0; r < r1; ++r)
        for (int c = 0; c < width; ++c) {
          const std::size_t k0 = static_cast<std::size_t>(r - r0) * (width + 1) + c;
          const std::size_t k1 = k0 + (width + 1);
          const Vec3f sum = corners[k0] + corners[k0 + 1] + corners[k1] + corners[k1 + 1];
          store(r, c, 0.5f * sample(c, r) + 0.125f * sum);
        }
    } else {
      const int n = opt.antialias == Antialias::kGrid ? opt.grid_n : 1;
      const float inv = 1.0f / static_cast<float>(n * n);
      for (int r = r0; r < r1; ++r)
        for (int c = 0; c < width; ++c) {
          Vec3f acc = Vec3f::Zero();
          for (int a = 0; a < n; ++a)
            for (int b = 0; b < n; ++b)
              acc += sample(c - 0.5 + (b + 0.5) / n, r - 0.5 + (a + 0.5) / n);
          store(r, c, acc * inv);
        }
    }
  });
  return out;
}

detail::RayContext make_context(const World& world, const Eigen::Vector3d& origin,
                                const Appearance& app, double pixel_angle) {
  detail::RayContext ctx;
  ctx.origin = origin;
  ctx.origin_above_ground = origin.z() - world.impl().ground_z(origin.x(), origin.y());
  ctx.street_view = app.street_view_content;
  ctx.pixel_angle = pixel_angle;
  return ctx;
}

}  // namespace

cv::Mat render_pinhole(const World& world, const lie::SE3d& T_cw, const map::Camera& camera,
                       const Appearance& appearance, const RenderOptions& options) {
  camera.validate();
  GEODRIFT_CHECK(T_cw.matrix().allFinite(), "render_pinhole: pose T_cw is not finite");
  const Eigen::Matrix3d R_wc = T_cw.rotation().matrix().transpose();
  const Eigen::Vector3d centre = -(R_wc * T_cw.translation());
  const detail::RayContext ctx = make_context(world, centre, appearance, 1.0 / camera.fx);
  const double ifx = 1.0 / camera.fx, ify = 1.0 / camera.fy;
  return render_image(world.impl(), ctx, appearance, camera.width, camera.height, options,
                      [&](double x, double y) {
                        const Eigen::Vector3d rc((x - camera.cx) * ifx, (y - camera.cy) * ify, 1.0);
                        return Eigen::Vector3d((R_wc * rc).normalized());
                      });
}

cv::Mat render_depth(const World& world, const lie::SE3d& T_cw, const map::Camera& camera,
                     const Appearance& appearance, int threads) {
  camera.validate();
  GEODRIFT_CHECK(T_cw.matrix().allFinite(), "render_depth: pose T_cw is not finite");
  const Eigen::Matrix3d R_wc = T_cw.rotation().matrix().transpose();
  const Eigen::Vector3d centre = -(R_wc * T_cw.translation());
  const detail::RayContext ctx = make_context(world, centre, appearance, 1.0 / camera.fx);
  cv::Mat out(camera.height, camera.width, CV_32FC1);
  parallel_rows(camera.height, thread_count(threads), 8, [&](int r0, int r1) {
    for (int r = r0; r < r1; ++r)
      for (int c = 0; c < camera.width; ++c) {
        const Eigen::Vector3d rc((c - camera.cx) / camera.fx, (r - camera.cy) / camera.fy, 1.0);
        const double len = rc.norm();
        const detail::Hit h = world.impl().trace(R_wc * rc / len, ctx);
        out.at<float>(r, c) = static_cast<float>(h.t / len);
      }
  });
  return out;
}

Eigen::Vector3d panorama_direction(double u, double v, int width, int height, double heading,
                                   double gamma) {
  const double beta = heading + 2.0 * M_PI * (u / width - 0.5);
  const double el = 0.5 * M_PI - M_PI * v / height;
  const double yaw = 0.5 * M_PI - beta + gamma;
  return Eigen::Vector3d(std::cos(el) * std::cos(yaw), std::cos(el) * std::sin(yaw), std::sin(el));
}

Eigen::Vector2d panorama_pixel(const Eigen::Vector3d& dir, int width, int height, double heading,
                               double gamma) {
  const Eigen::Vector3d d = dir.normalized();
  const double el = std::asin(std::clamp(d.z(), -1.0, 1.0));
  const double yaw = std::atan2(d.y(), d.x());
  double rel = 0.5 * M_PI - yaw + gamma - heading;  // bearing relative to the heading
  rel = std::remainder(rel, 2.0 * M_PI);            // (-pi, pi]
  double u = width * (rel / (2.0 * M_PI) + 0.5);
  if (u >= width) u -= width;
  if (u < 0) u += width;
  return Eigen::Vector2d(u, height * (0.5 * M_PI - el) / M_PI);
}

cv::Mat render_panorama(const World& world, const Eigen::Vector3d& centre, double heading,
                        const Appearance& appearance, const PanoramaOptions& options) {
  GEODRIFT_CHECK(centre.allFinite() && std::isfinite(heading),
                 "render_panorama: centre or heading not finite");
  GEODRIFT_CHECK(options.width >= 8 && options.height >= 4, "render_panorama: size "
                                                                << options.width << "x"
                                                                << options.height << " below 8x4");
  const double gamma = world.local_frame().meridian_convergence(centre);
  const int W = options.width, H = options.height;
  const detail::RayContext ctx = make_context(world, centre, appearance, 2.0 * M_PI / W);
  return render_image(world.impl(), ctx, appearance, W, H, options.render, [&](double x, double y) {
    return panorama_direction(x + 0.5, y + 0.5, W, H, heading, gamma);
  });
}

}  // namespace geodrift::render
