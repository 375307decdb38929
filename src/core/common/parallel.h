#pragma once
// Internal to the core: independent image operations side by side on OpenCV's thread pool.

#include <functional>
#include <vector>

#include <opencv2/core/utility.hpp>

namespace skin3d {

/**
 * Runs independent tasks on OpenCV's thread pool (on two cores, two at a time). Each task must write only its
 * own outputs. Meant for pairs of whole-image filters (the left and right views, a map and its weights): a
 * single OpenCV filter mostly runs on one core, two side by side take about half the time.
 */
inline void runTasks(const std::vector<std::function<void()>>& tasks) {
  cv::parallel_for_(cv::Range(0, static_cast<int>(tasks.size())), [&](const cv::Range& r) {
    for (int i = r.start; i < r.end; ++i) tasks[static_cast<std::size_t>(i)]();
  });
}

/** f(i) for every i in [0, n) (an index of points, an image row), in parallel stripes; each call must write
 *  only its own outputs. */
template <class Index, class F>
void forEachIndex(Index n, const F& f) {
  cv::parallel_for_(cv::Range(0, static_cast<int>(n)), [&](const cv::Range& r) {
    for (int i = r.start; i < r.end; ++i) f(static_cast<Index>(i));
  });
}

}  // namespace skin3d
