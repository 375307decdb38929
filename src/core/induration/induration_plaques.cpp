// SPDX-License-Identifier: BSD-3-Clause
// Induration measurement: the plaque search. See include/skin3d/induration/induration.h.
#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <opencv2/imgproc.hpp>

#include "../common/text.h"
#include "induration_detail.h"

namespace skin3d {
namespace induration {
namespace induration_detail {

using common::num;

namespace {

/** A plaque whose outline borders unmeasured skin along more than this share may extend beyond what was
 *  measured: a warning says so. */
constexpr double kOpenOutline = 0.1;

/** m: the healthy-skin ring around a plaque is at least this wide (its heights' median and scatter). */
constexpr double kRingWidth = 1.0e-3;
/** A plaque found only at the wider scale must have a height over this share of its footprint: its smoothed heights
 *  were filled across gaps and averaged over several mm, and over a sparse region they say little (the at-edge
 *  rule asks the same of a plaque's surroundings). */
constexpr double kWideMeasuredShare = 0.8;
/** Sums over one plaque's region (footprint, heights of its interior, sigma along the local normal). */
struct PlaqueSums {
  double area = 0, sh = 0, sh2 = 0, ssig2 = 0, vol = 0;
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  std::vector<float> hk;  // interior heights
  double aspect = 1;      // length over width of its measured points (aspectOf)
  int px = 0, nc = 0;     // footprint pixels, pixels with a height
};

/** "N px at pixel (x, y)": where a region was, for the warnings. */
std::string atPixel(const cv::Rect& box) {
  return "pixel (" + std::to_string(box.x + box.width / 2) + ", " + std::to_string(box.y + box.height / 2) + ")";
}

/**
 * The plaques: regions above the detection threshold in the working band, each re-drawn from its core at
 * edge_fraction of its median height, measured, and checked (surroundings known, not too high, enough heights).
 */
class PlaqueSearch {
 public:
  PlaqueSearch(const Surface& s, const cv::Mat& band, const cv::Mat& reach, const HeightNoise& noise, IndurationResult& res)
      : s_(s), o_(s.o), band_(band), reach_(reach), noise_(noise), res_(res) {
    // A plaque cut by a narrow unknown or low strip (a step edge the matcher could not follow, a line of noise)
    // is one plaque: regions closer than about one interior margin are joined (closing) before labelling.
    const int jr = (o_.interior_margin_px + 1) / 2;
    join_ = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * jr + 1, 2 * jr + 1));
    off_band_ = s.known_mask & ~band;  // measured, but seen too obliquely
    final_labels_ = cv::Mat(s.xyz.size(), CV_32S, cv::Scalar(0));
    relief_mask_ = cv::Mat(s.xyz.size(), CV_8U, cv::Scalar(0));
    relief_cores_ = cv::Mat(s.xyz.size(), CV_8U, cv::Scalar(0));
  }

  /** At each scale, draws every core, largest first: a plaque whose core the matcher cut in two (an occlusion
   *  shadow across it) is drawn from its larger piece, and the smaller piece, already inside it, is skipped; a core
   *  mostly inside a plaque of an earlier scale is that plaque. Then the ids by decreasing area, the labels, and
   *  the warnings of the regions ignored. */
  void run(const std::vector<SearchScale>& scales) {
    for (std::size_t i = 0; i < scales.size(); ++i) {
      const SearchScale& sc = scales[i];
      hs_ = sc.hs;
      threshold_ = sc.threshold;
      smoothing_ = sc.smoothing;
      min_pixels_ = sc.min_pixels;
      if (i == 0) first_threshold_ = sc.threshold;
      first_scale_ = i == 0;
      cv::Mat above = (hs_ > threshold_) & band_;
      if (o_.interior_margin_px > 0) {
        cv::morphologyEx(above, above, cv::MORPH_CLOSE, join_);
        above.setTo(0, off_band_);
      }
      // a plaque is drawn inside its core's region above the threshold: a region under the scale's fewest pixels
      // (less the holes a drawn plaque may fill: half) cannot give one
      if (min_pixels_ > 0) above = largeEnough(above, 0.5 * min_pixels_);
      if (sc.plaque_like_only) above = plaqueLikeRegions(above, hs_, s_.xyz, s_.known_mask, smoothing_, threshold_, o_.max_height);
      drawCores(above, cv::Mat());
      // relief found: the rest of its core (beyond the relief's skirt) is searched again, at most twice; the cores
      // the relief was not part of were drawn already
      for (int again = 0; again < 2 && relief_found_ > 0; ++again) {
        relief_found_ = 0;
        above.setTo(0, relief_mask_);
        const cv::Mat was_relief = relief_cores_.clone();
        relief_cores_.setTo(0);
        drawCores(above, was_relief);
      }
      relief_found_ = 0;
      relief_cores_.setTo(0);
    }
    renumberByArea();
    warnIgnored(first_threshold_, o_.min_measured_share, noise_.correlation_area, &ignored_, &res_.warnings);
    if (!ignored_.relief.empty()) res_.relief = relief_mask_;
  }

