// SPDX-License-Identifier: BSD-3-Clause
/**
 * bench_slam [--quick] [--benchmark_* flags of Google Benchmark]
 *
 * ES-EKF SLAM update rate against the landmark-pool size (issue 5): one SLAM frame is
 * Eskf::predict(0.1 s) + Eskf::update() with 30 observations of distinct, randomly chosen active slots
 * (a 90-dimensional stacked update), for pools of K = 100, 300 and 1000 active landmarks
 * (n = 12 + 3 K = 312, 912, 3012 error-state dimensions). Variants, all in the same run:
 *   fast_2threads   structure-aware path, EskfOptions::threads = 2 (the default)
 *   fast_1thread    structure-aware path, threads = 1
 *   fast_1thread_eigen  the same with the downdate through Eigen instead of OpenBLAS (blas_downdate = false;
 *                   the same code as fast_1thread when the library was built without OpenBLAS)
 *   fast_joseph     structure-aware path, joseph_explicit_gain (explicit gain, 2x the flops), threads = 2
 *   dense           the textbook dense reference predictDense() + updateDense() (O(n^3))
 * and, unless --quick, one extra row: fast_2threads and fast_1thread at K = 1000 with 200 observations per
 * frame (the globe experiments' max_updates_per_frame, config/slam_globe.yaml).
 * Then gyro_interval/K:1000 (K:300 with --quick): the 10 gyro samples of one frame (100 Hz, bias estimated),
 * fused one by one (predict + updateGyro each) and by Eskf::propagateWithGyro, side by side (Google
 * Benchmark's own table; not in the summary).
 *
 * Set-up per K (seeded, identical for every variant): rig at the origin moving at 2 cm/s, K landmarks added
 * with addLandmark() from stereo-like measurements (points ~0.4 m in front of the camera, covariance
 * R diag(0.2 mm, 0.2 mm, 1 mm)^2 R^T with a random rotation R), then 5 untimed predict + update frames so the
 * covariance is dense and correlated. fast_2threads and dense start from copies of the very same filter;
 * fast_1thread and fast_joseph are built by the same procedure with their options (equal up to rounding; the
 * largest difference is printed). Every repetition starts from a fresh copy, and every variant sees the same
 * sequence of observed slots and noise draws. Each timed iteration: predict(0.1), then (untimed) 30
 * measurements z = predicted observation + N(0, C) noise against the predicted state, then the update; only
 * predict + update are timed (manual time). The counters report the mean predict and update times and the
 * mean NIS per degree of freedom (a health check: it stays finite and below 1 because the simulated noise is
 * the measurement noise alone).
 *
 * Defaults added unless given: --benchmark_repetitions=5 --benchmark_display_aggregates_only=true
 * (the dense K = 1000 case runs 1 iteration per repetition and at most 3 repetitions: a frame takes seconds).
 * After the runs a summary table (medians over the repetitions) is printed to stdout (to stderr when
 * --benchmark_format is json or csv): per K, ms per frame of each variant, Hz, the dense / fast ratio and
 * whether 30 Hz holds; plus the machine (CPU model, cores, load average, Eigen SIMD) and the date.
 * A benchmark, not a test: nothing is asserted. Exit codes: 0 ok, 1 a benchmark failed, 2 bad command line.
 */
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <exception>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <numeric>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "skin3d/geometry/quaternion.h"
#include "skin3d/slam/eskf.h"

#include "bench_common.h"

