// SPDX-License-Identifier: BSD-3-Clause
// Induration results (induration_io.h): induration.yaml read back with yaml-cpp (values, units, the
// repeatability over frames from hand-computed means and standard deviations), the false-colour height map
// (located by rendering maps that differ in one region, so the test does not depend on the layout), and
// the binary PLY mesh of small organised clouds counted by hand.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "skin3d/induration/induration_io.h"

using namespace skin3d::induration;
using skin3d::stereo::DenseCloud;

namespace {

const float kNaN = std::numeric_limits<float>::quiet_NaN();

std::string tempPath(const std::string& name) {
  return ::testing::TempDir() + "skin3d_test_induration_io_" + name;
}

Plaque makePlaque(int id, Eigen::Vector3d centroid, double area_mm2, double mean_mm, double max_mm, double std_mm,
                  int pasi) {
  Plaque p;
  p.id = id;
  p.centroid = centroid;
  p.area = area_mm2 * 1e-6;
  p.mean_height = mean_mm * 1e-3;
  p.top_height = mean_mm * 1e-3;  // flat tops
  p.max_height = max_mm * 1e-3;
  p.std_height = std_mm * 1e-3;
  p.mean_height_sigma = 0.01e-3;
  p.pasi_class = pasi;
  p.pixels = 1000 + id;
  p.bbox = cv::Rect(10 * id, 20, 30, 40);
  return p;
}

std::vector<double> numbers(const YAML::Node& seq) {
  std::vector<double> v;
  for (const auto& n : seq) v.push_back(n.as<double>());
  return v;
}

std::string readAll(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
}

}  // namespace

// ------------------------------------------------------------------------------------------ induration.yaml

