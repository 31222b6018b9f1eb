#pragma once
/// @file
/// Helpers shared by the subcommands: option parsing, progress on a TTY, and small formatting
/// helpers; the atomic output folder (no partial outputs) is in output_dir.hpp.

#include <unistd.h>

#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <filesystem>
#include <geodrift/error.hpp>
#include <geodrift/io/detail/text_io.hpp>
#include <iomanip>
#include <map>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "output_dir.hpp"

namespace geodrift::cli {

/// A usage error (unknown option, missing value, bad syntax): exit code 2.
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Command-line options of one subcommand: "--name value", "--name=value" or a flag "--name".
class Args {
 public:
  /// @param valued options that take a value; @param flags options that do not.
  /// @throws UsageError for an unknown option, a missing value, a positional argument or an
  ///         option given twice.
  Args(int argc, char** argv, const std::set<std::string>& valued,
       const std::set<std::string>& flags) {
    for (int i = 1; i < argc; ++i) {
      std::string a = argv[i];
      if (a.rfind("--", 0) != 0 || a.size() < 3) {
        if (a == "-h") {
          flags_.insert("help");
          continue;
        }
        throw UsageError("unexpected argument '" + a + "' (options start with --)");
      }
      std::string key = a.substr(2), value;
      bool has_value = false;
      const auto eq = key.find('=');
      if (eq != std::string::npos) {
        value = key.substr(eq + 1);
        key = key.substr(0, eq);
        has_value = true;
      }
      if (flags.count(key)) {
        if (has_value) throw UsageError("option --" + key + " takes no value");
        flags_.insert(key);
      } else if (valued.count(key)) {
        if (!has_value) {
          if (i + 1 >= argc) throw UsageError("option --" + key + " needs a value");
          value = argv[++i];
        }
        if (values_.count(key)) throw UsageError("option --" + key + " given twice");
        values_[key] = value;
      } else {
        throw UsageError("unknown option '--" + key + "' (see --help)");
      }
    }
  }
  bool flag(const std::string& k) const { return flags_.count(k) != 0; }
  bool has(const std::string& k) const { return values_.count(k) != 0; }
  std::string get(const std::string& k, const std::string& def = "") const {
    const auto it = values_.find(k);
    return it == values_.end() ? def : it->second;
  }
  /// @throws UsageError when the option is absent.
  std::string required(const std::string& k) const {
    if (!has(k)) throw UsageError("missing required option --" + k + " (see --help)");
    return get(k);
  }
  /// Integer value. @throws UsageError when it is not an integer.
  long long get_int(const std::string& k, long long def) const {
    if (!has(k)) return def;
    const std::string v = get(k);
    std::size_t pos = 0;
    long long x = 0;
    try {
      x = std::stoll(v, &pos);
    } catch (const std::exception&) {
      pos = 0;
    }
    if (pos == 0 || pos != v.size())
      throw UsageError("option --" + k + ": '" + v + "' is not an integer");
    return x;
  }

 private:
  std::map<std::string, std::string> values_;
  std::set<std::string> flags_;
};

/// Splits "a,b,c" into finite numbers. @throws UsageError naming the option.
inline std::vector<double> parse_number_list(const std::string& option, const std::string& text,
                                             char sep = ',') {
  std::vector<double> out;
  std::stringstream ss(text);
  std::string tok;
  while (std::getline(ss, tok, sep)) {
    char* end = nullptr;
    const double v = std::strtod(tok.c_str(), &end);
    if (tok.empty() || end != tok.c_str() + tok.size() || !std::isfinite(v))
      throw UsageError("option --" + option + ": '" + tok + "' in '" + text +
                       "' is not a finite number");
    out.push_back(v);
  }
  return out;
}

/// True when stderr is a terminal (progress is shown only then).
inline bool stderr_is_tty() { return ::isatty(::fileno(stderr)) != 0; }

/// printf-style formatting into a string (messages with numbers in them).
#if defined(__GNUC__)
__attribute__((format(printf, 1, 2)))
#endif
inline std::string
strprintf(const char* format, ...) {
  va_list args, again;
  va_start(args, format);
  va_copy(again, args);
  const int n = std::vsnprintf(nullptr, 0, format, args);
  va_end(args);
  std::string out(n > 0 ? static_cast<std::size_t>(n) : 0, '\0');
  if (n > 0) std::vsnprintf(out.data(), out.size() + 1, format, again);
  va_end(again);
  return out;
}

/// The command line as one string (for report.json).
inline std::string command_line(int argc, char** argv) {
  std::string s = "geodrift";
  for (int i = 0; i < argc; ++i) s += std::string(" ") + argv[i];
  return s;
}

/// A number for report.json: shortest round-trip text, or null when not finite.
inline std::string json_num(double v) {
  return std::isfinite(v) ? io::detail::fmt(v) : std::string("null");
}

/// A number for a CSV cell: shortest round-trip text, or an empty cell when not finite.
inline std::string csv_num(double v) {
  return std::isfinite(v) ? io::detail::fmt(v) : std::string();
}

/// Reads a times file (one timestamp per non-comment line, strictly increasing) for `n` poses
/// of `for_path`.
inline std::vector<double> read_times_file(const std::string& path, std::size_t n,
                                           const std::string& for_path) {
  io::detail::LineReader reader(path);
  std::vector<double> t;
  std::string raw;
  while (reader.next(&raw)) {
    const std::string s = io::detail::trim(raw);
    if (s.empty() || s[0] == '#') continue;
    const auto f = io::detail::split_ws(s);
    if (f.size() != 1)
      io::detail::parse_error(
          path, reader.line(),
          "expected one timestamp, found " + std::to_string(f.size()) + " fields");
    const double v = io::detail::parse_double(f[0], path, reader.line(), "timestamp");
    if (!t.empty() && !(v > t.back())) {
      std::ostringstream os;
      os << std::setprecision(17) << "timestamp " << v << " does not increase (previous "
         << t.back() << ")";
      io::detail::parse_error(path, reader.line(), os.str());
    }
    t.push_back(v);
  }
  if (t.size() != n)
    throw InvalidArgument(path + ": " + std::to_string(t.size()) + " timestamps for " +
                          std::to_string(n) + " poses of " + for_path);
  return t;
}

}  // namespace geodrift::cli
