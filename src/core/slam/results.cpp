// SPDX-License-Identifier: BSD-3-Clause
// Results directory writers and the trajectory error (see results.h).
#include "skin3d/slam/results.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iomanip>
#include <sstream>
#include <stdexcept>
#include <sys/stat.h>

namespace skin3d {
namespace slam {

namespace {
std::ofstream open(const std::string& path) {
  std::ofstream f(path);
  if (!f) throw std::runtime_error("cannot write '" + path + "'");
  f.precision(10);
  return f;
}
void close(std::ofstream& f, const std::string& path) {
  f.close();
  if (!f) throw std::runtime_error("error while writing '" + path + "'");
}
}  // namespace

StateRow stateRow(const SlamSystem& slam, const FrameStats& stats) {
  StateRow r;
  r.t = stats.time;
  r.stats = stats;
  const Eskf& f = slam.filter();
  r.v = f.state().v;
  r.w = f.state().w;
  r.trace_rig = f.rigTrace();
  r.trace_landmarks = f.landmarksTrace();
  r.trace_all = f.totalTrace();
  r.pose_position_std = std::sqrt(std::max(0.0, f.covariance().topLeftCorner<3, 3>().trace()));
  r.corr_vx_wy = slam.correlationVxWy();
  r.pool_size = slam.pool().capacity();
  r.pool_in_use = slam.pool().used();
  r.ever_seen = static_cast<long>(slam.pool().everSeen());
  const int rd = f.rigDim();
  r.rig_covariance = f.covariance().topLeftCorner(rd, rd).cast<float>();
  return r;
}

TrajectoryError trajectoryError(const std::vector<StampedPose>& estimate, const std::vector<StampedPose>& reference,
                                double max_dt) {
  TrajectoryError e;
  if (reference.empty()) return e;
  std::vector<StampedPose> ref = reference;
  std::sort(ref.begin(), ref.end(), [](const StampedPose& a, const StampedPose& b) { return a.t < b.t; });
  double ss = 0.0, sr = 0.0, sum = 0.0;
  for (const auto& p : estimate) {
    auto it = std::lower_bound(ref.begin(), ref.end(), p.t, [](const StampedPose& a, double t) { return a.t < t; });
    const StampedPose* best = nullptr;
    if (it != ref.end()) best = &*it;
    if (it != ref.begin() && (!best || std::abs(std::prev(it)->t - p.t) < std::abs(best->t - p.t))) best = &*std::prev(it);
    if (!best || std::abs(best->t - p.t) > max_dt) continue;
    const double d = (p.p - best->p).norm();
    const double a = p.q.angularDistance(best->q);
    ss += d * d;
    sr += a * a;
    sum += d;
    e.max = std::max(e.max, d);
    e.final = d;
    ++e.pairs;
  }
  if (e.pairs > 0) {
    e.rmse = std::sqrt(ss / e.pairs);
    e.rotation_rmse = std::sqrt(sr / e.pairs);
    e.mean = sum / e.pairs;
  }
  return e;
}

void writeTum(const std::string& path, const std::vector<StampedPose>& trajectory) {
  auto f = open(path);
  f << "# skin3d trajectory: t x y z qx qy qz qw (world <- left optical frame; s, m)\n";
  for (const auto& p : trajectory)
    f << p.t << ' ' << p.p.x() << ' ' << p.p.y() << ' ' << p.p.z() << ' ' << p.q.x() << ' ' << p.q.y() << ' '
      << p.q.z() << ' ' << p.q.w() << '\n';
  close(f, path);
}

std::vector<StampedPose> readTum(const std::string& path) {
  std::ifstream f(path);
  if (!f) throw std::runtime_error("cannot read '" + path + "'");
  std::vector<StampedPose> out;
  std::string line;
  int n = 0;
  while (std::getline(f, line)) {
    ++n;
    if (line.empty() || line[0] == '#') continue;
    std::istringstream is(line);
    StampedPose p;
    double qx, qy, qz, qw;
    if (!(is >> p.t >> p.p.x() >> p.p.y() >> p.p.z() >> qx >> qy >> qz >> qw))
      throw std::runtime_error("'" + path + "' line " + std::to_string(n) + ": expected t x y z qx qy qz qw");
    p.q = Eigen::Quaterniond(qw, qx, qy, qz).normalized();
    out.push_back(p);
  }
  return out;
}

void writePly(const std::string& path, const std::vector<MapPoint>& map) {
  auto f = open(path);
  f << "ply\nformat ascii 1.0\ncomment skin3d SLAM map: landmarks in the world frame (m), position std (m)\n"
    << "element vertex " << map.size() << "\nproperty float x\nproperty float y\nproperty float z\n"
    << "property float std\nproperty int id\nproperty int observations\nend_header\n";
  for (const auto& m : map)
    f << m.position.x() << ' ' << m.position.y() << ' ' << m.position.z() << ' '
      << std::sqrt(std::max(0.0, m.covariance.trace())) << ' ' << m.id << ' ' << m.times_observed << '\n';
  close(f, path);
}

void writeStateCsv(const std::string& path, const std::vector<StateRow>& rows) {
  auto f = open(path);
  f << "t,vx,vy,vz,wx,wy,wz,trace_rig,trace_landmarks,trace_all,position_std_m,corr_vx_wy,pool_size,pool_in_use,"
       "ever_seen,measurements,rejected,associated,used,initialised,forks_deleted,pruned,gyro_used,nis,nis_dof\n";
  for (const auto& r : rows)
    f << r.t << ',' << r.v.x() << ',' << r.v.y() << ',' << r.v.z() << ',' << r.w.x() << ',' << r.w.y() << ','
      << r.w.z() << ',' << r.trace_rig << ',' << r.trace_landmarks << ',' << r.trace_all << ','
      << r.pose_position_std << ',' << r.corr_vx_wy << ',' << r.pool_size << ',' << r.pool_in_use << ','
      << r.ever_seen << ',' << r.stats.measurements << ',' << r.stats.rejected_invalid << ',' << r.stats.associated
      << ',' << r.stats.used << ',' << r.stats.initialised << ',' << r.stats.forks_deleted << ',' << r.stats.pruned
      << ',' << r.stats.gyro_used << ',' << r.stats.nis << ',' << r.stats.nis_dof << '\n';
  close(f, path);
}

void writeRigCovarianceCsv(const std::string& path, const std::vector<StateRow>& rows) {
  auto f = open(path);
  int n = 0;
  for (const auto& r : rows) n = std::max(n, static_cast<int>(r.rig_covariance.rows()));
  static const char* kNames[] = {"px", "py", "pz", "thx", "thy", "thz", "vx",  "vy",  "vz",
                                 "wx", "wy", "wz", "bgx", "bgy", "bgz"};
  f << "# skin3d rig error-state covariance per frame, row-major (m, rad, m/s, rad/s); variables:";
  for (int i = 0; i < n && i < 15; ++i) f << ' ' << kNames[i];
  f << "\nt";
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) f << ",P_" << i << '_' << j;
  f << '\n';
  f.precision(7);
  for (const auto& r : rows) {
    if (r.rig_covariance.rows() != n || r.rig_covariance.cols() != n) continue;  // e.g. rows without a filter
    f << std::setprecision(10) << r.t << std::setprecision(7);
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) f << ',' << r.rig_covariance(i, j);
    f << '\n';
  }
  close(f, path);
}

