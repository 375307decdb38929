// SPDX-License-Identifier: BSD-3-Clause
//
// Feature detection and left-right matching on a rectified stereo pair (stereo/features.h).
//
// Detectors (OpenCV 4.6 features2d; Debian's OpenCV has no xfeatures2d):
//  - KAZE  (the thesis' choice): cv::KAZE(extended = false, upright = false, threshold = options.threshold,
//    4 octaves x 4 sublevels, PM_G2 diffusivity): 64-float descriptors (CV_32F), compared with L2.
//  - AKAZE: cv::AKAZE with its default binary MLDB descriptor (rotation-invariant, 486 bits stored in 61
//    bytes, CV_8U), compared with the Hamming distance; threshold = options.threshold. MLDB is AKAZE's
//    native descriptor, the cheapest to compute (the 64-float DESCRIPTOR_KAZE[_UPRIGHT] cost ~20 % more
//    per image on the rendered globe), and it is rotation-invariant, which the UPRIGHT float variant is not
//    (a hand-held rig rolls between frames: that matters to the SLAM's frame-to-map association).
//  - ORB: cv::ORB (nfeatures = max_features, or 100000 for "all"; 8 levels, scale 1.2, Harris score,
//    31 px patch), rBRIEF 256 bits (32 bytes, CV_8U), Hamming. FAST threshold = options.threshold if
//    > 1 (rounded), else OpenCV's default 20.
//  A detector instance is created per detect() call, so detect() is thread-safe (process() detects the
//  two images concurrently).
//
// detect(): accepts 8-bit images with 1, 3 (BGR) or 4 (BGRA) channels (colour is converted to grey);
// another depth throws std::invalid_argument. An empty image or one without any contrast (min == max,
// e.g. black) gives no features without running the detector. Keypoints are returned strongest first
// (descending response; ties by row, column, size, so the order is deterministic); with max_features > 0
// only the max_features strongest are kept. KAZE/AKAZE describe every detected keypoint (describing only
// the kept ones would build the nonlinear scale space a second time, which costs more).
//
// match(): for a left keypoint (u_l, v_l), the candidates are the right keypoints with |v_l - v_r| <=
// max_row_diff and min_disparity <= (u_l - u_r) - disparity_offset <= max_disparity. Right keypoints are
// bucketed by integer row (round(v)) and sorted by u within a bucket, so each left keypoint looks only at
// the buckets of its row band and, by binary search, at the u-interval of the disparity window.
// Ratio test: best < ratio * second-best descriptor distance (L2 or Hamming); ratio = 1 switches the test
// off (ties accepted). Cross-check: the left keypoint must be the unique best left candidate (same row and
// disparity constraints, seen from the right keypoint); a tie counts as ambiguous and is rejected. Distances
// are compared at a resolution of 1e-5 (below it, the difference between the float descriptors of two exact
// copies of a patch is rounding noise: a tie, not a distinctive match). A left keypoint with a single
// candidate is accepted with strength 1 whatever its descriptor distance (there is no absolute distance
// threshold in FeatureOptions); the cross-check is then its only guard. Without
// cross_check several left keypoints may match the same right keypoint. strength = 1 - best / second-best
// (1 with a single candidate), floored at FLT_EPSILON so that it stays in (0, 1] when ratio = 1 lets ties
// through. StereoMatch::descriptor: the left descriptor's floats; for binary descriptors one float (0 or 1)
// per bit, byte by byte, least significant bit first (8 * bytes floats: 256 for ORB, 488 for AKAZE-MLDB
// whose last two bits are always 0). Left and right features must come from the same FeatureType
// (same descriptor type and length), else std::invalid_argument. Left and right images of different
// sizes are the caller's problem: they are processed as given (the matches are then meaningless), never
// a crash.

#include "skin3d/stereo/features.h"

#include "../common/text.h"

#include <algorithm>
#include <cctype>
#include <cfloat>
#include <cmath>
#include <exception>
#include <limits>
#include <numeric>
#include <opencv2/core/hal/hal.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <stdexcept>
#include <thread>