TEST(IndurationIo, YamlRoundTripWithRepeatability) {
  const Eigen::Vector3d a(0.010, 0.020, 0.300), b(-0.020, 0.000, 0.310);
  std::vector<FrameRecord> frames(3);
  // Frame 0: plaque 1 at a, plaque 2 at b.
  frames[0].stamp = 1700000000.123456;  // a wall-clock stamp: needs all its digits
  frames[0].seconds = 1.25;
  frames[0].valid_fraction = 0.9;
  frames[0].result.reference_ok = true;
  frames[0].result.reference.normal = Eigen::Vector3d(0, 0.6, -0.8);
  frames[0].result.reference.d = 0.25;
  frames[0].result.reference.rms = 0.02e-3;
  frames[0].result.reference.points = 5000;
  frames[0].result.known_points = 9000;
  frames[0].result.warnings = {"little texture in the lower left"};
  frames[0].result.plaques = {makePlaque(1, a, 20.0, 0.40, 0.60, 0.10, 2), makePlaque(2, b, 10.0, 0.10, 0.15, 0.02, 0)};
  // Frame 1: the same plaques, ids swapped, moved by 1 and 2 mm; and one new plaque 30 mm away.
  frames[1] = frames[0];
  frames[1].stamp = 101.5;
  frames[1].result.warnings.clear();
  frames[1].result.plaques = {makePlaque(1, b + Eigen::Vector3d(0.001, 0, 0), 12.0, 0.16, 0.25, 0.04, 1),
                              makePlaque(2, a + Eigen::Vector3d(0, 0.002, 0), 24.0, 0.44, 0.64, 0.12, 2),
                              makePlaque(3, a + Eigen::Vector3d(0.030, 0, 0), 50.0, 1.00, 1.20, 0.20, 4)};
  // Frame 2: no reference; one plaque 6 mm from a (outside the 5 mm match radius).
  frames[2].stamp = 102.5;
  frames[2].result.reference_ok = false;
  frames[2].result.warnings = {"no healthy skin left to fit the reference"};
  frames[2].result.plaques = {makePlaque(1, a + Eigen::Vector3d(0.006, 0, 0), 30.0, 0.9, 1.0, 0.1, 3)};

  IndurationOptions options;
  const std::string path = tempPath("induration.yaml");
  writeInduration(path, frames, options, "left_optical_frame", "unit test");
  const YAML::Node y = YAML::LoadFile(path);

  EXPECT_EQ(y["frame_id"].as<std::string>(), "left_optical_frame");
  EXPECT_EQ(y["source"].as<std::string>(), "unit test");
  ASSERT_TRUE(y["units"].IsMap());
  // Options in human units.
  const YAML::Node o = y["options"];
  EXPECT_EQ(o["reference_model"].as<std::string>(), "auto");
  EXPECT_NEAR(o["min_height_mm"].as<double>(), 0.05, 1e-9);
  EXPECT_NEAR(o["min_area_mm2"].as<double>(), 20.0, 1e-9);
  const std::vector<double> pasi = numbers(o["pasi_boundaries_mm"]);
  ASSERT_EQ(pasi.size(), 4u);
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(pasi[i], 0.125 + 0.25 * i, 1e-9);

  // Frames.
  ASSERT_EQ(y["frames"].size(), 3u);
  const YAML::Node f0 = y["frames"][0];
  EXPECT_NEAR(f0["stamp"].as<double>(), 1700000000.123456, 1e-6);
  EXPECT_NEAR(f0["seconds"].as<double>(), 1.25, 1e-9);
  EXPECT_NEAR(f0["valid_fraction"].as<double>(), 0.9, 1e-9);
  EXPECT_TRUE(f0["reference_ok"].as<bool>());
  const std::vector<double> n = numbers(f0["reference"]["n"]);
  ASSERT_EQ(n.size(), 3u);
  EXPECT_NEAR(n[0], 0.0, 1e-12);
  EXPECT_NEAR(n[1], 0.6, 1e-9);
  EXPECT_NEAR(n[2], -0.8, 1e-9);
  EXPECT_NEAR(f0["reference"]["d"].as<double>(), 0.25, 1e-12);  // m
  EXPECT_NEAR(f0["reference"]["rms_mm"].as<double>(), 0.02, 1e-9);
  ASSERT_EQ(f0["warnings"].size(), 1u);
  EXPECT_EQ(f0["warnings"][0].as<std::string>(), "little texture in the lower left");
  ASSERT_EQ(f0["plaques"].size(), 2u);
  const YAML::Node p = f0["plaques"][0];
  EXPECT_EQ(p["id"].as<int>(), 1);
  const std::vector<double> c = numbers(p["centroid_m"]);
  ASSERT_EQ(c.size(), 3u);
  EXPECT_NEAR(c[0], 0.010, 1e-9);
  EXPECT_NEAR(c[1], 0.020, 1e-9);
  EXPECT_NEAR(c[2], 0.300, 1e-9);
  EXPECT_NEAR(p["area_mm2"].as<double>(), 20.0, 1e-7);
  EXPECT_NEAR(p["mean_height_mm"].as<double>(), 0.40, 1e-9);
  EXPECT_NEAR(p["max_height_mm"].as<double>(), 0.60, 1e-9);
  EXPECT_NEAR(p["std_height_mm"].as<double>(), 0.10, 1e-9);
  EXPECT_NEAR(p["mean_height_sigma_mm"].as<double>(), 0.01, 1e-9);
  EXPECT_EQ(p["pasi_class"].as<int>(), 2);
  ASSERT_EQ(y["frames"][1]["plaques"].size(), 3u);
  EXPECT_FALSE(y["frames"][2]["reference_ok"].as<bool>());
  EXPECT_EQ(y["frames"][2]["warnings"][0].as<std::string>(), "no healthy skin left to fit the reference");

  // Repeatability: frame 0's plaques, matched by centroid (not by id), frame 2's plaque too far away.
  const YAML::Node rep = y["repeatability"]["plaques"];
  ASSERT_EQ(rep.size(), 2u);
  const YAML::Node r1 = rep[0], r2 = rep[1];
  EXPECT_EQ(r1["id"].as<int>(), 1);
  EXPECT_EQ(r1["frames_found"].as<int>(), 2);
  ASSERT_EQ(r1["ids_per_frame"].size(), 3u);
  EXPECT_EQ(r1["ids_per_frame"][0].as<int>(), 1);
  EXPECT_EQ(r1["ids_per_frame"][1].as<int>(), 2);
  EXPECT_TRUE(r1["ids_per_frame"][2].IsNull());
  // Plaque 1: mean heights 0.40, 0.44 mm -> mean 0.42, sample std 0.04 / sqrt(2); max 0.60, 0.64; area 20, 24.
  EXPECT_NEAR(r1["mean_height_mm"]["mean"].as<double>(), 0.42, 1e-9);
  EXPECT_NEAR(r1["mean_height_mm"]["std"].as<double>(), 0.04 / std::sqrt(2.0), 1e-9);
  EXPECT_NEAR(r1["top_height_mm"]["mean"].as<double>(), 0.42, 1e-9);
  EXPECT_NEAR(r1["max_height_mm"]["mean"].as<double>(), 0.62, 1e-9);
  EXPECT_NEAR(r1["max_height_mm"]["std"].as<double>(), 0.04 / std::sqrt(2.0), 1e-9);
  EXPECT_NEAR(r1["area_mm2"]["mean"].as<double>(), 22.0, 1e-7);
  EXPECT_NEAR(r1["area_mm2"]["std"].as<double>(), 4.0 / std::sqrt(2.0), 1e-7);
  EXPECT_EQ(r1["pasi_class_of_mean"].as<int>(), 2);  // 0.42 mm: 0.375 ... 0.625
  // Plaque 2: 0.10 and 0.16 mm: each frame alone says class 0 and 1; their mean 0.13 mm is class 1.
  EXPECT_EQ(r2["id"].as<int>(), 2);
  EXPECT_EQ(r2["ids_per_frame"][1].as<int>(), 1);
  EXPECT_NEAR(r2["mean_height_mm"]["mean"].as<double>(), 0.13, 1e-9);
  EXPECT_NEAR(r2["mean_height_mm"]["std"].as<double>(), 0.06 / std::sqrt(2.0), 1e-9);
  EXPECT_NEAR(r2["area_mm2"]["mean"].as<double>(), 11.0, 1e-7);
  EXPECT_EQ(r2["pasi_class_of_mean"].as<int>(), 1);
  const std::vector<double> rc = numbers(r2["centroid_m"]);
  ASSERT_EQ(rc.size(), 3u);
  EXPECT_NEAR(rc[0], -0.0195, 1e-9);  // b and b + 1 mm in x
  std::remove(path.c_str());
}

