#include "geodrift/geotag/vocabulary.hpp"

#include <algorithm>
#include <cmath>
#include <istream>
#include <numeric>
#include <opencv2/core.hpp>
#include <ostream>
#include <random>

#include "geodrift/error.hpp"
#include "geotag_io.hpp"

namespace geodrift::geotag {

void root_sift(cv::Mat* d) {
  GEODRIFT_CHECK(d->empty() || d->type() == CV_32F, "root_sift: descriptors must be CV_32F");
  for (int r = 0; r < d->rows; ++r) {
    float* p = d->ptr<float>(r);
    double l1 = 0;
    for (int c = 0; c < d->cols; ++c) l1 += std::abs(p[c]);
    const double inv = l1 > 0 ? 1.0 / l1 : 0.0;
    for (int c = 0; c < d->cols; ++c) p[c] = static_cast<float>(std::sqrt(std::abs(p[c]) * inv));
  }
}

namespace {
/// Squared L2 distance. Eight partial sums let the compiler use vector registers without
/// -ffast-math (one serial float sum cannot be reordered); 128-dim descriptors are 16 steps.
float sq_dist(const float* a, const float* b, int n) {
  float acc[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  int i = 0;
  for (; i + 8 <= n; i += 8)
    for (int k = 0; k < 8; ++k) {
      const float d = a[i + k] - b[i + k];
      acc[k] += d * d;
    }
  float s = ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7]));
  for (; i < n; ++i) {
    const float d = a[i] - b[i];
    s += d * d;
  }
  return s;
}
}  // namespace

Vocabulary Vocabulary::train(const cv::Mat& descriptors, const Options& o,
                             const std::function<void(std::size_t, std::size_t)>& progress) {
  GEODRIFT_CHECK(o.branching >= 2 && o.branching <= 256,
                 "vocabulary branching " << o.branching << " outside [2, 256]");
  GEODRIFT_CHECK(o.depth >= 1 && o.depth <= 8, "vocabulary depth " << o.depth << " outside [1, 8]");
  GEODRIFT_CHECK(o.max_training_descriptors >= o.branching,
                 "vocabulary training subsample " << o.max_training_descriptors
                                                  << " smaller than the branching factor");
  GEODRIFT_CHECK(o.kmeans_iterations >= 1,
                 "k-means iterations " << o.kmeans_iterations << " must be >= 1");
  GEODRIFT_CHECK(descriptors.type() == CV_32F && descriptors.cols > 0,
                 "vocabulary training needs CV_32F descriptors");
  GEODRIFT_CHECK(
      descriptors.rows >= o.branching,
      "vocabulary training: " << descriptors.rows << " descriptors, need at least " << o.branching);
  std::vector<int> rows(descriptors.rows);
  std::iota(rows.begin(), rows.end(), 0);
  std::mt19937_64 rng(o.seed);
  if (static_cast<int>(rows.size()) > o.max_training_descriptors) {
    std::shuffle(rows.begin(), rows.end(), rng);
    rows.resize(o.max_training_descriptors);
    std::sort(rows.begin(), rows.end());
  }
  Vocabulary v;
  v.nodes_.emplace_back();
  v.centers_ = cv::Mat::zeros(1, descriptors.cols, CV_32F);
  const std::size_t total = rows.size();
  std::size_t done = 0;
  const auto leaf_done = [&](std::size_t n) {
    done += n;
    if (progress) progress(done, total);
  };
  // cv::kmeans draws from cv::theRNG(); seed it for a reproducible vocabulary.
  cv::theRNG().state = o.seed;
  v.build(descriptors, std::move(rows), 0, 0, o, leaf_done);
  return v;
}

