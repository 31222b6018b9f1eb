#pragma once
// Binary serialisation helpers of the geotag database (little-endian host assumed, checked by a
// byte-order mark in the file header). Private to frontends/geotag/src.

#include <cstdint>
#include <istream>
#include <opencv2/core.hpp>
#include <ostream>
#include <string>

#include "geodrift/error.hpp"

namespace geodrift::geotag::io {

template <class T>
void write_pod(std::ostream& os, const T& v) {
  os.write(reinterpret_cast<const char*>(&v), sizeof(T));
}

template <class T>
T read_pod(std::istream& is, const char* what) {
  T v{};
  is.read(reinterpret_cast<char*>(&v), sizeof(T));
  if (is.gcount() != static_cast<std::streamsize>(sizeof(T)))
    throw Error(std::string("geotag database is truncated (reading ") + what + ")");
  return v;
}

inline void write_string(std::ostream& os, const std::string& s) {
  write_pod<std::uint32_t>(os, static_cast<std::uint32_t>(s.size()));
  os.write(s.data(), static_cast<std::streamsize>(s.size()));
}

inline std::string read_string(std::istream& is, const char* what) {
  const std::uint32_t n = read_pod<std::uint32_t>(is, what);
  if (n > (1u << 20)) throw Error(std::string("geotag database: corrupt string (") + what + ")");
  std::string s(n, '\0');
  is.read(s.data(), n);
  if (is.gcount() != static_cast<std::streamsize>(n))
    throw Error(std::string("geotag database is truncated (reading ") + what + ")");
  return s;
}

/// A continuous matrix: rows, cols, type, raw bytes.
inline void write_mat(std::ostream& os, const cv::Mat& m) {
  const cv::Mat c = m.isContinuous() ? m : m.clone();
  write_pod<std::int32_t>(os, c.rows);
  write_pod<std::int32_t>(os, c.cols);
  write_pod<std::int32_t>(os, c.type());
  os.write(reinterpret_cast<const char*>(c.data),
           static_cast<std::streamsize>(c.total() * c.elemSize()));
}

inline cv::Mat read_mat(std::istream& is, const char* what) {
  const int rows = read_pod<std::int32_t>(is, what), cols = read_pod<std::int32_t>(is, what);
  const int type = read_pod<std::int32_t>(is, what);
  if (rows < 0 || cols < 0 || (rows > 0 && cols > 0 && double(rows) * cols > 1e9) ||
      (type != CV_8U && type != CV_32F && type != CV_8UC1))
    throw Error(std::string("geotag database: corrupt matrix (") + what + ")");
  cv::Mat m(rows, cols, type);
  const std::streamsize n = static_cast<std::streamsize>(m.total() * m.elemSize());
  is.read(reinterpret_cast<char*>(m.data), n);
  if (is.gcount() != n)
    throw Error(std::string("geotag database is truncated (reading ") + what + ")");
  return m;
}

}  // namespace geodrift::geotag::io