TEST(IndurationIo, YamlOneFrameHasNoStdAndUnwritablePathIsNamed) {
  std::vector<FrameRecord> frames(1);
  frames[0].result.reference_ok = true;
  frames[0].result.plaques = {makePlaque(1, Eigen::Vector3d(0, 0, 0.3), 5.0, 0.3, 0.4, 0.05, 1)};
  const std::string path = tempPath("one.yaml");
  writeInduration(path, frames, IndurationOptions(), "f", "s");
  const YAML::Node y = YAML::LoadFile(path);
  const YAML::Node r = y["repeatability"]["plaques"][0];
  EXPECT_NEAR(r["mean_height_mm"]["mean"].as<double>(), 0.3, 1e-9);
  EXPECT_TRUE(r["mean_height_mm"]["std"].IsNull());  // one value: no spread to report
  std::remove(path.c_str());

  const std::string bad = "/nonexistent_skin3d_dir/sub/induration.yaml";
  try {
    writeInduration(bad, frames, IndurationOptions(), "f", "s");
    FAIL() << "no error for " << bad;
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(bad), std::string::npos) << e.what();
  }
}

// ------------------------------------------------------------------------------------------ height map image

namespace {

/** @brief Pixels where two images differ. */
std::vector<cv::Point> differing(const cv::Mat& a, const cv::Mat& b) {
  std::vector<cv::Point> out;
  if (a.size() != b.size()) return out;
  for (int r = 0; r < a.rows; ++r)
    for (int c = 0; c < a.cols; ++c)
      if (a.at<cv::Vec3b>(r, c) != b.at<cv::Vec3b>(r, c)) out.emplace_back(c, r);
  return out;
}

bool isGrey(const cv::Vec3b& v) {
  return v[0] == v[1] && v[1] == v[2];
}

}  // namespace