void writeSphereFit(const std::string& path, const geometry::SphereFit& fit) {
  YAML::Emitter y;
  y << YAML::BeginMap;
  y << YAML::Key << "centre_m" << YAML::Value << YAML::Flow << YAML::BeginSeq << fit.centre.x() << fit.centre.y()
    << fit.centre.z() << YAML::EndSeq;
  y << YAML::Key << "radius_mm" << YAML::Value << 1e3 * fit.radius;
  y << YAML::Key << "radius_std_mm" << YAML::Value << 1e3 * std::sqrt(std::max(0.0, fit.covariance(3, 3)));
  y << YAML::Key << "rms_residual_mm" << YAML::Value << 1e3 * fit.rms_inliers;
  y << YAML::Key << "rms_residual_all_mm" << YAML::Value << 1e3 * fit.rms_all;
  y << YAML::Key << "points" << YAML::Value << fit.points;
  y << YAML::Key << "inliers" << YAML::Value << fit.inliers;
  y << YAML::Key << "method" << YAML::Value
    << "algebraic start, then Gauss-Newton with Tukey biweight (k = 4.685 robust sigmas); rms over inliers";
  y << YAML::EndMap;
  auto f = open(path);
  f << "# skin3d robust sphere fit of the SLAM map\n" << y.c_str() << '\n';
  close(f, path);
}

