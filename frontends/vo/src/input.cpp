// Calibration files and frame sources.

#include "geodrift/vo/input.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/utils/logger.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <opencv2/videoio/registry.hpp>
#include <sstream>
#include <utility>

#include "calibration_yaml.hpp"
#include "geodrift/error.hpp"

namespace fs = std::filesystem;

namespace geodrift::vo {
namespace {

std::vector<double> numbers_after(const std::string& line, std::size_t pos) {
  std::istringstream is(line.substr(pos));
  std::vector<double> v;
  double x;
  while (is >> x) v.push_back(x);
  return v;
}

constexpr int kMaxImageSide = detail::kMaxCalibrationImageSide;

/// Calibration files are a few kilobytes; anything larger is not one (and is not read whole).
constexpr std::uintmax_t kMaxCalibrationBytes = 16u << 20;

bool read_text_calibration(const std::string& path, Calibration* c) {
  std::ifstream in(path);
  if (!in) throw Error("cannot read calibration file '" + path + "'");
  std::string line;
  bool have_k = false;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    const auto colon = line.find(':');
    if (colon == std::string::npos) continue;
    std::string key = line.substr(0, colon);
    key.erase(0, key.find_first_not_of(" \t"));
    key.erase(key.find_last_not_of(" \t") + 1);
    const std::vector<double> v = numbers_after(line, colon + 1);
    if (key == "P0" || (key == "K" && v.size() == 9)) {
      GEODRIFT_CHECK(key != "P0" || v.size() == 12, path << ":" << lineno << ": P0 has " << v.size()
                                                         << " numbers, expected 12 (3x4)");
      const int row = key == "P0" ? 4 : 3;
      c->camera.fx = v[0];
      c->camera.cx = v[2];
      c->camera.fy = v[row + 1];
      c->camera.cy = v[row + 2];
      have_k = true;
    } else if (key == "D") {
      c->distortion = v;
    } else if (key == "size" && v.size() == 2) {
      // Checked before the cast: a double outside int's range does not convert (UB).
      for (double d : v)
        GEODRIFT_CHECK(d >= 0 && d <= kMaxImageSide && d == std::floor(d),
                       path << ":" << lineno << ": image size " << d << " is not an integer in [0, "
                            << kMaxImageSide << "]");
      c->camera.width = static_cast<int>(v[0]);
      c->camera.height = static_cast<int>(v[1]);
    }
  }
  return have_k;
}

/// OpenCV FileStorage XML (`<opencv_storage>`). YAML never reaches OpenCV's parser, which can
/// loop forever on malformed YAML (docs/fuzzing.md); geodrift reads YAML itself.
bool read_xml_calibration(const std::string& path, Calibration* c) {
  cv::FileStorage fs;
  // Not a FileStorage file: no calibration found here (load_calibration says so). OpenCV's
  // parser throws cv::Exception for most malformed files but std::length_error for some (an
  // unknown !!type tag followed by a key without a value), so any std::exception means "not
  // parsable".
  try {
    if (!fs.open(path, cv::FileStorage::READ)) return false;
  } catch (const std::exception&) {
    return false;
  }
  cv::Mat K, D;
  // OpenCV throws cv::Exception for a node that is not a matrix (a scalar, a sequence, a
  // malformed !!opencv-matrix); geodrift reports it as its own error naming the file.
  // OpenCV also allocates rows x cols before it counts the data, so a calibration matrix's size
  // is checked first (K is 3x3, D at most 1x14 or 14x1).
  const auto read_matrix = [&](std::initializer_list<const char*> names, cv::Mat* m) {
    for (const char* name : names) {
      try {
        const cv::FileNode node = fs[name];
        if (node.empty()) continue;
        if (node.isMap()) {
          for (const char* dim : {"rows", "cols"}) {
            const cv::FileNode d = node[dim];
            GEODRIFT_CHECK(d.isInt() && static_cast<int>(d) >= 1 && static_cast<int>(d) <= 16,
                           path << ": '" << name << "' " << dim
                                << " is not an integer in [1, 16] (a calibration matrix)");
          }
        }
        node >> *m;
      } catch (const cv::Exception& e) {
        throw InvalidArgument(path + ": '" + name + "' is not a readable OpenCV matrix (" + e.err +
                              ")");
      } catch (const Error&) {
        throw;
      } catch (const std::exception& e) {
        throw InvalidArgument(path + ": '" + name + "' is not a readable OpenCV matrix (" +
                              e.what() + ")");
      }
      GEODRIFT_CHECK(m->empty() || m->channels() == 1,
                     path << ": '" << name << "' has " << m->channels() << " channels, expected 1");
    }
  };
  read_matrix({"camera_matrix", "K"}, &K);
  read_matrix({"distortion_coefficients", "D"}, &D);
  if (K.empty()) return false;
  GEODRIFT_CHECK(K.rows == 3 && K.cols == 3,
                 path << ": camera matrix is " << K.rows << "x" << K.cols << ", expected 3x3");
  K.convertTo(K, CV_64F);
  c->camera.fx = K.at<double>(0, 0);
  c->camera.fy = K.at<double>(1, 1);
  c->camera.cx = K.at<double>(0, 2);
  c->camera.cy = K.at<double>(1, 2);
  if (!D.empty()) {
    D.convertTo(D, CV_64F);
    c->distortion.assign(D.begin<double>(), D.end<double>());
  }
  const std::pair<const char*, int*> sizes[] = {{"image_width", &c->camera.width},
                                                {"image_height", &c->camera.height}};
  for (const auto& [name, out] : sizes) {
    const cv::FileNode n = fs[name];
    if (n.empty()) continue;
    // Read as a real and checked before the cast (an int node converts exactly).
    const double v = n.isInt() || n.isReal() ? static_cast<double>(n) : -1.0;
    GEODRIFT_CHECK(v >= 0 && v <= kMaxImageSide && v == std::floor(v),
                   path << ": " << name << " is not an integer in [0, " << kMaxImageSide << "]");
    *out = static_cast<int>(v);
  }
  return true;
}

/// YAML (read by calibration_yaml.cpp) or, when the first character is '<', OpenCV XML.
bool read_yaml_calibration(const std::string& path, Calibration* c) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error("cannot read calibration file '" + path + "'");
  std::ostringstream text;
  text << in.rdbuf();
  const std::string s = text.str();
  const auto first = s.find_first_not_of(" \t\r\n");
  if (first != std::string::npos && s[first] == '<') return read_xml_calibration(path, c);
  return detail::parse_calibration_yaml(s, path, c);
}

