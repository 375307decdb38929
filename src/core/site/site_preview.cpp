// SPDX-License-Identifier: BSD-3-Clause
// The live view of a site scan: the fused grid in coarse cells, heights above a quick body model (site_fusion.h).
#include <algorithm>
#include <cmath>
#include <limits>

#include "site_detail.h"

namespace skin3d {
namespace site {

SitePreview SiteFusion::preview(int max_cells) const {
  SitePreview p;
  if (!grid_) return p;
  const site_detail::FusionGrid& g = *grid_;
  const int step = std::max(1, static_cast<int>(std::ceil(std::sqrt(static_cast<double>(g.nu) * g.nv /
                                                                    std::max(1, max_cells)))));
  const int W = (g.nu + step - 1) / step, H = (g.nv + step - 1) / step;
  p.model = g.surf.model;
  p.cell = step * g.cell;
  p.u0 = g.umin + 0.5 * p.cell;
  p.v0 = g.vmin + 0.5 * p.cell;
  for (const SiteFrame& f : frames_) p.frames_fused += f.fused;
  // each preview cell: the inverse-variance mean of its fused cells, their mean sigma, their most frames
  site_detail::FusedMap m;
  m.surface = g.surf;
  m.cell = p.cell;
  m.wref = g.wref;
  m.u0 = p.u0;
  m.v0 = p.v0;
  m.value.create(H, W, CV_64F);
  p.sigma.create(H, W, CV_32F);
  p.frames.create(H, W, CV_8U);
  for (int J = 0; J < H; ++J)
    for (int I = 0; I < W; ++I) {
      double sw = 0, swh = 0, ss = 0;
      int n = 0, most = 0;
      for (int j = J * step; j < std::min(g.nv, (J + 1) * step); ++j)
        for (int i = I * step; i < std::min(g.nu, (I + 1) * step); ++i) {
          const std::size_t k = g.idx(i, j);
          if (!(g.sw[k] > 0)) continue;
          sw += g.sw[k];
          swh += g.swh[k];
          ss += 1.0 / std::sqrt(g.sw[k]);
          ++n;
          most = std::max<int>(most, g.count[k]);
        }
      m.value.at<double>(J, I) = n ? swh / sw : site_detail::kNaN;
      p.sigma.at<float>(J, I) = n ? static_cast<float>(ss / n) : std::numeric_limits<float>::quiet_NaN();
      p.frames.at<uchar>(J, I) = static_cast<uchar>(most);
    }
  const site_detail::BodyModel bm = site_detail::fitBodyModel(m, cv::Mat());
  p.height.create(H, W, CV_32F);
  p.world_xyz.create(H, W, CV_32FC3);
  for (int J = 0; J < H; ++J)
    for (int I = 0; I < W; ++I) {
      const double val = m.value.at<double>(J, I);
      if (!std::isfinite(val)) {
        p.height.at<float>(J, I) = std::numeric_limits<float>::quiet_NaN();
        p.world_xyz.at<cv::Vec3f>(J, I) = cv::Vec3f::all(std::numeric_limits<float>::quiet_NaN());
        continue;
      }
      const double u = p.u0 + I * p.cell, v = p.v0 + J * p.cell;
      p.height.at<float>(J, I) = static_cast<float>(val - bm.eval(g.surf, u, v));
      const Eigen::Vector3d X = g.surf.toWorld(Eigen::Vector3d(u, v, g.wref + val));
      p.world_xyz.at<cv::Vec3f>(J, I) = cv::Vec3f(static_cast<float>(X.x()), static_cast<float>(X.y()), static_cast<float>(X.z()));
    }
  return p;
}

}  // namespace site
}  // namespace skin3d