namespace {

using skin3d::bench::cpuModel;
using skin3d::bench::loadAverage;
using skin3d::bench::today;

using skin3d::slam::Eskf;
using skin3d::slam::EskfOptions;
using skin3d::slam::RigState;

constexpr double kDt = 0.1;          // s per frame (10 Hz camera)
constexpr int kWarmupFrames = 5;     // untimed frames that correlate the covariance
constexpr int kWarmupObservations = 30;

enum class Variant { kFast2, kFast1, kFast1Eigen, kJoseph, kDense };
constexpr Variant kVariants[] = {Variant::kFast2, Variant::kFast1, Variant::kFast1Eigen, Variant::kJoseph, Variant::kDense};

const char* variantName(Variant v) {
  switch (v) {
    case Variant::kFast2: return "fast_2threads";
    case Variant::kFast1: return "fast_1thread";
    case Variant::kFast1Eigen: return "fast_1thread_eigen";
    case Variant::kJoseph: return "fast_joseph";
    case Variant::kDense: return "dense";
  }
  return "?";
}

EskfOptions variantOptions(Variant v) {
  EskfOptions o;  // defaults otherwise (velocity / angular-rate noise of a hand-held rig)
  o.threads = v == Variant::kFast1 || v == Variant::kFast1Eigen ? 1 : 2;
  o.joseph_explicit_gain = v == Variant::kJoseph;
  o.blas_downdate = v != Variant::kFast1Eigen;
  return o;
}

// The filter the dense reference starts from is the fast_2threads one (it ignores threads and the gain form).
Variant setupVariant(Variant v) { return v == Variant::kDense ? Variant::kFast2 : v; }

Eigen::Vector3d gauss3(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  return Eigen::Vector3d(n(rng), n(rng), n(rng));
}

// Uniformly distributed random rotation (normalised 4-D Gaussian).
Eigen::Matrix3d randomRotation(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  skin3d::geometry::Quat q(n(rng), n(rng), n(rng), n(rng));
  q.normalize();
  return q.toRotationMatrix();
}

// One pool size: the warmed-up filter plus each slot's measurement covariance and its Cholesky factor.
struct Scenario {
  std::unique_ptr<Eskf> filter;
  std::vector<Eigen::Matrix3d> Cz, Lz;
};

// Partial Fisher-Yates: the first `count` entries of `slots` become distinct random slots.
void drawSlots(std::vector<int>& slots, int count, std::mt19937_64& rng) {
  for (int i = 0; i < count; ++i) {
    std::uniform_int_distribution<int> pick(i, static_cast<int>(slots.size()) - 1);
    std::swap(slots[i], slots[pick(rng)]);
  }
}

// count observations of random distinct active slots, consistent with the filter's current state.
void makeObservations(const Eskf& f, const Scenario& sc, std::vector<int>& slots, int count,
                      std::mt19937_64& rng, std::vector<Eskf::Observation>* obs) {
  drawSlots(slots, count, rng);
  obs->resize(count);
  for (int i = 0; i < count; ++i) {
    const int s = slots[i];
    Eskf::Observation& o = (*obs)[i];
    o.slot = s;
    o.z = f.predictObservation(s) + sc.Lz[s] * gauss3(rng);
    o.C = sc.Cz[s];
  }
}

std::unique_ptr<Scenario> buildScenario(int K, Variant v) {
  auto sc = std::make_unique<Scenario>();
  std::mt19937_64 rng(20261121u + static_cast<unsigned>(K));  // same for every variant of one K
  sc->filter = std::make_unique<Eskf>(variantOptions(v));
  Eskf& f = *sc->filter;
  f.setCapacity(K);
  RigState x;
  x.v = Eigen::Vector3d(0.02, 0.0, 0.0);  // hand-held scan: 2 cm/s sideways
  f.reset(x);                             // default rig covariance (pose exactly known: the gauge)
  std::uniform_real_distribution<double> ux(-0.10, 0.10), uy(-0.075, 0.075), uz(-0.03, 0.03);
  const Eigen::Vector3d sd(0.2e-3, 0.2e-3, 1.0e-3);  // stereo: 0.2 mm lateral, 1 mm depth (1 sigma)
  sc->Cz.resize(K);
  sc->Lz.resize(K);
  for (int j = 0; j < K; ++j) {
    const Eigen::Vector3d z(ux(rng), uy(rng), 0.4 + uz(rng));
    const Eigen::Matrix3d R = randomRotation(rng);
    Eigen::Matrix3d C = R * sd.cwiseAbs2().asDiagonal() * R.transpose();
    C = 0.5 * (C + C.transpose());
    sc->Cz[j] = C;
    sc->Lz[j] = C.llt().matrixL();
    f.addLandmark(j, z + sc->Lz[j] * gauss3(rng), C);
  }
  std::vector<int> slots(K);
  std::iota(slots.begin(), slots.end(), 0);
  std::vector<Eskf::Observation> obs;
  for (int k = 0; k < kWarmupFrames; ++k) {
    f.predict(kDt);
    makeObservations(f, *sc, slots, std::min(kWarmupObservations, K), rng, &obs);
    f.update(obs);
  }
  return sc;
}

const Scenario& scenario(int K, Variant v) {
  static std::map<std::pair<int, int>, std::unique_ptr<Scenario>> cache;
  const Variant sv = setupVariant(v);
  auto key = std::make_pair(K, static_cast<int>(sv));
  auto it = cache.find(key);
  if (it == cache.end()) {
    it = cache.emplace(key, buildScenario(K, sv)).first;
    if (sv != Variant::kFast2) {  // report how close it is to the reference set-up
      const Scenario& ref = scenario(K, Variant::kFast2);
      const double dc = (it->second->filter->covariance() - ref.filter->covariance()).cwiseAbs().maxCoeff();
      const double cmax = ref.filter->covariance().cwiseAbs().maxCoeff();
      std::fprintf(stderr, "# set-up K=%d %s: max |C - C_ref| = %.2e (max |C_ref| = %.2e)\n", K,
                   variantName(sv), dc, cmax);
    }
  }
  return *it->second;
}

// One benchmark: frames of predict + update on a fresh copy of the pool's warmed-up filter.
void runFrames(benchmark::State& st, int K, Variant v, int nobs) {
  const Scenario& sc = scenario(K, v);
  Eskf f = *sc.filter;
  std::mt19937_64 rng(7u + 1000u * static_cast<unsigned>(K) + static_cast<unsigned>(nobs));
  std::vector<int> slots(K);
  std::iota(slots.begin(), slots.end(), 0);
  std::vector<Eskf::Observation> obs;
  double t_pred = 0, t_upd = 0, nis = 0;
  long dof = 0;
  const bool dense = v == Variant::kDense;
  using Clock = std::chrono::steady_clock;
  try {
    for (auto _ : st) {
      const auto t0 = Clock::now();
      if (dense) f.predictDense(kDt); else f.predict(kDt);
      const auto t1 = Clock::now();
      makeObservations(f, sc, slots, nobs, rng, &obs);  // not timed
      const auto t2 = Clock::now();
      const Eskf::UpdateResult r = dense ? f.updateDense(obs) : f.update(obs);
      const auto t3 = Clock::now();
      const double tp = std::chrono::duration<double>(t1 - t0).count();
      const double tu = std::chrono::duration<double>(t3 - t2).count();
      st.SetIterationTime(tp + tu);
      t_pred += tp;
      t_upd += tu;
      nis += r.nis;
      dof += r.dof;
    }
  } catch (const std::exception& e) {
    st.SkipWithError(e.what());
    return;
  }
  const Eigen::VectorXd d = f.covariance().diagonal();
  if (!d.allFinite() || d.minCoeff() < -1e-12 || !std::isfinite(nis)) {
    st.SkipWithError("filter became unhealthy (non-finite or negative variance)");
    return;
  }
  const double it = static_cast<double>(std::max<benchmark::IterationCount>(1, st.iterations()));
  st.counters["n"] = f.dim();
  st.counters["m"] = 3 * nobs;
  st.counters["pred_ms"] = 1e3 * t_pred / it;
  st.counters["upd_ms"] = 1e3 * t_upd / it;
  st.counters["frames"] = it;
  st.counters["nis/dof"] = dof > 0 ? nis / static_cast<double>(dof) : 0.0;
}

// The gyro samples between two frames (issue 18): 10 samples at 100 Hz over the frame's 0.1 s, fused one by one
// (predict + updateGyro each: 10 full-covariance updates) or by Eskf::propagateWithGyro (one landmark-block
// update); same filter to rounding (test_eskf). Timed: the 0.1 s of prediction and the 10 gyro updates only.
void runGyroInterval(benchmark::State& st, int K, bool batched) {
  EskfOptions o = variantOptions(Variant::kFast2);
  o.estimate_gyro_bias = true;
  Eskf f(o);
  {
    const Scenario& sc = scenario(K, Variant::kFast2);  // same landmarks, on a 15-dim rig
    f.setCapacity(sc.filter->capacity());
    f.reset(sc.filter->state());
    for (int j = 0; j < sc.filter->capacity(); ++j)
      if (sc.filter->isActive(j)) f.addLandmark(j, sc.filter->predictObservation(j), sc.filter->landmarkCovariance(j));
  }
  std::mt19937_64 rng(11u + static_cast<unsigned>(K));
  std::normal_distribution<double> g(0.0, 0.002);
  const Eigen::Matrix3d C = Eigen::Matrix3d::Identity() * 0.002 * 0.002;
  using Clock = std::chrono::steady_clock;
  try {
    for (auto _ : st) {
      std::vector<Eskf::GyroStep> steps(10);
      for (auto& s : steps) {
        s.dt = kDt / 10;
        s.z = f.state().w + f.state().gyro_bias + Eigen::Vector3d(g(rng), g(rng), g(rng));
        s.C = C;
      }
      const auto t0 = Clock::now();
      if (batched) {
        f.propagateWithGyro(steps);
      } else {
        for (const auto& s : steps) {
          f.predict(s.dt);
          f.updateGyro(s.z, s.C);
        }
      }
      st.SetIterationTime(std::chrono::duration<double>(Clock::now() - t0).count());
    }
  } catch (const std::exception& e) {
    st.SkipWithError(e.what());
    return;
  }
  st.counters["n"] = f.dim();
}

// ----------------------------------------------------------------------------- results and summary

struct Config {
  int K;
  int nobs;
  Variant v;
  std::string name;
};

struct Result {
  bool have = false;
  bool error = false;
  std::string error_message;
  double ms = 0;       // median ms per frame
  double min_ms = 0;   // best repetition
  double cpu_ms = 0;   // median CPU time of the calling thread per frame (includes the untimed measurement set-up)
  double pred_ms = 0, upd_ms = 0, nis_dof = 0;
  int reps = 1;
  long iterations = 0;  // per repetition
};

std::map<std::string, Result> g_results;

double counter(const benchmark::BenchmarkReporter::Run& r, const char* name) {
  auto it = r.counters.find(name);
  return it == r.counters.end() ? 0.0 : static_cast<double>(it->second);
}

// One run's figures (the single run, or the median of the repetitions) into its result.
void take(const benchmark::BenchmarkReporter::Run& r, double ms, double cpu_ms, Result* res) {
  res->ms = ms;
  res->cpu_ms = cpu_ms;
  res->pred_ms = counter(r, "pred_ms");
  res->upd_ms = counter(r, "upd_ms");
  res->nis_dof = counter(r, "nis/dof");
  res->iterations = static_cast<long>(counter(r, "frames"));
  res->reps = static_cast<int>(r.repetitions);
  res->have = true;
}

void collect(const std::vector<benchmark::BenchmarkReporter::Run>& runs) {
  for (const auto& r : runs) {
    Result& res = g_results[r.run_name.function_name];
    if (r.error_occurred) {
      res.error = true;
      res.error_message = r.error_message;
      continue;
    }
    const double ms = r.iterations > 0 ? 1e3 * r.real_accumulated_time / static_cast<double>(r.iterations) : 0;
    const double cpu_ms = r.iterations > 0 ? 1e3 * r.cpu_accumulated_time / static_cast<double>(r.iterations) : 0;
    if (r.run_type == benchmark::BenchmarkReporter::Run::RT_Iteration) {
      if (!res.have || r.repetitions <= 1) {  // the single run when there are no aggregates
        res.min_ms = res.have ? std::min(res.min_ms, ms) : ms;
        take(r, ms, cpu_ms, &res);
      } else {
        res.min_ms = std::min(res.min_ms, ms);
      }
    } else if (r.aggregate_name == "median") {
      take(r, ms, cpu_ms, &res);
    } else if (r.aggregate_name == "min") {
      res.min_ms = ms;
    }
  }
}

// The display reporter of the requested format, collecting the runs as they are reported.
template <typename Base>
class Collecting : public Base {
 public:
  using Base::Base;
  void ReportRuns(const std::vector<benchmark::BenchmarkReporter::Run>& runs) override {
    collect(runs);
    Base::ReportRuns(runs);
  }
};

// About 3 significant digits, never an exponent.
std::string num(double x) {
  char buf[32];
  const double a = std::fabs(x);
  std::snprintf(buf, sizeof buf, a >= 100 ? "%.0f" : a >= 10 ? "%.1f" : a >= 1 ? "%.2f" : "%.3f", x);
  return buf;
}

std::string cell(const Result* r) {
  if (r == nullptr || (!r->have && !r->error)) return "-";
  if (r->error) return "FAILED";
  return num(r->ms) + " (" + num(1e3 / r->ms) + " Hz)";
}

void printSummary(std::FILE* out, const std::vector<Config>& configs, const std::string& load_before) {
  auto find = [&](int K, int nobs, Variant v) -> const Result* {
    for (const Config& c : configs)
      if (c.K == K && c.nobs == nobs && c.v == v) {
        auto it = g_results.find(c.name);
        return it == g_results.end() ? nullptr : &it->second;
      }
    return nullptr;
  };
  int reps = 0;
  for (const auto& kv : g_results) reps = std::max(reps, kv.second.reps);
  std::fprintf(out, "\n## bench_slam summary: ES-EKF SLAM frame = predict(%.1f s) + update(observations)\n", kDt);
  std::fprintf(out, "machine: %s, %u hardware threads, Eigen SIMD: %s; downdate: %s; date %s; load average %s before, %s after\n",
               cpuModel().c_str(), std::thread::hardware_concurrency(), Eigen::SimdInstructionSetsInUse(),
               Eskf::blasAvailable() ? "OpenBLAS (serial)" : "Eigen only", today().c_str(), load_before.c_str(),
               loadAverage().c_str());
  std::fprintf(out, "ms per frame (Hz), median of up to %d repetitions (manual time: predict + update only)\n\n",
               reps);
  std::fprintf(out, "| K | n | obs/frame | fast, 2 threads | fast, 1 thread | fast, 1 thread, Eigen downdate | "
                    "fast, explicit-gain Joseph | dense reference | dense / fast (2 thr) | dense / fast (1 thr) | "
                    ">= 30 Hz (fast, 2 thr / 1 thr) |\n");
  std::fprintf(out, "|---|---|---|---|---|---|---|---|---|---|---|\n");
  auto ratio = [](const Result* a, const Result* b) -> std::string {
    if (a == nullptr || b == nullptr || !a->have || !b->have || a->error || b->error) return "-";
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.0fx", a->ms / b->ms);
    return buf;
  };
  std::vector<std::pair<int, int>> rows;
  for (const Config& c : configs)
    if (std::find(rows.begin(), rows.end(), std::make_pair(c.K, c.nobs)) == rows.end()) rows.emplace_back(c.K, c.nobs);
  bool any = false;
  for (const auto& row : rows) {
    const int K = row.first, nobs = row.second;
    const Result* f2 = find(K, nobs, Variant::kFast2);
    const Result* f1 = find(K, nobs, Variant::kFast1);
    const Result* fe = find(K, nobs, Variant::kFast1Eigen);
    const Result* fj = find(K, nobs, Variant::kJoseph);
    const Result* dn = find(K, nobs, Variant::kDense);
    if (!f2 && !f1 && !fe && !fj && !dn) continue;
    any = true;
    auto holds = [](const Result* r) -> std::string {
      if (!r || !r->have || r->error) return "-";
      const bool med = 1e3 / r->ms >= 30.0, best = 1e3 / r->min_ms >= 30.0;
      return med ? "yes" : (best ? "median no, best repetition yes" : "no");
    };
    const std::string ok = holds(f2) + " / " + holds(f1);
    std::fprintf(out, "| %d | %d | %d | %s | %s | %s | %s | %s | %s | %s | %s |\n", K, 12 + 3 * K, nobs,
                 cell(f2).c_str(), cell(f1).c_str(), cell(fe).c_str(), cell(fj).c_str(), cell(dn).c_str(),
                 ratio(dn, f2).c_str(), ratio(dn, f1).c_str(), ok.c_str());
  }
  if (!any) {
    std::fprintf(out, "(no benchmark matched)\n");
    return;
  }
  std::fprintf(out, "\nper variant (ms): median predict / update; median CPU time of the calling thread per frame (well "
                    "below the frame time with 2 threads = the helper thread waited for a core); best repetition; "
                    "repetitions x timed frames; mean NIS per dof (health)\n");
  for (const Config& c : configs) {
    auto it = g_results.find(c.name);
    if (it == g_results.end()) continue;
    const Result& r = it->second;
    if (r.error) {
      std::fprintf(out, "  %-40s FAILED: %s\n", c.name.c_str(), r.error_message.c_str());
      continue;
    }
    std::fprintf(out, "  %-34s predict %8.3f  update %9.3f  cpu %9.3f  best %9.3f  %d x %ld frames  NIS/dof %.3f\n",
                 c.name.c_str(), r.pred_ms, r.upd_ms, r.cpu_ms, r.min_ms, r.reps, r.iterations, r.nis_dof);
  }
}

bool hasFlag(const std::vector<std::string>& args, const std::string& prefix) {
  for (const std::string& a : args)
    if (a.rfind(prefix, 0) == 0) return true;
  return false;
}

std::string flagValue(const std::vector<std::string>& args, const std::string& prefix) {
  for (const std::string& a : args)
    if (a.rfind(prefix, 0) == 0) return a.substr(prefix.size());
  return "";
}

}  // namespace

