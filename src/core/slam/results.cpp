// SPDX-License-Identifier: BSD-3-Clause
// Results directory writers and the trajectory error (see results.h).
#include "skin3d/slam/results.h"

#include <Eigen/Eigenvalues>
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
/** A time for the CSV files: fixed, microseconds (what a double holds of an epoch stamp), never 10 digits. */
std::string stampText(double t) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.6f", t);
  return buf;
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
  if (f.rigDim() == 15) r.gyro_bias = f.state().gyro_bias;
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

AteAlignment parseAteAlignment(const std::string& name) {
  if (name == "auto") return AteAlignment::Auto;
  if (name == "none") return AteAlignment::None;
  if (name == "first_pose") return AteAlignment::FirstPose;
  if (name == "se3") return AteAlignment::SE3;
  throw std::invalid_argument("unknown ATE alignment '" + name + "' (auto, none, first_pose or se3)");
}

std::string ateAlignmentName(AteAlignment a) {
  switch (a) {
    case AteAlignment::Auto: return "auto";
    case AteAlignment::None: return "none";
    case AteAlignment::FirstPose: return "first_pose";
    case AteAlignment::SE3: return "se3";
  }
  return "?";
}

std::vector<std::pair<int, int>> associateByTime(const std::vector<StampedPose>& estimate,
                                                 const std::vector<StampedPose>& reference, double max_dt) {
  std::vector<int> order(reference.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int>(i);
  std::sort(order.begin(), order.end(), [&](int a, int b) { return reference[a].t < reference[b].t; });
  std::vector<std::pair<int, int>> pairs;
  for (std::size_t e = 0; e < estimate.size(); ++e) {
    const double t = estimate[e].t;
    auto it = std::lower_bound(order.begin(), order.end(), t, [&](int r, double v) { return reference[r].t < v; });
    int best = -1;
    if (it != order.end()) best = *it;
    if (it != order.begin() && (best < 0 || std::abs(reference[*std::prev(it)].t - t) < std::abs(reference[best].t - t)))
      best = *std::prev(it);
    if (best < 0 || std::abs(reference[best].t - t) > max_dt) continue;
    pairs.emplace_back(static_cast<int>(e), best);
  }
  return pairs;
}

Eigen::Isometry3d alignSE3(const std::vector<StampedPose>& estimate, const std::vector<StampedPose>& reference,
                           const std::vector<std::pair<int, int>>& pairs) {
  if (pairs.size() < 3)
    throw std::invalid_argument("an SE(3) alignment needs at least 3 paired poses (have " +
                                std::to_string(pairs.size()) + ")");
  Eigen::Matrix3Xd src(3, pairs.size()), dst(3, pairs.size());
  for (std::size_t i = 0; i < pairs.size(); ++i) {
    src.col(i) = reference[pairs[i].second].p;
    dst.col(i) = estimate[pairs[i].first].p;
  }
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.matrix() = Eigen::umeyama(src, dst, false);
  return T;
}

TrajectoryError trajectoryError(const std::vector<StampedPose>& estimate, const std::vector<StampedPose>& reference,
                                AteAlignment alignment, double max_dt) {
  TrajectoryError e;
  e.max_dt = max_dt;
  e.alignment = alignment;
  const auto pairs = associateByTime(estimate, reference, max_dt);
  if (pairs.empty()) {
    if (alignment == AteAlignment::Auto) e.alignment = AteAlignment::None;
    return e;
  }
  const StampedPose& e0 = estimate[pairs.front().first];
  const StampedPose& r0 = reference[pairs.front().second];
  Eigen::Isometry3d first = Eigen::Isometry3d::Identity();  // estimate world <- reference world at the first pair
  first.linear() = (e0.q * r0.q.conjugate()).normalized().toRotationMatrix();
  first.translation() = e0.p - first.linear() * r0.p;
  if (alignment == AteAlignment::Auto) {
    const bool same = (e0.p - r0.p).norm() <= 0.010 && e0.q.angularDistance(r0.q) <= 0.010;
    e.alignment = same ? AteAlignment::None : AteAlignment::SE3;
    char note[200];
    std::snprintf(note, sizeof note,
                  "auto: the reference's first paired pose is %.1f mm / %.1f mrad from the estimate's: %s",
                  1e3 * (e0.p - r0.p).norm(), 1e3 * e0.q.angularDistance(r0.q),
                  same ? "the same world, not aligned" : "another world, SE(3)-aligned");
    e.alignment_note = note;
  }
  if (e.alignment == AteAlignment::SE3 && pairs.size() < 3) {
    e.alignment = AteAlignment::FirstPose;
    e.alignment_note += std::string(e.alignment_note.empty() ? "" : "; ") + "fewer than 3 pairs: first-pose alignment";
  }
  {
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const auto& pr : pairs) mean += estimate[pr.first].p / static_cast<double>(pairs.size());
    Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
    for (const auto& pr : pairs)
      C += (estimate[pr.first].p - mean) * (estimate[pr.first].p - mean).transpose() / static_cast<double>(pairs.size());
    const Eigen::Vector3d ev = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(C).eigenvalues().cwiseMax(0.0).cwiseSqrt();
    e.spread = Eigen::Vector3d(ev(2), ev(1), ev(0));
  }
  if (e.alignment == AteAlignment::SE3 && e.spread(1) < 0.05 * e.spread(0))
    e.alignment_note += std::string(e.alignment_note.empty() ? "" : "; ") +
                        "the positions lie nearly on a line: the fit leaves the rotation about it loose, so the "
                        "rotation error after alignment says little";
  if (e.alignment == AteAlignment::FirstPose) e.transform = first;
  if (e.alignment == AteAlignment::SE3) e.transform = alignSE3(estimate, reference, pairs);
  const Eigen::Quaterniond qT(e.transform.linear());
  double ss = 0.0, sr = 0.0, sum = 0.0;
  for (const auto& pr : pairs) {
    const StampedPose& p = estimate[pr.first];
    const StampedPose& r = reference[pr.second];
    const double d = (p.p - e.transform * r.p).norm();
    const double a = p.q.angularDistance(qT * r.q);
    ss += d * d;
    sr += a * a;
    sum += d;
    e.max = std::max(e.max, d);
    e.final = d;
    ++e.pairs;
  }
  e.rmse = std::sqrt(ss / e.pairs);
  e.rotation_rmse = std::sqrt(sr / e.pairs);
  e.mean = sum / e.pairs;
  return e;
}

