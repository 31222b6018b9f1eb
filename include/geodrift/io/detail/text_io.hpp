#pragma once

/// @file
/// Implementation helpers of the io/ text readers and writers (trajectory, anchors, COLMAP,
/// CSV, GeoJSON, KML, PLY, SVG): line-numbered parse errors and atomic file writing. Nothing
/// outside io/ names these.
///
/// Error convention: a malformed input throws geodrift::InvalidArgument "<path>:<line>: <what>";
/// a file that cannot be opened, written or renamed throws geodrift::Error naming the path.

#include <unistd.h>

#include <Eigen/Core>
#include <atomic>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iomanip>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "geodrift/error.hpp"

namespace geodrift::io {

/// The length unit the writers state for a monocular map frame M (VO output, simulated SLAM):
/// its scale is arbitrary and drifts, so its coordinates are not metres.
inline constexpr const char* kMapUnits = "M units (arbitrary scale, not metres)";

}  // namespace geodrift::io

namespace geodrift::io::detail {

/// Throws InvalidArgument "<path>:<line>: <what>".
[[noreturn]] inline void parse_error(const std::string& path, int line, const std::string& what) {
  std::ostringstream os;
  os << path << ":" << line << ": " << what;
  throw InvalidArgument(os.str());
}

/// Opens `path` for reading. @throws Error "cannot open '<path>' for reading: <reason>".
inline std::ifstream open_for_reading(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec))
    throw Error("cannot open '" + path + "' for reading: it is a directory");
  std::ifstream in(path);
  if (!in) {
    throw Error("cannot open '" + path + "' for reading: " + std::strerror(errno));
  }
  return in;
}

/// Removes leading/trailing whitespace (including a CR of CRLF files).
inline std::string trim(const std::string& s) {
  const char* ws = " \t\r\n\f\v";
  const std::size_t b = s.find_first_not_of(ws);
  if (b == std::string::npos) return std::string();
  const std::size_t e = s.find_last_not_of(ws);
  return s.substr(b, e - b + 1);
}

/// Splits on runs of whitespace.
inline std::vector<std::string> split_ws(const std::string& s) {
  std::vector<std::string> out;
  std::istringstream is(s);
  std::string w;
  while (is >> w) out.push_back(w);
  return out;
}

/// Splits on commas, trimming each field (no quoting: geodrift's CSV fields never contain
/// commas).
inline std::vector<std::string> split_csv(const std::string& s) {
  std::vector<std::string> out;
  std::size_t start = 0;
  while (true) {
    const std::size_t c = s.find(',', start);
    out.push_back(trim(s.substr(start, c == std::string::npos ? std::string::npos : c - start)));
    if (c == std::string::npos) break;
    start = c + 1;
  }
  return out;
}

/// A field's text as quoted in an error message: at most 40 characters, longer ones cut with
/// their length given, so a corrupt multi-megabyte token does not flood the terminal.
inline std::string quote_field(const std::string& s) {
  if (s.size() <= 40) return "'" + s + "'";
  return "'" + s.substr(0, 32) + "...' (" + std::to_string(s.size()) + " characters)";
}

/// Parses a finite double; `field` names it in the error.
/// @throws InvalidArgument "<path>:<line>: <field> '<text>' is not a number" or "... is not
///         finite" for nan/inf.
inline double parse_double(const std::string& text, const std::string& path, int line,
                           const std::string& field) {
  const std::string s = trim(text);
  if (s.empty()) parse_error(path, line, field + " is empty");
  char* end = nullptr;
  errno = 0;
  const double v = std::strtod(s.c_str(), &end);
  if (end == s.c_str() || *end != '\0') {
    parse_error(path, line, field + " " + quote_field(s) + " is not a number");
  }
  if (!std::isfinite(v)) parse_error(path, line, field + " " + quote_field(s) + " is not finite");
  return v;
}

/// Parses an integer in [lo, hi]; `field` names it in the error.
inline long long parse_int(const std::string& text, const std::string& path, int line,
                           const std::string& field, long long lo = std::numeric_limits<int>::min(),
                           long long hi = std::numeric_limits<int>::max()) {
  const std::string s = trim(text);
  if (s.empty()) parse_error(path, line, field + " is empty");
  char* end = nullptr;
  errno = 0;
  const long long v = std::strtoll(s.c_str(), &end, 10);
  if (end == s.c_str() || *end != '\0' || errno == ERANGE) {
    parse_error(path, line, field + " " + quote_field(s) + " is not an integer");
  }
  if (v < lo || v > hi) {
    std::ostringstream os;
    os << field << " " << v << " outside [" << lo << ", " << hi << "]";
    parse_error(path, line, os.str());
  }
  return v;
}

/// Longest line LineReader accepts (64 MiB). geodrift's text formats have short lines except
/// COLMAP's images.txt, whose POINTS2D line holds ~30 bytes per keypoint (64 MiB is two million
/// keypoints in one image); a longer line is a binary or corrupt file, refused before it is
/// split into fields.
inline constexpr std::size_t kMaxLineBytes = std::size_t{64} << 20;

