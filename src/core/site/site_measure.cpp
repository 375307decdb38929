// SPDX-License-Identifier: BSD-3-Clause
// The site measurement: the body model, the unrolled height map measured as one frame, plaques back in `world`.
#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <opencv2/imgproc.hpp>

#include "site_detail.h"

namespace skin3d {
namespace site {
namespace site_detail {

namespace {

constexpr int kCylinderTerms = 15, kPlaneTerms = 6;
constexpr double kFlatDistance = 1.0;
/** deg: a plaque no pair saw within this incidence in both cameras is listed apart (the "usable angle": the
 *  footprint stretched by more than 1.4, the depth noise grown with it; the edges of a sweep, mismatches there) */
constexpr double kUsableIncidence = 45.0;  // m, the unrolled map is seen from this far straight above (float precision: 0.1 um)

/** basis of the body model at (u, v) with its derivatives along u and v */
void basis(const SiteSurface& s, double u, double v, Eigen::VectorXd* f, Eigen::VectorXd* fu, Eigen::VectorXd* fv) {
  if (s.model == "cylinder") {
    const double R = s.radius, th = v / R;
    f->resize(kCylinderTerms);
    fu->setZero(kCylinderTerms);
    fv->setZero(kCylinderTerms);
    int k = 0;
    auto put = [&](double val, double dval_dth, bool with_u) {
      (*f)[k] = val;
      (*fv)[k] = dval_dth / R;
      ++k;
      if (with_u) {
        (*f)[k] = u * val;
        (*fu)[k] = val;
        (*fv)[k] = u * dval_dth / R;
        ++k;
      }
    };
    put(1.0, 0.0, true);
    for (int h = 1; h <= 4; ++h) {
      put(std::cos(h * th), -h * std::sin(h * th), h <= 2);
      put(std::sin(h * th), h * std::cos(h * th), h <= 2);
    }
    (*f)[k] = u * u;
    (*fu)[k] = 2 * u;
    (*fv)[k] = 0;
  } else {
    f->resize(kPlaneTerms);
    *f << 1, u, v, u * u, u * v, v * v;
    fu->resize(kPlaneTerms);
    *fu << 0, 1, 0, 2 * u, v, 0;
    fv->resize(kPlaneTerms);
    *fv << 0, 0, 1, 0, u, 2 * v;
  }
}

double median(std::vector<double> v) {
  if (v.empty()) return kNaN;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

}  // namespace

double BodyModel::eval(const SiteSurface& s, double u, double v, double* du, double* dv) const {
  Eigen::VectorXd f, fu, fv;
  basis(s, u, v, &f, &fu, &fv);
  if (du) *du = fu.dot(coef);
  if (dv) *dv = fv.dot(coef);
  return f.dot(coef);
}

BodyModel fitBodyModel(const FusedMap& m, const cv::Mat& exclude) {
  BodyModel bm;
  bm.name = m.surface.model == "cylinder" ? "cylinder + Fourier series to the 4th harmonic around it" : "plane + quadratic";
  std::vector<std::pair<int, int>> cells;
  for (int j = 0; j < m.value.rows; ++j)
    for (int i = 0; i < m.value.cols; ++i)
      if (std::isfinite(m.value.at<double>(j, i)) && (exclude.empty() || !exclude.at<uchar>(j, i))) cells.emplace_back(i, j);
  const std::size_t step = std::max<std::size_t>(1, cells.size() / 150000);
  std::vector<std::pair<int, int>> use;
  for (std::size_t k = 0; k < cells.size(); k += step) use.push_back(cells[k]);
  const int n = static_cast<int>(use.size());
  const int p = m.surface.model == "cylinder" ? kCylinderTerms : kPlaneTerms;
  if (n < 4 * p) {
    bm.coef.setZero(p);
    return bm;
  }
  Eigen::MatrixXd A(n, p);
  Eigen::VectorXd y(n), w = Eigen::VectorXd::Ones(n);
  Eigen::VectorXd f, fu, fv;
  for (int k = 0; k < n; ++k) {
    const double u = m.u0 + use[k].first * m.cell, v = m.v0 + use[k].second * m.cell;
    basis(m.surface, u, v, &f, &fu, &fv);
    A.row(k) = f.transpose();
    y[k] = m.value.at<double>(use[k].second, use[k].first);
  }
  Eigen::VectorXd coef = Eigen::VectorXd::Zero(p);
  double scale = 0;
  for (int it = 0; it < 10; ++it) {
    const Eigen::VectorXd sw = w.array().sqrt();
    coef = (sw.asDiagonal() * A).colPivHouseholderQr().solve(sw.asDiagonal() * y);
    const Eigen::VectorXd r = y - A * coef;
    std::vector<double> a(n);
    for (int k = 0; k < n; ++k) a[k] = std::fabs(r[k]);
    scale = std::max(1.4826 * median(a), 1e-6);
    const double c = 4.685 * scale;
    for (int k = 0; k < n; ++k) {
      const double q = r[k] / c;
      w[k] = std::fabs(q) < 1 ? (1 - q * q) * (1 - q * q) : 0.0;
    }
  }
  bm.coef = coef;
  bm.rms = scale;
  return bm;
}

/** The world point of every known cell and the fused area on the body (the cells' stretch from the unrolled map). */
void worldPoints(const FusedMap& m, const cv::Mat& stretch, SiteResult* r) {
  const int W = m.value.cols, H = m.value.rows;
  r->world_xyz.create(H, W, CV_32FC3);
  double area = 0;
  for (int j = 0; j < H; ++j)
    for (int i = 0; i < W; ++i) {
      const double val = m.value.at<double>(j, i);
      if (!std::isfinite(val)) {
        r->world_xyz.at<cv::Vec3f>(j, i) = cv::Vec3f(NAN, NAN, NAN);
        continue;
      }
      const Eigen::Vector3d X = m.surface.toWorld(Eigen::Vector3d(m.u0 + i * m.cell, m.v0 + j * m.cell, m.wref + val));
      r->world_xyz.at<cv::Vec3f>(j, i) = cv::Vec3f(static_cast<float>(X.x()), static_cast<float>(X.y()), static_cast<float>(X.z()));
      area += m.cell * m.cell * stretch.at<float>(j, i);
    }
  r->fused_area = area;
}

SiteResult measureSite(const FusedMap& m, const induration::IndurationOptions& options, const std::vector<SiteFrame>& frames) {
  SiteResult r;
  r.surface = m.surface;
  r.cell = m.cell;
  r.u0 = m.u0;
  r.v0 = m.v0;
  r.sigma = m.sigma.clone();
  r.frames = m.frames.clone();
  const int W = m.value.cols, H = m.value.rows;
  const double uc = m.u0 + 0.5 * (W - 1) * m.cell, vc = m.v0 + 0.5 * (H - 1) * m.cell;
  induration::IndurationOptions o = options;
  o.max_incidence_deg = 90;  // the fusion kept only what was seen within site_max_incidence_deg
  cv::Mat exclude;
  BodyModel bm;
  cv::Mat h(H, W, CV_32F), stretch(H, W, CV_32F);
  for (int pass = 0; pass < 2; ++pass) {
    bm = fitBodyModel(m, exclude);
    geometry::DenseCloud flat;
    flat.xyz.create(H, W, CV_32FC3);
    flat.sigma = m.sigma.clone();
    flat.ray.create(H, W, CV_32FC3);
    for (int j = 0; j < H; ++j)
      for (int i = 0; i < W; ++i) {
        const double u = m.u0 + i * m.cell, v = m.v0 + j * m.cell;
        double du, dv;
        const double mv = bm.eval(m.surface, u, v, &du, &dv);
        double k, st;
        if (m.surface.model == "cylinder") {
          const double rr = m.wref + mv, R = m.surface.radius, dth = dv * R;  // dw / dtheta
          k = std::sqrt(1 + (dth / rr) * (dth / rr) + du * du);
          st = std::sqrt(rr * rr + dth * dth + du * du * rr * rr) / R;
        } else {
          k = std::sqrt(1 + du * du + dv * dv);
          st = k;
        }
        stretch.at<float>(j, i) = static_cast<float>(st);
        const double val = m.value.at<double>(j, i);
        const double hh = std::isfinite(val) ? (val - mv) / k : kNaN;
        h.at<float>(j, i) = static_cast<float>(hh);
        const double x = u - uc, y = v - vc;
        const Eigen::Vector3d ray = Eigen::Vector3d(x, y, kFlatDistance).normalized();
        flat.ray.at<cv::Vec3f>(j, i) = cv::Vec3f(static_cast<float>(ray.x()), static_cast<float>(ray.y()), static_cast<float>(ray.z()));
        const double z = kFlatDistance - hh;
        flat.xyz.at<cv::Vec3f>(j, i) = std::isfinite(hh) ? cv::Vec3f(static_cast<float>(x * z / kFlatDistance),
                                                                    static_cast<float>(y * z / kFlatDistance), static_cast<float>(z))
                                                        : cv::Vec3f(NAN, NAN, NAN);
      }
    r.flat = induration::measureInduration(flat, o);
    if (r.flat.labels.empty()) break;
    exclude = r.flat.labels > 0;
    if (options.exclusion_margin_px > 0) {
      const int k = 2 * options.exclusion_margin_px + 1;
      cv::dilate(exclude, exclude, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(k, k)));
    }
  }
  r.body_model = bm.name;
  r.body_rms = bm.rms;
  r.height = r.flat.reference_ok && !r.flat.height_map.empty() ? r.flat.height_map.clone() : h;
  r.labels = r.flat.labels.empty() ? cv::Mat(H, W, CV_32S, cv::Scalar(0)) : r.flat.labels.clone();
  r.warnings = r.flat.warnings;
  worldPoints(m, stretch, &r);
  // plaques in world
  for (const induration::Plaque& p : r.flat.plaques) {
    SitePlaque s;
    s.id = p.id;
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    double st = 0, uu = 0, vv = 0;
    int n = 0, known = 0;
    const cv::Rect box = p.bbox & cv::Rect(0, 0, W, H);  // the plaque's labels lie in its box
    for (int j = box.y; j < box.y + box.height; ++j)
      for (int i = box.x; i < box.x + box.width; ++i) {
        if (r.labels.at<int>(j, i) != p.id) continue;
        st += stretch.at<float>(j, i);
        uu += i;
        vv += j;
        ++n;
        const cv::Vec3f& X = r.world_xyz.at<cv::Vec3f>(j, i);
        if (std::isfinite(X[0])) {
          c += Eigen::Vector3d(X[0], X[1], X[2]);
          ++known;
        }
      }
    if (n == 0) continue;
    s.centroid = known > 0 ? Eigen::Vector3d(c / known) : Eigen::Vector3d::Zero();
    const double factor = st / n;
    s.top_height = p.top_height;
    s.top_height_sigma = p.top_height_sigma;
    s.mean_height = p.mean_height;
    s.max_height = p.max_height;
    s.area = p.area * factor;
    s.volume = p.volume * factor;
    s.pasi_class = p.pasi_class;
    s.measured_share = p.measured_fraction;
    // the views: frames whose own measurement found a plaque there; the best incidence any frame had on it
    const double reach = std::max(3e-3, std::sqrt(s.area / M_PI));
    const double u = m.u0 + uu / n * m.cell, v = m.v0 + vv / n * m.cell;
    double du, dv;
    const double mv = bm.eval(m.surface, u, v, &du, &dv);
    const Eigen::Vector3d base(u, v, m.wref + mv);
    const Eigen::Vector3d out = m.surface.outward(base);
    Eigen::Vector3d tu, tv;
    m.surface.tangents(base, &tu, &tv);
    Eigen::Vector3d nrm = (tu + du * out).cross(tv + dv * out).normalized();
    if (nrm.dot(out) < 0) nrm = -nrm;
    for (const SiteFrame& f : frames) {
      if (!f.fused) continue;
      const Eigen::Vector3d cl = f.pose.translation();
      double inc = std::acos(std::min(1.0, nrm.dot((cl - s.centroid).normalized()))) * 180 / M_PI;
      if (f.right_centre.allFinite())
        inc = std::max(inc, std::acos(std::min(1.0, nrm.dot((f.pose * f.right_centre - s.centroid).normalized()))) * 180 / M_PI);
      s.best_incidence_deg = std::min(s.best_incidence_deg, inc);
      s.frames_within_45 += inc <= 45;
      double best = 1e9, top = 0;
      for (const induration::Plaque& q : f.plaques) {
        const double d = (f.pose * q.centroid - s.centroid).norm();
        if (d < best) {
          best = d;
          top = q.top_height;
        }
      }
      if (best <= reach) s.view_tops.push_back(top);
    }
    s.views = static_cast<int>(s.view_tops.size());
    if (s.views >= 2) {
      double mean = 0, v2 = 0;
      for (double t : s.view_tops) mean += t / s.views;
      for (double t : s.view_tops) v2 += (t - mean) * (t - mean);
      s.spread = std::sqrt(v2 / (s.views - 1));
    }
    if (s.best_incidence_deg > kUsableIncidence) {
      char buf[256];
      std::snprintf(buf, sizeof(buf), "a raised region of %.1f mm^2 reading %.3f mm at (%.1f, %.1f, %.1f) mm was never seen within "
                    "%.0f deg (best %.0f deg): listed apart, not as a plaque", s.area * 1e6, s.top_height * 1e3,
                    s.centroid.x() * 1e3, s.centroid.y() * 1e3, s.centroid.z() * 1e3, kUsableIncidence, s.best_incidence_deg);
      r.warnings.push_back(buf);
      r.grazing.push_back(s);
    } else {
      r.plaques.push_back(s);
    }
  }
  return r;
}

}  // namespace site_detail
}  // namespace site
}  // namespace skin3d
