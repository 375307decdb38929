// SPDX-License-Identifier: BSD-3-Clause
// YAML input/output and the printed table of the stereo design calculator.
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <fstream>
#include <iomanip>
#include <map>
#include <set>
#include <sstream>

#include "../common/yaml_section.h"
#include "skin3d/geometry/design.h"
#include "skin3d/geometry/quaternion.h"

namespace skin3d {
namespace geometry {

namespace {

constexpr double kDeg = M_PI / 180.0;

using Section = common::YamlSection<DesignConfigError>;

std::string fmt(double v, int prec = 3) {
  if (std::isinf(v)) return "inf";
  std::ostringstream os;
  os << std::fixed << std::setprecision(prec) << v;
  return os.str();
}

void emitVec(YAML::Emitter& e, const Eigen::VectorXd& v) {
  e << YAML::Flow << YAML::BeginSeq;
  for (int i = 0; i < v.size(); ++i) e << v[i];
  e << YAML::EndSeq;
}

void emitPoly(YAML::Emitter& e, const std::vector<Eigen::Vector2d>& poly) {
  e << YAML::BeginSeq;
  for (const auto& p : poly) emitVec(e, p);
  e << YAML::EndSeq;
}

void emitCurve(YAML::Emitter& e, const std::vector<std::pair<double, double>>& c) {
  e << YAML::BeginSeq;
  for (const auto& p : c) emitVec(e, Eigen::Vector2d(p.first, p.second));
  e << YAML::EndSeq;
}

double yamlNumber(double v) { return std::isinf(v) ? std::numeric_limits<double>::infinity() : v; }

}  // namespace

DesignConfig parseDesignConfig(const std::string& yaml_text, const std::string& source) {
  YAML::Node root;
  try {
    root = YAML::Load(yaml_text);
  } catch (const YAML::ParserException& e) {
    throw DesignConfigError("(file)", "cannot parse " + source + " as YAML: line " + std::to_string(e.mark.line + 1) +
                                          ", column " + std::to_string(e.mark.column + 1) + ": " + e.msg);
  }
  if (!root || root.IsNull()) throw DesignConfigError("(file)", source + " is empty");
  if (!root.IsMap()) throw DesignConfigError("(file)", source + ": the top level must be a mapping with sections "
                                                                "sensor, lens, geometry, requirement");
  DesignConfig c;
  Section top(root, "", {"name", "sensor", "lens", "geometry", "requirement", "analysis"});
  c.name = top.text("name", source);

  Section sensor = top.sub("sensor", true, {"width_px", "height_px", "pixel_size_um", "width_mm", "height_mm"});
  c.width_px = sensor.integer("width_px", true);
  c.height_px = sensor.integer("height_px", true);
  c.pixel_size_mm = sensor.number("pixel_size_um", true) / 1000.0;
  c.sensor_width_mm = sensor.number("width_mm", false);
  c.sensor_height_mm = sensor.number("height_mm", false);

  Section lens = top.sub("lens", true, {"focal_length_mm", "f_number", "circle_of_confusion_mm"});
  c.focal_length_mm = lens.number("focal_length_mm", true);
  c.f_number = lens.number("f_number", true);
  c.coc_mm = lens.number("circle_of_confusion_mm", false);

  Section geo = top.sub("geometry", true, {"baseline_mm", "convergence_deg", "left_rotation_deg", "right_rotation_deg",
                                        "working_distance_mm"});
  const auto b = geo.list("baseline_mm", 3, true);
  c.baseline_mm = Eigen::Vector3d(b[0], b[1], b[2]);
  const bool has_conv = geo.has("convergence_deg");
  c.convergence_deg = geo.number("convergence_deg", false, 0.0);
  const auto rl = geo.list("left_rotation_deg", 3, false);
  const auto rr = geo.list("right_rotation_deg", 3, false);
  if (rl.empty() != rr.empty())
    Section::fail(geo.field(rl.empty() ? "left_rotation_deg" : "right_rotation_deg"),
         "missing: give both per-camera rotations, or neither");
  if (!rl.empty()) {
    if (has_conv) Section::fail(geo.field("convergence_deg"), "give either convergence_deg or the two per-camera rotations, not both");
    c.per_camera_rotation = true;
    c.left_rotation_deg = Eigen::Vector3d(rl[0], rl[1], rl[2]);
    c.right_rotation_deg = Eigen::Vector3d(rr[0], rr[1], rr[2]);
  }
  c.working_distance_mm = geo.number("working_distance_mm", false);

  Section req = top.sub("requirement", true, {"depth_resolution_mm", "object_size_mm"});
  c.depth_resolution_mm = req.number("depth_resolution_mm", true);
  c.object_size_mm = req.number("object_size_mm", true);

  Section an = top.sub("analysis", false, {"grid", "pixel_sigma_px"});
  const auto grid = an.list("grid", 2, false);
  if (!grid.empty()) {
    for (double g : grid)
      if (std::floor(g) != g) Section::fail(an.field("grid"), "must be two whole numbers [nx, ny]");
    c.grid_nx = static_cast<int>(grid[0]);
    c.grid_ny = static_cast<int>(grid[1]);
  }
  c.pixel_sigma_px = an.number("pixel_sigma_px", false, c.pixel_sigma_px);

  validateDesignConfig(c);
  return c;
}

DesignConfig loadDesignConfig(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw DesignConfigError("--config", "cannot read design config '" + path + "'");
  std::stringstream ss;
  ss << in.rdbuf();
  return parseDesignConfig(ss.str(), path);
}

std::string designReportYaml(const DesignReport& r) {
  const DesignConfig& c = r.config;
  YAML::Emitter e;
  e.SetDoublePrecision(9);
  e << YAML::Comment("skin3d stereo design report. Lengths in mm, angles in degrees, areas in mm^2.");
  e << YAML::BeginMap;
  e << YAML::Key << "name" << YAML::Value << c.name;
  e << YAML::Key << "input" << YAML::Value << YAML::BeginMap;
  e << YAML::Key << "width_px" << YAML::Value << c.width_px << YAML::Key << "height_px" << YAML::Value << c.height_px;
  e << YAML::Key << "pixel_size_um" << YAML::Value << c.pixel_size_mm * 1000.0;
  e << YAML::Key << "focal_length_mm" << YAML::Value << c.focal_length_mm;
  e << YAML::Key << "f_number" << YAML::Value << c.f_number;
  e << YAML::Key << "circle_of_confusion_mm" << YAML::Value << c.coc_mm;
  e << YAML::Key << "baseline_mm" << YAML::Value;
  emitVec(e, c.baseline_mm);
  e << YAML::Key << "depth_resolution_mm" << YAML::Value << c.depth_resolution_mm;
  e << YAML::Key << "object_size_mm" << YAML::Value << c.object_size_mm;
  e << YAML::Key << "pixel_sigma_px" << YAML::Value << c.pixel_sigma_px;
  e << YAML::EndMap;

  e << YAML::Key << "sensor" << YAML::Value << YAML::BeginMap;
  e << YAML::Key << "width_mm" << YAML::Value << r.sensor_width_mm;
  e << YAML::Key << "height_mm" << YAML::Value << r.sensor_height_mm;
  e << YAML::Key << "diagonal_mm" << YAML::Value << r.sensor_diagonal_mm;
  e << YAML::Key << "megapixels" << YAML::Value << r.megapixels;
  e << YAML::Key << "focal_length_px" << YAML::Value << r.focal_length_px;
  e << YAML::EndMap;

  e << YAML::Key << "angle_of_view_deg" << YAML::Value << YAML::BeginMap;
  e << YAML::Key << "horizontal" << YAML::Value << r.aov_h_deg << YAML::Key << "vertical" << YAML::Value << r.aov_v_deg
    << YAML::Key << "diagonal" << YAML::Value << r.aov_d_deg << YAML::EndMap;

  e << YAML::Key << "field_of_view_mm" << YAML::Value << YAML::BeginMap;
  e << YAML::Key << "at_distance_mm" << YAML::Value << r.working_distance_mm;
  e << YAML::Key << "horizontal" << YAML::Value << r.fov_w_mm << YAML::Key << "vertical" << YAML::Value << r.fov_h_mm
    << YAML::Key << "diagonal" << YAML::Value << r.fov_d_mm << YAML::EndMap;

  e << YAML::Key << "depth_of_field" << YAML::Value << YAML::BeginMap;
  e << YAML::Key << "hyperfocal_mm" << YAML::Value << r.hyperfocal_mm;
  e << YAML::Key << "near_mm" << YAML::Value << r.near_mm;
  e << YAML::Key << "far_mm" << YAML::Value << yamlNumber(r.far_mm);
  e << YAML::Key << "total_mm" << YAML::Value << yamlNumber(r.depth_of_field_mm);
  e << YAML::EndMap;

  e << YAML::Key << "stereo" << YAML::Value << YAML::BeginMap;
  e << YAML::Key << "baseline_mm" << YAML::Value << r.baseline_mm;
  e << YAML::Key << "working_distance_mm" << YAML::Value << r.working_distance_mm;
  e << YAML::Key << "optimum_working_distance_mm" << YAML::Value << r.optimum_working_distance_mm;
  e << YAML::Key << "depth_resolution_mm_per_px" << YAML::Value << r.depth_resolution_mm;
  e << YAML::Key << "requirement_met" << YAML::Value << (r.depth_resolution_mm <= c.depth_resolution_mm);
  e << YAML::Key << "min_baseline_mm" << YAML::Value << r.min_baseline_mm;
  e << YAML::Key << "min_baseline_at_working_distance_mm" << YAML::Value << r.min_baseline_at_working_distance_mm;
  e << YAML::Key << "recommended_convergence_deg" << YAML::Value << r.recommended_convergence_deg;
  e << YAML::Key << "optical_axes_angle_deg" << YAML::Value << r.optical_axes_angle_deg;
  e << YAML::EndMap;

  e << YAML::Key << "cameras" << YAML::Value << YAML::BeginMap;
  const auto cam = [&](const char* name, const Eigen::Matrix3d& R, const Eigen::Vector3d& centre,
                       const std::vector<Eigen::Vector2d>& fp, double area) {
    e << YAML::Key << name << YAML::Value << YAML::BeginMap;
    e << YAML::Key << "centre_mm" << YAML::Value;
    emitVec(e, centre);
    e << YAML::Key << "rotation_vector_deg" << YAML::Value;
    emitVec(e, Eigen::Vector3d(so3Log(R) / kDeg));
    e << YAML::Key << "footprint_mm" << YAML::Value;
    emitPoly(e, fp);
    e << YAML::Key << "footprint_area_mm2" << YAML::Value << area;
    e << YAML::EndMap;
  };
  cam("left", r.R_rig_left, r.c_left, r.footprint_left, r.footprint_left_area_mm2);
  cam("right", r.R_rig_right, r.c_right, r.footprint_right, r.footprint_right_area_mm2);
  e << YAML::EndMap;

  e << YAML::Key << "overlap" << YAML::Value << YAML::BeginMap;
  e << YAML::Key << "area_mm2" << YAML::Value << r.overlap_area_mm2;
  e << YAML::Key << "fraction_of_left_view" << YAML::Value << r.overlap_fraction;
  e << YAML::Key << "extent_x_mm" << YAML::Value;
  emitVec(e, Eigen::Vector2d(r.overlap_min.x(), r.overlap_max.x()));
  e << YAML::Key << "extent_y_mm" << YAML::Value;
  emitVec(e, Eigen::Vector2d(r.overlap_min.y(), r.overlap_max.y()));
  e << YAML::Key << "polygon_mm" << YAML::Value;
  emitPoly(e, r.overlap);
  e << YAML::EndMap;

  e << YAML::Key << "uncertainty" << YAML::Value << YAML::BeginMap;
  e << YAML::Key << "pixel_sigma_px" << YAML::Value << c.pixel_sigma_px;
  e << YAML::Key << "points" << YAML::Value << r.grid.size();
  e << YAML::Key << "max_axis_mm" << YAML::Value << r.max_axis_mm;
  e << YAML::Key << "mean_depth_sigma_mm" << YAML::Value << r.mean_depth_sigma_mm;
  e << YAML::Key << "max_depth_sigma_mm" << YAML::Value << r.max_depth_sigma_mm;
  e << YAML::Key << "grid" << YAML::Value << YAML::BeginSeq;
  for (const auto& g : r.grid) {
    e << YAML::BeginMap;
    e << YAML::Key << "point_mm" << YAML::Value;
    emitVec(e, g.X);
    e << YAML::Key << "uv_left" << YAML::Value;
    emitVec(e, g.uv_left);
    e << YAML::Key << "uv_right" << YAML::Value;
    emitVec(e, g.uv_right);
    e << YAML::Key << "axes_mm" << YAML::Value;
    emitVec(e, g.axes);
    e << YAML::Key << "axis_directions" << YAML::Value << YAML::Flow << YAML::BeginSeq;
    for (int k = 0; k < 3; ++k) emitVec(e, g.axis_dirs.col(k));
    e << YAML::EndSeq;
    e << YAML::Key << "covariance_mm2" << YAML::Value;
    emitVec(e, Eigen::Map<const Eigen::Matrix<double, 9, 1>>(g.cov.data()));
    e << YAML::Key << "sigma_depth_mm" << YAML::Value << g.sigma_depth;
    e << YAML::EndMap;
  }
  e << YAML::EndSeq << YAML::EndMap;

  e << YAML::Key << "curves" << YAML::Value << YAML::BeginMap;
  e << YAML::Key << "resolution_vs_baseline_mm" << YAML::Value;
  emitCurve(e, r.resolution_vs_baseline);
  e << YAML::Key << "resolution_vs_distance_mm" << YAML::Value;
  emitCurve(e, r.resolution_vs_distance);
  e << YAML::EndMap;
  e << YAML::EndMap;
  return std::string(e.c_str()) + "\n";
}

std::string designReportTable(const DesignReport& r) {
  std::ostringstream os;
  const auto row = [&](const std::string& name, const std::string& value, const std::string& unit) {
    os << "  " << std::left << std::setw(46) << name << std::right << std::setw(14) << value << "  " << unit << "\n";
  };
  os << "Stereo design: " << r.config.name << "\n";
  os << "Image sensor\n";
  row("resolution", std::to_string(r.config.width_px) + "x" + std::to_string(r.config.height_px), "px");
  row("pixel size", fmt(r.config.pixel_size_mm * 1000.0, 3), "um");
  row("sensor width x height", fmt(r.sensor_width_mm) + "x" + fmt(r.sensor_height_mm), "mm");
  row("sensor diagonal", fmt(r.sensor_diagonal_mm), "mm");
  row("focal length", fmt(r.config.focal_length_mm) + " = " + fmt(r.focal_length_px, 1), "mm = px");
  os << "Lens (angle of view)\n";
  row("horizontal / vertical / diagonal", fmt(r.aov_h_deg, 2) + " / " + fmt(r.aov_v_deg, 2) + " / " + fmt(r.aov_d_deg, 2), "deg");
  os << "Field of view at the working distance " << fmt(r.working_distance_mm) << " mm\n";
  row("horizontal / vertical / diagonal", fmt(r.fov_w_mm, 1) + " / " + fmt(r.fov_h_mm, 1) + " / " + fmt(r.fov_d_mm, 1), "mm");
  os << "Depth of field (f/" << fmt(r.config.f_number, 1) << ", circle of confusion " << fmt(r.config.coc_mm, 4) << " mm)\n";
  row("hyperfocal distance", fmt(r.hyperfocal_mm, 1), "mm");
  row("near / far limit", fmt(r.near_mm, 1) + " / " + fmt(r.far_mm, 1), "mm");
  row("depth of field", fmt(r.depth_of_field_mm, 1), "mm");
  os << "Stereo geometry\n";
  row("baseline |b|", fmt(r.baseline_mm), "mm");
  row("working distance", fmt(r.working_distance_mm), "mm");
  row("optimum working distance (eq. 2.26)", fmt(r.optimum_working_distance_mm), "mm");
  row("depth resolution at working distance (2.25)", fmt(r.depth_resolution_mm, 4), "mm/px");
  row("required depth resolution", fmt(r.config.depth_resolution_mm, 4) +
      (r.depth_resolution_mm <= r.config.depth_resolution_mm ? " (met)" : " (NOT met)"), "mm");
  row("minimum baseline (eq. 2.27)", fmt(r.min_baseline_mm), "mm");
  row("minimum baseline at working distance", fmt(r.min_baseline_at_working_distance_mm), "mm");
  row("recommended convergence (eq. 2.24)", fmt(r.recommended_convergence_deg, 2), "deg");
  row("angle between optical axes (configured)", fmt(r.optical_axes_angle_deg, 2), "deg");
  os << "Fields of view on the working plane\n";
  row("left camera area", fmt(r.footprint_left_area_mm2, 0), "mm^2");
  row("right camera area", fmt(r.footprint_right_area_mm2, 0), "mm^2");
  row("overlap area", fmt(r.overlap_area_mm2, 0), "mm^2");
  row("overlap / left view", fmt(100.0 * r.overlap_fraction, 1), "%");
  row("overlap extent x", fmt(r.overlap_min.x(), 1) + " .. " + fmt(r.overlap_max.x(), 1), "mm");
  row("overlap extent y", fmt(r.overlap_min.y(), 1) + " .. " + fmt(r.overlap_max.y(), 1), "mm");
  os << "Reconstruction uncertainty (MMSE, " << fmt(r.config.pixel_sigma_px, 2) << " px, " << r.grid.size()
     << " grid points)\n";
  row("largest 1-sigma ellipsoid axis", fmt(r.max_axis_mm, 4), "mm");
  row("depth 1-sigma mean / max", fmt(r.mean_depth_sigma_mm, 4) + " / " + fmt(r.max_depth_sigma_mm, 4), "mm");
  return os.str();
}

}  // namespace geometry
}  // namespace skin3d
