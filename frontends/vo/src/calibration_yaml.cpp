// Calibration YAML read by geodrift itself (see calibration_yaml.hpp for the accepted forms).

#include "calibration_yaml.hpp"

#include <cmath>
#include <cstdlib>
#include <optional>
#include <sstream>
#include <utility>
#include <vector>

#include "geodrift/error.hpp"

namespace geodrift::vo::detail {
namespace {

/// Largest number of values a calibration matrix may list (OpenCV's calibration matrices are at
/// most 3x3, distortion at most 14; the cap only bounds work on garbage).
constexpr std::size_t kMaxMatrixValues = 256;

/// One `key: value` line; `children` holds the more-indented `key: value` lines below it.
struct Entry {
  std::string key;
  std::string value;  ///< trimmed; a flow list continued over lines is joined into one value
  int line = 0;
  std::vector<Entry> children;
};

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r");
  if (b == std::string::npos) return "";
  return s.substr(b, s.find_last_not_of(" \t\r") - b + 1);
}

std::string unquote(const std::string& s) {
  if (s.size() >= 2 && (s.front() == '"' || s.front() == '\'') && s.back() == s.front())
    return s.substr(1, s.size() - 2);
  return s;
}

/// At most 40 characters of a bad value, for messages.
std::string quoted(const std::string& s) {
  return "'" + (s.size() > 40 ? s.substr(0, 40) + "..." : s) + "'";
}

/// The line without a `# comment` (a '#' at the start or after a blank, outside quotes).
std::string strip_comment(const std::string& line) {
  char quote = 0;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char ch = line[i];
    if (quote) {
      if (ch == quote) quote = 0;
    } else if (ch == '"' || ch == '\'') {
      quote = ch;
    } else if (ch == '#' && (i == 0 || line[i - 1] == ' ' || line[i - 1] == '\t')) {
      return line.substr(0, i);
    }
  }
  return line;
}

/// Splits `key: value` (the colon followed by a blank or the end of the line).
bool split_key(const std::string& text, std::string* key, std::string* value) {
  for (std::size_t i = 0; i < text.size(); ++i) {
    if (text[i] != ':') continue;
    if (i + 1 < text.size() && text[i + 1] != ' ' && text[i + 1] != '\t') continue;
    *key = unquote(trim(text.substr(0, i)));
    *value = trim(text.substr(i + 1));
    return !key->empty();
  }
  return false;
}

class Parser {
 public:
  Parser(const std::string& text, std::string path) : path_(std::move(path)) { split(text); }

  bool read(Calibration* c) {
    const Entry* k = unique({"camera_matrix", "K"});
    if (k) {
      const std::vector<double> v = matrix(*k, /*want_square3=*/true);
      c->camera.fx = v[0];
      c->camera.cx = v[2];
      c->camera.fy = v[4];
      c->camera.cy = v[5];
      if (const Entry* d = unique({"distortion_coefficients", "D"}))
        c->distortion = matrix(*d, /*want_square3=*/false);
      image_side("image_width", &c->camera.width);
      image_side("image_height", &c->camera.height);
      return true;
    }
    return read_orb_slam(c);
  }

 private:
  [[noreturn]] void fail(int line, const std::string& what) const {
    throw InvalidArgument(path_ + ":" + std::to_string(line) + ": " + what);
  }

  /// Builds the top-level entries. A flow list `[ ...` open at the end of a line takes the
  /// following lines up to its `]`.
  void split(const std::string& text) {
    std::istringstream in(text);
    std::string raw;
    int lineno = 0;
    int top_indent = -1;
    Entry* open = nullptr;  // entry whose flow list is still open
    int open_depth = 0;
    while (std::getline(in, raw)) {
      ++lineno;
      const std::string line = strip_comment(raw);
      if (open) {
        open->value += " " + trim(line);
        open_depth = list_depth(open_depth, line);
        if (open_depth == 0) open = nullptr;
        continue;
      }
      const std::string t = trim(line);
      if (t.empty() || t[0] == '%' || t == "---" || t == "...") continue;
      const int indent = static_cast<int>(line.find_first_not_of(" \t"));
      std::string key, value;
      if (!split_key(t, &key, &value)) continue;  // not a `key: value` line: not ours to read
      if (top_indent < 0) top_indent = indent;
      Entry e{key, value, lineno, {}};
      Entry* added;
      if (indent <= top_indent || top_.empty()) {
        top_.push_back(std::move(e));
        added = &top_.back();
      } else {
        top_.back().children.push_back(std::move(e));
        added = &top_.back().children.back();
      }
      open_depth = list_depth(0, added->value);
      if (open_depth > 0) open = added;
    }
    if (open) fail(open->line, "'" + open->key + "': the list opened with '[' is never closed");
  }

