// SPDX-License-Identifier: BSD-3-Clause
// Private pieces of the site scan shared by its files (site_fusion.cpp, site_measure.cpp, site_io.cpp) and tests.
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "skin3d/site/site_fusion.h"

namespace skin3d {
namespace site {
namespace site_detail {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

/** The body surface from a frame's reference (site_fusion.h, 1.); *why says when a quadric was not taken as a limb. */
SiteSurface surfaceFromReference(const induration::ReferenceSurface& ref, const geometry::DenseCloud& cloud,
                                 const Eigen::Isometry3d& T_W_C, std::string* why);
/** Median distance between horizontally neighbouring known points (m); 0 if too few. */
double medianPixelFootprint(const geometry::DenseCloud& cloud);

/** The fused height field over the body surface (site_fusion.h, 3.). */
struct FusionGrid {
  SiteSurface surf;
  double cell = 0, wref = 0;       // w is stored as w - wref (the cylinder's radius; 0 for a plane)
  int nu = 0, nv = 0;
  double umin = 0, vmin = 0;
  bool periodic = false;
  std::vector<float> sw;           // sum of weights
  std::vector<double> swh;         // sum of weight x (w - wref)
  std::vector<float> sw2v;         // sum of weight^2 x variance (the variance of the cell's mean: sw2v / sw^2)
  std::vector<std::uint8_t> count, best;
  std::vector<float> bestw;
  std::vector<int> last;           // the last frame that touched the cell
  std::string note;                // why the body surface is what it is, when that needs saying
  std::size_t idx(int i, int j) const { return static_cast<std::size_t>(j) * nu + i; }
  bool cellOf(double u, double v, int* i, int* j) const {
    *i = static_cast<int>(std::floor((u - umin) / cell));
    *j = static_cast<int>(std::floor((v - vmin) / cell));
    if (periodic) *j = ((*j % nv) + nv) % nv;
    return *i >= 0 && *i < nu && *j >= 0 && *j < nv;
  }
  /** The fused surface's tangent plane under the point uvw (its fused value val, slopes su, sv from lookup): its
   *  outward normal in world, and the surface point *P. */
  Eigen::Vector3d tangentPlane(const Eigen::Vector3d& uvw, double val, double su, double sv, Eigen::Vector3d* P) const {
    const Eigen::Vector3d base(uvw.x(), uvw.y(), wref + val);
    const Eigen::Vector3d out = surf.outward(base);
    *P = surf.toWorld(base);
    Eigen::Vector3d tu, tv;
    surf.tangents(base, &tu, &tv);
    Eigen::Vector3d n = (tu + su * out).cross(tv + sv * out).normalized();
    return n.dot(out) < 0 ? Eigen::Vector3d(-n) : n;
  }
  /** fused w - wref at (u, v) (nearest cell), its sigma and slopes; false where nothing is fused */
  bool lookup(double u, double v, double* val, double* sigma, double* su, double* sv) const {
    int i, j;
    if (!cellOf(u, v, &i, &j)) return false;
    const std::size_t k = idx(i, j);
    if (!(sw[k] > 0)) return false;
    *val = swh[k] / sw[k];
    *sigma = 1.0 / std::sqrt(sw[k]);
    auto at = [&](int ii, int jj, double* out) {
      if (periodic) jj = ((jj % nv) + nv) % nv;
      if (ii < 0 || ii >= nu || jj < 0 || jj >= nv) return false;
      const std::size_t q = idx(ii, jj);
      if (!(sw[q] > 0)) return false;
      *out = swh[q] / sw[q];
      return true;
    };
    double a, b;
    *su = (at(i + 2, j, &a) && at(i - 2, j, &b)) ? (a - b) / (4 * cell) : 0.0;
    *sv = (at(i, j + 2, &a) && at(i, j - 2, &b)) ? (a - b) / (4 * cell) : 0.0;
    return true;
  }
};

/** The fused field, cropped: value = w - wref (m, NaN unknown), rows v, columns u; cell (0, 0) at (u0, v0). */
struct FusedMap {
  SiteSurface surface;
  double cell = 0, wref = 0, u0 = 0, v0 = 0;
  cv::Mat value, sigma, frames;  // CV_64F, CV_32F, CV_8U
};

/** The smooth body model fitted to the fused field (site_fusion.h, 4.). */
struct BodyModel {
  std::string name;
  Eigen::VectorXd coef;
  double rms = 0;
  /** model value (w - wref) at (u, v) and its derivatives along u and v */
  double eval(const SiteSurface& s, double u, double v, double* du = nullptr, double* dv = nullptr) const;
};
/** Tukey-weighted fit of the body model to the known cells not in `exclude` (CV_8U, may be empty). */
BodyModel fitBodyModel(const FusedMap& m, const cv::Mat& exclude);

/** The site measurement on a fused map. */
SiteResult measureSite(const FusedMap& m, const induration::IndurationOptions& options, const std::vector<SiteFrame>& frames);

/** A frame's skin point and its sigma along the ray (site_fusion.cpp, skinSamples). */
struct Sample {
  Eigen::Vector3d X;    // camera frame
  float sigma;          // m along the ray
};

/** What fusing a frame needs of its cameras. */
struct View {
  Eigen::Vector3d rc;  // the right camera's centre, camera frame
  bool have_right;
  double cos_max;      // cos(site_max_incidence_deg)
};

/** A camera-frame point in world and on the surface, and the cosine of the larger incidence of both cameras on the
 *  body's normal there. */
double incidenceCos(const FusionGrid& g, const View& v, const Eigen::Isometry3d& T, const Eigen::Vector3d& Xc,
                    Eigen::Vector3d* Xw, Eigen::Vector3d* uvw);

/** Compares a frame with the fused surface (its seams) and fuses it (site_fusion.cpp; `own`: its height noise and
 *  correlation area); returns the samples fused and how many fell on skin fused before. */
long fuseFrame(FusionGrid& g, const View& view, const std::vector<Sample>& samples, const induration::IndurationResult& own,
               const SiteOptions& o, SiteFrame* F, long* on_old_out);

/** A fused frame as the pose graph needs it again: its samples, cameras, noise, and its record's index. */
struct KeptFrame {
  int index = 0;
  std::vector<Sample> samples;
  View view;
  double height_noise = 0, noise_correlation_px2 = 1;
};

/** One frame's samples over one seam block, as a function of the frame's pose T = (R, t): their weighted mean
 *  offset from the fused surface's tangent planes is trace(R M) + n . t - c (M = mean of X n^T, X in the camera
 *  frame; n the mean normal; c the mean n . P), exact for fixed tangent planes. var: the mean's variance. */
struct BlockSummary {
  long block = 0;
  Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
  Eigen::Vector3d n = Eigen::Vector3d::Zero();
  double c = 0, var = 0;
};
/** The summaries of a frame's samples (every `stride`-th) at pose T over blocks of `block` m (blocks with half
 *  their share of samples); noise2, corr: the frame's height noise (m^2) and its correlation area (px^2). */
std::vector<BlockSummary> blockSummaries(const FusionGrid& g, const View& view, const std::vector<Sample>& samples,
                                         const Eigen::Isometry3d& T, double block, int stride, double noise2, double corr);
/** A summary's offset at pose T (the cost's own function, for tests). */
double blockOffset(const BlockSummary& s, const Eigen::Isometry3d& T);
/** The pose graph over the frames' summaries (site_graph.cpp): every block two frames share is a residual, their
 *  offsets' difference over its sigma (Huber at 2 sigma), plus a weak prior on each pose as `given` (5 mrad, 1 mm);
 *  frame `fixed` holds the gauge. Poses are replaced
 *  when the solution is usable. */
SitePoseGraph solvePoseGraph(const std::vector<std::vector<BlockSummary>>& blocks, int fixed, const std::vector<Eigen::Isometry3d>& given,
                             std::vector<Eigen::Isometry3d>* poses, int max_iterations = 30);

/** Aligns a frame to the fused surface from its given pose (site_fusion.h, 2.; site_register.cpp): sets F->pose,
 *  overlap, correction_rms, registration_iterations; false (F->reason says why) when it must be left out. */
bool registerFrame(const FusionGrid& g, const View& view, const std::vector<Sample>& samples, const SiteOptions& o,
                   const Eigen::Isometry3d& T_W_C, SiteFrame* F);

}  // namespace site_detail
}  // namespace site
}  // namespace skin3d