TEST(IndurationIo, HeightMapColoursUnknownGreyAndScaleBar) {
  const int rows = 200, cols = 240;
  const cv::Rect r1(20, 20, 40, 40), r2(100, 100, 40, 40);
  cv::Mat zero(rows, cols, CV_32F, cv::Scalar(0.0f));
  cv::Mat with_unknown = zero.clone(), with_high = zero.clone(), both = zero.clone();
  with_unknown(r1).setTo(kNaN);
  with_high(r2).setTo(1e-3f);  // 1 mm = the top of the colour scale below
  both(r1).setTo(kNaN);
  both(r2).setTo(1e-3f);
  const cv::Mat img_zero = heightMapImage(zero, cv::Mat(), {}, 1.0);
  const cv::Mat img_unknown = heightMapImage(with_unknown, cv::Mat(), {}, 1.0);
  const cv::Mat img_high = heightMapImage(with_high, cv::Mat(), {}, 1.0);
  ASSERT_EQ(img_zero.type(), CV_8UC3);
  EXPECT_GE(img_zero.cols, cols);  // not shrunk: narrower than max_width
  EXPECT_GE(img_zero.rows, rows);
  EXPECT_EQ(img_unknown.size(), img_zero.size());

  // The unknown region: exactly its pixels change, to one dark grey.
  const auto unk = differing(img_zero, img_unknown);
  EXPECT_EQ(unk.size(), static_cast<size_t>(r1.area()));
  std::set<std::vector<int>> unknown_colours;
  for (const auto& q : unk) {
    const cv::Vec3b v = img_unknown.at<cv::Vec3b>(q);
    unknown_colours.insert({v[0], v[1], v[2]});
    EXPECT_TRUE(isGrey(v)) << q;
    EXPECT_GT(v[0], 20) << q;
    EXPECT_LT(v[0], 110) << q;
  }
  EXPECT_EQ(unknown_colours.size(), 1u);
  // Height 0 and height max: different colours, neither grey (a colour map, not a grey ramp).
  const auto high = differing(img_zero, img_high);
  ASSERT_EQ(high.size(), static_cast<size_t>(r2.area()));
  const cv::Vec3b c0 = img_zero.at<cv::Vec3b>(high[0]), cmax = img_high.at<cv::Vec3b>(high[0]);
  EXPECT_GT(cv::norm(cv::Vec3d(c0) - cv::Vec3d(cmax)), 100.0);
  EXPECT_FALSE(isGrey(c0));
  EXPECT_FALSE(isGrey(cmax));
  // Both changes together are the union of the two (independent regions).
  EXPECT_EQ(differing(img_zero, heightMapImage(both, cv::Mat(), {}, 1.0)).size(), unk.size() + high.size());

  // Scale bar: the map is one colour, yet some columns of the right part hold a colour ramp.
  int ramp_columns = 0;
  for (int c = 0; c < img_zero.cols; ++c) {
    std::set<std::vector<int>> colours;
    for (int r = 0; r < img_zero.rows; ++r) {
      const cv::Vec3b v = img_zero.at<cv::Vec3b>(r, c);
      if (!isGrey(v)) colours.insert({v[0], v[1], v[2]});
    }
    if (colours.size() >= 50) {
      ++ramp_columns;
      EXPECT_GE(c, cols / 2) << "colour ramp outside the right part";
    }
  }
  EXPECT_GE(ramp_columns, 5);
  // The ramp holds the colours of 0 and of the maximum.
  bool has0 = false, hasmax = false;
  for (int r = 0; r < img_zero.rows; ++r)
    for (int c = cols; c < img_zero.cols; ++c) {
      has0 |= img_zero.at<cv::Vec3b>(r, c) == c0;
      hasmax |= img_zero.at<cv::Vec3b>(r, c) == cmax;
    }
  EXPECT_TRUE(has0);
  EXPECT_TRUE(hasmax);
}