  /// Bracket depth after `s`, starting from `depth` (never below zero).
  static int list_depth(int depth, const std::string& s) {
    for (char ch : s) {
      if (ch == '[') ++depth;
      if (ch == ']' && depth > 0) --depth;
    }
    return depth;
  }

  /// The one top-level entry with any of `names` (nullptr if none); two are an error.
  const Entry* unique(std::initializer_list<const char*> names) const {
    const Entry* found = nullptr;
    for (const Entry& e : top_)
      for (const char* n : names)
        if (e.key == n) {
          if (found)
            fail(e.line, "'" + e.key + "' repeats '" + found->key + "' of line " +
                             std::to_string(found->line));
          found = &e;
        }
    return found;
  }

  double number(const Entry& e, const std::string& token, const std::string& what) const {
    const std::string s = unquote(trim(token));
    char* end = nullptr;
    const double v = s.empty() ? 0.0 : std::strtod(s.c_str(), &end);
    if (s.empty() || end != s.c_str() + s.size())
      fail(e.line, "'" + e.key + "' " + what + " " + quoted(s) + " is not a number");
    return v;
  }

  /// The numbers of a `[a, b, ...]` flow list (nothing but blanks after the `]`).
  std::vector<double> list(const Entry& e, const std::string& text) const {
    const std::string t = trim(text);
    const auto close = t.find(']');
    if (t.empty() || t[0] != '[' || close == std::string::npos || t.find('[', 1) < close ||
        !trim(t.substr(close + 1)).empty())
      fail(e.line, "'" + e.key + "' " + quoted(t) + " is not a list [a, b, ...] of numbers");
    std::vector<double> v;
    std::istringstream items(t.substr(1, close - 1));
    std::string item;
    while (std::getline(items, item, ',')) {
      if (v.size() == kMaxMatrixValues)
        fail(e.line, "'" + e.key + "' lists more than " + std::to_string(kMaxMatrixValues) +
                         " numbers (a calibration matrix)");
      v.push_back(number(e, item, "item"));
    }
    if (v.empty()) fail(e.line, "'" + e.key + "' is an empty list");
    return v;
  }