std::string formatStamp(const StampedPose& p) {
  char buf[48];
  if (p.stamp_ns >= 0) {
    std::snprintf(buf, sizeof buf, "%lld.%09lld", static_cast<long long>(p.stamp_ns / 1000000000),
                  static_cast<long long>(p.stamp_ns % 1000000000));
  } else {
    std::snprintf(buf, sizeof buf, "%.9f", p.t);
  }
  return buf;
}

std::int64_t parseStampNs(const std::string& text) {
  const auto dot = text.find('.');
  const std::string whole = text.substr(0, dot), frac = dot == std::string::npos ? "" : text.substr(dot + 1);
  if (whole.empty() || whole.size() > 10) return -1;
  for (char c : whole + frac)
    if (c < '0' || c > '9') return -1;
  std::string ns = frac.substr(0, std::min<std::size_t>(9, frac.size()));
  ns.append(9 - ns.size(), '0');
  return std::stoll(whole) * 1000000000LL + std::stoll(ns);
}

void writeTum(const std::string& path, const std::vector<StampedPose>& trajectory) {
  auto f = open(path);
  f << "# skin3d trajectory: t x y z qx qy qz qw (world <- left optical frame; s, m)\n";
  f.precision(10);
  for (const auto& p : trajectory)
    f << formatStamp(p) << ' ' << p.p.x() << ' ' << p.p.y() << ' ' << p.p.z() << ' ' << p.q.x() << ' ' << p.q.y()
      << ' ' << p.q.z() << ' ' << p.q.w() << '\n';
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
    std::string stamp;
    double qx, qy, qz, qw;
    if (!(is >> stamp >> p.p.x() >> p.p.y() >> p.p.z() >> qx >> qy >> qz >> qw))
      throw std::runtime_error("'" + path + "' line " + std::to_string(n) + ": expected t x y z qx qy qz qw");
    try {
      p.t = std::stod(stamp);
    } catch (const std::exception&) {
      throw std::runtime_error("'" + path + "' line " + std::to_string(n) + ": the stamp '" + stamp + "' is not a number");
    }
    p.stamp_ns = parseStampNs(stamp);
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

void writeMapCovarianceCsv(const std::string& path, const std::vector<MapPoint>& map) {
  auto f = open(path);
  f << "# skin3d SLAM map: each landmark's position (m, world) and its 3x3 covariance (m^2, upper triangle)\n"
    << "id,x,y,z,c_xx,c_xy,c_xz,c_yy,c_yz,c_zz,observations\n";
  f.precision(17);
  for (const auto& m : map) {
    const Eigen::Matrix3d& C = m.covariance;
    f << m.id << ',' << m.position.x() << ',' << m.position.y() << ',' << m.position.z() << ',' << C(0, 0) << ','
      << C(0, 1) << ',' << C(0, 2) << ',' << C(1, 1) << ',' << C(1, 2) << ',' << C(2, 2) << ',' << m.times_observed
      << '\n';
  }
  close(f, path);
}

void writeStateCsv(const std::string& path, const std::vector<StateRow>& rows) {
  auto f = open(path);
  f << "t,vx,vy,vz,wx,wy,wz,trace_rig,trace_landmarks,trace_all,position_std_m,corr_vx_wy,pool_size,pool_in_use,"
       "ever_seen,measurements,rejected,associated,used,initialised,forks_deleted,pruned,gyro_used,nis,nis_dof,bgx,bgy,bgz\n";
  for (const auto& r : rows)
    f << stampText(r.t) << ',' << r.v.x() << ',' << r.v.y() << ',' << r.v.z() << ',' << r.w.x() << ',' << r.w.y() << ','
      << r.w.z() << ',' << r.trace_rig << ',' << r.trace_landmarks << ',' << r.trace_all << ','
      << r.pose_position_std << ',' << r.corr_vx_wy << ',' << r.pool_size << ',' << r.pool_in_use << ','
      << r.ever_seen << ',' << r.stats.measurements << ',' << r.stats.rejected_invalid << ',' << r.stats.associated
      << ',' << r.stats.used << ',' << r.stats.initialised << ',' << r.stats.forks_deleted << ',' << r.stats.pruned
      << ',' << r.stats.gyro_used << ',' << r.stats.nis << ',' << r.stats.nis_dof << ',' << r.gyro_bias.x() << ','
      << r.gyro_bias.y() << ',' << r.gyro_bias.z() << '\n';
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
    f << stampText(r.t);
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) f << ',' << r.rig_covariance(i, j);
    f << '\n';
  }
  close(f, path);
}