TEST(IndurationIo, HeightMapAutomaticScaleOutlinesAndSize) {
  const int rows = 200, cols = 240;
  const cv::Rect r2(100, 100, 40, 40);  // 1600 of 48000 px: above the 99th percentile
  cv::Mat h(rows, cols, CV_32F, cv::Scalar(0.0f));
  h(r2).setTo(0.5e-3f);
  // Automatic scale = the 99th percentile (0.5 mm here) ...
  EXPECT_TRUE(differing(heightMapImage(h, cv::Mat(), {}, 0.0), heightMapImage(h, cv::Mat(), {}, 0.5)).empty());
  EXPECT_FALSE(differing(heightMapImage(h, cv::Mat(), {}, 0.5), heightMapImage(h, cv::Mat(), {}, 1.0)).empty());
  // ... but at least 0.25 mm.
  cv::Mat flat(rows, cols, CV_32F, cv::Scalar(0.01e-3f));
  EXPECT_TRUE(differing(heightMapImage(flat, cv::Mat(), {}, 0.0), heightMapImage(flat, cv::Mat(), {}, 0.25)).empty());
  // With plaques, 1.25 x the highest plaque's max height, whatever lies far above the reference elsewhere
  // (skin: the limb's silhouette, millimetres off, on 5 % of the points).
  {
    cv::Mat skin = h.clone();
    skin(cv::Rect(0, 0, cols, 12)).setTo(20e-3f);  // 2880 of 48000 px at 20 mm
    Plaque top;
    top.id = 1;
    top.mean_height = 0.5e-3;
    top.max_height = 0.8e-3;
    top.bbox = r2;
    EXPECT_TRUE(differing(heightMapImage(skin, cv::Mat(), {top}, 0.0), heightMapImage(skin, cv::Mat(), {top}, 1.0)).empty());
    EXPECT_FALSE(differing(heightMapImage(skin, cv::Mat(), {}, 0.0), heightMapImage(skin, cv::Mat(), {}, 1.0)).empty());  // p99: 20 mm
  }

  // A plaque's outline is drawn in white.
  cv::Mat labels(rows, cols, CV_32S, cv::Scalar(0));
  labels(r2).setTo(1);
  Plaque p;
  p.id = 1;
  p.mean_height = 0.5e-3;
  p.bbox = r2;
  const cv::Mat plain = heightMapImage(h, cv::Mat(), {}, 1.0), outlined = heightMapImage(h, labels, {p}, 1.0);
  int white = 0;
  for (const auto& q : differing(plain, outlined)) white += outlined.at<cv::Vec3b>(q) == cv::Vec3b(255, 255, 255);
  EXPECT_GE(white, 100);  // at least most of the 4 x 40 px boundary

  // Wide maps are shrunk to max_width.
  cv::Mat wide(300, 4000, CV_32F, cv::Scalar(0.2e-3f));
  const cv::Mat w = heightMapImage(wide, cv::Mat(), {}, 0.0, 1600);
  EXPECT_LE(w.cols, 1600);
  EXPECT_GE(w.cols, 800);
  EXPECT_LT(w.rows, 300);  // the aspect ratio is kept: 4000 x 300 -> about 1500 x 113 (+ title / bar room)

  // Bad input is named.
  EXPECT_THROW(heightMapImage(cv::Mat(10, 10, CV_8U, cv::Scalar(0)), cv::Mat(), {}), std::invalid_argument);
  EXPECT_THROW(heightMapImage(h, cv::Mat(10, 10, CV_32S, cv::Scalar(0)), {}), std::invalid_argument);
}

// ------------------------------------------------------------------------------------------ PLY