 private:
  /** Labels the cores of `above` and draws them, largest first (only those touching `only`, when given). */
  void drawCores(const cv::Mat& above, const cv::Mat& only) {
    cv::Mat cents;
    n_ = cv::connectedComponentsWithStats(above, lab_, stats_, cents, 8, CV_32S);
    std::vector<char> use(std::max(0, n_), only.empty() ? 1 : 0);
    if (!only.empty())
      for (int y = 0; y < lab_.rows; ++y)
        for (int x = 0; x < lab_.cols; ++x)
          if (only.at<uchar>(y, x)) use[lab_.at<int>(y, x)] = 1;
    std::vector<int> cores;
    for (int k = 1; k < n_; ++k)
      if (use[k]) cores.push_back(k);
    std::stable_sort(cores.begin(), cores.end(),
                     [&](int a, int b) { return stats_.at<int>(a, cv::CC_STAT_AREA) > stats_.at<int>(b, cv::CC_STAT_AREA); });
    for (const int k : cores) drawCore(k);
  }

  /** Core k's plaque, if it is one; `level` (m): the outline's level instead of the core's own (coreLevels). */
  void drawCore(int k, double level = kNaN) {
    const cv::Rect bb(stats_.at<int>(k, cv::CC_STAT_LEFT), stats_.at<int>(k, cv::CC_STAT_TOP),
                      stats_.at<int>(k, cv::CC_STAT_WIDTH), stats_.at<int>(k, cv::CC_STAT_HEIGHT));
    if (takenAlready(k, bb)) return;  // part of a plaque drawn already
    if (inRelief(k, bb)) return;      // relief found already
    double edge = 0, ceiling = 0;
    bool limited = false;
    if (!coreLevels(k, bb, &edge, &ceiling, &limited)) return;
    if (std::isfinite(level)) {
      edge = level;
      limited = false;
    }
    cv::Rect box;
    cv::Mat mask;
    growRegion(k, bb, edge, ceiling, &box, &mask);
    if (isShoulder(k, bb, edge, box)) return;
    // statistics: area and centroid over the whole plaque; heights over its interior (the plaque eroded by
    // interior_margin_px: the matching window blurs the edge into a ramp, which would pull the mean down)
    // footprints on the reference's tangent plane at the region (the plane itself for the plane model)
    const ReferenceSurface local = localPlane(box, mask);
    const cv::Mat A = footprint(s_.cloud.ray, local, box);
    // a few pixels of a neighbour are left to it; a plaque of an earlier scale drawn at the threshold (its outline
    // the noise's, not its own) that this region covers by half or more is replaced by it
    std::map<int, int> covered;
    for (int y = 0; y < box.height; ++y)
      for (int x = 0; x < box.width; ++x) {
        const int l = final_labels_.at<int>(y + box.y, x + box.x);
        if (taken(l)) mask.at<uchar>(y, x) = 0;
        else if (l != 0 && mask.at<uchar>(y, x)) ++covered[l];
      }
    std::vector<int> replace;
    for (const auto& c : covered)
      if (2 * c.second >= plaques_[c.first - 1].pixels) replace.push_back(c.first);
    for (int y = 0; y < box.height; ++y)
      for (int x = 0; x < box.width; ++x) {
        const int l = final_labels_.at<int>(y + box.y, x + box.x);
        if (l != 0 && mask.at<uchar>(y, x) && std::find(replace.begin(), replace.end(), l) == replace.end()) mask.at<uchar>(y, x) = 0;
      }
    // area, share measured, volume, label and the top's profile over the footprint the measurements support
    // (mean, max, std: the region's interior, as before)
    const Footprint foot =
        measuredFootprint(mask, box, s_.known_mask, res_.height_map, edge, 4 * std::max(1, o_.interior_margin_px));
    PlaqueSums sums = accumulate(box, mask, foot.pixels, A, local);
    if (sums.area < o_.min_area || sums.px < min_pixels_ || sums.hk.size() < 10) return;
    if (atEdgeOrTooHigh(box, mask, sums)) return;
    // Drawn on the smoothed heights, a region must also stand above the noise in its own measured heights: an
    // interior whose mean is below the detection threshold is the smoothed noise's upper tail (or heights filled
    // across a gap), not a plaque the instrument can tell from the skin.
    // (A region drawn again below the threshold around a bump on raised skin: the bump stands above the threshold, and
    // the border's profile measured the raised skin around it.)
    if (sums.sh / sums.hk.size() < threshold_ && !std::isfinite(level)) {
      if (first_scale_) ignored_.low.emplace_back(sums.px, std::to_string(sums.px) + " px at " + atPixel(box) + ", mean " +
                                     num(std::round(sums.sh / sums.hk.size() * 1e5) / 100) + " mm");
      return;
    }
    // a plaque only the wider scale finds was drawn on heights smoothed (and filled) over several mm: it must be
    // oval like a plaque, not a strip of the reference's departure along the band, and measured over most of it
    if (!first_scale_ && (sums.aspect > kMaxPlaqueAspect || sums.nc < kWideMeasuredShare * sums.px)) return;
    // a plaque is one patch of skin: its footprint fills the ellipse of its second moments (a filled ellipse: 1; an
    // irregular or kidney-shaped outline: 0.7-0.9), while pieces strung along the edge of the measured surface or
    // scattered over it fill a few per cent of theirs
    const double fill = ellipseFill(foot.pixels);
    if (fill < kMinEllipseFill) {
      if (first_scale_) ignored_.scattered.emplace_back(sums.px, std::to_string(sums.px) + " px at " + atPixel(box) + ", " +
                                           num(std::round(100.0 * fill)) + " % of its ellipse");
      return;
    }
    if (sums.nc < o_.min_measured_share * sums.px) {
      if (first_scale_) ignored_.sparse.emplace_back(sums.px, std::to_string(sums.px) + " px at " + atPixel(box) + ", " +
                                        num(std::round(100.0 * sums.nc / std::max(1, sums.px))) + " % measured");
      return;
    }
    // a plaque is sharply demarcated and has one top; a smooth, bell-like rise or two tops is relief (kMaxBorderFactor)
    const BorderShape border = regionBorder(k, box, foot.pixels, local);
    if (border.relief()) {
      // the relief and its skirt above the threshold: no plaque can be measured there; the rest of the core (a
      // plaque beside the relief, joined to it by the skirt) is searched again (run)
      // (a ring of its skirt, searched again with the relief inside it filled, is that relief: listed once)
      int overlap = 0;
      for (int y = 0; y < box.height; ++y)
        for (int x = 0; x < box.width; ++x) overlap += foot.pixels.at<uchar>(y, x) && relief_mask_.at<uchar>(y + box.y, x + box.x);
      markRelief(box, foot.pixels, border);
      relief_cores_(bb).setTo(255, lab_(bb) == k);
      ++relief_found_;
      if (4 * overlap > sums.px) return;
      ignored_.relief.emplace_back(sums.px, std::to_string(sums.px) + " px at " + atPixel(box) + ", rising " +
                                        num(std::round(border.rise * 1e5) / 100) + " mm" +
                                        (border.dip > kMaxInwardDip ? " with two tops"
                                                                    : ", its border " + num(std::round(border.width * 1e4) / 10) +
                                                                          " mm wide (a plaque's: up to " +
                                                                          num(std::round(border.limit * 1e4) / 10) + " mm)"));
      return;
    }
    // a bump on raised skin: it rises above the skin around it by less than the detection threshold and by less than
    // that skin stands above the reference (a low plaque's top broken up by the noise into pieces above the
    // threshold): not a plaque of its own, but part of one. Drawn again at half its top's height, below the threshold,
    // where the profile shows raised skin around it.
    if (border.base > border.rise && border.rise < threshold_) {
      if (!std::isfinite(level) && border.base > 3 * border.rise_error) return drawCore(k, 0.5 * (border.base + border.rise));
      if (first_scale_) ignored_.on_raised.emplace_back(sums.px, std::to_string(sums.px) + " px at " + atPixel(box) + ", " +
                                           num(std::round(border.rise * 1e5) / 100) + " mm above skin at " +
                                           num(std::round(border.base * 1e5) / 100) + " mm");
      return;
    }
    addPlaque(box, foot, sums, limited, replace, border);
  }