  /// K (3x3, row-major) or a distortion vector (1xN or Nx1), from any accepted form.
  std::vector<double> matrix(const Entry& e, bool want_square3) const {
    std::string value = e.value;
    if (value.rfind("!!", 0) == 0) {
      const auto blank = value.find_first_of(" \t");
      const std::string tag = value.substr(0, blank);
      if (tag != "!!opencv-matrix")
        fail(e.line, "'" + e.key + "' has the tag " + quoted(tag) + ", expected !!opencv-matrix");
      value = blank == std::string::npos ? "" : trim(value.substr(blank));
    }
    std::vector<double> v;
    int rows = 0, cols = 0;
    if (!value.empty() && value[0] == '[') {
      v = list(e, value);
      rows = want_square3 ? (v.size() == 9 ? 3 : 0) : 1;
      cols = want_square3 ? (v.size() == 9 ? 3 : 0) : static_cast<int>(v.size());
      if (want_square3 && rows == 0)
        fail(e.line, "'" + e.key + "' lists " + std::to_string(v.size()) +
                         " numbers, expected 9 (3x3, row-major)");
    } else if (!value.empty()) {
      fail(e.line, "'" + e.key + "' is not a readable OpenCV matrix: " + quoted(value) +
                       " is neither a list [a, b, ...] nor an indented rows/cols/data block");
    } else {
      const Entry* data = nullptr;
      for (const Entry& child : e.children) {
        if (child.key == "rows" || child.key == "cols") {
          const double d = number(child, child.value, "value");
          if (!(d >= 1 && d <= 16 && d == std::floor(d)))
            fail(child.line, "'" + e.key + "' " + child.key +
                                 " is not an integer in [1, 16] (a calibration matrix)");
          (child.key == "rows" ? rows : cols) = static_cast<int>(d);
        } else if (child.key == "data") {
          data = &child;
        }
      }
      if (rows == 0 || cols == 0 || !data)
        fail(e.line,
             "'" + e.key + "' is not a readable OpenCV matrix: it needs rows, cols and data");
      v = list(*data, data->value);
      if (v.size() != static_cast<std::size_t>(rows) * cols)
        fail(data->line, "'" + e.key + "' data lists " + std::to_string(v.size()) +
                             " numbers, rows x cols is " + std::to_string(rows) + "x" +
                             std::to_string(cols));
    }
    if (want_square3 && (rows != 3 || cols != 3))
      fail(e.line, "camera matrix '" + e.key + "' is " + std::to_string(rows) + "x" +
                       std::to_string(cols) + ", expected 3x3");
    if (!want_square3 && rows != 1 && cols != 1)
      fail(e.line, "distortion '" + e.key + "' is " + std::to_string(rows) + "x" +
                       std::to_string(cols) + ", expected one row or one column");
    return v;
  }

  void image_side(const char* name, int* out) const {
    const Entry* e = unique({name});
    if (!e) return;
    const double v = number(*e, e->value, "value");
    if (!(v >= 0 && v <= kMaxCalibrationImageSide && v == std::floor(v)))
      fail(e->line, std::string(name) + " is not an integer in [0, " +
                        std::to_string(kMaxCalibrationImageSide) + "]");
    *out = static_cast<int>(v);
  }

  /// ORB-SLAM2 (`Camera.fx`) and ORB-SLAM3 (`Camera1.fx`) settings files.
  bool read_orb_slam(Calibration* c) const {
    for (const char* prefix : {"Camera.", "Camera1."}) {
      const auto get = [&](const char* name) -> std::optional<double> {
        const std::string key = std::string(prefix) + name;
        const Entry* e = unique({key.c_str()});
        if (!e) return std::nullopt;
        return number(*e, e->value, "value");
      };
      const std::optional<double> fx = get("fx");
      if (!fx) continue;
      if (const Entry* type = unique({"Camera.type"})) {
        const std::string t = unquote(type->value);
        if (t != "PinHole")
          fail(type->line, "Camera.type " + quoted(t) +
                               " is not supported (geodrift reads pinhole cameras with OpenCV "
                               "distortion: PinHole)");
      }
      const std::optional<double> fy = get("fy"), cx = get("cx"), cy = get("cy");
      if (!fy || !cx || !cy)
        throw InvalidArgument(path_ + ": " + prefix + "fx is given but not all of " + prefix +
                              "fy, cx, cy");
      c->camera.fx = *fx;
      c->camera.fy = *fy;
      c->camera.cx = *cx;
      c->camera.cy = *cy;
      std::vector<double> d;
      for (const char* name : {"k1", "k2", "p1", "p2"})
        if (const std::optional<double> x = get(name)) d.push_back(*x);
      if (!d.empty() && d.size() != 4)
        throw InvalidArgument(path_ + ": " + prefix + "k1, k2, p1, p2 must be given together");
      if (const std::optional<double> k3 = get("k3")) {
        if (d.empty())
          throw InvalidArgument(path_ + ": " + prefix + "k3 is given without k1, k2, p1, p2");
        d.push_back(*k3);
      }
      c->distortion = d;
      image_side("Camera.width", &c->camera.width);
      image_side("Camera.height", &c->camera.height);
      return true;
    }
    return false;
  }

  std::string path_;
  std::vector<Entry> top_;
};

}  // namespace

bool parse_calibration_yaml(const std::string& text, const std::string& path, Calibration* c) {
  return Parser(text, path).read(c);
}

}  // namespace geodrift::vo::detail
