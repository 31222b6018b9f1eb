// Bad input gives InvalidArgument with a message naming the problem.
#include <catch2/catch.hpp>
#include <cmath>
#include <limits>

#include "geodrift/error.hpp"
#include "geodrift/kvld/kvld.hpp"

namespace kvld = geodrift::kvld;
using Catch::Matchers::Contains;
using geodrift::InvalidArgument;

// Throws InvalidArgument and the message contains `text`.
#define CHECK_INVALID(expr, text)            \
  do {                                       \
    CHECK_THROWS_AS(expr, InvalidArgument);  \
    CHECK_THROWS_WITH(expr, Contains(text)); \
  } while (false)

TEST_CASE("ImageScale rejects empty, colour, tiny and non-finite images", "[kvld][errors]") {
  CHECK_INVALID(kvld::ImageScale(cv::Mat()), "empty");
  CHECK_INVALID(kvld::ImageScale(cv::Mat(20, 20, CV_8UC3, cv::Scalar(1, 2, 3))), "single-channel");
  CHECK_INVALID(kvld::ImageScale(cv::Mat(2, 20, CV_8U, cv::Scalar(0))), "smaller than 3x3");
  CHECK_INVALID(kvld::ImageScale(cv::Mat(10, 10, CV_8S, cv::Scalar(0))), "unsupported depth");
  cv::Mat nan_img(10, 10, CV_32F, cv::Scalar(1));
  nan_img.at<float>(4, 7) = std::numeric_limits<float>::quiet_NaN();
  CHECK_INVALID(kvld::ImageScale(nan_img), "(7, 4)");
  std::vector<float> buf(100, 1.0f);
  CHECK_INVALID(kvld::ImageScale(nullptr, 10, 10, 10), "null");
  CHECK_INVALID(kvld::ImageScale(buf.data(), 10, 10, 9), "stride");
  CHECK_INVALID(kvld::ImageScale(buf.data(), 10, 10, 10, 0.0), "base radius");
}

TEST_CASE("filter rejects bad keypoints, match indices and options", "[kvld][errors]") {
  const kvld::ImageScale s1(cv::Mat(60, 80, CV_8U, cv::Scalar(5)));
  const kvld::ImageScale s2(cv::Mat(40, 50, CV_8U, cv::Scalar(5)));
  const std::vector<kvld::Keypoint> F1{{10, 10, 2, 0}, {30, 40, 2, 0}};
  const std::vector<kvld::Keypoint> F2{{5, 5, 2, 0}, {20, 30, 2, 0}};
  const std::vector<kvld::Match> ok{{0, 0}, {1, 1}};
  CHECK_NOTHROW(kvld::filter(s1, s2, F1, F2, ok));

  CHECK_INVALID(kvld::filter(s1, s2, F1, F2, {{0, 0}, {2, 1}}),
                "match 1 refers to keypoint 2 of image 1, which has 2");
  CHECK_INVALID(kvld::filter(s1, s2, F1, F2, {{0, -1}}), "keypoint -1 of image 2");
  auto bad = F1;
  bad[1].x = std::numeric_limits<double>::quiet_NaN();
  CHECK_INVALID(kvld::filter(s1, s2, bad, F2, ok),
                "keypoint 1 of image 1 has a non-finite position");
  // Keypoints of image 1 used with the (smaller) scale space of image 2.
  CHECK_INVALID(kvld::filter(s2, s1, F1, F2, ok), "outside the 50x40 image");
  bad = F1;
  bad[0].scale = 0;
  CHECK_INVALID(kvld::filter(s1, s2, bad, F2, ok), "scale 0");
  bad = F1;
  bad[0].angle = std::numeric_limits<double>::quiet_NaN();
  CHECK_INVALID(kvld::filter(s1, s2, bad, F2, ok), "non-finite angle");
  kvld::Options no_geo;
  no_geo.geometry = false;
  CHECK_NOTHROW(kvld::filter(s1, s2, bad, F2, ok, no_geo));  // angle unused

  kvld::Options opt;
  opt.inlier_rate = 0;
  CHECK_INVALID(kvld::filter(s1, s2, F1, F2, ok, opt), "inlier_rate 0");
  opt = {};
  opt.K = 0;
  CHECK_INVALID(kvld::filter(s1, s2, F1, F2, ok, opt), "K 0");
  opt = {};
  opt.juge = std::nan("");
  std::string why;
  CHECK_FALSE(opt.validate(&why));
  CHECK_THAT(why, Contains("juge"));
  CHECK(kvld::Options{}.validate());

  const kvld::Result empty = kvld::filter(s1, s2, F1, F2, {});
  CHECK(empty.matches.empty());
  CHECK(empty.runs == 0);
  CHECK(empty.survival_ratio == 0.0);
}

TEST_CASE("compute_vld and match_putative reject bad input", "[kvld][errors]") {
  const kvld::ImageScale s(cv::Mat(30, 30, CV_8U, cv::Scalar(5)));
  CHECK_INVALID(kvld::compute_vld(s, 1, std::nan(""), 10, 10), "non-finite endpoint");
  const cv::Mat a(3, 32, CV_8U, cv::Scalar(0)), b(3, 16, CV_8U, cv::Scalar(0));
  CHECK_INVALID(kvld::match_putative(a, b), "widths differ");
  const cv::Mat f(3, 32, CV_32F, cv::Scalar(0));
  CHECK_INVALID(kvld::match_putative(a, f), "types differ");
  const cv::Mat i32(3, 32, CV_32S, cv::Scalar(0));
  CHECK_INVALID(kvld::match_putative(i32, i32), "CV_8UC1");
  kvld::PutativeOptions po;
  po.ratio = 1.5;
  CHECK_INVALID(kvld::match_putative(a, a, po), "ratio 1.5");
}