  /** Whether plaque label l (0: none) holds its pixels against the scale being searched: every plaque does at the
   *  first scale; at a later one, only those not drawn at their scale's threshold. */
  bool taken(int l) const { return l != 0 && (first_scale_ || !tentative_[l - 1]); }

  /** True when at least half of core k (box `bb`) lies where `in(y, x)` holds. */
  template <typename In>
  bool mostlyIn(int k, const cv::Rect& bb, In in) const {
    int in_core = 0, inside = 0;
    for (int y = bb.y; y < bb.y + bb.height; ++y)
      for (int x = bb.x; x < bb.x + bb.width; ++x)
        if (lab_.at<int>(y, x) == k) {
          ++in_core;
          inside += in(y, x);
        }
    return 2 * inside >= in_core;
  }

  /** True when at least half of core k lies in a plaque drawn already. */
  bool takenAlready(int k, const cv::Rect& bb) const {
    return mostlyIn(k, bb, [&](int y, int x) { return taken(final_labels_.at<int>(y, x)); });
  }

  /** True when at least half of core k lies in relief found already (at an earlier scale or pass). */
  bool inRelief(int k, const cv::Rect& bb) const {
    return mostlyIn(k, bb, [&](int y, int x) { return relief_mask_.at<uchar>(y, x) != 0; });
  }

  /** Marks the footprint `fp` (in `box`) grown by the border's reach (in image px: over the finest pixel's size on
   *  the skin, at most 300 px) as relief. */
  void markRelief(const cv::Rect& box, const cv::Mat& fp, const BorderShape& border) {
    const int r = border.pixel > 0 ? static_cast<int>(std::ceil(std::min(300.0, border.reach / border.pixel))) : 0;
    const cv::Rect win = cv::Rect(box.x - r, box.y - r, box.width + 2 * r, box.height + 2 * r) & cv::Rect(0, 0, s_.xyz.cols, s_.xyz.rows);
    cv::Mat m = cv::Mat::zeros(win.size(), CV_8U);
    fp.copyTo(m(box - win.tl()), fp);
    if (r > 0) cv::dilate(m, m, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r + 1, 2 * r + 1)));
    relief_mask_(win).setTo(255, m & band_(win));
  }


