// SPDX-License-Identifier: BSD-3-Clause
// The site's results (docs/results.md "Site"): site.yaml, site_height_map.png, site_coverage.png, site_surface.ply.
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "skin3d/induration/induration_io.h"
#include "site_detail.h"

namespace skin3d {
namespace site {

namespace {

void vec(YAML::Emitter& y, const Eigen::Vector3d& v, double scale = 1.0) {
  y << YAML::Flow << YAML::BeginSeq << scale * v.x() << scale * v.y() << scale * v.z() << YAML::EndSeq;
}
void num(YAML::Emitter& y, double v) {
  if (std::isfinite(v)) y << v;
  else y << YAML::Null;
}

void writePly(const std::string& path, const SiteResult& r) {
  std::vector<std::pair<int, int>> cells;
  for (int j = 0; j < r.world_xyz.rows; ++j)
    for (int i = 0; i < r.world_xyz.cols; ++i)
      if (std::isfinite(r.world_xyz.at<cv::Vec3f>(j, i)[0])) cells.emplace_back(i, j);
  std::ofstream f(path, std::ios::binary);
  if (!f) throw std::runtime_error("cannot write " + path);
  f << "ply\nformat binary_little_endian 1.0\ncomment skin3d site surface, frame world, metres\n"
    << "element vertex " << cells.size()
    << "\nproperty float x\nproperty float y\nproperty float z\nproperty float height\nproperty float sigma\n"
       "property uchar frames\nend_header\n";
  for (const auto& c : cells) {
    const cv::Vec3f& X = r.world_xyz.at<cv::Vec3f>(c.second, c.first);
    const float v[5] = {X[0], X[1], X[2], r.height.at<float>(c.second, c.first), r.sigma.at<float>(c.second, c.first)};
    f.write(reinterpret_cast<const char*>(v), sizeof(v));
    const std::uint8_t n = r.frames.at<std::uint8_t>(c.second, c.first);
    f.write(reinterpret_cast<const char*>(&n), 1);
  }
  if (!f) throw std::runtime_error("cannot write " + path);
}

}  // namespace

/** Frames per cell in false colour (0 = dark grey), with a legend. */
cv::Mat coverageImage(const cv::Mat& frames, int max_width) {
  double mx = 1;
  cv::minMaxLoc(frames, nullptr, &mx);
  mx = std::max(1.0, mx);
  cv::Mat scaled;
  frames.convertTo(scaled, CV_8U, 255.0 / mx);
  cv::Mat colour;
  cv::applyColorMap(scaled, colour, cv::COLORMAP_VIRIDIS);
  colour.setTo(cv::Scalar(40, 40, 40), frames == 0);
  if (colour.cols > max_width) cv::resize(colour, colour, cv::Size(), max_width / static_cast<double>(colour.cols),
                                          max_width / static_cast<double>(colour.cols), cv::INTER_AREA);
  cv::Mat out(colour.rows + 40, colour.cols, CV_8UC3, cv::Scalar(255, 255, 255));
  colour.copyTo(out(cv::Rect(0, 0, colour.cols, colour.rows)));
  cv::putText(out, "frames fused per cell: dark grey 0 ... yellow " + std::to_string(static_cast<int>(mx)),
              cv::Point(8, colour.rows + 28), cv::FONT_HERSHEY_SIMPLEX, 0.7, cv::Scalar(0, 0, 0), 2);
  return out;
}

void writeSiteResults(const std::string& dir, const SiteResult& r, const std::vector<SiteFrame>& frames,
                      const std::string& source, const std::vector<std::string>& command_line, const std::string& frame) {
  std::filesystem::create_directories(dir);
  YAML::Emitter y;
  y << YAML::BeginMap;
  y << YAML::Key << "frame" << YAML::Value << frame;
  y << YAML::Key << "source" << YAML::Value << source;
  y << YAML::Key << "command_line" << YAML::Value << YAML::Flow << command_line;
  y << YAML::Key << "surface" << YAML::Value << YAML::BeginMap;
  y << YAML::Key << "model" << YAML::Value << r.surface.model;
  y << YAML::Key << "origin_m" << YAML::Value;
  vec(y, r.surface.origin);
  y << YAML::Key << (r.surface.model == "cylinder" ? "axis" : "normal") << YAML::Value;
  vec(y, r.surface.axis);
  if (r.surface.model == "cylinder") y << YAML::Key << "radius_mm" << YAML::Value << r.surface.radius * 1e3;
  y << YAML::Key << "cell_um" << YAML::Value << r.cell * 1e6;
  y << YAML::Key << "fused_area_mm2" << YAML::Value << r.fused_area * 1e6;
  y << YAML::EndMap;
  y << YAML::Key << "reference" << YAML::Value << YAML::BeginMap;
  y << YAML::Key << "body_model" << YAML::Value << r.body_model;
  y << YAML::Key << "body_scatter_um" << YAML::Value;
  num(y, r.body_rms * 1e6);
  y << YAML::Key << "unrolled_model" << YAML::Value << r.flat.reference.model;
  y << YAML::Key << "unrolled_rms_um" << YAML::Value;
  num(y, r.flat.reference.rms * 1e6);
  y << YAML::Key << "detection_threshold_mm" << YAML::Value << r.flat.detection_threshold * 1e3;
  y << YAML::Key << "follows_skin" << YAML::Value << r.flat.reference_follows;
  y << YAML::EndMap;
  y << YAML::Key << "seams" << YAML::Value << YAML::BeginMap << YAML::Key << "rms_um" << YAML::Value;
  num(y, r.seam_rms * 1e6);
  y << YAML::Key << "noise_um" << YAML::Value;
  num(y, r.seam_noise * 1e6);
  y << YAML::Key << "beyond_noise_um" << YAML::Value;
  num(y, r.seam_excess * 1e6);
  y << YAML::Key << "rigid_um" << YAML::Value;
  num(y, r.seam_rigid * 1e6);
  y << YAML::EndMap;
  {
    const SitePoseGraph& g = r.pose_graph;
    y << YAML::Key << "pose_graph" << YAML::Value << YAML::BeginMap << YAML::Key << "run" << YAML::Value << g.run;
    if (g.run) {
      y << YAML::Key << "used" << YAML::Value << g.used << YAML::Key << "frames" << YAML::Value << g.frames;
      y << YAML::Key << "pairs" << YAML::Value << g.pairs << YAML::Key << "block_comparisons" << YAML::Value << g.blocks;
      y << YAML::Key << "rms_before_um" << YAML::Value;
      num(y, g.rms_before * 1e6);
      y << YAML::Key << "rms_after_um" << YAML::Value;
      num(y, g.rms_after * 1e6);
      y << YAML::Key << "passes" << YAML::Value << g.passes << YAML::Key << "iterations" << YAML::Value << g.iterations;
      y << YAML::Key << "converged" << YAML::Value << g.converged;
      y << YAML::Key << "seconds" << YAML::Value << g.seconds << YAML::Key << "solver" << YAML::Value << g.message;
    }
    y << YAML::EndMap;
  }
  y << YAML::Key << "seconds_measure" << YAML::Value << r.seconds_measure;
  y << YAML::Key << "frames_fused" << YAML::Value << r.frames_fused;
  y << YAML::Key << "frames_left_out" << YAML::Value << r.frames_left_out;
  for (const auto* list : {&r.plaques, &r.grazing}) {
    y << YAML::Key << (list == &r.plaques ? "plaques" : "seen_only_at_grazing_angles") << YAML::Value << YAML::BeginSeq;
    for (const SitePlaque& p : *list) {
      y << YAML::BeginMap;
      y << YAML::Key << "id" << YAML::Value << p.id;
      y << YAML::Key << "centroid_m" << YAML::Value;
      vec(y, p.centroid);
      y << YAML::Key << "top_height_mm" << YAML::Value << p.top_height * 1e3;
      y << YAML::Key << "top_height_sigma_mm" << YAML::Value << p.top_height_sigma * 1e3;
      y << YAML::Key << "mean_height_mm" << YAML::Value << p.mean_height * 1e3;
      y << YAML::Key << "area_mm2" << YAML::Value << p.area * 1e6;
      y << YAML::Key << "volume_mm3" << YAML::Value << p.volume * 1e9;
      y << YAML::Key << "pasi" << YAML::Value << p.pasi_class;
      y << YAML::Key << "views" << YAML::Value << p.views;
      y << YAML::Key << "view_top_heights_mm" << YAML::Value << YAML::Flow << YAML::BeginSeq;
      for (double t : p.view_tops) y << t * 1e3;
      y << YAML::EndSeq;
      y << YAML::Key << "best_incidence_deg" << YAML::Value << p.best_incidence_deg;
      y << YAML::Key << "frames_within_45_deg" << YAML::Value << p.frames_within_45;
      y << YAML::Key << "measured_share" << YAML::Value << p.measured_share;
      y << YAML::Key << "spread_um" << YAML::Value << p.spread * 1e6;
      y << YAML::EndMap;
    }
    y << YAML::EndSeq;
  }
  y << YAML::Key << "frames" << YAML::Value << YAML::BeginSeq;
  for (const SiteFrame& f : frames) {
    y << YAML::Flow << YAML::BeginMap;
    y << YAML::Key << "index" << YAML::Value << f.index << YAML::Key << "stamp" << YAML::Value << f.stamp;
    y << YAML::Key << "fused" << YAML::Value << f.fused;
    if (!f.fused) y << YAML::Key << "left_out" << YAML::Value << f.reason;
    y << YAML::Key << "samples" << YAML::Value << f.samples;
    y << YAML::Key << "overlap" << YAML::Value << f.overlap;
    y << YAML::Key << "seam_rms_um" << YAML::Value;
    num(y, f.seam_rms * 1e6);
    y << YAML::Key << "seam_beyond_noise_um" << YAML::Value;
    num(y, f.seam_excess * 1e6);
    y << YAML::Key << "seam_rigid_um" << YAML::Value;
    num(y, f.seam_rigid * 1e6);
    y << YAML::Key << "seconds" << YAML::Value << YAML::Flow << YAML::BeginMap << YAML::Key << "register" << YAML::Value
      << f.seconds_register << YAML::Key << "fuse" << YAML::Value << f.seconds_fuse << YAML::EndMap;
    y << YAML::Key << "registration_correction_mm" << YAML::Value << f.correction_rms * 1e3;
    y << YAML::Key << "plaques_own" << YAML::Value << static_cast<int>(f.plaques.size());
    if (f.fused) {  // where the pair was placed: world <- its left optical frame, after the registration
      const Eigen::Quaterniond q(f.pose.linear());
      y << YAML::Key << "translation_m" << YAML::Value << YAML::Flow << YAML::BeginSeq << f.pose.translation().x()
        << f.pose.translation().y() << f.pose.translation().z() << YAML::EndSeq;
      y << YAML::Key << "quaternion_wxyz" << YAML::Value << YAML::Flow << YAML::BeginSeq << q.w() << q.x() << q.y() << q.z()
        << YAML::EndSeq;
    }
    y << YAML::EndMap;
  }
  y << YAML::EndSeq;
  y << YAML::Key << "warnings" << YAML::Value << YAML::BeginSeq;
  for (const auto& w : r.warnings) y << w;
  y << YAML::EndSeq;
  y << YAML::EndMap;
  const std::string yaml = dir + "/site.yaml";
  std::ofstream f(yaml);
  f << y.c_str() << "\n";
  if (!f) throw std::runtime_error("cannot write " + yaml);
  if (!r.height.empty()) {
    const std::string png = dir + "/site_height_map.png";
    // the picture outlines the site's plaques; regions never seen within 45 deg are listed in site.yaml, not drawn
    std::vector<induration::Plaque> shown;
    cv::Mat labels = r.labels.clone();
    for (const auto& p : r.flat.plaques) {
      const bool kept = std::any_of(r.plaques.begin(), r.plaques.end(), [&](const SitePlaque& q) { return q.id == p.id; });
      if (kept) shown.push_back(p);
      else labels.setTo(0, r.labels == p.id);
    }
    if (!cv::imwrite(png, induration::heightMapImage(r.height, labels, shown, 0.0, 1600, r.flat.unfollowed)))
      throw std::runtime_error("cannot write " + png);
    const std::string cov = dir + "/site_coverage.png";
    if (!cv::imwrite(cov, coverageImage(r.frames))) throw std::runtime_error("cannot write " + cov);
    const std::string tif = dir + "/site_height_map.tiff";
    if (!cv::imwrite(tif, r.height)) throw std::runtime_error("cannot write " + tif);
    writePly(dir + "/site_surface.ply", r);
  }
}

}  // namespace site
}  // namespace skin3d
