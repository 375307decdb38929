// SPDX-License-Identifier: BSD-3-Clause
// Error-state EKF SLAM: the covariance kernels of the update (lower-triangle downdate, triangular solve, mirror),
// split over threads, through OpenBLAS when the build found it (SKIN3D_HAVE_OPENBLAS), else through Eigen.
#include "skin3d/slam/eskf.h"

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <mutex>
#include <system_error>
#include <thread>
#include <vector>

#include "eskf_detail.h"

#ifdef SKIN3D_HAVE_OPENBLAS
#include <cblas.h>
// OpenBLAS's own extensions (declared in its cblas.h; repeated here in case another cblas.h comes first)
extern "C" {
int openblas_get_parallel(void);
void openblas_set_num_threads(int num_threads);
}
#endif

namespace skin3d {
namespace slam {
namespace eskf_detail {
namespace {

// Columns [begin, end) of an n x n matrix split into `parts` pieces holding equal areas of the lower
// triangle (piece k starts at n (1 - sqrt(1 - k / parts))).
std::vector<int> triangleSplit(int n, int parts) {
  std::vector<int> b(parts + 1);
  for (int k = 0; k <= parts; ++k)
    b[k] = static_cast<int>(std::lround(n * (1.0 - std::sqrt(1.0 - static_cast<double>(k) / parts))));
  b[parts] = n;
  return b;
}

// Runs body(k) for k = 0..parts-1, parts-1 of them on new threads and the last on the caller's. The
// pieces write disjoint data; if a thread cannot be started its piece runs on the calling thread.
template <typename Body>
void runParallel(int parts, const Body& body) {
  std::vector<std::thread> pool;
  std::vector<int> local;
  pool.reserve(parts - 1);
  for (int k = 0; k + 1 < parts; ++k) {
    try {
      pool.emplace_back(body, k);
    } catch (const std::system_error&) {
      local.push_back(k);
    }
  }
  local.push_back(parts - 1);
  for (int k : local) body(k);
  for (auto& t : pool) t.join();
}

int usefulThreads(int n, int threads) { return n < 384 ? 1 : std::max(1, std::min(threads, 8)); }

#ifdef SKIN3D_HAVE_OPENBLAS
// OpenBLAS picks its kernels for the CPU at run time (AVX2 / AVX-512 where Eigen is compiled for SSE2 only).
// The threads are ours (runParallel): a multi-threaded OpenBLAS found at run time is set to one thread.
void useSerialBlas() {
  static std::once_flag once;
  std::call_once(once, [] {
    if (openblas_get_parallel() != 0) openblas_set_num_threads(1);
  });
}
#endif

}  // namespace

// Lower triangle (diagonal included) of C += alpha X Y^T; the strict upper triangle is not touched.
// With OpenBLAS and X == Y (the default update's C - U U^T): dsyrk on each part's diagonal block, dgemm below it.
void lowerUpdate(Eigen::MatrixXd& C, const Eigen::MatrixXd& X, const Eigen::MatrixXd& Y, double alpha,
                 int threads, bool use_blas) {
  const int n = static_cast<int>(C.rows());
  const int parts = usefulThreads(n, threads);
  const std::vector<int> b = triangleSplit(n, parts);
#ifdef SKIN3D_HAVE_OPENBLAS
  const bool blas = use_blas && &X == &Y && X.cols() > 0;
  if (blas) useSerialBlas();
#else
  const bool blas = false;
  (void)use_blas;
#endif
  runParallel(parts, [&](int k) {
    const int c0 = b[k], w = b[k + 1] - b[k], below = n - b[k + 1];
    if (w <= 0) return;
#ifdef SKIN3D_HAVE_OPENBLAS
    if (blas) {
      const int m = static_cast<int>(X.cols()), ldx = static_cast<int>(X.outerStride());
      const int ldc = static_cast<int>(C.outerStride());
      double* c = C.data();
      cblas_dsyrk(CblasColMajor, CblasLower, CblasNoTrans, w, m, alpha, X.data() + c0, ldx, 1.0, c + c0 + c0 * ldc, ldc);
      if (below > 0)
        cblas_dgemm(CblasColMajor, CblasNoTrans, CblasTrans, below, w, m, alpha, X.data() + c0 + w, ldx, X.data() + c0,
                    ldx, 1.0, c + (c0 + w) + c0 * ldc, ldc);
      return;
    }
#endif
    (void)blas;
    C.block(c0, c0, w, w).triangularView<Eigen::Lower>() +=
        alpha * X.middleRows(c0, w) * Y.middleRows(c0, w).transpose();
    if (below > 0)
      C.block(c0 + w, c0, below, w).noalias() += alpha * X.bottomRows(below) * Y.middleRows(c0, w).transpose();
  });
}

// U <- U L^-T for the lower-triangular Cholesky factor L of S (m x m): the rows of U are independent, so they are
// split over the threads; each part through OpenBLAS's dtrsm (run-time CPU kernels) when use_blas, else Eigen.
void solveRightLowerTransposed(Eigen::MatrixXd& U, const Eigen::MatrixXd& L, int threads, bool use_blas) {
  const int n = static_cast<int>(U.rows()), m = static_cast<int>(U.cols());
  if (n == 0 || m == 0) return;
  const int parts = usefulThreads(n, threads);
#ifdef SKIN3D_HAVE_OPENBLAS
  if (use_blas) useSerialBlas();
#else
  use_blas = false;
#endif
  runParallel(parts, [&](int k) {
    const int r0 = static_cast<int>(static_cast<long>(n) * k / parts);
    const int r1 = static_cast<int>(static_cast<long>(n) * (k + 1) / parts);
    if (r1 <= r0) return;
#ifdef SKIN3D_HAVE_OPENBLAS
    if (use_blas) {
      cblas_dtrsm(CblasColMajor, CblasRight, CblasLower, CblasTrans, CblasNonUnit, r1 - r0, m, 1.0, L.data(),
                  static_cast<int>(L.outerStride()), U.data() + r0, static_cast<int>(U.outerStride()));
      return;
    }
#endif
    auto rows = U.middleRows(r0, r1 - r0);
    L.triangularView<Eigen::Lower>().transpose().solveInPlace<Eigen::OnTheRight>(rows);
  });
}

// Copies the strict lower triangle onto the upper one (exact symmetry), in cache-sized tiles.
void mirrorLower(Eigen::MatrixXd& C, int threads) {
  const int n = static_cast<int>(C.rows());
  constexpr int kTile = 64;
  // Upper-triangle area left of column j grows like j^2: split the columns at n sqrt(k / parts).
  const int parts = usefulThreads(n, threads);
  std::vector<int> b(parts + 1);
  for (int k = 0; k <= parts; ++k)
    b[k] = static_cast<int>(std::lround(n * std::sqrt(static_cast<double>(k) / parts)));
  b[parts] = n;
  double* data = C.data();
  const Eigen::Index ld = C.outerStride();
  runParallel(parts, [&](int k) {
    for (int j0 = b[k]; j0 < b[k + 1]; j0 += kTile) {
      const int j1 = std::min(j0 + kTile, b[k + 1]);
      for (int i0 = 0; i0 < j1; i0 += kTile) {
        const int i1 = std::min(i0 + kTile, j1);
        for (int j = j0; j < j1; ++j) {
          double* col = data + j * ld;   // C(., j)
          const int iend = std::min(i1, j);
          for (int i = i0; i < iend; ++i) col[i] = data[i * ld + j];  // C(i, j) = C(j, i)
        }
      }
    }
  });
}

}  // namespace eskf_detail

// ============================================================================ options

bool Eskf::blasAvailable() {
#ifdef SKIN3D_HAVE_OPENBLAS
  return true;
#else
  return false;
#endif
}

}  // namespace slam
}  // namespace skin3d
