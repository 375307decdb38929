// SPDX-License-Identifier: BSD-3-Clause
#include <Eigen/LU>
#include <cmath>
#include <random>
#include <sstream>

#include "../common/yaml_section.h"
#include "../common/text.h"
#include "skin3d/geometry/quaternion.h"
#include "skin3d/sim/dataset.h"

namespace skin3d {
namespace sim {

namespace {

using Section = common::YamlSection<SimConfigError>;
constexpr double kDeg = M_PI / 180.0;

using common::num;

[[noreturn]] void bad(const std::string& field, double value, const std::string& why) {
  throw SimConfigError(field, "field '" + field + "' = " + num(value) + ": " + why);
}

std::vector<Plateau> defaultPlateaus() {
  std::vector<Plateau> out;
  const double xs1[4] = {-0.0375, -0.0125, 0.0125, 0.0375}, xs2[3] = {-0.025, 0.0, 0.025};
  for (int i = 0; i < 7; ++i) {
    Plateau p;
    p.centre = i < 4 ? Eigen::Vector2d(xs1[i], -0.02) : Eigen::Vector2d(xs2[i - 4], 0.02);
    p.size = Eigen::Vector2d(0.015, 0.015);
    p.height = 0.0001 * (i + 1);
    out.push_back(p);
  }
  return out;
}

RigConfig partOneRig() {
  RigConfig r;
  r.focal_length = 2.94e-3;
  r.pixel_size = 1.12e-6;
  r.width = 4224;
  r.height = 3136;
  r.baseline = Eigen::Vector3d(0.210, 0.0, 0.0);
  r.convergence = 54.4 * kDeg;
  return r;
}

void readRig(const Section& s, RigConfig* r) {
  r->focal_length = s.number("focal_length_mm", false, r->focal_length * 1e3) * 1e-3;
  r->pixel_size = s.number("pixel_size_um", false, r->pixel_size * 1e6) * 1e-6;
  r->width = s.integer("width_px", false, r->width);
  r->height = s.integer("height_px", false, r->height);
  const auto b = s.list("baseline_mm", 3, false);
  if (!b.empty()) r->baseline = Eigen::Vector3d(b[0], b[1], b[2]) * 1e-3;
  r->convergence = s.number("convergence_deg", false, r->convergence / kDeg) * kDeg;
  if (s.has("distortion")) {
    r->distortion = s.list("distortion", 0, false);
    if (!r->distortion.empty() && r->distortion.size() != 5 && r->distortion.size() != 4)
      bad(s.field("distortion"), r->distortion.size(), "plumb_bob takes 4 or 5 coefficients (k1 k2 p1 p2 [k3])");
  }
}

void readPhotometry(const Section& s, RealismOptions* r) {
  r->gain = s.number("gain", false, r->gain);
  r->offset = s.number("offset", false, r->offset);
  r->gamma = s.number("gamma", false, r->gamma);
}

}  // namespace

DatasetKind parseDatasetKind(const std::string& name) {
  if (name == "globe-landmarks") return DatasetKind::GlobeLandmarks;
  if (name == "globe-images") return DatasetKind::GlobeImages;
  if (name == "workpiece") return DatasetKind::Workpiece;
  if (name == "skin") return DatasetKind::Skin;
  throw SimConfigError("kind", "unknown dataset kind '" + name + "'; known: globe-landmarks, globe-images, workpiece, skin");
}

std::string datasetKindName(DatasetKind kind) {
  switch (kind) {
    case DatasetKind::GlobeLandmarks:
      return "globe-landmarks";
    case DatasetKind::GlobeImages:
      return "globe-images";
    case DatasetKind::Workpiece:
      return "workpiece";
    case DatasetKind::Skin:
      return "skin";
  }
  return "?";
}

RigConfig scaleRig(const RigConfig& rig, double resolution_scale) {
  RigConfig r = rig;
  r.width = std::max(1, static_cast<int>(std::lround(rig.width * resolution_scale)));
  r.height = std::max(1, static_cast<int>(std::lround(rig.height * resolution_scale)));
  r.pixel_size = rig.pixel_size * rig.width / r.width;
  return r;
}

void WorkpieceConfig::validate() const {
  if (!(plate_size.x() > 0) || !(plate_size.y() > 0) || !plate_size.allFinite())
    bad("workpiece.plate_size_mm", plate_size.minCoeff() * 1e3, "both sides must be > 0");
  if (plateaus.empty()) throw SimConfigError("workpiece.plateaus", "field 'workpiece.plateaus': at least one plateau");
  for (size_t i = 0; i < plateaus.size(); ++i) {
    const auto& p = plateaus[i];
    const std::string f = "workpiece.plateaus[" + std::to_string(i) + "]";
    if (!(p.height > 0) || !std::isfinite(p.height) || p.height > 0.01)
      bad(f + ".height_mm", p.height * 1e3, "must be in (0, 10] mm");
    if (!(p.size.minCoeff() > 0) || !p.size.allFinite()) bad(f + ".size_mm", p.size.minCoeff() * 1e3, "must be > 0");
    const Eigen::Vector2d lo = p.centre - 0.5 * p.size, hi = p.centre + 0.5 * p.size;
    if ((lo.array() < -0.5 * plate_size.array()).any() || (hi.array() > 0.5 * plate_size.array()).any())
      bad(f + ".centre_mm", p.centre.x() * 1e3, "the plateau must lie on the plate");
  }
  if (!(working_distance > 0) || !std::isfinite(working_distance))
    bad("workpiece.working_distance_mm", working_distance * 1e3, "must be > 0");
  if (!std::isfinite(tilt) || std::abs(tilt) >= 60 * kDeg)
    bad("workpiece.tilt_deg", tilt / kDeg, "must be in (-60, 60)");
  if (!(resolution_scale > 0) || resolution_scale > 1)
    bad("workpiece.resolution_scale", resolution_scale, "must be in (0, 1]");
  if (frames < 1) bad("workpiece.frames", frames, "must be >= 1");
  if (!(fps > 0) || !std::isfinite(fps)) bad("workpiece.fps", fps, "must be > 0");
  if (!(texel > 0) || texel > 1e-3) bad("workpiece.texel_um", texel * 1e6, "must be in (0, 1000]");
  scaledRig().makeRig();
}

SkinGeometry SkinConfig::geometryFor(std::uint64_t seed, double* y, double* t, double* r) const {
  SkinGeometry g = geometry;
  *y = yaw;
  *t = tilt;
  *r = roll;
  if (random) {
    try {
      g = randomSkinGeometry(seed, plaque_count, dome_max, sweep.enabled ? sweep.plaque_span : 55.0 * kDeg);
    } catch (const std::runtime_error& e) {
      throw SimConfigError("skin.plaque_count", std::string("field 'skin.plaque_count': ") + e.what());
    }
    g.length = geometry.length;
    g.ridges = geometry.ridges;  // relief is always as configured
    std::mt19937_64 rng(seed * 0x9E3779B97F4A7C15ull + 0xC0FFEEull);
    auto u = [&](double m) { return m * (2.0 * static_cast<double>(rng() >> 11) * (1.0 / 9007199254740992.0) - 1.0); };
    *y = u(max_yaw);
    *t = u(max_tilt);
    *r = u(max_roll);
  }
  g.contrast = contrast;
  g.scale_texture = scale_texture;
  return g;
}

void SkinConfig::validate() const {
  if (plaque_count < 0 || plaque_count > 12) bad("skin.plaque_count", plaque_count, "must be in 0..12");
  if (!(dome_max >= 0 && dome_max <= 1)) bad("skin.dome_max", dome_max, "must be in [0, 1]");
  for (const auto& [name, v] : {std::pair<const char*, double>{"yaw_deg", yaw}, {"tilt_deg", tilt}, {"roll_deg", roll},
                                {"max_yaw_deg", max_yaw}, {"max_tilt_deg", max_tilt}, {"max_roll_deg", max_roll}})
    if (!std::isfinite(v) || std::abs(v) > 90 * kDeg) bad(std::string("skin.") + name, v / kDeg, "must be in [-90, 90]");
  if (std::abs(tilt) > 30 * kDeg || max_tilt > 30 * kDeg) bad("skin.tilt_deg", tilt / kDeg, "tilts beyond 30 deg are not supported");
  if (!(working_distance > 0) || !std::isfinite(working_distance))
    bad("skin.working_distance_mm", working_distance * 1e3, "must be > 0");
  if (!(resolution_scale > 0) || resolution_scale > 1) bad("skin.resolution_scale", resolution_scale, "must be in (0, 1]");
  if (frames < 1) bad("skin.frames", frames, "must be >= 1");
  if (!(fps > 0) || !std::isfinite(fps)) bad("skin.fps", fps, "must be > 0");
  if (!(contrast >= 0) || contrast > 5) bad("skin.contrast", contrast, "must be in [0, 5]");
  sweep.validate();
  const double ay = geometry.semi_axis_y, az = geometry.semi_axis_z;
  if (!(ay >= 0.01 && ay <= 0.2) || !(az >= 0.01 && az <= 0.2))
    bad("skin.limb.semi_axes_mm", std::min(ay, az) * 1e3, "must be in [10, 200] mm");
  if (!(geometry.length > 0.02)) bad("skin.limb.length_mm", geometry.length * 1e3, "must be > 20 mm");
  if (!random) {
    try {
      SkinScene probe(geometry, 1);
    } catch (const std::invalid_argument& e) {
      throw SimConfigError("skin.plaques", std::string("field 'skin.plaques': ") + e.what());
    }
  }
  scaledRig().makeRig();
}

DatasetConfig defaultDatasetConfig(DatasetKind kind) {
  DatasetConfig c;
  c.kind = kind;
  c.workpiece.rig = partOneRig();
  c.workpiece.plateaus = defaultPlateaus();
  c.skin.rig = partOneRig();
  // The right camera's photometry differs from the left's, as two real modules do.
  c.images.right.gain = 0.93;
  c.images.right.offset = 0.015;
  c.images.right.gamma = 1.05;
  if (kind == DatasetKind::Workpiece) {
    // The Part I lenses are focused at the working distance; a little more blur than the binned SLAM rig.
    c.images.left.blur_sigma = c.images.right.blur_sigma = 0.8;
  }
  if (kind == DatasetKind::Skin) {
    // The same rig and lenses as the workpiece; skin is darker than the white plate, so at the same exposure
    // fewer electrons: about 3.5 DN of noise against the skin's few grey levels of texture.
    c.images.left.blur_sigma = c.images.right.blur_sigma = 0.8;
    c.images.left.full_well = c.images.right.full_well = 3000;
  }
  return c;
}

void makeIdeal(DatasetConfig* c) {
  c->images.ideal = true;
  c->images.left = RealismOptions::ideal();
  c->images.right = RealismOptions::ideal();
  c->images.perturbation.enabled = false;
}

namespace {

/** The globe and gyro sections. */
void readGlobe(const Section& top, GlobeConfig& g) {
  const Section gs = top.sub("globe", false,
                             {"radius_mm", "distance_mm", "latitude_deg", "tilt_deg", "rate_rad_s", "frames", "fps",
                              "landmarks", "descriptor_size", "descriptor_noise", "lookalike_fraction",
                              "lookalike_distance", "pixel_sigma_px", "max_incidence_deg"});
  g.radius = gs.number("radius_mm", false, g.radius * 1e3) * 1e-3;
  g.distance = gs.number("distance_mm", false, g.distance * 1e3) * 1e-3;
  g.latitude = gs.number("latitude_deg", false, g.latitude / kDeg) * kDeg;
  g.tilt = gs.number("tilt_deg", false, g.tilt / kDeg) * kDeg;
  g.rate = gs.number("rate_rad_s", false, g.rate);
  g.frames = gs.integer("frames", false, g.frames);
  g.fps = gs.number("fps", false, g.fps);
  g.landmarks = gs.integer("landmarks", false, g.landmarks);
  g.descriptor_size = gs.integer("descriptor_size", false, g.descriptor_size);
  g.descriptor_noise = gs.number("descriptor_noise", false, g.descriptor_noise);
  g.lookalike_fraction = gs.number("lookalike_fraction", false, g.lookalike_fraction);
  g.lookalike_distance = gs.number("lookalike_distance", false, g.lookalike_distance);
  g.pixel_sigma = gs.number("pixel_sigma_px", false, g.pixel_sigma);
  g.max_incidence = gs.number("max_incidence_deg", false, g.max_incidence / kDeg) * kDeg;

  const Section gy = top.sub("gyro", false, {"rate_hz", "noise_rad_s", "bias_rad_s", "bias_walk"});
  g.gyro_rate = gy.number("rate_hz", false, g.gyro_rate);
  g.gyro_noise = gy.number("noise_rad_s", false, g.gyro_noise);
  const auto bias = gy.list("bias_rad_s", 3, false);
  if (!bias.empty()) g.gyro_bias = Eigen::Vector3d(bias[0], bias[1], bias[2]);
  g.gyro_bias_walk = gy.number("bias_walk", false, g.gyro_bias_walk);

}

/** The workpiece section. */
void readWorkpiece(const Section& top, WorkpieceConfig& w) {
  const Section ws = top.sub("workpiece", false,
                             {"plate_size_mm", "plateaus", "working_distance_mm", "tilt_deg", "resolution_scale",
                              "frames", "fps", "texel_um"});
  const auto ps = ws.list("plate_size_mm", 2, false);
  if (!ps.empty()) w.plate_size = Eigen::Vector2d(ps[0], ps[1]) * 1e-3;
  if (ws.has("plateaus")) {
    w.plateaus.clear();
    for (const auto& p : ws.sequence("plateaus", {"centre_mm", "size_mm", "height_mm"})) {
      Plateau q;
      const auto cc = p.list("centre_mm", 2, true), sz = p.list("size_mm", 2, true);
      q.centre = Eigen::Vector2d(cc[0], cc[1]) * 1e-3;
      q.size = Eigen::Vector2d(sz[0], sz[1]) * 1e-3;
      q.height = p.number("height_mm", true) * 1e-3;
      w.plateaus.push_back(q);
    }
  }
  w.working_distance = ws.number("working_distance_mm", false, w.working_distance * 1e3) * 1e-3;
  w.tilt = ws.number("tilt_deg", false, w.tilt / kDeg) * kDeg;
  w.resolution_scale = ws.number("resolution_scale", false, w.resolution_scale);
  w.frames = ws.integer("frames", false, w.frames);
  w.fps = ws.number("fps", false, w.fps);
  w.texel = ws.number("texel_um", false, w.texel * 1e6) * 1e-6;

}

/** The skin section (limb, plaques, pose, imaging). */
void readSkin(const Section& top, SkinConfig& k) {
  const Section ks = top.sub("skin", false,
                             {"random", "plaque_count", "dome_max", "limb", "plaques", "ridges", "yaw_deg", "tilt_deg", "roll_deg",
                              "max_yaw_deg", "max_tilt_deg", "max_roll_deg", "working_distance_mm", "resolution_scale",
                              "frames", "fps", "contrast", "scale_texture", "sweep"});
  k.random = ks.boolean("random", k.random);
  k.plaque_count = ks.integer("plaque_count", false, k.plaque_count);
  k.dome_max = ks.number("dome_max", false, k.dome_max);
  const Section ls = ks.sub("limb", false, {"semi_axes_mm", "length_mm"});
  const auto ax = ls.list("semi_axes_mm", 2, false);
  if (!ax.empty()) {
    k.geometry.semi_axis_y = ax[0] * 1e-3;
    k.geometry.semi_axis_z = ax[1] * 1e-3;
  }
  k.geometry.length = ls.number("length_mm", false, k.geometry.length * 1e3) * 1e-3;
  if (ks.has("plaques")) {
    k.geometry.plaques.clear();
    for (const auto& p : ks.sequence("plaques", {"centre_mm", "radii_mm", "orientation_deg", "height_mm", "ramp_mm",
                                                 "dome", "irregularity"})) {
      SkinPlaque q;
      const auto cc = p.list("centre_mm", 2, true), rr = p.list("radii_mm", 2, true);
      q.centre = Eigen::Vector2d(cc[0], cc[1]) * 1e-3;
      q.radii = Eigen::Vector2d(rr[0], rr[1]) * 1e-3;
      q.orientation = p.number("orientation_deg", false, 0.0) * kDeg;
      q.height = p.number("height_mm", true) * 1e-3;
      q.ramp = p.number("ramp_mm", false, q.ramp * 1e3) * 1e-3;
      q.dome = p.number("dome", false, q.dome);
      q.irregularity = p.number("irregularity", false, q.irregularity);
      q.shape_seed = k.geometry.plaques.size() + 1;
      k.geometry.plaques.push_back(q);
    }
  }
  if (ks.has("ridges")) {
    k.geometry.ridges.clear();
    for (const auto& p : ks.sequence("ridges", {"centre_mm", "orientation_deg", "length_mm", "width_mm", "height_mm"})) {
      SkinRidge r;
      const auto cc = p.list("centre_mm", 2, true);
      r.centre = Eigen::Vector2d(cc[0], cc[1]) * 1e-3;
      r.orientation = p.number("orientation_deg", false, 0.0) * kDeg;
      r.length = p.number("length_mm", false, r.length * 1e3) * 1e-3;
      r.width = p.number("width_mm", false, r.width * 1e3) * 1e-3;
      r.height = p.number("height_mm", true) * 1e-3;
      k.geometry.ridges.push_back(r);
    }
  }
  k.yaw = ks.number("yaw_deg", false, k.yaw / kDeg) * kDeg;
  k.tilt = ks.number("tilt_deg", false, k.tilt / kDeg) * kDeg;
  k.roll = ks.number("roll_deg", false, k.roll / kDeg) * kDeg;
  k.max_yaw = ks.number("max_yaw_deg", false, k.max_yaw / kDeg) * kDeg;
  k.max_tilt = ks.number("max_tilt_deg", false, k.max_tilt / kDeg) * kDeg;
  k.max_roll = ks.number("max_roll_deg", false, k.max_roll / kDeg) * kDeg;
  k.working_distance = ks.number("working_distance_mm", false, k.working_distance * 1e3) * 1e-3;
  k.resolution_scale = ks.number("resolution_scale", false, k.resolution_scale);
  k.frames = ks.integer("frames", false, k.frames);
  k.fps = ks.number("fps", false, k.fps);
  k.contrast = ks.number("contrast", false, k.contrast);
  k.scale_texture = ks.boolean("scale_texture", k.scale_texture);
  const Section sw = ks.sub("sweep", false, {"enabled", "frames", "arc_deg", "fps", "jitter_mm", "jitter_deg",
                                              "plaque_span_deg", "gyro"});
  SkinSweepConfig& w = k.sweep;
  w.enabled = sw.boolean("enabled", w.enabled);
  w.frames = sw.integer("frames", false, w.frames);
  w.arc = sw.number("arc_deg", false, w.arc / kDeg) * kDeg;
  w.fps = sw.number("fps", false, w.fps);
  w.jitter = sw.number("jitter_mm", false, w.jitter * 1e3) * 1e-3;
  w.jitter_rot = sw.number("jitter_deg", false, w.jitter_rot / kDeg) * kDeg;
  w.plaque_span = sw.number("plaque_span_deg", false, w.plaque_span / kDeg) * kDeg;
  const Section gs = sw.sub("gyro", false, {"rate_hz", "noise_rad_s", "bias_rad_s"});
  w.gyro_rate = gs.number("rate_hz", false, w.gyro_rate);
  w.gyro_noise = gs.number("noise_rad_s", false, w.gyro_noise);
  if (gs.has("bias_rad_s")) {
    const auto b = gs.list("bias_rad_s", 3, false);
    w.gyro_bias = Eigen::Vector3d(b[0], b[1], b[2]);
  }

}

/** The images section (realism, photometry, calibration error); returns the section for its "ideal" key. */
Section readImages(const Section& top, ImageConfig& im) {
  const Section is =
      top.sub("images", false,
              {"ideal", "supersample", "realism", "left", "right", "calibration_error", "light_elevation_deg"});
  im.supersample = is.integer("supersample", false, im.supersample);
  im.light_elevation = is.number("light_elevation_deg", false, im.light_elevation / kDeg) * kDeg;
  const Section re = is.sub("realism", false, {"blur_sigma_px", "vignetting", "full_well", "read_noise_dn"});
  for (RealismOptions* r : {&im.left, &im.right}) {
    r->blur_sigma = re.number("blur_sigma_px", false, r->blur_sigma);
    r->vignetting = re.number("vignetting", false, r->vignetting);
    r->full_well = re.number("full_well", false, r->full_well);
    r->read_noise = re.number("read_noise_dn", false, r->read_noise);
  }
  readPhotometry(is.sub("left", false, {"gain", "offset", "gamma"}), &im.left);
  readPhotometry(is.sub("right", false, {"gain", "offset", "gamma"}), &im.right);
  const Section ce = is.sub("calibration_error", false,
                            {"enabled", "model", "baseline_rel", "rotation_deg", "principal_point_px", "focal_rel",
                             "views", "corner_sigma_px", "k_coefficients", "board", "board_fill", "distance_rel", "max_tilt_deg"});
  im.perturbation.enabled = ce.boolean("enabled", im.perturbation.enabled);
  im.perturbation.model = parseCalibrationErrorModel(ce.text("model", calibrationErrorModelName(im.perturbation.model)));
  im.perturbation.views = ce.integer("views", false, im.perturbation.views);
  im.perturbation.k_coefficients = ce.integer("k_coefficients", false, im.perturbation.k_coefficients);
  im.perturbation.corner_sigma_px = ce.number("corner_sigma_px", false, im.perturbation.corner_sigma_px);
  im.perturbation.board_fill = ce.number("board_fill", false, im.perturbation.board_fill);
  im.perturbation.max_tilt = ce.number("max_tilt_deg", false, im.perturbation.max_tilt / kDeg) * kDeg;
  if (ce.has("board")) {
    const std::vector<double> b = ce.list("board", 2, false);
    im.perturbation.board_cols = static_cast<int>(b[0]);
    im.perturbation.board_rows = static_cast<int>(b[1]);
  }
  if (ce.has("distance_rel")) {
    const std::vector<double> d = ce.list("distance_rel", 2, false);
    im.perturbation.min_distance_rel = d[0];
    im.perturbation.max_distance_rel = d[1];
  }
  im.perturbation.baseline_rel = ce.number("baseline_rel", false, im.perturbation.baseline_rel);
  im.perturbation.rotation = ce.number("rotation_deg", false, im.perturbation.rotation / kDeg) * kDeg;
  im.perturbation.principal_point = ce.number("principal_point_px", false, im.perturbation.principal_point);
  im.perturbation.focal_rel = ce.number("focal_rel", false, im.perturbation.focal_rel);
  return is;
}

}  // namespace

void applyDatasetYaml(DatasetConfig* c, const std::string& yaml_text, const std::string& source) {
  YAML::Node root;
  try {
    root = YAML::Load(yaml_text);
  } catch (const YAML::ParserException& e) {
    throw SimConfigError("(file)", "cannot parse " + source + " as YAML: line " + std::to_string(e.mark.line + 1) +
                                       ", column " + std::to_string(e.mark.column + 1) + ": " + e.msg);
  }
  c->source = source;
  if (!root || root.IsNull()) return;  // an empty file changes nothing
  const Section top(root, "", {"seed", "globe", "gyro", "rig", "workpiece", "skin", "images"});
  if (top.has("seed")) {
    const double s = top.number("seed", false);
    if (s < 0 || std::floor(s) != s) bad("seed", s, "must be a whole number >= 0");
    c->seed = static_cast<std::uint64_t>(s);
  }
  readGlobe(top, c->globe);
  const std::set<std::string> rig_keys = {"focal_length_mm", "pixel_size_um",   "width_px",  "height_px",
                                          "baseline_mm",     "convergence_deg", "distortion"};
  // `rig` applies to the kind's own rig: the SLAM rig for the globe, the Part I rig for the workpiece.
  const Section rs = top.sub("rig", false, rig_keys);
  readRig(rs, c->kind == DatasetKind::Workpiece ? &c->workpiece.rig : c->kind == DatasetKind::Skin ? &c->skin.rig : &c->globe.rig);

  readWorkpiece(top, c->workpiece);
  readSkin(top, c->skin);
  const Section is = readImages(top, c->images);
  if (is.boolean("ideal", false)) makeIdeal(c);
  validateDatasetConfig(*c);
}

void validateDatasetConfig(const DatasetConfig& c) {
  if (c.kind == DatasetKind::Workpiece) {
    c.workpiece.validate();
  } else if (c.kind == DatasetKind::Skin) {
    c.skin.validate();
  } else {
    c.globe.validate();
  }
  if (c.kind != DatasetKind::GlobeLandmarks) {
    const ImageConfig& im = c.images;
    if (im.supersample < 1 || im.supersample > 8) bad("images.supersample", im.supersample, "must be in 1..8");
    for (const auto* r : {&im.left, &im.right}) {
      const std::string side = r == &im.left ? "left" : "right";
      if (!(r->gain > 0) || !std::isfinite(r->gain)) bad("images." + side + ".gain", r->gain, "must be > 0");
      if (!(r->gamma > 0) || !std::isfinite(r->gamma)) bad("images." + side + ".gamma", r->gamma, "must be > 0");
      if (!std::isfinite(r->offset) || std::abs(r->offset) > 0.5)
        bad("images." + side + ".offset", r->offset, "must be in [-0.5, 0.5]");
      if (!(r->blur_sigma >= 0)) bad("images.realism.blur_sigma_px", r->blur_sigma, "must be >= 0");
      if (!(r->vignetting >= 0) || r->vignetting >= 1)
        bad("images.realism.vignetting", r->vignetting, "must be in [0, 1)");
      if (!(r->full_well >= 0)) bad("images.realism.full_well", r->full_well, "must be >= 0 (0: no shot noise)");
      if (!(r->read_noise >= 0)) bad("images.realism.read_noise_dn", r->read_noise, "must be >= 0");
    }
    const auto& p = im.perturbation;
    for (const auto& [name, v] : {std::pair<const char*, double>{"baseline_rel", p.baseline_rel},
                                  {"rotation_deg", p.rotation / kDeg},
                                  {"principal_point_px", p.principal_point},
                                  {"focal_rel", p.focal_rel}})
      if (!(v >= 0) || !std::isfinite(v)) bad(std::string("images.calibration_error.") + name, v, "must be >= 0");
    if (p.k_coefficients < 0 || p.k_coefficients > 3)
      bad("images.calibration_error.k_coefficients", p.k_coefficients, "must be in 0..3");
    if (p.views < 3 || p.views > 200) bad("images.calibration_error.views", p.views, "must be in 3..200");
    if (!(p.corner_sigma_px >= 0) || !std::isfinite(p.corner_sigma_px))
      bad("images.calibration_error.corner_sigma_px", p.corner_sigma_px, "must be >= 0");
    if (p.board_cols < 3 || p.board_rows < 3 || p.board_cols > 40 || p.board_rows > 40)
      bad("images.calibration_error.board", p.board_cols, "needs [cols, rows] of inner corners, each in 3..40");
    if (!(p.board_fill > 0) || p.board_fill > 1)
      bad("images.calibration_error.board_fill", p.board_fill, "must be in (0, 1]");
    if (!(p.min_distance_rel > 0) || !(p.max_distance_rel >= p.min_distance_rel) || !std::isfinite(p.max_distance_rel))
      bad("images.calibration_error.distance_rel", p.min_distance_rel, "needs [min, max] with 0 < min <= max");
    if (!(p.max_tilt >= 0) || p.max_tilt >= 80 * kDeg)
      bad("images.calibration_error.max_tilt_deg", p.max_tilt / kDeg, "must be in [0, 80)");
  }
}

}  // namespace sim
}  // namespace skin3d