namespace {

struct Ply {
  std::string header;
  size_t header_bytes = 0;
  long vertices = -1, faces = -1;
  std::vector<cv::Vec3f> xyz;
  std::vector<cv::Vec3b> rgb;
  std::vector<std::vector<int32_t>> face;
  size_t file_bytes = 0;
};

uint32_t le32(const unsigned char* p) {
  return p[0] | (p[1] << 8) | (p[2] << 16) | (static_cast<uint32_t>(p[3]) << 24);
}

Ply readPly(const std::string& path) {
  Ply ply;
  const std::string data = readAll(path);
  ply.file_bytes = data.size();
  const std::string end = "end_header\n";
  const size_t e = data.find(end);
  if (e == std::string::npos) return ply;
  ply.header_bytes = e + end.size();
  ply.header = data.substr(0, ply.header_bytes);
  std::istringstream hs(ply.header);
  std::string line;
  while (std::getline(hs, line)) {
    std::istringstream ls(line);
    std::string w1, w2;
    long n;
    if (ls >> w1 >> w2 >> n && w1 == "element") (w2 == "vertex" ? ply.vertices : ply.faces) = n;
  }
  const auto* p = reinterpret_cast<const unsigned char*>(data.data()) + ply.header_bytes;
  const auto* stop = reinterpret_cast<const unsigned char*>(data.data()) + data.size();
  for (long i = 0; i < ply.vertices && p + 15 <= stop; ++i, p += 15) {
    cv::Vec3f v;
    for (int k = 0; k < 3; ++k) {
      const uint32_t u = le32(p + 4 * k);
      std::memcpy(&v[k], &u, 4);
    }
    ply.xyz.push_back(v);
    ply.rgb.emplace_back(p[12], p[13], p[14]);
  }
  for (long i = 0; i < ply.faces && p < stop; ++i) {
    const int n = *p++;
    std::vector<int32_t> f;
    for (int k = 0; k < n && p + 4 <= stop; ++k, p += 4) f.push_back(static_cast<int32_t>(le32(p)));
    ply.face.push_back(f);
  }
  return ply;
}

/** @brief 4 x 3 cloud: x = 1 mm per column, y = 1 mm per row, z = 300 mm + 0.1 mm per column; NaN at (1, 1). */
DenseCloud smallCloud() {
  DenseCloud cloud;
  cloud.xyz = cv::Mat(3, 4, CV_32FC3);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) cloud.xyz.at<cv::Vec3f>(r, c) = cv::Vec3f(1e-3f * c, 1e-3f * r, 0.3f + 1e-4f * c);
  cloud.xyz.at<cv::Vec3f>(1, 1) = cv::Vec3f(kNaN, kNaN, kNaN);
  return cloud;
}

std::set<std::set<int32_t>> faceSets(const Ply& ply) {
  std::set<std::set<int32_t>> s;
  for (const auto& f : ply.face) s.insert(std::set<int32_t>(f.begin(), f.end()));
  return s;
}

}  // namespace

TEST(IndurationIo, SurfacePlyOfASmallCloud) {
  const DenseCloud cloud = smallCloud();
  cv::Mat colour(3, 4, CV_8UC3);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) colour.at<cv::Vec3b>(r, c) = cv::Vec3b(10 * c, 50 + 20 * r, 200);  // B G R
  const std::string path = tempPath("surface.ply");
  writeSurfacePly(path, cloud, colour);
  const Ply ply = readPly(path);
  EXPECT_NE(ply.header.find("format binary_little_endian 1.0\n"), std::string::npos);
  EXPECT_NE(ply.header.find("property list uchar int vertex_indices\n"), std::string::npos);
  // 12 pixels, one unknown: 11 vertices. Of the 3 x 2 cells only the two of column 2 ... 3 avoid (1, 1).
  EXPECT_EQ(ply.vertices, 11);
  EXPECT_EQ(ply.faces, 4);
  EXPECT_EQ(ply.file_bytes, ply.header_bytes + 11 * (3 * 4 + 3) + 4 * (1 + 3 * 4));
  // Vertices row by row without the unknown pixel, with the colour of their pixel as RGB.
  const std::vector<cv::Point> pixels = {{0, 0}, {1, 0}, {2, 0}, {3, 0}, {0, 1}, {2, 1},
                                         {3, 1}, {0, 2}, {1, 2}, {2, 2}, {3, 2}};
  ASSERT_EQ(ply.xyz.size(), pixels.size());
  for (size_t i = 0; i < pixels.size(); ++i) {
    EXPECT_EQ(ply.xyz[i], cloud.xyz.at<cv::Vec3f>(pixels[i])) << i;
    const cv::Vec3b bgr = colour.at<cv::Vec3b>(pixels[i]);
    EXPECT_EQ(ply.rgb[i], cv::Vec3b(bgr[2], bgr[1], bgr[0])) << i;
  }
  // Faces: cell (row 0, col 2) has vertices 2, 3, 5, 6; cell (row 1, col 2) has 5, 6, 9, 10.
  ASSERT_EQ(ply.face.size(), 4u);
  for (const auto& f : ply.face) EXPECT_EQ(f.size(), 3u);
  const std::set<std::set<int32_t>> expected = {{2, 3, 5}, {3, 5, 6}, {5, 6, 9}, {6, 9, 10}};
  const std::set<std::set<int32_t>> expected_other_diagonal = {{2, 3, 6}, {2, 5, 6}, {5, 6, 10}, {5, 9, 10}};
  const auto got = faceSets(ply);
  EXPECT_TRUE(got == expected || got == expected_other_diagonal);
  // All triangles wound the same way (their normals on the same side of the surface).
  int towards = 0;
  for (const auto& f : ply.face) {
    const cv::Vec3f a = ply.xyz[f[0]], b = ply.xyz[f[1]], c = ply.xyz[f[2]];
    towards += (b - a).cross(c - a)[2] < 0;
  }
  EXPECT_TRUE(towards == 0 || towards == 4) << towards;
  std::remove(path.c_str());
}