std::string writeResults(const std::string& dir, const RunRecord& run) {
  ::mkdir(dir.c_str(), 0755);
  struct stat st;
  if (::stat(dir.c_str(), &st) != 0 || !S_ISDIR(st.st_mode)) throw std::runtime_error("cannot create directory '" + dir + "'");
  writeTum(dir + "/trajectory.tum", run.trajectory);
  writePly(dir + "/map.ply", run.map);
  writeStateCsv(dir + "/state.csv", run.rows);
  writeRigCovarianceCsv(dir + "/rig_covariance.csv", run.rows);
  if (!run.ground_truth.empty()) writeTum(dir + "/ground_truth.tum", run.ground_truth);
  YAML::Emitter y;
  y << YAML::BeginMap;
  for (const auto& kv : run.info) y << YAML::Key << kv.first << YAML::Value << kv.second;
  y << YAML::Key << "frames" << YAML::Value << run.trajectory.size();
  y << YAML::Key << "landmarks_in_map" << YAML::Value << run.map.size();
  if (!run.rows.empty()) {
    const StateRow& r = run.rows.back();
    y << YAML::Key << "landmarks_ever_seen" << YAML::Value << r.ever_seen;
    y << YAML::Key << "final_covariance_trace" << YAML::Value << YAML::BeginMap << YAML::Key << "rig" << YAML::Value
      << r.trace_rig << YAML::Key << "landmarks_m2" << YAML::Value << r.trace_landmarks << YAML::Key << "all"
      << YAML::Value << r.trace_all << YAML::EndMap;
    y << YAML::Key << "corr_vx_wy_final" << YAML::Value << r.corr_vx_wy;
  }
  if (!run.ground_truth.empty()) {
    const TrajectoryError e = trajectoryError(run.trajectory, run.ground_truth);
    y << YAML::Key << "ate" << YAML::Value << YAML::BeginMap << YAML::Key << "pairs" << YAML::Value << e.pairs
      << YAML::Key << "rmse_mm" << YAML::Value << 1e3 * e.rmse << YAML::Key << "mean_mm" << YAML::Value << 1e3 * e.mean
      << YAML::Key << "max_mm" << YAML::Value << 1e3 * e.max << YAML::Key << "final_mm" << YAML::Value << 1e3 * e.final
      << YAML::Key << "rotation_rmse_mrad" << YAML::Value << 1e3 * e.rotation_rmse << YAML::Key << "alignment"
      << YAML::Value << run.ground_truth_alignment << YAML::EndMap;
  }
  if (run.fit_sphere && run.map.size() >= 4) {
    std::vector<Eigen::Vector3d> pts;
    for (const auto& m : run.map) pts.push_back(m.position);
    try {
      const geometry::SphereFit fit = geometry::fitSphere(pts);
      writeSphereFit(dir + "/sphere_fit.yaml", fit);
      y << YAML::Key << "sphere_fit" << YAML::Value << YAML::BeginMap << YAML::Key << "radius_mm" << YAML::Value
        << 1e3 * fit.radius << YAML::Key << "rms_residual_mm" << YAML::Value << 1e3 * fit.rms_inliers << YAML::Key
        << "inliers" << YAML::Value << fit.inliers << YAML::EndMap;
    } catch (const std::invalid_argument& e) {
      y << YAML::Key << "sphere_fit" << YAML::Value << (std::string("failed: ") + e.what());
    }
  }
  y << YAML::EndMap;
  const std::string text = std::string("# skin3d SLAM run summary (mm where the key says so)\n") + y.c_str() + "\n";
  auto f = open(dir + "/summary.yaml");
  f << text;
  close(f, dir + "/summary.yaml");
  return text;
}

std::pair<std::vector<Eigen::Vector3d>, std::vector<std::vector<float>>> readLandmarkMap(const std::string& path) {
  std::ifstream f(path);
  if (!f) throw std::invalid_argument("cannot read the known map '" + path + "'");
  std::pair<std::vector<Eigen::Vector3d>, std::vector<std::vector<float>>> out;
  std::string line;
  int n = 0;
  while (std::getline(f, line)) {
    ++n;
    if (line.empty() || line[0] == '#') continue;
    std::vector<double> v;
    std::stringstream ss(line);
    std::string cell;
    while (std::getline(ss, cell, ',')) {
      try {
        v.push_back(std::stod(cell));
      } catch (const std::exception&) {
        throw std::invalid_argument("'" + path + "' line " + std::to_string(n) + ": '" + cell + "' is not a number");
      }
    }
    if (v.size() < 4) throw std::invalid_argument("'" + path + "' line " + std::to_string(n) + ": need id,x,y,z[,descriptor]");
    out.first.emplace_back(v[1], v[2], v[3]);
    out.second.emplace_back(v.begin() + 4, v.end());
  }
  if (out.first.empty()) throw std::invalid_argument("the known map '" + path + "' has no landmarks");
  return out;
}

}  // namespace slam
}  // namespace skin3d