namespace skin3d {
namespace stereo {

namespace {

using common::num;

[[noreturn]] void badOption(const std::string& field, double value, const std::string& rule) {
  throw std::invalid_argument("feature options: " + field + " = " + num(value) + ": " + rule);
}

std::string matType(const cv::Mat& m) {
  static const char* depths[] = {"8U", "8S", "16U", "16S", "32S", "32F", "64F", "16F"};
  return std::string("CV_") + depths[m.depth()] + "C" + std::to_string(m.channels());
}

/** 8-bit grey view of an 8-bit image; empty stays empty. */
cv::Mat toGray8(const cv::Mat& image, const char* who) {
  if (image.empty()) return cv::Mat();
  if (image.depth() != CV_8U)
    throw std::invalid_argument(std::string(who) + ": the image must be 8-bit (got " + matType(image) + ")");
  cv::Mat gray;
  switch (image.channels()) {
    case 1:
      return image;
    case 3:
      cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
      return gray;
    case 4:
      cv::cvtColor(image, gray, cv::COLOR_BGRA2GRAY);
      return gray;
    default:
      throw std::invalid_argument(std::string(who) + ": the image must have 1, 3 or 4 channels (got " + matType(image) +
                                  ")");
  }
}

cv::Ptr<cv::Feature2D> makeDetector(const FeatureOptions& o) {
  const float threshold = static_cast<float>(o.threshold);
  switch (o.type) {
    case FeatureType::KAZE:
      return cv::KAZE::create(false, false, threshold, o.octaves, o.octave_layers, cv::KAZE::DIFF_PM_G2);
    case FeatureType::AKAZE:
      return cv::AKAZE::create(cv::AKAZE::DESCRIPTOR_MLDB, 0, 3, threshold, o.octaves, o.octave_layers,
                               cv::KAZE::DIFF_PM_G2);
    case FeatureType::ORB: {
      const int nfeatures = o.max_features > 0 ? o.max_features : 100000;
      const int fast = o.threshold > 1.0 ? static_cast<int>(std::lround(o.threshold)) : 20;
      return cv::ORB::create(nfeatures, 1.2f, 8, 31, 0, 2, cv::ORB::HARRIS_SCORE, 31, fast);
    }
  }
  throw std::invalid_argument("feature options: type = " + std::to_string(static_cast<int>(o.type)) +
                              ": unknown feature type");
}

/** Sorts strongest first (deterministic ties) and keeps at most max_features (0 = all). */
void keepStrongest(std::vector<cv::KeyPoint>* keypoints, cv::Mat* descriptors, int max_features) {
  const std::vector<cv::KeyPoint>& k = *keypoints;
  std::vector<int> order(k.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&k](int a, int b) {
    if (k[a].response != k[b].response) return k[a].response > k[b].response;
    if (k[a].pt.y != k[b].pt.y) return k[a].pt.y < k[b].pt.y;
    if (k[a].pt.x != k[b].pt.x) return k[a].pt.x < k[b].pt.x;
    if (k[a].size != k[b].size) return k[a].size < k[b].size;
    return a < b;
  });
  if (max_features > 0 && static_cast<int>(order.size()) > max_features) order.resize(max_features);
  std::vector<cv::KeyPoint> kept;
  kept.reserve(order.size());
  cv::Mat desc(static_cast<int>(order.size()), descriptors->cols, descriptors->type());
  for (size_t i = 0; i < order.size(); ++i) {
    kept.push_back(k[order[i]]);
    descriptors->row(order[i]).copyTo(desc.row(static_cast<int>(i)));
  }
  *keypoints = std::move(kept);
  *descriptors = desc;
}

void checkFeatures(const ImageFeatures& f, const char* side) {
  if (f.keypoints.empty()) return;
  if (f.descriptors.rows != static_cast<int>(f.keypoints.size()))
    throw std::invalid_argument(std::string("StereoFeatureMatcher::match: ") + side + " features have " +
                                std::to_string(f.keypoints.size()) + " keypoints but " +
                                std::to_string(f.descriptors.rows) + " descriptor rows");
  if (f.descriptors.type() != CV_32FC1 && f.descriptors.type() != CV_8UC1)
    throw std::invalid_argument(std::string("StereoFeatureMatcher::match: ") + side +
                                " descriptors must be CV_32FC1 or CV_8UC1 (got " + matType(f.descriptors) + ")");
}

/** Keypoint indices bucketed by integer row (floor(v + 0.5)), sorted by u within a bucket. */
class RowIndex {
 public:
  explicit RowIndex(const std::vector<cv::KeyPoint>& kps) {
    if (kps.empty()) return;
    int lo = bucketOf(kps[0].pt.y), hi = lo;
    for (const auto& k : kps) {
      lo = std::min(lo, bucketOf(k.pt.y));
      hi = std::max(hi, bucketOf(k.pt.y));
    }
    row0_ = lo;
    buckets_.resize(static_cast<size_t>(hi - lo + 1));
    for (size_t i = 0; i < kps.size(); ++i)
      buckets_[bucketOf(kps[i].pt.y) - row0_].push_back({kps[i].pt.x, static_cast<int>(i)});
    for (auto& b : buckets_) std::sort(b.begin(), b.end());
  }