void writePoseCovarianceCsv(const std::string& path, const std::vector<StampedPose>& trajectory,
                            const std::vector<Eigen::Matrix<double, 6, 6>>& covariance) {
  if (covariance.size() != trajectory.size())
    throw std::runtime_error("cannot write '" + path + "': " + std::to_string(covariance.size()) + " covariances for " +
                             std::to_string(trajectory.size()) + " poses");
  auto f = open(path);
  f << "# skin3d smoother pose covariance per frame, row-major (m, rad; theta: R_true = Exp(theta) R); variables: px py "
       "pz thx thy thz\nt";
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 6; ++j) f << ",P_" << i << '_' << j;
  f << '\n';
  f.precision(7);
  for (std::size_t k = 0; k < trajectory.size(); ++k) {
    f << stampText(trajectory[k].t);
    for (int i = 0; i < 6; ++i)
      for (int j = 0; j < 6; ++j) f << ',' << covariance[k](i, j);
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
  writeMapCovarianceCsv(dir + "/map_covariance.csv", run.map);
  writeStateCsv(dir + "/state.csv", run.rows);
  writeRigCovarianceCsv(dir + "/rig_covariance.csv", run.rows);
  if (!run.smoother_pose_covariance.empty())
    writePoseCovarianceCsv(dir + "/smoother_covariance.csv", run.trajectory, run.smoother_pose_covariance);
  else
    std::remove((dir + "/smoother_covariance.csv").c_str());  // an earlier run's
  if (!run.ground_truth.empty()) writeTum(dir + "/ground_truth.tum", run.ground_truth);
  YAML::Emitter y;
  y << YAML::BeginMap;
  for (const auto& kv : run.info) y << YAML::Key << kv.first << YAML::Value << kv.second;
  auto bias = [&y](const char* key, const Eigen::Vector3d& b, const Eigen::Vector3d& std) {
    y << YAML::Key << key << YAML::Value << YAML::BeginMap << YAML::Key << "rad_s" << YAML::Value << YAML::Flow
      << YAML::BeginSeq << b[0] << b[1] << b[2] << YAML::EndSeq << YAML::Key << "std_rad_s" << YAML::Value << YAML::Flow
      << YAML::BeginSeq << std[0] << std[1] << std[2] << YAML::EndSeq << YAML::EndMap;
  };
  if (run.smoother_bias_valid) {
    bias("smoother_final_gyro_bias", run.smoother_bias, run.smoother_bias_std);
    bias("smoother_mean_gyro_bias", run.smoother_mean_bias, run.smoother_mean_bias_std);
  }
  y << YAML::Key << "frames" << YAML::Value << run.trajectory.size();
  y << YAML::Key << "landmarks_in_map" << YAML::Value << run.map.size();
  if (!run.rows.empty()) {
    const StateRow& r = run.rows.back();
    y << YAML::Key << "landmarks_ever_seen" << YAML::Value << r.ever_seen;
    y << YAML::Key << "final_covariance_trace" << YAML::Value << YAML::BeginMap << YAML::Key << "rig" << YAML::Value
      << r.trace_rig << YAML::Key << "landmarks_m2" << YAML::Value << r.trace_landmarks << YAML::Key << "all"
      << YAML::Value << r.trace_all << YAML::EndMap;
    y << YAML::Key << "corr_vx_wy_final" << YAML::Value << r.corr_vx_wy;
    if (r.rig_covariance.rows() == 15) {  // the gyro bias was estimated: its final value and std, rad/s
      y << YAML::Key << "final_gyro_bias" << YAML::Value << YAML::BeginMap << YAML::Key << "rad_s" << YAML::Value
        << YAML::Flow << YAML::BeginSeq;
      for (int i = 0; i < 3; ++i) y << r.gyro_bias[i];
      y << YAML::EndSeq << YAML::Key << "std_rad_s" << YAML::Value << YAML::Flow << YAML::BeginSeq;
      for (int i = 0; i < 3; ++i) y << std::sqrt(std::max(0.0, static_cast<double>(r.rig_covariance(12 + i, 12 + i))));
      y << YAML::EndSeq << YAML::EndMap;
    }
  }
  if (!run.ground_truth.empty()) {
    auto ate = [&](const char* key, AteAlignment a, const char* what) {
      const TrajectoryError e = trajectoryError(run.trajectory, run.ground_truth, a, run.ate_max_dt);
      y << YAML::Key << key << YAML::Value << YAML::BeginMap << YAML::Key << "pairs" << YAML::Value << e.pairs
        << YAML::Key << "rmse_mm" << YAML::Value << 1e3 * e.rmse << YAML::Key << "mean_mm" << YAML::Value
        << 1e3 * e.mean << YAML::Key << "max_mm" << YAML::Value << 1e3 * e.max << YAML::Key << "final_mm"
        << YAML::Value << 1e3 * e.final << YAML::Key << "rotation_rmse_mrad" << YAML::Value << 1e3 * e.rotation_rmse
        << YAML::Key << "alignment" << YAML::Value << ateAlignmentName(e.alignment);
      std::string note = what;
      if (!e.alignment_note.empty()) note += std::string(note.empty() ? "" : "; ") + e.alignment_note;
      if (!note.empty()) y << YAML::Key << "alignment_note" << YAML::Value << note;
      if (e.alignment != AteAlignment::None) {
        const Eigen::Vector3d t = e.transform.translation();
        const Eigen::Quaterniond q(e.transform.linear());
        y << YAML::Key << "alignment_transform" << YAML::Value << YAML::Flow << YAML::BeginSeq << t.x() << t.y()
          << t.z() << q.x() << q.y() << q.z() << q.w() << YAML::EndSeq;
      }
      y << YAML::Key << "max_dt_s" << YAML::Value << e.max_dt;
      y << YAML::Key << "position_spread_mm" << YAML::Value << YAML::Flow << YAML::BeginSeq << 1e3 * e.spread(0)
        << 1e3 * e.spread(1) << 1e3 * e.spread(2) << YAML::EndSeq;
      if (!run.ground_truth_alignment.empty())
        y << YAML::Key << "ground_truth" << YAML::Value << run.ground_truth_alignment;
      y << YAML::EndMap;
    };
    ate("ate", run.ate_alignment, run.ate_alignment == AteAlignment::Auto ? "" : "as asked");
    ate("ate_se3", AteAlignment::SE3, "always SE(3)-aligned (Umeyama, no scale), as evo_ape --align");
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
