// SPDX-License-Identifier: BSD-3-Clause
// The site scan's fusion: body surface, registration, fusion into the unrolled height field (site_fusion.h).
#include "skin3d/site/site_fusion.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>

#include "skin3d/geometry/quaternion.h"
#include "site_detail.h"

namespace skin3d {
namespace site {

using site_detail::kNaN;

void SiteOptions::validate() const {
  auto bad = [](const std::string& k, double v, const std::string& why) {
    throw std::invalid_argument("site option '" + k + "' = " + std::to_string(v) + ": " + why);
  };
  if (!(cell >= 0) || cell > 5e-3) bad("site_cell_mm", cell * 1e3, "must be 0 (automatic) or in (0, 5] mm");
  if (!(max_incidence_deg > 0 && max_incidence_deg <= 90)) bad("site_max_incidence_deg", max_incidence_deg, "must be in (0, 90]");
  if (register_stride < 1 || register_stride > 64) bad("site_register_stride", register_stride, "must be in 1..64");
  if (register_iterations < 1 || register_iterations > 100) bad("site_register_iterations", register_iterations, "must be in 1..100");
  if (!(min_overlap >= 0 && min_overlap <= 1)) bad("site_min_overlap", min_overlap, "must be in [0, 1]");
  if (!(max_correction > 0)) bad("site_max_correction_mm", max_correction * 1e3, "must be > 0");
  if (!(seam_block > 0) || seam_block > 0.05) bad("site_seam_block_mm", seam_block * 1e3, "must be in (0, 50] mm");
}

// ------------------------------------------------------------------ the body surface

Eigen::Vector3d SiteSurface::toSurface(const Eigen::Vector3d& X) const {
  const Eigen::Vector3d d = X - origin;
  if (model == "cylinder") {
    const double u = axis.dot(d);
    const Eigen::Vector3d p = d - u * axis;
    return Eigen::Vector3d(u, radius * std::atan2(e2.dot(p), e1.dot(p)), p.norm());
  }
  return Eigen::Vector3d(e1.dot(d), e2.dot(d), axis.dot(d));
}

Eigen::Vector3d SiteSurface::toWorld(const Eigen::Vector3d& uvw) const {
  if (model == "cylinder") {
    const double th = uvw.y() / radius;
    return origin + uvw.x() * axis + uvw.z() * (std::cos(th) * e1 + std::sin(th) * e2);
  }
  return origin + uvw.x() * e1 + uvw.y() * e2 + uvw.z() * axis;
}

Eigen::Vector3d SiteSurface::outward(const Eigen::Vector3d& uvw) const {
  if (model == "cylinder") {
    const double th = uvw.y() / radius;
    return std::cos(th) * e1 + std::sin(th) * e2;
  }
  return axis;
}

void SiteSurface::tangents(const Eigen::Vector3d& uvw, Eigen::Vector3d* tu, Eigen::Vector3d* tv) const {
  if (model == "cylinder") {
    const double th = uvw.y() / radius;
    *tu = axis;
    *tv = (uvw.z() / radius) * (-std::sin(th) * e1 + std::cos(th) * e2);
  } else {
    *tu = e1;
    *tv = e2;
  }
}

double pointToPlane(const Eigen::Vector3d& X, const Eigen::Vector3d& P, const Eigen::Vector3d& n,
                    Eigen::Matrix<double, 1, 6>* J) {
  // X -> Exp(dphi) X + dt: d(n . X) / d dphi = n . (-[X]x) = (X x n)^T, d / d dt = n^T
  if (J) {
    J->leftCols<3>() = X.cross(n).transpose();
    J->rightCols<3>() = n.transpose();
  }
  return n.dot(X - P);
}

namespace site_detail {

SiteSurface surfaceFromReference(const induration::ReferenceSurface& ref, const geometry::DenseCloud& cloud,
                                 const Eigen::Isometry3d& T_W_C, std::string* why) {
  // median known point and the points for the radius
  std::vector<Eigen::Vector3d> pts;
  const int step = std::max(1, static_cast<int>(std::sqrt(cloud.xyz.total() / 20000.0)));
  for (int y = 0; y < cloud.xyz.rows; y += step)
    for (int x = 0; x < cloud.xyz.cols; x += step) {
      const cv::Vec3f& p = cloud.xyz.at<cv::Vec3f>(y, x);
      if (std::isfinite(p[0]) && std::isfinite(p[2])) pts.emplace_back(p[0], p[1], p[2]);
    }
  if (pts.size() < 100) throw std::invalid_argument("too few points to choose the body surface");
  auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  };
  std::vector<double> xs, ys, zs;
  for (const auto& p : pts) {
    xs.push_back(p.x());
    ys.push_back(p.y());
    zs.push_back(p.z());
  }
  const Eigen::Vector3d med(median(xs), median(ys), median(zs));
  SiteSurface s;
  if (ref.model == "quadric") {
    const auto& c = ref.coefficients;
    Eigen::Matrix3d A;
    A << c[0], 0.5 * c[3], 0.5 * c[4], 0.5 * c[3], c[1], 0.5 * c[5], 0.5 * c[4], 0.5 * c[5], c[2];
    const Eigen::Vector3d b(c[6], c[7], c[8]);
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(A);
    int k0 = 0;
    for (int k = 1; k < 3; ++k)
      if (std::fabs(es.eigenvalues()[k]) < std::fabs(es.eigenvalues()[k0])) k0 = k;
    const int k1 = (k0 + 1) % 3, k2 = (k0 + 2) % 3;
    const double l0 = es.eigenvalues()[k0], l1 = es.eigenvalues()[k1], l2 = es.eigenvalues()[k2];
    if (l1 * l2 > 0 && std::fabs(l0) < 0.25 * std::min(std::fabs(l1), std::fabs(l2))) {
      const Eigen::Vector3d ax = es.eigenvectors().col(k0).normalized();
      Eigen::Vector3d y0 = Eigen::Vector3d::Zero();
      for (int k : {k1, k2}) y0 -= 0.5 * es.eigenvectors().col(k).dot(b) / es.eigenvalues()[k] * es.eigenvectors().col(k);
      const Eigen::Vector3d x0 = ref.q_centre + ref.q_scale * y0;  // a point on the axis, camera frame
      std::vector<double> rs;
      for (const auto& p : pts) rs.push_back(((p - x0) - (p - x0).dot(ax) * ax).norm());
      const double R = median(rs);
      if (R > 5e-3 && R < 0.5) {
        s.model = "cylinder";
        s.radius = R;
        s.axis = T_W_C.linear() * ax;
        // theta = 0 where the axis is nearest to the median point: the middle of the first view
        const Eigen::Vector3d d = med - x0;
        s.origin = T_W_C * (x0 + d.dot(ax) * ax);
        s.e1 = T_W_C.linear() * (d - d.dot(ax) * ax).normalized();
        s.e2 = s.axis.cross(s.e1);
        return s;
      }
      if (why) *why = "the first frame's quadric is a cylinder of radius " + std::to_string(R * 1e3) + " mm (not a body): a plane is used";
    } else if (why) {
      *why = "the first frame's quadric is not a cylinder (eigenvalues " + std::to_string(l0) + ", " + std::to_string(l1) +
             ", " + std::to_string(l2) + "): the site is unrolled on a plane";
    }
  }
  // a plane: the reference's tangent plane at the median point, its normal towards the camera
  Eigen::Vector4d tp = ref.tangentPlane(med);
  Eigen::Vector3d n = tp.head<3>().normalized();
  if (n.dot(-med) < 0) n = -n;
  s.model = "plane";
  s.axis = T_W_C.linear() * n;
  s.origin = T_W_C * med;
  Eigen::Vector3d a = std::fabs(n.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  const Eigen::Vector3d e1c = (a - a.dot(n) * n).normalized();
  s.e1 = T_W_C.linear() * e1c;
  s.e2 = s.axis.cross(s.e1);
  return s;
}

}  // namespace site_detail

// ------------------------------------------------------------------ the fused grid


SiteFusion::SiteFusion(const SiteOptions& options, const induration::IndurationOptions& induration)
    : options_(options), induration_(induration) {
  options_.validate();
  induration_.validate();
}

SiteFusion::~SiteFusion() { delete grid_; }  // NOLINT: the grid is site_detail::FusionGrid

bool SiteFusion::empty() const { return grid_ == nullptr; }

void SiteFusion::skip(double stamp, const std::string& reason) {
  SiteFrame f;
  f.index = static_cast<int>(frames_.size());
  f.stamp = stamp;
  f.reason = reason;
  frames_.push_back(f);
}

namespace site_detail {

/** A camera-frame point in world and on the surface, and the cosine of the larger incidence of both cameras on the
 *  body's normal there. */
double incidenceCos(const FusionGrid& g, const View& v, const Eigen::Isometry3d& T, const Eigen::Vector3d& Xc,
                    Eigen::Vector3d* Xw, Eigen::Vector3d* uvw) {
  *Xw = T * Xc;
  *uvw = g.surf.toSurface(*Xw);
  const Eigen::Vector3d n = g.surf.outward(*uvw);
  double c = n.dot((T.translation() - *Xw).normalized());
  if (v.have_right) c = std::min(c, n.dot((T * v.rc - *Xw).normalized()));
  return c;
}

/** The body surface and the grid from a frame (site_fusion.h, 1. and 3.); nullptr with *reason when it cannot. */
FusionGrid* makeGrid(const SiteOptions& o, const geometry::DenseCloud& cloud, const induration::IndurationResult& own,
                     const Eigen::Isometry3d& T_W_C, std::string* reason) {
  if (!own.reference_ok) {
    *reason = "its own measurement found no healthy-skin reference to choose the body surface from";
    return nullptr;
  }
  std::string why;
  SiteSurface s;
  try {
    s = site_detail::surfaceFromReference(own.reference, cloud, T_W_C, &why);
  } catch (const std::invalid_argument& e) {
    *reason = e.what();
    return nullptr;
  }
  double cell = o.cell;
  if (cell == 0) cell = site_detail::medianPixelFootprint(cloud);
  if (!(cell > 0)) {
    *reason = "cannot tell the pixel footprint (too few neighbouring points)";
    return nullptr;
  }
  // extent: the first view's, widened by half its span (plane: by its span) each way; the cylinder's whole turn
  double umin = 1e9, umax = -1e9, vmin = 1e9, vmax = -1e9;
  for (int y = 0; y < cloud.xyz.rows; y += 4)
    for (int x = 0; x < cloud.xyz.cols; x += 4) {
      const cv::Vec3f& p = cloud.xyz.at<cv::Vec3f>(y, x);
      if (!std::isfinite(p[0])) continue;
      const Eigen::Vector3d uvw = s.toSurface(T_W_C * Eigen::Vector3d(p[0], p[1], p[2]));
      umin = std::min(umin, uvw.x());
      umax = std::max(umax, uvw.x());
      vmin = std::min(vmin, uvw.y());
      vmax = std::max(vmax, uvw.y());
    }
  auto* g = new FusionGrid;
  g->surf = s;
  g->cell = cell;
  const double su = umax - umin, sv = vmax - vmin;
  const double grow = s.model == "cylinder" ? 0.5 : 1.0;
  g->umin = umin - grow * su;
  g->nu = static_cast<int>(std::ceil((1 + 2 * grow) * su / cell));
  if (s.model == "cylinder") {
    g->periodic = true;
    g->wref = s.radius;
    g->vmin = -M_PI * s.radius;
    g->nv = static_cast<int>(std::ceil(2 * M_PI * s.radius / cell));
    g->cell = 2 * M_PI * s.radius / g->nv;  // a whole number of cells around
  } else {
    g->vmin = vmin - sv;
    g->nv = static_cast<int>(std::ceil(3 * sv / cell));
  }
  const double cells = static_cast<double>(g->nu) * g->nv;
  if (cells > 60e6) {
    delete g;
    *reason = "the site grid would have " + std::to_string(static_cast<long>(cells / 1e6)) +
               " million cells of " + std::to_string(cell * 1e6) + " um: set site_cell_mm larger";
    return nullptr;
  }
  const std::size_t n = static_cast<std::size_t>(cells);
  g->sw.assign(n, 0.f);
  g->swh.assign(n, 0.0);
  g->sw2v.assign(n, 0.f);
  g->count.assign(n, 0);
  g->best.assign(n, 0);
  g->bestw.assign(n, 0.f);
  g->last.assign(n, -1);
  g->note = why;
  return g;
}

/** The frame's skin points (camera frame) with their sigma: where its own measurement has a height within `hmax` of
 *  its reference (the background, mismatches beyond the limb's silhouette and outliers have none). */
std::vector<Sample> skinSamples(const geometry::DenseCloud& cloud, const induration::IndurationResult& own, float hmax) {
  // only the skin: where the frame's own measurement has a height within max_height of its reference (the
  // background, mismatches beyond the limb's silhouette and outliers have none)
  const bool have_heights = own.height_map.size() == cloud.xyz.size() && own.height_map.type() == CV_32F;
  std::vector<Sample> samples;
  samples.reserve(cloud.xyz.total() / 2);
  for (int y = 0; y < cloud.xyz.rows; ++y) {
    const cv::Vec3f* p = cloud.xyz.ptr<cv::Vec3f>(y);
    const float* sg = cloud.sigma.ptr<float>(y);
    const float* hh = have_heights ? own.height_map.ptr<float>(y) : nullptr;
    for (int x = 0; x < cloud.xyz.cols; ++x) {
      if (!(std::isfinite(p[x][0]) && std::isfinite(p[x][2]) && std::isfinite(sg[x]) && sg[x] > 0)) continue;
      if (hh && !(std::fabs(hh[x]) <= hmax)) {
        // no height in its own map: outlier removal (steep plaque ramps too) or off the reference; keep it when it
        // lies within max_height of that reference (the ramp), not when it is background
        if (!std::isnan(hh[x]) || !own.reference_ok) continue;
        if (!(std::fabs(own.reference.height(Eigen::Vector3d(p[x][0], p[x][1], p[x][2]))) <= hmax)) continue;
      }
      samples.push_back({Eigen::Vector3d(p[x][0], p[x][1], p[x][2]), sg[x]});
    }
  }
  return samples;
}

/** Compares a frame with the fused surface (its seams) and fuses it (site_fusion.h, 3. and 5.); returns the samples
 *  fused and how many fell on skin fused before. */
long fuseFrame(FusionGrid& g, const View& view, const std::vector<Sample>& samples, const induration::IndurationResult& own,
               const SiteOptions& o, SiteFrame* F, long* on_old_out) {
  const double cos_max = view.cos_max;
  const int B = std::max(1, static_cast<int>(std::lround(o.seam_block / g.cell)));
  const int nbu = (g.nu + B - 1) / B, nbv = (g.nv + B - 1) / B;
  struct Fuse {
    double u, v, h, w, var;
  };
  // the variance each sample brings to a block mean: the frame's measured height noise (its stated sigma when that
  // is larger), times the area over which that noise is correlated (the matcher's window): neighbouring samples
  // share their error, so n of them average it down by n / that area, not by n
  const double corr = std::isfinite(own.noise_correlation_px2) ? std::max(1.0, own.noise_correlation_px2) : 1.0;
  const double noise2 = std::isfinite(own.height_noise) ? own.height_noise * own.height_noise : 0.0;
  std::vector<Fuse> fuse;
  fuse.reserve(samples.size());
  for (const Sample& s : samples) {
    Eigen::Vector3d Xw, uvw;
    const double ci = incidenceCos(g, view, F->pose, s.X, &Xw, &uvw);
    if (ci < cos_max) continue;
    fuse.push_back({uvw.x(), uvw.y(), uvw.z() - g.wref, ci * ci / (static_cast<double>(s.sigma) * s.sigma),
                    std::max(noise2, static_cast<double>(s.sigma) * s.sigma) * corr});
  }
  // per block: the weighted mean of (sample - the fused cell it falls in, as fused before this frame), and the
  // variance the stated sigmas give it
  std::vector<double> fw(static_cast<std::size_t>(nbu) * nbv, 0.0), fwd(fw.size(), 0.0), fw2v(fw.size(), 0.0);
  std::vector<int> fn(fw.size(), 0);
  long on_old = 0;
  for (const Fuse& q : fuse) {
    int ic, jc;
    if (!g.cellOf(q.u, q.v, &ic, &jc)) continue;
    if (!(g.sw[g.idx(ic, jc)] > 0)) continue;
    ++on_old;
    // the fused surface interpolated at the sample (bilinear over the four cells around it, all fused): a sample
    // compared with its cell's centre would differ by the slope across the cell on a plaque's ramp
    const double fu = (q.u - g.umin) / g.cell - 0.5, fv = (q.v - g.vmin) / g.cell - 0.5;
    const int i0 = static_cast<int>(std::floor(fu)), j0 = static_cast<int>(std::floor(fv));
    const double a = fu - i0, bb = fv - j0;
    double val = 0, var = 0;
    bool all = true;
    for (int dj = 0; dj < 2 && all; ++dj)
      for (int di = 0; di < 2 && all; ++di) {
        int i = i0 + di, j = j0 + dj;
        if (g.periodic) j = ((j % g.nv) + g.nv) % g.nv;
        if (i < 0 || i >= g.nu || j < 0 || j >= g.nv || !(g.sw[g.idx(i, j)] > 0)) {
          all = false;
          break;
        }
        const std::size_t k = g.idx(i, j);
        const double c = (di ? a : 1 - a) * (dj ? bb : 1 - bb);
        val += c * g.swh[k] / g.sw[k];
        var += c * c * g.sw2v[k] / (static_cast<double>(g.sw[k]) * g.sw[k]);
      }
    if (!all) continue;
    const std::size_t kb = static_cast<std::size_t>(jc / B) * nbu + ic / B;
    fw[kb] += q.w;
    fwd[kb] += q.w * (q.h - val);
    fw2v[kb] += q.w * q.w * (q.var + var);
    ++fn[kb];
  }
  double s2 = 0, n2 = 0;
  int nb = 0;
  // the rigid part of the disagreement: a plane (offset and tilts in u, v) fitted to the block differences, each
  // weighted by its noise; its RMS over the blocks is what a pose error leaves, measured through the noise
  Eigen::Matrix3d Ap = Eigen::Matrix3d::Zero();
  Eigen::Vector3d bp = Eigen::Vector3d::Zero();
  std::vector<std::pair<Eigen::Vector3d, double>> blocks;
  for (std::size_t kb = 0; kb < fw.size(); ++kb) {
    if (fn[kb] < B * B / 2) continue;
    const double d = fwd[kb] / fw[kb];
    s2 += d * d;
    const double var = std::min(fw2v[kb] / (fw[kb] * fw[kb]), 2 * std::max(noise2, 1e-18));  // within one correlation area: its noise
    n2 += var;
    ++nb;
    const double bu = ((kb % nbu) + 0.5) * B * g.cell, bv = ((kb / nbu) + 0.5) * B * g.cell;
    const Eigen::Vector3d x(1.0, bu, bv);
    Ap += x * x.transpose() / std::max(var, 1e-18);
    bp += x * d / std::max(var, 1e-18);
    blocks.emplace_back(x, d);
  }
  if (nb >= 10) {
    const Eigen::Vector3d c = Ap.ldlt().solve(bp);
    double r2 = 0;
    for (const auto& [x, d] : blocks) r2 += std::pow(x.dot(c), 2);
    F->seam_rigid = std::sqrt(r2 / nb);
  } else {
    F->seam_rigid = kNaN;
  }
  long fused = 0;
  for (const Fuse& q : fuse) {
    const double fu = (q.u - g.umin) / g.cell - 0.5, fv = (q.v - g.vmin) / g.cell - 0.5;
    const int i0 = static_cast<int>(std::floor(fu)), j0 = static_cast<int>(std::floor(fv));
    const double a = fu - i0, bb = fv - j0;
    bool any = false;
    for (int dj = 0; dj < 2; ++dj)
      for (int di = 0; di < 2; ++di) {
        int i = i0 + di, j = j0 + dj;
        if (g.periodic) j = ((j % g.nv) + g.nv) % g.nv;
        if (i < 0 || i >= g.nu || j < 0 || j >= g.nv) continue;
        const double ws = q.w * (di ? a : 1 - a) * (dj ? bb : 1 - bb);
        if (ws <= 0) continue;
        const std::size_t k = g.idx(i, j);
        g.sw[k] += static_cast<float>(ws);
        g.swh[k] += ws * q.h;
        g.sw2v[k] += static_cast<float>(ws * ws * q.var);
        if (g.last[k] != F->index) {
          g.last[k] = F->index;
          if (g.count[k] < 255) ++g.count[k];
        }
        if (ws > g.bestw[k]) {
          g.bestw[k] = static_cast<float>(ws);
          g.best[k] = static_cast<std::uint8_t>(std::min(F->index, 255));
        }
        any = true;
      }
    fused += any;
  }
  F->seam_blocks = nb;
  F->seam_rms = nb > 0 ? std::sqrt(s2 / nb) : kNaN;
  F->seam_noise = nb > 0 ? std::sqrt(n2 / nb) : kNaN;
  F->seam_excess = nb > 0 ? std::sqrt(std::max(0.0, s2 - n2) / nb) : kNaN;
  *on_old_out = on_old;
  return fused;
}

}  // namespace site_detail

const SiteFrame& SiteFusion::add(const geometry::DenseCloud& cloud, const induration::IndurationResult& own,
                                 const Eigen::Isometry3d& T_W_C, double stamp) {
  SiteFrame f;
  f.index = static_cast<int>(frames_.size());
  f.stamp = stamp;
  f.pose_given = f.pose = T_W_C;
  f.plaques = own.plaques;
  f.right_centre = Eigen::Vector3d(cloud.right_centre[0], cloud.right_centre[1], cloud.right_centre[2]);
  frames_.push_back(f);
  SiteFrame& F = frames_.back();
  if (cloud.xyz.empty() || cloud.sigma.size() != cloud.xyz.size()) {
    F.reason = "no dense cloud with sigma";
    return F;
  }
  const bool have_right = std::isfinite(cloud.right_centre[0]);
  const Eigen::Vector3d rc_c = have_right ? Eigen::Vector3d(cloud.right_centre[0], cloud.right_centre[1], cloud.right_centre[2])
                                          : Eigen::Vector3d::Zero();
  if (!grid_) {
    std::string why;
    grid_ = site_detail::makeGrid(options_, cloud, own, T_W_C, &why);
    if (!grid_) {
      F.reason = why;
      return F;
    }
  }
  site_detail::FusionGrid& g = *grid_;

  std::vector<site_detail::Sample> samples = site_detail::skinSamples(cloud, own, static_cast<float>(induration_.max_height));
  if (samples.size() < 100) {
    F.reason = "only " + std::to_string(samples.size()) + " points were matched";
    return F;
  }
  const double cos_max = std::cos(options_.max_incidence_deg * M_PI / 180.0);
  const site_detail::View view{rc_c, have_right, cos_max};

  using Clock = std::chrono::steady_clock;
  auto t_reg = Clock::now();
  const bool first = std::none_of(frames_.begin(), frames_.end() - 1, [](const SiteFrame& q) { return q.fused; });
  if (!first && options_.register_frames && !site_detail::registerFrame(g, view, samples, options_, T_W_C, &F)) return F;
  F.seconds_register = std::chrono::duration<double>(Clock::now() - t_reg).count();
  const auto t_fuse = Clock::now();
  long on_old = 0;
  const long fused = site_detail::fuseFrame(g, view, samples, own, options_, &F, &on_old);
  F.samples = fused;
  F.seconds_fuse = std::chrono::duration<double>(Clock::now() - t_fuse).count();
  if (first) F.overlap = 0;
  else if (!options_.register_frames) F.overlap = fused > 0 ? static_cast<double>(on_old) / fused : 0.0;
  if (fused == 0) {
    F.reason = "none of its samples lies within site_max_incidence_deg on the site's surface";
    return F;
  }
  F.fused = true;
  F.reason.clear();
  if (options_.pose_graph) {
    auto k = std::make_unique<site_detail::KeptFrame>();
    k->index = F.index;
    k->samples = std::move(samples);  // not used here again
    k->view = view;
    k->height_noise = own.height_noise;
    k->noise_correlation_px2 = own.noise_correlation_px2;
    kept_.push_back(std::move(k));
  }
  return F;
}

namespace site_detail {

double medianPixelFootprint(const geometry::DenseCloud& cloud) {
  std::vector<double> d;
  const int step = std::max(1, static_cast<int>(std::sqrt(cloud.xyz.total() / 40000.0)));
  for (int y = 0; y < cloud.xyz.rows; y += step)
    for (int x = 0; x + 1 < cloud.xyz.cols; x += step) {
      const cv::Vec3f& a = cloud.xyz.at<cv::Vec3f>(y, x);
      const cv::Vec3f& b = cloud.xyz.at<cv::Vec3f>(y, x + 1);
      if (std::isfinite(a[0]) && std::isfinite(b[0])) d.push_back(cv::norm(a - b));
    }
  if (d.size() < 20) return 0;
  std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
  return d[d.size() / 2];
}

}  // namespace site_detail

SiteResult SiteFusion::measure() const {
  const auto t0 = std::chrono::steady_clock::now();
  SiteResult r;
  if (!grid_) {
    r.warnings.push_back("no frame could be fused: nothing to measure");
    return r;
  }
  const site_detail::FusionGrid& g = *grid_;
  site_detail::FusedMap map;
  map.surface = g.surf;
  map.cell = g.cell;
  map.wref = g.wref;
  // crop to the fused cells; around a limb the rows start after the widest run of empty ones (v wraps)
  int i0 = g.nu, i1 = -1;
  std::vector<char> row_has(g.nv, 0);
  for (int j = 0; j < g.nv; ++j)
    for (int i = 0; i < g.nu; ++i)
      if (g.sw[g.idx(i, j)] > 0) {
        i0 = std::min(i0, i);
        i1 = std::max(i1, i);
        row_has[j] = 1;
      }
  if (i1 < 0) {
    r.warnings.push_back("no cell of the site has a fused height");
    return r;
  }
  int j0 = 0, H = g.nv;
  if (g.periodic) {
    int best_len = 0, best_end = 0;
    for (int start = 0; start < g.nv; ++start) {  // runs of empty rows, circularly
      if (row_has[start] || !row_has[(start + g.nv - 1) % g.nv]) continue;
      int len = 0;
      while (len < g.nv && !row_has[(start + len) % g.nv]) ++len;
      if (len > best_len) {
        best_len = len;
        best_end = (start + len) % g.nv;
      }
    }
    j0 = best_end;
    H = g.nv - best_len;
  } else {
    int lo = g.nv, hi = -1;
    for (int j = 0; j < g.nv; ++j)
      if (row_has[j]) {
        lo = std::min(lo, j);
        hi = std::max(hi, j);
      }
    j0 = lo;
    H = hi - lo + 1;
  }
  const int W = i1 - i0 + 1;
  map.value.create(H, W, CV_64F);
  map.sigma.create(H, W, CV_32F);
  map.frames.create(H, W, CV_8U);
  for (int j = 0; j < H; ++j)
    for (int i = 0; i < W; ++i) {
      const std::size_t k = g.idx(i0 + i, (j0 + j) % g.nv);
      const bool ok = g.sw[k] > 0;
      map.value.at<double>(j, i) = ok ? g.swh[k] / g.sw[k] : kNaN;
      map.sigma.at<float>(j, i) = ok ? static_cast<float>(1.0 / std::sqrt(g.sw[k])) : std::numeric_limits<float>::quiet_NaN();
      map.frames.at<uchar>(j, i) = g.count[k];
    }
  map.u0 = g.umin + (i0 + 0.5) * g.cell;
  map.v0 = g.vmin + (j0 + 0.5) * g.cell;
  r = site_detail::measureSite(map, induration_, frames_);
  if (!g.note.empty()) r.warnings.insert(r.warnings.begin(), g.note);
  for (const SiteFrame& f : frames_) {
    if (f.fused) {
      ++r.frames_fused;
    } else {
      ++r.frames_left_out;
      r.warnings.push_back("frame " + std::to_string(f.index) + " (t = " + std::to_string(f.stamp) + " s) left out: " + f.reason);
    }
  }
  double s2 = 0, n2 = 0;
  int nb = 0;
  for (const SiteFrame& f : frames_)
    if (f.fused && f.seam_blocks > 0) {
      s2 += f.seam_rms * f.seam_rms * f.seam_blocks;
      n2 += f.seam_noise * f.seam_noise * f.seam_blocks;
      nb += f.seam_blocks;
    }
  double g2 = 0;
  int ng = 0;
  for (const SiteFrame& f : frames_)
    if (f.fused && std::isfinite(f.seam_rigid)) {
      g2 += f.seam_rigid * f.seam_rigid * f.seam_blocks;
      ng += f.seam_blocks;
    }
  r.seam_rigid = ng > 0 ? std::sqrt(g2 / ng) : kNaN;
  r.seam_rms = nb > 0 ? std::sqrt(s2 / nb) : kNaN;
  r.seam_noise = nb > 0 ? std::sqrt(n2 / nb) : kNaN;
  r.seam_excess = nb > 0 ? std::sqrt(std::max(0.0, s2 - n2) / nb) : kNaN;
  r.pose_graph = graph_;
  r.seconds_measure = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return r;
}

}  // namespace site
}  // namespace skin3d