  /** The core's edge level (edge_fraction of its median height, at least the threshold) and its ceiling; false
   *  when the core has under 10 heights. */
  bool coreLevels(int k, const cv::Rect& bb, double* edge, double* ceiling, bool* limited) const {
    std::vector<float> hv;
    for (int y = bb.y; y < bb.y + bb.height; ++y)
      for (int x = bb.x; x < bb.x + bb.width; ++x)
        if (lab_.at<int>(y, x) == k && !std::isnan(res_.height_map.at<float>(y, x))) hv.push_back(res_.height_map.at<float>(y, x));
    if (hv.size() < 10) return false;
    // The level is taken from the core's inner part: drawn on heights smoothed by sigma, a core reaches up to about
    // 2 sigma beyond the plaque's outline (a 1 mm plaque at the 0.07 mm threshold: 1.5 sigma), a skirt of healthy
    // heights that can outnumber a tall plaque's own when the noise calls for wide smoothing (a 12 MP rig at
    // 0.1 mm per pixel: 20 px, the core's median then on the skirt and its outline 2.5 times the plaque's area).
    // (A core narrower than 4 sigma: its inner half.)
    std::vector<float> inner;
    if (smoothing_ > 0) {
      const cv::Rect pad = cv::Rect(bb.x - 1, bb.y - 1, bb.width + 2, bb.height + 2) & cv::Rect(0, 0, lab_.cols, lab_.rows);
      cv::Mat core = lab_(pad) == k, dist;
      cv::distanceTransform(core, dist, cv::DIST_L2, cv::DIST_MASK_5);
      double dmax = 0;
      cv::minMaxLoc(dist, nullptr, &dmax);
      const double d0 = std::min(2 * smoothing_, 0.5 * dmax);
      for (int y = 0; y < pad.height; ++y)
        for (int x = 0; x < pad.width; ++x) {
          const float h = (first_scale_ ? res_.height_map : hs_).at<float>(y + pad.y, x + pad.x);
          if (dist.at<float>(y, x) >= d0 && !std::isnan(h)) inner.push_back(h);
        }
    }
    std::vector<float>& mv = inner.size() >= 10 ? inner : hv;
    std::nth_element(mv.begin(), mv.begin() + mv.size() / 2, mv.end());
    const double median = mv[mv.size() / 2];
    *edge = std::max(threshold_, o_.edge_fraction * median);
    *limited = o_.edge_fraction * median < threshold_;  // outlined by the threshold, not at its own half height
    // The core holds the plaque's top: a pixel of its region far above the core's highest is another bump (a
    // stripe of mismatches along the measured surface's edge, a neighbouring higher plaque), not this plaque.
    std::nth_element(hv.begin(), hv.begin() + static_cast<std::ptrdiff_t>(0.99 * (hv.size() - 1)), hv.end());
    *ceiling = 2.0 * hv[static_cast<std::size_t>(0.99 * (hv.size() - 1))] + threshold_;
    return true;
  }

  /** The region above `edge` (and below `upper`) connected to core k, in the box. */
  cv::Mat connected(int k, const cv::Rect& bb, double edge, const cv::Rect& box, double upper) const {
    cv::Mat region = (hs_(box) > edge) & (hs_(box) < upper);
    if (o_.interior_margin_px > 0) {
      cv::morphologyEx(region, region, cv::MORPH_CLOSE, join_);
      region.setTo(0, off_band_(box));
    }
    cv::Mat rl;
    const int rn = cv::connectedComponents(region, rl, 8, CV_32S);
    std::vector<char> keep(rn, 0);
    for (int y = bb.y; y < bb.y + bb.height; ++y)
      for (int x = bb.x; x < bb.x + bb.width; ++x)
        if (lab_.at<int>(y, x) == k) keep[rl.at<int>(y - box.y, x - box.x)] = 1;
    keep[0] = 0;
    cv::Mat out = cv::Mat::zeros(box.size(), CV_8U);
    for (int y = 0; y < box.height; ++y)
      for (int x = 0; x < box.width; ++x)
        if (keep[rl.at<int>(y, x)]) out.at<uchar>(y, x) = 255;
    return out;
  }

  /** The region at the edge level connected to the core, within a margin around the core's box; the margin
   *  doubles (up to 3 times) while the region reaches the box's border inside the image: the part of a plaque
   *  beyond its core's box (past a gap the core could not cross) must not be cut off along a straight line.
   *  Holes (background not reachable from the box border) are filled. */
  void growRegion(int k, const cv::Rect& bb, double edge, double ceiling, cv::Rect* box, cv::Mat* mask) const {
    const cv::Mat& xyz = s_.xyz;
    int m = 4 * std::max(1, static_cast<int>(std::ceil(smoothing_))) + 2 * o_.exclusion_margin_px + 2;
    for (int grow = 0;; ++grow, m *= 2) {
      *box = cv::Rect(bb.x - m, bb.y - m, bb.width + 2 * m, bb.height + 2 * m) & cv::Rect(0, 0, xyz.cols, xyz.rows);
      *mask = connected(k, bb, edge, *box, ceiling);
      const cv::Rect& b = *box;
      const bool touches = (b.x > 0 && cv::countNonZero(mask->col(0)) > 0) || (b.y > 0 && cv::countNonZero(mask->row(0)) > 0) ||
                           (b.x + b.width < xyz.cols && cv::countNonZero(mask->col(b.width - 1)) > 0) ||
                           (b.y + b.height < xyz.rows && cv::countNonZero(mask->row(b.height - 1)) > 0);
      if (!touches || grow == 3) break;
    }
    *mask |= holesOf(*mask);
  }