bool is_image(const fs::path& p) {
  std::string e = p.extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char ch) { return std::tolower(ch); });
  return e == ".png" || e == ".jpg" || e == ".jpeg" || e == ".pgm" || e == ".ppm" || e == ".bmp" ||
         e == ".tif" || e == ".tiff";
}

cv::Mat to_gray(const cv::Mat& img) {
  if (img.channels() == 1 && img.depth() == CV_8U) return img;
  cv::Mat g = img;
  if (img.channels() == 3) cv::cvtColor(img, g, cv::COLOR_BGR2GRAY);
  if (img.channels() == 4) cv::cvtColor(img, g, cv::COLOR_BGRA2GRAY);
  if (g.depth() != CV_8U) {
    double lo, hi;
    cv::minMaxLoc(g, &lo, &hi);
    g.convertTo(g, CV_8U, g.depth() == CV_16U ? 1.0 / 256.0 : 255.0 / std::max(hi, 1e-12));
  }
  return g;
}

class FolderSource final : public FrameSource {
 public:
  FolderSource(const std::string& dir, double fps) {
    fs::path root(dir);
    if (!fs::is_directory(root)) throw Error("image folder '" + dir + "' does not exist");
    fs::path imgs = fs::is_directory(root / "image_0") ? root / "image_0" : root;
    for (const auto& e : fs::directory_iterator(imgs))
      if (e.is_regular_file() && is_image(e.path())) files_.push_back(e.path().string());
    std::sort(files_.begin(), files_.end());
    if (files_.empty()) throw Error("image folder '" + imgs.string() + "' holds no images");
    desc_ = imgs.string() + " (" + std::to_string(files_.size()) + " images)";
    std::ifstream t((root / "times.txt").string());
    double x;
    while (t >> x) times_.push_back(x);
    if (times_.size() != files_.size()) {
      times_.clear();
      for (std::size_t i = 0; i < files_.size(); ++i) times_.push_back(i / fps);
    }
  }
  bool next(Frame* f) override {
    if (i_ >= files_.size()) return false;
    const cv::Mat img = cv::imread(files_[i_], cv::IMREAD_UNCHANGED);
    if (img.empty()) throw Error("cannot read image '" + files_[i_] + "'");
    f->index = static_cast<int>(i_);
    f->timestamp = times_[i_];
    f->name = fs::path(files_[i_]).filename().string();
    f->gray = to_gray(img);
    ++i_;
    return true;
  }
  int size() const override { return static_cast<int>(files_.size()); }
  std::string description() const override { return desc_; }

 private:
  std::vector<std::string> files_;
  std::vector<double> times_;
  std::size_t i_ = 0;
  std::string desc_;
};