void Vocabulary::build(const cv::Mat& data, std::vector<int> rows, int node, int level,
                       const Options& o, const std::function<void(std::size_t)>& leaf_done) {
  if (level == o.depth || static_cast<int>(rows.size()) < 2 * o.branching) {
    nodes_[node].word = num_words_++;
    leaf_done(rows.size());
    return;
  }
  cv::Mat sub(static_cast<int>(rows.size()), data.cols, CV_32F);
  for (std::size_t i = 0; i < rows.size(); ++i)
    data.row(rows[i]).copyTo(sub.row(static_cast<int>(i)));
  cv::Mat labels, centers;
  cv::kmeans(
      sub, o.branching, labels,
      cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, o.kmeans_iterations, 1e-4),
      1, cv::KMEANS_PP_CENTERS, centers);
  const int first = static_cast<int>(nodes_.size());
  nodes_[node].first_child = first;
  nodes_[node].num_children = o.branching;
  nodes_.resize(nodes_.size() + o.branching);
  cv::vconcat(centers_, centers, centers_);
  std::vector<std::vector<int>> parts(o.branching);
  for (std::size_t i = 0; i < rows.size(); ++i)
    parts[labels.at<int>(static_cast<int>(i))].push_back(rows[i]);
  for (int c = 0; c < o.branching; ++c)
    build(data, std::move(parts[c]), first + c, level + 1, o, leaf_done);
}

int Vocabulary::quantize(const float* d) const {
  GEODRIFT_CHECK(!nodes_.empty(), "quantize: the vocabulary is empty");
  int n = 0;
  const int dim = centers_.cols;
  while (nodes_[n].word < 0) {
    const Node& nd = nodes_[n];
    int best = nd.first_child;
    float best_d = sq_dist(d, centers_.ptr<float>(best), dim);
    for (int c = 1; c < nd.num_children; ++c) {
      const float dd = sq_dist(d, centers_.ptr<float>(nd.first_child + c), dim);
      if (dd < best_d) {
        best_d = dd;
        best = nd.first_child + c;
      }
    }
    n = best;
  }
  return nodes_[n].word;
}

std::vector<int> Vocabulary::quantize(const cv::Mat& d) const {
  GEODRIFT_CHECK(d.empty() || (d.type() == CV_32F && d.cols == centers_.cols),
                 "quantize: descriptors must be CV_32F with " << centers_.cols << " columns");
  std::vector<int> w(d.rows);
  for (int r = 0; r < d.rows; ++r) w[r] = quantize(d.ptr<float>(r));
  return w;
}

void Vocabulary::write(std::ostream& os) const {
  io::write_pod<std::int32_t>(os, num_words_);
  io::write_pod<std::int32_t>(os, static_cast<std::int32_t>(nodes_.size()));
  for (const Node& n : nodes_) {
    io::write_pod<std::int32_t>(os, n.first_child);
    io::write_pod<std::int32_t>(os, n.num_children);
    io::write_pod<std::int32_t>(os, n.word);
  }
  io::write_mat(os, centers_);
}

Vocabulary Vocabulary::read(std::istream& is) {
  Vocabulary v;
  v.num_words_ = io::read_pod<std::int32_t>(is, "vocabulary word count");
  const int n = io::read_pod<std::int32_t>(is, "vocabulary node count");
  GEODRIFT_CHECK(
      n >= 1 && n < (1 << 26) && v.num_words_ >= 1 && v.num_words_ <= n,
      "vocabulary: inconsistent sizes (" << n << " nodes, " << v.num_words_ << " words)");
  v.nodes_.resize(n);
  for (Node& nd : v.nodes_) {
    nd.first_child = io::read_pod<std::int32_t>(is, "vocabulary node");
    nd.num_children = io::read_pod<std::int32_t>(is, "vocabulary node");
    nd.word = io::read_pod<std::int32_t>(is, "vocabulary node");
    const bool leaf = nd.word >= 0;
    GEODRIFT_CHECK(leaf ? nd.word < v.num_words_
                        : (nd.first_child >= 1 && nd.num_children >= 1 &&
                           nd.first_child + nd.num_children <= n),
                   "vocabulary: corrupt node");
  }
  v.centers_ = io::read_mat(is, "vocabulary centres");
  GEODRIFT_CHECK(v.centers_.rows == n && v.centers_.type() == CV_32F,
                 "vocabulary: " << v.centers_.rows << " centres for " << n << " nodes");
  return v;
}