/// Line-by-line reader that knows the 1-based number of the line just read.
class LineReader {
 public:
  explicit LineReader(const std::string& path) : path_(path), in_(open_for_reading(path)) {}
  /// Reads the next line (without its newline and trailing CR). Returns false at end of file.
  /// @throws InvalidArgument "<path>:<line>: ..." for a line longer than kMaxLineBytes.
  bool next(std::string* line) {
    if (!std::getline(in_, *line)) {
      if (in_.bad()) throw Error("error while reading '" + path_ + "'");
      return false;
    }
    ++line_;
    if (line->size() > kMaxLineBytes) {
      const std::size_t n = line->size();
      line->clear();
      line->shrink_to_fit();
      parse_error(path_, line_,
                  "line of " + std::to_string(n) + " bytes, longer than the " +
                      std::to_string(kMaxLineBytes >> 20) +
                      " MiB limit (a binary or corrupt file?)");
    }
    if (!line->empty() && line->back() == '\r') line->pop_back();
    // A UTF-8 byte-order mark (spreadsheet exports) is not part of the first field.
    if (line_ == 1 && line->compare(0, 3, "\xEF\xBB\xBF") == 0) line->erase(0, 3);
    return true;
  }
  int line() const { return line_; }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
  std::ifstream in_;
  int line_ = 0;
};

/// Writes a file atomically: `write` fills a stream bound to a temporary file in the same
/// directory, which is renamed onto `path` only when everything succeeded. On any failure
/// (exception from `write`, I/O error, rename failure) the temporary file is removed and the
/// previous content of `path`, if any, is untouched: no partial file is ever left.
/// @throws Error naming the path on I/O failure; rethrows whatever `write` throws.
inline void write_atomically(const std::string& path,
                             const std::function<void(std::ostream&)>& write) {
  namespace fs = std::filesystem;
  static std::atomic<unsigned> counter{0};
  const fs::path target(path);
  const fs::path dir = target.has_parent_path() ? target.parent_path() : fs::path(".");
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) {
    throw Error("cannot write '" + path + "': directory '" + dir.string() + "' does not exist");
  }
  const fs::path tmp =
      dir / ("." + target.filename().string() + ".tmp." + std::to_string(::getpid()) + "." +
             std::to_string(counter.fetch_add(1)));
  try {
    {
      std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
      if (!out) {
        throw Error("cannot write '" + path + "': cannot create temporary file '" + tmp.string() +
                    "': " + std::strerror(errno));
      }
      out.exceptions(std::ios::failbit | std::ios::badbit);
      errno = 0;  // a failed write below leaves its cause here (ENOSPC, EFBIG, EIO, ...)
      write(out);
      out.flush();
      out.close();
    }
    fs::rename(tmp, target, ec);
    if (ec) throw Error("cannot write '" + path + "': rename failed: " + ec.message());
  } catch (const std::ios_base::failure& e) {
    const int err = errno;
    fs::remove(tmp, ec);
    throw Error("cannot write '" + path + "': I/O error: " +
                (err != 0 ? std::string(std::strerror(err)) : std::string(e.what())));
  } catch (...) {
    fs::remove(tmp, ec);
    throw;
  }
}

/// Formats a double: with precision 0 (default) the SHORTEST text that reads back to exactly
/// the same double (std::to_chars), e.g. 0.1 -> "0.1"; otherwise with `precision` significant
/// digits. "nan" for NaN.
inline std::string fmt(double v, int precision = 0) {
  if (std::isnan(v)) return "nan";
  if (precision <= 0) {
    char buf[64];
    const std::to_chars_result r = std::to_chars(buf, buf + sizeof(buf), v);
    if (r.ec == std::errc()) return std::string(buf, r.ptr);
    precision = 17;  // cannot happen with 64 chars; max_digits10 also round-trips
  }
  std::ostringstream os;
  os << std::setprecision(precision) << v;
  return os.str();
}

/// Formats a double with a fixed number of decimals (e.g. 3 for millimetres).
inline std::string fmt_fixed(double v, int decimals) {
  if (std::isnan(v)) return "nan";
  std::ostringstream os;
  os << std::fixed << std::setprecision(decimals) << v;
  return os.str();
}

/// XML/SVG text escaping.
inline std::string xml_escape(const std::string& s) {
  std::string out;
  out.reserve(s.size());
  for (const char c : s) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&apos;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

/// JSON string escaping (quotes included).
inline std::string json_string(const std::string& s) {
  std::string out = "\"";
  for (const char c : s) {
    switch (c) {
      case '"':
        out += "\\\"";
        break;
      case '\\':
        out += "\\\\";
        break;
      case '\n':
        out += "\\n";
        break;
      case '\t':
        out += "\\t";
        break;
      case '\r':
        out += "\\r";
        break;
      default:
        if (static_cast<unsigned char>(c) < 0x20) {
          char buf[8];
          std::snprintf(buf, sizeof(buf), "\\u%04x", c);
          out += buf;
        } else {
          out += c;
        }
    }
  }
  return out + "\"";
}

}  // namespace geodrift::io::detail