class VideoSource final : public FrameSource {
 public:
  explicit VideoSource(const std::string& path) : path_(path) {
    if (!fs::is_regular_file(path)) throw Error("video file '" + path + "' does not exist");
    // OpenCV logs every backend it tries on an undecodable file; the error below says it once.
    const auto level = cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_SILENT);
    // Only the backends that decode files: with CAP_ANY, OpenCV also offers the name to camera
    // backends (gphoto2 enumerates every USB device for it, and leaks while doing so).
    bool opened = false;
    for (const cv::VideoCaptureAPIs api :
         {cv::CAP_FFMPEG, cv::CAP_GSTREAMER, cv::CAP_OPENCV_MJPEG}) {
      if (opened || !cv::videoio_registry::hasBackend(api)) continue;
      try {
        opened = cap_.open(path, api) && cap_.isOpened();
      } catch (const cv::Exception&) {
        opened = false;
      }
    }
    cv::utils::logging::setLogLevel(level);
    if (!opened) throw Error("cannot open video '" + path + "' (not a video OpenCV can decode)");
    fps_ = cap_.get(cv::CAP_PROP_FPS);
    if (!(fps_ > 0 && fps_ < 1000)) fps_ = 30.0;
    if (!cap_.read(first_) || first_.empty())
      throw Error("video '" + path + "' has no readable frame");
  }
  bool next(Frame* f) override {
    cv::Mat img;
    if (!first_.empty()) {
      img = first_;
      first_.release();
    } else if (!cap_.read(img) || img.empty()) {
      return false;
    }
    const double ms = cap_.get(cv::CAP_PROP_POS_MSEC);
    f->index = i_;
    f->timestamp = (i_ > 0 && ms > 0) ? ms / 1000.0 : i_ / fps_;
    f->name = "frame_" + std::to_string(i_);
    f->gray = to_gray(img);
    ++i_;
    return true;
  }
  int size() const override { return -1; }
  std::string description() const override { return "video " + path_; }

 private:
  std::string path_;
  cv::VideoCapture cap_;
  cv::Mat first_;
  double fps_ = 30.0;
  int i_ = 0;
};

}  // namespace

Calibration load_calibration(const std::string& path) {
  if (!fs::is_regular_file(path)) throw Error("calibration file '" + path + "' does not exist");
  std::error_code ec;
  const std::uintmax_t bytes = fs::file_size(path, ec);
  GEODRIFT_CHECK(!ec && bytes <= kMaxCalibrationBytes,
                 "calibration file '" << path << "' is " << bytes
                                      << " bytes; a calibration file is at most "
                                      << (kMaxCalibrationBytes >> 20) << " MiB");
  Calibration c;
  c.source = path;
  std::string ext = fs::path(path).extension().string();
  const bool yaml_ext = ext == ".yaml" || ext == ".yml" || ext == ".xml";
  bool ok = yaml_ext ? read_yaml_calibration(path, &c) : read_text_calibration(path, &c);
  if (!ok && !yaml_ext) ok = read_yaml_calibration(path, &c);
  GEODRIFT_CHECK(ok, "calibration file '"
                         << path
                         << "' has no 'P0:' line, 'K:' line, OpenCV/ROS camera_matrix or "
                            "ORB-SLAM Camera.fx");
  GEODRIFT_CHECK(std::isfinite(c.camera.fx) && c.camera.fx > 0 && std::isfinite(c.camera.fy) &&
                     c.camera.fy > 0 && std::isfinite(c.camera.cx) && std::isfinite(c.camera.cy),
                 path << ": intrinsics fx " << c.camera.fx << " fy " << c.camera.fy << " cx "
                      << c.camera.cx << " cy " << c.camera.cy << " are not finite and positive");
  for (double d : c.distortion)
    GEODRIFT_CHECK(std::isfinite(d), path << ": distortion coefficient " << d << " not finite");
  GEODRIFT_CHECK(c.distortion.empty() || c.distortion.size() == 4 || c.distortion.size() == 5 ||
                     c.distortion.size() == 8,
                 path << ": " << c.distortion.size()
                      << " distortion coefficients, expected 4, 5 or 8 (OpenCV order)");
  return c;
}

std::unique_ptr<FrameSource> open_image_folder(const std::string& dir, double fps) {
  GEODRIFT_CHECK(fps > 0, "fps " << fps << " must be > 0");
  return std::make_unique<FolderSource>(dir, fps);
}

std::unique_ptr<FrameSource> open_video(const std::string& path) {
  return std::make_unique<VideoSource>(path);
}

std::string default_calibration_path(const std::string& image_dir) {
  const fs::path p = fs::path(image_dir) / "calib.txt";
  return fs::is_regular_file(p) ? p.string() : std::string();
}

cv::Mat Undistorter::apply(const cv::Mat& gray) {
  if (!calib_.has_distortion()) return gray;
  if (gray.size() != size_) {
    const map::Camera& c = calib_.camera;
    const cv::Matx33d K(c.fx, 0, c.cx, 0, c.fy, c.cy, 0, 0, 1);
    cv::initUndistortRectifyMap(K, calib_.distortion, cv::noArray(), K, gray.size(), CV_16SC2,
                                map1_, map2_);
    size_ = gray.size();
  }
  cv::Mat out;
  cv::remap(gray, out, map1_, map2_, cv::INTER_LINEAR, cv::BORDER_CONSTANT, 0);
  return out;
}

}  // namespace geodrift::vo