  /** Calls fn(index) for every keypoint with row in [v_lo, v_hi] (by bucket; exact test left to fn) and u
   *  in [u_lo, u_hi]. */
  template <class Fn>
  void forEach(double v_lo, double v_hi, double u_lo, double u_hi, Fn&& fn) const {
    if (buckets_.empty() || !(u_lo <= u_hi)) return;
    const int b0 = std::max(0, bucketOf(v_lo) - row0_);
    const int b1 = std::min(static_cast<int>(buckets_.size()) - 1, bucketOf(v_hi) - row0_);
    const auto key = [](const std::pair<float, int>& e, double u) { return e.first < u; };
    for (int b = b0; b <= b1; ++b) {
      const auto& bucket = buckets_[b];
      for (auto it = std::lower_bound(bucket.begin(), bucket.end(), u_lo, key); it != bucket.end() && it->first <= u_hi;
           ++it)
        fn(it->second);
    }
  }

 private:
  static int bucketOf(double v) {
    const double b = std::floor(v + 0.5);
    return static_cast<int>(std::max(-1e6, std::min(1e6, b)));  // keypoints are image pixels; clamp anyway
  }
  int row0_ = 0;
  std::vector<std::vector<std::pair<float, int>>> buckets_;
};

/** Descriptor distances closer than this are equal: KAZE's unit-norm float descriptors of two exact copies of
 *  a patch differ by float rounding (~1e-7), which must not decide a ratio test or a cross-check. Hamming
 *  distances are integers, unaffected. */
constexpr double kDistanceResolution = 1e-5;

/** Distance between descriptor rows: squared L2 (float) or Hamming (binary). */
class Distance {
 public:
  Distance(const cv::Mat& left, const cv::Mat& right) : left_(left), right_(right), binary_(left.depth() == CV_8U) {}
  bool binary() const { return binary_; }
  /** The cost compared between candidates (monotone in the distance). */
  double cost(int l, int r) const {
    if (binary_) return cv::hal::normHamming(left_.ptr<uchar>(l), right_.ptr<uchar>(r), left_.cols);
    return cv::hal::normL2Sqr_(left_.ptr<float>(l), right_.ptr<float>(r), left_.cols);
  }
  /** The descriptor distance of a cost. */
  double distance(double cost) const { return binary_ ? cost : std::sqrt(cost); }