  /** A core whose half-height region reaches a plaque drawn already (from a larger core) is that plaque's
   *  shoulder (its ramp, a step the matcher blurred, a piece past a gap): no valley below its half height
   *  separates them, so it is not a plaque of its own. (Without the ceiling: the way up to a higher plaque is
   *  above the core's own top.) */
  bool isShoulder(int k, const cv::Rect& bb, double edge, const cv::Rect& box) const {
    const cv::Mat loose = connected(k, bb, edge, box, std::numeric_limits<double>::infinity());
    int overlap = 0;
    for (int y = 0; y < box.height && overlap < 10; ++y)
      for (int x = 0; x < box.width; ++x)
        if (loose.at<uchar>(y, x) && taken(final_labels_.at<int>(y + box.y, x + box.x))) ++overlap;
    return overlap >= 10;
  }

  /** The reference's tangent plane at the region's mean point (the reference itself unless it is a quadric). */
  ReferenceSurface localPlane(const cv::Rect& box, const cv::Mat& mask) const {
    const ReferenceSurface& ref = res_.reference;
    ReferenceSurface local = ref;
    if (ref.model != "quadric") return local;
    Eigen::Vector3d m = Eigen::Vector3d::Zero();
    int mk = 0;
    for (int y = 0; y < box.height; ++y)
      for (int x = 0; x < box.width; ++x)
        if (mask.at<uchar>(y, x) && known(s_.xyz.at<cv::Vec3f>(y + box.y, x + box.x))) {
          const cv::Vec3f& q = s_.xyz.at<cv::Vec3f>(y + box.y, x + box.x);
          m += Eigen::Vector3d(q[0], q[1], q[2]);
          ++mk;
        }
    if (mk > 0) {
      const Eigen::Vector4d tp = ref.tangentPlane(m / mk);
      local.model = "plane";
      local.normal = tp.head<3>();
      local.d = tp(3);
    }
    return local;
  }