TEST(IndurationIo, SurfacePlyStepGreyColourAndDepthJumps) {
  const DenseCloud cloud = smallCloud();
  const std::string path = tempPath("surface_step.ply");
  // Every 2nd px: pixels (0,0) (2,0) (0,2) (2,2) [x, y], all known (the NaN at (1,1) is skipped): one cell.
  cv::Mat grey(3, 4, CV_8UC1);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) grey.at<uchar>(r, c) = static_cast<uchar>(40 * r + c);
  writeSurfacePly(path, cloud, grey, 2);
  Ply ply = readPly(path);
  EXPECT_EQ(ply.vertices, 4);
  EXPECT_EQ(ply.faces, 2);
  EXPECT_EQ(ply.file_bytes, ply.header_bytes + 4 * 15 + 2 * 13);
  ASSERT_EQ(ply.xyz.size(), 4u);
  EXPECT_EQ(ply.xyz[3], cloud.xyz.at<cv::Vec3f>(2, 2));
  EXPECT_EQ(ply.rgb[3], cv::Vec3b(82, 82, 82));  // grey 40 * 2 + 2
  for (const auto& f : ply.face)
    for (int32_t i : f) EXPECT_TRUE(i >= 0 && i < 4) << i;

  // No colour image: white. A pixel 100 mm in front of 1 mm cells: its cell has no faces.
  DenseCloud jump;
  jump.xyz = cv::Mat(3, 3, CV_32FC3);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) jump.xyz.at<cv::Vec3f>(r, c) = cv::Vec3f(1e-3f * c, 1e-3f * r, 0.3f);
  jump.xyz.at<cv::Vec3f>(0, 0)[2] = 0.2f;
  writeSurfacePly(path, jump, cv::Mat());
  ply = readPly(path);
  EXPECT_EQ(ply.vertices, 9);
  EXPECT_EQ(ply.faces, 6);  // 4 cells, the one at (0, 0) dropped
  for (const auto& c : ply.rgb) EXPECT_EQ(c, cv::Vec3b(255, 255, 255));
  for (const auto& f : ply.face)
    for (int32_t i : f) EXPECT_NE(i, 0) << "a face uses the jumped pixel";
  // Without the jump all 4 cells are meshed.
  jump.xyz.at<cv::Vec3f>(0, 0)[2] = 0.3f;
  writeSurfacePly(path, jump, cv::Mat());
  EXPECT_EQ(readPly(path).faces, 8);
  std::remove(path.c_str());

  // Errors name the file or the problem.
  const std::string bad = "/nonexistent_skin3d_dir/surface.ply";
  try {
    writeSurfacePly(bad, cloud, cv::Mat());
    FAIL() << "no error for " << bad;
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(bad), std::string::npos) << e.what();
  }
  EXPECT_THROW(writeSurfacePly(path, cloud, cv::Mat(), 0), std::invalid_argument);
  EXPECT_THROW(writeSurfacePly(path, cloud, cv::Mat(5, 5, CV_8UC3)), std::invalid_argument);
  EXPECT_THROW(writeSurfacePly(path, DenseCloud(), cv::Mat()), std::invalid_argument);
}