int main(int argc, char** argv) {
  // Our own flags first; everything else goes to Google Benchmark.
  bool quick = false;
  std::vector<std::string> args{argv[0]};
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--quick") {
      quick = true;
    } else if (a == "-h" || a == "--help") {
      std::printf(
          "usage: bench_slam [--quick] [--benchmark_* flags]\n"
          "  ES-EKF SLAM frame rate (predict + 30-observation update) against the pool size K = 100, 300, 1000\n"
          "  (--quick: K = 100, 300 only), structure-aware path (2 threads, 1 thread, explicit-gain Joseph)\n"
          "  and the dense reference; a summary table of medians is printed at the end.\n"
          "  Defaults: --benchmark_repetitions=5 --benchmark_display_aggregates_only=true\n"
          "  e.g. --benchmark_filter=K:1000 --benchmark_repetitions=9 --benchmark_format=json\n");
      return 0;
    } else {
      args.push_back(a);
    }
  }
  if (!hasFlag(args, "--benchmark_repetitions")) args.push_back("--benchmark_repetitions=5");
  if (!hasFlag(args, "--benchmark_display_aggregates_only") && !hasFlag(args, "--benchmark_report_aggregates_only"))
    args.push_back("--benchmark_display_aggregates_only=true");
  int reps = 5;
  try {
    reps = std::max(1, std::stoi(flagValue(args, "--benchmark_repetitions=")));
  } catch (const std::exception&) {
  }
  const std::string format = flagValue(args, "--benchmark_format=");

  std::vector<char*> cargv;
  for (std::string& a : args) cargv.push_back(&a[0]);
  cargv.push_back(nullptr);
  int cargc = static_cast<int>(args.size());
  benchmark::Initialize(&cargc, cargv.data());
  if (benchmark::ReportUnrecognizedArguments(cargc, cargv.data())) return 2;

  const std::vector<int> pools = quick ? std::vector<int>{100, 300} : std::vector<int>{100, 300, 1000};
  std::vector<Config> configs;
  auto minStat = [](const std::vector<double>& v) { return v.empty() ? 0.0 : *std::min_element(v.begin(), v.end()); };
  auto add = [&](int K, int nobs, Variant v) {
    std::ostringstream name;
    name << "slam/K:" << K << "/obs:" << nobs << "/" << variantName(v);
    configs.push_back({K, nobs, v, name.str()});
    auto* b = benchmark::RegisterBenchmark(configs.back().name.c_str(),
                                           [K, nobs, v](benchmark::State& st) { runFrames(st, K, v, nobs); });
    b->UseManualTime()->Unit(benchmark::kMillisecond)->ComputeStatistics("min", minStat);
    if (v == Variant::kDense && K >= 1000) {
      b->Iterations(1)->Repetitions(std::min(reps, 3));  // seconds per frame
    } else if (nobs > 30) {
      b->MinTime(1.5);  // ~0.2-0.3 s per frame: a few more frames per repetition
    } else {
      b->MinTime(0.5);
    }
  };
  for (int K : pools)
    for (Variant v : kVariants) add(K, 30, v);
  if (!quick) {
    add(1000, 200, Variant::kFast2);
    add(1000, 200, Variant::kFast1);
    add(1000, 200, Variant::kFast1Eigen);
  }
  // The gyro between two frames, one by one against propagateWithGyro (printed by Google Benchmark's own table).
  for (int K : {quick ? 300 : 1000})
    for (bool batched : {false, true}) {
      const std::string name = "gyro_interval/K:" + std::to_string(K) + "/10_samples/" +
                               (batched ? "propagateWithGyro" : "one_by_one");
      benchmark::RegisterBenchmark(name.c_str(), [K, batched](benchmark::State& st) { runGyroInterval(st, K, batched); })
          ->UseManualTime()
          ->Unit(benchmark::kMillisecond)
          ->MinTime(0.5);
    }

  const std::string load_before = loadAverage();
  std::unique_ptr<benchmark::BenchmarkReporter> reporter;
  if (format == "json") {
    reporter = std::make_unique<Collecting<benchmark::JSONReporter>>();
  } else if (format == "csv") {
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wdeprecated-declarations"  // deprecated in 1.7.1, still supported by the flag
    reporter = std::make_unique<Collecting<benchmark::CSVReporter>>();
#pragma GCC diagnostic pop
  } else if (format.empty() || format == "console") {
    const bool color = isatty(fileno(stdout)) != 0;
    reporter = std::make_unique<Collecting<benchmark::ConsoleReporter>>(
        color ? benchmark::ConsoleReporter::OO_ColorTabular : benchmark::ConsoleReporter::OO_Tabular);
  } else {
    std::fprintf(stderr, "bench_slam: unknown --benchmark_format=%s (console, json or csv)\n", format.c_str());
    return 2;
  }
  benchmark::RunSpecifiedBenchmarks(reporter.get());
  benchmark::Shutdown();

  std::fflush(stdout);
  std::FILE* out = (format == "json" || format == "csv") ? stderr : stdout;
  printSummary(out, configs, load_before);
  std::fflush(out);
  for (const auto& kv : g_results)
    if (kv.second.error) return 1;
  return 0;
}
