#pragma once

/// @file
/// Bag-of-words retrieval over SIFT (the paper's Sec. 3.3, "Similar Geo-tagged Image
/// Retrieval", after Agarwal et al. 2015): a hierarchical k-means vocabulary (Nister &
/// Stewenius 2006, "vocabulary tree") and a tf-idf inverted file scored by cosine similarity.
///
/// Descriptors are RootSIFT (Arandjelovic & Zisserman 2012: L1-normalise, then square root),
/// rows of a CV_32F matrix with 128 columns; root_sift() converts OpenCV's SIFT output.
///
/// Why hierarchical: flat k-means with 10^4 centres costs N * 10^4 * 128 flops per iteration;
/// the tree costs N * branching * depth * 128 for training and quantisation, ~250 x less at
/// branching 10, depth 4, which keeps building a 2,400-view database to minutes on 2 cores.

#include <cstdint>
#include <functional>
#include <iosfwd>
#include <opencv2/core.hpp>
#include <utility>
#include <vector>

namespace geodrift::geotag {

/// Converts SIFT descriptors (CV_32F rows) to RootSIFT in place.
void root_sift(cv::Mat* descriptors);

/// A vocabulary tree: words are its leaves.
class Vocabulary {
 public:
  struct Options {
    int branching = 10;  ///< children per node (k of each k-means)
    int depth = 4;       ///< levels below the root; at most branching^depth words
    /// Training subsample: at most this many descriptors, drawn uniformly (seeded).
    int max_training_descriptors = 200000;
    int kmeans_iterations = 12;
    std::uint64_t seed = 42;
  };

  Vocabulary() = default;

  /// Trains by recursive k-means (k-means++ seeding) on a seeded subsample of `descriptors`
  /// (CV_32F, D columns). A node with fewer than 2 * branching descriptors becomes a leaf.
  /// @param progress  called as progress(done, total) with descriptors assigned to leaves so
  ///                  far; may be empty.
  /// @throws InvalidArgument for bad options, a non-CV_32F matrix or fewer descriptors than
  ///         `branching`.
  static Vocabulary train(const cv::Mat& descriptors, const Options& options,
                          const std::function<void(std::size_t, std::size_t)>& progress = {});

  int num_words() const { return num_words_; }
  int descriptor_size() const { return centers_.cols; }
  bool empty() const { return num_words_ == 0; }

  /// Word of one descriptor (row pointer, descriptor_size() floats): greedy descent.
  int quantize(const float* descriptor) const;
  /// Words of every row.
  std::vector<int> quantize(const cv::Mat& descriptors) const;

  void write(std::ostream& os) const;
  /// @throws Error on a truncated or inconsistent stream.
  static Vocabulary read(std::istream& is);

 private:
  struct Node {
    int first_child = -1;  ///< index into nodes_ / centers_ rows; children are contiguous
    int num_children = 0;
    int word = -1;  ///< leaf: word id
  };
  void build(const cv::Mat& data, std::vector<int> rows, int node, int level, const Options& o,
             const std::function<void(std::size_t)>& leaf_done);

  std::vector<Node> nodes_;  ///< nodes_[0] is the root
  cv::Mat centers_;          ///< row i = centre of node i (row 0 unused)
  int num_words_ = 0;
};

/// A sparse tf-idf vector: (word, weight), words ascending, L2 norm 1.
using BowVector = std::vector<std::pair<int, float>>;

/// tf-idf inverted file over a fixed document set (the database views).
class InvertedIndex {
 public:
  InvertedIndex() = default;
  /// @param doc_words  the words of each document (repetitions = term frequency).
  InvertedIndex(const std::vector<std::vector<int>>& doc_words, int num_words);

  int num_documents() const { return num_docs_; }
  /// idf(w) = log(N / n_w), n_w = documents containing w (0 for words never seen).
  double idf(int word) const { return idf_[word]; }
  /// Words with idf > 0: seen in some but not all documents. Only they can rank documents; 0
  /// means the vocabulary is too coarse for the database (every word in every view).
  int num_informative_words() const {
    int n = 0;
    for (float f : idf_) n += f > 0 ? 1 : 0;
    return n;
  }
  /// The L2-normalised tf-idf vector of a word list under this index's idf.
  BowVector vectorize(const std::vector<int>& words) const;
  /// Cosine similarity of the query with every document (0 for documents sharing no word).
  std::vector<float> scores(const BowVector& query) const;

  void write(std::ostream& os) const;
  static InvertedIndex read(std::istream& is);

 private:
  int num_docs_ = 0;
  std::vector<float> idf_;
  std::vector<std::vector<std::pair<int, float>>> postings_;  ///< word -> (doc, weight)
};

}  // namespace geodrift::geotag