InvertedIndex::InvertedIndex(const std::vector<std::vector<int>>& doc_words, int num_words)
    : num_docs_(static_cast<int>(doc_words.size())), idf_(num_words, 0.0f), postings_(num_words) {
  std::vector<int> df(num_words, 0);
  std::vector<std::vector<std::pair<int, int>>> tf(doc_words.size());
  for (std::size_t d = 0; d < doc_words.size(); ++d) {
    std::vector<int> w = doc_words[d];
    std::sort(w.begin(), w.end());
    for (std::size_t i = 0; i < w.size();) {
      GEODRIFT_CHECK(w[i] >= 0 && w[i] < num_words,
                     "inverted index: word " << w[i] << " out of range");
      std::size_t j = i;
      while (j < w.size() && w[j] == w[i]) ++j;
      tf[d].push_back({w[i], static_cast<int>(j - i)});
      ++df[w[i]];
      i = j;
    }
  }
  for (int w = 0; w < num_words; ++w)
    idf_[w] = df[w] > 0 ? static_cast<float>(std::log(double(num_docs_) / df[w])) : 0.0f;
  for (std::size_t d = 0; d < tf.size(); ++d) {
    double norm2 = 0;
    for (const auto& [w, n] : tf[d]) norm2 += double(n * idf_[w]) * (n * idf_[w]);
    const double inv = norm2 > 0 ? 1.0 / std::sqrt(norm2) : 0.0;
    for (const auto& [w, n] : tf[d])
      if (idf_[w] > 0)
        postings_[w].push_back({static_cast<int>(d), static_cast<float>(n * idf_[w] * inv)});
  }
}

BowVector InvertedIndex::vectorize(const std::vector<int>& words) const {
  std::vector<int> w = words;
  std::sort(w.begin(), w.end());
  BowVector v;
  double norm2 = 0;
  for (std::size_t i = 0; i < w.size();) {
    std::size_t j = i;
    while (j < w.size() && w[j] == w[i]) ++j;
    GEODRIFT_CHECK(w[i] >= 0 && w[i] < static_cast<int>(idf_.size()),
                   "vectorize: word " << w[i] << " out of range");
    const float x = static_cast<float>(j - i) * idf_[w[i]];
    if (x > 0) {
      v.push_back({w[i], x});
      norm2 += double(x) * x;
    }
    i = j;
  }
  const float inv = norm2 > 0 ? static_cast<float>(1.0 / std::sqrt(norm2)) : 0.0f;
  for (auto& e : v) e.second *= inv;
  return v;
}

std::vector<float> InvertedIndex::scores(const BowVector& q) const {
  std::vector<float> s(num_docs_, 0.0f);
  for (const auto& [w, x] : q)
    for (const auto& [d, y] : postings_[w]) s[d] += x * y;
  return s;
}

void InvertedIndex::write(std::ostream& os) const {
  io::write_pod<std::int32_t>(os, num_docs_);
  io::write_pod<std::int32_t>(os, static_cast<std::int32_t>(idf_.size()));
  for (float f : idf_) io::write_pod<float>(os, f);
  for (const auto& p : postings_) {
    io::write_pod<std::int32_t>(os, static_cast<std::int32_t>(p.size()));
    for (const auto& [d, w] : p) {
      io::write_pod<std::int32_t>(os, d);
      io::write_pod<float>(os, w);
    }
  }
}

InvertedIndex InvertedIndex::read(std::istream& is) {
  InvertedIndex ix;
  ix.num_docs_ = io::read_pod<std::int32_t>(is, "index document count");
  const int nw = io::read_pod<std::int32_t>(is, "index word count");
  GEODRIFT_CHECK(ix.num_docs_ >= 0 && nw >= 0 && nw < (1 << 26), "inverted index: corrupt sizes");
  ix.idf_.resize(nw);
  for (float& f : ix.idf_) f = io::read_pod<float>(is, "idf");
  ix.postings_.resize(nw);
  for (auto& p : ix.postings_) {
    const int n = io::read_pod<std::int32_t>(is, "posting list size");
    GEODRIFT_CHECK(n >= 0 && n <= ix.num_docs_, "inverted index: corrupt posting list");
    p.resize(n);
    for (auto& [d, w] : p) {
      d = io::read_pod<std::int32_t>(is, "posting");
      w = io::read_pod<float>(is, "posting");
      GEODRIFT_CHECK(d >= 0 && d < ix.num_docs_, "inverted index: posting names document " << d);
    }
  }
  return ix;
}

}  // namespace geodrift::geotag