 private:
  const cv::Mat& left_;
  const cv::Mat& right_;
  bool binary_;
};

std::vector<float> descriptorOf(const cv::Mat& desc, int row) {
  std::vector<float> out;
  if (desc.depth() == CV_32F) {
    const float* p = desc.ptr<float>(row);
    out.assign(p, p + desc.cols);
  } else {
    const uchar* p = desc.ptr<uchar>(row);
    out.reserve(static_cast<size_t>(desc.cols) * 8);
    for (int b = 0; b < desc.cols; ++b)
      for (int k = 0; k < 8; ++k) out.push_back(static_cast<float>((p[b] >> k) & 1));
  }
  return out;
}

cv::Mat toBgr8(const cv::Mat& image) {
  if (image.empty()) return cv::Mat();
  cv::Mat img8 = image;
  if (image.depth() != CV_8U) {
    double mn = 0, mx = 0;
    cv::minMaxLoc(image.reshape(1), &mn, &mx);
    const double scale = mx > mn ? 255.0 / (mx - mn) : 1.0;
    image.convertTo(img8, CV_8U, scale, -mn * scale);
  }
  cv::Mat bgr;
  switch (img8.channels()) {
    case 1:
      cv::cvtColor(img8, bgr, cv::COLOR_GRAY2BGR);
      break;
    case 3:
      bgr = img8.clone();
      break;
    case 4:
      cv::cvtColor(img8, bgr, cv::COLOR_BGRA2BGR);
      break;
    default: {
      std::vector<cv::Mat> planes;
      cv::split(img8, planes);
      cv::cvtColor(planes[0], bgr, cv::COLOR_GRAY2BGR);
    }
  }
  return bgr;
}

}  // namespace

FeatureType parseFeatureType(const std::string& name) {
  std::string n = name;
  std::transform(n.begin(), n.end(), n.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (n == "kaze") return FeatureType::KAZE;
  if (n == "akaze") return FeatureType::AKAZE;
  if (n == "orb") return FeatureType::ORB;
  throw std::invalid_argument("unknown feature type '" + name + "' (known: kaze, akaze, orb)");
}

std::string featureTypeName(FeatureType type) {
  switch (type) {
    case FeatureType::KAZE:
      return "kaze";
    case FeatureType::AKAZE:
      return "akaze";
    case FeatureType::ORB:
      return "orb";
  }
  return "unknown(" + std::to_string(static_cast<int>(type)) + ")";
}

void FeatureOptions::validate() const {
  if (type != FeatureType::KAZE && type != FeatureType::AKAZE && type != FeatureType::ORB)
    badOption("type", static_cast<int>(type), "unknown feature type (known: kaze, akaze, orb)");
  if (!(threshold > 0) || !std::isfinite(threshold))
    badOption("threshold", threshold, "must be a finite number > 0 (ORB: FAST threshold if > 1)");
  if (type == FeatureType::ORB && threshold > 255.0)
    badOption("threshold", threshold, "an ORB FAST threshold must be <= 255");
  if (max_features < 0) badOption("max_features", max_features, "must be >= 0 (0 = all)");
  if (octaves < 1 || octaves > 8) badOption("octaves", octaves, "must be in 1..8");
  if (octave_layers < 1 || octave_layers > 8) badOption("octave_layers", octave_layers, "must be in 1..8");
  if (!(ratio > 0 && ratio <= 1)) badOption("ratio", ratio, "must be in (0, 1]");
  if (!(max_row_diff >= 0) || !std::isfinite(max_row_diff))
    badOption("max_row_diff", max_row_diff, "must be a finite number >= 0 (px)");
  if (!std::isfinite(min_disparity)) badOption("min_disparity", min_disparity, "must be finite (px)");
  if (std::isnan(max_disparity) || max_disparity < min_disparity)
    badOption("max_disparity", max_disparity, "must be >= min_disparity = " + num(min_disparity));
  if (!std::isfinite(disparity_offset)) badOption("disparity_offset", disparity_offset, "must be finite (px)");
  if (!(border_margin >= 0) || !std::isfinite(border_margin))
    badOption("border_margin", border_margin, "must be a finite number >= 0 (keypoint diameters)");
}

StereoFeatureMatcher::StereoFeatureMatcher(const FeatureOptions& options) : options_(options) {
  options_.validate();
}

ImageFeatures StereoFeatureMatcher::detect(const cv::Mat& image) const {
  ImageFeatures f;
  const cv::Mat gray = toGray8(image, "StereoFeatureMatcher::detect");
  if (gray.empty()) return f;
  f.image_size = gray.size();
  double mn = 0, mx = 0;
  cv::minMaxLoc(gray, &mn, &mx);
  if (mn == mx) return f;  // no contrast, no features (KAZE's contrast factor would be 0)
  makeDetector(options_)->detectAndCompute(gray, cv::noArray(), f.keypoints, f.descriptors);
  if (f.keypoints.empty()) {
    f.descriptors = cv::Mat();
    return f;
  }
  keepStrongest(&f.keypoints, &f.descriptors, options_.max_features);
  return f;
}

std::vector<StereoMatch> StereoFeatureMatcher::match(const ImageFeatures& left, const ImageFeatures& right,
                                                     MatchStats* stats) const {
  MatchStats st;
  st.left_features = static_cast<int>(left.keypoints.size());
  st.right_features = static_cast<int>(right.keypoints.size());
  checkFeatures(left, "left");
  checkFeatures(right, "right");
  std::vector<StereoMatch> out;
  if (left.keypoints.empty() || right.keypoints.empty()) {
    if (stats) *stats = st;
    return out;
  }
  if (left.descriptors.type() != right.descriptors.type() || left.descriptors.cols != right.descriptors.cols)
    throw std::invalid_argument("StereoFeatureMatcher::match: left descriptors (" + matType(left.descriptors) + ", " +
                                std::to_string(left.descriptors.cols) + " columns) and right descriptors (" +
                                matType(right.descriptors) + ", " + std::to_string(right.descriptors.cols) +
                                " columns) differ: both must come from the same feature type");

  const FeatureOptions& o = options_;
  const std::vector<cv::KeyPoint>& kl = left.keypoints;
  const std::vector<cv::KeyPoint>& kr = right.keypoints;
  const RowIndex right_rows(kr);
  const RowIndex left_rows(kl);
  const Distance dist(left.descriptors, right.descriptors);
  // The exact constraint, shared by both directions so that the cross-check sees the same candidate sets.
  const auto admissible = [&](int l, int r) {
    const double dv = std::abs(static_cast<double>(kl[l].pt.y) - kr[r].pt.y);
    const double d = (static_cast<double>(kl[l].pt.x) - kr[r].pt.x) - o.disparity_offset;
    return dv <= o.max_row_diff && d >= o.min_disparity && d <= o.max_disparity;
  };
  const double slack = 1e-3;  // px, generous bucket/interval search; admissible() decides

  // Best left candidate of a right keypoint: its index, or -1 if there is none or it is not unique (another
  // candidate within kDistanceResolution of it); computed on demand.
  std::vector<int> best_left(kr.size(), -2);
  const auto bestLeftOf = [&](int r) {
    if (best_left[r] != -2) return best_left[r];
    const double u = kr[r].pt.x, v = kr[r].pt.y;
    double best = std::numeric_limits<double>::infinity(), second = best;
    int idx = -1;
    left_rows.forEach(v - o.max_row_diff - slack, v + o.max_row_diff + slack,
                      u + o.disparity_offset + o.min_disparity - slack,
                      u + o.disparity_offset + o.max_disparity + slack, [&](int l) {
                        if (!admissible(l, r)) return;
                        const double c = dist.cost(l, r);
                        if (c < best) {
                          second = best;
                          best = c;
                          idx = l;
                        } else if (c < second) {
                          second = c;
                        }
                      });
    const bool unique = std::isinf(second) || dist.distance(second) - dist.distance(best) > kDistanceResolution;
    best_left[r] = unique ? idx : -1;
    return best_left[r];
  };

  for (int l = 0; l < static_cast<int>(kl.size()); ++l) {
    const double u = kl[l].pt.x, v = kl[l].pt.y;
    double best = std::numeric_limits<double>::infinity(), second = best;
    int best_r = -1, n = 0;
    right_rows.forEach(v - o.max_row_diff - slack, v + o.max_row_diff + slack,
                       u - o.disparity_offset - o.max_disparity - slack,
                       u - o.disparity_offset - o.min_disparity + slack, [&](int r) {
                         if (!admissible(l, r)) return;
                         ++n;
                         const double c = dist.cost(l, r);
                         if (c < best) {
                           second = best;
                           best = c;
                           best_r = r;
                         } else if (c < second) {
                           second = c;
                         }
                       });
    if (n == 0) continue;
    ++st.candidates;
    float strength = 1.0f;
    if (n > 1) {
      // Distances below the resolution are rounding noise of the descriptor computation (exact copies).
      const double b = std::max(dist.distance(best), kDistanceResolution);
      const double s = std::max(dist.distance(second), kDistanceResolution);
      if (o.ratio < 1.0 && !(b < o.ratio * s)) {
        ++st.ratio_rejected;
        continue;
      }
      strength = std::min(1.0f, std::max(FLT_EPSILON, static_cast<float>(1.0 - b / s)));
    }
    if (o.cross_check && bestLeftOf(best_r) != l) {
      ++st.cross_rejected;
      continue;
    }
    if (o.border_margin > 0.0) {
      const double margin = o.border_margin * std::max(kl[l].size, kr[best_r].size);
      const auto cut = [margin](const cv::Point2f& p, const cv::Size& s) {
        return !s.empty() && (p.x < margin || p.y < margin || p.x > s.width - 1 - margin || p.y > s.height - 1 - margin);
      };
      if (cut(kl[l].pt, left.image_size) || cut(kr[best_r].pt, right.image_size)) {
        ++st.border_rejected;
        continue;
      }
    }
    StereoMatch m;
    m.left = Eigen::Vector2d(kl[l].pt.x, kl[l].pt.y);
    m.right = Eigen::Vector2d(kr[best_r].pt.x, kr[best_r].pt.y);
    m.descriptor = descriptorOf(left.descriptors, l);
    m.strength = strength;
    m.size = kl[l].size;
    m.octave = kl[l].octave;
    out.push_back(std::move(m));
  }
  st.matches = static_cast<int>(out.size());
  if (stats) *stats = st;
  return out;
}

std::vector<StereoMatch> StereoFeatureMatcher::process(const cv::Mat& left_rect, const cv::Mat& right_rect,
                                                       MatchStats* stats) const {
  ImageFeatures fl, fr;
  std::exception_ptr right_error;
  std::thread worker([&] {
    try {
      fr = detect(right_rect);
    } catch (...) {
      right_error = std::current_exception();
    }
  });
  try {
    fl = detect(left_rect);
  } catch (...) {
    worker.join();
    throw;
  }
  worker.join();
  if (right_error) std::rethrow_exception(right_error);
  return match(fl, fr, stats);
}

cv::Mat drawStereoMatches(const cv::Mat& left_rect, const cv::Mat& right_rect,
                          const std::vector<StereoMatch>& matches) {
  const cv::Mat l = toBgr8(left_rect), r = toBgr8(right_rect);
  const int width = l.cols + r.cols, height = std::max(l.rows, r.rows);
  if (width == 0 || height == 0) return cv::Mat();
  cv::Mat canvas(height, width, CV_8UC3, cv::Scalar::all(0));
  if (!l.empty()) l.copyTo(canvas(cv::Rect(0, 0, l.cols, l.rows)));
  if (!r.empty()) r.copyTo(canvas(cv::Rect(l.cols, 0, r.cols, r.rows)));

  // Weak matches first, so that the strong (green) ones are drawn on top.
  std::vector<const StereoMatch*> order;
  order.reserve(matches.size());
  for (const auto& m : matches)
    if (m.left.allFinite() && m.right.allFinite()) order.push_back(&m);
  std::stable_sort(order.begin(), order.end(),
                   [](const StereoMatch* a, const StereoMatch* b) { return a->strength < b->strength; });
  constexpr int kShift = 4;  // sub-pixel drawing: coordinates in 1/16 px
  const auto fixed = [](double x, double y) {
    const double s = 1 << kShift;
    const auto clampi = [](double v) { return static_cast<int>(std::max(-1e8, std::min(1e8, std::round(v)))); };
    return cv::Point(clampi(x * s), clampi(y * s));
  };
  for (const StereoMatch* m : order) {
    const double s = std::min(1.0, std::max(0.0, static_cast<double>(m->strength)));
    const cv::Scalar colour(0, 255.0 * s, 255.0 * (1.0 - s));  // BGR: red (weak) -> green (strong)
    const cv::Point pl = fixed(m->left.x(), m->left.y()), pr = fixed(m->right.x() + l.cols, m->right.y());
    cv::line(canvas, pl, pr, colour, 1, cv::LINE_AA, kShift);
    cv::circle(canvas, pl, 3 << kShift, colour, 1, cv::LINE_AA, kShift);
    cv::circle(canvas, pr, 3 << kShift, colour, 1, cv::LINE_AA, kShift);
  }
  cv::putText(canvas, std::to_string(matches.size()) + " matches (red weak - green strong)", cv::Point(8, 20),
              cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(255, 255, 0), 1, cv::LINE_AA);
  return canvas;
}

}  // namespace stereo
}  // namespace skin3d
