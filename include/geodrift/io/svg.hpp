#pragma once

/// @file
/// Simple SVG plots (SVG 1.1, no scripts, no external resources): topview.svg (several paths
/// seen from above in W's horizontal plane, equal aspect, north up, plus anchor markers) and
/// scale.svg (y(x) line plots such as the scale factor along the path). Each file carries a
/// <title>, a <desc> and a visible footer stating the geodrift version, frame and units.
///
/// Data coordinates are mapped to the canvas with y flipped (north / larger y up). Axis ticks are
/// "nice" numbers (1, 2, 5 × 10^k).

#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "geodrift/error.hpp"
#include "geodrift/io/detail/text_io.hpp"
#include "geodrift/version.hpp"

namespace geodrift::io {

/// A polyline or data series: label (legend), CSS colour, stroke width (px), points (x, y).
struct SvgSeries {
  std::string label;
  std::string color = "#1f77b4";
  double width = 1.5;
  std::vector<Eigen::Vector2d> points;
  bool dashed = false;
};

/// A marker: a small circle with a label, e.g. an anchor.
struct SvgMarker {
  std::string label;
  Eigen::Vector2d position = Eigen::Vector2d::Zero();
  std::string color = "#d62728";
};

/// An uncertainty ellipse: the `probability` region of a 2D Gaussian with covariance `cov`
/// (m²) centred at `centre`, e.g. a keyframe's horizontal position uncertainty.
struct SvgEllipse {
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
  Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
};

namespace detail {

/// Tick step: a 1/2/5 × 10^k close to span / target_ticks.
inline double nice_step(double span, int target_ticks = 6) {
  if (!(span > 0.0)) return 1.0;
  const double raw = span / target_ticks;
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  const double f = raw / mag;
  return (f < 1.5 ? 1.0 : f < 3.5 ? 2.0 : f < 7.5 ? 5.0 : 10.0) * mag;
}

inline std::string tick_label(double v, double step) {
  std::ostringstream os;
  const int decimals = step >= 1.0 ? 0 : static_cast<int>(std::ceil(-std::log10(step) - 1e-9));
  os.setf(std::ios::fixed);
  os.precision(decimals);
  os << (std::abs(v) < 0.5 * step * 1e-6 ? 0.0 : v);
  return os.str();
}

struct PlotBox {
  double x0, x1, y0, y1;            // data range
  double left, top, width, height;  // canvas rectangle (px)
  double px(double x) const { return left + (x - x0) / (x1 - x0) * width; }
  double py(double y) const { return top + (1.0 - (y - y0) / (y1 - y0)) * height; }
};

/// Checks all series/markers are finite and returns the data bounding box (xmin, xmax, ymin,
/// ymax), padded when degenerate.
inline Eigen::Vector4d data_bounds(const std::vector<SvgSeries>& series,
                                   const std::vector<SvgMarker>& markers, const char* what) {
  double x0 = std::numeric_limits<double>::infinity(), x1 = -x0, y0 = x0, y1 = -x0;
  for (const SvgSeries& s : series)
    for (std::size_t i = 0; i < s.points.size(); ++i) {
      const Eigen::Vector2d& p = s.points[i];
      GEODRIFT_CHECK(p.allFinite(),
                     what << ": series '" << s.label << "' point " << i << " is not finite");
      x0 = std::min(x0, p.x()), x1 = std::max(x1, p.x());
      y0 = std::min(y0, p.y()), y1 = std::max(y1, p.y());
    }
  for (const SvgMarker& m : markers) {
    GEODRIFT_CHECK(m.position.allFinite(), what << ": marker '" << m.label << "' is not finite");
    x0 = std::min(x0, m.position.x()), x1 = std::max(x1, m.position.x());
    y0 = std::min(y0, m.position.y()), y1 = std::max(y1, m.position.y());
  }
  GEODRIFT_CHECK(std::isfinite(x0), what << ": nothing to plot (no points)");
  if (x1 - x0 < 1e-9) x0 -= 1.0, x1 += 1.0;
  if (y1 - y0 < 1e-9) y0 -= 1.0, y1 += 1.0;
  return {x0, x1, y0, y1};
}

inline void svg_axes(std::ostream& os, const PlotBox& b, const std::string& x_label,
                     const std::string& y_label) {
  os << "<rect x=\"" << b.left << "\" y=\"" << b.top << "\" width=\"" << b.width << "\" height=\""
     << b.height << "\" fill=\"none\" stroke=\"#444\"/>\n";
  const double sx = nice_step(b.x1 - b.x0), sy = nice_step(b.y1 - b.y0);
  for (double v = std::ceil(b.x0 / sx) * sx; v <= b.x1 + 1e-9 * sx; v += sx) {
    const double x = b.px(v);
    os << "<line x1=\"" << x << "\" y1=\"" << b.top << "\" x2=\"" << x << "\" y2=\""
       << b.top + b.height << "\" stroke=\"#ddd\"/>\n"
       << "<text x=\"" << x << "\" y=\"" << b.top + b.height + 16
       << "\" font-size=\"11\" text-anchor=\"middle\">" << tick_label(v, sx) << "</text>\n";
  }
  for (double v = std::ceil(b.y0 / sy) * sy; v <= b.y1 + 1e-9 * sy; v += sy) {
    const double y = b.py(v);
    os << "<line x1=\"" << b.left << "\" y1=\"" << y << "\" x2=\"" << b.left + b.width << "\" y2=\""
       << y << "\" stroke=\"#ddd\"/>\n"
       << "<text x=\"" << b.left - 6 << "\" y=\"" << y + 4
       << "\" font-size=\"11\" text-anchor=\"end\">" << tick_label(v, sy) << "</text>\n";
  }
  os << "<text x=\"" << b.left + b.width / 2 << "\" y=\"" << b.top + b.height + 36
     << "\" font-size=\"13\" text-anchor=\"middle\">" << xml_escape(x_label) << "</text>\n"
     << "<text x=\"" << b.left - 52 << "\" y=\"" << b.top + b.height / 2
     << "\" font-size=\"13\" text-anchor=\"middle\" transform=\"rotate(-90 " << b.left - 52 << ' '
     << b.top + b.height / 2 << ")\">" << xml_escape(y_label) << "</text>\n";
}

inline void svg_series(std::ostream& os, const PlotBox& b, const std::vector<SvgSeries>& series) {
  for (const SvgSeries& s : series) {
    if (s.points.empty()) continue;
    os << "<polyline data-label=\"" << xml_escape(s.label) << "\" fill=\"none\" stroke=\""
       << xml_escape(s.color) << "\" stroke-width=\"" << s.width << "\""
       << (s.dashed ? " stroke-dasharray=\"6 4\"" : "") << " points=\"";
    for (std::size_t i = 0; i < s.points.size(); ++i)
      os << (i ? " " : "") << fmt(b.px(s.points[i].x()), 8) << ',' << fmt(b.py(s.points[i].y()), 8);
    os << "\"/>\n";
  }
}

inline void svg_legend(std::ostream& os, double x, double y, const std::vector<SvgSeries>& series,
                       bool with_marker, const std::string& marker_label,
                       const std::string& marker_color) {
  int row = 0;
  for (const SvgSeries& s : series) {
    if (s.label.empty()) continue;
    const double yy = y + 18 * row++;
    os << "<line x1=\"" << x << "\" y1=\"" << yy << "\" x2=\"" << x + 24 << "\" y2=\"" << yy
       << "\" stroke=\"" << xml_escape(s.color) << "\" stroke-width=\"" << s.width << "\""
       << (s.dashed ? " stroke-dasharray=\"6 4\"" : "") << "/>\n<text x=\"" << x + 30 << "\" y=\""
       << yy + 4 << "\" font-size=\"12\">" << xml_escape(s.label) << "</text>\n";
  }
  if (with_marker) {
    const double yy = y + 18 * row;
    os << "<circle cx=\"" << x + 12 << "\" cy=\"" << yy << "\" r=\"4\" fill=\""
       << xml_escape(marker_color) << "\"/>\n<text x=\"" << x + 30 << "\" y=\"" << yy + 4
       << "\" font-size=\"12\">" << xml_escape(marker_label) << "</text>\n";
  }
}

inline void svg_begin(std::ostream& os, double w, double h, const std::string& title,
                      const std::string& desc) {
  os << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
     << "<svg xmlns=\"http://www.w3.org/2000/svg\" version=\"1.1\" width=\"" << w << "\" height=\""
     << h << "\" viewBox=\"0 0 " << w << ' ' << h << "\" font-family=\"sans-serif\">\n<title>"
     << xml_escape(title) << "</title>\n<desc>" << xml_escape(desc)
     << "</desc>\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n"
     << "<text x=\"" << w / 2 << "\" y=\"24\" font-size=\"16\" text-anchor=\"middle\">"
     << xml_escape(title) << "</text>\n";
}

inline void svg_end(std::ostream& os, double h, const std::string& desc) {
  os << "<text x=\"8\" y=\"" << h - 8 << "\" font-size=\"10\" fill=\"#666\">" << xml_escape(desc)
     << "</text>\n</svg>\n";
}

}  // namespace detail

/// Writes a top view of paths in W (x east, y north, metres; equal aspect, north up) with
/// markers (e.g. anchors), atomically.
/// @param path        output file.
/// @param paths       polylines in (x, y) of W.
/// @param markers     labelled points in (x, y) of W; the legend shows one entry
///                    `marker_label` for all of them when non-empty.
/// @param ellipses    uncertainty ellipses (drawn under the paths) at `ellipse_probability`.
/// @param title       plot title.
/// @param frame_note  statement of the frame (e.g. "W = UTM 32N shifted to ..."), written in
///                    <desc> and the footer with the geodrift version and units.
/// @throws InvalidArgument for a non-finite point or nothing to plot; Error on I/O failure.
inline void write_svg_topview(const std::string& path, const std::vector<SvgSeries>& paths,
                              const std::vector<SvgMarker>& markers, const std::string& title,
                              const std::string& frame_note,
                              const std::string& marker_label = "anchors",
                              const std::vector<SvgEllipse>& ellipses = {},
                              double ellipse_probability = 0.95) {
  const Eigen::Vector4d bb = detail::data_bounds(paths, markers, "write_svg_topview");
  // Equal aspect: fit the larger span into a 760 px square-ish area.
  const double dx = bb[1] - bb[0], dy = bb[3] - bb[2];
  const double pad = 0.05 * std::max(dx, dy);
  const double span_x = dx + 2 * pad, span_y = dy + 2 * pad;
  const double scale = 760.0 / std::max(span_x, span_y);
  detail::PlotBox b{bb[0] - pad, bb[1] + pad, bb[2] - pad,    bb[3] + pad,
                    80,          44,          span_x * scale, span_y * scale};
  const double W = b.left + b.width + 190, H = b.top + b.height + 70;
  const std::string desc = std::string("geodrift ") + kVersion + "; frame: " + frame_note +
                           "; axes: x east, y north, metres";
  detail::write_atomically(path, [&](std::ostream& os) {
    detail::svg_begin(os, W, H, title, desc);
    detail::svg_axes(os, b, "x (east) [m]", "y (north) [m]");
    // Ellipses under the paths: semi-axes √(χ²₂(p)·λ) along Σ's eigenvectors; SVG's y grows
    // downwards, so the angle changes sign. Non-finite or non-positive Σ are skipped.
    const double k2 = -2.0 * std::log(1.0 - ellipse_probability);
    for (const SvgEllipse& e : ellipses) {
      if (!e.cov.allFinite() || !e.centre.allFinite()) continue;
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(0.5 * (e.cov + e.cov.transpose()));
      if (!(es.eigenvalues()[0] >= 0)) continue;
      const Eigen::Vector2d major = es.eigenvectors().col(1);
      const double deg = std::atan2(major.y(), major.x()) * 180.0 / M_PI;
      const double rx = std::sqrt(k2 * es.eigenvalues()[1]) * scale;
      const double ry = std::sqrt(k2 * es.eigenvalues()[0]) * scale;
      const double cx = b.px(e.centre.x()), cy = b.py(e.centre.y());
      os << "<ellipse cx=\"" << detail::fmt(cx, 8) << "\" cy=\"" << detail::fmt(cy, 8) << "\" rx=\""
         << detail::fmt(std::max(rx, 0.3), 6) << "\" ry=\"" << detail::fmt(std::max(ry, 0.3), 6)
         << "\" transform=\"rotate(" << detail::fmt(-deg, 6) << " " << detail::fmt(cx, 8) << " "
         << detail::fmt(cy, 8)
         << ")\" fill=\"#ff7f0e\" fill-opacity=\"0.15\" stroke=\"#ff7f0e\" "
            "stroke-width=\"0.5\"/>\n";
    }
    detail::svg_series(os, b, paths);
    for (const SvgMarker& m : markers)
      os << "<circle cx=\"" << detail::fmt(b.px(m.position.x()), 8) << "\" cy=\""
         << detail::fmt(b.py(m.position.y()), 8) << "\" r=\"4\" fill=\""
         << detail::xml_escape(m.color) << "\"><title>" << detail::xml_escape(m.label)
         << "</title></circle>\n";
    detail::svg_legend(os, b.left + b.width + 16, b.top + 10, paths, !markers.empty(), marker_label,
                       markers.empty() ? "" : markers.front().color);
    if (!ellipses.empty()) {
      int rows = markers.empty() ? 0 : 1;
      for (const SvgSeries& p : paths) rows += !p.label.empty();
      const double ly = b.top + 10 + 18.0 * rows;
      os << "<ellipse cx=\"" << detail::fmt(b.left + b.width + 28, 8) << "\" cy=\""
         << detail::fmt(ly, 8)
         << "\" rx=\"9\" ry=\"5\" fill=\"#ff7f0e\" fill-opacity=\"0.15\" stroke=\"#ff7f0e\"/>\n"
         << "<text x=\"" << detail::fmt(b.left + b.width + 46, 8) << "\" y=\""
         << detail::fmt(ly + 4, 8) << "\" font-size=\"12\">"
         << detail::fmt(100 * ellipse_probability, 4) << " % ellipses</text>\n";
    }
    detail::svg_end(os, H, desc);
  });
}

/// Writes a y(x) line plot (e.g. the scale factor along the path), atomically.
/// @param reference_y draw a dashed horizontal reference line at this y (e.g. 1.0); NaN: none.
/// @throws InvalidArgument for a non-finite point or nothing to plot; Error on I/O failure.
inline void write_svg_line_plot(const std::string& path, const std::vector<SvgSeries>& series,
                                const std::string& title, const std::string& x_label,
                                const std::string& y_label, const std::string& frame_note,
                                double reference_y = std::numeric_limits<double>::quiet_NaN()) {
  std::vector<SvgMarker> none;
  Eigen::Vector4d bb = detail::data_bounds(series, none, "write_svg_line_plot");
  if (std::isfinite(reference_y))
    bb[2] = std::min(bb[2], reference_y), bb[3] = std::max(bb[3], reference_y);
  const double pady = 0.05 * (bb[3] - bb[2]);
  detail::PlotBox b{bb[0], bb[1], bb[2] - pady, bb[3] + pady, 80, 44, 720, 360};
  const double W = b.left + b.width + 190, H = b.top + b.height + 70;
  const std::string desc = std::string("geodrift ") + kVersion + "; " + frame_note;
  detail::write_atomically(path, [&](std::ostream& os) {
    detail::svg_begin(os, W, H, title, desc);
    detail::svg_axes(os, b, x_label, y_label);
    if (std::isfinite(reference_y))
      os << "<line x1=\"" << b.left << "\" y1=\"" << b.py(reference_y) << "\" x2=\""
         << b.left + b.width << "\" y2=\"" << b.py(reference_y)
         << "\" stroke=\"#888\" stroke-dasharray=\"4 4\"/>\n";
    detail::svg_series(os, b, series);
    detail::svg_legend(os, b.left + b.width + 16, b.top + 10, series, false, "", "");
    detail::svg_end(os, H, desc);
  });
}

}  // namespace geodrift::io