  /** Area over the footprint `fp`, volume and centroid over the known pixels, heights over the interior. */
  PlaqueSums accumulate(const cv::Rect& box, const cv::Mat& mask, const cv::Mat& fp, const cv::Mat& A,
                        const ReferenceSurface& local) const {
    cv::Mat interior;
    if (o_.interior_margin_px > 0) {
      cv::erode(mask, interior,
                cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * o_.interior_margin_px + 1, 2 * o_.interior_margin_px + 1)),
                cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, 0);
      if (cv::countNonZero(interior) < 10) interior = mask;  // too small to have an interior
    } else {
      interior = mask;
    }
    PlaqueSums t;
    Eigen::Matrix3d sq = Eigen::Matrix3d::Zero();
    for (int y = 0; y < box.height; ++y)
      for (int x = 0; x < box.width; ++x) {
        if (!mask.at<uchar>(y, x)) continue;
        const float h = res_.height_map.at<float>(y + box.y, x + box.x);
        if (fp.at<uchar>(y, x)) {
          ++t.px;
          t.area += A.at<double>(y, x);
        }
        if (std::isnan(h)) continue;
        t.vol += std::max(0.0f, h) * A.at<double>(y, x);
        const cv::Vec3f& q = s_.xyz.at<cv::Vec3f>(y + box.y, x + box.x);
        const Eigen::Vector3d qd(q[0], q[1], q[2]);
        t.c += qd;
        sq += qd * qd.transpose();
        ++t.nc;
        if (!interior.at<uchar>(y, x)) continue;
        t.hk.push_back(h);
        t.sh += h;
        t.sh2 += static_cast<double>(h) * h;
        if (!s_.cloud.sigma.empty()) {
          const float sg = s_.cloud.sigma.at<float>(y + box.y, x + box.x);
          const cv::Vec3f& r = s_.cloud.ray.at<cv::Vec3f>(y + box.y, x + box.x);
          const double cosi = std::fabs(local.normal.x() * r[0] + local.normal.y() * r[1] + local.normal.z() * r[2]);
          if (std::isfinite(sg)) t.ssig2 += (sg * cosi) * (sg * cosi);
        }
      }
    t.aspect = aspectOf(t.c, sq, t.nc);
    return t;
  }

  /** The shape of the border of the region `fp` (in `box`) of core k (borderShape): the window around it, as deep
   *  outside as the region is inside, its pixels inside (1), on the skin around that may be used (2: the working
   *  band's skin on no plaque and no other core) or neither (0), their heights, and the pixels' map onto the
   *  reference's tangent plane `local` there. */
  BorderShape regionBorder(int k, const cv::Rect& box, const cv::Mat& fp, const ReferenceSurface& local) const {
    cv::Mat din;
    cv::distanceTransform(fp, din, cv::DIST_L2, cv::DIST_MASK_5);
    double dmax = 0;
    cv::minMaxLoc(din, nullptr, &dmax);
    if (dmax < 3) return BorderShape();
    const int r = static_cast<int>(std::ceil(std::min(2 * dmax, 300.0))) + 2;
    const cv::Rect win = cv::Rect(box.x - r, box.y - r, box.width + 2 * r, box.height + 2 * r) & cv::Rect(0, 0, s_.xyz.cols, s_.xyz.rows);
    cv::Mat cls(win.size(), CV_8U, cv::Scalar(0)), hw(win.size(), CV_32F, cv::Scalar(kNaN));
    for (int y = 0; y < win.height; ++y)
      for (int x = 0; x < win.width; ++x) {
        const int gy = y + win.y, gx = x + win.x;
        const bool in = box.contains(cv::Point(gx, gy)) && fp.at<uchar>(gy - box.y, gx - box.x) != 0;
        const int l = lab_.at<int>(gy, gx);
        const bool use = reach_.at<uchar>(gy, gx) && final_labels_.at<int>(gy, gx) == 0 && (l == 0 || l == k);
        cls.at<uchar>(y, x) = in ? 1 : use ? 2 : 0;
        hw.at<float>(y, x) = res_.height_map.at<float>(gy, gx);
      }
    const Eigen::Matrix2d J = pixelOnPlane(s_.cloud.ray, box, local, std::max(1, static_cast<int>(dmax / 4)));
    return borderShape(cls, hw, J, noise_, threshold_);
  }

  /** A region whose surroundings are mostly unknown lies at the edge of the measured surface (or is an island of
   *  mismatches): its height above the reference means nothing (listed in ignored_.at_edge); one higher than max_height
   *  is not skin (a warning). True when the region is ignored for either reason. */
  bool atEdgeOrTooHigh(const cv::Rect& box, const cv::Mat& mask, const PlaqueSums& t) {
    const int r1 = 2 * o_.interior_margin_px, r2 = 4 * o_.interior_margin_px;
    // Only the surroundings in the working band count (where the reference says the skin faces both
    // cameras): a plaque next to the band's edge keeps its measurable side; an island beyond a silhouette,
    // where no ray meets the reference in the band, has none. Computed in a window of the box grown by r2
    // (the ring cannot reach further); beyond the image border counts as in the band and unknown.
    const cv::Rect win(box.x - r2, box.y - r2, box.width + 2 * r2, box.height + 2 * r2);
    const cv::Rect in = win & cv::Rect(0, 0, s_.xyz.cols, s_.xyz.rows);
    cv::Mat full = cv::Mat::zeros(win.size(), CV_8U), d1, d2;
    cv::Mat known_pad = cv::Mat::zeros(win.size(), CV_8U), reach_pad(win.size(), CV_8U, cv::Scalar(255));
    full(cv::Rect(r2, r2, box.width, box.height)).setTo(255, mask);
    // the matcher's scattered gaps (a few px, where its fit and the semi-global answer disagree on weak texture)
    // are closed first: they are skin that was seen, and on a coarse rig they took a quarter of a plaque's ring;
    // the edge of the measured surface is a gap wider than the closing
    cv::Mat known_closed;
    cv::morphologyEx(s_.known_mask(in), known_closed, cv::MORPH_CLOSE, join_);
    known_closed.copyTo(known_pad(in - win.tl()));
    reach_(in).copyTo(reach_pad(in - win.tl()));
    cv::dilate(full, d1, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r1 + 1, 2 * r1 + 1)));
    cv::dilate(full, d2, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r2 + 1, 2 * r2 + 1)));
    const cv::Mat ring = d2 & ~d1 & reach_pad;
    const int ring_all = cv::countNonZero(d2 & ~d1);
    const int ring_n = cv::countNonZero(ring), ring_known = cv::countNonZero(ring & known_pad);
    const double mean_h = t.sh / static_cast<double>(t.hk.size());
    if (ring_n < 0.25 * ring_all || ring_known < 0.8 * ring_n) {
      // (in pixels: beyond a silhouette the reference's tangent plane is edge-on and an area means nothing)
      if (first_scale_) ignored_.at_edge.emplace_back(t.px, std::to_string(t.px) + " px at " + atPixel(box) + ", " +
                                      num(std::round(100.0 * ring_known / std::max(1, ring_n))) + " % of its surroundings known");
      return true;
    }
    if (mean_h > o_.max_height) {
      res_.warnings.push_back("a region " + num(std::round(mean_h * 1e5) / 100) + " mm above the reference at " +
                              atPixel(box) + " was ignored: higher than max_height " + num(o_.max_height * 1e3) +
                              " mm (not skin)");
      return true;
    }
    return false;
  }

  /** The healthy skin around a plaque's footprint `fp` (in `box`; `pixel_m`: a pixel's size on the skin there): a
   *  ring beyond the reach of its edge, as wide as the matcher's ramp (2 interior_margin_px, at least 8 px) or
   *  kRingWidth, whichever is wider, known, in the working band, on no plaque and no other raised core. The edge
   *  reaches beyond the half-height outline by half the plaque's border ramp (kHalfRamp) and by the blur of the
   *  smoothing, the matcher's ramp and the exclusion margin. */
  struct Surround {
    double offset = kNaN, sigma = kNaN;  //!< m: median height and robust sigma of the ring's heights
    int pixels = 0;
  };
  Surround surround(const cv::Rect& box, const cv::Mat& fp, double pixel_m) const {
    auto px = [&](double m) { return pixel_m > 0 ? static_cast<int>(std::ceil(std::min(200.0, m / pixel_m))) : 0; };
    const int r1 = o_.exclusion_margin_px + o_.interior_margin_px + static_cast<int>(std::ceil(2 * smoothing_)) + px(kHalfRamp);
    const int r2 = r1 + std::max({8, 2 * o_.interior_margin_px, px(kRingWidth)});
    const cv::Rect win = cv::Rect(box.x - r2, box.y - r2, box.width + 2 * r2, box.height + 2 * r2) &
                         cv::Rect(0, 0, s_.xyz.cols, s_.xyz.rows);
    cv::Mat full = cv::Mat::zeros(win.size(), CV_8U), d1, d2;
    full(box - win.tl()).setTo(255, fp);
    cv::dilate(full, d1, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r1 + 1, 2 * r1 + 1)));
    cv::dilate(full, d2, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r2 + 1, 2 * r2 + 1)));
    std::vector<float> v;
    for (int y = 0; y < win.height; ++y)
      for (int x = 0; x < win.width; ++x) {
        if (!d2.at<uchar>(y, x) || d1.at<uchar>(y, x)) continue;
        const int gy = y + win.y, gx = x + win.x;
        if (!reach_.at<uchar>(gy, gx) || final_labels_.at<int>(gy, gx) != 0 || lab_.at<int>(gy, gx) != 0) continue;
        const float h = res_.height_map.at<float>(gy, gx);
        if (std::isfinite(h)) v.push_back(h);
      }
    Surround out;
    out.pixels = static_cast<int>(v.size());
    if (v.size() < 30) return out;
    const auto ms = medianAndScale(v);
    out.offset = ms.first;
    out.sigma = ms.second;
    return out;
  }

  /** The plaque's figures, its warnings (partly measured, open outline) and its label. */
  void addPlaque(const cv::Rect& box, const Footprint& foot, PlaqueSums& t, bool limited, const std::vector<int>& replace,
                 const BorderShape& border) {
    Plaque p;
    p.border_width = border.width;
    const double nk = static_cast<double>(t.hk.size());
    p.area = t.area;
    p.centroid = t.c / std::max(1, t.nc);
    p.mean_height = t.sh / nk;
    p.std_height = std::sqrt(std::max(0.0, t.sh2 / nk - p.mean_height * p.mean_height));
    std::nth_element(t.hk.begin(), t.hk.begin() + static_cast<long>(0.99 * (nk - 1)), t.hk.end());
    p.max_height = t.hk[static_cast<std::size_t>(0.99 * (nk - 1))];
    p.mean_height_sigma = std::sqrt(t.ssig2) / nk;
    // the top: from the height profile; a plaque too small to have 30 heights clear of its ramp takes the 99th
    // percentile of its interior (the mean would read its blurred ramp). The profile's distances are from the
    // footprint's outline: where a plaque runs into unmeasured skin, the region's part in the gap would move
    // its deepest point off the measured top (partly measured plaques of seeds 5, 8, 11: +28.5, -6.8, +10.1 um
    // -> +21.7, -2.9, +6.4 um; seeds 9 and 10, not looked at for this: within 2 um)
    // Its uncertainty: the plaque's own height noise (a scaly plaque gives the matcher more texture than the skin
    // around it: on the rendered limb its heights scatter 2.4-3.5 times less), counted with the correlation area
    // measured on the healthy skin (the matcher's window sets it); and the skin around it standing off the
    // reference beyond what the ring's own noise explains (the reference's local error).
    const double pixel_m = std::sqrt(t.area / std::max(1, t.px));
    const Surround sur = surround(box, foot.pixels, pixel_m);
    p.surround_offset = sur.offset;
    double sig = interiorNoise(res_.height_map(box), foot.pixels, o_.interior_margin_px);
    if (!std::isfinite(sig)) sig = sur.pixels >= 100 ? sur.sigma : noise_.sigma;
    const double kHalfPi = 0.5 * 3.14159265358979323846;
    double top_sigma = kNaN;
    p.top_height = topHeight(foot.pixels, res_.height_map(box), o_.interior_margin_px,
                             sig * sig * noise_.correlation_area, &top_sigma);
    if (!std::isfinite(p.top_height)) {
      // the 99th percentile of heights scattered by sig stands about 2.3 sig above their level: that, not a
      // mean's standard error, is what this top may be off by
      p.top_height = p.max_height;
      top_sigma = 2.33 * sig;
    }
    double offset2 = 0;
    if (std::isfinite(sur.offset) && sur.pixels > 0)
      offset2 = std::max(0.0, sur.offset * sur.offset - kHalfPi * sur.sigma * sur.sigma * noise_.correlation_area / sur.pixels);
    p.top_height_sigma = std::sqrt(top_sigma * top_sigma + offset2);
    if (!(p.top_height - 3 * p.top_height_sigma > threshold_) && t.px < kMismatchAreas * noise_.correlation_area) {
      ignored_.mismatch.emplace_back(t.px, num(std::round(t.area * 1e7) / 10) + " mm^2 at " + atPixel(box) + ", top " +
                                       num(std::round(p.top_height * 1e5) / 100) + " +- " +
                                       num(std::round(p.top_height_sigma * 1e5) / 100) + " mm");
      return;
    }
    p.pasi_class = pasiClass(p.top_height, o_.pasi_boundaries);
    // a low plaque's outline is drawn at the detection threshold, above its half height: its area is the one within
    // half its rise from the skin around to its top, from its border's profile
    const bool resolved = border.rise > 3 * border.rise_error;  // the profile tells the half-rise level
    if (resolved && limited) {
      const double ratio = border.areaRatioAt(border.base + 0.5 * (p.top_height - border.base));
      if (std::isfinite(ratio)) p.area = t.area * ratio;
    }
    p.pixels = t.px;
    p.measured_fraction = t.px > 0 ? t.nc / static_cast<double>(t.px) : 0.0;
    // the volume: the footprint's, and the skirt's outside the outline (the ramp's lower half and the matcher's blur:
    // without it the volume read 4-13 % low on rendered sweeps)
    p.volume = (p.measured_fraction > 0 ? t.vol / p.measured_fraction : 0.0) + (resolved ? border.skirt_volume : 0.0);
    p.outline_unmeasured = foot.open;
    const std::string what = "a plaque of " + num(std::round(t.area * 1e7) / 10) + " mm^2 at " + atPixel(box);
    std::vector<std::string> warnings;
    if (p.measured_fraction < 0.9)
      warnings.push_back(what + " is only partly measured: " + num(std::round(100 * p.measured_fraction)) +
                              " % of its footprint has a height (its mean and volume rest on that part)");
    if (p.outline_unmeasured > kOpenOutline)
      warnings.push_back(what + " borders unmeasured skin along " + num(std::round(100 * p.outline_unmeasured)) +
                              " % of its outline: it may extend there (its area is what was measured; turn the skin "
                              "towards the rig to measure all of it)");
    p.bbox = box;
    p.id = static_cast<int>(plaques_.size()) + 1;
    for (const int l : replace) {
      removed_[l - 1] = 1;
      const cv::Rect& b = plaques_[l - 1].bbox;
      for (int y = b.y; y < b.y + b.height; ++y)
        for (int x = b.x; x < b.x + b.width; ++x)
          if (final_labels_.at<int>(y, x) == l) final_labels_.at<int>(y, x) = 0;
    }
    for (int y = 0; y < box.height; ++y)
      for (int x = 0; x < box.width; ++x)
        if (foot.pixels.at<uchar>(y, x)) final_labels_.at<int>(y + box.y, x + box.x) = p.id;
    plaques_.push_back(p);
    plaque_warnings_.push_back(warnings);
    // tentative: outlined at the threshold, and its top not clearly above it (3 stated sigma): a noise peak of a
    // larger, lower plaque, or a plaque the first scale barely sees; one standing clearly above is the first scale's
    tentative_.push_back(limited && !(p.top_height - 3 * p.top_height_sigma > threshold_));
    removed_.push_back(0);
  }

  /** ids in order of decreasing area, in the result and in its label image (a plaque replaced by a wider scale's
   *  is dropped, its warnings with it). */
  void renumberByArea() {
    std::vector<int> order;
    for (std::size_t i = 0; i < plaques_.size(); ++i)
      if (!removed_[i]) order.push_back(static_cast<int>(i));
    std::sort(order.begin(), order.end(), [&](int a, int b) { return plaques_[a].area > plaques_[b].area; });
    std::vector<int> new_id(plaques_.size() + 1, 0);
    for (std::size_t i = 0; i < order.size(); ++i) {
      new_id[plaques_[order[i]].id] = static_cast<int>(i) + 1;
      res_.plaques.push_back(plaques_[order[i]]);
      res_.plaques.back().id = static_cast<int>(i) + 1;
      for (const auto& w : plaque_warnings_[order[i]]) res_.warnings.push_back(w);
    }
    for (int y = 0; y < final_labels_.rows; ++y)
      for (int x = 0; x < final_labels_.cols; ++x) {
        int& l = final_labels_.at<int>(y, x);
        if (l) l = new_id[l];
      }
    res_.labels = final_labels_;
  }

  const Surface& s_;
  const IndurationOptions& o_;
  const cv::Mat band_, reach_;
  const HeightNoise noise_;
  // the scale being searched: smoothed heights, threshold (m), smoothing (px), fewest footprint pixels
  cv::Mat hs_;
  double threshold_ = 0, smoothing_ = 0, min_pixels_ = 0, first_threshold_ = 0;
  bool first_scale_ = true;  // the regions ignored are reported from the first scale only (once)
  IndurationResult& res_;
  cv::Mat join_, off_band_, lab_, stats_, final_labels_;
  cv::Mat relief_mask_;  // CV_8U: raised regions found to be relief, not plaques, with their skirts
  int relief_found_ = 0;  // relief found in the pass over the cores being drawn
  cv::Mat relief_cores_;  // CV_8U: the cores in which that relief was found
  int n_ = 0;
  std::vector<Plaque> plaques_;
  std::vector<std::vector<std::string>> plaque_warnings_;  // per plaque: partly measured, open outline
  std::vector<char> tentative_;  // per plaque: drawn at its scale's threshold (a wider scale may replace it)
  std::vector<char> removed_;    // per plaque: replaced by a wider scale's
  IgnoredRegions ignored_;       // raised regions found not to be plaques, by kind
};

}  // namespace

void findPlaques(const Surface& s, const std::vector<SearchScale>& scales, const cv::Mat& band, const cv::Mat& reach,
                 const HeightNoise& noise, IndurationResult& res) {
  PlaqueSearch(s, band, reach, noise, res).run(scales);
}

}  // namespace induration_detail
}  // namespace induration
}  // namespace skin3d
